// Edges and points of a level as triangles of their thickness, for viewers that draw LINES and POINTS one
// pixel wide whatever their size (CesiumJS, most glTF viewers): 3D Tiles output writes them this way by
// default (stream/tiles.h).
//
// - An edge of thickness t (core/mesh.h: D_A + D_B, Low & Tan §3.3.1) becomes two crossed quads along it,
//   each of width w = max(t, min_width), one in the plane of the edge and u, the other of the edge and v,
//   where (d, u, v) is an orthonormal frame around the edge direction d (u from the axis least aligned with
//   d). 4 triangles and 8 vertices an edge; each quad's normal is its plane's (the material is double
//   sided). From any side, a quad is at least w·cos 45° wide on screen; a closed thin prism costs 6 to 8.
// - A point becomes an octahedron around it of radius max(size / 2, point_radius), its size being the
//   diameter of what collapsed into it (core/mesh.h point_size; point_radius alone when the mesh has no
//   sizes): 8 triangles, 6 vertices with radial unit normals.
// - An edge whose ends coincide in float (never emitted: its cells differ, but their representatives may
//   round together) is drawn as a point of radius max(w/2, point_radius).
// - Colours and materials: a new vertex takes the colour of the edge end or point it stands for, a new
//   triangle the material of its edge or point.
// The triangles of the input keep their vertices and ids; the new vertices follow, edges first then points,
// in input order. So the result depends on the input only, and a triangle's bytes do not depend on which
// other primitives share its part.
//
// Geometric effect: every point of an expanded primitive is within `max_radius` (the largest w/2 over the
// edges and the octahedra's radii over the points, the diagonal case included) of the edge or point it replaces,
// which lies inside it: error bounds of the edge or point grow by at most that (stream/tiles.cpp).
#pragma once

#include "core/mesh.h"

namespace lodstream::core {

struct ThickOptions {
  double min_width = 0;     // scene units; the width of an edge thinner than this (thickness 0: a wire)
  double point_radius = 0;  // scene units; the radius of a point smaller than this; > 0 when the mesh has points
};

// `mesh` with its edges and points replaced by triangles (the returned mesh has no edges, thickness or
// points). `max_radius`, when not null, receives the largest distance of a new vertex from its primitive
// (0 when there is none). Normals: given to every new vertex when `mesh` has normals, else none.
LodMesh expand_thick(const LodMesh& mesh, const ThickOptions& options, double* max_radius);

}  // namespace lodstream::core
