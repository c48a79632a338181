// SPDX-License-Identifier: MIT
#pragma once
// Progress reporting and cancellation for long algorithms (> ~1 s).
// Algorithms take a `const Progress&` and call `step(fraction)`, which throws CancelledError when
// the cancel flag is raised. The CLI's sink draws a bar on a TTY and prints plain lines otherwise;
// tests pass Progress::none().
#include <atomic>
#include <functional>
#include <string>

#include "core/error.h"

namespace voxlight::core {

class Progress {
  public:
    using Sink = std::function<void(const std::string& stage, double fraction)>;
    /// A sink that also shows what a stage says of itself as it goes (the path tracer's spp and
    /// error): `detail` changes from report to report while `stage` stays the same.
    using DetailedSink =
        std::function<void(const std::string& stage, double fraction, const std::string& detail)>;
    Progress() = default;
    Progress(Sink sink, const std::atomic<bool>* cancel) : cancel_(cancel) {
        if (sink)
            sink_ = [sink = std::move(sink)](const std::string& stage, double f,
                                             const std::string&) { sink(stage, f); };
    }
    static Progress detailed(DetailedSink sink, const std::atomic<bool>* cancel) {
        Progress p;
        p.sink_ = std::move(sink);
        p.cancel_ = cancel;
        return p;
    }
    static const Progress& none();

    /// Report `fraction` ∈ [0,1] of `stage` (with `detail`, for sinks that show it); throws
    /// CancelledError if cancellation was requested.
    void report(const std::string& stage, double fraction, const std::string& detail = {}) const {
        checkCancel();
        if (sink_) sink_(stage, fraction, detail);
    }
    void checkCancel() const {
        if (cancel_ && cancel_->load(std::memory_order_relaxed)) throw CancelledError();
    }
    bool cancelled() const { return cancel_ && cancel_->load(std::memory_order_relaxed); }
    /// Whether a cancel flag is attached at all (work that can only be stopped at a cost, e.g. in
    /// a child process, skips that cost when nobody can cancel).
    bool cancellable() const { return cancel_ != nullptr; }

  private:
    DetailedSink sink_;
    const std::atomic<bool>* cancel_ = nullptr;
};

inline const Progress& Progress::none() {
    static const Progress p;
    return p;
}

}  // namespace voxlight::core
