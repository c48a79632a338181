// SPDX-License-Identifier: MIT
#pragma once
// The transfer-function editor (Dear ImGui): the volume's value histogram on a log scale, the
// extinction (σt, 1/mm) curve over it with its control points, a colour strip, presets, and the
// window (level/width). Points: drag to move (value between its neighbours, σt ≥ 0), double-click
// on empty canvas to add one (colour interpolated), select to edit its colour, value and σt, or
// delete it (at least two stay). Must be called inside an ImGui window.
#include <array>
#include <string>

#include "optics/transfer_function.h"
#include "viewer/volume_summary.h"

namespace voxlight::viewer {

struct TfEditorState {
    int selected = -1;  ///< point index shown in the fields below the canvas
    int dragging = -1;  ///< point under a drag
    float yMax = 0.f;   ///< extinction at the canvas top (kept fixed during a drag)
    int preset = 0;     ///< combo index: 0 = the scene's own TF
    std::string error;  ///< the last edit the TF refused (shown in red)
};

struct TfEditResult {
    bool changed = false;  ///< `tf` was replaced this frame
    bool active = false;   ///< a drag is in progress (render coarse)
};

/// Draws the editor. `sceneTf` is the scene's own TF (preset 0), `robust` the volume's robust
/// range for relative presets.
TfEditResult drawTfEditor(TfEditorState& state, optics::TransferFunction& tf,
                          const optics::TransferFunction& sceneTf, const Histogram& histogram,
                          const std::array<float, 2>& robust, float width);

}  // namespace voxlight::viewer
