// SPDX-License-Identifier: MIT
#include "iso/lattice.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <numbers>
#include <string>
#include <thread>

#include "core/error.h"
#include "core/rng.h"
#include "core/timing.h"
#include "grid/brick_traversal.h"
#include "sh/sh_basis.h"

namespace voxlight::iso {

namespace {

constexpr double kPi = std::numbers::pi;
/// Cells per skip-brick edge (a brick's value range covers its 8³ cells' 9³ corner voxels).
constexpr int kSkipBrick = 8;
/// Block::done values: not computed (0), a texel with its own surface, a plateau texel.
constexpr std::uint8_t kSurfaceTexel = 1, kPlateauTexel = 2;
/// Bisection steps for a crossing inside one monotone piece of a cell's cubic: 2⁻³⁰ of a cell.
/// Crossing search: the bracket is narrowed to this fraction of the monotone piece (bisection's 30
/// halvings gave 2^-30 ≈ 9e-10), in at most kMaxRootSteps steps.
constexpr double kRootTolerance = 1e-9;
constexpr int kMaxRootSteps = 60;
/// OnSurface reads: a texel counts as on the query point's face when their smoothed normals are
/// within 60° (cos 0.5) — the two faces of a thin plate or rib are ≈ 180° apart, a curved surface
/// turns far less than 60° over the one voxel between texels.
constexpr double kSameFaceCosine = 0.5;
/// Isovalues whose skip distances (Tracer::skipFor) are kept: the on-surface lattice's and a
/// bake's or renderer's one. A further isovalue (an isovalue slider) replaces the least recently
/// used one, so the memory stays bounded (1 B per cell each) and every isovalue gets its jumps.
constexpr std::size_t kMaxSkipFields = 2;

std::string number(double v) {
    char b[64];
    std::snprintf(b, sizeof b, "%.6g", v);
    return b;
}

void checkOptions(const LatticeOptions& o) {
    if (o.samples < 1 || o.samples > 1000000)
        throw InputError("lattice", "samples",
                         "must be 1…1000000 paths per texel, got " + std::to_string(o.samples),
                         "give e.g. 100 (Wyman: ~100 suffice)");
    if (o.bounces < 0 || o.bounces > 16)
        throw InputError("lattice", "bounces", "must be 0…16, got " + std::to_string(o.bounces),
                         "give e.g. 1");
    if (!(o.resolution >= kMinLatticeResolution - 1e-12 && o.resolution <= 8.0 + 1e-12))
        throw InputError("lattice", "resolution",
                         "must be 1/2…8 texels per voxel, got " + number(o.resolution),
                         "give 1 (the volume's own resolution), 0.5 or 2");
    if (o.shOrder < 1 || o.shOrder > 5)
        throw InputError("lattice", "sh_order",
                         "must be 1…5 (1…25 coefficients), got " + std::to_string(o.shOrder),
                         "give 3 (9 coefficients) or 5 (25, Wyman's)");
    if (!(o.memoryBudgetMiB > 0.0) || !std::isfinite(o.memoryBudgetMiB))
        throw InputError("lattice", "memory", "the memory budget must be a positive number of MiB",
                         "give e.g. 4096");
}

void checkLightsForMode(const std::vector<std::shared_ptr<const lights::Light>>& ls,
                        LatticeMode mode) {
    for (const auto& l : ls) {
        VL_CHECK(l != nullptr);
        if (mode == LatticeMode::ShTransfer && l->kind() != "directional" &&
            l->kind() != "environment")
            throw InputError("lattice", "mode",
                             "an SH transfer lattice takes distant lights only (directional, "
                             "environment); the scene has a " +
                                 std::string(l->kind()) + " light",
                             "use the irradiance lattice (mode \"irradiance\") for point and area "
                             "lights");
    }
}

/// Uniform cubic B-spline weights and derivative weights for the 4 taps floor(x)−1 … floor(x)+2
/// at fractional position f ∈ [0, 1).
void bspline(double f, double w[4], double dw[4]) {
    const double f2 = f * f, f3 = f2 * f;
    w[0] = (1 - 3 * f + 3 * f2 - f3) / 6.0;
    w[1] = (4 - 6 * f2 + 3 * f3) / 6.0;
    w[2] = (1 + 3 * f + 3 * f2 - 3 * f3) / 6.0;
    w[3] = f3 / 6.0;
    dw[0] = (-1 + 2 * f - f2) / 2.0;
    dw[1] = (-4 * f + 3 * f2) / 2.0;
    dw[2] = (1 + 2 * f - 3 * f2) / 2.0;
    dw[3] = f2 / 2.0;
}

/// Orthonormal basis around unit n (Duff et al. 2017).
void basis(const glm::dvec3& n, glm::dvec3& t, glm::dvec3& b) {
    const double sign = std::copysign(1.0, n.z);
    const double a = -1.0 / (sign + n.z);
    const double c = n.x * n.y * a;
    t = {1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x};
    b = {c, sign + n.y * n.y * a, -n.y};
}

glm::dvec3 cosineSample(const glm::dvec3& n, double u1, double u2) {
    glm::dvec3 t, b;
    basis(n, t, b);
    const double r = std::sqrt(u1), phi = 2.0 * kPi * u2;
    return r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(std::max(0.0, 1.0 - u1)) * n;
}

glm::dvec3 sphereSample(double u1, double u2) {
    const double z = 1.0 - 2.0 * u1, r = std::sqrt(std::max(0.0, 1.0 - z * z)),
                 phi = 2.0 * kPi * u2;
    return {r * std::cos(phi), r * std::sin(phi), z};
}

}  // namespace

/// A point this close to the removed side of a kept plane is on it (mm): mesh vertices on a cut
/// are stored in float (1e-5 mm at 100 mm from the origin); a thousandth of a millimetre is far
/// below any voxel.
constexpr double kOnKeptPlaneMm = 1e-3;

/// Empty-space skipping for one isovalue: per trilinear cell, the Chebyshev distance (cells) to
/// the nearest cell with a corner above the isovalue (or NaN) — the only cells in which a ray
/// starting below it can cross it — capped at 255. Every texel of the on-surface lattice and every
/// vertex of a bake traces against the same isovalue, so the field is built once (one byte per
/// cell, a breadth-first pass) and lets rays cross soft tissue and air in jumps instead of testing
/// cell by cell (the 8³ bricks alone left most cells around bone to the cell test, about half the
/// lattice's time).
struct IlluminationLattice::SkipField {
    double iso;
    std::vector<std::uint8_t> distance;  ///< per cell, at Tracer::skipIndex
    std::vector<std::uint8_t> tiles;     ///< per tile of Tracer::kSkipTile³ cells, in tiles
};

/// The volume's physical values as floats, skip bricks, and the ray/isosurface queries.
struct IlluminationLattice::Tracer {
    glm::ivec3 n;  ///< voxels per axis
    std::vector<float> s;
    glm::ivec3 bricks;
    std::vector<std::array<float, 2>> range;  ///< per skip brick: min, max of its corner voxels
    core::Geometry geo;
    glm::dmat3 worldToIdx;   ///< direction (world, per mm) → index units per mm
    glm::dmat3 gradToWorld;  ///< index-space gradient → world gradient (per mm)
    double minSpacing;
    glm::ivec3 lastCell;  ///< largest trilinear cell index per axis
    static constexpr int kSkipTile = 4;
    glm::ivec3 skipTiles;  ///< tiles of kSkipTile³ cells per axis (skipIndex)
    mutable std::mutex skipMutex;
    /// Most recently used last. Shared: a caller keeps the field it traces with alive while
    /// another isovalue replaces it here.
    mutable std::vector<std::shared_ptr<const SkipField>> skipFields;
    mutable std::uint64_t skipFieldsBuilt = 0;

    explicit Tracer(const core::Volume& v) : n(v.dims()), geo(v.geometry()) {
        s.resize(std::size_t(v.voxelCount()));
        v.visit([&](const auto& view) {
            tbb::parallel_for(0, n.z, [&](int k) {
                for (int j = 0; j < n.y; ++j)
                    for (int i = 0; i < n.x; ++i) s[idx(i, j, k)] = view.at(i, j, k);
            });
            return 0;
        });
        const glm::dmat3 invSpacing(glm::dvec3(1.0 / geo.spacing.x, 0, 0),
                                    glm::dvec3(0, 1.0 / geo.spacing.y, 0),
                                    glm::dvec3(0, 0, 1.0 / geo.spacing.z));
        worldToIdx = invSpacing * glm::transpose(geo.direction);
        gradToWorld = geo.direction * invSpacing;
        minSpacing = std::min({geo.spacing.x, geo.spacing.y, geo.spacing.z});
        lastCell = glm::max(n - 2, glm::ivec3(0));
        skipTiles = (lastCell + kSkipTile) / kSkipTile;
        const glm::ivec3 cells = glm::max(n - 1, glm::ivec3(1));
        bricks = (cells + kSkipBrick - 1) / kSkipBrick;
        range.resize(std::size_t(bricks.x) * bricks.y * bricks.z);
        tbb::parallel_for(0, bricks.z, [&](int bz) {
            for (int by = 0; by < bricks.y; ++by)
                for (int bx = 0; bx < bricks.x; ++bx) {
                    float lo = INFINITY, hi = -INFINITY;
                    const glm::ivec3 b(bx, by, bz);
                    const glm::ivec3 a = b * kSkipBrick, e = glm::min(a + kSkipBrick, n - 1);
                    for (int k = a.z; k <= e.z; ++k)
                        for (int j = a.y; j <= e.y; ++j)
                            for (int i = a.x; i <= e.x; ++i) {
                                const float x = s[idx(i, j, k)];
                                // ±inf count (as in the skip flags and the cell test); NaN
                                // has no order.
                                if (!std::isnan(x)) lo = std::min(lo, x), hi = std::max(hi, x);
                            }
                    range[brickIndex(b)] = {lo, hi};
                }
        });
    }

    std::size_t idx(int i, int j, int k) const {
        return std::size_t(i) + std::size_t(n.x) * (std::size_t(j) + std::size_t(n.y) * k);
    }
    std::size_t cellIndex(const glm::ivec3& c) const {
        return std::size_t(c.x) +
               std::size_t(lastCell.x + 1) *
                   (std::size_t(c.y) + std::size_t(lastCell.y + 1) * std::size_t(c.z));
    }
    /// Where cell c's skip distance is stored: in tiles of kSkipTile³ cells (one 64-byte cache
    /// line), so that the cells a ray steps through share lines — in a plain x-fastest layout of
    /// a 256³ volume nearly every lookup missed the cache (80 % of the traversal's time).
    std::size_t skipIndex(const glm::ivec3& c) const {
        const glm::ivec3 l = c % kSkipTile;
        return tileIndex(c / kSkipTile) * std::size_t(kSkipTile * kSkipTile * kSkipTile) +
               std::size_t(l.x + kSkipTile * (l.y + kSkipTile * l.z));
    }
    std::size_t tileIndex(const glm::ivec3& t) const {
        return std::size_t(t.x) +
               std::size_t(skipTiles.x) *
                   (std::size_t(t.y) + std::size_t(skipTiles.y) * std::size_t(t.z));
    }
    /// The skip distances for `iso` (built on first request, thread-safe; when kMaxSkipFields
    /// isovalues hold theirs, the least recently used is dropped), or nullptr for a non-finite
    /// isovalue or a grid beyond chebyshevDistances' 32-bit indices (the bricks alone then).
    std::shared_ptr<const SkipField> skipFor(double iso) const {
        std::lock_guard<std::mutex> lock(skipMutex);
        for (auto it = skipFields.begin(); it != skipFields.end(); ++it)
            if ((*it)->iso == iso) {
                std::rotate(it, it + 1, skipFields.end());  // now the most recently used
                return skipFields.back();
            }
        const glm::ivec3 cells = lastCell + 1;
        if (!std::isfinite(iso) ||
            std::uint64_t(cells.x) * std::uint64_t(cells.y) * std::uint64_t(cells.z) >
                std::numeric_limits<std::uint32_t>::max())  // chebyshevDistances' indices
            return nullptr;
        std::vector<std::uint8_t> flags(std::size_t(cells.x) * cells.y * cells.z);
        const std::size_t dx = n.x > 1 ? 1 : 0, dy = n.y > 1 ? std::size_t(n.x) : 0,
                          dz = n.z > 1 ? std::size_t(n.x) * std::size_t(n.y) : 0;
        // Isolated: a thread waiting in this loop must not pick up another path's task, which
        // could come back here and lock skipMutex again.
        tbb::this_task_arena::isolate([&] {
            tbb::parallel_for(0, cells.z, [&](int k) {
                for (int j = 0; j < cells.y; ++j)
                    for (int i = 0; i < cells.x; ++i) {
                        const float* b = s.data() + idx(i, j, k);
                        const float v[8] = {b[0],  b[dx],      b[dy],      b[dy + dx],
                                            b[dz], b[dz + dx], b[dz + dy], b[dz + dy + dx]};
                        bool above = false;
                        for (const float x : v) above = above || !(double(x) <= iso);
                        flags[cellIndex({i, j, k})] = above;
                    }
            });
        });
        const std::vector<std::uint8_t> linear = grid::chebyshevDistances(cells, flags.data(), 255);
        auto f = std::make_shared<SkipField>();
        f->iso = iso;
        f->distance.assign(std::size_t(skipTiles.x) * skipTiles.y * skipTiles.z *
                               (kSkipTile * kSkipTile * kSkipTile),
                           255);  // the padding of partial edge tiles: never a cell of the volume
        tbb::this_task_arena::isolate([&] {
            tbb::parallel_for(0, cells.z, [&](int k) {
                for (int j = 0; j < cells.y; ++j)
                    for (int i = 0; i < cells.x; ++i)
                        f->distance[skipIndex({i, j, k})] = linear[cellIndex({i, j, k})];
            });
        });
        // The tiles' own distances (a tile is flagged when any of its cells is): open space is
        // crossed on these, 1/64 of the cells' bytes, which stay in cache.
        std::vector<std::uint8_t> tileFlags(std::size_t(skipTiles.x) * skipTiles.y * skipTiles.z,
                                            0);
        for (std::size_t t = 0; t < tileFlags.size(); ++t)
            for (int q = 0; q < kSkipTile * kSkipTile * kSkipTile; ++q)
                if (f->distance[t * (kSkipTile * kSkipTile * kSkipTile) + std::size_t(q)] == 0) {
                    tileFlags[t] = 1;
                    break;
                }
        f->tiles = grid::chebyshevDistances(skipTiles, tileFlags.data(), 255);
        if (skipFields.size() >= kMaxSkipFields) skipFields.erase(skipFields.begin());
        skipFields.push_back(std::move(f));
        ++skipFieldsBuilt;
        return skipFields.back();
    }
    /// Bytes held: the float copy of the volume, the bricks' ranges and the skip fields kept.
    std::size_t bytes() const {
        std::size_t b = s.size() * sizeof(float) + range.size() * sizeof(range[0]);
        std::lock_guard<std::mutex> lock(skipMutex);
        for (const auto& f : skipFields) b += f->distance.size() + f->tiles.size();
        return b;
    }
    std::size_t brickIndex(const glm::ivec3& b) const {
        return std::size_t(b.x) +
               std::size_t(bricks.x) * (std::size_t(b.y) + std::size_t(bricks.y) * b.z);
    }
    float voxel(int i, int j, int k) const {
        return s[idx(std::clamp(i, 0, n.x - 1), std::clamp(j, 0, n.y - 1),
                     std::clamp(k, 0, n.z - 1))];
    }

    /// Trilinear physical value at index position p (clamped).
    double value(const glm::dvec3& pIn) const {
        const glm::dvec3 p = glm::clamp(pIn, glm::dvec3(0.0), glm::dvec3(n - 1));
        const glm::ivec3 c = glm::min(glm::ivec3(p), glm::max(n - 2, glm::ivec3(0)));
        const glm::dvec3 f = p - glm::dvec3(c);
        double r = 0;
        for (int q = 0; q < 8; ++q) {
            const int dx = q & 1, dy = (q >> 1) & 1, dz = q >> 2;
            const double w = (dx ? f.x : 1 - f.x) * (dy ? f.y : 1 - f.y) * (dz ? f.z : 1 - f.z);
            if (w != 0.0) r += w * voxel(c.x + dx, c.y + dy, c.z + dz);
        }
        return r;
    }

    /// Outward (−∇) unit world normal of the tricubic B-spline smoothed field at index p; zero
    /// where that gradient vanishes.
    glm::dvec3 smoothNormal(const glm::dvec3& pIn) const {
        const glm::dvec3 p = glm::clamp(pIn, glm::dvec3(0.0), glm::dvec3(n - 1));
        const glm::ivec3 c = glm::ivec3(glm::floor(p));
        double w[3][4], dw[3][4];
        for (int a = 0; a < 3; ++a) bspline(p[a] - c[a], w[a], dw[a]);
        glm::dvec3 g(0.0);
        for (int z = 0; z < 4; ++z)
            for (int y = 0; y < 4; ++y)
                for (int x = 0; x < 4; ++x) {
                    const double v = voxel(c.x + x - 1, c.y + y - 1, c.z + z - 1);
                    g.x += v * dw[0][x] * w[1][y] * w[2][z];
                    g.y += v * w[0][x] * dw[1][y] * w[2][z];
                    g.z += v * w[0][x] * w[1][y] * dw[2][z];
                }
        const glm::dvec3 gw = gradToWorld * g;
        const double len = glm::length(gw);
        return len > 0.0 && std::isfinite(len) ? -gw / len : glm::dvec3(0.0);
    }

    /// Kept half-spaces in index space (LatticeOptions::keep): signed distance (mm) at index
    /// point i is dot(i, grad) + offset, ≥ 0 kept.
    struct KeptPlane {
        glm::dvec3 grad;
        double offset;
    };
    std::vector<KeptPlane> kept;

    void keepOnly(const std::vector<core::HalfSpace>& planes) {
        for (const core::HalfSpace& h : planes) {
            const glm::dvec3 grad = geo.spacing * (glm::transpose(geo.direction) * h.normal);
            kept.push_back({grad, glm::dot(geo.origin - h.point, h.normal)});
        }
    }

    /// hitInVolume() with only the kept region's matter (the intersection of half-spaces, convex:
    /// a ray meets it in one interval). A ray entering it inside matter meets the cut face there
    /// (the cap of a capped mesh); matter outside it is gone for the light (shadows_from_removed
    /// false: until 7 December the bake and the lattice traced the whole volume, the removed
    /// bone's shadows kept).
    bool hit(const glm::dvec3& origin, const glm::dvec3& omega, double iso, double tMax,
             double* tHit = nullptr, const SkipField* skip = nullptr) const {
        if (kept.empty()) return hitInVolume(origin, omega, iso, tMax, tHit, skip);
        const glm::dvec3 d = worldToIdx * omega;
        double tEnter = 0.0, tLeave = tMax;
        for (const KeptPlane& k : kept) {
            const double dist = glm::dot(origin, k.grad) + k.offset;
            const double rate = glm::dot(d, k.grad);  // mm of distance per mm along the ray
            // A vertex on a capped plane sits on it to rounding: inside.
            if (dist >= -kOnKeptPlaneMm) {
                if (rate < 0.0) tLeave = std::min(tLeave, std::max(dist, 0.0) / -rate);
            } else {
                if (!(rate > 0.0)) return false;  // outside, moving away (or along)
                tEnter = std::max(tEnter, -dist / rate);
            }
        }
        if (!(tLeave > tEnter)) return false;
        if (tEnter == 0.0) return hitInVolume(origin, omega, iso, tLeave, tHit, skip);
        const glm::dvec3 entry = origin + tEnter * d;
        // Past the volume's box before reaching the kept region: nothing to meet (the box is
        // convex too; value() would clamp to a border voxel and call it a cut face).
        constexpr double kBoxSlack = 1e-9;
        for (int a = 0; a < 3; ++a)
            if (entry[a] < -kBoxSlack || entry[a] > double(n[a] - 1) + kBoxSlack) return false;
        if (value(entry) - iso > 0.0) {  // enters through the cut face of the matter
            if (tHit) *tHit = tEnter;
            return true;
        }
        double t = 0.0;
        if (!hitInVolume(entry, omega, iso, tLeave - tEnter, &t, skip)) return false;
        if (tHit) *tHit = tEnter + t;
        return true;
    }

    /// First t ∈ (0, tMax] (mm) where the trilinear field along origin + t·ω (index origin, world
    /// unit ω) crosses `iso` from the side the origin is on. Returns false when the ray leaves the
    /// volume (or passes tMax) first. `skip`: skipFor(iso)'s distances, used by rays that start
    /// below iso (nullptr: the bricks alone); the same crossings either way, since the cells it
    /// jumps over cannot hold one.
    bool hitInVolume(const glm::dvec3& origin, const glm::dvec3& omega, double iso, double tMax,
                     double* tHit = nullptr, const SkipField* skip = nullptr) const {
        const glm::dvec3 d = worldToIdx * omega;  // index units per mm
        // Which side the origin is on: −1 below iso (the outside; also exactly at iso, as on a
        // plateau, so that only values above it stop the ray), +1 above.
        const double sigma = value(origin) - iso > 0.0 ? 1.0 : -1.0;
        if (sigma > 0.0) skip = nullptr;
        glm::dvec3 inv;
        glm::ivec3 step;
        for (int a = 0; a < 3; ++a) {
            inv[a] = d[a] != 0.0 ? 1.0 / d[a] : INFINITY;
            step[a] = d[a] > 0.0 ? 1 : -1;
        }
        // The volume box in index space [0, n − 1]: exit parameter.
        double tExit = tMax;
        for (int a = 0; a < 3; ++a)
            if (d[a] != 0.0)
                tExit = std::min(tExit, ((d[a] > 0 ? n[a] - 1 : 0) - origin[a]) * inv[a]);
        if (!(tExit > 0.0)) return false;
        double t = 0.0;
        glm::ivec3 c = glm::clamp(glm::ivec3(glm::floor(origin)), glm::ivec3(0), lastCell);
        glm::dvec3 tNext;
        auto initNext = [&] {
            for (int a = 0; a < 3; ++a)
                tNext[a] =
                    d[a] != 0.0 ? ((c[a] + (d[a] > 0 ? 1 : 0)) - origin[a]) * inv[a] : INFINITY;
        };
        initNext();
        // Crosses the box of cells [lo, hi] around c, which holds no crossing, without reading
        // its cells: the DDA moves to the box's last cell along the ray (per axis, the boundaries
        // crossed before the ray leaves the box, never past the box), and the caller's next step
        // leaves it. The cell indices only ever move along the ray, so the walk ends.
        auto jump = [&](const glm::ivec3& lo, const glm::ivec3& hi) {
            double tBox = INFINITY;
            for (int a = 0; a < 3; ++a)
                if (d[a] != 0.0)
                    tBox = std::min(tBox, ((d[a] > 0 ? hi[a] + 1 : lo[a]) - origin[a]) * inv[a]);
            for (int a = 0; a < 3; ++a) {
                if (!(tNext[a] < tBox)) continue;  // also an axis the ray does not cross
                int k = int(std::ceil((tBox - tNext[a]) * std::abs(d[a])));
                k = std::min(k, d[a] > 0 ? hi[a] - c[a] : c[a] - lo[a]);
                if (k <= 0) continue;
                c[a] += step[a] * k;
                tNext[a] += k * std::abs(inv[a]);
            }
        };
        while (true) {
            bool test = true;  // whether this cell may hold a crossing
            if (skip) {
                // The tile's distance R: the tiles within R − 1 hold no crossing; else the
                // cell's distance r: the cube of cells within r − 1 holds none.
                const glm::ivec3 tc = c / kSkipTile;
                const int R = skip->tiles[tileIndex(tc)];
                if (R >= 1) {
                    jump(glm::max((tc - (R - 1)) * kSkipTile, glm::ivec3(0)),
                         glm::min((tc + R) * kSkipTile - 1, lastCell));
                    test = false;
                } else {
                    const int r = skip->distance[skipIndex(c)];
                    if (r >= 2)
                        jump(glm::max(c - (r - 1), glm::ivec3(0)), glm::min(c + (r - 1), lastCell));
                    test = r == 0;
                }
            } else {
                const glm::ivec3 b = c / kSkipBrick;
                const auto& r = range[brickIndex(b)];
                if (!mayCross(r[0], r[1], iso, sigma)) {
                    // No crossing in this brick's cells: to where the ray leaves it.
                    jump(b * kSkipBrick, glm::min(b * kSkipBrick + (kSkipBrick - 1), lastCell));
                    test = false;
                }
            }
            // One cell that may hold a crossing (or, with skip distances, an empty one crossed).
            const double t1 = std::min({tNext.x, tNext.y, tNext.z, tExit});
            if (test && cellHit(c, origin, d, t, t1, iso, sigma, tHit)) return true;
            if (t1 >= tExit) return false;
            const int a = tNext.x <= tNext.y && tNext.x <= tNext.z ? 0 : tNext.y <= tNext.z ? 1 : 2;
            t = std::max(t, t1);
            c[a] += step[a];
            if (c[a] < 0 || c[a] > lastCell[a]) return false;
            tNext[a] += std::abs(inv[a]);
        }
    }

    /// Whether values in [lo, hi] can lie strictly across iso from the side sigma.
    static bool mayCross(float lo, float hi, double iso, double sigma) {
        return sigma < 0.0 ? double(hi) > iso : double(lo) < iso;
    }

    /// The first crossing inside cell c over t ∈ [t0, t1]: the trilinear field along the ray is a
    /// cubic in t; its critical points split [t0, t1] into monotone pieces, and the first piece
    /// whose end lies across `iso` holds the crossing (bisection).
    bool cellHit(const glm::ivec3& c, const glm::dvec3& o, const glm::dvec3& d, double t0,
                 double t1, double iso, double sigma, double* tHit) const {
        if (!(t1 > t0)) return false;
        // c is a cell (c + 1 ≤ n − 1 wherever the axis has 2 voxels): direct reads.
        const float* base = s.data() + idx(c.x, c.y, c.z);
        const std::size_t dx = n.x > 1 ? 1 : 0, dy = n.y > 1 ? std::size_t(n.x) : 0,
                          dz = n.z > 1 ? std::size_t(n.x) * std::size_t(n.y) : 0;
        const float v[8] = {base[0],  base[dx],      base[dy],      base[dy + dx],
                            base[dz], base[dz + dx], base[dz + dy], base[dz + dy + dx]};
        float lo = v[0], hi = v[0];
        for (int q = 1; q < 8; ++q) lo = std::min(lo, v[q]), hi = std::max(hi, v[q]);
        if (!mayCross(lo, hi, iso, sigma)) return false;
        // Local coordinate along the cell: q(u) = q0 + d·u, u = t − t0.
        const glm::dvec3 q0 = o + t0 * d - glm::dvec3(c);
        // Along x: e_jk(u) = v0jk (1 − qx) + v1jk qx = A + B u.
        double A[4], B[4];
        for (int jk = 0; jk < 4; ++jk) {
            const double a0 = v[2 * jk], a1 = v[2 * jk + 1];
            A[jk] = a0 + (a1 - a0) * q0.x;
            B[jk] = (a1 - a0) * d.x;
        }
        // Along y: quadratic per k.
        double Q[2][3];
        for (int k = 0; k < 2; ++k) {
            const double a0 = A[2 * k], b0 = B[2 * k], a1 = A[2 * k + 1], b1 = B[2 * k + 1];
            // (a0 + b0 u)(1 − qy − dy u) + (a1 + b1 u)(qy + dy u)
            const double wy0 = 1.0 - q0.y, wy1 = q0.y;
            Q[k][0] = a0 * wy0 + a1 * wy1;
            Q[k][1] = b0 * wy0 - a0 * d.y + b1 * wy1 + a1 * d.y;
            Q[k][2] = -b0 * d.y + b1 * d.y;
        }
        // Along z: cubic.
        const double wz0 = 1.0 - q0.z, wz1 = q0.z;
        double C[4];
        C[0] = Q[0][0] * wz0 + Q[1][0] * wz1 - iso;
        C[1] = Q[0][1] * wz0 - Q[0][0] * d.z + Q[1][1] * wz1 + Q[1][0] * d.z;
        C[2] = Q[0][2] * wz0 - Q[0][1] * d.z + Q[1][2] * wz1 + Q[1][1] * d.z;
        C[3] = -Q[0][2] * d.z + Q[1][2] * d.z;
        auto g = [&](double u) { return sigma * (((C[3] * u + C[2]) * u + C[1]) * u + C[0]); };
        const double L = t1 - t0;
        if (g(0.0) < 0.0) {
            if (tHit) *tHit = t0;
            return true;
        }
        // Critical points of the cubic inside (0, L).
        double cuts[4] = {0.0, L, L, L};
        int nc = 1;
        const double a = 3 * C[3], bq = 2 * C[2], cq = C[1];
        if (a != 0.0) {
            const double disc = bq * bq - 4 * a * cq;
            if (disc > 0.0) {
                const double sq = std::sqrt(disc);
                double r1 = (-bq - sq) / (2 * a), r2 = (-bq + sq) / (2 * a);
                if (r1 > r2) std::swap(r1, r2);
                if (r1 > 0.0 && r1 < L) cuts[nc++] = r1;
                if (r2 > 0.0 && r2 < L) cuts[nc++] = r2;
            }
        } else if (bq != 0.0) {
            const double r = -cq / bq;
            if (r > 0.0 && r < L) cuts[nc++] = r;
        }
        cuts[nc++] = L;
        for (int piece = 0; piece + 1 < nc; ++piece) {
            double lo2 = cuts[piece], hi2 = cuts[piece + 1];
            double fhi = g(hi2);
            if (fhi >= 0.0) continue;
            // The crossing in [lo2, hi2] (g(lo2) ≥ 0 > g(hi2), g monotone there) to within
            // kRootTolerance of the piece: regula falsi with the Illinois step (the end kept twice
            // has its value halved), superlinear where bisection took 30 halvings.
            if (tHit) {
                double flo = g(lo2);
                const double tol = (hi2 - lo2) * kRootTolerance;
                int kept = 0;
                for (int it = 0; it < kMaxRootSteps && hi2 - lo2 > tol; ++it) {
                    double m =
                        flo > fhi ? lo2 + (hi2 - lo2) * flo / (flo - fhi) : 0.5 * (lo2 + hi2);
                    if (!(m > lo2 && m < hi2)) m = 0.5 * (lo2 + hi2);
                    const double fm = g(m);
                    if (fm >= 0.0) {
                        lo2 = m, flo = fm;
                        if (kept == -1) fhi *= 0.5;
                        kept = -1;
                    } else {
                        hi2 = m, fhi = fm;
                        if (kept == 1) flo *= 0.5;
                        kept = 1;
                    }
                }
                *tHit = t0 + hi2;
            }
            return true;
        }
        return false;
    }

    /// The trilinear field's gradient at x (index, per voxel): central differences of a quarter
    /// voxel.
    glm::dvec3 indexGradient(const glm::dvec3& x) const {
        constexpr double h = 0.25;
        glm::dvec3 g;
        for (int a = 0; a < 3; ++a) {
            glm::dvec3 e(0.0);
            e[a] = h;
            g[a] = (value(x + e) - value(x - e)) / (2.0 * h);
        }
        return g;
    }

    /// p (index) moved onto the trilinear isosurface at iso by Newton steps along the gradient
    /// (central differences of a quarter voxel), each at most half a voxel, to within 1e-4 voxel;
    /// false when the gradient vanishes or the point would move more than maxVoxels.
    bool project(const glm::dvec3& p, double iso, double maxVoxels, glm::dvec3& out) const {
        constexpr double kTol = 1e-4, kMaxStep = 0.5;
        constexpr int kIterations = 32;
        glm::dvec3 x = p;
        for (int it = 0; it < kIterations; ++it) {
            const double f = value(x) - iso;
            const glm::dvec3 g = indexGradient(x);
            const double g2 = glm::dot(g, g);
            if (!(g2 > 0.0) || !std::isfinite(g2)) return false;
            glm::dvec3 step = -f / g2 * g;
            const double len = glm::length(step);
            if (len <= kTol) {
                out = x;
                return glm::length(x - p) <= maxVoxels;
            }
            if (len > kMaxStep) step *= kMaxStep / len;
            x = glm::clamp(x + step, glm::dvec3(0.0), glm::dvec3(n - 1));
            if (glm::length(x - p) > maxVoxels + kMaxStep) return false;
        }
        return false;
    }

    /// Where the isosurface has no point near p because the matter runs into the volume's box
    /// (a bone cut by the scan's field of view, a slab on a face: the ray caster shows a cap
    /// there, the box face over values ≥ iso): the nearest face point within maxVoxels whose
    /// value is ≥ iso, and that face's outward world normal. False when there is none.
    bool capPoint(const glm::dvec3& p, double iso, double maxVoxels, glm::dvec3& out,
                  glm::dvec3& normal) const {
        double best = maxVoxels;
        bool found = false;
        for (int a = 0; a < 3; ++a)
            for (int side = 0; side < 2; ++side) {
                const double face = side ? double(n[a] - 1) : 0.0;
                const double dist = std::abs(p[a] - face);
                if (!(dist <= best)) continue;
                glm::dvec3 q = glm::clamp(p, glm::dvec3(0.0), glm::dvec3(n - 1));
                q[a] = face;
                if (!(value(q) >= iso)) continue;
                best = dist, found = true;
                out = q;
                normal = glm::normalize(geo.direction[a]) * (side ? 1.0 : -1.0);
            }
        return found;
    }

    /// A render's surface point x (index) on the isosurface at iso: its world normal and the point
    /// paths leave from. On a cap — x on the box face over a value ≥ iso (kCapFaceVoxels) and not
    /// on the isosurface itself (farther than that from it by the field's first-order distance
    /// |f − iso| / |∇f|: a crossing that meets the face, the rim, keeps its own normal) — the
    /// face's outward normal and x itself (every direction of its hemisphere leaves the volume);
    /// elsewhere the smoothed normal and startPoint. False when there is no normal (a plateau) or,
    /// with `needStart`, no start point outside.
    bool surfaceFrame(const glm::dvec3& x, double iso, bool needStart, glm::dvec3& nrm,
                      glm::dvec3& start, bool* cap = nullptr) const {
        glm::dvec3 onFace;
        const bool onCap =
            capPoint(x, iso, kCapFaceVoxels, onFace, nrm) &&
            !(std::abs(value(x) - iso) <= kCapFaceVoxels * glm::length(indexGradient(x)));
        if (cap) *cap = onCap;
        start = x;
        if (onCap) return true;
        nrm = smoothNormal(x);
        if (nrm == glm::dvec3(0.0)) return false;
        return !needStart || startPoint(x, nrm, iso, start);
    }

    /// A start point for paths leaving a surface point p (index) along world normal nrm: p moved
    /// out by kStartOffsetVoxels, then further in steps until it is on the outside (value < iso).
    /// False when still inside after kMaxStartWalkVoxels.
    bool startPoint(const glm::dvec3& p, const glm::dvec3& nrm, double iso, glm::dvec3& out) const {
        const glm::dvec3 dn =
            worldToIdx * nrm * minSpacing;  // one voxel (smallest spacing) along n
        constexpr int kWalkSteps = 8;
        for (int k = 0; k <= kWalkSteps; ++k) {
            const double voxels =
                kStartOffsetVoxels + (kMaxStartWalkVoxels - kStartOffsetVoxels) * k / kWalkSteps;
            out = p + voxels * dn;
            if (value(out) < iso) return true;
        }
        return false;
    }
};

struct IlluminationLattice::Block {
    std::vector<float> data;
    std::vector<std::uint8_t> done;
};

IlluminationLattice::IlluminationLattice(std::shared_ptr<const core::Volume> volume,
                                         const optics::TransferFunction& tf,
                                         std::vector<std::shared_ptr<const lights::Light>> lights,
                                         const LatticeOptions& options)
    : volume_(std::move(volume)), tf_(tf), lights_(std::move(lights)), options_(options) {
    checkOptions(options_);
    VL_CHECK(volume_ != nullptr);
    checkLightsForMode(lights_, options_.mode);
    const auto r = volume_->physicalRange();
    if (!(r[0] < r[1]))
        throw InputError("lattice", "volume",
                         "the volume is flat (every voxel " + number(r[0]) + ")",
                         "an isosurface needs values on both sides of the isovalue");
    if (options_.placement == TexelPlacement::OnSurface &&
        !(options_.surfaceIso > r[0] && options_.surfaceIso < r[1]))
        throw InputError("lattice", "isovalue",
                         "texels on the surface need an isovalue strictly inside the data range [" +
                             number(r[0]) + ", " + number(r[1]) + "], got " +
                             number(options_.surfaceIso),
                         "choose an isovalue the volume crosses");
    // Texels from the first voxel to the last, at most 1/resolution apart: the floor of
    // (n − 1)·resolution stopped short of the last voxel where that was not whole (64 voxels at
    // 0.5: texels at 0, 2, …, 62, the vertices past 62 extrapolated and 25 % too bright; probe).
    const glm::ivec3 n = volume_->dims();
    for (int a = 0; a < 3; ++a) {
        dims_[a] = int(std::ceil((n[a] - 1) * options_.resolution - 1e-9)) + 1;
        step_[a] =
            dims_[a] > 1 ? double(n[a] - 1) / double(dims_[a] - 1) : 1.0 / options_.resolution;
    }
    blocks_ = (dims_ + kLatticeBlock - 1) / kLatticeBlock;
    tracer_ = std::make_unique<Tracer>(*volume_);
    tracer_->keepOnly(options_.keep);
    redot();
}

IlluminationLattice::~IlluminationLattice() = default;

std::size_t IlluminationLattice::floatsPerTexel() const {
    const std::size_t onSurface = options_.placement == TexelPlacement::OnSurface ? 3 : 0;
    return onSurface + (options_.mode == LatticeMode::Irradiance
                            ? 3
                            : 3 + 3 * std::size_t(options_.shOrder * options_.shOrder));
}

double IlluminationLattice::storedMiB() const {
    const double perBlock =
        double(kLatticeBlock * kLatticeBlock * kLatticeBlock) * (4.0 * floatsPerTexel() + 1.0);
    return double(blockMap_.size()) * perBlock / (1024.0 * 1024.0);
}

namespace {
std::uint64_t keyOf(const glm::ivec3& b) {
    return std::uint64_t(b.x) | (std::uint64_t(b.y) << 21) | (std::uint64_t(b.z) << 42);
}
int inBlock(const glm::ivec3& t) {
    const glm::ivec3 l = t % kLatticeBlock;
    return l.x + kLatticeBlock * (l.y + kLatticeBlock * l.z);
}
}  // namespace

IlluminationLattice::Block* IlluminationLattice::blockFor(const glm::ivec3& t) const {
    const auto it = blockMap_.find(keyOf(t / kLatticeBlock));
    return it == blockMap_.end() ? nullptr : it->second.get();
}

bool IlluminationLattice::computed(const glm::ivec3& t) const {
    const Block* b = blockFor(t);
    return b && b->done[std::size_t(inBlock(t))];
}

bool IlluminationLattice::plateau(const glm::ivec3& t) const {
    const Block* b = blockFor(t);
    VL_CHECK(b && b->done[std::size_t(inBlock(t))]);
    return b->done[std::size_t(inBlock(t))] == kPlateauTexel;
}

const float* IlluminationLattice::texelData(const glm::ivec3& t) const {
    const Block* b = blockFor(t);
    VL_CHECK(b && b->done[std::size_t(inBlock(t))]);
    return b->data.data() + std::size_t(inBlock(t)) * floatsPerTexel();
}

glm::vec3 IlluminationLattice::texelIrradiance(const glm::ivec3& t) const {
    const float* d = texelData(t);
    return {d[0], d[1], d[2]};
}

std::span<const glm::vec3> IlluminationLattice::texelTransfer(const glm::ivec3& t) const {
    VL_CHECK(options_.mode == LatticeMode::ShTransfer);
    const float* d = texelData(t) + 3;
    static_assert(sizeof(glm::vec3) == 3 * sizeof(float));
    return {reinterpret_cast<const glm::vec3*>(d),
            std::size_t(options_.shOrder * options_.shOrder)};
}

glm::vec3 IlluminationLattice::irradiance(const glm::dvec3& world) const {
    return irradiance(world, NAN);
}

int IlluminationLattice::stencil(const glm::dvec3& world, glm::ivec3 texel[8],
                                 double weight[8]) const {
    const glm::dvec3 q = volume_->geometry().worldToIndex(world) / step_;
    glm::ivec3 i0;
    glm::dvec3 f;
    for (int a = 0; a < 3; ++a) {
        const double x = std::clamp(q[a], 0.0, double(dims_[a] - 1));
        i0[a] = std::min(int(x), std::max(dims_[a] - 2, 0));
        f[a] = x - i0[a];
    }
    int n = 0;
    for (int c = 0; c < 8; ++c) {
        const glm::ivec3 o(c & 1, (c >> 1) & 1, c >> 2);
        const double w = (o.x ? f.x : 1 - f.x) * (o.y ? f.y : 1 - f.y) * (o.z ? f.z : 1 - f.z);
        if (w == 0.0) continue;  // a point on a texel's plane needs no texel beyond it
        texel[n] = glm::min(i0 + o, dims_ - 1);
        weight[n++] = w;
    }
    return n;
}

int IlluminationLattice::surfaceStencil(const glm::dvec3& world, double surfaceIso,
                                        glm::ivec3 texel[8], double weight[8]) const {
    // Groups in order of preference (header): texels with a surface on the inside of
    // surfaceIso, inside plateaus, then the outside ones — only those a require() computed.
    glm::ivec3 all[8];
    double w[8];
    int group[8], best = 2;
    const int n = stencil(world, all, w);
    const bool onSurface = options_.placement == TexelPlacement::OnSurface;
    glm::dvec3 nq(0.0);
    if (onSurface) nq = tracer_->smoothNormal(volume_->geometry().worldToIndex(world));
    const std::size_t fpt = floatsPerTexel();
    for (int c = 0; c < n; ++c) {
        if (onSurface) {
            // Texels that sit on another face of the surface (the far side of a thin rib: the
            // normal there turns away) are read only where no texel shares this point's face.
            const float* d = texelData(all[c]);
            const glm::dvec3 nt(d[fpt - 3], d[fpt - 2], d[fpt - 1]);
            group[c] = plateau(all[c]) ? 2 : glm::dot(nq, nt) < kSameFaceCosine ? 1 : 0;
        } else {
            group[c] = outsideOf(all[c], surfaceIso) ? 2 : plateau(all[c]) ? 1 : 0;
        }
        best = std::min(best, group[c]);
    }
    double wsum = 0.0;
    int m = 0;
    for (int c = 0; c < n; ++c)
        if (group[c] == best) {
            texel[m] = all[c];
            weight[m++] = w[c];
            wsum += w[c];
        }
    if (wsum > 0.0)
        for (int c = 0; c < m; ++c) weight[c] /= wsum;
    return m;
}

glm::vec3 IlluminationLattice::irradiance(const glm::dvec3& world, double surfaceIso) const {
    glm::ivec3 texel[8];
    double weight[8];
    const int n = surfaceStencil(world, surfaceIso, texel, weight);
    glm::dvec3 e(0.0);
    for (int c = 0; c < n; ++c) e += weight[c] * glm::dvec3(texelIrradiance(texel[c]));
    return glm::vec3(e);
}

void IlluminationLattice::transfer(const glm::dvec3& world, double surfaceIso,
                                   std::span<glm::vec3> out) const {
    VL_CHECK(options_.mode == LatticeMode::ShTransfer &&
             out.size() == std::size_t(options_.shOrder * options_.shOrder));
    glm::ivec3 texel[8];
    double weight[8];
    const int n = surfaceStencil(world, surfaceIso, texel, weight);
    std::array<glm::dvec3, 25> sum;  // shOrder ≤ 5: at most 25 coefficients, no allocation
    VL_CHECK(out.size() <= sum.size());
    std::fill_n(sum.begin(), out.size(), glm::dvec3(0.0));
    for (int c = 0; c < n; ++c) {
        const std::span<const glm::vec3> t = texelTransfer(texel[c]);
        for (std::size_t i = 0; i < out.size(); ++i) sum[i] += weight[c] * glm::dvec3(t[i]);
    }
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = glm::vec3(sum[i]);
}

bool IlluminationLattice::outsideOf(const glm::ivec3& t, double surfaceIso) const {
    return !std::isnan(surfaceIso) && tracer_->value(texelIndexPosition(t)) < surfaceIso;
}

void IlluminationLattice::redot() {
    lightSh_.clear();
    if (options_.mode != LatticeMode::ShTransfer) return;
    const int C = options_.shOrder * options_.shOrder;
    lightSh_.assign(std::size_t(C), glm::vec3(0.f));
    for (const auto& l : lights_) {
        const std::vector<glm::vec3> c = l->shCoefficients(glm::dvec3(0.0), options_.shOrder - 1);
        for (int i = 0; i < C; ++i) lightSh_[std::size_t(i)] += c[std::size_t(i)];
    }
    const std::size_t fpt = floatsPerTexel();
    for (auto& [key, block] : blockMap_)
        for (std::size_t t = 0; t < block->done.size(); ++t)
            if (block->done[t]) dotTexel(block->data.data() + t * fpt);
}

void IlluminationLattice::dotTexel(float* d) const {
    // E = max(0, Σ ℓ_i ⊙ T_i): band-limited delta lights ring below zero in their shadows.
    glm::dvec3 e(0.0);
    for (std::size_t i = 0; i < lightSh_.size(); ++i)
        e += glm::dvec3(lightSh_[i]) * glm::dvec3(d[3 + 3 * i], d[4 + 3 * i], d[5 + 3 * i]);
    e = glm::max(e, 0.0);
    d[0] = float(e.x), d[1] = float(e.y), d[2] = float(e.z);
}

void IlluminationLattice::setLights(std::vector<std::shared_ptr<const lights::Light>> lights) {
    checkLightsForMode(lights, options_.mode);
    lights_ = std::move(lights);
    if (options_.mode == LatticeMode::ShTransfer) {
        redot();
    } else {
        blockMap_.clear();
        stored_ = 0;
    }
}

LatticeStats IlluminationLattice::require(std::span<const glm::dvec3> worldPoints,
                                          const core::Progress& progress) {
    return require(worldPoints, NAN, progress);
}

LatticeStats IlluminationLattice::require(std::span<const glm::dvec3> worldPoints,
                                          double surfaceIso, const core::Progress& progress) {
    std::vector<glm::ivec3> needed;
    needed.reserve(worldPoints.size() * 2);
    for (const glm::dvec3& w : worldPoints) {
        // The texels irradiance() reads: with a surface isovalue only those inside it, unless
        // none is.
        glm::ivec3 texel[8];
        double weight[8];
        bool outside[8];
        int inside = 0;
        const int n = stencil(w, texel, weight);
        for (int c = 0; c < n; ++c) {
            // On-surface texels all estimate the one surface: every texel of the stencil.
            outside[c] = options_.placement == TexelPlacement::OwnIsosurface &&
                         outsideOf(texel[c], surfaceIso);
            inside += !outside[c];
        }
        for (int c = 0; c < n; ++c)
            if (!outside[c] || inside == 0) needed.push_back(texel[c]);
    }
    return computeTexels(std::move(needed), progress);
}

LatticeStats IlluminationLattice::requireIsosurface(double isovalue,
                                                    const core::Progress& progress) {
    const Tracer& tr = *tracer_;
    const glm::ivec3 cells = glm::max(tr.n - 1, glm::ivec3(1));
    std::vector<std::vector<glm::ivec3>> perSlice(std::size_t(cells.z));
    tbb::parallel_for(0, cells.z, [&](int k) {
        auto& out = perSlice[std::size_t(k)];
        for (int j = 0; j < cells.y; ++j)
            for (int i = 0; i < cells.x; ++i) {
                float lo = INFINITY, hi = -INFINITY;
                for (int q = 0; q < 8; ++q) {
                    const float v = tr.voxel(i + (q & 1), j + ((q >> 1) & 1), k + (q >> 2));
                    lo = std::min(lo, v), hi = std::max(hi, v);
                }
                if (!(lo <= isovalue && isovalue <= hi && lo < hi)) continue;
                // The texels whose trilinear stencil covers some point of cell [i, i+1]×….
                glm::ivec3 a, b;
                const glm::ivec3 c(i, j, k);
                for (int ax = 0; ax < 3; ++ax) {
                    a[ax] = std::clamp(int(std::floor(c[ax] / step_[ax] + 1e-9)), 0, dims_[ax] - 1);
                    b[ax] = std::clamp(int(std::ceil((c[ax] + 1) / step_[ax] - 1e-9)), 0,
                                       dims_[ax] - 1);
                }
                for (int z = a.z; z <= b.z; ++z)
                    for (int y = a.y; y <= b.y; ++y)
                        for (int x = a.x; x <= b.x; ++x) out.emplace_back(x, y, z);
            }
    });
    std::vector<glm::ivec3> needed;
    for (auto& v : perSlice) needed.insert(needed.end(), v.begin(), v.end());
    return computeTexels(std::move(needed), progress);
}

LatticeStats IlluminationLattice::computeTexels(std::vector<glm::ivec3> needed,
                                                const core::Progress& progress) {
    core::Stopwatch clock;
    LatticeStats st;
    st.texelsFull = std::uint64_t(dims_.x) * dims_.y * dims_.z;
    auto linear = [&](const glm::ivec3& t) {
        return std::uint64_t(t.x) +
               std::uint64_t(dims_.x) * (std::uint64_t(t.y) + std::uint64_t(dims_.y) * t.z);
    };
    std::sort(needed.begin(), needed.end(),
              [&](const glm::ivec3& a, const glm::ivec3& b) { return linear(a) < linear(b); });
    needed.erase(std::unique(needed.begin(), needed.end()), needed.end());
    st.texelsNeeded = needed.size();
    std::vector<glm::ivec3> todo;
    for (const glm::ivec3& t : needed)
        if (!computed(t)) todo.push_back(t);
    st.texelsReused = st.texelsNeeded - todo.size();
    st.texelsComputed = todo.size();

    // Allocate the blocks first (serially), within the budget.
    std::vector<std::uint64_t> newBlocks;
    for (const glm::ivec3& t : todo) {
        const std::uint64_t k = keyOf(t / kLatticeBlock);
        if (!blockMap_.count(k)) newBlocks.push_back(k);
    }
    std::sort(newBlocks.begin(), newBlocks.end());
    newBlocks.erase(std::unique(newBlocks.begin(), newBlocks.end()), newBlocks.end());
    const std::size_t fpt = floatsPerTexel();
    constexpr std::size_t kTexelsPerBlock = kLatticeBlock * kLatticeBlock * kLatticeBlock;
    const double perBlockMiB = double(kTexelsPerBlock) * (4.0 * fpt + 1.0) / (1024.0 * 1024.0);
    if (double(blockMap_.size() + newBlocks.size()) * perBlockMiB > options_.memoryBudgetMiB)
        throw InputError("lattice", "memory",
                         "the lattice needs " +
                             number(double(blockMap_.size() + newBlocks.size()) * perBlockMiB) +
                             " MiB of texels, over the budget of " +
                             number(options_.memoryBudgetMiB) + " MiB",
                         "lower the lattice resolution or the SH order, or raise the budget");
    for (const std::uint64_t k : newBlocks) {
        auto b = std::make_unique<Block>();
        b->data.assign(kTexelsPerBlock * fpt, 0.f);
        b->done.assign(kTexelsPerBlock, 0);
        blockMap_.emplace(k, std::move(b));
    }

    const LatticeOptions& o = options_;
    const int C = o.shOrder * o.shOrder;
    const bool sh = o.mode == LatticeMode::ShTransfer;
    std::atomic<std::uint64_t> paths{0}, shadows{0}, plateaus{0}, finished{0};
    std::atomic<std::size_t> done{0};
    const std::thread::id caller = std::this_thread::get_id();
    const char* stage = "illumination lattice";
    progress.report(stage, 0.0);

    tbb::task_arena arena(o.threads > 0 ? o.threads : tbb::task_arena::automatic);
    arena.execute([&] {
        // Built before the paths rather than by the first of them while the others wait.
        // Built once before the paths and handed to each: held here, it stays alive for the
        // whole call even if other isovalues' requests evict it from the tracer meanwhile.
        const std::shared_ptr<const SkipField> prebuilt =
            o.placement == TexelPlacement::OnSurface && !todo.empty() ? skipFor(o.surfaceIso)
                                                                      : nullptr;
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, todo.size(), 16), [&](const auto& rg) {
            if (progress.cancelled()) return;
            std::uint64_t nPaths = 0, nShadow = 0, nPlateau = 0, nDone = 0;
            PathSums sums(C);
            for (std::size_t r = rg.begin(); r != rg.end(); ++r) {
                const glm::ivec3 t = todo[r];
                const glm::dvec3 xt = texelIndexPosition(t);
                if (o.placement == TexelPlacement::OwnIsosurface) {
                    estimate(xt, tracer_->value(xt), linear(t), o.samples, false, sums);
                } else {
                    glm::dvec3 xs;
                    if (tracer_->project(xt, o.surfaceIso, kMaxProjectionVoxels, xs)) {
                        estimate(xs, o.surfaceIso, linear(t), o.samples, true, sums,
                                 prebuilt.get());
                        // The normal where the texel sits on the surface, last in its data.
                        const glm::dvec3 nrm = tracer_->smoothNormal(xs);
                        float* d = blockFor(t)->data.data() + std::size_t(inBlock(t)) * fpt;
                        for (int a = 0; a < 3; ++a) d[fpt - 3 + std::size_t(a)] = float(nrm[a]);
                    } else if (glm::dvec3 nrm;
                               tracer_->capPoint(xt, o.surfaceIso, kMaxProjectionVoxels, xs, nrm)) {
                        // Matter cut by the box: the cap the ray caster shows, lit as a surface
                        // with the face's normal (it was left out, and read as black).
                        estimate(xs, o.surfaceIso, linear(t), o.samples, true, sums, prebuilt.get(),
                                 &nrm);
                        float* d = blockFor(t)->data.data() + std::size_t(inBlock(t)) * fpt;
                        for (int a = 0; a < 3; ++a) d[fpt - 3 + std::size_t(a)] = float(nrm[a]);
                    } else {  // no point of the surface near: left out of reads
                        sums.E = glm::dvec3(0.0);
                        std::fill(sums.T.begin(), sums.T.end(), glm::dvec3(0.0));
                        sums.plateau = true;
                        sums.paths = sums.shadowRays = 0;
                    }
                }
                nPaths += sums.paths, nShadow += sums.shadowRays, nPlateau += sums.plateau;
                float* d = blockFor(t)->data.data() + std::size_t(inBlock(t)) * fpt;
                if (sh) {
                    for (int i = 0; i < C; ++i)
                        for (int ch = 0; ch < 3; ++ch)
                            d[3 + 3 * i + ch] = float(sums.T[std::size_t(i)][ch]);
                    dotTexel(d);
                } else {
                    d[0] = float(sums.E.x), d[1] = float(sums.E.y), d[2] = float(sums.E.z);
                }
                blockFor(t)->done[std::size_t(inBlock(t))] =
                    sums.plateau ? kPlateauTexel : kSurfaceTexel;
                ++nDone;
            }
            paths += nPaths;
            shadows += nShadow;
            plateaus += nPlateau;
            finished += nDone;
            const std::size_t now = done.fetch_add(rg.size()) + rg.size();
            if (std::this_thread::get_id() == caller)
                progress.report(stage, double(now) / double(std::max<std::size_t>(todo.size(), 1)));
        });
    });
    // Texels finished before a cancel are complete and stay; the rest were never marked.
    stored_ += finished;
    if (progress.cancelled()) throw CancelledError();
    progress.report(stage, 1.0);
    st.texelsStored = stored_;
    st.pathsTraced = paths;
    st.shadowRays = shadows;
    st.plateauTexels = plateaus;
    st.seconds = clock.seconds();
    st.storedMiB = storedMiB();
    st.tracerMiB = tracerMiB();
    st.skipFieldsBuilt = skipFieldsBuilt();
    return st;
}

void IlluminationLattice::estimate(const glm::dvec3& xt, double iso, std::uint64_t key, int samples,
                                   bool sharedIso, PathSums& out, const SkipField* given,
                                   const glm::dvec3* cap) const {
    const Tracer& tr = *tracer_;
    const std::shared_ptr<const SkipField> held = sharedIso && !given ? skipFor(iso) : nullptr;
    const SkipField* skip = given ? given : held.get();
    const LatticeOptions& o = options_;
    const int C = o.shOrder * o.shOrder;
    const bool sh = o.mode == LatticeMode::ShTransfer;
    out.paths = out.shadowRays = 0;
    std::fill(out.T.begin(), out.T.end(), glm::dvec3(0.0));
    // Irradiance from the delta lights at surface point x (index) with normal n (world; zero =
    // the full-sphere average, cos θ → 1/4).
    auto directDelta = [&](const glm::dvec3& x, const glm::dvec3& nrm) {
        glm::dvec3 e(0.0);
        const glm::dvec3 world = tr.geo.indexToWorld(x);
        for (const auto& l : lights_) {
            if (!l->isDelta()) continue;
            const lights::LightSample ls = l->sample(world, glm::vec2(0.5f));
            if (!(ls.pdf > 0.f)) continue;
            const double cosT = nrm == glm::dvec3(0.0) ? 0.25 : glm::dot(nrm, glm::dvec3(ls.wi));
            if (cosT <= 0.0) continue;
            ++out.shadowRays;
            if (tr.hit(x, glm::dvec3(ls.wi), iso, double(ls.distance), nullptr, skip)) continue;
            e += glm::dvec3(ls.value) * cosT;
        }
        return e;
    };
    const glm::dvec3 albedo = glm::clamp(glm::dvec3(tf_.eval(float(iso)).albedo), 0.0, 1.0);
    glm::dvec3 n0 = cap ? *cap : tr.smoothNormal(xt);
    glm::dvec3 x0 = xt;
    // (A cap's paths start on the box face: every direction of its hemisphere leaves the volume.)
    if (!cap && n0 != glm::dvec3(0.0) && !tr.startPoint(xt, n0, iso, x0)) n0 = glm::dvec3(0.0);
    out.plateau = n0 == glm::dvec3(0.0);
    if (out.plateau) x0 = xt;
    glm::dvec3 E(0.0);  // Σ over paths of what follows the first direction
    // Delta lights at the start are the same for every path: once.
    const glm::dvec3 direct0 = sh ? glm::dvec3(0.0) : directDelta(x0, n0);
    for (int smp = 0; smp < samples; ++smp) {
        core::CounterRng rng(core::hashCounters(key, std::uint64_t(smp)), o.seed);
        glm::dvec3 x = x0, nrm = n0, beta(1.0);
        for (int vertex = 0;; ++vertex) {
            const double u1 = rng.uniformDouble(), u2 = rng.uniformDouble();
            const bool sphere = nrm == glm::dvec3(0.0);
            const glm::dvec3 w = sphere ? sphereSample(u1, u2) : cosineSample(nrm, u1, u2);
            double th = 0.0;
            if (!tr.hit(x, w, iso, INFINITY, &th, skip)) {
                // Escaped: distant/area radiance, π per cosine-weighted sample (the full sphere:
                // π·L as well, see the header).
                if (sh) {
                    sh::evalShUnitDouble(o.shOrder - 1, w, out.y);
                    for (int i = 0; i < C; ++i)
                        out.T[std::size_t(i)] += kPi * beta * out.y[std::size_t(i)];
                } else {
                    const glm::dvec3 world = tr.geo.indexToWorld(x);
                    for (const auto& l : lights_)
                        if (!l->isDelta())
                            E += kPi * beta * glm::dvec3(l->radiance(world, glm::vec3(w)));
                }
                break;
            }
            if (vertex >= o.bounces) break;
            // A diffuse bounce on the same isosurface.
            beta *= albedo;
            if (beta == glm::dvec3(0.0)) break;
            const glm::dvec3 y1 = x + th * (tr.worldToIdx * w);
            glm::dvec3 ny = tr.smoothNormal(y1);
            if (ny == glm::dvec3(0.0)) break;
            if (glm::dot(ny, w) > 0.0) ny = -ny;  // face the arriving path
            glm::dvec3 xs;
            if (!tr.startPoint(y1, ny, iso, xs)) break;
            if (!sh) E += beta * directDelta(xs, ny);
            x = xs;
            nrm = ny;
        }
        ++out.paths;
    }
    const double inv = 1.0 / samples;
    out.E = direct0 + E * inv;
    for (auto& t : out.T) t *= inv;
}

int IlluminationLattice::skipFieldCount() const {
    std::lock_guard<std::mutex> lock(tracer_->skipMutex);
    return int(tracer_->skipFields.size());
}

std::uint64_t IlluminationLattice::skipFieldsBuilt() const {
    std::lock_guard<std::mutex> lock(tracer_->skipMutex);
    return tracer_->skipFieldsBuilt;
}

double IlluminationLattice::tracerMiB() const {
    return double(tracer_->bytes()) / (1024.0 * 1024.0);
}

std::shared_ptr<const IlluminationLattice::SkipField> IlluminationLattice::skipFor(
    double iso) const {
    return options_.skipDistances ? tracer_->skipFor(iso) : nullptr;
}

glm::vec3 IlluminationLattice::pointIrradiance(const glm::dvec3& world, double iso, int samples,
                                               std::uint64_t key) const {
    VL_CHECK(options_.mode == LatticeMode::Irradiance && samples > 0);
    PathSums sums(options_.shOrder * options_.shOrder);
    const glm::dvec3 x = volume_->geometry().worldToIndex(world);
    glm::dvec3 nrm, start;
    bool cap = false;
    tracer_->surfaceFrame(x, iso, false, nrm, start, &cap);
    estimate(x, iso, key, samples, true, sums, nullptr, cap ? &nrm : nullptr);
    return glm::vec3(sums.E);
}

glm::vec3 IlluminationLattice::directIrradiance(const glm::dvec3& world, double iso,
                                                bool shadows) const {
    const Tracer& tr = *tracer_;
    const glm::dvec3 x = volume_->geometry().worldToIndex(world);
    glm::dvec3 nrm, start;
    if (!tr.surfaceFrame(x, iso, shadows, nrm, start)) return glm::vec3(0.f);
    glm::dvec3 e(0.0);
    const std::shared_ptr<const SkipField> held = shadows ? skipFor(iso) : nullptr;
    const SkipField* skip = held.get();
    for (const auto& l : lights_) {
        if (!l->isDelta()) continue;
        const lights::LightSample ls = l->sample(world, glm::vec2(0.5f));
        if (!(ls.pdf > 0.f)) continue;
        const double cosT = glm::dot(nrm, glm::dvec3(ls.wi));
        if (cosT <= 0.0) continue;
        if (shadows && tr.hit(start, glm::dvec3(ls.wi), iso, double(ls.distance), nullptr, skip))
            continue;
        e += glm::dvec3(ls.value) * cosT;
    }
    return glm::vec3(e);
}

glm::vec3 IlluminationLattice::vicinityIrradiance(const glm::dvec3& world, double iso,
                                                  double radiusMm, int samples,
                                                  std::uint64_t key) const {
    VL_CHECK(samples > 0 && radiusMm > 0.0);
    const Tracer& tr = *tracer_;
    const glm::dvec3 x = volume_->geometry().worldToIndex(world);
    glm::dvec3 nrm, start;
    if (!tr.surfaceFrame(x, iso, true, nrm, start)) return glm::vec3(0.f);
    const std::shared_ptr<const SkipField> held = skipFor(iso);
    const SkipField* skip = held.get();
    bool sky = true;  // no environment or area light: a white sky of radiance 1
    for (const auto& l : lights_) sky = sky && l->isDelta();
    glm::dvec3 e(0.0);
    for (int smp = 0; smp < samples; ++smp) {
        core::CounterRng rng(core::hashCounters(key, std::uint64_t(smp)), options_.seed);
        const double u1 = rng.uniformDouble(), u2 = rng.uniformDouble();
        const glm::dvec3 w = cosineSample(nrm, u1, u2);
        if (tr.hit(start, w, iso, radiusMm, nullptr, skip)) continue;
        if (sky) {
            e += glm::dvec3(kPi);
            continue;
        }
        for (const auto& l : lights_)
            if (!l->isDelta()) e += kPi * glm::dvec3(l->radiance(world, glm::vec3(w)));
    }
    return glm::vec3(e / double(samples));
}

LatticeStats bakeVertexColours(Mesh& mesh, IlluminationLattice& lattice, double isovalue,
                               const glm::vec3& albedo, float scale, BakeSource source,
                               const core::Progress& progress, std::vector<float>* transfer) {
    VL_CHECK(!transfer ||
             (source == BakeSource::Lattice && lattice.options().mode == LatticeMode::ShTransfer));
    std::vector<glm::dvec3> points;
    points.reserve(mesh.n_vertices());
    for (const auto v : mesh.vertices()) {
        const auto& p = mesh.point(v);
        points.emplace_back(p[0], p[1], p[2]);
    }
    std::vector<glm::vec3> e(points.size());
    LatticeStats st;
    if (source == BakeSource::Lattice) {
        st = lattice.require(points, progress);
        for (std::size_t i = 0; i < points.size(); ++i) e[i] = lattice.irradiance(points[i]);
        if (transfer) {
            const std::size_t C =
                std::size_t(lattice.options().shOrder * lattice.options().shOrder);
            transfer->assign(points.size() * C * 3, 0.f);
            std::vector<glm::vec3> t(C);
            for (std::size_t i = 0; i < points.size(); ++i) {
                lattice.transfer(points[i], NAN, t);
                std::memcpy(transfer->data() + i * C * 3, t.data(), C * sizeof(glm::vec3));
            }
        }
    } else {
        // Paths from every vertex on the mesh's own isosurface (the lattice's reference).
        core::Stopwatch clock;
        const int samples = lattice.options().samples;
        std::atomic<std::size_t> done{0};
        const std::thread::id caller = std::this_thread::get_id();
        const char* stage = "baking light at the vertices";
        progress.report(stage, 0.0);
        tbb::task_arena arena(lattice.options().threads > 0 ? lattice.options().threads
                                                            : tbb::task_arena::automatic);
        arena.execute([&] {
            tbb::parallel_for(
                tbb::blocked_range<std::size_t>(0, points.size(), 64), [&](const auto& r) {
                    if (progress.cancelled()) return;
                    for (std::size_t i = r.begin(); i != r.end(); ++i)
                        e[i] =
                            lattice.pointIrradiance(points[i], isovalue, samples, std::uint64_t(i));
                    const std::size_t now = done.fetch_add(r.size()) + r.size();
                    if (std::this_thread::get_id() == caller)
                        progress.report(stage, double(now) / double(points.size()));
                });
        });
        if (progress.cancelled()) throw CancelledError();
        progress.report(stage, 1.0);
        st.pathsTraced = std::uint64_t(samples) * points.size();
        st.seconds = clock.seconds();
    }
    const glm::vec3 k = albedo * float(scale / kPi);
    for (const auto v : mesh.vertices()) {
        const glm::vec3 c = k * e[v.idx()];
        mesh.set_color(v, Mesh::Color(c.x, c.y, c.z));
    }
    return st;
}

}  // namespace voxlight::iso
