// SPDX-License-Identifier: MIT
#pragma once
// The viewer's background renderer: one thread that renders scenes through the pipeline (the same
// code `voxlight render` runs, with its artifact cache, so a camera change re-runs only the frame
// stages) while the UI thread keeps drawing. The UI never waits for it:
//   submit()  hands over the newest scene and returns at once. A full-resolution pass in progress
//             for an older state is cancelled (core::Progress's cancel flag); a coarse pass is let
//             finish (it is short), then the newest request is taken — requests in between are
//             dropped, never queued.
//   take()    returns the newest finished image, if any, without blocking (a mutex held only to
//             move a buffer).
// Progressive refinement: each new state is first rendered coarse (coarseScene: 1/4 of the size,
// twice the step), then — unless the request says the user is still interacting — at full
// resolution. A request repeating a state already rendered coarse goes straight to full.
// Kronander's interleaved update for the SH methods: after a TF change (or a cut) both passes
// shade from the last visibility fields at once (pipeline::RunOptions::staleFields; the image
// says staleShading), while a second thread computes the new fields in the same session — not
// cancelled by camera or light moves, only by a state that needs other fields — and the state
// is rendered again when they are ready. The UI never waits for either.
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/image.h"
#include "io/scene.h"
#include "viewer/sh_grids.h"

namespace voxlight::pipeline {
class Session;
struct CasterSetup;
}  // namespace voxlight::pipeline

namespace voxlight::viewer {

struct RenderRequest {
    io::Scene scene;               ///< the full-resolution scene
    std::uint64_t generation = 0;  ///< the state's number: equal numbers are equal scenes
    bool interacting = false;      ///< the user is dragging: coarse only
    /// Only prepare what the image stage reads (pipeline::Session::prepare), no pixels: for the
    /// GLSL ray caster, which renders on the UI thread. No separate coarse pass: an interacting
    /// request prepares the coarse scene instead (RenderedImage::coarse). After a TF change or a cut
    /// the setup holds the last fields (staleShading) while the field thread computes the new
    /// ones; then the same state is prepared again — the interleaved update, as for images.
    bool prepareOnly = false;
    /// Full pass: run the Frame stages this many times (the start-up measurement; the image and
    /// RenderedImage::frameSeconds are the median frame's).
    int frames = 1;
};

/// A finished render, display-encoded as the CLI's PNG is (render::toDisplay with the scene's
/// exposure and display transform, then 8 bits per channel rounded to nearest).
struct RenderedImage {
    std::uint64_t generation = 0;
    bool coarse = false;
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgba;  ///< row 0 = top
    /// Full passes: the linear film (radiance + T·background, alpha = coverage; the raw estimate,
    /// never the denoised one) as `voxlight render --exr` writes it — EXR screenshots.
    std::shared_ptr<const core::ImageRGBA> film;
    double seconds = 0.0;  ///< the pipeline run, wall clock
    /// The Frame stages (camera, render) of one frame, median over the request's frames.
    double frameSeconds = 0.0;
    int frames = 1;  ///< the frames frameSeconds is the median of
    /// prepareOnly: what the image stage would read; null when the scene's method does not render
    /// with the CPU ray caster (then `method` names it).
    std::shared_ptr<const pipeline::CasterSetup> setup;
    /// prepareOnly, SH methods: setup's visibility fields resampled for the GLSL ray caster
    /// (viewer/sh_grids.h; on this thread, kept per field).
    ShGrids shGrids;
    double shResampleSeconds = 0.0;  ///< of the fields resampled for this result (0: all kept)
    bool prepared = false;           ///< a prepareOnly result (no pixels)
    std::string method;              ///< prepareOnly: the scene's method
    double exposureStops = 0.0;      ///< prepareOnly: the scene's display settings (io::ImageDesc)
    std::string display;
    nlohmann::json camera;  ///< the camera as used (pipeline details "camera")
    std::vector<std::string> warnings;
    /// The pipeline stages this pass computed (not served from the cache), in order.
    std::vector<std::string> computedStages;
    std::string error;  ///< non-empty: the render failed (an InputError's message); no pixels
    /// Shaded from an earlier state's visibility fields (the new ones are being computed; the
    /// same state is rendered again when they are ready).
    bool staleShading = false;
};

struct WorkerOptions {
    int coarseFactor = 4;             ///< coarse pass: image size divided by this
    double coarseStepScale = 2.0;     ///< coarse pass: render.step multiplied by this
    double coarseTermination = 0.01;  ///< coarse pass: early ray termination at least this
    /// OS priority (Linux nice, 0–19) of the worker thread and of the oneTBB threads that join
    /// its parallel loops: the UI thread (nice 0) is scheduled first. 0 leaves them as they are.
    int nice = 10;
};

/// 8-bit display pixels of a linear film (the CLI's PNG mapping): exposure, display transform,
/// clamp, round to nearest.
std::vector<std::uint8_t> displayBytes(const io::Scene& scene, const core::ImageRGBA& film);

class RenderWorker {
  public:
    explicit RenderWorker(WorkerOptions options = {});
    ~RenderWorker();  ///< cancels the running pass and joins the thread
    RenderWorker(const RenderWorker&) = delete;
    RenderWorker& operator=(const RenderWorker&) = delete;

    /// Hands the volume the viewer loaded for `scene` (its info and histogram) to the session
    /// (pipeline::adoptVolume): the worker's runs read it from memory, never from the file again.
    void adoptVolume(const io::Scene& scene, std::shared_ptr<const core::Volume> volume);
    void submit(RenderRequest request);
    std::optional<RenderedImage> take();

    struct Status {
        bool busy = false;
        bool coarse = false;    ///< the running pass
        double fraction = 0.0;  ///< of the running pass's current stage
        std::uint64_t generation = 0;
        bool updatingFields = false;  ///< the field thread computes visibility for a new state
        double fieldFraction = 0.0;   ///< of its current stage
    };
    Status status() const;
    /// Renders finished so far (both passes), for tests and the stats panel.
    std::uint64_t completed() const { return completed_.load(); }
    /// Passes cancelled so far.
    std::uint64_t cancelled() const { return cancelled_.load(); }

  private:
    void loop();
    void fieldLoop();
    /// False when cancelled; `stale`: some field stood in for this state's.
    bool renderPass(const RenderRequest& request, bool coarse, std::string* staleFields = nullptr);
    /// False when cancelled or failed; `staleFields` as renderPass's (the interleaved update
    /// on the GLSL path: the setup holds the stand-in fields).
    bool preparePass(const RenderRequest& request, std::string* staleFields = nullptr);
    /// After a finished full (or prepare) pass of `request` (mutex_ held): remember it, and have
    /// the field thread compute the fields `stale` names (empty: none stood in).
    void scheduleFields(const RenderRequest& request, const std::string& stale);

    WorkerOptions options_;
    mutable std::mutex mutex_;
    std::condition_variable wake_;
    std::optional<RenderRequest> pending_;
    bool stop_ = false;
    bool runningFull_ = false;
    std::uint64_t runningGeneration_ = 0;
    std::uint64_t coarseDone_ = ~std::uint64_t(0);  ///< generation last rendered coarse
    std::atomic<bool> cancel_{false};
    std::atomic<bool> busy_{false}, busyCoarse_{false};
    std::atomic<double> fraction_{0.0};
    std::atomic<std::uint64_t> completed_{0}, cancelled_{0};
    std::mutex resultMutex_;
    std::optional<RenderedImage> result_;
    /// The session (cache of volume, tables and fields) both threads run scenes through.
    std::unique_ptr<pipeline::Session> session_;
    ShGridCache shGridCache_;  ///< the worker thread's (preparePass)
    // The field thread (guarded by mutex_): the state whose fields to compute, and the last
    // full request (rendered again when its fields are ready).
    std::optional<RenderRequest> fieldPending_;
    std::string fieldSignature_;  ///< the fields being computed (their keys), "" when idle
    std::optional<RenderRequest> lastFull_;
    bool fieldBusy_ = false;
    std::atomic<bool> fieldCancel_{false};
    std::atomic<double> fieldFraction_{0.0};
    std::condition_variable fieldWake_;
    std::thread thread_;
    std::thread fieldThread_;
};

}  // namespace voxlight::viewer
