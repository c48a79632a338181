// SPDX-License-Identifier: MIT
// voxlight iso SCENE.json|VOLUME -o MESH.(ply|obj|glb) [--isovalue V] [--stats STATS.json]
//              [--set key=value]... [--cap] [--remove-degenerate] [--keep-largest K]
//              [--min-component-faces N] [--smooth N] [--decimate FACES]
//              [--no-self-intersections] [--bake [--samples N] [--bounces K]
//              [--bake-from vertices|lattice] [--lattice-resolution R]
//              [--lattice-mode irradiance|sh] [--sh-order O]] [-q]
// Extracts the scene's isosurface as a mesh (iso/: VTK flying edges → OpenMesh, world mm, outward
// gradient normals), cuts it by the scene's clip planes and crop box (open cut, or capped with
// --cap: iso/extract.h), optionally cleans
// it up (CGAL), reports it and writes it with vertex colours.
//
// The isovalue, first found wins: --isovalue; the scene's method.params.iso_value (the `iso`
// render method's parameter, so that `voxlight render` of the same scene shows the same surface);
// the transfer function's surface value (where its extinction reaches a tenth of its maximum,
// optics::TransferFunction::surfaceValue — what the `iso` render method uses by default). The
// vertex colour is the transfer function's albedo at the isovalue; with --bake, the light the
// scene's lights give each vertex (iso/lattice.h: shadows, sky, interreflections) —
// albedo·E/π·2^exposure — traced from the vertex itself (default) or read from Wyman's
// illumination lattice (--bake-from lattice); when the scene has no lights, a uniform white sky of
// radiance 1 (an unoccluded vertex shows its albedo: ambient occlusion with bounces).
//
// Bad input exits 2 with one line and writes nothing: an isovalue outside the data range (the
// line names the range), a flat volume (no isosurface exists), clip planes / crop box that remove
// the whole surface, an output path that cannot be written or whose extension is not .ply, .obj or
// .glb.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <sstream>

#include "app/cli_support.h"
#include "app/output_files.h"
#include "app/volume_options.h"
#include "core/half_space.h"
#include "core/timing.h"
#include "io/scene.h"
#include "iso/cleanup.h"
#include "iso/export.h"
#include "iso/extract.h"
#include "iso/lattice.h"
#include "pipeline/pipeline.h"
#include "pipeline/scene_inputs.h"

namespace voxlight::app {

namespace {
/// Mean thickness (2·volume / area, voxels) below which a capped mesh is the two caps of one plane
/// lying on each other: caps are nudged kCapPlaneNudge (1e-4 voxel) off their planes, and a slab
/// a hundredth of a voxel thin holds no voxel sample.
constexpr double kMinCappedThicknessVoxels = 1e-2;
namespace fs = std::filesystem;
using nlohmann::json;

json stage(const std::string& name, bool ran, const std::string& reason, double seconds) {
    return {{"name", name}, {"ran", ran}, {"reason", reason}, {"seconds", seconds}};
}

/// Self-intersecting face pairs per face above which decimation's folds get a warning: the torso's
/// bone at 100 k faces has 6 pairs (README), the abdominal CT at 5000 faces had 2736.
constexpr double kFoldedShare = 0.01;

/// Share of the vertices whose baked colour may pass white (clamped to 1 in every export) before
/// the bake says so: a few highlights are normal, a quarter of the mesh white is lost detail
/// (probe: courtyard.hdr at intensity 1 clamped 24 % of the vertices without a word).
constexpr double kClampedShare = 0.1;

/// "N % of the vertices …" when more than kClampedShare of the baked colours pass white, with the
/// exposure at which the 95th percentile of their largest channel is white; empty otherwise.
std::string clampedBakeWarning(const iso::Mesh& mesh, double exposureStops) {
    std::vector<float> largest;
    largest.reserve(mesh.n_vertices());
    std::size_t over = 0;
    for (const auto v : mesh.vertices()) {
        const auto& c = mesh.color(v);
        const float m = std::max({c[0], c[1], c[2]});
        over += m > 1.f;
        largest.push_back(m);
    }
    if (largest.empty() || double(over) <= kClampedShare * double(largest.size())) return {};
    const auto p95 = largest.begin() + std::ptrdiff_t(0.95 * double(largest.size() - 1));
    std::nth_element(largest.begin(), p95, largest.end());
    std::ostringstream os;
    os << std::lround(100.0 * double(over) / double(largest.size()))
       << " % of the vertices bake brighter than white and are clamped to it in the export, their "
          "detail lost (set image.exposure to "
       << std::floor(10.0 * (exposureStops - std::log2(double(*p95)))) / 10.0
       << ", or lower the lights' intensity)";
    return os.str();
}

json reportJson(const iso::MeshReport& r) {
    return {{"vertices", r.vertices},
            {"faces", r.faces},
            {"components", r.components},
            {"boundary_edges", r.boundaryEdges},
            {"non_manifold_vertices", r.nonManifoldVertices},
            {"self_intersections", r.selfIntersections < 0 ? json() : json(r.selfIntersections)},
            {"closed", r.closed},
            {"area_mm2", r.areaMm2},
            {"volume_mm3", r.closed ? json(r.volumeMm3) : json()}};
}

}  // namespace

Command addIsoCommand(CLI::App& app) {
    Command c;
    c.sub = app.add_subcommand("iso", "Extract the scene's isosurface as a mesh (PLY, OBJ, glTF)");
    auto scene = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto stats = std::make_shared<std::string>();
    auto sets = std::make_shared<std::vector<std::string>>();
    auto isovalue = std::make_shared<double>(0.0);
    auto cleanup = std::make_shared<iso::CleanupOptions>();
    auto noSelfIntersections = std::make_shared<bool>(false);
    auto maxMemoryMiB = std::make_shared<double>(8192.0);
    auto quiet = std::make_shared<bool>(false);
    auto bake = std::make_shared<bool>(false);
    auto lattice = std::make_shared<iso::LatticeOptions>();
    auto latticeMode = std::make_shared<std::string>("irradiance");
    auto bakeFrom = std::make_shared<std::string>("vertices");
    auto exportSh = std::make_shared<bool>(false);
    auto cap = std::make_shared<bool>(false);
    auto latticeTexels = std::make_shared<std::string>("surface");
    c.sub->add_option("INPUT", *scene, "Scene JSON, or a volume file / DICOM folder")->required();
    c.sub->add_option("-o,--output", *out, "Mesh file: .ply, .obj or .glb")->required();
    CLI::Option* isoOption =
        c.sub->add_option("--isovalue", *isovalue,
                          "Isovalue in physical units (HU for CT); default: the scene's "
                          "method.params.iso_value, else the transfer function's surface value");
    c.sub->add_option("--stats", *stats, "Write stages, timings and the mesh report as JSON");
    c.sub->add_option("--set", *sets, "Override a scene key, e.g. --set crop_box.min=[0,0,0]")
        ->allow_extra_args(false);
    auto shorthands = addVolumeShorthands(*c.sub);
    c.sub->add_flag("--cap", *cap,
                    "Close the cuts of clip planes and crop box with flat caps (a closed surface "
                    "stays watertight)");
    c.sub->add_flag("--remove-degenerate", cleanup->removeDegenerate,
                    "Remove degenerate (zero-area) faces");
    c.sub
        ->add_option("--keep-largest", cleanup->keepLargest,
                     "Keep only the K largest connected components")
        ->check(CLI::Range(1, 1 << 30));
    c.sub
        ->add_option("--min-component-faces", cleanup->minComponentFaces,
                     "Drop connected components with fewer faces")
        ->check(CLI::Range(std::size_t(0), std::size_t(1) << 40));
    c.sub
        ->add_option("--smooth", cleanup->smoothIterations,
                     "Smooth with N iterations of Taubin lambda|mu smoothing, 0-50 (closed "
                     "parts keep their volume)")
        ->check(CLI::Range(0, iso::kMaxSmoothIterations));
    c.sub
        ->add_option("--decimate", cleanup->targetFaces,
                     "Decimate (edge collapse) to about this many faces")
        ->check(CLI::Range(std::size_t(4), std::size_t(1) << 40));
    c.sub
        ->add_option(
            "--max-memory-mb", *maxMemoryMiB,
            "Refuse before extracting when the surface promises a larger peak (about " +
                std::to_string(int(iso::kTrianglesPerCrossedEdge * iso::kPeakBytesPerTriangle)) +
                " bytes per voxel edge it crosses; 8192; 0: no limit)")
        ->check(finiteNumber())
        ->check(CLI::Range(0.0, double(1 << 30)));
    c.sub->add_flag("--no-self-intersections", *noSelfIntersections,
                    "Skip the self-intersection count of the report (its costly part)");
    c.sub->add_flag("--bake", *bake,
                    "Bake the scene's lights (shadows, sky, interreflections) into the vertex "
                    "colours: paths traced from each vertex, or Wyman's illumination lattice "
                    "(--bake-from)");
    c.sub
        ->add_option("--samples", lattice->samples,
                     "--bake: paths per vertex (or per lattice texel) (100)")
        ->check(CLI::Range(1, 1000000));
    c.sub->add_option("--bounces", lattice->bounces, "--bake: diffuse interreflections (1)")
        ->check(CLI::Range(0, 16));
    c.sub
        ->add_option("--lattice-resolution", lattice->resolution,
                     "--bake: lattice texels per voxel along each axis, 0.5…8 (1)")
        ->check(finiteNumber())
        ->check(CLI::Range(iso::kMinLatticeResolution, 8.0));
    c.sub
        ->add_option("--bake-from", *bakeFrom,
                     "--bake: vertices (paths from each vertex: accurate, the default) or lattice "
                     "(Wyman's illumination lattice, trilinear)")
        ->check(CLI::IsMember({"vertices", "lattice"}));
    c.sub
        ->add_option("--lattice-mode", *latticeMode,
                     "--bake: irradiance (any lights) or sh (SH transfer, distant lights)")
        ->check(CLI::IsMember({"irradiance", "sh"}));
    c.sub->add_option("--sh-order", lattice->shOrder, "--bake with sh: SH order 1…5 (5: 25 coeff.)")
        ->check(CLI::Range(1, 5));
    c.sub
        ->add_option("--lattice-texels", *latticeTexels,
                     "--bake-from lattice: surface (texels moved onto the isosurface being baked: "
                     "accurate, the default) or own (Wyman's: each texel on its own isosurface, "
                     "shared by every isovalue)")
        ->check(CLI::IsMember({"surface", "own"}));
    c.sub->add_flag("--export-sh", *exportSh,
                    "--bake --bake-from lattice --lattice-mode sh: also write each vertex's SH "
                    "irradiance transfer into the PLY (relight the mesh without tracing)");
    c.sub->add_flag("-q,--quiet", *quiet, "No progress output");
    CLI::App* sub = c.sub;
    c.run = [=] {
        core::Stopwatch total;
        // The bake's own options do nothing without it: said, not ignored.
        if (!*bake)
            for (const char* o : {"--samples", "--bounces", "--lattice-resolution", "--bake-from",
                                  "--lattice-mode", "--sh-order", "--lattice-texels"})
                if (sub->count(o) > 0)
                    throw InputError("command line", o, "takes effect only with --bake",
                                     std::string("add --bake, or leave out ") + o);
        // Options of the lattice do nothing for the vertex bake, and the SH order nothing for
        // irradiance: said, not ignored.
        if (*bakeFrom != "lattice")
            for (const char* o : {"--lattice-resolution", "--lattice-texels", "--sh-order"})
                if (sub->count(o) > 0)
                    throw InputError("command line", o,
                                     "takes effect only with --bake-from lattice (the default "
                                     "bake traces paths from each vertex)",
                                     std::string("add --bake-from lattice, or leave out ") + o);
        if (*latticeMode != "sh" && sub->count("--sh-order") > 0)
            throw InputError("command line", "--sh-order",
                             "takes effect only with --lattice-mode sh",
                             "add --lattice-mode sh, or leave out --sh-order");
        checkOutputs({{"--output", *out, iso::meshExtensions()}, {"--stats", *stats, {".json"}}},
                     {{"INPUT", *scene}});
        if (*exportSh) {
            if (!*bake || *bakeFrom != "lattice" || *latticeMode != "sh")
                throw InputError("command line", "--export-sh",
                                 "needs the SH transfer of a lattice bake",
                                 "add --bake --bake-from lattice --lattice-mode sh");
            if (iso::meshFormatFor(*out) != iso::MeshFormat::Ply)
                throw InputError("command line", "--export-sh",
                                 "per-vertex SH transfer is written to PLY only",
                                 "write the mesh to a .ply file");
        }
        const io::Scene s = loadInput(*scene, shorthands->overrides(*sets));
        pipeline::Session().plan(s);  // the scene is valid as `render` reads it
        const core::Progress progress = terminalProgress(*quiet);
        json stages = json::array();

        core::Stopwatch sw;
        const auto volumePtr =
            std::make_shared<const core::Volume>(pipeline::loadSceneVolume(s, progress));
        const core::Volume& volume = *volumePtr;
        for (const auto& w : volume.warnings)
            std::fprintf(stderr, "voxlight: warning: %s\n", w.c_str());
        stages.push_back(stage("volume", true, "loaded: " + volume.description, sw.seconds()));
        const optics::TransferFunction tf = pipeline::buildTransferFunction(s, volume);

        // The isovalue and who gave it (errors about it name that place).
        iso::ExtractOptions options;
        std::string isoSource = "command line", isoField = "--isovalue";
        if (isoOption->count() > 0) {
            options.isovalue = *isovalue;
        } else if (s.method.name == "iso" && s.method.params.contains("iso_value")) {
            options.isovalue = s.method.params["iso_value"].get<double>();
            isoSource = s.source, isoField = "method.params.iso_value";
        } else {
            options.isovalue = tf.surfaceValue();
            isoSource = s.source, isoField = "transfer_function";
        }
        options.color = tf.eval(float(options.isovalue)).albedo;
        options.cap = *cap;
        options.maxMemoryMiB = *maxMemoryMiB;
        for (const auto& p : s.clipPlanes)
            options.keep.push_back({p.point, glm::normalize(p.normal)});
        if (s.cropBox)
            for (const auto& h : core::boxHalfSpaces(s.cropBox->min, s.cropBox->max))
                options.keep.push_back(h);

        sw.restart();
        iso::Extraction ex;
        try {
            ex = iso::extractIsosurface(volume, options, progress);
        } catch (const InputError& e) {
            if (e.source() == "isosurface" && e.field() == "memory")
                throw InputError("command line", "--max-memory-mb", e.problem(), e.fix());
            if (e.source() != "isosurface" || (e.field() != "volume" && e.field() != "isovalue"))
                throw;
            if (e.field() == "volume") throw InputError(s.source, "volume", e.problem(), e.fix());
            const std::string fix = isoField == "transfer_function"
                                        ? e.fix() +
                                              " with --isovalue (the transfer function's "
                                              "surface value is not inside the data)"
                                        : e.fix();
            throw InputError(isoSource, isoField, e.problem(), fix);
        }
        const iso::ExtractStats& es = ex.stats;
        stages.push_back(stage(
            "extract", true,
            "computed: flying edges " + std::to_string(es.flyingEdgesTriangles) + " triangles",
            sw.seconds()));
        if (ex.mesh.n_faces() == 0 && es.flyingEdgesTriangles == 0) {
            // Nothing cut it away: the surface itself has no triangles here.
            const glm::ivec3 d = volume.dims();
            if (d.x < 2 || d.y < 2 || d.z < 2)
                throw InputError(s.source, "volume",
                                 "is one voxel thick along an axis: marching cubes needs 2 voxels "
                                 "per axis for a surface",
                                 "use a volume with at least 2 voxels on every axis");
            throw InputError(
                isoSource, isoField,
                "gives no isosurface triangles (value " + std::to_string(options.isovalue) + ")",
                "choose another isovalue");
        }
        if (ex.mesh.n_faces() == 0)
            throw InputError(s.source, s.cropBox ? "crop_box" : "clip_planes",
                             "the clip planes and crop box remove the whole isosurface (" +
                                 std::to_string(es.flyingEdgesTriangles) + " triangles)",
                             "move them so that part of the surface is kept");
        if (options.cap && !options.keep.empty() &&
            std::none_of(ex.mesh.edges().begin(), ex.mesh.edges().end(),
                         [&](const auto e) { return ex.mesh.is_boundary(e); })) {
            // Caps close what the cuts keep; planes that keep a region of no thickness (two
            // opposite planes through one point) leave two coincident caps: a closed mesh of
            // zero volume, written as "one clean closed part" (probe). Mean thickness 2V/A.
            double volume6 = 0.0, area2 = 0.0;
            for (const auto f : ex.mesh.faces()) {
                std::array<glm::dvec3, 3> t;
                int k = 0;
                for (const auto v : ex.mesh.fv_range(f)) {
                    const auto& p = ex.mesh.point(v);
                    t[k++] = glm::dvec3(p[0], p[1], p[2]);
                }
                volume6 += glm::dot(t[0], glm::cross(t[1], t[2]));
                area2 += glm::length(glm::cross(t[1] - t[0], t[2] - t[0]));
            }
            const double thickness = area2 > 0.0 ? 2.0 * (volume6 / 6.0) / (area2 / 2.0) : 0.0;
            if (std::abs(thickness) <
                kMinCappedThicknessVoxels * core::minComponent(volume.geometry().spacing))
                throw InputError(s.source, s.cropBox ? "crop_box" : "clip_planes",
                                 "the clip planes and crop box keep a region of no thickness: "
                                 "the caps would lie on each other",
                                 "move them so that a slab of the volume is kept");
        }

        sw.restart();
        if (options.cap) cleanup->heldPlanes = ex.planes;  // a cap's rim stays on its plane
        const iso::CleanupStats cs = iso::cleanUp(ex.mesh, *cleanup, progress);
        if (cs.verticesMoved)
            iso::setGradientNormals(ex.mesh, volume, cleanup->heldPlanes, iso::kOnCapPlaneMm);
        stages.push_back(stage("cleanup", cleanup->any(),
                               cleanup->any() ? "computed: " + std::to_string(cs.facesBefore) +
                                                    " → " + std::to_string(cs.facesAfter) + " faces"
                                              : "not needed: no clean-up option given",
                               sw.seconds()));
        if (ex.mesh.n_faces() == 0)
            throw InputError("command line", "--min-component-faces",
                             "the clean-up removed every face", "lower the minimum");

        sw.restart();
        const iso::MeshReport report = iso::reportMesh(ex.mesh, !*noSelfIntersections, progress);
        stages.push_back(stage("report", true, "computed", sw.seconds()));

        // Baked light (the lattice's texels at the vertices only).
        sw.restart();
        iso::LatticeStats ls;
        std::string lightsUsed, bakeWarning;
        iso::VertexTransfer transfer;
        if (*bake) {
            iso::LatticeOptions lo = *lattice;
            lo.mode =
                *latticeMode == "sh" ? iso::LatticeMode::ShTransfer : iso::LatticeMode::Irradiance;
            const double physicalIso =
                es.storedIsovalue * volume.mapping.slope + volume.mapping.intercept;
            lo.placement = *latticeTexels == "own" ? iso::TexelPlacement::OwnIsosurface
                                                   : iso::TexelPlacement::OnSurface;
            if (lo.placement == iso::TexelPlacement::OnSurface) lo.surfaceIso = physicalIso;
            // What the cuts remove is gone for the light too unless shadows_from_removed (the
            // planes as cut: a capped plane through vertices was nudged, and its cap lies on it).
            for (std::size_t i = 0; i < s.clipPlanes.size(); ++i)
                if (!s.clipPlanes[i].shadowsFromRemoved) lo.keep.push_back(ex.planes.at(i));
            if (s.cropBox && !s.cropBox->shadowsFromRemoved)
                for (std::size_t i = s.clipPlanes.size(); i < ex.planes.size(); ++i)
                    lo.keep.push_back(ex.planes[i]);
            std::vector<std::shared_ptr<const lights::Light>> ls0 = pipeline::buildLights(s);
            if (ls0.empty()) {
                ls0.push_back(pipeline::whiteSky());
                lightsUsed = "a uniform white sky (the scene has no lights)";
            } else {
                lightsUsed = std::to_string(ls0.size()) + " scene light(s)";
            }
            if (*bakeFrom == "vertices" && lo.mode == iso::LatticeMode::ShTransfer)
                throw InputError("command line", "--lattice-mode",
                                 "an SH transfer bake needs the lattice",
                                 "add --bake-from lattice, or drop --lattice-mode sh");
            try {
                iso::IlluminationLattice lat(volumePtr, tf, std::move(ls0), lo);
                ls = iso::bakeVertexColours(
                    ex.mesh, lat,
                    es.storedIsovalue * volume.mapping.slope + volume.mapping.intercept,
                    options.color, float(std::exp2(s.image.exposureStops)),
                    *bakeFrom == "lattice" ? iso::BakeSource::Lattice : iso::BakeSource::Vertices,
                    progress, *exportSh ? &transfer.values : nullptr);
                if (*exportSh) transfer.order = lo.shOrder;
                bakeWarning = clampedBakeWarning(ex.mesh, s.image.exposureStops);
            } catch (const InputError& e) {
                if (e.source() != "lattice") throw;
                static const std::map<std::string, std::string> option = {
                    {"samples", "--samples"},
                    {"bounces", "--bounces"},
                    {"resolution", "--lattice-resolution"},
                    {"sh_order", "--sh-order"},
                    {"mode", "--lattice-mode"},
                    {"memory", "--lattice-resolution"}};
                const auto it = option.find(e.field());
                if (it == option.end()) throw InputError(s.source, e.field(), e.problem(), e.fix());
                // iso has no option for the budget: the lattice's "or raise the budget" named a
                // fix that does not exist here (probe).
                if (e.field() == "memory")
                    throw InputError("command line", it->second, e.problem(),
                                     lo.mode == iso::LatticeMode::ShTransfer
                                         ? "lower --lattice-resolution or --sh-order"
                                         : "lower --lattice-resolution, or bake from the "
                                           "vertices (the default)");
                throw InputError("command line", it->second, e.problem(), e.fix());
            }
        }
        const std::string bakeWhat =
            *bakeFrom == "lattice"
                ? std::to_string(ls.texelsComputed) + " texels of " + std::to_string(ls.texelsFull)
                : std::to_string(ex.mesh.n_vertices()) + " vertices";
        stages.push_back(stage("bake_light", *bake,
                               *bake ? "computed: " + bakeWhat + " (" + lightsUsed + ", " +
                                           std::to_string(lattice->samples) + " paths, " +
                                           std::to_string(lattice->bounces) + " bounce(s))"
                                     : "not needed: no --bake (vertex colour = the TF's albedo)",
                               sw.seconds()));

        sw.restart();
        throwIfCancelled();
        OutputFiles files;
        const iso::ExportInfo info{volume.description, options.isovalue, volume.mapping.unit};
        files.write(*out, "--output", [&](const fs::path& p) {
            iso::writeMesh(ex.mesh, p, *iso::meshFormatFor(*out), info,
                           *exportSh ? &transfer : nullptr);
        });
        stages.push_back(stage("write_mesh", true, "computed: " + *out, sw.seconds()));
        if (!stats->empty()) {
            json j = {{"stages", stages},
                      {"total_seconds", total.seconds()},
                      {"peak_rss_mb", core::peakRssMiB()},
                      {"isosurface",
                       {{"isovalue", es.isovalue},
                        {"isovalue_source", isoField},
                        {"stored_isovalue", es.storedIsovalue},
                        {"integer_isovalue_nudged", es.nudged},
                        {"data_range", es.range},
                        {"flying_edges_triangles", es.flyingEdgesTriangles},
                        {"clipped_triangles", es.clippedTriangles},
                        {"faces_refused_non_manifold", es.rejectedFaces},
                        {"caps", *cap ? json{{"triangles", es.capTriangles},
                                             {"open_cut_edges", es.capOpenEdges},
                                             {"failed_planes", es.capFailures}}
                                      : json(nullptr)},
                        {"cleanup",
                         {{"degenerate_faces_removed", cs.degenerateFacesRemoved},
                          {"components_removed", cs.componentsRemoved},
                          {"faces_before", cs.facesBefore},
                          {"faces_after", cs.facesAfter}}},
                        {"report", reportJson(report)},
                        {"bake", *bake ? json{{"vertices", ex.mesh.n_vertices()},
                                              {"texels_full", ls.texelsFull},
                                              {"texels_computed", ls.texelsComputed},
                                              {"texels_plateau", ls.plateauTexels},
                                              {"paths", ls.pathsTraced},
                                              {"shadow_rays", ls.shadowRays},
                                              {"seconds", ls.seconds},
                                              {"stored_mib", ls.storedMiB},
                                              {"tracer_mib", ls.tracerMiB},
                                              {"skip_fields_built", ls.skipFieldsBuilt},
                                              {"samples", lattice->samples},
                                              {"bounces", lattice->bounces},
                                              {"resolution", lattice->resolution},
                                              {"mode", *latticeMode},
                                              {"from", *bakeFrom},
                                              {"lattice_texels", *latticeTexels},
                                              {"sh_transfer_exported", *exportSh},
                                              {"lights", lightsUsed}}
                                       : json(nullptr)},
                        {"units", "mm"},
                        {"frame", "LPS"}}},
                      {"scene", s.document}};
            const std::string text = j.dump(2, ' ', false, json::error_handler_t::replace);
            files.write(*stats, "--stats", [&](const fs::path& p) { writeTextFile(p, text); });
        }
        throwIfCancelled();
        files.commit();
        if (es.capOpenEdges)
            std::fprintf(stderr,
                         "voxlight: warning: %zu cut edge(s) left uncapped: the surface is open "
                         "there (it reaches the volume's border)\n",
                         es.capOpenEdges);
        if (es.capFailures)
            std::fprintf(stderr,
                         "voxlight: warning: the cap of %zu plane(s) could not be filled whole: "
                         "the mesh may have holes there\n",
                         es.capFailures);
        // Decimation far below the surface's detail folds it (probe: the abdominal CT to 5000 faces,
        // 2736 self-intersecting pairs, area +22 %), said only by the report's count until now.
        if (cleanup->targetFaces > 0 && report.selfIntersections > 0 &&
            double(report.selfIntersections) > kFoldedShare * double(ex.mesh.n_faces()))
            std::fprintf(
                stderr,
                "voxlight: warning: --decimate %zu folded the mesh: %lld self-intersecting "
                "face pairs on %zu faces (decimate less, or drop small parts first with "
                "--min-component-faces)\n",
                cleanup->targetFaces, (long long)report.selfIntersections,
                std::size_t(ex.mesh.n_faces()));
        if (!bakeWarning.empty())
            std::fprintf(stderr, "voxlight: warning: %s\n", bakeWarning.c_str());
        if (es.rejectedFaces)
            std::fprintf(stderr,
                         "voxlight: warning: %zu triangle(s) left out: they would have made an "
                         "edge non-manifold\n",
                         es.rejectedFaces);
        if (!*quiet) {
            std::ostringstream line;
            line << "isosurface at " << es.isovalue << (volume.mapping.unit.empty() ? "" : " ")
                 << volume.mapping.unit << " (" << isoField << "): " << report;
            std::fprintf(stderr, "%s\nwrote %s (total %.2f s)\n", line.str().c_str(), out->c_str(),
                         total.seconds());
        }
        return kExitOk;
    };
    return c;
}

}  // namespace voxlight::app
