// common/fmbd_cb.h: Craig-Bampton (and normal-mode) reduction of one FE body, the fmbd-cb file
// SPDX-License-Identifier: MIT
//
// docs/THEORY.md section 1 ([H10-H22]). The body's active dofs are split into interior s and
// boundary b (every active dof of the interface nodes, plus the nodes of extra groups):
//   fixed-interface modes   Ks phi = kappa Ms phi, Phi' Ms Phi = I, ascending  (fmbd_eig)
//   constraint modes        Psi = -Ks^-1 Kc  (one multi-rhs solve with the factor of Ks)
//   A = Ms Psi + Mc,  Ks^-1 A,  Ks^-1 Ms Ks^-1 A,  Phi' A   (what cbcheck needs, section 2)
//   reduced matrices in closed form (T0 is never formed):
//     K_ = [Lambda 0; 0 Kb + Kc' Psi],  M_ = [I Phi'A; A'Phi Mb_],
//     Mb_ = Psi' A + Mc' Psi + Mb  (= Psi' Ms Psi + Psi' Mc + Mc' Psi + Mb)
//   reduced eigenproblem K_ Xi = chibar M_ Xi (LAPACK dsygvd), Xi' M_ Xi = I, ascending;
//   rigid-body modes: chibar <= rigid_rtol * kappa_1 (flagged in `rigid`).
// One CHOLMOD factor of Ks (sigma = 0; Ks is positive definite when the interior is held)
// serves the Lanczos iterations and every solve. Reduced coordinates are ordered
// [nd modal; nb boundary dofs in `boundary` order].
//
// Method "nm" (normal modes, for comparison): free-free modes of the whole body with the
// rigid-body modes removed (ns = ndof, nb = 0), or (hold) the modes with the boundary dofs
// held (nb = 0 and the held dofs listed in `held`); the reduced matrices are I and
// diag(kappa).
#ifndef FMBD_CB_H
#define FMBD_CB_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_chol.h"
#include "fmbd_csr.h"
#include "fmbd_eig.h"
#include "fmbd_fe.h"
#include "fmbd_h5.h"

/// Options of fmbd_cb_reduce; fill with fmbd_cb_opts_defaults.
typedef struct fmbd_cb_opts {
  bool nm;            ///< method "nm" instead of "cb". Default false
  bool hold;          ///< nm: hold the boundary dofs (else free-free). Default false
  int64_t nmodes;     ///< fixed-interface (or normal) modes wanted. Default 20
  double fmax_hz;     ///< > 0: every mode up to this frequency instead of a count. Default 0
  double rigid_rtol;  ///< reduced chibar <= rigid_rtol * kappa_1 is rigid. Default 1e-6
  double sym_rtol;    ///< K, M symmetric to |Aij - Aji| <= sym_rtol max|A|. Default 1e-10
  double fixed_tol;   ///< eig.tol of the runs with the boundary held (fixed-interface, nm
                      ///< hold); free-free runs take eig.tol. Default 1e-11
  fmbd_eig_opts eig;  ///< eigensolver options (nev / lambda_max / free_body are set here)
} fmbd_cb_opts;

/// @brief Fill the defaults documented in fmbd_cb_opts (and fmbd_eig_opts_defaults for eig).
void fmbd_cb_opts_defaults(fmbd_cb_opts *o);

/// Where the time went (wall seconds), for the -v breakdown.
typedef struct fmbd_cb_timing {
  double partition, ordering, factor, lanczos, sturm, residuals, constraint, projection,
      reduced_eig;
  int64_t solves;  ///< sparse solves (Lanczos + constraint + projections)
  int eig_passes;  ///< Lanczos runs
  const char *ordering_name;
  double nnz_l;  ///< entries of the Cholesky factor of Ks
} fmbd_cb_timing;

/// A reduced body: everything the fmbd-cb file holds beyond the copied description.
/// Dense matrices are column-major; all arrays owned (fmbd_cb_destroy).
typedef struct fmbd_cb {
  char method[8];           ///< "cb" or "nm"
  int64_t ndof;             ///< active FE dofs of the body
  int64_t ns, nb, nd;       ///< interior dofs, boundary dofs (constraint modes), modes
  int64_t nr;               ///< reduced order nd + nb
  int64_t *interior;        ///< (ns) rows of /dofs, ascending
  int64_t *boundary;        ///< (nb) rows of /dofs, ascending
  int64_t nheld;            ///< nm with hold: held dofs (not reduced coordinates)
  int64_t *held;            ///< (nheld) rows of /dofs, or NULL
  double *kappa;            ///< (nd) fixed-interface eigenvalues, ascending [rad^2/s^2]
  double kappa_next;        ///< the next one above kappa[nd-1] (NAN if unknown)
  double *Phi;              ///< ns x nd, Phi' Ms Phi = I
  double *Psi;              ///< ns x nb
  double *A;                ///< ns x nb, Ms Psi + Mc
  double *KsinvA;           ///< ns x nb
  double *KsinvMsKsinvA;    ///< ns x nb
  double *PhitA;            ///< nd x nb
  double *Mr, *Kr;          ///< nr x nr reduced matrices
  double *chibar;           ///< (nr) reduced eigenvalues, ascending
  double *Xi;               ///< nr x nr reduced eigenvectors, Xi' Mr Xi = I
  int64_t *rigid;           ///< (nr) 1 = rigid-body mode
  int64_t n_rigid;          ///< rigid-body modes of the reduced problem
  int64_t n_rigid_removed;  ///< nm free-free: rigid-body modes found and left out
  double sturm_shift;       ///< Sturm check of the modes (NAN if none / dense)
  int64_t sturm_count;      ///< eigenvalues below sturm_shift (-1 if none)
  double max_residual;      ///< largest relative residual of the modes
  double rigid_scale;       ///< max Kb_ii / Mb_ii before condensation (0 unknown): rigid-mode
                            ///< scale when nd = 0 (not stored in the file)
  char *fe_file;            ///< name of the fe file (owned, may be NULL)
  char fe_sha256[65];       ///< its SHA-256 ("" if unknown)
  fmbd_cb_timing time;      ///< cost of the reduction (not stored in the file)
} fmbd_cb;

/// @brief Release a reduced body and set *cb = NULL. NULL is fine.
void fmbd_cb_destroy(fmbd_cb **cb);

/// @brief Boundary dofs of a body: every active dof of every interface node, plus every
/// active dof of the nodes of the named mesh groups (or interfaces). Sorted, unique.
/// @param[in] groups  (ngroups) names, borrowed; an unknown name is FMBD_ERR_VALUE
/// @param[out] boundary caller frees with fmbd_free; *nb its length
int fmbd_cb_boundary(const fmbd_fe_body *b, int ngroups, const char *const *groups, int64_t *nb,
                     int64_t **boundary);

/// @brief Check K and M of a body: present, ndof x ndof, symmetric (sym_rtol), positive
/// diagonal of K where M has mass. FMBD_ERR_VALUE/FORMAT naming the matrix and the dof
/// (node, direction); the caller sets the file context.
int fmbd_cb_check_body(const fmbd_fe_body *b, double sym_rtol);

/// @brief Reduce: the partition, factor, modes, constraint modes, projections, reduced
/// eigensolution (see the file comment).
/// @param[in] K, M    borrowed, ndof x ndof, full symmetric CSR
/// @param[in] dofs    borrowed (ndof, 2) node, direction: for messages (may be NULL)
/// @param[in] nb, boundary borrowed: boundary rows of K (sorted, unique)
/// @param[in] o       borrowed, NULL = defaults
/// @param[out] out    caller destroys with fmbd_cb_destroy
/// @return FMBD_OK; FMBD_ERR_SINGULAR (Ks not positive definite: a floating interior region;
/// the message names the dof); FMBD_ERR_VALUE (more modes than interior dofs, fmax below the
/// first mode); FMBD_ERR_CONVERGE (eigensolver, with the number of converged modes)
int fmbd_cb_reduce(const fmbd_csr *K, const fmbd_csr *M, const int64_t *dofs, int64_t nb,
                   const int64_t *boundary, const fmbd_cb_opts *o, fmbd_cb **out);

/// @brief fmbd_cb_reduce that takes the FE matrices (FMBD_TAKE): *K and *M are destroyed (set
/// NULL) as soon as the interior/boundary blocks are extracted, which lowers the peak memory
/// by their size (method cb and nm --hold; nm free-free keeps them, the caller frees them). The
/// caller destroys whatever is left in *K, *M (NULL after the extraction, always on success
/// of cb / nm --hold).
int fmbd_cb_reduce_take(fmbd_csr **K, fmbd_csr **M, const int64_t *dofs, int64_t nb,
                        const int64_t *boundary, const fmbd_cb_opts *o, fmbd_cb **out);

/// @brief The boundary block of the reduced matrices from the constraint modes: Kr = Kb + Kc' Psi,
/// Mr = Psi' A + Mc' Psi + Mb (nb x nb, symmetrised), cb->nr = nb, and cb->rigid_scale.
/// Needs cb->ns, nb, Psi and A; the modal part is added by fmbd_cb_update_reduced.
/// @param[in] Kc, Mc  ns x nb interior-boundary blocks; Kb, Mb nb x nb (borrowed)
int fmbd_cb_condense_boundary(fmbd_cb *cb, const fmbd_csr *Kc, const fmbd_csr *Mc,
                              const fmbd_csr *Kb, const fmbd_csr *Mb);

/// @brief Recompute PhitA, the reduced matrices and the reduced eigensolution from kappa, Phi
/// and the stored boundary blocks (after the modes changed). Needs no FE matrix.
int fmbd_cb_update_reduced(fmbd_cb *cb, double rigid_rtol);

/// @brief EXTEND the fixed-interface mode set to nd_new modes (cbcheck, when it needs more
/// modes than fe2cb wrote). Refactors Ks from K (the cb's interior), recomputes the lowest
/// nd_new modes with the checked eigensolver, verifies that the old kappa are reproduced
/// (relative 1e-8) and orients each new mode like the old one it replaces (sign of
/// phi_old' Ms phi_new), then replaces kappa, Phi, kappa_next and updates the reduced
/// problem (fmbd_cb_update_reduced). cb must have method "cb" or nm-hold. nd_new <= nd is a
/// truncation (no solve).
/// @param[in] K, M  the body's FE matrices (fmbd_fe_read), borrowed
/// @param[in] eig   eigensolver options (progress), NULL = defaults
int fmbd_cb_extend(const fmbd_csr *K, const fmbd_csr *M, fmbd_cb *cb, int64_t nd_new,
                   const fmbd_eig_opts *eig);

/// @brief Write the /cb and /reduced groups (not the description, not the root attributes).
int fmbd_cb_write(fmbd_h5 *f, const fmbd_cb *cb);

/// @brief Read /cb and /reduced of an fmbd-cb file into a new struct (checks the format and
/// the major version, the shapes against each other, and index ranges).
/// @param[out] out caller destroys with fmbd_cb_destroy
int fmbd_cb_read(fmbd_h5 *f, fmbd_cb **out);
/// @brief fmbd_cb_read without what only cbcheck's estimates use (/cb/A, KsinvA,
/// KsinvMsKsinvA, PhitA, /reduced/M, K: left NULL): the shapes of the modes, Phi, Psi, Xi and
/// the eigenvalues, for a modal body (fmbd-run's .cb.h5 bodies). The same checks.
int fmbd_cb_read_basis(fmbd_h5 *f, fmbd_cb **out);

#endif
