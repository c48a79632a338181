// SPDX-License-Identifier: MIT
#pragma once
// The radiance volume of PVRT's render (Zhang, Dong & Ma 2013 §6, "early evaluation"): each frame
// the lights are projected into the basis (Basis::project → c_k), every stored point's in-scattered
// radiance S(x) = Σ_k c_k ⊙ t_k(x) is evaluated once (from the transfer, or through CPCA), and
// the ordinary ray caster marches the volume with a shader that reads S trilinearly — so a light
// change costs one pass over the stored points, not a precompute.
//
// With n > 1 exitance coefficients (transfer.h) the volume holds, per grid point, the n RGB SH
// coefficients t_j = Σ_k c_k ⊙ t_{k,j} of the incident radiance instead of S, and the shader
// evaluates the Henyey–Greenstein in-scattered radiance toward the eye per sample,
// L_s = Σ_j g^{l(j)} Ŷ_j(−toEye) t_j (exitanceWeights), trilinear in the coefficients, clamped at 0
// after the sum; g is the method's phase_g, or the TF's phase g channel at the sample's value
// where the TF has one. n = 1 is the isotropic S, view-independent, exactly as before.
//
// S is clamped at 0: a truncated SH expansion of the lighting can ring below zero where the
// transfer is sharp (radiance never is). The marcher multiplies S by the segment's α and the TF
// albedo and adds the TF emission (render/shading.h), exactly as for the SH visibility shaders.
#include <cstdlib>
#include <glm/glm.hpp>
#include <memory>
#include <new>
#include <span>
#include <utility>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"
#include "optics/transfer_function.h"
#include "pvrt/cpca.h"
#include "pvrt/transfer.h"
#include "render/ray_caster.h"

namespace voxlight::pvrt {

/// The radiance volume's allocator: memory from calloc, elements default-initialised (resize()
/// writes nothing). A large block is fresh zero pages from the kernel, mapped on first write, so
/// the n = 16 volume (48 MB at grid 64³) costs a light change only the pages of stored points —
/// empty grid points stay 0 without a memset.
template <class T>
struct ZeroedAllocator {
    using value_type = T;
    ZeroedAllocator() = default;
    template <class U>
    ZeroedAllocator(const ZeroedAllocator<U>&) {}
    T* allocate(std::size_t count) {
        if (void* p = std::calloc(count, sizeof(T))) return static_cast<T*>(p);
        throw std::bad_alloc();
    }
    void deallocate(T* p, std::size_t) { std::free(p); }
    template <class U>
    void construct(U* p) {
        ::new (static_cast<void*>(p)) U;  // default-init: the calloc zeros stay
    }
    template <class U, class... A>
    void construct(U* p, A&&... a) {
        ::new (static_cast<void*>(p)) U(std::forward<A>(a)...);
    }
    template <class U>
    bool operator==(const ZeroedAllocator<U>&) const {
        return true;
    }
};

struct RadianceVolume {
    glm::ivec3 res{0};
    glm::vec3 scale{1.f};  ///< voxels per grid step (TransferLayout::scale)
    int exitance = 1;      ///< n: RGB entries per grid point (1: S; else SH of L_in, transfer.h)
    /// True when the n > 1 coefficients were already evaluated toward one eye per grid point
    /// (EyeFold): exitance is 1 and values hold L_s, not clamped (the shader clamps after the
    /// trilinear blend, as for the per-sample evaluation).
    bool towardEye = false;
    /// Per grid point (x fastest) n RGB entries: S (n = 1) or the exitance coefficients; 0 where
    /// no point is stored.
    std::vector<glm::vec3, ZeroedAllocator<glm::vec3>> values;
    /// Stored points whose S (n = 1) or whose coefficient 0 (the mean incident radiance, n > 1)
    /// was negative in some channel: clamped at 0 for n = 1; for n > 1 the coefficients are kept
    /// and the evaluated L_s is clamped in the shader.
    std::uint64_t clamped = 0;

    /// Trilinear S at continuous voxel coordinate p (clamped to the grid); n = 1 only.
    glm::vec3 sample(const glm::vec3& p) const;
    /// Trilinear Σ_j w_j t_j at p (n weights, exitanceWeights), not clamped.
    glm::vec3 sampleWeighted(const glm::vec3& p, const float* w) const;
    std::size_t bytes() const { return values.size() * sizeof(glm::vec3); }
};

struct EyeFold;
/// S = Σ_k c_k ⊙ t_k at every stored point of `transfer` (c: basis-size RGB coefficients).
/// Parallel over z-slices of the grid, deterministic.
/// With n = transfer.exitance > 1: t_j = Σ_k c_k ⊙ t_{k,j} per coefficient (not clamped); with
/// `eye` as well, those evaluated toward it per grid point as combineCpca does (EyeFold).
RadianceVolume combineTransfer(const Transfer& transfer, std::span<const glm::vec3> light,
                               int threads = 0, const EyeFold* eye = nullptr);
/// The same from per-stored-point radiance already evaluated (e.g. by CPCA; n entries per point,
/// [point][j]): scattered into the grid, clamped at 0 when n = 1.
RadianceVolume scatterRadiance(const TransferLayout& layout, std::span<const glm::vec3> perPoint,
                               int exitance = 1);

/// An eye toward which combineCpca and combineTransfer evaluate n > 1 coefficients per grid point (Zhang et al. fold
/// the view in the same way): L_s(x) = Σ_j g^{l(j)} Ŷ_j(−ω_eye(x)) t_j(x) with ω_eye(x) the unit
/// direction from the grid point's world position to the eye (perspective) or −forward
/// (orthographic) — the per-sample shader's −ray direction, taken at the grid points instead of at
/// the samples. One RGB per grid point instead of n, so the light change writes n× less and a
/// frame reads one trilinear RGB per sample; a camera move reruns it.
struct EyeFold {
    float g = 0.f;              ///< HG asymmetry (|g| < 1)
    core::Geometry geometry;    ///< voxel → world
    bool orthographic = false;  ///< true: toEye = −forward everywhere
    glm::dvec3 eye{0.0};        ///< perspective: the eye's world position
    glm::dvec3 forward{0.0, 0.0, 1.0};
};

/// The same as cpca.radiance(light, n) followed by scatterRadiance (n = exitance) but in one pass
/// in the CPCA domain, writing straight into the grid (Zhang eq. 18–19): the lights projected onto
/// each cluster's mean and N components (Cpca::projectLight), then per stored point n·3 floats =
/// mean + Σ_i w_i·component_i, vectorised over the n·3 entries, parallel over z-slices; empty
/// points are never written (ZeroedAllocator). Equal to the two-step result up to float rounding
/// of the fused multiply-adds (tests/pvrt/test_exitance.cpp). cpca.rows() = layout.points.
/// With `eye` and n > 1: the coefficients of each point evaluated toward it instead (EyeFold;
/// towardEye set, exitance 1); the clamped count is then of points whose L_s is negative.
RadianceVolume combineCpca(const TransferLayout& layout, const Cpca& cpca,
                           std::span<const glm::vec3> light, int exitance, int threads = 0,
                           const EyeFold* eye = nullptr);

/// The ray caster's shading model reading a radiance volume: isotropic S (n = 1), or HG with
/// asymmetry phaseG (|g| < 1) — per sample the TF's phase g channel instead when `table` has one.
std::unique_ptr<render::ShadingModel> makePvrtModel(
    const render::RayCaster& caster, const render::Camera& camera,
    std::shared_ptr<const RadianceVolume> radiance, float phaseG = 0.f,
    std::shared_ptr<const optics::TfTable> table = nullptr);

}  // namespace voxlight::pvrt
