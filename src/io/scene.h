// SPDX-License-Identifier: MIT
#pragma once
// The scene file (JSON): what to render and how. One document drives `voxlight render`, `iso`,
// `sweep`, `replay` and the viewer. Parsing is strict: an unknown key, a wrong type or a value out
// of range is an InputError naming the dotted key path ("camera.fov_y"), what was found and what is
// allowed. `--set key=value` overrides any key before validation (value parsed as JSON when it
// parses, else taken as a string; arrays indexed by number: lights.0.color).
//
// Schema (every key optional except volume; defaults in the structs below):
// {
//   "volume": "ct.nii.gz" | {"path": "dicom/", "series": "1.2.3", "nonfinite": "reject"|"min",
//                            "strict_geometry": false (true: refuse a gantry-tilted or variably
//                            spaced DICOM series instead of resampling it; --strict-geometry)}
//             | {"phantom": "torso", "size": 128},
//   "transfer_function": "ct-bone" | {"preset": "ct-bone", "extinction_scale": 1.0}
//             | {"points": [{"value": -1000, "color": [r,g,b], "extinction": 0.0,
//                            "emission": [r,g,b], "specular": [r,g,b] (BRDF F0, 0..1; 0),
//                            "roughness": (0, 1] (1), "phase_g": (-1, 1) (on every point or
//                            none; none = method.params.phase_g)}, ...]},
//             (specular, roughness and phase_g are read only by pathtrace's scattering modes:
//             pathtrace/path_tracer.h)
//             (either form may add "window": {"level": L, "width": W})
//   "camera": {"projection": "perspective"|"orthographic",
//              "view": "anterior"|"posterior"|"left"|"right"|"superior"|"inferior"|"oblique"
//                      |"auto" (a named view; excludes azimuth/elevation/eye/up; "auto" is
//                      anterior, or the face of a thin slab: pipeline/scene_inputs.h),
//              "azimuth": deg, "elevation": deg,
//              "distance": mm (0 = fit), "fov_y": deg, "ortho_height": mm (0 = fit),
//              "target": [x,y,z] mm, "eye": [x,y,z], "up": [x,y,z], "roll": deg,
//              "margin": 0.05 (fitting: fraction of the image left empty on each side),
//              "aperture": mm (thin-lens diameter; 0 = pinhole, everything sharp; rendered by
//                          pathtrace, other methods warn), "focus_distance": mm along the view
//                          or "auto" (the first visible surface at the image centre)},
//   "lights": [{"type": "directional", "direction": [x,y,z] (the direction the light travels),
//               "color": [r,g,b], "intensity": irradiance E (radiance units × sr)},
//              {"type": "point", "position": [x,y,z], "color": ..., "intensity": I, irradiance
//               I / d² at d mm — so I = 10⁶ matches a directional intensity of 1 at 1 m (the
//               units were given as W/m² and W/sr, 10⁶ apart with distances in mm),
//               "min_distance": mm},
//              {"type": "area", "shape": "sphere"|"rect"|"disk", "position": ..., "normal": ...,
//               "radius": mm, "size": [w,h]},
//              {"type": "environment", "path": "sky.hdr", "intensity": 1,
//               "rotation": [x,y,z] deg (about the world x, then y, then z axis; the map's
//               frame is lights/environment_light.h's), "layout": "equirect"|"probe"}],
//   "clip_planes": [{"point": [x,y,z], "normal": [x,y,z],    (keeps the side the normal points to,
//                    "shadows_from_removed": false}],        as VTK),
//   "crop_box": {"min": [x,y,z], "max": [x,y,z],            (world mm),
//                "shadows_from_removed": false},
//             shadows_from_removed (per plane, and once for the whole crop box; default false):
//             camera rays never see removed matter, in every method. false: removed matter is
//             gone for the light too (no shadow, no scattering; the SH methods run a clip-aware
//             visibility update, pipeline/raycast_methods.cpp). true: a section view — removed
//             matter still casts shadows (it occludes light but never scatters or emits).
//   "method": "gradient" | {"name": "gradient", "params": {...}},
//   "image": {"width": 512, "height": 512, "background": [r,g,b], "exposure": 0.0 (stops),
//             "display": "clinical"|"srgb"|"filmic" (PNG display transform, render/tonemap.h;
//                        EXR stays linear)},
//   "render": {"step": 0.5 (voxels), "seed": 1, "threads": 0 (0 = all),
//              "termination": 0.001 (transmittance that ends a ray)},
//   "effects": ["specular", ...]
// }
// Method names, their params and the effect names are checked by the pipeline's method registry
// (pipeline/registry.h), not here: io/ knows the scene's shape, not what each method reads.
// Units: mm, degrees in the file (radians in code after conversion), colours linear RGB.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/error.h"
#include "io/volume_io.h"

namespace voxlight::io {

struct VolumeSource {
    std::filesystem::path
        path;             ///< resolved against the scene file's directory; empty when a phantom
    std::string written;  ///< the path as the scene wrote it (for errors)
    std::string key;      ///< where: "volume" or "volume.path"
    std::string phantom;  ///< phantom name; empty when a path
    int phantomSize = 0;  ///< 0 = phantom default
    ReadOptions readOptions;
};

struct TransferFunctionPoint {
    double value = 0.0;            ///< physical value (HU for CT)
    glm::dvec3 color{1.0};         ///< albedo, 0..1
    double extinction = 0.0;       ///< σt, 1/mm, ≥ 0
    glm::dvec3 emission{0.0};      ///< emitted radiance, linear RGB, ≥ 0
    glm::dvec3 specular{0.0};      ///< BRDF specular colour F0, 0..1
    double roughness = 1.0;        ///< BRDF roughness, (0, 1]
    std::optional<double> phaseG;  ///< Henyey–Greenstein g, (−1, 1); unset = the method's phase_g
};

struct TransferFunctionDesc {
    std::string preset;  ///< non-empty: a named preset (optics/ knows the list)
    std::vector<TransferFunctionPoint>
        points;                    ///< non-empty: explicit points, strictly increasing value
    double extinctionScale = 1.0;  ///< multiplies σt (density slider)
    /// Window/level {level, width} (physical units): remaps the TF's value axis so that its
    /// reference window becomes this one; MIP/MinIP grey ramp. Unset = the TF's own window.
    std::optional<glm::dvec2> window;
};

/// A standard view: orbit angles (camera.h) and the image's up.
struct NamedView {
    std::string name;
    double azimuthDeg, elevationDeg;
    glm::dvec3 up;
};
const std::vector<NamedView>& namedViews();
const NamedView* findView(const std::string& name);  ///< nullptr when unknown

/// Smallest orthographic view height (mm) a scene takes besides 0 (fit): a micrometre, far below
/// any medical voxel; smaller heights (a viewer zoomed 10⁴⁰-fold) show one flat colour.
inline constexpr double kMinOrthoHeightMm = 1e-3;

struct CameraDesc {
    std::string projection = "perspective";  ///< "perspective" | "orthographic"
    std::string view;  ///< a named view (sets azimuth, elevation, up); empty = none
    double azimuthDeg = 30.0, elevationDeg = 20.0, rollDeg = 0.0;
    double distance = 0.0;     ///< mm from target; 0 = fit the volume in view
    double fovYDeg = 30.0;     ///< perspective vertical field of view
    double orthoHeight = 0.0;  ///< orthographic view height, mm; 0 = fit, else ≥ kMinOrthoHeightMm
    std::optional<glm::dvec3> target;  ///< default: volume centre
    std::optional<glm::dvec3> eye;  ///< set → explicit look-at (azimuth/elevation/distance ignored)
    glm::dvec3 up{0.0, 0.0, 1.0};   ///< LPS +z = superior
    double margin = 0.05;           ///< fitting: image fraction left empty on each side
    double apertureMm = 0.0;        ///< thin-lens diameter; 0 = pinhole
    std::optional<double> focusMm;  ///< along the view from the eye; unset = autofocus
};

struct LightDesc {
    std::string type;  ///< "directional" | "point" | "area" | "environment"
    glm::dvec3 color{1.0};
    double intensity = 1.0;
    glm::dvec3 direction{0.0, 0.0, -1.0};  ///< directional: direction the light travels
    glm::dvec3 position{0.0};              ///< point / area centre
    double minDistance = 1.0;              ///< point: mm, clamps 1/d² near the light
    std::string shape = "sphere";          ///< area
    glm::dvec3 normal{0.0, 0.0, -1.0};     ///< area (rect/disk)
    double radius = 10.0;                  ///< area sphere/disk
    glm::dvec2 size{20.0, 20.0};           ///< area rect
    std::filesystem::path path;            ///< environment map
    glm::dvec3 rotationDeg{0.0};           ///< environment rotation (x, y, z Euler, degrees)
    std::string layout = "equirect";       ///< environment: "equirect" | "probe"
};

struct ClipPlaneDesc {
    glm::dvec3 point{0.0};
    glm::dvec3 normal{0.0, 0.0, 1.0};  ///< unit; the kept half-space is dot(x − point, normal) ≥ 0
    bool shadowsFromRemoved = false;  ///< removed matter still occludes the light (section view)
};

struct CropBoxDesc {
    glm::dvec3 min{0.0}, max{0.0};
    bool shadowsFromRemoved = false;  ///< as ClipPlaneDesc, for everything outside the box
};

struct MethodDesc {
    std::string name = "gradient";
    nlohmann::json params = nlohmann::json::object();
};

struct ImageDesc {
    int width = 512, height = 512;
    glm::dvec3 background{0.0};
    double exposureStops = 0.0;
    std::string display = "clinical";  ///< PNG display transform (render/tonemap.h)
};

struct RenderSettings {
    double stepVoxels = 0.5;  ///< ray-marching step in units of the smallest voxel spacing
    std::uint64_t seed = 1;
    int threads = 0;  ///< 0 = all hardware threads
    /// Early ray termination below this transmittance (what is behind contributes less); 0 turns
    /// it off. The default 1e-3 keeps the error below an 8-bit level; interactive views may trade
    /// accuracy for speed (VTK's CPU ray caster stops at 255/32768 ≈ 7.8e-3).
    double termination = 1e-3;
};

/// What one override did to a document, so that an error its value causes names the override
/// (what the user typed) instead of the scene file. `key` is its dotted key; `created` the
/// shortest prefix of the key that the document lacked before it (empty when every parent
/// existed): `--set method.params.rays=64` on a scene without a method creates "method", and
/// "method: needs a 'name'" is then the override's doing.
struct OverrideRecord {
    std::string key;      ///< dotted, array indices canonical ("lights.0.x")
    std::string created;  ///< see above
    std::string said;     ///< how the user gave it: "--set key=value" unless the caller renames it
    /// The value was null and a key that was there is gone (an error may then name its parent).
    bool removed = false;
};

struct Scene {
    std::string source;  ///< file name used in error messages
    VolumeSource volume;
    TransferFunctionDesc transferFunction;
    CameraDesc camera;
    std::vector<LightDesc> lights;
    std::vector<ClipPlaneDesc> clipPlanes;
    std::optional<CropBoxDesc> cropBox;
    MethodDesc method;
    ImageDesc image;
    RenderSettings render;
    /// Effect names as given (the pipeline checks them against its catalogue and the method).
    std::vector<std::string> effects;
    bool effectsGiven = false;  ///< the scene has an "effects" key (even an empty list)
    nlohmann::json document;    ///< the validated document after overrides (echoed into stats)
    /// The overrides loadScene / volumeScene applied (errors their values cause name them).
    std::vector<OverrideRecord> overrides;
};

/// Applies "dotted.key=value" to a JSON document and says what it did. Throws InputError on a
/// malformed override, one that is not UTF-8, a value nesting deeper than the scene's depth limit
/// (64) — source "--set" — or a key that cannot be placed (source "--set key=value"). The value
/// null removes the key (its default applies again): --set camera.azimuth=null; removing a key
/// under something that is not an object changes nothing.
OverrideRecord applyOverride(nlohmann::json& doc, const std::string& assignment);

/// Applies overrides in order (applyOverride); a relative path given by one to a path key
/// (isPathKey) is made absolute against the current directory, where the user typed it.
std::vector<OverrideRecord> applyOverrides(nlohmann::json& doc,
                                           const std::vector<std::string>& overrides);

/// The override an error at `field` comes from (a scene key as errors name it, array elements as
/// "lights[0].intensity" or "lights.0.intensity"): the last one whose key is `field` or one of its
/// parents (the error lies in the value it set), that created `field` or one of its parents, or
/// that removed a key under `field` (`--set method.name=null`: "method: needs a 'name'").
/// nullptr when none did: the scene itself is at fault. (An error about two keys together — a
/// width × height limit, a parameter another one rules out — names one of them and is blamed by
/// that one alone.)
const OverrideRecord* blamedOverride(const std::vector<OverrideRecord>& overrides,
                                     const std::string& field);

/// `e` with the override it comes from (blamedOverride) as its source, when its source is
/// `source` (the scene the overrides were applied to); else `e` itself.
InputError blameOverride(const InputError& e, const std::string& source,
                         const std::vector<OverrideRecord>& overrides);

/// Validates and converts a document. `source` names it in errors; relative paths resolve against
/// `baseDir`. A document nesting arrays/objects deeper than 64 levels, or holding a value nlohmann
/// cannot convert or print (a string that is not UTF-8), is an InputError naming `source`.
Scene parseScene(const nlohmann::json& doc, const std::string& source,
                 const std::filesystem::path& baseDir);

/// applyOverrides then parseScene, the result holding the overrides' records; an error a value of
/// theirs causes names the override (blameOverride). What loadScene, volumeScene and a session's
/// frames use.
Scene parseWithOverrides(nlohmann::json doc, const std::vector<std::string>& overrides,
                         const std::string& source, const std::filesystem::path& baseDir);

/// The scene a volume file (or DICOM folder) makes on its own (`voxlight render ct.nii.gz`):
/// {"volume": path, "camera": {"view": "auto"}}, everything else at its default (the TF is
/// the modality's preset, chosen once the volume is loaded; no lights = a headlight), then the
/// overrides. The path and relative paths in overrides resolve against the current directory.
Scene volumeScene(const std::filesystem::path& volume,
                  const std::vector<std::string>& overrides = {});

/// Every key of `scene` written out at its value (defaults included), in the schema above, so that
/// parseScene(sceneDocument(s)) describes the same render. Paths are written absolute. The
/// transfer function is written as given (empty = the modality default: the caller may fill in
/// the preset), method.params as given.
nlohmann::json sceneDocument(const Scene& scene);
/// One entry of sceneDocument's "lights" (every key of the light's type, paths absolute).
nlohmann::json lightDocument(const LightDesc& light);
/// One entry of sceneDocument's "clip_planes".
nlohmann::json clipPlaneDocument(const ClipPlaneDesc& plane);

/// True for the keys whose string values are file paths (volume, volume.path, lights.N.path):
/// given on the command line (--set) they resolve against the current directory.
bool isPathKey(const std::string& dottedKey);

/// Reads a JSON file with the scene file's limits (loadScene's failures below, before parsing:
/// not a directory, readable, at most 16 MiB, nesting at most 64 levels, valid JSON). Every
/// failure is an InputError naming the file. Also reads session files (session/session.h).
nlohmann::json readJsonFile(const std::filesystem::path& path);

/// Reads a scene file, applies overrides in order (path keys given by them resolve against the
/// current directory, other paths against the scene's folder), validates. Every failure is an InputError naming
/// the file: a directory, an unreadable file or one over 16 MiB, nesting deeper than 64 levels (refused by a linear scan
/// before parsing, with the byte offset), any JSON error (syntax, invalid UTF-8, a number out of
/// range such as 1e999).
Scene loadScene(const std::filesystem::path& path, const std::vector<std::string>& overrides = {});

}  // namespace voxlight::io
