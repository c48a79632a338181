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

#include "core/volume.h"
#include "io/scene.h"
#include "optics/transfer_function.h"
#include "render/camera.h"

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
/// orthographic shrinks the view height. False (and `c` unchanged) when the factor is not a
/// positive finite number or the view would leave what a scene can render (an orthographic height
/// outside [io::kMinOrthoHeightMm, 10⁶ mm], the eye within a nanometre of the target or a coordinate past
/// 10⁶ mm): a factor of ∞ once made the height 0, which the scene reads as "fit".
bool zoom(LookAt& c, double factor);
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

// Lights. A light's direction is given as the azimuth and elevation (degrees) of where it comes
// from, in the camera's convention (render/camera.h): the unit vector toward the light is
// (sin az · cos el, −cos az · cos el, sin el), so azimuth 0 is in front of the patient (anterior,
// −y), 90 at the patient's left (+x), elevation 90 above (superior, +z). A directional light
// travels the opposite way; a point light sits at that angle from the volume's centre.

/// Unit vector toward a light at (azimuthDeg, elevationDeg).
glm::dvec3 towardLight(double azimuthDeg, double elevationDeg);
/// Inverse of towardLight for any non-zero vector: {azimuth ∈ (−180, 180], elevation ∈ [−90,
/// 90]} in degrees (azimuth 0 straight above or below).
glm::dvec2 lightAngles(const glm::dvec3& toward);
/// The angles of a light: a directional light's source direction (−direction), a point or area
/// light's position seen from `pivot`, an environment map's rotation about z (azimuth) and x
/// (elevation).
glm::dvec2 lightAnglesOf(const io::LightDesc& light, const glm::dvec3& pivot);
/// Places a light at the angles (lightAnglesOf's meaning): a point or area light keeps its
/// distance from `pivot` (an area light's normal faces the pivot); elevation is clamped to
/// [−90, 90].
void setLightAngles(io::LightDesc& light, const glm::dvec2& anglesDeg, const glm::dvec3& pivot);
/// Turns a light by (dAzimuth, dElevation) degrees: setLightAngles(lightAnglesOf + d).
void turnLight(io::LightDesc& light, double dAzimuthDeg, double dElevationDeg,
               const glm::dvec3& pivot);
/// A new light of `type` ("directional", "point" or "environment") from the upper front left of
/// the patient (azimuth 45, elevation 30), a point light `distanceMm` from `pivot`; an
/// environment light needs the map's `path`, an existing file (InputError naming `source` and
/// `field`.path otherwise; the map itself is read by the renderer).
io::LightDesc newLight(const std::string& type, const glm::dvec3& pivot, double distanceMm,
                       const std::string& path, const std::string& source,
                       const std::string& field);
/// The scene's "lights" list for `lights` (io::lightDocument each; empty: the headlight).
nlohmann::json lightsJson(const std::vector<io::LightDesc>& lights);

// Clip planes. The viewer keeps disabled planes (they are not in the scene it renders).
struct ViewClipPlane {
    io::ClipPlaneDesc plane;
    bool enabled = true;
};
/// A plane with unit normal `normal` through `centre` + offsetMm · normal (keeps the side the
/// normal points to). InputError naming `source`/`field` for a zero or non-finite normal.
io::ClipPlaneDesc clipPlaneThrough(const glm::dvec3& normal, const glm::dvec3& centre,
                                   double offsetMm, const std::string& source,
                                   const std::string& field);
/// Moves a plane by `mm` along its normal (positive: toward the kept side, removing more).
void moveClipPlane(io::ClipPlaneDesc& plane, double mm);
/// Flips a plane: the other side is kept, the plane stays where it is.
void flipClipPlane(io::ClipPlaneDesc& plane);
/// The scene's "clip_planes" list: the enabled planes (io::clipPlaneDocument each).
nlohmann::json clipPlanesJson(const std::vector<ViewClipPlane>& planes);
/// Where `plane` cuts the box of the volume's voxel centres (`g`): the polygon's corners in world
/// mm, in order around it (3–6 of them); empty when the plane misses the box.
std::vector<glm::dvec3> clipOutline(const io::ClipPlaneDesc& plane, const core::Geometry& g);
/// The camera a LookAt renders with, for projecting world points to an image of `width` ×
/// `height` pixels (render::Camera::project).
render::Camera projectionCamera(const LookAt& c, int width, int height);
/// The gizmo's drag: millimetres along `plane`'s normal for a mouse motion of (dx, dy) image
/// pixels on `camera`'s image, at the handle `handle` (world mm, on the plane). The motion's part
/// along the normal's image direction moves the plane as far as the handle's image follows the
/// cursor. When the normal points (within ~10°) along the view, the image direction is degenerate:
/// dragging up moves the plane away from the eye, at the handle depth's mm per pixel.
double clipDragMm(const io::ClipPlaneDesc& plane, const glm::dvec3& handle,
                  const render::Camera& camera, double dx, double dy);

/// One step of a scripted UI run (`voxlight view --script`): a gesture as the mouse, keyboard
/// or a panel makes it, applied through the same code path (viewer.cpp). Pixels as the mouse
/// moves them. `source` and `field` ("[3].clip_move") name the step in errors found when it runs
/// (an index past the scene's planes or lights).
struct ScriptStep {
    enum class Kind {
        Orbit,   ///< left-drag by (a, b) pixels
        Pan,     ///< middle-drag by (a, b) pixels
        Zoom,    ///< a wheel notches (> 0 closer)
        Window,  ///< right-drag by (a, b) pixels: window/level
        View,  ///< the key of a named view: `view` is anterior, posterior, left, … or A/P/L/R/S/I
        PathTrace,    ///< the panel's "render this view" with the path tracer, `a` spp
        ClipAdd,      ///< a plane: normal `vec` (or facing the camera), `a` mm from the centre
        ClipMove,     ///< the panel's slider: plane `index` by `a` mm along its normal
        ClipDrag,     ///< the gizmo's drag of plane `index` by (a, b) pixels over `frames` frames
        ClipEdit,     ///< plane `index`: flip, enabled, shadows_from_removed
        ClipRemove,   ///< plane `index`
        LightAdd,     ///< a light of `lightType` (optional angles, distance, colour, intensity)
        LightEdit,    ///< light `index`: angles, position, colour, intensity
        LightTurn,    ///< turn light `index` by (a, b) degrees of azimuth and elevation
        LightRemove,  ///< light `index`
        Gizmo,        ///< the G key's state: the clip-plane gizmo shown (a = 1) or hidden (0)
        Drop,         ///< `paths` dropped on the window (GLFW's drop callback is called)
        Shading,      ///< the panel's local/global visibility switch: `view` is local or global
        Drag,  ///< a `dragMotion` (Orbit, Pan, Window) drag by (a, b) pixels over `frames` frames
    };
    Kind kind = Kind::Orbit;
    double a = 0.0, b = 0.0;
    std::string view;
    std::string source, field;

    // Clip-plane and light steps.
    int index = 0;
    int frames = 1;
    Kind dragMotion = Kind::Orbit;  ///< Drag: which mouse drag
    bool facingCamera = false;      ///< ClipAdd: the normal is the camera's view direction
    glm::dvec3 vec{0.0};            ///< ClipAdd: the normal
    bool flip = false;
    std::optional<bool> enabled, shadowsFromRemoved;
    std::string lightType, path;
    std::optional<double> azimuth, elevation, distance, intensity;
    std::optional<glm::dvec3> position, color;
    std::vector<std::string> paths;  ///< Drop
};
/// A script file's steps: a JSON array of one-key objects —
///   {"orbit": [dx, dy]}, {"pan": [dx, dy]}, {"zoom": notches}, {"window": [dx, dy]},
///   {"drag": {"kind": "orbit" | "pan" | "window", "by": [dx, dy], "frames": n}} (that mouse
///   drag in n motions, one per UI frame; n 1…10000, default 1),
///   {"view": "L"}, {"pathtrace": spp} (1…65536),
///   {"clip_add": {"normal": [x, y, z] | "camera", "offset": mm, "shadows_from_removed": b}},
///   {"clip_move": {"index": i, "by": mm}},
///   {"clip_drag": {"index": i, "by": [dx, dy], "frames": n}} (n 1…10000, default 1),
///   {"clip_edit": {"index": i, "flip": true, "enabled": b, "shadows_from_removed": b}},
///   {"clip_remove": i},
///   {"light_add": {"type": "directional" | "point" | "environment", "azimuth": deg,
///                  "elevation": deg, "distance": mm, "color": [r, g, b], "intensity": x,
///                  "path": map}},
///   {"light_edit": {"index": i, "azimuth": deg, "elevation": deg, "position": [x, y, z],
///                   "color": [r, g, b], "intensity": x}},
///   {"light_turn": {"index": i, "azimuth": deg, "elevation": deg}} (by these angles),
///   {"light_remove": i}, {"gizmo": true | false} (the clip-plane gizmo drawn over the image),
///   {"drop": ["path", …]} (files dropped on the window, 1…64 non-empty paths; the last opens),
///   {"shading": "local" | "global"} (the SH visibility switch of an sh-local / sh-global scene).
/// InputError naming the file and `[i].key.field` for anything else (unknown step or key, a
/// missing required key, wrong type, non-finite number, out-of-range value, unknown view).
std::vector<ScriptStep> parseScript(const nlohmann::json& doc, const std::string& source);

/// The method of scene document `doc` switched between sh-local (global false) and sh-global:
/// sh-global's own params (global_resolution, global_near) move to `stash` and back, the shared
/// ones (rays, coefficients, radius, LOD, window, ambient) stay, so both name the same local
/// field and the pipeline recomputes nothing it has (visibility/ keys). False (doc unchanged)
/// when the method is neither, or already the one asked for.
/// An effects list, when the document has one, follows: local_shadows, plus global_shadows for
/// sh-global.
bool switchShVisibility(nlohmann::json& doc, bool global, nlohmann::json& stash);
/// A scene's effects list as the path tracer takes it ("render this view" from any method):
/// multiple_scattering kept, any shadow effect as global_shadows (it casts every shadow), the
/// rest (specular, which the path tracer refuses) dropped; not a list: unchanged.
nlohmann::json pathTraceEffects(const nlohmann::json& effects);

/// Parses an edited scene document (paths absolute, as io::sceneDocument writes them); `source`
/// names it in errors.
io::Scene sceneFromDocument(const nlohmann::json& doc, const std::string& source);

}  // namespace voxlight::viewer
