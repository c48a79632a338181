// SPDX-License-Identifier: MIT
#pragma once
// NRRD header validation before VTK's vtkNrrdReader sees a file (part of the VTK volume module).
//
// VTK 9.1's reader crashes on a missing or late `dimension`, loops forever on a detached header
// without a final newline, fills missing data with zeros and drops `space`, `space directions` and
// `space origin`. parseNrrdHeader reads the text header itself (at most kMaxNrrdHeaderBytes, ending
// at the first empty line, or at the end of a detached header) and throws InputError naming the
// file and the field for anything VTK would mishandle; checkNrrdDataSize compares the data's length
// with what the header claims; nrrdGeometry maps the space fields to voxlight's patient LPS.
//
// Accepted: dimension 3 (or 2, read as one slice), sizes 1..core::kMaxDim per axis, the VTK scalar
// types, encodings raw, gzip and (detached only) ascii, attached data or one detached data file, or
// raw slices in one file each ("data file: LIST" or "name%03d.raw first last step", as VTK reads).
// Named spaces: right-anterior-superior (RAS), left-anterior-superior (LAS), left-posterior-
// superior (LPS); scanner-xyz, 3D-right-handed and a bare `space dimension: 3` carry no anatomical
// labels and are taken as LPS (as ITK does); 3D-left-handed is taken as LAS (x, −y, z), as VTK
// groups it. Space directions must be finite, non-zero and orthogonal (within checkDirection's
// tolerance); spacing is their length, direction their unit vector, origin the space origin. Without
// space directions the NRRD orientation is undefined: voxlight then keeps VTK's reading (identity
// direction, `spacings`, the space origin as written, rows as VTK orders them).
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/volume.h"

namespace voxlight::io::detail {

/// Header bytes read at most: real headers are < 4 KiB; key/value comments may add a little.
inline constexpr std::uint64_t kMaxNrrdHeaderBytes = std::uint64_t(1) << 20;

enum class NrrdEncoding { Raw, Gzip, Ascii };

struct NrrdHeader {
    int dimension = 0;
    std::vector<std::int64_t> sizes;  ///< per axis, fastest first
    std::string type;                 ///< as written, e.g. "short"
    int typeBytes = 0;
    NrrdEncoding encoding = NrrdEncoding::Raw;
    std::uint64_t headerBytes = 0;  ///< attached data starts here
    /// Detached data: one file, or one file per slice (k) from a LIST or a "%d" pattern; empty when
    /// the data is attached after the header.
    std::vector<std::filesystem::path> dataFiles;
    bool spaceFlipsY = false;    ///< LAS / 3D-left-handed: VTK reads rows of raw data bottom-up
    glm::dmat3 spaceToLps{1.0};  ///< maps the header's space coordinates to LPS
    std::vector<glm::dvec3> spaceDirections;  ///< per axis, in space coordinates (may be empty)
    std::optional<glm::dvec3> spaceOrigin;    ///< in space coordinates
    std::vector<double> spacings;             ///< the `spacings` field (may be empty)

    std::uint64_t voxelCount() const;
};

/// Parses and validates the header of `path` (.nrrd or .nhdr); throws InputError on anything VTK
/// would crash on, hang on or misread.
NrrdHeader parseNrrdHeader(const std::filesystem::path& path);

/// Throws InputError when the data holds fewer bytes (raw) or values (ascii) than the header
/// claims. Gzip data is checked after decoding (VTK reports a short stream).
void checkNrrdDataSize(const NrrdHeader& h, const std::filesystem::path& path);

/// Spacing, origin and direction in patient LPS (dims left for the caller).
core::Geometry nrrdGeometry(const NrrdHeader& h, const std::filesystem::path& path);

}  // namespace voxlight::io::detail
