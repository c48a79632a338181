// SPDX-License-Identifier: MIT
// PLY and OBJ writers (export.h); glTF is in export_gltf.cpp.
#include "iso/export.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>

#include "core/error.h"

namespace voxlight::iso {

namespace {

struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

[[noreturn]] void failWrite(const std::filesystem::path& path) {
    throw InputError(path.string(), "output", std::string("cannot write: ") + std::strerror(errno),
                     "check free space and permissions");
}

File openForWrite(const std::filesystem::path& path) {
    File f(std::fopen(path.c_str(), "wb"));
    if (!f) failWrite(path);
    return f;
}

void closeChecked(File f, const std::filesystem::path& path) {
    std::FILE* raw = f.release();
    const bool bad = std::ferror(raw) != 0;
    if (std::fclose(raw) != 0 || bad) failWrite(path);
}

std::uint8_t srgb8(float linear) { return std::uint8_t(std::lround(255.f * srgbEncode(linear))); }

void writePly(const Mesh& mesh, const std::filesystem::path& path, const ExportInfo& info,
              const VertexTransfer* transfer) {
    static_assert(std::endian::native == std::endian::little, "PLY writer assumes little endian");
    File f = openForWrite(path);
    std::string header = "ply\nformat binary_little_endian 1.0\n";
    for (const auto& line :
         detail::commentLines(info, "red green blue: sRGB-encoded 8-bit of the linear colour"))
        header += "comment " + line + "\n";
    const std::size_t C =
        transfer ? std::size_t(transfer->order) * std::size_t(transfer->order) : 0;
    VL_CHECK(!transfer || transfer->values.size() == C * 3 * mesh.n_vertices());
    if (transfer)
        header += "comment sh<i>_r sh<i>_g sh<i>_b, i < " + std::to_string(C) +
                  ": irradiance transfer in voxlight's real orthonormal SH basis (i = l*l + l + "
                  "m) over LPS directions; E = max(0, sum_i L_i * sh<i>) for distant light of "
                  "radiance SH L, colour = albedo * E / pi\n";
    header += "element vertex " + std::to_string(mesh.n_vertices()) +
              "\nproperty float x\nproperty float y\nproperty float z\n"
              "property float nx\nproperty float ny\nproperty float nz\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    for (std::size_t i = 0; i < C; ++i)
        for (const char* ch : {"r", "g", "b"})
            header += "property float sh" + std::to_string(i) + "_" + ch + "\n";
    header += "element face " + std::to_string(mesh.n_faces()) +
              "\nproperty list uchar int vertex_indices\nend_header\n";
    std::fwrite(header.data(), 1, header.size(), f.get());
    // Packed records: 6 floats + 3 bytes (+ 3·C floats) per vertex, 1 + 3 ints per face.
    const std::size_t kVertexBytes = 6 * sizeof(float) + 3 + 3 * C * sizeof(float);
    std::vector<char> buf(kVertexBytes * mesh.n_vertices());
    char* out = buf.data();
    for (const auto v : mesh.vertices()) {
        const Mesh::Point& p = mesh.point(v);
        const Mesh::Normal& n = mesh.normal(v);
        const Mesh::Color& c = mesh.color(v);
        const float xyz[6] = {float(p[0]), float(p[1]), float(p[2]),
                              float(n[0]), float(n[1]), float(n[2])};
        const std::uint8_t rgb[3] = {srgb8(c[0]), srgb8(c[1]), srgb8(c[2])};
        std::memcpy(out, xyz, sizeof xyz);
        std::memcpy(out + sizeof xyz, rgb, 3);
        if (C > 0)
            std::memcpy(out + sizeof xyz + 3,
                        transfer->values.data() + std::size_t(v.idx()) * 3 * C,
                        3 * C * sizeof(float));
        out += kVertexBytes;
    }
    std::fwrite(buf.data(), 1, buf.size(), f.get());
    constexpr std::size_t kFaceBytes = 1 + 3 * sizeof(std::int32_t);
    buf.assign(kFaceBytes * mesh.n_faces(), 0);
    out = buf.data();
    for (const auto fh : mesh.faces()) {
        std::int32_t idx[3];
        int k = 0;
        for (const auto v : mesh.fv_range(fh)) idx[k++] = v.idx();
        *out = 3;
        std::memcpy(out + 1, idx, sizeof idx);
        out += kFaceBytes;
    }
    std::fwrite(buf.data(), 1, buf.size(), f.get());
    closeChecked(std::move(f), path);
}

void writeObj(const Mesh& mesh, const std::filesystem::path& path, const ExportInfo& info) {
    File f = openForWrite(path);
    for (const auto& line : detail::commentLines(
             info, "v x y z r g b: r g b sRGB-encoded in [0, 1] of the linear colour"))
        std::fprintf(f.get(), "# %s\n", line.c_str());
    for (const auto v : mesh.vertices()) {
        const Mesh::Point& p = mesh.point(v);
        const Mesh::Color& c = mesh.color(v);
        std::fprintf(f.get(), "v %.6f %.6f %.6f %.6f %.6f %.6f\n", p[0], p[1], p[2],
                     srgbEncode(c[0]), srgbEncode(c[1]), srgbEncode(c[2]));
    }
    for (const auto v : mesh.vertices()) {
        const Mesh::Normal& n = mesh.normal(v);
        std::fprintf(f.get(), "vn %.6f %.6f %.6f\n", n[0], n[1], n[2]);
    }
    for (const auto fh : mesh.faces()) {
        int idx[3];
        int k = 0;
        for (const auto v : mesh.fv_range(fh)) idx[k++] = v.idx() + 1;
        std::fprintf(f.get(), "f %d//%d %d//%d %d//%d\n", idx[0], idx[0], idx[1], idx[1], idx[2],
                     idx[2]);
    }
    closeChecked(std::move(f), path);
}

std::string lower(std::string s) {
    for (auto& ch : s) ch = char(std::tolower(static_cast<unsigned char>(ch)));
    return s;
}

}  // namespace

std::optional<MeshFormat> meshFormatFor(const std::filesystem::path& path) {
    const std::string ext = lower(path.extension().string());
    if (ext == ".ply") return MeshFormat::Ply;
    if (ext == ".obj") return MeshFormat::Obj;
    if (ext == ".glb") return MeshFormat::Glb;
    return std::nullopt;
}

const std::vector<std::string>& meshExtensions() {
    static const std::vector<std::string> e = {".ply", ".obj", ".glb"};
    return e;
}

float srgbEncode(float linear) {
    const float x = std::clamp(linear, 0.f, 1.f);
    return x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x, 1.f / 2.4f) - 0.055f;
}

void writeMesh(const Mesh& mesh, const std::filesystem::path& path, MeshFormat format,
               const ExportInfo& info, const VertexTransfer* transfer) {
    if (mesh.n_faces() == 0)
        throw InputError(path.string(), "mesh", "has no faces to write",
                         "choose an isovalue, clip planes and crop box that leave a surface");
    if (transfer && format != MeshFormat::Ply)
        throw InputError(path.string(), "format", "per-vertex SH transfer is written to PLY only",
                         "export to a .ply file");
    switch (format) {
        case MeshFormat::Ply:
            return writePly(mesh, path, info, transfer);
        case MeshFormat::Obj:
            return writeObj(mesh, path, info);
        case MeshFormat::Glb:
            return detail::writeGlb(mesh, path, info);
    }
}

namespace detail {
std::vector<std::string> commentLines(const ExportInfo& info, const std::string& colourEncoding) {
    char iso[64];
    std::snprintf(iso, sizeof iso, "%.6g", info.isovalue);
    std::vector<std::string> lines = {
        "voxlight isosurface" + (info.description.empty() ? "" : ": " + info.description),
        std::string("isovalue ") + iso + (info.unit.empty() ? "" : " " + info.unit),
        "coordinates: millimetres, patient LPS (+x patient left, +y posterior, +z superior)",
        "normals: unit, outward (toward lower values)", "colours: " + colourEncoding};
    // One comment per line: a description must not start a line of its own.
    for (auto& l : lines)
        std::replace_if(
            l.begin(), l.end(), [](char c) { return c == '\n' || c == '\r'; }, ' ');
    return lines;
}
}  // namespace detail

}  // namespace voxlight::iso
