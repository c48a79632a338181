// SPDX-License-Identifier: MIT
// voxlight's NIfTI geometry and values against nibabel, an independent reader (Debian's
// python3-nibabel).
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "io/volume_io.h"
#include "support/test_support.h"

using namespace voxlight;

namespace {

/// Runs nibabel on `path`; returns {dims, affine (RAS, 4×4), scaled values at probe voxels}, or
/// null if unavailable.
nlohmann::json nibabelFacts(const std::filesystem::path& path) {
    const std::string script =
        "import sys, json\n"
        "try:\n"
        "    import nibabel as nib, numpy as np\n"
        "except ImportError:\n"
        "    print('null'); sys.exit(0)\n"
        "img = nib.load(sys.argv[1])\n"
        "data = np.asanyarray(img.dataobj)\n"
        "scaled = img.get_fdata(dtype=np.float64)\n"
        "s = data.shape\n"
        "probes = [(0,0,0), (s[0]//2, s[1]//2, s[2]//2), (s[0]//3, s[1]//4, s[2]//5), (s[0]-1, "
        "s[1]-1, s[2]-1)]\n"
        "print(json.dumps({'dims': list(map(int, s[:3])), 'affine': img.affine.tolist(),\n"
        "  'probes': [list(p) for p in probes], 'values': [float(scaled[p]) for p in probes]}))\n";
    const std::string cmd = "/usr/bin/python3 -c \"" +
                            [&] {
                                std::string esc;
                                for (char c : script)
                                    esc += (c == '"' ? std::string("\\\"") : std::string(1, c));
                                return esc;
                            }() +
                            "\" '" + path.string() + "' 2>/dev/null";
    FILE* pipe = ::popen(cmd.c_str(), "r");
    if (!pipe) return nullptr;
    std::string out;
    std::array<char, 4096> buf;
    while (std::size_t n = std::fread(buf.data(), 1, buf.size(), pipe)) out.append(buf.data(), n);
    ::pclose(pipe);
    const auto j = nlohmann::json::parse(out, nullptr, false);
    return j.is_discarded() ? nlohmann::json(nullptr) : j;
}

// nibabel computes in float64 from the same float32 header fields; agreement is limited by float32
// rounding of the sform (values up to ~200 mm → ~2e-5 mm).
constexpr double kWorldTolMm = 1e-3;
// Scaled values: slope·stored + intercept in float32 (voxlight sampler) vs float64 (nibabel);
// values up to ~4000.
constexpr double kValueTol = 1e-3;

void compareWithNibabel(const std::filesystem::path& path) {
    const nlohmann::json nib = nibabelFacts(path);
    if (nib.is_null())
        GTEST_SKIP()
            << "/usr/bin/python3 with nibabel is not available (tools/setup.sh installs it)";
    const core::Volume v = io::readVolume(path);
    ASSERT_EQ(v.dims(), glm::ivec3(nib["dims"][0], nib["dims"][1], nib["dims"][2])) << path;
    const auto& A = nib["affine"];
    for (std::size_t p = 0; p < nib["probes"].size(); ++p) {
        const auto& q = nib["probes"][p];
        const glm::dvec3 ijk(q[0].get<double>(), q[1].get<double>(), q[2].get<double>());
        // nibabel: RAS = A·[ijk,1]; voxlight: LPS = indexToWorld(ijk). LPS = (−R, −A, S).
        glm::dvec3 ras;
        for (int r = 0; r < 3; ++r)
            ras[r] = A[r][0].get<double>() * ijk.x + A[r][1].get<double>() * ijk.y +
                     A[r][2].get<double>() * ijk.z + A[r][3].get<double>();
        const glm::dvec3 lps = v.geometry().indexToWorld(ijk);
        EXPECT_NEAR(lps.x, -ras.x, kWorldTolMm) << path << " voxel " << q.dump();
        EXPECT_NEAR(lps.y, -ras.y, kWorldTolMm) << path << " voxel " << q.dump();
        EXPECT_NEAR(lps.z, ras.z, kWorldTolMm) << path << " voxel " << q.dump();
        EXPECT_NEAR(v.at(int(ijk.x), int(ijk.y), int(ijk.z)), nib["values"][p].get<double>(),
                    kValueTol)
            << path << " voxel " << q.dump();
    }
}

}  // namespace

TEST(IndependentReader, Colin27AgreesWithNibabel) {
    VL_REQUIRE_FILE(path, "/usr/share/mricron/templates/ch2.nii.gz");
    const core::Volume v = io::readVolume(path);
    EXPECT_EQ(v.dims(), glm::ivec3(181, 217, 181));
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(v.geometry().spacing[a], 1.0, 1e-6);
    const auto r = v.physicalRange();
    EXPECT_GE(r[0], 0.0);
    EXPECT_GT(r[1], 100.0);  // a T1 brain: plenty of contrast, uint8 template
    compareWithNibabel(path);
}

TEST(IndependentReader, ObliqueGantryPitchCtAgreesWithNibabel) {
    VL_REQUIRE_SHARED(path, "ct/ct-pitch-oblique.nii.gz");
    compareWithNibabel(path);
}

TEST(IndependentReader, ScaledContrastMrAgreesWithNibabel) {
    VL_REQUIRE_SHARED(path, "mr/mr-gd-contrast.nii.gz");
    compareWithNibabel(path);
}

TEST(IndependentReader, AbdomenCtAgreesWithNibabel) {
    VL_REQUIRE_SHARED(path, "ct/abdomen-totalseg/example_ct.nii.gz");
    compareWithNibabel(path);
}
