// SPDX-License-Identifier: MIT
#pragma once
// The isosurface mesh: an OpenMesh triangle mesh in world millimetres (patient LPS, core/volume.h),
// with per-vertex normals and colours. What every stage of iso/ (extraction, clipping, clean-up,
// export, and later the illumination lattice that bakes lighting into the colours) reads and writes.
//
//   point   double, mm, LPS (+x patient left, +y posterior, +z superior)
//   normal  double, unit, *outward*: −∇s/|∇s| of the volume's physical value s at the vertex, i.e.
//           pointing toward lower values. For a "value above the isovalue is inside" surface (bone,
//           skin, a contrast-filled vessel) that is out of the object.
//   colour  float, linear RGB in [0, 1] (for now the transfer function's albedo at the isovalue;
//           exporters encode it as the format expects, iso/export.h).
// Faces are wound counter-clockwise seen from the side the normals point to.
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>

namespace voxlight::iso {

struct MeshTraits : public OpenMesh::DefaultTraits {
    using Point = OpenMesh::Vec3d;
    using Normal = OpenMesh::Vec3d;  // OpenMesh wants points and normals of one scalar type
    using Color = OpenMesh::Vec3f;
    VertexAttributes(OpenMesh::Attributes::Normal | OpenMesh::Attributes::Color);
    HalfedgeAttributes(OpenMesh::Attributes::PrevHalfedge);
};
using Mesh = OpenMesh::TriMesh_ArrayKernelT<MeshTraits>;

}  // namespace voxlight::iso
