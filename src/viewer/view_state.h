// SPDX-License-Identifier: MIT
#pragma once
// The viewer's state as scene edits: what the mouse and the panels change, written back into the
// scene document (io/scene.h) that the worker renders. Nothing here knows about windows or GL, so
// the same code paths can be driven by tests.
//
// Camera: a scene starts with its own camera (fitted to the visible matter, as `voxlight render`
// frames it). The first orbit, pan or zoom continues from the camera the renderer actually used
// (pipeline details "camera": eye, forward, up, fov / ortho height) as an explicit look-at camera
// (camera.eye/target/up), so the picture does not jump. Orbit turns the eye about the target: yaw
// about the patient's superior axis (+z, LPS), pitch about the image's right axis. Snapping to a
// named view (A/P/L/R/S/I, io::namedViews) goes back to a fitted camera.
//
// Window/level: as clinical viewers, a right-drag changes the TF's window — horizontal motion the
// width (right = wider), vertical the level (down = higher) — via TransferFunction::withWindow,
// so the TF's shape is kept and only its value axis is remapped.
#include <glm/glm.hpp>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "io/scene.h"
#include "optics/transfer_function.h"

namespace voxlight::viewer {

/// An explicit look-at camera (world mm, LPS).
struct LookAt {
    glm::dvec3 eye{0.0, -1.0, 0.0}, target{0.0}, up{0.0, 0.0, 1.0};
    bool perspective = true;
    double fovYDeg = 30.0;       ///< perspective
    double orthoHeight = 100.0;  ///< orthographic, mm
};

/// The look-at camera that reproduces a rendered camera (pipeline details "camera"), with the
/// target on the view axis at the depth of `pivot` (the volume's centre), so orbiting turns about
/// the middle of the anatomy. Throws InternalError when `camera` lacks the fields.
LookAt lookAtFromRendered(const nlohmann::json& camera, const glm::dvec3& pivot);

/// Orbit: yaw (degrees) about the world superior axis (+z) through the target, then pitch
/// (degrees) about the image's right axis; the distance to the target is kept. Pitch stops 1°
/// short of looking straight along ±z so the image's up stays defined.
void orbit(LookAt& c, double yawDeg, double pitchDeg);
/// Pan by a motion of (dx, dy) pixels on a viewport `viewportHeight` pixels tall: the point under
/// the cursor at the target's depth follows the cursor.
void pan(LookAt& c, double dx, double dy, int viewportHeight);
/// Zoom by `factor` (> 1 = closer / larger): perspective moves the eye toward the target,
/// orthographic shrinks the view height.
void zoom(LookAt& c, double factor);
/// camera JSON of the scene schema for `c` (keeps `previous`'s aperture and focus_distance).
nlohmann::json cameraJson(const LookAt& c, const nlohmann::json& previous);
/// camera JSON of a named view, fitted (keeps previous's projection, fov_y, margin, aperture).
nlohmann::json namedViewJson(const std::string& view, const nlohmann::json& previous);

/// The window after a right-drag of (dx, dy) pixels from `start`: width × 2^(dx / 200), level +
/// dy · start width / 400 (a full 400-pixel drag moves the level by one window width).
optics::Window dragWindow(const optics::Window& start, double dx, double dy);

/// transfer_function JSON (scene schema, explicit points and window) for `tf`: every channel of
/// every point, extinction_scale 1 (the scale is already in the points).
nlohmann::json transferFunctionJson(const optics::TransferFunction& tf);

/// The scene the worker renders at a reduced cost for interaction: image size / `factor` (at
/// least 16 pixels a side), step × `stepScale`, early termination at ≥ `termination`.
io::Scene coarseScene(const io::Scene& full, int factor, double stepScale, double termination);

/// One step of a scripted UI run (`voxlight view --script`): a gesture as the mouse or keyboard
/// makes it, applied through the same code path (viewer.cpp). Pixels as the mouse moves them.
struct ScriptStep {
    enum class Kind {
        Orbit,   ///< left-drag by (a, b) pixels
        Pan,     ///< middle-drag by (a, b) pixels
        Zoom,    ///< a wheel notches (> 0 closer)
        Window,  ///< right-drag by (a, b) pixels: window/level
        View,  ///< the key of a named view: `view` is anterior, posterior, left, … or A/P/L/R/S/I
        PathTrace,  ///< the panel's "render this view" with the path tracer, `a` spp
    };
    Kind kind = Kind::Orbit;
    double a = 0.0, b = 0.0;
    std::string view;
};
/// A script file's steps: a JSON array of one-key objects — {"orbit": [dx, dy]}, {"pan": [dx,
/// dy]}, {"zoom": notches}, {"window": [dx, dy]}, {"view": "L"}, {"pathtrace": spp} (1…65536). InputError naming the file and
/// `[i].key` for anything else (unknown key, wrong type, non-finite number, unknown view).
std::vector<ScriptStep> parseScript(const nlohmann::json& doc, const std::string& source);

/// Parses an edited scene document (paths absolute, as io::sceneDocument writes them); `source`
/// names it in errors.
io::Scene sceneFromDocument(const nlohmann::json& doc, const std::string& source);

}  // namespace voxlight::viewer
