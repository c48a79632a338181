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
    Progress() = default;
    Progress(Sink sink, const std::atomic<bool>* cancel)
        : sink_(std::move(sink)), cancel_(cancel) {}
    static const Progress& none();

    /// Report `fraction` ∈ [0,1] of `stage`; throws CancelledError if cancellation was requested.
    void report(const std::string& stage, double fraction) const {
        checkCancel();
        if (sink_) sink_(stage, fraction);
    }
    void checkCancel() const {
        if (cancel_ && cancel_->load(std::memory_order_relaxed)) throw CancelledError();
    }
    bool cancelled() const { return cancel_ && cancel_->load(std::memory_order_relaxed); }
    /// Whether a cancel flag is attached at all (work that can only be stopped at a cost, e.g. in
    /// a child process, skips that cost when nobody can cancel).
    bool cancellable() const { return cancel_ != nullptr; }

  private:
    Sink sink_;
    const std::atomic<bool>* cancel_ = nullptr;
};

inline const Progress& Progress::none() {
    static const Progress p;
    return p;
}

}  // namespace voxlight::core
