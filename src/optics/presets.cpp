// SPDX-License-Identifier: MIT
#include "optics/presets.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace voxlight::optics {

const std::vector<PresetInfo>& presetCatalog() {
    static const std::vector<PresetInfo> c = {
        {"ct-bone", "CT skeleton: ivory bone, soft tissue transparent", false},
        {"ct-angio", "CT angiography: contrast vessels red, bone ivory, metal silver", false},
        {"ct-soft-tissue", "CT soft tissue: skin/fat faint, muscle and organs pink-red", false},
        {"ct-lung", "CT lung: translucent parenchyma cast", false},
        {"mr-t1-brain", "MR T1 head/brain surface (relative to the volume's range)", true},
        {"generic", "grey ramp over the volume's robust range (relative)", true},
        {"phantom-step", "sigma_t 0.02/mm above 0.5 (exact-optics sphere/slab phantoms)", false},
    };
    return c;
}

std::array<float, 2> robustRange(const core::Volume& volume, float loFraction, float hiFraction) {
    constexpr std::uint64_t kTargetSamples = 1u << 20;
    const std::uint64_t n = volume.voxelCount();
    // An odd stride avoids aliasing with the x/y extents (which are usually even).
    const std::uint64_t stride = std::max<std::uint64_t>(1, (n / kTargetSamples) | 1);
    std::vector<float> values;
    values.reserve(std::size_t(n / stride + 1));
    volume.visit([&](const auto& v) {
        for (std::uint64_t i = 0; i < n; i += stride) {
            const float x = v.slope * float(v.data[i]) + v.intercept;
            if (std::isfinite(x)) values.push_back(x);
        }
    });
    if (values.empty()) return {0.f, 1.f};
    auto quantile = [&](float q) {
        const std::size_t k = std::min(values.size() - 1, std::size_t(q * (values.size() - 1)));
        std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(k), values.end());
        return values[k];
    };
    float lo = quantile(loFraction), hi = quantile(hiFraction);
    // A relative preset's points, a fraction of the range apart (≥ 0.1), need float steps between them:
    // a range of a few steps (a constant volume; values a float step apart, which at 1e8 are 8
    // apart) collapses them — a constant volume at 1e8 was refused for a window of width 0 (lo + 1
    // rounds to lo), values one step apart rendered nothing. Such a range becomes
    // kMinRangeFloatSteps steps of its magnitude from lo; a constant volume's at least 1 (its
    // range since the first release).
    constexpr float kMinRangeFloatSteps = 64.f;
    const float mag = std::max(std::abs(lo), std::abs(hi));
    const float span = kMinRangeFloatSteps * (std::nextafter(mag, HUGE_VALF) - mag);
    if (!(hi > lo))
        hi = lo + (std::isfinite(span) ? std::max(1.f, span) : 1.f);
    else if (hi - lo < span && std::isfinite(lo + span))
        hi = lo + span;
    return {lo, hi};
}

namespace {
TfPoint pt(float value, float sigma, glm::vec3 color) { return {value, color, sigma, {0, 0, 0}}; }
/// The point with the BRDF channels (pathtrace hybrid scattering): a grey specular F0 and a
/// roughness. Dielectric tissue reflects F0 ≈ 0.02–0.05 at normal incidence (water 0.02);
/// wet, smooth contrast-filled lumen walls read glossier than porous bone.
TfPoint surf(TfPoint p, float specular, float roughness) {
    p.specular = glm::vec3(specular);
    p.roughness = roughness;
    return p;
}
/// The same surface channels on every point.
std::vector<TfPoint> allSurf(std::vector<TfPoint> pts, float specular, float roughness) {
    for (auto& p : pts) p = surf(p, specular, roughness);
    return pts;
}

TransferFunction absolutePreset(const std::string& name) {
    const glm::vec3 ivory(0.93f, 0.85f, 0.70f), bright(0.97f, 0.94f, 0.86f);
    if (name == "ct-bone")
        // Bone: a low, matte specular (porous, dry surface).
        return TransferFunction(
            allSurf({pt(-1024, 0, ivory), pt(140, 0, {0.70f, 0.42f, 0.30f}),
                     pt(250, 0.25f, {0.85f, 0.65f, 0.48f}), pt(450, 1.2f, ivory),
                     pt(1000, 3.f, bright), pt(3071, 3.f, bright)},
                    0.04f, 0.7f),
            {500, 2000}, name);
    if (name == "ct-angio") {
        const glm::vec3 red(0.80f, 0.10f, 0.07f), metal(0.80f, 0.84f, 0.92f);
        // Lumen red up to ≈ 330 HU, bone ivory from ≈ 430 HU (cortex at 3 mm voxels is often
        // only 400–700 HU), metal silver above 1500 HU. The red band is only moderately dense
        // (σt ≤ 0.3/mm): a contrast-filled vessel is many mm thick and still turns opaque, while
        // the 1–2 mm partial-volume rim on every bone surface stays translucent, so bone reads
        // ivory rather than red.
        // Surfaces: contrast lumen glossy (F0 0.08, roughness 0.3), bone matte as in ct-bone,
        // metal a bright, fairly smooth specular.
        return TransferFunction(
            {surf(pt(-1024, 0, red), 0.08f, 0.3f), surf(pt(110, 0, red), 0.08f, 0.3f),
             surf(pt(200, 0.12f, red), 0.08f, 0.3f),
             surf(pt(330, 0.3f, {0.85f, 0.24f, 0.15f}), 0.08f, 0.3f),
             surf(pt(430, 1.2f, ivory), 0.04f, 0.7f), surf(pt(1150, 3.f, bright), 0.04f, 0.7f),
             surf(pt(1500, 6.f, metal), 0.9f, 0.25f), surf(pt(3071, 6.f, metal), 0.9f, 0.25f)},
            {400, 1400}, name);
    }
    if (name == "ct-soft-tissue") {
        const glm::vec3 fat(0.90f, 0.78f, 0.45f), muscle(0.78f, 0.30f, 0.24f);
        // Soft tissue scatters mostly by the phase function anyway (its σt is small, so the
        // opacity factor of P_brdf is); where it does take the BRDF, a faint, rough specular.
        return TransferFunction(
            allSurf({pt(-1024, 0, fat), pt(-160, 0, fat), pt(-90, 0.004f, fat),
                     pt(-30, 0.001f, fat), pt(20, 0.02f, muscle),
                     pt(80, 0.06f, {0.86f, 0.42f, 0.36f}), pt(220, 0.15f, {0.92f, 0.82f, 0.72f}),
                     pt(600, 1.f, bright), pt(3071, 1.f, bright)},
                    0.03f, 0.8f),
            {40, 400}, name);
    }
    if (name == "ct-lung") {
        const glm::vec3 pink(0.92f, 0.62f, 0.58f);
        // Parenchyma (≈ −850 HU) only: starts above −900 HU so that air outside the body (−1000 ±
        // noise, up to ≈ −930 HU in the shared abdomen CT) stays clear, and ends at −550 HU because
        // every air/tissue boundary passes through this range by partial volume (a shell whose
        // opacity grows with ∫σt over the range).
        // A translucent cast: faint, rough specular (mostly phase: σt ≤ 0.04/mm).
        return TransferFunction(
            allSurf({pt(-1024, 0, pink), pt(-900, 0, pink), pt(-850, 0.02f, pink),
                     pt(-700, 0.04f, {0.95f, 0.72f, 0.68f}), pt(-550, 0, pink), pt(3071, 0, pink)},
                    0.02f, 0.9f),
            {-600, 1500}, name);
    }
    if (name == "phantom-step")
        return TransferFunction(
            {pt(0.f, 0, {0.9f, 0.9f, 0.9f}), pt(0.499f, 0, {0.9f, 0.9f, 0.9f}),
             pt(0.501f, 0.02f, {0.9f, 0.9f, 0.9f}), pt(1.f, 0.02f, {0.9f, 0.9f, 0.9f})},
            {0.5f, 1.f}, name);
    return {};
}

TransferFunction relativePreset(const std::string& name) {
    if (name == "mr-t1-brain")
        // Skin/brain surface: a low, moderately rough specular (moist tissue).
        return TransferFunction(
            allSurf(
                {pt(0, 0, {0.55f, 0.40f, 0.35f}), pt(0.14f, 0, {0.60f, 0.45f, 0.40f}),
                 pt(0.26f, 0.06f, {0.78f, 0.56f, 0.47f}), pt(0.45f, 0.35f, {0.84f, 0.68f, 0.60f}),
                 pt(0.75f, 0.7f, {0.90f, 0.82f, 0.76f}), pt(1, 0.8f, {0.98f, 0.96f, 0.92f})},
                0.04f, 0.5f),
            {0.5f, 1.f}, name);
    if (name == "generic")
        return TransferFunction(
            allSurf({pt(0, 0, glm::vec3(0.85f)), pt(0.25f, 0, glm::vec3(0.85f)),
                     pt(0.5f, 0.5f, glm::vec3(0.9f)), pt(1, 1.f, glm::vec3(0.95f))},
                    0.04f, 0.5f),
            {0.5f, 1.f}, name);
    return {};
}

}  // namespace

std::string presetList() {
    std::vector<std::string> names;
    for (const auto& p : presetCatalog()) names.push_back(p.name);
    return joinNames(names);
}

const PresetInfo* findPreset(const std::string& name) {
    for (const auto& p : presetCatalog())
        if (p.name == name) return &p;
    return nullptr;
}

TransferFunction makePreset(const std::string& name, const std::array<float, 2>& robust) {
    const PresetInfo* it = findPreset(name);
    if (!it)
        throw InputError("presets", "name", "'" + name + "' is not a preset",
                         "choose one of: " + presetList());
    if (!it->relative) return absolutePreset(name);
    const float lo = robust[0], hi = robust[1] > robust[0] ? robust[1] : robust[0] + 1.f;
    return relativePreset(name).withWindow({0.5f * (lo + hi), hi - lo});
}

bool looksLikeHounsfield(const core::Volume& volume) {
    if (volume.modality == core::Modality::CT && volume.mapping.unit == "HU") return true;
    if (volume.modality != core::Modality::Unknown) return false;
    // Air (−1000 HU) or the scanners' outside-the-field padding (−1024, −2048, −3024) fills at
    // least the darkest percent of a CT in HU, and its bright end is soft tissue to bone; MR
    // and unsigned/windowed CT hold nothing below zero.
    const auto [lo, hi] = robustRange(volume, 0.01f, 0.995f);
    return lo >= kHounsfieldAirMin && lo <= kHounsfieldAirMax && hi >= 0.f && hi <= 4000.f;
}

std::string defaultPresetName(const core::Volume& volume) {
    if (looksLikeHounsfield(volume)) return "ct-bone";
    if (volume.modality == core::Modality::MR) return "mr-t1-brain";
    return "generic";
}

}  // namespace voxlight::optics
