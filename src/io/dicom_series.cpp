// SPDX-License-Identifier: MIT
#include "io/dicom_series.h"

#include "io/dicom_module.h"

// GDCM stays in this translation unit: its headers clash with OpenImageIO's (see BUILD-NOTES.md).
#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmPixelFormat.h>
#include <gdcmScanner.h>
#include <gdcmTag.h>
#include <gdcmTrace.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <system_error>
#include <vector>

namespace voxlight::io::detail {
namespace {

namespace fs = std::filesystem;

// --- Tolerances
// -------------------------------------------------------------------------------------------------
/// Image Orientation (Patient) cosines must be unit length and orthogonal to this accuracy. DS
/// values carry up to 16 characters, so honest rounding stays below 1e-6; beyond 1e-3 the tag is
/// corrupt, not rounded.
constexpr double kCosineTol = 1e-3;
/// Two slices belong to the same orientation if every cosine agrees to this; scanners write the
/// same IOP string to every slice of a series, while a 3-plane localizer differs by O(1).
constexpr double kOrientationMatchTol = 1e-4;
/// Pixel Spacing must agree across slices to this relative accuracy (rounding of DS strings only).
constexpr double kPixelSpacingMatchRel = 1e-4;
/// Slices whose positions along the normal differ by less than this (mm) are at the same place: no
/// CT/MR slice spacing comes near 1 µm, and positions are written with ≥ 3 decimals.
constexpr double kDuplicateTolMm = 1e-3;
/// A slice may sit at most this fraction of the slice spacing off the uniform grid through the
/// first and last slice. Covers positions rounded to 0.1 mm (DS written with one decimal) for
/// slices ≥ 1 mm; a tenth of a slice is below what trilinear sampling can show. Beyond it the
/// spacing is variable: the stack is resampled (slice_stack.h), or refused under --strict-geometry.
constexpr double kMaxGridOffset = 0.1;
/// A gap within this of an integer multiple k ≥ 2 of the typical spacing is reported as k−1 missing
/// slices rather than as variable spacing (missing files is the common cause of such gaps).
constexpr double kMissingSliceRatioTol = 0.15;
/// Slice positions may drift sideways (perpendicular to the normal) by at most this fraction of the
/// finest pixel spacing over the whole series; more is a sheared grid (gantry tilt) that a Volume
/// (orthonormal D) cannot hold: it is resampled (slice_stack.h), or refused under
/// --strict-geometry.
constexpr double kMaxShearPixels = 0.2;
/// Image Position (Patient) beyond this far from the origin (mm; 100 m, where a scanner's frame
/// spans metres) is damaged data: such positions made the slice geometry overflow (a position of
/// 1e300 mm gave NaN gaps and grid sizes no integer holds).
constexpr double kMaxPatientCoordinateMm = 1e5;
/// Largest magnitude the rescale may give a stored value (bits allocated at its extreme): 1e15 is
/// far past any physical quantity a scanner stores (HU, MR units, PET Bq/ml) yet leaves a 32-bit
/// PET slope of 1e5 alone.
constexpr double kMaxRescaledMagnitude = 1e15;
/// Rescale slope/intercept count as identical across slices to this relative accuracy.
constexpr double kRescaleMatchRel = 1e-9;

/// Selects the group of files without a Series Instance UID (anonymised data often blanks it).
constexpr const char* kNoUidSelector = "none";

// --- DICOM tags read by the header scan
// -------------------------------------------------------------------------
const gdcm::Tag kTagModality(0x0008, 0x0060);
const gdcm::Tag kTagSeriesDescription(0x0008, 0x103e);
const gdcm::Tag kTagSliceThickness(0x0018, 0x0050);
const gdcm::Tag kTagSeriesUid(0x0020, 0x000e);
const gdcm::Tag kTagSeriesNumber(0x0020, 0x0011);
const gdcm::Tag kTagFrameOfReferenceUid(0x0020, 0x0052);
const gdcm::Tag kTagInstanceNumber(0x0020, 0x0013);
const gdcm::Tag kTagPosition(0x0020, 0x0032);
const gdcm::Tag kTagOrientation(0x0020, 0x0037);
const gdcm::Tag kTagSamplesPerPixel(0x0028, 0x0002);
const gdcm::Tag kTagNumberOfFrames(0x0028, 0x0008);
const gdcm::Tag kTagRows(0x0028, 0x0010);
const gdcm::Tag kTagColumns(0x0028, 0x0011);
const gdcm::Tag kTagPixelSpacing(0x0028, 0x0030);
const gdcm::Tag kTagBitsAllocated(0x0028, 0x0100);
const gdcm::Tag kTagPixelRepresentation(0x0028, 0x0103);
const gdcm::Tag kTagRescaleIntercept(0x0028, 0x1052);
const gdcm::Tag kTagRescaleSlope(0x0028, 0x1053);

/// GDCM reports problems by returning false and printing to std::cerr; voxlight reports them as
/// InputError, so the printing is switched off once (the flags are process-wide).
void silenceGdcm() {
    static std::once_flag once;
    std::call_once(once, [] {
        gdcm::Trace::DebugOff();
        gdcm::Trace::WarningOff();
        gdcm::Trace::ErrorOff();
    });
}

std::string str(const fs::path& p) { return p.string(); }

std::string trim(std::string_view s) {
    const auto isPad = [](char c) {
        return c == ' ' || c == '\0' || c == '\t' || c == '\r' || c == '\n';
    };
    while (!s.empty() && isPad(s.front())) s.remove_prefix(1);
    while (!s.empty() && isPad(s.back())) s.remove_suffix(1);
    return std::string(s);
}

std::string formatNumber(double v, int precision = 6) {
    std::ostringstream os;
    os.precision(precision);
    os << v;
    return os.str();
}

std::string formatPoint(const glm::dvec3& p) {
    return "(" + formatNumber(p.x, 8) + ", " + formatNumber(p.y, 8) + ", " + formatNumber(p.z, 8) +
           ")";
}

/// Parses a DS/IS multi-value string ("1\0\0\0\1\0") into numbers; throws InputError naming the
/// file and tag.
std::vector<double> parseNumbers(const std::string& value, const fs::path& file,
                                 const char* field) {
    std::vector<double> out;
    std::size_t start = 0;
    while (start <= value.size()) {
        std::size_t end = value.find('\\', start);
        if (end == std::string::npos) end = value.size();
        std::string item = trim(std::string_view(value).substr(start, end - start));
        if (!item.empty() && item.front() == '+') item.erase(0, 1);
        double v = 0.0;
        const auto [ptr, ec] = std::from_chars(item.data(), item.data() + item.size(), v);
        if (item.empty() || ec != std::errc() || ptr != item.data() + item.size() ||
            !std::isfinite(v))
            throw InputError(str(file), field,
                             "value \"" + value + "\" is not a list of finite numbers",
                             "the file is damaged; re-export the series from the PACS or scanner");
        out.push_back(v);
        start = end + 1;
    }
    return out;
}

/// Header fields of one slice file, as read by the scan.
struct SliceHeader {
    fs::path file;
    std::string seriesUid, description, modality, seriesNumber, frameOfReference;
    int rows = 0, columns = 0, bitsAllocated = 0, pixelRepresentation = 0, samplesPerPixel = 1,
        frames = 1;
    bool hasPosition = false, hasOrientation = false, hasPixelSpacing = false;
    glm::dvec3 position{0.0};
    std::array<double, 6> orientation{};
    glm::dvec2 pixelSpacing{1.0};  ///< DICOM order: [row spacing (Δj), column spacing (Δi)]
    double sliceThickness = 0.0;
    double slope = 1.0, intercept = 0.0;
    double along = 0.0;  ///< position projected on the slice normal (mm), filled when sorting
};

/// What the framing check saw of a file's top-level Pixel Data element, for checkPixelData().
struct PixelDataInfo {
    bool followed = false;        ///< the walk reached the end of the data set (else: unknown)
    bool present = false;         ///< (7FE0,0010) at the top level
    bool encapsulated = false;    ///< undefined length: a basic offset table item, then fragments
    std::string syntax;           ///< Transfer Syntax UID ("" = no meta header: implicit VR LE)
    std::string vr;               ///< explicit VR of the element ("" when implicit)
    std::uint64_t length = 0;     ///< native: the value length in bytes
    std::uint64_t fragments = 0;  ///< encapsulated: fragments after the basic offset table
    std::string firstFragment;    ///< encapsulated: the first fragment's first bytes (≤ 4 KiB)
    std::uint64_t firstFragmentLength = 0;
};

/// Step 0: framing check. Debian's GDCM is built with assertions on and *aborts the process*
/// (assert(is.good())) on a file cut short inside its header, and silently accepts one cut inside
/// the pixel data. So before GDCM sees a file, walk its data elements — tag and length only, no
/// values interpreted except the transfer syntax — and refuse a file whose elements run past its
/// end. Anything the walk cannot follow (deflated data sets, UN sequences, odd VRs) is left to GDCM
/// rather than refused.
class FramingCheck {
  public:
    /// Throws InputError naming the file and the element that runs past its end; silent when the
    /// framing is complete or cannot be followed.
    static PixelDataInfo check(const fs::path& file) {
        FramingCheck c(file);
        const std::string cut = c.ok_ ? c.run() : std::string("cannot be opened");
        if (!cut.empty())
            throw InputError(str(file), c.field_, "is truncated or damaged: " + cut,
                             "copy the series again, or remove this file from the folder");
        return c.pixelData_;
    }

  private:
    static constexpr std::uint32_t kUndefinedLength = 0xffffffffu;

    explicit FramingCheck(const fs::path& file) : in_(file, std::ios::binary) {
        std::error_code ec;
        size_ = fs::file_size(file, ec);
        ok_ = bool(in_) && !ec;
    }

    bool read(void* dst, std::size_t n) {
        in_.read(static_cast<char*>(dst), std::streamsize(n));
        return std::size_t(in_.gcount()) == n;
    }
    std::uint16_t u16(const unsigned char* p) const {
        return bigEndian_ ? std::uint16_t(p[0] << 8 | p[1]) : std::uint16_t(p[0] | p[1] << 8);
    }
    std::uint32_t u32(const unsigned char* p) const {
        return bigEndian_ ? std::uint32_t(p[0]) << 24 | std::uint32_t(p[1]) << 16 |
                                std::uint32_t(p[2]) << 8 | p[3]
                          : std::uint32_t(p[3]) << 24 | std::uint32_t(p[2]) << 16 |
                                std::uint32_t(p[1]) << 8 | p[0];
    }
    static std::string tagName(std::uint16_t g, std::uint16_t e) {
        char buf[16];
        std::snprintf(buf, sizeof buf, "(%04X,%04X)", unsigned(g), unsigned(e));
        return buf;
    }
    std::string cutShort(std::uint16_t g, std::uint16_t e, std::uint64_t need, std::uint64_t at) {
        field_ = g == 0x7fe0 && e == 0x0010 ? std::string("PixelData") : tagName(g, e);
        return "element " + tagName(g, e) + " needs " + std::to_string(need) + " bytes at offset " +
               std::to_string(at) + " but the file is only " + std::to_string(size_) +
               " bytes long";
    }

    std::string run() {
        // File meta information (Part 10): "DICM" at 128, then group 0002 in explicit VR little
        // endian.
        std::uint64_t pos = 0;
        char magic[4] = {};
        in_.seekg(128);
        const bool part10 = size_ >= 132 && read(magic, 4) && std::memcmp(magic, "DICM", 4) == 0;
        std::string syntax;
        if (part10) {
            pos = 132;
            while (true) {
                unsigned char h[8];
                in_.seekg(std::streamoff(pos));
                if (pos + 8 > size_ || !read(h, 8)) return "the file ends inside its meta header";
                if (u16(h) != 0x0002) break;
                // GDCM asserts on an invalid VR in the meta header, which is always explicit.
                if (!isVr(h[4], h[5])) return badVr(0x0002, u16(h + 2), h + 4);
                std::uint32_t len = 0;
                std::uint64_t head = 8;
                if (longLength(h[4], h[5])) {
                    unsigned char l[4];
                    if (pos + 12 > size_ || !read(l, 4))
                        return "the file ends inside its meta header";
                    len = u32(l), head = 12;
                } else {
                    len = u16(h + 6);
                }
                if (len == kUndefinedLength || pos + head + len > size_)
                    return cutShort(0x0002, u16(h + 2), len, pos + head);
                if (u16(h + 2) == 0x0010 && len < 128) {  // Transfer Syntax UID
                    syntax.resize(len);
                    if (!read(syntax.data(), len)) return "the file ends inside its meta header";
                    syntax = trim(syntax);
                }
                pos += head + len;
            }
        }
        // Data set encoding from the transfer syntax; bare data sets: guess from the first
        // element's VR bytes.
        pixelData_.syntax = syntax;
        if (syntax == "1.2.840.10008.1.2.1.99")
            return {};  // deflated: GDCM inflates, nothing to walk
        bigEndian_ = syntax == "1.2.840.10008.1.2.2";
        if (part10) {
            explicitVr_ = syntax != "1.2.840.10008.1.2";
        } else {
            unsigned char h[6];
            in_.seekg(0);
            explicitVr_ = read(h, 6) && std::isupper(h[4]) && std::isupper(h[5]);
        }
        return walk(pos);
    }

    /// One of the 34 value representations of PS3.5 Table 6.2-1.
    static bool isVr(unsigned char a, unsigned char b) {
        static const char* kVrs[] = {"AE", "AS", "AT", "CS", "DA", "DS", "DT", "FD", "FL",
                                     "IS", "LO", "LT", "OB", "OD", "OF", "OL", "OV", "OW",
                                     "PN", "SH", "SL", "SQ", "SS", "ST", "SV", "TM", "UC",
                                     "UI", "UL", "UN", "UR", "US", "UT", "UV"};
        for (const char* v : kVrs)
            if (a == v[0] && b == v[1]) return true;
        return false;
    }
    std::string badVr(std::uint16_t g, std::uint16_t e, const unsigned char* vr) {
        field_ = tagName(g, e);
        std::string shown;
        for (int i = 0; i < 2; ++i) {
            char buf[8];
            std::snprintf(buf, sizeof buf, std::isprint(vr[i]) ? "%c" : "\\x%02X", vr[i]);
            shown += buf;
        }
        return "element " + tagName(g, e) + " has the invalid value representation \"" + shown +
               "\" (explicit VR data must name one of DICOM's VRs)";
    }
    static bool longLength(unsigned char a, unsigned char b) {
        static const char* kLong[] = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ",
                                      "SV", "UC", "UN", "UR", "UT", "UV"};
        for (const char* v : kLong)
            if (a == v[0] && b == v[1]) return true;
        return false;
    }

    /// Image attributes GDCM reads with gdcm::Attribute<>, which asserts (aborts) when the file's VR
    /// differs from the dictionary's, and the binary ones' value length (US: VM 1).
    static const char* expectedVr(std::uint16_t g, std::uint16_t e, std::uint32_t* binaryLength) {
        struct Known {
            std::uint16_t g, e;
            const char* vr;
            std::uint32_t length;  ///< exact length of a binary value, 0 for strings
        };
        static const Known kKnown[] = {
            {0x0028, 0x0002, "US", 2}, {0x0028, 0x0004, "CS", 0}, {0x0028, 0x0006, "US", 2},
            {0x0028, 0x0008, "IS", 0}, {0x0028, 0x0010, "US", 2}, {0x0028, 0x0011, "US", 2},
            {0x0028, 0x0030, "DS", 0}, {0x0028, 0x0100, "US", 2}, {0x0028, 0x0101, "US", 2},
            {0x0028, 0x0102, "US", 2}, {0x0028, 0x0103, "US", 2}, {0x0028, 0x1050, "DS", 0},
            {0x0028, 0x1051, "DS", 0}, {0x0028, 0x1052, "DS", 0}, {0x0028, 0x1053, "DS", 0},
            {0x0020, 0x0032, "DS", 0}, {0x0020, 0x0037, "DS", 0}, {0x0018, 0x0050, "DS", 0},
            {0x0018, 0x0088, "DS", 0}, {0x0020, 0x0013, "IS", 0}, {0x0008, 0x0060, "CS", 0},
            {0x0020, 0x000e, "UI", 0}, {0x0008, 0x0016, "UI", 0}, {0x0028, 0x0034, "IS", 0},
        };
        for (const Known& k : kKnown)
            if (k.g == g && k.e == e) {
                *binaryLength = k.length;
                return k.vr;
            }
        return nullptr;
    }
    /// VR and length of a top-level image attribute: a mismatch is refused (GDCM would abort).
    std::string checkAttribute(std::uint16_t g, std::uint16_t e, const unsigned char* vr,
                               std::uint32_t len) {
        std::uint32_t binaryLength = 0;
        const char* expected = expectedVr(g, e, &binaryLength);
        if (!expected) return {};
        if (vr && !(vr[0] == expected[0] && vr[1] == expected[1]) &&
            !(vr[0] == 'U' && vr[1] == 'N')) {
            field_ = tagName(g, e);
            return "element " + tagName(g, e) + " has value representation " +
                   std::string(reinterpret_cast<const char*>(vr), 2) + ", DICOM defines " +
                   expected;
        }
        if (binaryLength && len != binaryLength) {
            field_ = tagName(g, e);
            return "element " + tagName(g, e) + " (" + expected + ") is " + std::to_string(len) +
                   " bytes long, expected " + std::to_string(binaryLength);
        }
        return {};
    }

    /// Outcome of walking a part: complete, cut short / overrunning (a message), or not followable
    /// here.
    struct Result {
        bool followable = true;
        std::string problem;  ///< non-empty: truncated or damaged
        bool stop() const { return !followable || !problem.empty(); }
    };
    static Result unfollowable() { return {false, {}}; }
    Result damaged(std::uint16_t g, std::uint16_t e, std::uint64_t need, std::uint64_t at,
                   std::uint64_t end) {
        if (end == size_) return {true, cutShort(g, e, need, at)};
        field_ = tagName(g, e);
        return {true, "element " + tagName(g, e) + " declares " + std::to_string(need) +
                          " bytes at offset " + std::to_string(at) +
                          ", beyond the end of its enclosing item at offset " +
                          std::to_string(end)};
    }
    Result neverClosed(std::uint16_t g, std::uint16_t e, std::uint64_t opened) {
        field_ = g == 0x7fe0 && e == 0x0010 ? std::string("PixelData") : tagName(g, e);
        return {true, "the file ends inside element " + tagName(g, e) +
                          " (undefined length, opened at offset " + std::to_string(opened) +
                          ", never closed by its delimiter)"};
    }
    /// Reads an 8-byte element or item header at `pos`; false if it does not fit before `end`.
    bool header(std::uint64_t pos, std::uint64_t end, unsigned char* h) {
        in_.clear();
        in_.seekg(std::streamoff(pos));
        return pos + 8 <= end && read(h, 8);
    }
    static constexpr int kMaxNesting = 32;  ///< deeper nesting than any real data set: give up

    /// Walks the elements of a data set in [pos, end). With `delimited` (an undefined-length item)
    /// it ends at its item delimiter. Sequences are entered (explicit VR, or undefined length);
    /// other values are skipped after checking that they fit inside `end`.
    Result walkDataSet(std::uint64_t& pos, std::uint64_t end, bool delimited, int depth) {
        if (depth > kMaxNesting) return unfollowable();
        while (pos < end) {
            unsigned char h[12];
            if (!header(pos, end, h))
                return {true,
                        "the file ends inside an element header at offset " + std::to_string(pos)};
            const std::uint16_t g = u16(h), e = u16(h + 2);
            if (g == 0xfffe) {
                pos += 8;
                if (e == 0xe00d && delimited) return {};
                if (e == 0xe00d) continue;  // stray item delimiter: harmless
                // An item or sequence delimiter where an element belongs: GDCM asserts on it.
                field_ = tagName(g, e);
                return {true, "item tag " + tagName(g, e) + " at offset " +
                                  std::to_string(pos - 8) + " where a data element belongs"};
            }
            std::uint32_t len = 0;
            std::uint64_t head = 8;
            bool sequence = false;
            if (!explicitVr_) {
                len = u32(h + 4);
                sequence = len == kUndefinedLength;  // implicit: only undefined lengths are known
            } else if (!isVr(h[4], h[5])) {
                // Invalid VR in explicit data: GDCM either guesses or asserts; refuse the file.
                return {true, badVr(g, e, h + 4)};
            } else if (longLength(h[4], h[5])) {
                if (pos + 12 > end || !read(h + 8, 4))
                    return {true, "the file ends inside element " + tagName(g, e)};
                len = u32(h + 8), head = 12;
                if (h[4] == 'U' && h[5] == 'N' && len == kUndefinedLength) return unfollowable();
                sequence = h[4] == 'S' && h[5] == 'Q';
            } else {
                len = u16(h + 6);
            }
            const std::uint64_t start = pos;
            pos += head;
            const bool pixelData = depth == 0 && g == 0x7fe0 && e == 0x0010;
            if (depth == 0 && len != kUndefinedLength) {
                const std::string bad = checkAttribute(g, e, explicitVr_ ? h + 4 : nullptr, len);
                if (!bad.empty()) return {true, bad};
            }
            if (pixelData) {
                pixelData_.present = true;
                pixelData_.encapsulated = len == kUndefinedLength;
                pixelData_.length = len;
                if (explicitVr_) pixelData_.vr = std::string(reinterpret_cast<char*>(h + 4), 2);
            }
            Result r;
            if (len == kUndefinedLength) {
                r = sequence ? walkItems(pos, end, true, depth + 1)
                             : walkFragments(pos, end, pixelData ? &pixelData_ : nullptr);
                if (r.problem == "open") r = neverClosed(g, e, start);
            } else if (pos + len > end) {
                return damaged(g, e, len, pos, end);
            } else if (sequence) {
                std::uint64_t sub = pos;
                r = walkItems(sub, pos + len, false, depth + 1);
                pos += len;
            } else {
                pos += len;
            }
            if (r.stop()) return r;
        }
        return delimited ? Result{true, "open"} : Result{};
    }

    /// Items of a sequence in [pos, end); with `delimited`, up to the sequence delimiter.
    Result walkItems(std::uint64_t& pos, std::uint64_t end, bool delimited, int depth) {
        while (pos < end) {
            unsigned char h[8];
            if (!header(pos, end, h))
                return {true,
                        "the file ends inside an item header at offset " + std::to_string(pos)};
            const std::uint16_t g = u16(h), e = u16(h + 2);
            const std::uint32_t len = u32(h + 4);
            pos += 8;
            if (g != 0xfffe) return unfollowable();
            if (e == 0xe0dd) {
                if (delimited) return {};
                continue;
            }
            if (e != 0xe000) return unfollowable();
            Result r;
            if (len == kUndefinedLength) {
                r = walkDataSet(pos, end, true, depth + 1);
                if (r.problem == "open") r = neverClosed(g, e, pos);
            } else if (pos + len > end) {
                return damaged(g, e, len, pos, end);
            } else {
                std::uint64_t sub = pos;
                r = walkDataSet(sub, pos + len, false, depth + 1);
                pos += len;
            }
            if (r.stop()) return r;
        }
        return delimited ? Result{true, "open"} : Result{};
    }

    /// Fragments of encapsulated pixel data (items holding compressed bytes) up to the delimiter;
    /// with `info`, counts them and keeps the head of the first after the basic offset table.
    Result walkFragments(std::uint64_t& pos, std::uint64_t end, PixelDataInfo* info) {
        std::uint64_t items = 0;
        while (pos < end) {
            unsigned char h[8];
            if (!header(pos, end, h))
                return {true,
                        "the file ends inside a fragment header at offset " + std::to_string(pos)};
            const std::uint16_t g = u16(h), e = u16(h + 2);
            const std::uint32_t len = u32(h + 4);
            pos += 8;
            if (g == 0xfffe && e == 0xe0dd) return {};
            if (info && (g != 0xfffe || e != 0xe000 || len == kUndefinedLength || len % 2 ||
                         (items == 0 && len % 4))) {
                // The image's own fragments: GDCM's repairs of odd or shifted items assert
                // (SequenceOfFragments::ReadValue), so a malformed one is refused here.
                field_ = "PixelData";
                return {true, "the encapsulated pixel data holds a malformed " +
                                  std::string(items == 0 ? "basic offset table" : "fragment") +
                                  " at offset " + std::to_string(pos - 8) + ": " + tagName(g, e) +
                                  " of length " + std::to_string(len) +
                                  " (items must be (FFFE,E000) of even length" +
                                  (items == 0 ? ", the offset table a multiple of 4" : "") + ")"};
            }
            if (g != 0xfffe || e != 0xe000 || len == kUndefinedLength) return unfollowable();
            if (pos + len > end) return damaged(0x7fe0, 0x0010, len, pos, end);
            if (info && items++ > 0 && info->fragments++ == 0) {
                info->firstFragmentLength = len;
                info->firstFragment.resize(std::min<std::uint64_t>(len, 4096));
                if (!read(info->firstFragment.data(), info->firstFragment.size()))
                    return {true,
                            "the file ends inside a fragment at offset " + std::to_string(pos)};
            }
            pos += len;
        }
        return {true, "open"};
    }

    std::string walk(std::uint64_t pos) {
        const Result r = walkDataSet(pos, size_, false, 0);
        pixelData_.followed = r.followable && r.problem.empty();
        return r.followable ? r.problem : std::string();
    }

    std::ifstream in_;
    std::uint64_t size_ = 0;
    bool ok_ = false, bigEndian_ = false, explicitVr_ = true;
    std::string field_;  ///< the element cut short, for InputError::field
    PixelDataInfo pixelData_;
};

/// Transfer syntaxes GDCM decodes: native ones, and the encapsulated ones with the codec family.
enum class Codec { Native, Jpeg, JpegLs, Jpeg2000, Rle, Unknown };
Codec codecOf(const std::string& syntax) {
    static const std::map<std::string, Codec> kSyntaxes = {
        {"", Codec::Native},  // no meta header: implicit VR little endian
        {"1.2.840.10008.1.2", Codec::Native},
        {"1.2.840.10008.1.2.1", Codec::Native},
        {"1.2.840.10008.1.2.2", Codec::Native},
        {"1.2.840.10008.1.2.1.99", Codec::Native},
        {"1.2.840.10008.1.2.4.50", Codec::Jpeg},
        {"1.2.840.10008.1.2.4.51", Codec::Jpeg},
        {"1.2.840.10008.1.2.4.57", Codec::Jpeg},
        {"1.2.840.10008.1.2.4.70", Codec::Jpeg},
        {"1.2.840.10008.1.2.4.80", Codec::JpegLs},
        {"1.2.840.10008.1.2.4.81", Codec::JpegLs},
        {"1.2.840.10008.1.2.4.90", Codec::Jpeg2000},
        {"1.2.840.10008.1.2.4.91", Codec::Jpeg2000},
        {"1.2.840.10008.1.2.5", Codec::Rle},
    };
    const auto it = kSyntaxes.find(syntax);
    return it == kSyntaxes.end() ? Codec::Unknown : it->second;
}

std::uint32_t be32(const std::string& s, std::size_t at) {
    const auto b = [&](std::size_t i) {
        return std::uint32_t(static_cast<unsigned char>(s[at + i]));
    };
    return b(0) << 24 | b(1) << 16 | b(2) << 8 | b(3);
}
std::uint16_t be16(const std::string& s, std::size_t at) {
    return std::uint16_t(static_cast<unsigned char>(s[at]) << 8 |
                         static_cast<unsigned char>(s[at + 1]));
}

/// Pixel data checked against the image attributes before GDCM decodes it: the value length of
/// native data against rows × columns × samples × bits × frames (GDCM's RAW codec reads past a
/// short one), the transfer syntax against the codecs GDCM has, and the first fragment's own image
/// size (JPEG 2000 SIZ, JPEG/JPEG-LS SOF, RLE header) against Rows/Columns: a damaged codestream
/// claiming a huge image makes OpenJPEG allocate gigabytes before it fails.
void checkPixelData(const SliceHeader& h, const PixelDataInfo& pd) {
    if (!pd.followed) return;  // the framing walk could not follow the file: GDCM decides
    const std::string src = str(h.file);
    const std::string fix = "the file is damaged; copy the series again or re-export it";
    if (!pd.present)
        throw InputError(src, "PixelData", "the image has no Pixel Data element (7FE0,0010)", fix);
    const Codec codec = codecOf(pd.syntax);
    if (codec == Codec::Unknown)
        throw InputError(src, "TransferSyntaxUID",
                         "\"" + pd.syntax + "\" is not a transfer syntax GDCM decodes",
                         "convert the file with gdcmconv --raw (or dcmdjpeg) first");
    const std::uint64_t bytesPerSample = std::uint64_t(std::max(h.bitsAllocated, 0) + 7) / 8;
    const std::uint64_t pixels = std::uint64_t(std::max(h.rows, 0)) *
                                 std::uint64_t(std::max(h.columns, 0)) *
                                 std::uint64_t(std::max(h.samplesPerPixel, 1));
    const std::uint64_t frames = std::uint64_t(std::max(h.frames, 1));
    if (codec == Codec::Native) {
        if (pd.encapsulated)
            throw InputError(src, "PixelData",
                             "is encapsulated (compressed fragments) but the transfer syntax " +
                                 pd.syntax + " says uncompressed",
                             fix);
        if (!pd.vr.empty() && pd.vr != "OB" && pd.vr != "OW" && pd.vr != "UN")
            throw InputError(src, "PixelData",
                             "has value representation " + pd.vr + ", expected OB or OW", fix);
        const std::uint64_t need = pixels * bytesPerSample * frames;
        if (pd.length < need)
            throw InputError(src, "PixelData",
                             "holds " + std::to_string(pd.length) + " bytes but " +
                                 std::to_string(h.columns) + "x" + std::to_string(h.rows) +
                                 " pixels of " + std::to_string(h.bitsAllocated) + " bits (" +
                                 std::to_string(frames) + " frame(s), " +
                                 std::to_string(std::max(h.samplesPerPixel, 1)) +
                                 " sample(s)) need " + std::to_string(need),
                             "the file is truncated or damaged; copy the series again");
        return;
    }
    if (!pd.encapsulated)
        throw InputError(src, "PixelData",
                         "is not encapsulated (a plain value of " + std::to_string(pd.length) +
                             " bytes) but the transfer syntax " + pd.syntax + " is compressed",
                         fix);
    if (pd.fragments == 0)
        throw InputError(src, "PixelData", "holds no compressed fragment after its offset table",
                         fix);
    const std::string& f = pd.firstFragment;
    const auto mismatch = [&](const char* what, std::uint64_t width, std::uint64_t height,
                              std::uint64_t components) {
        if (width == std::uint64_t(h.columns) && height == std::uint64_t(h.rows) &&
            components == std::uint64_t(std::max(h.samplesPerPixel, 1)))
            return;
        throw InputError(src, "PixelData",
                         std::string("the ") + what + " codestream is " + std::to_string(width) +
                             "x" + std::to_string(height) + " with " + std::to_string(components) +
                             " component(s) but the header says " + std::to_string(h.columns) +
                             "x" + std::to_string(h.rows) + " with " +
                             std::to_string(std::max(h.samplesPerPixel, 1)),
                         fix);
    };
    if (codec == Codec::Jpeg2000) {
        // The codestream (possibly inside JP2 boxes) starts with SOC FF4F and SIZ FF51.
        const std::size_t at = f.find("\xff\x4f\xff\x51");
        if (at == std::string::npos || at + 4 + 38 > f.size())
            throw InputError(src, "PixelData",
                             "the first fragment holds no JPEG 2000 codestream header (SOC, SIZ)",
                             fix);
        const std::size_t siz = at + 4;  // Lsiz
        const std::uint64_t xsiz = be32(f, siz + 4), ysiz = be32(f, siz + 8);
        const std::uint64_t xo = be32(f, siz + 12), yo = be32(f, siz + 16);
        const std::uint64_t xt = be32(f, siz + 20), yt = be32(f, siz + 24);
        const std::uint64_t xto = be32(f, siz + 28), yto = be32(f, siz + 32);
        const std::uint64_t csiz = be16(f, siz + 36);
        if (xo >= xsiz || yo >= ysiz || xt == 0 || yt == 0 || xto > xo || yto > yo ||
            be16(f, siz) != 38 + 3 * csiz)
            throw InputError(src, "PixelData",
                             "the JPEG 2000 image header (SIZ) is inconsistent (image " +
                                 std::to_string(xsiz) + "x" + std::to_string(ysiz) + ", offset " +
                                 std::to_string(xo) + "," + std::to_string(yo) + ", tiles " +
                                 std::to_string(xt) + "x" + std::to_string(yt) + ")",
                             fix);
        mismatch("JPEG 2000", xsiz - xo, ysiz - yo, csiz);
        const std::uint64_t tiles = ((xsiz - xto + xt - 1) / xt) * ((ysiz - yto + yt - 1) / yt);
        if (tiles > 65535)
            throw InputError(src, "PixelData",
                             "the JPEG 2000 codestream claims " + std::to_string(tiles) +
                                 " tiles (the format allows 65535)",
                             fix);
        if (at + 4 + 38 + 3 * csiz <= f.size())
            for (std::uint64_t c = 0; c < csiz; ++c) {
                const std::size_t comp = siz + 38 + 3 * c;
                const unsigned bits = (static_cast<unsigned char>(f[comp]) & 0x7f) + 1;
                if (bits > 38 || static_cast<unsigned char>(f[comp + 1]) == 0 ||
                    static_cast<unsigned char>(f[comp + 2]) == 0)
                    throw InputError(src, "PixelData",
                                     "the JPEG 2000 component header (SIZ) is invalid", fix);
            }
    } else if (codec == Codec::Jpeg || codec == Codec::JpegLs) {
        // SOI, then markers up to the frame header (SOFn, or SOF55 for JPEG-LS).
        if (f.size() < 4 || be16(f, 0) != 0xffd8)
            throw InputError(src, "PixelData",
                             "the first fragment does not start a JPEG stream (no SOI marker)",
                             fix);
        std::size_t p = 2;
        while (p + 4 <= f.size()) {
            if (static_cast<unsigned char>(f[p]) != 0xff) break;
            const unsigned marker = be16(f, p);
            const std::size_t len = be16(f, p + 2);
            const bool sof = (marker >= 0xffc0 && marker <= 0xffcf && marker != 0xffc4 &&
                              marker != 0xffc8 && marker != 0xffcc) ||
                             marker == 0xfff7;
            if (sof) {
                if (p + 10 > f.size()) break;
                const std::uint64_t height = be16(f, p + 5), width = be16(f, p + 7);
                const std::uint64_t comps = static_cast<unsigned char>(f[p + 9]);
                if (height != 0)
                    mismatch(codec == Codec::Jpeg ? "JPEG" : "JPEG-LS", width, height, comps);
                return;
            }
            if (len < 2) break;
            p += 2 + len;
        }
        // No frame header within the first 4 KiB: unusual but not proof of damage; GDCM decides.
    } else if (codec == Codec::Rle) {
        // RLE header: 16 little-endian uint32, the segment count (1..15) and their offsets.
        if (f.size() < 64)
            throw InputError(src, "PixelData",
                             "the RLE fragment is shorter than its 64-byte header", fix);
        const auto le32 = [&](std::size_t i) {
            const auto b = [&](std::size_t k) {
                return std::uint32_t(static_cast<unsigned char>(f[4 * i + k]));
            };
            return b(0) | b(1) << 8 | b(2) << 16 | b(3) << 24;
        };
        const std::uint32_t segments = le32(0);
        const std::uint64_t expected =
            std::uint64_t(std::max(h.samplesPerPixel, 1)) * bytesPerSample;
        if (segments != expected)
            throw InputError(src, "PixelData",
                             "the RLE header lists " + std::to_string(segments) + " segments; " +
                                 std::to_string(h.bitsAllocated) + "-bit pixels need " +
                                 std::to_string(expected),
                             fix);
        std::uint64_t previous = 0;
        for (std::uint32_t i = 1; i <= segments && i < 16; ++i) {
            const std::uint64_t off = le32(i);
            if (off < 64 || off <= previous || off >= pd.firstFragmentLength)
                throw InputError(src, "PixelData",
                                 "the RLE header's segment offset " + std::to_string(off) +
                                     " lies outside the fragment of " +
                                     std::to_string(pd.firstFragmentLength) + " bytes",
                                 fix);
            previous = off;
        }
    }
}

std::vector<fs::path> listFiles(const fs::path& dir) {
    std::vector<fs::path> files;
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
        std::error_code fec;
        if (it->is_regular_file(fec)) files.push_back(it->path());
    }
    if (ec)
        throw InputError(str(dir), "", "cannot list the folder: " + ec.message(),
                         "check that it exists and is readable");
    std::sort(files.begin(), files.end());
    return files;
}

/// Step 1: header scan of the candidate files with gdcm::Scanner (reads only the tags up to
/// (0028,1053), never the pixel data). Files that look like DICOM but cannot be parsed are
/// reported, not skipped: they are usually truncated slices of the series.
std::vector<SliceHeader> scanHeaders(const std::vector<fs::path>& candidates) {
    gdcm::Scanner scanner;
    for (const gdcm::Tag& t :
         {kTagModality, kTagSeriesDescription, kTagSliceThickness, kTagSeriesUid, kTagSeriesNumber,
          kTagFrameOfReferenceUid, kTagInstanceNumber, kTagPosition, kTagOrientation,
          kTagSamplesPerPixel, kTagNumberOfFrames, kTagRows, kTagColumns, kTagPixelSpacing,
          kTagBitsAllocated, kTagPixelRepresentation, kTagRescaleIntercept, kTagRescaleSlope})
        scanner.AddTag(t);
    std::vector<std::string> names;
    names.reserve(candidates.size());
    for (const auto& f : candidates) names.push_back(f.string());
    try {
        scanner.Scan(names);
    } catch (const std::exception& e) {
        throw InputError(str(candidates.front().parent_path()), "",
                         std::string("GDCM failed while scanning "
                                     "the DICOM headers: ") +
                             e.what(),
                         "remove damaged files from the folder");
    }

    std::vector<SliceHeader> headers;
    for (const auto& f : candidates) {
        const std::string name = f.string();
        if (!scanner.IsKey(name.c_str()))
            throw InputError(str(f), "",
                             "the file looks like DICOM but GDCM cannot parse its header "
                             "(truncated or damaged file)",
                             "remove it from the folder or copy the series again");
        const auto& m = scanner.GetMapping(name.c_str());
        const auto get = [&](const gdcm::Tag& t) -> std::optional<std::string> {
            const auto it = m.find(t);
            if (it == m.end() || !it->second) return std::nullopt;
            return trim(it->second);
        };
        const auto getInt = [&](const gdcm::Tag& t, const char* field, int fallback) {
            const auto v = get(t);
            if (!v || v->empty()) return fallback;
            const auto nums = parseNumbers(*v, f, field);
            if (nums.size() != 1 || nums[0] != std::floor(nums[0]) || std::abs(nums[0]) > 1e9)
                throw InputError(str(f), field, "value \"" + *v + "\" is not an integer",
                                 "the file is damaged; re-export the series");
            return int(nums[0]);
        };

        SliceHeader h;
        h.file = f;
        h.rows = getInt(kTagRows, "Rows", 0);
        h.columns = getInt(kTagColumns, "Columns", 0);
        // Objects without an image matrix (DICOMDIR, structured reports, presentation states) are
        // not slices.
        if (h.rows == 0 && h.columns == 0) continue;
        h.seriesUid = get(kTagSeriesUid).value_or("");
        h.description = get(kTagSeriesDescription).value_or("");
        h.modality = get(kTagModality).value_or("");
        h.seriesNumber = get(kTagSeriesNumber).value_or("");
        h.frameOfReference = get(kTagFrameOfReferenceUid).value_or("");
        h.bitsAllocated = getInt(kTagBitsAllocated, "BitsAllocated", 0);
        h.pixelRepresentation = getInt(kTagPixelRepresentation, "PixelRepresentation", 0);
        h.samplesPerPixel = getInt(kTagSamplesPerPixel, "SamplesPerPixel", 1);
        h.frames = getInt(kTagNumberOfFrames, "NumberOfFrames", 1);
        if (auto v = get(kTagPosition); v && !v->empty()) {
            const auto p = parseNumbers(*v, f, "ImagePositionPatient");
            if (p.size() != 3)
                throw InputError(
                    str(f), "ImagePositionPatient",
                    "has " + std::to_string(p.size()) + " values \"" + *v + "\", expected 3",
                    "the file is damaged; re-export the series");
            for (double c : p)
                if (std::abs(c) > kMaxPatientCoordinateMm)
                    throw InputError(str(f), "ImagePositionPatient",
                                     "\"" + *v + "\" lies more than " +
                                         formatNumber(kMaxPatientCoordinateMm) +
                                         " mm from the scanner's origin",
                                     "the file is damaged; re-export the series");
            h.position = {p[0], p[1], p[2]};
            h.hasPosition = true;
        }
        if (auto v = get(kTagOrientation); v && !v->empty()) {
            const auto o = parseNumbers(*v, f, "ImageOrientationPatient");
            if (o.size() != 6)
                throw InputError(
                    str(f), "ImageOrientationPatient",
                    "has " + std::to_string(o.size()) + " values \"" + *v + "\", expected 6",
                    "the file is damaged; re-export the series");
            std::copy(o.begin(), o.end(), h.orientation.begin());
            h.hasOrientation = true;
        }
        if (auto v = get(kTagPixelSpacing); v && !v->empty()) {
            const auto s = parseNumbers(*v, f, "PixelSpacing");
            if (s.size() != 2 || !(s[0] > 0.0) || !(s[1] > 0.0))
                throw InputError(
                    str(f), "PixelSpacing",
                    "\"" + *v + "\" is not two positive numbers (row\\column spacing, mm)",
                    "the file is damaged; re-export the series");
            h.pixelSpacing = {s[0], s[1]};
            h.hasPixelSpacing = true;
        }
        if (auto v = get(kTagSliceThickness); v && !v->empty()) {
            const auto t = parseNumbers(*v, f, "SliceThickness");
            if (t.size() == 1 && t[0] > 0.0) h.sliceThickness = t[0];
        }
        if (auto v = get(kTagRescaleSlope); v && !v->empty()) {
            const auto s = parseNumbers(*v, f, "RescaleSlope");
            if (s.size() != 1 || s[0] == 0.0)
                throw InputError(str(f), "RescaleSlope",
                                 "\"" + *v + "\" is not one non-zero number",
                                 "the file is damaged; re-export the series");
            h.slope = s[0];
        }
        if (auto v = get(kTagRescaleIntercept); v && !v->empty()) {
            const auto s = parseNumbers(*v, f, "RescaleIntercept");
            if (s.size() != 1)
                throw InputError(str(f), "RescaleIntercept", "\"" + *v + "\" is not one number",
                                 "the file is damaged; re-export the series");
            h.intercept = s[0];
        }
        // The rescale's reach over the stored type: a slope of 1e30 took a CT to 2.9e33 "HU"
        // without a word (probe). No physical quantity a scanner stores comes near it.
        if (h.bitsAllocated > 0 && h.bitsAllocated <= 64) {
            const double stored =
                std::ldexp(1.0, h.bitsAllocated - (h.pixelRepresentation ? 1 : 0));
            const double reach = std::abs(h.slope) * stored + std::abs(h.intercept);
            if (!(reach <= kMaxRescaledMagnitude))
                throw InputError(str(f),
                                 std::abs(h.intercept) > kMaxRescaledMagnitude / 2
                                     ? "RescaleIntercept"
                                     : "RescaleSlope",
                                 "slope " + formatNumber(h.slope) + " and intercept " +
                                     formatNumber(h.intercept) + " take " +
                                     std::to_string(h.bitsAllocated) + "-bit values up to " +
                                     formatNumber(reach) + ", beyond any physical quantity",
                                 "the file is damaged; re-export the series");
        }
        headers.push_back(std::move(h));
    }
    return headers;
}

std::string uidLabel(const std::string& uid) {
    return uid.empty() ? std::string("<no SeriesInstanceUID>") : uid;
}

/// "UID "description" (N slices)" for each series, for the mixed-series and unknown-UID messages.
std::string listSeries(const std::map<std::string, std::vector<SliceHeader>>& groups) {
    std::string out;
    for (const auto& [uid, slices] : groups) {
        if (!out.empty()) out += "; ";
        out += uidLabel(uid) + " \"" + slices.front().description + "\" (" +
               std::to_string(slices.size()) + (slices.size() == 1 ? " slice" : " slices");
        if (uid.empty())
            out +=
                std::string(", select with --series ") + kNoUidSelector + " (scene: volume.series)";
        out += ")";
    }
    return out;
}

bool nearlyEqual(double a, double b, double rel) {
    return std::abs(a - b) <= rel * std::max({1.0, std::abs(a), std::abs(b)});
}

std::string orientationString(const std::array<double, 6>& o) {
    std::string s;
    for (int i = 0; i < 6; ++i) s += (i ? "\\" : "") + formatNumber(o[i], 8);
    return s;
}

/// Step 3: every slice must share the first slice's matrix, pixel type, orientation and pixel
/// spacing.
void checkConsistency(const std::vector<SliceHeader>& slices) {
    const SliceHeader& ref = slices.front();
    const auto differ = [&](const SliceHeader& h, const char* field, const std::string& mine,
                            const std::string& theirs) {
        return InputError(
            str(h.file), field,
            "is " + mine + " but " + theirs + " in " + ref.file.filename().string() +
                " of the same series",
            "all slices of a series must share it; remove the odd file or choose another series");
    };
    // Files without a Series Instance UID are grouped as one series (anonymised data often blanks
    // it): what else identifies a series must then agree, or two series were stacked into one
    // volume (a CT and an MR, labelled by whichever sorted first — until 7 December).
    const bool noUid = ref.seriesUid.empty();
    const auto identity = [&](const SliceHeader& h, const char* field, const std::string& mine,
                              const std::string& theirs) {
        if (mine == theirs) return;
        const auto shown = [](const std::string& v) {
            return v.empty() ? "absent" : '"' + v + '"';
        };
        throw InputError(
            str(h.file), field,
            "is " + shown(mine) + " but " + shown(theirs) + " in " + ref.file.filename().string() +
                (noUid ? ": the folder holds more than one series, and its files carry no "
                         "SeriesInstanceUID to tell them apart"
                       : " of the same series"),
            noUid ? "put each series in its own folder and load that folder"
                  : "the series is damaged; remove the odd file or re-export the series");
    };
    for (const SliceHeader& h : slices) {
        identity(h, "Modality", h.modality, ref.modality);
        identity(h, "FrameOfReferenceUID", h.frameOfReference, ref.frameOfReference);
        if (noUid) {
            identity(h, "SeriesNumber", h.seriesNumber, ref.seriesNumber);
            identity(h, "SeriesDescription", h.description, ref.description);
        }
        // A multi-frame file among single-frame slices (only the first file's count was checked:
        // "the decoded image is 512x512 but the header says 512x512").
        if (h.frames != ref.frames)
            throw InputError(
                str(h.file), "NumberOfFrames",
                "is " + std::to_string(h.frames) + " but " + std::to_string(ref.frames) + " in " +
                    ref.file.filename().string() +
                    (h.frames > 1 ? ": a multi-frame file among single-frame slices" : ""),
                "remove the odd file, or convert the series to NIfTI with dcm2niix "
                "and load that");
        if (h.rows != ref.rows)
            throw differ(h, "Rows", std::to_string(h.rows), std::to_string(ref.rows));
        if (h.columns != ref.columns)
            throw differ(h, "Columns", std::to_string(h.columns), std::to_string(ref.columns));
        if (h.bitsAllocated != ref.bitsAllocated)
            throw differ(h, "BitsAllocated", std::to_string(h.bitsAllocated),
                         std::to_string(ref.bitsAllocated));
        if (h.pixelRepresentation != ref.pixelRepresentation)
            throw differ(h, "PixelRepresentation", std::to_string(h.pixelRepresentation),
                         std::to_string(ref.pixelRepresentation));
        if (h.samplesPerPixel != ref.samplesPerPixel)
            throw differ(h, "SamplesPerPixel", std::to_string(h.samplesPerPixel),
                         std::to_string(ref.samplesPerPixel));
        if (h.hasOrientation != ref.hasOrientation || h.hasPosition != ref.hasPosition)
            throw InputError(str(h.file),
                             h.hasOrientation ? "ImagePositionPatient" : "ImageOrientationPatient",
                             "is present in some slices of the series and absent in others",
                             "the series is damaged; re-export it");
        for (int i = 0; i < 6; ++i)
            if (std::abs(h.orientation[i] - ref.orientation[i]) > kOrientationMatchTol)
                throw InputError(
                    str(h.file), "ImageOrientationPatient",
                    "is " + orientationString(h.orientation) + " but " +
                        orientationString(ref.orientation) + " in " + ref.file.filename().string() +
                        ": the series mixes slice orientations (e.g. a 3-plane localizer)",
                    "choose a series whose slices share one orientation");
        if (h.hasPixelSpacing != ref.hasPixelSpacing ||
            !nearlyEqual(h.pixelSpacing[0], ref.pixelSpacing[0], kPixelSpacingMatchRel) ||
            !nearlyEqual(h.pixelSpacing[1], ref.pixelSpacing[1], kPixelSpacingMatchRel)) {
            // A slice without the tag was said to hold the assumed 1\\1 (probe).
            const auto spacing = [](const SliceHeader& x) {
                return x.hasPixelSpacing ? formatNumber(x.pixelSpacing[0]) + "\\" +
                                               formatNumber(x.pixelSpacing[1])
                                         : std::string("absent");
            };
            throw differ(h, "PixelSpacing", spacing(h), spacing(ref));
        }
    }
}

/// Orthonormal slice axes from Image Orientation (Patient): i = row cosine, j = column cosine, n =
/// i × j.
struct SliceAxes {
    glm::dvec3 i, j, n;
};

SliceAxes sliceAxes(const SliceHeader& h) {
    const glm::dvec3 r(h.orientation[0], h.orientation[1], h.orientation[2]);
    const glm::dvec3 c(h.orientation[3], h.orientation[4], h.orientation[5]);
    if (std::abs(glm::length(r) - 1.0) > kCosineTol ||
        std::abs(glm::length(c) - 1.0) > kCosineTol || std::abs(glm::dot(r, c)) > kCosineTol)
        throw InputError(
            str(h.file), "ImageOrientationPatient",
            orientationString(h.orientation) +
                " is not two orthogonal unit vectors (row and column direction cosines)",
            "the file is damaged; re-export the series");
    // Re-orthonormalise (Gram–Schmidt) so that rounding in the DS strings cannot make D
    // non-orthonormal.
    SliceAxes a;
    a.i = glm::normalize(r);
    a.j = glm::normalize(c - glm::dot(c, a.i) * a.i);
    a.n = glm::cross(a.i, a.j);
    return a;
}

/// What step 4 found about the slice positions.
struct StackLayout {
    double spacing = 0.0;  ///< uniform slice spacing (mm); for an irregular stack the mean gap
    bool regular = true;
    std::string irregularity;  ///< for the warning (see dicom_module::SeriesResult)
};

/// Step 4: sort by position along the normal and check that the positions form a uniform, unsheared
/// stack. A sheared (gantry tilt) or variably spaced stack is refused when `strict`, and otherwise
/// reported in the result for resampling. Duplicate positions and missing slices are always
/// refused: resampling would hide them.
StackLayout sortAndCheckPositions(std::vector<SliceHeader>& slices, const SliceAxes& axes,
                                  const fs::path& source, bool strict) {
    const std::string src = str(source);
    for (auto& h : slices) h.along = glm::dot(axes.n, h.position);
    std::stable_sort(slices.begin(), slices.end(),
                     [](const SliceHeader& a, const SliceHeader& b) { return a.along < b.along; });
    const std::size_t n = slices.size();
    const auto where = [](const SliceHeader& h) {
        return formatPoint(h.position) + " [" + h.file.filename().string() + "]";
    };
    const std::string strictFix =
        "omit --strict-geometry (or set the scene's volume.strict_geometry to false) to load it "
        "resampled onto a regular grid with a warning, or reslice it to an orthogonal grid first "
        "(e.g. with dcm2niix)";

    // Duplicate positions: two acquisitions (echoes, phases) or the same slice twice.
    for (std::size_t s = 0; s + 1 < n; ++s)
        if (slices[s + 1].along - slices[s].along < kDuplicateTolMm)
            throw InputError(
                src, "ImagePositionPatient",
                "two slices are at the same position " + formatPoint(slices[s].position) + ": " +
                    slices[s].file.filename().string() + " and " +
                    slices[s + 1].file.filename().string(),
                "the folder holds several acquisitions at the same positions (echoes, phases, or "
                "the same series copied twice); put each in its own folder");

    StackLayout layout;
    // Gantry tilt: positions must move along the normal; measure the sideways drift from the first
    // slice.
    double maxDrift = 0.0, driftAngle = 0.0, driftAlong = 0.0;
    for (std::size_t s = 1; s < n; ++s) {
        const glm::dvec3 v = slices[s].position - slices[0].position;
        const double along = glm::dot(v, axes.n);
        const double drift = glm::length(v - along * axes.n);
        if (drift > maxDrift) {
            maxDrift = drift;
            driftAlong = along;
            driftAngle = std::atan2(drift, std::abs(along)) * 180.0 / 3.14159265358979323846;
        }
    }
    const double finestPixel = std::min(slices[0].pixelSpacing[0], slices[0].pixelSpacing[1]);
    if (maxDrift > kMaxShearPixels * finestPixel) {
        if (strict)
            throw InputError(src, "ImagePositionPatient",
                             "gantry tilt of " + formatNumber(driftAngle, 3) +
                                 " degrees is refused under --strict-geometry (scene: "
                                 "volume.strict_geometry); the slice "
                                 "positions drift " +
                                 formatNumber(maxDrift, 4) + " mm sideways over " +
                                 formatNumber(std::abs(driftAlong), 4) +
                                 " mm instead of following the slice normal (tolerance " +
                                 formatNumber(kMaxShearPixels) + " pixel)",
                             strictFix);
        layout.regular = false;
        layout.irregularity = "gantry tilt of " + formatNumber(driftAngle, 3) + " degrees";
    }

    if (n < 2) return layout;

    // Missing slices: a gap close to k ≥ 2 times the typical (median) spacing.
    std::vector<double> gaps(n - 1);
    for (std::size_t s = 0; s + 1 < n; ++s) gaps[s] = slices[s + 1].along - slices[s].along;
    std::vector<double> sorted = gaps;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double typical = sorted[sorted.size() / 2];
    for (std::size_t s = 0; s + 1 < n; ++s) {
        const double ratio = gaps[s] / typical;
        const double k = std::round(ratio);
        if (k >= 2.0 && std::abs(ratio - k) < kMissingSliceRatioTol) {
            const int missing = int(k) - 1;
            throw InputError(
                src, "ImagePositionPatient",
                "missing slice" + std::string(missing > 1 ? "s" : "") + ": the gap between " +
                    where(slices[s]) + " and " + where(slices[s + 1]) + " is " +
                    formatNumber(gaps[s], 4) + " mm, " + formatNumber(k) +
                    " times the typical spacing of " + formatNumber(typical, 4) + " mm (" +
                    std::to_string(missing) + " slice" + (missing > 1 ? "s" : "") + " missing)",
                "copy the complete series; voxlight does not interpolate missing slices");
        }
    }

    // Variable spacing: every slice must sit on the uniform grid through the first and last slice.
    const double spacing = (slices[n - 1].along - slices[0].along) / double(n - 1);
    layout.spacing = spacing;
    double worst = 0.0;
    std::size_t worstSlice = 0;
    for (std::size_t s = 0; s < n; ++s) {
        const double off = std::abs(slices[s].along - (slices[0].along + double(s) * spacing));
        if (off > worst) worst = off, worstSlice = s;
    }
    if (worst > kMaxGridOffset * spacing) {
        const auto [lo, hi] = std::minmax_element(gaps.begin(), gaps.end());
        if (strict)
            throw InputError(src, "ImagePositionPatient",
                             "variable slice spacing is refused under --strict-geometry (scene: "
                             "volume.strict_geometry): gaps between slices "
                             "range from " +
                                 formatNumber(*lo, 4) + " to " + formatNumber(*hi, 4) +
                                 " mm; the slice at " + where(slices[worstSlice]) + " is " +
                                 formatNumber(worst, 3) + " mm off a uniform grid of " +
                                 formatNumber(spacing, 5) + " mm (tolerance " +
                                 formatNumber(kMaxGridOffset * 100) + " % of the spacing)",
                             strictFix);
        layout.irregularity += std::string(layout.regular ? "" : " and ") +
                               "slice spacing varying from " + formatNumber(*lo, 4) + " to " +
                               formatNumber(*hi, 4) + " mm";
        layout.regular = false;
    }
    return layout;
}

/// Stored pixel type of the series and the voxel type voxlight keeps it in.
struct PixelPlan {
    gdcm::PixelFormat::ScalarType decoded;
    core::VoxelType stored;
    bool perSliceRescale = false;  ///< slices differ in rescale: store physical values as float32
};

PixelPlan planPixels(const std::vector<SliceHeader>& slices) {
    const SliceHeader& ref = slices.front();
    const bool isSigned = ref.pixelRepresentation == 1;
    PixelPlan plan{};
    switch (ref.bitsAllocated) {
        case 8:
            plan.decoded = isSigned ? gdcm::PixelFormat::INT8 : gdcm::PixelFormat::UINT8;
            plan.stored = isSigned ? core::VoxelType::Int16 : core::VoxelType::UInt8;
            break;
        case 16:
            plan.decoded = isSigned ? gdcm::PixelFormat::INT16 : gdcm::PixelFormat::UINT16;
            plan.stored = isSigned ? core::VoxelType::Int16 : core::VoxelType::UInt16;
            break;
        case 32:
            plan.decoded = isSigned ? gdcm::PixelFormat::INT32 : gdcm::PixelFormat::UINT32;
            plan.stored = core::VoxelType::Float32;
            break;
        default:
            throw InputError(
                str(ref.file), "BitsAllocated",
                std::to_string(ref.bitsAllocated) + " bits per pixel is not supported (8, 16, 32)",
                "convert the series to a standard pixel format, e.g. with gdcmconv --raw");
    }
    for (const SliceHeader& h : slices)
        if (!nearlyEqual(h.slope, ref.slope, kRescaleMatchRel) ||
            !nearlyEqual(h.intercept, ref.intercept, kRescaleMatchRel))
            plan.perSliceRescale = true;
    if (plan.perSliceRescale) plan.stored = core::VoxelType::Float32;
    return plan;
}

template <class Src, class Dst>
void convertSlice(const char* in, Dst* out, std::size_t count, double slope, double intercept,
                  bool applyRescale) {
    const Src* src = reinterpret_cast<const Src*>(in);
    for (std::size_t i = 0; i < count; ++i) {
        Src v;
        std::memcpy(&v, src + i, sizeof(Src));  // the scratch buffer carries no alignment promise
        out[i] = applyRescale ? Dst(slope * double(v) + intercept) : Dst(v);
    }
}

/// Step 6: decode one slice with gdcm::ImageReader (raw, RLE, JPEG, JPEG-LS, JPEG 2000) into `dst`.
void readSlicePixels(const SliceHeader& h, const PixelPlan& plan, core::Volume& volume, int k,
                     std::vector<char>& scratch) {
    const std::string src = str(h.file);
    gdcm::ImageReader reader;
    reader.SetFileName(src.c_str());
    bool ok = false;
    try {
        ok = reader.Read();
    } catch (const std::exception& e) {
        throw InputError(src, "PixelData",
                         std::string("GDCM failed to read the image: ") + e.what(),
                         "the file is damaged or truncated; copy the series again");
    }
    if (!ok)
        throw InputError(
            src, "PixelData",
            "GDCM cannot read the image (truncated or damaged file, or an unsupported encoding)",
            "copy the series again, or decompress it with gdcmconv --raw");
    const gdcm::Image& image = reader.GetImage();
    const unsigned nd = image.GetNumberOfDimensions();
    if (image.GetColumns() != unsigned(h.columns) || image.GetRows() != unsigned(h.rows) ||
        (nd >= 3 && image.GetDimension(2) != 1))
        throw InputError(src, "PixelData",
                         "the decoded image is " + std::to_string(image.GetColumns()) + "x" +
                             std::to_string(image.GetRows()) + " but the header says " +
                             std::to_string(h.columns) + "x" + std::to_string(h.rows),
                         "the file is damaged; re-export the series");
    const gdcm::PixelFormat& pf = image.GetPixelFormat();
    if (pf.GetSamplesPerPixel() != 1 || pf.GetScalarType() != plan.decoded)
        throw InputError(
            src, "PixelData",
            std::string("decodes to pixel format ") + pf.GetScalarTypeAsString() + " with " +
                std::to_string(pf.GetSamplesPerPixel()) + " sample(s), expected " +
                gdcm::PixelFormat(plan.decoded).GetScalarTypeAsString() + " grey values",
            "decompress the series with gdcmconv --raw and check it in a DICOM viewer");

    const std::size_t count = std::size_t(h.rows) * std::size_t(h.columns);
    const std::size_t bytes = count * pf.GetPixelSize();
    if (image.GetBufferLength() != bytes)
        throw InputError(src, "PixelData",
                         "holds " + std::to_string(image.GetBufferLength()) + " bytes, expected " +
                             std::to_string(bytes),
                         "the file is damaged or truncated; copy the series again");

    // Decode straight into the volume when the types agree; otherwise through one reused slice
    // buffer.
    const std::size_t offset = volume.linearIndex(0, 0, k);
    const bool direct = !plan.perSliceRescale &&
                        core::voxelBytes(volume.type()) == pf.GetPixelSize() &&
                        plan.stored != core::VoxelType::Float32;
    char* target =
        direct ? static_cast<char*>(volume.data()) + offset * pf.GetPixelSize() : nullptr;
    if (!direct) {
        scratch.resize(bytes);
        target = scratch.data();
    }
    bool decoded = false;
    try {
        decoded = image.GetBuffer(target);
    } catch (const std::exception& e) {
        throw InputError(src, "PixelData",
                         std::string("GDCM failed to decode the pixels: ") + e.what(),
                         "the file is damaged or truncated; copy the series again");
    }
    if (!decoded)
        throw InputError(src, "PixelData",
                         "GDCM cannot decode the pixel data (truncated or damaged file)",
                         "copy the series again, or decompress it with gdcmconv --raw");
    if (direct) return;

    const bool rescale = plan.perSliceRescale;
    switch (volume.type()) {
        case core::VoxelType::Int16:  // int8 widened
            convertSlice<std::int8_t>(target, volume.dataAs<std::int16_t>() + offset, count, 1.0,
                                      0.0, false);
            break;
        case core::VoxelType::Float32: {
            float* out = volume.dataAs<float>() + offset;
            switch (plan.decoded) {
                case gdcm::PixelFormat::UINT8:
                    convertSlice<std::uint8_t>(target, out, count, h.slope, h.intercept, rescale);
                    break;
                case gdcm::PixelFormat::INT8:
                    convertSlice<std::int8_t>(target, out, count, h.slope, h.intercept, rescale);
                    break;
                case gdcm::PixelFormat::UINT16:
                    convertSlice<std::uint16_t>(target, out, count, h.slope, h.intercept, rescale);
                    break;
                case gdcm::PixelFormat::INT16:
                    convertSlice<std::int16_t>(target, out, count, h.slope, h.intercept, rescale);
                    break;
                case gdcm::PixelFormat::UINT32:
                    convertSlice<std::uint32_t>(target, out, count, h.slope, h.intercept, rescale);
                    break;
                case gdcm::PixelFormat::INT32:
                    convertSlice<std::int32_t>(target, out, count, h.slope, h.intercept, rescale);
                    break;
                default:
                    throw InternalError("unexpected DICOM scalar type");
            }
            break;
        }
        default:
            throw InternalError("unexpected DICOM conversion");
    }
}

}  // namespace

dicom_module::SeriesResult readDicomSeriesWithGdcm(const std::filesystem::path& path,
                                                   const ReadOptions& options,
                                                   const core::Progress& progress,
                                                   const dicom_module::Hooks& hooks) {
    silenceGdcm();
    progress.report("dicom", 0.0);

    // Step 1: the folder and its candidate files (a cheap DICM/first-tag probe drops LICENSE.txt
    // and the like).
    std::error_code ec;
    const bool isDir = fs::is_directory(path, ec);
    if (!isDir && !fs::is_regular_file(path, ec))
        throw InputError(str(path), "", "does not exist or is not a file or folder",
                         "check the path of the DICOM folder");
    if (!isDir && !looksLikeDicomFile(path))
        throw InputError(
            str(path), "",
            "is not a DICOM file (no \"DICM\" marker at byte 128 and no DICOM data set at its "
            "start)",
            "give the folder of a DICOM series, or a file in one of voxlight's formats");
    const fs::path dir =
        isDir ? path : (path.has_parent_path() ? path.parent_path() : fs::path("."));
    std::vector<fs::path> candidates;
    std::size_t skipped = 0;
    for (const auto& f : listFiles(dir)) {
        if (looksLikeDicomFile(f))
            candidates.push_back(f);
        else
            ++skipped;
    }
    if (candidates.empty())
        throw InputError(str(dir), "",
                         skipped == 0 ? std::string("holds no DICOM files (the folder is empty)")
                                      : "holds no DICOM files (" + std::to_string(skipped) +
                                            " other file" + (skipped == 1 ? "" : "s") + " ignored)",
                         "point to the folder that holds the slices of one series");
    // Step 1b: refuse truncated files before GDCM reads them (it asserts on some; see
    // FramingCheck).
    std::map<fs::path, PixelDataInfo> pixelData;
    for (const auto& f : candidates) {
        if (hooks.reading) hooks.reading(f);
        const PixelDataInfo& info = pixelData[f] = FramingCheck::check(f);
        // GDCM's header scan already fails (or asserts) on a transfer syntax it does not know.
        if (codecOf(info.syntax) == Codec::Unknown)
            throw InputError(str(f), "TransferSyntaxUID",
                             "\"" + info.syntax + "\" is not a transfer syntax GDCM decodes",
                             "convert the file with gdcmconv --raw (or dcmdjpeg) first");
    }
    progress.checkCancel();

    // Step 2: scan headers and group by Series Instance UID; pick the series.
    if (hooks.reading) hooks.reading(candidates.size() == 1 ? candidates.front() : dir);
    std::vector<SliceHeader> headers = scanHeaders(candidates);
    if (headers.empty())
        throw InputError(str(dir), "Rows",
                         "holds DICOM files but no images (" + std::to_string(candidates.size()) +
                             " DICOM object(s) without an image matrix, e.g. DICOMDIR or reports)",
                         "point to the folder that holds the image slices");
    std::map<std::string, std::vector<SliceHeader>> groups;
    std::string pathUid;
    bool pathUidKnown = false;
    for (auto& h : headers) {
        if (!isDir && fs::equivalent(h.file, path, ec)) pathUid = h.seriesUid, pathUidKnown = true;
        groups[h.seriesUid].push_back(std::move(h));
    }
    headers.clear();
    std::string chosen;
    if (!options.dicomSeriesUid.empty()) {
        chosen = options.dicomSeriesUid == kNoUidSelector ? std::string() : options.dicomSeriesUid;
        if (!groups.count(chosen))
            throw InputError(str(dir), "SeriesInstanceUID",
                             "series " + options.dicomSeriesUid +
                                 " is not in the folder, which holds " +
                                 std::to_string(groups.size()) + " series: " + listSeries(groups),
                             "choose one of the listed UIDs with --series UID (in a scene: "
                             "\"volume\": {\"path\": …, \"series\": UID})");
    } else if (pathUidKnown) {
        chosen = pathUid;  // a file was given: read the series it belongs to
    } else if (!isDir) {
        throw InputError(str(path), "Rows", "is a DICOM object without an image matrix",
                         "give the folder of an image series");
    } else if (groups.size() > 1) {
        throw InputError(
            str(dir), "SeriesInstanceUID",
            "the folder holds " + std::to_string(groups.size()) + " series: " + listSeries(groups),
            "choose one with --series UID (in a scene: \"volume\": {\"path\": …, \"series\": "
            "UID})");
    } else {
        chosen = groups.begin()->first;
    }
    std::vector<SliceHeader> slices = std::move(groups[chosen]);
    groups.clear();

    // Step 3: the slices must agree on matrix, pixel type, orientation and spacing; one frame each.
    const SliceHeader& first = slices.front();
    if (first.frames > 1)
        throw InputError(str(first.file), "NumberOfFrames",
                         "multi-frame DICOM (" + std::to_string(first.frames) +
                             " frames in one file) is not supported yet",
                         "convert it to a NIfTI file (e.g. with dcm2niix) and load that");
    if (first.samplesPerPixel != 1)
        throw InputError(
            str(first.file), "SamplesPerPixel",
            "colour images (" + std::to_string(first.samplesPerPixel) +
                " samples per pixel) are not supported; voxlight renders scalar volumes",
            "choose a greyscale CT or MR series");
    if (first.rows < 1 || first.columns < 1)
        throw InputError(str(first.file), "Rows", "the image matrix is empty",
                         "choose another series");
    if (!first.hasPosition || !first.hasOrientation)
        throw InputError(
            str(first.file), first.hasPosition ? "ImageOrientationPatient" : "ImagePositionPatient",
            "is missing, so the slice cannot be placed in patient space (not a cross-sectional "
            "image, e.g. a secondary capture or projection radiograph)",
            "choose a CT or MR series with Image Position/Orientation (Patient)");
    checkConsistency(slices);
    const SliceAxes axes = sliceAxes(slices.front());

    // Step 4: sort along the normal; spacing from positions (not SliceThickness), checked for
    // uniformity.
    const fs::path source = isDir ? path : dir;
    const StackLayout layout = sortAndCheckPositions(slices, axes, source, options.strictGeometry);
    double sliceSpacing = layout.spacing;
    std::vector<std::string> notes;
    if (slices.size() == 1) {
        if (slices[0].sliceThickness > 0.0) {
            sliceSpacing = slices[0].sliceThickness;
            notes.push_back("single slice; slice spacing taken from SliceThickness " +
                            formatNumber(sliceSpacing) + " mm");
        } else {
            sliceSpacing = 1.0;
            notes.push_back("single slice without SliceThickness; slice spacing assumed 1 mm");
        }
    }
    if (!slices[0].hasPixelSpacing) notes.push_back("PixelSpacing absent; assumed 1 mm");

    // Step 5: geometry (origin = first slice after sorting; D = [row cosine, column cosine,
    // normal]) and size check before allocating. DICOM Pixel Spacing is [row spacing, column
    // spacing] = [Δj, Δi].
    core::Geometry g;
    g.dims = {slices[0].columns, slices[0].rows,
              int(std::min<std::size_t>(slices.size(), INT32_MAX))};
    g.spacing = {slices[0].pixelSpacing[1], slices[0].pixelSpacing[0], sliceSpacing};
    g.origin = slices[0].position;
    g.direction = glm::dmat3(axes.i, axes.j, axes.n);
    if (g.dims.x > core::kMaxDim || g.dims.y > core::kMaxDim ||
        slices.size() > std::size_t(core::kMaxDim) || g.voxelCount() > core::kMaxVoxels)
        throw InputError(str(source), "Rows",
                         "the series is " + std::to_string(g.dims.x) + "x" +
                             std::to_string(g.dims.y) + "x" + std::to_string(slices.size()) +
                             " voxels, beyond voxlight's limit (" + std::to_string(core::kMaxDim) +
                             " per axis, " + std::to_string(core::kMaxVoxels) + " voxels)",
                         "load a part of the series or downsample it");

    const PixelPlan plan = planPixels(slices);
    // Step 5b: every slice's pixel data against its header, before GDCM decodes any.
    for (const SliceHeader& h : slices) checkPixelData(h, pixelData[h.file]);
    const std::size_t volumeBytes = std::size_t(g.voxelCount()) * core::voxelBytes(plan.stored);
    core::Volume volume =
        hooks.allocate
            ? core::Volume(g, plan.stored, hooks.allocate(volumeBytes, volumeBytes / slices.size()))
            : core::Volume(g, plan.stored);

    // Step 6: decode slice by slice into the volume (one decoded slice alive at a time).
    std::vector<char> scratch;
    for (std::size_t s = 0; s < slices.size(); ++s) {
        if (hooks.reading) hooks.reading(slices[s].file);
        readSlicePixels(slices[s], plan, volume, int(s), scratch);
        progress.report("dicom", double(s + 1) / double(slices.size()));
    }

    // Step 7: value mapping, modality, description.
    const SliceHeader& ref = slices.front();
    if (plan.perSliceRescale) {
        volume.mapping.slope = 1.0;
        volume.mapping.intercept = 0.0;
        notes.push_back(
            "rescale slope/intercept differ per slice; stored as float32 physical values");
    } else {
        volume.mapping.slope = ref.slope;
        volume.mapping.intercept = ref.intercept;
    }
    if (ref.modality == "CT") {
        volume.modality = core::Modality::CT;
        volume.mapping.unit = "HU";
    } else if (ref.modality == "MR") {
        volume.modality = core::Modality::MR;
    }
    volume.description = ref.description.empty() ? dir.filename().string() : ref.description;
    if (!notes.empty()) {
        volume.description += " (";
        for (std::size_t i = 0; i < notes.size(); ++i)
            volume.description += (i ? "; " : "") + notes[i];
        volume.description += ")";
    }
    dicom_module::SeriesResult result;
    result.stack = std::move(volume);
    if (!layout.regular) {
        for (const SliceHeader& h : slices) result.slicePositions.push_back(h.position);
        result.irregularity = layout.irregularity;
    }
    return result;
}

}  // namespace voxlight::io::detail

namespace {
constexpr voxlight::io::dicom_module::Api kApi{voxlight::io::dicom_module::kAbiVersion,
                                               &voxlight::io::detail::readDicomSeriesWithGdcm};
}  // namespace

// The module's single exported symbol (it is built with hidden visibility; dicom_module.h).
extern "C" __attribute__((visibility("default"))) const void* voxlight_dicom_module() {
    return &kApi;
}
