// SPDX-License-Identifier: MIT
#include "render/scene_render.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/phantoms.h"
#include "core/timing.h"
#include "grid/brick_grid.h"
#include "io/volume_io.h"
#include "optics/presets.h"

namespace voxlight::render {

using nlohmann::json;

const std::vector<std::string>& rayCasterMethods() {
    static const std::vector<std::string> m = {"emission-absorption", "gradient", "mip", "minip",
                                               "iso"};
    return m;
}

core::Volume loadSceneVolume(const io::Scene& scene, const core::Progress& progress) {
    const io::VolumeSource& src = scene.volume;
    if (!src.phantom.empty()) {
        core::PhantomOptions o;
        o.size = src.phantomSize;
        return core::makePhantom(src.phantom, o, progress);
    }
    return io::readVolume(src.path, src.readOptions, progress);
}

optics::TransferFunction buildTransferFunction(const io::Scene& scene, const core::Volume& volume) {
    const io::TransferFunctionDesc& d = scene.transferFunction;
    optics::TransferFunction tf;
    if (!d.points.empty()) {
        std::vector<optics::TfPoint> pts;
        for (const auto& p : d.points)
            pts.push_back(
                {float(p.value), glm::vec3(p.color), float(p.extinction), glm::vec3(p.emission)});
        const float lo = pts.front().value, hi = pts.back().value;
        optics::Window w{0.5f * (lo + hi), hi > lo ? hi - lo : 1.f};
        if (d.window) w = {float(d.window->x), float(d.window->y)};
        tf = optics::TransferFunction(std::move(pts), w, "custom");
    } else {
        const std::string name = d.preset.empty() ? optics::defaultPresetName(volume) : d.preset;
        const auto& cat = optics::presetCatalog();
        const auto it = std::find_if(cat.begin(), cat.end(),
                                     [&](const optics::PresetInfo& p) { return p.name == name; });
        const bool relative = it != cat.end() && it->relative;
        try {
            tf = optics::makePreset(
                name, relative ? optics::robustRange(volume) : std::array<float, 2>{0.f, 1.f});
        } catch (const InputError& e) {
            throw InputError(scene.source, "transfer_function.preset", e.problem(), e.fix());
        }
        if (d.window) tf = tf.withWindow({float(d.window->x), float(d.window->y)});
    }
    if (d.extinctionScale != 1.0) tf = tf.scaledExtinction(float(d.extinctionScale));
    return tf;
}

CameraSpec buildCameraSpec(const io::CameraDesc& d) {
    CameraSpec s;
    s.projection =
        d.projection == "orthographic" ? Projection::Orthographic : Projection::Perspective;
    s.azimuthDeg = d.azimuthDeg;
    s.elevationDeg = d.elevationDeg;
    s.rollDeg = d.rollDeg;
    s.distance = d.distance;
    s.fovYDeg = d.fovYDeg;
    s.orthoHeight = d.orthoHeight;
    s.target = d.target;
    s.eye = d.eye;
    s.up = d.up;
    return s;
}

namespace {

/// Strict reader of method.params.
class Params {
  public:
    Params(const io::Scene& s, std::vector<std::string> allowed)
        : s_(s), j_(s.method.params), allowed_(std::move(allowed)) {
        for (auto it = j_.begin(); it != j_.end(); ++it)
            if (std::find(allowed_.begin(), allowed_.end(), it.key()) == allowed_.end()) {
                std::string list;
                for (const auto& a : allowed_) list += (list.empty() ? "" : ", ") + a;
                throw InputError(s_.source, "method.params." + it.key(),
                                 "is not a parameter of method '" + s_.method.name + "'",
                                 "allowed: " + list);
            }
    }
    double number(const std::string& k, double def, double lo, double hi) {
        double v = def;
        if (j_.contains(k)) {
            if (!j_[k].is_number())
                throw InputError(s_.source, "method.params." + k, "must be a number");
            v = j_[k].get<double>();
            if (!std::isfinite(v) || v < lo || v > hi) {
                std::ostringstream os;
                os << "must be in [" << lo << ", " << hi << "], got " << v;
                throw InputError(s_.source, "method.params." + k, os.str());
            }
        }
        used[k] = v;
        return v;
    }
    bool boolean(const std::string& k, bool def) {
        bool v = def;
        if (j_.contains(k)) {
            if (!j_[k].is_boolean())
                throw InputError(s_.source, "method.params." + k, "must be true or false");
            v = j_[k].get<bool>();
        }
        used[k] = v;
        return v;
    }
    bool has(const std::string& k) const { return j_.contains(k); }
    json used = json::object();

  private:
    const io::Scene& s_;
    const json& j_;
    std::vector<std::string> allowed_;
};

}  // namespace

void checkPresetName(const io::Scene& scene) {
    const std::string& preset = scene.transferFunction.preset;
    if (preset.empty()) return;
    const auto& cat = optics::presetCatalog();
    if (std::any_of(cat.begin(), cat.end(),
                    [&](const optics::PresetInfo& p) { return p.name == preset; }))
        return;
    std::string list;
    for (const auto& p : cat) list += (list.empty() ? "" : ", ") + p.name;
    throw InputError(scene.source, "transfer_function.preset", "'" + preset + "' is not a preset",
                     "choose one of: " + list);
}

RenderOptions buildRenderOptions(const io::Scene& scene, json* usedOut) {
    // The TF preset is named before the volume is loaded: refuse an unknown one now.
    checkPresetName(scene);
    RenderOptions o;
    const std::string& m = scene.method.name;
    const auto& impl = rayCasterMethods();
    if (std::find(impl.begin(), impl.end(), m) == impl.end()) {
        std::string list;
        for (const auto& a : impl) list += (list.empty() ? "" : ", ") + a;
        throw InputError(scene.source, "method.name",
                         "'" + m + "' is not implemented by the ray caster in this build",
                         "choose one of: " + list);
    }
    std::vector<std::string> allowed = {"step", "preintegrated", "empty_space_skipping",
                                        "early_termination", "jitter"};
    if (m == "emission-absorption") allowed.push_back("ambient");
    if (m == "gradient")
        allowed.insert(allowed.end(),
                       {"ambient", "diffuse", "specular", "shininess", "central_differences"});
    if (m == "iso") allowed.insert(allowed.end(), {"iso_value", "ambient", "diffuse"});
    Params p(scene, allowed);
    o.mode = m == "emission-absorption" ? Mode::EmissionAbsorption
             : m == "gradient"          ? Mode::Gradient
             : m == "mip"               ? Mode::Mip
             : m == "minip"             ? Mode::MinIp
                                        : Mode::Isosurface;
    o.stepVoxels = float(p.number("step", scene.render.stepVoxels, 0.01, 16.0));
    o.preintegrated = p.boolean("preintegrated", true);
    o.emptySpaceSkipping = p.boolean("empty_space_skipping", true);
    o.earlyTermination = p.boolean("early_termination", true);
    o.jitter = p.boolean("jitter", true);
    if (m == "emission-absorption") o.ambient = float(p.number("ambient", 1.0, 0.0, 1e6));
    if (m == "gradient" || m == "iso") {
        o.blinnPhong.ambient = float(p.number("ambient", o.blinnPhong.ambient, 0.0, 1e6));
        o.blinnPhong.diffuse = float(p.number("diffuse", o.blinnPhong.diffuse, 0.0, 1e6));
    }
    if (m == "gradient") {
        o.blinnPhong.specular = float(p.number("specular", o.blinnPhong.specular, 0.0, 1e6));
        o.blinnPhong.shininess = float(p.number("shininess", o.blinnPhong.shininess, 1.0, 1e4));
        o.centralDifferences = p.boolean("central_differences", o.centralDifferences);
    }
    if (m == "iso" && p.has("iso_value")) o.isoValue = float(p.number("iso_value", 0.0, -1e9, 1e9));
    o.seed = scene.render.seed;
    o.threads = scene.render.threads;
    o.terminationTransmittance = float(scene.render.termination);
    o.background = glm::vec3(scene.image.background);
    for (const auto& c : scene.clipPlanes) o.clipPlanes.push_back({c.point, c.normal});
    if (scene.cropBox) o.cropBox = CropBox{scene.cropBox->min, scene.cropBox->max};
    for (std::size_t i = 0; i < scene.lights.size(); ++i) {
        const io::LightDesc& l = scene.lights[i];
        Light light;
        light.radiance = glm::vec3(l.color * l.intensity);
        if (l.type == "directional") {
            light.type = Light::Type::Directional;
            light.direction = glm::vec3(l.direction);
        } else if (l.type == "point") {
            light.type = Light::Type::Point;
            light.position = glm::vec3(l.position);
            light.minDistance = float(l.minDistance);
        } else {
            throw InputError(scene.source, "lights[" + std::to_string(i) + "].type",
                             "'" + l.type + "' lights are not supported by method '" + m + "'",
                             "use directional or point lights, or a method that supports them");
        }
        o.lights.push_back(light);
    }
    if (usedOut) *usedOut = p.used;
    return o;
}

SceneRenderResult renderScene(const io::Scene& scene, const core::Progress& progress, int frames) {
    if (frames < 1 || frames > kMaxFrames)
        throw InputError("command line", "--frames",
                         "must be between 1 and " + std::to_string(kMaxFrames));
    SceneRenderResult res;
    core::Stopwatch sw;
    // Validate everything cheap before the expensive load.
    json used;
    RenderOptions options = buildRenderOptions(scene, &used);
    res.method = {{"name", scene.method.name}, {"params", used}};

    core::Volume volume = loadSceneVolume(scene, progress);
    {
        std::ostringstream os;
        os << (scene.volume.phantom.empty() ? scene.volume.path.string()
                                            : "phantom '" + scene.volume.phantom + "'")
           << ": " << volume.dims().x << "x" << volume.dims().y << "x" << volume.dims().z << " "
           << core::toString(volume.type());
        res.stages.push_back({"load_volume", true, os.str(), sw.seconds()});
    }
    if (const std::uint64_t bad = volume.countNonFinite(); bad > 0)
        res.details["nonfinite_voxels"] = bad;  // rendered as the TF's lowest value

    sw.restart();
    const grid::BrickGrid grid = grid::BrickGrid::build(volume, progress);
    res.stages.push_back(
        {"brick_grid", true,
         std::to_string(grid.size()) + " bricks of " + std::to_string(grid::kBrickSize) + "^3",
         sw.seconds()});

    sw.restart();
    const optics::TransferFunction tf = buildTransferFunction(scene, volume);
    const RayCaster caster(volume, grid, tf, options);
    // Fit the camera to what the TF shows (clinical viewers frame the anatomy, not the air).
    const auto bounds = visibleWorldBounds(caster);
    const Camera camera(buildCameraSpec(scene.camera), bounds[0], bounds[1], scene.image.width,
                        scene.image.height);
    res.stages.push_back({"transfer_function", true,
                          "'" + tf.name() + "', " +
                              std::to_string(caster.majorants().nonEmptyCount()) + " of " +
                              std::to_string(caster.majorants().size()) + " bricks visible",
                          sw.seconds()});

    std::vector<double> frameSeconds;
    for (int f = 0; f < frames; ++f) {
        sw.restart();
        res.stats = {};
        res.film = caster.render(camera, progress, &res.stats);
        frameSeconds.push_back(sw.seconds());
    }
    std::vector<double> sorted = frameSeconds;
    std::sort(sorted.begin(), sorted.end());
    const double renderSeconds = sorted[sorted.size() / 2];
    if (frames > 1) res.details["frame_seconds"] = frameSeconds;
    res.stages.push_back({"render", true,
                          toString(options.mode) + " " + std::to_string(camera.width()) + "x" +
                              std::to_string(camera.height()),
                          renderSeconds});

    json points = json::array();
    for (const auto& p : tf.points())
        points.push_back({{"value", p.value},
                          {"color", {p.color.r, p.color.g, p.color.b}},
                          {"extinction", p.extinction}});
    res.details["transfer_function"] = {
        {"name", tf.name()},
        {"window", {{"level", tf.window().level}, {"width", tf.window().width}}},
        {"points", points}};
    if (options.mode == Mode::Isosurface) res.method["params"]["iso_value"] = caster.isoValue();
    res.details["volume"] = {{"dims", {volume.dims().x, volume.dims().y, volume.dims().z}},
                             {"type", std::string(core::toString(volume.type()))},
                             {"modality", std::string(core::toString(volume.modality))}};
    res.details["camera"] = {
        {"eye", {camera.eye().x, camera.eye().y, camera.eye().z}},
        {"forward", {camera.forward().x, camera.forward().y, camera.forward().z}},
        {"up", {camera.up().x, camera.up().y, camera.up().z}},
        {"projection",
         camera.projection() == Projection::Perspective ? "perspective" : "orthographic"},
        {"fov_y_deg", camera.fovY() * 180.0 / 3.14159265358979323846},
        {"ortho_height_mm", camera.orthoHeight()}};
    res.details["render"] = {{"step_voxels", options.stepVoxels},
                             {"step_mm", caster.stepMm()},
                             {"seed", options.seed},
                             {"termination", scene.render.termination},
                             {"threads", options.threads}};
    res.details["counters"] = {
        {"rays", res.stats.rays},
        {"samples", res.stats.samples},
        {"rays_terminated_early", res.stats.terminatedEarly},
        {"samples_per_second", renderSeconds > 0 ? double(res.stats.samples) / renderSeconds : 0.0},
        {"bricks", res.stats.bricksTotal},
        {"bricks_visible", res.stats.bricksNonEmpty}};
    return res;
}

json statsJson(const SceneRenderResult& r, double totalSeconds) {
    json stages = json::array();
    for (const auto& s : r.stages)
        stages.push_back(
            {{"name", s.name}, {"ran", s.ran}, {"reason", s.reason}, {"seconds", s.seconds}});
    json j = {{"stages", stages},
              {"total_seconds", totalSeconds},
              {"peak_rss_mb", core::peakRssMiB()},
              {"method", r.method}};
    for (auto it = r.details.begin(); it != r.details.end(); ++it) j[it.key()] = it.value();
    return j;
}

}  // namespace voxlight::render
