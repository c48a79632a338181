// SPDX-License-Identifier: MIT
// Film → display, the GLSL mirror of render/tonemap.cpp toDisplay(): 2^exposure, then the display
// transform (0 clinical: clamp; 1 srgb: clamp + sRGB curve; 2 filmic: ACES (Narkowicz) + sRGB),
// opaque. The RGBA8 target rounds to 8 bits as the CLI's PNG writer does.
#version 450 core
layout(location = 0) out vec4 outColor;
uniform sampler2D uFilm;  // linear radiance + T·background, row 0 = image top
uniform float uExposureScale;
uniform int uDisplay;

float linearToSrgb(float x) {
    if (!(x > 0.0)) return 0.0;
    if (x >= 1.0) return 1.0;
    return x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055;
}
float acesFilmic(float x) {
    if (!(x > 0.0)) return 0.0;
    if (isinf(x)) return 1.0;
    const float a = 2.51, b = 0.03, c = 2.43, d = 0.59, e = 0.14;
    return clamp((x * (a * x + b)) / (x * (c * x + d) + e), 0.0, 1.0);
}
float displayOf(float x) {
    if (uDisplay == 0) return x > 0.0 ? min(x, 1.0) : 0.0;
    if (uDisplay == 2) return linearToSrgb(acesFilmic(x));
    return linearToSrgb(x);
}
void main() {
    const vec3 film = texelFetch(uFilm, ivec2(gl_FragCoord.xy), 0).rgb;
    const vec3 k = uExposureScale * film;
    outColor = vec4(displayOf(k.r), displayOf(k.g), displayOf(k.b), 1.0);
}
