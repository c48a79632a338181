// SPDX-License-Identifier: MIT
#include "iso/extract.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>

#include "core/timing.h"
#include "io/module_loader.h"
#include "iso/cap_fill.h"
#include "iso/flying_edges_module.h"

namespace voxlight::iso {

namespace {

const fe_module::Api& feModule() {
    static std::once_flag once;
    static io::detail::LoadedModule loaded;
    std::call_once(once, [] {
        loaded = io::detail::loadModule(fe_module::kFileName, fe_module::kEntryPoint,
                                        fe_module::kAbiVersion);
    });
    if (!loaded.api)
        throw InputError("isosurface", "iso module",
                         "isosurface extraction (VTK) is unavailable: " + loaded.error,
                         std::string("put ") + fe_module::kFileName +
                             " (built with voxlight) beside the voxlight executable");
    return *static_cast<const fe_module::Api*>(loaded.api);
}

std::string number(double v) {
    char b[64];
    std::snprintf(b, sizeof b, "%.6g", v);
    return b;
}

bool isIntegerType(core::VoxelType t) { return t != core::VoxelType::Float32; }

/// Central-difference gradient of stored values at voxel (i,j,k), per index step (one-sided at the
/// border, zero along an axis of size 1).
template <class View>
glm::vec3 voxelGradient(const View& v, int i, int j, int k) {
    auto diff = [&](int n, int c, auto at) -> float {
        if (n < 2) return 0.f;
        const int lo = std::max(c - 1, 0), hi = std::min(c + 1, n - 1);
        return (at(hi) - at(lo)) / float(hi - lo);
    };
    return {diff(v.nx, i, [&](int x) { return v.stored(x, j, k); }),
            diff(v.ny, j, [&](int y) { return v.stored(i, y, k); }),
            diff(v.nz, k, [&](int z) { return v.stored(i, j, z); })};
}

/// Trilinear interpolation of voxelGradient at continuous index p (clamped to the grid).
template <class View>
glm::vec3 gradientAt(const View& v, glm::dvec3 p) {
    const glm::ivec3 n(v.nx, v.ny, v.nz);
    glm::ivec3 i0;
    glm::vec3 f;
    for (int a = 0; a < 3; ++a) {
        const double x = std::clamp(p[a], 0.0, double(n[a] - 1));
        i0[a] = std::min(int(x), std::max(n[a] - 2, 0));
        f[a] = float(x - i0[a]);
    }
    const glm::ivec3 i1 = glm::min(i0 + 1, n - 1);
    glm::vec3 g(0.f);
    for (int c = 0; c < 8; ++c) {
        const int x = c & 1 ? i1.x : i0.x, y = c & 2 ? i1.y : i0.y, z = c & 4 ? i1.z : i0.z;
        const float w = (c & 1 ? f.x : 1 - f.x) * (c & 2 ? f.y : 1 - f.y) * (c & 4 ? f.z : 1 - f.z);
        if (w != 0.f) g += w * voxelGradient(v, x, y, z);
    }
    return g;
}

/// Outward unit normals (−∇ of physical values, world mm) at world points; zero where ∇ = 0.
std::vector<glm::vec3> gradientNormals(const std::vector<glm::dvec3>& points,
                                       const core::Volume& volume) {
    const core::Geometry& geo = volume.geometry();
    // d(physical)/d(world) = slope · D · diag(1/spacing) · d(stored)/d(index).
    const glm::dmat3 toWorld =
        volume.mapping.slope * geo.direction *
        glm::dmat3(glm::dvec3(1.0 / geo.spacing.x, 0, 0), glm::dvec3(0, 1.0 / geo.spacing.y, 0),
                   glm::dvec3(0, 0, 1.0 / geo.spacing.z));
    std::vector<glm::vec3> normals(points.size());
    volume.visit([&](const auto& view) {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 4096),
                          [&](const tbb::blocked_range<std::size_t>& r) {
                              for (std::size_t i = r.begin(); i != r.end(); ++i) {
                                  const glm::dvec3 g =
                                      toWorld *
                                      glm::dvec3(gradientAt(view, geo.worldToIndex(points[i])));
                                  const double len = glm::length(g);
                                  normals[i] = len > 0 ? glm::vec3(-g / len) : glm::vec3(0.f);
                              }
                          });
        return 0;
    });
    return normals;
}

/// Sets vertex v's normal to normals[v]; where that is zero (the gradient vanished: a plateau exactly
/// at the isovalue), to the mesh's own area-weighted normal instead.
void applyNormals(Mesh& mesh, const std::vector<glm::vec3>& normals) {
    bool anyZero = false;
    for (const auto v : mesh.vertices()) {
        const glm::vec3& n = normals[v.idx()];
        anyZero = anyZero || n == glm::vec3(0.f);
        mesh.set_normal(v, Mesh::Normal(n.x, n.y, n.z));
    }
    if (!anyZero) return;
    mesh.request_face_normals();
    mesh.update_face_normals();
    for (const auto v : mesh.vertices())
        if (normals[v.idx()] == glm::vec3(0.f)) {
            const Mesh::Normal n = mesh.calc_vertex_normal(v);
            const double len = n.norm();
            mesh.set_normal(v, len > 0 ? n / len : n);
        }
    mesh.release_face_normals();
}

/// An indexed triangle list in world mm.
struct Soup {
    std::vector<glm::dvec3> points;
    std::vector<std::uint32_t> triangles;
    /// With caps (all empty without): per point, the sum of the outward normals of the caps it
    /// lies on (zero elsewhere), and whether it lies inside a cap, off the isosurface (a later plane
    /// cut a cap's diagonal there); per triangle, whether it belongs to a cap.
    std::vector<glm::dvec3> capNormal;
    std::vector<char> offSurface;
    std::vector<char> capFace;
};

/// Cuts `soup` by one half-space, keeping dot(x − p, n) ≥ 0 (header comment: open cut). The points
/// on the plane (made by the cut, or lying on it), as indices after the cut.
std::vector<std::uint32_t> clipSoup(Soup& soup, const core::HalfSpace& h, double snap) {
    const std::size_t np = soup.points.size();
    std::vector<double> d(np);
    for (std::size_t i = 0; i < np; ++i) {
        d[i] = h.distance(soup.points[i]);
        // On the plane: no sliver (kClipSnapVoxels), and moved onto it (≤ the snap), so that a
        // cap's vertices all lie on its plane — what clean-up's hold tests (cleanup.h).
        if (std::abs(d[i]) <= snap) soup.points[i] -= d[i] * h.normal, d[i] = 0.0;
    }
    // The point where edge (a in, b out) crosses the plane, made once per edge.
    std::unordered_map<std::uint64_t, std::uint32_t> cuts;
    const bool caps = !soup.capNormal.empty();
    bool fromCap = false;  // the triangle being cut belongs to a cap
    auto cut = [&](std::uint32_t a, std::uint32_t b) -> std::uint32_t {
        if (d[a] == 0.0) return a;  // a lies on the plane: no new point, no sliver
        const std::uint64_t key = (std::uint64_t(std::min(a, b)) << 32) | std::max(a, b);
        const auto [it, fresh] = cuts.try_emplace(key, std::uint32_t(soup.points.size()));
        if (fresh) {
            const double t = d[a] / (d[a] - d[b]);
            soup.points.push_back(soup.points[a] + t * (soup.points[b] - soup.points[a]));
            if (caps) {
                // On an edge between two points of an earlier cap: in that cap's plane too.
                const bool inCap =
                    soup.capNormal[a] != glm::dvec3(0.0) && soup.capNormal[b] != glm::dvec3(0.0);
                soup.capNormal.push_back(inCap ? soup.capNormal[a] : glm::dvec3(0.0));
                soup.offSurface.push_back(fromCap);
            }
        } else if (caps && !fromCap) {
            soup.offSurface[it->second] = 0;  // the edge is a surface triangle's too (a rim)
        }
        return it->second;
    };
    std::vector<std::uint32_t> out;
    std::vector<char> outCap;
    out.reserve(soup.triangles.size());
    auto emit = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
        if (a == b || b == c || c == a) return;
        out.insert(out.end(), {a, b, c});
        if (caps) outCap.push_back(fromCap);
    };
    for (std::size_t t = 0; t < soup.triangles.size(); t += 3) {
        fromCap = caps && soup.capFace[t / 3];
        const std::uint32_t v[3] = {soup.triangles[t], soup.triangles[t + 1],
                                    soup.triangles[t + 2]};
        const bool in[3] = {d[v[0]] >= 0, d[v[1]] >= 0, d[v[2]] >= 0};
        const int count = int(in[0]) + int(in[1]) + int(in[2]);
        if (count == 3) {
            emit(v[0], v[1], v[2]);
            continue;
        }
        if (count == 0) continue;
        // Rotate so that v[0] is the odd one out (the lone inside or the lone outside vertex),
        // keeping the winding.
        int r = 0;
        for (int k = 0; k < 3; ++k)
            if (in[k] == (count == 1)) r = k;
        const std::uint32_t a = v[r], b = v[(r + 1) % 3], c = v[(r + 2) % 3];
        if (count == 1) {
            emit(a, cut(a, b), cut(a, c));
        } else {
            const std::uint32_t ab = cut(b, a), ac = cut(c, a);
            emit(ab, b, c);
            emit(ab, c, ac);
        }
    }
    soup.triangles = std::move(out);
    if (caps) soup.capFace = std::move(outCap);
    // Drop the points no triangle uses any more.
    std::vector<std::uint32_t> remap(soup.points.size(), UINT32_MAX);
    std::vector<glm::dvec3> kept, keptCap;
    std::vector<char> keptOff;
    for (auto& i : soup.triangles) {
        if (remap[i] == UINT32_MAX) {
            remap[i] = std::uint32_t(kept.size());
            kept.push_back(soup.points[i]);
            if (caps) keptCap.push_back(soup.capNormal[i]), keptOff.push_back(soup.offSurface[i]);
        }
        i = remap[i];
    }
    if (caps) soup.capNormal = std::move(keptCap), soup.offSurface = std::move(keptOff);
    std::vector<std::uint32_t> onPlane;
    for (std::size_t i = 0; i < remap.size(); ++i)
        if (remap[i] != UINT32_MAX && (i >= np || d[i] == 0.0)) onPlane.push_back(remap[i]);
    soup.points = std::move(kept);
    return onPlane;
}

/// Closes the cut that clipSoup made by `h` with a flat cap (header comment: capped cut): the
/// boundary edges on the plane, reversed, are the cap's contours; CGAL fills them (cap_fill.h: nested
/// ones are holes), and the cap is wound to agree with the surface along them. Chains that do not close
/// (the surface was open there, e.g. at the volume's border) are left open and counted.
void capSoup(Soup& soup, const core::HalfSpace& h, const std::vector<std::uint32_t>& onPlane,
             ExtractStats& st) {
    std::vector<char> on(soup.points.size(), 0);
    for (const std::uint32_t i : onPlane) on[i] = 1;
    auto key = [](std::uint32_t a, std::uint32_t b) { return (std::uint64_t(a) << 32) | b; };
    std::unordered_map<std::uint64_t, int> directed;
    for (std::size_t t = 0; t < soup.triangles.size(); t += 3)
        for (int e = 0; e < 3; ++e) {
            const std::uint32_t a = soup.triangles[t + e], b = soup.triangles[t + (e + 1) % 3];
            if (on[a] && on[b]) ++directed[key(a, b)];
        }
    // Boundary edges a→b of the surface on the plane; the cap runs along them as b→a.
    std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
    for (const auto& [k, n] : directed) {
        const std::uint32_t a = std::uint32_t(k >> 32), b = std::uint32_t(k);
        if (n == 1 && !directed.count(key(b, a))) edges.emplace_back(b, a);
    }
    std::sort(edges.begin(), edges.end());  // a deterministic order whatever the hash map's
    // Peel chains that do not close: a vertex with no edge in (or out) starts (or ends) one.
    std::unordered_map<std::uint32_t, int> in, out;
    for (const auto& [a, b] : edges) ++out[a], ++in[b];
    std::vector<char> dropped(edges.size(), 0);
    for (bool changed = true; changed;) {
        changed = false;
        for (std::size_t e = 0; e < edges.size(); ++e) {
            if (dropped[e]) continue;
            const auto [a, b] = edges[e];
            if (in[a] == 0 || out[b] == 0) {
                dropped[e] = 1, changed = true;
                --out[a], --in[b];
                ++st.capOpenEdges;
            }
        }
    }
    // The contours in the plane's own 2-D coordinates (any orthonormal basis of it).
    const glm::dvec3 n = h.normal;
    const glm::dvec3 u = glm::normalize(
        glm::cross(n, std::abs(n.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0)));
    const glm::dvec3 w = glm::cross(n, u);
    std::vector<std::uint32_t> local(soup.points.size(), UINT32_MAX), global;
    std::vector<glm::dvec2> points;
    std::vector<std::uint32_t> segments;
    auto index = [&](std::uint32_t v) {
        if (local[v] == UINT32_MAX) {
            local[v] = std::uint32_t(global.size());
            global.push_back(v);
            const glm::dvec3 q = soup.points[v] - h.point;
            points.emplace_back(glm::dot(q, u), glm::dot(q, w));
        }
        return local[v];
    };
    std::pair<std::uint32_t, std::uint32_t> reference{UINT32_MAX, UINT32_MAX};
    for (std::size_t e = 0; e < edges.size(); ++e)
        if (!dropped[e]) {
            segments.push_back(index(edges[e].first));
            segments.push_back(index(edges[e].second));
            if (reference.first == UINT32_MAX) reference = edges[e];
        }
    if (segments.empty()) return;
    bool ok = true;
    std::vector<std::uint32_t> tris = detail::fillContours(points, segments, ok);
    if (!ok) ++st.capFailures;
    // Winding: the triangle on the reference edge must run along it (b→a of the surface's a→b);
    // the cap is flat, so every triangle takes the same side of the plane's normal as that one.
    auto side = [&](std::size_t t) {
        const glm::dvec3& p = soup.points[global[tris[t]]];
        const glm::dvec3 n =
            glm::cross(soup.points[global[tris[t + 1]]] - p, soup.points[global[tris[t + 2]]] - p);
        return glm::dot(n, h.normal) >= 0.0;
    };
    std::optional<bool> want;
    const std::uint32_t ra = local[reference.first], rb = local[reference.second];
    for (std::size_t t = 0; t < tris.size() && !want; t += 3)
        for (int k = 0; k < 3; ++k) {
            if (tris[t + k] == ra && tris[t + (k + 1) % 3] == rb) want = side(t);
            if (tris[t + k] == rb && tris[t + (k + 1) % 3] == ra) want = !side(t);
        }
    if (!want)
        want = false;  // no triangle on that edge (a failed fill): face away from the kept side
    soup.capNormal.resize(soup.points.size(), glm::dvec3(0.0));
    soup.offSurface.resize(soup.points.size(), 0);
    soup.capFace.resize(soup.triangles.size() / 3, 0);
    for (std::size_t t = 0; t < tris.size(); t += 3) {
        if (side(t) != *want) std::swap(tris[t + 1], tris[t + 2]);
        for (int k = 0; k < 3; ++k) soup.triangles.push_back(global[tris[t + k]]);
        soup.capFace.push_back(1);
    }
    for (const std::uint32_t v : global) soup.capNormal[v] -= h.normal;  // the cap faces away
    st.capTriangles += tris.size() / 3;
}

}  // namespace

namespace {
/// Voxel edges whose two ends lie on either side of `stored` (the mesh's vertices, one per such
/// edge) at voxels within a voxel diagonal of every half-space of `keep`: what the surface's size
/// scales with.
std::uint64_t crossedEdges(const core::Volume& volume, double stored,
                           const std::vector<core::HalfSpace>& keep,
                           const core::Progress& progress) {
    const glm::ivec3 n = volume.dims();
    const core::Geometry& geo = volume.geometry();
    const double margin = glm::length(geo.spacing);
    std::vector<std::uint64_t> perSlice(std::size_t(n.z), 0);
    volume.visit([&](const auto& v) {
        tbb::parallel_for(0, n.z, [&](int k) {
            if (progress.cancelled()) return;
            std::uint64_t count = 0;
            for (int j = 0; j < n.y; ++j)
                for (int i = 0; i < n.x; ++i) {
                    const std::size_t at =
                        std::size_t(i) + v.sy * std::size_t(j) + v.sz * std::size_t(k);
                    const bool above = double(v.data[at]) > stored;
                    int crossed = 0;
                    if (i + 1 < n.x) crossed += (double(v.data[at + 1]) > stored) != above;
                    if (j + 1 < n.y) crossed += (double(v.data[at + v.sy]) > stored) != above;
                    if (k + 1 < n.z) crossed += (double(v.data[at + v.sz]) > stored) != above;
                    if (crossed == 0) continue;
                    const glm::dvec3 c = geo.indexToWorld(glm::dvec3(i, j, k));
                    bool kept = true;
                    for (const core::HalfSpace& h : keep) kept = kept && h.distance(c) >= -margin;
                    if (kept) count += std::uint64_t(crossed);
                }
            perSlice[std::size_t(k)] = count;
        });
    });
    progress.checkCancel();
    std::uint64_t total = 0;
    for (const std::uint64_t c : perSlice) total += c;
    return total;
}
}  // namespace

Extraction extractIsosurface(const core::Volume& volume, const ExtractOptions& options,
                             const core::Progress& progress) {
    Extraction result;
    ExtractStats& st = result.stats;
    st.isovalue = options.isovalue;
    st.range = volume.physicalRange();
    const auto [lo, hi] = st.range;
    if (!(lo < hi))
        throw InputError(
            "isosurface", "volume",
            "the volume is flat (every voxel is " + number(lo) + "): it has no isosurface",
            "use a volume whose values vary");
    if (!(options.isovalue > lo && options.isovalue < hi))
        throw InputError(
            "isosurface", "isovalue",
            number(options.isovalue) + " is outside the data range [" + number(lo) + ", " +
                number(hi) + "]",
            "choose an isovalue strictly between " + number(lo) + " and " + number(hi));

    // Physical → stored, with the integer rule of the header comment.
    const double slope = volume.mapping.slope;
    double stored = (options.isovalue - volume.mapping.intercept) / slope;
    if (isIntegerType(volume.type()) &&
        std::abs(stored - std::round(stored)) <= 1e-9 * std::max(1.0, std::abs(stored))) {
        stored = std::round(stored) - (slope > 0 ? kIntegerIsoNudge : -kIntegerIsoNudge);
        st.nudged = true;
        // An isovalue within the rule's tolerance of the data's lower end snaps to it, and the
        // nudge then leaves the range: every voxel would be inside and the mesh empty. That is
        // the lower end itself, and refused like it.
        const double storedLo = (lo - volume.mapping.intercept) / slope,
                     storedHi = (hi - volume.mapping.intercept) / slope;
        if (!(stored > std::min(storedLo, storedHi) && stored < std::max(storedLo, storedHi)))
            throw InputError("isosurface", "isovalue",
                             number(options.isovalue) +
                                 " rounds to the lower end of the data range [" + number(lo) +
                                 ", " + number(hi) + "] (integer data)",
                             "choose an isovalue strictly between " + number(lo) + " and " +
                                 number(hi) + ", not equal to " + number(lo) + " up to rounding");
    }
    st.storedIsovalue = stored;
    if (options.maxMemoryMiB > 0.0) {
        const std::uint64_t edges = crossedEdges(volume, stored, options.keep, progress);
        const double triangles = kTrianglesPerCrossedEdge * double(edges);
        const double mib = triangles * kPeakBytesPerTriangle / (1024.0 * 1024.0);
        if (mib > options.maxMemoryMiB)
            throw InputError("isosurface", "memory",
                             "the isosurface at " + number(options.isovalue) + " crosses " +
                                 std::to_string(edges) + " voxel edges: about " +
                                 number(std::round(triangles / 1e5) / 10.0) + " M triangles, " +
                                 number(std::round(mib / 1024.0 * 10.0) / 10.0) +
                                 " GiB at the peak, over the budget of " +
                                 number(options.maxMemoryMiB) + " MiB",
                             "choose an isovalue above the noise, keep less of the volume "
                             "(crop_box, clip_planes), or raise the budget");
    }

    // Flying edges, index space → world mm.
    core::Stopwatch sw;
    fe_module::Soup fe = feModule().flyingEdges(volume, stored, progress);
    st.flyingEdgesSeconds = sw.seconds();
    st.flyingEdgesTriangles = fe.triangles.size() / 3;
    sw.restart();
    Soup soup;
    soup.points.resize(fe.points.size() / 3);
    const core::Geometry& geo = volume.geometry();
    for (std::size_t i = 0; i < soup.points.size(); ++i)
        soup.points[i] =
            geo.indexToWorld({fe.points[3 * i], fe.points[3 * i + 1], fe.points[3 * i + 2]});
    soup.triangles = std::move(fe.triangles);
    fe.points = {};
    const glm::dvec3& sp = volume.geometry().spacing;
    double largest = 0.0;
    for (const glm::dvec3& p : soup.points)
        largest = std::max({largest, std::abs(p.x), std::abs(p.y), std::abs(p.z)});
    const double snap =
        std::max(kClipSnapVoxels * std::min({sp.x, sp.y, sp.z}),
                 kClipSnapFloatSteps * double(std::numeric_limits<float>::epsilon()) * largest);
    const double nudge = std::max(kCapPlaneNudge * std::min({sp.x, sp.y, sp.z}), 4.0 * snap);
    for (core::HalfSpace h : options.keep) {
        progress.checkCancel();
        // A capped plane through mesh vertices would pinch the cap's contours there (two loops
        // meeting at one vertex: a non-manifold cap); moved off them into the removed side.
        if (options.cap &&
            std::any_of(soup.points.begin(), soup.points.end(),
                        [&](const glm::dvec3& p) { return std::abs(h.distance(p)) <= snap; }))
            h.point -= nudge * h.normal;
        result.planes.push_back(h);
        const std::vector<std::uint32_t> onPlane = clipSoup(soup, h, snap);
        // Each cap is cut by the planes after it, so the caps meet along their lines.
        if (options.cap) capSoup(soup, h, onPlane, st);
    }
    st.clippedTriangles = soup.triangles.size() / 3;
    st.clipSeconds = sw.seconds();

    // Normals, and the winding that agrees with them (VTK's winding is flipped by a mirroring
    // direction matrix or a negative slope; a whole-mesh vote decides).
    sw.restart();
    progress.report("isosurface normals", 0.0);
    std::vector<glm::vec3> normals = gradientNormals(soup.points, volume);
    // A rim vertex is shared by the surface and its cap (watertight) but has one normal: the
    // bisector of the two (header comment), so neither side is shaded edge-on.
    // A point inside a cap (off the surface) takes the cap's normal alone.
    for (std::size_t i = 0; i < soup.capNormal.size(); ++i) {
        if (soup.capNormal[i] == glm::dvec3(0.0)) continue;
        const glm::dvec3 c = glm::normalize(soup.capNormal[i]);
        normals[i] = soup.offSurface[i] || normals[i] == glm::vec3(0.f)
                         ? glm::vec3(c)
                         : glm::vec3(glm::normalize(glm::dvec3(normals[i]) + c));
    }
    double agree = 0.0;
    for (std::size_t t = 0; t < soup.triangles.size(); t += 3) {
        const glm::dvec3& a = soup.points[soup.triangles[t]];
        const glm::dvec3 n = glm::cross(soup.points[soup.triangles[t + 1]] - a,
                                        soup.points[soup.triangles[t + 2]] - a);
        const glm::vec3 g = normals[soup.triangles[t]] + normals[soup.triangles[t + 1]] +
                            normals[soup.triangles[t + 2]];
        agree += glm::dot(n, glm::dvec3(g));
    }
    st.flipped = agree < 0.0;
    st.normalsSeconds = sw.seconds();

    // OpenMesh half-edge mesh.
    sw.restart();
    progress.report("isosurface mesh", 0.0);
    Mesh& mesh = result.mesh;
    const std::size_t nf = soup.triangles.size() / 3;
    mesh.reserve(soup.points.size(), nf * 3 / 2 + 16, nf);
    std::vector<Mesh::VertexHandle> vh(soup.points.size());
    const Mesh::Color color(options.color.r, options.color.g, options.color.b);
    for (std::size_t i = 0; i < soup.points.size(); ++i) {
        const glm::dvec3& p = soup.points[i];
        vh[i] = mesh.add_vertex(Mesh::Point(p.x, p.y, p.z));
        mesh.set_color(vh[i], color);
    }
    // OpenMesh reports every refused face on its error stream; they are counted instead.
    omerr().disable();
    for (std::size_t t = 0; t < nf; ++t) {
        if ((t & 0xFFFF) == 0) progress.report("isosurface mesh", double(t) / double(nf));
        const std::uint32_t* f = &soup.triangles[3 * t];
        const Mesh::FaceHandle h = st.flipped ? mesh.add_face(vh[f[0]], vh[f[2]], vh[f[1]])
                                              : mesh.add_face(vh[f[0]], vh[f[1]], vh[f[2]]);
        if (!h.is_valid()) ++st.rejectedFaces;
    }
    omerr().enable();
    applyNormals(mesh, normals);
    st.meshSeconds = sw.seconds();
    progress.report("isosurface mesh", 1.0);
    return result;
}

void setGradientNormals(Mesh& mesh, const core::Volume& volume,
                        const std::vector<core::HalfSpace>& capPlanes, double onPlaneMm) {
    std::vector<glm::dvec3> points(mesh.n_vertices());
    for (const auto v : mesh.vertices()) {
        const Mesh::Point& p = mesh.point(v);
        points[v.idx()] = {p[0], p[1], p[2]};
    }
    std::vector<glm::vec3> normals = gradientNormals(points, volume);
    if (!capPlanes.empty()) {
        // The outward normal of the caps through each vertex (as capSoup sums them), zero off
        // every capped plane.
        std::vector<glm::dvec3> cap(points.size(), glm::dvec3(0.0));
        for (std::size_t i = 0; i < points.size(); ++i)
            for (const core::HalfSpace& h : capPlanes)
                if (std::abs(h.distance(points[i])) <= onPlaneMm) cap[i] -= h.normal;
        for (const auto v : mesh.vertices()) {
            const std::size_t i = std::size_t(v.idx());
            if (cap[i] == glm::dvec3(0.0)) continue;
            // A cap's own vertex: every face around it lies on capped planes.
            bool offSurface = true;
            for (const auto f : mesh.vf_range(v))
                for (const auto w : mesh.fv_range(f))
                    offSurface = offSurface && cap[std::size_t(w.idx())] != glm::dvec3(0.0);
            const glm::dvec3 c = glm::normalize(cap[i]);
            normals[i] = offSurface || normals[i] == glm::vec3(0.f)
                             ? glm::vec3(c)
                             : glm::vec3(glm::normalize(glm::dvec3(normals[i]) + c));
        }
    }
    applyNormals(mesh, normals);
}

}  // namespace voxlight::iso
