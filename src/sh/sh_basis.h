// SPDX-License-Identifier: MIT
#pragma once
// Real orthonormal spherical harmonics (SH): the basis every SH quantity in voxlight (visibility,
// lights, transfer) is expressed in.
//
// References: Wyman et al. 2006, Appendix (real SH, eq. 12–15); Kronander et al. 2012 §3.2; Sloan,
// "Efficient spherical harmonic evaluation", JCGT 2013 (Cartesian recurrences); Green, "Spherical
// harmonic lighting: the gritty details", 2003.
//
// Conventions (the single place they are stated; every sh/ and lights/ file follows them):
// * Index i = l(l+1) + m for band l = 0..L and order m = −l..l; a band-L expansion has (L+1)²
//   coefficients.
// * Orthonormal: ∫_S² Y_i Y_j dω = δ_ij (dω = sinθ dθ dφ; the sphere has area 4π).
// * Spherical coordinates: θ is the angle from +z, φ the angle from +x towards +y, so
//   ω = (sinθ cosφ, sinθ sinφ, cosθ).
// * Y_l^0 = K_l^0 P_l(cosθ); Y_l^m = √2 K_l^m P_l^m(cosθ) cos(mφ) for m > 0;
//   Y_l^m = √2 K_l^|m| P_l^|m|(cosθ) sin(|m|φ) for m < 0, with
//   K_l^m = √((2l+1)/(4π) · (l−m)!/(l+m)!).
// * **No Condon–Shortley phase**: P_l^m here is the associated Legendre function *without* the
//   (−1)^m factor (as C++17 std::assoc_legendre). Hence band 1 is
//   (Y_1^{-1}, Y_1^0, Y_1^1) = √(3/4π)·(y, z, x) with positive signs, and
//   Y_l^{±l} ∝ +Re/Im((x+iy)^l). This is the convention of Ivanic & Ruedenberg's real rotation
//   recursion (band-1 rotation matrix = the 3×3 rotation with rows/columns permuted to (y, z, x)),
//   so no sign fix-ups are needed there. Tested in tests/sh/test_sh_basis.cpp (CondonShortley*).
//   Converting to/from a CS-phase basis: multiply coefficient (l, m) by (−1)^m.
//
// Evaluation paths (all agree to float precision, see tests):
// * evalShFixed<L>(unitDir, out): L ≤ 4, hand-unrolled Cartesian polynomials, float, no allocation,
//   no checks beyond VL_DCHECK — the hot-loop path (a few ns per direction).
// * evalSh(L, dir, out): any L ≤ kMaxBand; checks and normalises `dir` (zero, NaN or Inf →
//   InputError), uses the unrolled path for L ≤ 4 and the Cartesian recurrence otherwise.
// * evalShUnit(L, unitDir, out) / evalShUnitDouble: the Cartesian normalised-Legendre recurrence
//   (no factorials, no trigonometry, exact at the poles), float or double, for any L ≤ kMaxBand.
// * evalShSlow(l, m, θ, φ): textbook reference in spherical coordinates (Legendre three-term
//   recurrence, K_l^m via a product of ratios so no factorial overflow), double; for tests and
//   validation only.
//
// Supported bands: rendering uses L ≤ 4 (1/4/9/16/25 coefficients); every routine is tested to
// L = 8 and accepts up to kMaxBand = 32 for high-band experiments (e.g. Zhang 2013 Fig. 7, SH with
// ≈ 642 coefficients).
#include <glm/glm.hpp>
#include <span>

namespace voxlight::sh {

/// Largest band any sh/ routine accepts.
inline constexpr int kMaxBand = 32;
/// Coefficient count of a band-L expansion.
constexpr int shCount(int maxBand) { return (maxBand + 1) * (maxBand + 1); }
inline constexpr int kMaxCoeffs = shCount(kMaxBand);
/// Largest band of the unrolled fast path.
inline constexpr int kMaxFixedBand = 4;

/// Flat index of (l, m).
constexpr int shIndex(int l, int m) { return l * (l + 1) + m; }
/// Band l of flat index i.
int shBandOf(int i);
/// Band L whose expansion has exactly `count` coefficients; throws InputError when count is not a
/// square (1, 4, 9 …).
int shBandForCount(int count);

/// Validates a band from outside (scene JSON, CLI): 0 ≤ L ≤ kMaxBand, else InputError naming
/// `source` and `field`.
void checkBand(int maxBand, const char* source = "sh", const char* field = "bands");

/// Unit vector of `dir`, or InputError (source, field) when it is zero, NaN or infinite.
glm::vec3 normalizeDirection(const glm::vec3& dir, const char* source = "sh",
                             const char* field = "direction");
glm::dvec3 normalizeDirection(const glm::dvec3& dir, const char* source = "sh",
                              const char* field = "direction");

/// Unit direction from spherical coordinates (θ from +z, φ from +x towards +y).
glm::dvec3 sphericalToDirection(double theta, double phi);

/// Fast unrolled evaluation of all (L+1)² basis functions at a *unit* direction, L ≤ 4. `out` must
/// hold shCount(L) floats. No allocation; VL_DCHECK only (debug) on the direction's length.
template <int L>
void evalShFixed(const glm::vec3& unitDir, float* out);

/// evalShFixed for the bands of a field of `count` ≤ 16 coefficients (1–4: band 1, 5–9: band 2,
/// else band 3): the hot-loop evaluation of a light's direction against such a field.
inline void evalShForCount(int count, const glm::vec3& unitDir, float* out) {
    if (count <= 4)
        evalShFixed<1>(unitDir, out);
    else if (count <= 9)
        evalShFixed<2>(unitDir, out);
    else
        evalShFixed<3>(unitDir, out);
}

/// Recurrence evaluation at a unit direction, any L ≤ kMaxBand. `out.size() >= shCount(L)`.
void evalShUnit(int maxBand, const glm::vec3& unitDir, std::span<float> out);
void evalShUnitDouble(int maxBand, const glm::dvec3& unitDir, std::span<double> out);

/// Checked evaluation: normalises `dir` (InputError if zero/NaN/Inf) and picks the fastest path.
void evalSh(int maxBand, const glm::vec3& dir, std::span<float> out);

/// Reference Y_l^m(θ, φ) in double from the textbook definition above. For tests and validation,
/// not for hot loops.
double evalShSlow(int l, int m, double theta, double phi);
/// Same at a direction (normalised; InputError if zero).
double evalShSlow(int l, int m, const glm::dvec3& dir);

/// ∫ f g over the sphere for two expansions: the dot product over min(a.size(), b.size())
/// coefficients.
double shDot(std::span<const float> a, std::span<const float> b);

/// f(ω) = Σ_i c_i Y_i(ω) for a coefficient vector of (L+1)² entries (any L ≤ kMaxBand); `dir` must
/// be unit length.
float shReconstruct(std::span<const float> coeffs, const glm::vec3& unitDir);
double shReconstructDouble(std::span<const double> coeffs, const glm::dvec3& unitDir);

// ---- Unrolled polynomials (header so that hot loops inline them)
// ---------------------------------------------------
namespace detail {
// Constants: K_l^m (×√2 for m ≠ 0) times the integer factors of the Cartesian polynomials (Sloan
// 2013, without the Condon–Shortley sign).
inline constexpr float kY00 = 0.28209479177387814f;  // 1/(2√π)
inline constexpr float kY1 = 0.48860251190291992f;   // √(3/4π)
inline constexpr float kY2a = 1.0925484305920792f;   // √(15/4π)            xy, yz, xz
inline constexpr float kY20 = 0.31539156525252005f;  // √(5/16π)            3z²−1
inline constexpr float kY22 = 0.54627421529603959f;  // √(15/16π)           x²−y²
inline constexpr float kY33 = 0.59004358992664352f;  // √(35/32π)           y(3x²−y²), x(x²−3y²)
inline constexpr float kY32 = 2.8906114426405538f;  // √(105/4π)           xyz
inline constexpr float kY31 = 0.45704579946446572f;  // √(21/32π)           y(5z²−1), x(5z²−1)
inline constexpr float kY30 = 0.37317633259011540f;  // √(7/16π)            z(5z²−3)
inline constexpr float kY32b = 1.4453057213202769f;  // √(105/16π)          z(x²−y²)
inline constexpr float kY44 = 2.5033429417967046f;   // 3√(35/π)/4          xy(x²−y²)
inline constexpr float kY43 = 1.7701307697799304f;  // 3√(35/2π)/4         yz(3x²−y²), xz(x²−3y²)
inline constexpr float kY42 = 0.94617469575756008f;  // 3√(5/π)/4           xy(7z²−1)
inline constexpr float kY41 = 0.66904654355728921f;  // 3√(5/2π)/4          yz(7z²−3), xz(7z²−3)
inline constexpr float kY40 = 0.10578554691520431f;   // 3/(16√π)            35z⁴−30z²+3
inline constexpr float kY42b = 0.47308734787878004f;  // 3√(5/π)/8           (x²−y²)(7z²−1)
inline constexpr float kY44b = 0.62583573544917614f;  // 3√(35/π)/16         x⁴−6x²y²+y⁴
}  // namespace detail

template <int L>
inline void evalShFixed(const glm::vec3& d, float* out) {
    static_assert(L >= 0 && L <= kMaxFixedBand,
                  "evalShFixed covers bands 0..4; use evalShUnit beyond");
    using namespace detail;
    out[0] = kY00;
    if constexpr (L >= 1) {
        const float x = d.x, y = d.y, z = d.z;
        out[1] = kY1 * y;
        out[2] = kY1 * z;
        out[3] = kY1 * x;
        if constexpr (L >= 2) {
            const float x2 = x * x, y2 = y * y, z2 = z * z;
            out[4] = kY2a * x * y;
            out[5] = kY2a * y * z;
            out[6] = kY20 * (3.0f * z2 - 1.0f);
            out[7] = kY2a * x * z;
            out[8] = kY22 * (x2 - y2);
            if constexpr (L >= 3) {
                const float fz5 = 5.0f * z2 - 1.0f;
                out[9] = kY33 * y * (3.0f * x2 - y2);
                out[10] = kY32 * x * y * z;
                out[11] = kY31 * y * fz5;
                out[12] = kY30 * z * (5.0f * z2 - 3.0f);
                out[13] = kY31 * x * fz5;
                out[14] = kY32b * z * (x2 - y2);
                out[15] = kY33 * x * (x2 - 3.0f * y2);
                if constexpr (L >= 4) {
                    const float fz7a = 7.0f * z2 - 1.0f, fz7b = 7.0f * z2 - 3.0f;
                    out[16] = kY44 * x * y * (x2 - y2);
                    out[17] = kY43 * y * z * (3.0f * x2 - y2);
                    out[18] = kY42 * x * y * fz7a;
                    out[19] = kY41 * y * z * fz7b;
                    out[20] = kY40 * (35.0f * z2 * z2 - 30.0f * z2 + 3.0f);
                    out[21] = kY41 * x * z * fz7b;
                    out[22] = kY42b * (x2 - y2) * fz7a;
                    out[23] = kY43 * x * z * (x2 - 3.0f * y2);
                    out[24] = kY44b * (x2 * x2 - 6.0f * x2 * y2 + y2 * y2);
                }
            }
        }
    }
}

}  // namespace voxlight::sh
