// common/fmbd_eig.h: lowest eigenpairs of K x = lambda M x (shift-invert Lanczos: ARPACK, or a
// block Krylov-Schur method for many pairs)
// SPDX-License-Identifier: MIT
//
// K symmetric positive semi-definite, M symmetric positive definite (positive semi-definite
// works: massless dofs give infinite eigenvalues, never returned), both ndof x ndof in full
// CSR storage. The solver returns the lowest eigenpairs, by count or up to a bound, ascending,
// M-normalised (X' M X = I), and guarantees that none was skipped:
//
// - Shift-invert Lanczos (ARPACK dsaupd/dseupd, mode 3, bmat 'G', which "LM", explicit tol:
//   docs/TOOLCHAIN.md gotcha 11) on OP = (K - sigma M)^-1 M with one CHOLMOD factor.
// - Shift strategy (docs/THEORY.md section 8): if K is positive definite (a held body: CB interior)
//   sigma = 0 and the caller's factor of K is reused. A body that may have rigid-body modes
//   (free_body) gets a NEGATIVE shift scaled to its spectrum: a cheap first pass (12 pairs,
//   loose tol) at sigma0 = -1e-6 max_i(K_ii/M_ii) estimates the first flexible eigenvalue
//   lambda_f (the lowest one above 1e-6 of the largest found); the real pass uses
//   sigma = -lambda_f / 2, so rigid (0) and flexible eigenvalues map to operator eigenvalues
//   of the same order and K - sigma M is as well conditioned as it can be. A shift at -10
//   against lambda_f = 4e7 loses modes (docs/THEORY.md section 8): this is what the strategy
//   avoids.
// - On problems of 10,000 dofs and more, and from 60 wanted pairs on at any size (option
//   block), a thick-restart block Lanczos (block Krylov-Schur) with locking on the symmetric
//   form L^-1 P M P' L^-T of the same operator replaces ARPACK: blocks of 4 vectors below 60
//   pairs, 16 from 60 on, one multi-right-hand-side solve per block (fmbd_eig.c has the method
//   and its references). Same checks below; bench/README.md has the measured gain. In count
//   mode the run also computes a margin of nev/10 (at least 3) pairs above the nev wanted ones
//   (both paths); the block path converges the wanted pairs to tol and the margin ones to
//   max(tol, 1e-8): they only place the Sturm shift and give next_lambda.
// - Every pair is checked by its residual ||K x - lambda M x|| / max(||K x||, |sigma| ||M x||)
//   (the second term keeps rigid-body pairs, K x ~ 0, meaningful).
// - Sturm check: an LDL' factorisation of K - s M (no pivoting; supernodal, fmbd_chol) counts
//   the eigenvalues below s by Sylvester's law of inertia, with s placed in the first clear gap
//   above the last wanted eigenvalue (between two returned ones). The count must equal the
//   number returned below s; otherwise the solve is repeated with more vectors (a missing
//   member of a repeated pair, a skipped mode) up to max_passes times.
// - Small problems (n <= dense_max) are solved densely with LAPACK (complete by construction).
// - Every ARPACK failure (info < 0, maxit reached, too few converged) becomes
//   FMBD_ERR_CONVERGE with the number of converged pairs.
#ifndef FMBD_EIG_H
#define FMBD_EIG_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_chol.h"
#include "fmbd_csr.h"

/// Progress report: stage ("Lanczos", "Sturm check", "residuals"), solves so far in this
/// stage, pairs wanted.
typedef void (*fmbd_eig_progress_fn)(void *ctx, const char *stage, int64_t solves, int64_t nev);

/// Options; fill with fmbd_eig_opts_defaults, then change.
typedef struct fmbd_eig_opts {
  int64_t nev;        ///< pairs wanted (count mode); in bound mode the first guess (0: 20)
  double lambda_max;  ///< > 0: bound mode, every eigenvalue <= lambda_max. Default 0
  bool free_body;     ///< K may be singular (rigid-body modes): negative shift. Default false
  double tol;         ///< ARPACK tol (relative Ritz accuracy). Default 1e-12
  double resid_tol;   ///< accepted relative residual of each pair. Default 1e-6, or the
                      ///< attainable 1e3 eps max(K_ii/M_ii) / lambda if larger
  int maxit;          ///< ARPACK restarts per run. Default 500
  int max_passes;     ///< runs with more vectors after a failed check. Default 4
  bool sturm;         ///< do the Sturm count check. Default true
  int64_t ncv;        ///< Lanczos basis size (0: automatic, nev + max(20, nev/2), capped)
  int64_t dense_max;  ///< solve densely with LAPACK up to this order. Default 400
  int64_t block;      ///< Lanczos block size: 1 = ARPACK (single vector), >= 2 = block
                      ///< Krylov-Schur with blocks of that many vectors, 0 = automatic (blocks
                      ///< of 16 from 60 wanted pairs on, of 4 below that on problems of 10,000
                      ///< dofs and more, ARPACK on smaller ones). Default 0, or the environment
                      ///< variable FMBD_EIG_BLOCK when set
  const double *v0;   ///< (n) start vector of the first Lanczos pass, borrowed, or NULL
                      ///< (default): ARPACK's random start / a fixed pseudo-random block. A
                      ///< pass after a failed check starts afresh without it. With the block
                      ///< method it becomes the first column of the start block (as OP v0)
  bool orth_check;    ///< block method: measure the final basis' loss of orthogonality
                      ///< (fmbd_eig_result.orth_loss; m^2 n flops). Default false; always
                      ///< measured (and logged) at log level debug (-vv)
  fmbd_eig_progress_fn progress;  ///< may be NULL (default)
  void *progress_ctx;
  /// K's values released by the caller (K->data NULL) while the Lanczos run does not read them
  /// (fe2cb's peak memory, bench/README.md "fe2cb's memory"): called once before the residual
  /// check, must put them back into K. Only with F given, sturm false, not free_body and the
  /// sparse path (n > dense_max). NULL (default): K's values are always there
  int (*need_k)(void *ctx);
  void *need_k_ctx;
} fmbd_eig_opts;

/// @brief The defaults documented above.
void fmbd_eig_opts_defaults(fmbd_eig_opts *o);

/// The solution and its cost. Free the arrays with fmbd_eig_result_free.
typedef struct fmbd_eig_result {
  int64_t n;            ///< order of the problem
  int64_t nev;          ///< pairs returned
  double *lambda;       ///< (nev) ascending; owned
  double *X;            ///< n x nev column-major, X' M X = I; owned
  double *resid;        ///< (nev) relative residual of each pair; owned
  double next_lambda;   ///< lowest eigenvalue found above the last returned (NAN if none)
  double sigma;         ///< shift of the final Lanczos pass
  double sturm_shift;   ///< shift of the Sturm check (NAN if none)
  int64_t sturm_count;  ///< eigenvalues below sturm_shift by inertia (-1 if not checked)
  bool dense;           ///< solved densely (LAPACK)
  int64_t block;        ///< block size of the last Lanczos pass (1: ARPACK)
  int passes;           ///< Lanczos runs, including the estimate pass
  int64_t n_solves;     ///< operator applications (sparse solves)
  int64_t n_restarts;   ///< ARPACK restart iterations, summed over runs
  double orth_loss;     ///< block method, when measured (opts orth_check or -vv): max |(V' V -
                        ///< I)_ij| of the last pass' final basis V; else NAN
  double t_factor_s;    ///< shifted factorisations done here (not the caller's)
  double t_lanczos_s;   ///< ARPACK iterations + solves + eigenvector extraction
  double t_sturm_s;     ///< LDL' factorisations of the Sturm check
  double t_check_s;     ///< residual computation
} fmbd_eig_result;

/// @brief max_i K_ii / M_ii over the dofs with mass: the upper end of the spectrum of
/// K x = lambda M x (Rayleigh quotients of unit vectors), the scale of shifts and zero tests.
double fmbd_eig_spectrum_scale(const fmbd_csr *K, const fmbd_csr *M);

/// @brief Lowest eigenpairs of K x = lambda M x (see the file comment).
/// @param[in] K, M  borrowed, ndof x ndof, symmetric (full storage; not checked here)
/// @param[in] F     borrowed, may be NULL: a factor analysed for K (and M) and factored at a
///                  shift below every eigenvalue (e.g. fmbd_chol_create_llt(K): sigma 0); used
///                  instead of a new factorisation unless free_body asks for a negative shift
/// @param[in] o     borrowed; NULL = defaults (then nev = 20)
/// @param[out] res  caller frees with fmbd_eig_result_free (also on failure)
/// @return FMBD_OK; FMBD_ERR_VALUE (nev >= n, bad options); FMBD_ERR_SINGULAR (K singular
///         and not free_body: the message names the row); FMBD_ERR_CONVERGE (ARPACK failed,
///         or a check still fails after max_passes: says how many pairs converged)
int fmbd_eig_solve(const fmbd_csr *K, const fmbd_csr *M, fmbd_chol *F, const fmbd_eig_opts *o,
                   fmbd_eig_result *res);

/// @brief Release the arrays and zero the struct. NULL is fine.
void fmbd_eig_result_free(fmbd_eig_result *res);

/// @brief The Sturm check of a result computed with o->sturm = false, done afterwards (so that
/// the caller can free its Cholesky factor first: the LDL' factor is as large). The shift goes
/// midway between the last returned eigenvalue and res->next_lambda; it needs a relative gap
/// of 1e-6 between them.
/// @param[in,out] res  sturm_shift, sturm_count and t_sturm_s are set
/// @param[out] ok  true: the count equals res->nev; false: a mode was skipped, or no gap above
///                 the last pair to place the shift (then solve again with o->sturm = true)
/// @param[in] like  a factor of K's pattern whose analysis (ordering, and where it allows the
///                  symbolic factor: fmbd_chol_analyze_like) the LDL' reuses, or NULL
int fmbd_eig_sturm_check(const fmbd_csr *K, const fmbd_csr *M, fmbd_chol *like,
                         fmbd_eig_result *res, bool *ok);

/// @brief Relative residual ||K x - lambda M x|| / max(||K x||, |scale| ||M x||) of one pair.
/// @param[in] work  2n doubles of scratch
double fmbd_eig_residual(const fmbd_csr *K, const fmbd_csr *M, double lambda, const double *x,
                         double scale, double *work);

#endif
