// SPDX-License-Identifier: MIT
#pragma once
// Direction sets on the unit sphere with quadrature weights, used to project functions onto SH
// (Kronander 2012 eq. 4: V_i = (4π/N) Σ_k V(ω_k) Y_i(ω_k)) and as ray directions for visibility.
//
// Every set carries per-direction weights in steradians that sum to 4π, so that
// ∫ f dω ≈ Σ_k w_k f(ω_k). For sets where every direction represents the same area the weights are
// 4π/N.
//
// * Subdivided polyhedra (Kronander §4.1: "vertices of a tetrahedron, icosahedron or octahedron
//   subdivided … using the partition method of Lessing et al."): every face is partitioned into
//   frequency² sub-triangles on its plane (geodesic "class I" partition) and the vertices are
//   projected to the sphere. Vertex counts: tetrahedron 2f²+2, octahedron 4f²+2, icosahedron 10f²+2
//   (f = 1, 2, 4, 8, 16 → 12, 42, 162, 642, 2562 — the DSF sets of Zhang 2013). Weights: Equal
//   (4π/N, Kronander) or Area (one third of the solid angle of the incident spherical triangles —
//   better quadrature, still summing to exactly 4π).
// * Spherical Fibonacci (Keinert et al. 2015 / Marques 2013): N nearly uniform directions, weights
//   4π/N.
// * Stratified jittered (Ritschel 2007 §4: M precomputed jittered patterns): equal-area strata in
//   (z, φ), one counter-based random point per stratum; weights = the stratum's solid angle.
// * Uniform Monte-Carlo: N i.i.d. uniform directions, weights 4π/N.
// * Gauss–Legendre product rule: exact for spherical polynomials of degree ≤ 2n−1 (n nodes in z, 2n
//   in φ); the high-order truth for orthonormality and projection tests.
// All random sets are pure functions of (count, seed, pattern): independent of threads.
#include <cstdint>
#include <glm/glm.hpp>
#include <iosfwd>
#include <string_view>
#include <vector>

namespace voxlight::sh {

struct SphereSamples {
    std::vector<glm::dvec3> directions;  ///< unit vectors
    std::vector<double> weights;         ///< solid angle per direction [sr], Σ = 4π
    std::size_t size() const { return directions.size(); }
};
std::ostream& operator<<(std::ostream& os, const SphereSamples& s);

enum class Polyhedron { Tetrahedron, Octahedron, Icosahedron };
std::string_view toString(Polyhedron p);

/// Triangulated sphere: projected vertices and the (counter-clockwise seen from outside) triangles.
struct SphereMesh {
    std::vector<glm::dvec3> vertices;
    std::vector<glm::ivec3> triangles;
};

/// Base polyhedron with every face partitioned into frequency² triangles, vertices projected to the
/// sphere. frequency in 1..256, else InputError.
SphereMesh subdividedPolyhedron(Polyhedron base, int frequency);

enum class SampleWeighting { Equal, Area };
/// The vertices of subdividedPolyhedron() as a sample set.
SphereSamples polyhedronSamples(Polyhedron base, int frequency,
                                SampleWeighting weighting = SampleWeighting::Area);

/// Spherical Fibonacci set of n ≥ 1 directions.
SphereSamples fibonacciSamples(int n);

/// n ≥ 1 stratified jittered directions: round(√(n/2)) equal-height bands in z, each split evenly
/// in φ (bands differ by at most one stratum); pattern selects one of many independent patterns
/// (Ritschel's M patterns).
SphereSamples jitteredSamples(int n, std::uint64_t seed = 0, std::uint64_t pattern = 0);

/// n ≥ 1 independent uniform random directions.
SphereSamples uniformRandomSamples(int n, std::uint64_t seed = 0);

/// Gauss–Legendre nodes and weights on [−1, 1] (n ≥ 1): exact for polynomials of degree ≤ 2n−1.
void gaussLegendre(int n, std::vector<double>& nodes, std::vector<double>& weights);

/// Product rule: n Gauss–Legendre nodes in z × 2n equally spaced φ. Exact for SH products up to
/// band sum 2n−1.
SphereSamples gaussLegendreSamples(int n);

/// Smallest angle [rad] between any two directions of a set (O(N log N) is not needed for N ≤ ~10⁴:
/// O(N²)).
double minimumSeparation(const std::vector<glm::dvec3>& dirs);

}  // namespace voxlight::sh
