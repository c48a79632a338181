// SPDX-License-Identifier: MIT
#pragma once
// An SH visibility field (render/sh_shading.h: local, global or hierarchical) resampled on a
// regular grid of half floats, four coefficients per texel: what a GPU ray caster reads from 3D
// textures (the viewer's shaders/raycast.frag, RGBA16F; one texture for 4 coefficients, 3 for 9,
// 4 for 16). Computed once per field on the CPU (after the visibility stage), uploaded once.
//
// Grid: res_a points per axis, point g at voxel coordinate g·step_a, step_a = (dims_a − 1)/(res_a
// − 1) (node centred: the first and last points on the first and last voxel centres), read at
// texture coordinate (p/step + ½)/res for voxel coordinate p. Preferred: two points per voxel and
// axis (step ½, res = 2·(dims − 1) + 1), whose points hold every voxel centre and every point
// half-way between: the sample points of the fields' own grids (the hierarchical 1:s grid at
// voxel g·s, the local field's block levels cell centred at (g + ½)·2^k − ½, ½-integers for k ≥ 1)
// are among them, so the texture's trilinear interpolation reproduces the field's own wherever
// the field is trilinear between those points. When that exceeds the byte budget: one point per
// voxel (step 1); beyond that every axis coarser by the same factor.
// Each point stores field.sample(position) — for sh-global the near ⊗ far product as the CPU
// shader reads it. Half floats: 11 significant bits (relative 4.9e-4; |V_i| ≤ √(4π)).
#include <cstddef>
#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "core/progress.h"
#include "visibility/global_visibility.h"
#include "visibility/hierarchical_visibility.h"
#include "visibility/local_visibility.h"

namespace voxlight::render {

/// Default byte budget of one resampled field: 256³ points of 4 coefficients.
inline constexpr std::size_t kShFieldGridBudgetBytes = std::size_t(128) << 20;
/// Points per voxel and axis when they fit the budget.
inline constexpr int kShFieldGridOversample = 2;

struct ShFieldGrid {
    glm::ivec3 res{0};
    glm::vec3 step{1.f};  ///< voxels between neighbouring points (0 on an axis of one voxel)
    int coefficients = 0;
    /// Voxel coordinate of point g.
    glm::vec3 position(const glm::ivec3& g) const { return glm::vec3(g) * step; }
    /// ⌈coefficients/4⌉ textures; texture t holds coefficients 4t…4t+3 of point g at
    /// texels[t][4·(g.x + res.x·(g.y + res.y·g.z)) + c] (IEEE half floats; 0 past `coefficients`).
    std::vector<std::vector<std::uint16_t>> texels;
    int textures() const { return int(texels.size()); }
    /// A local field's (LocalVisibility) sample spacing at each point as its interpolation blends
    /// it (LocalVisibility::sample), half floats: the near shadow reads it (render/sh_shading.h
    /// ShLocalShader, ShGlobalShader). Also for a global field with the near/far split (its local
    /// field's); empty for other fields.
    std::vector<std::uint16_t> spacing;
    std::size_t bytes() const;
    /// Coefficient i of point g as a float (tests).
    float at(const glm::ivec3& g, int i) const;
};

/// Points per axis for a volume of `dims` and `coefficients` within `budgetBytes` (see above).
/// `maxPerAxis` > 0: two points per voxel only where every axis stays within it (a GPU's largest
/// 3D texture side); one point per voxel otherwise.
glm::ivec3 shFieldGridResolution(const glm::ivec3& dims, int coefficients,
                                 std::size_t budgetBytes = kShFieldGridBudgetBytes,
                                 int maxPerAxis = 0);
/// Whether a resampling of the field stores ShFieldGrid::spacing too: 2 bytes per point on top
/// of the coefficients the budget counts (a quarter more at 4 coefficients; the 256³ volumes keep
/// their one point per voxel).
inline bool resamplesSpacing(const visibility::LocalVisibility&) { return true; }
inline bool resamplesSpacing(const visibility::GlobalVisibility& field) {
    return field.nearFromLocal();
}
inline bool resamplesSpacing(const visibility::HierarchicalVisibility&) { return false; }

/// A resampling that stops on a cancel and resumes where it stopped: z-slices [0, slicesDone) of
/// `grid` hold their values.
struct ShFieldResampling {
    ShFieldGrid grid;
    int slicesDone = 0;
    bool finished() const { return slicesDone >= grid.res.z; }
};
/// z-slices filled between two looks at the cancel flag: every attempt gets at least this far, so
/// a resampling cancelled again and again (a viewer's camera drag) still finishes.
inline constexpr int kShFieldResampleChunk = 8;
/// A resampling of a field with `coefficients` for a volume of `dims`, nothing filled yet.
ShFieldResampling startShFieldResampling(int coefficients, const glm::ivec3& dims,
                                         std::size_t budgetBytes = kShFieldGridBudgetBytes,
                                         int maxPerAxis = 0);
/// Fills the rest of `r` from `field` in chunks of kShFieldResampleChunk slices (parallel within a
/// chunk), reporting progress ("SH field resampling"); after each chunk a raised cancel throws
/// CancelledError with `r` holding what is done. The same bytes as one uninterrupted pass, for any
/// thread count.
void continueShFieldResampling(const visibility::LocalVisibility& field, ShFieldResampling& r,
                               const core::Progress& progress = core::Progress::none());
void continueShFieldResampling(const visibility::GlobalVisibility& field, ShFieldResampling& r,
                               const core::Progress& progress = core::Progress::none());
void continueShFieldResampling(const visibility::HierarchicalVisibility& field,
                               ShFieldResampling& r,
                               const core::Progress& progress = core::Progress::none());

/// The field sampled at every grid point (parallel over z-slices; the same bytes for any thread
/// count). `dims`: the volume's voxels per axis; budget and maxPerAxis as above. Reports its
/// progress and stops at a chunk's end on a cancel (CancelledError; nothing is returned).
ShFieldGrid resampleShField(const visibility::LocalVisibility& field, const glm::ivec3& dims,
                            std::size_t budgetBytes = kShFieldGridBudgetBytes, int maxPerAxis = 0,
                            const core::Progress& progress = core::Progress::none());
ShFieldGrid resampleShField(const visibility::GlobalVisibility& field, const glm::ivec3& dims,
                            std::size_t budgetBytes = kShFieldGridBudgetBytes, int maxPerAxis = 0,
                            const core::Progress& progress = core::Progress::none());
ShFieldGrid resampleShField(const visibility::HierarchicalVisibility& field, const glm::ivec3& dims,
                            std::size_t budgetBytes = kShFieldGridBudgetBytes, int maxPerAxis = 0,
                            const core::Progress& progress = core::Progress::none());

}  // namespace voxlight::render
