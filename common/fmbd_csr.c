// common/fmbd_csr.c: compressed sparse row matrices
// SPDX-License-Identifier: MIT
#include "fmbd_csr.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_vec.h"

int fmbd_csr_create(int64_t nrows, int64_t ncols, int64_t nnz, fmbd_csr **out) {
  FMBD_CHECK(nrows >= 0 && ncols >= 0 && nnz >= 0, FMBD_ERR_VALUE, "negative matrix size");
  fmbd_csr *A = fmbd_calloc(1, sizeof *A);
  if (!A) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  A->nrows = nrows;
  A->ncols = ncols;
  A->indptr = fmbd_calloc((size_t)nrows + 1, sizeof(int64_t));
  A->indices = fmbd_malloc((size_t)nnz * sizeof(int64_t));
  A->data = fmbd_calloc((size_t)nnz, sizeof(double));
  if (!A->indptr || !A->indices || !A->data) {
    fmbd_csr_destroy(&A);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory for a %lld x %lld matrix with %lld entries",
              (long long)nrows, (long long)ncols, (long long)nnz);
  }
  *out = A;
  return FMBD_OK;
}

void fmbd_csr_destroy(fmbd_csr **A) {
  if (!A || !*A) return;
  fmbd_free((*A)->indptr);
  fmbd_free((*A)->indices);
  fmbd_free((*A)->data);
  fmbd_free(*A);
  *A = NULL;
}

int fmbd_csr_duplicate(const fmbd_csr *A, fmbd_csr **out) {
  int64_t nnz = fmbd_csr_nnz(A);
  FMBD_CALL(fmbd_csr_create(A->nrows, A->ncols, nnz, out));
  memcpy((*out)->indptr, A->indptr, (size_t)(A->nrows + 1) * sizeof(int64_t));
  memcpy((*out)->indices, A->indices, (size_t)nnz * sizeof(int64_t));
  memcpy((*out)->data, A->data, (size_t)nnz * sizeof(double));
  return FMBD_OK;
}

static int cmp_i64(const void *a, const void *b) {
  int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
  return (x > y) - (x < y);
}

int fmbd_csr_pattern_from_elements(int64_t n, int64_t nelem, int k, const int64_t *edofs,
                                   fmbd_csr **out) {
  int rc = FMBD_OK;
  int64_t *start = NULL, *inc = NULL, *mark = NULL, *rowptr = NULL;
  fmbd_csr *A = NULL;
  // --- dof -> element incidence, itself in CSR form ---
  FMBD_GALLOC(start = fmbd_calloc((size_t)n + 1, sizeof *start));
  for (int64_t e = 0; e < nelem; e++) {
    for (int a = 0; a < k; a++) {
      int64_t d = edofs[e * k + a];
      FMBD_GCHECK(d < n, FMBD_ERR_VALUE, "element %lld refers to dof %lld of %lld", (long long)e,
                  (long long)d, (long long)n);
      if (d >= 0) start[d + 1]++;
    }
  }
  for (int64_t i = 0; i < n; i++) start[i + 1] += start[i];
  FMBD_GALLOC(inc = fmbd_malloc((size_t)(start[n] ? start[n] : 1) * sizeof *inc));
  FMBD_GALLOC(mark = fmbd_malloc((size_t)(n ? n : 1) * sizeof *mark));
  FMBD_GALLOC(rowptr = fmbd_calloc((size_t)n + 1, sizeof *rowptr));
  for (int64_t i = 0; i < n; i++) mark[i] = start[i];
  for (int64_t e = 0; e < nelem; e++) {
    for (int a = 0; a < k; a++) {
      int64_t d = edofs[e * k + a];
      if (d >= 0) inc[mark[d]++] = e;
    }
  }
  // --- pass 0 counts the distinct columns of each row, pass 1 fills them ---
  for (int pass = 0; pass < 2; pass++) {
    for (int64_t i = 0; i < n; i++) mark[i] = -1;
    for (int64_t i = 0; i < n; i++) {
      int64_t len = 0;
      for (int64_t p = start[i]; p < start[i + 1]; p++) {
        const int64_t *ed = edofs + inc[p] * k;
        for (int a = 0; a < k; a++) {
          int64_t d = ed[a];
          if (d >= 0 && mark[d] != i) {
            mark[d] = i;
            if (pass) A->indices[rowptr[i] + len] = d;
            len++;
          }
        }
      }
      if (pass) {
        qsort(A->indices + rowptr[i], (size_t)len, sizeof(int64_t), cmp_i64);
      } else {
        rowptr[i + 1] = rowptr[i] + len;
      }
    }
    if (!pass) {
      FMBD_GCALL(fmbd_csr_create(n, n, rowptr[n], &A));
      memcpy(A->indptr, rowptr, (size_t)(n + 1) * sizeof *rowptr);
    }
  }
  *out = A;
  A = NULL;
done:
  fmbd_free(start);
  fmbd_free(inc);
  fmbd_free(mark);
  fmbd_free(rowptr);
  fmbd_csr_destroy(&A);
  return rc;
}

int64_t fmbd_csr_find(const fmbd_csr *A, int64_t i, int64_t j) {
  int64_t lo = A->indptr[i], hi = A->indptr[i + 1] - 1;
  while (lo <= hi) {
    int64_t mid = lo + (hi - lo) / 2, c = A->indices[mid];
    if (c == j) return mid;
    if (c < j)
      lo = mid + 1;
    else
      hi = mid - 1;
  }
  return -1;
}

double fmbd_csr_get(const fmbd_csr *A, int64_t i, int64_t j) {
  int64_t p = A->lower && j > i ? fmbd_csr_find(A, j, i) : fmbd_csr_find(A, i, j);
  return p < 0 ? 0.0 : A->data[p];
}

int fmbd_csr_add_block(fmbd_csr *A, int k, const int64_t *dofs, const double *Ke) {
  for (int a = 0; a < k; a++) {
    int64_t i = dofs[a];
    if (i < 0) continue;
    for (int b = 0; b < k; b++) {
      int64_t j = dofs[b];
      if (j < 0) continue;
      int64_t p = fmbd_csr_find(A, i, j);
      FMBD_CHECK(p >= 0, FMBD_ERR_INTERNAL, "entry (%lld, %lld) not in the sparsity pattern",
                 (long long)i, (long long)j);
      A->data[p] += Ke[a * k + b];
    }
  }
  return FMBD_OK;
}

// y = A x for a lower-stored symmetric A: each off-diagonal entry serves its row and, as the
// transposed entry, its column
static void sym_matvec(const fmbd_csr *A, const double *x, double *y) {
  memset(y, 0, (size_t)A->nrows * sizeof(double));
  for (int64_t i = 0; i < A->nrows; i++) {
    double s = 0.0, xi = x[i];
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      int64_t j = A->indices[p];
      double a = A->data[p];
      s += a * x[j];
      if (j != i) y[j] += a * xi;
    }
    y[i] += s;
  }
}

void fmbd_csr_matvec(const fmbd_csr *A, const double *x, double *y) {
  if (A->lower) {
    sym_matvec(A, x, y);
    return;
  }
  for (int64_t i = 0; i < A->nrows; i++) {
    double s = 0.0;
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) s += A->data[p] * x[A->indices[p]];
    y[i] = s;
  }
}

// Y(rows, 0..w-1) = A X for w <= NB columns held row-major in xt (stride sx >= w): one pass
// over A for all w, each entry updating w contiguous sums in the order fmbd_csr_matvec adds them
// (same results, bit for bit). Full passes of 5 to NB = 8 columns go through rows8_full (a
// remainder of 5-7 padded with zero columns to 8: the padding's sums are never stored, the
// others are added as before) and rows8_lower, which pick a vector kernel where the processor
// has one (below).
enum { NB = 8 };
static inline void rows_full(const fmbd_csr *A, int w, int sx, const double *xt, double *Y,
                             int64_t ldy) {
  for (int64_t i = 0; i < A->nrows; i++) {
    double s[NB] = {0};
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      double a = A->data[p];
      const double *x = xt + A->indices[p] * sx;
      for (int k = 0; k < w; k++) s[k] += a * x[k];
    }
    for (int k = 0; k < w; k++) Y[i + k * ldy] = s[k];
  }
}

// the same for A and B on one pattern (A's indptr and indices), B's values in bd: Y = A X and
// Z = B X in one pass over the pattern, each sum in rows_full's order
static inline void rows_pair(const fmbd_csr *A, const double *bd, int w, int sx, const double *xt,
                             double *Y, double *Z, int64_t ldy) {
  for (int64_t i = 0; i < A->nrows; i++) {
    double s[NB] = {0}, t[NB] = {0};
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      double a = A->data[p], b = bd[p];
      const double *x = xt + A->indices[p] * sx;
      for (int k = 0; k < w; k++) s[k] += a * x[k];
      for (int k = 0; k < w; k++) t[k] += b * x[k];
    }
    for (int k = 0; k < w; k++) Y[i + k * ldy] = s[k], Z[i + k * ldy] = t[k];
  }
}

// the same for a lower-stored symmetric A (sym_matvec's order), the transposed entries' sums in
// yt (row-major, stride w)
static inline void rows_lower_rm(const fmbd_csr *A, int w, const double *xt, double *yt) {
  memset(yt, 0, (size_t)A->nrows * (size_t)w * sizeof(double));
  for (int64_t i = 0; i < A->nrows; i++) {
    double s[NB] = {0};
    const double *xi = xt + i * w;
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      int64_t j = A->indices[p];
      double a = A->data[p];
      const double *x = xt + j * w;
      for (int k = 0; k < w; k++) s[k] += a * x[k];
      if (j != i) {
        double *y = yt + j * w;
        for (int k = 0; k < w; k++) y[k] += a * xi[k];
      }
    }
    double *y = yt + i * w;
    for (int k = 0; k < w; k++) y[k] += s[k];
  }
}

// Vector kernels of the 8-column passes (x86-64 with GCC or clang): the 8 sums as one vector
// of the compiler's vector extensions, kept in registers across a row (as plain arrays, above,
// GCC 12 keeps them on the stack and goes through memory at every entry), compiled for AVX2
// (two registers) and AVX-512 (one) and chosen when called (__builtin_cpu_supports): one
// portable binary. Not for the baseline x86-64: GCC lowers 64-byte vectors to SSE2 through the
// stack, 4 times slower than the plain loops (300 modes of the 51 k-dof rod: M products 13-18 s
// against 3-5 s, bench/README.md "The sparse product's kernels"), so that and every other
// processor keep the plain loops. Every lane does the plain code's operations in its order,
// a * x then + (no contraction into FMA: GCC compiles -std=c11 with -ffp-contract=off, the
// target attributes inherit it, and clang is told so below), so the results are the same bits on
// every instruction set and as fmbd_csr_matvec's (tests/unit/t300).
#ifdef FMBD_HAVE_V4D  // fmbd_vec.h: x86-64, GCC or clang, not FMBD_NO_VECTOR
#define FMBD_VEC8 1
#ifdef __clang__
// clang contracts a * x + s into FMA by default, GCC at -std=c11 not
#pragma clang fp contract(off)
#endif

// the 8 sums as two 4-wide vectors: GCC 12 keeps them in registers with AVX2 and AVX-512 (an
// 8-wide type it splits for AVX2 through the stack); the first 5 <= w <= 8 columns stored
static inline __attribute__((always_inline)) void vrows8_full(const fmbd_csr *A, const double *xt,
                                                              int w, double *Y, int64_t ldy) {
  const int64_t *ip = A->indptr, *ix = A->indices;
  const double *d = A->data;
  for (int64_t i = 0; i < A->nrows; i++) {
    v4d s0 = {0}, s1 = {0};
    for (int64_t p = ip[i]; p < ip[i + 1]; p++) {
      const double *x = xt + ix[p] * NB;
      s0 += d[p] * LD4(x);
      s1 += d[p] * LD4(x + 4);
    }
    for (int k = 0; k < 4; k++) Y[i + k * ldy] = s0[k];
    for (int k = 4; k < w; k++) Y[i + k * ldy] = s1[k - 4];
  }
}

// rows_pair's vector form: four 4-wide sums, the pattern and x read once for both matrices; the
// first 1 <= w <= 8 columns stored
static inline __attribute__((always_inline)) void vrows8_pair(const fmbd_csr *A, const double *bd,
                                                              const double *xt, int w, double *Y,
                                                              double *Z, int64_t ldy) {
  const int64_t *ip = A->indptr, *ix = A->indices;
  const double *d = A->data;
  for (int64_t i = 0; i < A->nrows; i++) {
    v4d s0 = {0}, s1 = {0}, t0 = {0}, t1 = {0};
    for (int64_t p = ip[i]; p < ip[i + 1]; p++) {
      const double *x = xt + ix[p] * NB;
      v4d x0 = LD4(x), x1 = LD4(x + 4);
      s0 += d[p] * x0;
      s1 += d[p] * x1;
      t0 += bd[p] * x0;
      t1 += bd[p] * x1;
    }
    for (int k = 0; k < 4 && k < w; k++) Y[i + k * ldy] = s0[k], Z[i + k * ldy] = t0[k];
    for (int k = 4; k < w; k++) Y[i + k * ldy] = s1[k - 4], Z[i + k * ldy] = t1[k - 4];
  }
}

static inline __attribute__((always_inline)) void vrows8_lower(const fmbd_csr *A, const double *xt,
                                                               double *yt) {
  const int64_t *ip = A->indptr, *ix = A->indices;
  const double *d = A->data;
  int64_t n = A->nrows;
  memset(yt, 0, (size_t)n * NB * sizeof(double));
  for (int64_t i = 0; i < n; i++) {
    v4d s0 = {0}, s1 = {0}, x0 = LD4(xt + i * NB), x1 = LD4(xt + i * NB + 4);
    for (int64_t p = ip[i]; p < ip[i + 1]; p++) {
      int64_t j = ix[p];
      double a = d[p];
      const double *x = xt + j * NB;
      s0 += a * LD4(x);
      s1 += a * LD4(x + 4);
      if (j != i) {
        double *y = yt + j * NB;
        ST4(y, LD4(y) + a * x0);
        ST4(y + 4, LD4(y + 4) + a * x1);
      }
    }
    double *y = yt + i * NB;
    ST4(y, LD4(y) + s0);
    ST4(y + 4, LD4(y + 4) + s1);
  }
}

// 4 columns row-major in and out (fmbd_csr_matmat_rows4): one 4-wide sum, lower or full
__attribute__((target("avx2"))) static void rows4_avx2(const fmbd_csr *A, const double *xt,
                                                       double *yt) {
  const int64_t *ip = A->indptr, *ix = A->indices;
  const double *d = A->data;
  int64_t n = A->nrows;
  if (!A->lower) {
    for (int64_t i = 0; i < n; i++) {
      v4d s = {0};
      for (int64_t p = ip[i]; p < ip[i + 1]; p++) s += d[p] * LD4(xt + ix[p] * 4);
      ST4(yt + i * 4, s);
    }
    return;
  }
  memset(yt, 0, (size_t)n * 4 * sizeof(double));
  for (int64_t i = 0; i < n; i++) {
    v4d s = {0}, xi = LD4(xt + i * 4);
    for (int64_t p = ip[i]; p < ip[i + 1]; p++) {
      int64_t j = ix[p];
      double a = d[p];
      s += a * LD4(xt + j * 4);
      if (j != i) ST4(yt + j * 4, LD4(yt + j * 4) + a * xi);
    }
    ST4(yt + i * 4, LD4(yt + i * 4) + s);
  }
}

__attribute__((target("avx512f"))) static void rows8_full_avx512(const fmbd_csr *A,
                                                                 const double *xt, int w, double *Y,
                                                                 int64_t ldy) {
  vrows8_full(A, xt, w, Y, ldy);
}
__attribute__((target("avx2"))) static void rows8_full_avx2(const fmbd_csr *A, const double *xt,
                                                            int w, double *Y, int64_t ldy) {
  vrows8_full(A, xt, w, Y, ldy);
}
__attribute__((target("avx512f"))) static void rows8_pair_avx512(const fmbd_csr *A,
                                                                 const double *bd, const double *xt,
                                                                 int w, double *Y, double *Z,
                                                                 int64_t ldy) {
  vrows8_pair(A, bd, xt, w, Y, Z, ldy);
}
__attribute__((target("avx2"))) static void rows8_pair_avx2(const fmbd_csr *A, const double *bd,
                                                            const double *xt, int w, double *Y,
                                                            double *Z, int64_t ldy) {
  vrows8_pair(A, bd, xt, w, Y, Z, ldy);
}
__attribute__((target("avx512f"))) static void rows8_lower_avx512(const fmbd_csr *A,
                                                                  const double *xt, double *yt) {
  vrows8_lower(A, xt, yt);
}
__attribute__((target("avx2"))) static void rows8_lower_avx2(const fmbd_csr *A, const double *xt,
                                                             double *yt) {
  vrows8_lower(A, xt, yt);
}
#endif

// xt of stride NB (columns w..NB-1 zero), 5 <= w <= NB
static void rows8_full(const fmbd_csr *A, const double *xt, int w, double *Y, int64_t ldy) {
#ifdef FMBD_VEC8
  if (__builtin_cpu_supports("avx512f")) {
    rows8_full_avx512(A, xt, w, Y, ldy);
    return;
  }
  if (__builtin_cpu_supports("avx2")) {
    rows8_full_avx2(A, xt, w, Y, ldy);
    return;
  }
#endif
  rows_full(A, w, NB, xt, Y, ldy);
}

// xt of stride NB (columns w..NB-1 zero), 1 <= w <= NB
static void rows8_pair(const fmbd_csr *A, const double *bd, const double *xt, int w, double *Y,
                       double *Z, int64_t ldy) {
#ifdef FMBD_VEC8
  if (__builtin_cpu_supports("avx512f")) {
    rows8_pair_avx512(A, bd, xt, w, Y, Z, ldy);
    return;
  }
  if (__builtin_cpu_supports("avx2")) {
    rows8_pair_avx2(A, bd, xt, w, Y, Z, ldy);
    return;
  }
#endif
  rows_pair(A, bd, w, NB, xt, Y, Z, ldy);
}

void fmbd_csr_matmat_rows4(const fmbd_csr *A, const double *xt, double *yt) {
#ifdef FMBD_VEC8
  if (__builtin_cpu_supports("avx2")) {
    rows4_avx2(A, xt, yt);
    return;
  }
#endif
  if (A->lower) {
    rows_lower_rm(A, 4, xt, yt);
    return;
  }
  for (int64_t i = 0; i < A->nrows; i++) {
    double s[4] = {0};
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      const double *x = xt + A->indices[p] * 4;
      for (int k = 0; k < 4; k++) s[k] += A->data[p] * x[k];
    }
    for (int k = 0; k < 4; k++) yt[i * 4 + k] = s[k];
  }
}

// yt = A xt (row-major, stride NB) for a lower-stored A
static void rows8_lower(const fmbd_csr *A, const double *xt, double *yt) {
#ifdef FMBD_VEC8
  if (__builtin_cpu_supports("avx512f")) {
    rows8_lower_avx512(A, xt, yt);
    return;
  }
  if (__builtin_cpu_supports("avx2")) {
    rows8_lower_avx2(A, xt, yt);
    return;
  }
#endif
  rows_lower_rm(A, NB, xt, yt);
}

void fmbd_csr_matmat(const fmbd_csr *A, int64_t nrhs, const double *X, int64_t ldx, double *Y,
                     int64_t ldy) {
  // up to 8 columns at a time through a row-major copy of X (min(nrhs, 8) columns: no more
  // than is used): the matrix is read once per 8 columns (and once for a remainder of 2-7,
  // e.g. the block eigensolver's blocks of 4) and each entry updates contiguous sums (one
  // column at a time read A nrhs times: the block eigensolver's M products, fmbd_eig.c, spent
  // a third of their time there). A lower-stored A needs a second n x w copy for its blocked
  // form: with 2-4 columns alone it goes one column at a time (fe2cb at 188 k dofs, blocks of
  // 4: +11 MB on the peak; the block Lanczos' operator has its own row-major pass,
  // fmbd_chol_apply_op); from 5 columns on, 5-7 padded to 8 (no more memory than a block of
  // 8: the residual check's last 7 of 23 pairs, one pass instead of 7), and a remainder of 2-4
  // after a block of 8 by rows of 4 (fmbd_csr_matmat_rows4: fe2cb's 12 boundary columns, one
  // pass instead of 4).
  int64_t nc = A->ncols, wm = nrhs < NB ? nrhs : NB;
  if (wm >= 5) wm = NB;  // room for a remainder of 5-7 padded to 8
  bool blocked = A->lower ? nrhs >= 5 : nrhs >= 2;
  double *xt = blocked ? fmbd_malloc((size_t)(nc ? nc : 1) * (size_t)wm * sizeof(double)) : NULL;
  double *yt =
      xt && A->lower ? fmbd_malloc((size_t)(nc ? nc : 1) * (size_t)wm * sizeof(double)) : NULL;
  if (!xt || (A->lower && !yt)) {
    // one column, or no room for the copies: a pass per column
    for (int64_t c = 0; c < nrhs; c++) fmbd_csr_matvec(A, X + c * ldx, Y + c * ldy);
    fmbd_free(xt);
    fmbd_free(yt);
    return;
  }
  for (int64_t c = 0; c < nrhs; c += NB) {
    int w = nrhs - c < NB ? (int)(nrhs - c) : NB;
    if (w == 1) {
      fmbd_csr_matvec(A, X + c * ldx, Y + c * ldy);
      continue;
    }
    // xt's stride: 5-7 columns padded with zero columns to 8; lower: 2-4 padded to 4
    int sx = w >= 5 ? NB : (A->lower ? 4 : w);
    for (int64_t j = 0; j < nc; j++) {
      for (int k = 0; k < w; k++) xt[j * sx + k] = X[j + (c + k) * ldx];
      for (int k = w; k < sx; k++) xt[j * sx + k] = 0.0;
    }
    if (A->lower) {
      if (sx == NB)
        rows8_lower(A, xt, yt);
      else
        fmbd_csr_matmat_rows4(A, xt, yt);
      for (int64_t i = 0; i < A->nrows; i++) {
        for (int k = 0; k < w; k++) Y[i + (c + k) * ldy] = yt[i * sx + k];
      }
    } else if (sx == NB)
      rows8_full(A, xt, w, Y + c * ldy, ldy);
    else
      rows_full(A, w, w, xt, Y + c * ldy, ldy);
  }
  fmbd_free(xt);
  fmbd_free(yt);
}

void fmbd_csr_matmat_pair(const fmbd_csr *A, const fmbd_csr *B, int64_t nrhs, const double *X,
                          int64_t ldx, double *Y, double *Z, int64_t ldy) {
  // one pattern in memory (an fe body's K and M, fmbd_fe_assemble or fmbd_fe_read): 8 columns
  // a pass, padded with zero columns, the pattern and X read once for both matrices. Otherwise,
  // or without room for the copy of X, two products
  int64_t nc = A->ncols;
  bool one = A != B && !A->lower && !B->lower && A->indptr == B->indptr &&
             A->indices == B->indices && A->nrows == B->nrows && A->ncols == B->ncols;
  double *xt = one && nrhs > 0 ? fmbd_malloc((size_t)(nc ? nc : 1) * NB * sizeof(double)) : NULL;
  if (!xt) {
    fmbd_csr_matmat(A, nrhs, X, ldx, Y, ldy);
    fmbd_csr_matmat(B, nrhs, X, ldx, Z, ldy);
    return;
  }
  for (int64_t c = 0; c < nrhs; c += NB) {
    int w = nrhs - c < NB ? (int)(nrhs - c) : NB;
    for (int64_t j = 0; j < nc; j++) {
      for (int k = 0; k < w; k++) xt[j * NB + k] = X[j + (c + k) * ldx];
      for (int k = w; k < NB; k++) xt[j * NB + k] = 0.0;
    }
    rows8_pair(A, B->data, xt, w, Y + c * ldy, Z + c * ldy, ldy);
  }
  fmbd_free(xt);
}

int fmbd_csr_keep_lower(fmbd_csr *A, fmbd_csr *B) {
  FMBD_CHECK(A->nrows == A->ncols && !A->lower, FMBD_ERR_INTERNAL,
             "keep_lower of a non-square or already lower matrix");
  FMBD_CHECK(!B || (B->indptr == A->indptr && B->indices == A->indices && !B->lower),
             FMBD_ERR_INTERNAL, "keep_lower: the second matrix does not share the first's pattern");
  int64_t n = A->nrows, q = 0;
  for (int64_t i = 0; i < n; i++) {
    int64_t p0 = A->indptr[i], p1 = A->indptr[i + 1];
    A->indptr[i] = q;
    for (int64_t p = p0; p < p1 && A->indices[p] <= i; p++, q++) {
      A->indices[q] = A->indices[p];
      A->data[q] = A->data[p];
      if (B) B->data[q] = B->data[p];
    }
  }
  A->indptr[n] = q;
  // shrink (a failed shrink keeps the larger block: still valid)
  size_t sz = (size_t)(q ? q : 1);
  int64_t *ix = fmbd_realloc(A->indices, sz * sizeof(int64_t));
  if (ix) A->indices = ix;
  double *d = fmbd_realloc(A->data, sz * sizeof(double));
  if (d) A->data = d;
  A->lower = true;
  if (B) {
    B->indices = A->indices;
    d = fmbd_realloc(B->data, sz * sizeof(double));
    if (d) B->data = d;
    B->lower = true;
  }
  return FMBD_OK;
}

int fmbd_csr_submatrix(const fmbd_csr *A, int64_t nr, const int64_t *rows, int64_t nc,
                       const int64_t *cols, fmbd_csr **out) {
  int rc = FMBD_OK;
  int64_t *cmap = NULL;
  fmbd_csr *B = NULL;
  FMBD_GALLOC(cmap = fmbd_malloc((size_t)(A->ncols ? A->ncols : 1) * sizeof *cmap));
  for (int64_t j = 0; j < A->ncols; j++) cmap[j] = -1;
  for (int64_t j = 0; j < nc; j++) {
    FMBD_GCHECK(cols[j] >= 0 && cols[j] < A->ncols, FMBD_ERR_VALUE, "column %lld out of range",
                (long long)cols[j]);
    cmap[cols[j]] = j;
  }
  int64_t nnz = 0;
  for (int64_t r = 0; r < nr; r++) {
    int64_t i = rows[r];
    FMBD_GCHECK(i >= 0 && i < A->nrows, FMBD_ERR_VALUE, "row %lld out of range", (long long)i);
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) nnz += cmap[A->indices[p]] >= 0;
  }
  FMBD_GCALL(fmbd_csr_create(nr, nc, nnz, &B));
  nnz = 0;
  for (int64_t r = 0; r < nr; r++) {
    int64_t i = rows[r], s = nnz;
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      int64_t j = cmap[A->indices[p]];
      if (j >= 0) {
        B->indices[nnz] = j;
        B->data[nnz++] = A->data[p];
      }
    }
    // columns keep A's order only if cols is increasing: sort the row with its values
    for (int64_t a = s + 1; a < nnz; a++) {
      int64_t cj = B->indices[a];
      double v = B->data[a];
      int64_t b = a - 1;
      while (b >= s && B->indices[b] > cj) {
        B->indices[b + 1] = B->indices[b];
        B->data[b + 1] = B->data[b];
        b--;
      }
      B->indices[b + 1] = cj;
      B->data[b + 1] = v;
    }
    B->indptr[r + 1] = nnz;
  }
  *out = B;
  B = NULL;
done:
  fmbd_free(cmap);
  fmbd_csr_destroy(&B);
  return rc;
}

int fmbd_csr_transpose(const fmbd_csr *A, fmbd_csr **out) {
  int64_t nnz = fmbd_csr_nnz(A);
  fmbd_csr *B = NULL;
  FMBD_CALL(fmbd_csr_create(A->ncols, A->nrows, nnz, &B));
  for (int64_t p = 0; p < nnz; p++) B->indptr[A->indices[p] + 1]++;
  for (int64_t j = 0; j < A->ncols; j++) B->indptr[j + 1] += B->indptr[j];
  int64_t *pos = fmbd_malloc((size_t)(A->ncols ? A->ncols : 1) * sizeof *pos);
  if (!pos) {
    fmbd_csr_destroy(&B);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  memcpy(pos, B->indptr, (size_t)A->ncols * sizeof *pos);
  for (int64_t i = 0; i < A->nrows; i++) {
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      int64_t q = pos[A->indices[p]]++;
      B->indices[q] = i;
      B->data[q] = A->data[p];
    }
  }
  fmbd_free(pos);
  *out = B;
  return FMBD_OK;
}

int fmbd_csr_matmul(const fmbd_csr *A, const fmbd_csr *B, fmbd_csr **out) {
  FMBD_CHECK(A->ncols == B->nrows, FMBD_ERR_VALUE, "matmul: %lld columns against %lld rows",
             (long long)A->ncols, (long long)B->nrows);
  int rc = FMBD_OK;
  int64_t *mark = NULL, *rowptr = NULL;
  double *acc = NULL;
  fmbd_csr *C = NULL;
  int64_t n = B->ncols;
  FMBD_GALLOC(mark = fmbd_malloc((size_t)(n ? n : 1) * sizeof *mark));
  FMBD_GALLOC(acc = fmbd_calloc((size_t)(n ? n : 1), sizeof *acc));
  FMBD_GALLOC(rowptr = fmbd_calloc((size_t)A->nrows + 1, sizeof *rowptr));
  for (int pass = 0; pass < 2; pass++) {
    for (int64_t j = 0; j < n; j++) mark[j] = -1;
    for (int64_t i = 0; i < A->nrows; i++) {
      int64_t len = 0, s = pass ? rowptr[i] : 0;
      for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
        int64_t k = A->indices[p];
        double a = A->data[p];
        for (int64_t q = B->indptr[k]; q < B->indptr[k + 1]; q++) {
          int64_t j = B->indices[q];
          if (mark[j] != i) {
            mark[j] = i;
            if (pass) {
              C->indices[s + len] = j;
              acc[j] = 0.0;
            }
            len++;
          }
          if (pass) acc[j] += a * B->data[q];
        }
      }
      if (pass) {
        qsort(C->indices + s, (size_t)len, sizeof(int64_t), cmp_i64);
        for (int64_t t = s; t < s + len; t++) C->data[t] = acc[C->indices[t]];
      } else {
        rowptr[i + 1] = rowptr[i] + len;
      }
    }
    if (!pass) {
      FMBD_GCALL(fmbd_csr_create(A->nrows, n, rowptr[A->nrows], &C));
      memcpy(C->indptr, rowptr, (size_t)(A->nrows + 1) * sizeof *rowptr);
    }
  }
  *out = C;
  C = NULL;
done:
  fmbd_free(mark);
  fmbd_free(acc);
  fmbd_free(rowptr);
  fmbd_csr_destroy(&C);
  return rc;
}

int fmbd_csr_ptap(const fmbd_csr *A, const fmbd_csr *P, fmbd_csr **out) {
  int rc = FMBD_OK;
  fmbd_csr *AP = NULL, *Pt = NULL;
  FMBD_GCALL(fmbd_csr_matmul(A, P, &AP));
  FMBD_GCALL(fmbd_csr_transpose(P, &Pt));
  FMBD_GCALL(fmbd_csr_matmul(Pt, AP, out));
done:
  fmbd_csr_destroy(&AP);
  fmbd_csr_destroy(&Pt);
  return rc;
}

// the error of a value that is not finite, entry p of row i
static int bad_value(const fmbd_csr *A, int64_t i, int64_t p) {
  FMBD_FAIL(FMBD_ERR_VALUE, "data: %s at row %lld, column %lld", isnan(A->data[p]) ? "NaN" : "Inf",
            (long long)i, (long long)A->indices[p]);
}

int fmbd_csr_check(const fmbd_csr *A) {
  FMBD_CHECK(A->nrows >= 0 && A->ncols >= 0, FMBD_ERR_FORMAT, "negative shape");
  if (A->indptr[0] != 0) {
    fmbd_err_context(NULL, "indptr");
    FMBD_FAIL(FMBD_ERR_FORMAT, "indptr: does not start at 0");
  }
  // the whole indptr first: a bad row pointer otherwise shows up as a confusing defect of the
  // indices of another row
  for (int64_t i = 0; i < A->nrows; i++) {
    if (A->indptr[i + 1] < A->indptr[i]) {
      FMBD_FAIL(
          FMBD_ERR_FORMAT, "indptr: not monotone: entry %lld (%lld) is below entry %lld (%lld)",
          (long long)(i + 1), (long long)A->indptr[i + 1], (long long)i, (long long)A->indptr[i]);
    }
  }
  for (int64_t i = 0; i < A->nrows; i++) {
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      int64_t j = A->indices[p];
      if (j < 0 || j >= A->ncols) {
        FMBD_FAIL(FMBD_ERR_FORMAT, "indices: column %lld out of range at row %lld", (long long)j,
                  (long long)i);
      }
      if (p > A->indptr[i] && j <= A->indices[p - 1]) {
        FMBD_FAIL(FMBD_ERR_FORMAT, "indices: not strictly increasing at row %lld", (long long)i);
      }
      if (!isfinite(A->data[p])) return bad_value(A, i, p);
    }
  }
  return FMBD_OK;
}

int fmbd_csr_check_values(const fmbd_csr *A) {
  const double *x = A->data;
  for (int64_t i = 0; i < A->nrows; i++) {
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      if (!isfinite(x[p])) return bad_value(A, i, p);
    }
  }
  return FMBD_OK;
}

double fmbd_csr_max_abs(const fmbd_csr *A) {
  // four running maxima (fmax's one chain took 1.4 ns a value: 11 ms for the 51 k rod's K);
  // a NaN compares false and is skipped, as fmax skips it
  double m[4] = {0.0, 0.0, 0.0, 0.0};
  int64_t nnz = fmbd_csr_nnz(A), p = 0;
  const double *x = A->data;
  for (; p + 4 <= nnz; p += 4) {
    for (int k = 0; k < 4; k++) {
      double a = fabs(x[p + k]);
      m[k] = a > m[k] ? a : m[k];
    }
  }
  for (; p < nnz; p++) m[0] = fabs(x[p]) > m[0] ? fabs(x[p]) : m[0];
  double a = m[0] > m[1] ? m[0] : m[1], b = m[2] > m[3] ? m[2] : m[3];
  return a > b ? a : b;
}

// entries ahead whose partners the symmetry walk prefetches
#define PREFETCH_AHEAD 8

// The symmetry walk of nm (1 or 2) value arrays x[m] on A's pattern (A->data unused), each
// against its own tolerance: bad[m] gets the first offending row of x[m] or -1, the row
// fmbd_csr_is_symmetric gives for that matrix alone. One pass: the rows i that hold (i, j),
// j > i, come in increasing i, so the partner (j, i) is found by a cursor moving forward
// along row j; the entries it steps over, and those left below the diagonal at the end, have
// no partner (O(nnz), no searches; the same answer and bad row as the two searching passes of
// fmbd_csr_is_symmetric's fallback). The walk's cost is its scattered reads of the partner
// rows, which two matrices on one pattern share. false: no memory for the cursors.
static bool sym_walk(const fmbd_csr *A, int nm, const double *const *x, const double *tol,
                     int64_t *bad) {
  int64_t n = A->nrows, *cur = fmbd_malloc((size_t)(n ? n : 1) * sizeof(int64_t));
  if (!cur) return false;
  const int64_t *ip = A->indptr, *ix = A->indices, nnz = ip[n];
  const double *x0 = x[0], *x1 = x[nm - 1];
  const double t0 = tol[0], t1 = tol[nm - 1];
  int64_t lower_bad[2] = {INT64_MAX, INT64_MAX};  // first row with an entry only below
  bool live[2] = {true, nm > 1};                  // no value defect found yet
  for (int64_t j = 0; j < n; j++) cur[j] = ip[j];
  for (int64_t i = 0; i < n && (live[0] || live[1]); i++) {
    for (int64_t p = ip[i]; p < ip[i + 1]; p++) {
      int64_t j = ix[p];
      if (j <= i) continue;
      if (p + PREFETCH_AHEAD < nnz) {  // the partner of a later entry: its row's cursor is at
        int64_t jf = ix[p + PREFETCH_AHEAD];  // most one entry behind it
        __builtin_prefetch(ix + cur[jf]);
        __builtin_prefetch(x0 + cur[jf]);
        if (nm > 1) __builtin_prefetch(x1 + cur[jf]);
      }
      int64_t q = cur[j], e = ip[j + 1];
      for (; q < e && ix[q] < i; q++) {
        if (fabs(x0[q]) > t0 && j < lower_bad[0]) lower_bad[0] = j;
        if (nm > 1 && fabs(x1[q]) > t1 && j < lower_bad[1]) lower_bad[1] = j;
      }
      bool hit = q < e && ix[q] == i;
      double a0 = hit ? x0[q] : 0.0, a1 = hit ? x1[q] : 0.0;
      cur[j] = q + hit;
      if (live[0] && fabs(x0[p] - a0) > t0) {
        live[0] = false;
        bad[0] = i;
      }
      if (live[1] && fabs(x1[p] - a1) > t1) {
        live[1] = false;
        bad[1] = i;
      }
    }
  }
  for (int m = 0; m < nm; m++) {
    if (!live[m]) continue;
    const double *xm = x[m];
    for (int64_t j = 0; j < n && j < lower_bad[m]; j++) {
      for (int64_t q = cur[j]; q < ip[j + 1] && ix[q] < j; q++) {
        if (fabs(xm[q]) > tol[m]) {
          lower_bad[m] = j;
          break;
        }
      }
    }
    bad[m] = lower_bad[m] == INT64_MAX ? -1 : lower_bad[m];
  }
  fmbd_free(cur);
  return true;
}

bool fmbd_csr_is_symmetric_pair(const fmbd_csr *A, const fmbd_csr *B, double rtol, int64_t bad[2]) {
  bad[0] = bad[1] = -1;
  bool shared = A->nrows == A->ncols && B->nrows == A->nrows && B->ncols == A->ncols &&
                B->indptr == A->indptr && B->indices == A->indices;
  if (shared) {
    const double *x[2] = {A->data, B->data};
    double tol[2] = {rtol * fmbd_csr_max_abs(A), rtol * fmbd_csr_max_abs(B)};
    if (sym_walk(A, 2, x, tol, bad)) return bad[0] < 0 && bad[1] < 0;
  }
  bool a = fmbd_csr_is_symmetric(A, rtol, &bad[0]);
  bool b = fmbd_csr_is_symmetric(B, rtol, &bad[1]);
  return a && b;
}

bool fmbd_csr_is_symmetric(const fmbd_csr *A, double rtol, int64_t *bad_row) {
  if (bad_row) *bad_row = -1;
  if (A->nrows != A->ncols) return false;
  double tol = rtol * fmbd_csr_max_abs(A);
  int64_t n = A->nrows, bad = -1;
  const double *x = A->data;
  if (sym_walk(A, 1, &x, &tol, &bad)) {
    if (bad_row) *bad_row = bad;
    return bad < 0;
  }
  for (int64_t i = 0; i < n; i++) {
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      int64_t j = A->indices[p];
      if (j <= i) continue;
      int64_t q = fmbd_csr_find(A, j, i);
      double aji = q < 0 ? 0.0 : A->data[q];
      if (fabs(A->data[p] - aji) > tol) {
        if (bad_row) *bad_row = i;
        return false;
      }
    }
  }
  // entries present only in the lower triangle
  for (int64_t i = 0; i < n; i++) {
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) {
      int64_t j = A->indices[p];
      if (j >= i) continue;
      if (fmbd_csr_find(A, j, i) < 0 && fabs(A->data[p]) > tol) {
        if (bad_row) *bad_row = i;
        return false;
      }
    }
  }
  return true;
}

void fmbd_csr_diagonal(const fmbd_csr *A, double *d) {
  int64_t n = A->nrows < A->ncols ? A->nrows : A->ncols;
  for (int64_t i = 0; i < n; i++) d[i] = fmbd_csr_get(A, i, i);
}
