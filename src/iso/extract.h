// SPDX-License-Identifier: MIT
#pragma once
// Isosurface extraction: vtkFlyingEdges3D (in a module, flying_edges_module.h) → optional open cut by
// clip planes / crop box → OpenMesh triangle mesh in world mm (iso/mesh.h) with outward normals
// from the volume gradient and a uniform vertex colour.
//
// Which side is inside: the surface separates voxels whose physical value is ≥ the isovalue
// ("inside": bone above 300 HU) from those below. Normals point outward, toward lower values.
//
// Integer isovalues on integer data: when the isovalue is an integer in *stored* units (300 HU on
// a CT stored as int16 with intercept −1024), voxels exactly at the isovalue put flying-edges
// vertices exactly on grid points, giving zero-area triangles and, where several edges meet there,
// coincident vertices (BUILD-NOTES). extract moves such an isovalue by kIntegerIsoNudge = ½ stored
// unit toward the outside — to the half-integer between the isovalue and the next lower value —
// so that voxels equal to the isovalue count as inside, as above. The surface moves by ½/g voxel
// where the data rise by g stored units per voxel (0.5 mm at a 1 HU/mm ramp, 0.0005 mm at a bone
// edge of 1000 HU/mm). Half-integer (and non-integer) isovalues are used as given.
// A smaller nudge is not safe: 1/256 unit on a 1000-per-voxel edge leaves vertices 4e-6 voxel from
// grid points, below float resolution at index ≈ 30 — zero-area triangles and, on the 256³ torso
// at 300 HU, 98 self-intersecting face pairs (tests/iso IntegerIsovalueOnIntegerDataIsHandled).
//
// Clipping (open cut): the kept region is the intersection of the half-spaces dot(x − p, n) ≥ 0
// (clip planes; crop-box faces via core::boxHalfSpaces). Triangles crossing a plane are cut along
// it exactly (new vertices on the crossed edges, shared between neighbours, so the cut surface
// stays 2-manifold with a boundary along the cut); nothing caps the hole.
//
// Capped cut (ExtractOptions::cap): after each plane's cut, the boundary edges on the plane are
// closed contours where the surface was closed; a constrained Delaunay triangulation (CGAL,
// cap_fill.h) fills them by nesting parity (a contour inside another is a hole: a cut through a bone's cortex caps the ring, not the marrow), wound to
// agree with the surface. The cap shares the rim's vertices, so a closed surface stays closed
// (watertight: the mesh report's boundary edges stay 0), and the planes after it cut the cap too, so
// the caps of a crop box meet along its edges. The price of sharing: a rim vertex has one normal,
// the surface's gradient normal, so a renderer that interpolates vertex normals shades the cap's
// rim like the surface next to it. Contours that do not close (the surface was open there, at the
// volume's border) are left open and counted (capOpenEdges).
//
// Cost: flying edges, then one pass per half-space, one parallel pass for normals, and OpenMesh's
// half-edge construction (serial; bench/bench_iso.cpp compares the whole with flying edges alone).
#include <array>
#include <cstddef>
#include <glm/glm.hpp>
#include <vector>

#include "core/half_space.h"
#include "core/progress.h"
#include "core/volume.h"
#include "iso/mesh.h"

namespace voxlight::iso {

/// Stored units an integer isovalue on integer data is moved by (see header comment): half of the
/// smallest data step, the largest distance from every stored value, so that interpolated vertices
/// stay ≥ ½/(value range) of an edge away from grid points.
inline constexpr double kIntegerIsoNudge = 0.5;

/// Voxels (of the smallest spacing) a capped plane that passes through mesh vertices (within the
/// snap below) is moved toward the removed side: such vertices would pinch the cap's contours (two
/// loops meeting at one vertex, a non-manifold cap; the torso cut at x = 0 had one). 10⁻⁴ voxel is
/// far below anything visible and far above float rounding of the vertices' distances; at least
/// 4 snaps.
inline constexpr double kCapPlaneNudge = 1e-4;
/// A vertex this close to a cutting plane lies on it (the cut passes through it): a plane a hair
/// off a voxel plane (1e-7 mm, an OBJ's 6 decimals) cut slivers whose new points rounded onto the
/// old ones in the float32 files — 803 zero-area faces on the abdominal CT (probe). The larger of
/// 10⁻⁵ voxel and 16 float steps of the mesh's largest coordinate.
inline constexpr double kClipSnapVoxels = 1e-5, kClipSnapFloatSteps = 16.0;

/// Peak memory per triangle of an extraction and its report (measured: 6.56 M triangles of a 128³
/// noise volume, 1.22 GB peak; 53 M of a 256³ one, 9.5 GB — VTK's soup, the OpenMesh mesh, CGAL's
/// copy for the report).
inline constexpr double kPeakBytesPerTriangle = 185.0;
/// Triangles per voxel edge the isosurface crosses (each such edge is one vertex of the mesh): a
/// closed triangle mesh has about twice as many faces as vertices (Euler); measured 2.10 on a 128³
/// noise volume's 3.1 M vertices. (Per crossed cell it varies 2–3.2 with the data.)
inline constexpr double kTrianglesPerCrossedEdge = 2.1;

struct ExtractOptions {
    double isovalue = 0.0;              ///< physical units (HU for CT); strictly inside the range
    std::vector<core::HalfSpace> keep;  ///< clip planes and crop faces; empty = no cut
    glm::vec3 color{1.f};               ///< linear RGB of every vertex
    bool cap = false;                   ///< close each cut with a flat cap (header comment)
    /// Refuse (InputError field "memory") before extracting when the voxel edges the surface
    /// crosses inside `keep` promise a peak above this (kTrianglesPerCrossedEdge ×
    /// kPeakBytesPerTriangle each); 0 = no limit. A noisy isovalue on a 512³ volume asks ≈ 75 GB.
    double maxMemoryMiB = 0.0;
};

struct ExtractStats {
    double isovalue = 0.0;                  ///< physical, as asked
    double storedIsovalue = 0.0;            ///< what flying edges was given (stored units)
    bool nudged = false;                    ///< the integer rule above moved it
    std::array<double, 2> range{0.0, 0.0};  ///< the volume's physical value range
    std::size_t flyingEdgesTriangles = 0;   ///< before clipping
    std::size_t clippedTriangles = 0;       ///< after clipping (= flying edges' without planes)
    std::size_t rejectedFaces =
        0;                         ///< triangles OpenMesh refused (would make an edge non-manifold)
    bool flipped = false;          ///< faces were re-wound to agree with the outward normals
    std::size_t capTriangles = 0;  ///< triangles the caps added (ExtractOptions::cap)
    std::size_t capOpenEdges = 0;  ///< cut edges left open: chains that do not close
    std::size_t capFailures = 0;   ///< planes whose contours crossed (part of the fill missing)
    double flyingEdgesSeconds = 0, clipSeconds = 0, normalsSeconds = 0, meshSeconds = 0;
};

struct Extraction {
    Mesh mesh;
    ExtractStats stats;
    /// ExtractOptions::keep as cut: a capped plane through vertices moved kCapPlaneNudge toward
    /// its removed side (its cap's vertices lie on this one; clean-up holds them: cleanup.h).
    std::vector<core::HalfSpace> planes;
};

/// Extracts the isosurface. Throws InputError (source "isosurface") with field "volume" when the
/// volume is flat (min = max: there is no surface), with field "isovalue" when the isovalue is not
/// strictly inside (min, max), or on integer data rounds to the min (the integer rule would move it
/// below the data) — the message names the range; the caller maps the field to its own
/// option or key.
/// An empty mesh is returned only when clipping removed everything. Throws CancelledError through
/// `progress`; InputError (field "iso module") when the VTK module cannot be loaded.
Extraction extractIsosurface(const core::Volume& volume, const ExtractOptions& options,
                             const core::Progress& progress = core::Progress::none());

/// Sets every vertex normal to −∇s/|∇s| at the vertex (∇s: trilinear interpolation of the voxels'
/// central-difference gradients, one-sided at the border, taken to world mm through spacing and
/// direction). Where the gradient vanishes the normal is the mesh's own (area-weighted faces).
/// Used by extraction and again after clean-up moved vertices. A vertex on one of `capPlanes`
/// (within `onPlaneMm`) is shaded as extraction shades caps: a cap's own vertex (its faces all on
/// capped planes) takes the cap's normal, a rim vertex the bisector of the gradient's and the
/// cap's (the rim normals were gradients after --smooth or --decimate: every cap face's vertex
/// normals turned away from it, the cap shaded edge-on).
void setGradientNormals(Mesh& mesh, const core::Volume& volume,
                        const std::vector<core::HalfSpace>& capPlanes = {}, double onPlaneMm = 0.0);

}  // namespace voxlight::iso
