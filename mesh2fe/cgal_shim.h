// mesh2fe/cgal_shim.h: C interface to CGAL Mesh_3 (tetrahedra inside a closed triangulated surface)
// SPDX-License-Identifier: MIT
//
// The only C++ of the project, in its own translation unit mesh2fe/cgal_shim.cpp (it takes
// ~45 s and ~3 GB to compile: it changes rarely). Plain arrays in, plain arrays out; every
// exception is caught in the shim and turned into a status and a message.
#ifndef FMBD_CGAL_SHIM_H
#define FMBD_CGAL_SHIM_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Status codes of the shim.
enum fmbd_cgal_status {
  FMBD_CGAL_OK = 0,
  FMBD_CGAL_BAD_SURFACE = 1,  ///< not a closed, manifold, non-self-intersecting triangle surface
  FMBD_CGAL_FAILED = 2,       ///< CGAL threw, or the mesh came out empty
  FMBD_CGAL_NOMEM = 3         ///< allocation failed
};

/// Meshing criteria (all lengths in the units of the coordinates).
typedef struct fmbd_cgal_criteria {
  double size;             ///< target edge length of facets, cells and sharp features (> 0)
  double facet_distance;   ///< max distance of facet centres to the input surface (> 0)
  double facet_angle_deg;  ///< min facet angle (25 is CGAL's usual; <= 30)
  double radius_edge;      ///< max cell radius-edge ratio (2 to 3)
  double
      feature_angle_deg;  ///< dihedral angle above which an input edge is kept as a sharp feature
} fmbd_cgal_criteria;

/// @brief Mesh the inside of a closed triangle surface with tetrahedra (CGAL Mesh_3 on a
/// Polyhedral_mesh_domain_with_features_3, sharp edges detected and protected).
/// @param[in] nv, xyz  surface vertices, (nv, 3) row-major
/// @param[in] nf, tri  triangles, (nf, 3) row-major 0-based vertex indices (any orientation,
///                     but consistent neighbours are required)
/// @param[in] crit     criteria
/// @param[out] nnodes, nodes  mesh vertices (nnodes, 3); caller frees *nodes with fmbd_free
/// @param[out] ntet, tet      tetrahedra (ntet, 4), positively oriented; caller frees with
/// fmbd_free
/// @param[out] msg     a message on failure (NUL-terminated, at most msglen bytes)
/// @return FMBD_CGAL_OK or another fmbd_cgal_status; on failure nothing is allocated.
int fmbd_cgal_mesh_surface(int64_t nv, const double *xyz, int64_t nf, const int64_t *tri,
                           const fmbd_cgal_criteria *crit, int64_t *nnodes, double **nodes,
                           int64_t *ntet, int64_t **tet, char *msg, int msglen);

#ifdef __cplusplus
}
#endif

#endif
