// SPDX-License-Identifier: MIT
#pragma once
// Internal to iso/: the fill of a capped cut (extract.h, ExtractOptions::cap) — CGAL's side, kept
// out of extract.cpp as cleanup.cpp keeps CGAL out of the rest.
#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

namespace voxlight::iso::detail {

/// Fills the region bounded by closed contours in a plane: `points` in the plane's 2-D coordinates,
/// `segments` pairs of indices into them (any order, any orientation). Inside is where a ray from
/// outside has crossed an odd number of contours (so a contour within another bounds a hole, one
/// within that an island), by a constrained Delaunay triangulation (CGAL CDT_2, exact predicates)
/// marked by nesting depth. Triangles as indices into `points`, counter-clockwise in the plane's
/// coordinates. `ok` is false when contours crossed each other (the crossing's triangles are left
/// out: their new vertex is on no contour).
std::vector<std::uint32_t> fillContours(const std::vector<glm::dvec2>& points,
                                        const std::vector<std::uint32_t>& segments, bool& ok);

}  // namespace voxlight::iso::detail
