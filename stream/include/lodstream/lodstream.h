// lodstream: out-of-core level-of-detail generation for huge CAD and architectural scenes.
//
// The public interface of the engine. Every entry point returns a Result: no exception crosses this
// boundary (std::bad_alloc becomes Status::internal with a message). Everything here is safe to call
// from several threads on distinct inputs and work directories.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace lodstream {

// Process exit codes follow sysexits.h; the CLI returns them unchanged.
enum class Status : int {
  ok = 0,
  usage = 64,      // bad options, unsupported or unrecognised file format
  bad_data = 65,   // malformed input; the message names the file and the line or byte offset
  no_input = 66,   // input missing, unreadable, or a directory
  internal = 70,   // a bug in lodstream (or out of memory); please report it
  io_error = 74,   // cannot write output or work directory (disk full included)
  cancelled = 130, // the progress callback returned false (the CLI maps SIGINT to this)
};

// A short stable name for a status ("ok", "usage", "bad_data", ...).
const char* status_name(Status status);

// Progress and cancellation. `stage` is a stage name ("ingest", "weld", ...), `fraction` the part of that
// stage done, in [0, 1]. The callback may be called from several threads at once and must be thread-safe.
// Returning false cancels the job: the call returns Status::cancelled and leaves no file behind under a
// final name.
using ProgressFn = bool (*)(void* user, const char* stage, double fraction);

struct Options {
  // Worker threads; 0 = all hardware threads. Output bytes never depend on it.
  unsigned threads = 0;
  // Cap on the process's peak resident memory (VmHWM, mapped file pages included), in bytes.
  // 0 = half of physical memory. Minimum: min_memory_bytes. Output bytes never depend on it; whether a
  // job fits does: memory that grows with the output (simplify's finest level's cells) is checked against
  // it, and a job that needs more stops with Status::usage naming what it needs.
  uint64_t memory_bytes = 0;
  // Input bytes per parse chunk; 0 = derived from memory_bytes. Tests force tiny values (down to 1);
  // output bytes never depend on it.
  uint64_t chunk_bytes = 0;
  // Work directory holding the scene store and intermediate files. Empty = a fresh directory under
  // $TMPDIR (or /tmp), removed when the call returns. A given directory is kept, and a stage whose inputs
  // and options are unchanged is not redone when the same job runs again on it.
  std::string work_dir;
  ProgressFn progress = nullptr;
  void* progress_user = nullptr;
  // Before a job writes anything, its work directory's and outputs' bytes are estimated from the input's
  // size and format and checked against the free space of the file systems they go to: a job that would
  // not fit stops with Status::io_error and the figures. false skips the check (the estimate is typical,
  // not a bound: a disk that fills anyway still ends the job with Status::io_error, resumable).
  bool check_disk_space = true;
};

inline constexpr uint64_t min_memory_bytes = 64ull << 20;

struct Result {
  Status status = Status::ok;
  std::string message;  // one line, empty when ok
  bool ok() const { return status == Status::ok; }
};

// Memory figures. A job's peak_rss_bytes is the process's VmHWM when the job ends: what outside tools see
// (/usr/bin/time -v, a parent's getrusage ru_maxrss, cgroups), never reset by lodstream, so in a process
// that did other work first it includes that work's peak. A stage's peak_rss_bytes is the highest resident
// set (mapped file pages included) sampled every 5 ms while the stage ran, by a thread the job runs for it
// (never above the VmHWM at the stage's end): a sampled figure, which can miss a spike shorter than the
// interval (the job's VmHWM cannot).
struct StageStats {
  std::string name;
  double seconds = 0;
  // User and system CPU time of the whole process while the stage ran, all threads: on a shared machine a
  // stage's wall time follows the load, its CPU time much less.
  double cpu_seconds = 0;
  uint64_t peak_rss_bytes = 0;  // highest resident set sampled during the stage
  bool reused = false;          // the stage's output was already in the work directory
};

// A job's work directory when the job ended (a temporary one just before it was removed): its files'
// bytes in all and per top-level entry (a directory's files summed), and the input's bytes (a report's:
// its originals').
struct WorkDirUsage {
  std::string path;
  uint64_t bytes = 0;
  uint64_t input_bytes = 0;
  std::vector<std::pair<std::string, uint64_t>> entries;  // by name
};
// `usage` as the JSON object manifest.json, report.json and `info --json` give under "work_dir".
std::string work_dir_json(const WorkDirUsage& usage);

// What `lodstream info` reports: ingest statistics of one input file.
struct SceneInfo {
  std::string path;
  std::string format;            // "obj", "ply-ascii", "ply-binary-le", "ply-binary-be", "stl-binary", "stl-ascii", "glb", "gltf"
  uint64_t file_bytes = 0;
  uint64_t vertex_records = 0;   // vertex records in the file (for STL: triangle corners)
  uint64_t vertices = 0;         // vertices as stored (for STL: after welding corners by exact position)
  uint64_t vertices_welded = 0;  // distinct positions among stored vertices
  uint64_t unused_vertices = 0;  // stored vertices no triangle, line or point refers to
  uint64_t polygons = 0;         // input faces (STL facets, OBJ f, PLY face records)
  uint64_t triangles = 0;        // triangles kept: n - 2 per face of n distinct corners, in the face's plane
  uint64_t degenerate = 0;       // triangle slots lost to repeated corners: sum of (n - 2) = triangles + degenerate
  uint64_t degenerate_segments = 0; // line segments dropped: both ends name the same vertex
  uint64_t lines = 0;            // line segments (OBJ l, PLY edge elements, two-corner faces, face_segments)
  uint64_t face_segments = 0;    // segments made from faces naming two vertices (f a b b), counted in lines
  uint64_t polygons_concave = 0; // faces of 4+ corners the fan would leave: triangulated inside them instead
  uint64_t polygons_fallback = 0; // faces of 4+ corners with no plane or self-intersecting: fan kept
  uint64_t points = 0;           // points (OBJ p)
  uint64_t objects = 0;          // objects that own at least one primitive (OBJ o/g, STL solids)
  uint64_t skipped_statements = 0; // recognised but unused records (OBJ vt/vn/usemtl..., PLY other elements)
  double bbox_min[3] = {0, 0, 0};
  double bbox_max[3] = {0, 0, 0};
  std::vector<StageStats> stages;
  double seconds = 0;
  uint64_t peak_rss_bytes = 0;  // the process's VmHWM at the end (see StageStats)
  WorkDirUsage work_dir;
};

// Ingests `path` into the scene store of the work directory and reports its statistics.
Result info(const std::string& path, const Options& options, SceneInfo* out);

// The format of the input file `path` as info() names it (SceneInfo::format), from its header alone (no
// ingest). Fails as ingest would: no_input (cannot open), usage (unrecognised), bad_data (a broken header).
Result input_format(const std::string& path, std::string* format);

// ---- simplify: the LOD pipeline (grade -> sort -> cluster -> emit -> write) ----

enum class Grading { lowtan, rossignac };           // cos(θ/2)·Lmax (Low & Tan) or Lmax/θ (Rossignac & Borrel)
enum class Clustering { floating, uniform };        // floating cells, or the origin-anchored uniform grid
enum class CellShape { cube, sphere };
enum class CellVariant { nearest, heaviest };       // which containing cell a vertex joins (floating only)
enum class Representative { center, mean, quadric };

struct SimplifyOptions {
  std::string output_dir;  // created if missing; lodN.ply, lodN.obj, lods.glb and manifest.json go here
  Grading grading = Grading::lowtan;
  Clustering clustering = Clustering::floating;
  CellShape cell = CellShape::cube;
  CellVariant variant = CellVariant::nearest;
  Representative representative = Representative::quadric;  // measured best (README, "quality of floating cells")
  // Levels: explicit cell sizes (strictly increasing), or target triangle counts (searched for), or
  // neither: cell sizes estimated so that counts fall roughly geometrically from the input to a few
  // thousand. Then `levels` = 0 (default) asks for up to default_levels levels and stops where the counts
  // stop falling: a level with no triangles (for an input without triangles: no edges or points), or no
  // fewer than the level kept before it, is left out, and SimplifyReport::notice says so. `levels` = N
  // asks for exactly N. Either way the finest level has triangles whenever some cell size leaves any: its
  // size is searched for when the estimate leaves none. This is checked by counting the levels before
  // they are made, on inputs whose estimate aims below a few thousand triangles at its coarsest level
  // (fewer than 4000 · 2^levels triangles: 128,000 at 5 levels; every input without triangles, whose levels
  // aim at its segments and points). Larger inputs keep their estimated levels unchecked, at no extra cost.
  std::vector<double> cell_sizes;
  std::vector<uint64_t> target_triangles;
  unsigned levels = 0;
  double crease_degrees = 30;    // normals: faces meeting at a sharper angle keep separate normals
  // LOD selection (Low & Tan §4): a level of cell size c is used from the distance where c spans
  // pixels_per_cell pixels of a `resolution`-pixel-high image with vertical field of view fov_degrees.
  double fov_degrees = 60;
  unsigned resolution = 1080;
  double pixels_per_cell = 5;
  // Regions: a level is emitted, and tiled, in octree regions of at most
  // tile_triangles / 2 of its cells. The level files' vertex and primitive order follows the regions, so
  // their bytes depend on it.
  uint64_t tile_triangles = 200'000;
  bool write_ply = true;
  bool write_obj = false;
  bool write_glb = true;
  // 3D Tiles 1.1 (README "3D Tiles"): tiles/tileset.json and one GLB per tile: a tile is a region of a level
  // (tile_triangles above); edges and points as triangles of their thickness (tile_lines = triangles) or
  // as glTF LINES and POINTS. tiles_transform: empty, the root's 4x4 transform (16 numbers, column-major), or
  // longitude, latitude (degrees) and height (metres) placing the scene's east-north-up frame on WGS84.
  bool write_tiles = false;
  enum class TileLines { triangles, lines } tile_lines = TileLines::triangles;
  // Tile GLBs: float (plain), KHR_mesh_quantization (quantized: positions snapped to a grid of the level's
  // cell size / 32 or finer, SHORT; normals BYTE; UNSIGNED_SHORT indices where they fit), or quantized and
  // EXT_meshopt_compression (meshopt, the default; quantized when built without meshoptimizer).
  enum class TileEncoding { plain, quantized, meshopt } tile_encoding = TileEncoding::meshopt;
  std::vector<double> tiles_transform;
  // The input's up axis for tiles: Y (glTF's, default) or Z (common in CAD, PLY and the sample scenes): a Z-up
  // input gets a root rotation so that it stands upright in a 3D Tiles viewer (the GLBs are unchanged).
  bool tiles_z_up = false;
  // Testing: cap the vertices graded at once (0 = from the memory budget), to force seams. Ranges are
  // at most 256, so the cap is raised to vertices / 256 when it is smaller.
  uint64_t grade_range_vertices = 0;
  // Silhouette labels (Mata et al. 2006; README "Silhouette labels"): with silhouette_interval D > 0, a
  // vertex within D pixels of an outline (its label: the minimum over silhouette_views views of its
  // distance to the outline, seen at the level's switching distance) gets cells silhouette_factor times
  // the level's cell size (0 < f < 1). 0 = off.
  double silhouette_interval = 0;
  double silhouette_factor = 0.5;
  unsigned silhouette_views = 16;
  unsigned silhouette_resolution = 512;
  // With max_error_px E > 0: each level keeps the switching distance of its first cell size, and its cell
  // size (and, with labels, first its factor) is lowered until its silhouette p95 there, measured by
  // `report`'s rule on max_error_views views, is at most E (or the passes run out: the manifest says so).
  double max_error_px = 0;
  unsigned max_error_views = 8;
  // Past one machine (README "Running on a cluster"): with shard_count N > 0 this call is task shard_index
  // (0 <= I < N) over a shared work directory (Options::work_dir, required): it runs the shared stages
  // (ingest to cluster) unless another task did, under the work directory's lock, then emits its share
  // of every level's regions into output_dir/shards/; merge() then writes the outputs. shard_prepare: run
  // the shared stages only (any N), then stop. Not with max_error_px.
  unsigned shard_index = 0, shard_count = 0;
  bool shard_prepare = false;
  // With ingest_count N > 0: only parse byte range ingest_index of N of the input into the work
  // directory (WORK/ingest-ranges; README "Running on a cluster"), then stop; the prepare job (or the
  // first task) joins the N ranges into the scene store, the same bytes as one machine's ingest. The
  // report gets the stage "ingest-range" and, in scene.file_bytes, the bytes the task parsed.
  unsigned ingest_index = 0, ingest_count = 0;
  // The clustering pass as N shares (stream/cluster_shares.h; README "Running on a cluster"). With
  // cluster_share_count N > 0: run the stages before clustering unless another task did (under the work
  // directory's lock), then share cluster_share_index of the clustering, then stop. With cluster_shares
  // N > 0 on a sharded run (shard_count or shard_prepare): the shared clustering stage merges the N
  // shares' files, first running any share no task ran, instead of clustering the whole scene itself.
  // The outputs are the same bytes either way.
  unsigned cluster_share_index = 0, cluster_share_count = 0;
  unsigned cluster_shares = 0;
  // Grade and the weight index's sort as N shares (stream/grade_shares.h). With grade_share_count N > 0:
  // run the stages before grading unless another task did (under the work directory's lock), then share
  // grade_share_index of the grading, then stop. Any later process of the run (a clustering share, the
  // prepare job, a task) finds the shares' plan in the work directory, runs any share no task ran and
  // merges them into the weight index: the same bytes as one machine's.
  unsigned grade_share_index = 0, grade_share_count = 0;
};

inline constexpr unsigned default_levels = 5;

struct LevelStats {
  double cell_size = 0;
  uint64_t cells = 0;
  uint64_t vertices = 0, triangles = 0, edges = 0, points = 0;
  uint64_t edges_on_triangles = 0, points_covered = 0;  // eliminated
  uint64_t target_triangles = 0;  // 0 when no target was given
  double switch_distance = 0;     // use this level from this camera distance on (scene units)
  double screen_coverage = 0;     // the scene's bounding-box diagonal over the image height at that distance
  std::vector<std::string> files; // written, relative to the output directory
  double fine_cell_size = 0;      // silhouette labels: the cell size near the outline (0 = none)
  double near_outline = 0;        // silhouette labels: the label below which a vertex is near (scene units)
  double measured_p95_px = -1;    // max_error_px: the silhouette p95 of the last pass (-1 = not measured)
};

struct TilesStats {
  uint64_t tiles = 0, content_tiles = 0;  // in tileset.json; with a GLB
  uint64_t bytes = 0;                     // GLBs and tileset.json
  uint64_t triangles = 0, max_triangles = 0;  // over all tiles; in the largest (edges and points expanded)
};

struct SimplifyReport {
  std::string input;
  SceneInfo scene;                 // ingest statistics (census fields left 0)
  uint64_t vertices_graded = 0;    // distinct used positions: the weight index's records
  uint64_t distinct_positions = 0;
  double surface_area = 0;
  uint64_t grade_ranges = 0;
  std::vector<LevelStats> levels;
  unsigned levels_asked = 0;       // sizes or targets given, SimplifyOptions::levels, or default_levels
  std::string notice;              // one line when fewer levels were made than asked, saying why; else empty
  uint64_t labelled_vertices = 0;  // silhouette labels: index records some view sees
  uint64_t label_chunks = 0, label_view_groups = 0;  // and the chunk scenes and view groups traced (0 when reused)
  unsigned error_passes = 0;       // max_error_px: clustering and measuring passes made
  TilesStats tiles;                // SimplifyOptions::write_tiles only
  unsigned search_iterations = 0;  // target search: clustering passes made
  double search_seconds = 0;
  // SimplifyOptions::cluster_share_count: the share's figures per level, as JSON (stream/cluster_shares.h
  // run_cluster_share); empty when the whole stage was already done.
  std::string cluster_share;
  // SimplifyOptions::grade_share_count: the share's figures ({"ranges": [first, end), "records"}), as
  // JSON; empty when the whole stage was already done.
  std::string grade_share;
  std::vector<StageStats> stages;
  double seconds = 0;
  uint64_t peak_rss_bytes = 0;  // the process's VmHWM at the end (see StageStats)
  WorkDirUsage work_dir;
};

// Simplifies `input` into the levels described by `simplify`, writing them and manifest.json into
// simplify.output_dir. Output bytes depend only on the input and `simplify`, never on `options`.
Result simplify(const std::string& input, const SimplifyOptions& simplify, const Options& options,
                SimplifyReport* out);

// Writes into `output_dir` what simplify writes there (level files, lods.glb, tiles, manifest.json), from
// the parts its N tasks (SimplifyOptions::shard_count) left in output_dir/shards/, the same bytes as one
// machine's run (manifest.json's timings aside: it lists every task's stages under "shards"). Fails with
// Status::no_input naming the tasks whose parts are missing. `out` gets the manifest's figures.
Result merge(const std::string& output_dir, const Options& options, SimplifyReport* out);

// The task index and count a scheduler gives: SLURM_ARRAY_TASK_ID and SLURM_ARRAY_TASK_COUNT (Slurm job
// arrays), JOB_COMPLETION_INDEX (Kubernetes Indexed Jobs) or AWS_BATCH_JOB_ARRAY_INDEX (AWS Batch arrays);
// LODSTREAM_SHARD_COUNT, when set, gives the count (required with the last two, which carry no count).
// false with `error` set when none is set or they are unusable.
bool shard_from_env(unsigned* index, unsigned* count, std::string* error);

// ---- report: the LOD error report (../shared/DESIGN.md "Error report") ----

struct ReportOptions {
  std::string output_dir;  // created if missing; report.json, report.html and one CSV per level go here
  // What to measure: simplify output directories (each read through its manifest.json; the original is the
  // manifest's input, unless `original` is given), or else `original` with `lods`, finest first.
  std::vector<std::string> runs;
  std::string original;
  std::vector<std::string> lods;            // PLY (as simplify writes them, or any PLY) or OBJ
  std::vector<double> switch_distances;     // for `lods`: one per LOD; empty = from each LOD's Hausdorff max
  unsigned views = 32;                      // view directions on a Fibonacci sphere
  unsigned resolution = 512;                // square images, resolution × resolution pixels
  uint64_t seed = 1;                        // view targets and surface samples
  uint64_t samples = 250000;                // Hausdorff samples of each kind (vertex, edge, face) per direction
  double fov_degrees = 60;                  // for `lods` (runs use their manifest's)
  double pixels_per_cell = 5;               // for `lods` without distances: Hausdorff max spans this many pixels
  unsigned html_views = 3;                  // views rendered into report.html per level
  // The pixel rule, for original and level alike: a pixel is covered when its centre ray hits, or else any
  // of k × k rays spread over it (k = supersample, 1 to 16). Lines and points are drawn one pixel wide,
  // thick edges at their thickness (README, "report").
  unsigned supersample = 3;
  // Past one machine (README "Running on a cluster"): with shard_count N > 0 this call is task shard_index
  // (0 <= I < N) over a shared work directory (Options::work_dir, required): it ingests the originals
  // unless another task did (under the work directory's lock), then, when every level has its switching
  // distance, takes part in drawing their samples (units every task takes up) and traces the I-th N-th of
  // every original's and every level's primitives for every view and sample (else the I-th N-th of every
  // level's views and samples against the whole original), and writes what it measured to
  // output_dir/shards/report/; merge_report() then writes report.json, the CSVs and report.html.
  // shard_prepare: the shared stages only.
  unsigned shard_index = 0, shard_count = 0;
  bool shard_prepare = false;
  // With ingest_count N > 0: only parse byte range ingest_index of N of every original into the work
  // directory (WORK/ingest-ranges, WORK/ingest-ranges-G for the G-th further original), then stop; the
  // prepare job (or the first task) joins them into the scene stores, as simplify's (SimplifyOptions).
  unsigned ingest_index = 0, ingest_count = 0;
};

// Distribution of an error over pixels or samples. Units depend on the field.
struct ErrorStats {
  double max = 0, p95 = 0, mean = 0, rms = 0;
  uint64_t count = 0;  // pixels or samples measured
};

struct ReportLevel {
  std::string file;               // the LOD file measured
  double cell_size = 0;           // 0 when unknown (LOD files given directly)
  uint64_t vertices = 0, triangles = 0, edges = 0, points = 0;
  double switch_distance = 0;     // camera distance of every view (scene units)
  double pixel_size = 0;          // object size of one pixel at that distance (scene units)
  // Silhouette: over pixels covered by exactly one of original and LOD, the distance (pixels) from such a
  // pixel to the original's outline, from exact Euclidean distance transforms of the original's coverage.
  ErrorStats silhouette;
  uint64_t mismatched_pixels = 0, covered_pixels = 0;  // covered: by either image
  double mismatch_fraction = 0;   // mismatched / covered
  // Thin features: pixels of the original in no 2 × 2 block of its pixels (parts about a pixel wide or
  // small), and of those, the ones the level covers too.
  uint64_t thin_pixels = 0, thin_kept_pixels = 0;
  double thin_kept_fraction = 1;  // thin_kept_pixels / thin_pixels (1 when there are none)
  ErrorStats depth;               // pixels covered by both: |depth difference| in pixels at that depth
  ErrorStats normal;              // pixels covered by both: angle between camera-facing normals, degrees
  // Two-sided Hausdorff distance (scene units) by Metro-style sampling; closest points by Embree.
  ErrorStats lod_to_original, original_to_lod;
  double hausdorff_max = 0, hausdorff_mean = 0, hausdorff_rms = 0;  // the larger of the two directions
  double hausdorff_max_percent = 0, hausdorff_mean_percent = 0;    // of the original's bbox diagonal
  double hausdorff_max_pixels = 0, hausdorff_mean_pixels = 0;      // at the switching distance
  std::string csv;                // per-view figures, relative to the output directory
  double seconds = 0;
};

struct ReportRun {
  std::string name;               // the simplify directory, or the original's file name
  std::string original;
  uint64_t original_triangles = 0, original_vertices = 0;
  double bbox_diagonal = 0;
  double fov_degrees = 60;
  std::vector<ReportLevel> levels;
};

struct Report {
  std::vector<ReportRun> runs;
  uint64_t rays = 0;              // primary rays cast
  double ray_seconds = 0;         // wall time spent casting them
  uint64_t point_queries = 0;
  double query_seconds = 0;
  uint64_t original_chunks = 0;          // chunks the originals were cut into to fit --memory (1 = in core)
  uint64_t original_primitives = 0;      // primitives of the originals traced (a task by ranges: of its ranges)
  uint64_t chunk_scenes = 0;             // chunk scenes built (a chunk is built once per pass over them)
  uint64_t chunk_embree_peak_bytes = 0;  // the largest chunk scene's peak by Embree's memory monitor
  uint64_t chunk_triangles = 0;          // triangles of that chunk
  uint64_t level_chunks = 0;             // the most chunks a level was traced in (1 = in core)
  uint64_t chunk_replans = 0;            // times the chunks still to come were cut again by measured bytes
  double chunk_triangle_bytes = 0;       // Embree's bytes per triangle the chunks were last cut by
  std::vector<StageStats> stages;
  // The measure stage's parts (chunk_read, chunk_build, wire_build, queries_on_original, rays_on_original,
  // level_read, level_build, queries_on_level, rays_on_level, compare): wall and CPU seconds summed over
  // chunks and levels; peak_rss_bytes unused.
  std::vector<StageStats> phases;
  double seconds = 0;
  uint64_t peak_rss_bytes = 0;  // the process's VmHWM at the end (see StageStats)
  WorkDirUsage work_dir;
};

// Measures every level of every run, writing report.json (written last), report.html and the CSVs.
Result report(const ReportOptions& report, const Options& options, Report* out);

// Writes into `output_dir` what report writes there (report.json, the CSVs, report.html) from the shares
// its N tasks (ReportOptions::shard_count) left in output_dir/shards/report/, the same bytes as one
// machine's report (report.json's timings and performance counters aside: it lists every task's stages
// under "shards"). Fails with Status::no_input naming the tasks whose shares are missing.
Result merge_report(const std::string& output_dir, const Options& options, Report* out);
// True when output_dir/shards/report/ exists: `lodstream merge` then merges a report, not a simplify.
bool has_report_shards(const std::string& output_dir);

// ---- grid: adaptive subdivision of height fields and range grids (DeHaemer 1989) ----

enum class GridSplit { center, first, greatest, curvature, random };  // where a failing polygon splits
enum class GridGaps { none, extra_vertices, fill };  // corners only (cracks), extra vertices, fill polygons
enum class GridMethod { subdivision, growth };
enum class GridAxis { x, y, z };  // the axis of a cylindrical scan

struct GridOptions {
  std::string output_dir;  // created if missing; grid.obj, grid.ply, grid.glb and summary.json go here
  // Vertical tolerance in z units (metres for Terrain-RGB): every valid sample under a polygon lies within
  // it of the triangles drawn for that polygon. < 0 = not given (then target_polygons is required).
  double tolerance = -1;
  GridSplit split = GridSplit::greatest;
  unsigned divide = 4;     // 4, or 2 (across the longer side)
  GridGaps gaps = GridGaps::extra_vertices;
  // > 0: refine the polygon of greatest error first until this many polygons (fill polygons not
  // counted) or until the tolerance holds everywhere. Extra vertices may then split a few more.
  uint64_t target_polygons = 0;
  GridMethod method = GridMethod::subdivision;  // growth: needs a tolerance, no target
  uint64_t seed = 1;       // GridSplit::random
  // Then merge two polygons sharing a whole side while their union passes (not in the thesis: fewer
  // polygons and T-junctions for the same tolerance). Needs a tolerance.
  bool merge = false;
  double z_scale = 1;      // PGM samples only (io/grid_reader.h)
  double spacing = 0;      // > 0 overrides the file's sample distance
  bool write_obj = true;   // the drawn triangles (as the GLB), or the n-gons with `polygons`
  bool write_ply = true;   // the drawn triangles (as the GLB), or the n-gons with `polygons`
  bool write_glb = true;   // the drawn triangles, one level
  // OBJ and PLY hold the polygons (rings: n-gons with extra vertices, fill polygons) instead of the drawn
  // triangles. The tolerance holds for the drawn triangles only: a viewer triangulates an n-gon its own
  // way (mostly as a fan from its first corner), which may leave the tolerance.
  bool polygons = false;
  // A cylindrical range grid (a Cyberware scan, DeHaemer 1989 §II.B): the samples are radii (PGM: value
  // · z_scale), 0 or NODATA is no return (a hole); column i is at longitude i · angle_step about `axis`
  // (right-hand rule, 0 at the axis' cyclic successor: +Z for y, +X for z, +Y for x), row j at height
  // (rows - 1 - j) · height_step above the last row (plus the ASC's yll). Empty top and bottom rows are
  // trimmed. The tolerance then bounds each sample's radius error along its ray from the axis, measured
  // on the 3D triangles drawn; a full turn (columns · angle_step = 360) is closed at the seam with
  // shared vertices. The output is a 3D mesh, open at the top and bottom rims (not capped).
  bool cylindrical = false;
  double height_step = 0;  // scene units per row; 0 = the file's cell size (ASC) or 1. Not with spacing.
  double angle_step = 0;   // degrees per column; 0 = 360 / columns. Columns may not cover more than 360.
  GridAxis axis = GridAxis::y;  // grid.obj and grid.ply; grid.glb always has the axis on glTF's up (Y)
};

struct GridReport {
  std::string input, format;
  uint32_t width = 0, height = 0;
  double spacing = 0;
  uint64_t valid_samples = 0, hole_cells = 0;  // hole cells: cells touching NODATA, left out
  // The thesis' table columns: polygons (fill polygons included), vertices retained, vertices sent
  // (draw_vertices: the sum of polygon sizes), bytes of the thesis' data structure (24 per vertex for
  // position and normal, 12 per polygon node, 4 per vertex reference), fill polygons and their references.
  uint64_t polygons = 0, fill_polygons = 0, fill_vertices = 0, vertices = 0, draw_vertices = 0, bytes = 0;
  uint64_t triangles = 0;               // the drawn triangulation (GLB), fill triangles included
  std::string obj_ply_faces;            // what grid.obj and grid.ply hold: "triangles" (drawn) or "polygons"
  // Vertical error of every valid sample against the drawn triangles over it (z units).
  double max_error = 0, rms_error = 0;
  uint64_t measured_samples = 0, uncovered_samples = 0;
  uint64_t t_junctions = 0, gaps = 0, cracks = 0;  // cracks: gaps left open (GridGaps::none)
  double max_gap = 0;
  uint64_t trials = 0, verify_splits = 0, merges = 0;
  // Cylindrical grids: max_error and rms_error are radius errors along the samples' rays, measured on the
  // written (float) vertices; the empty rows trimmed at the top and bottom; closed: a full turn.
  uint32_t trimmed_rows_top = 0, trimmed_rows_bottom = 0;
  double angle_step = 0, height_step = 0;  // degrees, scene units
  bool closed = false;
  std::vector<std::string> files;       // written, relative to the output directory
  std::vector<StageStats> stages;
  double seconds = 0;
  uint64_t peak_rss_bytes = 0;  // the process's VmHWM at the end (see StageStats)
};

// Reads the height grid `input` (io/grid_reader.h formats), subdivides it and writes the drawn triangles
// (or the polygons, GridOptions::polygons) and summary.json (last) into grid.output_dir. Errors: usage
// (options, unknown format), no_input, bad_data (malformed grid, fewer than 2 x 2 samples), io_error,
// cancelled.
Result grid(const std::string& input, const GridOptions& grid, const Options& options, GridReport* out);

// Peak resident memory of this process so far (VmHWM), in bytes; 0 if unknown.
uint64_t peak_rss_bytes();

// A size as the CLI and the job server take it: "1G", "512M", "64k", "1.5GiB", "1000000" -> bytes (binary
// multiples, case-insensitive). False on anything else.
bool parse_size(const std::string& text, uint64_t* out);

}  // namespace lodstream
