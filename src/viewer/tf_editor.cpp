// SPDX-License-Identifier: MIT
#include "viewer/tf_editor.h"

#include <imgui.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/error.h"
#include "optics/presets.h"

namespace voxlight::viewer {

namespace {
/// Canvas height in pixels and the pick radius of a control point.
constexpr float kCanvasHeight = 150.f, kPickRadius = 7.f, kStripHeight = 12.f;

ImU32 colorOf(const glm::vec3& c, float alpha = 1.f) {
    return ImGui::ColorConvertFloat4ToU32(ImVec4(c.r, c.g, c.b, alpha));
}

/// Replaces `tf` by one with `points`, or records why the TF refuses them.
bool rebuild(TfEditorState& state, optics::TransferFunction& tf,
             std::vector<optics::TfPoint> points) {
    try {
        tf = optics::TransferFunction(std::move(points), tf.window(), tf.name());
        state.error.clear();
        return true;
    } catch (const InputError& e) {
        state.error = e.what();
        return false;
    }
}
}  // namespace

TfEditResult drawTfEditor(TfEditorState& state, optics::TransferFunction& tf,
                          const optics::TransferFunction& sceneTf, const Histogram& histogram,
                          const std::array<float, 2>& robust, float width) {
    TfEditResult result;
    // Presets: the scene's own TF, then the catalogue.
    {
        const auto& catalog = optics::presetCatalog();
        std::vector<const char*> names{"scene's transfer function"};
        for (const auto& p : catalog) names.push_back(p.name.c_str());
        int choice = state.preset;
        if (ImGui::Combo("preset", &choice, names.data(), int(names.size()))) {
            try {
                tf = choice == 0 ? sceneTf : optics::makePreset(catalog[choice - 1].name, robust);
                state.preset = choice;
                state.selected = state.dragging = -1;
                state.yMax = 0.f;
                state.error.clear();
                result.changed = true;
            } catch (const InputError& e) {
                state.error = e.what();
            }
        }
    }
    // The canvas: value axis = the volume's range, σt axis = 0 … yMax.
    const double lo = histogram.lo, hi = histogram.hi;
    if (state.dragging < 0 || state.yMax <= 0.f)
        state.yMax = std::max(tf.maxExtinction() * 1.15f, 1e-3f);
    const ImVec2 origin = ImGui::GetCursorScreenPos();
    const ImVec2 size(width, kCanvasHeight);
    auto xOf = [&](double v) { return origin.x + float((v - lo) / (hi - lo)) * size.x; };
    auto yOf = [&](float e) {
        return origin.y + size.y - std::clamp(e / state.yMax, 0.f, 1.f) * size.y;
    };
    auto valueAt = [&](float x) { return lo + double(x - origin.x) / size.x * (hi - lo); };
    auto extinctionAt = [&](float y) {
        return std::max(0.f, (origin.y + size.y - y) / size.y * state.yMax);
    };
    ImDrawList* dl = ImGui::GetWindowDrawList();
    dl->AddRectFilled(origin, ImVec2(origin.x + size.x, origin.y + size.y),
                      IM_COL32(20, 20, 24, 255));
    // Histogram, log scale.
    const std::vector<float> bins = histogram.logNormalized();
    const float binW = size.x / float(std::max<std::size_t>(bins.size(), 1));
    for (std::size_t i = 0; i < bins.size(); ++i) {
        const float x0 = origin.x + binW * float(i);
        dl->AddRectFilled(ImVec2(x0, origin.y + size.y * (1.f - bins[i])),
                          ImVec2(x0 + binW, origin.y + size.y), IM_COL32(90, 90, 100, 255));
    }
    // The extinction curve and its control points.
    const auto& pts = tf.points();
    for (std::size_t i = 0; i + 1 < pts.size(); ++i)
        dl->AddLine(ImVec2(xOf(pts[i].value), yOf(pts[i].extinction)),
                    ImVec2(xOf(pts[i + 1].value), yOf(pts[i + 1].extinction)),
                    IM_COL32(255, 220, 120, 255), 2.f);
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const ImVec2 c(std::clamp(xOf(pts[i].value), origin.x, origin.x + size.x),
                       yOf(pts[i].extinction));
        dl->AddCircleFilled(c, 5.f, colorOf(pts[i].color));
        dl->AddCircle(
            c, 6.f,
            int(i) == state.selected ? IM_COL32(255, 255, 255, 255) : IM_COL32(0, 0, 0, 255), 0,
            int(i) == state.selected ? 2.5f : 1.f);
    }
    // Mouse: pick, drag, add.
    ImGui::InvisibleButton("tf_canvas", size);
    const ImVec2 mouse = ImGui::GetIO().MousePos;
    if (ImGui::IsItemActivated()) {
        int best = -1;
        float bestD = kPickRadius;
        for (std::size_t i = 0; i < pts.size(); ++i) {
            const float d =
                std::hypot(mouse.x - xOf(pts[i].value), mouse.y - yOf(pts[i].extinction));
            if (d <= bestD) best = int(i), bestD = d;
        }
        state.dragging = best;
        if (best >= 0) state.selected = best;
    }
    if (ImGui::IsItemHovered() && ImGui::IsMouseDoubleClicked(ImGuiMouseButton_Left) &&
        state.dragging < 0) {
        // Add a point here, coloured as the TF is at this value.
        const double v = valueAt(mouse.x);
        std::vector<optics::TfPoint> p = pts;
        const optics::TfSample s = tf.eval(float(v));
        optics::TfPoint q = p.front();  // keeps the surface channels' presence (phase g)
        q.value = float(v);
        q.color = s.albedo;
        q.emission = s.emission;
        q.extinction = extinctionAt(mouse.y);
        auto at = std::lower_bound(p.begin(), p.end(), q.value,
                                   [](const optics::TfPoint& a, float x) { return a.value < x; });
        const int index = int(at - p.begin());
        p.insert(at, q);
        if (rebuild(state, tf, std::move(p))) {
            state.selected = index;
            result.changed = true;
        }
    }
    if (ImGui::IsItemActive() && state.dragging >= 0 && std::size_t(state.dragging) < pts.size() &&
        (ImGui::GetIO().MouseDelta.x != 0.f || ImGui::GetIO().MouseDelta.y != 0.f)) {
        std::vector<optics::TfPoint> p = pts;
        const std::size_t i = std::size_t(state.dragging);
        // Between its neighbours (values stay strictly increasing).
        const double gap = (hi - lo) * 1e-3;
        double v = valueAt(mouse.x);
        if (i > 0) v = std::max(v, double(p[i - 1].value) + gap);
        if (i + 1 < p.size()) v = std::min(v, double(p[i + 1].value) - gap);
        p[i].value = float(v);
        p[i].extinction = extinctionAt(mouse.y);
        result.changed = rebuild(state, tf, std::move(p)) || result.changed;
    }
    if (!ImGui::IsItemActive()) state.dragging = -1;
    result.active = state.dragging >= 0;
    if (ImGui::IsItemHovered()) {
        const double v = valueAt(mouse.x);
        const int b = std::clamp(int((v - lo) / (hi - lo) * double(histogram.counts.size())), 0,
                                 int(histogram.counts.size()) - 1);
        ImGui::SetTooltip("value %.1f  voxels %llu  sigma_t %.4f /mm", v,
                          (unsigned long long)histogram.counts[std::size_t(b)],
                          double(tf.eval(float(v)).extinction));
    }
    // Colour strip: the TF's colour, brightness by opacity over 1 mm.
    const ImVec2 strip = ImGui::GetCursorScreenPos();
    for (int x = 0; x < int(size.x); ++x) {
        const optics::TfSample s = tf.eval(float(valueAt(origin.x + float(x) + 0.5f)));
        const float alpha = 1.f - std::exp(-s.extinction);
        dl->AddRectFilled(ImVec2(strip.x + float(x), strip.y),
                          ImVec2(strip.x + float(x) + 1.f, strip.y + kStripHeight),
                          colorOf(s.albedo, 0.25f + 0.75f * alpha));
    }
    ImGui::Dummy(ImVec2(size.x, kStripHeight));
    ImGui::Text("%.0f", lo);
    ImGui::SameLine(size.x - 40.f);
    ImGui::Text("%.0f", hi);
    ImGui::TextDisabled("histogram: log(1 + voxels); curve: sigma_t, top = %.3f /mm", state.yMax);
    // The selected point.
    if (state.selected >= 0 && std::size_t(state.selected) < tf.points().size()) {
        std::vector<optics::TfPoint> p = tf.points();
        optics::TfPoint& q = p[std::size_t(state.selected)];
        bool edit = false;
        ImGui::Text("point %d of %zu", state.selected + 1, p.size());
        edit |= ImGui::ColorEdit3("colour", &q.color.r);
        edit |= ImGui::DragFloat("value", &q.value, float(hi - lo) / 1000.f);
        edit |= ImGui::DragFloat("sigma_t (1/mm)", &q.extinction, state.yMax / 500.f, 0.f, 1e6f,
                                 "%.4f");
        if (edit) result.changed = rebuild(state, tf, p) || result.changed;
        if (p.size() > 2 && ImGui::Button("delete point")) {
            p.erase(p.begin() + state.selected);
            if (rebuild(state, tf, std::move(p))) {
                state.selected = -1;
                result.changed = true;
            }
        }
    } else {
        ImGui::TextDisabled("click a point to edit it; double-click to add one");
    }
    // Window / level (also right-drag on the image).
    {
        optics::Window w = tf.window();
        bool edit = ImGui::DragFloat("level", &w.level, std::max(w.width, 1.f) / 200.f);
        edit |= ImGui::DragFloat("width", &w.width, std::max(w.width, 1.f) / 200.f, 1e-3f, 1e7f);
        if (edit && w.width > 0.f) {
            tf = tf.withWindow(w);
            result.changed = true;
        }
    }
    if (!state.error.empty())
        ImGui::TextColored(ImVec4(1, 0.4f, 0.4f, 1), "%s", state.error.c_str());
    return result;
}

}  // namespace voxlight::viewer
