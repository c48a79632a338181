// SPDX-License-Identifier: MIT
#include "viewer/display_loss.h"

#include <X11/Xlib.h>

#include <cstdio>
#include <cstdlib>
#include <utility>

namespace voxlight::viewer {

namespace {
// One guard at a time (one viewer window per process); Xlib's handler is process-wide.
std::function<int()> gOnLost;
XIOErrorHandler gPrevious = nullptr;

int onIoError(Display*) {
    int code = 1;  // Xlib's own
    try {
        if (gOnLost) code = gOnLost();
    } catch (...) {
    }
    std::fflush(stdout);
    std::fflush(stderr);
    // Not exit(): static destructors and atexit handlers would run with other threads still
    // rendering and the GL context half torn down. The files the function wrote are complete.
    std::_Exit(code);
}
}  // namespace

DisplayLossGuard::DisplayLossGuard(std::function<int()> onLost) {
    gOnLost = std::move(onLost);
    gPrevious = XSetIOErrorHandler(onIoError);
}

DisplayLossGuard::~DisplayLossGuard() {
    XSetIOErrorHandler(gPrevious);
    gOnLost = nullptr;
}

}  // namespace voxlight::viewer
