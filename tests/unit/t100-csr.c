// tests/unit/t100-csr.c: CSR assembly, products, checks
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>

#include "check.h"
#include "fmbd.h"

// The first offending row of a dense matrix D with stored-entry mask S (n x n, row-major), as
// fmbd_csr_is_symmetric defines it, by brute force: the first row i holding an entry (i, j),
// j > i, that differs from D(j, i) by more than tol; else the first row j holding an entry
// (j, i), i < j, above tol whose partner (i, j) is not stored; else -1.
static int64_t dense_bad_row(int n, const double *D, const unsigned char *S, double tol) {
  for (int i = 0; i < n; i++)
    for (int j = i + 1; j < n; j++)
      if (S[i * n + j] && fabs(D[i * n + j] - D[j * n + i]) > tol) return i;
  for (int j = 0; j < n; j++)
    for (int i = 0; i < j; i++)
      if (S[j * n + i] && !S[i * n + j] && fabs(D[j * n + i]) > tol) return j;
  return -1;
}

// fmbd_csr_is_symmetric and fmbd_csr_is_symmetric_pair (one walk over two value arrays on
// one pattern) against dense_bad_row on random patterns: symmetric values, then value
// defects and one-sided entries, some above and some below the tolerance
static void random_symmetry(void) {
  unsigned seed = 12345u;
#define RND() (seed = seed * 1103515245u + 12345u, (double)((seed >> 8) & 0xffffff) / 16777216.0)
  enum { N = 24 };
  double D[2][N * N];
  unsigned char S[N * N];
  for (int trial = 0; trial < 400; trial++) {
    int n = 1 + (int)(RND() * N);
    double dens = 0.05 + 0.5 * RND(), rtol = 1e-6;
    for (int i = 0; i < n; i++) {
      for (int j = 0; j <= i; j++) {
        unsigned char st = i == j || RND() < dens;
        S[i * n + j] = S[j * n + i] = st;
        for (int m = 0; m < 2; m++) D[m][i * n + j] = D[m][j * n + i] = st ? RND() - 0.5 : 0.0;
      }
    }
    D[0][0] = D[1][0] = 1.0;  // max|D| = 1: tol = rtol
    int ndef = (int)(RND() * 4);
    for (int k = 0; k < ndef; k++) {
      int m = RND() < 0.5, i = (int)(RND() * n), j = (int)(RND() * n);
      if (i == j) continue;
      // below or above the tolerance (the values' round-off, 1e-16, far from either side)
      static const double sizes[4] = {0.3, 0.9, 1.5, 30.0};
      double size = sizes[(int)(RND() * 4)] * rtol;
      if (RND() < 0.5 && S[i * n + j]) {
        D[m][i * n + j] += size;  // a value defect
      } else if (!S[i * n + j]) {
        S[i * n + j] = 1;  // a one-sided entry (both matrices hold the pattern)
        D[m][i * n + j] = size;
        D[1 - m][i * n + j] = 0.0;
      }
    }
    fmbd_csr *A = NULL, *B = NULL;
    int64_t nnz = 0;
    for (int q = 0; q < n * n; q++) nnz += S[q];
    EXPECT(fmbd_csr_create(n, n, nnz, &A) == 0 && fmbd_csr_create(n, n, nnz, &B) == 0, "create");
    if (!A || !B) break;
    nnz = 0;
    for (int i = 0; i < n; i++) {
      A->indptr[i] = nnz;
      for (int j = 0; j < n; j++) {
        if (!S[i * n + j]) continue;
        A->indices[nnz] = j;
        A->data[nnz] = D[0][i * n + j];
        B->data[nnz++] = D[1][i * n + j];
      }
    }
    A->indptr[n] = nnz;
    int64_t ref[2] = {dense_bad_row(n, D[0], S, rtol), dense_bad_row(n, D[1], S, rtol)};
    int64_t one[2], pair[2];
    bool ok0 = fmbd_csr_is_symmetric(A, rtol, &one[0]);
    EXPECT(ok0 == (ref[0] < 0) && one[0] == ref[0], "trial %d: A row %lld, expected %lld", trial,
           (long long)one[0], (long long)ref[0]);
    // B on A's pattern arrays (as fmbd_fe_body's M on K's), then on copies of them
    int64_t *own_p = B->indptr, *own_i = B->indices;
    B->indptr = A->indptr;
    B->indices = A->indices;
    bool ok1 = fmbd_csr_is_symmetric(B, rtol, &one[1]);
    EXPECT(ok1 == (ref[1] < 0) && one[1] == ref[1], "trial %d: B row %lld, expected %lld", trial,
           (long long)one[1], (long long)ref[1]);
    bool okp = fmbd_csr_is_symmetric_pair(A, B, rtol, pair);
    EXPECT(okp == (ref[0] < 0 && ref[1] < 0) && pair[0] == ref[0] && pair[1] == ref[1],
           "trial %d: shared pattern rows %lld %lld, expected %lld %lld", trial, (long long)pair[0],
           (long long)pair[1], (long long)ref[0], (long long)ref[1]);
    for (int i = 0; i <= n; i++) own_p[i] = A->indptr[i];
    for (int64_t q = 0; q < nnz; q++) own_i[q] = A->indices[q];
    B->indptr = own_p;
    B->indices = own_i;
    okp = fmbd_csr_is_symmetric_pair(A, B, rtol, pair);
    EXPECT(okp == (ref[0] < 0 && ref[1] < 0) && pair[0] == ref[0] && pair[1] == ref[1],
           "trial %d: copied pattern rows %lld %lld, expected %lld %lld", trial, (long long)pair[0],
           (long long)pair[1], (long long)ref[0], (long long)ref[1]);
    fmbd_csr_destroy(&A);
    fmbd_csr_destroy(&B);
  }
#undef RND
}

int main(void) {
  // 1-D chain of 4 two-dof elements over 5 dofs, element matrix [1 -1; -1 1]
  int64_t ed[8] = {0, 1, 1, 2, 2, 3, 3, 4};
  fmbd_csr *A = NULL, *B = NULL, *P = NULL, *C = NULL;
  EXPECT(fmbd_csr_pattern_from_elements(5, 4, 2, ed, &A) == 0, "pattern");
  EXPECT(fmbd_csr_nnz(A) == 13, "nnz %lld", (long long)fmbd_csr_nnz(A));
  double ke[4] = {1, -1, -1, 1};
  for (int e = 0; e < 4; e++) EXPECT(fmbd_csr_add_block(A, 2, ed + 2 * e, ke) == 0, "add");
  EXPECT(
      fmbd_csr_get(A, 2, 2) == 2.0 && fmbd_csr_get(A, 0, 0) == 1.0 && fmbd_csr_get(A, 1, 2) == -1.0,
      "values");
  EXPECT(fmbd_csr_check(A) == 0, "check");
  int64_t bad;
  EXPECT(fmbd_csr_is_symmetric(A, 0.0, &bad), "symmetric");
  {
    // asymmetries and the row reported: a value (row 1), an entry only below the diagonal
    // (row 3), one only above it (row 0); a tiny lower-only entry within the tolerance
    fmbd_csr *S = NULL;
    EXPECT(fmbd_csr_pattern_from_elements(5, 4, 2, ed, &S) == 0, "pattern");
    for (int e = 0; e < 4; e++) fmbd_csr_add_block(S, 2, ed + 2 * e, ke);
    int64_t r = -1;
    S->data[fmbd_csr_find(S, 1, 2)] += 1e-3;
    EXPECT(!fmbd_csr_is_symmetric(S, 1e-6, &r) && r == 1, "value asymmetry row %lld", (long long)r);
    EXPECT(fmbd_csr_is_symmetric(S, 1e-2, &r) && r == -1, "within tolerance");
    S->data[fmbd_csr_find(S, 1, 2)] -= 1e-3;
    fmbd_csr *T = NULL;  // the chain plus (3, 0) only, then (0, 3) only
    EXPECT(fmbd_csr_create(5, 5, 14, &T) == 0, "create");
    int64_t ptr[6] = {0, 2, 5, 8, 12, 14}, col[14] = {0, 1, 0, 1, 2, 1, 2, 3, 0, 2, 3, 4, 3, 4};
    for (int i = 0; i < 6; i++) T->indptr[i] = ptr[i];
    for (int q = 0; q < 14; q++) {
      T->indices[q] = col[q];
      T->data[q] = q == 8 ? 0.5 : 1.0;
    }
    EXPECT(!fmbd_csr_is_symmetric(T, 1e-6, &r) && r == 3, "lower-only entry row %lld",
           (long long)r);
    T->data[8] = 1e-9;
    EXPECT(fmbd_csr_is_symmetric(T, 1e-6, &r), "lower-only entry within the tolerance");
    // the same entry moved above the diagonal: row 0 holds (0, 3), row 3 does not hold (3, 0)
    int64_t ptr2[6] = {0, 3, 6, 9, 12, 14}, col2[14] = {0, 1, 3, 0, 1, 2, 1, 2, 3, 2, 3, 4, 3, 4};
    for (int i = 0; i < 6; i++) T->indptr[i] = ptr2[i];
    for (int q = 0; q < 14; q++) T->indices[q] = col2[q], T->data[q] = q == 2 ? 0.5 : 1.0;
    EXPECT(!fmbd_csr_is_symmetric(T, 1e-6, &r) && r == 0, "upper-only entry row %lld",
           (long long)r);
    fmbd_csr_destroy(&S);
    fmbd_csr_destroy(&T);
  }
  double x[5] = {1, 1, 1, 1, 1}, y[5];
  fmbd_csr_matvec(A, x, y);
  for (int i = 0; i < 5; i++) EXPECT(fabs(y[i]) < 1e-15, "rigid mode y[%d]=%g", i, y[i]);
  // P: 5 x 2 interpolation, PtAP against the dense product
  int64_t pe[2] = {0, 4};
  EXPECT(fmbd_csr_submatrix(A, 5, (int64_t[]){0, 1, 2, 3, 4}, 2, pe, &B) == 0, "submatrix");
  EXPECT(B->nrows == 5 && B->ncols == 2 && fmbd_csr_get(B, 0, 0) == 1.0 &&
             fmbd_csr_get(B, 4, 1) == 1.0,
         "submatrix values");
  EXPECT(fmbd_csr_create(5, 2, 6, &P) == 0, "create");
  int64_t pp[6] = {0, 1, 2, 4, 5, 6}, pi[6] = {0, 0, 0, 1, 1, 1};
  double pv[6] = {1, 0.5, 0.5, 0.5, 0.5, 1};
  for (int i = 0; i < 6; i++) {
    P->indptr[i] = pp[i];
    P->indices[i] = pi[i];
    P->data[i] = pv[i];
  }
  EXPECT(fmbd_csr_check(P) == 0, "P check");
  EXPECT(fmbd_csr_ptap(A, P, &C) == 0, "ptap");
  // dense reference
  double Pd[5][2] = {{1, 0}, {0.5, 0}, {0.5, 0.5}, {0, 0.5}, {0, 1}}, ref[2][2] = {{0}};
  for (int a = 0; a < 2; a++)
    for (int b = 0; b < 2; b++)
      for (int i = 0; i < 5; i++)
        for (int j = 0; j < 5; j++) ref[a][b] += Pd[i][a] * fmbd_csr_get(A, i, j) * Pd[j][b];
  for (int a = 0; a < 2; a++)
    for (int b = 0; b < 2; b++)
      EXPECT(fabs(fmbd_csr_get(C, a, b) - ref[a][b]) < 1e-14, "ptap (%d,%d) %g vs %g", a, b,
             fmbd_csr_get(C, a, b), ref[a][b]);
  // a broken matrix is caught
  P->indices[1] = 7;
  EXPECT(fmbd_csr_check(P) == FMBD_ERR_FORMAT, "out of range column not caught");
  P->indices[1] = 0;
  P->data[2] = NAN;
  EXPECT(fmbd_csr_check(P) == FMBD_ERR_VALUE, "NaN not caught");
  // allocation failure cleans up
  for (int n = 0; n < 8; n++) {
    fmbd_csr *D = NULL;
    fmbd_alloc_fail_after(n);
    int rc = fmbd_csr_pattern_from_elements(5, 4, 2, ed, &D);
    fmbd_alloc_fail_after(-1);
    EXPECT(rc == 0 || rc == FMBD_ERR_NOMEM, "rc %d", rc);
    EXPECT(rc != 0 || D != NULL, "no output");
    fmbd_csr_destroy(&D);
  }
  fmbd_csr_destroy(&A);
  fmbd_csr_destroy(&B);
  fmbd_csr_destroy(&P);
  fmbd_csr_destroy(&C);
  fmbd_csr_destroy(&C);
  random_symmetry();
  TEST_EXIT();
}
