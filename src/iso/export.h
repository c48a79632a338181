// SPDX-License-Identifier: MIT
#pragma once
// Mesh export: binary PLY, OBJ and glTF 2.0 binary (.glb), chosen by file extension.
//
// Every format carries positions in millimetres in the volume's patient LPS frame (+x patient
// left, +y posterior, +z superior: core/volume.h), per-vertex outward unit normals and per-vertex
// colours, and says so in its own place for comments:
//   .ply  binary_little_endian 1.0; vertex: float x y z, float nx ny nz, uchar red green blue
//         (sRGB-encoded 8-bit: what viewers display as is); face: list uchar int vertex_indices;
//         `comment` lines give units, frame, isovalue, colour encoding.
//   .obj  `v x y z r g b` (the common vertex-colour extension; r g b sRGB-encoded in [0, 1]),
//         `vn`, `f a//a b//b c//c`; `#` comment lines as for PLY.
//   .glb  one mesh, one primitive (TRIANGLES) with POSITION, NORMAL (float VEC3) and COLOR_0
//         (float VEC3, *linear* RGB as glTF requires), uint32 indices; a matte material (metallic
//         0, roughness 1, base colour white) so that viewers show the vertex colours. Vertex data
//         stay in mm LPS; the mesh's node carries the matrix 0.001 · [x→X, z→Y, −y→Z] that takes them
//         to glTF's metres with +Y up = superior and +Z = anterior, so viewers show true size
//         upright. asset.extras records units, frame and isovalue. Written through tinygltf.
// Writers write exactly the path they are given (callers write a temporary and rename it:
// app/output_files.h). Failure is an InputError naming the path.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "iso/mesh.h"

namespace voxlight::iso {

enum class MeshFormat { Ply, Obj, Glb };

/// The format a file name's extension (case-insensitive) asks for; nullopt for any other.
std::optional<MeshFormat> meshFormatFor(const std::filesystem::path& path);
/// ".ply", ".obj", ".glb".
const std::vector<std::string>& meshExtensions();

/// What the file's comments / extras record besides units and frame.
struct ExportInfo {
    std::string description;  ///< e.g. the volume's description
    double isovalue = 0.0;    ///< physical units
    std::string unit;         ///< "HU", or empty
};

/// Per-vertex SH irradiance transfer (`voxlight iso --bake --lattice-mode sh --export-sh`; the
/// lattice's ShTransfer mode, iso/lattice.h), written to PLY only as extra vertex properties after
/// the colour: `property float sh<i>_r`, `sh<i>_g`, `sh<i>_b` for i < order², in voxlight's real
/// orthonormal SH basis (sh/sh_basis.h: index i = l² + l + m) over directions in patient LPS. A
/// viewer relights the mesh with any distant light of SH coefficients L (radiance, same basis) by
/// E_c = max(0, Σ_i L_i,c · sh<i>_c) and colour = albedo · E / π (the `comment` lines say so).
struct VertexTransfer {
    int order = 0;              ///< bands; (order)² coefficients per channel
    std::vector<float> values;  ///< [(vertex · order² + i) · 3 + channel]
};

/// sRGB encoding (IEC 61966-2-1) of a linear value in [0, 1] (clamped).
float srgbEncode(float linear);

/// Writes `mesh` (≥ 1 face) to `path` in `format`, with the per-vertex transfer when given
/// (PLY only: InputError for the other formats).
void writeMesh(const Mesh& mesh, const std::filesystem::path& path, MeshFormat format,
               const ExportInfo& info, const VertexTransfer* transfer = nullptr);

namespace detail {
void writeGlb(const Mesh& mesh, const std::filesystem::path& path, const ExportInfo& info);
/// The comment lines PLY and OBJ share (no comment prefix).
std::vector<std::string> commentLines(const ExportInfo& info, const std::string& colourEncoding);
}  // namespace detail

}  // namespace voxlight::iso
