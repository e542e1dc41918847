// common/fmbd_dense.h: dense linear algebra (LAPACKE / CBLAS wrappers), column-major
// SPDX-License-Identifier: MIT
//
// Dense matrices in memory are COLUMN-major (LAPACK's): entry (i, j) of an m x n matrix with
// leading dimension ld is A[i + j*ld]. Sizes are int64_t; LAPACK takes 32-bit lapack_int, so
// every wrapper checks that the sizes (and the workspace LAPACK will ask for) fit, and fails
// with FMBD_ERR_VALUE otherwise. A LAPACK failure becomes an FMBD_ERR_* naming the routine and
// its info. Arguments are borrowed; nothing is allocated except LAPACK's own workspace (inside
// LAPACKE, not counted by fmbd_alloc). HDF5 stores matrices row-major: use
// fmbd_h5_write_f64_cm / fmbd_h5_read_f64_cm, which transpose.
#ifndef FMBD_DENSE_H
#define FMBD_DENSE_H

#include <stdbool.h>
#include <stdint.h>

/// @brief Generalized symmetric-definite eigenproblem A x = w B x (LAPACK dsygvd, upper
/// triangles used).
/// @param[in]     n  order (0 is fine: nothing to do)
/// @param[in,out] A  n x n symmetric; on return the eigenvectors, B-orthonormal (X' B X = I),
///                   column k belongs to w[k]
/// @param[in,out] B  n x n symmetric positive definite; destroyed (its Cholesky factor)
/// @param[out]    w  n eigenvalues, ascending
/// @return FMBD_OK; FMBD_ERR_SINGULAR if B is not positive definite; FMBD_ERR_CONVERGE if
///         the tridiagonal solver failed; FMBD_ERR_VALUE for a NaN input or n too large.
int fmbd_dense_sygv(int64_t n, double *A, double *B, double *w);
/// @brief Symmetric eigenproblem A x = w x (dsyevd, upper triangle used).
/// @param[in,out] A n x n; on return the orthonormal eigenvectors (columns)
/// @param[out]    w n eigenvalues, ascending
/// @return FMBD_OK, FMBD_ERR_CONVERGE, FMBD_ERR_VALUE
int fmbd_dense_syev(int64_t n, double *A, double *w);
/// @brief Cholesky factorization A = L L' (dpotrf, lower). The strict upper triangle of A is
/// left untouched (not zeroed).
/// @param[in,out] A n x n symmetric positive definite (lower triangle read); L on return
/// @return FMBD_OK; FMBD_ERR_SINGULAR if A is not positive definite
int fmbd_dense_chol(int64_t n, double *A);
/// @brief Solve A X = B with the factor of fmbd_dense_chol (dpotrs, lower).
/// @param[in]     L    n x n factor (leading dimension n)
/// @param[in,out] B    n x nrhs right-hand sides, leading dimension ldb >= max(1, n); X on return
int fmbd_dense_chol_solve(int64_t n, const double *L, int64_t nrhs, double *B, int64_t ldb);
/// @brief Solve A X = B by LU with partial pivoting (dgesv).
/// @param[in,out] A n x n (leading dimension n); destroyed (its LU factors)
/// @param[in,out] B n x nrhs, leading dimension ldb >= max(1, n); X on return
/// @return FMBD_OK; FMBD_ERR_SINGULAR if A is exactly singular; FMBD_ERR_NOMEM
int fmbd_dense_lu_solve(int64_t n, double *A, int64_t nrhs, double *B, int64_t ldb);
/// @brief C = alpha op(A) op(B) + beta C (cblas_dgemm, column-major); op(X) = X for 'N'/'n',
/// X' for 'T'/'t'/'C'/'c'. op(A) is m x k, op(B) is k x n, C is m x n. With beta == 0, C need
/// not be initialised. Sizes beyond 32-bit int (never met in this toolchain) are computed with
/// a plain loop instead of BLAS, still correct. m, n or k == 0 is fine.
void fmbd_dense_gemm(char ta, char tb, int64_t m, int64_t n, int64_t k, double alpha,
                     const double *A, int64_t lda, const double *B, int64_t ldb, double beta,
                     double *C, int64_t ldc);
/// @brief Whether a 3x3 inertia tensor (row- or column-major: it must be symmetric) is
/// physical: symmetric to 1e-9 of its trace, its principal moments >= -1e-9 trace and each
/// at most the sum of the other two (triangle inequality, + 1e-9 trace). *why (static text)
/// names the defect when false.
bool fmbd_dense_inertia_ok(const double T[9], const char **why);

/// @brief Singular values of an m x n matrix (dgesdd, no vectors).
/// @param[in,out] A m x n (leading dimension m); destroyed
/// @param[out]    s min(m, n) singular values, descending
/// @return FMBD_OK, FMBD_ERR_CONVERGE, FMBD_ERR_VALUE
int fmbd_dense_svd_values(int64_t m, int64_t n, double *A, double *s);

#endif
