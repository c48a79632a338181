// SPDX-License-Identifier: MIT
#pragma once
// Mesh clean-up and the mesh report, both through CGAL Polygon Mesh Processing (PMP) and Surface
// Mesh Simplification (SMS). CGAL stays inside cleanup.cpp: this header speaks iso::Mesh only.
//
// Clean-up steps, each off unless asked, run in this order:
//   1. remove degenerate faces        PMP::remove_degenerate_faces (zero-area triangles, collapsed
//                                     edges), keeping the mesh combinatorially valid
//   2. keep the k largest components  PMP::keep_largest_connected_components (size = faces)
//   3. drop small components          PMP::keep_large_connected_components (fewer faces than the
//                                     minimum)
//   4. smoothing                      Taubin λ|μ (Taubin 1995, "A signal processing approach to
//                                     fair surface design"): per iteration a Laplacian step of
//                                     λ = 0.5, then one of μ = −0.53 (uniform weights). Low-pass
//                                     without the shrinking of plain Laplacian smoothing; boundary
//                                     vertices and those on capped planes stay put. Written here
//                                     on CGAL's mesh: CGAL's own smooth_shape (mean curvature
//                                     flow) rippled and thinned the torso's ribs (area −26 % after
//                                     3 steps) and cost 10 s there.
//   5. decimation                     SMS::edge_collapse with Lindstrom–Turk cost and placement
//                                     and a Bounded_normal_change_filter (no face turned over),
//                                     stopping at about `targetFaces` faces (CGAL 5.5 stops on an
//                                     edge count: 1.5 × targetFaces, exact for closed meshes).
// Vertex colours and normals follow their vertex (a collapsed edge keeps one end's). Normals of
// moved vertices are stale afterwards (CleanupStats::verticesMoved): callers set them again
// (extract.h's setGradientNormals).
#include <cstddef>
#include <iosfwd>
#include <vector>

#include "core/half_space.h"
#include "core/progress.h"
#include "iso/mesh.h"

namespace voxlight::iso {

/// Taubin's pass-band pair (his paper's example values: k_PB = 1/λ + 1/μ ≈ 0.11). Per iteration
/// the filter scales a mode of the umbrella operator's eigenvalue k by (1 − λk)(1 − μk) =
/// 1 + |λμ|·k·(k_PB − k): above 1 inside the pass band, at most 1 + |λμ|·k_PB²/4 = 1.00085 —
/// compounded over 1000 iterations ×2.3: the torso's bone grew 2.7× in volume and crossed itself
/// thousands of times (probe). A smaller pass band (0.01) gains less but erodes what is thinner
/// than about 60 edges (the ribs: −15 % volume at 100 iterations).
inline constexpr double kTaubinLambda = 0.5, kTaubinMu = -0.53;
/// A vertex this close to a held plane (mm) is on it: cut points are computed on the plane to
/// ~1e-13 mm; a nanometre is far below any voxel.
inline constexpr double kOnCapPlaneMm = 1e-6;
/// Most iterations --smooth takes: the pass band's gain compounds to at most 4.3 % (1.00085^50).
inline constexpr int kMaxSmoothIterations = 50;

struct CleanupOptions {
    bool removeDegenerate = false;
    int keepLargest = 0;                ///< keep the k largest components; 0 = keep all
    std::size_t minComponentFaces = 0;  ///< drop components with fewer faces; 0 = drop none
    int smoothIterations = 0;           ///< Taubin λ|μ iterations; 0 = no smoothing
    std::size_t targetFaces = 0;        ///< decimate to about this many faces; 0 = no decimation
    /// Capped cuts: smoothing holds the vertices on these planes (within kOnCapPlaneMm), as it
    /// holds an open cut's boundary — a cap is a fan of rim-to-rim triangles, and averaging over
    /// those long edges dragged rim vertices across it (hundreds of self-intersections on a capped
    /// sphere, rim moved 1.9 mm in one iteration; probe).
    /// Decimation collapses no edge at a vertex on these planes (the cap stays as cut).
    std::vector<core::HalfSpace> heldPlanes;

    bool any() const {
        return removeDegenerate || keepLargest > 0 || minComponentFaces > 0 ||
               smoothIterations > 0 || targetFaces > 0;
    }
};

struct CleanupStats {
    std::size_t facesBefore = 0, facesAfter = 0;
    std::size_t degenerateFacesRemoved = 0;  ///< faces step 1 removed
    std::size_t componentsRemoved = 0;       ///< by steps 2 and 3
    bool verticesMoved = false;              ///< smoothing or decimation ran
    double seconds = 0.0;
};

/// Runs the steps `options` asks for (none: returns at once). Throws CancelledError between steps.
CleanupStats cleanUp(Mesh& mesh, const CleanupOptions& options,
                     const core::Progress& progress = core::Progress::none());

struct MeshReport {
    std::size_t vertices = 0, faces = 0;
    std::size_t components = 0;           ///< connected components (by shared edges)
    std::size_t boundaryEdges = 0;        ///< edges with a face on one side only
    std::size_t nonManifoldVertices = 0;  ///< pinched vertices (several fans of faces)
    /// Pairs of faces that intersect other than along a shared edge or vertex; −1 when not checked.
    long long selfIntersections = -1;
    bool closed = false;     ///< no boundary edges
    double areaMm2 = 0.0;    ///< total surface area
    double volumeMm3 = 0.0;  ///< enclosed volume (signed: > 0 when normals point out); closed only
    double seconds = 0.0;
};
std::ostream& operator<<(std::ostream& os, const MeshReport& r);

/// Measures `mesh`. The self-intersection test (PMP::self_intersections, a box-intersection sweep:
/// the report's costly part) runs when `checkSelfIntersections`.
MeshReport reportMesh(const Mesh& mesh, bool checkSelfIntersections,
                      const core::Progress& progress = core::Progress::none());

}  // namespace voxlight::iso
