// tests/unit/t100-csr.c: CSR assembly, products, checks
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>

#include "check.h"
#include "fmbd.h"

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
  TEST_EXIT();
}
