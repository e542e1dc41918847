// tests/unit/t130-dense.c: dense LAPACK/BLAS wrappers against closed forms
// SPDX-License-Identifier: MIT
#include <math.h>
#include <string.h>

#include "check.h"
#include "fmbd.h"
#include "fmbd_dense.h"

// 1-D linear FE Laplacian on (0,1), fixed ends, n interior nodes, h = 1/(n+1) (docs/TOOLCHAIN.md
// section 3c): K = tridiag(-1, 2, -1)/h, M = tridiag(1, 4, 1) h/6. Exact discrete eigenvalues
// lambda_k = 6/h^2 (1 - cos k pi h)/(2 + cos k pi h), k = 1..n.
static void laplacian(int n, double *K, double *M) {
  double h = 1.0 / (n + 1);
  memset(K, 0, sizeof(double) * (size_t)(n * n));
  memset(M, 0, sizeof(double) * (size_t)(n * n));
  for (int i = 0; i < n; i++) {
    K[i + i * n] = 2.0 / h;
    M[i + i * n] = 4.0 * h / 6.0;
    if (i + 1 < n) {
      K[i + 1 + i * n] = K[i + (i + 1) * n] = -1.0 / h;
      M[i + 1 + i * n] = M[i + (i + 1) * n] = h / 6.0;
    }
  }
}

static void test_sygv(void) {
  enum { N = 60 };
  static double K[N * N], M[N * N], K0[N * N], M0[N * N], w[N], R[N * N], T[N * N];
  laplacian(N, K, M);
  memcpy(K0, K, sizeof K);
  memcpy(M0, M, sizeof M);
  EXPECT(fmbd_dense_sygv(N, K, M, w) == FMBD_OK, "sygv failed");
  double h = 1.0 / (N + 1), lmax = 6.0 / (h * h) * 2.0;  // upper bound of the spectrum
  // Tolerance: dsygvd is backward stable; the eigenvalue error is about n eps kappa(M) lmax
  // with kappa(M) <= 3 (eigenvalues of tridiag(1,4,1) lie in (2, 6)), 60*2.2e-16*3 = 4e-14;
  // 1e-12 lmax leaves a factor 25 of margin and is still 1e4 below any real bug.
  double worst = 0.0;
  for (int k = 1; k <= N; k++) {
    double c = cos(k * M_PI * h);
    double exact = 6.0 / (h * h) * (1.0 - c) / (2.0 + c);
    worst = fmax(worst, fabs(w[k - 1] - exact) / lmax);
  }
  EXPECT(worst < 1e-12, "eigenvalue error %.3g of lambda_max", worst);
  for (int k = 1; k < N; k++) EXPECT(w[k] > w[k - 1], "not ascending at %d", k);
  // X' M X = I (same backward-error argument: 1e-12)
  fmbd_dense_gemm('N', 'N', N, N, N, 1.0, M0, N, K, N, 0.0, T, N);
  fmbd_dense_gemm('T', 'N', N, N, N, 1.0, K, N, T, N, 0.0, R, N);
  double orth = 0.0;
  for (int j = 0; j < N; j++) {
    for (int i = 0; i < N; i++) orth = fmax(orth, fabs(R[i + j * N] - (i == j)));
  }
  EXPECT(orth < 1e-12, "X'MX - I = %.3g", orth);
  // residual K x - w M x relative to lmax |M x|: 1e-12 as above
  double res = 0.0;
  for (int j = 0; j < N; j++) {
    double kx[N], mx[N];
    fmbd_dense_gemm('N', 'N', N, 1, N, 1.0, K0, N, K + j * N, N, 0.0, kx, N);
    fmbd_dense_gemm('N', 'N', N, 1, N, 1.0, M0, N, K + j * N, N, 0.0, mx, N);
    double nm = 0.0;
    for (int i = 0; i < N; i++) nm = fmax(nm, fabs(mx[i]));
    for (int i = 0; i < N; i++) res = fmax(res, fabs(kx[i] - w[j] * mx[i]) / (lmax * nm));
  }
  EXPECT(res < 1e-12, "residual %.3g", res);

  // B indefinite: FMBD_ERR_SINGULAR naming the routine
  double A2[4] = {1, 0, 0, 1}, B2[4] = {1, 2, 2, 1}, w2[2];
  fmbd_err_clear();
  EXPECT(fmbd_dense_sygv(2, A2, B2, w2) == FMBD_ERR_SINGULAR, "indefinite B");
  EXPECT(strstr(fmbd_err_get()->msg, "dsygvd") != NULL, "message: %s", fmbd_err_get()->msg);
  // NaN input: LAPACKE's NaN check gives an illegal-argument info -> FMBD_ERR_VALUE
  double A3[4] = {NAN, 0, 0, 1}, B3[4] = {1, 0, 0, 1};
  EXPECT(fmbd_dense_sygv(2, A3, B3, w2) == FMBD_ERR_VALUE, "NaN input");
  EXPECT(fmbd_dense_sygv(0, NULL, NULL, NULL) == FMBD_OK, "n = 0");
  EXPECT(fmbd_dense_sygv(40000, A2, B2, w2) == FMBD_ERR_VALUE, "too large for lapack_int work");
}

static void test_syev(void) {
  // [[2,1],[1,2]]: eigenvalues 1, 3, vectors (1,-1)/sqrt2, (1,1)/sqrt2; exact in floating
  // point up to a few ulps: tolerance 1e-14
  double A[4] = {2, 1, 1, 2}, w[2];
  EXPECT(fmbd_dense_syev(2, A, w) == FMBD_OK, "syev");
  EXPECT(fabs(w[0] - 1) < 1e-14 && fabs(w[1] - 3) < 1e-14, "w = %g %g", w[0], w[1]);
  EXPECT(fabs(fabs(A[0]) - M_SQRT1_2) < 1e-14 && fabs(A[0] + A[1]) < 1e-14, "vector 1");
  EXPECT(fabs(fabs(A[2]) - M_SQRT1_2) < 1e-14 && fabs(A[2] - A[3]) < 1e-14, "vector 2");
}

static void test_chol_lu(void) {
  enum { N = 30 };
  static double K[N * N], M[N * N], L[N * N], x[N * 2], b[N * 2];
  laplacian(N, K, M);
  memcpy(L, K, sizeof K);
  // right-hand sides b = K x for x_i = sin(i) + j (two columns); solves recover x to
  // kappa(K) eps ~ 4 (N+1)^2/pi^2 * eps = 4e-13 relative: tolerance 1e-11
  for (int j = 0; j < 2; j++) {
    for (int i = 0; i < N; i++) x[i + j * N] = sin(i + 1.0) + j;
  }
  fmbd_dense_gemm('N', 'N', N, 2, N, 1.0, K, N, x, N, 0.0, b, N);
  EXPECT(fmbd_dense_chol(N, L) == FMBD_OK, "chol");
  EXPECT(fmbd_dense_chol_solve(N, L, 2, b, N) == FMBD_OK, "chol_solve");
  double err = 0.0;
  for (int i = 0; i < 2 * N; i++) err = fmax(err, fabs(b[i] - x[i]));
  EXPECT(err < 1e-11, "chol solve error %.3g", err);
  // not positive definite
  double A2[4] = {1, 2, 2, 1};
  fmbd_err_clear();
  EXPECT(fmbd_dense_chol(2, A2) == FMBD_ERR_SINGULAR, "indefinite");
  EXPECT(strstr(fmbd_err_get()->msg, "dpotrf") != NULL, "message %s", fmbd_err_get()->msg);
  EXPECT(fmbd_dense_chol_solve(2, A2, 1, b, 1) == FMBD_ERR_VALUE, "ldb < n");

  // LU: a nonsymmetric 3x3 with a known solution (integers: exact to rounding, 1e-14)
  double A[9] = {0, 1, 2, 3, 0, 1, 1, 1, 0};  // col-major: rows (0 3 1), (1 0 1), (2 1 0)
  double rhs[3] = {0 * 1 + 3 * 2 + 1 * 3, 1 * 1 + 0 * 2 + 1 * 3, 2 * 1 + 1 * 2 + 0 * 3};
  EXPECT(fmbd_dense_lu_solve(3, A, 1, rhs, 3) == FMBD_OK, "lu");
  EXPECT(fabs(rhs[0] - 1) < 1e-14 && fabs(rhs[1] - 2) < 1e-14 && fabs(rhs[2] - 3) < 1e-14,
         "lu solution %g %g %g", rhs[0], rhs[1], rhs[2]);
  double S[4] = {1, 2, 2, 4}, r2[2] = {1, 1};
  fmbd_err_clear();
  EXPECT(fmbd_dense_lu_solve(2, S, 1, r2, 2) == FMBD_ERR_SINGULAR, "singular");
  EXPECT(strstr(fmbd_err_get()->msg, "dgesv") != NULL, "message %s", fmbd_err_get()->msg);
  // the pivot array is the one allocation: its failure is FMBD_ERR_NOMEM
  double A4[4] = {1, 0, 0, 1}, r4[2] = {1, 1};
  fmbd_alloc_fail_after(0);
  EXPECT(fmbd_dense_lu_solve(2, A4, 1, r4, 2) == FMBD_ERR_NOMEM, "allocation failure");
  fmbd_alloc_fail_after(-1);
}

static void test_gemm(void) {
  // all four transposition cases on non-square blocks with padded leading dimensions, against
  // a plain triple loop; the sums have 5 terms of O(1): 1e-13 covers any summation order
  enum { m = 4, n = 3, k = 5, ld = 7 };
  double A[ld * 7], B[ld * 7], C[ld * n], R[m * n];
  for (int i = 0; i < ld * 7; i++) {
    A[i] = sin(0.3 * i + 1);
    B[i] = cos(0.7 * i);
  }
  const char *ops = "NT";
  for (int a = 0; a < 2; a++) {
    for (int b = 0; b < 2; b++) {
      for (int i = 0; i < ld * n; i++) C[i] = 1.0;
      fmbd_dense_gemm(ops[a], ops[b], m, n, k, 2.0, A, ld, B, ld, 0.5, C, ld);
      double err = 0.0;
      for (int j = 0; j < n; j++) {
        for (int i = 0; i < m; i++) {
          double s = 0.0;
          for (int l = 0; l < k; l++) {
            double x = a ? A[l + i * ld] : A[i + l * ld];
            double y = b ? B[j + l * ld] : B[l + j * ld];
            s += x * y;
          }
          R[i + j * m] = 2.0 * s + 0.5;
          err = fmax(err, fabs(C[i + j * ld] - R[i + j * m]));
        }
      }
      EXPECT(err < 1e-13, "gemm %c%c error %.3g", ops[a], ops[b], err);
      EXPECT(C[m] == 1.0, "gemm %c%c wrote outside the block", ops[a], ops[b]);
    }
  }
  // k = 0: C = beta C
  double c0[2] = {2, 4};
  fmbd_dense_gemm('N', 'N', 2, 1, 0, 1.0, NULL, 0, NULL, 0, 0.5, c0, 2);
  EXPECT(c0[0] == 1.0 && c0[1] == 2.0, "k = 0: %g %g", c0[0], c0[1]);
}

static void test_svd(void) {
  // A = R(a) diag(5, 2) R(b)' padded to 3x2 with a zero row: singular values 5, 2 (orthogonal
  // factors, rounding only: 1e-14 relative to 5)
  double ca = cos(0.4), sa = sin(0.4), cb = cos(1.1), sb = sin(1.1);
  double U[4] = {ca, sa, -sa, ca}, V[4] = {cb, sb, -sb, cb}, D[4] = {5, 0, 0, 2}, T[4], A2[4];
  fmbd_dense_gemm('N', 'N', 2, 2, 2, 1.0, U, 2, D, 2, 0.0, T, 2);
  fmbd_dense_gemm('N', 'T', 2, 2, 2, 1.0, T, 2, V, 2, 0.0, A2, 2);
  double A[6] = {A2[0], A2[1], 0, A2[2], A2[3], 0}, s[2];
  EXPECT(fmbd_dense_svd_values(3, 2, A, s) == FMBD_OK, "svd");
  EXPECT(fabs(s[0] - 5) < 5e-14 && fabs(s[1] - 2) < 5e-14, "s = %.17g %.17g", s[0], s[1]);
}

int main(void) {
  test_sygv();
  test_syev();
  test_chol_lu();
  test_gemm();
  test_svd();
  TEST_EXIT();
}
