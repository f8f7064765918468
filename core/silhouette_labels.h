// Silhouette labels for simplification: every vertex's distance to the object's outline, the minimum over
// K views, so that the clustering can keep smaller cells near the outline.
//
// Susana Mata, Luis Pastor and Angel Rodríguez. Silhouette detection for adaptive polygonal mesh
// simplification using distance transforms. GRAPP 2006, §3: the mesh is mapped onto a grid in the view
// plane (§3.1: here the pixels of a ray-cast coverage image, core/view_cast.h), the distance transform of
// the binary image gives every pixel its distance to the background (§3.2: the exact Euclidean transform,
// core/distance_transform.h), and the distances are back-projected to the vertices (§3.3: a vertex takes
// the label of the pixel it projects to). The paper labels one view; its future work asks for all views,
// and here a vertex keeps the minimum over K views on a Fibonacci sphere, each framing the whole object.
//
// Units: a label is kept in scene units, so that one label serves every level: the pixel distance times
// the width of a pixel at the vertex's depth in that view (Camera::pixel_size). A level shown from distance
// s with pixel width w(s) sees the label as label / w(s) pixels (the object at that distance).
//
// Per view and vertex (the pixel (x, y) holding the vertex's projection, by view_cast's pixel rule):
//   covered pixel     sqrt of its squared distance to the nearest uncovered pixel (>= 1 pixel), each
//                     bounded by the distance to the nearest pixel outside the image, whose coverage is
//                     unknown (as core/silhouette_error.h does)
//   uncovered pixel   0: the vertex lies on the outline (its surface is thinner than the pixel there)
//   behind the eye or outside the image: no label from this view
// A vertex hidden behind another surface takes the label of the pixel it projects to, as in the paper
// (a face is labelled by the cells it maps to, visible or not).
//
// Determinism: a label depends on the vertex's position and the view images only, and the minimum over
// views is the same in any order, so labels are the same for any thread count or chunking.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/view_cast.h"

namespace lodstream::core {

// The label of a vertex no view sees: larger than every real label.
inline constexpr float kNoLabel = 3.0e38f;

// View k of K for labels: from the Fibonacci direction k (core/view_cast.h), looking at `center`, from
// far enough that the ball of `radius` around it fills the field of view at most (distance radius / sin(fov/2)).
Camera label_camera(unsigned k, unsigned count, const double center[3], double radius, double fov_degrees,
                    unsigned resolution);

// One view's distance image: out[p] = squared distance in pixels from a covered pixel p to the nearest
// uncovered one, bounded by the image border (see above); 0 at uncovered pixels. coverage: resolution²
// bytes, nonzero = covered (ViewImage::kind). out: resolution² entries.
void outline_distances(std::span<const uint8_t> coverage, unsigned resolution, std::span<uint32_t> out);

// Lowers labels[i] to vertex i's label in this view (scene units), for the positions xyz (3 per vertex,
// float or double).
void lower_labels(const Camera& camera, std::span<const uint32_t> squared, std::span<const float> xyz,
                  std::span<float> labels);
void lower_labels(const Camera& camera, std::span<const uint32_t> squared, std::span<const double> xyz,
                  std::span<float> labels);

}  // namespace lodstream::core
