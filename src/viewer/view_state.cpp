// SPDX-License-Identifier: MIT
#include "viewer/view_state.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <glm/gtc/quaternion.hpp>

#include "core/error.h"

namespace voxlight::viewer {

namespace {
using nlohmann::json;

glm::dvec3 vec3(const json& j, const char* key) {
    if (!j.contains(key) || !j[key].is_array() || j[key].size() != 3)
        throw InternalError(std::string("rendered camera lacks '") + key + "'");
    return {j[key][0].get<double>(), j[key][1].get<double>(), j[key][2].get<double>()};
}
json array(const glm::dvec3& v) { return json::array({v.x, v.y, v.z}); }
glm::dvec3 rotate(const glm::dvec3& v, const glm::dvec3& axis, double radians) {
    return glm::angleAxis(radians, glm::normalize(axis)) * v;
}
/// Keys of a camera that describe the lens, not its placement (kept across edits).
constexpr const char* kLensKeys[] = {"aperture", "focus_distance"};
}  // namespace

LookAt lookAtFromRendered(const json& camera, const glm::dvec3& pivot) {
    LookAt c;
    c.eye = vec3(camera, "eye");
    const glm::dvec3 forward = glm::normalize(vec3(camera, "forward"));
    c.up = glm::normalize(vec3(camera, "up"));
    c.perspective = camera.value("projection", std::string("perspective")) == "perspective";
    c.fovYDeg = camera.value("fov_y_deg", 30.0);
    c.orthoHeight = camera.value("ortho_height_mm", 100.0);
    // The target on the view axis at the pivot's depth (at least 1 mm in front of the eye).
    const double depth = std::max(glm::dot(pivot - c.eye, forward), 1.0);
    c.target = c.eye + depth * forward;
    return c;
}

void orbit(LookAt& c, double yawDeg, double pitchDeg) {
    const glm::dvec3 superior{0.0, 0.0, 1.0};
    glm::dvec3 offset = c.eye - c.target;
    glm::dvec3 up = c.up;
    // Yaw about the world superior axis through the target.
    const double yaw = glm::radians(yawDeg);
    offset = rotate(offset, superior, yaw);
    up = rotate(up, superior, yaw);
    // Pitch about the image's right axis, stopping short of the poles.
    const double r = glm::length(offset);
    const glm::dvec3 forward = -offset / r;
    const glm::dvec3 right = glm::normalize(glm::cross(forward, up));
    const double elevation = std::asin(std::clamp(offset.z / r, -1.0, 1.0));
    const double limit = glm::radians(89.0);
    const double target = std::clamp(elevation + glm::radians(pitchDeg), -limit, limit);
    const double pitch = target - elevation;
    offset = rotate(offset, right, -pitch);
    up = rotate(up, right, -pitch);
    c.eye = c.target + offset;
    // Re-orthogonalise the up vector against the new view direction.
    const glm::dvec3 f = glm::normalize(c.target - c.eye);
    c.up = glm::normalize(up - glm::dot(up, f) * f);
}

void pan(LookAt& c, double dx, double dy, int viewportHeight) {
    const glm::dvec3 f = glm::normalize(c.target - c.eye);
    const glm::dvec3 right = glm::normalize(glm::cross(f, c.up));
    const glm::dvec3 up = glm::cross(right, f);
    const double viewHeight =
        c.perspective ? 2.0 * glm::length(c.target - c.eye) * std::tan(glm::radians(c.fovYDeg) / 2)
                      : c.orthoHeight;
    const double mmPerPixel = viewHeight / std::max(viewportHeight, 1);
    // Dragging right moves the picture right: the camera moves left.
    const glm::dvec3 shift = (-dx * right + dy * up) * mmPerPixel;
    c.eye += shift;
    c.target += shift;
}

bool zoom(LookAt& c, double factor) {
    constexpr double kMaxMm = 1e6, kMinEyeDistanceMm = 1e-6;  // the scene's bounds (io/scene.cpp)
    if (!(factor > 0.0) || !std::isfinite(factor)) return false;
    if (c.perspective) {
        const glm::dvec3 offset = (c.eye - c.target) / factor;
        const double d = glm::length(offset);
        const glm::dvec3 eye = c.target + offset;
        const glm::dvec3 a = glm::abs(eye);
        if (!(d >= kMinEyeDistanceMm) || !(std::max({a.x, a.y, a.z}) <= kMaxMm)) return false;
        c.eye = eye;
        return true;
    }
    const double h = c.orthoHeight / factor;
    if (!(h >= io::kMinOrthoHeightMm && h <= kMaxMm)) return false;
    c.orthoHeight = h;
    return true;
}

json cameraJson(const LookAt& c, const json& previous) {
    json j = {{"projection", c.perspective ? "perspective" : "orthographic"},
              {"eye", array(c.eye)},
              {"target", array(c.target)},
              {"up", array(c.up)}};
    if (c.perspective)
        j["fov_y"] = c.fovYDeg;
    else
        j["ortho_height"] = c.orthoHeight;
    for (const char* k : kLensKeys)
        if (previous.is_object() && previous.contains(k)) j[k] = previous[k];
    return j;
}

json namedViewJson(const std::string& view, const json& previous) {
    json j = {{"view", view}};
    for (const char* k : {"projection", "fov_y", "margin", "aperture", "focus_distance"})
        if (previous.is_object() && previous.contains(k)) j[k] = previous[k];
    return j;
}

optics::Window dragWindow(const optics::Window& start, double dx, double dy) {
    optics::Window w;
    w.width = float(start.width * std::exp2(dx / 200.0));
    w.level = float(start.level + dy * start.width / 400.0);
    return w;
}

json transferFunctionJson(const optics::TransferFunction& tf) {
    json points = json::array();
    for (const optics::TfPoint& p : tf.points()) {
        json q = {{"value", p.value},
                  {"color", {p.color.r, p.color.g, p.color.b}},
                  {"extinction", p.extinction},
                  {"emission", {p.emission.r, p.emission.g, p.emission.b}},
                  {"specular", {p.specular.r, p.specular.g, p.specular.b}},
                  {"roughness", p.roughness}};
        if (!std::isnan(p.phaseG)) q["phase_g"] = p.phaseG;
        points.push_back(q);
    }
    return {{"points", points},
            {"window", {{"level", tf.window().level}, {"width", tf.window().width}}}};
}

io::Scene coarseScene(const io::Scene& full, int factor, double stepScale, double termination) {
    json doc = full.document;
    doc["image"]["width"] = std::max(16, full.image.width / std::max(factor, 1));
    doc["image"]["height"] = std::max(16, full.image.height / std::max(factor, 1));
    doc["render"]["step"] = full.render.stepVoxels * stepScale;
    doc["render"]["termination"] = std::max(full.render.termination, termination);
    return sceneFromDocument(doc, full.source);
}

io::Scene sceneFromDocument(const json& doc, const std::string& source) {
    return io::parseScene(doc, source, "/");
}

glm::dvec3 towardLight(double azimuthDeg, double elevationDeg) {
    const double az = glm::radians(azimuthDeg), el = glm::radians(elevationDeg);
    return {std::sin(az) * std::cos(el), -std::cos(az) * std::cos(el), std::sin(el)};
}

glm::dvec2 lightAngles(const glm::dvec3& toward) {
    const double len = glm::length(toward);
    if (!(len > 0.0)) return {0.0, 0.0};
    const glm::dvec3 t = toward / len;
    const double el = glm::degrees(std::asin(std::clamp(t.z, -1.0, 1.0)));
    const double horizontal = std::hypot(t.x, t.y);
    const double az = horizontal > 1e-12 ? glm::degrees(std::atan2(t.x, -t.y)) : 0.0;
    return {az == -180.0 ? 180.0 : az, el};
}

glm::dvec2 lightAnglesOf(const io::LightDesc& light, const glm::dvec3& pivot) {
    if (light.type == "directional") return lightAngles(-light.direction);
    if (light.type == "environment") return {light.rotationDeg.z, light.rotationDeg.x};
    return lightAngles(light.position - pivot);
}

void setLightAngles(io::LightDesc& light, const glm::dvec2& anglesDeg, const glm::dvec3& pivot) {
    // Azimuth into (−180, 180], elevation into [−90, 90].
    double az = std::remainder(anglesDeg.x, 360.0);
    if (az == -180.0) az = 180.0;
    const double el = std::clamp(anglesDeg.y, -90.0, 90.0);
    const glm::dvec3 toward = towardLight(az, el);
    if (light.type == "directional") {
        light.direction = -toward;
    } else if (light.type == "environment") {
        light.rotationDeg.z = az;
        light.rotationDeg.x = el;
    } else {
        // Point and area lights keep their distance from the pivot (at least 1 mm).
        const double d = std::max(glm::length(light.position - pivot), 1.0);
        light.position = pivot + d * toward;
        if (light.type == "area") light.normal = -toward;
    }
}

void turnLight(io::LightDesc& light, double dAzimuthDeg, double dElevationDeg,
               const glm::dvec3& pivot) {
    const glm::dvec2 a = lightAnglesOf(light, pivot);
    // As the camera's orbit, turning stops 1° short of the poles so the azimuth stays defined.
    double el = a.y;
    if (dElevationDeg != 0.0) el = std::clamp(a.y + dElevationDeg, -89.0, 89.0);
    setLightAngles(light, {a.x + dAzimuthDeg, el}, pivot);
}

io::LightDesc newLight(const std::string& type, const glm::dvec3& pivot, double distanceMm,
                       const std::string& path, const std::string& source,
                       const std::string& field) {
    io::LightDesc l;
    l.type = type;
    if (type == "point") {
        if (!(distanceMm > 0.0) || !std::isfinite(distanceMm))
            throw InputError(source, field + ".distance", "must be a finite distance > 0 mm");
        l.position = pivot + glm::dvec3(0.0, -distanceMm, 0.0);  // turned into place below
        // Irradiance 1 at the pivot, as a directional light of intensity 1 (W/sr, 1/d² in mm).
        l.intensity = distanceMm * distanceMm;
    } else if (type == "environment") {
        if (path.empty())
            throw InputError(source, field + ".path", "an environment light needs a map",
                             "give the path of an .hdr or .exr environment map");
        if (!std::filesystem::is_regular_file(path))
            throw InputError(source, field + ".path", "'" + path + "' is not a file",
                             "give the path of an .hdr or .exr environment map");
        l.path = path;
    } else if (type != "directional") {
        throw InputError(source, field + ".type", "'" + type + "' is not a light the viewer adds",
                         "use directional, point or environment");
    }
    if (type != "environment") setLightAngles(l, {45.0, 30.0}, pivot);
    return l;
}

nlohmann::json lightsJson(const std::vector<io::LightDesc>& lights) {
    json j = json::array();
    for (const io::LightDesc& l : lights) j.push_back(io::lightDocument(l));
    return j;
}

io::ClipPlaneDesc clipPlaneThrough(const glm::dvec3& normal, const glm::dvec3& centre,
                                   double offsetMm, const std::string& source,
                                   const std::string& field) {
    const double len = glm::length(normal);
    if (!(len > 1e-12) || !std::isfinite(len))
        throw InputError(source, field, "must be a non-zero, finite normal");
    if (!std::isfinite(offsetMm)) throw InputError(source, field, "offset must be finite");
    io::ClipPlaneDesc p;
    p.normal = normal / len;
    p.point = centre + offsetMm * p.normal;
    return p;
}

void moveClipPlane(io::ClipPlaneDesc& plane, double mm) { plane.point += mm * plane.normal; }

void flipClipPlane(io::ClipPlaneDesc& plane) { plane.normal = -plane.normal; }

nlohmann::json clipPlanesJson(const std::vector<ViewClipPlane>& planes) {
    json j = json::array();
    for (const ViewClipPlane& p : planes)
        if (p.enabled) j.push_back(io::clipPlaneDocument(p.plane));
    return j;
}

std::vector<glm::dvec3> clipOutline(const io::ClipPlaneDesc& plane, const core::Geometry& g) {
    // The box's corners (voxel centres) and the plane's signed distance at each.
    const glm::dvec3 last = glm::dvec3(glm::max(g.dims - 1, glm::ivec3(0)));
    std::array<glm::dvec3, 8> corner;
    std::array<double, 8> dist;
    for (int i = 0; i < 8; ++i) {
        const glm::dvec3 ijk(i & 1 ? last.x : 0.0, i & 2 ? last.y : 0.0, i & 4 ? last.z : 0.0);
        corner[i] = g.indexToWorld(ijk);
        dist[i] = glm::dot(corner[i] - plane.point, plane.normal);
    }
    // Where the twelve edges cross the plane (an edge in the plane contributes its ends).
    std::vector<glm::dvec3> pts;
    const auto add = [&](const glm::dvec3& p) {
        for (const glm::dvec3& q : pts)
            if (glm::length(p - q) < 1e-9 * (1.0 + glm::length(p))) return;
        pts.push_back(p);
    };
    for (int a = 0; a < 8; ++a)
        for (int bit = 1; bit < 8; bit <<= 1) {
            if (a & bit) continue;
            const int b = a | bit;
            if (dist[a] == 0.0) add(corner[a]);
            if (dist[b] == 0.0) add(corner[b]);
            if ((dist[a] < 0.0 && dist[b] > 0.0) || (dist[a] > 0.0 && dist[b] < 0.0))
                add(corner[a] + (corner[b] - corner[a]) * (dist[a] / (dist[a] - dist[b])));
        }
    if (pts.size() < 3) return {};
    // Order the corners by their angle about the centroid, in a basis of the plane.
    glm::dvec3 c(0.0);
    for (const glm::dvec3& p : pts) c += p;
    c /= double(pts.size());
    const glm::dvec3 n = plane.normal;
    const glm::dvec3 u = glm::normalize(
        glm::cross(n, std::abs(n.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0)));
    const glm::dvec3 v = glm::cross(n, u);
    std::sort(pts.begin(), pts.end(), [&](const glm::dvec3& p, const glm::dvec3& q) {
        return std::atan2(glm::dot(p - c, v), glm::dot(p - c, u)) <
               std::atan2(glm::dot(q - c, v), glm::dot(q - c, u));
    });
    return pts;
}

render::Camera projectionCamera(const LookAt& c, int width, int height) {
    render::CameraSpec spec;
    spec.projection =
        c.perspective ? render::Projection::Perspective : render::Projection::Orthographic;
    spec.eye = c.eye;
    spec.target = c.target;
    spec.up = c.up;
    spec.fovYDeg = c.fovYDeg;
    spec.orthoHeight = c.orthoHeight;
    // Nothing is fitted (the eye and the ortho height are given): the box is not used.
    return render::Camera(spec, c.target - 1.0, c.target + 1.0, std::max(width, 1),
                          std::max(height, 1));
}

double clipDragMm(const io::ClipPlaneDesc& plane, const glm::dvec3& handle,
                  const render::Camera& camera, double dx, double dy) {
    // Millimetres per image pixel at the handle's depth.
    const double depth = glm::dot(handle - camera.eye(), camera.forward());
    const double viewHeight = camera.projection() == render::Projection::Perspective
                                  ? 2.0 * std::max(depth, 1e-3) * std::tan(camera.fovY() / 2)
                                  : camera.orthoHeight();
    const double mmPerPixel = viewHeight / camera.height();
    // The image direction of the normal: where the handle goes when the plane moves `step` mm.
    constexpr double kProbePixels = 20.0;
    const double step = kProbePixels * mmPerPixel;
    double x0, y0, x1, y1;
    if (camera.project(handle, x0, y0) && camera.project(handle + step * plane.normal, x1, y1)) {
        const glm::dvec2 s(x1 - x0, y1 - y0);
        // Degenerate below sin 10° of the probe's length: the normal is nearly along the view.
        constexpr double kMinFraction = 0.17;
        if (glm::length(s) >= kMinFraction * kProbePixels)
            return glm::dot(glm::dvec2(dx, dy), s) / glm::dot(s, s) * step;
    }
    const double along = glm::dot(plane.normal, camera.forward()) >= 0.0 ? 1.0 : -1.0;
    return -dy * mmPerPixel * along;
}

bool switchShVisibility(nlohmann::json& doc, bool global, nlohmann::json& stash) {
    if (!doc.contains("method")) return false;
    nlohmann::json& m = doc["method"];
    if (m.is_string()) m = {{"name", m}, {"params", nlohmann::json::object()}};
    if (!m.is_object() || !m.contains("name")) return false;
    const std::string name = m["name"].get<std::string>();
    if ((name != "sh-local" && name != "sh-global") || (name == "sh-global") == global)
        return false;
    if (!m.contains("params") || !m["params"].is_object()) m["params"] = nlohmann::json::object();
    nlohmann::json& params = m["params"];
    if (!stash.is_object()) stash = nlohmann::json::object();
    for (const char* k : {"global_resolution", "global_near", "global_integration"}) {
        if (global) {
            if (stash.contains(k)) params[k] = stash[k];
        } else if (params.contains(k)) {
            stash[k] = params[k];
            params.erase(k);
        }
    }
    m["name"] = global ? "sh-global" : "sh-local";
    // An effects list follows the method: sh-global casts global_shadows, sh-local cannot (each
    // refuses the other's list).
    if (doc.contains("effects") && doc["effects"].is_array()) {
        nlohmann::json effects = nlohmann::json::array();
        for (const auto& e : doc["effects"])
            if (e != "global_shadows" && e != "local_shadows") effects.push_back(e);
        effects.push_back("local_shadows");
        if (global) effects.push_back("global_shadows");
        doc["effects"] = effects;
    }
    return true;
}

nlohmann::json pathTraceEffects(const nlohmann::json& effects) {
    if (!effects.is_array()) return effects;
    nlohmann::json out = nlohmann::json::array();
    bool shadows = false;
    for (const auto& e : effects) {
        if (e == "local_shadows" || e == "global_shadows")
            shadows = true;
        else if (e == "multiple_scattering")
            out.push_back(e);
    }
    if (shadows) out.push_back("global_shadows");
    return out;
}

std::vector<ScriptStep> parseScript(const nlohmann::json& doc, const std::string& source) {
    if (!doc.is_array())
        throw InputError(source, "script", "must be a JSON array of steps",
                         R"(write e.g. [{"orbit": [40, 0]}, {"view": "L"}])");
    static const char* const kSteps =
        "orbit, pan, zoom, window, drag, view, pathtrace, clip_add, clip_move, clip_drag, "
        "clip_edit, "
        "clip_remove, light_add, light_edit, light_turn, light_remove, gizmo, drop or shading";
    std::vector<ScriptStep> steps;
    for (std::size_t i = 0; i < doc.size(); ++i) {
        const nlohmann::json& e = doc[i];
        const std::string at = "[" + std::to_string(i) + "]";
        if (!e.is_object() || e.size() != 1)
            throw InputError(source, at, "must be an object with one key", kSteps);
        const std::string key = e.begin().key();
        const nlohmann::json& v = e.begin().value();
        const std::string field = at + "." + key;
        auto number = [&](const nlohmann::json& x, const std::string& f) {
            if (!x.is_number() || !std::isfinite(x.get<double>()))
                throw InputError(source, f, "must hold finite numbers");
            return x.get<double>();
        };
        auto number3 = [&](const nlohmann::json& x, const std::string& f) {
            if (!x.is_array() || x.size() != 3)
                throw InputError(source, f, "must be [x, y, z] (three numbers)");
            return glm::dvec3(number(x[0], f), number(x[1], f), number(x[2], f));
        };
        // A whole number in [lo, hi].
        auto whole = [&](const nlohmann::json& x, const std::string& f, double lo, double hi) {
            const double n = number(x, f);
            if (n != std::floor(n) || n < lo || n > hi)
                throw InputError(source, f,
                                 "must be a whole number in " + std::to_string(int(lo)) + "…" +
                                     std::to_string(int(hi)) + ", got " + x.dump());
            return int(n);
        };
        auto boolean = [&](const nlohmann::json& x, const std::string& f) {
            if (!x.is_boolean()) throw InputError(source, f, "must be true or false");
            return x.get<bool>();
        };
        // An object step's keys: only `allowed`, every one of `required`.
        auto object = [&](std::initializer_list<const char*> allowed,
                          std::initializer_list<const char*> required) {
            std::string list;
            for (const char* k : allowed) list += std::string(list.empty() ? "" : ", ") + k;
            if (!v.is_object()) throw InputError(source, field, "must be an object", list);
            for (const auto& item : v.items()) {
                const std::string& k = item.key();
                if (std::find_if(allowed.begin(), allowed.end(),
                                 [&](const char* a) { return k == a; }) == allowed.end())
                    throw InputError(source, field + "." + k, "is not a key of " + key,
                                     "use " + list);
            }
            for (const char* k : required)
                if (!v.contains(k))
                    throw InputError(source, field, std::string("needs '") + k + "'");
        };
        constexpr double kMaxIndex = 1000;
        ScriptStep st;
        st.source = source;
        st.field = field;
        if (key == "orbit" || key == "pan" || key == "window") {
            if (!v.is_array() || v.size() != 2)
                throw InputError(source, field, "must be [dx, dy] in pixels");
            st.kind = key == "orbit" ? ScriptStep::Kind::Orbit
                      : key == "pan" ? ScriptStep::Kind::Pan
                                     : ScriptStep::Kind::Window;
            st.a = number(v[0], field), st.b = number(v[1], field);
        } else if (key == "zoom") {
            st.kind = ScriptStep::Kind::Zoom;
            st.a = number(v, field);
        } else if (key == "pathtrace") {
            st.kind = ScriptStep::Kind::PathTrace;
            st.a = number(v, field);
            if (!(st.a >= 1 && st.a <= 65536) || st.a != std::floor(st.a))
                throw InputError(source, at + ".pathtrace", "must be a whole spp, 1…65536");
        } else if (key == "view") {
            static const std::vector<std::pair<std::string, std::string>> keys = {
                {"A", "anterior"}, {"P", "posterior"}, {"L", "left"},
                {"R", "right"},    {"S", "superior"},  {"I", "inferior"}};
            if (!v.is_string()) throw InputError(source, at + ".view", "must be a view name");
            st.kind = ScriptStep::Kind::View;
            st.view = v.get<std::string>();
            for (const auto& [k, name] : keys)
                if (st.view == k) st.view = name;
            if (!io::findView(st.view))
                throw InputError(source, at + ".view", "'" + st.view + "' is not a named view",
                                 "use A, P, L, R, S, I or anterior, posterior, left, right, "
                                 "superior, inferior");
        } else if (key == "clip_add") {
            st.kind = ScriptStep::Kind::ClipAdd;
            object({"normal", "offset", "shadows_from_removed"}, {"normal"});
            const json& n = v["normal"];
            if (n.is_string()) {
                if (n.get<std::string>() != "camera")
                    throw InputError(source, field + ".normal",
                                     "must be [x, y, z] or \"camera\", got " + n.dump());
                st.facingCamera = true;
            } else {
                st.vec = number3(n, field + ".normal");
                if (!(glm::length(st.vec) > 1e-12))
                    throw InputError(source, field + ".normal", "must not be [0, 0, 0]");
            }
            if (v.contains("offset")) st.a = number(v["offset"], field + ".offset");
            if (v.contains("shadows_from_removed"))
                st.shadowsFromRemoved =
                    boolean(v["shadows_from_removed"], field + ".shadows_from_removed");
        } else if (key == "clip_move") {
            st.kind = ScriptStep::Kind::ClipMove;
            object({"index", "by"}, {"index", "by"});
            st.index = whole(v["index"], field + ".index", 0, kMaxIndex);
            st.a = number(v["by"], field + ".by");
        } else if (key == "clip_drag") {
            st.kind = ScriptStep::Kind::ClipDrag;
            object({"index", "by", "frames"}, {"index", "by"});
            st.index = whole(v["index"], field + ".index", 0, kMaxIndex);
            const json& by = v["by"];
            if (!by.is_array() || by.size() != 2)
                throw InputError(source, field + ".by", "must be [dx, dy] in pixels");
            st.a = number(by[0], field + ".by"), st.b = number(by[1], field + ".by");
            if (v.contains("frames")) st.frames = whole(v["frames"], field + ".frames", 1, 10000);
        } else if (key == "drag") {
            st.kind = ScriptStep::Kind::Drag;
            object({"kind", "by", "frames"}, {"kind", "by"});
            const json& kind = v["kind"];
            if (!kind.is_string() || (kind != "orbit" && kind != "pan" && kind != "window"))
                throw InputError(source, field + ".kind",
                                 "must be \"orbit\", \"pan\" or \"window\"");
            st.dragMotion = kind == "orbit" ? ScriptStep::Kind::Orbit
                            : kind == "pan" ? ScriptStep::Kind::Pan
                                            : ScriptStep::Kind::Window;
            const json& by = v["by"];
            if (!by.is_array() || by.size() != 2)
                throw InputError(source, field + ".by", "must be [dx, dy] in pixels");
            st.a = number(by[0], field + ".by"), st.b = number(by[1], field + ".by");
            if (v.contains("frames")) st.frames = whole(v["frames"], field + ".frames", 1, 10000);
        } else if (key == "clip_edit") {
            st.kind = ScriptStep::Kind::ClipEdit;
            object({"index", "flip", "enabled", "shadows_from_removed"}, {"index"});
            if (v.size() < 2)
                throw InputError(source, field, "changes nothing",
                                 "give flip, enabled or shadows_from_removed");
            st.index = whole(v["index"], field + ".index", 0, kMaxIndex);
            if (v.contains("flip")) {
                st.flip = boolean(v["flip"], field + ".flip");
                if (!st.flip)
                    throw InputError(source, field + ".flip", "must be true when given",
                                     "leave it out to keep the plane's side");
            }
            if (v.contains("enabled")) st.enabled = boolean(v["enabled"], field + ".enabled");
            if (v.contains("shadows_from_removed"))
                st.shadowsFromRemoved =
                    boolean(v["shadows_from_removed"], field + ".shadows_from_removed");
        } else if (key == "clip_remove" || key == "light_remove") {
            st.kind =
                key == "clip_remove" ? ScriptStep::Kind::ClipRemove : ScriptStep::Kind::LightRemove;
            st.index = whole(v, field, 0, kMaxIndex);
        } else if (key == "light_add" || key == "light_edit") {
            const bool add = key == "light_add";
            st.kind = add ? ScriptStep::Kind::LightAdd : ScriptStep::Kind::LightEdit;
            if (add)
                object({"type", "azimuth", "elevation", "distance", "color", "intensity", "path"},
                       {"type"});
            else
                object({"index", "azimuth", "elevation", "position", "color", "intensity"},
                       {"index"});
            if (add) {
                if (!v["type"].is_string())
                    throw InputError(source, field + ".type", "must be a string",
                                     "directional, point or environment");
                st.lightType = v["type"].get<std::string>();
                if (st.lightType != "directional" && st.lightType != "point" &&
                    st.lightType != "environment")
                    throw InputError(source, field + ".type",
                                     "'" + st.lightType + "' is not a light the viewer adds",
                                     "use directional, point or environment");
                if (v.contains("path")) {
                    if (!v["path"].is_string() || v["path"].get<std::string>().empty())
                        throw InputError(source, field + ".path", "must be a file path");
                    st.path = v["path"].get<std::string>();
                }
                if (st.lightType == "environment" && st.path.empty())
                    throw InputError(source, field + ".path", "an environment light needs a map",
                                     "give the path of an .hdr or .exr environment map");
                if (st.lightType != "environment" && v.contains("path"))
                    throw InputError(source, field + ".path", "is for environment lights only");
                if (v.contains("distance")) {
                    if (st.lightType != "point")
                        throw InputError(source, field + ".distance", "is for point lights only");
                    st.distance = number(v["distance"], field + ".distance");
                    if (!(*st.distance > 0.0))
                        throw InputError(source, field + ".distance", "must be > 0 mm");
                }
            } else {
                if (v.size() < 2)
                    throw InputError(source, field, "changes nothing",
                                     "give azimuth, elevation, position, color or intensity");
                st.index = whole(v["index"], field + ".index", 0, kMaxIndex);
                if (v.contains("position"))
                    st.position = number3(v["position"], field + ".position");
            }
            if (v.contains("azimuth")) st.azimuth = number(v["azimuth"], field + ".azimuth");
            if (v.contains("elevation")) {
                st.elevation = number(v["elevation"], field + ".elevation");
                if (std::abs(*st.elevation) > 90.0)
                    throw InputError(source, field + ".elevation",
                                     "must be in [-90, 90] degrees, got " + v["elevation"].dump());
            }
            if (v.contains("color")) {
                st.color = number3(v["color"], field + ".color");
                if (glm::any(glm::lessThan(*st.color, glm::dvec3(0.0))))
                    throw InputError(source, field + ".color", "must be ≥ 0 (linear RGB)");
            }
            if (v.contains("intensity")) {
                st.intensity = number(v["intensity"], field + ".intensity");
                if (*st.intensity < 0.0)
                    throw InputError(source, field + ".intensity", "must be ≥ 0");
            }
        } else if (key == "light_turn") {
            st.kind = ScriptStep::Kind::LightTurn;
            object({"index", "azimuth", "elevation"}, {"index"});
            if (v.size() < 2)
                throw InputError(source, field, "turns nothing", "give azimuth and/or elevation");
            st.index = whole(v["index"], field + ".index", 0, kMaxIndex);
            if (v.contains("azimuth")) st.a = number(v["azimuth"], field + ".azimuth");
            if (v.contains("elevation")) st.b = number(v["elevation"], field + ".elevation");
        } else if (key == "gizmo") {
            st.kind = ScriptStep::Kind::Gizmo;
            st.a = boolean(v, field) ? 1.0 : 0.0;
        } else if (key == "shading") {
            st.kind = ScriptStep::Kind::Shading;
            if (!v.is_string() || (v != "local" && v != "global"))
                throw InputError(source, field, "must be \"local\" or \"global\"");
            st.view = v.get<std::string>();
        } else if (key == "drop") {
            constexpr std::size_t kMaxDropped = 64;
            st.kind = ScriptStep::Kind::Drop;
            if (!v.is_array() || v.empty() || v.size() > kMaxDropped)
                throw InputError(source, field, "must be an array of 1…64 paths",
                                 R"(write e.g. {"drop": ["ct.nii.gz"]})");
            for (const auto& x : v) {
                if (!x.is_string() || x.get<std::string>().empty())
                    throw InputError(source, field, "must hold non-empty path strings");
                st.paths.push_back(x.get<std::string>());
            }
        } else {
            throw InputError(source, field, "is not a script step", "use " + std::string(kSteps));
        }
        steps.push_back(st);
    }
    return steps;
}

}  // namespace voxlight::viewer
