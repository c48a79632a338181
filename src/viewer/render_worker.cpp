// SPDX-License-Identifier: MIT
#include "viewer/render_worker.h"

#include <oneapi/tbb/task_scheduler_observer.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/image.h"
#include "core/progress.h"
#include "core/timing.h"
#include "pipeline/pipeline.h"
#include "render/tonemap.h"
#include "viewer/gl_support.h"
#include "viewer/view_state.h"

namespace voxlight::viewer {

namespace {
/// Lowers the calling thread's OS priority (Linux nice is per thread); raising it back would need
/// privileges, so only threads that do background work call this.
void lowerThisThread(int nice) {
    if (nice > 0) ::setpriority(PRIO_PROCESS, id_t(::syscall(SYS_gettid)), nice);
}
/// Lowers every oneTBB worker thread that joins the arena of the thread that made it (the
/// render worker's): the ray caster's and the precompute stages' parallel loops.
class LowerArenaWorkers : public tbb::task_scheduler_observer {
  public:
    explicit LowerArenaWorkers(int nice) : nice_(nice) { observe(true); }
    ~LowerArenaWorkers() override { observe(false); }
    void on_scheduler_entry(bool isWorker) override {
        if (isWorker) lowerThisThread(nice_);
    }

  private:
    int nice_;
};
}  // namespace

std::vector<std::uint8_t> displayBytes(const io::Scene& scene, const core::ImageRGBA& film) {
    const core::ImageRGBA shown = render::toDisplay(film, float(scene.image.exposureStops),
                                                    render::displayFromString(scene.image.display));
    std::vector<std::uint8_t> out(shown.pixels.size());
    for (std::size_t i = 0; i < out.size(); ++i)
        out[i] = std::uint8_t(std::lround(std::clamp(shown.pixels[i], 0.f, 1.f) * 255.f));
    return out;
}

RenderWorker::RenderWorker(WorkerOptions options)
    : options_(options),
      session_(std::make_unique<pipeline::Session>()),
      thread_([this] { loop(); }),
      fieldThread_([this] { fieldLoop(); }) {}

RenderWorker::~RenderWorker() {
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
        cancel_ = true;
        fieldCancel_ = true;
    }
    wake_.notify_all();
    fieldWake_.notify_all();
    thread_.join();
    fieldThread_.join();
}

void RenderWorker::submit(RenderRequest request) {
    {
        std::lock_guard lock(mutex_);
        // A full pass of an older state is wasted work now; a coarse pass finishes (it is short
        // and keeps the picture moving while the user drags).
        if (busy_ && runningFull_ && request.generation != runningGeneration_) cancel_ = true;
        pending_ = std::move(request);
    }
    wake_.notify_one();
}

std::optional<RenderedImage> RenderWorker::take() {
    std::lock_guard lock(resultMutex_);
    std::optional<RenderedImage> r = std::move(result_);
    result_.reset();
    return r;
}

RenderWorker::Status RenderWorker::status() const {
    Status s;
    s.busy = busy_;
    s.coarse = busyCoarse_;
    s.fraction = fraction_;
    s.fieldFraction = fieldFraction_;
    std::lock_guard lock(mutex_);
    s.generation = runningGeneration_;
    s.updatingFields = fieldBusy_ || fieldPending_.has_value();
    return s;
}

void RenderWorker::loop() {
    // The UI thread gets a core before the render work does (its frames, not the renders, are
    // what must keep pace on a machine with two cores).
    lowerThisThread(options_.nice);
    LowerArenaWorkers lowerWorkers(options_.nice);
    std::unique_lock lock(mutex_);
    for (;;) {
        wake_.wait(lock, [&] { return stop_ || pending_.has_value(); });
        if (stop_) return;
        RenderRequest request = std::move(*pending_);
        pending_.reset();
        cancel_ = false;
        runningGeneration_ = request.generation;
        if (request.prepareOnly) {
            runningFull_ = !request.interacting;  // a coarse prepare finishes, as a coarse pass
            busy_ = true;
            lock.unlock();
            std::string stale;
            const bool done = preparePass(request, &stale);
            lock.lock();
            busy_ = false;
            runningFull_ = false;
            if (stop_) return;
            if (done) scheduleFields(request, stale);
            continue;
        }
        const bool needCoarse = coarseDone_ != request.generation;
        // Coarse first, for a picture within a fraction of the full render's time.
        if (needCoarse) {
            runningFull_ = false;
            busy_ = busyCoarse_ = true;
            lock.unlock();
            const bool done = renderPass(request, true);
            lock.lock();
            busy_ = busyCoarse_ = false;
            if (done) coarseDone_ = request.generation;
            if (stop_) return;
        }
        if (request.interacting || pending_) continue;  // a newer state waits: render that
        runningFull_ = true;
        busy_ = true;
        lock.unlock();
        std::string stale;
        const bool done = renderPass(request, false, &stale);
        lock.lock();
        busy_ = false;
        runningFull_ = false;
        if (stop_) return;
        if (!done) continue;
        scheduleFields(request, stale);
    }
}

void RenderWorker::scheduleFields(const RenderRequest& request, const std::string& stale) {
    // What is rendered again when the fields are ready: the state at full resolution (a coarse
    // prepare of a drag would otherwise come back after the released state's full one).
    lastFull_ = request;
    lastFull_->interacting = false;
    // Shaded from earlier fields: have the field thread compute this state's, unless it is
    // computing them already (a camera or light move needs the same fields: let it go on).
    if (!stale.empty() && stale != fieldSignature_) {
        if (fieldBusy_) fieldCancel_ = true;
        fieldPending_ = request;
        fieldSignature_ = stale;
        fieldWake_.notify_one();
    }
}

void RenderWorker::fieldLoop() {
    lowerThisThread(options_.nice);
    LowerArenaWorkers lowerWorkers(options_.nice);
    std::unique_lock lock(mutex_);
    for (;;) {
        fieldWake_.wait(lock, [&] { return stop_ || fieldPending_.has_value(); });
        if (stop_) return;
        io::Scene scene = std::move(fieldPending_->scene);
        fieldPending_.reset();
        fieldCancel_ = false;
        fieldBusy_ = true;
        lock.unlock();
        // The fields come from a run of the state itself (a tiny image: its frame costs nothing)
        // without stand-ins; they land in the shared session's cache.
        scene.image.width = scene.image.height = 8;
        bool done = false;
        fieldFraction_ = 0.0;
        try {
            const core::Progress progress(
                [this](const std::string&, double f) { fieldFraction_ = f; }, &fieldCancel_);
            (void)session_->run(scene, {}, progress);
            done = true;
        } catch (const std::exception&) {
            // Cancelled, or an error the render thread reports for the same state.
        }
        lock.lock();
        fieldBusy_ = false;
        if (!fieldPending_) fieldSignature_.clear();
        if (stop_) return;
        // Render the newest full state again: with its fields ready it is no longer stale.
        if (done && !fieldPending_ && !pending_ && lastFull_) {
            pending_ = lastFull_;
            wake_.notify_one();
        }
    }
}

bool RenderWorker::renderPass(const RenderRequest& request, bool coarse, std::string* staleFields) {
    RenderedImage out;
    out.generation = request.generation;
    out.coarse = coarse;
    fraction_ = 0.0;
    const core::Progress progress([this](const std::string&, double f) { fraction_ = f; },
                                  &cancel_);
    try {
        const io::Scene scene =
            coarse ? coarseScene(request.scene, options_.coarseFactor, options_.coarseStepScale,
                                 options_.coarseTermination)
                   : request.scene;
        core::Stopwatch sw;
        pipeline::RunOptions runOptions;
        runOptions.staleFields = true;  // old shading at once after a TF change or a cut
        runOptions.frames = coarse ? 1 : std::clamp(request.frames, 1, pipeline::kMaxFrames);
        out.frames = runOptions.frames;
        pipeline::RunResult r = session_->run(scene, runOptions, progress);
        for (const auto& st : r.stages)
            if (st.ran) out.computedStages.push_back(st.name);
        for (const auto& st : r.stages)
            if (st.stale) {
                out.staleShading = true;
                if (staleFields) *staleFields += st.name + ":" + st.wantedKey + " ";
            }
        out.seconds = sw.seconds();
        for (const pipeline::StageRecord& st : r.stages)
            if (st.kind == pipeline::StageKind::Frame && st.ran) out.frameSeconds += st.seconds;
        const auto denoised = r.images.find("denoised");
        const core::ImageRGBA& film = denoised != r.images.end() ? denoised->second : r.image;
        out.width = film.width;
        out.height = film.height;
        out.rgba = displayBytes(scene, film);
        if (!coarse) out.film = std::make_shared<const core::ImageRGBA>(std::move(r.image));
        if (r.details.contains("camera")) out.camera = r.details["camera"];
        out.warnings = r.warnings;
    } catch (const CancelledError&) {
        ++cancelled_;
        return false;
    } catch (const std::exception& e) {
        out.error = e.what();
    }
    ++completed_;
    const bool ok = out.error.empty();
    std::lock_guard lock(resultMutex_);
    result_ = std::move(out);
    return ok;
}

void RenderWorker::adoptVolume(const io::Scene& scene, std::shared_ptr<const core::Volume> volume) {
    pipeline::adoptVolume(*session_, scene, std::move(volume));
}

bool RenderWorker::preparePass(const RenderRequest& request, std::string* staleFields) {
    RenderedImage out;
    out.generation = request.generation;
    // While the user drags, the coarse scene (as the CPU path's coarse pass): the GLSL ray caster
    // renders the setup at its camera's size, step and termination.
    out.coarse = request.interacting;
    out.method = request.scene.method.name;
    out.prepared = true;
    out.exposureStops = request.scene.image.exposureStops;
    out.display = request.scene.image.display;
    fraction_ = 0.0;
    const core::Progress progress([this](const std::string&, double f) { fraction_ = f; },
                                  &cancel_);
    try {
        core::Stopwatch sw;
        pipeline::RunOptions runOptions;
        runOptions.staleFields = true;  // old shading at once after a TF change or a cut
        std::vector<pipeline::StageRecord> records;
        // The coarse step stays within what the shader takes, 1 % inside for the float rounding
        // of the scene's step (the pixels are the larger saving anyway).
        const double stepScale =
            std::clamp(0.99 * kGlMaxStepVoxels / request.scene.render.stepVoxels, 1.0,
                       options_.coarseStepScale);
        const io::Scene scene = out.coarse ? coarseScene(request.scene, options_.coarseFactor,
                                                         stepScale, options_.coarseTermination)
                                           : request.scene;
        std::optional<pipeline::CasterSetup> setup =
            session_->prepare(scene, progress, &out.warnings, runOptions, &records);
        for (const auto& st : records) {
            if (st.ran) out.computedStages.push_back(st.name);
            if (st.stale) {
                out.staleShading = true;
                if (staleFields) *staleFields += st.name + ":" + st.wantedKey + " ";
            }
        }
        out.seconds = sw.seconds();
        if (setup) {
            out.width = setup->camera->width();
            out.height = setup->camera->height();
            out.camera = pipeline::cameraDetails(*setup->camera);
            out.setup = std::make_shared<const pipeline::CasterSetup>(std::move(*setup));
            const core::Stopwatch resample;
            const std::size_t before = shGridCache_.resampled();
            out.shGrids = shGridCache_.get(*out.setup, progress);  // a newer state cancels it
            if (shGridCache_.resampled() != before) out.shResampleSeconds = resample.seconds();
        }
    } catch (const CancelledError&) {
        ++cancelled_;
        return false;
    } catch (const std::exception& e) {
        out.error = e.what();
    }
    ++completed_;
    const bool ok = out.error.empty();
    std::lock_guard lock(resultMutex_);
    result_ = std::move(out);
    return ok;
}

}  // namespace voxlight::viewer
