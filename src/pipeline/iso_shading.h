// SPDX-License-Identifier: MIT
#pragma once
// Frames of method `iso-lattice` (Wyman et al. 2006 §5; NOTES.md §3): the isosurface by direct
// ray casting — the first crossing of the isovalue per pixel, as method `iso` finds it
// (render/dvr_march.h marchIso) — shaded from the illumination lattice or by one of Wyman's
// baselines (Figs. 8–10), so that they can be put side by side on the same surface and camera:
//
//   lattice   E trilinear from the lattice's texels (iso/lattice.h), computed lazily: only the
//             texels the frame's hit points read, kept for the next frame (a new view or isovalue
//             computes only texels not seen before; the stats say how many)
//   paths     E by `samples` paths traced from each hit point itself (no texels, no
//             interpolation: Wyman's per-pixel reference, Fig. 11) — slow, the truth the lattice
//             is measured against
//   lambert   Σ delta lights E_l · max(0, n·l), no shadows (Fig. 8a)
//   shadows   the same with one hard shadow ray per light against the isosurface (Fig. 8c)
//   vicinity  Stewart's vicinity shading: sky light occluded only within a radius (Fig. 10)
//   phong     the clinical baseline: Blinn–Phong with ambient at the ray caster's normal (Fig. 8b)
//
// Every shading but phong uses the tricubic B-spline smoothed normal (the lattice's), so the
// differences between them are the light transport, not the normals. Pixel colour = albedo ⊙
// E/π (the radiance a Lambertian surface leaves; the albedo is the TF's at the isovalue), phong
// albedo ⊙ diffuse + specular; a miss shows the background. Pixels are pure functions of (scene,
// pixel): identical for any thread count.
#include <cstdint>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/progress.h"
#include "iso/lattice.h"
#include "render/camera.h"
#include "render/ray_caster.h"
#include "render/shading.h"

namespace voxlight::pipeline {

enum class IsoShading { Lattice, Paths, Lambert, Shadows, Vicinity, Phong };

/// The names method.params.shading takes, in the order of the enum.
const std::vector<std::string>& isoShadingNames();
IsoShading isoShadingFromName(const std::string& name);  ///< name must be one of isoShadingNames()
/// Whether the shading traces against the isosurface (needs an IlluminationLattice's tracer).
inline bool isoShadingTraces(IsoShading s) { return s != IsoShading::Phong; }

struct IsoShadingOptions {
    IsoShading shading = IsoShading::Lattice;
    int samples = 100;            ///< paths (paths) or directions (vicinity) per pixel
    double vicinityRadiusMm = 0;  ///< vicinity: occluders farther than this do not count
    render::BlinnPhongParams phong;
};

struct IsoFrameStats {
    std::uint64_t hits = 0;     ///< pixels whose ray hit the isosurface
    std::uint64_t samples = 0;  ///< volume samples the hit search took
    iso::LatticeStats lattice;  ///< lattice: what this frame's require() did
    double hitSeconds = 0.0, shadeSeconds = 0.0;
};

/// One frame. `lattice` must be non-null when isoShadingTraces(o.shading); its lights are what
/// the traced shadings use; phong uses the caster's options' lights (none: the headlight of
/// method `iso`). Throws CancelledError through progress, InputError from the lattice (memory).
core::ImageRGBA renderLitIsosurface(const render::RayCaster& caster, const render::Camera& camera,
                                    iso::IlluminationLattice* lattice, const IsoShadingOptions& o,
                                    const core::Progress& progress, IsoFrameStats& stats);

}  // namespace voxlight::pipeline
