// SPDX-License-Identifier: MIT
#pragma once
// What a fitted camera frames: the visible matter, not the grid. The hull points are the corners
// of the boxes of visible voxels in the skip cells at the edge of what the TF / mode leaves
// visible, cut by the clip planes and crop box; the camera (camera.h) fits their projection.
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include "core/volume.h"
#include "grid/brick_traversal.h"
#include "render/ray_caster.h"

namespace voxlight::render {

/// Whether a voxel of this physical value shows (σt > 0 under the TF, widened as the skip cells
/// are). Empty: every voxel of a non-empty cell counts (MIP/MinIP, isosurfaces).
using VoxelShows = std::function<bool(float value)>;

/// World points (mm) whose convex hull holds everything visible inside the kept region of
/// `planes` and `crop`. For each non-empty skip cell at the edge of the non-empty set: its showing
/// voxels farthest out along the 26 cube directions, half a voxel further out (within about half a
/// voxel of the matter), or the whole cell's corners when `shows` is empty. A cell cut by a plane
/// uses the box of its showing voxels widened by one voxel; a box cut by the planes contributes its
/// kept corners
/// and the points where its edges cross a plane (a vertex where two planes and a face meet inside
/// a box is not added, so the hull may fall short of it by less than a cell). Empty when nothing
/// is visible.
std::vector<glm::dvec3> visibleHullPoints(const core::Volume& volume,
                                          const grid::BrickMajorants& cells,
                                          const VoxelShows& shows,
                                          std::span<const ClipPlane> planes,
                                          const std::optional<CropBox>& crop);

/// visibleHullPoints, or the volume's box corners when nothing is visible (the image is then
/// empty, and says so).
std::vector<glm::dvec3> framingPoints(const core::Volume& volume, const grid::BrickMajorants& cells,
                                      const VoxelShows& shows, std::span<const ClipPlane> planes,
                                      const std::optional<CropBox>& crop);

}  // namespace voxlight::render
