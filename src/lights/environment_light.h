// SPDX-License-Identifier: MIT
#pragma once
// Environment (image-based) light: an HDR image of the radiance arriving from infinity (Kronander
// §3.4, Zhang §5, Kroes §3). Conventions and units: lights/light.h.
//
// Map frame (before rotation): +z = up, the image centre looks along +x, image right is −y (not
// mirrored when seen from inside). World direction ω_world = rotation · ω_map; with the identity
// the map's up is world +z (patient superior in LPS).
// * Equirectangular (latitude–longitude, width = 2·height): pixel (c, r), row 0 at the top, covers
//   θ ∈ [π r/H, π(r+1)/H] from +z and φ ∈ [π − 2π(c+1)/W, π − 2π c/W] (φ from +x toward +y):
//   EquirectLayout {W, H, φ0 = π, Δφ = −2π/W} of sh_projection.h.
// * Angular light probe (Debevec's angular map, square): for image coordinates (u, v) ∈ [−1, 1]²
//   (u right, v up, ρ = √(u²+v²) ≤ 1) the direction is at angle πρ from the centre direction
//   (+x), toward (u·right + v·up)/ρ. The probe is resampled (bilinear) to an equirect of 2S × S at
//   load time; everything below works on that grid.
// Radiance is piecewise constant per pixel (nearest lookup), so sampling pdf and radiance agree
// exactly. Importance sampling: a pixel is drawn with probability ∝ luminance × solid angle, then a
// uniform point in (φ, cos θ) inside it, so pdf(ω) = luminance(pixel(ω)) / Σ_p luminance_p Ω_p
// exactly. SH: projected once (band ≤ 8, exact pixel solid angles) in the map frame, rotated with
// the cached ShRotation when the rotation changes. DSF: the energy-conserving basis projection at
// the rotated DSF directions (sh::Dsf::projectEquirect; Zhang §5.1 rotates by re-sampling, which
// this is with the basis as the prefilter) — chosen over Gaussian point sampling because a small
// sun keeps its power (tested on city.hdr). The projection (~150 ms for 1024×512) does not depend
// on the point x: it runs once per (DSF direction count, rotation) and is cached; thread-safe. Bad
// input → InputError: missing/corrupt file, 8-bit (non-HDR) image, wrong aspect ratio, zero size,
// any NaN/Inf pixel, or a negative one beyond lossy-compression noise (with its coordinates).
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>

#include "core/image.h"
#include "lights/light.h"
#include "sh/sh_projection.h"
#include "sh/sh_rotation.h"

namespace voxlight::lights {

enum class EnvironmentLayout { Equirect, AngularProbe };
std::string_view toString(EnvironmentLayout l);

struct EnvironmentOptions {
    EnvironmentLayout layout = EnvironmentLayout::Equirect;
    glm::dmat3 rotation{1.0};  ///< world-from-map, a proper rotation (see setRotation)
    float scale = 1.0f;        ///< radiance multiplier, ≥ 0
};

class EnvironmentLight final : public Light {
  public:
    /// From an HDR image in memory (linear radiance; io::readHdrImage reads .hdr/.exr files);
    /// `source` names it in error messages.
    EnvironmentLight(const core::ImageRGBA& image, const EnvironmentOptions& options,
                     std::string source = "image");

    /// InputError unless a rotation within sh::checkRotation's tolerance; stored orthonormalised
    /// (rotation() returns the nearest exact rotation).
    void setRotation(const glm::dmat3& worldFromMap);
    void setScale(float scale);
    const glm::dmat3& rotation() const { return rotation_; }
    float scale() const { return scale_; }
    /// The equirect grid (map frame, unscaled) everything works on.
    int width() const { return w_; }
    int height() const { return h_; }
    const std::vector<glm::vec3>& texels() const { return rgb_; }
    sh::EquirectLayout layout() const;

    /// Texel channels with tiny negative values (lossy compression) that were set to 0 at load.
    std::size_t clampedTexels() const { return clamped_; }
    /// Negative texels down to −this × the map's maximum are compression noise (set to 0); below:
    /// InputError.
    static constexpr float kLossyNegativeTolerance = 1e-4f;
    /// Largest texel radiance (after the light's colour × intensity). Measured on a 64² sphere:
    /// one texel of 1e20 still rendered, 1e22 gave `sh-local` a black image (3e38 everywhere:
    /// black `gradient`/`pvrt`, Inf pixels in the path tracer) — float overflow somewhere in the
    /// chain, not traced to one operation. 1e15 keeps five orders of margin (all six methods
    /// render a uniform 1e15 map finite) and is ≈ 10⁶ × the sun's luminance in cd/m².
    static constexpr double kMaxRadiance = 1e15;
    /// InputError naming `source` and the first texel that is not finite or more negative than
    /// lossy compression leaves, or whose radiance × scale[channel] is above kMaxRadiance (that
    /// texel alone above it names `source`; else the scale is to blame: source "light", field
    /// "intensity"). The constructor's own check, for callers that scale a map before handing it
    /// over (the scene's colour × intensity).
    static void checkTexels(const core::ImageRGBA& image, const std::string& source,
                            const glm::vec3& scale = glm::vec3(1.0f));

    /// Radiance arriving from world direction ω (scaled).
    glm::vec3 lookup(const glm::vec3& worldDir) const;

    std::string_view kind() const override { return "environment"; }
    bool isDelta() const override { return false; }
    LightSample sample(const glm::dvec3& x, const glm::vec2& u) const override;
    float pdf(const glm::dvec3& x, const glm::vec3& wi) const override;
    glm::vec3 radiance(const glm::dvec3& x, const glm::vec3& wi) const override {
        return lookup(wi);
    }
    std::string toString() const override;

    /// How many times dsfCoefficients projected the map (cache misses): for tests and profiling.
    std::size_t dsfProjectionCount() const;

  protected:
    const char* errorSource() const override { return source_.c_str(); }

  private:
    void writeSh(const glm::dvec3& x, int maxBand, std::span<glm::vec3> out) const override;
    void writeDsf(const glm::dvec3& x, const sh::Dsf& dsf, std::span<glm::vec3> out) const override;
    int pixelOf(const glm::dvec3& mapDir) const;
    void buildSampling();

    std::string source_;
    int w_ = 0, h_ = 0;
    std::vector<glm::vec3> rgb_;  // map frame, unscaled, row-major
    glm::dmat3 rotation_{1.0};
    float scale_ = 1.0f;
    std::size_t clamped_ = 0;
    // Importance sampling: row marginal CDF (h+1) and per-row conditional CDFs (h·(w+1));
    // normaliser Σ lum·Ω.
    std::vector<double> rowCdf_, colCdf_;
    double lumIntegral_ = 0;
    // SH of the map frame to kShCacheBand, and its rotation for the current rotation.
    static constexpr int kShCacheBand = 8;
    std::vector<glm::vec3> shMap_, shWorld_;
    // Unscaled DSF projections of the rotated map, one entry per DSF size (a Dsf is determined by
    // its direction count), each valid for the rotation it was made with. Behind a shared_ptr so
    // the light stays movable (std::mutex is not); copies share it, which stays correct because
    // every entry carries its own key.
    struct DsfCache {
        struct Entry {
            int size = 0;
            glm::dmat3 rotation{1.0};
            std::vector<glm::vec3> coefficients;
        };
        std::mutex mutex;
        std::vector<Entry> entries;
        std::size_t projections = 0;
    };
    std::shared_ptr<DsfCache> dsfCache_ = std::make_shared<DsfCache>();
};

}  // namespace voxlight::lights
