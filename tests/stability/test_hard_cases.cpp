// SPDX-License-Identifier: MIT
// Hard cases through every method that renders a volume (issue #17 item 4, a first slice): tiny
// and degenerate grids, constant and non-finite voxels, extreme spacing and anisotropy, empty and
// opaque transfer functions. Each must either render finite, non-negative radiance with coverage
// in [0, 1], or refuse with an InputError — never crash, hang or produce NaN.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "stability/hard_cases_util.h"
#include "support/test_support.h"

using namespace voxlight;
using namespace voxlight::test;
using nlohmann::json;

namespace {

float sphereish(int i, int j, int k) { return float((i * 7 + j * 3 + k * 5) % 11) * 100.f; }
float constant(int, int, int) { return 400.f; }
float withNan(int i, int j, int k) {
    if ((i + j + k) % 5 == 0) return std::numeric_limits<float>::quiet_NaN();
    if ((i + j + k) % 7 == 0) return std::numeric_limits<float>::infinity();
    return sphereish(i, j, k);
}

const std::vector<HardVolume>& hardVolumes() {
    static const std::vector<HardVolume> v = {
        {"1x1x1", {1, 1, 1}, {1, 1, 1}, sphereish},
        {"2x2x2", {2, 2, 2}, {1, 1, 1}, sphereish},
        {"single-slice", {16, 16, 1}, {1, 1, 1}, sphereish},
        {"constant", {12, 12, 12}, {1, 1, 1}, constant},
        {"nan-inf-voxels", {12, 12, 12}, {1, 1, 1}, withNan},
        {"spacing-1e-3mm", {12, 12, 12}, {1e-3, 1e-3, 1e-3}, sphereish},
        {"spacing-1e3mm", {12, 12, 12}, {1e3, 1e3, 1e3}, sphereish},
        {"anisotropic-1:100", {12, 12, 12}, {0.1, 0.1, 10.0}, sphereish},
    };
    return v;
}

}  // namespace

TEST(HardCases, EveryMethodRendersFiniteOrRefusesClearly) {
    const test::TempDir tmp;
    const std::vector<std::string> methods = allMethods();
    ASSERT_GE(methods.size(), 8u);
    // Variants of the scene around each volume: as is; non-finite voxels replaced (the loader
    // refuses them by default); a clip plane that removes everything; one through the middle that
    // keeps shadows from the removed half; the camera inside the volume.
    const std::vector<std::string> variants = {"plain", "nonfinite-min", "clip-all", "clip-half",
                                               "camera-inside"};
    int rendered = 0, refused = 0;
    for (const HardVolume& h : hardVolumes()) {
        const auto path = writeHard(h, tmp.path());
        const glm::dvec3 centre = 0.5 * glm::dvec3(h.dims - 1) * h.spacing;
        for (const std::string& variant : variants)
            for (double sigma : {0.0, 0.05, 1e6}) {
                for (const std::string& method : methods) {
                    json volume = path.string();
                    if (variant == "nonfinite-min")
                        volume = {{"path", path.string()}, {"nonfinite", "min"}};
                    json d = {{"volume", volume},
                              {"transfer_function", tfOf(sigma)},
                              {"method", methodOf(method)},
                              {"lights", json::array({{{"type", "directional"},
                                                       {"direction", {0.3, 0.4, -0.8}},
                                                       {"intensity", 4}}})},
                              {"image", {{"width", 12}, {"height", 10}}}};
                    if (variant == "clip-all")
                        d["clip_planes"] =
                            json::array({{{"point", {-1e5, 0, 0}}, {"normal", {-1, 0, 0}}}});
                    if (variant == "clip-half")
                        d["clip_planes"] = json::array({{{"point", {centre.x, centre.y, centre.z}},
                                                         {"normal", {0, 0, 1}},
                                                         {"shadows_from_removed", true}}});
                    if (variant == "camera-inside")
                        d["camera"] = {{"eye", {centre.x, centre.y, centre.z}},
                                       {"target", {centre.x, centre.y + 1.0, centre.z}}};
                    const std::string what =
                        h.name + " " + variant + " σt " + std::to_string(sigma) + " " + method;
                    // A clear refusal is allowed (renderOrRefuse says which, for the record).
                    if (const auto r = renderOrRefuse(d, what)) {
                        expectSane(r->image, what);
                        ++rendered;
                    } else {
                        ++refused;
                    }
                }
            }
    }
    std::printf("%d renders, %d refusals\n", rendered, refused);
    EXPECT_GT(rendered, refused);
}
