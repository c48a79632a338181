// SPDX-License-Identifier: MIT
// Hard cases of isovalues, clip planes, memory budgets and long accumulations (issue #17 item 4):
// isovalues exactly at voxel values and at the data's min and max; clip planes exactly on voxel
// planes, on the volume's faces, and pairs whose kept regions do not meet; a volume over each
// method's memory budget; 10⁶ samples in the path tracer's accumulator. Each must give a valid
// result (finite, non-negative, compared with a cheap reference where there is one) or a clear
// InputError naming the field — never a crash, NaN or bad_alloc.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "core/progress.h"
#include "iso/cleanup.h"
#include "iso/extract.h"
#include "optics/transfer_function.h"
#include "pathtrace/pathtrace_test_util.h"
#include "stability/hard_cases_util.h"
#include "support/test_support.h"

using namespace voxlight;
using namespace voxlight::test;
using nlohmann::json;

namespace {

// A plane on one of the volume's faces keeps all of it: the image may differ from the unclipped
// one only by the rounding of where the rays enter (relative to the image's largest value).
constexpr double kBoxFacePlaneRelTol = 1e-4;
// A mesh vertex lies inside the volume's box up to float rounding of interpolated positions (mm).
constexpr double kMeshBoxTol = 1e-4;
// Unit normals: float/double rounding of a normalisation.
constexpr double kUnitNormalTol = 1e-6;
// Mean of 10⁶ equal doubles summed in double: each addition rounds by ≤ ½ ulp of a sum ≤ 10⁶ c,
// so the mean is off by ≤ 10⁶ · 2⁻⁵³ ≈ 1.1e-10 of c; the float output rounds it to 6e-8.
constexpr double kMillionMeanRelTol = 1e-7;
// A Bernoulli stream of 2²⁰ samples: the mean lies within this many standard errors of its closed
// form (a false failure once in ~10⁶ seeds; the seed is fixed, so the test is deterministic).
constexpr double kBernoulliSigmas = 5.0;
// The accumulated standard error against √(p(1−p)/n)·e: the sample variance of 2²⁰ Bernoulli
// draws is off by ~√(2/n) ≈ 0.14 % (1σ); 1 % is 7σ.
constexpr double kBernoulliStdErrorRelTol = 0.01;
// Standard error of a constant stream is 0; Σv²/n − mean² cancels to ~1e-10 c², so √(var/n)
// stays below 1e-8 c.
constexpr double kMillionStdErrorRelTol = 1e-8;

// An octahedral cone of integer values 0..600 around voxel (4, 4, 4) of a 9³ volume, with a
// plateau: values above 300 are cut to 300 except the centre's 600 (a one-voxel maximum).
float cone(int i, int j, int k) {
    const int d = std::abs(i - 4) + std::abs(j - 4) + std::abs(k - 4);
    if (d == 0) return 600.f;
    return float(std::min(300, 100 * std::max(0, 6 - d)));
}
const HardVolume kCone{"cone", {9, 9, 9}, {1, 1, 1}, cone};

json plane(double x, double nx, bool shadowsFromRemoved) {
    return {
        {"point", {x, 0, 0}}, {"normal", {nx, 0, 0}}, {"shadows_from_removed", shadowsFromRemoved}};
}

core::Volume inMemory(const HardVolume& h, core::VoxelType type) {
    core::Geometry g;
    g.dims = h.dims;
    g.spacing = h.spacing;
    core::Volume v(g, type);
    for (int k = 0; k < h.dims.z; ++k)
        for (int j = 0; j < h.dims.y; ++j)
            for (int i = 0; i < h.dims.x; ++i) {
                const float x = h.value(i, j, k);
                if (type == core::VoxelType::Float32)
                    v.dataAs<float>()[v.linearIndex(i, j, k)] = x;
                else
                    v.dataAs<std::int16_t>()[v.linearIndex(i, j, k)] = std::int16_t(x);
            }
    return v;
}

/// Finite vertices inside the box, finite normals, unit except at a vertex whose faces all have
/// zero area: an isovalue a rounding away from a one-voxel extremum collapses the surface onto the
/// voxel (every vertex on one point), where neither the gradient (0 at the extremum) nor the faces
/// give a direction; extract leaves such a normal 0 (iso/extract.cpp applyNormals).
void expectValidMesh(const iso::Mesh& mesh, const glm::dvec3& boxMax, const std::string& what) {
    auto collapsed = [&](iso::Mesh::VertexHandle vh) {
        for (const auto fh : mesh.vf_range(vh))
            if (mesh.calc_face_area(fh) > 0.0) return false;
        return true;
    };
    for (const auto vh : mesh.vertices()) {
        const auto p = mesh.point(vh);
        const auto n = mesh.normal(vh);
        for (int a = 0; a < 3; ++a) {
            ASSERT_TRUE(std::isfinite(p[a])) << what << ": vertex " << vh.idx();
            ASSERT_GE(p[a], -kMeshBoxTol) << what;
            ASSERT_LE(p[a], boxMax[a] + kMeshBoxTol) << what;
            ASSERT_TRUE(std::isfinite(n[a])) << what << ": normal of vertex " << vh.idx();
        }
        if (n.norm() == 0.0 && collapsed(vh)) continue;
        ASSERT_NEAR(n.norm(), 1.0, kUnitNormalTol) << what << ": normal of vertex " << vh.idx();
    }
}

}  // namespace

TEST(HardCases, IsovaluesAtVoxelValuesAndTheDataExtremes) {
    // Direct extraction (iso::extractIsosurface), float and integer storage. Strictly inside the
    // range: a valid mesh (isovalues 100 and 300 sit exactly on many voxels, 300 on a whole
    // plateau). At the min (0) and the max (600, one voxel): an InputError naming "isovalue", or a
    // valid mesh.
    const double lo = 0.0, hi = 600.0;
    const std::vector<double> isovalues = {lo,    std::nextafter(lo, hi), 100.0, 300.0,
                                           500.0, std::nextafter(hi, lo), hi};
    for (const core::VoxelType type : {core::VoxelType::Float32, core::VoxelType::Int16}) {
        const core::Volume v = inMemory(kCone, type);
        const glm::dvec3 boxMax = glm::dvec3(kCone.dims - 1) * kCone.spacing;
        for (const double iso : isovalues) {
            const std::string what =
                std::string(type == core::VoxelType::Float32 ? "float" : "int16") + " isovalue " +
                std::to_string(iso);
            // Integer data snap an isovalue within rounding of an integer to it (iso/extract.h):
            // one that snaps to the min is the min.
            const bool inside =
                iso > lo && iso < hi && !(type == core::VoxelType::Int16 && std::round(iso) == lo);
            try {
                iso::ExtractOptions eo;
                eo.isovalue = iso;
                const iso::Extraction ex = iso::extractIsosurface(v, eo);
                expectValidMesh(ex.mesh, boxMax, what);
                if (inside) {
                    EXPECT_GT(ex.mesh.n_faces(), 0u) << what;
                }
                const iso::MeshReport r = iso::reportMesh(ex.mesh, false);
                EXPECT_TRUE(std::isfinite(r.areaMm2)) << what;
                std::printf("%s: %zu faces, %zu rejected, closed %d\n", what.c_str(),
                            std::size_t(ex.mesh.n_faces()), ex.stats.rejectedFaces, int(r.closed));
            } catch (const InputError& e) {
                EXPECT_FALSE(inside) << what << ": " << e.what();
                EXPECT_EQ(e.field(), "isovalue") << what;
            }
        }
    }
    // Through the iso methods of the renderer: an image or a clear refusal naming iso_value.
    const TempDir tmp;
    const auto path = writeHard(kCone, tmp.path());
    for (const std::string method : {"iso", "iso-lattice"})
        for (const double iso : isovalues) {
            json m = methodOf(method);
            m["params"]["iso_value"] = iso;
            const std::string what = method + " iso_value " + std::to_string(iso);
            try {
                const auto r = pipeline::renderScene(io::parseScene(hardScene(path, m), "h", "."));
                expectSane(r.image, what);
            } catch (const InputError& e) {
                std::printf("refused: %s: %s\n", what.c_str(), e.what());
                EXPECT_NE(std::string(e.what()).find("iso_value"), std::string::npos)
                    << what << ": " << e.what();
            }
        }
}

TEST(HardCases, ClipPlanesOnVoxelPlanesAndWithAnEmptyIntersection) {
    const TempDir tmp;
    const auto path = writeHard(kBall, tmp.path());
    const double last = kBall.dims.x - 1;  // x of the last voxel plane (the box's far face), mm
    for (const std::string& method : allMethods()) {
        json d = hardScene(path, methodOf(method));
        const auto base = renderOrRefuse(d, method + " unclipped");
        if (!base) continue;
        expectSane(base->image, method);
        float peak = 0.f;
        for (float v : base->image.pixels) peak = std::max(peak, v);
        // Planes on the box's faces (x = 0 facing +x, x = last facing −x) keep everything: the
        // unclipped image is the reference.
        for (bool shadows : {false, true}) {
            for (const bool crop : {false, true}) {
                json c = d;
                if (crop)  // the crop box exactly the volume's box
                    c["crop_box"] = {{"min", {0, 0, 0}},
                                     {"max", {last, last, last}},
                                     {"shadows_from_removed", shadows}};
                else
                    c["clip_planes"] =
                        json::array({plane(0.0, 1.0, shadows), plane(last, -1.0, shadows)});
                const std::string what = method + (crop ? " crop box" : " planes") +
                                         " on the box faces, shadows_from_removed " +
                                         std::to_string(shadows);
                const auto r = renderOrRefuse(c, what);
                ASSERT_TRUE(r) << what;
                expectSane(r->image, what);
                for (std::size_t i = 0; i < r->image.pixels.size(); ++i)
                    ASSERT_NEAR(r->image.pixels[i], base->image.pixels[i],
                                kBoxFacePlaneRelTol * peak)
                        << what << " at " << i;
            }
        }
        // Planes exactly on an interior voxel plane (x = 4, through the ball's centre and its
        // samples), each way, and both at once (the kept region is that plane alone).
        for (bool shadows : {false, true}) {
            for (const json& planes :
                 {json::array({plane(4.0, 1.0, shadows)}), json::array({plane(4.0, -1.0, shadows)}),
                  json::array({plane(4.0, 1.0, shadows), plane(4.0, -1.0, shadows)})}) {
                d["clip_planes"] = planes;
                const std::string what = method + " " + planes.dump();
                if (const auto r = renderOrRefuse(d, what)) expectSane(r->image, what);
            }
            // Kept regions that do not meet (x ≥ 6 and x ≤ 2): nothing is left to see, so the
            // image is the background (black) with coverage 0.
            d["clip_planes"] = json::array({plane(6.0, 1.0, shadows), plane(2.0, -1.0, shadows)});
            const std::string what = method + " empty intersection";
            if (const auto r = renderOrRefuse(d, what)) {
                expectSane(r->image, what);
                for (std::size_t i = 0; i < r->image.pixels.size(); ++i)
                    ASSERT_EQ(r->image.pixels[i], 0.f)
                        << what << " shadows_from_removed " << shadows << " at " << i;
            }
        }
    }
}

TEST(HardCases, AVolumeOverTheMemoryBudget) {
    const TempDir tmp;
    const HardVolume big{"over-budget", {24, 24, 24}, {1, 1, 1}, [](int i, int j, int k) {
                             return float((i * 7 + j * 3 + k * 5) % 11) * 100.f;
                         }};
    const auto path = writeHard(big, tmp.path());
    // pvrt: 24³ points × 16 SH basis lights × RGB floats = 2.5 MB, over memory_mb 1.
    // iso-lattice: the SH-transfer lattice (25 coefficients × RGB per texel) at 8 texels per voxel
    // needs far more than lattice_memory_mb 1 on this volume's isosurface.
    struct Over {
        std::string method;
        json params;
        std::string field;   ///< the field the error names
        std::string budget;  ///< the budget key the message must mention
    };
    const std::vector<Over> overs = {
        {"pvrt",
         {{"resolution", 24}, {"order", 4}, {"photons", 1}, {"clusters", 0}, {"memory_mb", 1}},
         "method.params.memory_mb",  // the budget the scene lowered (as iso-lattice's)
         "memory_mb"},
        {"iso-lattice",
         {{"samples", 1},
          {"lattice_resolution", 8},
          {"lattice_mode", "sh"},
          {"sh_order", 5},
          {"lattice_memory_mb", 1}},
         "method.params.lattice_memory_mb",
         "budget"},
    };
    for (const Over& o : overs) {
        const json d = hardScene(path, {{"name", o.method}, {"params", o.params}});
        try {
            pipeline::renderScene(io::parseScene(d, "h", "."));
            ADD_FAILURE() << o.method << ": a volume over the budget rendered";
        } catch (const InputError& e) {
            EXPECT_EQ(e.field(), o.field) << o.method << ": " << e.what();
            EXPECT_NE(std::string(e.what()).find(o.budget), std::string::npos)
                << o.method << ": " << e.what();
        }
    }
    // sh-local and sh-global: lod_budget_mb is a target for the LOD selection, raised to one
    // sample per visible block when smaller (visibility/multires_grid.h) — the documented answer
    // is a coarser field, not an error. The smallest budget the scene allows must render.
    for (const std::string method : {"sh-local", "sh-global"}) {
        const json d =
            hardScene(path, {{"name", method}, {"params", {{"rays", 8}, {"lod_budget_mb", 1e-3}}}});
        const auto r = pipeline::renderScene(io::parseScene(d, "h", "."));
        expectSane(r.image, method + " lod_budget_mb 1e-3");
    }
    // The session's artifact cache: a budget of one byte drops everything but the newest entry;
    // every method must still render.
    for (const std::string& method : allMethods()) {
        pipeline::Session session(1);
        const json d = hardScene(path, methodOf(method));
        try {
            const auto r = session.run(io::parseScene(d, "h", "."));
            expectSane(r.image, method + " with a 1-byte cache");
        } catch (const InputError& e) {
            std::printf("refused: %s with a 1-byte cache: %s\n", method.c_str(), e.what());
        }
    }
}

TEST(HardCases, PathTracerAccumulatesAMillionSamples) {
    // A transparent medium: every path misses and returns the background, a constant stream.
    // After 2²⁰ ≈ 10⁶ samples per pixel the mean must be that constant (closed form) and the
    // standard error 0 up to the rounding bounds above — Σv and Σv² are kept in double.
    const Medium m = makeMedium("sphere", stepTf(0.f, glm::vec3(0.5f)), 8);
    const glm::dvec3 hi = glm::dvec3(m.volume->geometry().dims - 1);
    const render::Camera cam(render::CameraSpec{}, glm::dvec3(0.0), hi, 1, 1);
    for (const float c : {0.1f, 3e4f}) {
        pathtrace::Options o;
        o.samplesPerPixel = 1 << 20;
        o.background = glm::vec3(c, 0.f, 1.f);
        o.threads = 1;
        pathtrace::Stats st;
        core::ImageRGBA se;
        const core::ImageRGBA im = m.tracer(o).render(cam, core::Progress::none(), &st, &se);
        ASSERT_EQ(st.samplesPerPixel, 1 << 20);
        EXPECT_NEAR(im.pixels[0], c, kMillionMeanRelTol * c) << c;
        EXPECT_EQ(im.pixels[1], 0.f);
        EXPECT_NEAR(im.pixels[2], 1.f, kMillionMeanRelTol);
        EXPECT_EQ(im.pixels[3], 0.f);  // no coverage
        EXPECT_LE(se.pixels[0], kMillionStdErrorRelTol * c) << c;
        EXPECT_LE(se.pixels[2], kMillionStdErrorRelTol) << c;
        EXPECT_TRUE(std::isfinite(st.relativeStdError));
    }
}

TEST(HardCases, PathTracerAccumulatesAMillionBernoulliSamples) {
    // A non-constant stream with a closed form: one pixel whose ray (pixel centre, no jitter)
    // crosses a homogeneous medium of σt with albedo 0 and emission e. Each sample is e (the path
    // collided: probability p = 1 − exp(−σt·D), D the ray's length in the box) or 0 (it left into
    // a black background). After 2²⁰ samples: mean e·p, standard error e·√(p(1−p)/n).
    core::Geometry g;
    g.dims = {8, 8, 8};
    auto v = std::make_shared<core::Volume>(g, core::VoxelType::Float32);
    std::fill_n(v->dataAs<float>(), v->voxelCount(), 1.f);
    const float sigma = 0.1f, e = 2.f;
    const optics::TransferFunction tf(
        {{0.f, glm::vec3(0.f), sigma, glm::vec3(e)}, {2.f, glm::vec3(0.f), sigma, glm::vec3(e)}},
        {1.f, 2.f}, "emissive");
    const Medium m = makeMedium(v, tf);
    const glm::dvec3 hi(7.0);  // the tracer's box: voxel centres 0..n−1 (spacing 1, origin 0)
    const render::Camera cam(render::CameraSpec{}, glm::dvec3(0.0), hi, 1, 1);
    const render::Ray ray = cam.generateThroughLens(0.5, 0.5, 0.0, 0.0);
    double t0 = 0.0, t1 = INFINITY;  // slab test, independent of the tracer's
    for (int a = 0; a < 3; ++a) {
        double ta = (0.0 - ray.origin[a]) / ray.direction[a];
        double tb = (hi[a] - ray.origin[a]) / ray.direction[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta), t1 = std::min(t1, tb);
    }
    ASSERT_GT(t1, t0);
    const double p = -std::expm1(-double(sigma) * (t1 - t0));
    pathtrace::Options o;
    o.samplesPerPixel = 1 << 20;
    o.pixelJitter = false;
    o.threads = 1;
    pathtrace::Stats st;
    core::ImageRGBA se;
    const core::ImageRGBA im = m.tracer(o).render(cam, core::Progress::none(), &st, &se);
    ASSERT_EQ(st.samplesPerPixel, 1 << 20);
    const double n = st.samplesPerPixel;
    const double expectedSe = e * std::sqrt(p * (1.0 - p) / n);
    std::printf("p %.6f: mean %.6f (closed form %.6f), std error %.4g (closed form %.4g)\n", p,
                im.pixels[0], e * p, se.pixels[0], expectedSe);
    EXPECT_NEAR(im.pixels[0], e * p, kBernoulliSigmas * expectedSe) << "p " << p;
    EXPECT_NEAR(im.pixels[3], p, kBernoulliSigmas * expectedSe / e) << "coverage";
    EXPECT_NEAR(se.pixels[0], expectedSe, kBernoulliStdErrorRelTol * expectedSe) << "p " << p;
}
