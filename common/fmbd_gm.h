// common/fmbd_gm.h: global modes of a linearised mechanism (Cammarata 2021): sparse null-space
// basis of the constraint Jacobian, the constrained eigenproblem, classification, GMc bases
// SPDX-License-Identifier: MIT
//
// The constrained eigenproblem [C12] at a rigid-reference configuration
//     K x = w^2 M x,   Cq x = 0
// (M, K, Cq from fmbd_mbs_linearise; the caller chooses the rows of Cq, e.g. without the
// drivers) is solved on a null-space basis Z of Cq (docs/THEORY.md section 6):
// - COORDINATE PARTITIONING. Cq = [Cd Ci] up to a column permutation, Cd square nonsingular;
//   Z = [-Cd^-1 Ci; I]. Only the columns Cq touches (frame coordinates, joint-point modal or
//   nodal coordinates) take part: every other coordinate is independent and its column of Z
//   is a unit vector. The dependent columns are chosen by QR with column pivoting (LAPACK
//   dgeqp3) of the touched block with unit-normalised rows (the best-conditioned Cd the
//   pivoting finds), O(m^2 nt) for m equations and nt touched columns; Cd is factored sparse
//   (KLU) and Cd^-1 Ci solved for the touched independent columns only, so Z has
//   n - m unit rows plus m rows whose fill is that of Cd^-1 Ci: for flexible bodies Cq touches
//   only frame and joint-point coordinates, and Z stays sparse.
// - Kr = Z'KZ, Mr = Z'MZ (sparse, fmbd_csr_ptap), solved by fmbd_eig_solve (shift-invert
//   Lanczos on one factor of Kr - sigma Mr, a negative shift scaled to the spectrum when
//   there are zero modes, dense LAPACK below its dense_max), with fmbd_eig's never-miss
//   guarantee: residual of every pair and the Sturm (LDL' inertia) count of the eigenvalues
//   below the last one. Modes x = Z y, M-orthonormal (x'Mx = y'Mr y = 1).
// - CLASSIFICATION. f rigid-reference (zero-frequency) modes: the eigenvalues below
//   zero_tol * max_i(Kr_ii / Mr_ii), zero_tol 1e-11. A zero eigenvalue comes out at round-off,
//   about eps * that scale times the conditioning of Mr (5e-16 of the scale measured on a
//   four-bar); the spurious extra "mode" of a singular configuration (a flattened
//   parallelogram, met to the projection's 1e-12) at 8e-12 of it must count as a zero, so that
//   the mobility check refuses it; a genuine soft mode must stay above: the first bending mode of
//   a chain of 16 slender links is 6e-10 of the scale, of 64 such links 2.4e-12 (refused: such a
//   mechanism cannot be told from a singular one at this precision). f is checked against the
//   mechanism's mobility computed independently, n_r - rank(Cq restricted to the
//   coordinates K does not stiffen), the zero modes being exactly the motions without
//   strain that the constraints allow; a mismatch is an error. The rest are flexible modes.
#ifndef FMBD_GM_H
#define FMBD_GM_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_csr.h"
#include "fmbd_eig.h"

#define FMBD_GM_FORMAT "fmbd-gm"
#define FMBD_GM_FORMAT_VERSION "1.0"
#define FMBD_GM_FORMAT_MAJOR 1

/// Options: fill with fmbd_gm_defaults.
typedef struct fmbd_gm_opts {
  int64_t nmodes;     ///< flexible modes wanted (count mode), default 10
  double lambda_max;  ///< > 0: every flexible mode with w^2 <= lambda_max instead (bound mode)
  double zero_tol;    ///< zero-mode threshold relative to max(Kr_ii/Mr_ii), default 1e-11
  double rank_tol;    ///< pivot threshold of the partitioning and mobility QR, default 1e-10
  int64_t dense_max;  ///< passed to fmbd_eig, default 1000 (see fmbd_gm_defaults)
  fmbd_eig_progress_fn progress;
  void *progress_ctx;
} fmbd_gm_opts;
void fmbd_gm_defaults(fmbd_gm_opts *o);

/// A sparse null-space basis of Cq by coordinate partitioning.
typedef struct fmbd_gm_null {
  int64_t n, m;      ///< coordinates, equations (full row rank)
  fmbd_csr *Z;       ///< n x (n - m), Cq Z = 0
  int64_t *dep;      ///< (m) the dependent coordinates (columns of Cd), in pivot order
  int64_t *ind;      ///< (n - m) the independent coordinates, increasing: column k of Z is
                     ///< the unit vector at ind[k] plus the dependent rows
  int64_t ntouched;  ///< columns Cq touches
  double cond_est;   ///< |R_11| / |R_mm| of the pivoted QR (a conditioning indicator of Cd)
} fmbd_gm_null;

/// @brief Z with Cq Z = 0 (see the file comment).
/// @param[out] bad_row on FMBD_ERR_SINGULAR: a row of Cq dependent on the others (may be NULL)
/// @return FMBD_OK; FMBD_ERR_SINGULAR (the rows of Cq are dependent: *bad_row names one);
///         FMBD_ERR_VALUE (m > n); FMBD_ERR_EXTERNAL (LAPACK, KLU); FMBD_ERR_NOMEM
int fmbd_gm_nullspace(const fmbd_csr *Cq, double rank_tol, fmbd_gm_null *N, int64_t *bad_row);
void fmbd_gm_null_free(fmbd_gm_null *N);

/// @brief Rank of the rows of Cq restricted to the columns with cols[j] true (QR with column
/// pivoting, unit-normalised rows, |R_kk| > tol |R_11|). The mobility of a mechanism is
/// (number of such columns) - rank, with cols = the coordinates K does not stiffen.
int fmbd_gm_rank(const fmbd_csr *Cq, const bool *cols, double tol, int64_t *rank);

/// The global modes. Free with fmbd_gm_result_free.
typedef struct fmbd_gm_result {
  int64_t n, m, nz;     ///< coordinates, constraint rows, null-space size n - m
  int64_t nnz_z;        ///< entries of Z
  int64_t f;            ///< zero-frequency (rigid-reference) modes found
  int64_t mobility;     ///< n_r - rank(Cq on the unstiffened coordinates)
  int64_t nflex;        ///< flexible modes returned
  double *lambda;       ///< (f + nflex) w^2 ascending: f zeros (round-off) then flexible
  double *X;            ///< n x (f + nflex), column-major, X' M X = I, Cq X = 0
  double *resid;        ///< (f + nflex) relative residuals of the reduced pairs (fmbd_eig)
  double cq_resid;      ///< max_k ||Cq x_k|| / (||Cq|| ||x_k||) (should be round-off)
  double zero_bound;    ///< the zero-mode threshold used (rad^2/s^2)
  double next_lambda;   ///< first eigenvalue above the last returned (NAN if unknown)
  fmbd_eig_result eig;  ///< the reduced solution's record (its X, lambda moved out: NULL)
  double t_null_s, t_project_s, t_eig_s;  ///< wall times of the three stages
} fmbd_gm_result;

/// @brief Global modes of K x = w^2 M x, Cq x = 0.
/// @param[in] M, K  n x n symmetric (full storage), M positive definite on the null space
/// @param[in] Cq    m x n, full row rank
/// @param[in] rigid (n) true for the coordinates K does not stiffen (frame coordinates of
///                  every body): the mobility check; NULL skips it (mobility = -1)
/// @return FMBD_OK; FMBD_ERR_VALUE (more flexible modes asked than exist: the message says
///         how many; no flexible mode at all; the zero modes do not match the mobility);
///         FMBD_ERR_SINGULAR (dependent constraint rows: *bad_row, may be NULL, gets one,
///         see fmbd_gm_nullspace); errors of fmbd_eig_solve
int fmbd_gm_solve(const fmbd_csr *M, const fmbd_csr *K, const fmbd_csr *Cq, const bool *rigid,
                  const fmbd_gm_opts *o, fmbd_gm_result *res, int64_t *bad_row);
void fmbd_gm_result_free(fmbd_gm_result *res);

/// @brief Translational participation masses relative to the total mass: for each mode k
/// (column of X, x_k'Mx_k = 1) and direction a, mbar_ka = (x_k' M r_a)^2 / (r_a' M r_a),
/// r_a the rigid translation of the whole mechanism along a (rt: n x 3 column-major, e.g. 1
/// on the x, y, z frame coordinates of every body), so r_a' M r_a is the total mass. Over a
/// complete M-orthonormal basis of the constrained space the mbar_ka sum to the share of the
/// total mass that moves with a constrained translation (1 for a free mechanism).
/// @param[out] P (k x 3) column-major: P[k + nk * a]
void fmbd_gm_participation(const fmbd_csr *M, int64_t nk, const double *X, const double *rt,
                           double *P);

/// @brief The GMc basis of one body: the body's rows Q (nq x nk, the body's elastic
/// coordinates in the nk flexible modes) with the linearly dependent columns removed. Columns
/// are taken in mode order by Gram-Schmidt in the metric W (nq x nq symmetric positive
/// definite, sparse: the body's Mff, or the elastic block of a full FE body's M; NULL =
/// identity): column k is kept when its part
/// orthogonal to the kept ones has W-norm > tol times its own W-norm (independence) and its
/// W-norm is > tol times the largest column's (not round-off of a mode that leaves the body
/// still). The kept columns are returned W-orthonormalised (the Gram-Schmidt vectors): they span
/// the same space as the kept rows of the modes, the first j columns the span of the first j
/// kept modes' rows, and the body's GMc mass matrix is the identity (the raw rows scaled to unit
/// mass, Psi_i / sqrt(mbar_i) [C18], gave cond(Mff) 1e8 on a 4-link pendulum).
/// @param[out] B     nq x nk: the kept (orthonormalised) columns first (B[i + nq*j], j < *nkeep)
/// @param[out] keep  (nk) mode index of each kept column
/// @param[out] nkeep number kept
int fmbd_gm_gmc(int64_t nq, int64_t nk, const double *Q, const fmbd_csr *W, double tol, double *B,
                int64_t *keep, int64_t *nkeep);

#endif
