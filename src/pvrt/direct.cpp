// SPDX-License-Identifier: MIT
#include "pvrt/direct.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <ostream>

#include "core/error.h"
#include "core/half_space.h"
#include "core/timing.h"
#include "sh/dsf.h"

namespace voxlight::pvrt {

namespace {

/// A kept half-space in index space: signed distance (mm) d(ijk) = c + dot(g, ijk), kept ≥ 0.
struct IndexPlane {
    double c = 0;
    glm::dvec3 g{0.0};
    double at(const glm::dvec3& ijk) const { return c + glm::dot(g, ijk); }
};

/// An ordering of the voxels: linear index = Σ_a ijk_a · s[a].
struct Strides {
    std::size_t s[3] = {0, 0, 0};
    static Strides natural(const glm::ivec3& n) {
        return {{1, std::size_t(n.x), std::size_t(n.x) * std::size_t(n.y)}};
    }
    /// x slowest, then z, y fastest: the slices across x are contiguous (sweeps along x).
    static Strides xMajor(const glm::ivec3& n) {
        return {{std::size_t(n.y) * std::size_t(n.z), 1, std::size_t(n.y)}};
    }
    std::size_t at(int i, int j, int k) const {
        return std::size_t(i) * s[0] + std::size_t(j) * s[1] + std::size_t(k) * s[2];
    }
    bool operator==(const Strides& o) const {
        return s[0] == o.s[0] && s[1] == o.s[1] && s[2] == o.s[2];
    }
};

/// Trilinear interpolation of a per-voxel field (ordered by `st`) at continuous index p, clamped
/// to the grid.
template <class T>
double trilinear(const T* f, const glm::ivec3& n, const Strides& st, glm::dvec3 p) {
    const glm::dvec3 hi = glm::dvec3(glm::max(n - 1, glm::ivec3(0)));
    p = glm::clamp(p, glm::dvec3(0.0), hi);
    const glm::ivec3 i = glm::min(glm::ivec3(p), glm::max(n - 2, glm::ivec3(0)));
    const glm::dvec3 t = p - glm::dvec3(i);
    const std::size_t dx = n.x > 1 ? st.s[0] : 0, dy = n.y > 1 ? st.s[1] : 0,
                      dz = n.z > 1 ? st.s[2] : 0;
    const T* q = f + st.at(i.x, i.y, i.z);
    auto lerp = [](double a, double b, double w) { return a + w * (b - a); };
    const double c00 = lerp(q[0], q[dx], t.x), c10 = lerp(q[dy], q[dy + dx], t.x);
    const double c01 = lerp(q[dz], q[dz + dx], t.x), c11 = lerp(q[dz + dy], q[dz + dy + dx], t.x);
    return lerp(lerp(c00, c10, t.y), lerp(c01, c11, t.y), t.z);
}

/// Physical values in one voxel ordering (their σt integrals are looked up where a segment is not
/// transparent: storing them would triple the memory for a few per cent of time).
struct Fields {
    Strides strides;
    std::vector<float> value;

    Fields(const core::Volume& volume, const Strides& st)
        : strides(st), value(std::size_t(volume.voxelCount())) {
        const glm::ivec3 n = volume.dims();
        volume.visit([&](const auto view) {
            tbb::parallel_for(0, n.z, [&](int k) {
                for (int j = 0; j < n.y; ++j)
                    for (int i = 0; i < n.x; ++i) {
                        const std::size_t idx = strides.at(i, j, k);
                        value[idx] = view.at(i, j, k);
                    }
            });
        });
    }
};

/// The per-volume state of the sweep, shared by all directions: the fields in the natural order
/// and, for sweeps whose slices are across x (strided by nx in the natural order: measured 2.5×
/// slower), in x-major order; and the clip half-spaces that remove matter for the light.
class Sweeper {
  public:
    Sweeper(const core::Volume& volume, const optics::TfTable& table, const DirectOptions& o)
        : table_(table),
          geometry_(volume.geometry()),
          natural_(volume, Strides::natural(volume.dims())),
          xMajor_(volume, Strides::xMajor(volume.dims())) {
        // Clip geometry that removes matter for the light, as index-space half-spaces.
        std::vector<core::HalfSpace> removing;
        for (const render::ClipPlane& p : o.clipPlanes)
            if (!p.shadowsFromRemoved) removing.push_back({p.point, glm::normalize(p.normal)});
        if (o.cropBox && !o.cropBox->shadowsFromRemoved)
            for (const core::HalfSpace& h : core::boxHalfSpaces(o.cropBox->min, o.cropBox->max))
                removing.push_back(h);
        for (const core::HalfSpace& h : removing) {
            IndexPlane p;
            p.c = glm::dot(geometry_.origin - h.point, h.normal);
            p.g = geometry_.spacing * (glm::transpose(geometry_.direction) * h.normal);
            planes_.push_back(p);
        }
    }

    std::size_t voxels() const { return natural_.value.size(); }

    /// T∞ toward the unit world direction `w` into T (voxelCount entries), in the ordering it
    /// returns.
    const Strides& sweep(const glm::dvec3& w, std::vector<float>& T) const;

  private:
    struct Frame;
    void slowVoxel(const Frame& f, int c, int u, int v, float* T) const;
    /// The kept part [ta, tb] of the segment's parameter range [ta, tb] (in: the range inside the
    /// box) under the clip half-spaces, for the voxel at index x.
    void keep(const Frame& f, const glm::dvec3& x, double& ta, double& tb) const;
    /// Optical depth of the kept part [ta, tb] of the segment from voxel idx (t = 0) to the point
    /// at t = tEnd whose value is vEnd (value linear in between).
    double keptDepth(const Frame& f, std::size_t idx, double tEnd, double vEnd, double ta,
                     double tb) const;

    const optics::TfTable& table_;
    core::Geometry geometry_;
    Fields natural_, xMajor_;
    std::vector<IndexPlane> planes_;
};

/// One direction's sweep geometry.
struct Sweeper::Frame {
    int a = 0, u = 0, v = 0;         ///< main axis and the transverse axes (u: smaller stride)
    int sa = 1;                      ///< upstream slice = current + sa
    double step = 0;                 ///< mm from a slice to the next along ω
    glm::dvec3 delta{0.0};           ///< index offset of the upstream point (delta[a] = sa)
    glm::ivec3 n{0};                 ///< dims
    const Fields* fields = nullptr;  ///< the ordering swept in
    std::size_t stride[3] = {0, 0, 0};
    int ou = 0, ov = 0;    ///< lower taps of the stencil (−1 or 0)
    float fu = 0, fv = 0;  ///< bilinear fractions
    float w00 = 0, w10 = 0, w01 = 0, w11 = 0;
    float cu[4] = {}, cv[4] = {};    ///< Catmull–Rom weights of taps o−1 … o+2
    std::vector<double> planeDelta;  ///< per plane: d(upstream) − d(voxel), mm
};

void Sweeper::slowVoxel(const Frame& f, int c, int u, int v, float* T) const {
    glm::dvec3 x;
    x[f.a] = c, x[f.u] = u, x[f.v] = v;
    const std::size_t idx = std::size_t(c) * f.stride[f.a] + std::size_t(u) * f.stride[f.u] +
                            std::size_t(v) * f.stride[f.v];
    // Where the segment leaves the box sideways (t ∈ [0, 1] from the voxel to the upstream point).
    double tEnd = 1.0;
    for (int b : {f.u, f.v}) {
        const double hi = double(f.n[b] - 1), p = x[b], d = f.delta[b];
        if (d > 0) tEnd = std::min(tEnd, (hi - p) / d);
        if (d < 0) tEnd = std::min(tEnd, -p / d);
    }
    tEnd = std::max(tEnd, 0.0);
    float tUp = 1.f;
    double vEnd;
    if (tEnd >= 1.0) {
        // Upstream point inside: bilinear in the previous slice (taps clamped).
        const std::size_t prev = std::size_t(c + f.sa) * f.stride[f.a];
        auto tap = [&](const auto* field, int du, int dv) {
            const int uu = std::clamp(u + f.ou + du, 0, f.n[f.u] - 1);
            const int vv = std::clamp(v + f.ov + dv, 0, f.n[f.v] - 1);
            return double(
                field[prev + std::size_t(uu) * f.stride[f.u] + std::size_t(vv) * f.stride[f.v]]);
        };
        auto bilinear = [&](const auto* field) {
            return double(f.w00) * tap(field, 0, 0) + double(f.w10) * tap(field, 1, 0) +
                   double(f.w01) * tap(field, 0, 1) + double(f.w11) * tap(field, 1, 1);
        };
        tUp = float(bilinear(T));
        vEnd = bilinear(f.fields->value.data());
    } else {
        vEnd = trilinear(f.fields->value.data(), f.n, f.fields->strides, x + tEnd * f.delta);
    }
    double ta = 0.0, tb = tEnd;
    keep(f, x, ta, tb);
    T[idx] = tUp * std::exp(-float(keptDepth(f, idx, tEnd, vEnd, ta, tb)));
}

void Sweeper::keep(const Frame& f, const glm::dvec3& x, double& ta, double& tb) const {
    for (std::size_t i = 0; i < planes_.size(); ++i) {
        const double d0 = planes_[i].at(x), dd = f.planeDelta[i];
        if (dd == 0.0) {
            if (d0 < 0.0) tb = ta;
        } else if (dd > 0.0) {
            ta = std::max(ta, -d0 / dd);
        } else {
            tb = std::min(tb, -d0 / dd);
        }
    }
}

double Sweeper::keptDepth(const Frame& f, std::size_t idx, double tEnd, double vEnd, double ta,
                          double tb) const {
    if (!(tb > ta)) return 0.0;
    const double vx = f.fields->value[idx];
    auto valueAt = [&](double t) { return float(tEnd > 0 ? vx + (t / tEnd) * (vEnd - vx) : vx); };
    const float va = valueAt(ta), vb = valueAt(tb);
    if (table_.transparentSegment(va, vb)) return 0.0;
    const double ia = table_.sigmaIntegral(va);
    return f.step * (tb - ta) * table_.meanExtinction(va, ia, vb, table_.sigmaIntegral(vb));
}

const Strides& Sweeper::sweep(const glm::dvec3& w, std::vector<float>& T) const {
    T.assign(voxels(), 1.f);
    Frame f;
    f.n = geometry_.dims;
    // Index-space direction (index units per mm) and the main axis.
    const glm::dvec3 d = (glm::transpose(geometry_.direction) * w) / geometry_.spacing;
    f.a = 0;
    for (int b = 1; b < 3; ++b)
        if (std::abs(d[b]) > std::abs(d[f.a])) f.a = b;
    VL_CHECK(std::abs(d[f.a]) > 0.0);
    f.u = f.a == 0 ? 1 : 0;
    f.v = f.a == 2 ? 1 : 2;
    f.sa = d[f.a] > 0 ? 1 : -1;
    f.fields = f.a == 0 ? &xMajor_ : &natural_;
    for (int b = 0; b < 3; ++b) f.stride[b] = f.fields->strides.s[b];
    f.step = 1.0 / std::abs(d[f.a]);
    f.delta = d * f.step;
    f.delta[f.a] = f.sa;
    auto lowerTap = [](double delta, int& o, float& frac) {
        o = std::min(int(std::floor(delta)), 0);
        frac = float(delta - o);
    };
    lowerTap(f.delta[f.u], f.ou, f.fu);
    lowerTap(f.delta[f.v], f.ov, f.fv);
    f.w00 = (1.f - f.fu) * (1.f - f.fv);
    f.w10 = f.fu * (1.f - f.fv);
    f.w01 = (1.f - f.fu) * f.fv;
    f.w11 = f.fu * f.fv;
    auto catmullRom = [](float x, float* w) {
        const float x2 = x * x, x3 = x2 * x;
        w[0] = 0.5f * (-x3 + 2.f * x2 - x);
        w[1] = 0.5f * (3.f * x3 - 5.f * x2 + 2.f);
        w[2] = 0.5f * (-3.f * x3 + 4.f * x2 + x);
        w[3] = 0.5f * (x3 - x2);
    };
    catmullRom(f.fu, f.cu);
    catmullRom(f.fv, f.cv);
    for (const IndexPlane& p : planes_) f.planeDelta.push_back(glm::dot(p.g, f.delta));

    const int na = f.n[f.a], nu = f.n[f.u], nv = f.n[f.v];
    // Voxels whose 4 taps are in the grid (so their upstream point is inside the box) take the
    // fixed stencil, bicubic where its 4×4 taps are in the grid too; the ring next to the box's
    // sides the general path.
    const bool anyPlanes = !planes_.empty();
    const int uLo = -f.ou, uHi = nu - 2 - f.ou;  // fast u range (inclusive)
    const int cuLo = uLo + 1, cuHi = uHi - 1;    // range with all 4×4 cubic taps
    const double stepF = f.step;
    // Both orderings make u the contiguous axis (natural: x for sweeps along y or z; x-major: y).
    VL_CHECK(f.stride[f.u] == 1);
    constexpr std::ptrdiff_t su = 1;
    const std::ptrdiff_t sv = std::ptrdiff_t(f.stride[f.v]);
    float* t = T.data();
    const float* val = f.fields->value.data();
    const int first = f.sa > 0 ? na - 1 : 0;
    for (int s = 1; s < na; ++s) {
        const int c = first - f.sa * s;
        const std::ptrdiff_t up = std::ptrdiff_t(f.sa) * std::ptrdiff_t(f.stride[f.a]);
        tbb::parallel_for(tbb::blocked_range<int>(0, nv), [&](const tbb::blocked_range<int>& r) {
            for (int v = r.begin(); v < r.end(); ++v) {
                const bool rowFast = v + f.ov >= 0 && v + f.ov + 1 <= nv - 1;
                const bool rowCubic = rowFast && v + f.ov - 1 >= 0 && v + f.ov + 2 <= nv - 1;
                const int lo = rowFast ? std::max(uLo, 0) : nu,
                          hi = rowFast ? std::min(uHi, nu - 1) : -1;
                const int clo = rowCubic ? std::max(cuLo, 0) : nu,
                          chi = rowCubic ? std::min(cuHi, nu - 1) : -1;
                for (int u = 0; u < nu; ++u) {
                    if (u < lo || u > hi) {
                        slowVoxel(f, c, u, v, t);
                        continue;
                    }
                    const std::ptrdiff_t idx = std::ptrdiff_t(c) * std::ptrdiff_t(f.stride[f.a]) +
                                               std::ptrdiff_t(u) * su + std::ptrdiff_t(v) * sv;
                    const std::ptrdiff_t q = idx + up + f.ou * su + f.ov * sv;
                    const float t00 = t[q], t10 = t[q + su], t01 = t[q + sv], t11 = t[q + su + sv];
                    const float tMin = std::min(std::min(t00, t10), std::min(t01, t11));
                    const float tMax = std::max(std::max(t00, t10), std::max(t01, t11));
                    float tUp;
                    if (tMin == tMax) {
                        tUp = tMin;  // what the clamped cubic would give (most of empty space)
                    } else if (u >= clo && u <= chi) {
                        // Catmull–Rom, clamped to the 4 nearest taps (no new extrema).
                        const float* r = t + q - su - sv;
                        float sum = 0.f;
                        for (int y = 0; y < 4; ++y, r += sv)
                            sum += f.cv[y] * (f.cu[0] * r[0] + f.cu[1] * r[su] +
                                              f.cu[2] * r[2 * su] + f.cu[3] * r[3 * su]);
                        tUp = std::clamp(sum, tMin, tMax);
                    } else {
                        tUp = f.w00 * t00 + f.w10 * t10 + f.w01 * t01 + f.w11 * t11;
                    }
                    const float vUp = f.w00 * val[q] + f.w10 * val[q + su] + f.w01 * val[q + sv] +
                                      f.w11 * val[q + su + sv];
                    const float vx = val[idx];
                    if (anyPlanes) {
                        // A segment that crosses a clip plane attenuates over its kept part only.
                        glm::dvec3 x;
                        x[f.a] = c, x[f.u] = u, x[f.v] = v;
                        double ta = 0.0, tb = 1.0;
                        keep(f, x, ta, tb);
                        if (ta > 0.0 || tb < 1.0) {
                            t[idx] =
                                tUp *
                                std::exp(-float(keptDepth(f, std::size_t(idx), 1.0, vUp, ta, tb)));
                            continue;
                        }
                    }
                    if (table_.transparentSegment(vx, vUp)) {
                        t[idx] = tUp;
                        continue;
                    }
                    const float mean = table_.meanExtinction(vx, table_.sigmaIntegral(vx), vUp,
                                                             table_.sigmaIntegral(vUp));
                    t[idx] = tUp * std::exp(-float(stepF * mean));
                }
            }
        });
    }
    return f.fields->strides;
}

/// Trilinear stencil of a point in the voxel grid in one ordering: base index and fractions
/// (offsets: the strides, or 0 along an axis of one voxel).
struct Stencil {
    std::uint64_t base = 0;
    float fx = 0, fy = 0, fz = 0;
};

Stencil stencilAt(const glm::ivec3& n, const Strides& st, glm::vec3 p) {
    p = glm::clamp(p, glm::vec3(0.f), glm::vec3(glm::max(n - 1, glm::ivec3(0))));
    const glm::ivec3 i = glm::min(glm::ivec3(p), glm::max(n - 2, glm::ivec3(0)));
    Stencil s;
    s.base = st.at(i.x, i.y, i.z);
    s.fx = p.x - float(i.x), s.fy = p.y - float(i.y), s.fz = p.z - float(i.z);
    return s;
}

/// Trilinear reads of one ordering at the stored points.
struct PointSampler {
    std::vector<Stencil> stencils;
    std::size_t dx = 0, dy = 0, dz = 0;
    PointSampler(const glm::ivec3& n, const Strides& st, const TransferLayout& layout,
                 const std::vector<glm::ivec3>& points)
        : stencils(points.size()),
          dx(n.x > 1 ? st.s[0] : 0),
          dy(n.y > 1 ? st.s[1] : 0),
          dz(n.z > 1 ? st.s[2] : 0) {
        for (std::size_t p = 0; p < points.size(); ++p)
            stencils[p] = stencilAt(n, st, layout.position(points[p]));
    }
    float operator()(const float* f, std::size_t p) const {
        const Stencil& s = stencils[p];
        const float* q = f + s.base;
        const float c00 = q[0] + s.fx * (q[dx] - q[0]);
        const float c10 = q[dy] + s.fx * (q[dy + dx] - q[dy]);
        const float c01 = q[dz] + s.fx * (q[dz + dx] - q[dz]);
        const float c11 = q[dz + dy] + s.fx * (q[dz + dy + dx] - q[dz + dy]);
        const float c0 = c00 + s.fy * (c10 - c00), c1 = c01 + s.fy * (c11 - c01);
        return c0 + s.fz * (c1 - c0);
    }
};

glm::dvec3 unitTowardLight(const glm::dvec3& w) {
    const double len = glm::length(w);
    if (!(len > 0.0) || !std::isfinite(len))
        throw InternalError(
            "pvrt direct: the direction toward the light must be non-zero and finite");
    return w / len;
}

}  // namespace

std::ostream& operator<<(std::ostream& os, const DirectStats& s) {
    return os << "DirectStats{directions " << s.directions << ", voxel updates " << s.voxelUpdates
              << ", " << s.seconds << " s}";
}

float sampleVoxelField(const std::vector<float>& field, const glm::ivec3& dims,
                       const glm::vec3& p) {
    VL_CHECK(field.size() == std::size_t(dims.x) * std::size_t(dims.y) * std::size_t(dims.z));
    return float(trilinear(field.data(), dims, Strides::natural(dims), glm::dvec3(p)));
}

std::vector<float> sweepTransmittance(const core::Volume& volume, const optics::TfTable& table,
                                      const glm::dvec3& towardLight, const DirectOptions& options) {
    const glm::dvec3 w = unitTowardLight(towardLight);
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
    std::vector<float> T;
    arena.execute([&] {
        const Sweeper sweeper(volume, table, options);
        std::vector<float> swept;
        const Strides& st = sweeper.sweep(w, swept);
        const Strides natural = Strides::natural(volume.dims());
        if (st == natural) {
            T = std::move(swept);
            return;
        }
        // Back to the natural order.
        const glm::ivec3 n = volume.dims();
        T.resize(swept.size());
        tbb::parallel_for(0, n.z, [&](int k) {
            for (int j = 0; j < n.y; ++j)
                for (int i = 0; i < n.x; ++i) T[natural.at(i, j, k)] = swept[st.at(i, j, k)];
        });
    });
    return T;
}

DirectStats addDirectTransfer(const core::Volume& volume, const optics::TfTable& table,
                              const Basis& basis, Transfer& transfer, const DirectOptions& options,
                              const core::Progress& progress) {
    const core::Stopwatch clock;
    const TransferLayout& layout = transfer.layout;
    const glm::ivec3 dims = volume.dims();
    VL_CHECK(transfer.basis == basis.size());
    VL_CHECK(layout.slot.size() == std::size_t(layout.res.x) * layout.res.y * layout.res.z);
    VL_CHECK(layout.scale == glm::vec3(dims) / glm::vec3(layout.res));
    VL_CHECK(transfer.values.size() == std::size_t(layout.points) * transfer.rowSize());
    if (options.directions != 42 && options.directions != 162 && options.directions != 642)
        throw InputError("pvrt", "directions",
                         "the direct part's quadrature has no set of " +
                             std::to_string(options.directions) + " directions",
                         "use 42, 162 or 642 directions");

    DirectStats stats;
    if (layout.points == 0) return stats;

    // Quadrature directions and weights; the basis's own DSF when it is the same set, so that
    // direction j feeds basis light j alone.
    const bool sameDsf = basis.kind() == BasisKind::Dsf && basis.size() == options.directions;
    std::shared_ptr<const sh::Dsf> own;
    if (!sameDsf) own = std::make_shared<const sh::Dsf>(options.directions);
    const sh::Dsf& quad = sameDsf ? *basis.dsf() : *own;
    const int J = quad.size();
    const int m = basis.size();
    const int n = transfer.exitance;
    const int cols = n * m;  // row entries per channel
    VL_CHECK(validExitance(n));
    std::vector<double> yw(static_cast<std::size_t>(n));

    // Trilinear reads of the stored points in both voxel orderings the sweep uses.
    const std::vector<glm::ivec3> points = layout.storedPoints();
    const std::size_t P = points.size();
    const PointSampler naturalPoints(dims, Strides::natural(dims), layout, points);
    const PointSampler xMajorPoints(dims, Strides::xMajor(dims), layout, points);

    stats.directions = J;
    const int batch = std::min(kDirectionBatch, J);
    std::vector<float> Tvol, Tpts(std::size_t(batch) * P);
    struct Entry {
        int k;
        float c;
    };
    std::vector<std::vector<Entry>> entries(static_cast<std::size_t>(batch));
    std::vector<float> coefficients(std::size_t(batch) * std::size_t(cols));
    std::vector<int> idx(std::size_t(basis.maxSupport()));
    std::vector<float> val(std::size_t(basis.maxSupport()));
    const double inv4Pi = 1.0 / (4.0 * std::numbers::pi);

    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
    arena.execute([&] {
        const Sweeper sweeper(volume, table, options);
        for (int j0 = 0; j0 < J; j0 += batch) {
            const int nb = std::min(batch, J - j0);
            for (int b = 0; b < nb; ++b) {
                const int j = j0 + b;
                progress.report("pvrt direct", double(j) / double(J));
                const glm::dvec3 w = quad.directions()[std::size_t(j)];
                // Basis lights seen from ω_j, with the quadrature weight and the phase.
                const double scale = quad.basisSolidAngles()[std::size_t(j)] * inv4Pi;
                // Columns je·m + k: exitance coefficient je of basis light k (transfer.h), weighted
                // by Ŷ_je(ω_j) (exactly 1 for je = 0, so n = 1 is the isotropic sum bit for bit).
                auto& e = entries[std::size_t(b)];
                e.clear();
                scaledSh(n, w, yw.data());
                for (int je = 0; je < n; ++je) {
                    const double sy = scale * yw[std::size_t(je)];
                    if (sameDsf) {
                        e.push_back({je * m + j, float(sy)});
                    } else {
                        const int count = basis.evaluate(w, idx.data(), val.data());
                        for (int i = 0; i < count; ++i)
                            if (val[std::size_t(i)] != 0.f)
                                e.push_back({je * m + idx[std::size_t(i)],
                                             float(sy * val[std::size_t(i)])});
                    }
                }
                // T∞ of this direction at every voxel, then at the stored points.
                const PointSampler& at =
                    sweeper.sweep(w, Tvol) == Strides::natural(dims) ? naturalPoints : xMajorPoints;
                stats.voxelUpdates += sweeper.voxels();
                float* out = Tpts.data() + std::size_t(b) * P;
                tbb::parallel_for(tbb::blocked_range<std::size_t>(0, P),
                                  [&](const tbb::blocked_range<std::size_t>& r) {
                                      for (std::size_t p = r.begin(); p < r.end(); ++p)
                                          out[p] = at(Tvol.data(), p);
                                  });
            }
            // Add the batch into the rows, directions in order: SH through the dense nb × m
            // coefficient matrix (contiguous in k), DSF through its few entries per direction.
            const bool dense = basis.kind() == BasisKind::Sh;
            if (dense) {
                std::fill(coefficients.begin(), coefficients.end(), 0.f);
                for (int b = 0; b < nb; ++b)
                    for (const Entry& e : entries[std::size_t(b)])
                        coefficients[std::size_t(b) * std::size_t(cols) + std::size_t(e.k)] = e.c;
            }
            auto addRows = [&](const tbb::blocked_range<std::size_t>& r) {
                std::vector<double> acc(static_cast<std::size_t>(cols));
                for (std::size_t p = r.begin(); p < r.end(); ++p) {
                    float* row = transfer.row(std::int32_t(p));
                    if (!dense) {
                        for (int b = 0; b < nb; ++b) {
                            const float t = Tpts[std::size_t(b) * P + p];
                            for (const Entry& e : entries[std::size_t(b)])
                                for (int c = 0; c < 3; ++c) row[e.k * 3 + c] += t * e.c;
                        }
                        continue;
                    }
                    std::fill(acc.begin(), acc.end(), 0.0);
                    for (int b = 0; b < nb; ++b) {
                        const double t = Tpts[std::size_t(b) * P + p];
                        const float* cb = coefficients.data() + std::size_t(b) * std::size_t(cols);
                        for (int k = 0; k < cols; ++k) acc[std::size_t(k)] += t * double(cb[k]);
                    }
                    for (int k = 0; k < cols; ++k)
                        for (int c = 0; c < 3; ++c) row[k * 3 + c] += float(acc[std::size_t(k)]);
                }
            };
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, P), addRows);
        }
    });
    progress.report("pvrt direct", 1.0);
    stats.seconds = clock.seconds();
    return stats;
}

}  // namespace voxlight::pvrt
