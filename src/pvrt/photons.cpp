// SPDX-License-Identifier: MIT
#include "pvrt/photons.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

#include "core/error.h"
#include "core/rng.h"
#include "core/timing.h"

namespace voxlight::pvrt {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kInvFourPi = 0.25 / kPi;
/// Photons one tracing task handles (its events stay together, in photon order).
constexpr std::int64_t kPhotonsPerChunk = 256;
/// Russian roulette never survives with less than this probability (as the path tracer).
constexpr double kMinSurvival = 0.05;
/// Slabs per worker thread of the splat (load balance; the result does not depend on it).
constexpr int kSlabsPerThread = 4;
constexpr const char* kStage = "indirect transfer (photons)";

/// One face of the volume box cut into cells: index-space corner, cell edges along axes b and c,
/// world inward normal and tangents, cell area (mm²).
struct Face {
    int axis = 0, b = 1, c = 2;
    glm::dvec3 corner{0.0};       ///< index space
    double edgeB = 0, edgeC = 0;  ///< index units per cell
    int cellsB = 1, cellsC = 1;
    glm::dvec3 normal{0.0}, tangentB{0.0}, tangentC{0.0};  ///< world, unit
    double cellArea = 0.0;                                 ///< mm²
    std::int64_t firstCell = 0;
};

/// A collision or a free flight to splat: its position, or the flight's start p and end q (mm
/// along the volume's axes from voxel (0,0,0): ijk·spacing; q = p for a collision), the RGB
/// weight (β/(σt·4π) for a collision, β/4π for a flight) and the photon (index within the batch).
struct Event {
    glm::vec3 p, q;
    glm::vec3 w;
    std::uint32_t photon;
    /// Unit direction the scored light arrives from (−d of the flight; used when n > 1).
    glm::vec3 from{0.f};
};

/// ∫ (c² − u²)³ du from 0 to u (|u| ≤ c): the poly6 kernel's profile along a line at distance
/// r⊥ from the point, c² = h² − r⊥².
double poly6Line(double u, double c2) {
    const double u2 = u * u;
    return u * (c2 * c2 * c2 - c2 * c2 * u2 + 0.6 * c2 * u2 * u2 - u2 * u2 * u2 / 7.0);
}

/// Narrows [s0, s1] to the s where |a + s·d − centre| < h (one axis of a line a + s·d).
void narrowToSlab(double a, double d, double centre, double h, double& s0, double& s1) {
    if (std::abs(d) < 1e-12) {
        if (std::abs(a - centre) >= h) s1 = s0 - 1.0;
        return;
    }
    double lo = (centre - h - a) / d, hi = (centre + h - a) / d;
    if (lo > hi) std::swap(lo, hi);
    s0 = std::max(s0, lo);
    s1 = std::min(s1, hi);
}

/// Per photon of a batch: where its m fluxes start in the batch's flux arrays, and how many.
struct PhotonFluxes {
    std::uint32_t first = 0, count = 0;
};

struct Chunk {
    std::vector<Event> events;
    std::uint64_t collisions = 0;
};

void checkOptions(const PhotonOptions& o) {
    if (o.photonsPerCell < 1)
        throw InputError("pvrt", "photons_per_cell",
                         "must be at least 1 (got " + std::to_string(o.photonsPerCell) + ")",
                         "use 1, 10 or 100 (Zhang's NP)");
    if (!(o.kernelRadiusCells > 0.f) || !std::isfinite(o.kernelRadiusCells))
        throw InputError("pvrt", "kernel_radius",
                         "must be a positive number of grid steps (got " +
                             std::to_string(o.kernelRadiusCells) + ")",
                         "use e.g. 2");
    if (o.maxScatterings < 0)
        throw InputError("pvrt", "max_scatterings",
                         "must be at least 0 (got " + std::to_string(o.maxScatterings) + ")");
    if (o.rouletteAfter < 0)
        throw InputError("pvrt", "roulette_after",
                         "must be at least 0 (got " + std::to_string(o.rouletteAfter) + ")");
    if (!(std::abs(o.phaseG) < 1.f))
        throw InputError(
            "pvrt", "phase_g",
            "must lie strictly between -1 and 1 (got " + std::to_string(o.phaseG) + ")",
            "use e.g. 0.6 for forward scattering, 0 for isotropic");
    if (o.estimator != Estimator::Collision && o.estimator != Estimator::TrackLength)
        throw InputError("pvrt", "estimator", "is not an estimator",
                         "use \"collision\" or \"track-length\"");
}

}  // namespace

PhotonStats addIndirectTransfer(const pathtrace::PathTracer& medium, const Basis& basis,
                                Transfer& transfer, const PhotonOptions& options,
                                const core::Progress& progress) {
    checkOptions(options);
    const core::Stopwatch clock;
    const core::Geometry& geo = medium.volume().geometry();
    const TransferLayout& layout = transfer.layout;
    const int m = basis.size();
    VL_CHECK_EQ(transfer.basis, m);
    // Laid out for this volume: res ≤ dims, scale = dims / res.
    VL_CHECK(layout.res == glm::min(layout.res, geo.dims));
    VL_CHECK(glm::all(glm::lessThan(
        glm::abs(layout.scale * glm::vec3(layout.res) - glm::vec3(geo.dims)), glm::vec3(1e-3f))));
    VL_CHECK(layout.slot.size() == std::size_t(layout.res.x) * layout.res.y * layout.res.z);
    const int n = transfer.exitance;  // exitance coefficients per basis light (transfer.h)
    VL_CHECK(validExitance(n));
    VL_CHECK_EQ(transfer.values.size(), std::size_t(layout.points) * std::size_t(n) * m * 3);
    // Scattering: HG with the TF's phase g channel where it has one, else options.phaseG; g = 0
    // keeps the isotropic draw (and so the photons of n = 1, g = 0 bit for bit).
    const bool phaseChannel = medium.table().hasPhaseG();
    // Section views: planes (or a crop box) that remove matter for the camera but not the light.
    const pathtrace::Options& mo = medium.options();
    bool sectionView = mo.cropBox && mo.cropBox->shadowsFromRemoved;
    for (const render::ClipPlane& p : mo.clipPlanes)
        sectionView = sectionView || p.shadowsFromRemoved;
    PhotonStats stats;
    if (options.maxScatterings == 0 || layout.points == 0) {
        stats.seconds = clock.seconds();
        return stats;
    }

    // The box keptInterval clips to (index space; PathTracer's boxLo / boxHi).
    glm::dvec3 boxLo, boxHi;
    for (int a = 0; a < 3; ++a) {
        const int n = geo.dims[a];
        boxLo[a] = n > 1 ? 0.0 : -0.5;
        boxHi[a] = n > 1 ? double(n - 1) : 0.5;
    }
    const glm::dvec3 stepMm = glm::dvec3(layout.scale) * geo.spacing;  // grid step per axis

    // Faces and their boundary cells (about one grid step per side).
    std::array<Face, 6> faces;
    std::int64_t cells = 0;
    for (int a = 0; a < 3; ++a)
        for (int side = 0; side < 2; ++side) {
            Face& f = faces[std::size_t(2 * a + side)];
            f.axis = a;
            f.b = (a + 1) % 3;
            f.c = (a + 2) % 3;
            f.corner = boxLo;
            if (side == 1) f.corner[a] = boxHi[a];
            const double extB = boxHi[f.b] - boxLo[f.b], extC = boxHi[f.c] - boxLo[f.c];
            f.cellsB = std::max(1, int(std::ceil(extB * geo.spacing[f.b] / stepMm[f.b] - 1e-9)));
            f.cellsC = std::max(1, int(std::ceil(extC * geo.spacing[f.c] / stepMm[f.c] - 1e-9)));
            f.edgeB = extB / f.cellsB;
            f.edgeC = extC / f.cellsC;
            f.normal = geo.direction[a] * (side == 0 ? 1.0 : -1.0);
            f.tangentB = geo.direction[f.b];
            f.tangentC = geo.direction[f.c];
            f.cellArea = f.edgeB * geo.spacing[f.b] * f.edgeC * geo.spacing[f.c];
            f.firstCell = cells;
            cells += std::int64_t(f.cellsB) * f.cellsC;
        }
    const std::int64_t perCell = options.photonsPerCell;
    const std::int64_t photons = cells * perCell;

    // The kernel (mm) and, per axis, the grid points' coordinates (mm along the volume's axes).
    const double h = double(options.kernelRadiusCells) * std::max({stepMm.x, stepMm.y, stepMm.z});
    const double h2 = h * h;
    const double kernelNorm = 315.0 / (64.0 * kPi * std::pow(h, 9.0));
    std::array<std::vector<float>, 3> pointMm;
    glm::vec3 radiusSteps;
    for (int a = 0; a < 3; ++a) {
        pointMm[std::size_t(a)].resize(std::size_t(layout.res[a]));
        for (int g = 0; g < layout.res[a]; ++g) {
            glm::vec3 gv(0.f);
            gv[a] = float(g);
            pointMm[std::size_t(a)][std::size_t(g)] =
                float(double(layout.position(glm::ivec3(gv))[a]) * geo.spacing[a]);
        }
        radiusSteps[a] = float(h / stepMm[a]);
    }
    const glm::vec3 spacingF(geo.spacing), scale = layout.scale;
    // Grid-coordinate range [lo, hi] of the points within h of an event along axis a.
    auto pointRange = [&](const glm::vec3& p, int a, int& lo, int& hi) {
        const float g = (p[a] / spacingF[a] + 0.5f) / scale[a] - 0.5f;
        lo = std::max(0, int(std::ceil(g - radiusSteps[a])));
        hi = std::min(layout.res[a] - 1, int(std::floor(g + radiusSteps[a])));
    };
    // Grid-coordinate range [lo, hi] of the points whose coordinate along axis a lies within
    // [loMm − r, hiMm + r], r = h or 0 (one point of slack each side; the exact test is per
    // point).
    auto spanRange = [&](double loMm, double hiMm, int a, int& lo, int& hi, bool widen = true) {
        const double r = widen ? double(radiusSteps[a]) : 0.0;
        const double gl = (loMm / geo.spacing[a] + 0.5) / double(scale[a]) - 0.5;
        const double gh = (hiMm / geo.spacing[a] + 0.5) / double(scale[a]) - 0.5;
        lo = std::max(0, int(std::ceil(gl - r)) - 1);
        hi = std::min(layout.res[a] - 1, int(std::floor(gh + r)) + 1);
    };
    const bool trackLength = options.estimator == Estimator::TrackLength;

    const int maxSupport = basis.maxSupport();
    const std::int64_t batches = (photons + kPhotonsPerBatch - 1) / kPhotonsPerBatch;
    std::vector<PhotonFluxes> photonFluxes;
    std::vector<int> fluxIndex;
    std::vector<float> fluxValue;
    std::vector<Chunk> chunks;

    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
    const int slabs = std::min(layout.res.z, kSlabsPerThread * arena.max_concurrency());
    const int slabPlanes = (layout.res.z + slabs - 1) / slabs;

    progress.report(kStage, 0.0);
    for (std::int64_t batch = 0; batch < batches; ++batch) {
        const std::int64_t first = batch * kPhotonsPerBatch;
        const std::int64_t count = std::min(kPhotonsPerBatch, photons - first);
        const std::int64_t chunkCount = (count + kPhotonsPerChunk - 1) / kPhotonsPerChunk;
        photonFluxes.assign(std::size_t(count), {});
        fluxIndex.assign(std::size_t(count) * std::size_t(maxSupport), 0);
        fluxValue.assign(std::size_t(count) * std::size_t(maxSupport), 0.f);
        chunks.assign(std::size_t(chunkCount), {});

        arena.execute([&] {
            // Trace the batch's photons, chunk by chunk, keeping their collision events.
            tbb::parallel_for(std::int64_t(0), chunkCount, [&](std::int64_t ci) {
                if (progress.cancelled()) return;
                Chunk& chunk = chunks[std::size_t(ci)];
                const std::int64_t lo = ci * kPhotonsPerChunk;
                const std::int64_t hi = std::min(count, lo + kPhotonsPerChunk);
                for (std::int64_t local = lo; local < hi; ++local) {
                    const std::int64_t id = first + local;
                    core::CounterRng rng(std::uint64_t(id), options.seed);
                    // The boundary cell and the photon's start on it.
                    const std::int64_t cell = id / perCell;
                    std::size_t fi = 0;
                    while (fi + 1 < faces.size() && faces[fi + 1].firstCell <= cell) ++fi;
                    const Face& f = faces[fi];
                    const std::int64_t inFace = cell - f.firstCell;
                    const int ib = int(inFace % f.cellsB), ic = int(inFace / f.cellsB);
                    glm::dvec3 q = f.corner;
                    q[f.b] += (ib + rng.uniformDouble()) * f.edgeB;
                    q[f.c] += (ic + rng.uniformDouble()) * f.edgeC;
                    glm::dvec3 x = geo.indexToWorld(q);
                    // Cosine-distributed inward direction.
                    const double u1 = rng.uniformDouble(), u2 = rng.uniformDouble();
                    const double r = std::sqrt(u1), phi = 2.0 * kPi * u2;
                    glm::dvec3 d = glm::normalize(r * std::cos(phi) * f.tangentB +
                                                  r * std::sin(phi) * f.tangentC +
                                                  std::sqrt(std::max(0.0, 1.0 - u1)) * f.normal);
                    // Its fluxes Φ_k = B_k(−d)·π·ΔA / photons per cell.
                    PhotonFluxes& pf = photonFluxes[std::size_t(local)];
                    pf.first = std::uint32_t(local * maxSupport);
                    int* idx = fluxIndex.data() + pf.first;
                    float* val = fluxValue.data() + pf.first;
                    pf.count = std::uint32_t(basis.evaluate(-d, idx, val));
                    const double scaleFlux = kPi * f.cellArea / double(perCell);
                    bool any = false;
                    for (std::uint32_t j = 0; j < pf.count; ++j) {
                        val[j] = float(val[j] * scaleFlux);
                        any = any || val[j] != 0.f;
                    }
                    if (!any) continue;
                    // The trajectory, shared by all basis lights.
                    glm::dvec3 beta(1.0);
                    for (int scatterings = 0;; ++scatterings) {
                        const pathtrace::Ray ray{x, d};
                        double t0 = 0.0, t1 = INFINITY;
                        if (!medium.keptInterval(ray, t0, t1)) break;
                        // On the way in, matter removed by a section-view plane (shadows from
                        // removed matter on) occludes but never scatters: a collision there
                        // absorbs the photon. (The kept region is convex, so a photon that has
                        // scattered in it never meets that matter again on its way out.)
                        if (scatterings == 0 && sectionView) {
                            double l0 = 0.0, l1 = INFINITY;
                            if (medium.lightInterval(ray, l0, l1) && t0 > l0 &&
                                medium.freeFlight(ray, l0, std::min(t0, l1), rng))
                                break;
                        }
                        const std::optional<double> t = medium.freeFlight(ray, t0, t1, rng);
                        // Track-length estimator: the flight from here to the next collision
                        // (or out of the kept region), if the light has scattered before.
                        if (trackLength && scatterings >= 1) {
                            const double tEnd = t ? *t : t1;
                            if (tEnd > t0 && std::isfinite(tEnd)) {
                                const glm::dvec3 a = geo.worldToIndex(x + t0 * d) * geo.spacing;
                                const glm::dvec3 b = geo.worldToIndex(x + tEnd * d) * geo.spacing;
                                chunk.events.push_back({glm::vec3(a), glm::vec3(b),
                                                        glm::vec3(beta * kInvFourPi),
                                                        std::uint32_t(local), glm::vec3(-d)});
                            }
                        }
                        if (!t) break;
                        ++chunk.collisions;
                        x += *t * d;
                        const optics::TfSample s = medium.mediumAt(x);
                        // Collision estimator of the fluence of light scattered ≥ 1 times.
                        if (!trackLength && scatterings >= 1 && s.extinction > 0.f) {
                            const glm::dvec3 p = geo.worldToIndex(x) * geo.spacing;
                            chunk.events.push_back({glm::vec3(p), glm::vec3(p),
                                                    glm::vec3(beta * (kInvFourPi / s.extinction)),
                                                    std::uint32_t(local), glm::vec3(-d)});
                        }
                        if (scatterings == options.maxScatterings) break;
                        beta *= glm::dvec3(s.albedo);
                        if (!(std::max({beta.x, beta.y, beta.z}) > 0.0)) break;
                        if (scatterings + 1 >= options.rouletteAfter) {
                            const double q =
                                std::clamp(std::max({beta.x, beta.y, beta.z}), kMinSurvival, 1.0);
                            if (rng.uniformDouble() >= q) break;
                            beta /= q;
                        }
                        const float g =
                            phaseChannel
                                ? medium.table().surface(medium.volume().sampleWorld(x)).phaseG
                                : options.phaseG;
                        if (g != 0.f) {
                            // HG about the propagation direction (importance sampling: the
                            // phase over its pdf is 1, so β is unchanged).
                            const float u1 = float(rng.uniformDouble());
                            const float u2 = float(rng.uniformDouble());
                            d = pathtrace::sampleHenyeyGreenstein(d, g, u1, u2);
                            continue;
                        }
                        // Isotropic new direction.
                        const double cz = 1.0 - 2.0 * rng.uniformDouble();
                        const double sz = std::sqrt(std::max(0.0, 1.0 - cz * cz));
                        const double ph = 2.0 * kPi * rng.uniformDouble();
                        d = glm::dvec3(sz * std::cos(ph), sz * std::sin(ph), cz);
                    }
                }
            });
            if (progress.cancelled()) return;

            // Splat: disjoint z-slabs in parallel, each adding the events in photon order.
            tbb::parallel_for(0, slabs, [&](int slab) {
                if (progress.cancelled()) return;
                const int z0 = slab * slabPlanes;
                const int z1 = std::min(layout.res.z - 1, z0 + slabPlanes - 1);
                if (z0 > z1) return;
                // Adds kernel weight kw (× the photon's fluxes) to stored point `slot`.
                // Ŷ_je of the event's arrival direction (je < n; Ŷ_0 = 1, unused when n = 1).
                std::array<float, kMaxExitance> ye{};
                auto arrival = [&](const Event& e) {
                    if (n == 1) return;
                    double y[kMaxExitance];
                    scaledSh(n, glm::normalize(glm::dvec3(e.from)), y);
                    for (int je = 0; je < n; ++je) ye[std::size_t(je)] = float(y[je]);
                };
                const std::size_t block = std::size_t(m) * 3;  // one exitance coefficient's entries
                auto add = [&](const PhotonFluxes& pf, std::int32_t slot, const glm::vec3& kw) {
                    const int* idx = fluxIndex.data() + pf.first;
                    const float* val = fluxValue.data() + pf.first;
                    float* row = transfer.row(slot);
                    for (std::uint32_t j = 0; j < pf.count; ++j) {
                        float* dst = row + std::size_t(idx[j]) * 3;
                        dst[0] += val[j] * kw.x;
                        dst[1] += val[j] * kw.y;
                        dst[2] += val[j] * kw.z;
                    }
                    for (int je = 1; je < n; ++je) {
                        const glm::vec3 kj = kw * ye[std::size_t(je)];
                        for (std::uint32_t j = 0; j < pf.count; ++j) {
                            float* dst = row + std::size_t(je) * block + std::size_t(idx[j]) * 3;
                            dst[0] += val[j] * kj.x;
                            dst[1] += val[j] * kj.y;
                            dst[2] += val[j] * kj.z;
                        }
                    }
                };
                // A flight's weighted fluxes Φ_j·w (RGB), computed once per flight: each point
                // then adds W's line integral times them (contiguous when the basis lights are
                // 0 … m−1, as for SH: a vectorisable loop).
                // Layout [je][j][rgb]: with dense SH fluxes it matches the row's [je][k][rgb].
                std::vector<float> weighted(std::size_t(n) * std::size_t(maxSupport) * 3);
                // A flight a → b: every grid point of the slab within h of the segment gets
                // W integrated along it. The z planes, then per plane the rows and per row the
                // points, are bounded by the part of the segment within h of them (per row
                // exactly: where the row is within h of the flight's line).
                auto splatFlight = [&](const Event& e) {
                    const glm::dvec3 a(e.p), b(e.q);
                    const double len = glm::length(b - a);
                    if (!(len > 0.0)) return;
                    const glm::dvec3 dir = (b - a) / len;
                    const PhotonFluxes& pf = photonFluxes[e.photon];
                    const int* idx = fluxIndex.data() + pf.first;
                    const float* val = fluxValue.data() + pf.first;
                    bool dense = true;
                    for (std::uint32_t j = 0; j < pf.count; ++j) {
                        weighted[3 * j] = val[j] * e.w.x;
                        weighted[3 * j + 1] = val[j] * e.w.y;
                        weighted[3 * j + 2] = val[j] * e.w.z;
                        dense = dense && idx[j] == int(j);
                    }
                    dense = dense && (n == 1 || pf.count == std::uint32_t(m));
                    arrival(e);
                    const std::size_t c3 = std::size_t(pf.count) * 3;
                    for (int je = 1; je < n; ++je)
                        for (std::size_t i = 0; i < c3; ++i)
                            weighted[std::size_t(je) * c3 + i] = weighted[i] * ye[std::size_t(je)];
                    const float* wv = weighted.data();
                    const std::size_t n3 = c3 * std::size_t(n);
                    int zlo, zhi;
                    spanRange(std::min(a.z, b.z), std::max(a.z, b.z), 2, zlo, zhi);
                    zlo = std::max(zlo, z0);
                    zhi = std::min(zhi, z1);
                    for (int gz = zlo; gz <= zhi; ++gz) {
                        const double pz = pointMm[2][std::size_t(gz)];
                        double sz0 = 0.0, sz1 = len;
                        narrowToSlab(a.z, dir.z, pz, h, sz0, sz1);
                        if (sz0 > sz1) continue;
                        const double ya = a.y + sz0 * dir.y, yb = a.y + sz1 * dir.y;
                        int ylo, yhi;
                        spanRange(std::min(ya, yb), std::max(ya, yb), 1, ylo, yhi);
                        for (int gy = ylo; gy <= yhi; ++gy) {
                            const double py = pointMm[1][std::size_t(gy)];
                            double s0 = sz0, s1 = sz1;
                            narrowToSlab(a.y, dir.y, py, h, s0, s1);
                            if (s0 > s1) continue;
                            const double xa = a.x + s0 * dir.x, xb = a.x + s1 * dir.x;
                            double xmin = std::min(xa, xb) - h, xmax = std::max(xa, xb) + h;
                            // Within h of the flight's line: A·X² + B·X + C < 0.
                            const glm::dvec3 q(-a.x, py - a.y, pz - a.z);
                            const double qd = glm::dot(q, dir);
                            const double qa = 1.0 - dir.x * dir.x;
                            const double qb = 2.0 * (q.x - qd * dir.x);
                            const double qc = glm::dot(q, q) - qd * qd - h2;
                            if (qa > 1e-9) {
                                const double disc = qb * qb - 4.0 * qa * qc;
                                if (disc <= 0.0) continue;
                                const double root = std::sqrt(disc);
                                xmin = std::max(xmin, (-qb - root) / (2.0 * qa));
                                xmax = std::min(xmax, (-qb + root) / (2.0 * qa));
                                if (xmin > xmax) continue;
                            }
                            int xlo, xhi;
                            spanRange(xmin, xmax, 0, xlo, xhi, false);
                            for (int gx = xlo; gx <= xhi; ++gx) {
                                const std::int32_t slot = layout.slot[layout.linear({gx, gy, gz})];
                                if (slot < 0) continue;
                                const glm::dvec3 rel =
                                    glm::dvec3(pointMm[0][std::size_t(gx)], py, pz) - a;
                                const double along = glm::dot(rel, dir);
                                const double c2 = h2 - (glm::dot(rel, rel) - along * along);
                                if (!(c2 > 0.0)) continue;
                                const double c = std::sqrt(c2);
                                const double u0 = std::max(-along, -c);
                                const double u1 = std::min(len - along, c);
                                if (!(u1 > u0)) continue;
                                const float k =
                                    float(kernelNorm * (poly6Line(u1, c2) - poly6Line(u0, c2)));
                                float* row = transfer.row(slot);
                                if (dense) {
                                    for (std::size_t i = 0; i < n3; ++i) row[i] += k * wv[i];
                                } else {
                                    for (int je = 0; je < n; ++je) {
                                        const float* wj = wv + std::size_t(je) * c3;
                                        float* rj = row + std::size_t(je) * block;
                                        for (std::uint32_t j = 0; j < pf.count; ++j) {
                                            float* dst = rj + std::size_t(idx[j]) * 3;
                                            dst[0] += k * wj[3 * j];
                                            dst[1] += k * wj[3 * j + 1];
                                            dst[2] += k * wj[3 * j + 2];
                                        }
                                    }
                                }
                            }
                        }
                    }
                };
                for (const Chunk& chunk : chunks)
                    for (const Event& e : chunk.events) {
                        if (trackLength) {
                            splatFlight(e);
                            continue;
                        }
                        int zlo, zhi;
                        pointRange(e.p, 2, zlo, zhi);
                        zlo = std::max(zlo, z0);
                        zhi = std::min(zhi, z1);
                        if (zlo > zhi) continue;
                        int ylo, yhi, xlo, xhi;
                        pointRange(e.p, 1, ylo, yhi);
                        pointRange(e.p, 0, xlo, xhi);
                        const PhotonFluxes& pf = photonFluxes[e.photon];
                        arrival(e);
                        for (int gz = zlo; gz <= zhi; ++gz) {
                            const float dz = pointMm[2][std::size_t(gz)] - e.p.z;
                            for (int gy = ylo; gy <= yhi; ++gy) {
                                const float dy = pointMm[1][std::size_t(gy)] - e.p.y;
                                const float dyz = dy * dy + dz * dz;
                                if (double(dyz) >= h2) continue;
                                for (int gx = xlo; gx <= xhi; ++gx) {
                                    const std::int32_t slot =
                                        layout.slot[layout.linear({gx, gy, gz})];
                                    if (slot < 0) continue;
                                    const float dx = pointMm[0][std::size_t(gx)] - e.p.x;
                                    const double r2 = double(dx * dx + dyz);
                                    if (r2 >= h2) continue;
                                    const double u = h2 - r2;
                                    add(pf, slot, float(kernelNorm * u * u * u) * e.w);
                                }
                            }
                        }
                    }
            });
        });
        progress.checkCancel();
        for (const Chunk& chunk : chunks) {
            stats.collisions += chunk.collisions;
            stats.splats += chunk.events.size();
        }
        stats.photons += std::uint64_t(count);
        progress.report(kStage, double(batch + 1) / double(batches));
    }
    stats.seconds = clock.seconds();
    return stats;
}

}  // namespace voxlight::pvrt
