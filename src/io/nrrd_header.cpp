// SPDX-License-Identifier: MIT
// NRRD header validation and orientation (nrrd_header.h). Field names and semantics follow the
// teem NRRD format definition (NRRD0001..NRRD0005); only what VTK 9.1's reader can then read
// correctly is accepted.
#include "io/nrrd_header.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

#include "core/error.h"

namespace voxlight::io::detail {

namespace fs = std::filesystem;

namespace {

/// VTK 9.1 reads a first axis of at most this many samples as vector components, not as x.
constexpr std::int64_t kVtkComponentAxisMax = 9;
/// VTK 9.1 passes the gzip data length to gzread as a 32-bit unsigned: longer data would wrap and
/// load partly as zeros.
constexpr std::uint64_t kVtkMaxGzipBytes = (std::uint64_t(1) << 32) - 1;
/// VTK 9.1 counts pattern indices with an int (i += step): keep first, last and step far from its
/// overflow.
constexpr std::int64_t kMaxPatternIndex = 1'000'000'000;
/// VTK 9.1 formats pattern names into a buffer this much longer than the pattern (longer names are
/// cut); we make the same names.
constexpr std::size_t kVtkPatternSlack = 20;
/// Direction cosines are written with ~6 digits: the same tolerance as the NIfTI/VTI check.
constexpr double kOrthoTol = 1e-3;

std::string trim(std::string s) {
    s.erase(0, s.find_first_not_of(" \t\r"));
    s.erase(s.find_last_not_of(" \t\r") + 1);
    return s;
}

std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

std::vector<std::string> splitWs(const std::string& s) {
    std::istringstream is(s);
    std::vector<std::string> out;
    std::string t;
    while (is >> t) out.push_back(t);
    return out;
}

/// Bytes per sample of the NRRD type names VTK 9.1 accepts (its NrrdType2VTKType), or 0.
int typeBytes(const std::string& t) {
    static const std::array<std::pair<const char*, int>, 40> kTypes = {{
        {"signed char", 1},
        {"int8", 1},
        {"int8_t", 1},
        {"uchar", 1},
        {"unsigned char", 1},
        {"uint8", 1},
        {"uint8_t", 1},
        {"short", 2},
        {"short int", 2},
        {"signed short", 2},
        {"signed short int", 2},
        {"int16", 2},
        {"int16_t", 2},
        {"ushort", 2},
        {"unsigned short", 2},
        {"unsigned short int", 2},
        {"uint16", 2},
        {"uint16_t", 2},
        {"int", 4},
        {"signed int", 4},
        {"int32", 4},
        {"int32_t", 4},
        {"uint", 4},
        {"unsigned int", 4},
        {"uint32", 4},
        {"uint32_t", 4},
        {"float", 4},
        {"longlong", 8},
        {"long long", 8},
        {"long long int", 8},
        {"signed long long", 8},
        {"signed long long int", 8},
        {"int64", 8},
        {"int64_t", 8},
        {"ulonglong", 8},
        {"unsigned long long", 8},
        {"unsigned long long int", 8},
        {"uint64", 8},
        {"uint64_t", 8},
        {"double", 8},
    }};
    for (const auto& [name, bytes] : kTypes)
        if (t == name) return bytes;
    return 0;
}

class Parser {
  public:
    explicit Parser(const fs::path& path) : path_(path) {}

    [[noreturn]] void fail(const std::string& field, const std::string& problem,
                           const std::string& fix = "fix the NRRD header") const {
        throw InputError(path_.string(), field, problem, fix);
    }

    std::int64_t parseInt(const std::string& field, const std::string& s) const {
        errno = 0;
        char* end = nullptr;
        const long long v = std::strtoll(s.c_str(), &end, 10);
        if (s.empty() || *end != '\0') fail(field, "'" + s + "' is not an integer");
        if (errno == ERANGE) fail(field, "'" + s + "' overflows a 64-bit integer");
        return v;
    }

    double parseDouble(const std::string& field, const std::string& s) const {
        char* end = nullptr;
        const double v = std::strtod(s.c_str(), &end);
        if (s.empty() || *end != '\0') fail(field, "'" + s + "' is not a number");
        if (!std::isfinite(v)) fail(field, "holds a non-finite value '" + s + "'");
        return v;
    }

    /// "(a,b,c)" with exactly three finite components.
    glm::dvec3 parseVector(const std::string& field, const std::string& s) const {
        if (s.size() < 2 || s.front() != '(' || s.back() != ')')
            fail(field, "'" + s + "' is not a vector like (1,0,0)");
        std::vector<double> v;
        std::string rest = s.substr(1, s.size() - 2);
        std::size_t start = 0;
        while (true) {
            const std::size_t comma = rest.find(',', start);
            v.push_back(parseDouble(field, trim(rest.substr(start, comma - start))));
            if (comma == std::string::npos) break;
            start = comma + 1;
        }
        if (v.size() != 3)
            fail(field, "'" + s + "' has " + std::to_string(v.size()) +
                            " components; voxlight reads 3-D spaces only");
        return {v[0], v[1], v[2]};
    }

    void setSpace(NrrdHeader& h, const std::string& value) const {
        const std::string s = lower(value);
        const glm::dmat3 identity(1.0);
        const glm::dmat3 flipXY(glm::dvec3(-1, 0, 0), glm::dvec3(0, -1, 0), glm::dvec3(0, 0, 1));
        const glm::dmat3 flipY(glm::dvec3(1, 0, 0), glm::dvec3(0, -1, 0), glm::dvec3(0, 0, 1));
        if (s.find("time") != std::string::npos)
            fail("space", "'" + value + "' has a time axis; voxlight reads 3-D volumes",
                 "extract one time point first");
        if (s == "right-anterior-superior" || s == "ras")
            h.spaceToLps = flipXY;
        else if (s == "left-anterior-superior" || s == "las" || s == "3d-left-handed")
            h.spaceToLps = flipY;
        else if (s == "left-posterior-superior" || s == "lps" || s == "scanner-xyz" ||
                 s == "3d-right-handed")
            h.spaceToLps = identity;
        else
            fail("space", "'" + value + "' is not a 3-D space voxlight knows",
                 "use right-anterior-superior, left-anterior-superior, left-posterior-superior, "
                 "scanner-xyz or 3D-right-handed");
        // VTK 9.1 reads raw rows bottom-up for exactly these spellings (its FileLowerLeft = 0).
        h.spaceFlipsY =
            value == "left-anterior-superior" || value == "LAS" || value == "3D-left-handed";
    }

    NrrdHeader parse() {
        std::ifstream in(path_, std::ios::binary);
        if (!in) fail("file", "cannot be opened", "check the path and permissions");
        std::error_code ec;
        const std::uint64_t fileBytes = fs::file_size(path_, ec);
        if (ec) fail("file", "cannot be opened", "check the path and permissions");
        std::string buf(std::size_t(std::min(fileBytes, kMaxNrrdHeaderBytes)), '\0');
        in.read(buf.data(), std::streamsize(buf.size()));
        buf.resize(std::size_t(in.gcount()));
        const bool wholeFile = buf.size() == fileBytes;

        NrrdHeader h;
        std::set<std::string> seen;
        bool ended = false, lastLineUnterminated = false;
        std::size_t pos = 0;
        for (int lineNo = 0; pos < buf.size(); ++lineNo) {
            const std::size_t nl = buf.find('\n', pos);
            if (nl == std::string::npos && !wholeFile)
                fail("header",
                     "has no blank line within the first " + std::to_string(kMaxNrrdHeaderBytes) +
                         " bytes",
                     "the file is not a NRRD or its header is corrupt");
            const std::size_t lineEnd = nl == std::string::npos ? buf.size() : nl;
            lastLineUnterminated = nl == std::string::npos;
            std::string line = buf.substr(pos, lineEnd - pos);
            pos = nl == std::string::npos ? buf.size() : nl + 1;
            if (!line.empty() && line.back() == '\r') line.pop_back();
            if (line.find('\0') != std::string::npos)
                fail("header", "holds a NUL byte in line " + std::to_string(lineNo + 1),
                     "the header is corrupt");
            if (lineNo == 0) {
                if (line.size() < 8 || line.compare(0, 7, "NRRD000") != 0 ||
                    !std::isdigit(static_cast<unsigned char>(line[7])))
                    fail("magic", "does not start with NRRD000<n>",
                         "the file is not a NRRD volume");
                continue;
            }
            if (line.empty()) {
                ended = true;
                h.headerBytes = pos;
                break;
            }
            if (line[0] == '#') continue;
            const std::size_t delim = line.find(": ");
            if (delim == std::string::npos) continue;  // "key:=value" pairs and stray text
            const std::string field = line.substr(0, delim);
            const std::string value = trim(line.substr(delim + 2));
            field_(h, seen, field, value);
            if ((field == "data file" || field == "datafile") && listed_) {
                // "data file: LIST": one file name per line up to the end of the header.
                while (pos < buf.size()) {
                    const std::size_t e = std::min(buf.find('\n', pos), buf.size());
                    lastLineUnterminated = e == buf.size();
                    const std::string name = trim(buf.substr(pos, e - pos));
                    // VTK reads the header as a C string: a NUL ends it there, without the final
                    // newline, and VTK 9.1 then loops forever (fuzz_nrrd_detached timeout).
                    if (name.find('\0') != std::string::npos)
                        fail("data file",
                             "holds a NUL byte in listed file " +
                                 std::to_string(h.dataFiles.size() + 1),
                             "the header is corrupt");
                    pos = std::min(e + 1, buf.size());
                    if (name.empty()) break;
                    h.dataFiles.push_back(beside(name));
                }
                ended = false;
                break;
            }
        }

        // A detached header: VTK loops forever on one without a final newline.
        if ((!h.dataFiles.empty() || listed_) && lastLineUnterminated && !ended)
            fail("header", "does not end with a newline (detached header)",
                 "add a newline after the last line");
        if (h.dataFiles.empty() && !listed_ && !ended)
            fail("header", "does not end with a blank line, so no data follows it",
                 "the file is truncated, or name the data with a 'data file:' field");
        if (!seen.count("dimension"))
            fail("dimension", "is missing", "add 'dimension: 3' before 'sizes'");
        if (!seen.count("sizes")) fail("sizes", "is missing", "add 'sizes: X Y Z'");
        if (!seen.count("type")) fail("type", "is missing", "add e.g. 'type: short'");
        if (h.dimension == 2 && (seen.count("space") || seen.count("space dimension") ||
                                 seen.count("space directions")))
            fail("dimension", "is 2 with a 3-D space, which VTK 9.1 misreads",
                 "write the slice as a 3-D NRRD with sizes X Y 1");
        if (!h.spaceDirections.empty() && int(h.spaceDirections.size()) != h.dimension)
            fail("space directions", "has " + std::to_string(h.spaceDirections.size()) +
                                         " vectors for " + std::to_string(h.dimension) + " axes");
        if (!h.spacings.empty() && int(h.spacings.size()) != h.dimension)
            fail("spacings", "has " + std::to_string(h.spacings.size()) + " values for " +
                                 std::to_string(h.dimension) + " axes");
        if (h.encoding == NrrdEncoding::Ascii && h.dataFiles.empty())
            fail("encoding", "ascii data attached to the header is misread by VTK 9.1",
                 "use raw or gzip encoding, or a detached ascii data file");
        if (h.dataFiles.size() > 1 || listed_) {
            if (h.dimension != 3 || h.encoding != NrrdEncoding::Raw)
                fail("data file", "one file per slice is read for raw 3-D data only",
                     "join the slices into one data file");
            if (subdim_ && *subdim_ != 3)
                fail("data file", "splits along axis " + std::to_string(*subdim_) +
                                      "; VTK 9.1 reads one file per slice (axis 3) only");
            if (std::int64_t(h.dataFiles.size()) != h.sizes[2])
                fail("data file", "lists " + std::to_string(h.dataFiles.size()) + " files for " +
                                      std::to_string(h.sizes[2]) + " slices");
        }
        if (h.encoding == NrrdEncoding::Ascii && h.typeBytes == 1)
            fail("encoding", "ascii with 8-bit type '" + h.type + "' is misread by VTK 9.1",
                 "use raw or gzip encoding");
        return h;
    }

  private:
    void field_(NrrdHeader& h, std::set<std::string>& seen, std::string field,
                const std::string& value) {
        if (field == "datafile") field = "data file";
        if (field == "lineskip") field = "line skip";
        if (field == "byteskip") field = "byte skip";
        if (field == "dimension" && seen.count("sizes"))
            fail("dimension", "appears after 'sizes'", "move 'dimension' before 'sizes'");
        if (!seen.insert(field).second) fail(field, "appears twice");
        if (field == "dimension") {
            const std::int64_t d = parseInt(field, value);
            if (d != 2 && d != 3)
                fail("dimension", "is " + value + "; voxlight reads 3-D volumes (or 2-D slices)",
                     "set 'dimension: 3'");
            h.dimension = int(d);
        } else if (field == "sizes") {
            if (!seen.count("dimension"))
                fail("dimension", "is missing before 'sizes'", "add 'dimension: 3' before it");
            const auto tok = splitWs(value);
            if (int(tok.size()) != h.dimension)
                fail("sizes", "has " + std::to_string(tok.size()) + " values for dimension " +
                                  std::to_string(h.dimension));
            std::ostringstream dims;
            std::uint64_t voxels = 1;
            bool outside = false;
            for (std::size_t a = 0; a < tok.size(); ++a) {
                const std::int64_t n = parseInt("sizes", tok[a]);
                if (n < 1)
                    fail("sizes", "axis " + std::to_string(a) + " has size " + tok[a],
                         "sizes must be positive");
                dims << (a ? "x" : "") << n;
                if (n > core::kMaxDim) outside = true;
                if (!outside) voxels *= std::uint64_t(n);
                h.sizes.push_back(n);
            }
            if (outside || voxels > core::kMaxVoxels)
                fail("sizes",
                     "declares dims " + dims.str() + ", outside the supported range (1.." +
                         std::to_string(core::kMaxDim) + " per axis, at most " +
                         std::to_string(core::kMaxVoxels) + " voxels)",
                     "the header is corrupt or the volume must be cropped/downsampled first");
            if (h.sizes[0] <= kVtkComponentAxisMax)
                fail("sizes",
                     "first axis has " + tok[0] + " samples; VTK 9.1 reads an axis of at most " +
                         std::to_string(kVtkComponentAxisMax) + " as vector components",
                     "use a volume at least 10 voxels wide, or reorder its axes");
        } else if (field == "type") {
            h.type = value;
            h.typeBytes = typeBytes(value);
            if (h.typeBytes == 0)
                fail("type", "'" + value + "' is not supported",
                     "use an integer type (int8..uint64), float or double");
        } else if (field == "encoding") {
            const std::string e = lower(value);
            if (e == "raw")
                h.encoding = NrrdEncoding::Raw;
            else if (e == "gzip" || e == "gz")
                h.encoding = NrrdEncoding::Gzip;
            else if (e == "ascii" || e == "text" || e == "txt")
                h.encoding = NrrdEncoding::Ascii;
            else
                fail("encoding", "'" + value + "' is not supported",
                     "use raw, gzip or (detached) ascii");
        } else if (field == "endian") {
            if (value != "little" && value != "big")
                fail("endian", "'" + value + "' is neither 'little' nor 'big'");
        } else if (field == "data file") {
            const auto tok = splitWs(value);
            if (tok.empty()) fail("data file", "is empty", "name the data file");
            if (tok[0] == "LIST") {
                if (tok.size() > 1) subdim_ = parseInt(field, tok[1]);
                listed_ = true;
            } else if (tok.size() >= 4) {
                filePattern(h, tok);
            } else {
                h.dataFiles.push_back(beside(value));
            }
        } else if (field == "space") {
            setSpace(h, value);
        } else if (field == "space dimension") {
            if (parseInt(field, value) != 3)
                fail("space dimension", "is " + value + "; voxlight reads 3-D spaces only");
        } else if (field == "space directions") {
            for (const auto& t : splitWs(value)) {
                if (t == "none")
                    fail("space directions", "has 'none' for an axis (a non-spatial axis)",
                         "voxlight reads scalar volumes with three spatial axes");
                h.spaceDirections.push_back(parseVector(field, t));
            }
        } else if (field == "space origin") {
            h.spaceOrigin = parseVector(field, value);
        } else if (field == "spacings") {
            for (const auto& t : splitWs(value)) {
                const double s = parseDouble(field, t);
                if (!(s > 0)) fail("spacings", "holds " + t + "; spacing must be positive");
                h.spacings.push_back(s);
            }
        } else if (field == "line skip" || field == "byte skip") {
            if (parseInt(field, value) != 0)
                fail(field, "is " + value + ", which VTK 9.1 does not support",
                     "remove the skipped bytes from the data");
        }
    }

    fs::path beside(const std::string& name) const {
        const fs::path p(name);
        return p.is_absolute() ? p : path_.parent_path() / p;
    }

    /// "<format> <first> <last> <step> [<subdim>]", format with one %d conversion (VTK passes it to
    /// snprintf, so anything else is refused).
    void filePattern(NrrdHeader& h, const std::vector<std::string>& tok) {
        const std::string& fmt = tok[0];
        int conversions = 0;
        for (std::size_t i = 0; i < fmt.size(); ++i) {
            if (fmt[i] != '%') continue;
            if (i + 1 < fmt.size() && fmt[i + 1] == '%') {
                ++i;
                continue;
            }
            std::size_t j = i + 1;
            while (j < fmt.size() && std::isdigit(static_cast<unsigned char>(fmt[j]))) ++j;
            if (j >= fmt.size() || fmt[j] != 'd' || j - i > 4)
                fail("data file", "pattern '" + fmt + "' must hold one %d conversion (e.g. %03d)");
            ++conversions;
            i = j;
        }
        if (conversions != 1)
            fail("data file", "pattern '" + fmt + "' must hold one %d conversion (e.g. %03d)");
        const std::int64_t first = parseInt("data file", tok[1]);
        const std::int64_t last = parseInt("data file", tok[2]);
        const std::int64_t step = parseInt("data file", tok[3]);
        if (tok.size() > 4) subdim_ = parseInt("data file", tok[4]);
        const auto inRange = [](std::int64_t x) {
            return x >= -kMaxPatternIndex && x <= kMaxPatternIndex;
        };
        if (!inRange(first) || !inRange(last) || !inRange(step))
            fail("data file", "pattern indices " + tok[1] + " " + tok[2] + " " + tok[3] +
                                  " are beyond +-" + std::to_string(kMaxPatternIndex));
        if (step <= 0 || last < first || (last - first) / step >= core::kMaxDim)
            fail("data file", "pattern range " + tok[1] + ".." + tok[2] + " step " + tok[3] +
                                  " is empty, endless or longer than " +
                                  std::to_string(core::kMaxDim) + " files");
        for (std::int64_t i = first; i <= last; i += step) {
            std::string name(fmt.size() + kVtkPatternSlack, '\0');
            const int n = std::snprintf(name.data(), name.size(), fmt.c_str(), int(i));
            name.resize(std::min(std::size_t(std::max(n, 0)), name.size() - 1));
            h.dataFiles.push_back(beside(name));
        }
    }

    fs::path path_;
    bool listed_ = false;                 ///< "data file: LIST"
    std::optional<std::int64_t> subdim_;  ///< the axis the files split (1-based), when stated
};

}  // namespace

std::uint64_t NrrdHeader::voxelCount() const {
    std::uint64_t n = 1;
    for (auto s : sizes) n *= std::uint64_t(s);
    return n;
}

NrrdHeader parseNrrdHeader(const fs::path& path) { return Parser(path).parse(); }

void checkNrrdDataSize(const NrrdHeader& h, const fs::path& path) {
    const std::uint64_t need = h.voxelCount() * std::uint64_t(h.typeBytes);
    if (h.dataFiles.size() > 1) {
        // One raw slice per file (parse() allows nothing else).
        const std::uint64_t perFile = need / h.dataFiles.size();
        for (const fs::path& f : h.dataFiles) {
            std::error_code ec;
            const std::uint64_t have = fs::file_size(f, ec);
            if (ec || !fs::is_regular_file(f))
                throw InputError(path.string(), "data file",
                                 "names '" + f.string() + "', which cannot be opened",
                                 "put the slice files beside the header");
            if (have < perFile)
                throw InputError(f.string(), "data",
                                 "file holds " + std::to_string(have) + " bytes, header claims " +
                                     std::to_string(perFile) + " per slice",
                                 "the data is truncated; copy it again");
        }
        return;
    }
    const bool detached = !h.dataFiles.empty();
    const fs::path data = detached ? h.dataFiles[0] : path;
    std::error_code ec;
    const std::uint64_t fileBytes = fs::file_size(data, ec);
    if (ec || !fs::is_regular_file(data))
        throw InputError(path.string(), "data file",
                         "names '" + data.string() + "', which cannot be opened",
                         "put the data file beside the header");
    const std::uint64_t offset = detached ? 0 : h.headerBytes;
    const std::uint64_t have = fileBytes - std::min(fileBytes, offset);
    const std::string dataName = data.string();
    switch (h.encoding) {
        case NrrdEncoding::Raw:
            if (have < need)
                throw InputError(dataName, "data",
                                 "file holds " + std::to_string(have) + " bytes, header claims " +
                                     std::to_string(need) + " (" + std::to_string(h.voxelCount()) +
                                     " x " + h.type + ")",
                                 "the data is truncated; copy it again");
            break;
        case NrrdEncoding::Gzip:
            if (need > kVtkMaxGzipBytes)
                throw InputError(
                    path.string(), "encoding",
                    "gzip data of " + std::to_string(need) + " bytes exceeds VTK 9.1's 4 GiB limit",
                    "store the volume raw");
            if (have == 0)
                throw InputError(
                    dataName, "data",
                    "file holds no gzip data, header claims " + std::to_string(need) + " bytes",
                    "the data is truncated; copy it again");
            break;  // a short stream is reported by VTK's gzread after decoding
        case NrrdEncoding::Ascii: {
            // Count whitespace-separated values (VTK would leave the missing ones unset).
            std::ifstream in(data, std::ios::binary);
            std::vector<char> chunk(1 << 16);
            std::uint64_t values = 0;
            bool inToken = false;
            while (values < h.voxelCount() && in) {
                in.read(chunk.data(), std::streamsize(chunk.size()));
                const auto n = in.gcount();
                for (std::streamsize i = 0; i < n; ++i) {
                    const bool ws = std::isspace(static_cast<unsigned char>(chunk[i])) != 0;
                    if (!ws && !inToken) ++values;
                    inToken = !ws;
                }
            }
            if (values < h.voxelCount())
                throw InputError(dataName, "data",
                                 "file holds " + std::to_string(values) +
                                     " ascii values, header claims " +
                                     std::to_string(h.voxelCount()),
                                 "the data is truncated; copy it again");
            break;
        }
    }
}

core::Geometry nrrdGeometry(const NrrdHeader& h, const fs::path& path) {
    core::Geometry g;
    g.dims = {int(h.sizes[0]), int(h.sizes[1]), h.dimension == 3 ? int(h.sizes[2]) : 1};
    if (!h.spaceDirections.empty()) {
        for (int a = 0; a < 3; ++a) {
            const glm::dvec3 v = h.spaceToLps * h.spaceDirections[std::size_t(a)];
            const double len = glm::length(v);
            if (!(len > 0) || !std::isfinite(len))
                throw InputError(path.string(), "space directions",
                                 "axis " + std::to_string(a) +
                                     (len > 0 ? " has a spacing vector too long to measure"
                                              : " has a zero-length direction"),
                                 "every axis needs a non-zero spacing vector in mm");
            g.spacing[a] = len;
            g.direction[a] = v / len;
        }
        const glm::dmat3 gram = glm::transpose(g.direction) * g.direction;
        for (int r = 0; r < 3; ++r)
            for (int c = r + 1; c < 3; ++c)
                if (std::abs(gram[c][r]) > kOrthoTol)
                    throw InputError(path.string(), "space directions",
                                     "axes " + std::to_string(r) + " and " + std::to_string(c) +
                                         " are not orthogonal (cosine " +
                                         std::to_string(gram[c][r]) + "): a sheared grid",
                                     "resample the volume to an orthogonal grid first");
        if (h.spaceOrigin) g.origin = h.spaceToLps * *h.spaceOrigin;
        // VTK reads raw rows of LAS files bottom-up: voxel (i, j, k) of its output is the file's
        // (i, ny−1−j, k), so start at the file's last row and walk j backwards.
        if (h.spaceFlipsY && h.encoding == NrrdEncoding::Raw) {
            g.origin += g.direction[1] * g.spacing[1] * double(g.dims.y - 1);
            g.direction[1] = -g.direction[1];
        }
    } else {
        // No space directions: orientation undefined (NRRD spec); keep VTK's reading.
        for (std::size_t a = 0; a < h.spacings.size(); ++a) g.spacing[int(a)] = h.spacings[a];
        if (h.spaceOrigin) g.origin = *h.spaceOrigin;
    }
    return g;
}

}  // namespace voxlight::io::detail
