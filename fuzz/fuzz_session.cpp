// SPDX-License-Identifier: MIT
// Session JSON as `voxlight replay SESSION.json` reads it before rendering: session::loadSession
// (format, version, scene, keyframes, every keyframe's state validated as a scene), the scene at
// every keyframe, the interpolated scene halfway between each pair (camera slerp, planes, lights)
// and the frame times at 25 fps.
#include "fuzz_common.h"
#include "session/session.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace voxlight;
    const auto path = fuzz::writeParts(data, size, {"in.json"});
    fuzz::runLoader([&] {
        const session::Session s = session::loadSession(path);
        for (std::size_t k = 0; k < s.keyframes.size(); ++k) {
            (void)s.sceneAt(k).document.dump();
            if (k + 1 < s.keyframes.size())
                (void)s.sceneAtTime(0.5 * (s.keyframes[k].time + s.keyframes[k + 1].time));
        }
        if (s.endTime() - s.startTime() < 60.0) (void)session::frameTimes(s, 25.0);
    });
    return 0;
}
