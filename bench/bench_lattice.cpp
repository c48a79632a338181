// SPDX-License-Identifier: MIT
// Illumination lattice (iso/lattice.h) against its reference, Wyman 2006 Fig. 11 style: the
// irradiance baked at mesh vertices from a lattice of 100 / 625 / 2,500 paths per texel, against
// per-point path tracing of the same isosurface at each vertex (IlluminationLattice::
// pointIrradiance, 10,000 paths) — the error a lit-mesh export carries — with the seconds beside
// each row. Three lattices are compared: texels moved onto the isosurface being baked
// (TexelPlacement::OnSurface, what `voxlight iso --bake-from lattice` and method iso-lattice use),
// and Wyman's texels on their own isosurfaces read by two rules: the texels inside the surface
// and all eight (Wyman's plain trilinear). A "per vertex" row gives the error of
// tracing the vertices themselves with as many paths (what the lattice saves or costs).
// Then the lazy texel counts for the whole bone mesh: vertices' texels (inside only), every
// crossed cell's, the full lattice; and the texels an isovalue step of 10 HU reuses.
//
// Scenes: the torso phantom (128³, so the table runs in minutes) and the shared abdomen CT when
// ../shared/datasets/ct/abdomen-totalseg/example_ct.nii.gz exists (skipped with a message if not),
// bone at 300 HU (torso 250 HU), a directional key light plus a uniform sky of 0.3, 1 bounce.
// Errors over kVertices vertices drawn with a fixed seed: NRMS = RMS(E − E_ref) / mean(E_ref), and
// the mean bias. Not a test; one run prints one table (timings are the machine's of the moment).
// Run: build/bench/bench_lattice [--quick]  (--quick: 100 and 625 paths, 2,500-path reference)
//
// build/bench/bench_lattice --goal [PAIRS]: the goal instead — the lazy on-surface bone
// lattice of a 256³ CT for its whole bone mesh at 100 paths per texel, 1 bounce (the torso phantom
// at 256³, bone at 250 HU; the LIDC chest 256×256×133, uint8, bone at 200, when present), with the
// skip distances and, as the baseline in the same process, with the 8³ bricks alone; PAIRS
// alternating pairs (default 3), medians and the ratio. `--paths N` runs the same at N paths.
// bench-deps: iso io core optics lights
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <vector>

#include "core/phantoms.h"
#include "core/rng.h"
#include "core/timing.h"
#include "io/volume_io.h"
#include "iso/extract.h"
#include "iso/lattice.h"
#include "lights/environment_light.h"
#include "optics/presets.h"

namespace fs = std::filesystem;
using namespace voxlight;

namespace {

constexpr int kVertices = 300;
constexpr int kReferencePaths = 10000;

std::vector<std::shared_ptr<const lights::Light>> sceneLights() {
    core::ImageRGBA sky(64, 32);
    for (std::size_t i = 0; i < sky.pixels.size(); ++i) sky.pixels[i] = 0.3f;
    return {std::make_shared<lights::DirectionalLight>(glm::vec3(3.f),
                                                       glm::vec3(-0.35f, -0.75f, 0.55f)),
            std::make_shared<lights::EnvironmentLight>(sky, lights::EnvironmentOptions{}, "sky")};
}

struct Errors {
    double nrms = 0, bias = 0;
};

Errors compare(const std::vector<glm::vec3>& e, const std::vector<glm::vec3>& ref) {
    double se = 0, d = 0, m = 0;
    for (std::size_t i = 0; i < e.size(); ++i) {
        const double x = e[i].y - ref[i].y;  // green: the channels differ only by albedo
        se += x * x;
        d += x;
        m += ref[i].y;
    }
    const double n = double(e.size()), mean = m / n;
    return {std::sqrt(se / n) / mean, d / n / mean};
}

/// The bone mesh at `isovalue` (stored units): its vertices (world mm) and the isovalue in
/// physical units, as the lattice takes it.
struct BoneSurface {
    iso::ExtractOptions options;
    std::vector<glm::dvec3> vertices;
    double iso = 0.0;
};

BoneSurface boneSurface(const core::Volume& volume, double isovalue) {
    BoneSurface b;
    b.options.isovalue = isovalue;
    const iso::Extraction ex = iso::extractIsosurface(volume, b.options);
    b.iso = ex.stats.storedIsovalue * volume.mapping.slope + volume.mapping.intercept;
    for (const auto v : ex.mesh.vertices()) {
        const auto& p = ex.mesh.point(v);
        b.vertices.emplace_back(p[0], p[1], p[2]);
    }
    return b;
}

void run(const char* name, std::shared_ptr<const core::Volume> volume, double isovalue,
         bool quick) {
    const optics::TransferFunction tf = optics::makePreset("ct-bone");
    const BoneSurface bone = boneSurface(*volume, isovalue);
    const iso::ExtractOptions& eo = bone.options;
    const double iso = bone.iso;
    const std::vector<glm::dvec3>& all = bone.vertices;
    std::vector<glm::dvec3> pts;
    core::CounterRng rng(7);
    for (int i = 0; i < kVertices; ++i)
        pts.push_back(all[std::size_t(rng.uniformDouble() * double(all.size()))]);
    std::printf("\n%s: bone at %g (%zu vertices; %d drawn), key light + sky 0.3, 1 bounce\n", name,
                isovalue, all.size(), kVertices);

    iso::LatticeOptions o;
    o.bounces = 1;
    const int refPaths = quick ? 2500 : kReferencePaths;
    core::Stopwatch sw;
    std::vector<glm::vec3> ref;
    {
        iso::IlluminationLattice lat(volume, tf, sceneLights(), o);
        for (std::size_t i = 0; i < pts.size(); ++i)
            ref.push_back(lat.pointIrradiance(pts[i], iso, refPaths, 1000003 + i));
    }
    std::printf("reference: %d paths per vertex, %.1f s\n", refPaths, sw.seconds());
    std::printf(
        "| paths per texel | on surface: texels | seconds | NRMS | bias | own isosurfaces, inside "
        "texels: NRMS | bias | own, all 8 (Wyman): NRMS | bias | per vertex, same paths: NRMS | "
        "seconds |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    std::vector<int> counts = {100, 625};
    if (!quick) counts.push_back(2500);
    for (const int n : counts) {
        o.samples = n;
        iso::LatticeOptions os = o;
        os.placement = iso::TexelPlacement::OnSurface;
        os.surfaceIso = iso;
        iso::IlluminationLattice onSurface(volume, tf, sceneLights(), os);
        sw.restart();
        const iso::LatticeStats st = onSurface.require(pts, iso);
        const double secSurface = sw.seconds();
        std::vector<glm::vec3> s, a, b, c;
        for (const auto& p : pts) s.push_back(onSurface.irradiance(p, iso));
        iso::IlluminationLattice inside(volume, tf, sceneLights(), o);
        inside.require(pts, iso);
        for (const auto& p : pts) a.push_back(inside.irradiance(p, iso));
        iso::IlluminationLattice plain(volume, tf, sceneLights(), o);
        plain.require(pts);
        for (const auto& p : pts) b.push_back(plain.irradiance(p));
        sw.restart();
        for (std::size_t i = 0; i < pts.size(); ++i)
            c.push_back(plain.pointIrradiance(pts[i], iso, n, 7000003 + i));
        const double secPoint = sw.seconds();
        const Errors es = compare(s, ref), ea = compare(a, ref), eb = compare(b, ref),
                     ec = compare(c, ref);
        std::printf(
            "| %d | %llu | %.1f | %.3f | %+.1f %% | %.3f | %+.1f %% | %.3f | %+.1f %% | %.3f | "
            "%.1f "
            "|\n",
            n, (unsigned long long)st.texelsComputed, secSurface, es.nrms, 100 * es.bias, ea.nrms,
            100 * ea.bias, eb.nrms, 100 * eb.bias, ec.nrms, secPoint);
    }

    // Lazy texel counts for the whole mesh, and the reuse of a 10 HU isovalue step (16 paths:
    // counts do not depend on paths).
    o.samples = 1;
    iso::IlluminationLattice lat(volume, tf, sceneLights(), o);
    const iso::LatticeStats sv = lat.require(all, iso);
    iso::ExtractOptions eo2 = eo;
    eo2.isovalue = isovalue + 10.0;
    const iso::Extraction ex2 = iso::extractIsosurface(*volume, eo2);
    std::vector<glm::dvec3> all2;
    for (const auto v : ex2.mesh.vertices()) {
        const auto& p = ex2.mesh.point(v);
        all2.emplace_back(p[0], p[1], p[2]);
    }
    const iso::LatticeStats s2 = lat.require(
        all2, ex2.stats.storedIsovalue * volume->mapping.slope + volume->mapping.intercept);
    iso::IlluminationLattice cells(volume, tf, sceneLights(), o);
    const iso::LatticeStats sc = cells.requireIsosurface(iso);
    std::printf(
        "texels: vertices (inside) %llu, crossed cells %llu, full lattice %llu; a +10 HU "
        "step needs %llu, reuses %llu (%.0f %%)\n",
        (unsigned long long)sv.texelsNeeded, (unsigned long long)sc.texelsNeeded,
        (unsigned long long)sv.texelsFull, (unsigned long long)s2.texelsNeeded,
        (unsigned long long)s2.texelsReused,
        100.0 * double(s2.texelsReused) / double(std::max<std::uint64_t>(s2.texelsNeeded, 1)));
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const std::size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

void goal(const char* name, std::shared_ptr<const core::Volume> volume, double isovalue, int pairs,
          int paths) {
    const BoneSurface bone = boneSurface(*volume, isovalue);
    const double iso = bone.iso;
    const std::vector<glm::dvec3>& all = bone.vertices;
    std::printf("\n%s: bone at %g, %zu vertices, on-surface lattice, %d paths, 1 bounce\n", name,
                isovalue, all.size(), paths);
    const optics::TransferFunction tf = optics::makePreset("ct-bone");
    std::vector<double> with, without;
    for (int pair = 0; pair < pairs; ++pair)
        for (const bool skip : {pair % 2 == 0, pair % 2 != 0}) {
            iso::LatticeOptions o;
            o.samples = paths;
            o.bounces = 1;
            o.placement = iso::TexelPlacement::OnSurface;
            o.surfaceIso = iso;
            o.skipDistances = skip;
            core::Stopwatch sw;
            iso::IlluminationLattice lat(volume, tf, sceneLights(), o);
            const iso::LatticeStats st = lat.require(all, iso);
            const double sec = sw.seconds();
            (skip ? with : without).push_back(sec);
            std::printf("  pair %d, %-11s %.1f s (%llu texels of %llu, %llu paths)\n", pair + 1,
                        skip ? "skip:" : "bricks only:", sec, (unsigned long long)st.texelsComputed,
                        (unsigned long long)st.texelsFull, (unsigned long long)st.pathsTraced);
            std::fflush(stdout);
        }
    std::printf("  median %.1f s with skip distances, %.1f s with the bricks alone: ratio %.2f\n",
                median(with), median(without), median(with) / median(without));
}

}  // namespace

int main(int argc, char** argv) {
    bool quick = false;
    for (int i = 1; i < argc; ++i) quick = quick || std::strcmp(argv[i], "--quick") == 0;
    for (int i = 1; i < argc; ++i)
        if (std::strcmp(argv[i], "--goal") == 0) {
            const int pairs = i + 1 < argc ? std::max(1, std::atoi(argv[i + 1])) : 3;
            int paths = 100;  // the goal's; --paths N for a quicker look
            for (int j = 1; j + 1 < argc; ++j)
                if (std::strcmp(argv[j], "--paths") == 0)
                    paths = std::max(1, std::atoi(argv[j + 1]));
            core::PhantomOptions po;
            po.size = 256;
            goal("torso phantom 256³",
                 std::make_shared<const core::Volume>(core::makePhantom("torso", po)), 250.0, pairs,
                 paths);
            const fs::path chest = fs::path(VOXLIGHT_SOURCE_DIR) / ".." / "shared" / "datasets" /
                                   "ct" / "lidc2-chest.mha";
            if (fs::exists(chest))
                goal("LIDC chest CT 256×256×133",
                     std::make_shared<const core::Volume>(io::readVolume(chest)), 200.0, pairs,
                     paths);
            else
                std::printf("\nLIDC chest skipped: %s is absent\n", chest.c_str());
            return 0;
        }
    core::PhantomOptions po;
    po.size = 128;
    run("torso phantom 128³", std::make_shared<const core::Volume>(core::makePhantom("torso", po)),
        250.0, quick);
    const fs::path ct = fs::path(VOXLIGHT_SOURCE_DIR) / ".." / "shared" / "datasets" / "ct" /
                        "abdomen-totalseg" / "example_ct.nii.gz";
    if (fs::exists(ct))
        run("abdomen CT", std::make_shared<const core::Volume>(io::readVolume(ct)), 300.0, quick);
    else
        std::printf("\nabdomen CT skipped: %s is absent\n", ct.c_str());
    return 0;
}
