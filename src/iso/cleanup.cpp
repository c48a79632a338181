// SPDX-License-Identifier: MIT
// CGAL's side of iso/: clean-up and report (cleanup.h). The mesh crosses into a CGAL::Surface_mesh
// and back; vertex colours and normals travel as Surface_mesh properties.
#include "iso/cleanup.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/connected_components.h>
#include <CGAL/Polygon_mesh_processing/manifoldness.h>
#include <CGAL/Polygon_mesh_processing/measure.h>
#include <CGAL/Polygon_mesh_processing/repair_degeneracies.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Bounded_normal_change_filter.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Constrained_placement.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/LindstromTurk_cost.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/LindstromTurk_placement.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <ostream>
#include <vector>

#include "core/error.h"
#include "core/timing.h"

namespace voxlight::iso {

namespace {
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using SurfaceMesh = CGAL::Surface_mesh<Kernel::Point_3>;
using Color = std::array<float, 3>;
using Normal = std::array<double, 3>;
namespace PMP = CGAL::Polygon_mesh_processing;
namespace SMS = CGAL::Surface_mesh_simplification;

/// The mesh's points, read through a check of the cancel flag (reportMesh).
struct CancellablePoints {
    using key_type = SurfaceMesh::Vertex_index;
    using value_type = Kernel::Point_3;
    using reference = const Kernel::Point_3&;
    using category = boost::readable_property_map_tag;
    const SurfaceMesh* mesh;
    const core::Progress* progress;
    friend reference get(const CancellablePoints& m, key_type v) {
        m.progress->checkCancel();
        return m.mesh->point(v);
    }
};

SurfaceMesh toCgal(const Mesh& mesh) {
    SurfaceMesh sm;
    sm.reserve(SurfaceMesh::size_type(mesh.n_vertices()), SurfaceMesh::size_type(mesh.n_edges()),
               SurfaceMesh::size_type(mesh.n_faces()));
    auto color = sm.add_property_map<SurfaceMesh::Vertex_index, Color>("v:voxlight_color").first;
    auto normal = sm.add_property_map<SurfaceMesh::Vertex_index, Normal>("v:voxlight_normal").first;
    std::vector<SurfaceMesh::Vertex_index> vi(mesh.n_vertices());
    for (const auto v : mesh.vertices()) {
        const Mesh::Point& p = mesh.point(v);
        vi[v.idx()] = sm.add_vertex(Kernel::Point_3(p[0], p[1], p[2]));
        const Mesh::Color& c = mesh.color(v);
        color[vi[v.idx()]] = {c[0], c[1], c[2]};
        const Mesh::Normal& n = mesh.normal(v);
        normal[vi[v.idx()]] = {n[0], n[1], n[2]};
    }
    for (const auto f : mesh.faces()) {
        std::array<SurfaceMesh::Vertex_index, 3> t;
        int k = 0;
        for (const auto v : mesh.fv_range(f)) t[k++] = vi[v.idx()];
        // Both are half-edge meshes: a face OpenMesh accepted, Surface_mesh accepts.
        VL_CHECK(sm.add_face(t[0], t[1], t[2]) != SurfaceMesh::null_face());
    }
    return sm;
}

/// Back to OpenMesh, dropping vertices no face uses any more.
Mesh fromCgal(const SurfaceMesh& sm) {
    Mesh mesh;
    const auto color = sm.property_map<SurfaceMesh::Vertex_index, Color>("v:voxlight_color").first;
    const auto normal =
        sm.property_map<SurfaceMesh::Vertex_index, Normal>("v:voxlight_normal").first;
    mesh.reserve(sm.number_of_vertices(), sm.number_of_edges(), sm.number_of_faces());
    std::vector<Mesh::VertexHandle> vh(sm.num_vertices());
    for (const auto v : sm.vertices()) {
        if (sm.is_isolated(v)) continue;
        const auto& p = sm.point(v);
        vh[v.idx()] = mesh.add_vertex(Mesh::Point(p.x(), p.y(), p.z()));
        const Color& c = color[v];
        mesh.set_color(vh[v.idx()], Mesh::Color(c[0], c[1], c[2]));
        const Normal& n = normal[v];
        mesh.set_normal(vh[v.idx()], Mesh::Normal(n[0], n[1], n[2]));
    }
    omerr().disable();
    for (const auto f : sm.faces()) {
        std::array<Mesh::VertexHandle, 3> t;
        int k = 0;
        for (const auto v : CGAL::vertices_around_face(sm.halfedge(f), sm)) t[k++] = vh[v.idx()];
        mesh.add_face(t[0], t[1], t[2]);
    }
    omerr().enable();
    return mesh;
}

/// Per closed component (by face component ids): six times its signed volume, and twice the rate
/// at which its area-weighted vertex normals (`unit`, filled here) sweep volume — twice the area
/// where the surface is smooth, less at sharp corners (an octahedron's vertex normal meets its
/// faces at 55°: the area alone made each pass restore 58 % of what was lost). Zero when open.
struct ComponentSizes {
    std::vector<double> volume6, sweep2;
};

ComponentSizes componentSizes(const SurfaceMesh& sm, const std::vector<std::size_t>& faceComp,
                              const std::vector<char>& closed,
                              std::vector<Kernel::Vector_3>& unit) {
    auto faceCross = [&](SurfaceMesh::Face_index f, std::array<SurfaceMesh::Vertex_index, 3>& t) {
        int i = 0;
        for (const auto v : CGAL::vertices_around_face(sm.halfedge(f), sm)) t[i++] = v;
        return CGAL::cross_product(sm.point(t[1]) - sm.point(t[0]),
                                   sm.point(t[2]) - sm.point(t[0]));
    };
    std::array<SurfaceMesh::Vertex_index, 3> t;
    unit.assign(sm.num_vertices(), Kernel::Vector_3(0, 0, 0));
    for (const auto f : sm.faces()) {
        if (!closed[faceComp[f.idx()]]) continue;
        const Kernel::Vector_3 n = faceCross(f, t);
        for (const auto v : t) unit[v.idx()] = unit[v.idx()] + n;
    }
    for (auto& n : unit) {
        const double len = std::sqrt(n.squared_length());
        if (len > 0.0) n = n / len;
    }
    ComponentSizes c;
    c.volume6.assign(closed.size(), 0.0);
    c.sweep2.assign(closed.size(), 0.0);
    for (const auto f : sm.faces()) {
        const std::size_t k = faceComp[f.idx()];
        if (!closed[k]) continue;
        const Kernel::Vector_3 n = faceCross(f, t);
        c.volume6[k] +=
            CGAL::determinant(sm.point(t[0]) - CGAL::ORIGIN, sm.point(t[1]) - CGAL::ORIGIN,
                              sm.point(t[2]) - CGAL::ORIGIN);
        for (const auto v : t) c.sweep2[k] += unit[v.idx()] * n / 3.0;
    }
    return c;
}

/// Taubin λ|μ smoothing (cleanup.h): each iteration moves every interior vertex by λ, then by μ,
/// times (mean of its neighbours − itself). Boundary vertices (open cuts, the volume's faces) stay.
/// Then every vertex of a closed component moves along its normal by the distance that returns the
/// component's volume before smoothing (lost volume / the rate its vertex normals sweep volume,
/// componentSizes): a small component's size is a high
/// frequency of the filter's — a one-voxel blob (an octahedron) lost a quarter of its size per
/// iteration and shrank to a point in 50, a calcification gone without a word.
void taubinSmooth(SurfaceMesh& sm, int iterations, const std::vector<core::HalfSpace>& heldPlanes,
                  const core::Progress& progress) {
    // Newton passes: one is exact to first order in δ; the blob (an octahedron, whose volume is far
    // from linear in δ) measured 1.6 % over after two, within 1e-6 after four.
    constexpr int kVolumePasses = 4;
    std::vector<Kernel::Point_3> next(sm.num_vertices());
    auto compMap = sm.add_property_map<SurfaceMesh::Face_index, std::size_t>("f:smooth_cc").first;
    const std::size_t components = PMP::connected_components(sm, compMap);
    std::vector<std::size_t> faceComp(sm.num_faces(), 0), vertexComp(sm.num_vertices(), 0);
    std::vector<char> closed(components, 1);
    for (const auto f : sm.faces()) {
        faceComp[f.idx()] = compMap[f];
        for (const auto h : CGAL::halfedges_around_face(sm.halfedge(f), sm)) {
            vertexComp[sm.target(h).idx()] = compMap[f];
            if (sm.is_border(sm.opposite(h))) closed[compMap[f]] = 0;
        }
    }
    sm.remove_property_map(compMap);
    // Held: isolated, on a border (open cuts, the volume's faces) or on a capped plane.
    std::vector<char> held(sm.num_vertices(), 0);
    for (const auto v : sm.vertices()) {
        const Kernel::Point_3& p = sm.point(v);
        const glm::dvec3 x(p.x(), p.y(), p.z());
        held[v.idx()] = sm.is_isolated(v) || sm.is_border(v, false) ||
                        std::any_of(heldPlanes.begin(), heldPlanes.end(), [&](const auto& h) {
                            return std::abs(h.distance(x)) <= kOnCapPlaneMm;
                        });
    }
    // A move that would take a vertex to the removed side of a capped plane is not made: it would
    // cross the cap (the abdominal CT capped at a voxel plane: 29 self-intersecting pairs after 5
    // iterations without this).
    auto keptSide = [&](const Kernel::Point_3& q) {
        const glm::dvec3 x(q.x(), q.y(), q.z());
        return std::none_of(heldPlanes.begin(), heldPlanes.end(),
                            [&](const auto& h) { return h.distance(x) < kOnCapPlaneMm; });
    };
    std::vector<Kernel::Vector_3> normal;
    const std::vector<double> volume6 = componentSizes(sm, faceComp, closed, normal).volume6;
    for (int it = 0; it < iterations; ++it) {
        progress.checkCancel();
        progress.report("mesh clean-up: smoothing", double(it) / double(iterations));
        for (const double f : {kTaubinLambda, kTaubinMu}) {
            for (const auto v : sm.vertices()) {
                const Kernel::Point_3& p = sm.point(v);
                next[v.idx()] = p;
                if (held[v.idx()]) continue;
                double sx = 0, sy = 0, sz = 0;
                int n = 0;
                for (const auto w : CGAL::vertices_around_target(sm.halfedge(v), sm)) {
                    const Kernel::Point_3& q = sm.point(w);
                    sx += q.x(), sy += q.y(), sz += q.z();
                    ++n;
                }
                const Kernel::Point_3 q(p.x() + f * (sx / n - p.x()), p.y() + f * (sy / n - p.y()),
                                        p.z() + f * (sz / n - p.z()));
                if (keptSide(q)) next[v.idx()] = q;
            }
            for (const auto v : sm.vertices()) sm.point(v) = next[v.idx()];
        }
        // The volume back: every vertex of a closed component along its normal by δ = lost
        // volume / sweep rate (first order in δ: a few passes where a small blob lost much).
        for (int pass = 0; pass < kVolumePasses; ++pass) {
            const ComponentSizes now = componentSizes(sm, faceComp, closed, normal);
            for (const auto v : sm.vertices()) {
                if (sm.is_isolated(v) || held[v.idx()]) continue;
                const std::size_t k = vertexComp[v.idx()];
                if (!closed[k] || !(now.sweep2[k] > 0.0)) continue;
                const double delta = (volume6[k] - now.volume6[k]) / 3.0 / now.sweep2[k];
                const Kernel::Point_3 q = sm.point(v) + delta * normal[v.idx()];
                if (keptSide(q)) sm.point(v) = q;
            }
        }
    }
}

}  // namespace

CleanupStats cleanUp(Mesh& mesh, const CleanupOptions& options, const core::Progress& progress) {
    if (options.smoothIterations > kMaxSmoothIterations || options.smoothIterations < 0)
        throw InputError("cleanup", "smooth",
                         "takes 0…" + std::to_string(kMaxSmoothIterations) + " iterations, got " +
                             std::to_string(options.smoothIterations),
                         "the pass band's gain compounds beyond that (cleanup.h)");
    CleanupStats st;
    st.facesBefore = st.facesAfter = mesh.n_faces();
    if (!options.any()) return st;
    core::Stopwatch sw;
    SurfaceMesh sm = toCgal(mesh);
    if (options.removeDegenerate) {
        progress.report("mesh clean-up: degenerate faces", 0.0);
        const std::size_t before = sm.number_of_faces();
        PMP::remove_degenerate_faces(sm);
        sm.collect_garbage();
        st.degenerateFacesRemoved = before - sm.number_of_faces();
    }
    if (options.keepLargest > 0) {
        progress.report("mesh clean-up: components", 0.0);
        st.componentsRemoved +=
            PMP::keep_largest_connected_components(sm, std::size_t(options.keepLargest));
        sm.collect_garbage();
    }
    if (options.minComponentFaces > 0) {
        progress.report("mesh clean-up: components", 0.5);
        st.componentsRemoved += PMP::keep_large_connected_components(sm, options.minComponentFaces);
        sm.collect_garbage();
    }
    if (options.smoothIterations > 0 && sm.number_of_faces() > 0) {
        progress.report("mesh clean-up: smoothing", 0.0);
        taubinSmooth(sm, options.smoothIterations, options.heldPlanes, progress);
        st.verticesMoved = true;
    }
    if (options.targetFaces > 0 && sm.number_of_faces() > options.targetFaces) {
        progress.report("mesh clean-up: decimation", 0.0);
        SMS::Count_stop_predicate<SurfaceMesh> stop(3 * options.targetFaces / 2);
        // A capped cut stays as cut: the cap's own edges and its rim (both ends on a capped
        // plane) never collapse, and a collapse next to them keeps their vertex where it is
        // (Constrained_placement), so the cap stays flat (it bent 0.01 mm off its plane, and its
        // rim shaded edge-on). Freezing every edge at the rim left the budget to the rest of the
        // surface, which folded (the angio torso to 5000 faces: 136 self-intersecting pairs).
        using ConstrainedMap = SurfaceMesh::Property_map<SurfaceMesh::Edge_index, bool>;
        ConstrainedMap constrained =
            sm.add_property_map<SurfaceMesh::Edge_index, bool>("e:on_cap", false).first;
        if (!options.heldPlanes.empty()) {
            std::vector<char> onCap(sm.num_vertices(), 0);
            for (const auto v : sm.vertices()) {
                const Kernel::Point_3& p = sm.point(v);
                const glm::dvec3 x(p.x(), p.y(), p.z());
                onCap[v.idx()] = std::any_of(
                    options.heldPlanes.begin(), options.heldPlanes.end(),
                    [&](const auto& h) { return std::abs(h.distance(x)) <= kOnCapPlaneMm; });
            }
            for (const auto e : sm.edges())
                constrained[e] = onCap[sm.vertex(e, 0).idx()] && onCap[sm.vertex(e, 1).idx()];
        }
        // Refuse collapses that would turn a face over (a source of self-intersections).
        SMS::edge_collapse(
            sm, stop,
            CGAL::parameters::filter(SMS::Bounded_normal_change_filter<>())
                .edge_is_constrained_map(constrained)
                .get_cost(SMS::LindstromTurk_cost<SurfaceMesh>())
                .get_placement(SMS::Constrained_placement<SMS::LindstromTurk_placement<SurfaceMesh>,
                                                          ConstrainedMap>(constrained)));
        sm.remove_property_map(constrained);
        sm.collect_garbage();
        st.verticesMoved = true;
    }
    progress.checkCancel();
    mesh = fromCgal(sm);
    st.facesAfter = mesh.n_faces();
    st.seconds = sw.seconds();
    progress.report("mesh clean-up", 1.0);
    return st;
}

MeshReport reportMesh(const Mesh& mesh, bool checkSelfIntersections,
                      const core::Progress& progress) {
    core::Stopwatch sw;
    MeshReport r;
    r.vertices = mesh.n_vertices();
    r.faces = mesh.n_faces();
    for (const auto e : mesh.edges())
        if (mesh.is_boundary(e)) ++r.boundaryEdges;
    r.closed = r.boundaryEdges == 0;
    if (r.faces == 0) return r;
    progress.report("mesh report", 0.0);
    SurfaceMesh sm = toCgal(mesh);
    auto component = sm.add_property_map<SurfaceMesh::Face_index, std::size_t>("f:cc").first;
    r.components = PMP::connected_components(sm, component);
    std::vector<SurfaceMesh::Halfedge_index> pinched;
    PMP::non_manifold_vertices(sm, std::back_inserter(pinched));
    r.nonManifoldVertices = pinched.size();
    r.areaMm2 = CGAL::to_double(PMP::area(sm));
    if (r.closed) r.volumeMm3 = CGAL::to_double(PMP::volume(sm));
    if (checkSelfIntersections) {
        progress.report("mesh report: self-intersections", 0.5);
        std::vector<std::pair<SurfaceMesh::Face_index, SurfaceMesh::Face_index>> pairs;
        // Every triangle CGAL builds reads its corners through this map: Ctrl-C ends the count
        // at once (CGAL's own does_self_intersect leaves the search by an exception the same
        // way) — it took 25 s to act on a 6.5-M-face mesh, whose count runs 31 s.
        PMP::self_intersections(
            sm, std::back_inserter(pairs),
            CGAL::parameters::vertex_point_map(CancellablePoints{&sm, &progress}));
        r.selfIntersections = static_cast<long long>(pairs.size());
    }
    r.seconds = sw.seconds();
    progress.report("mesh report", 1.0);
    return r;
}

std::ostream& operator<<(std::ostream& os, const MeshReport& r) {
    os << r.vertices << " vertices, " << r.faces << " faces, " << r.components << " component(s), "
       << r.boundaryEdges << " boundary edges, " << r.nonManifoldVertices
       << " non-manifold vertices, self-intersections ";
    if (r.selfIntersections < 0)
        os << "not checked";
    else
        os << r.selfIntersections;
    os << ", area " << r.areaMm2 << " mm2";
    if (r.closed) os << ", volume " << r.volumeMm3 << " mm3";
    return os;
}

}  // namespace voxlight::iso
