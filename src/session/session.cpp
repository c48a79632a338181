// SPDX-License-Identifier: MIT
#include "session/session.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <glm/gtc/quaternion.hpp>
#include <limits>
#include <mutex>
#include <optional>
#include <sstream>

#include "core/error.h"
#include "io/json_field.h"

namespace voxlight::session {

namespace fs = std::filesystem;
using nlohmann::json;

const std::vector<std::string>& stateParts() {
    static const std::vector<std::string> parts = {"camera", "transfer_function", "lights",
                                                   "clip_planes", "method"};
    return parts;
}

State stateOf(const io::Scene& scene) {
    return {scene.camera, scene.transferFunction, scene.lights, scene.clipPlanes, scene.method};
}

namespace {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
/// render/camera.h's kParallelUpCos: an up within 2.6° of the view is replaced by a world axis.
/// (session/ sits below render/, so the rule is repeated here for orienting keyframe cameras.)
constexpr double kParallelUpCos = 0.999;
/// Directions closer than this (cosine) are interpolated linearly and renormalised (slerp's
/// 1/sin θ loses precision as θ → 0).
constexpr double kNearlyParallelCos = 0.9995;
/// Directions this close to opposite have no unique slerp: the part is held instead.
constexpr double kOppositeCos = -0.999999;

using io::described;
using io::shortDump;
using io::typeName;

std::string number(double v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

/// The same error with its field under `prefix` ("keyframes[2]" + "camera.fov_y"), from `source`.
[[noreturn]] void rethrowUnder(const InputError& e, const std::string& source,
                               const std::string& prefix) {
    throw InputError(source, e.field().empty() ? prefix : prefix + "." + e.field(), e.problem(),
                     e.fix());
}

void applyParts(json& doc, const json& parts) {
    for (auto it = parts.begin(); it != parts.end(); ++it) {
        if (it.value().is_null())
            doc.erase(it.key());
        else
            doc[it.key()] = it.value();
    }
}

double lerp(double a, double b, double s) { return a + (b - a) * s; }
glm::dvec3 lerp(const glm::dvec3& a, const glm::dvec3& b, double s) { return a + (b - a) * s; }
json vec(const glm::dvec3& v) { return json::array({v.x, v.y, v.z}); }

/// Great-circle interpolation of unit directions; nullopt when they are (nearly) opposite.
std::optional<glm::dvec3> slerpDirection(const glm::dvec3& a, const glm::dvec3& b, double s) {
    const double c = std::clamp(glm::dot(a, b), -1.0, 1.0);
    if (c < kOppositeCos) return std::nullopt;
    if (c > kNearlyParallelCos) return glm::normalize(lerp(a, b, s));
    const double theta = std::acos(c), sinTheta = std::sin(theta);
    return (std::sin((1.0 - s) * theta) * a + std::sin(s * theta) * b) / sinTheta;
}

/// The camera's orientation as render::Camera builds it: columns right, up, back (= −forward),
/// roll applied. nullopt for a look-at camera without a target (its view direction needs the
/// volume's centre).
std::optional<glm::dmat3> orientation(const io::CameraDesc& c) {
    glm::dvec3 forward;
    if (c.eye) {
        if (!c.target) return std::nullopt;
        forward = glm::normalize(*c.target - *c.eye);
    } else {
        const double az = c.azimuthDeg * kDegToRad, el = c.elevationDeg * kDegToRad;
        forward =
            -glm::dvec3(std::sin(az) * std::cos(el), -std::cos(az) * std::cos(el), std::sin(el));
    }
    glm::dvec3 up = glm::normalize(c.up);
    if (std::abs(glm::dot(up, forward)) > kParallelUpCos) {
        const glm::dvec3 candidates[] = {glm::dvec3(0.0, forward.z > 0 ? 1.0 : -1.0, 0.0),
                                         glm::dvec3(0.0, 0.0, 1.0), glm::dvec3(1.0, 0.0, 0.0)};
        for (const glm::dvec3& cand : candidates)
            if (std::abs(glm::dot(cand, forward)) <= kParallelUpCos) {
                up = cand;
                break;
            }
    }
    glm::dvec3 right = glm::normalize(glm::cross(forward, up));
    up = glm::cross(right, forward);
    if (c.rollDeg != 0.0) {
        const double r = c.rollDeg * kDegToRad, co = std::cos(r), si = std::sin(r);
        const glm::dvec3 r2 = co * right + si * up, u2 = -si * right + co * up;
        right = r2, up = u2;
    }
    return glm::dmat3(right, up, -forward);
}

/// Distance from the target: the look-at eye's, or the orbit's (0 = fitted).
double cameraDistance(const io::CameraDesc& c) {
    return c.eye ? glm::length(*c.eye - *c.target) : c.distance;
}

/// The camera between a (s = 0) and b (s = 1), as a camera part; nullopt = hold a.
std::optional<json> interpolateCamera(const io::CameraDesc& a, const io::CameraDesc& b, double s) {
    if (a.projection != b.projection) return std::nullopt;
    const auto ra = orientation(a), rb = orientation(b);
    if (!ra || !rb) return std::nullopt;
    // Orientation: the geodesic between the two rotations (glm::slerp takes the shorter way).
    const glm::dquat q = glm::slerp(glm::quat_cast(*ra), glm::quat_cast(*rb), s);
    const glm::dmat3 m = glm::mat3_cast(glm::normalize(q));
    const glm::dvec3 up = glm::normalize(m[1]), back = glm::normalize(m[2]);
    // back is the orbit direction (target → eye): camera.h's (sin az cos el, −cos az cos el,
    // sin el).
    const double el = std::asin(std::clamp(back.z, -1.0, 1.0)) / kDegToRad;
    const double az = std::atan2(back.x, -back.y) / kDegToRad;
    json cam = {{"projection", a.projection},
                {"azimuth", az},
                {"elevation", std::clamp(el, -90.0, 90.0)},
                {"up", vec(up)},
                {"roll", 0.0},
                {"fov_y", lerp(a.fovYDeg, b.fovYDeg, s)},
                {"margin", lerp(a.margin, b.margin, s)},
                {"aperture", lerp(a.apertureMm, b.apertureMm, s)}};
    const double da = cameraDistance(a), db = cameraDistance(b);
    cam["distance"] = da > 0.0 && db > 0.0 ? lerp(da, db, s) : da;
    cam["ortho_height"] = a.orthoHeight > 0.0 && b.orthoHeight > 0.0
                              ? lerp(a.orthoHeight, b.orthoHeight, s)
                              : a.orthoHeight;
    if (a.target && b.target)
        cam["target"] = vec(lerp(*a.target, *b.target, s));
    else if (a.target)
        cam["target"] = vec(*a.target);
    if (a.focusMm && b.focusMm)
        cam["focus_distance"] = lerp(*a.focusMm, *b.focusMm, s);
    else
        cam["focus_distance"] = a.focusMm ? json(*a.focusMm) : json("auto");
    return cam;
}

std::optional<std::vector<io::ClipPlaneDesc>> interpolatePlanes(
    const std::vector<io::ClipPlaneDesc>& a, const std::vector<io::ClipPlaneDesc>& b, double s) {
    if (a.size() != b.size()) return std::nullopt;
    std::vector<io::ClipPlaneDesc> out = a;
    for (std::size_t i = 0; i < a.size(); ++i) {
        if (a[i].shadowsFromRemoved != b[i].shadowsFromRemoved) return std::nullopt;
        const auto n = slerpDirection(a[i].normal, b[i].normal, s);
        if (!n) return std::nullopt;
        out[i].point = lerp(a[i].point, b[i].point, s);
        out[i].normal = *n;
    }
    return out;
}

std::optional<std::vector<io::LightDesc>> interpolateLights(const std::vector<io::LightDesc>& a,
                                                            const std::vector<io::LightDesc>& b,
                                                            double s) {
    if (a.size() != b.size()) return std::nullopt;
    std::vector<io::LightDesc> out = a;
    for (std::size_t i = 0; i < a.size(); ++i) {
        const io::LightDesc &la = a[i], &lb = b[i];
        if (la.type != lb.type || la.shape != lb.shape || la.path != lb.path ||
            la.layout != lb.layout)
            return std::nullopt;
        const auto dir = slerpDirection(la.direction, lb.direction, s);
        const auto normal = slerpDirection(la.normal, lb.normal, s);
        if (!dir || !normal) return std::nullopt;
        io::LightDesc& l = out[i];
        l.color = lerp(la.color, lb.color, s);
        l.intensity = lerp(la.intensity, lb.intensity, s);
        l.direction = *dir;
        l.position = lerp(la.position, lb.position, s);
        l.minDistance = lerp(la.minDistance, lb.minDistance, s);
        l.normal = *normal;
        l.radius = lerp(la.radius, lb.radius, s);
        l.size = la.size + (lb.size - la.size) * s;
        l.rotationDeg = lerp(la.rotationDeg, lb.rotationDeg, s);
    }
    return out;
}

/// Writes `text` to `path` through a temporary file in the same folder and a rename.
void writeAtomically(const fs::path& path, const std::string& text) {
    const std::string target = path.string();
    auto fail = [&](const std::string& what, int err) {
        throw InputError(target, "", what + ": " + std::strerror(err),
                         "check that the folder exists and is writable");
    };
    fs::path dir = path.parent_path();
    if (dir.empty()) dir = ".";
    std::string pattern = (dir / ("." + path.filename().string() + ".XXXXXX")).string();
    const int fd = ::mkstemp(pattern.data());
    if (fd < 0) fail("cannot be written", errno);
    const std::string temporary = pattern;
    std::size_t done = 0;
    while (done < text.size()) {
        const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            const int err = n < 0 ? errno : EIO;
            ::close(fd);
            ::unlink(temporary.c_str());
            fail("cannot be written", err);
        }
        done += std::size_t(n);
    }
    ::fchmod(fd, 0644);  // mkstemp makes 0600; a session is an ordinary document
    if (::fsync(fd) != 0 || ::close(fd) != 0) {
        const int err = errno;
        ::unlink(temporary.c_str());
        fail("cannot be written", err);
    }
    if (::rename(temporary.c_str(), target.c_str()) != 0) {
        const int err = errno;
        ::unlink(temporary.c_str());
        fail("cannot be replaced", err);
    }
}

}  // namespace

struct Session::DocumentCache {
    std::mutex mutex;
    const Keyframe* keyframes = nullptr;  ///< the storage the document was formed from
    std::size_t k = 0;                    ///< keyframes 0..k applied
    json scene, doc;
    /// Keyframe k as applied: the recorder replaces the last keyframe in place (same storage).
    double time = 0.0;
    json parts;
};

Session::CacheHolder::CacheHolder() : cache(std::make_shared<DocumentCache>()) {}
Session::CacheHolder::CacheHolder(const CacheHolder&) : CacheHolder() {}
Session::CacheHolder& Session::CacheHolder::operator=(const CacheHolder&) {
    cache = std::make_shared<DocumentCache>();  // a copy's keyframes are its own
    return *this;
}

json Session::documentAt(std::size_t k) const {
    VL_CHECK_LT(k, keyframes.size());
    DocumentCache& c = *cache_.cache;
    std::lock_guard lock(c.mutex);
    if (c.keyframes != keyframes.data() || c.k > k || c.scene != scene ||
        c.time != keyframes[c.k].time || c.parts != keyframes[c.k].parts) {
        c.keyframes = keyframes.data();
        c.scene = scene;
        c.doc = scene;
        c.k = 0;
        applyParts(c.doc, keyframes[0].parts);
    }
    for (; c.k < k; ++c.k) applyParts(c.doc, keyframes[c.k + 1].parts);
    c.time = keyframes[c.k].time;
    c.parts = keyframes[c.k].parts;
    return c.doc;
}

json Session::documentAtTime(double t) const {
    VL_CHECK(!keyframes.empty());
    t = std::clamp(t, startTime(), endTime());
    // The keyframe at or before t.
    std::size_t k = 0;
    while (k + 1 < keyframes.size() && keyframes[k + 1].time <= t) ++k;
    json doc = documentAt(k);
    if (keyframes[k].time == t || k + 1 == keyframes.size()) return doc;
    const double s = (t - keyframes[k].time) / (keyframes[k + 1].time - keyframes[k].time);
    json next = doc;  // not documentAt(k + 1): the next frame asks for k again
    applyParts(next, keyframes[k + 1].parts);
    const io::Scene a = io::parseScene(doc, source, baseDir);
    const io::Scene b = io::parseScene(next, source, baseDir);
    auto same = [&](const char* part) {
        return doc.value(part, json()) == next.value(part, json());
    };
    if (!same("camera"))
        if (auto cam = interpolateCamera(a.camera, b.camera, s)) doc["camera"] = *cam;
    // Planes and lights are written as the scene format writes them (absolute environment paths);
    // a part that is held keeps keyframe k's text.
    io::Scene mixed = a;
    bool planes = false, lights = false;
    if (!same("clip_planes"))
        if (auto p = interpolatePlanes(a.clipPlanes, b.clipPlanes, s))
            mixed.clipPlanes = *p, planes = true;
    if (!same("lights"))
        if (auto l = interpolateLights(a.lights, b.lights, s)) mixed.lights = *l, lights = true;
    if (planes || lights) {
        const json written = io::sceneDocument(mixed);
        if (planes) doc["clip_planes"] = written["clip_planes"];
        if (lights) doc["lights"] = written["lights"];
    }
    return doc;
}

std::string Session::fieldAt(std::size_t k, const std::string& field) const {
    const std::string part = field.substr(0, field.find_first_of(".["));
    for (std::size_t i = std::min(k + 1, keyframes.size()); i-- > 0;)
        if (keyframes[i].parts.contains(part))
            return "keyframes[" + std::to_string(i) + "]." + field;
    return field;
}

std::string Session::fieldAtTime(double t, const std::string& field) const {
    std::size_t k = 0;
    while (k + 1 < keyframes.size() && keyframes[k + 1].time <= t) ++k;
    return fieldAt(k, field);
}

io::Scene Session::sceneAt(std::size_t k, const std::vector<std::string>& overrides) const {
    try {
        return io::parseWithOverrides(documentAt(k), overrides, source, baseDir);
    } catch (const InputError& e) {
        // An error of this file's (not an override's) names the keyframe that set the key.
        if (e.source() != source) throw;
        throw InputError(source, fieldAt(k, e.field()), e.problem(), e.fix());
    }
}

io::Scene Session::sceneAtTime(double t, const std::vector<std::string>& overrides) const {
    try {
        return io::parseWithOverrides(documentAtTime(t), overrides, source, baseDir);
    } catch (const InputError& e) {
        if (e.source() != source) throw;
        throw InputError(source, fieldAtTime(t, e.field()), e.problem(), e.fix());
    }
}

std::vector<double> frameTimes(const Session& session, double fps) {
    if (!std::isfinite(fps) || !(fps > 0.0) || fps > 1000.0)
        throw InputError("--fps", "", "must be a number in (0, 1000], got " + number(fps),
                         "e.g. --fps 25");
    const double duration = session.endTime() - session.startTime();
    // Tolerance: a duration that is a whole number of frames ends on the last keyframe.
    const double count = std::floor(duration * fps + 1e-6) + 1.0;
    if (count > double(kMaxFrames))
        throw InputError("--fps", "",
                         number(fps) + " frames per second over " + number(duration) +
                             " s make more than " + std::to_string(kMaxFrames) + " frames",
                         "choose a lower frame rate");
    // A frame within that tolerance (a millionth of a frame) of a keyframe takes the keyframe's
    // own time: t0 + i/fps rounds (0.1 + 7/10 = 0.7999…), and a frame a rounding short of a
    // keyframe interpolates towards it instead of showing its state (a cut to a new method or
    // TF at the last keyframe never appeared).
    const double snap = 1e-6 / fps;
    std::vector<double> times;
    std::size_t k = 0;  // the first keyframe not before the previous frame
    for (std::size_t i = 0; i < std::size_t(count); ++i) {
        double t = std::min(session.startTime() + double(i) / fps, session.endTime());
        while (k + 1 < session.keyframes.size() && session.keyframes[k].time < t - snap) ++k;
        if (std::abs(session.keyframes[k].time - t) <= snap) t = session.keyframes[k].time;
        times.push_back(t);
    }
    return times;
}

Session parseSession(const json& doc, const std::string& source, const fs::path& baseDir) {
    auto fail = [&](const std::string& field, const std::string& problem,
                    const std::string& fix = {}) -> void {
        throw InputError(source, field, problem, fix);
    };
    Session s;
    s.source = source;
    s.baseDir = baseDir;
    if (!doc.is_object())
        fail("", "must be a JSON object, got " + typeName(doc),
             "a session starts {\"format\": \"voxlight-session\", \"version\": 2, ...}");
    static const std::vector<std::string> keys = {"format", "version", "description", "scene",
                                                  "keyframes"};
    for (auto it = doc.begin(); it != doc.end(); ++it)
        if (std::find(keys.begin(), keys.end(), it.key()) == keys.end())
            fail(it.key(), "unknown key", "allowed keys: " + joinNames(keys));
    if (!doc.contains("format") || doc["format"] != kFormatName)
        fail("format",
             doc.contains("format")
                 ? "must be \"voxlight-session\", got " + shortDump(doc["format"])
                 : "is required",
             "a session file starts {\"format\": \"voxlight-session\", \"version\": 2, ...}");
    // A whole number written as 2.0 is the version 2 (JSON has one number type).
    const json* v = doc.contains("version") ? &doc["version"] : nullptr;
    const bool whole = v && v->is_number_float() && std::isfinite(v->get<double>()) &&
                       v->get<double>() == std::floor(v->get<double>());
    if (!v || (!v->is_number_integer() && !whole))
        fail("version", v ? "must be an integer, got " + described(*v) : "is required",
             "\"version\": 2");
    // An unsigned version past long long's range read as -1 ("must be 1 or 2, got -1").
    const long long version =
        whole ? (std::abs(v->get<double>()) < 1e18 ? static_cast<long long>(v->get<double>())
                                                   : std::numeric_limits<long long>::max())
        : v->is_number_unsigned() &&
                v->get<std::uint64_t>() > std::uint64_t(std::numeric_limits<long long>::max())
            ? std::numeric_limits<long long>::max()
            : v->get<long long>();
    if (version > kFormatVersion)
        fail("version",
             "is " + shortDump(doc["version"]) + ", written by a newer voxlight (this one reads " +
                 std::to_string(kFormatVersion) + ")",
             "replay it with a newer voxlight");
    if (version < 1)
        fail("version", "must be 1 or 2, got " + std::to_string(version), "\"version\": 2");
    if (doc.contains("description")) {
        if (!doc["description"].is_string())
            fail("description", "must be a string, got " + typeName(doc["description"]),
                 "free text in quotes, or leave it out");
        s.description = doc["description"].get<std::string>();
    }

    // The scene: a file (its relative paths resolve against its folder, and so do the
    // keyframes') or inline (against the session's folder).
    if (!doc.contains("scene"))
        fail("scene", "is required",
             "give \"scene\": \"path/to/scene.json\" or an inline scene {\"volume\": ...}");
    const json& scene = doc["scene"];
    std::string sceneSource = source, scenePrefix = "scene";
    if (scene.is_string()) {
        s.scenePath = scene.get<std::string>();
        const fs::path p =
            fs::path(s.scenePath).is_absolute() ? fs::path(s.scenePath) : baseDir / s.scenePath;
        std::error_code ec;
        if (!fs::exists(p, ec))
            fail("scene", "names '" + p.string() + "', which does not exist",
                 "give the scene file's path relative to the session file, or the scene inline");
        s.scene = io::readJsonFile(p);
        s.baseDir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
        sceneSource = p.string(), scenePrefix.clear();
        if (!s.scene.is_object())
            throw InputError(sceneSource, "", "must be a scene object, got " + typeName(s.scene));
    } else if (scene.is_object()) {
        s.scene = scene;
    } else {
        fail("scene", "must be a scene file's path or a scene object, got " + typeName(scene),
             "give \"scene\": \"path/to/scene.json\" or an inline scene {\"volume\": ...}");
    }
    try {
        (void)io::parseScene(s.scene, sceneSource, s.baseDir);
    } catch (const InputError& e) {
        if (scenePrefix.empty()) throw;
        rethrowUnder(e, source, scenePrefix);
    }

    // The keyframes: times, then each state validated as a scene.
    if (!doc.contains("keyframes"))
        fail("keyframes", "is required", "add \"keyframes\": [{\"time\": 0}, ...]");
    const json& kfs = doc["keyframes"];
    if (!kfs.is_array() || kfs.empty())
        fail("keyframes", "must be a non-empty array of keyframes, got " + described(kfs),
             "e.g. \"keyframes\": [{\"time\": 0}, {\"time\": 2, \"camera\": {\"azimuth\": 90}}]");
    std::vector<std::string> allowed = {"time", "note"};
    for (const auto& p : stateParts()) allowed.push_back(p);
    for (std::size_t i = 0; i < kfs.size(); ++i) {
        const std::string at = "keyframes[" + std::to_string(i) + "]";
        const json& k = kfs[i];
        if (!k.is_object())
            fail(at, "must be an object, got " + described(k),
                 "e.g. {\"time\": 1.5, \"camera\": {...}}");
        Keyframe kf;
        for (auto it = k.begin(); it != k.end(); ++it) {
            if (std::find(allowed.begin(), allowed.end(), it.key()) == allowed.end())
                fail(at + "." + it.key(), "unknown key", "allowed keys: " + joinNames(allowed));
            if (it.key() == "method" && version < kMethodPartVersion)
                fail(at + ".method", "needs version 2 of the format (this file says 1)",
                     "set \"version\": 2");
            if (it.key() != "time" && it.key() != "note") kf.parts[it.key()] = it.value();
        }
        if (!k.contains("time"))
            fail(at + ".time", "is required", "the keyframe's time in seconds, e.g. \"time\": 1.5");
        const json& t = k["time"];
        if (!t.is_number())
            fail(at + ".time", "must be a number of seconds, got " + described(t),
                 "e.g. \"time\": 1.5, without quotes or units");
        kf.time = t.get<double>();
        if (!std::isfinite(kf.time) || kf.time < 0.0)
            fail(at + ".time", "must be a finite number of seconds ≥ 0, got " + number(kf.time),
                 "seconds since the session's start, e.g. \"time\": 0");
        if (i > 0 && !(kf.time > s.keyframes.back().time))
            fail(at + ".time",
                 "must be after the keyframe before it (" + number(s.keyframes.back().time) +
                     " s), got " + number(kf.time) + " s",
                 "keyframes are in time order, at most one per time");
        if (k.contains("note")) {
            if (!k["note"].is_string())
                fail(at + ".note", "must be a string, got " + typeName(k["note"]),
                     "free text in quotes, or leave it out");
            kf.note = k["note"].get<std::string>();
        }
        s.keyframes.push_back(std::move(kf));
        try {
            (void)io::parseScene(s.documentAt(i), source, s.baseDir);
        } catch (const InputError& e) {
            rethrowUnder(e, source, at);
        }
    }
    return s;
}

Session loadSession(const fs::path& path) {
    const json doc = io::readJsonFile(path);
    fs::path base = path.parent_path();
    if (base.empty()) base = ".";
    return parseSession(doc, path.string(), base);
}

json sessionDocument(const Session& s) {
    json d = {{"format", kFormatName}, {"version", kFormatVersion}};
    if (!s.description.empty()) d["description"] = s.description;
    d["scene"] = s.scenePath.empty() ? s.scene : json(s.scenePath);
    d["keyframes"] = json::array();
    for (const Keyframe& k : s.keyframes) {
        json j = {{"time", k.time}};
        if (!k.note.empty()) j["note"] = k.note;
        for (auto it = k.parts.begin(); it != k.parts.end(); ++it) j[it.key()] = it.value();
        d["keyframes"].push_back(j);
    }
    return d;
}

std::string sessionText(const Session& session) {
    return sessionDocument(session).dump(2, ' ', false, json::error_handler_t::replace);
}

void writeSession(const Session& session, const fs::path& path) {
    writeAtomically(path, sessionText(session) + "\n");
}

Recorder::Recorder(const io::Scene& scene, std::string description) : scene_(scene) {
    session_.source = "recorder";
    session_.baseDir = fs::current_path();
    session_.description = std::move(description);
    session_.scene = io::sceneDocument(scene);
    // An empty TF (the modality's default) has no written form: left out, as the scene left it.
    if (scene.transferFunction.preset.empty() && scene.transferFunction.points.empty())
        session_.scene.erase("transfer_function");
}

void Recorder::record(double seconds, const State& state, const std::string& note) {
    if (!std::isfinite(seconds) || seconds < 0.0)
        throw InputError("recorder", "time",
                         "must be a finite number of seconds ≥ 0, got " + number(seconds),
                         "pass the seconds since the recording started");
    std::vector<Keyframe>& kfs = session_.keyframes;
    if (!kfs.empty() && seconds < kfs.back().time)
        throw InputError("recorder", "time",
                         "must not be before the last keyframe (" + number(kfs.back().time) +
                             " s), got " + number(seconds) + " s",
                         "record in time order (the same time replaces the last keyframe)");
    if (!kfs.empty() && seconds == kfs.back().time) kfs.pop_back(), states_.pop_back();
    // Every part in the scene format (io::sceneDocument of the scene with this state).
    io::Scene s = scene_;
    s.camera = state.camera;
    s.transferFunction = state.transferFunction;
    s.lights = state.lights;
    s.clipPlanes = state.clipPlanes;
    s.method = state.method;
    const json written = io::sceneDocument(s);
    json full = json::object();
    for (const auto& part : stateParts()) full[part] = written.value(part, json());
    if (state.transferFunction.preset.empty() && state.transferFunction.points.empty())
        full["transfer_function"] = nullptr;
    Keyframe kf;
    kf.time = seconds;
    kf.note = note;
    for (const auto& part : stateParts())
        if (states_.empty() || full[part] != states_.back()[part]) kf.parts[part] = full[part];
    // Validated now, where the viewer can show the error, not when the session is replayed.
    json doc = kfs.empty() ? session_.scene : session_.documentAt(kfs.size() - 1);
    applyParts(doc, kf.parts);
    (void)io::parseScene(doc, "recorder", session_.baseDir);
    kfs.push_back(std::move(kf));
    states_.push_back(std::move(full));
}

void Recorder::save(const fs::path& path) const {
    if (session_.keyframes.empty())
        throw InputError(path.string(), "keyframes", "the recording holds no keyframe yet",
                         "call record() at least once before save()");
    writeSession(session_, path);
}

}  // namespace voxlight::session
