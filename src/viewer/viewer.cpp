// SPDX-License-Identifier: MIT
#include "viewer/viewer.h"

#define GLFW_INCLUDE_NONE
#include <GL/gl.h>
#include <GLFW/glfw3.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>
#include <imgui.h>
#include <imgui_stdlib.h>

#include <algorithm>
#include <cctype>
#include <cfloat>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "core/error.h"
#include "core/timing.h"
#include "render/ray_caster.h"
#include "session/session.h"
#include "viewer/display_loss.h"
#include "viewer/gl_ray_caster.h"
#include "viewer/render_worker.h"
#include "viewer/tf_editor.h"
#include "viewer/view_state.h"

namespace voxlight::viewer {

namespace {
using nlohmann::json;

/// Frame budget of the UI loop when idle: it sleeps in glfwWaitEventsTimeout (woken by any event)
/// for what is left of it, so an idle viewer leaves the cores to the renderer.
constexpr double kFrameBudgetSeconds = 1.0 / 60.0;
/// Mouse: degrees of orbit per pixel dragged; zoom factor per wheel notch.
constexpr double kOrbitDegPerPixel = 0.4, kZoomPerNotch = 1.1;
/// Frames left out of the frame-time statistics (GL shader compilation, ImGui's font atlas).
constexpr std::uint64_t kWarmUpFrames = 3;
/// Share of the GL slice budget a slice's rows are planned to take (the rest is for the slice's
/// fixed costs: a new TF table's upload, the uniforms, the wait).
constexpr double kGlSliceRowShare = 0.8;
/// Bounds of a frame's cost against the last one's, as its slices measure it (one slice's noise
/// must not make the next a single row or the whole frame).
constexpr double kGlCostScaleMin = 0.25, kGlCostScaleMax = 8.0;
/// A UI frame slower than this is logged with its phases (the issue's bound for the UI frame).
constexpr double kSlowFrameSeconds = 0.050;
/// Clip-plane gizmo: a left click this close (window pixels) to a plane's handle grabs it; the
/// normal's arrow length.
constexpr float kHandleGrabPixels = 12.f, kArrowPixels = 36.f;
/// Start-up measurement: timed frames of each path (the GL path's first frame, which uploads the
/// volume and compiles the shader's machine code, is not counted).
constexpr int kMeasureFrames = 3;
/// ... but only while one frame is shorter than this: a longer frame is timed once (its noise is
/// small beside it). A 2048² CPU frame of 7.6 s timed three times cost 23 s of a 62-s scripted
/// screenshot on llvmpipe.
constexpr double kMeasureOnceSeconds = 1.0;
/// How long a lost display waits for a screenshot the panel is writing (encoding a large PNG
/// takes a few seconds) before the process ends.
constexpr int kScreenshotFinishSeconds = 10;
/// The GL path's timing stops when the GL time spent on its probe (the central quarter of the
/// image, ×4) or on a frame is already this many times the CPU's median: on a software
/// rasteriser a GL frame can take seconds, and there is no need to finish one.
constexpr double kClearlySlower = 3.0;
/// Rows of a frame's first slice while the GL's time per pixel is still unknown.
constexpr int kGlFirstSliceRows = 4;
/// Window size when started without a scene.
constexpr int kDefaultImageWidth = 720, kDefaultImageHeight = 720;

const char* const kHelp =
    "left drag          orbit about the volume\n"
    "shift+left / middle drag   pan\n"
    "wheel, + / -       zoom\n"
    "right drag         window (horizontal) / level (vertical)\n"
    "A P L R S I        anterior, posterior, left, right, superior,\n"
    "                   inferior view (fitted to what the TF shows)\n"
    "O                  oblique view\n"
    "Home               back to the scene's own camera\n"
    "W                  back to the scene's window/level\n"
    "C                  add a clip plane facing the view (cuts away\n"
    "                   the front half; drag its handle to move it)\n"
    "left drag on a plane's handle   move the clip plane along its normal\n"
    "G                  show / hide the clip-plane gizmo\n"
    "ctrl+left drag     turn the selected light (horizontal: azimuth,\n"
    "                   vertical: elevation)\n"
    "F1 or H            show / hide this help\n"
    "F12                save a screenshot (path in the File panel;\n"
    "                   .exr: the image's linear radiance)\n"
    "Ctrl+O             focus the file field\n"
    "drop a file        open it (scene, volume, DICOM folder)\n"
    "Esc or Q           quit\n";

/// GLFW's last error, for the one-line message when the window cannot be opened.
std::string glfwErrorText() {
    const char* d = nullptr;
    const int code = glfwGetError(&d);
    return code == GLFW_NO_ERROR
               ? std::string("no reason given")
               : std::string(d ? d : "unknown") + " (GLFW error " + std::to_string(code) + ")";
}

/// Input GLFW reports through callbacks, collected for the next frame: paths dropped on the
/// window, and key presses (key, modifiers). ImGui's own key callback is chained to onKey.
std::mutex gInputMutex;
std::vector<std::string> gDropped;
std::vector<std::pair<int, int>> gKeyPresses;
void onDrop(GLFWwindow*, int count, const char** paths) {
    std::lock_guard lock(gInputMutex);
    for (int i = 0; i < count; ++i) gDropped.emplace_back(paths[i]);
}
/// Paths dropped since the last call (the frame's event phase takes them).
std::vector<std::string> takeDropped() {
    std::vector<std::string> dropped;
    std::lock_guard lock(gInputMutex);
    dropped.swap(gDropped);
    return dropped;
}
bool dropPending() {
    std::lock_guard lock(gInputMutex);
    return !gDropped.empty();
}
void onKey(GLFWwindow*, int key, int, int action, int mods) {
    if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
    std::lock_guard lock(gInputMutex);
    gKeyPresses.emplace_back(key, mods);
}

/// The patient direction(s) a world (LPS) vector points to, strongest first: "L", "AS", ... —
/// axes contributing less than a third of the largest are left out.
std::string patientDirection(const glm::dvec3& d) {
    const char* letters[3][2] = {{"L", "R"}, {"P", "A"}, {"S", "I"}};
    int order[3] = {0, 1, 2};
    std::sort(order, order + 3, [&](int a, int b) { return std::abs(d[a]) > std::abs(d[b]); });
    std::string out;
    for (int i : order)
        if (std::abs(d[i]) >= std::abs(d[order[0]]) / 3.0 && std::abs(d[i]) > 1e-9)
            out += letters[i][d[i] > 0 ? 0 : 1];
    return out;
}

/// A rolling record of durations (seconds) for the stats panel and the log.
struct Timings {
    std::deque<double> values;  ///< the newest `capacity` values
    std::size_t capacity = 240;
    double allMax = 0.0;                    ///< over the whole session
    std::uint64_t count = 0, overSlow = 0;  ///< all values; those over kSlowFrameSeconds
    void add(double s) {
        allMax = std::max(allMax, s);
        ++count;
        overSlow += s > kSlowFrameSeconds;
        values.push_back(s);
        if (values.size() > capacity) values.pop_front();
    }
    double last() const { return values.empty() ? 0.0 : values.back(); }
    double max() const {
        return values.empty() ? 0.0 : *std::max_element(values.begin(), values.end());
    }
    double mean() const {
        double s = 0.0;
        for (double v : values) s += v;
        return values.empty() ? 0.0 : s / double(values.size());
    }
    double min() const {
        return values.empty() ? 0.0 : *std::min_element(values.begin(), values.end());
    }
};

class Viewer {
  public:
    Viewer(const ViewerOptions& options, GLFWwindow* window) : options_(options), window_(window) {
        if (!options_.record.empty()) recordPath_ = options_.record;
        choice_ = options_.renderer;
        if (choice_ != RendererChoice::Cpu) {
            // GL errors never end the viewer: without a working GLSL path the CPU image is shown.
            gl_ = std::make_unique<GlRayCaster>();
            std::string why;
            if (!gl_->init(why)) {
                glError_ = why;
                gl_.reset();
                if (options_.log || choice_ == RendererChoice::Gpu)
                    std::fprintf(stderr, "view: GLSL ray caster off: %s\n", why.c_str());
            }
        }
    }
    ~Viewer() {
        *loadCancel_ = true;  // closing: the futures' destructors wait for the cancelled loads
        if (texture_) glDeleteTextures(1, &texture_);
        if (ptTexture_) glDeleteTextures(1, &ptTexture_);
    }

    void adopt(LoadedScene scene);
    std::optional<core::ImageRGBA> run();
    std::optional<core::ImageRGBA> runFrames();
    /// --record's session so far saved when the run ends early (a lost display, a script step's
    /// error): what became of it, as a clause to append to the run's last line.
    std::string keepRecording();

  private:
    // Scene edits: every change bumps the generation and asks the worker for a new picture.
    void changed() { ++generation_, dirty_ = true; }
    /// The panel's switch between local and global SH visibility (sh-local / sh-global scenes):
    /// both fields stay cached (pipeline, resampled grids, GL textures), so switching back and
    /// forth recomputes nothing once each was shown.
    void setShVisibility(bool global) {
        if (switchShVisibility(doc_, global, shStash_)) changed();
    }
    void setCamera(const json& camera) {
        doc_["camera"] = camera;
        changed();
    }
    void setTf(const optics::TransferFunction& tf) {
        tf_ = tf;
        doc_["transfer_function"] = transferFunctionJson(tf_);
        changed();
    }
    bool ensureLookAt();
    void snapView(const std::string& view);
    // What the gestures do (the mouse, the keys and a script call the same).
    void orbitBy(double dx, double dy);
    void panBy(double dx, double dy);
    bool zoomBy(double notches);
    void windowDrag(const optics::TransferFunction& start, double dx, double dy);
    // Lights and clip planes: the panel, the mouse and the script call these.
    void setLights() {
        doc_["lights"] = lightsJson(lights_);
        changed();
    }
    void setClipPlanes() {
        // The camera stays put: a fitted camera would re-frame to the matter the planes leave,
        // and the plane would run away from the cursor dragging it.
        if (!lookAt_ && ensureLookAt()) doc_["camera"] = cameraJson(*lookAt_, doc_["camera"]);
        doc_["clip_planes"] = clipPlanesJson(clips_);
        changed();
    }
    void addLight(const std::string& type, const std::string& path);
    void turnLightBy(int index, double dAzimuthDeg, double dElevationDeg);
    /// A plane through the volume's centre + offset along `normal`, or facing the view (normal
    /// = the camera's forward: the front half is cut away). False when no image was rendered yet.
    bool addClipPlane(std::optional<glm::dvec3> normal, double offsetMm);
    void moveClipPlaneBy(int index, double mm);
    /// The gizmo's drag: (dx, dy) window pixels, projected onto the plane's normal.
    void dragClipPlane(int index, double dx, double dy);
    /// The plane's handle: the volume's centre projected onto it (world mm).
    glm::dvec3 clipHandle(const io::ClipPlaneDesc& p) const {
        return loaded_->centre - glm::dot(loaded_->centre - p.point, p.normal) * p.normal;
    }
    /// The camera of the shown image at the drawn image's size (for the gizmo), if any.
    std::optional<render::Camera> shownCamera() const;
    /// World point → window pixel through the shown image's camera.
    std::optional<ImVec2> toWindow(const render::Camera& cam, const glm::dvec3& p) const;
    void drawGizmo(ImDrawList* dl);
    void drawLightsPanel(float width);
    void drawClipPanel(float width);
    /// Throws the script's InputError when a step names a plane or light that is not there.
    void checkIndex(const ScriptStep& st, std::size_t count, const char* what) const;
    /// Runs the next script step when the full image of the current state is shown.
    void runScript();
    /// An error the view raises after script steps ran, named by the last step (scriptNext_ > 0).
    InputError scriptStepError(const std::string& what) const;
    void recordState(const io::Scene& scene);
    // "Render this view with the path tracer": a second worker, its image shown in place of the
    // live one while the view is unchanged.
    void startPathTrace(int spp);
    void receivePathTrace();
    bool pathTraceShown() const { return ptReady_ && ptGen_ == generation_ && ptShow_; }
    std::string saveRecording(const std::string& path);
    /// The scene the view shows now, for the files it reads (see the definition).
    io::Scene sceneOnScreen() const;

  public:
    /// The display connection is gone (DisplayLossGuard): saves --record's session (the panel's
    /// own recording is not written anywhere unasked), lets a panel screenshot being written
    /// finish, says on stderr what was kept and returns the exit code (cancelled when the
    /// display went with a Ctrl-C).
    int displayLost();

  private:
    void submit(bool interacting);
    /// The current view as a scene of w × h pixels (the document's method unless `method` is set).
    io::Scene sceneAt(int w, int h, const json& method = json()) const;
    void receive();
    // The renderer: the start-up measurement and the choice (see ViewerOptions::renderer).
    void restartMeasurement();
    void updateRenderer();
    void choose(bool gpu, const std::string& reason);
    /// Starts rendering the prepared state with the GLSL ray caster (replacing a frame in
    /// progress) and runs its first slice; shown when its last slice is done (stepGl). False (and
    /// back to the CPU path, with the reason) when the GL fails.
    bool renderGl(const RenderedImage& prepared);
    /// One slice of the GLSL frame in progress, about ViewerOptions::glSliceSeconds of GL work;
    /// shows the frame after its last.
    bool stepGl();
    /// Rows of `width` texels for one slice of that budget at the last slice's GL time per pixel
    /// (kGlFirstSliceRows before any; all `left` with no budget), at least 1, at most `left`.
    int sliceRows(int width, int left) const;
    /// Rows of the GLSL frame from `firstRow` on for one slice: by the last frame's cost per row
    /// of this kind (coarse or full) and size, sliceRows() without one.
    /// `scale`: this frame's measured / predicted cost so far (a frame dearer than the last one,
    /// e.g. after a window change that shows more matter, is planned dearer from its 2nd slice);
    /// `predicted`: the rows' cost by the last frame (0 without one).
    /// `lastRows`: the job's last slice's rows (0 before its first).
    int glSliceRows(bool coarse, int width, int height, int firstRow, int lastRows, double scale,
                    double& predicted) const;
    struct RowCosts {
        int width = 0;
        std::vector<double> seconds;  ///< per row of the last frame; < 0: not measured
    };
    RowCosts glRowCosts_[2];  ///< full, coarse
    /// Opens `path` as the file field's Open button does; a drop on the window comes here too.
    void openPath(const std::string& path);
    void startLoad(const std::string& path);
    void pollLoad();
    void handleImageMouse();
    void handleKeys();
    void drawImage();
    void drawPanel();
    core::ImageRGBA readWindow() const;
    /// The linear radiance film of the image shown (the path-traced one when it shows; the GLSL
    /// path's film; the CPU worker's): what an EXR screenshot holds. Empty (0×0) before any.
    core::ImageRGBA shownRadiance() const;
    /// A screenshot for `path`: the linear film for .exr, else the window as drawn.
    core::ImageRGBA screenshotFor(const std::string& path) const;
    void logTimes();

    ViewerOptions options_;
    GLFWwindow* window_;
    RenderWorker worker_;

    std::optional<LoadedScene> loaded_;
    json shStash_;                  ///< sh-global's own params while the switch shows sh-local
    json doc_;                      ///< the scene as edited
    optics::TransferFunction tf_;   ///< the TF as edited (explicit after the first edit)
    std::optional<LookAt> lookAt_;  ///< set once the mouse moved the camera
    json renderedCamera_;           ///< the camera of the newest image
    std::uint64_t renderedCameraGen_ = 0, cameraResetGen_ = 0;
    std::uint64_t generation_ = 1;
    bool dirty_ = false, interactingSent_ = false;
    int imageW_ = 0, imageH_ = 0;                            ///< the image area, window pixels
    float drawX0_ = 0, drawY0_ = 0, drawW_ = 0, drawH_ = 0;  ///< where the image is drawn

    // Lights and clip planes as edited (written into doc_ by setLights / setClipPlanes).
    std::vector<io::LightDesc> lights_;
    std::vector<ViewClipPlane> clips_;
    int selectedLight_ = 0, selectedClip_ = 0;
    int newLightType_ = 0;
    std::string envPath_, editMessage_;
    bool showGizmo_ = true, panelDragging_ = false;
    int clipDragIndex_ = -1;

    // Mouse drags on the image.
    enum class Drag { None, Orbit, Pan, Window, Clip, Light } drag_ = Drag::None;
    static const char* dragName(Drag d);
    // A scripted drag in progress (a gizmo's, or an orbit, pan or window/level drag): the
    // per-frame motion, the frames left and those done.
    Drag scriptDrag_ = Drag::None;
    int scriptDragFrames_ = 0, scriptDragDone_ = 0, scriptDragIndex_ = 0;
    double scriptDragDx_ = 0.0, scriptDragDy_ = 0.0;
    bool scriptDragMoved_ = false;  ///< this frame made a scripted drag's motion
    /// UI frame work during the current drag (all its frames; --log says it when it ends).
    Timings dragWork_{{}, std::size_t(-1)};
    const char* dragWorkName_ = nullptr;
    ImVec2 dragStart_{0, 0};
    optics::TransferFunction tfAtDrag_;
    bool tfEditing_ = false;

    // The shown image.
    GLuint texture_ = 0;
    int texW_ = 0, texH_ = 0;
    bool shownFull_ = false;
    bool shownStale_ = false;  ///< shaded from an earlier state's visibility fields
    std::uint64_t shownGen_ = 0;
    std::string renderError_;
    std::vector<std::string> renderWarnings_;

    // Loading from the file field or a drop.
    std::string path_;
    std::future<LoadedScene> loading_;
    std::shared_ptr<std::atomic<bool>> loadCancel_ = std::make_shared<std::atomic<bool>>(false);
    std::shared_ptr<std::atomic<double>> loadFraction_ = std::make_shared<std::atomic<double>>(0.0);
    std::vector<std::future<LoadedScene>> retired_;  ///< superseded loads, cancelled, finishing
    std::string loadingPath_, loadError_;
    bool focusPath_ = false;
    std::string shotPath_ = "voxlight-view.png", shotMessage_;
    bool shotRequested_ = false;
    std::future<std::string> saving_;  ///< a screenshot being written: its message when done
    /// The last full CPU image's frame (its Frame stages, not the run's one-time stages).
    double lastFullFrameSeconds_ = 0.0;

    // Recording the exploration as a session.
    std::optional<session::Recorder> recorder_;
    core::Stopwatch recordClock_;
    std::string recordPath_ = "voxlight-session.json", recordMessage_;
    std::size_t scriptNext_ = 0;

    RenderWorker ptWorker_;
    std::uint64_t ptGen_ = 0;  ///< the state the path tracer renders (0: none asked)
    int ptSpp_ = 64;
    GLuint ptTexture_ = 0;
    int ptW_ = 0, ptH_ = 0;
    bool ptReady_ = false, ptShow_ = true;
    /// The films of the CPU image and of the path-traced one shown (EXR screenshots).
    std::shared_ptr<const core::ImageRGBA> shownFilm_, ptFilm_;
    std::string ptMessage_;

    // The GLSL path and the choice of renderer.
    RendererChoice choice_ = RendererChoice::Auto;
    std::unique_ptr<GlRayCaster> gl_;  ///< null: no working GLSL path (glError_ says why)
    std::string glError_;
    enum class Measure { Waiting, Prepare, CpuFrames, GlFrames, Done } measure_ = Measure::Waiting;
    bool gpu_ = false;      ///< the GLSL path draws the image
    bool shownGl_ = false;  ///< the image shown is the GLSL path's
    std::string rendererReason_ = "measuring both paths ...";
    std::optional<RenderedImage> prepared_;  ///< newest prepared state (GLSL path)
    std::vector<double> glMeasured_;         ///< timed GL frames of the measurement
    int glFramesRun_ = 0;
    int glMeasureRow_ = 0;           ///< rows of the measurement's current probe or frame done
    double glMeasureSeconds_ = 0.0;  ///< their GL time
    /// UI frames and seconds spent uploading textures (a new volume's, new SH fields) since the
    /// last GLSL frame or measurement step that reported them (--log).
    int glUploadFrames_ = 0;
    double glUploadSeconds_ = 0.0;
    std::uint64_t measureGen_ = 0;  ///< the state being measured
    int cpuFrames_ = 0;             ///< frames behind cpuMeasured_
    double cpuMeasured_ = 0.0;      ///< the CPU's median frame of the measurement
    Timings glTimes_, glCoarseTimes_;
    /// The GLSL frame in progress (renderGl, stepGl).
    struct GlJob {
        RenderedImage state;
        int nextRow = 0, slices = 0;
        double seconds = 0.0;    ///< GL time of its slices so far (each waited for)
        double costScale = 1.0;  ///< its last slice's time / the last frame's for those rows
        int lastRows = 0;
        /// The UI frame of its last slice (one slice per UI frame); none yet: ~0.
        std::uint64_t uiFrame = ~std::uint64_t(0);
    };
    std::optional<GlJob> glJob_;
    /// A state prepared while a coarse frame was in progress: that one finishes first (it is
    /// short; replacing it at every drag motion could leave the drag without pictures).
    std::optional<RenderedImage> glNext_;
    double glPixelSeconds_ = 0.0;  ///< GL seconds per pixel of the last slice (0: not measured)

    TfEditorState tfEditor_;
    bool showHelp_ = false, helpToggled_ = false;
    Timings frameWork_, frameInterval_, coarseTimes_, fullTimes_;
    core::Stopwatch logClock_;
    std::uint64_t frames_ = 0;
};

void Viewer::adopt(LoadedScene scene) {
    loaded_ = std::move(scene);
    shStash_ = json();
    // The volume read for the info panel and histogram is the pipeline's too: read once.
    worker_.adoptVolume(loaded_->scene, loaded_->volume);
    ptWorker_.adoptVolume(loaded_->scene, loaded_->volume);
    doc_ = loaded_->document;
    tf_ = loaded_->tf;
    tfEditor_ = {};
    lights_ = loaded_->scene.lights;
    clips_.clear();
    for (const io::ClipPlaneDesc& p : loaded_->scene.clipPlanes) clips_.push_back({p, true});
    selectedLight_ = selectedClip_ = 0;
    clipDragIndex_ = -1, scriptDragFrames_ = 0, scriptDrag_ = Drag::None;
    lookAt_.reset();
    cameraResetGen_ = generation_ + 1;
    path_ = loaded_->scene.source;
    restartMeasurement();
    if (!options_.record.empty() || recorder_) {
        // A newly opened volume starts a new session (a session holds one scene).
        recorder_.emplace(loaded_->scene, "recorded by voxlight view");
        recordClock_.restart();
    }
    changed();
}

bool Viewer::ensureLookAt() {
    if (lookAt_) return true;
    // Continue from the camera the renderer used for the current placement (none yet: wait).
    if (renderedCamera_.is_null() || renderedCameraGen_ < cameraResetGen_) return false;
    lookAt_ = lookAtFromRendered(renderedCamera_, loaded_->centre);
    return true;
}

void Viewer::snapView(const std::string& view) {
    if (!loaded_) return;
    lookAt_.reset();
    cameraResetGen_ = generation_ + 1;
    setCamera(namedViewJson(view, doc_.value("camera", json::object())));
}

io::Scene Viewer::sceneAt(int w, int h, const json& method) const {
    json doc = doc_;
    doc["image"]["width"] = w;
    doc["image"]["height"] = h;
    if (!method.is_null()) {
        doc["method"] = method;  // the path tracer's "render this view"
        if (doc.contains("effects")) doc["effects"] = pathTraceEffects(doc["effects"]);
    }
    return sceneFromDocument(doc, loaded_->scene.source);
}

void Viewer::submit(bool interacting) {
    if (!loaded_ || imageW_ < 1 || imageH_ < 1) return;
    try {
        io::Scene scene = sceneAt(imageW_, imageH_);
        if (!interacting) recordState(scene);
        RenderRequest request{std::move(scene), generation_, interacting};
        request.prepareOnly = gpu_;  // the GLSL path renders on this thread
        worker_.submit(std::move(request));
        renderError_.clear();
    } catch (const std::exception& e) {
        renderError_ = e.what();
    }
}

void Viewer::receive() {
    std::optional<RenderedImage> r = worker_.take();
    if (!r) return;
    if (!r->error.empty()) {
        renderError_ = r->error;
        return;
    }
    if (r->prepared) {
        if (options_.log && r->shResampleSeconds > 0.0)
            std::fprintf(stderr, "view: SH fields resampled for the GLSL path in %.3f s\n",
                         r->shResampleSeconds);
        // For the GLSL path (or its measurement): render it here when it draws the image.
        prepared_ = std::move(*r);
        // A coarse frame never replaces the full image of the same state (a late drag frame),
        // shown or on its way.
        const std::uint64_t g = prepared_->generation;
        const bool fullComing =
            (glJob_ && !glJob_->state.coarse && glJob_->state.generation == g) ||
            (glNext_ && !glNext_->coarse && glNext_->generation == g);
        const bool late = prepared_->coarse && ((shownFull_ && g == shownGen_) || fullComing);
        if (gpu_ && prepared_->generation >= shownGen_ && !late) renderGl(*prepared_);
        return;
    }
    if (measure_ == Measure::CpuFrames && !r->coarse && r->frameSeconds > 0.0 &&
        r->generation == measureGen_) {
        cpuMeasured_ = r->frameSeconds;
        cpuFrames_ = r->frames;
        measure_ = Measure::GlFrames;
    }
    if (gpu_) return;  // a CPU image of a state asked before the switch
    (r->coarse ? coarseTimes_ : fullTimes_).add(r->seconds);
    if (!r->coarse) lastFullFrameSeconds_ = r->frameSeconds;
    if (options_.log)
        std::fprintf(stderr, "view: render %s %dx%d in %.3f s (state %llu)%s\n",
                     r->coarse ? "coarse" : "full", r->width, r->height, r->seconds,
                     (unsigned long long)r->generation,
                     r->staleShading ? " shaded from earlier fields" : "");
    // An older state's image still shows the volume better than nothing; a newer one replaces it.
    if (r->generation < shownGen_) return;
    if (!texture_) glGenTextures(1, &texture_);
    glBindTexture(GL_TEXTURE_2D, texture_);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, r->width, r->height, 0, GL_RGBA, GL_UNSIGNED_BYTE,
                 r->rgba.data());
    // Full resolution is shown pixel for pixel; the coarse image is magnified smoothly.
    const GLint filter = r->coarse ? GL_LINEAR : GL_NEAREST;
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, filter);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, filter);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    texW_ = r->width, texH_ = r->height;
    shownFilm_ = r->film;
    shownFull_ = !r->coarse;
    shownStale_ = r->staleShading;
    shownGl_ = false;
    shownGen_ = r->generation;
    renderWarnings_ = r->warnings;
    if (!r->camera.is_null()) renderedCamera_ = r->camera, renderedCameraGen_ = r->generation;
}

void Viewer::restartMeasurement() {
    glJob_.reset();
    glRowCosts_[0] = glRowCosts_[1] = {};  // a new volume: nothing known of its rows
    glNext_.reset();
    measure_ = Measure::Waiting;
    glMeasured_.clear();
    glFramesRun_ = 0;
    glMeasureRow_ = 0, glMeasureSeconds_ = 0.0;
    glUploadFrames_ = 0, glUploadSeconds_ = 0.0;
    cpuMeasured_ = 0.0;
    gpu_ = false;
    rendererReason_ = "measuring both paths ...";
}

void Viewer::choose(bool gpu, const std::string& reason) {
    measure_ = Measure::Done;
    rendererReason_ = reason;
    // Said with --log, and always when the GLSL path was asked for and is not used.
    if (options_.log || (choice_ == RendererChoice::Gpu && !gpu))
        std::fprintf(stderr, "view: renderer %s: %s\n", gpu ? "gpu (GLSL)" : "cpu", reason.c_str());
    if (gpu == gpu_) return;
    gpu_ = gpu;
    if (!gpu_) glJob_.reset(), glNext_.reset();
    // The new path renders the current state (the GLSL path from a prepared state).
    if (gpu_ && prepared_ && prepared_->generation == generation_ && prepared_->setup)
        renderGl(*prepared_);
    else
        changed();
}

bool Viewer::renderGl(const RenderedImage& p) {
    if (glJob_ && glJob_->state.coarse && glJob_->slices > 0) {
        glNext_ = p;
        return true;
    }
    glJob_.reset();
    glNext_.reset();
    std::string why;
    if (!gl_) {
        why = glError_;
    } else if (!p.setup) {
        why = glUnsupportedReason(p.method, nullptr);
    } else {
        glJob_ = GlJob{p};
        return stepGl();
    }
    choose(false, "the GLSL path failed, the CPU draws: " + why);
    return false;
}

int Viewer::sliceRows(int width, int left) const {
    left = std::max(left, 1);
    if (!(options_.glSliceSeconds > 0.0)) return left;
    if (!(glPixelSeconds_ > 0.0)) return std::min(kGlFirstSliceRows, left);
    // Clamped in double: a tiny time per pixel must not overflow the int.
    return int(std::clamp(options_.glSliceSeconds / (glPixelSeconds_ * double(std::max(width, 1))),
                          1.0, double(left)));
}

int Viewer::glSliceRows(bool coarse, int width, int height, int firstRow, int lastRows,
                        double scale, double& predicted) const {
    predicted = 0.0;
    const int left = std::max(height - firstRow, 1);
    const RowCosts& costs = glRowCosts_[coarse ? 1 : 0];
    if (!(options_.glSliceSeconds > 0.0) || costs.width != width ||
        int(costs.seconds.size()) != height)
        return sliceRows(width, left);
    // The rows the budget holds at the last frame's cost per row (rows through empty space
    // are cheap, those through the body dear: an average per pixel misjudges a slice by 2×);
    // a row not measured yet at the last slice's cost per pixel. Some of the budget is kept for
    // what a slice costs besides its rows (a new TF table, the uniforms).
    const double budget = kGlSliceRowShare * options_.glSliceSeconds;
    double plan = 0.0, fromLast = 0.0;
    int rows = 0;
    bool guessed = false;
    for (int y = firstRow; y < height; ++y) {
        const double measured = costs.seconds[std::size_t(y)];
        const double c = measured >= 0.0 ? measured * scale : glPixelSeconds_ * double(width);
        if (rows > 0 && plan + c > budget) break;
        plan += c;
        if (measured >= 0.0)
            fromLast += measured;
        else
            guessed = true;
        ++rows;
    }
    // Only rows the last frame measured say how this frame compares with it; rows guessed from
    // the cost per pixel (cheap empty rows at the top make a dear middle look cheap) grow at most
    // twofold from slice to slice.
    predicted = guessed ? 0.0 : fromLast;
    if (guessed && lastRows > 0) rows = std::min(rows, 2 * lastRows);
    return std::clamp(rows, 1, left);
}

namespace {
/// ", after uploads of 0.210 s in 9 UI frames" for a --log line; empty without uploads.
std::string uploadNote(int frames, double seconds) {
    if (frames == 0) return {};
    char text[96];
    std::snprintf(text, sizeof text, ", after uploads of %.3f s in %d UI frame%s", seconds, frames,
                  frames == 1 ? "" : "s");
    return text;
}
}  // namespace

bool Viewer::stepGl() {
    if (!glJob_ || !gl_) return true;
    GlJob& job = *glJob_;
    const RenderedImage& p = job.state;
    const int w = p.setup->camera->width(), h = p.setup->camera->height();
    const int left = h - job.nextRow;
    double predicted = 0.0;
    const int rows =
        glSliceRows(p.coarse, w, h, job.nextRow, job.lastRows, job.costScale, predicted);
    const bool last = rows >= left;
    std::string why;
    try {
        core::Stopwatch sw;
        // A new volume's or new SH fields' textures first, a slice's budget per UI frame (without
        // slices render() uploads them with the frame).
        const GlRayCaster::Upload u =
            job.nextRow == 0 && options_.glSliceSeconds > 0.0
                ? gl_->upload(*p.setup, p.shGrids, options_.glSliceSeconds, why)
                : GlRayCaster::Upload::Ready;
        if (u == GlRayCaster::Upload::Progress) {
            glFinish();
            glUploadSeconds_ += sw.seconds();
            ++glUploadFrames_;
            job.uiFrame = frames_;
            return true;
        }
        const bool ok = u == GlRayCaster::Upload::Ready &&
                        gl_->renderRows(*p.setup, p.shGrids, float(p.exposureStops),
                                        render::displayFromString(p.display), why, job.nextRow,
                                        job.nextRow + rows, last);
        glFinish();  // the slice's real cost (the GL queues its work), and its bound
        if (ok) {
            const double t = sw.seconds();
            glPixelSeconds_ = t / (double(std::max(rows, 1)) * double(std::max(w, 1)));
            // The slice's rows' cost, for the next frame of this kind and size.
            RowCosts& costs = glRowCosts_[p.coarse ? 1 : 0];
            if (costs.width != w || int(costs.seconds.size()) != h)
                costs.width = w, costs.seconds.assign(std::size_t(h), -1.0);
            for (int y = job.nextRow; y < job.nextRow + rows; ++y)
                costs.seconds[std::size_t(y)] = t / double(std::max(rows, 1));
            if (predicted > 0.0)
                job.costScale = std::clamp(t / predicted, kGlCostScaleMin, kGlCostScaleMax);
            job.seconds += t;
            ++job.slices;
            job.nextRow += rows;
            job.lastRows = rows;
            job.uiFrame = frames_;
            if (!last) return true;
            (p.coarse ? glCoarseTimes_ : glTimes_).add(job.seconds);
            if (options_.log)
                std::fprintf(stderr,
                             "view: GLSL frame %s%dx%d in %.3f s, %d slice%s (state %llu, SH "
                             "fields uploaded so far: %zu)%s%s\n",
                             p.coarse ? "coarse " : "", gl_->width(), gl_->height(), job.seconds,
                             job.slices, job.slices == 1 ? "" : "s",
                             (unsigned long long)p.generation, gl_->shUploads(),
                             p.staleShading ? " shaded from earlier fields" : "",
                             uploadNote(glUploadFrames_, glUploadSeconds_).c_str());
            glUploadFrames_ = 0, glUploadSeconds_ = 0.0;
            // Full resolution is shown pixel for pixel; the coarse image is magnified smoothly
            // (as the CPU path's).
            const GLint filter = p.coarse ? GL_LINEAR : GL_NEAREST;
            glBindTexture(GL_TEXTURE_2D, GLuint(gl_->texture()));
            glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, filter);
            glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, filter);
            texW_ = gl_->width(), texH_ = gl_->height();
            shownFull_ = !p.coarse;
            shownGl_ = true;
            shownStale_ = p.staleShading;
            shownGen_ = p.generation;
            renderWarnings_ = p.warnings;
            if (!p.camera.is_null()) renderedCamera_ = p.camera, renderedCameraGen_ = p.generation;
            glJob_.reset();
            // A state that came meanwhile: its first slice in the next UI frame (one the GL
            // cannot draw goes through renderGl's fallback to the CPU path).
            if (glNext_) {
                RenderedImage next = std::move(*glNext_);
                glNext_.reset();
                if (next.generation >= shownGen_) {
                    if (next.setup)
                        glJob_ = GlJob{std::move(next)};
                    else
                        renderGl(next);
                }
            }
            return true;
        }
    } catch (const std::exception& e) {
        why = e.what();
    }
    glJob_.reset();
    glNext_.reset();
    choose(false, "the GLSL path failed, the CPU draws: " + why);
    return false;
}

void Viewer::updateRenderer() {
    if (!loaded_ || measure_ == Measure::Done) return;
    const int w = imageW_, h = imageH_;
    // A new state while measuring (its requests replace the measurement's): start again once
    // its full image is shown.
    if (measure_ != Measure::Waiting && generation_ != measureGen_) {
        measure_ = Measure::Waiting;
        glMeasured_.clear();
        glFramesRun_ = 0;
        glMeasureRow_ = 0, glMeasureSeconds_ = 0.0;
        glUploadFrames_ = 0, glUploadSeconds_ = 0.0;
        return;
    }
    switch (measure_) {
        case Measure::Waiting:
            // After the first full CPU image of the state (the volume and tables are loaded).
            if (!shownFull_ || shownGen_ != generation_ || dirty_) return;
            if (choice_ == RendererChoice::Cpu) return choose(false, "--renderer cpu");
            if (!gl_) return choose(false, "no GLSL path: " + glError_);
            prepared_.reset();
            measureGen_ = generation_;
            {
                RenderRequest request{sceneAt(w, h), generation_, false};
                request.prepareOnly = true;
                worker_.submit(std::move(request));
            }
            measure_ = Measure::Prepare;
            return;
        case Measure::Prepare: {
            if (!prepared_) return;
            const std::string no = glUnsupportedReason(prepared_->method, prepared_->setup.get());
            if (!no.empty()) return choose(false, "the scene needs the CPU path: " + no);
            if (choice_ == RendererChoice::Gpu) return choose(true, "--renderer gpu");
            // The CPU's frame: the same state rendered kMeasureFrames times, median (once when
            // the full image just shown took kMeasureOnceSeconds or more).
            RenderRequest request{sceneAt(w, h), generation_, false};
            request.frames = lastFullFrameSeconds_ >= kMeasureOnceSeconds ? 1 : kMeasureFrames;
            worker_.submit(std::move(request));
            measure_ = Measure::CpuFrames;
            return;
        }
        case Measure::CpuFrames:
            return;  // receive() moves on when the timed frames arrive
        case Measure::GlFrames: {
            // First a warm-up on a corner (uploads, the shader's machine code), untimed; then the
            // central quarter of the image as a probe; then full frames, median. Probe and frames
            // in slices of about glSliceSeconds of GL work per UI frame, as the GLSL path draws
            // (on a software rasteriser a GL frame takes seconds: the UI keeps its events), and
            // the measurement ends as soon as the GL time spent shows the GL clearly slower than
            // the CPU's frame.
            const int run = glFramesRun_;
            const pipeline::CasterSetup& setup = *prepared_->setup;
            const float exposure = float(prepared_->exposureStops);
            const render::Display display = render::displayFromString(prepared_->display);
            std::string why;
            core::Stopwatch sw;
            bool ok = false;
            if (run == 0) {
                // The volume's (and SH fields') uploads spread over UI frames, then a draw of
                // 8x8 pixels that makes the GL compile the shader's machine code.
                GlRayCaster::Upload u = GlRayCaster::Upload::Failed;
                try {
                    u = options_.glSliceSeconds > 0.0
                            ? gl_->upload(setup, prepared_->shGrids, options_.glSliceSeconds, why)
                            : GlRayCaster::Upload::Ready;
                    if (u == GlRayCaster::Upload::Progress) {
                        glFinish();
                        glUploadSeconds_ += sw.seconds();
                        ++glUploadFrames_;
                        return;
                    }
                    ok = u == GlRayCaster::Upload::Ready &&
                         gl_->render(setup, prepared_->shGrids, exposure, display, why,
                                     GlRayCaster::Scope::WarmUp);
                } catch (const std::exception& e) {
                    why = e.what();
                }
                glFinish();
                if (!ok) return choose(false, "the GLSL path failed, the CPU draws: " + why);
                if (options_.log)
                    std::fprintf(stderr,
                                 "view: measuring: GLSL warm-up (shader compile, small tables; "
                                 "8x8 pixels) %.3f s%s\n",
                                 sw.seconds(),
                                 uploadNote(glUploadFrames_, glUploadSeconds_).c_str());
                glUploadFrames_ = 0, glUploadSeconds_ = 0.0;
                glFramesRun_ = 1;
                return;
            }
            const bool probe = run == 1;
            const int fw = setup.camera->width(), fh = setup.camera->height();
            const int x0 = probe ? fw / 4 : 0, rw = probe ? std::max(fw / 2, 1) : fw;
            const int y0 = probe ? fh / 4 : 0, rh = probe ? std::max(fh / 2, 1) : fh;
            const int left = std::max(rh - glMeasureRow_, 1);
            const int rows = sliceRows(rw, left);
            const bool last = rows >= left;
            try {
                ok = gl_->renderRect(setup, prepared_->shGrids, exposure, display, why, x0,
                                     y0 + glMeasureRow_, rw, rows, last);
            } catch (const std::exception& e) {
                why = e.what();
            }
            glFinish();
            const double t = sw.seconds();
            if (!ok) return choose(false, "the GLSL path failed, the CPU draws: " + why);
            glPixelSeconds_ = t / (double(rows) * double(rw));
            glMeasureSeconds_ += t;
            glMeasureRow_ += rows;
            // The GL time already spent, as a full frame's lower bound (a quarter of the pixels
            // for the probe): clearly slower than the CPU → the CPU path, without finishing.
            const double atLeast = probe ? 4.0 * glMeasureSeconds_ : glMeasureSeconds_;
            if (atLeast > kClearlySlower * cpuMeasured_) {
                char reason[400];
                std::snprintf(reason, sizeof reason,
                              "measured at %dx%d: GLSL already %.3f s for %d of %d rows of the %s "
                              "(%s; a full frame over %.1f s), CPU ray caster %.3f s per frame "
                              "(median of %d) -> the CPU path is faster",
                              fw, fh, glMeasureSeconds_, glMeasureRow_, rh,
                              probe ? "image's central quarter" : "frame",
                              gl_->glRenderer().c_str(), atLeast, cpuMeasured_, cpuFrames_);
                glMeasureRow_ = 0, glMeasureSeconds_ = 0.0;
                return choose(false, reason);
            }
            if (!last) return;
            const double seconds = glMeasureSeconds_;
            glMeasureRow_ = 0, glMeasureSeconds_ = 0.0;
            ++glFramesRun_;
            if (options_.log)
                std::fprintf(stderr, "view: measuring: GLSL %s %.3f s\n",
                             probe ? "central quarter of the image" : "frame", seconds);
            if (probe) return;
            glMeasured_.push_back(seconds);
            if (int(glMeasured_.size()) < kMeasureFrames && seconds < kMeasureOnceSeconds) return;
            std::vector<double> g = glMeasured_;
            std::sort(g.begin(), g.end());
            const double gl = g[g.size() / 2];
            const bool gpu = gl < cpuMeasured_;
            char reason[320];
            std::snprintf(reason, sizeof reason,
                          "measured at %dx%d: GLSL %.3f s per frame (median of %zu, %s), CPU "
                          "ray caster %.3f s (median of %d) -> the %s is faster",
                          fw, fh, gl, g.size(), gl_->glRenderer().c_str(), cpuMeasured_, cpuFrames_,
                          gpu ? "GLSL path" : "CPU path");
            return choose(gpu, reason);
        }
        case Measure::Done:
            return;
    }
}

void Viewer::openPath(const std::string& path) {
    path_ = path;
    startLoad(path_);
}

void Viewer::startLoad(const std::string& path) {
    if (path.empty()) return;
    if (loading_.valid()) {
        // A newer choice replaces a load in progress: cancel it and let it finish on its own
        // (polled each frame, never waited for here).
        *loadCancel_ = true;
        retired_.push_back(std::move(loading_));
    }
    loadCancel_ = std::make_shared<std::atomic<bool>>(false);
    loadError_.clear();
    loadingPath_ = path;
    auto open = options_.openInput;
    loadFraction_ = std::make_shared<std::atomic<double>>(0.0);
    loading_ = std::async(
        std::launch::async, [cancel = loadCancel_, fraction = loadFraction_, open, path] {
            if (!open) throw InputError("viewer", "open", "opening files is not available here");
            const core::Progress progress(
                [fraction](const std::string&, double f) { *fraction = f; }, cancel.get());
            return prepareScene(open(path), progress);
        });
}

void Viewer::pollLoad() {
    std::erase_if(retired_, [](std::future<LoadedScene>& f) {
        return f.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
    });
    if (!loading_.valid() ||
        loading_.wait_for(std::chrono::seconds(0)) != std::future_status::ready)
        return;
    try {
        adopt(loading_.get());
    } catch (const CancelledError&) {
    } catch (const std::exception& e) {
        // The current volume stays; the error says why the new one did not load.
        loadError_ = std::string("could not open ") + loadingPath_ + ": " + e.what();
        if (options_.log) std::fprintf(stderr, "view: %s\n", loadError_.c_str());
    }
    loadingPath_.clear();
}

void Viewer::handleImageMouse() {
    ImGuiIO& io = ImGui::GetIO();
    const ImVec2 m = io.MousePos;
    const bool overImage = m.x >= 0 && m.y >= 0 && m.x < imageW_ && m.y < imageH_;
    if (drag_ == Drag::None && overImage && !io.WantCaptureMouse && loaded_) {
        if (ImGui::IsMouseClicked(ImGuiMouseButton_Left)) {
            drag_ = io.KeyShift ? Drag::Pan : Drag::Orbit;
            if (io.KeyCtrl && !lights_.empty()) drag_ = Drag::Light;
            // A click on a clip plane's handle grabs the plane (the nearest within reach).
            const std::optional<render::Camera> cam =
                showGizmo_ && drag_ == Drag::Orbit ? shownCamera() : std::nullopt;
            float best = kHandleGrabPixels;
            for (std::size_t i = 0; cam && i < clips_.size(); ++i) {
                if (!clips_[i].enabled) continue;
                const std::optional<ImVec2> h = toWindow(*cam, clipHandle(clips_[i].plane));
                if (!h) continue;
                const float d = std::hypot(h->x - m.x, h->y - m.y);
                if (d <= best) best = d, drag_ = Drag::Clip, clipDragIndex_ = int(i);
            }
            if (drag_ == Drag::Clip) selectedClip_ = clipDragIndex_;
        } else if (ImGui::IsMouseClicked(ImGuiMouseButton_Middle))
            drag_ = Drag::Pan;
        else if (ImGui::IsMouseClicked(ImGuiMouseButton_Right)) {
            drag_ = Drag::Window;
            tfAtDrag_ = tf_;
        }
        dragStart_ = m;
        if (io.MouseWheel != 0.f) zoomBy(double(io.MouseWheel));
    }
    const bool held = ImGui::IsMouseDown(ImGuiMouseButton_Left) ||
                      ImGui::IsMouseDown(ImGuiMouseButton_Middle) ||
                      ImGui::IsMouseDown(ImGuiMouseButton_Right);
    if (drag_ != Drag::None && !held) {
        drag_ = Drag::None;
        return;
    }
    const ImVec2 d = io.MouseDelta;
    if (drag_ == Drag::None || (d.x == 0.f && d.y == 0.f)) return;
    switch (drag_) {
        case Drag::Orbit:
            orbitBy(d.x, d.y);
            break;
        case Drag::Pan:
            panBy(d.x, d.y);
            break;
        case Drag::Window:
            windowDrag(tfAtDrag_, m.x - dragStart_.x, m.y - dragStart_.y);
            break;
        case Drag::Clip:
            dragClipPlane(clipDragIndex_, d.x, d.y);
            break;
        case Drag::Light:
            // Horizontal: azimuth (right = toward the patient's left, as the camera's azimuth);
            // vertical: elevation (up = higher).
            turnLightBy(selectedLight_, d.x * kOrbitDegPerPixel, -d.y * kOrbitDegPerPixel);
            break;
        case Drag::None:
            break;
    }
}

const char* Viewer::dragName(Drag d) {
    switch (d) {
        case Drag::Orbit:
            return "orbit";
        case Drag::Pan:
            return "pan";
        case Drag::Window:
            return "window/level";
        case Drag::Clip:
            return "clip-plane";
        case Drag::Light:
            return "light";
        case Drag::None:
            break;
    }
    return nullptr;
}

void Viewer::orbitBy(double dx, double dy) {
    if (!ensureLookAt()) return;
    orbit(*lookAt_, -dx * kOrbitDegPerPixel, dy * kOrbitDegPerPixel);
    setCamera(cameraJson(*lookAt_, doc_["camera"]));
}

void Viewer::panBy(double dx, double dy) {
    if (!ensureLookAt()) return;
    pan(*lookAt_, dx, dy, imageH_);
    setCamera(cameraJson(*lookAt_, doc_["camera"]));
}

bool Viewer::zoomBy(double notches) {
    if (!ensureLookAt()) return true;
    // A zoom past what a scene renders leaves the view as it was (the wheel: nothing happens).
    if (!zoom(*lookAt_, std::pow(kZoomPerNotch, notches))) return false;
    setCamera(cameraJson(*lookAt_, doc_["camera"]));
    return true;
}

void Viewer::windowDrag(const optics::TransferFunction& start, double dx, double dy) {
    const optics::Window w = dragWindow(start.window(), dx, dy);
    if (w.width > 0.f) setTf(start.withWindow(w));
}

void Viewer::checkIndex(const ScriptStep& st, std::size_t count, const char* what) const {
    if (std::size_t(st.index) < count) return;
    const bool bare =
        st.kind == ScriptStep::Kind::ClipRemove || st.kind == ScriptStep::Kind::LightRemove;
    throw InputError(st.source, bare ? st.field : st.field + ".index",
                     "there is no " + std::string(what) + " " + std::to_string(st.index) +
                         " (the view has " + std::to_string(count) + ")",
                     "indices count from 0 in the order the planes and lights were added");
}

InputError Viewer::scriptStepError(const std::string& what) const {
    // The scene the script's steps made (a window drag of 5000 pixels a width past 10⁹) is the
    // last step's doing: named, not the screenshot or the scene file whose key it changed.
    const ScriptStep& last = options_.script[scriptNext_ - 1];
    return InputError(last.source, last.field, "leaves a view that cannot be rendered: " + what,
                      "use a smaller value");
}

void Viewer::runScript() {
    if (scriptDragFrames_ > 0) {
        // A scripted drag: one motion per frame through the mouse drag's function, not waiting
        // for images (the worker renders coarse while it lasts).
        ++scriptDragDone_;
        switch (scriptDrag_) {
            case Drag::Orbit:
                orbitBy(scriptDragDx_, scriptDragDy_);
                break;
            case Drag::Pan:
                panBy(scriptDragDx_, scriptDragDy_);
                break;
            case Drag::Window:  // as the mouse's: from the TF at the press, by the total motion
                windowDrag(tfAtDrag_, scriptDragDone_ * scriptDragDx_,
                           scriptDragDone_ * scriptDragDy_);
                break;
            default:
                dragClipPlane(scriptDragIndex_, scriptDragDx_, scriptDragDy_);
                break;
        }
        --scriptDragFrames_;
        scriptDragMoved_ = true;
        return;
    }
    // Steps run on the renderer the viewer chose (after the start-up measurement).
    if (scriptNext_ >= options_.script.size() || !loaded_ || dirty_ || !shownFull_ || shownStale_ ||
        shownGen_ != generation_ || loading_.valid() || dropPending() || measure_ != Measure::Done)
        return;
    const ScriptStep& st = options_.script[scriptNext_++];
    switch (st.kind) {
        case ScriptStep::Kind::Orbit:
            orbitBy(st.a, st.b);
            break;
        case ScriptStep::Kind::Pan:
            panBy(st.a, st.b);
            break;
        case ScriptStep::Kind::Zoom:
            if (!zoomBy(st.a))
                throw InputError(st.source, st.field,
                                 "leaves a view that cannot be rendered (the eye on the target, "
                                 "or a view height under a micrometre or past a kilometre)",
                                 "use a smaller value");
            break;
        case ScriptStep::Kind::Window:
            windowDrag(tf_, st.a, st.b);
            break;
        case ScriptStep::Kind::View:
            snapView(st.view);
            break;
        case ScriptStep::Kind::PathTrace:
            startPathTrace(int(st.a));
            break;
        case ScriptStep::Kind::ClipAdd:
            if (!addClipPlane(st.facingCamera ? std::nullopt : std::optional(st.vec), st.a))
                throw InputError(st.source, st.field, "no image is shown yet to face");
            if (st.shadowsFromRemoved) {
                clips_.back().plane.shadowsFromRemoved = *st.shadowsFromRemoved;
                setClipPlanes();
            }
            break;
        case ScriptStep::Kind::ClipMove:
            checkIndex(st, clips_.size(), "clip plane");
            moveClipPlaneBy(st.index, st.a);
            break;
        case ScriptStep::Kind::ClipDrag:
            checkIndex(st, clips_.size(), "clip plane");
            scriptDrag_ = Drag::Clip;
            scriptDragIndex_ = st.index;
            scriptDragFrames_ = st.frames, scriptDragDone_ = 0;
            scriptDragDx_ = st.a / st.frames, scriptDragDy_ = st.b / st.frames;
            selectedClip_ = st.index;
            runScript();  // the first motion now
            break;
        case ScriptStep::Kind::Drag:
            scriptDrag_ = st.dragMotion == ScriptStep::Kind::Orbit ? Drag::Orbit
                          : st.dragMotion == ScriptStep::Kind::Pan ? Drag::Pan
                                                                   : Drag::Window;
            tfAtDrag_ = tf_;
            scriptDragFrames_ = st.frames, scriptDragDone_ = 0;
            scriptDragDx_ = st.a / st.frames, scriptDragDy_ = st.b / st.frames;
            runScript();  // the first motion now
            break;
        case ScriptStep::Kind::ClipEdit: {
            checkIndex(st, clips_.size(), "clip plane");
            ViewClipPlane& c = clips_[st.index];
            if (st.flip) flipClipPlane(c.plane);
            if (st.enabled) c.enabled = *st.enabled;
            if (st.shadowsFromRemoved) c.plane.shadowsFromRemoved = *st.shadowsFromRemoved;
            setClipPlanes();
            break;
        }
        case ScriptStep::Kind::ClipRemove:
            checkIndex(st, clips_.size(), "clip plane");
            clips_.erase(clips_.begin() + st.index);
            setClipPlanes();
            break;
        case ScriptStep::Kind::LightAdd:
        case ScriptStep::Kind::LightEdit: {
            io::LightDesc l;
            if (st.kind == ScriptStep::Kind::LightAdd) {
                const double d = st.distance.value_or(glm::length(loaded_->summary.extent));
                l = newLight(st.lightType, loaded_->centre, d, st.path, st.source, st.field);
            } else {
                checkIndex(st, lights_.size(), "light");
                l = lights_[st.index];
            }
            if (st.azimuth || st.elevation) {
                const glm::dvec2 a = lightAnglesOf(l, loaded_->centre);
                setLightAngles(l, {st.azimuth.value_or(a.x), st.elevation.value_or(a.y)},
                               loaded_->centre);
            }
            if (st.position) {
                if (l.type != "point" && l.type != "area")
                    throw InputError(
                        st.source, st.field + ".position",
                        "is for point lights; light " + std::to_string(st.index) + " is " + l.type);
                l.position = *st.position;
            }
            if (st.color) l.color = *st.color;
            if (st.intensity) l.intensity = *st.intensity;
            if (st.kind == ScriptStep::Kind::LightAdd) {
                lights_.push_back(l);
                selectedLight_ = int(lights_.size()) - 1;
            } else {
                lights_[st.index] = l;
            }
            setLights();
            break;
        }
        case ScriptStep::Kind::LightTurn:
            checkIndex(st, lights_.size(), "light");
            turnLightBy(st.index, st.a, st.b);
            break;
        case ScriptStep::Kind::LightRemove:
            checkIndex(st, lights_.size(), "light");
            lights_.erase(lights_.begin() + st.index);
            setLights();
            break;
        case ScriptStep::Kind::Gizmo:
            showGizmo_ = st.a != 0.0;
            break;
        case ScriptStep::Kind::Shading: {
            // The panel's local/global switch, which only the SH methods have (the step did
            // nothing on any other, silently).
            const json m = doc_.value("method", json());
            const std::string name = m.is_object()   ? m.value("name", "")
                                     : m.is_string() ? m.get<std::string>()
                                                     : loaded_->scene.method.name;
            if (name != "sh-local" && name != "sh-global")
                throw InputError(
                    st.source, st.field,
                    "switches sh-local and sh-global; the view's method is '" + name + "'",
                    "set the scene's method to sh-local or sh-global, or leave the "
                    "step out");
            setShVisibility(st.view == "global");
            break;
        }
        case ScriptStep::Kind::Drop: {
            // GLFW's drop callback itself; the next frame's events open the last path.
            std::vector<const char*> paths;
            for (const std::string& p : st.paths) paths.push_back(p.c_str());
            onDrop(window_, int(paths.size()), paths.data());
            break;
        }
    }
}

void Viewer::addLight(const std::string& type, const std::string& path) {
    lights_.push_back(newLight(type, loaded_->centre, glm::length(loaded_->summary.extent), path,
                               "lights panel", "new light"));
    selectedLight_ = int(lights_.size()) - 1;
    setLights();
}

void Viewer::turnLightBy(int index, double dAzimuthDeg, double dElevationDeg) {
    if (index < 0 || std::size_t(index) >= lights_.size()) return;
    turnLight(lights_[index], dAzimuthDeg, dElevationDeg, loaded_->centre);
    setLights();
}

bool Viewer::addClipPlane(std::optional<glm::dvec3> normal, double offsetMm) {
    if (!loaded_) return false;
    if (!normal) {
        // Facing the view: the camera of the shown image (its forward points into the volume).
        if (!renderedCamera_.contains("forward")) return false;
        const json& f = renderedCamera_["forward"];
        normal = glm::dvec3(f[0].get<double>(), f[1].get<double>(), f[2].get<double>());
    }
    clips_.push_back(
        {clipPlaneThrough(*normal, loaded_->centre, offsetMm, "clip planes", "normal"), true});
    selectedClip_ = int(clips_.size()) - 1;
    setClipPlanes();
    return true;
}

void Viewer::moveClipPlaneBy(int index, double mm) {
    if (index < 0 || std::size_t(index) >= clips_.size() || mm == 0.0) return;
    moveClipPlane(clips_[index].plane, mm);
    setClipPlanes();
}

void Viewer::dragClipPlane(int index, double dx, double dy) {
    if (index < 0 || std::size_t(index) >= clips_.size()) return;
    const std::optional<render::Camera> cam = shownCamera();
    if (!cam) return;
    const io::ClipPlaneDesc& p = clips_[index].plane;
    moveClipPlaneBy(index, clipDragMm(p, clipHandle(p), *cam, dx, dy));
}

std::optional<render::Camera> Viewer::shownCamera() const {
    if (!loaded_ || drawW_ < 1 || drawH_ < 1) return std::nullopt;
    for (const char* k : {"eye", "forward", "up"})
        if (!renderedCamera_.contains(k)) return std::nullopt;
    return projectionCamera(lookAtFromRendered(renderedCamera_, loaded_->centre),
                            int(std::lround(drawW_)), int(std::lround(drawH_)));
}

std::optional<ImVec2> Viewer::toWindow(const render::Camera& cam, const glm::dvec3& p) const {
    double x = 0, y = 0;
    if (!cam.project(p, x, y)) return std::nullopt;
    return ImVec2(drawX0_ + float(x), drawY0_ + float(y));
}

void Viewer::startPathTrace(int spp) {
    if (!loaded_ || imageW_ < 1 || imageH_ < 1) return;
    try {
        ptWorker_.submit(
            {sceneAt(imageW_, imageH_, {{"name", "pathtrace"}, {"params", {{"spp", spp}}}}),
             generation_, false});
        ptGen_ = generation_;
        ptReady_ = false, ptShow_ = true;
        ptMessage_ = "path tracing " + std::to_string(spp) + " spp ...";
    } catch (const std::exception& e) {
        ptMessage_ = e.what();
    }
}

void Viewer::receivePathTrace() {
    std::optional<RenderedImage> r = ptWorker_.take();
    if (!r || r->generation != ptGen_) return;
    if (!r->error.empty()) {
        ptMessage_ = "path tracer: " + r->error;
        return;
    }
    if (r->coarse) return;  // the worker's quarter-size preview: the live image stays
    if (!ptTexture_) glGenTextures(1, &ptTexture_);
    glBindTexture(GL_TEXTURE_2D, ptTexture_);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, r->width, r->height, 0, GL_RGBA, GL_UNSIGNED_BYTE,
                 r->rgba.data());
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    ptW_ = r->width, ptH_ = r->height;
    ptFilm_ = r->film;
    ptReady_ = true;
    char m[96];
    std::snprintf(m, sizeof m, "path traced in %.1f s", r->seconds);
    ptMessage_ = m;
}

void Viewer::recordState(const io::Scene& scene) {
    if (!recorder_) return;
    try {
        recorder_->record(recordClock_.seconds(), session::stateOf(scene));
    } catch (const std::exception& e) {
        recordMessage_ = std::string("recording stopped: ") + e.what();
        recorder_.reset();
    }
}

/// The one line of a lost display (`kept`: "; …" clauses of what was kept or not) and its exit
/// code: a cancel when the display went with a Ctrl-C (under xvfb-run the X server gets it too).
/// Whether the lost display is a cancel's: Ctrl-C under xvfb-run stops the X server and signals
/// us at once, and the signal may land on another thread a moment after the server's EOF reached
/// this one (seen under ASan in CI: exit 2 for a Ctrl-C). The flag is given up to
/// kCancelGraceMs to appear.
bool lostByCancel(const std::atomic<bool>* quit) {
    constexpr int kCancelGraceMs = 250;
    if (!quit) return false;
    for (int waited = 0; !quit->load() && waited < kCancelGraceMs; waited += 10)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return quit->load();
}

int reportDisplayLoss(bool cancelled, const std::string& kept) {
    if (cancelled) {
        std::fprintf(stderr, "\nvoxlight: cancelled%s\n", kept.c_str());
        return kExitViewerCancelled;
    }
    std::fprintf(stderr,
                 "\nvoxlight: error: display: the connection to the X server was lost (the "
                 "server quit or the connection dropped)%s\n",
                 kept.c_str());
    return kExitDisplayLost;
}

io::Scene Viewer::sceneOnScreen() const {
    // The edited document (lights added in the panel, maps included); the scene as opened where
    // the document is a state the scene refuses (a script step's error, shown in the panel).
    try {
        return sceneAt(std::max(imageW_, 1), std::max(imageH_, 1));
    } catch (const std::exception&) {
        return loaded_->scene;
    }
}

std::string Viewer::saveRecording(const std::string& path) {
    if (!recorder_) throw InputError("viewer", "session", "nothing is being recorded");
    if (options_.saveSession && loaded_ && !recorder_->session().keyframes.empty())
        options_.saveSession(recorder_->session(), path, sceneOnScreen());
    else
        recorder_->save(path);  // (its error when there is no keyframe yet)
    return "wrote " + path + " (" + std::to_string(recorder_->session().keyframes.size()) +
           " keyframes)";
}

std::string Viewer::keepRecording() {
    std::string kept;
    const std::size_t keyframes = recorder_ ? recorder_->session().keyframes.size() : 0;
    if (!options_.record.empty() && recorder_ && keyframes == 0) {
        kept = "; nothing was recorded yet (" + options_.record + " not written)";
    } else if (!options_.record.empty() && recorder_) {
        try {
            saveRecording(options_.record);
            kept = "; the session so far is in " + options_.record;
        } catch (const std::exception& e) {
            kept = std::string("; the session could not be saved: ") + e.what();
        }
    } else if (keyframes > 0) {
        kept = "; the panel's recording (" + std::to_string(keyframes) +
               " keyframes) was not saved (view --record SESSION.json saves it on any exit)";
    }
    return kept;
}

int Viewer::displayLost() {
    std::string kept = keepRecording();
    // A screenshot the panel is writing (on its own thread, no X): finished, or said to be cut.
    if (saving_.valid()) {
        if (saving_.wait_for(std::chrono::seconds(kScreenshotFinishSeconds)) ==
            std::future_status::ready)
            kept += "; " + saving_.get();
        else
            kept += "; the screenshot being written (" + shotPath_ + ") was cut off";
    }
    if (!options_.screenshot.empty()) kept += "; no screenshot was written";
    // Ctrl-C under xvfb-run reaches the X server too: the display goes because of the cancel.
    return reportDisplayLoss(lostByCancel(options_.quit), kept);
}

void Viewer::handleKeys() {
    // Presses recorded by the key callback: a tap shorter than a frame is not lost (ImGui 1.86
    // only sees which keys are down when a frame starts).
    std::vector<std::pair<int, int>> presses;
    {
        std::lock_guard lock(gInputMutex);
        presses.swap(gKeyPresses);
    }
    const bool typing = ImGui::GetIO().WantCaptureKeyboard;
    for (const auto& [key, mods] : presses) {
        const bool ctrl = (mods & GLFW_MOD_CONTROL) != 0;
        if (ctrl && key == GLFW_KEY_O) focusPath_ = true;
        if (key == GLFW_KEY_F12) shotRequested_ = true;
        if (typing || ctrl) continue;
        switch (key) {
            case GLFW_KEY_ESCAPE:
            case GLFW_KEY_Q:
                glfwSetWindowShouldClose(window_, GLFW_TRUE);
                break;
            case GLFW_KEY_F1:
            case GLFW_KEY_H:
                showHelp_ = !showHelp_, helpToggled_ = true;
                break;
            case GLFW_KEY_A:
                snapView("anterior");
                break;
            case GLFW_KEY_P:
                snapView("posterior");
                break;
            case GLFW_KEY_L:
                snapView("left");
                break;
            case GLFW_KEY_R:
                snapView("right");
                break;
            case GLFW_KEY_S:
                snapView("superior");
                break;
            case GLFW_KEY_I:
                snapView("inferior");
                break;
            case GLFW_KEY_O:
                snapView("oblique");
                break;
            case GLFW_KEY_HOME:
                if (!loaded_) break;
                lookAt_.reset();
                cameraResetGen_ = generation_ + 1;
                setCamera(loaded_->document.value("camera", json::object()));
                break;
            case GLFW_KEY_W:
                if (loaded_) setTf(tf_.withWindow(loaded_->tf.window()));
                break;
            case GLFW_KEY_C:
                addClipPlane(std::nullopt, 0.0);
                break;
            case GLFW_KEY_G:
                showGizmo_ = !showGizmo_;
                break;
            case GLFW_KEY_EQUAL:
            case GLFW_KEY_KP_ADD:
            case GLFW_KEY_MINUS:
            case GLFW_KEY_KP_SUBTRACT:
                if (loaded_ && ensureLookAt()) {
                    const bool in = key == GLFW_KEY_EQUAL || key == GLFW_KEY_KP_ADD;
                    if (zoom(*lookAt_, in ? kZoomPerNotch : 1.0 / kZoomPerNotch))
                        setCamera(cameraJson(*lookAt_, doc_["camera"]));
                }
                break;
            default:
                break;
        }
    }
}

void Viewer::drawImage() {
    ImDrawList* bg = ImGui::GetBackgroundDrawList();
    if ((!texture_ && !shownGl_) || texW_ < 1 || texH_ < 1) {
        bg->AddText(ImVec2(20, 20), IM_COL32(200, 200, 200, 255),
                    loaded_ ? "rendering ..."
                            : "open a scene, volume or DICOM folder (panel, or drop it here)");
        return;
    }
    // Fit the image into the area keeping its aspect (equal sizes: pixel for pixel).
    const float sx = float(imageW_) / float(texW_), sy = float(imageH_) / float(texH_);
    const float s = shownFull_ && texW_ == imageW_ && texH_ == imageH_ ? 1.f : std::min(sx, sy);
    const float w = float(texW_) * s, h = float(texH_) * s;
    const float x0 = std::floor((float(imageW_) - w) / 2),
                y0 = std::floor((float(imageH_) - h) / 2);
    const bool pt = pathTraceShown() && ptW_ == texW_ && ptH_ == texH_;
    const GLuint live = shownGl_ && gl_ ? GLuint(gl_->texture()) : texture_;
    bg->AddImage((ImTextureID)(intptr_t)(pt ? ptTexture_ : live), ImVec2(x0, y0),
                 ImVec2(x0 + w, y0 + h));
    drawX0_ = x0, drawY0_ = y0, drawW_ = w, drawH_ = h;
    drawGizmo(bg);
    // Orientation letters at the image's edges (the patient side each edge faces), from the
    // camera of the image shown — as radiology viewers label their views.
    if (renderedCamera_.contains("up") && renderedCamera_.contains("forward")) {
        const auto v = [&](const char* k) {
            const json& a = renderedCamera_[k];
            return glm::dvec3(a[0].get<double>(), a[1].get<double>(), a[2].get<double>());
        };
        const glm::dvec3 up = v("up"), right = glm::cross(v("forward"), up);
        const float cx = x0 + w / 2, cy = y0 + h / 2, pad = 6.f;
        const ImU32 color = IM_COL32(255, 230, 120, 255);
        const auto put = [&](const std::string& t, float x, float y) {
            const ImVec2 size = ImGui::CalcTextSize(t.c_str());
            bg->AddText(ImVec2(x - size.x / 2, y - size.y / 2), color, t.c_str());
        };
        put(patientDirection(-right), x0 + pad + 6, cy);
        put(patientDirection(right), x0 + w - pad - 6, cy);
        put(patientDirection(up), cx, y0 + pad + 6);
        put(patientDirection(-up), cx, y0 + h - pad - 6);
    }
}

void Viewer::drawGizmo(ImDrawList* dl) {
    if (!showGizmo_ || !loaded_ || clips_.empty()) return;
    const std::optional<render::Camera> cam = shownCamera();
    if (!cam) return;
    dl->PushClipRect(ImVec2(drawX0_, drawY0_), ImVec2(drawX0_ + drawW_, drawY0_ + drawH_), true);
    for (std::size_t i = 0; i < clips_.size(); ++i) {
        if (!clips_[i].enabled) continue;
        const io::ClipPlaneDesc& p = clips_[i].plane;
        const bool selected = int(i) == selectedClip_;
        const ImU32 color = selected ? IM_COL32(90, 220, 255, 255) : IM_COL32(90, 220, 255, 130);
        // Where the plane cuts the volume's box.
        std::vector<ImVec2> outline;
        for (const glm::dvec3& q : clipOutline(p, loaded_->volume->geometry()))
            if (const std::optional<ImVec2> w = toWindow(*cam, q)) outline.push_back(*w);
        if (outline.size() >= 3)
            dl->AddPolyline(outline.data(), int(outline.size()), color, ImDrawFlags_Closed,
                            selected ? 2.f : 1.f);
        // The handle (the volume's centre on the plane) and an arrow toward the kept side.
        const glm::dvec3 h = clipHandle(p);
        const std::optional<ImVec2> hw = toWindow(*cam, h);
        if (!hw) continue;
        const double probe = 0.05 * glm::length(loaded_->summary.extent) + 1.0;
        const std::optional<ImVec2> tip = toWindow(*cam, h + probe * p.normal);
        ImVec2 dir(0.f, 0.f);
        if (tip) dir = ImVec2(tip->x - hw->x, tip->y - hw->y);
        const float len = std::hypot(dir.x, dir.y);
        if (len > 2.f) {
            const ImVec2 u(dir.x / len, dir.y / len), n(-u.y, u.x);
            const ImVec2 e(hw->x + u.x * kArrowPixels, hw->y + u.y * kArrowPixels);
            dl->AddLine(*hw, e, color, 2.f);
            dl->AddTriangleFilled(ImVec2(e.x + u.x * 8, e.y + u.y * 8),
                                  ImVec2(e.x + n.x * 5, e.y + n.y * 5),
                                  ImVec2(e.x - n.x * 5, e.y - n.y * 5), color);
        } else {
            // The normal points along the view: a dot (toward the eye) or a cross (away).
            if (glm::dot(p.normal, cam->forward()) < 0) {
                dl->AddCircleFilled(*hw, 3.f, color);
            } else {
                dl->AddLine(ImVec2(hw->x - 4, hw->y - 4), ImVec2(hw->x + 4, hw->y + 4), color, 2.f);
                dl->AddLine(ImVec2(hw->x - 4, hw->y + 4), ImVec2(hw->x + 4, hw->y - 4), color, 2.f);
            }
        }
        dl->AddCircle(*hw, 7.f, color, 0, 2.f);
        if (selected) dl->AddCircleFilled(*hw, 4.f, color);
        dl->AddText(ImVec2(hw->x + 9, hw->y - 16), color, std::to_string(i).c_str());
    }
    dl->PopClipRect();
}

void Viewer::drawLightsPanel(float width) {
    const glm::dvec3 pivot = loaded_->centre;
    if (lights_.empty()) ImGui::TextDisabled("no lights: a headlight follows the camera");
    // The camera of the shown image, for the direction widget (anterior view before any).
    glm::dvec3 forward(0.0, 1.0, 0.0), up(0.0, 0.0, 1.0);
    if (renderedCamera_.contains("forward") && renderedCamera_.contains("up")) {
        const auto v = [&](const char* k) {
            const json& a = renderedCamera_[k];
            return glm::dvec3(a[0].get<double>(), a[1].get<double>(), a[2].get<double>());
        };
        forward = v("forward"), up = v("up");
    }
    const glm::dvec3 right = glm::cross(forward, up);
    int remove = -1;
    for (std::size_t i = 0; i < lights_.size(); ++i) {
        io::LightDesc& l = lights_[i];
        ImGui::PushID(int(i));
        char label[64];
        std::snprintf(label, sizeof label, "%zu  %s", i, l.type.c_str());
        if (ImGui::Selectable(label, selectedLight_ == int(i))) selectedLight_ = int(i);
        if (selectedLight_ != int(i)) {
            ImGui::PopID();
            continue;
        }
        bool edited = false;
        // The direction widget: the light's direction seen along the view (a disc: the centre
        // is toward the viewer, the rim at the image's edges; a hollow dot: behind the volume).
        // Click or drag inside to place the light on the same hemisphere.
        const float r = 44.f;
        const ImVec2 c0 = ImGui::GetCursorScreenPos();
        const ImVec2 c(c0.x + r + 2, c0.y + r + 2);
        ImGui::InvisibleButton("direction", ImVec2(2 * r + 4, 2 * r + 4));
        const glm::dvec2 ang = lightAnglesOf(l, pivot);
        glm::dvec3 t = l.type == "environment"   ? towardLight(ang.x, ang.y)
                       : l.type == "directional" ? -l.direction
                                                 : l.position - pivot;
        if (glm::length(t) > 0) t = glm::normalize(t);
        const double tx = glm::dot(t, right), ty = glm::dot(t, up), tz = -glm::dot(t, forward);
        if (ImGui::IsItemActive()) {
            const ImVec2 m = ImGui::GetIO().MousePos;
            double x = (m.x - c.x) / r, y = -(m.y - c.y) / r;
            const double rr = std::hypot(x, y);
            if (rr > 1.0) x /= rr, y /= rr;
            const double z = std::sqrt(std::max(0.0, 1.0 - x * x - y * y)) * (tz < 0 ? -1 : 1);
            setLightAngles(l, lightAngles(x * right + y * up - z * forward), pivot);
            edited = true;
            panelDragging_ = true;
        }
        ImDrawList* dl = ImGui::GetWindowDrawList();
        dl->AddCircleFilled(c, r, IM_COL32(40, 44, 52, 255));
        dl->AddCircle(c, r, IM_COL32(150, 150, 160, 255));
        const ImVec2 dot(c.x + float(tx) * r, c.y - float(ty) * r);
        const ImU32 lc = IM_COL32(255, 220, 120, 255);
        if (tz >= 0)
            dl->AddCircleFilled(dot, 5.f, lc);
        else
            dl->AddCircle(dot, 5.f, lc, 0, 2.f);
        dl->AddLine(c, dot, IM_COL32(255, 220, 120, 120));
        ImGui::SameLine();
        ImGui::BeginGroup();
        float az = float(ang.x), el = float(ang.y);
        ImGui::SetNextItemWidth(width - 2 * r - 110);
        bool turned = ImGui::SliderFloat("azimuth", &az, -180.f, 180.f, "%.0f deg");
        panelDragging_ |= ImGui::IsItemActive();
        ImGui::SetNextItemWidth(width - 2 * r - 110);
        turned |= ImGui::SliderFloat("elevation", &el, -90.f, 90.f, "%.0f deg");
        panelDragging_ |= ImGui::IsItemActive();
        if (turned) setLightAngles(l, {az, el}, pivot), edited = true;
        float intensity = float(l.intensity);
        ImGui::SetNextItemWidth(width - 2 * r - 110);
        if (ImGui::DragFloat("intensity", &intensity, float(l.intensity) * 0.01f + 0.001f, 0.f,
                             FLT_MAX, "%.3g", ImGuiSliderFlags_AlwaysClamp))
            l.intensity = intensity, edited = true;
        panelDragging_ |= ImGui::IsItemActive();
        float col[3] = {float(l.color.r), float(l.color.g), float(l.color.b)};
        if (ImGui::ColorEdit3("colour", col,
                              ImGuiColorEditFlags_NoInputs | ImGuiColorEditFlags_Float))
            l.color = glm::dvec3(col[0], col[1], col[2]), edited = true;
        ImGui::SameLine();
        if (ImGui::SmallButton("remove")) remove = int(i);
        ImGui::EndGroup();
        if (l.type == "point" || l.type == "area") {
            float pos[3] = {float(l.position.x), float(l.position.y), float(l.position.z)};
            ImGui::SetNextItemWidth(width - 90);
            if (ImGui::DragFloat3("position", pos, 1.f, -1e5f, 1e5f, "%.0f mm"))
                l.position = glm::dvec3(pos[0], pos[1], pos[2]), edited = true;
            panelDragging_ |= ImGui::IsItemActive();
        }
        if (l.type == "environment") ImGui::TextDisabled("%s", l.path.filename().c_str());
        if (edited) setLights();
        ImGui::PopID();
    }
    if (remove >= 0) {
        lights_.erase(lights_.begin() + remove);
        selectedLight_ = std::max(0, std::min(selectedLight_, int(lights_.size()) - 1));
        setLights();
    }
    const char* types[] = {"directional", "point", "environment"};
    ImGui::SetNextItemWidth(110.f);
    ImGui::Combo("##lighttype", &newLightType_, types, 3);
    ImGui::SameLine();
    if (newLightType_ == 2) {
        ImGui::SetNextItemWidth(width - 180.f);
        ImGui::InputTextWithHint("##envpath", "map .hdr / .exr", &envPath_);
        ImGui::SameLine();
    }
    if (ImGui::Button("add light")) {
        try {
            addLight(types[newLightType_], envPath_);
            editMessage_.clear();
        } catch (const std::exception& e) {
            editMessage_ = e.what();
        }
    }
}

void Viewer::drawClipPanel(float width) {
    int remove = -1;
    bool edited = false;
    for (std::size_t i = 0; i < clips_.size(); ++i) {
        ViewClipPlane& c = clips_[i];
        ImGui::PushID(int(i));
        edited |= ImGui::Checkbox("##on", &c.enabled);
        if (ImGui::IsItemHovered()) ImGui::SetTooltip("enabled");
        ImGui::SameLine();
        char label[96];
        const glm::dvec3& n = c.plane.normal;
        std::snprintf(label, sizeof label, "%zu  normal %.2f %.2f %.2f", i, n.x, n.y, n.z);
        if (ImGui::Selectable(label, selectedClip_ == int(i))) selectedClip_ = int(i);
        if (selectedClip_ == int(i)) {
            // Offset: the plane's signed distance from the volume's centre along its normal.
            const double offset = glm::dot(c.plane.point - loaded_->centre, n);
            const float half = 0.5f * float(glm::length(loaded_->summary.extent));
            float o = float(offset);
            ImGui::SetNextItemWidth(width - 70);
            if (ImGui::SliderFloat("offset", &o, -half, half, "%.1f mm"))
                moveClipPlane(c.plane, double(o) - offset), edited = true;
            panelDragging_ |= ImGui::IsItemActive();
            if (ImGui::Button("flip")) flipClipPlane(c.plane), edited = true;
            ImGui::SameLine();
            edited |= ImGui::Checkbox("shadows from removed", &c.plane.shadowsFromRemoved);
            if (ImGui::IsItemHovered())
                ImGui::SetTooltip(
                    "on: a section view, the removed matter still casts shadows\n"
                    "off: removed for the light too (no shadow, no scattering)");
            ImGui::SameLine();
            if (ImGui::SmallButton("remove")) remove = int(i);
        }
        ImGui::PopID();
    }
    if (remove >= 0) {
        clips_.erase(clips_.begin() + remove);
        selectedClip_ = std::max(0, std::min(selectedClip_, int(clips_.size()) - 1));
        edited = true;
    }
    if (edited) setClipPlanes();
    ImGui::TextDisabled("add");
    const std::pair<const char*, glm::dvec3> presets[] = {
        {"sagittal", {1.0, 0.0, 0.0}}, {"coronal", {0.0, 1.0, 0.0}}, {"axial", {0.0, 0.0, 1.0}}};
    for (const auto& [name, normal] : presets) {
        ImGui::SameLine();
        if (ImGui::SmallButton(name)) addClipPlane(normal, 0.0);
    }
    ImGui::SameLine();
    if (ImGui::SmallButton("facing the view (C)")) addClipPlane(std::nullopt, 0.0);
    ImGui::Checkbox("show the gizmo (G)", &showGizmo_);
    if (ImGui::IsItemHovered())
        ImGui::SetTooltip("drag a plane's handle in the image to move it along its normal");
}

void Viewer::drawPanel() {
    panelDragging_ = false;
    ImGui::SetNextWindowPos(ImVec2(float(imageW_), 0));
    ImGui::SetNextWindowSize(ImVec2(float(kPanelWidth), ImGui::GetIO().DisplaySize.y));
    ImGui::Begin("voxlight", nullptr,
                 ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize | ImGuiWindowFlags_NoCollapse);
    const float width = ImGui::GetContentRegionAvail().x;
    if (ImGui::CollapsingHeader("File", ImGuiTreeNodeFlags_DefaultOpen)) {
        if (focusPath_) ImGui::SetKeyboardFocusHere(), focusPath_ = false;
        const bool enter = ImGui::InputText("##path", &path_, ImGuiInputTextFlags_EnterReturnsTrue);
        ImGui::SameLine();
        if (ImGui::Button("Open") || enter) openPath(path_);
        if (!loadingPath_.empty()) {
            ImGui::TextDisabled("loading %s ...", loadingPath_.c_str());
            ImGui::ProgressBar(float(loadFraction_->load()), ImVec2(-1, 0));
        }
        if (!loadError_.empty()) {
            ImGui::PushStyleColor(ImGuiCol_Text, ImVec4(1, 0.4f, 0.4f, 1));
            ImGui::TextWrapped("%s", loadError_.c_str());
            ImGui::PopStyleColor();
        }
        if (options_.saveScreenshot) {
            ImGui::InputText("##shot", &shotPath_);
            ImGui::SameLine();
            if (ImGui::Button("Screenshot")) shotRequested_ = true;
            if (!shotMessage_.empty()) ImGui::TextDisabled("%s", shotMessage_.c_str());
        }
    }
    if (!renderError_.empty())
        ImGui::TextColored(ImVec4(1, 0.4f, 0.4f, 1), "render: %s", renderError_.c_str());
    for (const auto& w : renderWarnings_)
        ImGui::TextColored(ImVec4(1, 0.8f, 0.3f, 1), "%s", w.c_str());
    if (loaded_ && ImGui::CollapsingHeader("View", ImGuiTreeNodeFlags_DefaultOpen)) {
        const char* names[] = {"A", "P", "L", "R", "S", "I"};
        const char* views[] = {"anterior", "posterior", "left", "right", "superior", "inferior"};
        for (int i = 0; i < 6; ++i) {
            if (i) ImGui::SameLine();
            if (ImGui::Button(names[i], ImVec2(34, 0))) snapView(views[i]);
            if (ImGui::IsItemHovered()) ImGui::SetTooltip("%s view", views[i]);
        }
        ImGui::SameLine();
        if (ImGui::Button("scene camera")) {
            lookAt_.reset();
            cameraResetGen_ = generation_ + 1;
            setCamera(loaded_->document.value("camera", json::object()));
        }
    }
    if (loaded_ && doc_.contains("method") && doc_["method"].is_object()) {
        const std::string method = doc_["method"].value("name", "");
        if (method == "sh-local" || method == "sh-global") {
            ImGui::TextUnformatted("SH visibility");
            ImGui::SameLine();
            if (ImGui::RadioButton("local", method == "sh-local")) setShVisibility(false);
            ImGui::SameLine();
            if (ImGui::RadioButton("global", method == "sh-global")) setShVisibility(true);
        }
    }
    if (loaded_ && ImGui::CollapsingHeader("Info")) {
        const VolumeSummary& s = loaded_->summary;
        ImGui::TextWrapped("%s", s.description.c_str());
        ImGui::Text("format      %s", s.format.c_str());
        ImGui::Text("modality    %s", s.modality.c_str());
        ImGui::Text("dims        %d x %d x %d", s.dims.x, s.dims.y, s.dims.z);
        ImGui::Text("spacing     %.3f x %.3f x %.3f mm", s.spacing.x, s.spacing.y, s.spacing.z);
        ImGui::Text("extent      %.1f x %.1f x %.1f mm", s.extent.x, s.extent.y, s.extent.z);
        ImGui::Text("origin      %.1f, %.1f, %.1f mm", s.origin.x, s.origin.y, s.origin.z);
        ImGui::Text("orientation %s", s.orientation.c_str());
        ImGui::Text("type        %s", s.type.c_str());
        ImGui::Text("range       %.1f .. %.1f %s", s.range[0], s.range[1], s.unit.c_str());
        ImGui::Text("method      %s", loaded_->scene.method.name.c_str());
        for (const auto& w : s.warnings) ImGui::TextWrapped("warning: %s", w.c_str());
    }
    if (loaded_ && ImGui::CollapsingHeader("Transfer function", ImGuiTreeNodeFlags_DefaultOpen)) {
        optics::TransferFunction tf = tf_;
        const TfEditResult r = drawTfEditor(tfEditor_, tf, loaded_->tf, loaded_->histogram,
                                            loaded_->robustRange, width);
        tfEditing_ = r.active;
        if (r.changed) setTf(tf);
    }
    if (loaded_ && ImGui::CollapsingHeader("Lights", ImGuiTreeNodeFlags_DefaultOpen))
        drawLightsPanel(width);
    if (loaded_ && ImGui::CollapsingHeader("Clip planes", ImGuiTreeNodeFlags_DefaultOpen))
        drawClipPanel(width);
    if (!editMessage_.empty())
        ImGui::TextColored(ImVec4(1, 0.4f, 0.4f, 1), "%s", editMessage_.c_str());
    if (loaded_ && ImGui::CollapsingHeader("Path tracer")) {
        // This view, photoreal (method pathtrace): rendered in the background, shown in place of
        // the live image until the view changes.
        ImGui::SetNextItemWidth(120.f);
        ImGui::InputInt("spp", &ptSpp_);
        ptSpp_ = std::clamp(ptSpp_, 1, 65536);
        ImGui::SameLine();
        if (ImGui::Button("Render this view")) startPathTrace(ptSpp_);
        const RenderWorker::Status st = ptWorker_.status();
        if (st.busy) ImGui::ProgressBar(float(st.fraction), ImVec2(-1, 0));
        if (ptReady_ && ptGen_ == generation_)
            ImGui::Checkbox("show the path-traced image", &ptShow_);
        if (ptReady_ && ptGen_ != generation_) ImGui::TextDisabled("the view changed since");
        if (!ptMessage_.empty()) ImGui::TextWrapped("%s", ptMessage_.c_str());
    }
    if (loaded_ && ImGui::CollapsingHeader("Session")) {
        // Record the exploration (every settled state a keyframe) for `voxlight replay`.
        if (!recorder_) {
            if (ImGui::Button("Record")) {
                recorder_.emplace(loaded_->scene, "recorded by voxlight view");
                recordClock_.restart();
                recordMessage_.clear();
                changed();  // the current state is the first keyframe
            }
        } else {
            ImGui::Text("recording: %zu keyframes, %.1f s", recorder_->session().keyframes.size(),
                        recordClock_.seconds());
        }
        ImGui::SetNextItemWidth(width - 90.f);
        ImGui::InputText("##sessionpath", &recordPath_);
        ImGui::SameLine();
        ImGui::BeginDisabled(!recorder_);
        if (ImGui::Button("Save")) {
            try {
                recordMessage_ = saveRecording(recordPath_);
            } catch (const std::exception& e) {
                recordMessage_ = e.what();
            }
        }
        ImGui::EndDisabled();
        if (!recordMessage_.empty()) ImGui::TextWrapped("%s", recordMessage_.c_str());
    }
    if (ImGui::CollapsingHeader("Renderer", ImGuiTreeNodeFlags_DefaultOpen)) {
        ImGui::Text("active: %s", measure_ != Measure::Done ? "CPU ray caster (measuring)"
                                  : gpu_                    ? "GLSL ray caster (GPU)"
                                                            : "CPU ray caster");
        ImGui::TextWrapped("why: %s", rendererReason_.c_str());
        if (gl_) ImGui::TextDisabled("GL: %s", gl_->glRenderer().c_str());
        int c = int(choice_);
        const char* names[] = {"auto", "gpu", "cpu"};
        ImGui::SetNextItemWidth(120.f);
        if (ImGui::Combo("renderer", &c, names, 3) && c != int(choice_)) {
            choice_ = RendererChoice(c);
            if (choice_ != RendererChoice::Cpu && !gl_ && glError_.empty()) {
                gl_ = std::make_unique<GlRayCaster>();
                if (!gl_->init(glError_)) gl_.reset();
            }
            restartMeasurement();
            changed();
        }
        if (glTimes_.count > 0)
            ImGui::Text("GLSL frame    %.3f s (%zu)", glTimes_.last(), std::size_t(glTimes_.count));
        if (glCoarseTimes_.count > 0)
            ImGui::Text("GLSL coarse   %.3f s (%zu)", glCoarseTimes_.last(),
                        std::size_t(glCoarseTimes_.count));
    }
    if (ImGui::CollapsingHeader("Stats", ImGuiTreeNodeFlags_DefaultOpen)) {
        const RenderWorker::Status st = worker_.status();
        ImGui::Text("UI frame work  %.1f ms (mean %.1f, max %.1f)", frameWork_.last() * 1e3,
                    frameWork_.mean() * 1e3, frameWork_.max() * 1e3);
        ImGui::Text("UI frame interval max %.1f ms", frameInterval_.max() * 1e3);
        ImGui::Text("coarse render  %.3f s (%zu)", coarseTimes_.last(), coarseTimes_.values.size());
        ImGui::Text("full render    %.3f s (%zu)", fullTimes_.last(), fullTimes_.values.size());
        if (st.busy)
            ImGui::Text("rendering %s %3.0f %%", st.coarse ? "coarse" : "full", st.fraction * 100);
        else
            ImGui::TextDisabled("%s", shownFull_ ? "idle: full resolution shown" : "idle");
        // Kronander's interleaved update: the old shading stays until the new fields are ready.
        if (st.updatingFields)
            ImGui::TextColored(ImVec4(1.f, 0.8f, 0.3f, 1.f),
                               "updating shading (visibility) %3.0f %%; earlier shading shown",
                               st.fieldFraction * 100);
    }
    if (helpToggled_) ImGui::SetNextItemOpen(showHelp_), helpToggled_ = false;
    if (ImGui::CollapsingHeader("Help (F1)")) ImGui::TextUnformatted(kHelp);
    ImGui::End();
}

core::ImageRGBA Viewer::readWindow() const {
    int w = 0, h = 0;
    glfwGetFramebufferSize(window_, &w, &h);
    std::vector<std::uint8_t> bytes(std::size_t(4) * w * h);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadBuffer(GL_BACK);
    glReadPixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, bytes.data());
    core::ImageRGBA img(w, h);
    // GL's row 0 is the bottom; the image's is the top.
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::uint8_t* p = &bytes[4 * (std::size_t(h - 1 - y) * w + x)];
            float* q = img.at(x, y);
            for (int c = 0; c < 3; ++c) q[c] = float(p[c]) / 255.f;
            q[3] = 1.f;
        }
    return img;
}

core::ImageRGBA Viewer::shownRadiance() const {
    if (pathTraceShown() && ptFilm_ && ptW_ == texW_ && ptH_ == texH_) return *ptFilm_;
    // The GL film is the frame in progress's target: only when none is (and the image is full).
    if (shownGl_ && gl_) return !glJob_ && shownFull_ ? gl_->readFilm() : core::ImageRGBA();
    if (shownFilm_ && shownFull_) return *shownFilm_;
    return core::ImageRGBA();
}

core::ImageRGBA Viewer::screenshotFor(const std::string& path) const {
    std::string ext = std::filesystem::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext == ".exr" ? shownRadiance() : readWindow();
}

void Viewer::logTimes() {
    if (!options_.log || logClock_.seconds() < 1.0) return;
    logClock_.restart();
    std::fprintf(
        stderr, "view: ui frame work mean %.1f ms max %.1f ms, interval max %.1f ms (%zu frames)\n",
        frameWork_.mean() * 1e3, frameWork_.max() * 1e3, frameInterval_.max() * 1e3,
        frameWork_.values.size());
}

std::optional<core::ImageRGBA> Viewer::run() {
    try {
        return runFrames();
    } catch (const InputError& e) {
        // A script step's error (or a screenshot that never came) ends the run: the --record
        // session so far is saved as on any other exit, and the line says so.
        const std::string kept = keepRecording();
        if (kept.empty()) throw;
        throw InputError(e.source(), e.field(), e.problem() + kept, e.fix());
    }
}

std::optional<core::ImageRGBA> Viewer::runFrames() {
    const bool scripted = !options_.screenshot.empty();
    core::Stopwatch sinceStart, frameClock;
    std::optional<core::ImageRGBA> shot;
    while (!glfwWindowShouldClose(window_)) {
        if (options_.quit && options_.quit->load()) break;
        if (frames_ > kWarmUpFrames) frameInterval_.add(frameClock.seconds());
        frameClock.restart();
        core::Stopwatch work;
        glfwPollEvents();
        // Files dropped on the window: the last one opens, as if typed into the file field.
        if (const std::vector<std::string> dropped = takeDropped(); !dropped.empty())
            openPath(dropped.back());
        const double tEvents = work.seconds();
        pollLoad();
        receive();
        // The next slice of a GLSL frame begun in an earlier UI frame.
        if (gpu_ && glJob_ && glJob_->uiFrame != frames_) stepGl();
        receivePathTrace();
        const double tReceive = work.seconds();
        int fbW = 0, fbH = 0;
        glfwGetFramebufferSize(window_, &fbW, &fbH);
        const int w = std::max(fbW - kPanelWidth, 1), h = std::max(fbH, 1);
        if (w != imageW_ || h != imageH_) imageW_ = w, imageH_ = h, changed();

        ImGui_ImplOpenGL3_NewFrame();
        ImGui_ImplGlfw_NewFrame();
        ImGui::NewFrame();
        const double tNewFrame = work.seconds();
        scriptDragMoved_ = false;
        handleKeys();
        handleImageMouse();
        updateRenderer();
        try {
            runScript();
        } catch (const InputError& e) {
            // A step's own error (an index past the planes) names the script already.
            if (scriptNext_ == 0 || e.source() == options_.script[scriptNext_ - 1].source) throw;
            throw scriptStepError(e.what());
        }
        const double tInput = work.seconds();
        drawImage();
        const double tImage = work.seconds();
        drawPanel();
        const double tWidgets = work.seconds();
        ImGui::Render();
        glViewport(0, 0, fbW, fbH);
        glClearColor(0.08f, 0.08f, 0.09f, 1.f);
        glClear(GL_COLOR_BUFFER_BIT);
        ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());

        // Ask for a picture of the newest state; coarse while the user drags.
        // Which drag this frame belongs to (a mouse drag, a scripted one, a TF point's).
        const char* dragging = drag_ != Drag::None ? dragName(drag_)
                               : scriptDragMoved_  ? dragName(scriptDrag_)
                               : tfEditing_        ? "TF point"
                                                   : nullptr;
        const bool interacting =
            drag_ != Drag::None || tfEditing_ || panelDragging_ || scriptDragFrames_ > 0;
        if (dirty_) {
            submit(interacting);
            dirty_ = false;
            interactingSent_ = interacting;
        } else if (interactingSent_ && !interacting) {
            submit(false);  // the drag ended: refine the same state
            interactingSent_ = false;
        }
        ++frames_;
        if (scripted && frames_ >= std::uint64_t(std::max(options_.frames, 1)) && !dirty_ &&
            scriptNext_ >= options_.script.size() && scriptDragFrames_ == 0 &&
            (ptGen_ != generation_ || ptReady_) && measure_ == Measure::Done && shownFull_ &&
            !shownStale_ && shownGen_ == generation_ && !loading_.valid() && !dropPending() &&
            texW_ == imageW_ && texH_ == imageH_)
            shot = screenshotFor(options_.screenshot);
        if (shotRequested_ && options_.saveScreenshot && !saving_.valid()) {
            // Read back here (the frame is in the back buffer); encode and write on a thread.
            shotRequested_ = false;
            shotMessage_ = "writing " + shotPath_ + " ...";
            saving_ = std::async(
                std::launch::async,
                [save = options_.saveScreenshot, image = screenshotFor(shotPath_), path = shotPath_,
                 scene = loaded_ ? sceneOnScreen() : io::Scene{}]() -> std::string {
                    try {
                        if (image.width < 1)
                            return "nothing to save yet: no full-resolution "
                                   "image is shown";
                        save(image, path, scene);
                        return "wrote " + path;
                    } catch (const std::exception& e) {
                        return e.what();
                    }
                });
        }
        if (saving_.valid() &&
            saving_.wait_for(std::chrono::seconds(0)) == std::future_status::ready)
            shotMessage_ = saving_.get();
        const double tDraw = work.seconds();
        glfwSwapBuffers(window_);
        // The first frames compile the GL shaders and build the font atlas: not the UI's pace.
        if (frames_ > kWarmUpFrames) frameWork_.add(work.seconds());
        // The issue's "UI frame during a TF change / a clip-plane drag": each drag's frames on
        // their own, said when it ends.
        if (dragWork_.count > 0 && dragging != dragWorkName_) {
            if (options_.log)
                std::fprintf(stderr,
                             "view: %s drag: %llu frames, ui frame work mean %.1f ms, max %.1f ms, "
                             "%llu over %.0f ms\n",
                             dragWorkName_, (unsigned long long)dragWork_.count,
                             dragWork_.mean() * 1e3, dragWork_.allMax * 1e3,
                             (unsigned long long)dragWork_.overSlow, kSlowFrameSeconds * 1e3);
            dragWork_ = {{}, std::size_t(-1)};
        }
        if (dragging && frames_ > kWarmUpFrames) dragWork_.add(work.seconds());
        dragWorkName_ = dragging;
        // A slow frame says where its time went.
        if (options_.log && frames_ > kWarmUpFrames && work.seconds() > kSlowFrameSeconds)
            std::fprintf(stderr,
                         "view: slow frame %.1f ms: events %.1f, results %.1f, widgets %.1f "
                         "(new frame %.1f, input and script %.1f, image and gizmo %.1f, panel "
                         "%.1f), draw %.1f, present %.1f ms\n",
                         work.seconds() * 1e3, tEvents * 1e3, (tReceive - tEvents) * 1e3,
                         (tWidgets - tReceive) * 1e3, (tNewFrame - tReceive) * 1e3,
                         (tInput - tNewFrame) * 1e3, (tImage - tInput) * 1e3,
                         (tWidgets - tImage) * 1e3, (tDraw - tWidgets) * 1e3,
                         (work.seconds() - tDraw) * 1e3);
        logTimes();
        if (shot) break;
        if (scripted) {
            if (!renderError_.empty()) {
                if (scriptNext_ > 0) throw scriptStepError(renderError_);
                throw InputError(options_.screenshot, "render", renderError_);
            }
            if (sinceStart.seconds() > options_.screenshotTimeoutSeconds)
                throw InputError("view", "--screenshot",
                                 "the full-resolution image was not ready within " +
                                     std::to_string(int(options_.screenshotTimeoutSeconds)) + " s");
        }
        // Idle: sleep what is left of the frame budget, woken early by any input event.
        const double left = kFrameBudgetSeconds - frameClock.seconds();
        if (left > 0) glfwWaitEventsTimeout(left);
    }
    if (options_.log)
        std::fprintf(stderr,
                     "view: %llu frames; ui frame work max %.1f ms over the session, %llu over "
                     "%.0f ms, mean %.1f ms (last 240); coarse renders %zu (%.3f-%.3f s); full "
                     "renders %zu (%.3f-%.3f s)\n",
                     (unsigned long long)frames_, frameWork_.allMax * 1e3,
                     (unsigned long long)frameWork_.overSlow, kSlowFrameSeconds * 1e3,
                     frameWork_.mean() * 1e3, std::size_t(coarseTimes_.count), coarseTimes_.min(),
                     coarseTimes_.max(), std::size_t(fullTimes_.count), fullTimes_.min(),
                     fullTimes_.max());
    if (!options_.record.empty() && recorder_ && recorder_->session().keyframes.empty()) {
        // Closed before the first state was asked for: nothing to replay.
        std::fprintf(stderr, "voxlight view: nothing was recorded; %s was not written\n",
                     options_.record.c_str());
    } else if (!options_.record.empty() && recorder_) {
        // A session that cannot be saved is the run's error, with its reason (the window is gone).
        const std::string m = saveRecording(options_.record);
        if (options_.log) std::fprintf(stderr, "view: %s\n", m.c_str());
    }
    return shot;
}

}  // namespace

const char* helpText() { return kHelp; }

void checkScreenshotSize(const io::Scene& s) {
    try {
        render::checkImageSize(s.image.width, s.image.height);
    } catch (const InputError& e) {  // named by the scene's key, as render names it
        throw InputError(s.source, "image.width", e.problem(), e.fix());
    }
}

void requireDisplay() {
    if (!glfwInit())
        throw InputError("display", "OpenGL 4.5 window", "cannot be opened: " + glfwErrorText(),
                         "run on a desktop, or headless under xvfb-run -a");
    glfwTerminate();
}

std::optional<core::ImageRGBA> runViewer(const ViewerOptions& options,
                                         std::optional<LoadedScene> initial) {
    if (!options.screenshot.empty() && initial) checkScreenshotSize(initial->scene);
    if (!glfwInit())
        throw InputError("display", "OpenGL 4.5 window", "cannot be opened: " + glfwErrorText(),
                         "run on a desktop, or headless under xvfb-run -a");
    // From here to the end (window creation, the run, teardown) a lost display ends the process
    // through the viewer while it runs (its session, its messages), else with one line (a
    // --record session is saved before teardown).
    Viewer* live = nullptr;
    const DisplayLossGuard guard([&live, &options]() -> int {
        if (live) return live->displayLost();
        return reportDisplayLoss(lostByCancel(options.quit),
                                 options.screenshot.empty() ? "" : "; no screenshot was written");
    });
    struct Terminate {
        ~Terminate() { glfwTerminate(); }
    } terminate;
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    const bool scripted = !options.screenshot.empty();
    // Scripted runs keep the window at the scene's image size plus the panel, so the image area
    // is exactly the scene's image.
    if (scripted) glfwWindowHint(GLFW_RESIZABLE, GLFW_FALSE);
    const int w = (initial ? initial->scene.image.width : kDefaultImageWidth) + kPanelWidth;
    const int h = initial ? initial->scene.image.height : kDefaultImageHeight;
    GLFWwindow* window = glfwCreateWindow(w, h, "voxlight view", nullptr, nullptr);
    if (!window)
        throw InputError("display", "OpenGL 4.5 window", "cannot be opened: " + glfwErrorText(),
                         "run on a desktop, or headless under xvfb-run -a");
    glfwMakeContextCurrent(window);
    glfwSwapInterval(scripted ? 0 : 1);
    glfwSetDropCallback(window, onDrop);
    glfwSetKeyCallback(window, onKey);  // before ImGui's, which calls it after its own

    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini written into the working directory
    ImGui::StyleColorsDark();
    ImGui_ImplGlfw_InitForOpenGL(window, true);
    ImGui_ImplOpenGL3_Init("#version 450 core");
    std::optional<core::ImageRGBA> shot;
    try {
        // The viewer (its texture, its worker) goes before the context it was made in.
        Viewer viewer(options, window);
        struct Live {  // the guard's way to the viewer, until it is destroyed
            Viewer*& to;
            ~Live() { to = nullptr; }
        } alive{live = &viewer};
        if (initial) viewer.adopt(std::move(*initial));
        shot = viewer.run();
    } catch (...) {
        ImGui_ImplOpenGL3_Shutdown();
        ImGui_ImplGlfw_Shutdown();
        ImGui::DestroyContext();
        glfwDestroyWindow(window);
        throw;
    }
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    glfwDestroyWindow(window);
    return shot;
}

}  // namespace voxlight::viewer
