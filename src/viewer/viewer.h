// SPDX-License-Identifier: MIT
#pragma once
// voxlight view: the interactive viewer's window (GLFW, OpenGL 4.5 core, Dear ImGui).
//
// Layout: the volume image fills the window left of a fixed-width side panel; the image is
// rendered at the size of that area, so at rest one image pixel is one window pixel. On this project's GPU-less machines the image is the CPU
// ray caster's (RenderWorker, the pipeline `voxlight render` runs), shown as a texture; the UI
// thread never waits for it.
//
// Mouse on the image: left-drag orbits, middle-drag or shift+left-drag pans, the wheel zooms,
// right-drag sets window/level; a left-drag that starts on a clip plane's handle (the gizmo drawn
// over the image) moves that plane along its normal, ctrl+left-drag turns the selected light.
// Panels: file, view, info, transfer function, lights, clip planes, path tracer, session, stats,
// help. Keys: helpText() (also shown in the help panel).
//
// Scripted mode (options.screenshot): draws at least options.frames frames, waits — drawing
// frames, not blocking — until the full-resolution image of the current state is shown, then
// returns the window's content (the frame as drawn, panels included) — or, when the screenshot
// path ends in .exr, the linear radiance film of the image shown (the image area only: the CPU
// worker's film, the GLSL path's float film or the path tracer's raw estimate, as `voxlight render
// --exr` writes it). F12 / the panel's button does the same by the path's extension.
#include <atomic>
#include <functional>
#include <optional>
#include <string>

#include "core/image.h"
#include "io/scene.h"
#include "session/session.h"
#include "viewer/gl_support.h"
#include "viewer/loaded_scene.h"
#include "viewer/view_state.h"

namespace voxlight::viewer {

/// Width of the side panel in window pixels (the image area is the rest of the window).
inline constexpr int kPanelWidth = 380;

/// ViewerOptions::glSliceSeconds by default: half the UI frame's 50 ms budget.
inline constexpr double kDefaultGlSliceSeconds = 0.025;

/// The exit code when the display connection is lost mid-run (app's kExitBadInput: the display
/// is the run's environment, as when no window can be opened).
inline constexpr int kExitDisplayLost = 2;
/// The exit code when the display goes with a Ctrl-C (app's kExitCancelled: under xvfb-run the
/// interrupt reaches the X server too).
inline constexpr int kExitViewerCancelled = 130;

struct ViewerOptions {
    /// Non-empty: scripted run that returns a screenshot (the caller writes the file; .exr: the
    /// image's linear radiance, see above).
    std::string screenshot;
    int frames = 1;  ///< scripted: at least this many frames before the screenshot
    double screenshotTimeoutSeconds = 600.0;
    bool log = false;  ///< frame and render times on stderr
    /// Makes a scene from a path typed in the file field or dropped on the window (a scene file,
    /// a volume or a DICOM folder); throws InputError.
    std::function<io::Scene(const std::string&)> openInput;
    /// Writes a screenshot the user asks for (F12 or the panel's button) to a path; throws
    /// InputError (shown in the panel). `current`: the scene on screen (its files are inputs a
    /// path typed in the panel must not replace). Unset: the button is hidden.
    std::function<void(const core::ImageRGBA&, const std::string&, const io::Scene& current)>
        saveScreenshot;
    /// Writes the recorded session to a path (the panel's Save, and `record` when the viewer
    /// closes or loses its display); throws InputError. `current` as for saveScreenshot. Unset:
    /// session::writeSession.
    std::function<void(const session::Session&, const std::string&, const io::Scene& current)>
        saveSession;
    /// Steps run one per frame, each once the full image of the state before it is shown, through
    /// the code paths of the mouse and keys (view_state.h ScriptStep); a scripted screenshot is
    /// taken after the last.
    std::vector<ScriptStep> script;
    /// Non-empty: record the exploration as a session (session/session.h Recorder) — a keyframe
    /// for every state the viewer asks a full image of (settled states: the end of a drag, a
    /// key, a panel edit), timed from the first — and write it here when the viewer closes (or,
    /// scripted, before it returns). The panel's Session section saves it on demand too.
    std::string record;
    /// Which path draws the image: Auto measures both when a volume is loaded (a few frames of
    /// the GLSL ray caster, timed with glFinish, against the CPU worker's median frame) and keeps
    /// the faster; Gpu / Cpu force one. A scene the GLSL path cannot do (gl_support.h), a context
    /// without OpenGL 4.5 or a shader that does not compile fall back to the CPU path, and the
    /// stats panel (and --log) says why. Scripted screenshots wait for the choice.
    RendererChoice renderer = RendererChoice::Auto;
    /// GLSL path: GL time one UI frame spends on the image at most (about; measured per pixel of
    /// the last slice). A frame that takes longer (a software rasteriser, a slow GPU, a large
    /// window) is rendered in slices of rows over several UI frames, the last image shown
    /// meanwhile — the same pixels as in one pass. 0: whole frames (the UI waits for each).
    double glSliceSeconds = kDefaultGlSliceSeconds;
    /// Raised (e.g. by SIGINT): close the window and return.
    const std::atomic<bool>* quit = nullptr;
};

/// The keyboard shortcuts, one per line ("key  action").
const char* helpText();

/// A scripted screenshot of `scene` the renderer will refuse (its image size) is refused before
/// a window opens or a volume loads (a 16384² one failed after a minute or more of coarse
/// frames, naming the screenshot file): InputError naming the scene's image.width.
void checkScreenshotSize(const io::Scene& scene);

/// Throws runViewer's InputError (source "display") when no display can be reached, at once:
/// a command checks this before it loads a volume (a missing display was said only after the
/// load, seconds to minutes on a large series; probe).
void requireDisplay();

/// Opens the window and runs until it is closed (or, scripted, until the screenshot). Throws
/// InputError (source "display") when no OpenGL 4.5 window can be opened, with GLFW's reason.
std::optional<core::ImageRGBA> runViewer(const ViewerOptions& options,
                                         std::optional<LoadedScene> initial);

}  // namespace voxlight::viewer
