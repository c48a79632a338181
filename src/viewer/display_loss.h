// SPDX-License-Identifier: MIT
// What the viewer does when its display goes away (the X server quits, or the connection to it
// drops): Xlib's default ends the process at once with exit code 1 and its own "XIO: fatal
// IO error" line, and a session being recorded was lost with it. While a DisplayLossGuard lives,
// Xlib calls its function instead — on the thread whose X call failed, which is the UI thread: no
// other thread of the viewer talks to X — and the process then ends with the exit code the
// function returns. The function must not touch the display (it is gone) and must not throw; it
// may write files. Kept in its own file so that Xlib's macros (None, Bool, Status, …) stay out of
// the viewer's code.
#pragma once

#include <functional>

namespace voxlight::viewer {

class DisplayLossGuard {
  public:
    explicit DisplayLossGuard(std::function<int()> onLost);
    ~DisplayLossGuard();  ///< puts back the handler that was set before
    DisplayLossGuard(const DisplayLossGuard&) = delete;
    DisplayLossGuard& operator=(const DisplayLossGuard&) = delete;
};

}  // namespace voxlight::viewer
