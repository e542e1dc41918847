// common/fmbd_mesh.h: geometry and mesh input (gmsh C API; CGAL Mesh_3 for closed surfaces)
// SPDX-License-Identifier: MIT
//
// Fills the fmbd_mesh struct below (nodes, tet4/tet10 or beam2 elements, named node
// groups) from:
//   .geo .step .stp .brep   geometry, meshed by gmsh: 3-D (tetrahedra) when the model has
//                           volumes, 1-D (2-node line elements = beams) when it has only curves
//   .msh                    a gmsh mesh, taken as stored (tetrahedra, else line elements)
//   .stl .off               a closed triangulated surface, filled with tetrahedra by CGAL
//                           Mesh_3 through a meshing callback (mesh2fe/cgal_shim.cpp), so
//                           that only mesh2fe links CGAL
// Physical groups of any dimension become node groups named by their physical name (or
// "p<dim>_<tag>" when unnamed). Every mesh is validated (fmbd_mesh_check): no inverted or
// degenerate element, no node outside every element.
#ifndef FMBD_MESH_H
#define FMBD_MESH_H

#include <stdint.h>

// --- the mesh input ------------------------------------------------------------------------
/// The mesh as read from gmsh or CGAL: the contract between the mesh readers here and the FE
/// assembly (fmbd_fe_assemble, fmbd_fe.h).
typedef struct fmbd_mesh {
  int64_t nnodes;
  double *xyz;  // (nnodes, 3) row-major
  int64_t ntet;
  int tet_nodes;
  int64_t *tet;  // tet_nodes 4 or 10 (gmsh order); (ntet, tet_nodes)
  int64_t nbeam;
  int64_t *beam;  // (nbeam, 2)
  int ngroups;
  char **group_name;  // physical group names
  int64_t *group_ptr;
  int64_t *group_node;  // group g: group_node[group_ptr[g]..group_ptr[g+1]]
} fmbd_mesh;            // all arrays owned; fmbd_mesh_destroy(&m)

/// @brief Release every array of the mesh (fmbd_free) and zero the struct. NULL is fine.
/// The struct itself is not freed (it usually lives on the stack).
void fmbd_mesh_destroy(fmbd_mesh *m);

/// @brief Index of the group called `name`, or -1.
int fmbd_mesh_find_group(const fmbd_mesh *m, const char *name);

/// A tetrahedral mesher for closed triangle surfaces (the CGAL shim). Gets the surface
/// (nv vertices (nv, 3), nf triangles (nf, 3)) and the target size; returns FMBD_OK with
/// *nodes (nn, 3) and *tet (nt, 4) allocated with fmbd_malloc, or an FMBD_ERR_* code with the
/// error record set (fmbd_err_set).
typedef int (*fmbd_surface_mesher)(int64_t nv, const double *xyz, int64_t nf, const int64_t *tri,
                                   double size, int64_t *nn, double **nodes, int64_t *nt,
                                   int64_t **tet);

/// Options of fmbd_mesh_read. Fill with fmbd_mesh_opts_defaults, then change.
typedef struct fmbd_mesh_opts {
  int order;         ///< 1 (tet4) or 2 (tet10); 0 (default): 2 for geometry and surfaces, as
                     ///< stored for .msh. Beams are always 2-node (order ignored).
  double size;       ///< target element size in m; <= 0 (default): gmsh's own sizes from the
                     ///< geometry, and for .stl/.off the bounding-box diagonal / 25
  int gmsh_verbose;  ///< 0 (default): gmsh silent; 1: gmsh's Info lines on standard output (!)
  fmbd_surface_mesher surface_mesher;  ///< needed for .stl/.off (NULL default: FMBD_ERR_USAGE)
} fmbd_mesh_opts;

/// @brief Default options (order 0 = automatic, size 0 = from the geometry, gmsh silent).
void fmbd_mesh_opts_defaults(fmbd_mesh_opts *o);

/// @brief Read or mesh GEOMETRY into m, then validate it (fmbd_mesh_check).
/// @param[in] path  file name; its ending chooses the reader (case-insensitive)
/// @param[out] m    filled (owned arrays; release with fmbd_mesh_destroy(m)); left empty
///                  (zeroed) on failure
/// @return FMBD_OK; FMBD_ERR_IO (missing/unreadable), FMBD_ERR_USAGE (unknown ending),
///   FMBD_ERR_FORMAT (gmsh or the surface reader rejects the file, no volume or beam
///   elements, unsupported element types), FMBD_ERR_VALUE (bad elements, orphan nodes,
///   open surface), FMBD_ERR_EXTERNAL (gmsh/CGAL failure). The message names the file and
///   the element, node or group at fault.
int fmbd_mesh_read(const char *path, const fmbd_mesh_opts *opt, fmbd_mesh *m);

/// @brief Validate a mesh: every tetrahedron has a positive Jacobian determinant (tet4: the
/// constant one; tet10: at its corners, mid-edges, centroid and the 4-point Gauss points,
/// relative to the cube of its longest edge > 1e-10), every beam a positive length, every
/// node belongs to an element, and groups index existing nodes.
/// @return FMBD_OK or FMBD_ERR_VALUE naming the first bad element (0-based index) and its
/// Jacobian, or the node.
int fmbd_mesh_check(const fmbd_mesh *m);

/// @brief Add a node group: every node with lo[k] - tol <= x[k] <= hi[k] + tol, tol = 1e-9
/// times the mesh's bounding-box diagonal. FMBD_ERR_VALUE if the name exists already or the
/// box holds no node; FMBD_ERR_USAGE if lo > hi in a direction.
int fmbd_mesh_add_box_group(fmbd_mesh *m, const char *name, const double lo[3], const double hi[3]);

/// @brief Turn tet4 into tet10 with straight edges: one new node at the middle of each edge,
/// gmsh's local order (mid-edges of (0,1) (1,2) (0,2) (0,3) (2,3) (1,3)). Groups gain the
/// mid-edge nodes whose both edge ends are in the group. No-op for tet10 or beam meshes.
int fmbd_mesh_elevate(fmbd_mesh *m);

/// @brief Affine dimension of the nodes of group g: 0 (one point), 1 (collinear), 2 (coplanar)
/// or 3. A node counts as off the line (plane) through the others when its distance exceeds
/// 1e-8 times the group's extent. An RBE3 tie needs 2 or more (three non-collinear nodes) to
/// carry a moment about every axis.
int fmbd_mesh_group_affine_dim(const fmbd_mesh *m, int g);

/// Element shape of the tetrahedra (fmbd_mesh_quality): the worst aspect ratio
/// h_max / (2 sqrt 6 r_in) of the corners and the smallest scaled Jacobian (sqrt 2 x 6V over
/// the product of a corner's edge lengths, smallest over the corners), both 1 for the
/// regular tetrahedron; for tet10 also the smallest curvature ratio (det J at the check
/// points over its straight-sided value 6V; 1 straight). Elements 0-based (as in
/// /mesh/elements).
typedef struct fmbd_mesh_quality_stats {
  double worst_ar, min_sj;
  double worst_ar_sj, min_sj_ar;       // the other measure of those two elements
  int64_t worst_ar_elem, min_sj_elem;  // -1 without tetrahedra
  double min_cr;                       // tet10 (1 for tet4)
  int64_t min_cr_elem;
  int64_t n_ar_bad, n_sj_bad;  // beyond the warning thresholds below
} fmbd_mesh_quality_stats;
// warning thresholds (docs/STABILITY.md, "Element shape"): K's condition grows as AR^2
// (fe2cb's residual floor: 2.9e-7 at AR 6.3, 1.3e-4 at 85, 4.6e-4 at 169 on the same strip)
// and a sliver's stiffness across its thin direction as 1/thickness. gmsh's meshes of the
// examples stay below them (rod: AR 4.7, SJ 0.2; bracket: AR 20, SJ 0.057; SJ ~ 1/AR)
#define FMBD_MESH_AR_WARN 30.0
#define FMBD_MESH_SJ_WARN 0.02
/// @brief Shape measures of every tetrahedron (no-op fields for beam meshes).
void fmbd_mesh_quality(const fmbd_mesh *m, fmbd_mesh_quality_stats *q);

/// @brief Volume of the tetrahedra (exact for straight-sided tet4/tet10; tet10 uses the
/// 4-point rule on the quadratic geometry).
double fmbd_mesh_volume(const fmbd_mesh *m);

#endif
