// common/fmbd_rflex.h: the reduced flexible body (fmbd-rflex): modes, interface modes, FFRF
// inertia invariants, modal stress; written by cbcheck, read by fmbd-run
// SPDX-License-Identifier: MIT
//
// A `fmbd_rflex` holds the NM flexible modes kept by the secondary reduction (docs/THEORY.md
// section 3, [H46-H50]): p = PhiT aF, qF = T0 PhiT aF, modal mass I, modal stiffness
// diag(chibar_1..chibar_NM); rigid-body modes are excluded. Plus what the floating-frame
// equations need (docs/THEORY.md section 4): the inertia invariants of docs/THEORY.md section 9,
// evaluated with the lumped nodal masses /mesh/node_mass (Adams-style invariants).
//
// MEMORY LAYOUT (all arrays owned by the struct, released by fmbd_rflex_destroy):
// dense matrices are column-major as everywhere in libfmbd; the multi-index arrays are stored
// with the FIRST index fastest (Fortran order), i.e. the file's row-major (h5py) array fully
// transposed. Use the inline accessors below rather than index arithmetic:
//   shapes        ndof x nm            shapes[i + ndof*k]
//   translation   3 x nm per interface T[a + 3*k]            (file: (3, Nm))
//   S1            3 x nm               S1[a + 3*k]             (file: (3, Nm))
//   XS            3 x 3 x nm           XS[a + 3*b + 9*k]       (file: (3, 3, Nm))
//   SS            3 x 3 x nm x nm      SS[a + 3*b + 9*k + 9*nm*l]  (file: (3, 3, Nm, Nm))
//   second_moment 3 x 3 (symmetric)    J[a + 3*b]
//   stress        6 x nnodes x nm      stress[i + 6*p + 6*nnodes*k] (i = xx yy zz xy yz zx;
//                                      file: (nnodes, 6, Nm)); NULL when the file has none
//   node_xyz      3 x nnodes           node_xyz[a + 3*p]        (file /mesh/nodes (nnodes, 3))
//   dofs          2 x ndof             dofs[0 + 2*i] = node, dofs[1 + 2*i] = direction
#ifndef FMBD_RFLEX_H
#define FMBD_RFLEX_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_csr.h"
#include "fmbd_fe.h"
#include "fmbd_h5.h"

/// One interface (joint) node of the body and its modal motion.
typedef struct fmbd_rflex_interface {
  char *name;           ///< group name under /interfaces (owned)
  char *kind;           ///< "rbe2" or "rbe3" (owned)
  int64_t node;         ///< the interface node (index into the nodes)
  double x0[3];         ///< its position in the body (FE) frame (/mesh/nodes row `node`)
  double *translation;  ///< 3 x nm modal translations T[a + 3*k] (owned)
  double *rotation;     ///< 3 x nm modal rotations (small-angle vector) R[a + 3*k] (owned)
} fmbd_rflex_interface;

/// The reduced flexible body.
typedef struct fmbd_rflex {
  int64_t nm;            ///< number of flexible modes kept (Nm >= 0)
  int64_t ndof;          ///< active FE dofs (rows of /dofs)
  int64_t nnodes;        ///< nodes (rows of /mesh/nodes)
  double *eigenvalue;    ///< nm: chibar_k (rad^2/s^2), ascending, rigid-body modes excluded
  double *frequency_hz;  ///< nm: sqrt(chibar_k) / (2 pi)
  double *shapes;        ///< ndof x nm, mass-normalised (shapes' M shapes = I)
  double *stress;    ///< 6 x nnodes x nm modal nodal stress (Pa per unit modal coordinate), or NULL
  double *node_xyz;  ///< 3 x nnodes reference positions
  double *node_mass;  ///< nnodes lumped (HRZ) translational masses (/mesh/node_mass)
  int64_t *dofs;      ///< 2 x ndof (node, direction 0..5)
  fmbd_csr *expand;   ///< (6 nnodes) x ndof: row 6p+d = component d of node p (/expand)
  int ninterfaces;
  fmbd_rflex_interface *interfaces;  ///< ninterfaces entries, sorted by name
  // --- FFRF inertia invariants (docs/THEORY.md section 9) ---
  double mass;              ///< m = int rho dV (from /body)
  double first_moment[3];   ///< c = int rho x0 dV = m * centre of mass
  double second_moment[9];  ///< J[a + 3b] = int rho x0_a x0_b dV (inertia = tr(J) I - J)
  double *S1;               ///< 3 x nm: int rho S_k,a dV
  double *XS;               ///< 3 x 3 x nm: int rho x0_a S_k,b dV
  double *SS;               ///< 3 x 3 x nm x nm: int rho S_k,a S_l,b dV
  double *Mff;              ///< nm x nm modal mass (identity up to round-off)
  double *Kff;              ///< nm x nm modal stiffness (diag eigenvalue)
  // --- a subset body (cbcheck --for-scene; docs/FORMAT.md /subset): NULL/0 for a whole body.
  // It holds every node's position (places resolve as on the whole body) but the modal motion
  // (shapes, /dofs, /expand rows) of the held nodes only, and the modal stress of fewer.
  unsigned char *held;  ///< nnodes flags: FMBD_RFLEX_HELD_MOTION, FMBD_RFLEX_HELD_STRESS
  int64_t *stress_row;  ///< nnodes: the node's row in stress, or -1 (NULL: row = node)
  int64_t nstress;      ///< rows of stress (nnodes for a whole body)
  int64_t whole_ndof;   ///< the whole body's active dofs (/subset whole_ndof)
  bool ss_omitted;      ///< SS not formed (zero): built for partial inertia coupling only
                        ///< (fmbd_rflex_input no_ss); fmbd_rflex_write refuses it
} fmbd_rflex;

enum { FMBD_RFLEX_HELD_MOTION = 1, FMBD_RFLEX_HELD_STRESS = 2 };

// --- accessors (no bounds checks) ---------------------------------------------------------
static inline double fmbd_rflex_S1(const fmbd_rflex *r, int a, int64_t k) {
  return r->S1[a + 3 * k];
}
static inline double fmbd_rflex_XS(const fmbd_rflex *r, int a, int b, int64_t k) {
  return r->XS[a + 3 * b + 9 * k];
}
static inline double fmbd_rflex_SS(const fmbd_rflex *r, int a, int b, int64_t k, int64_t l) {
  return r->SS[a + 3 * b + 9 * k + 9 * r->nm * l];
}
static inline double fmbd_rflex_J(const fmbd_rflex *r, int a, int b) {
  return r->second_moment[a + 3 * b];
}

/// @brief Read a .rflex.h5 (format fmbd-rflex, major <= FMBD_RFLEX_MAJOR) into a new struct.
/// /modes/stress is optional (stress = NULL without it). Errors name the file and the path.
/// @param[in]  f   an open file (fmbd_h5_open)
/// @param[out] out caller releases with fmbd_rflex_destroy
/// @return FMBD_OK, FMBD_ERR_FORMAT (wrong kind, missing or misshapen dataset),
///         FMBD_ERR_VERSION, FMBD_ERR_VALUE, FMBD_ERR_NOMEM
int fmbd_rflex_read(fmbd_h5 *f, fmbd_rflex **out);

/// @brief Write the rflex objects of r: /modes/{eigenvalue,frequency_hz,shapes[,stress]},
/// /interfaces/<name>/{translation,rotation}, /ffrf/*; for a subset body also /subset, /dofs
/// and /expand (its own), and the caller copies the description without /dofs, /expand and
/// /mesh/elements (fmbd_check_write_rflex does). The description groups (/mesh, /dofs,
/// /material, /interfaces attributes and tied nodes, /clamped, /body, /expand) are copied by
/// the caller beforehand (fmbd_fe_copy_description); the /interfaces/<name> groups must exist.
/// @param[in] f a file from fmbd_h5_create(..., FMBD_RFLEX_FORMAT, FMBD_RFLEX_VERSION, ...)
int fmbd_rflex_write(fmbd_h5 *f, const fmbd_rflex *r);

/// What the secondary reduction needs (all borrowed). Column-major matrices.
typedef struct fmbd_rflex_input {
  const fmbd_fe_body *body;      ///< description: nodes, node_mass, dofs, expand, interfaces,
                                 ///< /body, elements and material (for stress); K, M unused
  int64_t ns, nb;                ///< interior and boundary dofs (ns + nb <= body->ndof; the
                                 ///< other dofs are held: zero in every mode)
  const int64_t *interior_dofs;  ///< (ns) rows of /dofs
  const int64_t *boundary_dofs;  ///< (nb) rows of /dofs
  int64_t nd;                    ///< fixed-interface modes of the reduced body
  const double *Phi;             ///< ns x nd (leading dimension ldphi >= ns)
  int64_t ldphi;
  const double *Psi;     ///< ns x nb constraint modes
  int64_t nm;            ///< flexible modes kept
  const double *chibar;  ///< (nm) their eigenvalues (> 0)
  const double *Xi;      ///< (nd+nb) x nm reduced eigenvectors, M_-orthonormal
  int64_t ldxi;          ///< leading dimension of Xi (>= nd+nb)
  bool stress;           ///< compute /modes/stress (fmbd_fe_nodal_stress)
  bool no_ss;       ///< for a body with partial inertia coupling only (docs/THEORY.md section 4c,
                    ///< which takes SS as zero): SS not formed, left zero, and r->ss_omitted set
  double *release;  ///< NULL, or a buffer handed over (fmbd_malloc'd: the caller's Phi), freed
                    ///< by fmbd_rflex_build once the shapes are formed, before the invariants
                    ///< (its peak memory), and on every failure
} fmbd_rflex_input;

/// @brief The secondary reduction [H46-H50]: shapes qF = T0 PhiT (T0 = [Phi_d Psi; 0 I] in
/// the s/b partition), node and interface modal motion through /expand, the /ffrf invariants
/// with the mass the modes come from (fmbd_rflex_consistent_invariants; docs/THEORY.md
/// section 9) (mass, first and second moments from /body:
/// J = tr(Ic)/2 I - Ic + m c c'), Mff = I, Kff = diag(chibar), optional modal stress.
/// @param[out] out caller releases with fmbd_rflex_destroy
/// @return FMBD_OK, FMBD_ERR_VALUE (inconsistent sizes), FMBD_ERR_NOMEM, errors of
///         fmbd_fe_nodal_stress
int fmbd_rflex_build(const fmbd_rflex_input *in, fmbd_rflex **out);

/// Any basis of FE displacement fields of a body (all borrowed; column-major).
typedef struct fmbd_rflex_basis {
  const fmbd_fe_body *body;  ///< description: nodes, node_mass, dofs, expand, interfaces, /body
                             ///< (elements and material for stress)
  const fmbd_csr *M, *K;     ///< the body's FE mass and stiffness (ndof x ndof), or NULL
  int64_t nm;                ///< shapes in the basis
  const double *S;           ///< ndof x nm shapes on the body's dofs (rigid motion excluded)
  int64_t lds;               ///< leading dimension of S (>= ndof)
  const double *Mff, *Kff;   ///< nm x nm: S'MS and S'KS when M, K are NULL (the caller knows
                             ///< them, e.g. from the modal body the shapes are combinations of)
  bool stress;               ///< compute /modes/stress
  bool semidefinite;         ///< S'MS may be singular (a body's part of a GMs basis, whose
                             ///< coordinates other bodies share): /modes/eigenvalue gets the
                             ///< Rayleigh quotients Kff_kk / Mff_kk (0 where Mff_kk is 0)
} fmbd_rflex_basis;

/// @brief The body fmbd-run integrates for ANY basis S of displacement fields (a global-mode
/// GMc basis, ...): Mff = S'MS, Kff = S'KS (not necessarily diagonal), the nodal and
/// interface motion and the FFRF invariants through the same function fmbd_rflex_build uses;
/// /modes/eigenvalue gets the Ritz values of Kff x = w Mff x (the body's eigenvalues in the
/// basis, ascending), frequency_hz their sqrt / 2 pi.
/// @param[out] out caller releases with fmbd_rflex_destroy
/// @return FMBD_OK, FMBD_ERR_VALUE (sizes; dependent shapes: S'MS not positive definite),
///         FMBD_ERR_NOMEM, errors of fmbd_fe_nodal_stress
int fmbd_rflex_from_basis(const fmbd_rflex_basis *in, fmbd_rflex **out);

/// @brief True when fmbd_rflex_build evaluates the invariants S1, XS, SS with the body's
/// scalar consistent mass (a solid body, tet4/tet10, meshed with consistent mass: the mass the
/// modes come from), false otherwise. A consistent-mass body with beams then takes S1 and the
/// antisymmetric part of XS from its full consistent mass (T'MS, R'MS) and the symmetric part
/// of XS and SS from the lumped nodal masses; a lumped-mass body uses the lumped nodal masses
/// (docs/THEORY.md section 9).
bool fmbd_rflex_consistent_invariants(const fmbd_fe_body *b);
/// @brief The scalar nodal mass Mn of the invariants (nnodes x nnodes): the assembled scalar
/// consistent mass of the solid elements when fmbd_rflex_consistent_invariants(b), else the
/// lumped nodal masses on the diagonal. Shared by the reduced bodies and the full FE bodies.
/// @param[out] out caller destroys with fmbd_csr_destroy
int fmbd_rflex_nodal_mass(const fmbd_fe_body *b, fmbd_csr **out);
/// @brief True when the rigid-flexible coupling (S1 and the rotational coupling R'MS) comes
/// from the full consistent mass (a consistent-mass body with beam elements), not from Mn.
bool fmbd_rflex_beam_coupling(const fmbd_fe_body *b);
/// @brief The consistent mass applied to the six rigid-body fields, on the active dofs:
/// C[i + ndof j] = (expand' M F_j)_i, with M the unconstrained consistent mass of the mesh
/// (element by element: the scalar tet mass on the translations, the 12 x 12 beam mass) and
/// F_j the rigid fields of the nodes: T_a (j = a: unit translation along a, no rotation) and
/// R_a (j = 3 + a: rotation about axis a through the frame origin, e_a x x0 at the
/// translations, e_a at the rotations). For every field S = expand s of the active dofs,
/// T_a' M S = C(:, a)' s (S1) and R_a' M S = C(:, 3 + a)' s (M_wf at q = 0; docs/THEORY.md
/// sections 4b and 9). Only for fmbd_rflex_beam_coupling(b) bodies.
/// @param[out] C ndof x 6, column-major
/// @return FMBD_OK, FMBD_ERR_VALUE (not such a body), FMBD_ERR_NOMEM, element errors
int fmbd_rflex_rigid_coupling(const fmbd_fe_body *b, double *C);

/// @brief Release r and its arrays; NULL and *r == NULL are fine; sets *r = NULL.
void fmbd_rflex_destroy(fmbd_rflex **r);

/// @brief Index of the interface called name, or -1.
int fmbd_rflex_find_interface(const fmbd_rflex *r, const char *name);

/// @brief Index of the node nearest to point x (3) and its distance (dist may be NULL).
int64_t fmbd_rflex_nearest_node(const fmbd_rflex *r, const double x[3], double *dist);

/// @brief A node's reference position and modal motion: rows 6p..6p+5 of /expand times
/// the shapes (for a joint attachment or an output point that is not an interface).
/// @param[in]  node index into the nodes
/// @param[out] x0   3 reference position (may be NULL)
/// @param[out] T    3 x nm modal translations T[a + 3k] (may be NULL)
/// @param[out] R    3 x nm modal rotations (may be NULL; zero for a solid node, which has
///                  no rotational dofs)
/// @return FMBD_OK, FMBD_ERR_VALUE (node out of range, or a node a subset body does not hold:
///         the message says so)
int fmbd_rflex_node_modes(const fmbd_rflex *r, int64_t node, double *x0, double *T, double *R);

/// @brief A node's modal stress: sigma[i + 6k] (i = xx yy zz xy yz zx) per unit modal
/// coordinate. FMBD_ERR_VALUE if the body has no stress, node is out of range, or a subset
/// body does not hold the node's stress.
int fmbd_rflex_node_stress(const fmbd_rflex *r, int64_t node, double *sigma);

/// @brief Form r's modal stress (/modes/stress) from its shapes and the body description b
/// (the one r was built from: same nodes and dofs; not a subset body) with fmbd_fe_nodal_stress:
/// at every node (nodes NULL), or only at the nodes `nodes` (nsel of them, repeats allowed;
/// fmbd_fe_nodal_stress_at, bitwise the whole field's rows): then r->stress_row maps a node to
/// its row (-1 elsewhere: fmbd_rflex_node_stress refuses it) and r->nstress counts the rows, in
/// node order. Any stress r held is replaced; without solid elements (or modes) r->stress is
/// NULL.
/// @return FMBD_OK, FMBD_ERR_VALUE (a node out of range, a body that is not b's), FMBD_ERR_NOMEM
int fmbd_rflex_form_stress(fmbd_rflex *r, const fmbd_fe_body *b, int64_t nsel,
                           const int64_t *nodes);

/// @brief Make r a subset body (docs/FORMAT.md /subset): keep the modal motion of the nodes
/// `motion` (and of every interface node) and the modal stress of the nodes `stress` (which
/// also keep their motion); the /dofs, shapes and /expand columns that no kept node reads are
/// dropped. Node positions, interfaces, invariants are unchanged. Applying it to a subset body
/// keeps the intersection with what it holds.
/// @return FMBD_OK, FMBD_ERR_VALUE (a node out of range, or stress asked where r has none),
///         FMBD_ERR_NOMEM
int fmbd_rflex_subset(fmbd_rflex *r, int64_t nmotion, const int64_t *motion, int64_t nstress,
                      const int64_t *stress);

/// @brief von Mises stress of a stress vector s (xx yy zz xy yz zx).
double fmbd_von_mises(const double s[6]);

#endif
