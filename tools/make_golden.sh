#!/bin/sh
# SPDX-License-Identifier: MIT
# Regenerates the renderer's golden images (tests/render/golden/*.png, 128x128) from the current
# build. Look at every image before committing them: they become the reference.
#   tools/make_golden.sh [BUILD_DIR]        (default: build)
set -eu
root=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$root/build}
ninja -C "$build" test_render
VOXLIGHT_UPDATE_GOLDEN=1 VOXLIGHT_SOURCE_DIR="$root" "$build/tests/render/test_render" --gtest_filter='Golden.*'
ls -l "$root/tests/render/golden"
