// SPDX-License-Identifier: MIT
#include "render/ray_caster.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <thread>

#include "core/rng.h"
#include "render/dvr_march.h"
#include "render/footprint.h"
#include "render/tonemap.h"

namespace voxlight::render {

std::string toString(Mode m) {
    switch (m) {
        case Mode::EmissionAbsorption:
            return "emission-absorption";
        case Mode::Gradient:
            return "gradient";
        case Mode::Mip:
            return "mip";
        case Mode::MinIp:
            return "minip";
        case Mode::Isosurface:
            return "iso";
    }
    return "?";
}

namespace {
/// Relative distance along a ray (of max(1, |t|)) within which a clip plane's or crop face's entry
/// counts as the volume box's own entry: a plane on the box's face removes nothing, so it must not
/// turn the face into a cut face (plane-normal shading) depending on how t rounded. The two
/// entries are computed differently (world vs. index space) and differ by ~1e-15 relative.
constexpr double kEntryTieRelTol = 1e-9;
bool beyondEntry(double t, double tn) {
    return t > tn + kEntryTieRelTol * std::max(1.0, std::abs(tn));
}

/// Finer majorant cells inside the non-empty bricks of `coarse` (empty bricks stay empty).
template <class F>
grid::BrickMajorants refineMajorants(const core::Volume& volume, const grid::BrickMajorants& coarse,
                                     F&& classify) {
    static_assert(grid::kBrickSize % kSkipCellVoxels == 0);
    constexpr int kRatio = grid::kBrickSize / kSkipCellVoxels;
    const glm::ivec3 dims = volume.dims();
    const glm::ivec3 counts = (dims + kSkipCellVoxels - 1) / kSkipCellVoxels;
    const std::size_t n = std::size_t(counts.x) * counts.y * counts.z;
    std::vector<float> maj(n, 0.f);
    std::vector<std::array<float, 2>> ranges(n);
    volume.visit([&](const auto& v) {
        tbb::parallel_for(0, counts.z, [&](int cz) {
            for (int cy = 0; cy < counts.y; ++cy)
                for (int cx = 0; cx < counts.x; ++cx) {
                    const std::size_t i =
                        std::size_t(cx) + std::size_t(counts.x) * (cy + std::size_t(counts.y) * cz);
                    const std::size_t b = coarse.index(cx / kRatio, cy / kRatio, cz / kRatio);
                    ranges[i] = coarse.valueRange(b);
                    if (!(coarse.majorant(b) > 0.f)) continue;
                    const glm::ivec3 first = glm::ivec3(cx, cy, cz) * kSkipCellVoxels;
                    const glm::ivec3 last = glm::min(first + kSkipCellVoxels, dims - 1);  // apron
                    float lo = INFINITY, hi = -INFINITY;
                    for (int k = first.z; k <= last.z; ++k)
                        for (int j = first.y; j <= last.y; ++j)
                            for (int x = first.x; x <= last.x; ++x) {
                                const float val = v.at(x, j, k);
                                if (!std::isfinite(val)) continue;
                                lo = std::min(lo, val);
                                hi = std::max(hi, val);
                            }
                    if (!(lo <= hi)) continue;  // only non-finite voxels
                    ranges[i] = {lo, hi};
                    const float m = float(classify(lo, hi));
                    maj[i] = m > 0.f ? m : 0.f;
                }
        });
    });
    return grid::BrickMajorants::fromCells(counts, kSkipCellVoxels, std::move(maj),
                                           std::move(ranges));
}
}  // namespace

namespace {

/// Central differences of the stored values at voxel (i, j, k) with clamped indices (what
/// gradientAt's clamped taps see); false when a difference does not fit in int16.
template <class View>
bool centralDifference(const View& v, const glm::ivec3& n, int i, int j, int k,
                       GradientEntry& out) {
    auto at = [&](int x, int y, int z) {
        return int(v.data[std::size_t(x) + v.sy * std::size_t(y) + v.sz * std::size_t(z)]);
    };
    const int dx = at(std::min(i + 1, n.x - 1), j, k) - at(std::max(i - 1, 0), j, k);
    const int dy = at(i, std::min(j + 1, n.y - 1), k) - at(i, std::max(j - 1, 0), k);
    const int dz = at(i, j, std::min(k + 1, n.z - 1)) - at(i, j, std::max(k - 1, 0));
    out = {std::int16_t(dx), std::int16_t(dy), std::int16_t(dz), 0};
    return std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) <= 32767;
}

/// Resizes `d` to `n` zeroed entries with one allocation, zeroing a chunk at a time and checking
/// `progress` in between: the first touch of a table of up to 1 GiB takes seconds on a loaded
/// machine (a 512³ CT's bricked table, 8 s after Ctrl-C before this).
void resizeCancellable(std::vector<GradientEntry>& d, std::size_t n,
                       const core::Progress& progress) {
    constexpr std::size_t kChunkEntries = std::size_t(1) << 22;  // 32 MiB
    d.reserve(n);
    while (d.size() < n) {
        progress.checkCancel();
        d.resize(std::min(n, d.size() + kChunkEntries));
    }
}

}  // namespace

VoxelGradients VoxelGradients::build(const core::Volume& volume, const core::Progress& progress) {
    VoxelGradients g;
    if (volume.type() == core::VoxelType::Float32 || volume.voxelCount() > kMaxVoxels) return g;
    const glm::ivec3 n = volume.dims();
    g.di = n.x > 1 ? 1 : 0;
    g.dj = n.y > 1 ? std::size_t(n.x) : 0;
    g.dk = n.z > 1 ? std::size_t(n.x) * std::size_t(n.y) : 0;
    g.slope = float(volume.mapping.slope);
    resizeCancellable(g.d, std::size_t(volume.voxelCount()), progress);
    std::atomic<bool> fits = true;
    volume.visit([&](const auto& v) {
        tbb::parallel_for(0, n.z, [&](int k) {
            if (progress.cancelled()) return;  // the workers stop taking slices
            bool ok = true;
            GradientEntry* out = g.d.data() + std::size_t(n.x) * std::size_t(n.y) * std::size_t(k);
            for (int j = 0; j < n.y; ++j)
                for (int i = 0; i < n.x; ++i) ok &= centralDifference(v, n, i, j, k, *out++);
            if (!ok) fits = false;
        });
    });
    progress.checkCancel();
    if (!fits) g.d = {};
    return g;
}

BrickedGradients BrickedGradients::build(const core::Volume& volume,
                                         const grid::BrickMajorants& cells,
                                         std::uint64_t maxEntries, const core::Progress& progress) {
    static_assert(kBrickVoxels % kSkipCellVoxels == 0, "bricks hold whole skip cells");
    BrickedGradients g;
    if (volume.type() == core::VoxelType::Float32 || cells.size() == 0) return g;
    VL_CHECK_EQ(cells.cellSize(), kSkipCellVoxels);
    const glm::ivec3 n = volume.dims();
    g.di = n.x > 1 ? 1 : 0;
    g.dj = n.y > 1 ? std::size_t(kStored) : 0;
    g.dk = n.z > 1 ? std::size_t(kStored) * kStored : 0;
    g.slope = float(volume.mapping.slope);
    g.bricks = (n + (kBrickVoxels - 1)) / kBrickVoxels;
    // Bricks holding a cell within one cell of a non-empty one (skip distance ≤ 1): those with a
    // non-empty cell first, then the neighbours, up to maxEntries (the rest fall back to six
    // taps, which is what all cells would do without a table).
    constexpr int kCells = kBrickVoxels / kSkipCellVoxels;  // per brick side
    const glm::ivec3 cc = cells.counts();
    const std::uint8_t* dist = cells.skipDistances();
    auto nearest = [&](const glm::ivec3& b) {  // smallest skip distance in brick b
        const glm::ivec3 lo = b * kCells, hi = glm::min(lo + kCells, cc);
        int d = 255;
        for (int z = lo.z; z < hi.z; ++z)
            for (int y = lo.y; y < hi.y; ++y)
                for (int x = lo.x; x < hi.x; ++x) d = std::min(d, int(dist[cells.index(x, y, z)]));
        return d;
    };
    g.slot.assign(std::size_t(g.bricks.x) * g.bricks.y * g.bricks.z, -1);
    std::vector<std::uint8_t> near(g.slot.size());
    std::size_t b = 0;
    for (int bz = 0; bz < g.bricks.z; ++bz)
        for (int by = 0; by < g.bricks.y; ++by)
            for (int bx = 0; bx < g.bricks.x; ++bx, ++b)
                near[b] = std::uint8_t(nearest({bx, by, bz}));
    const std::size_t maxBricks = std::size_t(maxEntries / kBrickEntries);
    std::vector<glm::ivec3> stored;
    for (int d = 0; d <= 1; ++d) {
        b = 0;
        for (int bz = 0; bz < g.bricks.z; ++bz)
            for (int by = 0; by < g.bricks.y; ++by)
                for (int bx = 0; bx < g.bricks.x; ++bx, ++b)
                    if (near[b] == d && stored.size() < maxBricks) {
                        g.slot[b] = std::int64_t(stored.size() * kBrickEntries);
                        stored.push_back({bx, by, bz});
                    }
    }
    if (stored.empty()) return {};
    resizeCancellable(g.d, stored.size() * kBrickEntries, progress);
    std::atomic<bool> fits = true;
    volume.visit([&](const auto& v) {
        // The apron (local index kBrickVoxels) and voxels past the grid clamp to the last voxel.
        tbb::parallel_for(std::size_t(0), stored.size(), [&](std::size_t s) {
            if (progress.cancelled()) return;  // the workers stop taking bricks
            const glm::ivec3 o = stored[s] * kBrickVoxels;
            GradientEntry* out = g.d.data() + s * kBrickEntries;
            bool ok = true;
            for (int lk = 0; lk < kStored; ++lk)
                for (int lj = 0; lj < kStored; ++lj)
                    for (int li = 0; li < kStored; ++li)
                        ok &= centralDifference(v, n, std::min(o.x + li, n.x - 1),
                                                std::min(o.y + lj, n.y - 1),
                                                std::min(o.z + lk, n.z - 1), *out++);
            if (!ok) fits = false;
        });
    });
    progress.checkCancel();
    if (!fits) return {};
    return g;
}

namespace {

/// Index-space box of the non-empty cells of `m` (cell edges, clamped to the voxel-centre box
/// [0, n − 1]); lo > hi when there is none.
std::array<glm::vec3, 2> nonEmptyCellBox(const grid::BrickMajorants& m, const glm::ivec3& dims) {
    const auto& [lo, hi] = m.nonEmptyCellRange();
    if (lo.x > hi.x) return {glm::vec3(0.f), glm::vec3(-1.f)};
    return {glm::vec3(lo * m.cellSize()),
            glm::min(glm::vec3((hi + 1) * m.cellSize()), glm::vec3(glm::max(dims - 1, 0)))};
}

}  // namespace

float resolveIsoValue(const optics::TransferFunction& tf, const RenderOptions& options) {
    const float iso = options.isoValue.value_or(tf.surfaceValue());
    if (!std::isfinite(iso)) throw InputError("render options", "iso_value", "must be finite");
    return iso;
}

grid::BrickMajorants buildSkipCells(const core::Volume& volume, const grid::BrickGrid& grid,
                                    const optics::TransferFunction& tf,
                                    const optics::TfTable& table, const RenderOptions& options) {
    const float widen = table.cellWidth();  // table interpolation leaks σt up to one cell
    switch (options.mode) {
        case Mode::Gradient:
        case Mode::EmissionAbsorption: {
            auto classify = [&](float lo, float hi) {
                return tf.maxExtinction(lo - widen, hi + widen);
            };
            return refineMajorants(volume, grid::BrickMajorants::build(grid, classify), classify);
        }
        case Mode::Mip:
        case Mode::MinIp: {
            // Nothing is skippable, but the kSkipCellVoxels³ value ranges let the extremum
            // search skip cells that cannot beat the current extremum (tighter than bricks).
            auto any = [](float, float) { return 1.f; };
            return refineMajorants(volume, grid::BrickMajorants::build(grid, any), any);
        }
        case Mode::Isosurface: {
            const float iso = resolveIsoValue(tf, options);
            auto classify = [&](float lo, float hi) { return lo <= iso && iso <= hi ? 1.f : 0.f; };
            return refineMajorants(volume, grid::BrickMajorants::build(grid, classify), classify);
        }
    }
    throw InternalError("unknown render mode");
}

GradientTableUse gradientTableUse(const core::Volume& volume, const RenderOptions& options) {
    return gradientTableUse(volume.voxelCount(), options);
}

GradientTableUse gradientTableUse(std::uint64_t voxelCount, const RenderOptions& options) {
    if (options.mode != Mode::Gradient || !options.centralDifferences)
        return GradientTableUse::None;
    const bool dense =
        options.gradientTable == GradientTable::Dense ||
        (options.gradientTable == GradientTable::Auto && voxelCount <= VoxelGradients::kMaxVoxels);
    return dense ? GradientTableUse::Dense : GradientTableUse::Bricked;
}

namespace {
/// A shared_ptr that does not own (the caller keeps the object alive).
template <class T>
std::shared_ptr<const T> borrowed(const T& object) {
    return std::shared_ptr<const T>(std::shared_ptr<const void>(), &object);
}

CasterTables buildTables(const core::Volume& volume, const grid::BrickGrid& grid,
                         const optics::TransferFunction& tf, const RenderOptions& options) {
    CasterTables t;
    t.table = std::make_shared<const optics::TfTable>(tf);
    t.skipCells = std::make_shared<const grid::BrickMajorants>(
        buildSkipCells(volume, grid, tf, *t.table, options));
    switch (gradientTableUse(volume, options)) {
        case GradientTableUse::Dense:
            t.voxelGradients =
                std::make_shared<const VoxelGradients>(VoxelGradients::build(volume));
            break;
        case GradientTableUse::Bricked:
            t.brickedGradients = std::make_shared<const BrickedGradients>(
                BrickedGradients::build(volume, *t.skipCells));
            break;
        case GradientTableUse::None:
            break;
    }
    return t;
}
}  // namespace

RayCaster::RayCaster(const core::Volume& volume, const grid::BrickGrid& grid,
                     const optics::TransferFunction& tf, RenderOptions options)
    : RayCaster(borrowed(volume), borrowed(tf), options, buildTables(volume, grid, tf, options)) {}

RayCaster::RayCaster(std::shared_ptr<const core::Volume> volumePtr,
                     std::shared_ptr<const optics::TransferFunction> tfPtr, RenderOptions options,
                     CasterTables tables)
    : volume_(std::move(volumePtr)),
      tf_(std::move(tfPtr)),
      tables_(std::move(tables)),
      options_(std::move(options)) {
    VL_CHECK(volume_ && tf_ && tables_.table && tables_.skipCells);
    const core::Volume& volume = *volume_;
    const optics::TransferFunction& tf = *tf_;
    VL_CHECK(!volume.empty());
    if (!(options_.stepVoxels > 0.f) || !std::isfinite(options_.stepVoxels))
        throw InputError("render options", "step", "must be a finite number > 0 (voxels)");
    if (options_.tileSize < 1) options_.tileSize = 16;
    if (!(options_.terminationTransmittance >= 0.f && options_.terminationTransmittance < 1.f))
        throw InputError("render options", "termination", "must be a transmittance in [0, 1)");
    const core::Geometry& g = volume.geometry();
    stepMm_ = float(options_.stepVoxels * core::minComponent(g.spacing));
    for (int a = 0; a < 3; ++a)
        gradientMatrix_[a] = glm::vec3(g.direction[a]) / float(2.0 * g.spacing[a]);
    for (int a = 0; a < 3; ++a) {
        // Volume box in index space: the voxel centres [0, n − 1] (a single slice gets ±0.5).
        const int n = g.dims[a];
        indexBoxLo_[a] = n > 1 ? 0.0 : -0.5;
        indexBoxHi_[a] = n > 1 ? double(n - 1) : 0.5;
    }
    worldToIndexMatrix_ = g.worldToIndexMatrix();
    weakGradient_ = kWeakGradientFraction * tf.window().width;
    isoValue_ = resolveIsoValue(tf, options_);
    const grid::BrickMajorants& cells = *tables_.skipCells;
    VL_CHECK_EQ(cells.cellSize(), kSkipCellVoxels);
    // Tables built for another volume would be read out of bounds: refuse them.
    VL_CHECK(cells.counts() == (g.dims + kSkipCellVoxels - 1) / kSkipCellVoxels);
    visibleIndexBox_ = nonEmptyCellBox(cells, g.dims);
    // visibleRange's box: where the cells' box reaches the grid's edge it extends to the volume
    // box (a single slice is the slab ±0.5, and its cell holds the samples clamped into it), then
    // the margin.
    clipBox_ = visibleIndexBox_;
    if (clipBox_[0].x <= clipBox_[1].x)
        for (int a = 0; a < 3; ++a) {
            if (clipBox_[0][a] <= 0.f) clipBox_[0][a] = float(indexBoxLo_[a]);
            if (clipBox_[1][a] >= float(g.dims[a] - 1)) clipBox_[1][a] = float(indexBoxHi_[a]);
            clipBox_[0][a] -= kVisibleBoxMarginVoxels;
            clipBox_[1][a] += kVisibleBoxMarginVoxels;
        }
}

RaySegment RayCaster::setupRay(const Camera& camera, int x, int y) const {
    const Ray ray = camera.generate(x, y);
    const core::Geometry& g = volume_->geometry();
    RaySegment r;
    r.originWorld = glm::vec3(ray.origin);
    r.dirWorld = glm::vec3(ray.direction);
    // worldToIndex without its per-call transpose and divisions (worldToIndexMatrix_ holds them).
    const glm::dvec3 oi = worldToIndexMatrix_ * (ray.origin - g.origin);
    const glm::dvec3 di = worldToIndexMatrix_ * ray.direction;
    r.originIndex = glm::vec3(oi);
    r.dirIndex = glm::vec3(di);
    double tn = 0.0, tf = std::numeric_limits<double>::infinity();
    // Volume box in index space (indexBoxLo_/Hi_).
    for (int a = 0; a < 3; ++a) {
        const double lo = indexBoxLo_[a], hi = indexBoxHi_[a];
        if (std::abs(di[a]) < 1e-300) {
            if (oi[a] < lo || oi[a] > hi) tf = -1.0;
            continue;
        }
        const double inv = 1.0 / di[a];
        double t1 = (lo - oi[a]) * inv, t2 = (hi - oi[a]) * inv;
        if (t1 > t2) std::swap(t1, t2);
        tn = std::max(tn, t1);
        tf = std::min(tf, t2);
    }
    // Clip planes: keep dot(x − p, n) ≥ 0.
    for (const ClipPlane& c : options_.clipPlanes) {
        const double a = glm::dot(ray.origin - c.point, c.normal);
        const double b = glm::dot(ray.direction, c.normal);
        if (std::abs(b) < 1e-12) {
            if (a < 0.0) tf = -1.0;
            continue;
        }
        const double t = -a / b;
        if (b > 0.0) {
            if (t > tn) {
                if (beyondEntry(t, tn)) {
                    r.clipEntry = true;
                    r.entryNormal = -glm::vec3(c.normal);
                }
                tn = t;
            }
        } else {
            tf = std::min(tf, t);
        }
    }
    if (options_.cropBox) {
        const CropBox& box = *options_.cropBox;
        for (int a = 0; a < 3; ++a) {
            const double d = ray.direction[a];
            if (std::abs(d) < 1e-12) {
                if (ray.origin[a] < box.min[a] || ray.origin[a] > box.max[a]) tf = -1.0;
                continue;
            }
            double t1 = (box.min[a] - ray.origin[a]) / d, t2 = (box.max[a] - ray.origin[a]) / d;
            if (t1 > t2) std::swap(t1, t2);
            if (t1 > tn) {
                if (beyondEntry(t1, tn)) {
                    r.clipEntry = true;
                    r.entryNormal = glm::vec3(0.f);
                    r.entryNormal[a] = d > 0 ? -1.f : 1.f;
                }
                tn = t1;
            }
            tf = std::min(tf, t2);
        }
    }
    r.tNear = float(tn);
    r.tFar = float(tf);
    if (!(r.tFar > r.tNear)) {  // miss
        r.tFar = r.tNear;
        return r;
    }
    r.jitter = options_.jitter
                   ? core::toUnitFloat(core::hashCounters(
                         std::uint64_t(y) * std::uint64_t(camera.width()) + std::uint64_t(x), 0, 0,
                         options_.seed))
                   : 0.f;
    return r;
}

bool RayCaster::visibleRange(const RaySegment& r, float& t0, float& t1) const {
    t0 = r.tNear;
    t1 = r.tFar;
    const auto& [lo, hi] = clipBox_;
    if (lo.x > hi.x) return false;  // nothing is visible
    for (int a = 0; a < 3; ++a) {
        const float l = lo[a], h = hi[a];
        const float o = r.originIndex[a], d = r.dirIndex[a];
        if (d == 0.f) {
            if (!(o >= l && o <= h)) return false;
            continue;
        }
        const float inv = 1.f / d;
        float ta = (l - o) * inv, tb = (h - o) * inv;
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    return t1 > t0;
}

namespace {

using detail::DvrModel;
using detail::finiteOr0;
using detail::writeMiss;

template <bool kMax>
class ExtremumModel final : public ShadingModel {
  public:
    std::string name() const override { return kMax ? "mip" : "minip"; }
    void renderTile(const RayCaster& c, const Camera& cam, int x0, int y0, int x1, int y1,
                    core::ImageRGBA& film, RenderStats& stats) const override {
        const glm::vec3 bg = c.options().background;
        const optics::Window w = c.transferFunction().window();
        c.volume().visit([&](const auto& view) {
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) {
                    float* px = film.at(x, y);
                    const RaySegment r = c.setupRay(cam, x, y);
                    float m = 0.f;
                    if (!r.hit() || !detail::marchExtremum<kMax>(c, view, r, m, stats.samples)) {
                        writeMiss(px, bg);
                        continue;
                    }
                    ++stats.rays;
                    // Grey through the window: a display value, as TF colours are (the default
                    // `clinical` display shows it straight — the window's linear ramp every
                    // viewer of a MIP shows; decoding it as sRGB put the window's centre at 21 %).
                    const float grey = std::clamp((m - w.lo()) / w.width, 0.f, 1.f);
                    px[0] = px[1] = px[2] = finiteOr0(grey);
                    px[3] = 1.f;
                }
        });
    }
};

class IsoModel final : public ShadingModel {
  public:
    explicit IsoModel(BlinnPhongShader shader) : shader_(std::move(shader)) {}
    std::string name() const override { return "iso"; }
    void renderTile(const RayCaster& c, const Camera& cam, int x0, int y0, int x1, int y1,
                    core::ImageRGBA& film, RenderStats& stats) const override {
        const glm::vec3 bg = c.options().background;
        const glm::vec3 albedo = c.transferFunction().eval(c.isoValue()).albedo;
        c.volume().visit([&](const auto& view) {
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x) {
                    float* px = film.at(x, y);
                    const RaySegment r = c.setupRay(cam, x, y);
                    detail::IsoHit hit;
                    if (!r.hit() || !detail::marchIso(c, view, r, hit, stats.samples)) {
                        writeMiss(px, bg);
                        continue;
                    }
                    ++stats.rays;
                    ShadeInput in;
                    in.position = r.originWorld + hit.t * r.dirWorld;
                    in.toEye = -r.dirWorld;
                    in.normal = hit.normal;
                    in.value = c.isoValue();
                    const Scatter s = shader_.scatter(in);
                    for (int k = 0; k < 3; ++k) px[k] = finiteOr0(albedo[k] * s.diffuse[k]);
                    px[3] = 1.f;
                }
        });
    }

  private:
    BlinnPhongShader shader_;
};

}  // namespace

std::array<glm::dvec3, 2> visibleWorldBounds(const RayCaster& caster) {
    return visibleWorldBounds(caster.volume().geometry(), caster.majorants());
}

std::array<glm::dvec3, 2> visibleWorldBounds(const core::Geometry& g,
                                             const grid::BrickMajorants& m) {
    if (m.nonEmptyCount() == 0 || m.nonEmptyCount() == m.size()) return g.worldBounds();
    const auto box = nonEmptyCellBox(m, g.dims);
    const glm::dvec3 first(box[0]), last(box[1]);
    glm::dvec3 bmin(INFINITY), bmax(-INFINITY);
    for (int c = 0; c < 8; ++c) {
        const glm::dvec3 ijk((c & 1) ? last.x : first.x, (c & 2) ? last.y : first.y,
                             (c & 4) ? last.z : first.z);
        const glm::dvec3 w = g.indexToWorld(ijk);
        bmin = glm::min(bmin, w);
        bmax = glm::max(bmax, w);
    }
    return {bmin, bmax};
}

std::unique_ptr<ShadingModel> makeBuiltinModel(const RayCaster& caster, const Camera& camera) {
    const RenderOptions& o = caster.options();
    std::vector<std::shared_ptr<const lights::Light>> lights = o.lights;
    if (lights.empty()) lights.push_back(headlight(camera, 1.f));
    switch (o.mode) {
        case Mode::EmissionAbsorption:
            return std::make_unique<DvrModel<EmissionAbsorptionShader>>(
                "emission-absorption", EmissionAbsorptionShader{o.ambient},
                PixelFootprint(caster, camera));
        case Mode::Gradient:
            return std::make_unique<DvrModel<BlinnPhongShader>>(
                "gradient", BlinnPhongShader(o.blinnPhong, lights, o.irradianceSh),
                PixelFootprint(caster, camera));
        case Mode::Mip:
            return std::make_unique<ExtremumModel<true>>();
        case Mode::MinIp:
            return std::make_unique<ExtremumModel<false>>();
        case Mode::Isosurface: {
            BlinnPhongParams lambert = o.blinnPhong;
            lambert.specular = 0.f;  // Lambertian (ARCHITECTURE §1)
            return std::make_unique<IsoModel>(BlinnPhongShader(lambert, lights, o.irradianceSh));
        }
    }
    throw InternalError("unknown render mode");
}

void checkImageSize(int width, int height) {
    if (std::uint64_t(width) * std::uint64_t(height) > kMaxPixels)
        throw InputError("render options", "image size",
                         "image of " + std::to_string(width) + "x" + std::to_string(height) +
                             " pixels is larger than the renderer's limit (" +
                             std::to_string(kMaxPixels) + " pixels)",
                         "render a smaller image");
}

core::ImageRGBA RayCaster::render(const Camera& camera, const core::Progress& progress,
                                  RenderStats* stats) const {
    const auto model = makeBuiltinModel(*this, camera);
    return render(camera, *model, progress, stats);
}

core::ImageRGBA RayCaster::render(const Camera& camera, const ShadingModel& model,
                                  const core::Progress& progress, RenderStats* stats) const {
    const int W = camera.width(), H = camera.height();
    checkImageSize(W, H);
    core::ImageRGBA film(W, H);
    const int ts = options_.tileSize;
    const int tilesX = (W + ts - 1) / ts, tilesY = (H + ts - 1) / ts;
    const int tiles = tilesX * tilesY;
    RenderStats total;
    total.skipCells = majorants().size();
    total.skipCellsVisible = majorants().nonEmptyCount();
    std::mutex statsMutex;
    tbb::task_arena arena(options_.threads > 0 ? options_.threads : tbb::task_arena::automatic);
    // One loop over all tiles (waves with a barrier each cost 4-5 % of a 40 ms frame in idle
    // threads at the barriers). Progress is reported, and cancellation checked, by the calling
    // thread (which works in the arena too) after each of its chunks; the workers only stop taking
    // tiles once cancellation is requested.
    const std::thread::id caller = std::this_thread::get_id();
    std::atomic<int> tilesDone{0};
    progress.report("render", 0.0);
    arena.execute([&] {
        tbb::parallel_for(
            tbb::blocked_range<int>(0, tiles, 1), [&](const tbb::blocked_range<int>& range) {
                if (progress.cancelled()) return;
                RenderStats local;
                for (int t = range.begin(); t < range.end(); ++t) {
                    const int x0 = (t % tilesX) * ts, y0 = (t / tilesX) * ts;
                    model.renderTile(*this, camera, x0, y0, std::min(W, x0 + ts),
                                     std::min(H, y0 + ts), film, local);
                }
                {
                    std::lock_guard lock(statsMutex);
                    total.rays += local.rays;
                    total.samples += local.samples;
                    total.terminatedEarly += local.terminatedEarly;
                }
                const int done = tilesDone.fetch_add(int(range.size())) + int(range.size());
                if (std::this_thread::get_id() == caller)
                    progress.report("render", double(done) / tiles);
            });
    });
    progress.report("render", 1.0);
    if (stats) *stats = total;
    return film;
}

}  // namespace voxlight::render
