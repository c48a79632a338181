// SPDX-License-Identifier: MIT
// PVRT direct transfer: the slice-swept transmittance against closed forms (slab, sphere) and a
// fine brute-force march (torso), and the transfer it produces against the quadrature it stands
// for (empty volume, a directional light, thread count, huge σt, clip geometry).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <numbers>

#include "core/error.h"
#include "core/phantoms.h"
#include "lights/light.h"
#include "optics/presets.h"
#include "pathtrace/pathtrace_test_util.h"
#include "pvrt/basis.h"
#include "pvrt/direct.h"
#include "pvrt/transfer.h"
#include "sh/sh_basis.h"

using namespace voxlight;

namespace {

constexpr double kInv4Pi = 1.0 / (4.0 * std::numbers::pi);

/// Along an axis the sweep meets no transverse interpolation and the pre-integrated step TF puts
/// the slab faces exactly at the 0.5-level set: only float rounding of τ and exp (and the
/// stepTf's 0.002-wide ramp) remain.
constexpr double kAxisTol = 1e-3;

/// Length (mm) of the part of the ray x + sω, s ≥ 0, inside the box of voxel centres that lies in
/// the open interval zMin < z < zMax.
double slabPath(const core::Geometry& g, const glm::dvec3& x, const glm::dvec3& w, double zMin,
                double zMax) {
    const auto box = g.worldBounds();
    double sBox = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
        if (w[a] > 0) sBox = std::min(sBox, (box[1][a] - x[a]) / w[a]);
        if (w[a] < 0) sBox = std::min(sBox, (box[0][a] - x[a]) / w[a]);
    }
    double s0 = 0, s1 = sBox;
    if (w.z == 0) {
        if (!(x.z > zMin && x.z < zMax)) return 0;
    } else {
        const double a = (zMin - x.z) / w.z, b = (zMax - x.z) / w.z;
        s0 = std::max(s0, std::min(a, b));
        s1 = std::min(s1, std::max(a, b));
    }
    return std::max(0.0, s1 - s0);
}

/// Fine brute-force T∞: midpoint rule with steps of `step` mm on the trilinear value, σt from the
/// TF table, to the box of voxel centres.
double marchTransmittance(const core::Volume& v, const optics::TfTable& table, const glm::dvec3& x,
                          const glm::dvec3& w, double step) {
    const auto box = v.geometry().worldBounds();
    double sBox = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
        if (w[a] > 0) sBox = std::min(sBox, (box[1][a] - x[a]) / w[a]);
        if (w[a] < 0) sBox = std::min(sBox, (box[0][a] - x[a]) / w[a]);
    }
    const int n = int(std::ceil(sBox / step));
    const double h = sBox / std::max(n, 1);
    double tau = 0;
    for (int i = 0; i < n; ++i)
        tau += h * table.extinction(v.sampleWorld(x + (i + 0.5) * h * w));
    return std::exp(-tau);
}

/// A layout with every grid point of `res` per axis stored (or only those `keep` accepts).
template <class Keep>
pvrt::TransferLayout layoutWhere(const glm::ivec3& dims, const glm::ivec3& res, Keep keep) {
    pvrt::TransferLayout l;
    l.res = res;
    l.scale = glm::vec3(dims) / glm::vec3(res);
    l.slot.assign(std::size_t(res.x) * res.y * res.z, -1);
    for (int z = 0; z < res.z; ++z)
        for (int y = 0; y < res.y; ++y)
            for (int x = 0; x < res.x; ++x)
                if (keep(glm::ivec3(x, y, z))) l.slot[l.linear({x, y, z})] = l.points++;
    return l;
}
pvrt::TransferLayout fullLayout(const glm::ivec3& dims, const glm::ivec3& res) {
    return layoutWhere(dims, res, [](const glm::ivec3&) { return true; });
}

pvrt::DirectOptions threads(int n) {
    pvrt::DirectOptions o;
    o.threads = n;
    return o;
}

// --- sweepTransmittance ---------------------------------------------------------------------

TEST(PvrtSweep, SlabAlongTheAxesIsExact) {
    const core::Volume v = core::makePhantom("slab", {.size = 32});
    const auto f = core::slabPhantomFacts(v.geometry());
    const double sigma = 2.0 / (f.zMax - f.zMin);
    const optics::TfTable table(test::stepTf(float(sigma), glm::vec3(1.f)));
    for (const glm::dvec3 w : {glm::dvec3(0, 0, 1), glm::dvec3(0, 0, -1), glm::dvec3(1, 0, 0)}) {
        const std::vector<float> T = pvrt::sweepTransmittance(v, table, w, threads(2));
        double worst = 0;
        const glm::ivec3 n = v.dims();
        for (int k = 0; k < n.z; ++k)
            for (int j = 0; j < n.y; ++j)
                for (int i = 0; i < n.x; ++i) {
                    const glm::dvec3 x = v.geometry().indexToWorld(glm::dvec3(i, j, k));
                    const double want = std::exp(-sigma * slabPath(v.geometry(), x, w, f.zMin, f.zMax));
                    worst = std::max(worst, std::abs(T[v.linearIndex(i, j, k)] - want));
                }
        EXPECT_LT(worst, kAxisTol) << "toward " << w.x << "," << w.y << "," << w.z;
    }
}

}  // namespace
