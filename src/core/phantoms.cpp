// SPDX-License-Identifier: MIT
#include "core/phantoms.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <numbers>

#include "core/rng.h"

namespace voxlight::core {

namespace {

constexpr double kPi = std::numbers::pi;

/// Partial-volume coverage of a voxel of size h whose centre is at signed distance d (negative
/// inside).
double coverage(double d, double h) { return std::clamp(0.5 - d / h, 0.0, 1.0); }
/// Ramp for the exact-optics phantoms: linear over ±h around the surface, so that all 8 corners of
/// any cell the surface crosses (at most √3/2·h away) lie on the linear part and the trilinear
/// 0.5-level set is the surface.
double exactRamp(double d, double h) { return std::clamp(0.5 - 0.5 * d / h, 0.0, 1.0); }

double sdEllipsoid(const glm::dvec3& p, const glm::dvec3& c, const glm::dvec3& r) {
    // First-order distance to an ellipsoid: exact on the surface, good to a voxel near it (all that
    // coverage needs).
    const glm::dvec3 q = (p - c) / r;
    const double k0 = glm::length(q);
    const double k1 = glm::length(q / r);
    return k1 > 0.0 ? k0 * (k0 - 1.0) / k1 : -std::min(r.x, std::min(r.y, r.z));
}
/// True when p is farther than `margin` outside the ellipsoid's bounding box (cheap rejection).
bool outsideBox(const glm::dvec3& p, const glm::dvec3& c, const glm::dvec3& r, double margin) {
    const glm::dvec3 d = glm::abs(p - c) - r;
    return d.x > margin || d.y > margin || d.z > margin;
}
double sdEllipse2(double x, double y, double rx, double ry) {
    const double qx = x / rx, qy = y / ry;
    const double k0 = std::sqrt(qx * qx + qy * qy);
    const double k1 = std::sqrt(qx * qx / (rx * rx) + qy * qy / (ry * ry));
    return k1 > 0.0 ? k0 * (k0 - 1.0) / k1 : -std::min(rx, ry);
}
double sdBox(const glm::dvec3& p, const glm::dvec3& lo, const glm::dvec3& hi) {
    const glm::dvec3 c = 0.5 * (lo + hi), e = 0.5 * (hi - lo);
    const glm::dvec3 q = glm::abs(p - c) - e;
    return glm::length(glm::max(q, 0.0)) + std::min(std::max(q.x, std::max(q.y, q.z)), 0.0);
}
double sdSphere(const glm::dvec3& p, const glm::dvec3& c, double r) {
    return glm::length(p - c) - r;
}
double sdTorusZ(const glm::dvec3& p, const glm::dvec3& c, double major, double minor) {
    const glm::dvec3 q = p - c;
    const double rho = std::sqrt(q.x * q.x + q.y * q.y) - major;
    return std::sqrt(rho * rho + q.z * q.z) - minor;
}
/// Capped cylinder along z.
double sdCylinderZ(const glm::dvec3& p, double cx, double cy, double r, double z0, double z1) {
    const double dr = std::hypot(p.x - cx, p.y - cy) - r;
    const double dz = std::max(z0 - p.z, p.z - z1);
    return std::min(std::max(dr, dz), 0.0) + std::hypot(std::max(dr, 0.0), std::max(dz, 0.0));
}

Geometry cubeGeometry(int n, double fovMm, const PhantomOptions& o) {
    Geometry g;
    g.dims = glm::ivec3(n);
    g.spacing = o.spacing.x > 0 ? o.spacing : glm::dvec3(fovMm / n);
    g.origin = -0.5 * glm::dvec3(n - 1) * g.spacing;  // volume centred on the world origin
    g.direction = glm::dmat3(1.0);
    return g;
}

/// Fills a volume slice by slice in parallel: f(world position) → stored value.
template <class T, class F>
void fill(Volume& vol, const std::string& stage, const Progress& progress, F&& f) {
    const Geometry& g = vol.geometry();
    T* out = vol.dataAs<T>();
    std::atomic<int> done{0};
    tbb::parallel_for(0, g.dims.z, [&](int k) {
        progress.checkCancel();
        for (int j = 0; j < g.dims.y; ++j)
            for (int i = 0; i < g.dims.x; ++i)
                out[vol.linearIndex(i, j, k)] = f(g.indexToWorld(glm::dvec3(i, j, k)), i, j, k);
        const int d = ++done;
        if (d % 16 == 0) progress.report(stage, double(d) / g.dims.z);
    });
    progress.report(stage, 1.0);
}

constexpr double kKronanderFov = 128.0;
constexpr double kPlateTop = -28.0, kPlateBottom = -40.0;

Volume makeKronander(int n, const PhantomOptions& o, const Progress& progress) {
    Volume v(cubeGeometry(n, kKronanderFov, o), VoxelType::UInt8);
    v.modality = Modality::Synthetic;
    v.description = "phantom kronander: sphere and torus on a flat plate";
    const double h = minComponent(v.geometry().spacing);
    const glm::dvec3 sphereC(-28.0, 0.0, kPlateTop + 22.0);
    const glm::dvec3 torusC(30.0, 0.0, kPlateTop + 8.0);
    fill<std::uint8_t>(v, "phantom", progress, [&](const glm::dvec3& p, int, int, int) {
        double d = sdBox(p, {-56.0, -56.0, kPlateBottom}, {56.0, 56.0, kPlateTop});
        d = std::min(d, sdSphere(p, sphereC, 22.0));
        d = std::min(d, sdTorusZ(p, torusC, 20.0, 8.0));
        return std::uint8_t(std::lround(255.0 * coverage(d, h)));
    });
    return v;
}

constexpr double kTorsoFov = 400.0;

/// HU of the torso phantom at world point p (mm, LPS: +x left, +y posterior, +z superior), voxel
/// size h.
double torsoHU(const glm::dvec3& p, double h) {
    double hu = -1000.0;  // air
    auto paint = [&](double d, double value) {
        if (d < 0.5 * h) hu += coverage(d, h) * (value - hu);
    };
    auto paintEllipsoid = [&](const glm::dvec3& c, const glm::dvec3& r, double value) {
        if (!outsideBox(p, c, r, h)) paint(sdEllipsoid(p, c, r), value);
    };
    const double zTop = 190.0, zBottom = -190.0;
    const double zCap = std::max(p.z - zTop, zBottom - p.z);  // body is a capped elliptic cylinder
    auto body = [&](double rx, double ry) { return std::max(sdEllipse2(p.x, p.y, rx, ry), zCap); };
    const double dSkin = body(170.0, 120.0);
    if (dSkin > 0.5 * h) return hu;
    paint(dSkin, 30.0);                 // skin
    paint(body(167.0, 117.0), -100.0);  // subcutaneous fat
    paint(body(150.0, 102.0), 50.0);    // muscle / soft tissue
    // Lungs (upper half), with a faint parenchyma texture added by the noise below.
    paintEllipsoid({-72.0, -5.0, 85.0}, {58.0, 78.0, 105.0}, -850.0);
    paintEllipsoid({72.0, -5.0, 85.0}, {55.0, 78.0, 105.0}, -850.0);
    // Heart (myocardium with contrast-enhanced blood pool).
    paintEllipsoid({22.0, -38.0, 35.0}, {62.0, 52.0, 55.0}, 45.0);
    paintEllipsoid({22.0, -38.0, 35.0}, {48.0, 38.0, 42.0}, 180.0);
    // Liver (patient right = −x), kidneys, spleen.
    paintEllipsoid({-62.0, -10.0, -55.0}, {82.0, 75.0, 62.0}, 60.0);
    paintEllipsoid({-58.0, 60.0, -115.0}, {25.0, 22.0, 45.0}, 35.0);
    paintEllipsoid({58.0, 60.0, -110.0}, {25.0, 22.0, 45.0}, 35.0);
    paintEllipsoid({78.0, 30.0, -45.0}, {35.0, 45.0, 40.0}, 45.0);
    // Rib cage: ten pairs of ribs from the transverse processes around to the front, sloping down
    // anteriorly and widening caudally, each a flattened tube (cortex with a marrow core); the
    // upper seven join the sternum through costal cartilage.
    if (p.z > -60.0 && p.z < 175.0 && p.y < 95.0) {
        const double phi =
            std::atan2(std::abs(p.x), p.y);  // 0 at the spine (posterior), π at the sternum
        const double t = phi / kPi;
        for (int n = 0; n < 10; ++n) {
            const double rx = 126.0 + 2.0 * n, ry = 88.0 + 0.8 * n;
            const double ring = sdEllipse2(p.x, p.y, rx, ry);
            if (std::abs(ring) > 8.0 + h) continue;
            const double zc = 160.0 - 21.0 * n - 55.0 * std::pow(t, 1.4);
            const double dz = p.z - zc;
            if (std::abs(dz) > 10.0 + h) continue;
            const double tEnd = 0.80 - 0.012 * n;
            if (t < 0.12 || t > 0.97) continue;
            if (t <= tEnd) {
                paint((std::hypot(ring / 4.5, dz / 7.5) - 1.0) * 4.5, 750.0);
                paint((std::hypot(ring / 2.5, dz / 5.0) - 1.0) * 2.5, 260.0);
            } else if (n < 7) {
                paint((std::hypot(ring / 3.5, dz / 6.0) - 1.0) * 3.5, 130.0);  // costal cartilage
            }
        }
    }
    // Sternum (manubrium and body), scapulae and clavicles.
    paint(sdBox(p, {-14.0, -101.0, 30.0}, {14.0, -89.0, 165.0}), 700.0);
    paint(sdBox(p, {-10.0, -98.0, 34.0}, {10.0, -92.0, 161.0}), 250.0);
    for (int side = -1; side <= 1; side += 2) {
        // Scapula: a thin plate on the posterior ribs, turned 35° to follow the back.
        const double c = std::cos(side * 0.61), s = std::sin(side * 0.61);
        const glm::dvec3 q = p - glm::dvec3(side * 78.0, 86.0, 112.0);
        const glm::dvec3 local(c * q.x + s * q.y, -s * q.x + c * q.y, q.z);
        // Triangular: narrow at the tip.
        const double taper = std::clamp((local.z + 55.0) / 110.0, 0.2, 1.0);
        paint(sdBox(local, {-40.0 * taper, -2.0, -55.0}, {40.0 * taper, 2.0, 55.0}), 650.0);
        // Clavicle: a capsule from the manubrium to the acromion.
        const glm::dvec3 a(side * 16.0, -92.0, 168.0), b(side * 118.0, 10.0, 182.0);
        const glm::dvec3 ab = b - a;
        const double u = std::clamp(glm::dot(p - a, ab) / glm::dot(ab, ab), 0.0, 1.0);
        paint(glm::length(p - (a + u * ab)) - 6.0, 700.0);
    }
    // Vertebral column: bodies (cortical shell, cancellous core), discs, spinous processes.
    const double spineX = 0.0, spineY = 78.0;
    // Only the vertebrae within reach of p (each spans 30 mm of z; processes reach 52 mm behind the
    // body axis).
    const bool nearSpine =
        std::abs(p.x - spineX) < 32.0 + h && p.y > spineY - 21.0 - h && p.y < spineY + 52.0 + h;
    const double zFirst =
        std::max(-180.0, -180.0 + 30.0 * std::floor((p.z - h + 180.0) / 30.0) - 30.0);
    for (double zc = zFirst; nearSpine && zc < 190.0 && zc <= p.z + h; zc += 30.0) {
        paint(sdCylinderZ(p, spineX, spineY, 21.0, zc, zc + 25.0), 950.0);
        paint(sdCylinderZ(p, spineX, spineY, 18.5, zc + 2.5, zc + 22.5), 260.0);
        paint(sdCylinderZ(p, spineX, spineY, 21.0, zc + 25.0, zc + 30.0), 90.0);  // disc
        paint(sdBox(p, {spineX - 5.0, spineY + 22.0, zc + 3.0},
                    {spineX + 5.0, spineY + 52.0, zc + 20.0}),
              800.0);
        paint(sdBox(p, {spineX - 32.0, spineY + 14.0, zc + 6.0},
                    {spineX + 32.0, spineY + 22.0, zc + 16.0}),
              800.0);  // transverse processes
    }
    // Descending aorta: contrast-filled lumen beside the spine, wall, and a braided nitinol/steel
    // stent.
    const double ax = 24.0, ay = 46.0, aR = 12.0;
    const double dAorta = sdCylinderZ(p, ax, ay, aR + 1.5, zBottom + 10.0, zTop - 10.0);
    paint(dAorta, 40.0);
    paint(sdCylinderZ(p, ax, ay, aR, zBottom + 10.0, zTop - 10.0), 320.0);
    if (dAorta < 2.0 && p.z > -80.0 && p.z < 20.0) {
        // Two families of 6 helices (pitch 60 mm, opposite hands) at radius 11.5 mm, wire radius
        // 0.9 mm.
        const double R = 11.5, pitch = 60.0, wire = 0.9;
        const double rho = std::hypot(p.x - ax, p.y - ay), phi = std::atan2(p.y - ay, p.x - ax);
        // Wire vs circumferential direction.
        const double sinA = pitch / std::hypot(pitch, 2.0 * kPi * R);
        double d = 1e9;
        for (int hand = -1; hand <= 1; hand += 2)
            for (int w = 0; w < 6; ++w) {
                double dphi = phi - (hand * 2.0 * kPi * p.z / pitch + w * kPi / 3.0);
                dphi = std::remainder(dphi, 2.0 * kPi);
                d = std::min(d, std::hypot(rho - R, R * dphi * sinA) - wire);
            }
        paint(d, 3000.0);
    }
    return hu;
}

Volume makeTorso(int n, const PhantomOptions& o, const Progress& progress) {
    Volume v(cubeGeometry(n, kTorsoFov, o), VoxelType::Int16);
    v.modality = Modality::CT;
    v.mapping.unit = "HU";
    v.description = "phantom torso: CT-like chest/abdomen with stented aorta";
    const double h = minComponent(v.geometry().spacing);
    fill<std::int16_t>(v, "phantom", progress, [&](const glm::dvec3& p, int i, int j, int k) {
        double hu = torsoHU(p, h);
        if (hu > -990.0) {
            // Quantum noise, ~10 HU: sum of two uniforms (triangular), counter-based so thread
            // count cannot matter.
            const std::uint64_t key =
                (std::uint64_t(k) << 40) ^ (std::uint64_t(j) << 20) ^ std::uint64_t(i);
            CounterRng rng(key, o.seed);
            hu += 12.0 * (rng.uniform() + rng.uniform() - 1.0);
        }
        return std::int16_t(std::lround(std::clamp(hu, -1024.0, 3071.0)));
    });
    return v;
}

Volume makeSphere(int n, const PhantomOptions& o, const Progress& progress) {
    Volume v(cubeGeometry(n, double(n), o), VoxelType::Float32);
    v.modality = Modality::Synthetic;
    v.description = "phantom sphere: homogeneous, value 1 inside";
    const SphereFacts s = spherePhantomFacts(v.geometry());
    const double h = minComponent(v.geometry().spacing);
    fill<float>(v, "phantom", progress, [&](const glm::dvec3& p, int, int, int) {
        return float(exactRamp(glm::length(p - s.centre) - s.radius, h));
    });
    return v;
}

Volume makeSlab(int n, const PhantomOptions& o, const Progress& progress) {
    Volume v(cubeGeometry(n, double(n), o), VoxelType::Float32);
    v.modality = Modality::Synthetic;
    v.description = "phantom slab: homogeneous, value 1 for |z - zc| < extent/4";
    const SlabFacts s = slabPhantomFacts(v.geometry());
    const double hz = v.geometry().spacing.z, zc = 0.5 * (s.zMin + s.zMax),
                 half = 0.5 * (s.zMax - s.zMin);
    fill<float>(v, "phantom", progress, [&](const glm::dvec3& p, int, int, int) {
        return float(exactRamp(std::abs(p.z - zc) - half, hz));
    });
    return v;
}

/// Value noise on the integer lattice: a hash of the cell corner, smoothly interpolated — a
/// deterministic stand-in for smoke (no RNG state, the same volume on every machine).
double latticeValue(int x, int y, int z) {
    std::uint32_t h = std::uint32_t(x) * 0x8da6b343u ^ std::uint32_t(y) * 0xd8163841u ^
                      std::uint32_t(z) * 0xcb1ab31fu;
    h ^= h >> 13;
    h *= 0x5bd1e995u;
    h ^= h >> 15;
    return double(h & 0xffffffu) / double(0xffffff);
}
double valueNoise(const glm::dvec3& p) {
    const glm::dvec3 f0 = glm::floor(p);
    const glm::ivec3 i(f0);
    glm::dvec3 f = p - f0;
    f = f * f * (3.0 - 2.0 * f);  // smoothstep: C1 across cells
    double c[2][2][2];
    for (int dz = 0; dz < 2; ++dz)
        for (int dy = 0; dy < 2; ++dy)
            for (int dx = 0; dx < 2; ++dx)
                c[dz][dy][dx] = latticeValue(i.x + dx, i.y + dy, i.z + dz);
    auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
    return lerp(lerp(lerp(c[0][0][0], c[0][0][1], f.x), lerp(c[0][1][0], c[0][1][1], f.x), f.y),
                lerp(lerp(c[1][0][0], c[1][0][1], f.x), lerp(c[1][1][0], c[1][1][1], f.x), f.y),
                f.z);
}

Volume makeCloud(int n, const PhantomOptions& o, const Progress& progress) {
    Volume v(cubeGeometry(n, double(n), o), VoxelType::Float32);
    v.modality = Modality::Synthetic;
    v.description =
        "phantom cloud: smoke-like density in [0, 1] (4 octaves of value noise in a "
        "soft ball)";
    const auto b = v.geometry().worldBounds();
    const glm::dvec3 c = 0.5 * (b[0] + b[1]);
    const double r = 0.42 * minComponent(b[1] - b[0]);
    fill<float>(v, "phantom", progress, [&](const glm::dvec3& p, int, int, int) {
        const glm::dvec3 q = (p - c) / r;  // unit ball
        double noise = 0.0, amp = 0.5;
        glm::dvec3 x = q * 3.0;
        for (int octave = 0; octave < 4; ++octave, amp *= 0.5, x *= 2.03)
            noise += amp * valueNoise(x);
        // Density: noise thresholded, fading out toward the ball's edge.
        const double fade = std::clamp(1.0 - glm::length(q), 0.0, 1.0);
        return float(std::clamp((noise - 0.35) * 2.5 * std::sqrt(fade) * 1.6, 0.0, 1.0));
    });
    return v;
}

}  // namespace

SphereFacts spherePhantomFacts(const Geometry& g) {
    const auto b = g.worldBounds();
    return {0.5 * (b[0] + b[1]), 0.35 * minComponent(b[1] - b[0])};
}

SlabFacts slabPhantomFacts(const Geometry& g) {
    const auto b = g.worldBounds();
    const double zc = 0.5 * (b[0].z + b[1].z), q = 0.25 * (b[1].z - b[0].z);
    return {zc - q, zc + q};
}

std::vector<std::pair<std::string, std::string>> phantomCatalog() {
    return {
        {"kronander",
         "sphere and torus on a perfectly flat plate (Kronander 2012 corner case), uint8, 128^3"},
        {"torso", "CT-like torso in HU with stented aorta, spine, ribs, lungs, int16, 256^3"},
        {"sphere", "homogeneous sphere (value 1) for exact optics tests, float32, 64^3"},
        {"slab", "homogeneous slab (value 1) for exact optics tests, float32, 64^3"},
        {"cloud", "smoke-like density in [0, 1] for scattering tests, float32, 64^3"}};
}

Volume makePhantomImpl(const std::string& name, const PhantomOptions& options,
                       const Progress& progress);

Volume makePhantom(const std::string& name, const PhantomOptions& options,
                   const Progress& progress) {
    Volume v = makePhantomImpl(name, options, progress);
    v.format = "phantom";
    return v;
}

Volume makePhantomImpl(const std::string& name, const PhantomOptions& options,
                       const Progress& progress) {
    auto sizeOr = [&](int def) {
        const int n = options.size != 0 ? options.size : def;  // negative: refused below
        if (n < 8 || n > 1024)
            throw InputError("phantom " + name, "size",
                             "must be between 8 and 1024, got " + std::to_string(n),
                             "pass --size N with 8 <= N <= 1024");
        return n;
    };
    if (name == "kronander") return makeKronander(sizeOr(128), options, progress);
    if (name == "torso") return makeTorso(sizeOr(256), options, progress);
    if (name == "sphere") return makeSphere(sizeOr(64), options, progress);
    if (name == "slab") return makeSlab(sizeOr(64), options, progress);
    if (name == "cloud") return makeCloud(sizeOr(64), options, progress);
    std::string names;
    for (const auto& [n, d] : phantomCatalog()) names += (names.empty() ? "" : ", ") + n;
    throw InputError("phantom", "name", "unknown phantom '" + name + "'",
                     "choose one of: " + names);
}

}  // namespace voxlight::core
