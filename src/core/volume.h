// SPDX-License-Identifier: MIT
#pragma once
// A scalar volume on a regular grid, in patient LPS millimetres.
//
// Geometry (ITK/DICOM convention): voxel (i,j,k) has its *centre* at
//     world = origin + D · (ijk ⊙ spacing)   [mm, LPS: +x patient left, +y posterior, +z superior]
// where D is the 3×3 direction matrix whose columns are the unit directions of the i, j, k axes. D
// must be orthonormal (det ±1); readers reject sheared grids (gantry tilt) with a clear message.
// Index space is continuous: sampling at (1.5, 0, 0) interpolates between voxels 1 and 2. Samples
// outside [0, n−1] clamp to the edge voxel (edge extension).
//
// Values: voxels are stored in their native type (uint8, int16, uint16, float32). The *physical*
// value (HU for CT) is
//     physical = slope · stored + intercept
// and every sampler returns physical values as float. Storage is x-fastest:
//     index = i + nx·(j + ny·k)
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <glm/glm.hpp>
#include <iosfwd>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/error.h"

namespace voxlight::core {

enum class VoxelType : std::uint8_t { UInt8, Int16, UInt16, Float32 };
std::string_view toString(VoxelType t);
std::size_t voxelBytes(VoxelType t);

template <class T>
constexpr VoxelType voxelTypeOf();
template <>
constexpr VoxelType voxelTypeOf<std::uint8_t>() {
    return VoxelType::UInt8;
}
template <>
constexpr VoxelType voxelTypeOf<std::int16_t>() {
    return VoxelType::Int16;
}
template <>
constexpr VoxelType voxelTypeOf<std::uint16_t>() {
    return VoxelType::UInt16;
}
template <>
constexpr VoxelType voxelTypeOf<float>() {
    return VoxelType::Float32;
}

enum class Modality : std::uint8_t { Unknown, CT, MR, Synthetic };
std::string_view toString(Modality m);

/// Largest volume voxlight accepts (voxels). 2^31 int16 voxels = 4 GiB, beyond this machine class's
/// sensible use.
inline constexpr std::uint64_t kMaxVoxels = std::uint64_t(1) << 31;
/// Largest size along one axis.
inline constexpr int kMaxDim = 16384;
/// Voxel spacings voxlight accepts (mm): 0.1 µm (past synchrotron micro-CT) to 10 m. Beyond them
/// no scanner's file is meant, and the optics' squared distances and optical depths overflow (a
/// spacing of 1e154 mm crashed the path tracer; 1e30 mm made PVRT's transfer NaN).
inline constexpr double kMinSpacingMm = 1e-4;
inline constexpr double kMaxSpacingMm = 1e4;
/// How far (in its smallest voxel spacing) a volume's voxels may lie from the world origin: the
/// methods keep positions in single precision, whose step is 2⁻²⁴ of the coordinate — at 2¹⁷
/// spacings ¹⁄₁₂₈ of a voxel. Measured on a 16³ sphere at 1 mm moved away from 0 (RMS image
/// difference against the sphere at 0, relative): 1e5 mm ≤ 0.1 % for sh-local, ritschel, pvrt and
/// iso-lattice, 1e6 mm 0.1–1.2 %, 1e7 mm 5–25 %, and at 1e9 mm pvrt and iso-lattice were black — with
/// exit code 0 and no warning. A scanner's patient coordinates are within 10⁴ spacings.
inline constexpr double kMaxOriginSpacings = 131072.0;

inline double minComponent(const glm::dvec3& v) { return std::min(v.x, std::min(v.y, v.z)); }
inline double maxComponent(const glm::dvec3& v) { return std::max(v.x, std::max(v.y, v.z)); }

struct Geometry {
    glm::ivec3 dims{0};
    glm::dvec3 spacing{1.0};    ///< mm between voxel centres along i, j, k (> 0)
    glm::dvec3 origin{0.0};     ///< world position of voxel (0,0,0)'s centre, mm
    glm::dmat3 direction{1.0};  ///< columns: unit world directions of the i, j, k axes

    std::uint64_t voxelCount() const {
        return std::uint64_t(dims.x) * std::uint64_t(dims.y) * std::uint64_t(dims.z);
    }
    glm::dvec3 indexToWorld(const glm::dvec3& ijk) const {
        return origin + direction * (ijk * spacing);
    }
    /// Inverse of indexToWorld (direction is orthonormal, so its inverse is its transpose).
    glm::dvec3 worldToIndex(const glm::dvec3& p) const {
        return (glm::transpose(direction) * (p - origin)) / spacing;
    }
    /// The linear part of worldToIndex, diag(1/spacing) · directionᵀ, for loops that apply it to
    /// many points: worldToIndex(p) = worldToIndexMatrix() · (p − origin).
    glm::dmat3 worldToIndexMatrix() const {
        glm::dmat3 m = glm::transpose(direction);
        for (int c = 0; c < 3; ++c)
            for (int r = 0; r < 3; ++r) m[c][r] /= spacing[r];
        return m;
    }
    /// Physical extent between the first and last voxel centres along each axis, mm.
    glm::dvec3 extent() const { return glm::dvec3(glm::max(dims - 1, glm::ivec3(0))) * spacing; }
    /// Axis-aligned world bounding box of the voxel centres: {min, max}.
    std::array<glm::dvec3, 2> worldBounds() const;
    /// Direction in words, e.g. "RAS"-style code of the axes as patient-orientation letters ("LPS"
    /// = identity).
    std::string orientationCode() const;
    /// Throws InternalError unless dims ≥ 1, spacing > 0 and finite, direction orthonormal.
    void validate() const;
};
std::ostream& operator<<(std::ostream& os, const Geometry& g);

/// stored → physical mapping.
struct ValueMapping {
    double slope = 1.0;
    double intercept = 0.0;
    std::string unit;  ///< "HU" for CT in Hounsfield units, empty when unknown
    double apply(double stored) const { return slope * stored + intercept; }
};

/// Typed, non-owning view for hot loops: no virtual call or type switch per sample.
template <class T>
struct VolumeView {
    const T* data = nullptr;
    int nx = 0, ny = 0, nz = 0;
    std::size_t sy = 0, sz = 0;  ///< strides of j and k in elements
    float slope = 1.f, intercept = 0.f;

    float stored(int i, int j, int k) const { return float(data[i + sy * j + sz * k]); }
    float at(int i, int j, int k) const { return slope * stored(i, j, k) + intercept; }

    /// Trilinear interpolation of the physical value at continuous index (x, y, z), clamped to the
    /// grid.
    [[gnu::always_inline]] float sample(float x, float y, float z) const {
        x = std::min(std::max(x, 0.f), float(nx - 1));
        y = std::min(std::max(y, 0.f), float(ny - 1));
        z = std::min(std::max(z, 0.f), float(nz - 1));
        int i = std::min(int(x), nx - 2 < 0 ? 0 : nx - 2);
        int j = std::min(int(y), ny - 2 < 0 ? 0 : ny - 2);
        int k = std::min(int(z), nz - 2 < 0 ? 0 : nz - 2);
        const float fx = x - float(i), fy = y - float(j), fz = z - float(k);
        const int di = nx > 1 ? 1 : 0;
        const std::size_t dj = ny > 1 ? sy : 0, dk = nz > 1 ? sz : 0;
        const T* p = data + i + sy * j + sz * k;
        const float c00 = float(p[0]) + fx * (float(p[di]) - float(p[0]));
        const float c10 = float(p[dj]) + fx * (float(p[dj + di]) - float(p[dj]));
        const float c01 = float(p[dk]) + fx * (float(p[dk + di]) - float(p[dk]));
        const float c11 = float(p[dk + dj]) + fx * (float(p[dk + dj + di]) - float(p[dk + dj]));
        const float c0 = c00 + fy * (c10 - c00);
        const float c1 = c01 + fy * (c11 - c01);
        return slope * (c0 + fz * (c1 - c0)) + intercept;
    }
};

/// Owning scalar volume. Move-only (volumes are large).
class Volume {
  public:
    Volume() = default;
    /// Allocates a zero-filled volume. Throws InputError if the size is absurd (> kMaxVoxels or an
    /// axis > kMaxDim): callers that read files check first and name the file; this is the last
    /// line of defence.
    Volume(const Geometry& geometry, VoxelType type);
    /// Adopts an existing buffer of voxelCount·voxelBytes(type) bytes without copying (e.g. a file
    /// reader's array); `storage`'s deleter releases it. Same size checks as above.
    Volume(const Geometry& geometry, VoxelType type, std::shared_ptr<std::byte> storage);
    Volume(Volume&&) noexcept = default;
    Volume& operator=(Volume&&) noexcept = default;
    Volume(const Volume&) = delete;
    Volume& operator=(const Volume&) = delete;

    const Geometry& geometry() const { return geometry_; }
    Geometry& geometry() { return geometry_; }
    const glm::ivec3& dims() const { return geometry_.dims; }
    VoxelType type() const { return type_; }
    std::uint64_t voxelCount() const { return geometry_.voxelCount(); }
    std::size_t sizeBytes() const { return std::size_t(voxelCount()) * voxelBytes(type_); }
    bool empty() const { return !data_; }

    ValueMapping mapping;
    Modality modality = Modality::Unknown;
    std::string description;  ///< free text: series description, phantom name, file name
    std::string format;       ///< where it came from: "NIfTI", "DICOM series", "phantom", ...
    /// What the reader changed about the data that the user must be told, one line each (e.g. a
    /// gantry-tilted DICOM series resampled onto a regular grid). Commands print each once on
    /// stderr as "voxlight: warning: ..."; render stats list them under "warnings".
    std::vector<std::string> warnings;

    void* data() { return data_.get(); }
    const void* data() const { return data_.get(); }
    template <class T>
    T* dataAs() {
        VL_CHECK(voxelTypeOf<T>() == type_);
        return reinterpret_cast<T*>(data_.get());
    }
    template <class T>
    const T* dataAs() const {
        VL_CHECK(voxelTypeOf<T>() == type_);
        return reinterpret_cast<const T*>(data_.get());
    }
    std::size_t linearIndex(int i, int j, int k) const {
        return std::size_t(i) +
               std::size_t(geometry_.dims.x) *
                   (std::size_t(j) + std::size_t(geometry_.dims.y) * std::size_t(k));
    }

    template <class T>
    VolumeView<T> view() const {
        VolumeView<T> v;
        v.data = dataAs<T>();
        v.nx = dims().x, v.ny = dims().y, v.nz = dims().z;
        v.sy = std::size_t(v.nx);
        v.sz = std::size_t(v.nx) * std::size_t(v.ny);
        v.slope = float(mapping.slope);
        v.intercept = float(mapping.intercept);
        return v;
    }

    /// Calls f(VolumeView<T>) with the view of the native type: the way to write a type-generic hot
    /// loop.
    template <class F>
    decltype(auto) visit(F&& f) const {
        switch (type_) {
            case VoxelType::UInt8:
                return f(view<std::uint8_t>());
            case VoxelType::Int16:
                return f(view<std::int16_t>());
            case VoxelType::UInt16:
                return f(view<std::uint16_t>());
            case VoxelType::Float32:
                return f(view<float>());
        }
        throw InternalError("unknown voxel type");
    }

    /// Physical value of voxel (i,j,k) (bounds-checked with VL_DCHECK only).
    float at(int i, int j, int k) const;
    /// Trilinear physical value at a continuous index (slow path: type switch per call).
    float sampleIndex(const glm::dvec3& ijk) const;
    /// Trilinear physical value at a world position (mm, LPS).
    float sampleWorld(const glm::dvec3& p) const { return sampleIndex(geometry_.worldToIndex(p)); }

    /// Min and max physical value over all voxels (parallel scan; not cached).
    std::array<double, 2> physicalRange() const;
    /// Number of NaN/Inf voxels (float volumes only; 0 otherwise).
    std::uint64_t countNonFinite() const;

  private:
    Geometry geometry_;
    VoxelType type_ = VoxelType::UInt8;
    std::shared_ptr<std::byte> data_;  ///< owned buffer, or an adopted one (e.g. a reader's array)
};

}  // namespace voxlight::core
