// SPDX-License-Identifier: MIT
#pragma once
// Which pixels' rays can cross a non-empty skip cell: in the compositing modes every other ray
// returns the background unchanged, so it need not be set up or walked through the cell grid.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "render/camera.h"

namespace voxlight::render {

class RayCaster;

/// Pixels are widened by this many on each side of a projected rectangle: the ray of a pixel that
/// crosses a cell passes through its box exactly in double precision, and the marcher's float ray
/// differs from it by far less than a pixel (the widening absorbs that rounding).
inline constexpr int kFootprintMarginPixels = 1;

/// A superset of the pixels whose rays cross a non-empty cell of caster.majorants(): the union of
/// the bounding rectangles of the projected corners of each run of non-empty cells along i (the
/// projection of a box lies inside the hull of its projected corners), widened by
/// kFootprintMarginPixels. Cells at the grid's edge reach out to the volume box (a single slice is
/// the slab ±0.5, and the marcher clamps its samples into the edge cell). Cells entirely behind a
/// perspective camera are left out (its rays start at the eye); every pixel is covered when
/// skipping (or the footprint) is off, or when a non-empty cell straddles the eye's plane (its
/// projection is unbounded).
class PixelFootprint {
  public:
    PixelFootprint(const RayCaster& caster, const Camera& camera);
    /// Whether the footprint belongs to `camera` (same view and image size); use covers() only
    /// then.
    bool builtFor(const Camera& camera) const;
    bool covers(int x, int y) const {
        return all_ || mask_[std::size_t(y) * std::size_t(width_) + std::size_t(x)] != 0;
    }
    bool coversEverything() const { return all_; }
    /// Covered pixels / all pixels.
    double coveredFraction() const;

  private:
    void coverAll() {
        all_ = true;
        mask_.clear();
    }
    bool all_ = false;
    int width_ = 0, height_ = 0;
    Camera::ProjectiveMap map_;  ///< what the mask was projected with
    std::vector<std::uint8_t> mask_;
};

}  // namespace voxlight::render
