// SPDX-License-Identifier: MIT
#pragma once
// Synthetic volumes. All are deterministic (same name + options → identical bytes), defined in
// millimetres so that `size` only changes the sampling, and antialiased (partial-volume edges from
// signed distances), like real scans.
//
//  kronander  Kronander et al. 2012 corner case (their Figs. 5–7): an opaque sphere and a torus
//             resting on a perfectly flat plate. uint8, 0 = air, 255 = solid; 1 mm voxels at size
//             128. The plate's top face is exactly the plane z = kronanderPlateTop(size) in world
//             mm, and it is axis-aligned, so it is flat to the last bit.
//  torso      CT-like torso in HU (int16): air, skin/fat/muscle, lungs, heart, liver, kidneys,
//             contrast-filled aorta with a braided metal stent, vertebrae with discs, ribs. 400 mm
//             field of view; 256³ by default.
//  sphere     Homogeneous sphere for exact optics: float32, value 1 inside, 0 outside, with a
//             linear ramp over ±1 voxel placed so the trilinear 0.5-level set is the sphere of
//             radius 0.35·extent centred in the volume.
//  slab       Homogeneous slab for exact optics: float32, value 1 for |z − zc| < 0.25·extent (same
//             0.5-level ramp), 0 elsewhere (same ramp), infinite in x and y within the volume.
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume.h"

namespace voxlight::core {

struct PhantomOptions {
    int size = 0;             ///< voxels per axis; 0 = the phantom's default
    glm::dvec3 spacing{0.0};  ///< mm; 0 = derived from the phantom's physical size and `size`
    std::uint64_t seed = 1;   ///< noise seed (torso)
};

/// Names accepted by makePhantom, with a one-line description each.
std::vector<std::pair<std::string, std::string>> phantomCatalog();

/// Builds the named phantom. Throws InputError (field "name" or "size") on an unknown name or a
/// size outside 8..1024.
Volume makePhantom(const std::string& name, const PhantomOptions& options = {},
                   const Progress& progress = Progress::none());

/// Analytic facts the exact tests rely on.
struct SphereFacts {
    glm::dvec3 centre;  ///< world mm
    double radius;      ///< mm
};
SphereFacts spherePhantomFacts(const Geometry& g);
struct SlabFacts {
    double zMin, zMax;  ///< world mm; the slab is zMin < z < zMax
};
SlabFacts slabPhantomFacts(const Geometry& g);

}  // namespace voxlight::core
