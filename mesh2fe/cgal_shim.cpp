// mesh2fe/cgal_shim.cpp: CGAL Mesh_3 behind a C interface (see cgal_shim.h)
// SPDX-License-Identifier: MIT
//
// One translation unit, compiled rarely (~45 s, ~3 GB). Follows the CGAL 5.5 manual's
// "Polyhedral domain with features" example: the closed surface becomes a polyhedron, its
// sharp edges (dihedral angle beyond crit->feature_angle_deg) are protected by balls so that
// edges and corners of the input survive, then make_mesh_3 refines the Delaunay tetrahedra
// to the criteria. Named parameters use the 5.5 `params::x = v` syntax (docs/TOOLCHAIN.md
// gotcha 15). No exception leaves this file.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/orientation.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Polyhedral_mesh_domain_with_features_3.h>
#include <CGAL/boost/graph/helpers.h>
#include <CGAL/make_mesh_3.h>

#include <cstdio>
#include <cstring>
#include <exception>
#include <new>
#include <unordered_map>
#include <vector>

extern "C" {
#include "fmbd_alloc.h"
}
#include "cgal_shim.h"

namespace {

typedef CGAL::Exact_predicates_inexact_constructions_kernel K;
typedef CGAL::Mesh_polyhedron_3<K>::type Polyhedron;
typedef CGAL::Polyhedral_mesh_domain_with_features_3<K> Mesh_domain;
typedef CGAL::Mesh_triangulation_3<Mesh_domain, CGAL::Default, CGAL::Sequential_tag>::type Tr;
typedef CGAL::Mesh_complex_3_in_triangulation_3<Tr, Mesh_domain::Corner_index,
                                                Mesh_domain::Curve_index>
    C3t3;
typedef CGAL::Mesh_criteria_3<Tr> Mesh_criteria;
namespace PMP = CGAL::Polygon_mesh_processing;
namespace params = CGAL::parameters;

void set_msg(char *msg, int msglen, const char *text) {
  if (msg && msglen > 0) {
    std::snprintf(msg, (size_t)msglen, "%s", text);
  }
}

int mesh_surface(int64_t nv, const double *xyz, int64_t nf, const int64_t *tri,
                 const fmbd_cgal_criteria *crit, int64_t *nnodes, double **nodes, int64_t *ntet,
                 int64_t **tet, char *msg, int msglen) {
  // --- the polygon soup -> a closed, consistently oriented polyhedron ---
  std::vector<K::Point_3> points;
  points.reserve((size_t)nv);
  for (int64_t i = 0; i < nv; i++) {
    points.emplace_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
  }
  std::vector<std::vector<std::size_t>> polygons((size_t)nf);
  for (int64_t f = 0; f < nf; f++) {
    for (int a = 0; a < 3; a++) {
      int64_t v = tri[3 * f + a];
      if (v < 0 || v >= nv) {
        set_msg(msg, msglen, "triangle refers to a vertex out of range");
        return FMBD_CGAL_BAD_SURFACE;
      }
      polygons[(size_t)f].push_back((std::size_t)v);
    }
  }
  if (!PMP::orient_polygon_soup(points, polygons)) {
    set_msg(msg, msglen,
            "the surface is not manifold (an edge is shared by more than two triangles, or "
            "triangles touch at a vertex only)");
    return FMBD_CGAL_BAD_SURFACE;
  }
  Polyhedron poly;
  PMP::polygon_soup_to_polygon_mesh(points, polygons, poly);
  if (!CGAL::is_closed(poly)) {
    set_msg(msg, msglen, "the surface is not closed (it has border edges)");
    return FMBD_CGAL_BAD_SURFACE;
  }
  if (!CGAL::is_triangle_mesh(poly)) {
    set_msg(msg, msglen, "the surface is not a triangle mesh");
    return FMBD_CGAL_BAD_SURFACE;
  }
  if (PMP::does_self_intersect(poly)) {
    set_msg(msg, msglen, "the surface intersects itself");
    return FMBD_CGAL_BAD_SURFACE;
  }
  if (!PMP::is_outward_oriented(poly)) {
    PMP::reverse_face_orientations(poly);
  }

  // --- domain with protected sharp features, criteria, mesh ---
  Mesh_domain domain(poly);
  domain.detect_features(crit->feature_angle_deg);
  Mesh_criteria criteria(
      params::edge_size = crit->size, params::facet_angle = crit->facet_angle_deg,
      params::facet_size = crit->size, params::facet_distance = crit->facet_distance,
      params::cell_radius_edge_ratio = crit->radius_edge, params::cell_size = crit->size);
  C3t3 c3t3 = CGAL::make_mesh_3<C3t3>(domain, criteria, params::no_perturb(), params::exude());

  // --- gather the tetrahedra of the complex and their vertices ---
  const Tr &tr = c3t3.triangulation();
  std::unordered_map<Tr::Vertex_handle, int64_t> index;
  std::vector<double> xyz_out;
  std::vector<int64_t> tet_out;
  for (auto c = c3t3.cells_in_complex_begin(); c != c3t3.cells_in_complex_end(); ++c) {
    Tr::Cell_handle ch = c;
    for (int a = 0; a < 4; a++) {
      Tr::Vertex_handle vh = ch->vertex(a);
      auto it = index.find(vh);
      int64_t id;
      if (it == index.end()) {
        id = (int64_t)index.size();
        index.emplace(vh, id);
        const auto &p = tr.point(ch, a);
        xyz_out.push_back(CGAL::to_double(p.x()));
        xyz_out.push_back(CGAL::to_double(p.y()));
        xyz_out.push_back(CGAL::to_double(p.z()));
      } else {
        id = it->second;
      }
      tet_out.push_back(id);
    }
  }
  if (tet_out.empty()) {
    set_msg(msg, msglen, "CGAL produced no tetrahedra (size too large for the part?)");
    return FMBD_CGAL_FAILED;
  }
  double *nd = (double *)fmbd_malloc(xyz_out.size() * sizeof(double));
  int64_t *tt = (int64_t *)fmbd_malloc(tet_out.size() * sizeof(int64_t));
  if (!nd || !tt) {
    fmbd_free(nd);
    fmbd_free(tt);
    set_msg(msg, msglen, "out of memory");
    return FMBD_CGAL_NOMEM;
  }
  std::memcpy(nd, xyz_out.data(), xyz_out.size() * sizeof(double));
  std::memcpy(tt, tet_out.data(), tet_out.size() * sizeof(int64_t));
  *nnodes = (int64_t)(xyz_out.size() / 3);
  *nodes = nd;
  *ntet = (int64_t)(tet_out.size() / 4);
  *tet = tt;
  return FMBD_CGAL_OK;
}

}  // namespace

extern "C" int fmbd_cgal_mesh_surface(int64_t nv, const double *xyz, int64_t nf, const int64_t *tri,
                                      const fmbd_cgal_criteria *crit, int64_t *nnodes,
                                      double **nodes, int64_t *ntet, int64_t **tet, char *msg,
                                      int msglen) {
  set_msg(msg, msglen, "");
  *nnodes = 0;
  *nodes = nullptr;
  *ntet = 0;
  *tet = nullptr;
  try {
    return mesh_surface(nv, xyz, nf, tri, crit, nnodes, nodes, ntet, tet, msg, msglen);
  } catch (const std::bad_alloc &) {
    set_msg(msg, msglen, "out of memory in CGAL");
    return FMBD_CGAL_NOMEM;
  } catch (const std::exception &e) {
    char buf[600];
    std::snprintf(buf, sizeof buf, "CGAL failed: %s", e.what());
    set_msg(msg, msglen, buf);
    return FMBD_CGAL_FAILED;
  } catch (...) {
    set_msg(msg, msglen, "CGAL failed with an unknown exception");
    return FMBD_CGAL_FAILED;
  }
}
