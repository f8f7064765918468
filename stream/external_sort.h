// External merge sort of fixed-size records under a memory budget.
//
// Records are pushed into one in-memory buffer; a full buffer is sorted (tbb::parallel_sort) and written
// to a run file. merge() visits every record in order: straight from the buffer when nothing spilled,
// otherwise by a k-way heap merge of the runs with one read buffer per run, the last run being the
// records still in the buffer (sorted, never written: writes into the page cache cost more than the
// sort); each run file is deleted as soon as it is exhausted (DuckDB's "free merged runs behind the
// readers"), and where the file system allows, the blocks of a run are released as they are read.
// Memory: the buffer, then the buffer's records and the run readers within the same budget
// (but at least 4096 records of read buffer per run file).
//
// Determinism: `Less` must be a total order on everything that distinguishes two records (break ties by
// an id), so the output is the same whatever the buffer size, i.e. whatever the memory budget.
#pragma once

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include <tbb/parallel_sort.h>

#include "core/status.h"
#include "io/file_writer.h"
#include "stream/work_dir.h"

namespace lodstream::stream {

template <class Rec, class Less>
class ExternalSorter {
  static_assert(std::is_trivially_copyable_v<Rec>, "records are written to disk as bytes");

 public:
  ExternalSorter(const WorkDir& dir, std::string name, uint64_t memory_bytes, Less less = Less())
      : dir_(dir), name_(std::move(name)), less_(less) {
    capacity_ = std::max<uint64_t>(memory_bytes / sizeof(Rec), 1024);
    limit_ = capacity_;
  }
  ExternalSorter(const ExternalSorter&) = delete;
  ExternalSorter& operator=(const ExternalSorter&) = delete;
  ~ExternalSorter() {
    for (const Run& r : runs_)
      if (!r.kept) ::unlink(r.path.c_str());
  }

  // Hint: about `total` records will be pushed (an upper bound is best). The first run is then cut short so
  // that the last one, which is merged from memory and never written, is a full buffer: of N records
  // with room for C, N − C are written instead of up to N − 1. Only the run boundaries change, never the
  // merged order.
  void expect(uint64_t total) {
    if (runs_.empty() && buffer_.empty() && total > capacity_) {
      const uint64_t rest = total % capacity_;
      limit_ = rest ? rest : capacity_;
    }
  }

  void push(const Rec& r) {
    if (buffer_.size() == limit_) {
      spill();
      limit_ = capacity_;
    }
    // Reserving does not make pages resident; growing by doubling would briefly hold 1.5x the buffer.
    if (buffer_.capacity() == 0) buffer_.reserve(static_cast<size_t>(capacity_));
    buffer_.push_back(r);
  }
  void push(std::span<const Rec> records) {
    for (const Rec& r : records) push(r);
  }
  // A run sorted elsewhere (another process's records, written as raw records in `less` order), merged
  // with the others: `records` records from record `first` of the file. Merging reads it and leaves it as
  // it is: its owner removes it.
  void add_sorted_run(const std::string& path, uint64_t records, uint64_t first = 0) {
    runs_.push_back({path, records, true, first});
  }
  size_t runs() const { return runs_.size(); }
  uint64_t spilled_records() const {
    uint64_t n = 0;
    for (const Run& r : runs_) n += r.records;
    return n;
  }

  // Calls visit(const Rec&) for every record in sorted order. Can be called once.
  template <class Visit>
  void merge(Visit&& visit) {
    tbb::parallel_sort(buffer_.begin(), buffer_.end(), less_);
    if (runs_.empty()) {
      for (const Rec& r : buffer_) visit(r);
      release(buffer_);
      return;
    }
    // The records still buffered are not spilled: sorted in place, they are merged from memory as the
    // last run (where a spill would have put them), and the file runs share what is left of the budget.
    const size_t files = runs_.size();
    const size_t k = files + (buffer_.empty() ? 0 : 1);
    const uint64_t per_run = std::max<uint64_t>((capacity_ - buffer_.size()) / files, 4096);
    std::vector<Reader> readers(k);
    for (size_t i = 0; i < files; ++i) readers[i].open(runs_[i], per_run);
    if (k > files) readers[files].open_memory(buffer_.data(), buffer_.size());
    // Min-heap of run indices on their current record; ties go to the lower run so equal records
    // keep a fixed order.
    std::vector<size_t> heap;
    auto greater = [&](size_t a, size_t b) {
      const Rec& ra = readers[a].current();
      const Rec& rb = readers[b].current();
      if (less_(rb, ra)) return true;
      if (less_(ra, rb)) return false;
      return a > b;
    };
    for (size_t i = 0; i < k; ++i)
      if (readers[i].valid()) heap.push_back(i);
    std::make_heap(heap.begin(), heap.end(), greater);
    while (!heap.empty()) {
      std::pop_heap(heap.begin(), heap.end(), greater);
      const size_t i = heap.back();
      visit(readers[i].current());
      if (readers[i].advance()) {
        std::push_heap(heap.begin(), heap.end(), greater);
      } else {
        heap.pop_back();
        readers[i].close();
      }
    }
    runs_.clear();
    release(buffer_);
  }

 private:
  struct Run {
    std::string path;
    uint64_t records = 0;
    bool kept = false;  // add_sorted_run's: read, never punched or removed
    uint64_t first = 0;  // the run's first record in the file
  };

  // Reads one run sequentially through a buffer of `records` records and deletes it when done.
  class Reader {
   public:
    ~Reader() { close(); }
    void open(const Run& run, uint64_t records) {
      path_ = run.path;
      left_ = run.records;
      kept_ = run.kept;
      // Read-write only to release what has been read (refill()).
      fd_ = ::open(path_.c_str(), (kept_ ? O_RDONLY : O_RDWR) | O_CLOEXEC);
      if (fd_ < 0) fail(Status::io_error, path_ + ": cannot open sort run: " + std::strerror(errno));
      if (run.first && ::lseek(fd_, static_cast<off_t>(run.first * sizeof(Rec)), SEEK_SET) < 0)
        fail(Status::io_error, path_ + ": cannot seek in sort run: " + std::strerror(errno));
      buf_.resize(static_cast<size_t>(std::min<uint64_t>(records, std::max<uint64_t>(left_, 1))));
      refill();
    }
    // Reads n records at `data` (which must outlive the reader) instead of a file.
    void open_memory(const Rec* data, size_t n) {
      data_ = data;
      pos_ = 0;
      len_ = n;
    }
    bool valid() const { return pos_ < len_; }
    const Rec& current() const { return data_[pos_]; }
    bool advance() {
      if (++pos_ < len_) return true;
      refill();
      return pos_ < len_;
    }
    void close() {
      if (fd_ >= 0) {
        ::close(fd_);
        if (!kept_) ::unlink(path_.c_str());
        fd_ = -1;
      }
      release(buf_);
    }

   private:
    void refill() {
      pos_ = len_ = 0;
      // Every record read so far has been visited: give its blocks back to the file system, so that the
      // runs shrink while the merged output grows and the merge needs little more disk than its output.
      // Where the file system cannot punch holes the run is freed at the end, as before.
      if (!kept_ && read_bytes_ > punched_bytes_) {
        fallocate(fd_, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, static_cast<off_t>(punched_bytes_),
                  static_cast<off_t>(read_bytes_ - punched_bytes_));
        punched_bytes_ = read_bytes_;
      }
      if (left_ == 0) return;
      const size_t n = static_cast<size_t>(std::min<uint64_t>(left_, buf_.size()));
      char* p = reinterpret_cast<char*>(buf_.data());
      size_t want = n * sizeof(Rec), got = 0;
      while (got < want) {
        const ssize_t r = ::read(fd_, p + got, want - got);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) fail(Status::io_error, path_ + ": cannot read sort run: " + std::strerror(r < 0 ? errno : EIO));
        got += static_cast<size_t>(r);
      }
      read_bytes_ += want;
      data_ = buf_.data();
      len_ = n;
      left_ -= n;
    }
    std::string path_;
    int fd_ = -1;
    bool kept_ = false;
    uint64_t left_ = 0;
    uint64_t read_bytes_ = 0, punched_bytes_ = 0;
    std::vector<Rec> buf_;
    const Rec* data_ = nullptr;  // buf_, or the records given to open_memory
    size_t pos_ = 0, len_ = 0;
  };

  template <class V>
  static void release(V& v) {
    V().swap(v);
  }

  void spill() {
    tbb::parallel_sort(buffer_.begin(), buffer_.end(), less_);
    Run run{dir_.scratch("sort-" + name_), buffer_.size()};
    io::FileWriter w(run.path, 4 << 20);
    w.write(buffer_.data(), buffer_.size() * sizeof(Rec));
    w.commit();
    runs_.push_back(std::move(run));
    buffer_.clear();
  }

  const WorkDir& dir_;
  std::string name_;
  Less less_;
  uint64_t capacity_ = 0;
  uint64_t limit_ = 0;  // records in the buffer that trigger a spill: capacity_, or less for the first run
  std::vector<Rec> buffer_;
  std::vector<Run> runs_;
};

}  // namespace lodstream::stream
