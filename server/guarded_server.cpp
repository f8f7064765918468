// Connections with a deadline per request for cpp-httplib: see guarded_server.h.
#include "server/guarded_server.h"

#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <string>

namespace lodstream::serve {
namespace {

using Clock = std::chrono::steady_clock;

void address_of(int fd, bool peer, std::string& ip, int& port) {
  sockaddr_storage addr{};
  socklen_t len = sizeof addr;
  const int rc = peer ? ::getpeername(fd, reinterpret_cast<sockaddr*>(&addr), &len)
                      : ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  ip.clear();
  port = 0;
  if (rc != 0) return;
  char host[NI_MAXHOST], serv[NI_MAXSERV];
  if (::getnameinfo(reinterpret_cast<sockaddr*>(&addr), len, host, sizeof host, serv, sizeof serv,
                    NI_NUMERICHOST | NI_NUMERICSERV) != 0)
    return;
  ip = host;
  port = std::atoi(serv);
}

// The socket's stream for one connection. Reads are buffered (the library reads request heads a byte at
// a time); every wait is bounded by the idle timeout and by what is left of the request's allowance.
class DeadlineStream final : public httplib::Stream {
 public:
  DeadlineStream(int fd, const ConnectionLimits& limits) : fd_(fd), limits_(limits) {}

  // A new request begins: its allowance starts now, with nothing moved yet.
  void start_request() {
    start_ = Clock::now();
    moved_ = 0;
  }

  bool has_buffered() const { return begin_ < end_; }

  bool is_readable() const override { return has_buffered() || wait(POLLIN); }
  bool is_writable() const override { return wait(POLLOUT); }

  ssize_t read(char* ptr, size_t size) override {
    if (size == 0) return 0;
    if (!has_buffered()) {
      if (!wait(POLLIN)) return -1;
      ssize_t n;
      do n = ::recv(fd_, buffer_, sizeof buffer_, 0);
      while (n < 0 && errno == EINTR);
      if (n <= 0) return n;
      begin_ = 0;
      end_ = static_cast<size_t>(n);
    }
    const size_t n = std::min(size, end_ - begin_);
    std::copy(buffer_ + begin_, buffer_ + begin_ + n, ptr);
    begin_ += n;
    moved_ += n;
    return static_cast<ssize_t>(n);
  }

  using httplib::Stream::write;
  ssize_t write(const char* ptr, size_t size) override {
    if (!wait(POLLOUT)) return -1;
    ssize_t n;
    do n = ::send(fd_, ptr, size, MSG_NOSIGNAL);
    while (n < 0 && errno == EINTR);
    if (n > 0) moved_ += static_cast<size_t>(n);
    return n;
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override { address_of(fd_, true, ip, port); }
  void get_local_ip_and_port(std::string& ip, int& port) const override { address_of(fd_, false, ip, port); }
  socket_t socket() const override { return fd_; }

 private:
  // Milliseconds the request may still wait: its allowance (head_seconds + moved / min_rate) less the
  // time it has taken, capped by the idle timeout; 0 when it has fallen behind.
  int wait_budget_ms() const {
    using namespace std::chrono;
    const double allowance = limits_.head_seconds + static_cast<double>(moved_) / static_cast<double>(std::max<size_t>(limits_.min_rate, 1));
    const double taken = duration<double>(Clock::now() - start_).count();
    const double left = std::min(allowance - taken, static_cast<double>(limits_.idle_seconds));
    return left <= 0 ? 0 : static_cast<int>(std::ceil(left * 1000));
  }

  bool wait(short events) const {
    for (;;) {
      const int ms = wait_budget_ms();
      if (ms == 0) return false;
      pollfd p{fd_, events, 0};
      const int rc = ::poll(&p, 1, ms);
      if (rc < 0 && errno == EINTR) continue;
      return rc > 0 && (p.revents & (events | POLLHUP | POLLERR)) != 0;
    }
  }

  int fd_;
  ConnectionLimits limits_;
  Clock::time_point start_ = Clock::now();
  size_t moved_ = 0;
  char buffer_[4096];
  size_t begin_ = 0, end_ = 0;
};

// Waits up to `seconds` for the next request's first byte, in short slices so that a stopping server is
// noticed; false when the client stays silent, hangs up, or the server stops.
bool next_request_arrives(const DeadlineStream& strm, int fd, int seconds, const std::atomic<socket_t>& listening) {
  if (strm.has_buffered()) return true;
  const auto until = Clock::now() + std::chrono::seconds(seconds);
  while (listening != INVALID_SOCKET && Clock::now() < until) {
    pollfd p{fd, POLLIN, 0};
    const int rc = ::poll(&p, 1, 100);
    if (rc < 0 && errno != EINTR) return false;
    if (rc > 0) {
      if ((p.revents & POLLIN) == 0) return false;
      char byte;
      return ::recv(fd, &byte, 1, MSG_PEEK) > 0;  // 0: the client closed its side
    }
  }
  return false;
}

// Closes after a lingering read, as web servers do: a client still sending a body the server did not
// want (an upload over the cap answered 413 early) would otherwise get a reset and lose the answer.
// The read is bounded in time and bytes, and ends at the first half second without data, so a client
// cannot hold the thread with it.
void linger_and_close(int fd) {
  constexpr auto kLinger = std::chrono::seconds(2);
  constexpr int kQuietMs = 500;
  constexpr size_t kLingerBytes = 64 << 20;
  ::shutdown(fd, SHUT_WR);
  const auto until = Clock::now() + kLinger;
  char sink[16384];
  size_t drained = 0;
  while (drained < kLingerBytes && Clock::now() < until) {
    pollfd p{fd, POLLIN, 0};
    const int rc = ::poll(&p, 1, kQuietMs);
    if (rc < 0 && errno == EINTR) continue;
    if (rc <= 0) break;
    const ssize_t n = ::recv(fd, sink, sizeof sink, 0);
    if (n <= 0) break;
    drained += static_cast<size_t>(n);
  }
  ::close(fd);
}

// cpp-httplib's thread pool, counting the connections that wait for a thread.
class CountingPool final : public httplib::TaskQueue {
 public:
  CountingPool(size_t threads, std::atomic<size_t>& waiting) : pool_(threads), waiting_(waiting) {}
  void enqueue(std::function<void()> fn) override {
    ++waiting_;
    pool_.enqueue([this, fn = std::move(fn)] {
      --waiting_;
      fn();
    });
  }
  void shutdown() override { pool_.shutdown(); }

 private:
  httplib::ThreadPool pool_;
  std::atomic<size_t>& waiting_;
};

}  // namespace

GuardedServer::GuardedServer(const ConnectionLimits& limits) : limits_(limits) {
  new_task_queue = [this] { return new CountingPool(std::max<size_t>(limits_.threads, 1), waiting_); };
}

void GuardedServer::widen_backlog(int backlog) {
  if (svr_sock_ != INVALID_SOCKET) ::listen(svr_sock_, backlog);
}

bool GuardedServer::process_and_close_socket(socket_t sock) {
  DeadlineStream strm(sock, limits_);
  bool ok = false;
  for (int left = limits_.keep_alive_requests; left > 0; --left) {
    if (!next_request_arrives(strm, sock, limits_.keep_alive_seconds, svr_sock_)) break;
    strm.start_request();
    bool closed = false;
    const bool last = left == 1 || waiting_ > 0;
    ok = process_request(strm, last, closed, [](httplib::Request&) {});
    if (!ok || closed || last) break;
  }
  linger_and_close(sock);
  return ok;
}

}  // namespace lodstream::serve
