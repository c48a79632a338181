// SPDX-License-Identifier: MIT
#pragma once
// Sessions: a recorded exploration — a scene, then a timeline of keyframes, each holding the
// state of the camera, the transfer function, the lights, the clip planes and the method at a time
// in seconds.
// `voxlight replay` re-renders them (every keyframe, or a fixed frame rate); the viewer records
// them through Recorder. The file format (version 2; version 1 had no "method" part) is specified
// in docs/sessions.md:
//
// {
//   "format": "voxlight-session", "version": 2,
//   "description": "free text (optional)",
//   "scene": "../scenes/demo-torso.json" | { ...a scene document, io/scene.h... },
//   "keyframes": [
//     {"time": 0.0},
//     {"time": 2.5, "camera": {...}, "transfer_function": ..., "lights": [...],
//                   "clip_planes": [...], "method": ..., "note": "free text (optional)"},
//     ...
//   ]
// }
//
// A keyframe holds whole *parts*: each of "camera", "transfer_function", "lights", "clip_planes"
// and "method" it names replaces that part of the state before it, in the scene file's own
// syntax; the parts it leaves out carry over from the keyframe before (keyframe 0: from the
// scene). A part set to null goes back to its default (as --set key=null). Times are seconds,
// finite, ≥ 0 and strictly increasing; there is at least one keyframe.
//
// Between keyframes (frames at a fixed rate), the state at time t in [t_k, t_k+1) is:
//   camera       — the orientation (view direction, up and roll) is slerped about the target
//                  (a quaternion geodesic: a turntable orbit when only the azimuth changes,
//                  never a line through the volume); target, distance, field of view, ortho
//                  height, margin, aperture and a numeric focus distance are linear. Orbit
//                  cameras (azimuth/elevation) and look-at cameras (eye + target) interpolate
//                  alike; interpolated frames are written as orbit cameras. Held at keyframe k
//                  instead when the two cameras are equal, differ in projection, or one cannot
//                  be oriented without the volume (an eye without a target); a distance, target
//                  or focus distance that only one of the two gives (the other fits or
//                  autofocuses) holds keyframe k's.
//   clip planes  — point linear, normal slerped, when both keyframes have the same number of
//                  planes with the same shadows_from_removed; else held.
//   lights       — colour, intensity, positions, sizes linear, directions slerped, when both
//                  keyframes have the same lights (count, type, area shape, environment map);
//                  else held.
//   transfer function — held: a TF change is a cut. Every distinct TF rebuilds its tables,
//                  skip cells and visibility, so an interpolated TF would recompute them for
//                  every frame.
// At a keyframe's time the state is that keyframe's exactly (the same document, bit for bit).
//
// Every failure to read a session is an io InputError naming the file, the field
// ("keyframes[2].time", "scene.volume", "keyframes[3].camera.azimuth") and the fix.
#include <cstddef>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "io/scene.h"

namespace voxlight::session {

/// The session format this code reads and writes ("version"); newer files are refused.
inline constexpr int kFormatVersion = 2;
/// The first version with the "method" part (the viewer's method and shading switches).
inline constexpr int kMethodPartVersion = 2;
/// The "format" value that marks a session file.
inline constexpr const char* kFormatName = "voxlight-session";
/// The parts of a scene a keyframe may hold.
const std::vector<std::string>& stateParts();

/// The state a keyframe records: the parts of a scene an exploration changes.
struct State {
    io::CameraDesc camera;
    io::TransferFunctionDesc transferFunction;  ///< empty: the modality's default
    std::vector<io::LightDesc> lights;          ///< empty: the headlight
    std::vector<io::ClipPlaneDesc> clipPlanes;
    io::MethodDesc method;  ///< held between keyframes (a switch of method is a cut)
};
/// The state of a scene (its camera, TF, lights, clip planes and method).
State stateOf(const io::Scene& scene);

struct Keyframe {
    double time = 0.0;  ///< seconds
    /// The parts this keyframe sets, as JSON in the scene's syntax (keys of stateParts()).
    nlohmann::json parts = nlohmann::json::object();
    std::string note;
};

struct Session {
    std::string source;             ///< the session file, named in errors
    std::filesystem::path baseDir;  ///< relative paths in the scene and keyframes resolve here
    std::string description;
    /// The scene as referenced ("" when inline) and its document (read from that file, or inline).
    std::string scenePath;
    nlohmann::json scene = nlohmann::json::object();
    std::vector<Keyframe> keyframes;  ///< at least one once parsed; times strictly increasing

    double startTime() const { return keyframes.front().time; }
    double endTime() const { return keyframes.back().time; }
    /// The scene document at keyframe k: the scene with the parts of keyframes 0..k applied.
    nlohmann::json documentAt(std::size_t k) const;
    /// The scene document at time t (clamped to [startTime(), endTime()]), interpolated as the
    /// header comment says. InputError (this session's file) when the state cannot be formed.
    nlohmann::json documentAtTime(double t) const;
    /// The scene at keyframe k / time t, with `overrides` (--set key=value, io::applyOverrides)
    /// applied last, validated (io::parseScene). InputError naming the file and key otherwise.
    io::Scene sceneAt(std::size_t k, const std::vector<std::string>& overrides = {}) const;
    io::Scene sceneAtTime(double t, const std::vector<std::string>& overrides = {}) const;
    /// `field` of the scene in force at keyframe k ("method.params.rays") as the session file
    /// spells its origin: "keyframes[i].method.params.rays" for the last keyframe i ≤ k that set
    /// its top-level part, else `field` itself (the scene's own).
    std::string fieldAt(std::size_t k, const std::string& field) const;
    /// The same for the keyframe in force at time t.
    std::string fieldAtTime(double t, const std::string& field) const;

  private:
    /// The last document documentAt() formed: the document at k + j is this one with j more
    /// keyframes applied (each call rebuilt 0..k: 8,000 keyframes took 5 s to load and as long
    /// again to replay; probe). Valid while the keyframes' storage, the scene and keyframe k (the
    /// recorder replaces the last one in place) are as they were; keyframes before k are never
    /// edited. Made with the session (no unguarded lazy creation), one per copy.
    struct DocumentCache;
    struct CacheHolder {
        std::shared_ptr<DocumentCache> cache;
        CacheHolder();
        CacheHolder(const CacheHolder&);
        CacheHolder& operator=(const CacheHolder&);
    };
    CacheHolder cache_;
};

/// Most frames one replay may ask for (keyframes, or duration × fps + 1).
inline constexpr std::size_t kMaxFrames = 100000;

/// The times of the frames at `fps` frames per second: startTime() + i / fps for every i whose
/// time is at most endTime() (a frame at the start, then every 1/fps seconds; the last keyframe
/// is a frame when the duration is a whole number of frames; a frame that falls on a keyframe,
/// to within a millionth of a frame, has that keyframe's exact time). InputError (source "--fps") when
/// fps is not a finite number in (0, 1000] or the frames would exceed kMaxFrames.
std::vector<double> frameTimes(const Session& session, double fps);

/// Validates a session document. `source` names it in errors; relative paths (the scene file,
/// and paths inside an inline scene or keyframes) resolve against `baseDir`. Every keyframe's
/// state is validated as a scene. Throws InputError (see the header comment).
Session parseSession(const nlohmann::json& doc, const std::string& source,
                     const std::filesystem::path& baseDir);
/// Reads (io::readJsonFile's limits) and validates a session file.
Session loadSession(const std::filesystem::path& path);

/// The session as a document in the file format (parseSession reads it back).
nlohmann::json sessionDocument(const Session& session);
/// The session file's text as writeSession writes it, without the final newline.
std::string sessionText(const Session& session);
/// Writes the session to `path` atomically: a temporary file beside it, renamed into place once
/// complete (a failure leaves the previous file, or none, never half of one). InputError naming
/// the path, with the system's reason, when it cannot be written.
void writeSession(const Session& session, const std::filesystem::path& path);

/// Records an exploration (the viewer's API). Usage:
///     session::Recorder rec(scene);            // the scene being explored
///     rec.record(0.0, session::stateOf(scene));
///     ... the user orbits, edits the TF, moves a plane ...
///     rec.record(secondsSinceStart, state);     // whenever the state changed (or on a timer)
///     rec.save("exploration.json");             // atomic; replay with `voxlight replay`
/// A keyframe stores only the parts that differ from the keyframe before (the first stores
/// all of them), so recording an unchanged state costs a few bytes.
class Recorder {
  public:
    /// Starts from `scene`, written inline with every key at its value and paths absolute
    /// (io::sceneDocument), so the session does not depend on where it is saved.
    explicit Recorder(const io::Scene& scene, std::string description = {});
    /// Appends a keyframe. `seconds` must be finite, ≥ 0 and not before the last keyframe's
    /// time; a record at the last keyframe's time replaces that keyframe. InputError (source
    /// "recorder", field "time") otherwise, or naming the part when the state is not valid.
    void record(double seconds, const State& state, const std::string& note = {});
    const Session& session() const { return session_; }
    /// writeSession(session(), path). InputError when there is no keyframe yet.
    void save(const std::filesystem::path& path) const;

  private:
    io::Scene scene_;  ///< the starting scene (template for writing states)
    Session session_;
    std::vector<nlohmann::json> states_;  ///< every part of each keyframe's state
};

}  // namespace voxlight::session
