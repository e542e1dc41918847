// tests/unit/t300-chol.c: CHOLMOD wrapper: solves, inertia counts, singular and indefinite input
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_chol.h"
#include "fmbd_csr.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "fmbd_log.h"
#include "t2_mesh.h"

// 1-D linear FE on n interior nodes (h = 1/(n+1)): K = tridiag(-1,2,-1)/h, M = tridiag(1,4,1)h/6;
// free = 1: n nodes with free ends (Neumann), K singular (constant mode)
static fmbd_csr *tridiag(int64_t n, double d, double o, double dend) {
  fmbd_csr *A = NULL;
  if (fmbd_csr_create(n, n, 3 * n, &A)) return NULL;
  int64_t k = 0;
  for (int64_t i = 0; i < n; i++) {
    A->indptr[i] = k;
    if (i > 0) A->indices[k] = i - 1, A->data[k++] = o;
    A->indices[k] = i, A->data[k++] = (i == 0 || i == n - 1) ? dend : d;
    if (i < n - 1) A->indices[k] = i + 1, A->data[k++] = o;
  }
  A->indptr[n] = k;
  return A;
}

// C = A (x) B (Kronecker product), rows sorted
static fmbd_csr *kron(const fmbd_csr *A, const fmbd_csr *B) {
  int64_t nb = B->nrows, N = A->nrows * nb;
  int64_t nnz = fmbd_csr_nnz(A) * fmbd_csr_nnz(B);
  fmbd_csr *C = NULL;
  if (fmbd_csr_create(N, N, nnz, &C)) return NULL;
  int64_t q = 0;
  for (int64_t i = 0; i < A->nrows; i++) {
    for (int64_t a = 0; a < nb; a++) {
      C->indptr[i * nb + a] = q;
      for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++)
        for (int64_t r = B->indptr[a]; r < B->indptr[a + 1]; r++) {
          C->indices[q] = A->indices[p] * nb + B->indices[r];
          C->data[q++] = A->data[p] * B->data[r];
        }
    }
  }
  C->indptr[N] = q;
  return C;
}

// C = A + B (same pattern: the Kronecker products below share theirs)
static void add_into(fmbd_csr *A, const fmbd_csr *B) {
  for (int64_t p = 0; p < fmbd_csr_nnz(A); p++) A->data[p] += B->data[p];
}

static int cmpd(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

// K and M kept as lower triangles (fmbd_csr_keep_lower, M on K's index arrays as fe2cb does):
// products, entries, the LL' solve and the LDL' count against the full storage
static void lower_storage(const fmbd_csr *K, const fmbd_csr *M, const double *ex) {
  int64_t n = K->nrows, nnz = fmbd_csr_nnz(K);
  fmbd_csr *Kl = NULL, *Ml = NULL;
  EXPECT(fmbd_csr_duplicate(K, &Kl) == 0 && fmbd_csr_duplicate(M, &Ml) == 0, "duplicate");
  // the same pattern (both Kronecker sums of tridiagonals): M on K's arrays
  fmbd_free(Ml->indptr);
  fmbd_free(Ml->indices);
  Ml->indptr = Kl->indptr;
  Ml->indices = Kl->indices;
  EXPECT(fmbd_csr_keep_lower(Kl, Ml) == 0 && Kl->lower && Ml->lower, "keep_lower");
  EXPECT(fmbd_csr_nnz(Kl) == (nnz + n) / 2, "lower nnz %lld of %lld", (long long)fmbd_csr_nnz(Kl),
         (long long)nnz);
  int64_t r = n / 2, c = K->indices[K->indptr[r]];  // the first entry of a row: left of it
  EXPECT(c < r && fmbd_csr_get(Kl, r, c) == fmbd_csr_get(K, r, c) &&
             fmbd_csr_get(Kl, c, r) == fmbd_csr_get(K, c, r) && fmbd_csr_get(K, c, r) != 0.0,
         "entries of the lower storage");
  // products: 11 columns (a block of 8 and 3 single ones); each sum has at most 27 terms, in
  // another order than the full product's: 27 eps |K| |x| bounds the difference (max norms)
  const int64_t nc = 11;
  double *X = fmbd_malloc((size_t)(n * nc) * sizeof(double));
  double *Y = fmbd_malloc((size_t)(n * nc) * sizeof(double));
  double *Z = fmbd_malloc((size_t)(n * nc) * sizeof(double));
  for (int64_t i = 0; i < n * nc; i++) X[i] = cos(0.71 * (double)i);
  const fmbd_csr *full[2] = {K, M}, *low[2] = {Kl, Ml};
  for (int t = 0; t < 2; t++) {
    double amax = fmbd_csr_max_abs(full[t]) * 27.0, e = 0.0;
    fmbd_csr_matmat(full[t], nc, X, n, Y, n);
    fmbd_csr_matmat(low[t], nc, X, n, Z, n);
    for (int64_t i = 0; i < n * nc; i++) e = fmax(e, fabs(Y[i] - Z[i]));
    EXPECT(e <= 27.0 * 2.2e-16 * amax, "lower-stored product %d differs by %.3g", t, e);
  }
  // every width of fmbd_csr_matmat's passes (16 and 8 columns, remainders, single columns) gives
  // the bits of one fmbd_csr_matvec per column in the same storage: each sum is added in the
  // same order whatever the number of columns a pass carries
  {
    const int64_t widths[] = {1, 4, 5, 6, 7, 8, 10, 11, 12, 13, 14, 16, 27, 35};
    double *X2 = fmbd_malloc((size_t)(n * 35) * sizeof(double));
    double *Y2 = fmbd_malloc((size_t)(n * 35) * sizeof(double));
    double *Z2 = fmbd_malloc((size_t)(n * 35) * sizeof(double));
    for (int64_t i = 0; i < n * 35; i++) X2[i] = sin(0.37 * (double)i + 0.1);
    for (int t = 0; t < 4; t++) {
      const fmbd_csr *A = t < 2 ? full[t] : low[t - 2];
      for (size_t wi = 0; wi < sizeof widths / sizeof widths[0]; wi++) {
        int64_t w = widths[wi];
        fmbd_csr_matmat(A, w, X2, n, Y2, n);
        for (int64_t k = 0; k < w; k++) fmbd_csr_matvec(A, X2 + k * n, Z2 + k * n);
        EXPECT(memcmp(Y2, Z2, (size_t)(n * w) * sizeof(double)) == 0,
               "matmat of %lld columns (matrix %d) against matvec per column", (long long)w, t);
      }
    }
    // fmbd_csr_matmat_pair: K and M on one pattern in memory (one pass for both, padded to 8
    // columns) and on two (two passes): the bits of matvec per column of each
    fmbd_csr *Ms = NULL;
    EXPECT(fmbd_csr_duplicate(M, &Ms) == 0, "duplicate");
    fmbd_free(Ms->indptr);
    fmbd_free(Ms->indices);
    Ms->indptr = K->indptr;
    Ms->indices = K->indices;
    double *W2 = fmbd_malloc((size_t)(n * 35) * sizeof(double));
    for (int t = 0; t < 2; t++) {
      const fmbd_csr *B = t ? M : Ms;
      for (size_t wi = 0; wi < sizeof widths / sizeof widths[0]; wi++) {
        int64_t w = widths[wi];
        bool same = true;
        fmbd_csr_matmat_pair(K, B, w, X2, n, Y2, W2, n);
        for (int64_t k = 0; k < w; k++) fmbd_csr_matvec(K, X2 + k * n, Z2 + k * n);
        same = same && memcmp(Y2, Z2, (size_t)(n * w) * sizeof(double)) == 0;
        for (int64_t k = 0; k < w; k++) fmbd_csr_matvec(M, X2 + k * n, Z2 + k * n);
        same = same && memcmp(W2, Z2, (size_t)(n * w) * sizeof(double)) == 0;
        EXPECT(same, "matmat_pair of %lld columns (%s) against matvec per column", (long long)w,
               t ? "two patterns" : "one pattern");
      }
    }
    Ms->indptr = Ms->indices = NULL;  // K's
    fmbd_csr_destroy(&Ms);
    fmbd_free(W2);
    fmbd_free(X2);
    fmbd_free(Y2);
    fmbd_free(Z2);
  }
  // fmbd_csr_matmat_rows4 (4 columns row-major in and out): the bits of matvec per column, in
  // both storages; fmbd_chol_apply_op (the block Lanczos' operator L^-1 P M P' L^-T in one
  // call, with the own solve's rows of 4 kept from sweep to sweep at 2-4 columns): the bits of
  // its parts called one after the other (the same operations in the same order), for every
  // width around the own path's 2-4, the own solve on and off, M full and lower-stored, and
  // leading dimensions above n
  {
    const int64_t ld = n + 5, wmax = 6;
    double *xt = fmbd_malloc((size_t)(n * 4) * sizeof(double));
    double *yt = fmbd_malloc((size_t)(n * 4) * sizeof(double));
    double *R = fmbd_malloc((size_t)(ld * wmax) * sizeof(double));
    double *W = fmbd_malloc((size_t)(ld * wmax) * sizeof(double));
    double *S = fmbd_malloc((size_t)(n * wmax) * sizeof(double));
    for (int t = 0; t < 4; t++) {
      const fmbd_csr *A = t < 2 ? full[t] : low[t - 2];
      for (int64_t i = 0; i < n; i++)
        for (int k = 0; k < 4; k++) xt[i * 4 + k] = X[i + k * n];
      fmbd_csr_matmat_rows4(A, xt, yt);
      bool same = true;
      for (int k = 0; k < 4; k++) {
        fmbd_csr_matvec(A, X + k * n, Z);
        for (int64_t i = 0; i < n; i++) same = same && yt[i * 4 + k] == Z[i];
      }
      EXPECT(same, "matmat_rows4 (matrix %d) against matvec per column", t);
    }
    fmbd_chol *Fo = NULL;
    EXPECT(fmbd_chol_create_llt(K, &Fo) == 0, "LL' for the operator");
    for (int own = 0; Fo && own < 2; own++) {
      fmbd_chol_set_own_solve(Fo, own);
      for (int t = 0; t < 2; t++) {
        const fmbd_csr *Mo = t ? Ml : M;
        for (int64_t w = 1; w <= wmax; w++) {
          for (int64_t i = 0; i < ld * wmax; i++) W[i] = R[i] = -1.0;
          for (int64_t k = 0; k < w; k++) memcpy(S + k * n, X + k * n, (size_t)n * sizeof(double));
          fmbd_chol_stats st0, st1;
          fmbd_chol_get_stats(Fo, &st0);
          double tm = 0.0;
          int rc = fmbd_chol_apply_op(Fo, Mo, w, X, n, W, ld, S, &tm);
          fmbd_chol_get_stats(Fo, &st1);
          for (int64_t k = 0; k < w; k++) memcpy(S + k * n, X + k * n, (size_t)n * sizeof(double));
          rc = rc ? rc : fmbd_chol_solve_half(Fo, FMBD_CHOL_BWD, w, S, n);
          fmbd_csr_matmat(Mo, w, S, n, R, ld);
          rc = rc ? rc : fmbd_chol_solve_half(Fo, FMBD_CHOL_FWD, w, R, ld);
          EXPECT(rc == 0 && memcmp(W, R, (size_t)(ld * wmax) * sizeof(double)) == 0 &&
                     st1.n_solves == st0.n_solves + w && tm >= 0.0,
                 "apply_op of %lld columns (own %d, M %s) against its parts", (long long)w, own,
                 t ? "lower" : "full");
        }
      }
    }
    fmbd_chol_destroy(&Fo);
    fmbd_free(xt);
    fmbd_free(yt);
    fmbd_free(R);
    fmbd_free(W);
    fmbd_free(S);
  }
  // LL' solve: the factor reads the lower triangle in both storages: the same solution
  fmbd_chol *F1 = NULL, *F2 = NULL;
  EXPECT(fmbd_chol_create_llt(K, &F1) == 0 && fmbd_chol_create_llt(Kl, &F2) == 0, "LL'");
  memcpy(Y, X, (size_t)(n * nc) * sizeof(double));
  memcpy(Z, X, (size_t)(n * nc) * sizeof(double));
  EXPECT(fmbd_chol_solve(F1, nc, Y, n) == 0 && fmbd_chol_solve(F2, nc, Z, n) == 0, "solves");
  EXPECT(memcmp(Y, Z, (size_t)(n * nc) * sizeof(double)) == 0, "LL' solves of the two storages");
  // solves by 3 columns (fmbd_chol_set_solve_width) after the workspaces were freed: the same
  // solutions to round-off (the BLAS kernels block differently; the backward error of either is
  // a few eps: 1e-13 relative to |X| leaves a wide margin), the same count
  fmbd_chol_stats s1, s2;
  fmbd_chol_get_stats(F2, &s1);
  fmbd_chol_release_workspace(F2);
  fmbd_chol_set_solve_width(F2, 3);
  memcpy(Z, X, (size_t)(n * nc) * sizeof(double));
  EXPECT(fmbd_chol_solve(F2, nc, Z, n) == 0, "solve by 3 columns");
  fmbd_chol_get_stats(F2, &s2);
  double ew = 0.0, yw = 0.0;
  for (int64_t i = 0; i < n * nc; i++) ew = fmax(ew, fabs(Y[i] - Z[i])), yw = fmax(yw, fabs(Y[i]));
  EXPECT(ew <= 1e-13 * yw && s2.n_solves == s1.n_solves + nc, "solve by 3 columns differs by %.3g",
         ew / yw);
  // values dropped with their block kept (fmbd_chol_drop_numeric_keep): a solve factors again
  // (the kept block freed: one owner), the same solution
  fmbd_chol_destroy(&F1);
  EXPECT(fmbd_chol_create_llt(Kl, &F1) == 0 && fmbd_chol_drop_numeric_keep(F1, 0) == 0, "keep");
  memcpy(Z, X, (size_t)(n * nc) * sizeof(double));
  EXPECT(F1 && fmbd_chol_solve(F1, nc, Z, n) == 0 &&
             memcmp(Y, Z, (size_t)(n * nc) * sizeof(double)) == 0,
         "solve after the values were dropped (block kept) differs");
  fmbd_chol_destroy(&F1);
  // Sturm counts: exact, from the lower storage (assembled before the supernodal loop); Fk
  // factors into F2's LL' block (fmbd_chol_analyze_like after fmbd_chol_drop_numeric_keep, 3
  // pages of it given back): the same counts
  fmbd_chol *Fs = NULL, *Fk = NULL;
  EXPECT(fmbd_chol_analyze(Kl, Ml, FMBD_CHOL_LDLT, &Fs) == 0, "LDL' analyse");
  EXPECT(fmbd_chol_drop_numeric_keep(F2, 3 * 4096) == 0 &&
             fmbd_chol_analyze_like(F2, Kl, Ml, FMBD_CHOL_LDLT, &Fk) == 0,
         "LDL' analyse like the LL', into its block");
  fmbd_chol_destroy(&F2);
  int64_t idx[] = {1, 30, 700, 1200};
  for (size_t t = 0; Fs && Fk && t < sizeof idx / sizeof idx[0]; t++) {
    int64_t k = idx[t];
    while (k < n && ex[k] - ex[k - 1] < 1e-9 * ex[k]) k++;
    double sgm = 0.5 * (ex[k - 1] + ex[k]);
    EXPECT(fmbd_chol_factor(Fs, sgm) == 0 && fmbd_chol_negative_pivots(Fs) == k,
           "lower-stored count below %.6g: %lld, exact %lld", sgm,
           (long long)fmbd_chol_negative_pivots(Fs), (long long)k);
    EXPECT(fmbd_chol_factor(Fk, sgm) == 0 && fmbd_chol_negative_pivots(Fk) == k,
           "count below %.6g in the LL' block: %lld, exact %lld", sgm,
           (long long)fmbd_chol_negative_pivots(Fk), (long long)k);
  }
  fmbd_chol_destroy(&Fs);
  fmbd_chol_destroy(&Fk);
  Ml->indptr = Ml->indices = NULL;  // Kl's
  fmbd_csr_destroy(&Ml);
  fmbd_csr_destroy(&Kl);
  fmbd_free(X);
  fmbd_free(Y);
  fmbd_free(Z);
}

// The library's own narrow-block supernodal solves (fmbd_chol_set_own_solve; used for blocks of
// 2 to 8 right-hand sides where the processor has AVX2 and FMA, 9 to 16 where it has AVX-512,
// 17 to 24 there where the solve width asks for them)
// against CHOLMOD's on the same factor: the full solve and both halves, every width 1..25 (the
// kernels' cases: 4-wide rows by one or two vectors, AVX-512 by chunks of 4 columns, groups of
// fewer than 4 columns and rows not a multiple of 8), a leading dimension above n, and
// the columns beyond the block untouched. Both are the same substitutions with the sums in
// another order; each triangular solve is backward stable with |dL| <= gamma_k |L|, k <= n
// the length of the longest sum (Higham, Accuracy and Stability of Numerical Algorithms, 2nd
// ed., Theorem 8.5), so two of them differ by at most about 2 n eps cond(L) in norm relative
// to the solution, cond(L) = sqrt(cond(A)) for a half and cond(A) for the full solve (A = L L').
// cond2(A) comes from A's exact eigenvalues (lam_min, lam_max).
static void own_solves(const fmbd_csr *A, double lam_min, double lam_max, const char *what) {
  int64_t n = A->nrows;
  const int64_t ld = n + 3, wmax = 25;
  fmbd_chol *F = NULL;
  EXPECT(fmbd_chol_create_llt(A, &F) == 0, "%s: LL'", what);
  if (!F) return;
  double *B = fmbd_malloc((size_t)(ld * (wmax + 1)) * sizeof(double));
  double *X = fmbd_malloc((size_t)(ld * (wmax + 1)) * sizeof(double));
  double *Y = fmbd_malloc((size_t)(ld * (wmax + 1)) * sizeof(double));
  for (int64_t i = 0; i < ld * (wmax + 1); i++)
    B[i] = sin(0.37 * (double)i) + 0.1 * cos(1.3 * (double)i);
  double cond = lam_max / lam_min, eps = 2.2e-16;
  // solve width 6 (calls of at most 6 columns: blocks of 7..25 split into nearly equal own
  // calls of 4 to 6), the default (64: one own call up to 16 columns, CHOLMOD's above) and 24
  // (one own call up to 24 columns with AVX-512)
  const int64_t sws[3] = {0, 6, 24};
  for (int si = 0; si < 3; si++)
    for (int64_t w = 1; w <= wmax; w++) {
      int64_t sw = sws[si];
      fmbd_chol_set_solve_width(F, sw);
      for (int kind = 0; kind < 3; kind++) {  // full solve, forward half, backward half
        double *out[2] = {X, Y};
        for (int own = 0; own < 2; own++) {
          fmbd_chol_set_own_solve(F, own);
          memcpy(out[own], B, (size_t)(ld * (wmax + 1)) * sizeof(double));
          int rc = kind == 0 ? fmbd_chol_solve(F, w, out[own], ld)
                             : fmbd_chol_solve_half(F, kind == 1 ? FMBD_CHOL_FWD : FMBD_CHOL_BWD, w,
                                                    out[own], ld);
          EXPECT(rc == 0, "%s: solve %d width %lld own %d: rc %d", what, kind, (long long)w, own,
                 rc);
        }
        double bound = 2.0 * (double)n * eps * (kind == 0 ? cond : sqrt(cond));
        for (int64_t c = 0; c < w; c++) {
          double e = 0.0, xm = 0.0;
          for (int64_t i = 0; i < n; i++) {
            e = fmax(e, fabs(X[i + c * ld] - Y[i + c * ld]));
            xm = fmax(xm, fabs(X[i + c * ld]));
          }
          EXPECT(e <= bound * xm,
                 "%s: solve %d width %lld column %lld: own and CHOLMOD's differ by "
                 "%.3g of %.3g (bound %.3g)",
                 what, kind, (long long)w, (long long)c, e, xm, bound * xm);
        }
        // the padding rows and the columns after the block are not touched
        int same = 1;
        for (int64_t c = 0; c <= wmax; c++) {
          for (int64_t i = c < w ? n : 0; i < ld; i++)
            same = same && Y[i + c * ld] == B[i + c * ld];
        }
        EXPECT(same, "%s: solve %d width %lld wrote outside the block", what, kind, (long long)w);
      }
    }
  // with AVX-512, each column's result does not depend on the own solve's width: 23 columns in
  // one pass (width 24) are the bits of 12 + 11 (width 12) and of 8 + 8 + 7 (width 9) (fe2cb's
  // Ritz vectors' back solve; the 4-column AVX2 kernels sum in another order)
  fmbd_chol_set_own_solve(F, true);
  for (int kind = 0; kind < 2 && fmbd_chol_own_width(F) == 24; kind++) {
    const int64_t sw3[3] = {24, 12, 9};
    double *out[3] = {X, Y, B};
    double *B0 = fmbd_malloc((size_t)(ld * 23) * sizeof(double));
    for (int64_t i = 0; i < ld * 23; i++)
      B0[i] = sin(0.37 * (double)i) + 0.1 * cos(1.3 * (double)i);
    for (int k = 0; k < 3; k++) {
      fmbd_chol_set_solve_width(F, sw3[k]);
      memcpy(out[k], B0, (size_t)(ld * 23) * sizeof(double));
      int rc = kind == 0 ? fmbd_chol_solve(F, 23, out[k], ld)
                         : fmbd_chol_solve_half(F, FMBD_CHOL_BWD, 23, out[k], ld);
      EXPECT(rc == 0, "%s: 23 columns by width %lld: rc %d", what, (long long)sw3[k], rc);
    }
    EXPECT(memcmp(X, Y, (size_t)(ld * 23) * sizeof(double)) == 0 &&
               memcmp(X, B, (size_t)(ld * 23) * sizeof(double)) == 0,
           "%s: 23 columns (%s): widths 24, 12 and 4 give other bits", what,
           kind ? "backward half" : "full solve");
    for (int64_t i = 0; i < ld * (wmax + 1); i++)
      B[i] = sin(0.37 * (double)i) + 0.1 * cos(1.3 * (double)i);
    fmbd_free(B0);
  }
  fmbd_chol_set_solve_width(F, 0);
  // the full solve's backward error, as for CHOLMOD's below: a small multiple of eps
  memcpy(Y, B, (size_t)(ld * 4) * sizeof(double));
  EXPECT(fmbd_chol_solve(F, 4, Y, ld) == 0, "%s: solve", what);
  double amax = 0.0;
  for (int64_t i = 0; i < n; i++) {
    double r = 0.0;
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) r += fabs(A->data[p]);
    amax = fmax(amax, r);
  }
  for (int64_t c = 0; c < 4; c++) {
    fmbd_csr_matvec(A, Y + c * ld, X);
    double e = 0.0, xm = 0.0, bm = 0.0;
    for (int64_t i = 0; i < n; i++) {
      e = fmax(e, fabs(X[i] - B[i + c * ld]));
      xm = fmax(xm, fabs(Y[i + c * ld]));
      bm = fmax(bm, fabs(B[i + c * ld]));
    }
    EXPECT(e / (amax * xm + bm) <= 1e-14, "%s: own solve, column %lld: backward error %.3g", what,
           (long long)c, e / (amax * xm + bm));
  }
  fmbd_chol_destroy(&F);
  fmbd_free(B);
  fmbd_free(X);
  fmbd_free(Y);
}

// the supernodal LDL' count against the simplicial one and the exact count, on a 3-D
// Laplacian (K3 = K(x)M(x)M + M(x)K(x)M + M(x)M(x)K, M3 = M(x)M(x)M): real supernodes
// The 3-D Laplacian pencil (K3, M3) of inertia_3d and own_llt on m^3 interior nodes, spacing h:
// K3 and M3 share the sine eigenvectors (tridiagonal Toeplitz factors: k_i = (2 - 2 cos(i pi h))
// / h, m_i = h (4 + 2 cos(i pi h)) / 6), so the eigenvalues of K3 - sigma M3 are k - sigma m over
// the products; their extremes in *lmin, *lmax, and the pencil's first eigenvalue in *lam1
static void k3_spectrum(int64_t m, double h, double sigma, double *lmin, double *lmax,
                        double *lam1) {
  *lmin = INFINITY, *lmax = 0.0, *lam1 = INFINITY;
  for (int64_t i = 1; i <= m; i++)
    for (int64_t j = 1; j <= m; j++)
      for (int64_t l = 1; l <= m; l++) {
        double kk[3], mm[3];
        int64_t ijl[3] = {i, j, l};
        for (int t = 0; t < 3; t++) {
          double c = cos((double)ijl[t] * M_PI * h);
          kk[t] = (2.0 - 2.0 * c) / h;
          mm[t] = h * (4.0 + 2.0 * c) / 6.0;
        }
        double ek = kk[0] * mm[1] * mm[2] + mm[0] * kk[1] * mm[2] + mm[0] * mm[1] * kk[2];
        double em = mm[0] * mm[1] * mm[2];
        *lam1 = fmin(*lam1, ek / em);
        *lmin = fmin(*lmin, ek - sigma * em);
        *lmax = fmax(*lmax, ek - sigma * em);
      }
}

// The 3-D Laplacian pencil on the unit cube's m^3 interior grid (linear elements of size h):
// K3 = K (x) M (x) M + M (x) K (x) M + M (x) M (x) K and M3 = M (x) M (x) M, from the 1-D
// stiffness K and mass M; the sine vectors are eigenvectors of both (k3_spectrum)
static void laplace3(int64_t m, double h, fmbd_csr **K3, fmbd_csr **M3) {
  fmbd_csr *K = tridiag(m, 2.0 / h, -1.0 / h, 2.0 / h),
           *M = tridiag(m, 4 * h / 6, h / 6, 4 * h / 6);
  fmbd_csr *KM = kron(K, M), *MM = kron(M, M);
  fmbd_csr *t1 = kron(M, KM), *t2 = kron(MM, K);
  *K3 = kron(K, MM);
  *M3 = kron(M, MM);
  add_into(*K3, t1);
  add_into(*K3, t2);
  fmbd_csr *tmp[] = {K, M, KM, MM, t1, t2};
  for (size_t t = 0; t < sizeof tmp / sizeof tmp[0]; t++) fmbd_csr_destroy(&tmp[t]);
}

static void inertia_3d(void) {
  const int64_t m = 11;
  const double h = 1.0 / (double)(m + 1);
  fmbd_csr *K3 = NULL, *M3 = NULL;
  laplace3(m, h, &K3, &M3);
  int64_t n = m * m * m;
  double *ex = malloc((size_t)n * sizeof(double));
  for (int64_t i = 0; i < m; i++)
    for (int64_t j = 0; j < m; j++)
      for (int64_t k = 0; k < m; k++) {
        double l[3];
        int64_t ijk[3] = {i, j, k};
        for (int t = 0; t < 3; t++) {
          double c = cos((double)(ijk[t] + 1) * M_PI * h);
          l[t] = 6.0 / (h * h) * (1 - c) / (2 + c);
        }
        ex[(i * m + j) * m + k] = l[0] + l[1] + l[2];
      }
  qsort(ex, (size_t)n, sizeof(double), cmpd);
  // K3's own extreme eigenvalues, for own_solves' bound
  double kmin, kmax, lam1_k3;
  k3_spectrum(m, h, 0.0, &kmin, &kmax, &lam1_k3);
  own_solves(K3, kmin, kmax, "3-D Laplacian");
  fmbd_chol *Fs = NULL, *Fp = NULL;
  int rc = fmbd_chol_analyze(K3, M3, FMBD_CHOL_LDLT, &Fs);
  rc = rc ? rc : fmbd_chol_analyze(K3, M3, FMBD_CHOL_LDLT_SIMPLICIAL, &Fp);
  EXPECT(rc == 0, "3-D analyse: rc %d", rc);
  int64_t idx[] = {1, 5, 30, 200, 700, 1200};
  for (size_t t = 0; rc == 0 && t < sizeof idx / sizeof idx[0]; t++) {
    int64_t k = idx[t];
    while (k < n && ex[k] - ex[k - 1] < 1e-9 * ex[k]) k++;  // a shift between distinct values
    double sgm = 0.5 * (ex[k - 1] + ex[k]);
    int r1 = fmbd_chol_factor(Fs, sgm), r2 = fmbd_chol_factor(Fp, sgm);
    EXPECT(r1 == 0 && r2 == 0 && fmbd_chol_negative_pivots(Fs) == k &&
               fmbd_chol_negative_pivots(Fp) == k,
           "3-D count below %.6g: supernodal %lld, simplicial %lld, exact %lld", sgm,
           (long long)fmbd_chol_negative_pivots(Fs), (long long)fmbd_chol_negative_pivots(Fp),
           (long long)k);
  }
  fmbd_chol_destroy(&Fs);
  fmbd_chol_destroy(&Fp);
  lower_storage(K3, M3, ex);
  free(ex);
  fmbd_csr_destroy(&K3);
  fmbd_csr_destroy(&M3);
}

// fmbd_chol_set_input_hook: the caller's matrix arrays dropped once the input is formed
static int g_hook_calls;
static double *g_hook_saved;
static void drop_values(void *ctx) {
  fmbd_csr *A = ctx;
  g_hook_calls++;
  g_hook_saved = A->data;
  A->data = NULL;  // a read after this point would crash (and ASan would name it)
}

// One dense supernode of 700 columns: A_ij = min(i, j) (i, j = 1..n), eigenvalues
// 1 / (4 sin^2((2k - 1) pi / (4n + 2))), k = 1..n (its inverse is the second-difference
// matrix). Exercises what small supernodes do not: the diagonal blocks' upper-triangle pages
// given back after the LL' (columns of more than a page above the diagonal), the LDL''s
// trailing updates by column blocks of 128 (gemm_lower), and the input hook.
static void dense_supernode(void) {
  const int64_t n = 700;
  fmbd_csr *A = NULL, *Al = NULL;
  EXPECT(fmbd_csr_create(n, n, n * n, &A) == 0, "allocation");
  for (int64_t i = 0; i < n; i++) {
    A->indptr[i] = i * n;
    for (int64_t j = 0; j < n; j++) {
      A->indices[i * n + j] = j;
      A->data[i * n + j] = (double)((i < j ? i : j) + 1);
    }
  }
  A->indptr[n] = n * n;
  double *ex = malloc((size_t)n * sizeof(double));
  for (int64_t k = 1; k <= n; k++) {
    double sn = sin((double)(2 * k - 1) * M_PI / (double)(4 * n + 2));
    ex[k - 1] = 1.0 / (4.0 * sn * sn);
  }
  qsort(ex, (size_t)n, sizeof(double), cmpd);
  own_solves(A, ex[0], ex[n - 1], "dense supernode");
  // LL' solve: backward error at round-off (|A|_inf <= n^2), the hook called once, A's values
  // not read after it
  fmbd_chol *F = NULL;
  EXPECT(fmbd_chol_analyze(A, NULL, FMBD_CHOL_LLT, &F) == 0, "dense analyse");
  g_hook_calls = 0;
  fmbd_chol_set_input_hook(drop_values, A);
  int rc = F ? fmbd_chol_factor(F, 0.0) : -1;
  fmbd_chol_set_input_hook(NULL, NULL);
  EXPECT(rc == 0 && g_hook_calls == 1, "dense LL': rc %d, hook called %d times", rc, g_hook_calls);
  if (g_hook_calls) A->data = g_hook_saved;
  double *x = malloc((size_t)n * sizeof(double)), *b = malloc((size_t)n * sizeof(double)),
         *r = malloc((size_t)n * sizeof(double));
  for (int64_t i = 0; i < n; i++) b[i] = x[i] = cos(0.3 * (double)i);
  EXPECT(rc == 0 && fmbd_chol_solve(F, 1, x, n) == 0, "dense solve");
  fmbd_csr_matvec(A, x, r);
  double e = 0.0, xm = 0.0;
  for (int64_t i = 0; i < n; i++) e = fmax(e, fabs(r[i] - b[i])), xm = fmax(xm, fabs(x[i]));
  // normwise backward error |A x - b| / (|A| |x| + |b|), |A|_inf = n (n + 1) / 2: a
  // backward-stable solve gives a small multiple of eps (cond(A) ~ 2e5 does not enter)
  double be = e / (0.5 * (double)(n * (n + 1)) * xm + 1.0);
  EXPECT(be <= 1e-14, "dense LL' backward error %.3g", be);
  // values dropped (fmbd_chol_drop_numeric): the next solve factors again, the same solution
  double *y = malloc((size_t)n * sizeof(double));
  memcpy(y, b, (size_t)n * sizeof(double));
  EXPECT(F && fmbd_chol_drop_numeric(F) == 0 && fmbd_chol_solve(F, 1, y, n) == 0 &&
             memcmp(x, y, (size_t)n * sizeof(double)) == 0,
         "solve after the values were dropped differs");
  free(y);
  fmbd_chol_destroy(&F);
  // LDL' counts from the lower storage (prefilled, the hook after it) against the exact ones
  EXPECT(fmbd_csr_duplicate(A, &Al) == 0 && fmbd_csr_keep_lower(Al, NULL) == 0, "lower copy");
  fmbd_csr *I = NULL;
  EXPECT(fmbd_csr_create(n, n, n, &I) == 0, "identity");
  for (int64_t i = 0; i < n; i++) I->indptr[i] = i, I->indices[i] = i, I->data[i] = 1.0;
  I->indptr[n] = n;
  fmbd_chol *Fs = NULL;
  EXPECT(fmbd_chol_analyze(Al, I, FMBD_CHOL_LDLT, &Fs) == 0, "dense LDL' analyse");
  int64_t idx[] = {1, 10, 350, 699};
  for (size_t t = 0; Fs && t < sizeof idx / sizeof idx[0]; t++) {
    int64_t k = idx[t];
    double sgm = 0.5 * (ex[k - 1] + ex[k]);
    g_hook_calls = 0;
    fmbd_chol_set_input_hook(drop_values, Al);
    rc = fmbd_chol_factor(Fs, sgm);
    fmbd_chol_set_input_hook(NULL, NULL);
    if (g_hook_calls) Al->data = g_hook_saved;
    EXPECT(rc == 0 && g_hook_calls == 1 && fmbd_chol_negative_pivots(Fs) == k,
           "dense count below %.6g: %lld, exact %lld (hook %d)", sgm,
           (long long)fmbd_chol_negative_pivots(Fs), (long long)k, g_hook_calls);
  }
  fmbd_chol_destroy(&Fs);
  fmbd_csr_destroy(&I);
  fmbd_csr_destroy(&Al);
  fmbd_csr_destroy(&A);
  free(ex);
  free(x);
  free(b);
  free(r);
}

// A = L D L' with L the unit lower triangle of ones, so A_ij = D_0 + ... + D_min(i,j), on one
// dense supernode of n = 100 columns (the LDL' panel's recursion several levels deep). In the
// natural order every operation of the LDL' is on small integers, exact: D comes back exactly,
// and a zero in D (at row 70, in the panel's right half) must stop the factorisation there.
// In CHOLMOD's own ordering the pivots are not exact, but Sylvester's law fixes their signs'
// count: the number of -1 in D.
static void exact_pivots(void) {
  const int64_t n = 100, zero_at = 70;
  double *D = malloc((size_t)n * sizeof(double));
  int64_t nneg = 0;
  for (int64_t k = 0; k < n; k++) {
    D[k] = (k % 3 == 1) ? -1.0 : 1.0;
    nneg += D[k] < 0.0;
  }
  int64_t *ident = malloc((size_t)n * sizeof(int64_t));
  for (int64_t k = 0; k < n; k++) ident[k] = k;
  for (int pass = 0; pass < 2; pass++) {
    // pass 0: D as above; pass 1: D[zero_at] = 0
    double d70 = D[zero_at];
    if (pass == 1) D[zero_at] = 0.0;
    fmbd_csr *A = NULL;
    EXPECT(fmbd_csr_create(n, n, n * n, &A) == 0, "allocation");
    for (int64_t i = 0; i < n; i++) {
      A->indptr[i] = i * n;
      for (int64_t j = 0; j < n; j++) {
        double v = 0.0;
        for (int64_t k = 0; k <= (i < j ? i : j); k++) v += D[k];
        A->indices[i * n + j] = j;
        A->data[i * n + j] = v;
      }
    }
    A->indptr[n] = n * n;
    fmbd_chol *F = NULL;
    EXPECT(fmbd_chol_analyze_perm(A, NULL, FMBD_CHOL_LDLT, ident, &F) == 0, "natural analyse");
    int rc = F ? fmbd_chol_factor(F, 0.0) : -1;
    if (pass == 0) {
      EXPECT(rc == 0 && fmbd_chol_negative_pivots(F) == nneg, "natural order: rc %d, %lld of %lld",
             rc, (long long)(F ? fmbd_chol_negative_pivots(F) : -1), (long long)nneg);
      fmbd_chol_destroy(&F);
      EXPECT(fmbd_chol_analyze(A, NULL, FMBD_CHOL_LDLT, &F) == 0, "analyse");
      rc = F ? fmbd_chol_factor(F, 0.0) : -1;
      EXPECT(rc == 0 && fmbd_chol_negative_pivots(F) == nneg, "own order: rc %d, %lld of %lld", rc,
             (long long)(F ? fmbd_chol_negative_pivots(F) : -1), (long long)nneg);
    } else {
      EXPECT(rc == FMBD_ERR_SINGULAR && F && fmbd_chol_failed_row(F) == zero_at,
             "zero pivot: rc %d at row %lld, expected %lld", rc,
             (long long)(F ? fmbd_chol_failed_row(F) : -1), (long long)zero_at);
    }
    fmbd_chol_destroy(&F);
    fmbd_csr_destroy(&A);
    D[zero_at] = d70;
  }
  free(D);
  free(ident);
}

// --- the library's own supernodal LL' against CHOLMOD's ------------------------------------
// Both factor the same P (A - sigma B) P' on the same symbolic factor (the same ordering), so
// their value blocks have one layout and can be compared entry by entry. Each is backward
// stable: L L' = A + dA with |dA| <= gamma_{c+1} |L| |L'| (c + 1 <= n the longest sum; Higham,
// Accuracy and Stability of Numerical Algorithms, 2nd ed., Theorem 10.3), and ||dA||_F <=
// gamma_n || |L| |L'| ||_F <= gamma_n ||L||_F^2 = gamma_n trace(A) (Cauchy-Schwarz). The
// Cholesky factor's perturbation bound (ibid. Theorem 10.8, to first order) ||dL||_F <=
// 2^-1/2 ||L||_2 ||A^-1||_2 ||dA||_F, for each computed factor against the exact one, gives
//   ||L_own - L_cholmod||_F <= sqrt(2) gamma_n trace(A) sqrt(lmax) / lmin
// (||L||_2 = sqrt(lmax)), lmin and lmax the extreme eigenvalues of A - sigma B. The upper
// triangles of the diagonal blocks are zero in both (never written), so the blocks compare
// whole. The same matrix stored in full and as its lower triangle (the two assembly paths).
static double llt_pair(const fmbd_csr *A, const fmbd_csr *B, double sigma, double lmin, double lmax,
                       const char *what) {
  int64_t n = A->nrows;
  fmbd_chol *F1 = NULL, *F2 = NULL;
  int64_t *perm = malloc((size_t)n * sizeof(int64_t));
  EXPECT(fmbd_chol_analyze(A, B, FMBD_CHOL_LLT, &F1) == 0 && fmbd_chol_get_perm(F1, perm) == 0 &&
             fmbd_chol_analyze_perm(A, B, FMBD_CHOL_LLT, perm, &F2) == 0,
         "%s: analyse", what);
  free(perm);
  double rel = INFINITY;
  if (!F1 || !F2) goto done;
  fmbd_chol_set_own_llt(F1, true);
  fmbd_chol_set_own_llt(F2, false);
  int rc1 = fmbd_chol_factor(F1, sigma), rc2 = fmbd_chol_factor(F2, sigma);
  EXPECT(rc1 == 0 && rc2 == 0, "%s: factor: own %d, CHOLMOD %d", what, rc1, rc2);
  int64_t n1 = 0, n2 = 0;
  const double *x1 = fmbd_chol_values(F1, &n1), *x2 = fmbd_chol_values(F2, &n2);
  EXPECT(x1 && x2 && n1 == n2 && n1 > 0, "%s: value blocks %lld and %lld", what, (long long)n1,
         (long long)n2);
  if (!x1 || !x2 || n1 != n2) goto done;
  double d = 0.0, l = 0.0, tr = 0.0;
  for (int64_t k = 0; k < n1; k++) {
    d += (x1[k] - x2[k]) * (x1[k] - x2[k]);
    l += x2[k] * x2[k];
  }
  for (int64_t i = 0; i < n; i++)
    tr += fmbd_csr_get(A, i, i) - sigma * (B ? fmbd_csr_get(B, i, i) : 0.0);
  double eps = 0x1p-53, gam = (double)n * eps / (1.0 - (double)n * eps);
  double bound = sqrt(2.0) * gam * tr * sqrt(lmax) / lmin;
  rel = sqrt(d / l);
  EXPECT(sqrt(d) <= bound, "%s: ||L_own - L_cholmod||_F = %.3g, bound %.3g (||L||_F %.3g)", what,
         sqrt(d), bound, sqrt(l));
  EXPECT(fabs(l - tr) <= 1e-12 * tr, "%s: ||L||_F^2 %.17g against trace %.17g", what, l, tr);
  // the own factor serves CHOLMOD's solves and the library's own: one residual each
  double *b = malloc((size_t)(4 * n) * sizeof(double)),
         *y = malloc((size_t)(4 * n) * sizeof(double));
  for (int64_t i = 0; i < 4 * n; i++) b[i] = y[i] = sin(0.37 * (double)i) + 0.1;
  for (int own = 0; own < 2; own++) {
    fmbd_chol_set_own_solve(F1, own);
    memcpy(y, b, (size_t)(4 * n) * sizeof(double));
    EXPECT(fmbd_chol_solve(F1, 4, y, n) == 0, "%s: solve", what);
    memcpy(b + n, y, (size_t)n * sizeof(double));  // x of the first column
    double e = 0.0, xm = 0.0, bm = 0.0;
    double *r = y + n;  // A x - sigma B x into the second column's place
    fmbd_csr_matvec(A, b + n, r);
    if (B && sigma != 0.0) {
      double *s = y + 2 * n;
      fmbd_csr_matvec(B, b + n, s);
      for (int64_t i = 0; i < n; i++) r[i] -= sigma * s[i];
    }
    for (int64_t i = 0; i < n; i++) {
      double b0 = sin(0.37 * (double)i) + 0.1;
      e = fmax(e, fabs(r[i] - b0));
      xm = fmax(xm, fabs(b[n + i]));
      bm = fmax(bm, fabs(b0));
    }
    // normwise backward error |A x - b| / (|A| |x| + |b|), |A|_inf <= n lmax... bounded here
    // by lmax sqrt(n) (|A|_inf <= sqrt(n) |A|_2): a backward-stable solve gives a modest
    // multiple of gamma_n
    EXPECT(e / (sqrt((double)n) * lmax * xm + bm) <= 4.0 * gam,
           "%s: solve with our factor (own solve %d): backward error %.3g", what, own,
           e / (sqrt((double)n) * lmax * xm + bm));
    for (int64_t i = 0; i < 4 * n; i++) b[i] = sin(0.37 * (double)i) + 0.1;
  }
  free(b);
  free(y);
done:
  fmbd_chol_destroy(&F1);
  fmbd_chol_destroy(&F2);
  return rel;
}

// a matrix that is not positive definite: our LL' and CHOLMOD's stop at the same pivot with
// the same message (fe2cb's rigid-mode message and fmbd_eig's shifts read failed_row)
static void llt_fail_pair(const fmbd_csr *A, const fmbd_csr *B, double sigma, const char *what) {
  char msg[2][1100];
  int64_t row[2] = {-2, -2};
  int rc[2] = {0, 0};
  for (int own = 0; own < 2; own++) {
    fmbd_chol *F = NULL;
    EXPECT(fmbd_chol_analyze(A, B, FMBD_CHOL_LLT, &F) == 0, "%s: analyse", what);
    if (!F) return;
    fmbd_chol_set_own_llt(F, own);
    rc[own] = fmbd_chol_factor(F, sigma);
    row[own] = fmbd_chol_failed_row(F);
    snprintf(msg[own], sizeof msg[own], "%s", fmbd_err_get()->msg);
    // the object factors again at a valid shift (below every eigenvalue)
    if (B) EXPECT(fmbd_chol_factor(F, -1.0) == 0, "%s: refactor after failure", what);
    fmbd_chol_destroy(&F);
  }
  EXPECT(rc[0] == FMBD_ERR_SINGULAR && rc[1] == FMBD_ERR_SINGULAR && row[0] == row[1] &&
             row[0] >= 0 && strcmp(msg[0], msg[1]) == 0,
         "%s: CHOLMOD rc %d row %lld \"%s\", own rc %d row %lld \"%s\"", what, rc[0],
         (long long)row[0], msg[0], rc[1], (long long)row[1], msg[1]);
}

static void own_llt(void) {
  // 3-D Laplacian (inertia_3d's): K3 and M3 share the sine eigenvectors, so the eigenvalues of
  // K3 - sigma M3 are k - sigma m over the products of the 1-D k_i and m_i
  const int64_t m = 11;
  const double h = 1.0 / (double)(m + 1);
  fmbd_csr *K3 = NULL, *M3 = NULL;
  laplace3(m, h, &K3, &M3);
  double lam1 = INFINITY;  // the pencil's first eigenvalue
  for (int pass = 0; pass < 2; pass++) {
    // pass 0: sigma 0 (well conditioned); 1: just below the first eigenvalue (near-singular)
    double sigma = pass == 0 ? 0.0 : lam1 * (1.0 - 1e-7);
    double lmin, lmax;
    k3_spectrum(m, h, sigma, &lmin, &lmax, &lam1);
    const char *what = pass == 0 ? "3-D Laplacian" : "3-D Laplacian near-singular";
    double r = llt_pair(K3, pass ? M3 : NULL, sigma, lmin, lmax, what);
    // the lower-triangle storage (fe2cb's; the factor's input assembled before the loop)
    fmbd_csr *Kl = NULL, *Ml = NULL;
    EXPECT(fmbd_csr_duplicate(K3, &Kl) == 0 && fmbd_csr_duplicate(M3, &Ml) == 0 &&
               fmbd_csr_keep_lower(Kl, NULL) == 0 && fmbd_csr_keep_lower(Ml, NULL) == 0,
           "lower copies");
    double rl = llt_pair(Kl, pass ? Ml : NULL, sigma, lmin, lmax, what);
    fmbd_log(FMBD_LOG_INFO, "%s: relative difference of the LL' factors %.2g (lower storage %.2g)",
             what, r, rl);
    fmbd_csr_destroy(&Kl);
    fmbd_csr_destroy(&Ml);
  }
  // past the first eigenvalue: not positive definite
  llt_fail_pair(K3, M3, lam1 * 1.5, "3-D Laplacian, shift past the first eigenvalue");

  // a tet10 stiffness (t2_mesh.h's box, 3 x 3 x 6 cells): K + s M, K's 6 rigid modes lifted by s
  fmbd_mesh mesh;
  box_mesh(&mesh, 0.3, 0.3, 1.0, 3, 3, 6, 2);
  fmbd_fe_opts o = t2_soft_options();
  fmbd_fe_body *b = NULL;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &b) == FMBD_OK, "tet10 assemble: %s", fmbd_err_get()->msg);
  if (b) {
    int64_t n = b->K->nrows;
    double s = 1e3;  // (rad/s)^2, far below the box's first flexible mode (~1e6)
    // lmax: Gershgorin (rigorous); lmin: inverse iteration with CHOLMOD's factor (60 steps
    // from a smooth start: the Rayleigh quotient converges from above, taken with a margin 2)
    double lmax = 0.0;
    for (int64_t i = 0; i < n; i++) {
      double r = 0.0;
      for (int64_t p = b->K->indptr[i]; p < b->K->indptr[i + 1]; p++) r += fabs(b->K->data[p]);
      for (int64_t p = b->M->indptr[i]; p < b->M->indptr[i + 1]; p++) r += s * fabs(b->M->data[p]);
      lmax = fmax(lmax, r);
    }
    fmbd_chol *F = NULL;
    double lmin = 0.0;
    EXPECT(fmbd_chol_analyze(b->K, b->M, FMBD_CHOL_LLT, &F) == 0, "tet10 analyse");
    if (F) {
      fmbd_chol_set_own_llt(F, false);
      EXPECT(fmbd_chol_factor(F, -s) == 0, "tet10 factor");
      double *x = malloc((size_t)(3 * n) * sizeof(double)), *ax = x + n, *bx = x + 2 * n;
      for (int64_t i = 0; i < n; i++) x[i] = 1.0 + 0.1 * sin((double)i);
      for (int it = 0; it < 60; it++) {
        double nx = 0.0;
        for (int64_t i = 0; i < n; i++) nx += x[i] * x[i];
        for (int64_t i = 0; i < n; i++) x[i] /= sqrt(nx);
        EXPECT(fmbd_chol_solve(F, 1, x, n) == 0, "tet10 solve");
      }
      double nx = 0.0, q = 0.0;
      for (int64_t i = 0; i < n; i++) nx += x[i] * x[i];
      fmbd_csr_matvec(b->K, x, ax);
      fmbd_csr_matvec(b->M, x, bx);
      for (int64_t i = 0; i < n; i++) q += x[i] * (ax[i] + s * bx[i]);
      lmin = q / nx / 2.0;
      free(x);
      fmbd_chol_destroy(&F);
    }
    double r = llt_pair(b->K, b->M, -s, lmin, lmax, "tet10 box");
    fmbd_log(FMBD_LOG_INFO, "tet10 box (%lld dofs): relative difference of the LL' factors %.2g",
             (long long)n, r);
    fmbd_fe_body_destroy(&b);
  }
  fmbd_mesh_destroy(&mesh);
  fmbd_csr_destroy(&K3);
  fmbd_csr_destroy(&M3);
}

int main(void) {
  fmbd_log_init("t300-chol", FMBD_LOG_WARN);  // FMBD_LOG=info: the factors' differences
  own_llt();
  inertia_3d();
  dense_supernode();
  exact_pivots();
  const int64_t n = 500;
  const double h = 1.0 / (double)(n + 1);
  fmbd_csr *K = tridiag(n, 2.0 / h, -1.0 / h, 2.0 / h);
  fmbd_csr *M = tridiag(n, 4.0 * h / 6.0, h / 6.0, 4.0 * h / 6.0);
  EXPECT(K && M, "allocation");

  // --- solve with several right-hand sides: residual at round-off ---------------------------
  fmbd_chol *F = NULL;
  int rc = fmbd_chol_create_llt(K, &F);
  EXPECT(rc == 0, "factor of a positive definite matrix failed: %d", rc);
  const int64_t nrhs = 3;
  double *B = fmbd_malloc((size_t)(n * nrhs) * sizeof(double));
  double *X = fmbd_malloc((size_t)(n * nrhs) * sizeof(double));
  double *R = fmbd_malloc((size_t)n * sizeof(double));
  for (int64_t i = 0; i < n * nrhs; i++) B[i] = X[i] = sin(0.37 * (double)i) + 0.1;
  rc = fmbd_chol_solve(F, nrhs, X, n);
  EXPECT(rc == 0, "solve failed");
  for (int64_t c = 0; c < nrhs; c++) {
    fmbd_csr_matvec(K, X + c * n, R);
    double e = 0, b = 0, x = 0;
    for (int64_t i = 0; i < n; i++) {
      e = fmax(e, fabs(R[i] - B[c * n + i]));
      b = fmax(b, fabs(B[c * n + i]));
      x = fmax(x, fabs(X[c * n + i]));
    }
    // normwise backward error |K x - b| / (|K| |x| + |b|) (max norms, |K|_inf = 4/h): a
    // backward-stable Cholesky solve gives a small multiple of eps = 2.2e-16
    double be = e / (4.0 / h * x + b);
    EXPECT(be <= 1e-14, "rhs %lld: backward error %.3g", (long long)c, be);
  }
  fmbd_chol_stats st;
  fmbd_chol_get_stats(F, &st);
  EXPECT(st.n == n && st.n_solves == nrhs && st.nnz_l >= n, "stats n %lld solves %lld lnz %g",
         (long long)st.n, (long long)st.n_solves, st.nnz_l);
  fmbd_chol_destroy(&F);
  EXPECT(F == NULL, "destroy sets NULL");

  // --- inertia: eigenvalues below s, exact discrete ones known -------------------------------
  // lambda_k = 6/h^2 (1 - cos k pi h) / (2 + cos k pi h), k = 1..n
  for (int k = 1; k <= 40; k += 13) {
    double lk = 6.0 / (h * h) * (1 - cos(k * M_PI * h)) / (2 + cos(k * M_PI * h));
    double lk1 = 6.0 / (h * h) * (1 - cos((k + 1) * M_PI * h)) / (2 + cos((k + 1) * M_PI * h));
    int64_t cnt = -1;
    rc = fmbd_chol_count_below(K, M, 0.5 * (lk + lk1), &cnt);
    EXPECT(rc == 0 && cnt == k, "count below the gap after mode %d: %lld (rc %d)", k,
           (long long)cnt, rc);
  }
  // reuse of one analysis for several shifts, negative count 0 below the first eigenvalue
  fmbd_chol *L = NULL;
  rc = fmbd_chol_analyze(K, M, FMBD_CHOL_LDLT, &L);
  EXPECT(rc == 0, "LDLT analyse");
  EXPECT(fmbd_chol_factor(L, 1.0) == 0 && fmbd_chol_negative_pivots(L) == 0, "count below 1");
  EXPECT(fmbd_chol_factor(L, 1e7) == 0 && fmbd_chol_negative_pivots(L) > 10, "count below 1e7");
  fmbd_chol_destroy(&L);
  // LL' of an indefinite shifted matrix fails with SINGULAR and a row
  rc = fmbd_chol_analyze(K, M, FMBD_CHOL_LLT, &L);
  EXPECT(rc == 0, "LLT analyse");
  rc = fmbd_chol_factor(L, 1e5);
  EXPECT(rc == FMBD_ERR_SINGULAR && fmbd_chol_failed_row(L) >= 0, "indefinite LL': rc %d row %lld",
         rc, (long long)fmbd_chol_failed_row(L));
  // the same object factors again at a valid shift
  EXPECT(fmbd_chol_factor(L, -1.0) == 0, "refactor after failure");
  fmbd_chol_destroy(&L);

  // --- singular: free-free 1-D bar (constant mode), and a floating block ------------------------
  fmbd_csr *Kf = tridiag(n, 2.0 / h, -1.0 / h, 1.0 / h);
  rc = fmbd_chol_create_llt(Kf, &F);
  EXPECT(rc == FMBD_ERR_SINGULAR, "singular free-free bar not detected: rc %d", rc);
  EXPECT(F == NULL, "no factor on failure");
  EXPECT(fmbd_err_get()->msg[0] != 0, "message set");
  // block diagonal: a held bar (rows 0..n-1) and a floating bar (rows n..2n-1)
  fmbd_csr *Kb = NULL;
  fmbd_csr_create(2 * n, 2 * n, 6 * n, &Kb);
  int64_t k = 0;
  for (int64_t i = 0; i < 2 * n; i++) {
    const fmbd_csr *S = i < n ? K : Kf;
    int64_t r = i % n, off = i < n ? 0 : n;
    Kb->indptr[i] = k;
    for (int64_t p = S->indptr[r]; p < S->indptr[r + 1]; p++)
      Kb->indices[k] = S->indices[p] + off, Kb->data[k++] = S->data[p];
  }
  Kb->indptr[2 * n] = k;
  rc = fmbd_chol_analyze(Kb, NULL, FMBD_CHOL_LLT, &L);
  EXPECT(rc == 0, "analyse block");
  rc = fmbd_chol_factor(L, 0.0);
  EXPECT(rc == FMBD_ERR_SINGULAR && fmbd_chol_failed_row(L) >= n,
         "floating block: rc %d, row %lld should lie in the floating half (>= %lld)", rc,
         (long long)fmbd_chol_failed_row(L), (long long)n);
  fmbd_chol_destroy(&L);

  // --- allocation failures: every countdown fails cleanly -------------------------------------
  for (int64_t c = 0; c < 200; c++) {
    fmbd_alloc_fail_after(c);
    rc = fmbd_chol_create_llt(K, &F);
    fmbd_alloc_fail_after(-1);
    if (rc == 0) {
      fmbd_chol_destroy(&F);
      break;
    }
    EXPECT(rc == FMBD_ERR_NOMEM && F == NULL, "countdown %lld: rc %d", (long long)c, rc);
  }

  // a failed allocation in our LL' (its workspaces, its value block) leaves the object able to
  // factor again, and the factor then solves
  for (int64_t c = 0; c < 40; c++) {
    EXPECT(fmbd_chol_analyze(K, NULL, FMBD_CHOL_LLT, &F) == 0, "analyse");
    fmbd_alloc_fail_after(c);
    rc = fmbd_chol_factor(F, 0.0);
    fmbd_alloc_fail_after(-1);
    EXPECT(rc == 0 || rc == FMBD_ERR_NOMEM, "countdown %lld in the factorisation: rc %d",
           (long long)c, rc);
    int rc2 = rc ? fmbd_chol_factor(F, 0.0) : 0;
    for (int64_t i = 0; i < n; i++) X[i] = B[i];
    EXPECT(rc2 == 0 && fmbd_chol_solve(F, 1, X, n) == 0, "countdown %lld: factor again %d",
           (long long)c, rc2);
    fmbd_csr_matvec(K, X, R);
    double e = 0.0, xm = 0.0, bm = 0.0;
    for (int64_t i = 0; i < n; i++) {
      e = fmax(e, fabs(R[i] - B[i]));
      xm = fmax(xm, fabs(X[i]));
      bm = fmax(bm, fabs(B[i]));
    }
    // the normwise backward error, as for the first solve above (|K|_inf = 4/h)
    EXPECT(e / (4.0 / h * xm + bm) <= 1e-14, "countdown %lld: backward error %.3g", (long long)c,
           e / (4.0 / h * xm + bm));
    fmbd_chol_destroy(&F);
    if (rc == 0) break;
  }

  fmbd_csr_destroy(&K);
  fmbd_csr_destroy(&M);
  fmbd_csr_destroy(&Kf);
  fmbd_csr_destroy(&Kb);
  fmbd_free(B);
  fmbd_free(X);
  fmbd_free(R);
  TEST_EXIT();
}
