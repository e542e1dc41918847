// common/fmbd_dense.c: dense linear algebra (LAPACKE / CBLAS wrappers), column-major
// SPDX-License-Identifier: MIT
#include "fmbd_dense.h"

#include <cblas.h>
#include <lapacke.h>
#include <limits.h>
#include <math.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"

// The largest value a lapack_int (32-bit int here, LP64) may take.
#define LAPACK_INT_MAX ((int64_t)INT_MAX)

// Map a LAPACK info < 0 (an illegal argument; LAPACKE also reports NaN inputs this way) or
// LAPACKE's out-of-memory code to an fmbd error. info > 0 is routine-specific: the callers.
#define FMBD_LAPACK(info, routine)                                                          \
  do {                                                                                      \
    if ((info) == LAPACK_WORK_MEMORY_ERROR || (info) == LAPACK_TRANSPOSE_MEMORY_ERROR)      \
      FMBD_FAIL(FMBD_ERR_NOMEM, "%s: out of memory for the workspace", routine);            \
    if ((info) < 0)                                                                         \
      FMBD_FAIL(FMBD_ERR_VALUE, "%s: argument %d has an illegal value (info = %d; a NaN?)", \
                routine, (int)-(info), (int)(info));                                        \
  } while (0)

// Whether 1 + 6n + 2n^2 (the dsygvd/dsyevd real workspace with vectors) fits a lapack_int.
static int eig_size_ok(int64_t n) {
  return n <= 32000;
}  // 2*32000^2 + 6*32000 + 1 < 2^31

int fmbd_dense_sygv(int64_t n, double *A, double *B, double *w) {
  FMBD_CHECK(n >= 0, FMBD_ERR_VALUE, "dsygvd: negative order %lld", (long long)n);
  if (n == 0) return FMBD_OK;
  FMBD_CHECK(eig_size_ok(n), FMBD_ERR_VALUE,
             "dsygvd: order %lld too large for 32-bit LAPACK workspace (max 32000)", (long long)n);
  lapack_int nn = (lapack_int)n;
  lapack_int info = LAPACKE_dsygvd(LAPACK_COL_MAJOR, 1, 'V', 'U', nn, A, nn, B, nn, w);
  FMBD_LAPACK(info, "dsygvd");
  if (info > nn)
    FMBD_FAIL(FMBD_ERR_SINGULAR,
              "dsygvd: B is not positive definite (leading minor of order %d, info = %d)",
              (int)(info - nn), (int)info);
  if (info > 0)
    FMBD_FAIL(FMBD_ERR_CONVERGE, "dsygvd: eigensolver failed to converge (info = %d)", (int)info);
  return FMBD_OK;
}

int fmbd_dense_syev(int64_t n, double *A, double *w) {
  FMBD_CHECK(n >= 0, FMBD_ERR_VALUE, "dsyevd: negative order %lld", (long long)n);
  if (n == 0) return FMBD_OK;
  FMBD_CHECK(eig_size_ok(n), FMBD_ERR_VALUE,
             "dsyevd: order %lld too large for 32-bit LAPACK workspace (max 32000)", (long long)n);
  lapack_int nn = (lapack_int)n;
  lapack_int info = LAPACKE_dsyevd(LAPACK_COL_MAJOR, 'V', 'U', nn, A, nn, w);
  FMBD_LAPACK(info, "dsyevd");
  if (info > 0)
    FMBD_FAIL(FMBD_ERR_CONVERGE, "dsyevd: eigensolver failed to converge (info = %d)", (int)info);
  return FMBD_OK;
}

int fmbd_dense_chol(int64_t n, double *A) {
  FMBD_CHECK(n >= 0 && n <= LAPACK_INT_MAX, FMBD_ERR_VALUE, "dpotrf: order %lld out of range",
             (long long)n);
  if (n == 0) return FMBD_OK;
  lapack_int nn = (lapack_int)n;
  lapack_int info = LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', nn, A, nn);
  FMBD_LAPACK(info, "dpotrf");
  if (info > 0)
    FMBD_FAIL(FMBD_ERR_SINGULAR,
              "dpotrf: matrix is not positive definite (leading minor of order %d)", (int)info);
  return FMBD_OK;
}

int fmbd_dense_chol_solve(int64_t n, const double *L, int64_t nrhs, double *B, int64_t ldb) {
  FMBD_CHECK(n >= 0 && n <= LAPACK_INT_MAX && nrhs >= 0 && nrhs <= LAPACK_INT_MAX &&
                 ldb >= (n > 1 ? n : 1) && ldb <= LAPACK_INT_MAX,
             FMBD_ERR_VALUE, "dpotrs: sizes out of range (n %lld, nrhs %lld, ldb %lld)",
             (long long)n, (long long)nrhs, (long long)ldb);
  if (n == 0 || nrhs == 0) return FMBD_OK;
  lapack_int info = LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)nrhs, L,
                                   (lapack_int)n, B, (lapack_int)ldb);
  FMBD_LAPACK(info, "dpotrs");
  return FMBD_OK;
}

int fmbd_dense_lu_solve(int64_t n, double *A, int64_t nrhs, double *B, int64_t ldb) {
  FMBD_CHECK(n >= 0 && n <= LAPACK_INT_MAX && nrhs >= 0 && nrhs <= LAPACK_INT_MAX &&
                 ldb >= (n > 1 ? n : 1) && ldb <= LAPACK_INT_MAX,
             FMBD_ERR_VALUE, "dgesv: sizes out of range (n %lld, nrhs %lld, ldb %lld)",
             (long long)n, (long long)nrhs, (long long)ldb);
  if (n == 0) return FMBD_OK;
  lapack_int *ipiv = fmbd_malloc((size_t)n * sizeof *ipiv);
  FMBD_CHECK(ipiv, FMBD_ERR_NOMEM, "dgesv: out of memory for %lld pivots", (long long)n);
  lapack_int info = LAPACKE_dgesv(LAPACK_COL_MAJOR, (lapack_int)n, (lapack_int)nrhs, A,
                                  (lapack_int)n, ipiv, B, (lapack_int)ldb);
  fmbd_free(ipiv);
  FMBD_LAPACK(info, "dgesv");
  if (info > 0)
    FMBD_FAIL(FMBD_ERR_SINGULAR, "dgesv: matrix is singular (U(%d,%d) is exactly zero)", (int)info,
              (int)info);
  return FMBD_OK;
}

static int is_trans(char t) {
  return t == 'T' || t == 't' || t == 'C' || t == 'c';
}

void fmbd_dense_gemm(char ta, char tb, int64_t m, int64_t n, int64_t k, double alpha,
                     const double *A, int64_t lda, const double *B, int64_t ldb, double beta,
                     double *C, int64_t ldc) {
  if (m <= 0 || n <= 0) return;
  int at = is_trans(ta), bt = is_trans(tb);
  if (k <= 0) {  // C = beta C (BLAS would insist on leading dimensions of empty A and B)
    for (int64_t j = 0; j < n; j++) {
      for (int64_t i = 0; i < m; i++) C[i + j * ldc] = beta == 0.0 ? 0.0 : beta * C[i + j * ldc];
    }
    return;
  }
  if (m <= LAPACK_INT_MAX && n <= LAPACK_INT_MAX && k <= LAPACK_INT_MAX && lda <= LAPACK_INT_MAX &&
      ldb <= LAPACK_INT_MAX && ldc <= LAPACK_INT_MAX) {
    cblas_dgemm(CblasColMajor, at ? CblasTrans : CblasNoTrans, bt ? CblasTrans : CblasNoTrans,
                (int)m, (int)n, (int)k, alpha, A, (int)lda, B, (int)ldb, beta, C, (int)ldc);
    return;
  }
  // sizes a 32-bit BLAS cannot take: a plain loop (slow, correct)
  for (int64_t j = 0; j < n; j++) {
    for (int64_t i = 0; i < m; i++) {
      double s = 0.0;
      for (int64_t l = 0; l < k; l++) {
        double a = at ? A[l + i * lda] : A[i + l * lda];
        double b = bt ? B[j + l * ldb] : B[l + j * ldb];
        s += a * b;
      }
      C[i + j * ldc] = beta == 0.0 ? alpha * s : alpha * s + beta * C[i + j * ldc];
    }
  }
}

int fmbd_dense_svd_values(int64_t m, int64_t n, double *A, double *s) {
  FMBD_CHECK(m >= 0 && n >= 0, FMBD_ERR_VALUE, "dgesdd: negative size");
  if (m == 0 || n == 0) return FMBD_OK;
  int64_t mn = m < n ? m : n, mx = m > n ? m : n;
  // dgesdd workspace (jobz = 'N'): 3 mn + max(mx, 7 mn); the matrix itself m*n <= 2^31
  FMBD_CHECK(mx <= LAPACK_INT_MAX && 3 * mn + (mx > 7 * mn ? mx : 7 * mn) <= LAPACK_INT_MAX,
             FMBD_ERR_VALUE, "dgesdd: %lld x %lld too large for 32-bit LAPACK", (long long)m,
             (long long)n);
  double dummy = 0.0;
  lapack_int info = LAPACKE_dgesdd(LAPACK_COL_MAJOR, 'N', (lapack_int)m, (lapack_int)n, A,
                                   (lapack_int)m, s, &dummy, 1, &dummy, 1);
  FMBD_LAPACK(info, "dgesdd");
  if (info > 0)
    FMBD_FAIL(FMBD_ERR_CONVERGE, "dgesdd: bidiagonal SVD failed to converge (info = %d)",
              (int)info);
  return FMBD_OK;
}

bool fmbd_dense_inertia_ok(const double T[9], const char **why) {
  double tr = T[0] + T[4] + T[8], A[9], w[3];
  *why = "";
  for (int i = 0; i < 9; i++) {
    if (!isfinite(T[i])) return *why = "not finite", false;
  }
  if (!(tr > 0)) return *why = "trace not positive", false;
  for (int a = 0; a < 3; a++) {
    for (int b = a + 1; b < 3; b++) {
      if (fabs(T[3 * a + b] - T[3 * b + a]) > 1e-9 * tr) return *why = "not symmetric", false;
    }
  }
  memcpy(A, T, sizeof A);
  if (fmbd_dense_syev(3, A, w) != FMBD_OK) return *why = "no eigenvalues", false;
  if (w[0] < -1e-9 * tr) return *why = "a negative principal moment", false;
  if (w[2] > w[0] + w[1] + 1e-9 * tr) {
    return *why = "a principal moment above the sum of the other two", false;
  }
  return true;
}
