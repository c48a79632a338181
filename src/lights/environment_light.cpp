// SPDX-License-Identifier: MIT
#include "lights/environment_light.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

#include "core/color.h"
#include "core/error.h"
#include "sh/sh_basis.h"

namespace voxlight::lights {

namespace {
constexpr double kPi = std::numbers::pi;

// Angular-probe image → equirect of 2S × S (map frame of environment_light.h), bilinear.
std::vector<glm::vec3> probeToEquirect(const core::ImageRGBA& img, int& w, int& h) {
    const int s = img.width;
    h = s;
    w = 2 * s;
    std::vector<glm::vec3> out(std::size_t(w) * h);
    auto texel = [&](int x, int y) {
        x = std::clamp(x, 0, s - 1), y = std::clamp(y, 0, s - 1);
        const float* p = img.at(x, y);
        return glm::vec3(p[0], p[1], p[2]);
    };
    for (int r = 0; r < h; ++r)
        for (int c = 0; c < w; ++c) {
            const glm::dvec3 d =
                sh::sphericalToDirection(kPi * (r + 0.5) / h, kPi - 2.0 * kPi * (c + 0.5) / w);
            const double rho = std::acos(std::clamp(d.x, -1.0, 1.0)) / kPi;
            const double planar = std::hypot(d.y, d.z);
            const double u = planar > 0 ? rho * -d.y / planar : 0.0,
                         v = planar > 0 ? rho * d.z / planar : 0.0;
            const double px = (u + 1.0) * 0.5 * s - 0.5, py = (1.0 - v) * 0.5 * s - 0.5;
            const int x0 = int(std::floor(px)), y0 = int(std::floor(py));
            const float fx = float(px - x0), fy = float(py - y0);
            out[std::size_t(r) * w + c] =
                (1 - fy) * ((1 - fx) * texel(x0, y0) + fx * texel(x0 + 1, y0)) +
                fy * ((1 - fx) * texel(x0, y0 + 1) + fx * texel(x0 + 1, y0 + 1));
        }
    return out;
}
}  // namespace

std::string_view toString(EnvironmentLayout l) {
    return l == EnvironmentLayout::Equirect ? "equirect" : "probe";  // as scenes spell it
}

void EnvironmentLight::checkTexels(const core::ImageRGBA& image, const std::string& source,
                                   const glm::vec3& scale) {
    // Every pixel must be a finite, non-negative radiance. Lossy EXR compression (DWAA/DWAB) leaves
    // tiny negative values next to dark edges; those down to −kLossyNegativeTolerance × the map's
    // largest value are set to 0 and counted (clampedTexels()); anything more negative is an error.
    float maxValue = 0;
    for (std::size_t i = 0; i < image.pixels.size(); ++i)
        if (i % 4 != 3 && std::isfinite(image.pixels[i]))
            maxValue = std::max(maxValue, image.pixels[i]);
    const float negativeFloor = -kLossyNegativeTolerance * maxValue;
    for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x)
            for (int c = 0; c < 3; ++c) {
                const float v = image.at(x, y)[c];
                const double radiance = double(v) * double(scale[c]);
                const bool bad = !std::isfinite(v) || v < negativeFloor;
                if (!bad && !(radiance > kMaxRadiance)) continue;
                std::ostringstream os;
                os << "pixel (" << x << ", " << y << ") channel "
                   << "RGB"[c] << " is " << v;
                if (bad)
                    throw InputError(
                        source, "pixels",
                        os.str() + (std::isfinite(v) ? " (negative radiance)" : " (not finite)"),
                        "repair the map (e.g. clamp or inpaint the bad pixels) and "
                        "re-export it");
                os << ", radiance " << radiance
                   << " under the light's colour × intensity, above the " << kMaxRadiance
                   << " voxlight carries";
                // The map alone past the limit names the map; a scale that pushed it, the light.
                if (v > kMaxRadiance)
                    throw InputError(source, "pixels", os.str(), "scale the map's values down");
                throw InputError("light", "intensity", "with " + source + "'s " + os.str(),
                                 "lower intensity or color");
            }
}

EnvironmentLight::EnvironmentLight(const core::ImageRGBA& image, const EnvironmentOptions& options,
                                   std::string source)
    : source_(std::move(source)) {
    if (image.width <= 0 || image.height <= 0 ||
        image.pixels.size() != std::size_t(4) * image.width * image.height)
        throw InputError(source_, "size",
                         "environment map is empty (" + std::to_string(image.width) + "×" +
                             std::to_string(image.height) + ")",
                         "give a non-empty HDR image");
    checkTexels(image, source_);
    if (options.layout == EnvironmentLayout::Equirect) {
        if (image.width != 2 * image.height)
            throw InputError(
                source_, "layout",
                "an equirectangular map needs width = 2·height, got " +
                    std::to_string(image.width) + "×" + std::to_string(image.height),
                "resample it to 2:1, or use layout \"probe\" for a square light probe");
        w_ = image.width, h_ = image.height;
        rgb_.resize(std::size_t(w_) * h_);
        for (std::size_t p = 0; p < rgb_.size(); ++p)
            rgb_[p] = {image.pixels[4 * p], image.pixels[4 * p + 1], image.pixels[4 * p + 2]};
    } else {
        if (image.width != image.height)
            throw InputError(source_, "layout",
                             "an angular light probe must be square, got " +
                                 std::to_string(image.width) + "×" + std::to_string(image.height),
                             "crop the probe to its circle, or use layout \"equirect\"");
        rgb_ = probeToEquirect(image, w_, h_);
    }
    for (auto& t : rgb_)
        for (int c = 0; c < 3; ++c)
            if (t[c] < 0) t[c] = 0.0f, ++clamped_;
    buildSampling();
    shMap_ = sh::projectEquirect(kShCacheBand, layout(), rgb_);
    setScale(options.scale);
    setRotation(options.rotation);
}

sh::EquirectLayout EnvironmentLight::layout() const { return {w_, h_, kPi, -2.0 * kPi / w_}; }

void EnvironmentLight::setRotation(const glm::dmat3& worldFromMap) {
    sh::checkRotation(worldFromMap, source_.c_str(), "rotation");
    // Stored orthonormalised: lookup() and pdf() use the transpose as the inverse.
    rotation_ = sh::orthonormalizeRotation(worldFromMap);
    // The SH rotation is built once per rotation change (the cache) and applied to the stored
    // projection.
    shWorld_.resize(shMap_.size());
    sh::ShRotation(rotation_, kShCacheBand).applyRgb(shMap_, shWorld_);
}

void EnvironmentLight::setScale(float scale) {
    if (!std::isfinite(scale) || scale < 0)
        throw InputError(source_, "scale",
                         "intensity scale must be finite and ≥ 0, got " + std::to_string(scale),
                         "use e.g. 1.0");
    scale_ = scale;
}

void EnvironmentLight::buildSampling() {
    rowCdf_.assign(h_ + 1, 0.0);
    colCdf_.assign(std::size_t(h_) * (w_ + 1), 0.0);
    const double dphi = 2.0 * kPi / w_;
    for (int r = 0; r < h_; ++r) {
        const double omega = dphi * (std::cos(kPi * r / h_) - std::cos(kPi * (r + 1) / h_));
        double* cdf = &colCdf_[std::size_t(r) * (w_ + 1)];
        for (int c = 0; c < w_; ++c)
            cdf[c + 1] = cdf[c] + core::luminance(rgb_[std::size_t(r) * w_ + c]) * omega;
        rowCdf_[r + 1] = rowCdf_[r] + cdf[w_];
    }
    lumIntegral_ = rowCdf_[h_];
}

int EnvironmentLight::pixelOf(const glm::dvec3& d) const {
    const double theta = std::acos(std::clamp(d.z, -1.0, 1.0));
    const int r = std::clamp(int(theta / kPi * h_), 0, h_ - 1);
    const double phi = std::atan2(d.y, d.x);
    int c = int(std::floor((kPi - phi) / (2.0 * kPi) * w_));
    c = ((c % w_) + w_) % w_;
    return r * w_ + c;
}

glm::vec3 EnvironmentLight::lookup(const glm::vec3& worldDir) const {
    const glm::dvec3 d = glm::transpose(rotation_) * glm::dvec3(worldDir);
    return scale_ * rgb_[pixelOf(d)];
}

LightSample EnvironmentLight::sample(const glm::dvec3&, const glm::vec2& u) const {
    LightSample s;
    if (!(lumIntegral_ > 0)) return s;
    // Row by the marginal CDF, column by the row's conditional CDF; the remapped uniforms place the
    // point.
    const double tx = std::min(double(u.x), 1.0 - 1e-12) * lumIntegral_;
    const int r = std::clamp(
        int(std::upper_bound(rowCdf_.begin(), rowCdf_.end(), tx) - rowCdf_.begin()) - 1, 0, h_ - 1);
    const double rowMass = rowCdf_[r + 1] - rowCdf_[r];
    const double ux = rowMass > 0 ? std::clamp((tx - rowCdf_[r]) / rowMass, 0.0, 1.0) : 0.5;
    const double* cdf = &colCdf_[std::size_t(r) * (w_ + 1)];
    const double ty = std::min(double(u.y), 1.0 - 1e-12) * cdf[w_];
    const int c = std::clamp(int(std::upper_bound(cdf, cdf + w_ + 1, ty) - cdf) - 1, 0, w_ - 1);
    const double colMass = cdf[c + 1] - cdf[c];
    const double uy = colMass > 0 ? std::clamp((ty - cdf[c]) / colMass, 0.0, 1.0) : 0.5;
    // Uniform in (cos θ, φ) within the pixel: uniform in solid angle.
    const double z0 = std::cos(kPi * r / h_), z1 = std::cos(kPi * (r + 1) / h_);
    const double z = z0 + ux * (z1 - z0);
    const double phi = kPi - 2.0 * kPi * (c + uy) / w_;
    const double st = std::sqrt(std::max(0.0, 1.0 - z * z));
    const glm::dvec3 mapDir(st * std::cos(phi), st * std::sin(phi), z);
    const glm::vec3 texel = rgb_[std::size_t(r) * w_ + c];
    s.wi = glm::vec3(rotation_ * mapDir);
    s.value = scale_ * texel;
    s.pdf = float(core::luminance(texel) / lumIntegral_);
    return s;
}

float EnvironmentLight::pdf(const glm::dvec3&, const glm::vec3& wi) const {
    if (!(lumIntegral_ > 0)) return 0.0f;
    const glm::dvec3 d = glm::transpose(rotation_) * glm::normalize(glm::dvec3(wi));
    return float(core::luminance(rgb_[pixelOf(d)]) / lumIntegral_);
}

void EnvironmentLight::writeSh(const glm::dvec3&, int maxBand, std::span<glm::vec3> out) const {
    if (maxBand <= kShCacheBand) {
        std::copy_n(shWorld_.begin(), out.size(), out.begin());
    } else {
        const auto mapFrame = sh::projectEquirect(maxBand, layout(), rgb_);
        sh::ShRotation(rotation_, maxBand).applyRgb(mapFrame, out);
    }
    for (auto& v : out) v *= scale_;
}

void EnvironmentLight::writeDsf(const glm::dvec3&, const sh::Dsf& dsf,
                                std::span<glm::vec3> out) const {
    // Look up (or make) the projection for this DSF size and the current rotation; the lock is
    // held while projecting so concurrent first calls do the work once.
    const std::lock_guard lock(dsfCache_->mutex);
    auto& entries = dsfCache_->entries;
    auto it = std::find_if(entries.begin(), entries.end(),
                           [&](const DsfCache::Entry& e) { return e.size == dsf.size(); });
    if (it == entries.end()) it = entries.insert(entries.end(), {dsf.size(), {}, {}});
    if (it->coefficients.empty() || it->rotation != rotation_) {
        it->coefficients = dsf.projectEquirect(layout(), rgb_, glm::transpose(rotation_));
        it->rotation = rotation_;
        ++dsfCache_->projections;
    }
    for (std::size_t k = 0; k < out.size(); ++k) out[k] = scale_ * it->coefficients[k];
}

std::size_t EnvironmentLight::dsfProjectionCount() const {
    const std::lock_guard lock(dsfCache_->mutex);
    return dsfCache_->projections;
}

std::string EnvironmentLight::toString() const {
    std::ostringstream os;
    os << "EnvironmentLight{" << source_ << ", " << w_ << "×" << h_ << " equirect, scale=" << scale_
       << "}";
    return os.str();
}

}  // namespace voxlight::lights
