// SPDX-License-Identifier: MIT
#include "pipeline/scene_inputs.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>

#include "core/hash.h"
#include "core/phantoms.h"
#include "io/image.h"
#include "io/volume_io.h"
#include "lights/area_light.h"
#include "lights/environment_light.h"
#include "optics/presets.h"

namespace voxlight::pipeline {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {
/// Path, size and modification time of a file (nothing when it does not exist: the loader will
/// say so).
void addFileIdentity(core::Hasher& h, const fs::path& p) {
    std::error_code ec;
    h.add(p.string());
    const auto size = fs::file_size(p, ec);
    h.add(ec ? std::uint64_t(0) : std::uint64_t(size));
    const auto time = fs::last_write_time(p, ec);
    h.add(ec ? std::int64_t(0) : std::int64_t(time.time_since_epoch().count()));
}

/// The data file a detached header names (MetaImage "ElementDataFile = x.raw", NRRD
/// "data file: x.raw.gz"), resolved against the header's folder; empty when none (or LOCAL, a
/// file list or pattern: those are covered by the content hash only).
fs::path detachedDataFile(const fs::path& header) {
    std::string ext = header.extension().string();
    for (auto& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext != ".mhd" && ext != ".nhdr") return {};
    std::ifstream in(header);
    std::string line;
    // Headers are short; stop at a bound so a wrong extension on a big binary costs nothing.
    for (int n = 0; n < 256 && std::getline(in, line); ++n) {
        const bool mhd = line.rfind("ElementDataFile", 0) == 0;
        const bool nrrd = line.rfind("data file:", 0) == 0 || line.rfind("datafile:", 0) == 0;
        if (!mhd && !nrrd) continue;
        std::string v = line.substr(line.find(mhd ? '=' : ':') + 1);
        v.erase(0, v.find_first_not_of(" \t"));
        while (!v.empty() && (v.back() == ' ' || v.back() == '\r' || v.back() == '\t'))
            v.pop_back();
        if (v.empty() || v == "LOCAL" || v.find(' ') != std::string::npos) return {};
        const fs::path data(v);
        return data.is_absolute() ? data : header.parent_path() / data;
    }
    return {};
}
}  // namespace

void checkSceneVolumeExists(const io::Scene& scene) {
    const io::VolumeSource& src = scene.volume;
    // Named by the scene's file and key, with where a relative path was looked for (the reader
    // alone said "relative to the current directory" of a path taken from the scene's).
    std::error_code ec;
    if (src.phantom.empty() && !src.written.empty() && !std::filesystem::exists(src.path, ec))
        throw InputError(
            scene.source, src.key,
            "'" + src.written + "' does not exist" +
                (src.path.string() != src.written ? " (looked for " + src.path.string() + ")"
                                                  : std::string()),
            "a scene file's relative paths are taken from its directory, --set "
            "and command-line paths from the current one");
}

core::Volume loadSceneVolume(const io::Scene& scene, const core::Progress& progress) {
    const io::VolumeSource& src = scene.volume;
    if (!src.phantom.empty()) {
        core::PhantomOptions o;
        o.size = src.phantomSize;
        return core::makePhantom(src.phantom, o, progress);
    }
    checkSceneVolumeExists(scene);
    return io::readVolume(src.path, src.readOptions, progress);
}

std::uint64_t volumeIdentity(const io::Scene& scene) {
    const io::VolumeSource& src = scene.volume;
    core::Hasher h;
    h.add("volume-source.v1");
    if (!src.phantom.empty()) {
        h.add("phantom").add(src.phantom).add(src.phantomSize);
        return h.value();
    }
    const io::ReadOptions& o = src.readOptions;
    h.add(o.dicomSeriesUid).add(int(o.nonFinite)).add(o.raw.has_value()).add(o.strictGeometry);
    std::error_code ec;
    const fs::path path =
        fs::weakly_canonical(src.path, ec).empty() ? src.path : fs::weakly_canonical(src.path, ec);
    if (fs::is_directory(path, ec)) {
        // A DICOM series: every file of the directory (sorted, so the order is fixed).
        std::vector<fs::path> files;
        for (const auto& e : fs::directory_iterator(path, ec))
            if (e.is_regular_file(ec)) files.push_back(e.path());
        std::sort(files.begin(), files.end());
        for (const auto& f : files) addFileIdentity(h, f);
    } else {
        addFileIdentity(h, path);
        // A detached header's data file: replacing it changes the identity too.
        if (const fs::path data = detachedDataFile(path); !data.empty()) addFileIdentity(h, data);
    }
    return h.value();
}

optics::TransferFunction buildTransferFunction(const io::Scene& scene, const core::Volume& volume) {
    const io::TransferFunctionDesc& d = scene.transferFunction;
    optics::TransferFunction tf;
    if (!d.points.empty()) {
        std::vector<optics::TfPoint> pts;
        for (const auto& p : d.points)
            pts.push_back({float(p.value), glm::vec3(p.color), float(p.extinction),
                           glm::vec3(p.emission), glm::vec3(p.specular), float(p.roughness),
                           p.phaseG ? float(*p.phaseG) : optics::kNoPhaseG});
        const float lo = pts.front().value, hi = pts.back().value;
        optics::Window w{0.5f * (lo + hi), hi > lo ? hi - lo : 1.f};
        if (d.window) w = {float(d.window->x), float(d.window->y)};
        tf = optics::TransferFunction(std::move(pts), w, "custom");
    } else {
        const std::string name = d.preset.empty() ? optics::defaultPresetName(volume) : d.preset;
        const optics::PresetInfo* info = optics::findPreset(name);
        const bool relative = info && info->relative;
        // A relative preset spans the data's robust range — unless a window replaces it anyway
        // (withWindow below is affine in it): data near ±3.4e38 could not be windowed even with
        // an explicit window, whose error then blamed the user's valid window.
        std::array<float, 2> range{0.f, 1.f};
        if (relative && !d.window) {
            range = optics::robustRange(volume);
            if (!std::isfinite(range[1] - range[0]) || !std::isfinite(range[0] + range[1])) {
                std::ostringstream os;
                os << "the data's values span [" << range[0] << ", " << range[1]
                   << "], too wide to window in float arithmetic";
                throw InputError(scene.source, "transfer_function.window", os.str(),
                                 "set transfer_function.window to the values to show, or rescale "
                                 "the data");
            }
        }
        try {
            tf = optics::makePreset(name, range);
        } catch (const InputError& e) {
            throw InputError(scene.source, "transfer_function.preset", e.problem(), e.fix());
        }
        if (d.window) tf = tf.withWindow({float(d.window->x), float(d.window->y)});
    }
    if (d.extinctionScale != 1.0) tf = tf.scaledExtinction(float(d.extinctionScale));
    return tf;
}

std::string resolveView(const io::CameraDesc& desc, std::span<const glm::dvec3> points) {
    if (desc.view != "auto" || points.empty()) return desc.view == "auto" ? "anterior" : desc.view;
    glm::dvec3 lo(INFINITY), hi(-INFINITY);
    for (const glm::dvec3& p : points) lo = glm::min(lo, p), hi = glm::max(hi, p);
    const glm::dvec3 e = hi - lo;  // LPS: x left, y posterior, z superior
    const double anterior = e.x * e.z, superior = e.x * e.y, left = e.y * e.z;
    if (superior > kAutoViewAreaRatio * anterior && superior >= left) return "superior";
    if (left > kAutoViewAreaRatio * anterior) return "left";
    return "anterior";
}

render::CameraSpec buildCameraSpec(const io::CameraDesc& d) {
    render::CameraSpec s;
    s.projection = d.projection == "orthographic" ? render::Projection::Orthographic
                                                  : render::Projection::Perspective;
    s.azimuthDeg = d.azimuthDeg;
    s.elevationDeg = d.elevationDeg;
    s.rollDeg = d.rollDeg;
    s.distance = d.distance;
    s.fovYDeg = d.fovYDeg;
    s.orthoHeight = d.orthoHeight;
    s.target = d.target;
    s.eye = d.eye;
    s.up = d.up;
    s.margin = d.margin;
    return s;
}

void checkPresetName(const io::Scene& scene) {
    const std::string& preset = scene.transferFunction.preset;
    if (preset.empty()) return;
    if (optics::findPreset(preset)) return;
    throw InputError(scene.source, "transfer_function.preset", "'" + preset + "' is not a preset",
                     "choose one of: " + optics::presetList());
}

namespace {
/// Two unit tangents (t1, t2) with t1 × t2 = n.
std::pair<glm::dvec3, glm::dvec3> tangentFrame(const glm::dvec3& n) {
    const glm::dvec3 ref = std::abs(n.z) < 0.9 ? glm::dvec3(0, 0, 1) : glm::dvec3(1, 0, 0);
    const glm::dvec3 t1 = glm::normalize(glm::cross(ref, n));
    return {t1, glm::cross(n, t1)};
}

/// The last environment map built (the key: its file's identity, colour × intensity and layout),
/// kept so that a rotation alone does not read and project the map again.
struct EnvironmentMapCache {
    std::mutex mutex;
    std::uint64_t key = 0;
    std::shared_ptr<const lights::EnvironmentLight> light;
    std::size_t builds = 0, turns = 0;
};
EnvironmentMapCache& environmentMapCache() {
    static EnvironmentMapCache cache;
    return cache;
}

std::shared_ptr<const lights::Light> buildLight(const io::LightDesc& l) {
    const glm::vec3 power = glm::vec3(l.color * l.intensity);
    if (l.type == "directional")
        return std::make_shared<lights::DirectionalLight>(power, glm::vec3(-l.direction));
    if (l.type == "point")
        return std::make_shared<lights::PointLight>(power, l.position, l.minDistance);
    if (l.type == "area") {
        if (l.shape == "sphere")
            return std::make_shared<lights::SphereLight>(power, l.position, l.radius);
        if (l.shape == "disk")
            return std::make_shared<lights::DiskLight>(power, l.position, l.normal, l.radius);
        const auto [t1, t2] = tangentFrame(l.normal);
        const glm::dvec3 eu = l.size.x * t1, ev = l.size.y * t2;
        return std::make_shared<lights::RectLight>(power, l.position - 0.5 * (eu + ev), eu, ev);
    }
    // Environment: the map scaled per channel by colour × intensity. A turn of the same map (the
    // viewer's lights panel, a session's keyframes) reuses the map and its SH projection: only the
    // SH rotation is applied (EnvironmentLight::setRotation), no file read or projection.
    const glm::dvec3 r = glm::radians(l.rotationDeg);
    const glm::dmat3 rx(1, 0, 0, 0, std::cos(r.x), std::sin(r.x), 0, -std::sin(r.x), std::cos(r.x));
    const glm::dmat3 ry(std::cos(r.y), 0, -std::sin(r.y), 0, 1, 0, std::sin(r.y), 0, std::cos(r.y));
    const glm::dmat3 rz(std::cos(r.z), std::sin(r.z), 0, -std::sin(r.z), std::cos(r.z), 0, 0, 0, 1);
    const glm::dmat3 rotation = rz * ry * rx;  // x, then y, then z (extrinsic), as the scene says
    core::Hasher key;
    key.add("environment-map.v1").addPod(power).add(l.layout);
    addFileIdentity(key, l.path);
    EnvironmentMapCache& cache = environmentMapCache();
    {
        const std::lock_guard<std::mutex> lock(cache.mutex);
        if (cache.light && cache.key == key.value()) {
            auto turned = std::make_shared<lights::EnvironmentLight>(*cache.light);
            turned->setRotation(rotation);
            ++cache.turns;
            return turned;
        }
    }
    core::ImageRGBA image = io::readHdrImage(l.path);
    // The map's own bad texels name the file; colour × intensity pushing one past the radiance
    // limit names the light's fields (the constructor sees only the product).
    lights::EnvironmentLight::checkTexels(image, l.path.string(), power);
    for (std::size_t i = 0; i < image.pixels.size(); ++i)
        if (i % 4 != 3) image.pixels[i] *= power[int(i % 4)];
    lights::EnvironmentOptions o;
    o.layout = l.layout == "probe" ? lights::EnvironmentLayout::AngularProbe
                                   : lights::EnvironmentLayout::Equirect;
    o.rotation = rotation;
    auto light = std::make_shared<lights::EnvironmentLight>(image, o, l.path.string());
    const std::lock_guard<std::mutex> lock(cache.mutex);
    cache.key = key.value();
    cache.light = light;
    ++cache.builds;
    return light;
}
}  // namespace

EnvironmentMapCounts environmentMapCounts() {
    EnvironmentMapCache& cache = environmentMapCache();
    const std::lock_guard<std::mutex> lock(cache.mutex);
    return {cache.builds, cache.turns};
}

std::shared_ptr<const lights::Light> whiteSky() {
    core::ImageRGBA white(64, 32);
    for (float& v : white.pixels) v = 1.f;
    return std::make_shared<lights::EnvironmentLight>(white, lights::EnvironmentOptions{},
                                                      "white sky");
}

std::vector<std::shared_ptr<const lights::Light>> buildLights(const io::Scene& scene) {
    std::vector<std::shared_ptr<const lights::Light>> out;
    for (std::size_t i = 0; i < scene.lights.size(); ++i) {
        // A missing map named only the file ("./courtyrd.hdr: file: does not exist"): the scene
        // and its key, as a missing volume is.
        const io::LightDesc& l = scene.lights[i];
        std::error_code ec;
        if (l.type == "environment" && !std::filesystem::exists(l.path, ec))
            throw InputError(scene.source, "lights[" + std::to_string(i) + "].path",
                             "names '" + l.path.string() + "', which does not exist",
                             "check the path (a scene file's relative paths are taken from its "
                             "folder, --set's from the current one)");
        try {
            out.push_back(buildLight(scene.lights[i]));
        } catch (const InputError& e) {
            // A file's own errors (environment map) name the file; the lights library names
            // its field: map it to the scene key.
            if (e.source() == "light")
                throw InputError(scene.source, "lights[" + std::to_string(i) + "]." + e.field(),
                                 e.problem(), e.fix());
            throw;
        }
    }
    return out;
}

std::uint64_t lightsIdentity(const io::Scene& scene) {
    core::Hasher h;
    h.add("lights.v1");
    for (const auto& l : scene.lights) {
        h.add(l.type).addPod(l.color).add(l.intensity).addPod(l.direction).addPod(l.position);
        h.add(l.minDistance).add(l.shape).addPod(l.normal).add(l.radius).addPod(l.size);
        h.addPod(l.rotationDeg).add(l.layout);
        if (l.type == "environment") addFileIdentity(h, l.path);
    }
    return h.value();
}

std::uint64_t environmentLightsIdentity(const io::Scene& scene) {
    core::Hasher h;
    h.add("environment-lights.v1");
    for (const auto& l : scene.lights) {
        if (l.type != "environment") continue;
        h.addPod(l.color).add(l.intensity).addPod(l.rotationDeg).add(l.layout);
        addFileIdentity(h, l.path);
    }
    return h.value();
}

bool hasEnvironmentLight(const io::Scene& scene) {
    return std::any_of(scene.lights.begin(), scene.lights.end(),
                       [](const io::LightDesc& l) { return l.type == "environment"; });
}

}  // namespace voxlight::pipeline
