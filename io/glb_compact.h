// Compact encoding of 3D Tiles content: a single-mesh GLB as io/glb_writer.h writes it, re-encoded with
// KHR_mesh_quantization (KhronosGroup/glTF extensions/2.0/Khronos/KHR_mesh_quantization) and optionally
// EXT_meshopt_compression (extensions/2.0/Vendor/EXT_meshopt_compression; meshoptimizer's vertex and index
// codecs, Kapoulkine 2019-2022), both read by CesiumJS.
//
// - Positions snap to a grid of step `quantum` (a power of two, scene units) anchored at the origin: every
//   coordinate becomes quantum·k for the nearest integer k, in every tile the same, so a vertex shared by
//   two tiles of a level snaps to the same point in both (the tiles stay crack-free). When the mesh's
//   snapped extent spans at most 65,535 steps per axis, positions are stored as SHORT (k − k0, padded to
//   8 bytes) with the node's translation quantum·k0 and scale quantum; else as floats of quantum·k.
//   A point moves by at most quantum·sqrt(3)/2.
// - Normals: BYTE normalized, round(127·n), padded to 4 bytes.
// - Triangle indices: UNSIGNED_SHORT when the primitive has at most 65,535 vertices, else UNSIGNED_INT;
//   triangles and vertices reordered for the vertex cache and fetch (meshopt_optimizeVertexCache,
//   meshopt_optimizeVertexFetchRemap) when compressing.
// - Other attributes (_THICKNESS, in scene units, not scaled by the node) are kept as they are.
// - With `meshopt`, every buffer view is compressed (ATTRIBUTES for vertex streams, TRIANGLES for indices,
//   filter NONE) into the BIN chunk; the uncompressed views lie in a fallback buffer without data, so the
//   extension is required.
// The output depends only on the input bytes and the arguments.
#pragma once

#include <string>
#include <string_view>

namespace lodstream::io {

enum class TileEncoding { plain, quantized, meshopt };

// Re-encodes `glb` (one node with one mesh, float POSITION and NORMAL, uint32 indices, one buffer: what
// write_glb writes for one level). `quantum` > 0 and a power of two. Failure(internal) on a GLB of another
// layout; Failure(usage) for meshopt when this build has no meshoptimizer.
std::string compact_glb(std::string_view glb, double quantum, TileEncoding encoding);

// A coordinate snapped as compact_glb snaps it: the float nearest quantum·round(x / quantum).
float snap_to_grid(float x, double quantum);

// The largest power of two <= x (x > 0 and finite).
double power_of_two_below(double x);

}  // namespace lodstream::io
