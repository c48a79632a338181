// SPDX-License-Identifier: MIT
#include "viewer/view_state.h"

#include <algorithm>
#include <cmath>
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

void zoom(LookAt& c, double factor) {
    if (!(factor > 0.0)) return;
    if (c.perspective)
        c.eye = c.target + (c.eye - c.target) / factor;
    else
        c.orthoHeight /= factor;
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

std::vector<ScriptStep> parseScript(const nlohmann::json& doc, const std::string& source) {
    if (!doc.is_array())
        throw InputError(source, "script", "must be a JSON array of steps",
                         R"(write e.g. [{"orbit": [40, 0]}, {"view": "L"}])");
    std::vector<ScriptStep> steps;
    for (std::size_t i = 0; i < doc.size(); ++i) {
        const nlohmann::json& e = doc[i];
        const std::string at = "[" + std::to_string(i) + "]";
        if (!e.is_object() || e.size() != 1)
            throw InputError(source, at, "must be an object with one key",
                             "orbit, pan, zoom, window, view or pathtrace");
        const std::string key = e.begin().key();
        const nlohmann::json& v = e.begin().value();
        auto number = [&](const nlohmann::json& x) {
            if (!x.is_number() || !std::isfinite(x.get<double>()))
                throw InputError(source, at + "." + key, "must hold finite numbers");
            return x.get<double>();
        };
        ScriptStep st;
        if (key == "orbit" || key == "pan" || key == "window") {
            if (!v.is_array() || v.size() != 2)
                throw InputError(source, at + "." + key, "must be [dx, dy] in pixels");
            st.kind = key == "orbit" ? ScriptStep::Kind::Orbit
                      : key == "pan" ? ScriptStep::Kind::Pan
                                     : ScriptStep::Kind::Window;
            st.a = number(v[0]), st.b = number(v[1]);
        } else if (key == "zoom") {
            st.kind = ScriptStep::Kind::Zoom;
            st.a = number(v);
        } else if (key == "pathtrace") {
            st.kind = ScriptStep::Kind::PathTrace;
            st.a = number(v);
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
        } else {
            throw InputError(source, at + "." + key, "is not a script step",
                             "use orbit, pan, zoom, window, view or pathtrace");
        }
        steps.push_back(st);
    }
    return steps;
}

}  // namespace voxlight::viewer
