// SPDX-License-Identifier: MIT
#include "sh/sphere_samples.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <ostream>
#include <string>
#include <tuple>

#include "core/error.h"
#include "core/rng.h"

namespace voxlight::sh {

namespace {
constexpr double kPi = std::numbers::pi;

void checkCount(int n, const char* what) {
    if (n < 1)
        throw InputError("sh", what, "sample count must be at least 1, got " + std::to_string(n),
                         "ask for a positive number of directions");
}

void basePolyhedron(Polyhedron p, std::vector<glm::dvec3>& v, std::vector<glm::ivec3>& f) {
    switch (p) {
        case Polyhedron::Tetrahedron:
            v = {{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}};
            f = {{0, 1, 2}, {0, 3, 1}, {0, 2, 3}, {1, 3, 2}};
            break;
        case Polyhedron::Octahedron:
            v = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
            f = {{4, 0, 2}, {4, 2, 1}, {4, 1, 3}, {4, 3, 0},
                 {5, 2, 0}, {5, 1, 2}, {5, 3, 1}, {5, 0, 3}};
            break;
        case Polyhedron::Icosahedron: {
            const double t = (1.0 + std::sqrt(5.0)) / 2.0;
            v = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                 {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
            f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                 {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                 {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                 {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
            break;
        }
    }
    for (auto& x : v) x = glm::normalize(x);
    // Make every face counter-clockwise seen from outside.
    for (auto& t : f) {
        const glm::dvec3 n = glm::cross(v[t.y] - v[t.x], v[t.z] - v[t.x]);
        if (glm::dot(n, v[t.x] + v[t.y] + v[t.z]) < 0) std::swap(t.y, t.z);
    }
}

// Solid angle of the spherical triangle (a, b, c) — Van Oosterom & Strackee 1983.
double sphericalTriangleArea(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
    const double num = std::abs(glm::dot(a, glm::cross(b, c)));
    const double den = 1.0 + glm::dot(a, b) + glm::dot(b, c) + glm::dot(c, a);
    return 2.0 * std::atan2(num, den);
}
}  // namespace

std::ostream& operator<<(std::ostream& os, const SphereSamples& s) {
    double sum = 0;
    for (double w : s.weights) sum += w;
    return os << "SphereSamples{n=" << s.size() << ", Σw=" << sum << "}";
}

std::string_view toString(Polyhedron p) {
    switch (p) {
        case Polyhedron::Tetrahedron:
            return "tetrahedron";
        case Polyhedron::Octahedron:
            return "octahedron";
        case Polyhedron::Icosahedron:
            return "icosahedron";
    }
    return "?";
}

SphereMesh subdividedPolyhedron(Polyhedron base, int frequency) {
    if (frequency < 1 || frequency > 256)
        throw InputError(
            "sh", "frequency",
            "polyhedron subdivision frequency " + std::to_string(frequency) + " is outside 1..256",
            "use 1, 2, 4, 8 or 16 (icosahedron: 12, 42, 162, 642, 2562 directions)");
    std::vector<glm::dvec3> bv;
    std::vector<glm::ivec3> bf;
    basePolyhedron(base, bv, bf);

    SphereMesh mesh;
    // Shared edge/corner vertices are merged through a key of their quantised projected position.
    std::map<std::tuple<long long, long long, long long>, int> index;
    auto vertexId = [&](const glm::dvec3& p) {
        const glm::dvec3 q = glm::normalize(p);
        const auto key = std::make_tuple(std::llround(q.x * 1e9), std::llround(q.y * 1e9),
                                         std::llround(q.z * 1e9));
        auto [it, inserted] = index.try_emplace(key, int(mesh.vertices.size()));
        if (inserted) mesh.vertices.push_back(q);
        return it->second;
    };
    const int f = frequency;
    for (const auto& face : bf) {
        const glm::dvec3 a = bv[face.x], b = bv[face.y], c = bv[face.z];
        // Grid point (i, j), i + j ≤ f, at a + (b−a) i/f + (c−a) j/f on the face plane.
        std::vector<int> ids((f + 1) * (f + 1), -1);
        auto id = [&](int i, int j) -> int& { return ids[i * (f + 1) + j]; };
        for (int i = 0; i <= f; ++i)
            for (int j = 0; i + j <= f; ++j)
                id(i, j) = vertexId(a + (b - a) * (double(i) / f) + (c - a) * (double(j) / f));
        for (int i = 0; i < f; ++i) {
            for (int j = 0; i + j < f; ++j) {
                mesh.triangles.push_back({id(i, j), id(i + 1, j), id(i, j + 1)});
                if (i + j + 1 < f)
                    mesh.triangles.push_back({id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)});
            }
        }
    }
    return mesh;
}

SphereSamples polyhedronSamples(Polyhedron base, int frequency, SampleWeighting weighting) {
    const SphereMesh mesh = subdividedPolyhedron(base, frequency);
    SphereSamples s;
    s.directions = mesh.vertices;
    const std::size_t n = mesh.vertices.size();
    if (weighting == SampleWeighting::Equal) {
        s.weights.assign(n, 4.0 * kPi / double(n));
        return s;
    }
    s.weights.assign(n, 0.0);
    for (const auto& t : mesh.triangles) {
        const double area =
            sphericalTriangleArea(mesh.vertices[t.x], mesh.vertices[t.y], mesh.vertices[t.z]);
        s.weights[t.x] += area / 3.0;
        s.weights[t.y] += area / 3.0;
        s.weights[t.z] += area / 3.0;
    }
    return s;
}

SphereSamples fibonacciSamples(int n) {
    checkCount(n, "fibonacci.count");
    SphereSamples s;
    s.directions.reserve(n);
    const double goldenAngle = kPi * (3.0 - std::sqrt(5.0));
    for (int i = 0; i < n; ++i) {
        const double z = 1.0 - (2.0 * i + 1.0) / n;
        const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
        const double phi = goldenAngle * i;
        s.directions.push_back({r * std::cos(phi), r * std::sin(phi), z});
    }
    s.weights.assign(n, 4.0 * kPi / n);
    return s;
}

SphereSamples jitteredSamples(int n, std::uint64_t seed, std::uint64_t pattern) {
    checkCount(n, "jittered.count");
    const int bands = std::clamp(int(std::lround(std::sqrt(n / 2.0))), 1, n);
    SphereSamples s;
    s.directions.reserve(n);
    s.weights.reserve(n);
    core::CounterRng rng(core::hashCounters(pattern, std::uint64_t(n), 0x5348u), seed);
    int k = 0;
    for (int b = 0; b < bands; ++b) {
        // Band b gets n/bands strata, the first n % bands bands one more.
        const int cols = n / bands + (b < n % bands ? 1 : 0);
        const double z0 = 1.0 - 2.0 * b / bands, z1 = 1.0 - 2.0 * (b + 1) / bands;
        for (int c = 0; c < cols; ++c, ++k) {
            const double z = z0 + (z1 - z0) * rng.uniformDouble();
            const double phi = 2.0 * kPi * (c + rng.uniformDouble()) / cols;
            const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
            s.directions.push_back({r * std::cos(phi), r * std::sin(phi), z});
            s.weights.push_back((z0 - z1) * 2.0 * kPi / cols);
        }
    }
    VL_CHECK_EQ(k, n);
    return s;
}

SphereSamples uniformRandomSamples(int n, std::uint64_t seed) {
    checkCount(n, "uniform.count");
    SphereSamples s;
    s.directions.reserve(n);
    for (int i = 0; i < n; ++i) {
        const std::uint64_t h = core::hashCounters(std::uint64_t(i), 0x756eu, 0, seed);
        const double z = 1.0 - 2.0 * core::toUnitDouble(h);
        const double phi = 2.0 * kPi * core::toUnitDouble(core::mix64(h));
        const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
        s.directions.push_back({r * std::cos(phi), r * std::sin(phi), z});
    }
    s.weights.assign(n, 4.0 * kPi / n);
    return s;
}

void gaussLegendre(int n, std::vector<double>& nodes, std::vector<double>& weights) {
    checkCount(n, "gauss_legendre.count");
    nodes.assign(n, 0.0);
    weights.assign(n, 0.0);
    // Newton iteration on P_n from the Tricomi initial guess; symmetric nodes computed once.
    for (int i = 0; i < (n + 1) / 2; ++i) {
        double x = std::cos(kPi * (i + 0.75) / (n + 0.5));
        double dp = 0;
        for (int it = 0; it < 100; ++it) {
            double p0 = 1.0, p1 = x;
            for (int k = 2; k <= n; ++k) {
                const double p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
                p0 = p1;
                p1 = p2;
            }
            if (n == 1) p0 = 1.0, p1 = x;
            dp = n * (x * p1 - p0) / (x * x - 1.0);
            const double dx = p1 / dp;
            x -= dx;
            if (std::abs(dx) < 1e-16) break;
        }
        // Recompute the derivative at the converged node.
        double p0 = 1.0, p1 = x;
        for (int k = 2; k <= n; ++k) {
            const double p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
            p0 = p1;
            p1 = p2;
        }
        dp = n == 1 ? 1.0 : n * (x * p1 - p0) / (x * x - 1.0);
        const double w = 2.0 / ((1.0 - x * x) * dp * dp);
        nodes[i] = x;
        nodes[n - 1 - i] = -x;
        weights[i] = weights[n - 1 - i] = w;
    }
    if (n == 1) {
        nodes[0] = 0.0;
        weights[0] = 2.0;
    }
}

SphereSamples gaussLegendreSamples(int n) {
    std::vector<double> z, wz;
    gaussLegendre(n, z, wz);
    const int nphi = 2 * n;
    SphereSamples s;
    s.directions.reserve(std::size_t(n) * nphi);
    s.weights.reserve(std::size_t(n) * nphi);
    for (int i = 0; i < n; ++i) {
        const double r = std::sqrt(std::max(0.0, 1.0 - z[i] * z[i]));
        for (int j = 0; j < nphi; ++j) {
            const double phi = 2.0 * kPi * (j + 0.5) / nphi;
            s.directions.push_back({r * std::cos(phi), r * std::sin(phi), z[i]});
            s.weights.push_back(wz[i] * 2.0 * kPi / nphi);
        }
    }
    return s;
}

double minimumSeparation(const std::vector<glm::dvec3>& dirs) {
    double maxDot = -1.0;
    for (std::size_t i = 0; i < dirs.size(); ++i)
        for (std::size_t j = i + 1; j < dirs.size(); ++j)
            maxDot = std::max(maxDot, glm::dot(dirs[i], dirs[j]));
    return std::acos(std::clamp(maxDot, -1.0, 1.0));
}

}  // namespace voxlight::sh
