// common/fmbd_chol.h: sparse symmetric factorisations through CHOLMOD (64-bit cholmod_l_*)
// SPDX-License-Identifier: MIT
//
// A factor object holds the CHOLMOD analysis (fill-reducing ordering, symbolic factor) of the
// pattern of A + B for two symmetric matrices A and B (B optional) given in full CSR storage,
// and a numeric factor of the shifted matrix A - sigma B for the sigma of the last
// fmbd_chol_factor call. The same analysis serves any number of shifts.
//
// Two kinds:
// - FMBD_CHOL_LLT: supernodal Cholesky LL' (BLAS-3, fast): numeric factorisation written here
//   (the LDLT's, with square roots) into CHOLMOD's symbolic supernodal factor, which CHOLMOD's
//   solves then read; CHOLMOD's own numeric LL' with FMBD_CHOL_LLT=cholmod in the environment
//   or fmbd_chol_set_own_llt(F, false). Fails with FMBD_ERR_SINGULAR when
//   A - sigma B is not positive definite, or when a pivot is tiny against the diagonal (a
//   singular matrix that round-off made barely positive, e.g. a floating region of a body):
//   the message names the row (the caller maps it to a dof; fmbd_chol_failed_row).
// - FMBD_CHOL_LDLT: LDL' without pivoting, for the inertia count only (no solves): the number
//   of negative entries of D is, by Sylvester's law of inertia, for B positive definite the
//   number of eigenvalues of A x = lambda B x below sigma (the Sturm-sequence check). Numeric
//   factorisation written here (left-looking supernodal, BLAS-3) on CHOLMOD's supernodal
//   symbolic analysis: CHOLMOD's own LDL' is simplicial only, 10-20 times slower than its
//   supernodal LL' on 3-D meshes (docs/TOOLCHAIN.md section 3e), and stores a row index per entry.
// - FMBD_CHOL_LDLT_SIMPLICIAL: the same count with CHOLMOD's simplicial LDL'
//   (c.supernodal = CHOLMOD_SIMPLICIAL, c.final_ll = 0): the reference of the tests.
//
// CHOLMOD's memory goes through fmbd_malloc & co and it never prints (c.print = 0,
// SuiteSparse_config.printf_func = NULL).
#ifndef FMBD_CHOL_H
#define FMBD_CHOL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "fmbd_csr.h"

enum fmbd_chol_kind { FMBD_CHOL_LLT = 0, FMBD_CHOL_LDLT = 1, FMBD_CHOL_LDLT_SIMPLICIAL = 2 };

typedef struct fmbd_chol fmbd_chol;

/// Cost and shape of a factor (for progress and the -v breakdown).
typedef struct fmbd_chol_stats {
  int64_t n;             ///< order of the matrix
  int64_t nnz_a;         ///< entries of the upper triangle of the analysed pattern
  double nnz_l;          ///< entries in L (CHOLMOD's lnz)
  double flops;          ///< floating-point operations of the last factorisation (CHOLMOD's fl)
  const char *ordering;  ///< "AMD", "METIS", "NESDIS", "natural", ... (static string)
  double t_analyze_s;    ///< wall time of the analysis (ordering + symbolic)
  double t_factor_s;     ///< wall time of all numeric factorisations so far
  double t_solve_s;      ///< wall time of all solves so far
  int64_t n_solves;      ///< right-hand sides solved so far
  int64_t n_factor;      ///< numeric factorisations so far
} fmbd_chol_stats;

/// @brief Analyse the pattern of A (+ B) and prepare a factor of the given kind. A and B are
/// square, same order, symmetric in full storage (only the upper triangle is read; the
/// caller checks symmetry). Borrowed: A and B must outlive the object (their values are
/// read again by every fmbd_chol_factor).
/// @param[in] A  borrowed
/// @param[in] B  borrowed, may be NULL (then sigma must be 0)
/// @param[in] kind FMBD_CHOL_LLT or FMBD_CHOL_LDLT
/// @param[out] out caller destroys with fmbd_chol_destroy
/// @return FMBD_OK, FMBD_ERR_VALUE (bad shapes), FMBD_ERR_NOMEM, FMBD_ERR_EXTERNAL
int fmbd_chol_analyze(const fmbd_csr *A, const fmbd_csr *B, int kind, fmbd_chol **out);

/// @brief fmbd_chol_analyze with a given fill-reducing permutation (perm[k] = the row that
/// becomes pivot k; e.g. fmbd_chol_get_perm of an earlier factor of the same pattern), which
/// saves the ordering time (METIS). perm NULL: CHOLMOD's choice. perm is copied.
int fmbd_chol_analyze_perm(const fmbd_csr *A, const fmbd_csr *B, int kind, const int64_t *perm,
                           fmbd_chol **out);
/// @brief fmbd_chol_analyze_perm with the ordering of the analysed factor like; where like is an
/// LLT of the same A whose values were dropped (fmbd_chol_drop_numeric) and the new factor an
/// LDLT with B NULL or on A's index arrays, like's symbolic factor is copied instead of
/// analysed again (the same result; fe2cb's Sturm check). Where like holds its LL' value block
/// (fmbd_chol_drop_numeric_keep) and the new factor is an LDLT of the same size, the block
/// becomes the new factor's (no fresh pages) and like no longer holds it.
int fmbd_chol_analyze_like(fmbd_chol *like, const fmbd_csr *A, const fmbd_csr *B, int kind,
                           fmbd_chol **out);
/// @brief The permutation of an analysed factor into perm (n entries, caller allocates).
int fmbd_chol_get_perm(const fmbd_chol *F, int64_t *perm);

/// @brief Numeric factorisation of A - sigma B.
/// LLT: FMBD_ERR_SINGULAR if not positive definite or if a pivot d_k = L_kk^2 falls below
/// pivot_rtol * A_kk - sigma B_kk (set with fmbd_chol_set_pivot_rtol, default 1e-13; a
/// floating region of an FE body gives pivots of order 1e-16..1e-14 of its diagonal, a
/// well-posed slender structure of 1000 elements about 1e-9). The message says which row
/// failed and, after the failure, fmbd_chol_failed_row gives it.
/// LDLT: fails only on an exactly zero or NaN pivot (FMBD_ERR_SINGULAR).
int fmbd_chol_factor(fmbd_chol *F, double sigma);

/// @brief Solve (A - sigma B) X = R in place for a block of nrhs right-hand sides.
/// @param[in,out] X  column-major n x nrhs with leading dimension ldx (>= n)
int fmbd_chol_solve(fmbd_chol *F, int64_t nrhs, double *X, int64_t ldx);

enum { FMBD_CHOL_FWD = 1, FMBD_CHOL_BWD = 2 };

/// @brief Half of an LLT solve, for the symmetric form L^-1 P B P' L^-T of a generalized
/// eigenproblem (A - sigma B = P' L L' P): FMBD_CHOL_FWD gives X <- L^-1 P X, FMBD_CHOL_BWD
/// X <- P' L^-T X (so that BWD after FWD is fmbd_chol_solve). Block of nrhs columns, in place.
/// A forward half counts as one solve in the statistics.
int fmbd_chol_solve_half(fmbd_chol *F, int which, int64_t nrhs, double *X, int64_t ldx);

/// @brief W = L^-1 P M P' L^-T X for an LLT factor (A - sigma B = P' L L' P) and a symmetric
/// M of its size (usually B): the symmetric shift-invert operator (fmbd_eig's block Lanczos) in
/// one call, the same bits as fmbd_chol_solve_half BWD, fmbd_csr_matmat and the FWD half. X
/// (n x nrhs, ldx) is kept, W (ldw) written; Y: scratch n x nrhs (leading dimension n) for the
/// path through CHOLMOD (blocks of 2-4 columns with the own solve keep their rows of 4 in its
/// workspace instead). *t_m (if t_m is not NULL) += the wall time of the product with M.
/// Counts as nrhs solves.
int fmbd_chol_apply_op(fmbd_chol *F, const fmbd_csr *M, int64_t nrhs, const double *X, int64_t ldx,
                       double *W, int64_t ldw, double *Y, double *t_m);

/// @brief Solves of blocks of 2 to 8 right-hand sides (2 to 16 where the processor has AVX-512)
/// with a supernodal LL' factor go through the library's own sweeps over the factor (4-wide
/// vectors, AVX2, or 8-wide, AVX-512; fmbd_chol.c "narrow-block
/// supernodal LL' solves") where the processor has them, else through CHOLMOD's (on: the
/// default). Off: always CHOLMOD's (the tests' reference). The results agree to round-off.
void fmbd_chol_set_own_solve(fmbd_chol *F, bool on);

/// @brief LLT factors computed by the library's own supernodal LL' (on: the default, unless the
/// environment says FMBD_CHOL_LLT=cholmod when the factor is analysed) or by CHOLMOD's
/// (cholmod_l_super_numeric). The factors agree to round-off; takes effect at the next
/// fmbd_chol_factor.
void fmbd_chol_set_own_llt(fmbd_chol *F, bool on);
/// @brief The value block of a numeric supernodal factor (CHOLMOD's layout: L->x, *nvalues =
/// L->xsize), or NULL (then *nvalues = 0): the tests compare the two LL' factorisations.
const double *fmbd_chol_values(const fmbd_chol *F, int64_t *nvalues);

/// @brief Solve at most w right-hand sides per CHOLMOD call (0: the default, 64). CHOLMOD keeps
/// two n x w workspaces; narrower calls read the factor more often. Each column's solution may
/// change at round-off with w (the BLAS kernels' blocking).
void fmbd_chol_set_solve_width(fmbd_chol *F, int64_t w);
/// @brief The width set by fmbd_chol_set_solve_width (0: the default).
int64_t fmbd_chol_solve_width(const fmbd_chol *F);
/// @brief The most columns the library's own supernodal solve takes in one pass over the
/// factor (24 with AVX-512, 8 with AVX2 alone; 0: CHOLMOD's solve), with one n x w workspace
/// (w: the columns rounded up to 4, at least 8) instead of CHOLMOD's two. A width set by
/// fmbd_chol_set_solve_width of up to this many columns is taken in one pass. Each column's
/// result does not depend on the width (the same operations per column).
int64_t fmbd_chol_own_width(const fmbd_chol *F);
/// @brief Free CHOLMOD's solve workspaces (n x nrhs of the largest solve so far, kept for
/// reuse): before a stage whose solves are narrower (fe2cb's projections after the Lanczos
/// run's wide back solve; peak memory). The next solve allocates them again.
void fmbd_chol_release_workspace(fmbd_chol *F);

/// @brief A function that the numeric factorisations of the calling thread (fmbd_chol_factor
/// of LLT, and of LDLT when A or B is stored as a lower triangle) call once they have formed
/// their input from A and B and before they factor it; from then until fmbd_chol_factor
/// returns they read neither matrix, so the caller may drop their arrays (fe2cb writes them to
/// a scratch file: peak memory, bench/README.md). Thread-local (the Sturm check makes its
/// factor inside fmbd_eig.c); fn NULL clears it.
typedef void (*fmbd_chol_input_fn)(void *ctx);
void fmbd_chol_set_input_hook(fmbd_chol_input_fn fn, void *ctx);

/// @brief Free the copy of the matrix kept for refactorisations (and CHOLMOD's workspace):
/// solves still work, fmbd_chol_factor does not any more (except for LLT, which assembles its
/// input from A and B). Lowers the peak memory of a long solve phase by the size of the upper
/// triangle.
void fmbd_chol_release_matrix(fmbd_chol *F);

/// @brief Free the numeric values of an LLT factor (the analysis stays): for a stage that
/// will most likely not solve again (fe2cb's residual check after the Lanczos run: the factor
/// is 1.1 GB of the 188 k dofs body's peak). A later solve first factors A (- sigma B) again,
/// so their arrays must then be in memory.
int fmbd_chol_drop_numeric(fmbd_chol *F);
/// @brief fmbd_chol_drop_numeric, but the value block is kept in F (not freed) for the next
/// fmbd_chol_analyze_like(F, ..., FMBD_CHOL_LDLT) to factor into: its pages stay resident
/// (fe2cb's Sturm check), but for about give_back bytes at its end, given back to the system
/// to make room for arrays read meanwhile. fmbd_chol_destroy frees it if no LDLT took it, and
/// a solve that factors again first.
int fmbd_chol_drop_numeric_keep(fmbd_chol *F, size_t give_back);

/// @brief Number of negative pivots of the last LDLT factorisation (-1 for LLT or before a
/// factorisation). With B positive definite: the number of eigenvalues below sigma.
int64_t fmbd_chol_negative_pivots(const fmbd_chol *F);

/// @brief Row (0-based, in the caller's numbering) at which the last factorisation failed,
/// or -1.
int64_t fmbd_chol_failed_row(const fmbd_chol *F);

/// @brief The shift of the current numeric factor.
double fmbd_chol_sigma(const fmbd_chol *F);

/// @brief Relative pivot threshold of the LLT singularity test (default 1e-13; 0 disables).
void fmbd_chol_set_pivot_rtol(fmbd_chol *F, double rtol);

/// @brief Statistics so far (copied into *st).
void fmbd_chol_get_stats(const fmbd_chol *F, fmbd_chol_stats *st);

/// @brief Release everything; *F = NULL. NULL and *F == NULL are fine.
void fmbd_chol_destroy(fmbd_chol **F);

/// @brief Set OpenBLAS's thread count (when the BLAS is OpenBLAS) and return the previous one
/// (-1: another BLAS, nothing done; n <= 0 only queries). Single right-hand-side supernodal
/// solves are BLAS-2 and memory-bound: one thread is faster than two there (measured on the
/// 51 k-dof rod: Lanczos 5.5 s instead of 11.8 s, fmbd_eig uses it), factorisations gain from
/// threads.
int fmbd_blas_set_threads(int n);

/// @brief Convenience: analyse A alone, factor it (LLT, sigma 0). On failure *out is NULL.
int fmbd_chol_create_llt(const fmbd_csr *A, fmbd_chol **out);

/// @brief Convenience for the Sturm check: number of eigenvalues of A x = lambda B x below
/// sigma (B positive definite) by an LDLT factorisation of A - sigma B (analysis included).
int fmbd_chol_count_below(const fmbd_csr *A, const fmbd_csr *B, double sigma, int64_t *count);

#endif
