// SPDX-License-Identifier: MIT
#include "io/scene.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string_view>
#include <utility>

#include "core/files.h"
#include "core/phantoms.h"
#include "io/json_field.h"

namespace voxlight::io {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr double kMaxCoord = 1e6;  // mm; a kilometre is not a medical scene
/// Largest |value| of a TF point: a float, with the span between two points (the interpolation's
/// denominator) still finite in float.
constexpr double kMaxTfValue = 1e37;
/// Smallest stored roughness: the smallest normal float, so that a tiny one (1e-300) does not
/// round to float 0 and be refused later as "not in (0, 1]". (Every roughness below ≈ 0.03
/// shades alike: GGX α = roughness² is held at ≥ kMinAlpha = 1e-3 in pathtrace/brdf.h.)
constexpr double kMinTfRoughness = double(std::numeric_limits<float>::min());

/// What an invalid shadows_from_removed should become.
constexpr const char* kShadowsFromRemovedFix =
    "write true (section view: removed matter still casts shadows) or false (removed matter is "
    "gone for the light too), without quotes";

/// Containers (arrays/objects) nested deeper than this are refused. nlohmann-json copies, compares
/// and dumps a document recursively, one stack frame per level, so ~100k levels overflow the
/// stack; a real scene nests 3 levels (lights[0].color) and method params a few more.
constexpr int kMaxSceneDepth = 64;

/// Scene files larger than this are refused while reading: real scenes are a few KB, and reading
/// /dev/zero or a volume given by mistake must not exhaust memory.
constexpr std::size_t kMaxSceneBytes = std::size_t(16) << 20;

/// Bytes of a message that are not printable ASCII, as \xNN: nlohmann's messages quote the bytes
/// they stopped at, which may be control characters or invalid UTF-8.
std::string printable(std::string_view text) {
    static constexpr char kHex[] = "0123456789abcdef";
    std::string out;
    for (const char ch : text) {
        const auto c = static_cast<unsigned char>(ch);
        if (c >= 0x20 && c < 0x7f) {
            out += ch;
        } else {
            out += "\\x";
            out += kHex[c >> 4];
            out += kHex[c & 15];
        }
    }
    return out;
}

/// nlohmann's message without its "[json.exception.parse_error.101] " prefix, made printable.
std::string jsonMessage(const nlohmann::json::exception& e) {
    const std::string what = e.what();
    const auto p = what.find("] ");
    return printable(p == std::string::npos ? what : what.substr(p + 2));
}

/// Byte offset in JSON text where a container opens deeper than kMaxSceneDepth (brackets inside
/// strings do not count), or npos. Linear and non-recursive, so it runs before the parser.
std::size_t tooDeepAt(std::string_view text) {
    int depth = 0;
    bool inString = false, escaped = false;
    for (std::size_t i = 0; i < text.size(); ++i) {
        const char c = text[i];
        if (inString) {
            if (escaped)
                escaped = false;
            else if (c == '\\')
                escaped = true;
            else if (c == '"')
                inString = false;
        } else if (c == '"') {
            inString = true;
        } else if (c == '[' || c == '{') {
            if (++depth > kMaxSceneDepth) return i;
        } else if ((c == ']' || c == '}') && depth > 0) {
            --depth;
        }
    }
    return std::string_view::npos;
}

/// Deepest container nesting of a document (a scalar is 0), walked with an explicit stack; stops
/// counting past kMaxSceneDepth + 1.
int nestingDepth(const json& doc) {
    int deepest = 0;
    std::vector<std::pair<const json*, int>> todo{{&doc, 0}};
    while (!todo.empty()) {
        const auto [node, depth] = todo.back();
        todo.pop_back();
        if (!node->is_structured()) continue;
        deepest = std::max(deepest, depth + 1);
        if (deepest > kMaxSceneDepth) break;
        for (const auto& child : *node) todo.emplace_back(&child, depth + 1);
    }
    return deepest;
}

fs::path resolvePath(const std::string& p, const fs::path& baseDir) {
    const fs::path path(p);
    return path.is_absolute() ? path : baseDir / path;
}

/// A file named by `f` (a string), resolved against `baseDir`; an empty name is refused here (it
/// resolved to the folder, and std::filesystem refused to make "" absolute: an internal error).
fs::path pathOf(const Field& f, const fs::path& baseDir) {
    const std::string name = f.string();
    if (name.empty()) f.fail("is an empty path", "name a file");
    return resolvePath(name, baseDir);
}

VolumeSource parseVolume(const Field& f, const fs::path& baseDir) {
    VolumeSource v;
    if (f.raw().is_null())
        f.fail("is required", "add \"volume\": \"path/to/volume\" or {\"phantom\": \"torso\"}");
    if (f.isString()) {
        v.path = pathOf(f, baseDir);
        v.written = f.string(), v.key = "volume";
        return v;
    }
    f.allowOnly({"path", "phantom", "size", "series", "nonfinite", "strict_geometry"});
    if (f.has("path") == f.has("phantom")) f.fail("needs exactly one of 'path' or 'phantom'");
    if (f.has("path")) {
        v.path = pathOf(f.child("path"), baseDir);
        v.written = f.child("path").string(), v.key = "volume.path";
    }
    if (f.has("phantom")) {
        // Named here, with the scene's key (makePhantom's own refusal names no file).
        std::vector<std::string> names;
        for (const auto& entry : core::phantomCatalog()) names.push_back(entry.first);
        v.phantom = f.child("phantom").oneOf(names);
    }
    f.get("size", v.phantomSize, 8, 1024);
    if (f.has("series")) {
        v.readOptions.dicomSeriesUid = f.child("series").string();
        if (v.readOptions.dicomSeriesUid.empty())
            f.child("series").fail("is empty (it read as no series given)",
                                   "give a SeriesInstanceUID, \"none\" for files without one, or "
                                   "remove the key");
    }
    f.get("strict_geometry", v.readOptions.strictGeometry,
          "write true (refuse a gantry-tilted or variably spaced DICOM series) or false (resample "
          "it with a warning), without quotes");
    if (f.has("nonfinite"))
        v.readOptions.nonFinite = f.child("nonfinite").oneOf({"reject", "min"}) == "min"
                                      ? NonFinitePolicy::ReplaceWithMin
                                      : NonFinitePolicy::Reject;
    return v;
}

TransferFunctionDesc parseTransferFunction(const Field& f) {
    TransferFunctionDesc tf;
    if (f.raw().is_null()) return tf;  // renderer picks a default for the modality
    // An empty name would be taken as no preset (the modality's default) without a word.
    const auto presetName = [](const Field& name) {
        std::string text = name.string();
        if (text.empty())
            name.fail("is an empty preset name",
                      "name a preset such as \"ct-bone\", or leave "
                      "transfer_function out for the modality's default");
        return text;
    };
    if (f.isString()) {
        tf.preset = presetName(f);
        return tf;
    }
    f.allowOnly({"preset", "points", "extinction_scale", "window"});
    // Neither: the automatic preset for the volume's modality (what a scene without the key
    // shows), with this window or extinction scale — `--set transfer_function.window.level=…`
    // on such a scene was refused as "needs exactly one of 'preset' or 'points'" (probe).
    if (f.has("preset") && f.has("points"))
        f.fail("takes one of 'preset' or 'points', not both",
               "remove one (without either, the modality's preset is chosen)");
    if (f.has("preset")) tf.preset = presetName(f.child("preset"));
    f.get("extinction_scale", tf.extinctionScale, 0.0, 1e6);
    if (f.has("window")) {
        const Field w = f.child("window");
        w.allowOnly({"level", "width"});
        if (!w.has("level") || !w.has("width"))
            w.fail("needs 'level' and 'width'", "e.g. {\"level\": 400, \"width\": 1500}");
        tf.window =
            glm::dvec2(w.child("level").number(-1e9, 1e9), w.child("width").number(1e-9, 1e9));
    }
    if (f.has("points")) {
        const Field pts = f.child("points");
        if (!pts.isArray() || pts.size() < 1)
            pts.fail("must be a non-empty array of control points");
        for (std::size_t i = 0; i < pts.size(); ++i) {
            const Field p = pts.at(i);
            p.allowOnly(
                {"value", "color", "extinction", "emission", "specular", "roughness", "phase_g"});
            TransferFunctionPoint tp;
            if (!p.has("value")) p.fail("needs a 'value'");
            // Voxel values and the TF's points are 32-bit floats from here on: a value must be
            // one, and two points a double tells apart may be one float (checked below).
            tp.value = p.child("value").number(-kMaxTfValue, kMaxTfValue);
            p.get("color", tp.color, 0.0, 1.0);
            p.get("extinction", tp.extinction, 0.0, 1e6);
            p.get("emission", tp.emission, 0.0, 1e9);
            if (p.has("specular")) {
                const Field sp = p.child("specular");
                if (!sp.isArray() || sp.size() != 3)
                    sp.fail("must be an array of 3 numbers in [0, 1], got " + typeName(sp.raw()) +
                                " " + shortDump(sp.raw()),
                            "e.g. \"specular\": [0.04, 0.04, 0.04]");
                tp.specular = sp.vec3(0.0, 1.0);
            }
            if (p.has("roughness")) {
                const Field r = p.child("roughness");
                if (!r.raw().is_number() || !(r.raw().get<double>() > 0.0) ||
                    !(r.raw().get<double>() <= 1.0))
                    r.fail("must be a number in (0, 1], got " + typeName(r.raw()) + " " +
                               shortDump(r.raw()),
                           "e.g. \"roughness\": 0.5 (small: glossy, 1: matte)");
                tp.roughness = std::max(r.raw().get<double>(), kMinTfRoughness);
            }
            if (p.has("phase_g")) {
                const Field g = p.child("phase_g");
                if (!g.raw().is_number() || !(std::abs(g.raw().get<double>()) < 1.0))
                    g.fail("must be a number strictly between -1 and 1, got " + typeName(g.raw()) +
                               " " + shortDump(g.raw()),
                           "e.g. \"phase_g\": 0.3 (0: isotropic, > 0: forward)");
                if (!(std::abs(float(g.raw().get<double>())) < 1.0f))
                    g.fail("is " + shortDump(g.raw()) +
                               ", which single precision (the renderers') rounds to ±1",
                           "give |phase_g| at most 0.9999999");
                tp.phaseG = g.raw().get<double>();
            }
            if (i > 0 && tp.phaseG.has_value() != tf.points.front().phaseG.has_value())
                p.child("phase_g").fail(
                    tp.phaseG ? "is given here but not on points[0]"
                              : "is missing here but given on points[0]",
                    "give phase_g on every point or on none (none: method.params.phase_g)");
            if (!tf.points.empty() && !(tp.value > tf.points.back().value)) {
                std::ostringstream os;
                os << "must be strictly increasing; got " << tp.value << " after "
                   << tf.points.back().value;
                p.child("value").fail(os.str(), "sort the points by value");
            }
            if (!tf.points.empty() && !(float(tp.value) > float(tf.points.back().value))) {
                std::ostringstream os;
                os << "is " << shortDump(p.child("value").raw()) << ", the same as points[" << i - 1
                   << "]'s " << shortDump(pts.at(i - 1).child("value").raw())
                   << " in single precision (voxel values are 32-bit floats)";
                p.child("value").fail(os.str(), "space the two points further apart");
            }
            tf.points.push_back(tp);
        }
    }
    return tf;
}

}  // namespace

const std::vector<NamedView>& namedViews() {
    // camera.h's orbit: azimuth 0 = from the patient's front. The axial views keep anterior at
    // the top of the image; seen from below (inferior) the patient's left is on the image's
    // right, as radiological axial slices are shown.
    static const std::vector<NamedView> views = {
        {"anterior", 0.0, 0.0, {0.0, 0.0, 1.0}},   {"posterior", 180.0, 0.0, {0.0, 0.0, 1.0}},
        {"left", 90.0, 0.0, {0.0, 0.0, 1.0}},      {"right", -90.0, 0.0, {0.0, 0.0, 1.0}},
        {"superior", 0.0, 90.0, {0.0, -1.0, 0.0}}, {"inferior", 0.0, -90.0, {0.0, -1.0, 0.0}},
        {"oblique", 30.0, 20.0, {0.0, 0.0, 1.0}},  {"auto", 0.0, 0.0, {0.0, 0.0, 1.0}},
    };
    return views;
}

const NamedView* findView(const std::string& name) {
    for (const NamedView& v : namedViews())
        if (v.name == name) return &v;
    return nullptr;
}

namespace {

CameraDesc parseCamera(const Field& f) {
    CameraDesc c;
    if (f.raw().is_null()) return c;
    f.allowOnly({"projection", "view", "azimuth", "elevation", "roll", "distance", "fov_y",
                 "ortho_height", "target", "eye", "up", "margin", "aperture", "focus_distance"});
    if (f.has("view")) {
        std::vector<std::string> names;
        for (const NamedView& v : namedViews()) names.push_back(v.name);
        f.get("view", c.view, names);
        // Named on the placement key: a `--set camera.azimuth=30` on a scene from `scene --init`
        // (which writes "view": "auto") was blamed on the scene file's camera.view.
        for (const char* other : {"azimuth", "elevation", "eye", "up"})
            if (f.has(other))
                f.child(other).fail("conflicts with camera.view '" + c.view + "'",
                                    "give either a named view or azimuth/elevation/eye/up "
                                    "(--set camera.view=null drops the view)");
        const NamedView* v = findView(c.view);
        c.azimuthDeg = v->azimuthDeg, c.elevationDeg = v->elevationDeg, c.up = v->up;
    }
    f.get("projection", c.projection, {"perspective", "orthographic"});
    f.get("azimuth", c.azimuthDeg, -360.0, 360.0);
    f.get("elevation", c.elevationDeg, -90.0, 90.0);
    f.get("roll", c.rollDeg, -360.0, 360.0);
    f.get("distance", c.distance, 0.0, kMaxCoord);
    f.get("fov_y", c.fovYDeg, 1.0, 170.0);
    f.get("ortho_height", c.orthoHeight, 0.0, kMaxCoord);
    if (c.orthoHeight > 0.0 && c.orthoHeight < kMinOrthoHeightMm)
        f.child("ortho_height")
            .fail("is below a micrometre (0.001 mm)",
                  "give 0 to fit the view to the volume, or a height of at least a micrometre");
    f.get("margin", c.margin, 0.0, 0.45);
    f.get("aperture", c.apertureMm, 0.0, kMaxCoord);
    if (f.has("focus_distance")) {
        const Field fd = f.child("focus_distance");
        if (fd.raw().is_string()) {
            std::string v;
            f.get("focus_distance", v, {"auto"});
        } else {
            double mm = 0.0;
            f.get("focus_distance", mm, 1e-3, kMaxCoord);
            c.focusMm = mm;
        }
    }
    if (f.has("target")) c.target = f.child("target").vec3(-kMaxCoord, kMaxCoord);
    if (f.has("eye")) c.eye = f.child("eye").vec3(-kMaxCoord, kMaxCoord);
    f.getDirection("up", c.up);
    if (c.eye && c.target && glm::length(*c.eye - *c.target) < 1e-9)
        f.child("eye").fail("coincides with the target", "move the eye away from the target");
    return c;
}

LightDesc parseLight(const Field& f, const fs::path& baseDir) {
    f.expectObject();
    LightDesc l;
    if (!f.has("type")) f.fail("needs a 'type'", "one of: directional, point, area, environment");
    l.type = f.child("type").oneOf({"directional", "point", "area", "environment"});
    std::vector<std::string> allowed = {"type", "color", "intensity"};
    if (l.type == "directional") allowed.insert(allowed.end(), {"direction"});
    if (l.type == "point") allowed.insert(allowed.end(), {"position", "min_distance"});
    if (l.type == "area") {
        // Each shape's own keys: a sphere's 'size' or a rect's 'radius' was ignored unsaid.
        const std::string shape =
            f.has("shape") ? f.child("shape").oneOf({"sphere", "rect", "disk"}) : "sphere";
        allowed.insert(allowed.end(), {"shape", "position"});
        if (shape == "sphere") allowed.insert(allowed.end(), {"radius"});
        if (shape == "rect") allowed.insert(allowed.end(), {"normal", "size"});
        if (shape == "disk") allowed.insert(allowed.end(), {"normal", "radius"});
    }
    if (l.type == "environment") allowed.insert(allowed.end(), {"path", "rotation", "layout"});
    // A key of another light type or shape is named as such ("unknown key" for a sphere's 'size'
    // sent users looking for a typo).
    static const std::vector<std::pair<std::string, std::string>> owners = {
        {"direction", "directional lights"},
        {"position", "point and area lights"},
        {"min_distance", "point lights"},
        {"shape", "area lights"},
        {"radius", "sphere and disk area lights"},
        {"normal", "rect and disk area lights"},
        {"size", "rect area lights"},
        {"path", "environment lights"},
        {"rotation", "environment lights"},
        {"layout", "environment lights"}};
    const std::string what =
        l.type == "area" ? (f.has("shape") ? f.child("shape").raw().get<std::string>() : "sphere") +
                               " area light"
                         : l.type + " light";
    for (const auto& [key, owner] : owners)
        if (f.has(key) && std::find(allowed.begin(), allowed.end(), key) == allowed.end())
            f.child(key).fail("applies to " + owner + ", not to " +
                                  (what.find_first_of("aeiou") == 0 ? "an " : "a ") + what,
                              "remove it, or change the light's type or shape");
    f.allowOnly(allowed);
    f.get("color", l.color, 0.0, 1e9);
    f.get("intensity", l.intensity, 0.0, 1e12);
    f.getDirection("direction", l.direction);
    f.get("position", l.position, -kMaxCoord, kMaxCoord);
    f.get("min_distance", l.minDistance, 1e-6, kMaxCoord);
    f.get("shape", l.shape, {"sphere", "rect", "disk"});
    f.getDirection("normal", l.normal);
    f.get("radius", l.radius, 1e-6, kMaxCoord);
    if (f.has("size")) {
        const Field s = f.child("size");
        if (!s.isArray() || s.size() != 2) s.fail("must be [width, height] in mm");
        l.size = {s.at(0).number(1e-6, kMaxCoord), s.at(1).number(1e-6, kMaxCoord)};
    }
    if (l.type == "environment") {
        if (!f.has("path")) f.fail("needs a 'path' to an .hdr or .exr environment map");
        l.path = pathOf(f.child("path"), baseDir);
    }
    f.get("rotation", l.rotationDeg, -360.0, 360.0);
    f.get("layout", l.layout, {"equirect", "probe"});
    return l;
}

}  // namespace

namespace {
/// An ASCII digit (std::isdigit of a negative char — a UTF-8 byte of a key — is undefined).
bool asciiDigit(char c) { return c >= '0' && c <= '9'; }

/// A dotted key's parts, empty ones kept ("lights..x" → "lights", "", "x"): the one place an
/// override's key is split (after dottedKey has written its bracket indices as dotted ones).
std::vector<std::string> keyParts(const std::string& key) {
    std::vector<std::string> parts;
    std::size_t start = 0;
    while (true) {
        const auto dot = key.find('.', start);
        parts.push_back(key.substr(start, dot == std::string::npos ? dot : dot - start));
        if (dot == std::string::npos) return parts;
        start = dot + 1;
    }
}

/// A key as errors print it ("lights[0].intensity") in the dotted form the parts are split from
/// ("lights.0.intensity"): an index is digits in brackets after a name or another index, followed
/// by a dot, another index or the end. Any other bracket is refused (read as part of a name, it
/// was an "unknown key" of the scene file's).
std::string dottedKey(const std::string& key, const std::string& said) {
    std::string out;
    for (std::size_t i = 0; i < key.size(); ++i) {
        if (key[i] != '[' && key[i] != ']') {
            out += key[i];
            continue;
        }
        const std::size_t close = key[i] == '[' ? key.find(']', i) : std::string::npos;
        const bool afterName = !out.empty() && out.back() != '.';
        const bool digits =
            close != std::string::npos && close > i + 1 &&
            std::all_of(key.begin() + long(i) + 1, key.begin() + long(close), asciiDigit);
        const bool thenEnds =
            close != std::string::npos &&
            (close + 1 == key.size() || key[close + 1] == '.' || key[close + 1] == '[');
        if (!(afterName && digits && thenEnds))
            throw InputError(said, key, "has a bracket that is not a list index",
                             "write an index as lights[0].intensity or lights.0.intensity");
        out += '.' + key.substr(i + 1, close - i - 1);
        i = close;
    }
    return out;
}

bool isIndexPart(const std::string& part) {
    return !part.empty() && std::all_of(part.begin(), part.end(), asciiDigit);
}

/// An all-digit part as an array index; an index no array can reach (past std::size_t) is the
/// largest, so "is past the end" answers it like any other.
std::size_t indexOfPart(const std::string& part) {
    std::size_t i = 0;
    const auto [end, ec] = std::from_chars(part.data(), part.data() + part.size(), i);
    return ec == std::errc() && end == part.data() + part.size()
               ? i
               : std::numeric_limits<std::size_t>::max();
}

/// Parts [0, n) joined with dots, their indices in canonical form ("lights.00.x" → "lights.0.x"):
/// the key as override records and errors' fields compare it.
std::string normalizedKey(const std::vector<std::string>& parts, std::size_t n) {
    std::string out;
    for (std::size_t k = 0; k < n && k < parts.size(); ++k) {
        if (k) out += '.';
        const std::string& part = parts[k];
        if (isIndexPart(part)) {
            const auto nonzero = part.find_first_not_of('0');
            out += nonzero == std::string::npos ? "0" : part.substr(nonzero);
        } else {
            out += part;
        }
    }
    return out;
}
/// A parser callback recording in `repeated` the first key that appears twice in one object, as
/// the path errors name (`lights[1].intensity`).
json::parser_callback_t duplicateKeyFinder(std::optional<std::string>& repeated) {
    struct Frame {
        bool array = false;
        std::size_t index = 0;  // arrays: the element being read
        std::string key;        // objects: the key being read
        std::set<std::string> keys;
    };
    auto frames = std::make_shared<std::vector<Frame>>();
    const auto path = [frames](const std::string& last) {
        std::string out;
        for (const Frame& f : *frames) {
            if (&f == &frames->back()) break;
            out += f.array ? "[" + std::to_string(f.index) + "]" : (out.empty() ? "" : ".") + f.key;
        }
        return out + (out.empty() ? "" : ".") + last;
    };
    // An element of an array ends: the next one has the next index.
    const auto elementDone = [frames] {
        if (!frames->empty() && frames->back().array) ++frames->back().index;
    };
    return [frames, path, elementDone, &repeated](int /*depth*/, json::parse_event_t event,
                                                  json& parsed) {
        switch (event) {
            case json::parse_event_t::object_start:
            case json::parse_event_t::array_start:
                frames->push_back({event == json::parse_event_t::array_start, 0, {}, {}});
                break;
            case json::parse_event_t::object_end:
            case json::parse_event_t::array_end:
                frames->pop_back();
                elementDone();
                break;
            case json::parse_event_t::key: {
                Frame& f = frames->back();
                f.key = parsed.get<std::string>();
                if (!f.keys.insert(f.key).second && !repeated) repeated = path(f.key);
                break;
            }
            case json::parse_event_t::value:
                elementDone();
                break;
        }
        return true;
    };
}
}  // namespace

OverrideRecord applyOverride(json& doc, const std::string& assignment) {
    const auto eq = assignment.find('=');
    if (eq == std::string::npos || eq == 0)
        throw InputError("--set", assignment, "is not of the form key=value",
                         "e.g. --set camera.azimuth=45");
    // Strings reach the stats JSON and error messages, whose writers refuse invalid UTF-8.
    try {
        (void)json(assignment).dump();
    } catch (const json::exception&) {
        throw InputError("--set", printable(assignment), "is not valid UTF-8",
                         "give keys and values as UTF-8 text");
    }
    const std::string key = dottedKey(assignment.substr(0, eq), "--set " + assignment),
                      text = assignment.substr(eq + 1);
    if (tooDeepAt(text) != std::string_view::npos)
        throw InputError(
            "--set", key,
            "value nests arrays/objects deeper than " + std::to_string(kMaxSceneDepth) + " levels",
            "flatten the value");
    std::optional<std::string> repeated;
    json value = json::parse(text, duplicateKeyFinder(repeated), /*allow_exceptions=*/false);
    if (value.is_discarded())
        value = text;  // bare words are strings: --set method.name=mip
    else if (repeated)
        throw InputError(
            "--set " + assignment, key + (repeated->rfind('[', 0) == 0 ? "" : ".") + *repeated,
            "is given twice in the same object", "keep one of the two: which value was meant?");
    // As errors name it: "--set key=value" once the key is known.
    const std::string said = "--set " + assignment;
    const std::vector<std::string> parts = keyParts(key);
    OverrideRecord record{normalizedKey(parts, parts.size()), {}, said, value.is_null()};
    json* node = &doc;
    json* parent = nullptr;
    std::string last;
    bool existed = true;  // whether the last key descended into was there before
    for (std::size_t k = 0; k < parts.size(); ++k) {
        parent = node;
        const std::string& part = parts[k];
        if (part.empty())
            throw InputError(said, key, "has an empty path component", "e.g. lights.0.intensity=2");
        if (isIndexPart(part) && node->is_array()) {
            const std::size_t i = indexOfPart(part);
            if (i >= node->size())
                throw InputError(said, key,
                                 "index " + part + " is past the end (size " +
                                     std::to_string(node->size()) + ")");
            node = &(*node)[i];
            continue;
        }
        // An index into nothing (a preset TF's points): no list to index, said so here — an
        // object created for it would read later as "points: must be a non-empty array".
        if (isIndexPart(part) && node->is_null() && k > 0) {
            if (record.removed) {
                record.removed = false;  // nothing was
                return record;
            }
            throw InputError(said, key, "'" + normalizedKey(parts, k) + "' is not there to index",
                             "set the whole list, e.g. " + normalizedKey(parts, k) + "=[...]");
        }
        if (node->is_null()) *node = json::object();
        // Shorthand forms expand so their keys can be overridden: "method": "mip" ≡ {"name":
        // "mip"}, etc.
        if (node->is_string() && node != &doc) {
            static const std::map<std::string, std::string> kShorthandKey = {
                {"method", "name"}, {"volume", "path"}, {"transfer_function", "preset"}};
            if (const auto it = kShorthandKey.find(k == 1 ? parts[0] : std::string());
                it != kShorthandKey.end())
                *node = json{{it->second, *node}};
        }
        if (!node->is_object()) {
            // Removing a key that cannot exist changes nothing (the scene's own shape is the
            // scene's to answer for when it is read).
            if (record.removed) {
                record.removed = false;  // nothing was
                return record;
            }
            throw InputError(said, key,
                             "'" + part + "' descends into " + typeName(*node) + ", not an object");
        }
        existed = node->contains(part);
        if (record.created.empty() && !existed) record.created = normalizedKey(parts, k + 1);
        node = &(*node)[part];
        last = part;
    }
    // null removes an object key: the default applies again (--set camera.azimuth=null).
    if (value.is_null() && parent && parent->is_object() && !last.empty()) {
        record.removed = parent->erase(last) > 0 && existed;       // not there before: nothing was
        if (record.created == record.key) record.created.clear();  // made and erased at once
    } else {
        *node = value;
    }
    return record;
}

namespace {
/// A field as errors name it ("lights[0].intensity") in the overrides' dotted form
/// ("lights.0.intensity").
std::string dottedField(const std::string& field) {
    std::string out;
    for (const char c : field) {
        if (c == '[')
            out += '.';
        else if (c != ']')
            out += c;
    }
    return out;
}
/// Whether dotted path `path` is `prefix` or lies under it.
bool atOrUnder(const std::string& path, const std::string& prefix) {
    return !prefix.empty() && path.compare(0, prefix.size(), prefix) == 0 &&
           (path.size() == prefix.size() || path[prefix.size()] == '.');
}
}  // namespace

const OverrideRecord* blamedOverride(const std::vector<OverrideRecord>& overrides,
                                     const std::string& field) {
    const std::string f = dottedField(field);
    for (auto it = overrides.rbegin(); it != overrides.rend(); ++it)
        if (atOrUnder(f, it->key) || atOrUnder(field, it->key) || atOrUnder(f, it->created) ||
            (it->removed && atOrUnder(it->key, f)) ||
            // A key it added under an object whose error names that object ("volume: needs
            // exactly one of 'path' or 'phantom'" after --set volume.path=… on a phantom).
            (!f.empty() && !it->created.empty() && atOrUnder(it->created, f)))
            return &*it;
    return nullptr;
}

InputError blameOverride(const InputError& e, const std::string& source,
                         const std::vector<OverrideRecord>& overrides) {
    if (e.source() != source) return e;
    const OverrideRecord* r = blamedOverride(overrides, e.field());
    return r ? InputError(r->said, e.field(), e.problem(), e.fix()) : e;
}

namespace {
Scene parseValidDepth(const json& doc, const std::string& source, const fs::path& baseDir) {
    Scene s;
    s.source = source;
    s.document = doc;
    const Field root(doc, "", s.source);
    root.allowOnly({"volume", "transfer_function", "camera", "lights", "clip_planes", "crop_box",
                    "method", "image", "render", "effects", "description"});
    s.volume = parseVolume(root.child("volume"), baseDir);
    s.transferFunction = parseTransferFunction(root.child("transfer_function"));
    s.camera = parseCamera(root.child("camera"));
    if (root.has("lights")) {
        const Field ls = root.child("lights");
        if (!ls.isArray()) ls.fail("must be an array of lights");
        for (std::size_t i = 0; i < ls.size(); ++i)
            s.lights.push_back(parseLight(ls.at(i), baseDir));
    }
    if (root.has("clip_planes")) {
        const Field cs = root.child("clip_planes");
        if (!cs.isArray()) cs.fail("must be an array of {point, normal, shadows_from_removed}");
        for (std::size_t i = 0; i < cs.size(); ++i) {
            const Field c = cs.at(i);
            c.allowOnly({"point", "normal", "shadows_from_removed"});
            ClipPlaneDesc p;
            c.get("point", p.point, -kMaxCoord, kMaxCoord);
            if (!c.has("normal")) c.fail("needs a 'normal'");
            p.normal = c.child("normal").unitVec3();
            c.get("shadows_from_removed", p.shadowsFromRemoved, kShadowsFromRemovedFix);
            s.clipPlanes.push_back(p);
        }
    }
    if (root.has("crop_box")) {
        const Field c = root.child("crop_box");
        c.allowOnly({"min", "max", "shadows_from_removed"});
        if (!c.has("min") || !c.has("max")) c.fail("needs 'min' and 'max' corners in mm");
        CropBoxDesc b{c.child("min").vec3(-kMaxCoord, kMaxCoord),
                      c.child("max").vec3(-kMaxCoord, kMaxCoord)};
        c.get("shadows_from_removed", b.shadowsFromRemoved, kShadowsFromRemovedFix);
        for (int a = 0; a < 3; ++a)
            if (!(b.min[a] < b.max[a])) c.child("min").fail("must be below 'max' on every axis");
        s.cropBox = b;
    }
    if (root.has("method")) {
        const Field m = root.child("method");
        // Which names exist, and what their params mean, is the method registry's business
        // (pipeline/registry.h); here only the shape.
        if (m.isString()) {
            s.method.name = m.string();
        } else {
            m.allowOnly({"name", "params"});
            if (!m.has("name")) m.fail("needs a 'name'", "e.g. \"gradient\"");
            s.method.name = m.child("name").string();
            if (m.has("params")) {
                m.child("params").expectObject();
                s.method.params = m.child("params").raw();
            }
        }
    }
    if (root.has("image")) {
        const Field im = root.child("image");
        im.allowOnly({"width", "height", "background", "exposure", "display"});
        im.get("width", s.image.width, 1, 16384);
        im.get("height", s.image.height, 1, 16384);
        im.get("background", s.image.background, 0.0, 1e9);
        im.get("exposure", s.image.exposureStops, -30.0, 30.0);
        im.get("display", s.image.display, {"clinical", "srgb", "filmic"});
    }
    if (root.has("render")) {
        const Field r = root.child("render");
        r.allowOnly({"step", "seed", "threads", "termination"});
        r.get("step", s.render.stepVoxels, 0.01, 16.0);
        int seed = 1;
        r.get("seed", seed, 0, 2147483647);
        s.render.seed = std::uint64_t(seed);
        r.get("threads", s.render.threads, 0, 1024);
        r.get("termination", s.render.termination, 0.0, 0.5);
    }
    if (root.has("effects")) {
        const Field e = root.child("effects");
        if (!e.isArray()) e.fail("must be an array of effect names", "e.g. [\"local_shadows\"]");
        s.effectsGiven = true;
        for (std::size_t i = 0; i < e.size(); ++i) s.effects.push_back(e.at(i).string());
    }
    return s;
}
}  // namespace

Scene parseScene(const json& doc, const std::string& source, const fs::path& baseDir) {
    // Checked before anything copies or dumps the document (both recurse per level).
    if (nestingDepth(doc) > kMaxSceneDepth)
        throw InputError(
            source, "",
            "nests arrays/objects deeper than " + std::to_string(kMaxSceneDepth) + " levels",
            "a scene needs a handful of levels; check --set keys and the file");
    try {
        return parseValidDepth(doc, source, baseDir);
    } catch (const json::exception& e) {
        // A value nlohmann cannot convert or print (e.g. a string that is not UTF-8).
        throw InputError(source, "", "cannot be read: " + jsonMessage(e),
                         "fix the value the message names");
    }
}

bool isPathKey(const std::string& key) {
    if (key == "volume" || key == "volume.path") return true;
    // lights.N.path
    if (key.rfind("lights.", 0) != 0) return false;
    const auto dot = key.find('.', 7);
    return dot != std::string::npos && dot > 7 && key.substr(dot) == ".path" &&
           std::all_of(key.begin() + 7, key.begin() + long(dot), asciiDigit);
}

std::vector<OverrideRecord> applyOverrides(json& doc, const std::vector<std::string>& overrides) {
    std::vector<OverrideRecord> records;
    for (const auto& o : overrides) {
        records.push_back(applyOverride(doc, o));
        const std::string key = dottedKey(o.substr(0, o.find('=')), "--set " + o);
        if (!isPathKey(key)) continue;
        // Walks to the value without creating anything: a removed key (null) stays removed.
        json* node = &doc;
        for (const std::string& part : keyParts(key)) {
            if (node->is_array()) {
                const std::size_t i = indexOfPart(part);
                node = i < node->size() ? &(*node)[i] : nullptr;
            } else if (node->is_object() && node->contains(part)) {
                node = &(*node)[part];
            } else {
                node = nullptr;
            }
            if (!node) break;
        }
        if (!node) continue;
        if (node->is_object() && node->contains("path")) node = &(*node)["path"];
        // (An empty path stays empty: the scene's check names it.)
        if (node->is_string() && !node->get<std::string>().empty() &&
            !fs::path(node->get<std::string>()).is_absolute())
            *node = fs::absolute(node->get<std::string>()).string();
    }
    return records;
}

Scene volumeScene(const fs::path& volume, const std::vector<std::string>& overrides) {
    json doc = {{"volume", fs::absolute(volume).lexically_normal().string()}};
    // The automatic view unless the overrides place the camera themselves.
    bool placed = false;
    for (const auto& o : overrides)
        for (const char* k : {"camera=", "camera.view=", "camera.azimuth=", "camera.elevation=",
                              "camera.eye=", "camera.up="})
            placed = placed || o.rfind(k, 0) == 0;
    if (!placed) doc["camera"] = {{"view", "auto"}};
    return parseWithOverrides(std::move(doc), overrides, volume.string(), fs::current_path());
}

Scene parseWithOverrides(json doc, const std::vector<std::string>& overrides,
                         const std::string& source, const fs::path& baseDir) {
    const std::vector<OverrideRecord> records = applyOverrides(doc, overrides);
    try {
        Scene s = parseScene(doc, source, baseDir);
        s.overrides = records;
        return s;
    } catch (const InputError& e) {
        throw blameOverride(e, source, records);
    }
}

namespace {
json vec3Document(const glm::dvec3& v) { return json::array({v.x, v.y, v.z}); }
}  // namespace

json lightDocument(const LightDesc& l) {
    const auto vec = vec3Document;
    json j = {{"type", l.type}, {"color", vec(l.color)}, {"intensity", l.intensity}};
    if (l.type == "directional") j["direction"] = vec(l.direction);
    if (l.type == "point") j["position"] = vec(l.position), j["min_distance"] = l.minDistance;
    if (l.type == "area") {
        j["shape"] = l.shape;
        j["position"] = vec(l.position);
        j["normal"] = vec(l.normal);
        j["radius"] = l.radius;
        j["size"] = {l.size.x, l.size.y};
    }
    if (l.type == "environment") {
        j["path"] = fs::absolute(l.path).lexically_normal().string();
        j["rotation"] = vec(l.rotationDeg);
        j["layout"] = l.layout;
    }
    return j;
}

json clipPlaneDocument(const ClipPlaneDesc& p) {
    return {{"point", vec3Document(p.point)},
            {"normal", vec3Document(p.normal)},
            {"shadows_from_removed", p.shadowsFromRemoved}};
}

json sceneDocument(const Scene& s) {
    auto vec = [](const glm::dvec3& v) { return json::array({v.x, v.y, v.z}); };
    json d = json::object();
    if (s.document.contains("description")) d["description"] = s.document["description"];
    const VolumeSource& v = s.volume;
    if (!v.phantom.empty()) {
        d["volume"] = {{"phantom", v.phantom}};
        if (v.phantomSize > 0) d["volume"]["size"] = v.phantomSize;
    } else {
        d["volume"] = {
            {"path", fs::absolute(v.path).lexically_normal().string()},
            {"nonfinite",
             v.readOptions.nonFinite == NonFinitePolicy::ReplaceWithMin ? "min" : "reject"}};
        if (!v.readOptions.dicomSeriesUid.empty())
            d["volume"]["series"] = v.readOptions.dicomSeriesUid;
        if (v.readOptions.strictGeometry) d["volume"]["strict_geometry"] = true;
    }
    const TransferFunctionDesc& t = s.transferFunction;
    json tf = json::object();
    if (!t.points.empty()) {
        tf["points"] = json::array();
        for (const auto& p : t.points) {
            json pt = {{"value", p.value},
                       {"color", vec(p.color)},
                       {"extinction", p.extinction},
                       {"emission", vec(p.emission)}};
            // The surface channels only when set (a scene without them reads back the same).
            if (p.specular != glm::dvec3(0.0)) pt["specular"] = vec(p.specular);
            if (p.roughness != 1.0) pt["roughness"] = p.roughness;
            if (p.phaseG) pt["phase_g"] = *p.phaseG;
            tf["points"].push_back(pt);
        }
    } else if (!t.preset.empty()) {
        tf["preset"] = t.preset;
    }
    tf["extinction_scale"] = t.extinctionScale;
    if (t.window) tf["window"] = {{"level", t.window->x}, {"width", t.window->y}};
    d["transfer_function"] = tf;
    const CameraDesc& c = s.camera;
    json cam = {{"projection", c.projection}};
    if (!c.view.empty()) {
        cam["view"] = c.view;
    } else {
        if (c.eye) {
            cam["eye"] = vec(*c.eye);
        } else {
            cam["azimuth"] = c.azimuthDeg;
            cam["elevation"] = c.elevationDeg;
        }
        cam["up"] = vec(c.up);
    }
    cam["roll"] = c.rollDeg;
    cam["distance"] = c.distance;
    cam["fov_y"] = c.fovYDeg;
    cam["ortho_height"] = c.orthoHeight;
    cam["margin"] = c.margin;
    cam["aperture"] = c.apertureMm;
    cam["focus_distance"] = c.focusMm ? json(*c.focusMm) : json("auto");
    if (c.target) cam["target"] = vec(*c.target);
    d["camera"] = cam;
    d["lights"] = json::array();
    for (const LightDesc& l : s.lights) d["lights"].push_back(lightDocument(l));
    d["clip_planes"] = json::array();
    for (const auto& p : s.clipPlanes) d["clip_planes"].push_back(clipPlaneDocument(p));
    if (s.cropBox)
        d["crop_box"] = {{"min", vec(s.cropBox->min)},
                         {"max", vec(s.cropBox->max)},
                         {"shadows_from_removed", s.cropBox->shadowsFromRemoved}};
    d["method"] = {{"name", s.method.name}, {"params", s.method.params}};
    d["image"] = {{"width", s.image.width},
                  {"height", s.image.height},
                  {"background", vec(s.image.background)},
                  {"exposure", s.image.exposureStops},
                  {"display", s.image.display}};
    d["render"] = {{"step", s.render.stepVoxels},
                   {"seed", s.render.seed},
                   {"threads", s.render.threads},
                   {"termination", s.render.termination}};
    if (s.effectsGiven) d["effects"] = s.effects;
    return d;
}

json readJsonFile(const fs::path& path) {
    const std::string file = path.string();
    std::error_code ec;
    if (fs::is_directory(path, ec))
        throw InputError(file, "", "is a directory, not a scene file", "give a .json file");
    core::refuseSpecialFile(path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(file, "", "cannot be opened", "check the path");
    std::string text;
    char chunk[1 << 16];
    while (in.read(chunk, sizeof chunk) || in.gcount() > 0) {
        text.append(chunk, std::size_t(in.gcount()));
        if (text.size() > kMaxSceneBytes)
            throw InputError(file, "", "is larger than 16 MiB, too large for a scene file",
                             "is this the right file?");
    }
    if (in.bad())
        throw InputError(file, "", "cannot be read", "check the file and its permissions");
    if (const std::size_t at = tooDeepAt(text); at != std::string_view::npos)
        throw InputError(file, "",
                         "nests arrays/objects deeper than " + std::to_string(kMaxSceneDepth) +
                             " levels (at byte " + std::to_string(at) + ")",
                         "a scene needs a handful of levels; is this the right file?");
    // nlohmann's lexer takes a NUL byte for the end of the input: what follows one was ignored.
    if (const std::size_t nul = text.find('\0'); nul != std::string::npos)
        throw InputError(file, "",
                         "is not valid JSON: a NUL byte at byte " + std::to_string(nul) +
                             " (JSON text holds none)",
                         "is this the right file? (a binary file, or text saved as UTF-16?)");
    json doc;
    std::optional<std::string> repeated;  // the first key an object holds twice, as a dotted path
    try {
        doc = json::parse(text, duplicateKeyFinder(repeated));
    } catch (const json::out_of_range& e) {
        throw InputError(file, "", "is not valid JSON: " + jsonMessage(e),
                         "numbers must be within double range (about ±1.8e308)");
    } catch (const json::exception& e) {
        // parse_error for syntax and invalid UTF-8; any other kind is reported the same way.
        throw InputError(file, "", "is not valid JSON: " + jsonMessage(e),
                         "fix the syntax at the byte shown");
    }
    // JSON readers disagree on which of two equal keys counts (nlohmann keeps the last, others
    // the first): the value a user edited may be the one dropped, so neither is taken.
    if (repeated)
        throw InputError(file, *repeated, "is given twice in the same object",
                         "keep one of the two: which value was meant?");
    return doc;
}

Scene loadScene(const fs::path& path, const std::vector<std::string>& overrides) {
    json doc = readJsonFile(path);
    fs::path base = path.parent_path();
    if (base.empty()) base = ".";
    return parseWithOverrides(std::move(doc), overrides, path.string(), base);
}

}  // namespace voxlight::io
