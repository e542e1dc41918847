// common/fmbd_fe.h: finite elements of a flexible body: mesh input, element matrices, assembly,
// interface ties (RBE2, RBE3), clamps, rigid-body properties, nodal stress, fmbd-fe file I/O
// SPDX-License-Identifier: MIT
//
// The pipeline:  fmbd_mesh (mesh2fe fills it from gmsh/CGAL)
//                  --fmbd_fe_assemble(options)--> fmbd_fe_body (K, M, dofs, expand, ...)
//                  --fmbd_fe_write--> BODY.fe.h5  --fmbd_fe_read--> fmbd_fe_body
//
// Units are SI throughout. Elements:
// - tet4: linear tetrahedron (constant strain);
// - tet10: quadratic isoparametric tetrahedron, gmsh node order: corners 0..3, then the mid-side
//   nodes 4..9 on the edges (0,1) (1,2) (2,0) (3,0) (3,2) (3,1) (gmsh reference element,
//   "MTetrahedron10"); mid-side nodes may lie off the straight edge (curved elements);
// - beam2: 2-node spatial Euler-Bernoulli beam, 6 dofs per node, cross-section A, Iy, Iz, J,
//   orientation vector in the local x-z plane.
// Isotropic linear elasticity (E, nu), density rho.
//
// Dof numbering (docs/DESIGN.md): node-major; a node on solid elements only carries 3 translations,
// a node on a beam and every interface node carry 3 translations and 3 rotations
// (direction 0..2 = ux uy uz, 3..5 = rx ry rz). Dofs removed by clamps and by ties are not active.
#ifndef FMBD_FE_H
#define FMBD_FE_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_csr.h"
#include "fmbd_h5.h"
#include "fmbd_mesh.h"  // the mesh input: struct fmbd_mesh

// --- options -------------------------------------------------------------------------------
typedef enum fmbd_fe_mass_kind {
  FMBD_FE_MASS_CONSISTENT = 0,  ///< consistent mass matrix
  FMBD_FE_MASS_LUMPED = 1       ///< HRZ lumped (Hinton, Rock, Zienkiewicz 1976): diagonal for
                                ///< solids; beams: diagonal translations, 3x3 rotational block
} fmbd_fe_mass_kind;

typedef enum fmbd_fe_tie_kind {
  FMBD_FE_RBE2 = 0,  ///< rigid spider: tied dofs eliminated exactly
  FMBD_FE_RBE3 = 1   ///< weighted-average (distributing) connection, see fmbd_fe_assemble
} fmbd_fe_tie_kind;

/// One interface request: a physical group tied to a new 6-dof node.
typedef struct fmbd_fe_interface_spec {
  const char *group;      ///< physical group name (borrowed); also the interface's name
  fmbd_fe_tie_kind kind;  ///< RBE2 or RBE3
  bool has_point;         ///< false: the node goes to the centroid of the group's nodes
  double point[3];        ///< the interface node's position if has_point
} fmbd_fe_interface_spec;

/// Material, mass and model options. Fill with fmbd_fe_opts_defaults, then change fields.
typedef struct fmbd_fe_opts {
  double E;                ///< Young's modulus [Pa], > 0. Default 210e9 (steel)
  double nu;               ///< Poisson's ratio, in (-1, 0.5). Default 0.3
  double rho;              ///< density [kg/m^3], > 0. Default 7850
  fmbd_fe_mass_kind mass;  ///< default FMBD_FE_MASS_CONSISTENT
  // beam section, required (all > 0) when the mesh has beam elements; default 0 = not given
  double area;  ///< A [m^2]
  double Iy;    ///< second moment about the local y axis [m^4] (bending in the local x-z plane)
  double Iz;    ///< second moment about the local z axis [m^4] (bending in the local x-y plane)
  double J;     ///< torsion constant [m^4]; the torsional mass uses rho*J
  /// Beam orientation vector (any vector in the local x-z plane, not parallel to the beam).
  /// Default (0,0,0) = automatic: global Z, or global X for elements within 0.1 rad of Z.
  double orientation[3];
  /// Optional per-element orientation vectors (nbeam, 3), overriding `orientation`
  /// (borrowed; NULL by default).
  const double *beam_orientation;
  int ninterfaces;                           ///< default 0
  const fmbd_fe_interface_spec *interfaces;  ///< (ninterfaces,) borrowed
  int nclamps;                               ///< default 0
  /// Clamped group names (borrowed). A clamp name that is also an interface clamps the interface
  /// node (its 6 dofs); otherwise every dof of every node of the mesh group is removed.
  const char *const *clamps;
} fmbd_fe_opts;

/// @brief Fill the defaults documented in fmbd_fe_opts.
void fmbd_fe_opts_defaults(fmbd_fe_opts *o);

// --- the body: everything an fmbd-fe file holds --------------------------------------------
typedef struct fmbd_fe_interface {
  char *name;  ///< group name (owned)
  fmbd_fe_tie_kind kind;
  int64_t node;     ///< the interface node (index into the body's nodes, >= nmesh_nodes)
  double point[3];  ///< its position
  int64_t nnodes;   ///< tied nodes
  int64_t *nodes;   ///< (nnodes,) owned
} fmbd_fe_interface;

typedef struct fmbd_fe_clamp {
  char *name;  ///< group (or interface) name (owned)
  int64_t nnodes;
  int64_t *nodes;  ///< (nnodes,) owned: nodes whose dofs were removed
} fmbd_fe_clamp;

typedef struct fmbd_fe_body {
  // /mesh: nodes are the mesh nodes first, then one node per interface
  int64_t nnodes;       ///< all nodes
  int64_t nmesh_nodes;  ///< mesh nodes (nodes nmesh_nodes.. are interface nodes)
  double *xyz;          ///< (nnodes, 3)
  int64_t ntet;
  int tet_nodes;
  int64_t *tet;  ///< (ntet, tet_nodes), tet_nodes 4 or 10 (0 if none)
  int64_t nbeam;
  int64_t *beam;             ///< (nbeam, 2)
  double *beam_orientation;  ///< (nbeam, 3) the orientation used, or NULL
  int ngroups;
  char **group_name;
  int64_t *group_ptr;
  int64_t *group_node;  ///< as fmbd_mesh
  double *node_mass;    ///< (nnodes,) HRZ lumped translational mass (0 on interface nodes)
  // /material
  double E, nu, rho;
  fmbd_fe_mass_kind mass_kind;
  bool has_section;  ///< beam section attributes present
  double area, Iy, Iz, J;
  // /dofs
  int64_t ndof;
  int64_t *dofs;      ///< (ndof, 2): node, direction (0..5), node-major
  int64_t *node_dof;  ///< (nnodes+1,) first row of /dofs of each node (derived on read)
  // matrices (NULL when absent: downstream files hold the description only)
  /// ndof x ndof, full symmetric storage. From fmbd_fe_assemble with a consistent mass, M
  /// shares K's indptr and indices arrays (one pattern in memory; fmbd_fe_body_destroy frees it
  /// once): treat the patterns as read-only.
  fmbd_csr *K, *M;
  fmbd_csr *expand;  ///< 6*nnodes x ndof: u_all = expand * q
  // /interfaces, /clamped
  int ninterfaces;
  fmbd_fe_interface *interfaces;
  int nclamped;
  fmbd_fe_clamp *clamped;
  // /body: rigid-body properties (from the consistent mass; see fmbd_fe_assemble)
  double mass;               ///< [kg]
  double center_of_mass[3];  ///< [m]
  double inertia[9];         ///< 3x3 row-major about the centre of mass [kg m^2]
  double volume;             ///< solid volume [m^3] (beams: A*L added)
} fmbd_fe_body;

/// @brief Assemble a body from a mesh.
///
/// Checks the inputs (E > 0, rho > 0, -1 < nu < 0.5, beam section given when beams exist,
/// node indices in range, every node on some element, groups found, each element's Jacobian
/// determinant > 0 at every quadrature point: FMBD_ERR_VALUE naming the element or group).
/// Element matrices: tet4 exact; tet10 stiffness with the 4-point degree-2 rule (exact on
/// straight-sided elements), mass with a 14-point degree-5 rule (exact for the degree-4
/// integrand N_a N_b on straight elements); a tet10 whose mid-side nodes are at the edge
/// midpoints (to 1e-10 of its size) is treated as affine (one Jacobian); beams in closed form
/// (Przemieniecki).
/// The ties and clamps are a sparse T (full dofs -> active dofs, u_full = T q), applied element
/// by element while assembling straight into the CSR of the active dofs: K' = T' K T and
/// M' = T' M T exactly, without forming K. RBE2 eliminates the tied nodes'
/// dofs exactly, u_s = u_m + theta_m x (x_s - x_m) (theta_s = theta_m for 6-dof nodes);
/// RBE3 keeps the interface node's 6 dofs and eliminates 6 translations of the group instead
/// (the MSC Nastran RBE3 "UM" form): see fmbd_fe_tie.c for the equations. A node tied to two
/// interfaces, or an RBE2-tied node that is also clamped, is refused (clamp the interface
/// instead); clamped nodes of an RBE3 group simply contribute zero translations.
/// /body: mass, centre of mass and inertia are r' M r for the rigid-body modes r of the
/// consistent element mass (exact for the element polynomials; beams: translational mass
/// rho*A*L and torsional rho*J, Euler-Bernoulli has no section rotary inertia).
/// @param[in] mesh borrowed
/// @param[in] opt borrowed; NULL = defaults
/// @param[out] out caller destroys with fmbd_fe_body_destroy
/// @return FMBD_OK, FMBD_ERR_VALUE (bad input, message names the element/group/node),
/// FMBD_ERR_NOMEM
int fmbd_fe_assemble(const fmbd_mesh *mesh, const fmbd_fe_opts *opt, fmbd_fe_body **out);

/// @brief Release a body and set *b = NULL. NULL and *b == NULL are fine.
void fmbd_fe_body_destroy(fmbd_fe_body **b);

/// @brief Write every object of the fmbd-fe format (/mesh /material /dofs /K /M /expand
/// /interfaces /clamped /body) into an open file (fmbd_h5_create'd by the caller, which
/// commits). K and M are written only if present.
int fmbd_fe_write(fmbd_h5 *f, const fmbd_fe_body *b);

/// @brief Read a body from an fmbd-fe file, or the description part of a downstream file
/// (fmbd-cb, fmbd-rflex): /K and /M are read when present, else left NULL. The caller checks
/// the root `format` (fmbd_h5_check_format). Validates shapes, index ranges and the dof list.
/// @param[out] out caller destroys with fmbd_fe_body_destroy
int fmbd_fe_read(fmbd_h5 *f, fmbd_fe_body **out);
/// @brief fmbd_fe_read without /K and /M (left NULL): the description, for a distributed
/// program whose processes read their row blocks of K and M (fmbd_h5_read_csr_rows).
int fmbd_fe_read_description(fmbd_h5 *f, fmbd_fe_body **out);
/// @brief fmbd_fe_read of /K and /M only (both required; ndof from /K's shape; everything else
/// left empty): for a caller that knows the file is one read whole before (cbcheck checks its
/// SHA-256 against the one fe2cb recorded), and needs only the matrices.
int fmbd_fe_read_matrices(fmbd_h5 *f, fmbd_fe_body **out);

/// @brief Copy /mesh /dofs /material /interfaces /clamped /body /expand (everything but /K
/// and /M) from src to dst.
int fmbd_fe_copy_description(fmbd_h5 *src, fmbd_h5 *dst);

/// @brief Nodal stresses of displacement fields: sigma = D B u at each node of each solid
/// element, averaged over the solid elements sharing the node. Nodes on no solid element
/// (beam-only and interface nodes) get zero (beam stresses are not computed).
/// @param[in] q (ndof x ncases) column-major active-dof vectors
/// @param[out] sigma (caller allocates nnodes*6*ncases): sigma[(c*nnodes + p)*6 + i],
/// i = xx yy zz xy yz zx (engineering shear stresses tau)
int fmbd_fe_nodal_stress(const fmbd_fe_body *b, int64_t ncases, const double *q, double *sigma);
/// @brief fmbd_fe_nodal_stress at some nodes only: the same computation restricted to the
/// solid elements around them (in the same order), so each selected node's stress is bitwise
/// the whole field's row. sel NULL: every node (fmbd_fe_nodal_stress).
/// @param[in] sel (nsel) distinct node indices
/// @param[out] sigma (caller allocates nsel*6*ncases): sigma[(c*nsel + i)*6 + j] at node sel[i]
/// @return FMBD_OK, FMBD_ERR_VALUE (a node out of range or selected twice), FMBD_ERR_NOMEM
int fmbd_fe_nodal_stress_at(const fmbd_fe_body *b, int64_t ncases, const double *q, int64_t nsel,
                            const int64_t *sel, double *sigma);

/// @brief Active dof of (node, direction), or -1 if that component is not active.
int64_t fmbd_fe_dof(const fmbd_fe_body *b, int64_t node, int direction);

/// @brief Find an interface by name: its index, or -1.
int fmbd_fe_find_interface(const fmbd_fe_body *b, const char *name);

// --- element level (exposed for tests and for tools) ----------------------------------------
/// @brief A tetrahedron quadrature rule on the unit tetrahedron (0,0,0) (1,0,0) (0,1,0)
/// (0,0,1): points as barycentric-free coordinates (xi, eta, zeta) and weights summing to 1/6.
/// degree: 1 (1 point), 2 (4 points), 5 (14 points). Others: FMBD_ERR_VALUE.
/// @param[out] pts borrowed static (npts, 3); @param[out] w borrowed static (npts,)
int fmbd_fe_tet_rule(int degree, int *npts, const double **pts, const double **w);

/// @brief Shape functions and their reference derivatives of tet4/tet10 at (xi, eta, zeta).
/// @param[out] N (nn,) ; @param[out] dN (nn, 3) row-major d/dxi d/deta d/dzeta
void fmbd_fe_tet_shape(int nn, const double xi[3], double *N, double *dN);

/// @brief Element matrices of a tet4 or tet10.
/// @param[in] xyz (nn, 3) node coordinates
/// @param[out] Ke (3nn x 3nn) row-major, dofs node-major (ux uy uz of node 0, ...); may be NULL
/// @param[out] Me (nn x nn) row-major scalar consistent mass (the 3D mass is Me (x) I3); may be
/// NULL
/// @param[out] volume element volume
/// @return FMBD_ERR_VALUE "element <elem>: Jacobian determinant <d> at quadrature point ..." if
/// det J <= 0 (inverted or degenerate) at a quadrature or node point
int fmbd_fe_tet_matrices(int nn, const double *xyz, double E, double nu, double rho, int64_t elem,
                         double *Ke, double *Me, double *volume);

/// @brief Local-to-global rotation of a beam: rows are the local x, y, z axes in global
/// coordinates. x = (x1 - x0)/L; z = component of v orthogonal to x, normalised; y = z cross x.
/// @return FMBD_ERR_VALUE if L == 0 or v is parallel to the axis
int fmbd_fe_beam_frame(const double x0[3], const double x1[3], const double v[3], int64_t elem,
                       double R[9], double *L);

/// @brief Global 12x12 element matrices (row-major, dofs: node 0 ux uy uz rx ry rz, node 1 ...)
/// of the Euler-Bernoulli beam; Me consistent (translational rho*A, torsional rho*J).
/// @param[in] v orientation vector (see fmbd_fe_opts.orientation)
int fmbd_fe_beam_matrices(const double x0[3], const double x1[3], const double v[3], double E,
                          double nu, double rho, double A, double Iy, double Iz, double J,
                          int64_t elem, double *Ke, double *Me);

/// @brief HRZ lumped mass of a beam element (global 12x12 row-major, block diagonal per node):
/// local translations rho*A*L/2, torsion rho*J*L/2, bending rotations rho*A*L^3/78 (the
/// consistent diagonal scaled by HRZ's factor of the paired transverse translation).
int fmbd_fe_beam_lumped(const double x0[3], const double x1[3], const double v[3], double rho,
                        double A, double J, int64_t elem, double *Me);

/// @brief HRZ lumping of an element mass matrix (Hinton, Rock, Zienkiewicz 1976): keep the
/// diagonal, scaled so that the diagonal of the translational dofs of each direction sums to
/// the element mass `m`. For the scalar tet mass: lumped[a] = m * Me[a][a] / sum_b Me[b][b].
/// @param[in] Me (n x n) row-major scalar mass; @param[out] d (n,)
void fmbd_fe_hrz_scalar(int n, const double *Me, double m, double *d);

/// @brief The 3 x 6 map from a rigid motion (translation t, small rotation w) of a frame to
/// the displacement of a point at offset r from its origin: u = t + w x r = [I, -[r]x] (t; w).
/// @param[out] A row-major 3 x 6 (A[6 i + j])
void fmbd_fe_rigid_rows(const double r[3], double A[18]);

#endif
