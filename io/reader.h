// The contract between the format readers (io/) and the ingest pipeline (stream/ingest.cpp).
//
// The pipeline runs three stages over the input, as a TBB parallel_pipeline with a bounded number of
// chunks in flight:
//   1. next_chunk  (one thread, file order)   cut a byte range of whole records and map it
//   2. parse       (many threads, any order)  turn the bytes into positions and vertex references
//   3. resolve     (one thread, file order)   make references and object ids global, raise the first error
// and then finish() once. Readers never allocate from header counts: every buffer grows with the bytes
// actually parsed, so a lying header costs nothing but its error message.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "io/mapped_file.h"

namespace lodstream::io {

// A byte range of the input holding whole records, cut by Reader::next_chunk.
struct Chunk {
  uint64_t seq = 0;           // chunk number in file order, from 0
  Window bytes;               // the mapped range [begin, end)
  uint32_t section = 0;       // reader-defined (PLY: index of the element the records belong to)
  uint64_t first_record = 0;  // reader-defined (PLY: index of the first record within its element)
  uint64_t record_count = 0;  // reader-defined (PLY: records in the chunk)
  uint64_t first_line = 0;    // reader-defined; 1-based line of bytes.begin() when the splitter knows it
};

// The first problem found in a chunk. Recorded by parse() (which must not throw for bad data) and raised
// by resolve(), so that the error the user sees is the first one in file order.
struct ParseError {
  bool set = false;
  uint64_t offset = 0;  // absolute byte offset of the offending record or byte
  uint64_t line = 0;    // for text formats: 1-based line number counted from the chunk's first byte; 0 = none
  std::string message;  // what is wrong, without the file name or location
};

// What one chunk parses into. Vertex references are reader-encoded after parse() and global 0-based
// vertex ids after resolve(). Object ids likewise become global ids into Reader::object_names().
struct ParsedChunk {
  uint64_t seq = 0;
  std::vector<double> positions;   // x, y, z per vertex record (per triangle corner for soup readers)
  std::vector<int64_t> triangles;  // 3 references per triangle, faces already split by add_face()
  // Compact forms a non-soup reader may fill instead, to save the widening and narrowing copies on hot
  // paths: positions32 (only when single_precision(); exact) in place of positions, and triangles32 in
  // place of triangles, holding final global vertex ids already checked against the vertex count. A chunk
  // uses one form of each pair, never both.
  std::vector<float> positions32;
  std::vector<uint32_t> triangles32;
  std::vector<int64_t> lines;      // 2 references per segment (polylines already split)
  std::vector<int64_t> points;     // 1 reference per point
  std::vector<uint32_t> triangle_objects;  // one per triangle (per soup triangle)
  std::vector<uint32_t> line_objects;      // one per segment
  std::vector<uint32_t> point_objects;     // one per point
  // Material ids into Reader::materials() after resolve(), one per primitive; empty means all 0 (always
  // so when the reader has no materials).
  std::vector<uint32_t> triangle_materials, line_materials, point_materials;
  // With Reader::has_colors(): RGBA (0..255) per vertex record parsed in this chunk.
  std::vector<uint8_t> colors;
  std::vector<std::string> object_names;   // reader-defined: names met in this chunk, for resolve()
  uint64_t polygons = 0;   // input faces in this chunk (OBJ f, PLY face records, STL facets)
  // Faces of m >= 4 distinct vertices, whose triangles need the positions: pairs (index of the face's first
  // triangle in this chunk, m). Their triangles are a placeholder, the fan (r0, ri, ri+1) of the face's
  // ring r, which ingest replaces by core::triangulate_polygon's triangles in place (same count, m - 2).
  std::vector<uint64_t> planar_faces;
  uint64_t degenerate = 0;     // triangle slots faces lost to repeated corners (see add_face)
  uint64_t face_segments = 0;  // line segments made from faces (see add_face), counted among `lines`
  std::vector<int64_t> face_scratch;  // reader scratch for one face, kept across chunks by clear()
  uint64_t skipped = 0;    // records recognised and deliberately not used (OBJ vt/vn/usemtl, ...)
  uint64_t newlines = 0;   // line breaks in the chunk (text formats), so resolve() can number lines
  int64_t reader_state = 0;  // reader-defined scratch value carried from parse() to resolve()
  ParseError error;

  void clear();  // empties every vector, keeping capacity
};

class Reader {
 public:
  explicit Reader(const MappedFile& file) : file_(file) {}
  virtual ~Reader() = default;

  // "obj", "ply-ascii", "ply-binary-le", "ply-binary-be", "stl-binary", "stl-ascii", "glb", "gltf".
  virtual std::string format() const = 0;
  // True when positions are per triangle corner with no shared indices (STL): the pipeline welds them by
  // exact position, and triangles/lines/points stay empty.
  virtual bool soup() const { return false; }
  // True when every coordinate the file can hold is a 32-bit float (PLY float x/y/z, STL): the store then
  // keeps positions as float, which is exact and half the bytes. Known after open().
  virtual bool single_precision() const { return false; }
  // True when vertices carry colours (PLY red/green/blue[/alpha]): every chunk then fills
  // ParsedChunk::colors. Known after open(). Never for soups.
  virtual bool has_colors() const { return false; }
  // Reads and checks the header, if any. Throws Failure(bad_data) with a location.
  virtual void open() {}
  // Cuts the next chunk of whole records starting where the previous one ended, of about `target_bytes`
  // (at least one record, even when target_bytes is 1) and maps it into chunk->bytes. Returns false at the
  // end of the data. Called from one thread, in file order. May throw Failure(bad_data) when the record
  // structure itself is broken (e.g. a truncated binary record).
  virtual bool next_chunk(uint64_t target_bytes, Chunk* chunk) = 0;
  // Parses one chunk into `out` (which arrives cleared). Called from several threads at once on distinct
  // chunks: must not modify the reader. Never throws for bad data: records the first problem in
  // out->error and returns.
  virtual void parse(const Chunk& chunk, ParsedChunk* out) const = 0;
  // Called from one thread, in file order, on every parsed chunk. Raises chunk->error if set (as
  // Failure(bad_data) with file and location), turns references into global 0-based vertex ids, object
  // ids into global ids, and checks whatever depends on earlier chunks.
  virtual void resolve(ParsedChunk* chunk) = 0;
  // After the last chunk, with the number of vertex records seen: checks that need the whole file
  // (counts the header promised, references to vertices defined later). Throws Failure(bad_data).
  virtual void finish(uint64_t vertex_records) {}

  // Global object names, index = object id. Readers without objects report one unnamed object.
  const std::vector<std::string>& object_names() const { return object_names_; }
  // The material table, final after finish(); empty when the input has no materials.
  const std::vector<core::Material>& materials() const { return materials_; }

 protected:
  const MappedFile& file_;
  std::vector<std::string> object_names_{std::string()};
  std::vector<core::Material> materials_;
};

// Splits one face of n >= 3 corners (references in the reader's encoding, equal exactly when they name
// the same vertex; overwritten as scratch) into triangles appended to `triangles` (with `object` in
// out->triangle_objects), line segments in out->lines / line_objects, and counts. The rule, by the face's
// ring r: the corners with each corner equal to its predecessor (cyclically, corner 0 kept) removed:
//   m = |r| = 1        nothing: out->degenerate += n - 2 (a face that is one vertex)
//   m = 2              the segment (r0, r1): degenerate += n - 2, face_segments += 1
//   m >= 3, distinct   m - 2 triangles, degenerate += n - m; m = 3 is the triangle itself, m >= 4 is
//                      recorded in out->planar_faces to be triangulated in its plane
//   m >= 3, a vertex   the ring touches itself (r = a b c b d ...): the fan (r0, ri, ri+1) in the file's
//     repeats          own order, each fan triangle naming a vertex twice kept as the segment it
//                      describes (degenerate += 1, face_segments += 1 each)
// so that, over all faces, sum (n - 2) = triangles + degenerate. Does not count out->polygons.
template <class T>
void add_face(int64_t* corners, size_t n, uint32_t object, std::vector<T>* triangles, ParsedChunk* out);

// Picks the reader for a file by its contents and extension.
// Throws Failure(usage) for an unrecognised format and Failure(bad_data) for an empty file.
std::unique_ptr<Reader> open_reader(const MappedFile& file);

// "path:LINE: message" and "path: byte OFFSET: message", thrown as Failure(bad_data).
[[noreturn]] void fail_at_line(const MappedFile& file, uint64_t line, const std::string& message);
[[noreturn]] void fail_at_offset(const MappedFile& file, uint64_t offset, const std::string& message);

// Chunk cutting for line-oriented text: from `*cursor`, a range ending just after a '\n' at or past
// cursor + target_bytes (or at end of file), so no line is split. Advances *cursor. Returns false at EOF.
bool next_line_chunk(const MappedFile& file, uint64_t* cursor, uint64_t target_bytes, Chunk* chunk);

}  // namespace lodstream::io

namespace lodstream::io {
// The readers, one per file: io/obj_reader.cpp, io/ply_reader.cpp, io/stl_reader.cpp.
std::unique_ptr<Reader> make_obj_reader(const MappedFile& file);
std::unique_ptr<Reader> make_ply_reader(const MappedFile& file);
std::unique_ptr<Reader> make_stl_reader(const MappedFile& file, bool ascii);
std::unique_ptr<Reader> make_gltf_reader(const MappedFile& file, bool glb);  // io/gltf_reader.cpp
}  // namespace lodstream::io
