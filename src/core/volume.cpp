// SPDX-License-Identifier: MIT
#include "core/volume.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <cmath>
#include <limits>
#include <ostream>
#include <sstream>

namespace voxlight::core {

std::string_view toString(VoxelType t) {
    switch (t) {
        case VoxelType::UInt8:
            return "uint8";
        case VoxelType::Int16:
            return "int16";
        case VoxelType::UInt16:
            return "uint16";
        case VoxelType::Float32:
            return "float32";
    }
    return "?";
}

std::size_t voxelBytes(VoxelType t) {
    switch (t) {
        case VoxelType::UInt8:
            return 1;
        case VoxelType::Int16:
        case VoxelType::UInt16:
            return 2;
        case VoxelType::Float32:
            return 4;
    }
    return 0;
}

std::string_view toString(Modality m) {
    switch (m) {
        case Modality::Unknown:
            return "unknown";
        case Modality::CT:
            return "CT";
        case Modality::MR:
            return "MR";
        case Modality::Synthetic:
            return "synthetic";
    }
    return "?";
}

std::array<glm::dvec3, 2> Geometry::worldBounds() const {
    glm::dvec3 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
    const glm::dvec3 last = glm::dvec3(glm::max(dims - 1, glm::ivec3(0)));
    for (int c = 0; c < 8; ++c) {
        const glm::dvec3 ijk((c & 1) ? last.x : 0.0, (c & 2) ? last.y : 0.0,
                             (c & 4) ? last.z : 0.0);
        const glm::dvec3 p = indexToWorld(ijk);
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    return {lo, hi};
}

std::string Geometry::orientationCode() const {
    // Patient-orientation letter of each axis' dominant direction, LPS world: +x=L, +y=P, +z=S.
    std::string code;
    for (int a = 0; a < 3; ++a) {
        const glm::dvec3 d = direction[a];
        int best = 0;
        for (int c = 1; c < 3; ++c)
            if (std::abs(d[c]) > std::abs(d[best])) best = c;
        static const char pos[3] = {'L', 'P', 'S'}, neg[3] = {'R', 'A', 'I'};
        code += d[best] >= 0 ? pos[best] : neg[best];
    }
    return code;
}

void Geometry::validate() const {
    VL_CHECK(dims.x >= 1 && dims.y >= 1 && dims.z >= 1);
    for (int a = 0; a < 3; ++a) VL_CHECK(std::isfinite(spacing[a]) && spacing[a] > 0.0);
    const glm::dmat3 g = glm::transpose(direction) * direction;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) VL_CHECK(std::abs(g[c][r] - (r == c ? 1.0 : 0.0)) < 1e-4);
}

std::ostream& operator<<(std::ostream& os, const Geometry& g) {
    os << g.dims.x << "x" << g.dims.y << "x" << g.dims.z << " voxels, spacing " << g.spacing.x
       << "x" << g.spacing.y << "x" << g.spacing.z << " mm, origin (" << g.origin.x << ", "
       << g.origin.y << ", " << g.origin.z << ") mm, orientation " << g.orientationCode();
    return os;
}

namespace {
void checkVolumeSize(const Geometry& geometry) {
    const glm::ivec3 d = geometry.dims;
    if (d.x < 1 || d.y < 1 || d.z < 1 || d.x > kMaxDim || d.y > kMaxDim || d.z > kMaxDim ||
        geometry.voxelCount() > kMaxVoxels) {
        std::ostringstream os;
        os << "volume size " << d.x << "x" << d.y << "x" << d.z
           << " is outside the supported range (1.." << kMaxDim << " per axis, at most "
           << kMaxVoxels << " voxels)";
        throw InputError("", "dims", os.str(), "crop or downsample the volume");
    }
}

/// A spacing outside [kMinSpacingMm, kMaxSpacingMm] is bad input (a damaged header), not a volume.
/// The limits themselves pass as a float32 header stores them (1e-4 reads back as 9.99999974e-5:
/// refused as "0.0001 is outside 0.0001..10000" before), so they carry a float's rounding.
void checkSpacing(const Geometry& g) {
    constexpr double kFloatRounding = 1e-7;  // above float32's half-ulp, 6e-8 relative
    for (int a = 0; a < 3; ++a)
        if (!(g.spacing[a] >= kMinSpacingMm * (1.0 - kFloatRounding) &&
              g.spacing[a] <= kMaxSpacingMm * (1.0 + kFloatRounding))) {
            std::ostringstream os;
            os << "voxel spacing " << g.spacing.x << " x " << g.spacing.y << " x " << g.spacing.z
               << " mm is outside " << kMinSpacingMm << ".." << kMaxSpacingMm << " mm";
            throw InputError("volume", "spacing", os.str(), "repair the header's voxel sizes");
        }
}

/// A volume whose voxels lie more than kMaxOriginSpacings of its finest spacing from the world
/// origin is refused: rendered there, its images are wrong without a sign (volume.h).
void checkOrigin(const Geometry& g) {
    double reach = 0.0;  // the largest |coordinate| of the box's eight corner voxels
    for (int c = 0; c < 8; ++c) {
        const glm::dvec3 ijk((c & 1) ? g.dims.x - 1 : 0, (c & 2) ? g.dims.y - 1 : 0,
                             (c & 4) ? g.dims.z - 1 : 0);
        const glm::dvec3 corner = g.indexToWorld(ijk);
        for (int a = 0; a < 3; ++a) reach = std::max(reach, std::abs(corner[a]));
    }
    if (!(reach <= kMaxOriginSpacings * minComponent(g.spacing))) {
        std::ostringstream os;
        os << "the voxels lie up to " << reach << " mm from the coordinate origin, more than "
           << kMaxOriginSpacings << " voxel spacings (" << minComponent(g.spacing)
           << " mm): single-precision positions there lose the voxel's fraction (origin "
           << g.origin.x << ", " << g.origin.y << ", " << g.origin.z << " mm)";
        throw InputError("volume", "origin", os.str(),
                         "move the origin nearer 0 in the file's header (its origin, offset or "
                         "position field)");
    }
}

/// A direction matrix that is not a rotation (a damaged sform/qform or space directions, found by
/// fuzz_nifti_gz) is bad input, not an internal fault: readers name the file when they rethrow.
void checkOrientation(const Geometry& g) {
    const glm::dmat3 gram = glm::transpose(g.direction) * g.direction;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            if (!(std::abs(gram[c][r] - (r == c ? 1.0 : 0.0)) < 1e-4))
                throw InputError("volume", "orientation",
                                 "axes are not orthonormal (a sheared or scaled direction matrix)",
                                 "fix the header's orientation (sform/qform, space directions)");
}
}  // namespace

Volume::Volume(const Geometry& geometry, VoxelType type) : geometry_(geometry), type_(type) {
    checkVolumeSize(geometry);
    checkSpacing(geometry);
    checkOrientation(geometry);
    checkOrigin(geometry);
    geometry_.validate();
    data_ = std::shared_ptr<std::byte>(new std::byte[sizeBytes()](),
                                       std::default_delete<std::byte[]>());
}

Volume::Volume(const Geometry& geometry, VoxelType type, std::shared_ptr<std::byte> storage)
    : geometry_(geometry), type_(type), data_(std::move(storage)) {
    checkVolumeSize(geometry);
    checkSpacing(geometry);
    checkOrientation(geometry);
    checkOrigin(geometry);
    geometry_.validate();
    VL_CHECK(data_ != nullptr);
}

float Volume::at(int i, int j, int k) const {
    VL_DCHECK(i >= 0 && j >= 0 && k >= 0 && i < dims().x && j < dims().y && k < dims().z);
    return visit([&](const auto& v) { return v.at(i, j, k); });
}

float Volume::sampleIndex(const glm::dvec3& ijk) const {
    return visit([&](const auto& v) { return v.sample(float(ijk.x), float(ijk.y), float(ijk.z)); });
}

std::array<double, 2> Volume::physicalRange() const {
    using Range = std::array<double, 2>;
    const std::size_t n = std::size_t(voxelCount());
    return visit([&](const auto& v) -> Range {
        const auto* p = v.data;
        using T = std::remove_cv_t<std::remove_pointer_t<decltype(p)>>;
        Range stored = tbb::parallel_reduce(
            tbb::blocked_range<std::size_t>(0, n, 1 << 16),
            Range{std::numeric_limits<double>::max(), -std::numeric_limits<double>::max()},
            [&](const tbb::blocked_range<std::size_t>& r, Range acc) {
                T lo = std::numeric_limits<T>::max(), hi = std::numeric_limits<T>::lowest();
                for (std::size_t i = r.begin(); i != r.end(); ++i) {
                    const T x = p[i];
                    if constexpr (std::is_floating_point_v<T>) {
                        if (!std::isfinite(x)) continue;
                    }
                    lo = x < lo ? x : lo;
                    hi = x > hi ? x : hi;
                }
                if (double(lo) <= double(hi)) {
                    acc[0] = std::min(acc[0], double(lo));
                    acc[1] = std::max(acc[1], double(hi));
                }
                return acc;
            },
            [](Range a, Range b) {
                return Range{std::min(a[0], b[0]), std::max(a[1], b[1])};
            });
        if (stored[0] > stored[1]) return Range{0.0, 0.0};  // no finite voxel
        const double a = mapping.apply(stored[0]), b = mapping.apply(stored[1]);
        return Range{std::min(a, b), std::max(a, b)};
    });
}

std::uint64_t Volume::countNonFinite() const {
    if (type_ != VoxelType::Float32) return 0;
    const float* p = dataAs<float>();
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, std::size_t(voxelCount()), 1 << 16), std::uint64_t(0),
        [&](const tbb::blocked_range<std::size_t>& r, std::uint64_t acc) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) acc += std::isfinite(p[i]) ? 0 : 1;
            return acc;
        },
        [](std::uint64_t a, std::uint64_t b) { return a + b; });
}

}  // namespace voxlight::core
