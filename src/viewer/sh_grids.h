// SPDX-License-Identifier: MIT
#pragma once
// The SH methods' visibility fields resampled for the GLSL ray caster (render/sh_field_grid.h),
// made on the render worker's thread after the pipeline's visibility stages (prepare), never on
// the UI thread, and kept per field: a camera or light change reuses them, and switching between
// sh-local and sh-global (both fields cached by the pipeline) resamples nothing once each was
// resampled. No OpenGL here.
#include <cstddef>
#include <memory>
#include <vector>

#include "render/sh_field_grid.h"

namespace voxlight::pipeline {
struct CasterSetup;
}

namespace voxlight::viewer {

struct ShGrids {
    /// What the method shades from: sh-local's local field, sh-global's global field or
    /// ritschel's hierarchical one; null for the other methods.
    std::shared_ptr<const render::ShFieldGrid> field;
    /// sh-global: its local field (the cut faces' band); null otherwise.
    std::shared_ptr<const render::ShFieldGrid> local;
};

class ShGridCache {
  public:
    /// Fields resampled at most this many at a time are kept (most recently used first).
    static constexpr std::size_t kKept = 4;
    /// Cancelled resamplings kept to resume (each holds its grid's memory).
    static constexpr std::size_t kPendingKept = 2;
    /// The smallest GL_MAX_3D_TEXTURE_SIZE OpenGL 4.5 allows: two points per voxel only where
    /// every texture side stays within it (any 4.5 GL then holds the grid of a volume it holds).
    static constexpr int kMaxTextureSide = 2048;
    explicit ShGridCache(std::size_t budgetBytes = render::kShFieldGridBudgetBytes)
        : budget_(budgetBytes) {}
    /// The grids of `setup.sh`'s fields, resampled when not kept already. A cancel (through
    /// `progress`) throws CancelledError; the field's partial resampling is kept and the next get
    /// resumes it (each attempt fills at least render::kShFieldResampleChunk slices), so a camera
    /// drag that cancels every attempt still gets the grid.
    ShGrids get(const pipeline::CasterSetup& setup,
                const core::Progress& progress = core::Progress::none());
    /// Fields resampled so far (tests: a second get of the same field resamples nothing).
    std::size_t resampled() const { return resampled_; }

  private:
    struct Entry {
        std::shared_ptr<const void> field;  ///< held, so that its address is never a newer one's
        std::shared_ptr<const render::ShFieldGrid> grid;
    };
    template <class Field>
    std::shared_ptr<const render::ShFieldGrid> of(const std::shared_ptr<const Field>& field,
                                                  const glm::ivec3& dims,
                                                  const core::Progress& progress);
    struct Pending {
        std::shared_ptr<const void> field;
        std::shared_ptr<render::ShFieldResampling> resampling;
    };
    std::size_t budget_;
    std::vector<Entry> entries_;
    std::vector<Pending> pending_;  ///< cancelled resamplings, most recent first
    std::size_t resampled_ = 0;
};

}  // namespace voxlight::viewer
