// SPDX-License-Identifier: MIT
// The GLSL mirror of the CPU ray caster's emission–absorption and gradient (Blinn–Phong) modes
// and its SH visibility shading (sh-local, sh-global, ritschel: render/sh_shading.h)
// (render/ray_caster.h, render/dvr_march.h, render/shading.h): the same optical model
// (ARCHITECTURE.md §1), ray set-up, sample lattice, pre-integrated segments, shading normal and
// lights, written line by line after the C++ so that the two images can be compared pixel by
// pixel. One fragment = one pixel (x, y) of the image, row 0 at the top (the film's row y is
// the framebuffer's row y, so a read-back gives the image top first).
//
// What differs from the CPU, and why the images differ by a few 8-bit levels at most:
//   - trilinear interpolation and the gradient's six taps by the texture unit (its own weight
//     precision; the CPU interpolates in float with FMA and reads a precomputed central-difference
//     table that equals the six taps up to rounding),
//   - ray set-up in float (the CPU's is double, then rounded to float),
//   - the pre-integration table's cumulative integrals as float pairs (hi + lo) instead of
//     double, and the specular power by pow() instead of the CPU's interpolated table,
//   - SH shading: the visibility field resampled (two points per voxel) as half floats and interpolated
//     by the texture unit (render/sh_field_grid.h) instead of the field's own interpolation.
// Empty-space skipping: rays are clipped to the box of the non-empty skip cells (the CPU's
// visibleRange()), and inside it a sample in an empty skip cell jumps ahead by the cell's skip
// distance (grid::BrickMajorants::skipDistances: the cube of cells within d − 1 is empty) to the
// last lattice sample still inside that cube. Only transparent segments are passed over, as the
// CPU's run traversal passes over them, so the image does not change.
#version 450 core
layout(location = 0) out vec4 outFilm;  // linear radiance + T·background, alpha = 1 − T

const int kMaxLights = 8;      // = viewer/gl_support.h kMaxGlLights
const int kMaxClipPlanes = 8;  // = viewer/gl_support.h kMaxGlClipPlanes
const float kOpacitySeriesTau = 0.01;  // dvr_march.h
const float kPointSampleFraction = 0.01;  // TfTable::kPointSampleFraction

// Volume: physical value = texel · uValueScale + uValueOffset; index space has voxel centres at
// integers, texture coordinates (p + 0.5) / dims.
uniform sampler3D uVolume;
uniform vec3 uDims;
uniform float uValueScale, uValueOffset;
uniform mat3 uWorldToIndex;  // diag(1/spacing) · directionᵀ
uniform vec3 uOrigin;
uniform vec3 uIndexBoxLo, uIndexBoxHi;      // the volume box in index space
uniform bool uAnyVisible;
uniform vec3 uVisibleLo, uVisibleHi;        // RayCaster::visibleRange's box (index space)
uniform mat3 uGradientMatrix;               // (Δi, Δj, Δk) → world gradient

// Skip distances of the kSkipCellVoxels³ skip cells (uSkip: options.emptySpaceSkipping).
uniform bool uSkip;
uniform usampler3D uSkipDistance;
uniform ivec3 uCellCounts;
uniform float uCellSize;

// Per-pixel jitter (RaySegment::jitter), computed on the CPU with the same hash.
uniform sampler2D uJitter;

// The TF table (optics::TfTable::nodes()): rows of kTableCells + 1 texels.
//   0: σt, σt·a (RGB)   1: σt·(1−a)·e (RGB)   2/3: cumulative of row 0, hi/lo float pair
//   4/5: cumulative of row 1, hi/lo           6: lookup albedo (RGB), σt   7: lookup emission
uniform sampler2D uTf;
uniform int uTfCells;
uniform float uTfLo, uTfInvCell, uTfCell;
uniform bool uTfEmissive;
uniform float uZeroBelow, uZeroAbove;

// Camera (render::Camera::pixelMap()).
uniform bool uPerspective;
uniform vec3 uEye, uForward, uRightStep, uUpStep;
uniform vec2 uPixelScale;

// Clip planes (keep dot(x − p, n) ≥ 0) and crop box, world mm.
uniform int uClipCount;
uniform vec3 uClipPoint[kMaxClipPlanes];
uniform vec3 uClipNormal[kMaxClipPlanes];
uniform bool uHasCrop;
uniform vec3 uCropMin, uCropMax;

// Marching.
uniform float uStepMm;
uniform float uTermination;  // 0 = no early termination
uniform bool uPreintegrated;
uniform float uBand;  // kClipFaceBandVoxels in mm
uniform float uWeak;  // RayCaster::weakGradient()
uniform vec3 uBackground;

// Shading: 0 emission–absorption (uniform ambient), 1 gradient Blinn–Phong, 2 SH visibility.
uniform int uMode;
uniform float uEaAmbient;
uniform float uAmbient, uDiffuse, uSpecular, uShininess;
uniform int uLightCount;
uniform bool uLightDirectional[kMaxLights];
uniform bool uLightOneSided[kMaxLights];
uniform vec3 uLightToLight[kMaxLights];
uniform vec3 uLightPosition[kMaxLights];
uniform vec3 uLightValue[kMaxLights];
uniform float uLightMinDistance[kMaxLights];
uniform vec3 uLightEmitterNormal[kMaxLights];

// SH visibility shading (uMode 2; render/sh_shading.h ShLights::shade, ShGlobalShader): the
// field resampled on a node-centred grid (render/sh_field_grid.h), coefficients
// 4t…4t+3 in uShField[t]; sh-global's local field in uShLocal[t] for the cut faces' band.
const int kMaxShTextures = 4;
const int kMaxShFaces = 14;  // = viewer/gl_support.h kMaxGlClipPlanes + the crop box's 6
const int kMaxShPoints = 8;  // = viewer/gl_support.h kMaxGlLights
const float kInv4Pi = 0.07957747154594767;
const float kInvSqrt4Pi = 0.28209479177387814;
const float kSqrt4Pi = 3.5449077018110318;
uniform int uShCount;  // 1, 4, 9 or 16
uniform vec3 uShTexScale, uShTexOffset;  // voxel coordinate p → texture coordinate p·scale + offset
uniform sampler3D uShField[kMaxShTextures];
uniform sampler3D uShLocal[kMaxShTextures];
uniform int uShFaceCount;  // faces that remove matter for the light (0: the field alone)
uniform vec3 uShFacePoint[kMaxShFaces];
uniform vec3 uShFaceNormal[kMaxShFaces];
uniform float uShInvBand;
uniform vec3 uShConstant[16];  // directional + environment + ambient L_i, windowed
uniform float uShWindow[16];
// sh-local's near shadow (render/sh_shading.h ShLocalShader): per directional light its
// direction and coefficients (uShConstant sums them), uShConstant without them, the spacing the
// field's interpolation blends (a texture beside the coefficients), the kept half-spaces.
uniform bool uShNear;
uniform sampler3D uShSpacing;
uniform vec3 uShSpread[16];
uniform int uShDirCount;
uniform vec3 uShDirToward[kMaxLights];
uniform vec3 uShDirCoeff[kMaxLights * 16];
uniform float uShNearFactor, uShH, uShWholeMm, uShNearTrace;
uniform int uShCutCount;
uniform vec3 uShCutPoint[kMaxShFaces];
uniform vec3 uShCutNormal[kMaxShFaces];
uniform int uShPointCount;
uniform vec3 uShPointPosition[kMaxShPoints];
uniform vec3 uShPointIntensity[kMaxShPoints];
uniform float uShPointMinDistance[kMaxShPoints];

struct Segment {
    float sigma;
    vec3 albedo;
    vec3 emission;
};

// ---- Transfer function (TfTable) -------------------------------------------------------------

vec4 tfRow(int row, int i) { return texelFetch(uTf, ivec2(i, row), 0); }

// TfTable::midpoint: lookup() at the mid value.
Segment midpointSegment(float sf, float sb) {
    float u = (0.5 * (sf + sb) - uTfLo) * uTfInvCell;
    u = u > 0.0 ? u : 0.0;
    u = u < float(uTfCells) ? u : float(uTfCells);
    const int i = min(int(u), uTfCells - 1);
    const float f = u - float(i);
    const vec4 a = tfRow(6, i), b = tfRow(6, i + 1);
    const vec3 ea = tfRow(7, i).rgb, eb = tfRow(7, i + 1).rgb;
    Segment s;
    s.sigma = a.a + f * (b.a - a.a);
    s.albedo = a.rgb + f * (b.rgb - a.rgb);
    s.emission = (vec3(1.0) - s.albedo) * (ea + f * (eb - ea));
    return s;
}

// Cumulative integrals from lo at `value` (TfTable::cumulativeSigma/-Weighted): the node's sum as
// a hi/lo float pair plus the part inside the cell (a·x + (b − a)·x²/2h, exact for the linear
// cell), for rows (integrand, cumulative hi, cumulative lo) = (r0, r1, r2).
struct Cumulative {
    vec4 hi, lo, part;
};
Cumulative cumulativeAt(float value, int r0, int r1, int r2) {
    const float u = (value - uTfLo) * uTfInvCell;
    Cumulative c;
    if (!(u > 0.0)) {  // below the range: constant extension of the first node
        c.hi = vec4(0.0);
        c.lo = vec4(0.0);
        c.part = tfRow(r0, 0) * (u * uTfCell);
        return c;
    }
    if (u >= float(uTfCells)) {
        c.hi = tfRow(r1, uTfCells);
        c.lo = tfRow(r2, uTfCells);
        c.part = tfRow(r0, uTfCells) * ((u - float(uTfCells)) * uTfCell);
        return c;
    }
    const int cell = int(u);
    const float x = (u - float(cell)) * uTfCell;
    const vec4 a = tfRow(r0, cell), b = tfRow(r0, cell + 1);
    c.hi = tfRow(r1, cell);
    c.lo = tfRow(r2, cell);
    c.part = a * x + (b - a) * (x * x * (0.5 * uTfInvCell));
    return c;
}
vec4 difference(Cumulative a, Cumulative b) {
    precise vec4 d = (b.hi - a.hi) + (b.lo - a.lo);
    precise vec4 r = d + (b.part - a.part);
    return r;
}

// TfTable::segment: the pre-integrated segment of values varying linearly from sf to sb.
Segment preintegratedSegment(float sf, float sb) {
    if (!(abs(sb - sf) * uTfInvCell > kPointSampleFraction)) return midpointSegment(sf, sb);
    const vec4 d = difference(cumulativeAt(sf, 0, 2, 3), cumulativeAt(sb, 0, 2, 3));
    Segment s;
    s.sigma = d.x / (sb - sf);
    s.albedo = vec3(0.0);
    s.emission = vec3(0.0);
    if (!(s.sigma > 0.0)) {
        s.sigma = 0.0;
        return s;
    }
    const float w = 1.0 / d.x;
    s.albedo = clamp(d.yzw * w, 0.0, 1.0);
    if (uTfEmissive) {
        const vec4 e = difference(cumulativeAt(sf, 1, 4, 5), cumulativeAt(sb, 1, 4, 5));
        s.emission = max(e.xyz * w, vec3(0.0));
    }
    return s;
}

// ---- Volume ----------------------------------------------------------------------------------

float valueAt(vec3 p) {
    return texture(uVolume, (p + 0.5) / uDims).r * uValueScale + uValueOffset;
}

// Central differences of the trilinear field at p ± 1 voxel (dvr_march.h gradientAt).
vec3 gradientAt(vec3 p) {
    const vec3 d = vec3(valueAt(p + vec3(1, 0, 0)) - valueAt(p - vec3(1, 0, 0)),
                        valueAt(p + vec3(0, 1, 0)) - valueAt(p - vec3(0, 1, 0)),
                        valueAt(p + vec3(0, 0, 1)) - valueAt(p - vec3(0, 0, 1)));
    return uGradientMatrix * d;
}

// dvr_march.h shadingNormal: the gradient normal, blended toward `fallback` where it is weak.
vec3 shadingNormal(vec3 g, vec3 fallback, vec3 toEye, float weak) {
    const float len2 = dot(g, g);
    vec3 n = fallback;
    if (len2 >= weak * weak && len2 > 0.0 && !isinf(len2)) {
        n = g * (-1.0 / sqrt(len2));
    } else if (len2 > 0.0 && !isinf(len2)) {
        const float len = sqrt(len2);
        const float w = len / weak;
        n = w * (-g / len) + (1.0 - w) * fallback;
        const float l2 = length(n);
        n = l2 > 1e-6 ? n / l2 : fallback;
    }
    return dot(n, toEye) < 0.0 ? -n : n;
}

// ---- Shading (render/shading.h BlinnPhongShader::scatter) ------------------------------------

void blinnPhong(vec3 position, vec3 normal, vec3 toEye, out vec3 diffuse, out vec3 specular) {
    diffuse = vec3(uAmbient);
    specular = vec3(0.0);
    for (int k = 0; k < uLightCount; ++k) {
        vec3 toLight;
        vec3 e = uLightValue[k];
        if (uLightDirectional[k]) {
            toLight = uLightToLight[k];
        } else {
            const vec3 d = uLightPosition[k] - position;
            const float dist = length(d);
            toLight = dist > 0.0 ? d / dist : normal;
            const float r = dist > uLightMinDistance[k] ? dist : uLightMinDistance[k];
            e /= r * r;
            if (uLightOneSided[k]) {
                const float c = -dot(toLight, uLightEmitterNormal[k]);
                if (c <= 0.0) continue;
                e *= c;
            }
        }
        const float ndl = dot(normal, toLight);
        if (ndl <= 0.0) continue;
        diffuse += (uDiffuse * ndl) * e;
        if (uSpecular > 0.0) {
            const float ndh = dot(normal, normalize(toLight + toEye));
            if (ndh > 0.0) specular += (uSpecular * pow(min(ndh, 1.0), uShininess)) * e;
        }
    }
}

// ---- SH visibility shading (render/sh_shading.h) ---------------------------------------------

// sh::evalShFixed<3>: real SH without the Condon–Shortley sign, index l(l+1)+m.
void shBasis(vec3 d, int count, out float y[16]) {
    const float x = d.x, yy = d.y, z = d.z;
    y[0] = 0.28209479177387814;
    if (count <= 1) return;
    y[1] = 0.48860251190291992 * yy;
    y[2] = 0.48860251190291992 * z;
    y[3] = 0.48860251190291992 * x;
    if (count <= 4) return;
    const float x2 = x * x, y2 = yy * yy, z2 = z * z;
    y[4] = 1.0925484305920792 * x * yy;
    y[5] = 1.0925484305920792 * yy * z;
    y[6] = 0.31539156525252005 * (3.0 * z2 - 1.0);
    y[7] = 1.0925484305920792 * x * z;
    y[8] = 0.54627421529603959 * (x2 - y2);
    if (count <= 9) return;
    const float fz5 = 5.0 * z2 - 1.0;
    y[9] = 0.59004358992664352 * yy * (3.0 * x2 - y2);
    y[10] = 2.8906114426405538 * x * yy * z;
    y[11] = 0.45704579946446572 * yy * fz5;
    y[12] = 0.37317633259011540 * z * (5.0 * z2 - 3.0);
    y[13] = 0.45704579946446572 * x * fz5;
    y[14] = 1.4453057213202769 * z * (x2 - y2);
    y[15] = 0.59004358992664352 * x * (x2 - 3.0 * y2);
}

// dvr_march.h meanScatterDepth: the α-weighted mean depth of the first scattering in a segment.
float meanScatterDepth(float tau, float dt) {
    if (tau < kOpacitySeriesTau) return dt * (0.5 - tau * (1.0 / 12.0));
    if (tau > 80.0) return dt / tau;
    return dt * (1.0 / tau - 1.0 / (exp(tau) - 1.0));
}

// The field's coefficients at texture coordinate tc.
void shField(vec3 tc, out float v[16]) {
    const int textures = (uShCount + 3) / 4;
    for (int t = 0; t < textures; ++t) {
        const vec4 c = texture(uShField[t], tc);
        v[4 * t] = c.x, v[4 * t + 1] = c.y, v[4 * t + 2] = c.z, v[4 * t + 3] = c.w;
    }
}

// TfTable::meanExtinction: mean σt over values varying linearly from sf to sb.
float meanSigma(float sf, float sb) {
    if (!(abs(sb - sf) * uTfInvCell > kPointSampleFraction)) return midpointSegment(sf, sb).sigma;
    const vec4 d = difference(cumulativeAt(sf, 0, 2, 3), cumulativeAt(sb, 0, 2, 3));
    return max(d.x / (sb - sf), 0.0);
}

// visibility::nearTransmittance: from voxel p along world unit vector w over lenMm (clipped at
// the volume's box), pre-integrated in equal sub-steps of at most half a voxel.
float nearTransmittance(vec3 p, vec3 w, float lenMm) {
    const vec3 d = uWorldToIndex * w;  // index units per mm
    const float largest = max(abs(d.x), max(abs(d.y), abs(d.z)));
    float exitT = 1e30;
    for (int a = 0; a < 3; ++a) {
        if (abs(d[a]) <= 1e-9 * largest) continue;
        exitT = min(exitT, ((d[a] > 0.0 ? uDims[a] - 1.0 : 0.0) - p[a]) / d[a]);
    }
    const float len = min(lenMm, max(exitT, 0.0));
    if (!(len > 0.0)) return 1.0;
    const int n = max(1, int(ceil(len / (0.5 * uShH))));
    const float dt = len / float(n);
    float s0 = valueAt(p), tau = 0.0;
    for (int k = 1; k <= n; ++k) {
        const float s1 = valueAt(p + (float(k) * dt) * d);
        tau += meanSigma(s0, s1) * dt;
        s0 = s1;
    }
    return exp(-tau);
}

// ShLocalShader's stretch toward a light: ℓ, shortened to the light, the volume's box and the
// kept region.
float nearLength(vec3 x, vec3 p, vec3 w, float ellMm, float maxMm) {
    float len = min(ellMm, maxMm);
    const vec3 d = uWorldToIndex * w;
    // The box exit as visibility::boxExitIndex (local_visibility.h), the C++ trace's formula.
    for (int a = 0; a < 3; ++a) {
        if (d[a] > 0.0) len = min(len, max((uDims[a] - 1.0 - p[a]) / d[a], 0.0));
        if (d[a] < 0.0) len = min(len, max(-p[a] / d[a], 0.0));
    }
    for (int f = 0; f < uShCutCount; ++f) {
        const float along = dot(w, uShCutNormal[f]);
        if (along < 0.0) len = min(len, max(dot(x - uShCutPoint[f], uShCutNormal[f]), 0.0) / -along);
    }
    return len;
}

// ShGlobalShader near a face that removes matter for the light: v toward the local field by
// 1 − w (w = 1 a band away from every face).
void shBlendLocal(vec3 tc, float w, inout float v[16]) {
    const int textures = (uShCount + 3) / 4;
    for (int t = 0; t < textures; ++t) {
        const vec4 l = texture(uShLocal[t], tc);
        for (int c = 0; c < 4; ++c) v[4 * t + c] = w * v[4 * t + c] + (1.0 - w) * l[c];
    }
}

// render/sh_shading.h nearShadowReading for one delta light toward w (at most maxMm away): the
// exit within reach = max(uShWholeMm, ℓ) gives Tw, the light's whole visibility, with weight ww
// (1 up to reach/2, 0 at reach); returns 1 — T over ℓ (or to the exit) and the field at the
// stretch's end in vt — or 2, the plain product (ℓ = 0, or ww = 1: not read).
int nearReading(vec3 x, vec3 p, vec3 w, float ellMm, float maxMm, float blend, out float T,
                out float vt[16], out float ww, out float Tw) {
    const float exitMm = nearLength(x, p, w, 1e30, maxMm);
    const float reach = max(uShWholeMm, ellMm);
    ww = 0.0;
    Tw = 1.0;
    T = 1.0;
    if (exitMm < reach) {
        Tw = nearTransmittance(p, w, exitMm);
        ww = min(1.0, 2.0 * (reach - exitMm) / reach);
        if (ww >= 1.0) return 2;
    }
    if (!(ellMm > 0.0)) return 2;
    const float len = min(ellMm, exitMm);
    T = nearTransmittance(p, w, len);
    const vec3 endTc = (p + uWorldToIndex * (w * len)) * uShTexScale + uShTexOffset;
    shField(endTc, vt);
    if (blend < 1.0) shBlendLocal(endTc, blend, vt);
    return 1;
}

// ShLocalShader::inScattered / ShGlobalShader::scatter with the near shadow: each delta light's
// term from nearReading — ww·Tw for the traced whole visibility plus (1 − ww)·(T times the field
// at the stretch's end, that reading at most an open field's; or the plain product).
vec3 shShadeNear(vec3 x, float v[16], float ellMm, float blend) {
    const vec3 p = uWorldToIndex * (x - uOrigin);
    vec3 sum = vec3(0.0);
    for (int i = 0; i < uShCount; ++i) sum += uShSpread[i] * v[i];
    float vt[16];
    for (int d = 0; d < uShDirCount; ++d) {
        float T, ww, Tw;
        const int how = nearReading(x, p, uShDirToward[d], ellMm, 1e30, blend, T, vt, ww, Tw);
        if (ww < 1.0) {
            // One sum: over the end's reading (capped at an open field's) or over v (plain).
            vec3 s = vec3(0.0);
            for (int i = 0; i < uShCount; ++i)
                s += uShDirCoeff[16 * d + i] * (how == 1 ? vt[i] : v[i]);
            const vec3 open = kSqrt4Pi * uShDirCoeff[16 * d];  // an open field's reading
            sum += (1.0 - ww) * (how == 1 ? T * min(s, open) : s);
        }
        sum += ww * Tw * kSqrt4Pi * uShDirCoeff[16 * d];  // an open field times Tw
    }
    for (int k = 0; k < uShPointCount; ++k) {
        const vec3 dd = uShPointPosition[k] - x;
        const float dist = length(dd);
        const float r = max(dist, uShPointMinDistance[k]);
        const vec3 e = uShPointIntensity[k] / (r * r);
        const float directional = min(1.0, dist / uShPointMinDistance[k]);
        if (directional > 0.0) {
            const vec3 w = dd / dist;
            float y[16];
            shBasis(w, uShCount, y);
            float T, ww, Tw;
            const int how = nearReading(x, p, w, ellMm, dist, blend, T, vt, ww, Tw);
            float term = 0.0;
            if (ww < 1.0) {
                float s = 0.0;
                for (int i = 0; i < uShCount; ++i)
                    s += uShWindow[i] * y[i] * (how == 1 ? vt[i] : v[i]);
                term = (1.0 - ww) * (how == 1 ? T * min(s, uShWindow[0]) : s);
            }
            term += ww * Tw * uShWindow[0];
            sum += (directional * term) * e;
        }
        sum += ((1.0 - directional) * kInvSqrt4Pi * v[0]) * e;
    }
    return max(sum * kInv4Pi, vec3(0.0));
}

// ShVisibilityShader / ShGlobalShader::scatter at world point x: 1/(4π) Σ L_i V_i, clamped at 0.
vec3 shShade(vec3 x) {
    const vec3 tc = (uWorldToIndex * (x - uOrigin)) * uShTexScale + uShTexOffset;
    float v[16];
    shField(tc, v);
    float w = 1.0;
    if (uShFaceCount > 0) {
        // Near a face that removes matter for the light: toward the local field.
        float d = 1e30;
        for (int f = 0; f < uShFaceCount; ++f)
            d = min(d, dot(x - uShFacePoint[f], uShFaceNormal[f]));
        w = clamp(d * uShInvBand, 0.0, 1.0);
        if (w < 1.0) shBlendLocal(tc, w, v);
    }
    if (uShNear) {
        const float ellMm =
            max((uShNearTrace + uShNearFactor * (texture(uShSpacing, tc).r - 1.0)) * uShH, 0.0);
        return shShadeNear(x, v, ellMm, w);
    }
    vec3 sum = vec3(0.0);
    for (int i = 0; i < uShCount; ++i) sum += uShConstant[i] * v[i];
    for (int k = 0; k < uShPointCount; ++k) {
        const vec3 d = uShPointPosition[k] - x;
        const float dist = length(d);
        const float r = max(dist, uShPointMinDistance[k]);
        const vec3 e = uShPointIntensity[k] / (r * r);
        const float directional = min(1.0, dist / uShPointMinDistance[k]);
        if (directional > 0.0) {
            float y[16];
            shBasis(d / dist, uShCount, y);
            float s = 0.0;
            for (int i = 0; i < uShCount; ++i) s += uShWindow[i] * y[i] * v[i];
            sum += (directional * s) * e;
        }
        // The uniform part inside minDistance: c_0 = E/√(4π).
        sum += ((1.0 - directional) * kInvSqrt4Pi * v[0]) * e;
    }
    return max(sum * kInv4Pi, vec3(0.0));
}

// ---- Ray set-up (RayCaster::setupRay) --------------------------------------------------------

struct Ray {
    vec3 originWorld, dirWorld, originIndex, dirIndex;
    float tNear, tFar;
    bool clipEntry;
    vec3 entryNormal;
};

bool setupRay(vec2 pixelCentre, out Ray r) {
    const float sx = pixelCentre.x * uPixelScale.x - 1.0;
    const float sy = 1.0 - pixelCentre.y * uPixelScale.y;
    if (uPerspective) {
        r.originWorld = uEye;
        r.dirWorld = normalize(uForward + sx * uRightStep + sy * uUpStep);
    } else {
        r.originWorld = uEye + sx * uRightStep + sy * uUpStep;
        r.dirWorld = uForward;
    }
    r.originIndex = uWorldToIndex * (r.originWorld - uOrigin);
    r.dirIndex = uWorldToIndex * r.dirWorld;
    r.clipEntry = false;
    r.entryNormal = vec3(0.0);
    float tn = 0.0, tf = 1e30;
    for (int a = 0; a < 3; ++a) {
        const float lo = uIndexBoxLo[a], hi = uIndexBoxHi[a];
        const float o = r.originIndex[a], d = r.dirIndex[a];
        if (abs(d) < 1e-30) {
            if (o < lo || o > hi) tf = -1.0;
            continue;
        }
        const float inv = 1.0 / d;
        float t1 = (lo - o) * inv, t2 = (hi - o) * inv;
        if (t1 > t2) {
            const float s = t1;
            t1 = t2;
            t2 = s;
        }
        tn = max(tn, t1);
        tf = min(tf, t2);
    }
    for (int c = 0; c < uClipCount; ++c) {
        const float a = dot(r.originWorld - uClipPoint[c], uClipNormal[c]);
        const float b = dot(r.dirWorld, uClipNormal[c]);
        if (abs(b) < 1e-12) {
            if (a < 0.0) tf = -1.0;
            continue;
        }
        const float t = -a / b;
        if (b > 0.0) {
            if (t > tn) {
                tn = t;
                r.clipEntry = true;
                r.entryNormal = -uClipNormal[c];
            }
        } else {
            tf = min(tf, t);
        }
    }
    if (uHasCrop) {
        for (int a = 0; a < 3; ++a) {
            const float d = r.dirWorld[a], o = r.originWorld[a];
            if (abs(d) < 1e-12) {
                if (o < uCropMin[a] || o > uCropMax[a]) tf = -1.0;
                continue;
            }
            float t1 = (uCropMin[a] - o) / d, t2 = (uCropMax[a] - o) / d;
            if (t1 > t2) {
                const float s = t1;
                t1 = t2;
                t2 = s;
            }
            if (t1 > tn) {
                tn = t1;
                r.clipEntry = true;
                r.entryNormal = vec3(0.0);
                r.entryNormal[a] = d > 0.0 ? -1.0 : 1.0;
            }
            tf = min(tf, t2);
        }
    }
    r.tNear = tn;
    r.tFar = tf;
    return tf > tn;
}

// RayCaster::visibleRange: the part of [tNear, tFar] inside the non-empty cells' box.
bool visibleRange(Ray r, out float t0, out float t1) {
    t0 = r.tNear;
    t1 = r.tFar;
    if (!uAnyVisible) return false;
    for (int a = 0; a < 3; ++a) {
        const float l = uVisibleLo[a], h = uVisibleHi[a];
        const float o = r.originIndex[a], d = r.dirIndex[a];
        if (d == 0.0) {
            if (!(o >= l && o <= h)) return false;
            continue;
        }
        const float inv = 1.0 / d;
        float ta = (l - o) * inv, tb = (h - o) * inv;
        if (ta > tb) {
            const float s = ta;
            ta = tb;
            tb = s;
        }
        t0 = max(t0, ta);
        t1 = min(t1, tb);
    }
    return t1 > t0;
}

// ---- The march (dvr_march.h marchDvr, SampleLattice) -----------------------------------------

// SampleLattice::t: t_0 = tNear, t_i = tNear + (jitter + i − 1)·Δ clamped to tFar, t_last = tFar.
float latticeT(int i, int last, float jitter, Ray r) {
    if (i <= 0) return r.tNear;
    const float t = fma(jitter + float(i - 1), uStepMm, r.tNear);
    return i >= last || t > r.tFar ? r.tFar : t;
}

void main() {
    const ivec2 pixel = ivec2(gl_FragCoord.xy);  // film row y = image row y
    outFilm = vec4(uBackground, 0.0);
    Ray r;
    if (!setupRay(vec2(pixel) + 0.5, r)) return;
    float v0, v1;
    if (!visibleRange(r, v0, v1)) return;
    const float jitter = texelFetch(uJitter, pixel, 0).r;
    // Sample points: t_0 = tNear, t_i = tNear + (jitter + i − 1)·Δ clamped to tFar, last = tFar.
    const float step = uStepMm;
    int last = 1 + int(ceil((r.tFar - r.tNear) / step - jitter));
    last = max(last, 1);
    // Lattice indices covering [v0, v1] (SampleLattice::before / after).
    int i0 = v0 < r.tNear + jitter * step ? 0 : 1 + int(floor((v0 - r.tNear) / step - jitter));
    i0 = i0 < last ? max(i0, 0) : last;
    int i1 = v1 < r.tNear + jitter * step ? 0 : 1 + int(floor((v1 - r.tNear) / step - jitter));
    i1 = i1 < last ? max(i1, 0) : last;
    if (i1 < last && latticeT(i1, last, jitter, r) < v1) ++i1;
    const vec3 toEye = -r.dirWorld;
    const float maxDir = max(abs(r.dirIndex.x), max(abs(r.dirIndex.y), abs(r.dirIndex.z)));
    vec3 L = vec3(0.0);
    float T = 1.0;
    int iPrev = i0;
    float tPrev = latticeT(i0, last, jitter, r);
    vec3 pPrev = r.originIndex + tPrev * r.dirIndex;
    float sPrev = valueAt(pPrev);
    while (iPrev < i1) {
        if (uSkip && maxDir > 0.0) {
            // In an empty cell: jump to the last lattice sample inside its empty cube.
            const ivec3 c = clamp(ivec3(floor(pPrev / uCellSize)), ivec3(0), uCellCounts - 1);
            const uint d = texelFetch(uSkipDistance, c, 0).r;
            if (d > 1u) {
                const float reach = tPrev + 0.999 * float(d - 1u) * uCellSize / maxDir;
                int iNew = reach < r.tNear + jitter * step
                               ? 0
                               : 1 + int(floor((reach - r.tNear) / step - jitter));
                iNew = min(iNew, last);
                if (iNew > iPrev) {
                    if (iNew >= i1) break;  // nothing but empty cells to the end of the range
                    iPrev = iNew;
                    tPrev = latticeT(iNew, last, jitter, r);
                    pPrev = r.originIndex + tPrev * r.dirIndex;
                    sPrev = valueAt(pPrev);
                    continue;
                }
            }
        }
        const int i = iPrev + 1;
        const float t = latticeT(i, last, jitter, r);
        const vec3 p = r.originIndex + t * r.dirIndex;
        const float s = valueAt(p);
        const float sf = sPrev, t0 = tPrev;
        iPrev = i;
        sPrev = s;
        tPrev = t;
        pPrev = p;
        if (uPreintegrated && (max(sf, s) <= uZeroBelow || min(sf, s) >= uZeroAbove))
            continue;  // transparent
        const Segment seg = uPreintegrated ? preintegratedSegment(sf, s) : midpointSegment(sf, s);
        const float dt = t - t0;
        const float tau = seg.sigma * dt;
        if (!(tau > 0.0)) continue;
        const float alpha = tau < kOpacitySeriesTau
                                ? tau * (1.0 - 0.5 * tau * (1.0 - tau * (1.0 / 3.0)))
                                : 1.0 - exp(-tau);
        vec3 diffuse = vec3(uEaAmbient), specular = vec3(0.0);
        if (uMode == 2) {
            // Shaded where the segment's light is scattered (dvr_march.h composite).
            diffuse = shShade(r.originWorld + (t0 + meanScatterDepth(tau, dt)) * r.dirWorld);
        } else if (uMode == 1) {
            const bool cutFace = r.clipEntry && (t - r.tNear) < uBand;
            const vec3 n =
                shadingNormal(gradientAt(p), cutFace ? r.entryNormal : toEye, toEye, uWeak);
            blinnPhong(r.originWorld + t * r.dirWorld, n, toEye, diffuse, specular);
        }
        L += (T * alpha) * (seg.emission + seg.albedo * diffuse + specular);
        T *= 1.0 - alpha;
        if (T < uTermination) break;
    }
    outFilm = vec4(L + T * uBackground, 1.0 - T);
}
