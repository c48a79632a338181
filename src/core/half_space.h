// SPDX-License-Identifier: MIT
#pragma once
// A half-space {x : dot(x − point, normal) ≥ 0} in world millimetres: what a clip plane or one
// face of a crop box keeps. Libraries below render/ (visibility/) read clip geometry as a list of
// these, the kept region being their intersection (convex).
#include <glm/glm.hpp>
#include <vector>

namespace voxlight::core {

struct HalfSpace {
    glm::dvec3 point{0.0};
    glm::dvec3 normal{0.0, 0.0, 1.0};  ///< unit
    /// Signed distance (mm) of world point x: ≥ 0 inside (kept), < 0 outside (removed).
    double distance(const glm::dvec3& x) const { return glm::dot(x - point, normal); }
};

/// The six half-spaces an axis-aligned box [lo, hi] (world mm) keeps.
inline std::vector<HalfSpace> boxHalfSpaces(const glm::dvec3& lo, const glm::dvec3& hi) {
    std::vector<HalfSpace> out;
    for (int a = 0; a < 3; ++a) {
        glm::dvec3 n(0.0);
        n[a] = 1.0;
        out.push_back({lo, n});
        out.push_back({hi, -n});
    }
    return out;
}

}  // namespace voxlight::core
