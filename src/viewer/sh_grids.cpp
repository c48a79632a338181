// SPDX-License-Identifier: MIT
#include "viewer/sh_grids.h"

#include "pipeline/pipeline.h"

namespace voxlight::viewer {

template <class Field>
std::shared_ptr<const render::ShFieldGrid> ShGridCache::of(
    const std::shared_ptr<const Field>& field, const glm::ivec3& dims,
    const core::Progress& progress) {
    if (!field) return nullptr;
    for (std::size_t i = 0; i < entries_.size(); ++i)
        if (entries_[i].field.get() == field.get()) {
            Entry e = entries_[i];
            entries_.erase(entries_.begin() + std::ptrdiff_t(i));
            entries_.insert(entries_.begin(), e);
            return e.grid;
        }
    // A resampling cancelled before resumes where it stopped.
    std::shared_ptr<render::ShFieldResampling> r;
    for (std::size_t i = 0; i < pending_.size() && !r; ++i)
        if (pending_[i].field.get() == field.get()) {
            r = pending_[i].resampling;
            pending_.erase(pending_.begin() + std::ptrdiff_t(i));
        }
    if (!r)
        r = std::make_shared<render::ShFieldResampling>(
            render::startShFieldResampling(field->coefficients(), dims, budget_, kMaxTextureSide));
    pending_.insert(pending_.begin(), Pending{field, r});
    if (pending_.size() > kPendingKept) pending_.resize(kPendingKept);
    render::continueShFieldResampling(*field, *r, progress);  // CancelledError: stays pending
    pending_.erase(pending_.begin());
    auto grid = std::make_shared<const render::ShFieldGrid>(std::move(r->grid));
    ++resampled_;
    entries_.insert(entries_.begin(), Entry{field, grid});
    if (entries_.size() > kKept) entries_.resize(kKept);
    return grid;
}

ShGrids ShGridCache::get(const pipeline::CasterSetup& setup, const core::Progress& progress) {
    ShGrids g;
    if (!setup.volume) return g;
    const glm::ivec3 dims = setup.volume->dims();
    const pipeline::CasterSetup::ShFields& f = setup.sh;
    if (f.hierarchical) {
        g.field = of(f.hierarchical, dims, progress);
    } else if (f.global) {
        g.field = of(f.global, dims, progress);
        g.local = of(f.local, dims, progress);
    } else if (f.local) {
        g.field = of(f.local, dims, progress);
    }
    return g;
}

}  // namespace voxlight::viewer
