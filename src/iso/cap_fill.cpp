// SPDX-License-Identifier: MIT
#include "iso/cap_fill.h"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <deque>
#include <set>

namespace voxlight::iso::detail {

namespace {
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_2<std::uint32_t, K>;
using Fbi = CGAL::Triangulation_face_base_with_info_2<int, K>;  // nesting depth, −1 = unvisited
using Fb = CGAL::Constrained_triangulation_face_base_2<K, Fbi>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// Exact_predicates_tag: crossing constraints are split at a constructed point instead of an error.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<K, Tds, CGAL::Exact_predicates_tag>;

/// Depth of every finite face: faces reached from the infinite face without crossing a contour
/// are 0; crossing one adds 1 (the nesting-parity fill of CGAL's polygon-with-holes example).
void markDepths(Cdt& cdt) {
    for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->info() = -1;
    std::deque<std::pair<Cdt::Face_handle, int>> seeds{{cdt.infinite_face(), 0}};
    while (!seeds.empty()) {
        const auto [start, depth] = seeds.front();
        seeds.pop_front();
        if (start->info() != -1) continue;
        std::deque<Cdt::Face_handle> queue{start};
        start->info() = depth;
        while (!queue.empty()) {
            const Cdt::Face_handle f = queue.front();
            queue.pop_front();
            for (int i = 0; i < 3; ++i) {
                const Cdt::Face_handle n = f->neighbor(i);
                if (n->info() != -1) continue;
                if (cdt.is_constrained({f, i})) {
                    seeds.emplace_back(n, depth + 1);
                } else {
                    n->info() = depth;
                    queue.push_back(n);
                }
            }
        }
    }
}
}  // namespace

std::vector<std::uint32_t> fillContours(const std::vector<glm::dvec2>& points,
                                        const std::vector<std::uint32_t>& segments, bool& ok) {
    ok = true;
    Cdt cdt;
    std::vector<Cdt::Vertex_handle> vh(points.size());
    std::set<Cdt::Vertex_handle> ours;  // CGAL's own vertices (at crossings) carry no index
    for (std::size_t i = 0; i < points.size(); ++i) {
        const std::size_t before = cdt.number_of_vertices();
        vh[i] = cdt.insert(K::Point_2(points[i].x, points[i].y));
        if (cdt.number_of_vertices() > before) vh[i]->info() = std::uint32_t(i);  // else: a twin
        ours.insert(vh[i]);
    }
    for (std::size_t s = 0; s + 1 < segments.size(); s += 2)
        if (vh[segments[s]] != vh[segments[s + 1]])
            cdt.insert_constraint(vh[segments[s]], vh[segments[s + 1]]);
    markDepths(cdt);
    std::vector<std::uint32_t> out;
    for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
        if (f->info() % 2 != 1) continue;
        std::uint32_t t[3];
        bool known = true;
        for (int k = 0; k < 3 && known; ++k) {
            known = ours.count(f->vertex(k)) > 0;
            if (known) t[k] = f->vertex(k)->info();
        }
        if (!known) {
            ok = false;  // a vertex CGAL made where contours crossed
            continue;
        }
        out.insert(out.end(), t, t + 3);
    }
    return out;
}

}  // namespace voxlight::iso::detail
