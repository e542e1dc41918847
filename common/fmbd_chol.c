// common/fmbd_chol.c: sparse symmetric factorisations through CHOLMOD (64-bit cholmod_l_*)
// SPDX-License-Identifier: MIT
#define _DEFAULT_SOURCE  // madvise (release_zero_pages)
#include "fmbd_chol.h"

#include <cblas.h>
#include <cholmod.h>
#include <dlfcn.h>
#ifdef __GLIBC__
#include <malloc.h>  // malloc_trim
#endif
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_vec.h"

// orderings of matrices of this order and more: METIS alone (fmbd_chol_analyze_perm)
enum { METIS_ONLY_N = 50000 };
// the supernodal LDL' and LL' panel's leaf width and product chunk (panel), and the width of
// the descendants' update blocks (super_factor)
enum { LDL_LEAF = 16, LDL_KC = 256, LDL_CB = 64 };
// entries whose places super_prefill finds (and prefetches) before it adds them; the mean run
// length from which scatter_update subtracts by runs instead of place by place
enum { PREFILL_CHUNK = 64, SCATTER_RUN = 8 };

struct fmbd_chol {
  int kind;
  int64_t n;
  const fmbd_csr *A, *B;  // borrowed
  cholmod_common c;
  int started;
  int released;          // fmbd_chol_release_matrix called: no refactorisation
  int dropped;           // fmbd_chol_drop_numeric called: the next solve factors again
  double *kept;          // fmbd_chol_drop_numeric_keep: the LL' value block (kept_n doubles),
  size_t kept_n;         // owned here until fmbd_chol_analyze_like hands it to an LDLT
  cholmod_sparse *S;     // upper triangle (stype = +1) of the union pattern, CSC: the analysis
                         // (and the values of the simplicial LDL'); LLT and LDLT free it after
  int64_t *posA, *posB;  // position in S of each upper entry of A / B (CSR order)
  cholmod_factor *L;
  cholmod_dense *X, *Y, *E;  // solve workspaces reused by cholmod_l_solve2
  int64_t solve_width;       // columns per cholmod_l_solve2 call (0: 64)
  bool own_solve;            // narrow blocks through own_solve where available (default)
  bool own_llt;              // LLT: our numeric LL' (super_factor; default) or CHOLMOD's
  double *ow;                // own_solve's workspace: Z (n x ow_w) and G (largest supernode x ow_w)
  int64_t ow_w;              // its width: 8, or 12 or 16 once a block that wide was solved
  double sigma;
  double pivot_rtol;
  // supernodal LDL' and LL' (our numeric factorisations on CHOLMOD's supernodal symbolic
  // analysis); the flags describe the value block in use (Lx, or L->x of our LL')
  double *Lx;       // LDLT: L->xsize values: D on the diagonal, unit-L below
  bool lx_zero;     // the block as calloc gave it (not yet touched: zero pages, not resident)
  size_t lx_dirty;  // lx_zero: its first bytes hold old values (fmbd_calloc_dirty)
  bool lx_kept;     // Lx is an LL' factor's block (fmbd_chol_analyze_like): resident, save the
                    // pages of zeros that release_zero_pages gave back
  int64_t *iperm, *col2super, *map, *head, *next, *lpos, *runs;
  double *wC, *wW;  // update workspaces
  int64_t sizeC, sizeW;
  int64_t neg;  // negative pivots of the last LDLT factorisation
  int64_t failed_row;
  fmbd_chol_stats st;
};

// fmbd_chol_set_input_hook: called once a factorisation's input is formed
static _Thread_local fmbd_chol_input_fn g_input_fn = NULL;
static _Thread_local void *g_input_ctx = NULL;

void fmbd_chol_set_input_hook(fmbd_chol_input_fn fn, void *ctx) {
  g_input_fn = fn;
  g_input_ctx = fn ? ctx : NULL;
}

static void input_formed(void) {
  if (g_input_fn) g_input_fn(g_input_ctx);
}

// CHOLMOD reports errors through a handler; keep the last message for ours.
static char g_cholmod_msg[256];
static void on_cholmod_error(int status, const char *file, int line, const char *message) {
  (void)file;
  (void)line;
  snprintf(g_cholmod_msg, sizeof g_cholmod_msg, "CHOLMOD status %d: %s", status,
           message ? message : "");
}

static void route_suitesparse_memory(void) {
  // every allocation of the project through fmbd_malloc (countdown tests reach CHOLMOD too);
  // CHOLMOD must never print (library code never writes stdout)
  SuiteSparse_config.malloc_func = fmbd_malloc;
  SuiteSparse_config.calloc_func = fmbd_calloc;
  SuiteSparse_config.realloc_func = fmbd_realloc;
  SuiteSparse_config.free_func = fmbd_free;
  SuiteSparse_config.printf_func = NULL;
}

// CHOLMOD's supernodal numeric factorisation runs its scatter and copy loops in OpenMP regions
// with num_threads(CHOLMOD_OMP_NUM_THREADS), 4 as Debian's libcholmod3 is compiled
// (cholmod_core.h), whatever OMP_NUM_THREADS says: on one thread (OMP_NUM_THREADS=1) and on
// this project's 2-core machines the 3 extra threads spun and slept on futexes, about 2.7 of
// the 8 CPU seconds of the 188 k dofs LL' (perf, bench/README.md "fe2cb's memory, third
// round"). With OpenMP's dynamic adjustment on, libgomp caps a region's threads at
// OMP_NUM_THREADS (the cores if unset) less the load average; the loops write disjoint
// entries, so the factor is the same. Set per calling thread (dyn-var is a per-task ICV), found
// at run time like OpenBLAS's thread count (fmbd_blas_set_threads); nothing without libgomp.
static void cap_openmp_threads(void) {
  static int looked = 0;
  static void (*set_dynamic)(int) = NULL;
  if (!looked) {
    looked = 1;
    void *self = dlopen(NULL, RTLD_LAZY);
    if (self) *(void **)&set_dynamic = dlsym(self, "omp_set_dynamic");
  }
  if (set_dynamic) set_dynamic(1);
}

static const char *ordering_name(int o) {
  switch (o) {
    case CHOLMOD_NATURAL:
      return "natural";
    case CHOLMOD_GIVEN:
      return "given";
    case CHOLMOD_AMD:
      return "AMD";
    case CHOLMOD_METIS:
      return "METIS";
    case CHOLMOD_NESDIS:
      return "NESDIS";
    case CHOLMOD_COLAMD:
      return "COLAMD";
    case CHOLMOD_POSTORDERED:
      return "postordered";
  }
  return "unknown";
}

static int cholmod_fail(fmbd_chol *F, const char *what) {
  int st = F->c.status;
  if (st == CHOLMOD_OUT_OF_MEMORY) {
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory in CHOLMOD %s (n = %lld)", what, (long long)F->n);
  }
  FMBD_FAIL(FMBD_ERR_EXTERNAL, "CHOLMOD %s failed: %s", what,
            g_cholmod_msg[0] ? g_cholmod_msg : "unknown status");
}

// --- the union pattern of the upper triangles of A and B, as CSC --------------------------
// For a symmetric matrix in full CSR storage, row j read as a column is column j; the upper
// triangle of column j is the part of row j with column index <= j.
static int build_pattern(fmbd_chol *F) {
  int rc = FMBD_OK;
  const fmbd_csr *A = F->A, *B = F->B;
  int64_t n = F->n, nnz = 0, nA = 0, nB = 0;
  for (int64_t j = 0; j < n; j++) {
    int64_t pa = A->indptr[j], ea = A->indptr[j + 1];
    int64_t pb = B ? B->indptr[j] : 0, eb = B ? B->indptr[j + 1] : 0;
    while (true) {
      int64_t ia = (pa < ea && A->indices[pa] <= j) ? A->indices[pa] : INT64_MAX;
      int64_t ib = (pb < eb && B->indices[pb] <= j) ? B->indices[pb] : INT64_MAX;
      if (ia == INT64_MAX && ib == INT64_MAX) break;
      if (ia <= ib) pa++, nA++;
      if (ib <= ia) pb++, nB++;
      nnz++;
    }
  }
  // the supernodal kinds assemble their numeric matrix from A and B themselves (LLT:
  // assemble_llt or super_factor, LDLT: super_factor): the pattern alone serves their analysis;
  // only the simplicial LDL' hands S's values to cholmod_l_factorize (and without B the upper
  // entries of A are S's entries in order: no map either)
  bool pos = F->kind == FMBD_CHOL_LDLT_SIMPLICIAL;
  F->S = cholmod_l_allocate_sparse((size_t)n, (size_t)n, (size_t)(nnz ? nnz : 1), 1, 1, 1,
                                   pos ? CHOLMOD_REAL : CHOLMOD_PATTERN, &F->c);
  if (!F->S) return cholmod_fail(F, "allocate_sparse");
  if (pos && B) {
    FMBD_GALLOC(F->posA = fmbd_malloc((size_t)(nA ? nA : 1) * sizeof(int64_t)));
    FMBD_GALLOC(F->posB = fmbd_malloc((size_t)(nB ? nB : 1) * sizeof(int64_t)));
  }
  SuiteSparse_long *Sp = F->S->p, *Si = F->S->i;
  double *Sx = F->S->x;
  nnz = nA = nB = 0;
  for (int64_t j = 0; j < n; j++) {
    Sp[j] = nnz;
    int64_t pa = A->indptr[j], ea = A->indptr[j + 1];
    int64_t pb = B ? B->indptr[j] : 0, eb = B ? B->indptr[j + 1] : 0;
    while (true) {
      int64_t ia = (pa < ea && A->indices[pa] <= j) ? A->indices[pa] : INT64_MAX;
      int64_t ib = (pb < eb && B->indices[pb] <= j) ? B->indices[pb] : INT64_MAX;
      if (ia == INT64_MAX && ib == INT64_MAX) break;
      int64_t i = ia < ib ? ia : ib;
      if (ia <= ib) {
        if (F->posA) F->posA[nA++] = nnz;
        pa++;
      }
      if (ib <= ia) {
        if (F->posB) F->posB[nB++] = nnz;
        pb++;
      }
      Si[nnz] = i;
      if (Sx) Sx[nnz] = 0.0;
      nnz++;
    }
  }
  Sp[n] = nnz;
  F->st.nnz_a = nnz;
done:
  return rc;
}

// S := upper(A - sigma B)
static void fill_values(fmbd_chol *F, double sigma) {
  const fmbd_csr *A = F->A, *B = F->B;
  double *Sx = F->S->x;
  memset(Sx, 0, (size_t)F->st.nnz_a * sizeof(double));
  int64_t k = 0;
  for (int64_t j = 0; j < F->n; j++) {
    for (int64_t p = A->indptr[j]; p < A->indptr[j + 1] && A->indices[p] <= j; p++) {
      Sx[F->posA ? F->posA[k] : k] += A->data[p];
      k++;
    }
  }
  if (B && sigma != 0.0) {
    k = 0;
    for (int64_t j = 0; j < F->n; j++) {
      for (int64_t p = B->indptr[j]; p < B->indptr[j + 1] && B->indices[p] <= j; p++) {
        Sx[F->posB[k++]] -= sigma * B->data[p];
      }
    }
  }
}

// --- the LL' input: tril(P (A - sigma B) P'), assembled here ----------------------------------
// What cholmod_l_factorize would hand cholmod_l_super_numeric (its permuted copy of S, made by
// cholmod_l_ptranspose; SuiteSparse CHOLMOD/Cholesky/cholmod_factorize.c), built directly from
// the upper triangles of A and B: S itself is not kept beside it (peak memory of the LL' step:
// one copy of the upper triangle instead of two, bench/README.md). The values are the sums
// fill_values forms (0 + A_ij - sigma B_ij, the same operations in the same order), each
// entry put at (max, min) of its permuted row and column; super_numeric assigns each entry to
// its place in the factor, so the order within a column is free and the factor is bitwise the
// one cholmod_l_factorize gives. dg[k]: the diagonal of pivot k (the singularity test).
static void llt_entries(const fmbd_chol *F, const fmbd_csr *B, double sigma, int64_t *cnt,
                        SuiteSparse_long *Ti, double *Tx, double *dg) {
  const fmbd_csr *A = F->A;
  const int64_t *iperm = F->iperm;
  for (int64_t j = 0; j < F->n; j++) {
    int64_t pa = A->indptr[j], ea = A->indptr[j + 1];
    int64_t pb = B ? B->indptr[j] : 0, eb = B ? B->indptr[j + 1] : 0;
    int64_t pj = iperm[j];
    while (true) {
      int64_t ia = (pa < ea && A->indices[pa] <= j) ? A->indices[pa] : INT64_MAX;
      int64_t ib = (pb < eb && B->indices[pb] <= j) ? B->indices[pb] : INT64_MAX;
      if (ia == INT64_MAX && ib == INT64_MAX) break;
      int64_t i = ia < ib ? ia : ib;
      double v = 0.0;
      if (ia == i) v += A->data[pa++];
      if (ib == i) v -= sigma * B->data[pb++];
      int64_t pi = iperm[i];
      int64_t col = pi < pj ? pi : pj, row = pi < pj ? pj : pi;
      if (Ti) {
        int64_t q = cnt[col]++;
        Ti[q] = row;
        Tx[q] = v;
        if (row == col) dg[col] = v;
      } else {
        cnt[col]++;
      }
    }
  }
}

static int assemble_llt(fmbd_chol *F, double sigma, cholmod_sparse **out, double *dg) {
  int rc = FMBD_OK;
  int64_t n = F->n, *cnt = NULL;
  const fmbd_csr *B = (F->B && sigma != 0.0) ? F->B : NULL;
  cholmod_sparse *T = NULL;
  *out = NULL;
  FMBD_GALLOC(cnt = fmbd_calloc((size_t)n + 1, sizeof(int64_t)));
  llt_entries(F, B, sigma, cnt, NULL, NULL, NULL);
  int64_t nnz = 0;
  for (int64_t k = 0; k < n; k++) {
    int64_t c = cnt[k];
    cnt[k] = nnz;
    nnz += c;
  }
  cnt[n] = nnz;
  T = cholmod_l_allocate_sparse((size_t)n, (size_t)n, (size_t)(nnz ? nnz : 1), 0, 1, -1,
                                CHOLMOD_REAL, &F->c);
  if (!T) FMBD_GCALL(cholmod_fail(F, "allocate_sparse"));
  SuiteSparse_long *Tp = T->p;
  for (int64_t k = 0; k <= n; k++) Tp[k] = cnt[k];
  for (int64_t k = 0; k < n; k++) dg[k] = 0.0;
  llt_entries(F, B, sigma, cnt, T->i, T->x, dg);
  *out = T;
  T = NULL;
done:
  cholmod_l_free_sparse(&T, &F->c);
  fmbd_free(cnt);
  return rc;
}

// --- the unused upper triangles of a supernodal factor's diagonal blocks ---------------------
// A supernodal factor stores each supernode's nsrow x nscol block in full, column-major, but
// its strictly upper triangle (rows above the diagonal in the first nscol rows) is never
// read: CHOLMOD's supernodal numeric factorisation zeroes the block, assembles and updates
// the lower part only, factors the diagonal block with dpotrf('L'), and its solves read the
// lower part (SuiteSparse CHOLMOD/Supernodal/t_cholmod_super_numeric.c, t_cholmod_super_solve.c);
// our LDL' does the same. At 188 k dofs these triangles are most of the 1.50e8 - 1.24e8
// values beyond L's entries (208 MB). The whole memory pages inside column c's upper part
// (c values) that hold only zeros are given back to the system (Linux madvise MADV_DONTNEED
// on private anonymous memory: a page touched again is a fresh zero page, so the values are
// the same whether or not a page was given back); a page with any nonzero is kept. Returns
// the bytes given back (0 where madvise is unavailable or fails).
static double release_zero_pages(const cholmod_factor *L, double *x) {
  double freed = 0.0;
#ifdef MADV_DONTNEED
  long pg = sysconf(_SC_PAGESIZE);
  if (pg <= 0 || !L->is_super || !x) return 0.0;
  const SuiteSparse_long *super = L->super, *pi = L->pi, *px = L->px;
  size_t per = (size_t)pg / sizeof(double);
  for (int64_t s = 0; s < (int64_t)L->nsuper; s++) {
    int64_t nscol = super[s + 1] - super[s], nsrow = pi[s + 1] - pi[s];
    if (nscol <= (int64_t)per) continue;  // no column holds a whole page above its diagonal
    for (int64_t c = (int64_t)per; c < nscol; c++) {
      double *col = x + px[s] + c * nsrow;
      uintptr_t lo = ((uintptr_t)col + (uintptr_t)pg - 1) & ~(uintptr_t)(pg - 1);
      uintptr_t hi = (uintptr_t)(col + c) & ~(uintptr_t)(pg - 1);
      if (hi <= lo) continue;
      const double *a = (const double *)lo, *e = (const double *)hi;
      bool zero = true;
      for (; a < e && zero; a++) zero = *a == 0.0;
      if (zero && madvise((void *)lo, hi - lo, MADV_DONTNEED) == 0) freed += (double)(hi - lo);
    }
  }
#else
  (void)L;
  (void)x;
#endif
  return freed;
}

// --- supernodal LDL' without pivoting, and LL' ------------------------------------------------
// Left-looking over CHOLMOD's supernodes (Ng and Peyton 1993; the structure of CHOLMOD's
// t_cholmod_super_numeric.c, written here for D): for each supernode s, assemble its columns of
// P (A - sigma B) P', subtract the updates L_d D_d L_d(rows of s)' of every descendant d (dense
// products by column blocks, each scattered into s while it is in cache), then factor the
// panel of s (diagonal block and rows below) as [L11; L21] D L11' (panel: recursive,
// unpivoted). Without pivoting the D of a symmetric indefinite matrix is the same as the
// simplicial LDL' one; its signs give the inertia of the matrix factored (Sylvester). BLAS-3
// throughout, so the Sturm count costs about one Cholesky factorisation instead of 10-20.
// What guards the count: a zero or NaN pivot stops it (FMBD_ERR_SINGULAR); the largest |L|
// entry (element growth, which an unpivoted LDL' of an indefinite matrix does not bound) is
// logged with the count; the eigensolver places the shift in a clear gap of its converged
// pairs, so a count that disagrees makes it solve again, never pass silently.
//
// The same code (ll true) is the LL' of the LLT kind, into the value block of CHOLMOD's own
// symbolic supernodal factor (L->x: the layout px / pi / s / super that cholmod_l_super_numeric
// fills, is_ll), so that CHOLMOD's solves and own_solve read it unchanged: the descendants'
// updates are L_d L_d(rows of s)' (no D, no scaled copy), the leaves take square roots. No
// pivoting is needed: for a symmetric positive definite matrix every pivot of the unpivoted
// elimination is a ratio of leading principal minors, hence positive, and the entries of L are
// bounded by the diagonal (l_ij^2 <= a_ii), so Cholesky is backward stable without any choice of
// pivots (Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed., section 10.1: the
// computed L L' = A + dA, |dA| <= gamma_{c+1} |L| |L'|, c the column count). A pivot that comes
// out <= 0 or NaN (the test of LAPACK's dpotrf, which CHOLMOD's LL' applies per supernode) means
// the matrix is not numerically positive definite: the factorisation stops at that column and
// reports it as CHOLMOD does (L->minor and CHOLMOD_NOT_POSDEF; check_pivots then gives the same
// message and failed_row, on which fe2cb's rigid-mode message and fmbd_eig's shifts rely).
static int super_setup(fmbd_chol *F, bool ll) {
  int rc = FMBD_OK;
  cholmod_factor *L = F->L;
  FMBD_GCHECK(L->is_super, FMBD_ERR_INTERNAL, "CHOLMOD analysis is not supernodal");
  int64_t n = F->n, ns = (int64_t)L->nsuper;
  const SuiteSparse_long *super = L->super, *pi = L->pi, *perm = L->Perm;
  if (!ll) {
    // zeroed by calloc: the pages that the factorisation never writes (most of the diagonal
    // blocks' upper triangles) are never made resident
    FMBD_GALLOC(F->Lx = fmbd_calloc_dirty(L->xsize ? L->xsize : 1, sizeof(double), &F->lx_dirty));
    F->lx_zero = true;
  }
  if (!F->iperm) FMBD_GALLOC(F->iperm = fmbd_malloc((size_t)(n ? n : 1) * sizeof(int64_t)));
  FMBD_GALLOC(F->col2super = fmbd_malloc((size_t)(n ? n : 1) * sizeof(int64_t)));
  FMBD_GALLOC(F->map = fmbd_malloc((size_t)(n ? n : 1) * sizeof(int64_t)));
  FMBD_GALLOC(F->head = fmbd_malloc((size_t)(ns + 1) * sizeof(int64_t)));
  FMBD_GALLOC(F->next = fmbd_malloc((size_t)(ns + 1) * sizeof(int64_t)));
  FMBD_GALLOC(F->lpos = fmbd_malloc((size_t)(ns + 1) * sizeof(int64_t)));
  for (int64_t k = 0; k < n; k++) F->iperm[perm ? perm[k] : k] = k;
  int64_t maxC = 1, maxW = 1, maxR = 1;
  for (int64_t d = 0; d < ns; d++) {
    int64_t ncol = super[d + 1] - super[d], nrow = pi[d + 1] - pi[d], off = nrow - ncol;
    if (off > maxR) maxR = off;
    for (int64_t k = super[d]; k < super[d + 1]; k++) F->col2super[k] = d;
    if (off * (off < LDL_CB ? off : LDL_CB) > maxC) maxC = off * (off < LDL_CB ? off : LDL_CB);
    if (ll) continue;  // the LL' multiplies L by itself: no scaled copies
    if (off * ncol > maxW) maxW = off * ncol;
    if (ncol * LDL_KC > maxW) maxW = ncol * LDL_KC;  // the panel's products (panel)
  }
  F->sizeC = maxC;
  F->sizeW = maxW;
  fmbd_log(FMBD_LOG_DEBUG, "%s: %lld supernodes, %.3g values in L, update workspaces %.3g + %.3g",
           ll ? "LL'" : "LDL'", (long long)ns, (double)L->xsize, (double)maxC, (double)maxW);
  FMBD_GALLOC(F->wC = fmbd_malloc((size_t)maxC * sizeof(double)));
  FMBD_GALLOC(F->wW = fmbd_malloc((size_t)maxW * sizeof(double)));
  FMBD_GALLOC(F->runs = fmbd_malloc((size_t)(2 * maxR + 2) * sizeof(int64_t)));
done:
  return rc;
}

// C (m x n, ldc) = alpha A B' + beta C (A m x k, B n x k, column-major), m >= n, where only
// the lower trapezoid (rows i >= column j) is wanted: by column blocks of 128, each product
// starting at its block's diagonal, so the part above the diagonal is not computed beyond the
// blocks' corners (half the flops of a square update, bench/README.md "third round")
static void gemm_lower(int64_t m, int64_t n, int64_t k, double alpha, const double *A, int64_t lda,
                       const double *B, int64_t ldb, double beta, double *C, int64_t ldc) {
  const int64_t cb = 128;
  for (int64_t c0 = 0; c0 < n; c0 += cb) {
    int64_t w = n - c0 < cb ? n - c0 : cb;
    cblas_dgemm(CblasColMajor, CblasNoTrans, CblasTrans, (int)(m - c0), (int)w, (int)k, alpha,
                A + c0, (int)lda, B + c0, (int)ldb, beta, C + c0 + c0 * ldc, (int)ldc);
  }
}

// --- a supernode's columns: unpivoted LDL' (or LL') of its nsrow x nscol panel --------------
// the leaf of panel: columns one by one (left-looking), each less the earlier leaf columns
// times D (LL': times nothing) (a dgemv where the column is long, plain loops where it is
// short); returns the index of a zero or NaN pivot (LL': <= 0 or NaN), or -1
static int64_t panel_leaf(int64_t m, int64_t n, double *A, int64_t lda, bool ll, int64_t *neg,
                          double *lmax) {
  double t[LDL_LEAF];
  for (int64_t j = 0; j < n; j++) {
    double *aj = A + j * lda;
    if (ll) {
      for (int64_t k = 0; k < j; k++) t[k] = A[j + k * lda];
    } else {
      for (int64_t k = 0; k < j; k++) t[k] = A[j + k * lda] * A[k + k * lda];
    }
    if (j > 0 && m - j >= 64) {
      cblas_dgemv(CblasColMajor, CblasNoTrans, (int)(m - j), (int)j, -1.0, A + j, (int)lda, t, 1,
                  1.0, aj + j, 1);
    } else {
      for (int64_t k = 0; k < j; k++) {
        const double *lk = A + k * lda;
        for (int64_t i = j; i < m; i++) aj[i] -= lk[i] * t[k];
      }
    }
    double d = aj[j];
    if (ll) {
      if (!(d > 0.0)) return j;
      d = sqrt(d);
      aj[j] = d;
      double r = 1.0 / d;
      for (int64_t i = j + 1; i < m; i++) aj[i] *= r;
      continue;
    }
    if (d == 0.0 || d != d) return j;
    *neg += d < 0.0;
    double r = 1.0 / d, big = *lmax;
    for (int64_t i = j + 1; i < m; i++) {
      double v = aj[i] * r;
      aj[i] = v;
      big = fabs(v) > big ? fabs(v) : big;
    }
    *lmax = big;
  }
  return -1;
}

// The panel A (m x n, m >= n, leading dimension lda: the diagonal block and the rows below it)
// factored in place as the lower trapezoid [L11; L21] with D on the diagonal (LL': L11
// itself), by halves (recursive blocking, as Gustavson's recursive Cholesky, IBM J. Res. Dev.
// 41(6), 1997): the left half, then the right half's columns (rows at and below their
// diagonal) less L(below, left) D L(right, left)' by dgemm, then the right half. The rows below
// the diagonal block, which a dtrsm (and for the LDL' a scaling by D^-1) solved before, are
// solved within the same products, so all flops but the leaves' (LDL_LEAF columns at most) go
// through dgemm: the panel stage of the 188 k-dof rod's LDL' 2.3 -> 1.8 s (bench/README.md,
// "The Sturm check's LDL'"). Nothing above the diagonal is read. W (LDL' only): the right
// half's rows of the left half times D, by chunks of LDL_KC columns (nscol x LDL_KC values at
// most). Returns the index of a zero or NaN pivot (LL': <= 0 or NaN), or -1.
static int64_t panel(int64_t m, int64_t n, double *A, int64_t lda, double *W, bool ll, int64_t *neg,
                     double *lmax) {
  if (n <= LDL_LEAF) return panel_leaf(m, n, A, lda, ll, neg, lmax);
  int64_t n1 = n / 2, n2 = n - n1;
  int64_t bad = panel(m, n1, A, lda, W, ll, neg, lmax);
  if (bad >= 0) return bad;
  if (ll) {
    // A(n1:m, n1:n) -= L(n1:m, 0:n1) L(n1:n, 0:n1)', lower trapezoid: the triangle by dsyrk
    // (nothing written above the diagonal: the LL' block's upper triangles stay zero, as
    // CHOLMOD's), the rows below by dgemm
    cblas_dsyrk(CblasColMajor, CblasLower, CblasNoTrans, (int)n2, (int)n1, -1.0, A + n1, (int)lda,
                1.0, A + n1 + n1 * lda, (int)lda);
    if (m > n)
      cblas_dgemm(CblasColMajor, CblasNoTrans, CblasTrans, (int)(m - n), (int)n2, (int)n1, -1.0,
                  A + n, (int)lda, A + n1, (int)lda, 1.0, A + n + n1 * lda, (int)lda);
  } else {
    // A(n1:m, n1:n) -= L(n1:m, 0:n1) D L(n1:n, 0:n1)', lower trapezoid
    for (int64_t k0 = 0; k0 < n1; k0 += LDL_KC) {
      int64_t kb = n1 - k0 < LDL_KC ? n1 - k0 : LDL_KC;
      for (int64_t c = 0; c < kb; c++) {
        const double *lc = A + n1 + (k0 + c) * lda;
        double dc = A[(k0 + c) + (k0 + c) * lda];
        for (int64_t r = 0; r < n2; r++) W[r + c * n2] = lc[r] * dc;
      }
      gemm_lower(m - n1, n2, kb, -1.0, A + n1 + k0 * lda, lda, W, n2, 1.0, A + n1 + n1 * lda, lda);
    }
  }
  bad = panel(m - n1, n2, A + n1 + n1 * lda, lda, W, ll, neg, lmax);
  return bad >= 0 ? n1 + bad : -1;
}

// The value block Lx cleared before a factorisation: when calloc gave it (lx_zero), only
// written once per page (below); the rows on and below each column's diagonal otherwise. Above the
// diagonal (the diagonal blocks' strictly upper triangles) nothing here writes and nothing reads
// (the kernels above, the solves: release_zero_pages), so those stay as they were: zero, never made
// resident, in our own blocks; in an LL' block that CHOLMOD factored (lx_kept), only the nonzeros
// are cleared (reading a page given back maps the shared zero page: no memory, no clearing). A
// calloc'd block is written once per page where the kernels will read (the rows on and below each
// column's diagonal): the prefill and the updates read each place before writing it, and a first
// read of an untouched page maps the shared zero page, which the write after it faults again (two
// page faults per page: 86,900 instead of 41,900 in the 180 MB factor at 51 k dofs,
// bench/README.md "The large blocks' pages"); a first write faults once.
static void clear_block(fmbd_chol *F, double *Lx) {
  const cholmod_factor *L = F->L;
  const SuiteSparse_long *super = L->super, *pi = L->pi, *px = L->px;
  if (F->lx_zero) {
    long pg = sysconf(_SC_PAGESIZE);
    uintptr_t mask = pg > 0 ? (uintptr_t)pg - 1 : 4095;
    for (int64_t s = 0; s < (int64_t)L->nsuper; s++) {
      int64_t nsrow = pi[s + 1] - pi[s];
      for (int64_t c = 0; c < super[s + 1] - super[s]; c++) {
        double *col = Lx + px[s] + c * nsrow, *a = col + c, *e = col + nsrow;
        if ((char *)col < (char *)Lx + F->lx_dirty) {
          // pages the pool reused (fmbd_calloc_dirty): the rows on and below the diagonal
          // cleared; above it, the whole pages given back (zero pages again, not resident, as
          // in a fresh block), the rest cleared
          memset(a, 0, (size_t)(e - a) * sizeof(double));
          uintptr_t lo = ((uintptr_t)col + mask) & ~mask, hi = (uintptr_t)a & ~mask;
#ifdef MADV_DONTNEED
          if (hi > lo && madvise((void *)lo, hi - lo, MADV_DONTNEED) == 0) {
            memset(col, 0, lo - (uintptr_t)col);
            memset((void *)hi, 0, (uintptr_t)a - hi);
            continue;
          }
#endif
          memset(col, 0, (size_t)c * sizeof(double));
          continue;
        }
        // the column's first place, then the first place of each page it enters
        *a = 0.0;
        for (a = (double *)(((uintptr_t)a + mask + 1) & ~mask); a < e; a += (mask + 1) / 8)
          *a = 0.0;
      }
    }
  } else {
    for (int64_t s = 0; s < (int64_t)L->nsuper; s++) {
      int64_t nsrow = pi[s + 1] - pi[s];
      for (int64_t c = 0; c < super[s + 1] - super[s]; c++) {
        double *col = Lx + px[s] + c * nsrow;
        for (int64_t i = 0; i < c && F->lx_kept; i++)
          if (col[i] != 0.0) col[i] = 0.0;
        memset(col + c, 0, (size_t)(nsrow - c) * sizeof(double));
      }
    }
  }
  F->lx_zero = F->lx_kept = false;
  F->lx_dirty = 0;
}

// P (A - sigma B) P' put into the cleared factor Lx before the supernodal loop, for a matrix
// stored as its lower triangle (fmbd_csr_keep_lower: a full row, which the loop reads per
// column, is not at hand): each entry (i, j), j <= i, goes to (max, min) of its permuted
// indices. The rows are visited in pivot order (row j = perm[k] for k = 0, 1, ...), supernode by
// supernode, so that every place is found without a search: an entry in column k (its other
// index a >= k) through `map`, set to the rows of k's supernode; one in an earlier column a < k
// (row k of a's supernode t) through a cursor in t's ascending row list, which only moves
// forward since k increases (`lpos`, set afresh by the loop afterwards). The writes of the
// first kind go down the factor's columns in order. The same sums (0 + a - sigma b) as the
// loop's assembly; the values come from the lower triangle instead of the column's own row.
// The places are found for PREFILL_CHUNK entries at a time, each prefetched for writing as
// soon as it is known, and then the chunk's sums are made (prefill_sums): the places lie all
// over the value block (180 MB at 51 k dofs), nearly every one a cache miss, and these now
// overlap instead of coming one at a time (0.02 s of the 0.41-0.47 s of a 51 k factorisation,
// bench/README.md "The factorisations' prefill"). Each place receives one entry of each
// matrix, so deferring the sums within a pass changes no bit.
// super_prefill's sums for nb entries of A (pass m: 0 A, and Bs's entry at the same place
// when given; 1 B alone), ps their positions in A's arrays, xs their places in the factor
static void prefill_sums(double *const *xs, const int64_t *ps, int64_t nb, const fmbd_csr *A,
                         const fmbd_csr *Bs, int m, double sigma) {
  if (m == 1) {
    for (int64_t e = 0; e < nb; e++) *xs[e] -= sigma * A->data[ps[e]];
  } else if (Bs) {
    for (int64_t e = 0; e < nb; e++) {
      *xs[e] += A->data[ps[e]];
      *xs[e] -= sigma * Bs->data[ps[e]];
    }
  } else {
    for (int64_t e = 0; e < nb; e++) *xs[e] += A->data[ps[e]];
  }
}
static int super_prefill(fmbd_chol *F, double sigma, double *Lx) {
  cholmod_factor *L = F->L;
  const SuiteSparse_long *super = L->super, *pi = L->pi, *px = L->px, *Ls = L->s, *perm = L->Perm;
  int64_t nsuper = (int64_t)L->nsuper, *map = F->map, *cur = F->lpos, *c2s = F->col2super;
  const int64_t *iperm = F->iperm;
  const fmbd_csr *mat[2] = {F->A, sigma != 0.0 ? F->B : NULL};
  // B on A's index arrays (fe2cb's Ms on Ks's): one place serves both entries, which then
  // get the same operations in the same order as in two passes (each position holds one
  // entry of each)
  const fmbd_csr *Bs = mat[1];
  bool both =
      Bs && Bs->indptr == F->A->indptr && Bs->indices == F->A->indices && Bs->lower == F->A->lower;
  if (both) mat[1] = NULL;
  double *xs[PREFILL_CHUNK];
  int64_t ps[PREFILL_CHUNK], nb = 0;
  for (int m = 0; m < 2; m++) {
    const fmbd_csr *A = mat[m];
    if (!A) continue;
    for (int64_t t = 0; t < nsuper; t++) cur[t] = pi[t];
    for (int64_t s = 0; s < nsuper; s++) {
      int64_t k1 = super[s], psi = pi[s], nsrow = pi[s + 1] - psi;
      double *Lsx = Lx + px[s];
      for (int64_t i = 0; i < nsrow; i++) map[Ls[psi + i]] = i;
      for (int64_t k = k1; k < super[s + 1]; k++) {
        int64_t j = perm ? perm[k] : k;
        for (int64_t p = A->indptr[j]; p < A->indptr[j + 1] && A->indices[p] <= j; p++) {
          int64_t a = iperm[A->indices[p]];
          double *x;
          if (a >= k1) {
            // column min(a, k) of s, row max(a, k)
            int64_t c = a < k ? a : k, r = a < k ? k : a, q = map[r];
            FMBD_CHECK(q >= 0 && q < nsrow && Ls[psi + q] == r, FMBD_ERR_INTERNAL,
                       "entry (%lld, %lld) not in the factor's pattern", (long long)r,
                       (long long)c);
            x = Lsx + (c - k1) * nsrow + q;
          } else {
            // column a of an earlier supernode t, row k
            int64_t t = c2s[a], q = cur[t], e = pi[t + 1];
            while (q < e && Ls[q] < k) q++;
            cur[t] = q;
            FMBD_CHECK(q < e && Ls[q] == k, FMBD_ERR_INTERNAL,
                       "entry (%lld, %lld) not in the factor's pattern", (long long)k,
                       (long long)a);
            x = Lx + px[t] + (a - super[t]) * (e - pi[t]) + (q - pi[t]);
          }
          __builtin_prefetch(x, 1, 3);
          xs[nb] = x;
          ps[nb++] = p;
          if (nb == PREFILL_CHUNK) {
            prefill_sums(xs, ps, nb, A, both ? Bs : NULL, m, sigma);
            nb = 0;
          }
        }
      }
    }
    prefill_sums(xs, ps, nb, A, both ? Bs : NULL, m, sigma);
    nb = 0;
  }
  return FMBD_OK;
}

// dst[0..len) -= src[0..len), by fours (independent subtractions the compiler turns into vector
// instructions at -O2; the plain loop stayed scalar: the update scatter was the LL's largest
// cost outside the BLAS, bench/README.md "our own LL'")
static inline void sub_run(double *restrict dst, const double *restrict src, int64_t len) {
  int64_t i = 0;
  for (; i + 4 <= len; i += 4) {
    dst[i] -= src[i];
    dst[i + 1] -= src[i + 1];
    dst[i + 2] -= src[i + 2];
    dst[i + 3] -= src[i + 3];
  }
  for (; i < len; i++) dst[i] -= src[i];
}

// Lsx (supernode s, columns k1.., nsrow rows, map: row -> place) -= C (nr2 x nr1, lower
// trapezoid), C's rows being the rows rows[0..nr2-1] of s (rows[0..nr1-1] also its columns).
// The places of the rows are found once (`runs`: the places, then the starts of the runs of
// consecutive places, 2 (nr2 + 1) values at most). Where the runs are long (a mean of
// SCATTER_RUN rows or more), each column subtracts run by run, contiguous on both sides; where
// they are short, place by place: most runs are short (one 51 k LL' scatters 40.8 M values in
// 6.1 M runs, 44 % of the values in runs under 8), and a run's start costs more than its
// values there (0.003-0.008 s less per 51 k factorisation, bench/README.md "The
// factorisations' prefill"). Either way every place gets the same one subtraction.
static void scatter_update(int64_t nr1, int64_t nr2, const double *C, const SuiteSparse_long *rows,
                           const int64_t *map, int64_t k1, double *Lsx, int64_t nsrow,
                           int64_t *runs) {
  int64_t *place = runs, *start = runs + nr2 + 1, nrun = 0;
  for (int64_t ii = 0; ii < nr2; ii++) {
    int64_t t = map[rows[ii]];
    place[ii] = t;
    if (ii == 0 || t != place[ii - 1] + 1) start[nrun++] = ii;
  }
  start[nrun] = nr2;
  if (nr2 < SCATTER_RUN * nrun) {
    for (int64_t jj = 0; jj < nr1; jj++) {
      double *col = Lsx + (rows[jj] - k1) * nsrow;
      const double *c = C + jj * nr2;
      int64_t i = jj;
      for (; i + 4 <= nr2; i += 4) {
        // four distinct places: loads first, then the stores
        double *d0 = col + place[i], *d1 = col + place[i + 1], *d2 = col + place[i + 2];
        double *d3 = col + place[i + 3];
        double v0 = *d0 - c[i], v1 = *d1 - c[i + 1], v2 = *d2 - c[i + 2], v3 = *d3 - c[i + 3];
        *d0 = v0;
        *d1 = v1;
        *d2 = v2;
        *d3 = v3;
      }
      for (; i < nr2; i++) col[place[i]] -= c[i];
    }
    return;
  }
  int64_t q = 0;
  for (int64_t jj = 0; jj < nr1; jj++) {
    while (start[q + 1] <= jj) q++;
    double *col = Lsx + (rows[jj] - k1) * nsrow;
    const double *c = C + jj * nr2;
    for (int64_t r = q; r < nrun; r++) {
      int64_t i0 = r == q ? jj : start[r], len = start[r + 1] - i0;
      sub_run(col + place[i0], c + i0, len);
    }
  }
}

// The supernodal factorisation of P (A - sigma B) P' into the value block Lx (super_setup's
// workspaces): LDL' (ll false; a zero or NaN pivot fails with FMBD_ERR_SINGULAR; the negative
// pivots in F->neg) or LL' (ll true; a pivot <= 0 or NaN stops it at pivot *minor, else
// *minor = -1). dg (LL', or NULL): the diagonal of P (A - sigma B) P' as assembled.
static int super_factor(fmbd_chol *F, double sigma, double *Lx, bool ll, double *dg,
                        int64_t *minor) {
  cholmod_factor *L = F->L;
  const SuiteSparse_long *super = L->super, *pi = L->pi, *px = L->px, *Ls = L->s, *perm = L->Perm;
  int64_t nsuper = (int64_t)L->nsuper;
  int64_t *map = F->map, *head = F->head, *next = F->next, *lpos = F->lpos, *c2s = F->col2super;
  const fmbd_csr *A = F->A, *B = F->B;
  int64_t neg = 0;
  double lmax = 0.0;  // largest |L| entry below the diagonal (LDL')
  if (minor) *minor = -1;
  clear_block(F, Lx);
  bool prefill = A->lower || (B && B->lower);
  if (prefill) {
    FMBD_CALL(super_prefill(F, sigma, Lx));
    input_formed();  // the loop below reads only the factor
    for (int64_t s = 0; dg && s < nsuper; s++) {
      int64_t nsrow = pi[s + 1] - pi[s];
      for (int64_t k = super[s]; k < super[s + 1]; k++)
        dg[k] = Lx[px[s] + (k - super[s]) * (nsrow + 1)];
    }
  }
  for (int64_t s = 0; s <= nsuper; s++) head[s] = -1;
  for (int64_t s = 0; s < nsuper; s++) {
    int64_t k1 = super[s], k2 = super[s + 1], nscol = k2 - k1;
    int64_t psi = pi[s], nsrow = pi[s + 1] - psi, psx = px[s];
    double *Lsx = Lx + psx;
    for (int64_t i = 0; i < nsrow; i++) map[Ls[psi + i]] = i;
    // --- assemble columns k1..k2-1 of P (A - sigma B) P' (rows >= k) ---
    for (int64_t k = k1; k < k2 && !prefill; k++) {
      int64_t j = perm ? perm[k] : k;
      double *col = Lsx + (k - k1) * nsrow;
      for (int64_t p = A->indptr[j]; p < A->indptr[j + 1]; p++) {
        int64_t r = F->iperm[A->indices[p]];
        if (r >= k) col[map[r]] += A->data[p];
      }
      if (B && sigma != 0.0) {
        for (int64_t p = B->indptr[j]; p < B->indptr[j + 1]; p++) {
          int64_t r = F->iperm[B->indices[p]];
          if (r >= k) col[map[r]] -= sigma * B->data[p];
        }
      }
      if (dg) dg[k] = col[k - k1];
    }
    // --- updates from the descendants linked to s ---
    int64_t d = head[s];
    head[s] = -1;
    while (d >= 0) {
      int64_t dnext = next[d];
      int64_t ndcol = super[d + 1] - super[d], pdi = pi[d], pdend = pi[d + 1];
      int64_t ndrow = pdend - pdi;
      const double *Ldx = Lx + px[d];
      int64_t p1 = lpos[d], p2 = p1;
      while (p2 < pdend && Ls[p2] < k2) p2++;
      int64_t nr1 = p2 - p1, nr2 = pdend - p1, r1 = p1 - pdi;
      // C = L_d(rows >= k1) W' (nr2 x nr1), W = L_d(rows in s) D_d (LDL': a scaled copy,
      // nr1 x ndcol) or L_d(rows in s) itself (LL')
      double *C = F->wC;
      const double *W = Ldx + r1;
      int64_t ldw = ndrow;
      if (!ll) {
        for (int64_t c = 0; c < ndcol; c++) {
          double dc = Ldx[c + c * ndrow];
          for (int64_t r = 0; r < nr1; r++) F->wW[r + c * nr1] = Ldx[r1 + r + c * ndrow] * dc;
        }
        W = F->wW;
        ldw = nr1;
      }
      // by column blocks of C, each scattered while it is in cache
      for (int64_t c0 = 0; c0 < nr1; c0 += LDL_CB) {
        int64_t w = nr1 - c0 < LDL_CB ? nr1 - c0 : LDL_CB;
        gemm_lower(nr2 - c0, w, ndcol, 1.0, Ldx + r1 + c0, ndrow, W + c0, ldw, 0.0, C, nr2 - c0);
        scatter_update(w, nr2 - c0, C, Ls + p1 + c0, map, k1, Lsx, nsrow, F->runs);
      }
      lpos[d] = p2;
      if (p2 < pdend) {
        int64_t t = c2s[Ls[p2]];
        next[d] = head[t];
        head[t] = d;
      }
      d = dnext;
    }
    // --- the diagonal block and the rows below it ---
    int64_t bad = panel(nsrow, nscol, Lsx, nsrow, F->wW, ll, &neg, &lmax);
    if (bad >= 0 && ll) {
      *minor = k1 + bad;
      return FMBD_OK;
    }
    if (bad >= 0) {
      F->failed_row = perm ? perm[k1 + bad] : k1 + bad;
      FMBD_FAIL(FMBD_ERR_SINGULAR, "zero pivot in LDL' at row %lld (shift %.17g is an eigenvalue)",
                (long long)F->failed_row, sigma);
    }
    if (nsrow > nscol) {
      lpos[s] = psi + nscol;
      int64_t t = c2s[Ls[psi + nscol]];
      next[s] = head[t];
      head[t] = s;
    }
  }
  if (!prefill && ll) input_formed();  // (the contract: A and B not read from here on)
  if (ll) return FMBD_OK;
  F->neg = neg;
  fmbd_log(FMBD_LOG_DEBUG,
           "LDL' of the matrix shifted by %.9g: %lld negative pivots, largest |L| %.3g", sigma,
           (long long)neg, lmax);
  return FMBD_OK;
}

// Our LL' (super_factor) into CHOLMOD's symbolic supernodal factor F->L: made numeric as
// cholmod_l_change_factor makes a symbolic supernodal factor an LL' one (CHOLMOD's
// Core/cholmod_change_factor.c, super_symbolic_to_ll_super: the value block of L->xsize
// doubles, xtype real, is_ll, minor n), the block zeroed by calloc here so that the diagonal
// blocks' upper triangles, never written, are never made resident (what release_zero_pages
// does after CHOLMOD's LL'); a factor made before (a new shift) is factored again in place. A
// pivot <= 0 or NaN is reported as CHOLMOD reports it (L->minor, CHOLMOD_NOT_POSDEF).
static int own_llt(fmbd_chol *F, double sigma, double *dg) {
  cholmod_factor *L = F->L;
  if (!F->runs) {
    // the loop's workspaces, at the first factorisation (all or none: a failed allocation
    // leaves none behind, and the next call tries again)
    int rc = super_setup(F, true);
    if (rc) {
      int64_t **iw[] = {&F->col2super, &F->map, &F->head, &F->next, &F->lpos, &F->runs};
      for (size_t i = 0; i < sizeof iw / sizeof iw[0]; i++) {
        fmbd_free(*iw[i]);
        *iw[i] = NULL;
      }
      fmbd_free(F->wC);
      fmbd_free(F->wW);
      F->wC = F->wW = NULL;
      return rc;
    }
  }
  if (L->xtype == CHOLMOD_PATTERN || !L->x) {
    size_t dirty;
    double *x = fmbd_calloc_dirty(L->xsize ? L->xsize : 1, sizeof(double), &dirty);
    FMBD_CHECK(x, FMBD_ERR_NOMEM, "out of memory (%.4g values of the LL' factor, n = %lld)",
               (double)L->xsize, (long long)F->n);
    fmbd_free(L->x);
    L->x = x;
    L->z = NULL;
    L->xtype = CHOLMOD_REAL;
    L->dtype = CHOLMOD_DOUBLE;
    L->is_ll = 1;
    F->lx_zero = true;
    F->lx_dirty = dirty;
    F->lx_kept = false;
  }
  int64_t minor = -1;
  F->c.status = CHOLMOD_OK;
  FMBD_CALL(super_factor(F, sigma, L->x, true, dg, &minor));
  L->minor = minor >= 0 ? (size_t)minor : (size_t)F->n;
  if (minor >= 0) F->c.status = CHOLMOD_NOT_POSDEF;
  return FMBD_OK;
}

// D's symbolic factor if it is the one an LDLT of (A, B) with D's ordering would make: D a
// supernodal LL' of the same matrix A (object and arrays) with its values dropped (the copy is
// then symbolic), B NULL or on A's index arrays (so the union pattern is A's)
static const fmbd_chol *same_analysis(const fmbd_chol *D, const fmbd_csr *A, const fmbd_csr *B,
                                      int kind) {
  if (!D || kind != FMBD_CHOL_LDLT || D->kind != FMBD_CHOL_LLT || D->B || D->A != A || !D->L ||
      !D->L->is_super || D->L->xtype != CHOLMOD_PATTERN || !D->L->Perm)
    return NULL;
  if (B && (B->indptr != A->indptr || B->indices != A->indices || B->lower != A->lower))
    return NULL;
  return D;
}

static int analyze(const fmbd_csr *A, const fmbd_csr *B, int kind, const int64_t *perm,
                   const fmbd_chol *like, fmbd_chol **out);

int fmbd_chol_analyze(const fmbd_csr *A, const fmbd_csr *B, int kind, fmbd_chol **out) {
  return fmbd_chol_analyze_perm(A, B, kind, NULL, out);
}

int fmbd_chol_get_perm(const fmbd_chol *F, int64_t *perm) {
  const SuiteSparse_long *p = F->L ? F->L->Perm : NULL;
  FMBD_CHECK(p, FMBD_ERR_INTERNAL, "factor without a permutation");
  for (int64_t k = 0; k < F->n; k++) perm[k] = p[k];
  return FMBD_OK;
}

int fmbd_chol_analyze_perm(const fmbd_csr *A, const fmbd_csr *B, int kind, const int64_t *perm,
                           fmbd_chol **out) {
  return analyze(A, B, kind, perm, NULL, out);
}

int fmbd_chol_analyze_like(fmbd_chol *like, const fmbd_csr *A, const fmbd_csr *B, int kind,
                           fmbd_chol **out) {
  *out = NULL;
  FMBD_CHECK(like && like->L && like->L->Perm, FMBD_ERR_INTERNAL,
             "analysis like a factor without a permutation");
  FMBD_CALL(analyze(A, B, kind, (const int64_t *)like->L->Perm, like, out));
  fmbd_chol *F = *out;
  if (F->kind == FMBD_CHOL_LDLT && like->kept && like->kept_n == (size_t)F->L->xsize) {
    // the LL' values' block (the same supernodes, so the same size) becomes the LDL' factor:
    // its pages are resident, where a fresh block's are faulted and zeroed by the kernel on
    // first touch (bench/README.md "The LL' factor's block for the LDL'"); clear_block clears
    // it. The calloc'd block super_setup made was never touched: no pages to give back.
    fmbd_free(F->Lx);
    F->Lx = like->kept;
    F->lx_zero = false;
    F->lx_dirty = 0;
    F->lx_kept = true;
    fmbd_log(FMBD_LOG_DEBUG, "LDL': factored into the LL' factor's block");
    like->kept = NULL;
    like->kept_n = 0;
  }
  return FMBD_OK;
}

// fmbd_chol_analyze_perm; like: an earlier factor whose symbolic factor is copied where it is
// the one this analysis would make (same_analysis), perm then being its ordering
static int analyze(const fmbd_csr *A, const fmbd_csr *B, int kind, const int64_t *perm,
                   const fmbd_chol *like, fmbd_chol **out) {
  int rc = FMBD_OK;
  fmbd_chol *F = NULL;
  *out = NULL;
  FMBD_CHECK(A && A->nrows == A->ncols, FMBD_ERR_VALUE, "matrix to factor is not square");
  FMBD_CHECK(!B || (B->nrows == A->nrows && B->ncols == A->ncols), FMBD_ERR_VALUE,
             "second matrix %lld x %lld, expected %lld x %lld", (long long)(B ? B->nrows : 0),
             (long long)(B ? B->ncols : 0), (long long)A->nrows, (long long)A->ncols);
  FMBD_CHECK(kind == FMBD_CHOL_LLT || kind == FMBD_CHOL_LDLT || kind == FMBD_CHOL_LDLT_SIMPLICIAL,
             FMBD_ERR_VALUE, "bad kind %d", kind);
  route_suitesparse_memory();
  cap_openmp_threads();
  FMBD_GALLOC(F = fmbd_calloc(1, sizeof *F));
  F->kind = kind;
  F->n = A->nrows;
  F->A = A;
  F->B = B;
  F->pivot_rtol = 1e-13;
  F->own_solve = true;
  // FMBD_CHOL_LLT=cholmod: CHOLMOD's numeric LL' instead of ours (side-by-side runs)
  const char *llt_env = getenv("FMBD_CHOL_LLT");
  F->own_llt = !(llt_env && strcmp(llt_env, "cholmod") == 0);
  F->neg = -1;
  F->failed_row = -1;
  F->st.n = F->n;
  F->st.ordering = "none";
  cholmod_l_start(&F->c);
  F->started = 1;
  F->c.print = 0;
  F->c.error_handler = on_cholmod_error;
  F->c.itype = CHOLMOD_LONG;
  if (kind == FMBD_CHOL_LLT || kind == FMBD_CHOL_LDLT) {
    // LDLT: only CHOLMOD's supernodal symbolic analysis is used; the numeric LDL' is ours
    F->c.supernodal = CHOLMOD_SUPERNODAL;
    F->c.final_asis = 1;
  } else {
    // simplicial LDL' without pivoting: D's signs give the inertia
    F->c.supernodal = CHOLMOD_SIMPLICIAL;
    F->c.final_ll = 0;
    F->c.final_asis = 1;
  }
  g_cholmod_msg[0] = 0;
  double t0 = fmbd_wall_s();
  const fmbd_chol *D = same_analysis(like, A, B, kind);
  if (D) {
    // the LL' analysis: the same pattern and ordering give the same symbolic factor
    F->L = cholmod_l_copy_factor(D->L, &F->c);
    if (!F->L) FMBD_GCALL(cholmod_fail(F, "copy_factor"));
    F->st.nnz_a = D->st.nnz_a;
    F->c.lnz = D->c.lnz;
    F->c.method[0].ordering = CHOLMOD_GIVEN;
    fmbd_log(FMBD_LOG_DEBUG, "analysis: the LL' one of the same pattern and ordering (copied)");
  } else {
    FMBD_GCALL(build_pattern(F));
    t0 = fmbd_wall_s();
    if (perm) {
      // the caller's fill-reducing ordering (e.g. of an earlier factor of the same pattern)
      F->c.nmethods = 1;
      F->c.method[0].ordering = CHOLMOD_GIVEN;
      F->c.postorder = 1;
      F->L = cholmod_l_analyze_p(F->S, (SuiteSparse_long *)perm, NULL, 0, &F->c);
    } else {
      if (F->n >= METIS_ONLY_N) {
        // CHOLMOD's default tries AMD first and METIS only when AMD's fill is high; on the FE
        // bodies above this size METIS always won (51 k and 188 k dofs: 1.24e8 entries in L
        // and 1.89e11 flops against AMD's 1.60e8 and 3.0e11 at 188 k), so the AMD pass is
        // skipped: the same ordering, 0.4 s less at 188 k (bench/README.md "fe2cb's memory,
        // third round")
        F->c.nmethods = 1;
        F->c.method[0].ordering = CHOLMOD_METIS;
      }
      F->L = cholmod_l_analyze(F->S, &F->c);
    }
  }
  F->st.t_analyze_s = fmbd_wall_s() - t0;
  if (!F->L || F->c.status < 0) FMBD_GCALL(cholmod_fail(F, "analyze"));
  F->st.ordering = ordering_name(F->c.method[D ? 0 : F->c.selected].ordering);
  F->st.nnz_l = F->c.lnz;
  if (F->L->is_super) {
    fmbd_log(FMBD_LOG_DEBUG,
             "analysis: %s ordering, %.4g entries in L, %lld supernodes holding %.4g values and "
             "%.4g row indices, largest update %.4g",
             F->st.ordering, F->c.lnz, (long long)F->L->nsuper, (double)F->L->xsize,
             (double)F->L->ssize, (double)F->L->maxcsize);
  }
  if (kind != FMBD_CHOL_LDLT_SIMPLICIAL) {
    // the numeric LL' and LDL' read A and B directly: the CHOLMOD copy of the pattern goes first
    cholmod_l_free_sparse(&F->S, &F->c);
    cholmod_l_free_work(&F->c);
  }
#ifdef __GLIBC__
  // the analysis's transient blocks (METIS's graph, CHOLMOD's copies of the pattern) are freed
  // but stay resident in glibc's heap, which the numeric factor (mmap) does not reuse: give
  // them back first (51 k dofs: 149 -> 74 MB resident, the LL' peak 326 -> 287 MB)
  malloc_trim(0);
#endif
  if (kind == FMBD_CHOL_LDLT) FMBD_GCALL(super_setup(F, false));
  if (kind == FMBD_CHOL_LLT) {
    FMBD_GALLOC(F->iperm = fmbd_malloc((size_t)(F->n ? F->n : 1) * sizeof(int64_t)));
    const SuiteSparse_long *p = F->L->Perm;
    for (int64_t k = 0; k < F->n; k++) F->iperm[p ? p[k] : k] = k;
  }
  *out = F;
  F = NULL;
done:
  fmbd_chol_destroy(&F);
  return rc;
}

// diagonal of the numeric factor in pivot order k: L_kk^2 (LL') or D_k (LDL')
static double pivot(const cholmod_factor *L, int64_t k) {
  const double *x = L->x;
  if (L->is_super) {
    const SuiteSparse_long *super = L->super, *pi = L->pi, *px = L->px;
    // binary search for the supernode holding column k
    int64_t lo = 0, hi = (int64_t)L->nsuper - 1;
    while (lo < hi) {
      int64_t mid = (lo + hi + 1) / 2;
      if (super[mid] <= k)
        lo = mid;
      else
        hi = mid - 1;
    }
    int64_t nsrow = pi[lo + 1] - pi[lo], c = k - super[lo];
    double l = x[px[lo] + c + c * nsrow];
    return l * l;
  }
  const SuiteSparse_long *p = L->p;
  double d = x[p[k]];
  return L->is_ll ? d * d : d;
}

static int check_pivots(fmbd_chol *F, int ok, double sigma, const double *dg);

int fmbd_chol_factor(fmbd_chol *F, double sigma) {
  FMBD_CHECK(F->B || sigma == 0.0, FMBD_ERR_VALUE, "shift %g without a second matrix", sigma);
  F->sigma = sigma;
  F->neg = -1;
  F->failed_row = -1;
  g_cholmod_msg[0] = 0;
  double t0 = fmbd_wall_s();
  if (F->kind == FMBD_CHOL_LDLT) {
    // assembled from A and B directly: no CHOLMOD matrix
    int rc = super_factor(F, sigma, F->Lx, false, NULL, NULL);
    F->st.t_factor_s += fmbd_wall_s() - t0;
    F->st.n_factor++;
    return rc;
  }
  // the LL' assembles its input from A and B (assemble_llt): only the simplicial LDL' needs
  // the copy that fmbd_chol_release_matrix frees
  FMBD_CHECK(!F->released || F->kind == FMBD_CHOL_LLT, FMBD_ERR_INTERNAL,
             "factor after fmbd_chol_release_matrix");
  cholmod_sparse *T = NULL;
  double *dg = NULL;
  int ok;
  if (F->kind == FMBD_CHOL_LLT) {
    // the diagonal of P (A - sigma B) P' as assembled, for check_pivots
    dg = fmbd_malloc((size_t)(F->n ? F->n : 1) * sizeof(double));
    if (!dg) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory (%lld pivots)", (long long)F->n);
  }
  if (F->kind == FMBD_CHOL_LLT && F->own_llt && F->L->is_super) {
    // our supernodal LL' (own_llt)
    int rc = own_llt(F, sigma, dg);
    if (rc) {
      fmbd_free(dg);
      return rc;
    }
    ok = 1;
  } else if (F->kind == FMBD_CHOL_LLT) {
    // supernodal LL' of our tril(P (A - sigma B) P'): cholmod_l_factorize's own permuted copy
    // is not made (assemble_llt)
    int rc = assemble_llt(F, sigma, &T, dg);
    if (rc) {
      fmbd_free(dg);
      return rc;
    }
    double beta[2] = {0.0, 0.0};
    input_formed();  // super_numeric reads T only
    ok = cholmod_l_super_numeric(T, NULL, beta, F->L, &F->c);
    cholmod_l_free_sparse(&T, &F->c);
    if (ok && F->c.status == CHOLMOD_OK) {
      double freed = release_zero_pages(F->L, F->L->x);
      fmbd_log(FMBD_LOG_DEBUG, "LL': %.0f MB of the diagonal blocks' upper triangles given back",
               freed / 1048576.0);
    }
#ifdef __GLIBC__
    malloc_trim(0);  // T and CHOLMOD's update workspace, freed, back to the system
#endif
  } else {
    fill_values(F, sigma);
    ok = cholmod_l_factorize(F->S, F->L, &F->c);
  }
  F->st.t_factor_s += fmbd_wall_s() - t0;
  F->st.n_factor++;
  F->st.flops = F->c.fl;
  F->st.nnz_l = F->c.lnz;
  int rc = check_pivots(F, ok, sigma, dg);
  fmbd_free(dg);
  return rc;
}

// the outcome of a CHOLMOD factorisation: its status, the inertia of the simplicial LDL', the
// singularity test of the LL' (dg: the diagonal of A - sigma B in pivot order)
static int check_pivots(fmbd_chol *F, int ok, double sigma, const double *dg) {
  if (!ok || F->c.status < 0) return cholmod_fail(F, "factorize");
  const SuiteSparse_long *perm = F->L->Perm;
  if (F->c.status == CHOLMOD_NOT_POSDEF) {
    int64_t k = (int64_t)F->L->minor;
    F->failed_row = (k >= 0 && k < F->n) ? (perm ? perm[k] : k) : -1;
    if (F->kind == FMBD_CHOL_LLT) {
      FMBD_FAIL(FMBD_ERR_SINGULAR,
                "matrix%s is not positive definite: pivot %lld of %lld fails at row %lld",
                sigma != 0.0 ? " (shifted)" : "", (long long)k + 1, (long long)F->n,
                (long long)F->failed_row);
    }
    FMBD_FAIL(FMBD_ERR_SINGULAR, "zero pivot in LDL' at row %lld (shift %.17g is an eigenvalue)",
              (long long)F->failed_row, sigma);
  }
  if (F->kind == FMBD_CHOL_LDLT_SIMPLICIAL) {
    int64_t neg = 0;
    for (int64_t k = 0; k < F->n; k++) {
      double d = pivot(F->L, k);
      if (!(d == d)) {
        F->failed_row = perm ? perm[k] : k;
        FMBD_FAIL(FMBD_ERR_SINGULAR, "NaN pivot in LDL' at row %lld", (long long)F->failed_row);
      }
      neg += d < 0.0;
    }
    F->neg = neg;
    return FMBD_OK;
  }
  // LL': a singular matrix that round-off left barely positive shows a pivot many orders
  // below its diagonal entry; report the first such row (in pivot order)
  if (F->pivot_rtol > 0.0) {
    for (int64_t k = 0; k < F->n; k++) {
      int64_t r = perm ? perm[k] : k;
      double a = dg[k];
      double d = pivot(F->L, k);
      if (!(d > F->pivot_rtol * fabs(a))) {
        F->failed_row = r;
        FMBD_FAIL(FMBD_ERR_SINGULAR,
                  "matrix is singular to working precision: pivot %.3g against diagonal %.3g "
                  "(ratio %.2g < %.1g) at row %lld",
                  d, a, a != 0.0 ? d / a : 0.0, F->pivot_rtol, (long long)r);
      }
    }
  }
  return FMBD_OK;
}

// --- narrow-block supernodal LL' solves of our own ------------------------------------------
// CHOLMOD's supernodal solve (t_cholmod_super_solve.c) calls dtrsm and dgemm once per supernode
// with as many columns as right-hand sides; with the block eigensolver's 4 columns those are
// BLAS calls of tiny width (OpenBLAS's small-matrix kernels: 15 % of fe2cb's CPU at 51 k dofs,
// 20 modes, bench/README.md "Fewer and cheaper Lanczos solves"), well below the rate at which
// the factor streams from memory, which is what bounds a narrow solve (each entry of L is used
// once per column; 4 columns of the 51 k-dof rod's factor, 180 MB: CHOLMOD 43-65 ms a full
// solve, here 31-39 ms, streaming L twice 18 ms). Here the same sweeps (forward: column by column
// of each supernode, the diagonal block's triangle then the rows below; backward: the transposed
// order) run on a row-major copy Z of the right-hand sides (each row's 4 or 8 values contiguous:
// one or two 4-wide vectors), 4 columns of a supernode at a time, so that each entry of L is loaded
// once per sweep and used for every right-hand side in registers:
//   forward, group of columns j..j+g-1 (g <= 4) of supernode s: the g x g triangle on their
//   rows, then rows i below: z_i -= L(i,j) z_j + ... + L(i,j+g-1) z_{j+g-1} (vector per row);
//   backward, the groups in reverse: z_j -= sum_i L(i,j) z_i over the rows below the group
//   (g vector sums), then the triangle.
// The supernode's rows are gathered into a contiguous buffer G (its own columns, then the rows
// of its off-diagonal part; zero for those in the forward sweep, whose sums are added to Z
// afterwards, as CHOLMOD's dgemm-and-scatter does), so one kernel call covers both parts. Only
// the lower part of each diagonal block is read (the upper is not kept: release_zero_pages).
// Compiled for AVX2 and FMA (4-wide vectors of the compiler's vector extensions, each product
// and sum as one fused multiply-add, the sums in the order written) and chosen when called
// (__builtin_cpu_supports); blocks of 5 to 16 columns by the AVX-512 kernels below where the
// processor has them (8, 12, 16 columns: 29, 40, 50 ms against CHOLMOD's 49, 61, 72 ms and
// these kernels' 33, 51, 63 ms by 8 and 12 or 16 wide rows, bench/README.md "The sweeps'
// prefetch"); elsewhere (another processor, another compiler, FMBD_NO_VECTOR), for single
// vectors (CHOLMOD's BLAS-2 path is faster: 28 against 37 ms) and, without AVX-512, for blocks
// of more than 8 columns, CHOLMOD's solve. The results agree with CHOLMOD's to
// round-off (the same substitutions, the sums in another order and fused: tests/unit/t300
// compares them, within the triangular solves' error bound).
#ifdef FMBD_HAVE_V4D  // fmbd_vec.h: x86-64, GCC or clang, not FMBD_NO_VECTOR
#define FMBD_OWN_SOLVE 1
#include <immintrin.h>
#ifdef __clang__
#pragma clang fp contract(off)
#endif

#define SFN static inline __attribute__((always_inline, target("avx2,fma")))
// t - a y, one rounding (FMA)
SFN v4d sn_fnma(double a, v4d y, v4d t) {
  return (v4d)_mm256_fnmadd_pd(_mm256_set1_pd(a), (__m256d)y, (__m256d)t);
}
// s + a z, one rounding
SFN v4d sn_fma(double a, v4d z, v4d s) {
  return (v4d)_mm256_fmadd_pd(_mm256_set1_pd(a), (__m256d)z, (__m256d)s);
}

// The next group's 4 columns of L (the forward sweep's; the backward sweep's: the previous
// group's), at the rows of the current one, asked for into the L2 cache: one cache line of each
// column per 8 rows, so they arrive a group ahead of their use. The sweeps stream L from memory
// once per sweep; the hardware prefetchers alone kept 4-column blocks at about half the
// streaming rate (each group's 4 columns are 4 new streams of a few hundred rows, a new page
// each for the larger supernodes). Into L1 (T0) it gained a few per cent only, half a group
// ahead a third as much, two or three groups ahead no more than one: the 51 k-dof rod's
// operator of 4 columns 32 -> 22 ms (bench/README.md "The sweeps' prefetch"). A hint only (it never
// faults): the addresses, which pass the ends of the factor's block at the first and last
// supernodes, are formed as integers.
static inline __attribute__((always_inline)) void sn_prefetch4(const double *p, int64_t off,
                                                               int64_t ld) {
  uintptr_t a = (uintptr_t)p + (uintptr_t)(off * (int64_t)sizeof(double)), d = (uintptr_t)ld * 8u;
  _mm_prefetch((const char *)a, _MM_HINT_T1);
  _mm_prefetch((const char *)(a + d), _MM_HINT_T1);
  _mm_prefetch((const char *)(a + 2 * d), _MM_HINT_T1);
  _mm_prefetch((const char *)(a + 3 * d), _MM_HINT_T1);
}

// T[i] -= L[i] Y[0] + L[i + ld] Y[1] + L[i + 2 ld] Y[2] + L[i + 3 ld] Y[3] for i < nr (in that
// order); rows of nv 4-wide vectors (row stride 4 nv)
SFN void sn_upd4(int64_t nr, const double *L, int64_t ld, const double *Y, double *T, int nv) {
  const int w = 4 * nv;
  v4d y0[2], y1[2], y2[2], y3[2];
  for (int v = 0; v < nv; v++) {
    y0[v] = LD4(Y + 4 * v);
    y1[v] = LD4(Y + w + 4 * v);
    y2[v] = LD4(Y + 2 * w + 4 * v);
    y3[v] = LD4(Y + 3 * w + 4 * v);
  }
  const double *L0 = L, *L1 = L + ld, *L2 = L + 2 * ld, *L3 = L + 3 * ld;
  for (int64_t i = 0; i < nr; i++) {
    double *t = T + i * w;
    if ((i & 7) == 0) sn_prefetch4(L0, i + 4 * ld, ld);
    for (int v = 0; v < nv; v++) {
      v4d x = sn_fnma(L0[i], y0[v], LD4(t + 4 * v));
      x = sn_fnma(L1[i], y1[v], x);
      x = sn_fnma(L2[i], y2[v], x);
      ST4(t + 4 * v, sn_fnma(L3[i], y3[v], x));
    }
  }
}

// the same for g < 4 columns
SFN void sn_upd(int64_t nr, const double *L, int64_t ld, int g, const double *Y, double *T,
                int nv) {
  const int w = 4 * nv;
  for (int64_t i = 0; i < nr; i++) {
    double *t = T + i * w;
    for (int v = 0; v < nv; v++) {
      v4d x = LD4(t + 4 * v);
      for (int q = 0; q < g; q++) x = sn_fnma(L[i + q * ld], LD4(Y + q * w + 4 * v), x);
      ST4(t + 4 * v, x);
    }
  }
}

// Y[q] -= sum_{i < nr} L[i + q ld] T[i] for q < 4: the even and the odd rows in separate sums
// (two sets of 4 nv vectors: an FMA's latency is several cycles), added at the end
SFN void sn_dot4(int64_t nr, const double *L, int64_t ld, const double *T, double *Y, int nv) {
  const int w = 4 * nv;
  v4d s0[2] = {{0}}, s1[2] = {{0}}, s2[2] = {{0}}, s3[2] = {{0}};
  v4d u0[2] = {{0}}, u1[2] = {{0}}, u2[2] = {{0}}, u3[2] = {{0}};
  const double *L0 = L, *L1 = L + ld, *L2 = L + 2 * ld, *L3 = L + 3 * ld;
  int64_t i = 0;
  for (; i + 1 < nr; i += 2) {
    const double *t = T + i * w;
    if ((i & 7) == 0) sn_prefetch4(L0, i - 4 * ld, ld);
    for (int v = 0; v < nv; v++) {
      v4d z = LD4(t + 4 * v), y = LD4(t + w + 4 * v);
      s0[v] = sn_fma(L0[i], z, s0[v]);
      s1[v] = sn_fma(L1[i], z, s1[v]);
      s2[v] = sn_fma(L2[i], z, s2[v]);
      s3[v] = sn_fma(L3[i], z, s3[v]);
      u0[v] = sn_fma(L0[i + 1], y, u0[v]);
      u1[v] = sn_fma(L1[i + 1], y, u1[v]);
      u2[v] = sn_fma(L2[i + 1], y, u2[v]);
      u3[v] = sn_fma(L3[i + 1], y, u3[v]);
    }
  }
  if (i < nr) {
    const double *t = T + i * w;
    for (int v = 0; v < nv; v++) {
      v4d z = LD4(t + 4 * v);
      s0[v] = sn_fma(L0[i], z, s0[v]);
      s1[v] = sn_fma(L1[i], z, s1[v]);
      s2[v] = sn_fma(L2[i], z, s2[v]);
      s3[v] = sn_fma(L3[i], z, s3[v]);
    }
  }
  for (int v = 0; v < nv; v++) {
    ST4(Y + 4 * v, LD4(Y + 4 * v) - (s0[v] + u0[v]));
    ST4(Y + w + 4 * v, LD4(Y + w + 4 * v) - (s1[v] + u1[v]));
    ST4(Y + 2 * w + 4 * v, LD4(Y + 2 * w + 4 * v) - (s2[v] + u2[v]));
    ST4(Y + 3 * w + 4 * v, LD4(Y + 3 * w + 4 * v) - (s3[v] + u3[v]));
  }
}

// the same for g < 4 columns
SFN void sn_dot(int64_t nr, const double *L, int64_t ld, int g, const double *T, double *Y,
                int nv) {
  const int w = 4 * nv;
  for (int q = 0; q < g; q++) {
    for (int v = 0; v < nv; v++) {
      v4d s = {0};
      for (int64_t i = 0; i < nr; i++) s = sn_fma(L[i + q * ld], LD4(T + i * w + 4 * v), s);
      ST4(Y + q * w + 4 * v, LD4(Y + q * w + 4 * v) - s);
    }
  }
}

// The sweeps over the supernodes on Z (n rows of 4 nv values, in the factor's order); G: a
// buffer of the largest supernode's rows.
SFN void sn_sweeps(const cholmod_factor *L, int fwd, int bwd, double *Z, double *G, int nv) {
  const SuiteSparse_long *super = L->super, *pi = L->pi, *px = L->px, *Ls = L->s;
  const double *Lx = L->x;
  const int64_t ns = (int64_t)L->nsuper;
  const int w = 4 * nv;
  for (int64_t s = 0; fwd && s < ns; s++) {
    int64_t k1 = super[s], nscol = super[s + 1] - k1, nsrow = pi[s + 1] - pi[s];
    const double *Ld = Lx + px[s];
    const SuiteSparse_long *rows = Ls + pi[s];
    memcpy(G, Z + k1 * w, (size_t)(nscol * w) * sizeof(double));
    memset(G + nscol * w, 0, (size_t)((nsrow - nscol) * w) * sizeof(double));
    for (int64_t j = 0; j < nscol; j += 4) {
      int g = nscol - j < 4 ? (int)(nscol - j) : 4;
      for (int q = 0; q < g; q++) {  // the g x g triangle
        double *zq = G + (j + q) * w;
        const double *lc = Ld + (j + q) * nsrow;
        for (int v = 0; v < nv; v++) ST4(zq + 4 * v, LD4(zq + 4 * v) / lc[j + q]);
        for (int r = q + 1; r < g; r++) {
          double *zr = G + (j + r) * w;
          for (int v = 0; v < nv; v++)
            ST4(zr + 4 * v, LD4(zr + 4 * v) - lc[j + r] * LD4(zq + 4 * v));
        }
      }
      int64_t i0 = j + g;
      if (g == 4)
        sn_upd4(nsrow - i0, Ld + i0 + j * nsrow, nsrow, G + j * w, G + i0 * w, nv);
      else
        sn_upd(nsrow - i0, Ld + i0 + j * nsrow, nsrow, g, G + j * w, G + i0 * w, nv);
    }
    memcpy(Z + k1 * w, G, (size_t)(nscol * w) * sizeof(double));
    for (int64_t i = nscol; i < nsrow; i++) {
      double *z = Z + rows[i] * w;
      for (int v = 0; v < nv; v++) ST4(z + 4 * v, LD4(z + 4 * v) + LD4(G + i * w + 4 * v));
    }
  }
  for (int64_t s = ns - 1; bwd && s >= 0; s--) {
    int64_t k1 = super[s], nscol = super[s + 1] - k1, nsrow = pi[s + 1] - pi[s];
    const double *Ld = Lx + px[s];
    const SuiteSparse_long *rows = Ls + pi[s];
    memcpy(G, Z + k1 * w, (size_t)(nscol * w) * sizeof(double));
    for (int64_t i = nscol; i < nsrow; i++)
      memcpy(G + i * w, Z + rows[i] * w, (size_t)w * sizeof(double));
    for (int64_t j = ((nscol - 1) / 4) * 4; j >= 0; j -= 4) {
      int g = nscol - j < 4 ? (int)(nscol - j) : 4;
      int64_t i0 = j + g;
      if (g == 4)
        sn_dot4(nsrow - i0, Ld + i0 + j * nsrow, nsrow, G + i0 * w, G + j * w, nv);
      else
        sn_dot(nsrow - i0, Ld + i0 + j * nsrow, nsrow, g, G + i0 * w, G + j * w, nv);
      for (int q = g - 1; q >= 0; q--) {  // the g x g triangle, transposed
        double *zq = G + (j + q) * w;
        const double *lc = Ld + (j + q) * nsrow;
        for (int r = q + 1; r < g; r++) {
          const double *zr = G + (j + r) * w;
          for (int v = 0; v < nv; v++)
            ST4(zq + 4 * v, LD4(zq + 4 * v) - lc[j + r] * LD4(zr + 4 * v));
        }
        for (int v = 0; v < nv; v++) ST4(zq + 4 * v, LD4(zq + 4 * v) / lc[j + q]);
      }
    }
    memcpy(Z + k1 * w, G, (size_t)(nscol * w) * sizeof(double));
  }
}

__attribute__((target("avx2,fma"))) static void sn_sweeps_avx2_1(const cholmod_factor *L, int fwd,
                                                                 int bwd, double *Z, double *G) {
  sn_sweeps(L, fwd, bwd, Z, G, 1);
}
__attribute__((target("avx2,fma"))) static void sn_sweeps_avx2_2(const cholmod_factor *L, int fwd,
                                                                 int bwd, double *Z, double *G) {
  sn_sweeps(L, fwd, bwd, Z, G, 2);
}
// --- the same sweeps with AVX-512, the supernode's rows column by column ---------------------
// For blocks of 5 to 16 columns (Z's rows padded to nc = 8, 12 or 16 values); blocks of 2 to 4
// stay with the kernels above, which stream L as fast (memory-bound there: 17 ms a full solve
// of 4 columns with either). The kernels above hold one row of the block per vector, so each
// entry of L is a
// broadcast load of its own: about ten instructions per row of 4 entries. Here the gathered
// rows G are stored column by column (ldg = the supernode's row count; column c of the block
// at G + c ldg), so 8 consecutive entries of a column of L are one vector load, used for 4
// columns of the block at a time (a pass over the rows per 4 columns) against broadcasts of the
// group's 4 x 4 values held in registers: 4 loads of L, 4 loads and 4 stores of G and 16 FMAs per 8
// rows of 4 columns of L, about three times fewer instructions. Forward: the same operations in the
// same order as sn_upd4 / sn_upd and the same triangles (scalar here, the same roundings), so the
// same bits. Backward: each of the 16 sums over the rows below the group is kept in 8 lanes (lane l
// the rows i = l mod 8) and added at the end, another order of the same sums than sn_dot4's even
// and odd rows: the result differs at round-off (tests/unit/t300 compares the solves with
// CHOLMOD's within the triangular solves' bound).
#define SN5 static inline __attribute__((always_inline, target("avx512f")))

// T_c[i] -= L[i] y[0][c] + ... + L[i + (g-1) ld] y[g-1][c] for i < nr, c < nc (in that order
// per entry): T_c = T + c ldt; y[q][c] = Y[q + c ldt] (the group's own rows of G). The 16
// broadcasts and the 4 columns' vectors in named variables (arrays of vectors were kept on the
// stack by the compiler)
SN5 void s5_upd(int64_t nr, const double *L, int64_t ld, int g, const double *Y, double *T,
                int64_t ldt, int nc) {
  for (int c0 = 0; c0 < nc; c0 += 4) {
    const double *Yc = Y + c0 * ldt;
    double *T0 = T + c0 * ldt, *T1 = T0 + ldt, *T2 = T1 + ldt, *T3 = T2 + ldt;
    const double *L0 = L, *L1 = L + ld, *L2 = L + 2 * ld, *L3 = L + 3 * ld;
    if (g < 4) {  // short groups: scalar broadcasts reloaded, masked rows
      for (int64_t i = 0; i < nr; i += 8) {
        __mmask8 m = nr - i >= 8 ? 0xff : (__mmask8)((1u << (nr - i)) - 1u);
        for (int c = 0; c < 4; c++) {
          double *t = T0 + c * ldt + i;
          __m512d x = _mm512_maskz_loadu_pd(m, t);
          for (int q = 0; q < g; q++)
            x = _mm512_fnmadd_pd(_mm512_maskz_loadu_pd(m, L + q * ld + i),
                                 _mm512_set1_pd(Yc[q + c * ldt]), x);
          _mm512_mask_storeu_pd(t, m, x);
        }
      }
      continue;
    }
#define S5Y(q, c) const __m512d y##q##c = _mm512_set1_pd(Yc[q + c * ldt])
    S5Y(0, 0);
    S5Y(1, 0);
    S5Y(2, 0);
    S5Y(3, 0);
    S5Y(0, 1);
    S5Y(1, 1);
    S5Y(2, 1);
    S5Y(3, 1);
    S5Y(0, 2);
    S5Y(1, 2);
    S5Y(2, 2);
    S5Y(3, 2);
    S5Y(0, 3);
    S5Y(1, 3);
    S5Y(2, 3);
    S5Y(3, 3);
#undef S5Y
    for (int64_t i = 0; i < nr; i += 8) {
      __mmask8 m = nr - i >= 8 ? 0xff : (__mmask8)((1u << (nr - i)) - 1u);
      __m512d l0 = _mm512_maskz_loadu_pd(m, L0 + i), l1 = _mm512_maskz_loadu_pd(m, L1 + i);
      __m512d l2 = _mm512_maskz_loadu_pd(m, L2 + i), l3 = _mm512_maskz_loadu_pd(m, L3 + i);
      sn_prefetch4(L0, i + 4 * ld, ld);
#define S5U(c)                                                                   \
  {                                                                              \
    __m512d x = _mm512_fnmadd_pd(l0, y0##c, _mm512_maskz_loadu_pd(m, T##c + i)); \
    x = _mm512_fnmadd_pd(l1, y1##c, x);                                          \
    x = _mm512_fnmadd_pd(l2, y2##c, x);                                          \
    _mm512_mask_storeu_pd(T##c + i, m, _mm512_fnmadd_pd(l3, y3##c, x));          \
  }
      S5U(0) S5U(1) S5U(2) S5U(3)
#undef S5U
    }
  }
}

// Y[q + c ldt] -= sum_{i < nr} L[i + q ld] T_c[i] for q < g, c < nc
SN5 void s5_dot(int64_t nr, const double *L, int64_t ld, int g, const double *T, double *Y,
                int64_t ldt, int nc) {
  for (int c0 = 0; c0 < nc; c0 += 4) {
    double *Yc = Y + c0 * ldt;
    const double *T0 = T + c0 * ldt, *T1 = T0 + ldt, *T2 = T1 + ldt, *T3 = T2 + ldt;
    if (g < 4) {
      for (int q = 0; q < g; q++) {
        for (int c = 0; c < 4; c++) {
          __m512d a = _mm512_setzero_pd();
          for (int64_t i = 0; i < nr; i += 8) {
            __mmask8 m = nr - i >= 8 ? 0xff : (__mmask8)((1u << (nr - i)) - 1u);
            a = _mm512_fmadd_pd(_mm512_maskz_loadu_pd(m, L + q * ld + i),
                                _mm512_maskz_loadu_pd(m, T0 + c * ldt + i), a);
          }
          Yc[q + c * ldt] -= _mm512_reduce_add_pd(a);
        }
      }
      continue;
    }
    const double *L0 = L, *L1 = L + ld, *L2 = L + 2 * ld, *L3 = L + 3 * ld;
#define S5Z(q, c) __m512d s##q##c = _mm512_setzero_pd()
    S5Z(0, 0);
    S5Z(1, 0);
    S5Z(2, 0);
    S5Z(3, 0);
    S5Z(0, 1);
    S5Z(1, 1);
    S5Z(2, 1);
    S5Z(3, 1);
    S5Z(0, 2);
    S5Z(1, 2);
    S5Z(2, 2);
    S5Z(3, 2);
    S5Z(0, 3);
    S5Z(1, 3);
    S5Z(2, 3);
    S5Z(3, 3);
#undef S5Z
    for (int64_t i = 0; i < nr; i += 8) {
      __mmask8 m = nr - i >= 8 ? 0xff : (__mmask8)((1u << (nr - i)) - 1u);
      __m512d l0 = _mm512_maskz_loadu_pd(m, L0 + i), l1 = _mm512_maskz_loadu_pd(m, L1 + i);
      __m512d l2 = _mm512_maskz_loadu_pd(m, L2 + i), l3 = _mm512_maskz_loadu_pd(m, L3 + i);
      sn_prefetch4(L0, i - 4 * ld, ld);
#define S5D(c)                                      \
  {                                                 \
    __m512d t = _mm512_maskz_loadu_pd(m, T##c + i); \
    s0##c = _mm512_fmadd_pd(l0, t, s0##c);          \
    s1##c = _mm512_fmadd_pd(l1, t, s1##c);          \
    s2##c = _mm512_fmadd_pd(l2, t, s2##c);          \
    s3##c = _mm512_fmadd_pd(l3, t, s3##c);          \
  }
      S5D(0) S5D(1) S5D(2) S5D(3)
#undef S5D
    }
#define S5R(q, c) Yc[q + c * ldt] -= _mm512_reduce_add_pd(s##q##c)
    S5R(0, 0);
    S5R(1, 0);
    S5R(2, 0);
    S5R(3, 0);
    S5R(0, 1);
    S5R(1, 1);
    S5R(2, 1);
    S5R(3, 1);
    S5R(0, 2);
    S5R(1, 2);
    S5R(2, 2);
    S5R(3, 2);
    S5R(0, 3);
    S5R(1, 3);
    S5R(2, 3);
    S5R(3, 3);
#undef S5R
  }
}

// sn_sweeps with G column by column (nc = 4 or 8 columns of Z's rows of nc)
SN5 void s5_sweeps(const cholmod_factor *L, int fwd, int bwd, double *Z, double *G, int nc) {
  const SuiteSparse_long *super = L->super, *pi = L->pi, *px = L->px, *Ls = L->s;
  const double *Lx = L->x;
  const int64_t ns = (int64_t)L->nsuper;
  for (int64_t s = 0; fwd && s < ns; s++) {
    int64_t k1 = super[s], nscol = super[s + 1] - k1, nsrow = pi[s + 1] - pi[s], ldg = nsrow;
    const double *Ld = Lx + px[s];
    const SuiteSparse_long *rows = Ls + pi[s];
    for (int64_t i = 0; i < nscol; i++)
      for (int c = 0; c < nc; c++) G[i + c * ldg] = Z[(k1 + i) * nc + c];
    for (int c = 0; c < nc; c++) memset(G + c * ldg + nscol, 0, (size_t)(nsrow - nscol) * 8);
    for (int64_t j = 0; j < nscol; j += 4) {
      int g = nscol - j < 4 ? (int)(nscol - j) : 4;
      for (int q = 0; q < g; q++) {  // the g x g triangle (sn_sweeps' operations)
        const double *lc = Ld + (j + q) * nsrow;
        for (int c = 0; c < nc; c++) {
          double *zc = G + c * ldg + j;
          zc[q] = zc[q] / lc[j + q];
          for (int r = q + 1; r < g; r++) zc[r] = zc[r] - lc[j + r] * zc[q];
        }
      }
      int64_t i0 = j + g;
      s5_upd(nsrow - i0, Ld + i0 + j * nsrow, nsrow, g, G + j, G + i0, ldg, nc);
    }
    for (int64_t i = 0; i < nscol; i++)
      for (int c = 0; c < nc; c++) Z[(k1 + i) * nc + c] = G[i + c * ldg];
    for (int64_t i = nscol; i < nsrow; i++) {
      double *z = Z + rows[i] * nc;
      for (int c = 0; c < nc; c++) z[c] = z[c] + G[i + c * ldg];
    }
  }
  for (int64_t s = ns - 1; bwd && s >= 0; s--) {
    int64_t k1 = super[s], nscol = super[s + 1] - k1, nsrow = pi[s + 1] - pi[s], ldg = nsrow;
    const double *Ld = Lx + px[s];
    const SuiteSparse_long *rows = Ls + pi[s];
    for (int64_t i = 0; i < nsrow; i++) {
      const double *z = Z + (i < nscol ? k1 + i : rows[i]) * nc;
      for (int c = 0; c < nc; c++) G[i + c * ldg] = z[c];
    }
    for (int64_t j = ((nscol - 1) / 4) * 4; j >= 0; j -= 4) {
      int g = nscol - j < 4 ? (int)(nscol - j) : 4;
      int64_t i0 = j + g;
      s5_dot(nsrow - i0, Ld + i0 + j * nsrow, nsrow, g, G + i0, G + j, ldg, nc);
      for (int q = g - 1; q >= 0; q--) {  // the g x g triangle, transposed
        const double *lc = Ld + (j + q) * nsrow;
        for (int c = 0; c < nc; c++) {
          double *zc = G + c * ldg + j;
          for (int r = q + 1; r < g; r++) zc[q] = zc[q] - lc[j + r] * zc[r];
          zc[q] = zc[q] / lc[j + q];
        }
      }
    }
    for (int64_t i = 0; i < nscol; i++)
      for (int c = 0; c < nc; c++) Z[(k1 + i) * nc + c] = G[i + c * ldg];
  }
}

__attribute__((target("avx512f"))) static void sn_sweeps_avx512(const cholmod_factor *L, int fwd,
                                                                int bwd, double *Z, double *G,
                                                                int nc) {
  s5_sweeps(L, fwd, bwd, Z, G, nc);
}
#endif

// own_solve's workspace given back; one wider than 8 columns also to the system (malloc_trim):
// otherwise fe2cb's 12 columns at 188 k dofs (18 MB, freed after the constraint modes) stayed
// resident beside the Lanczos run's arrays, the run's peak 14 MB higher; mapped by itself
// instead, the 51 k run's peak was 4.7 MB higher (its later arrays no longer reused those
// pages); with the trim both peaks are main's (bench/README.md "The sweeps' prefetch")
static void ow_free(fmbd_chol *F) {
  bool wide = F->ow && F->ow_w > 8;
  fmbd_free(F->ow);
#ifdef __GLIBC__
  if (wide) malloc_trim(0);
#endif
  F->ow = NULL;
  F->ow_w = 0;
}

#ifdef FMBD_OWN_SOLVE
// own_solve's and own_op's conditions, and the workspace allocated on first use
static bool own_fits(const fmbd_chol *F, int64_t nrhs) {
  const cholmod_factor *L = F->L;
  if (!F->own_solve || nrhs > 24 || nrhs < 2 || !L->is_super || !L->is_ll ||
      L->xtype != CHOLMOD_REAL || !__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma"))
    return false;
  return nrhs <= 8 || __builtin_cpu_supports("avx512f");
}

static bool own_ready(fmbd_chol *F, int64_t nrhs) {
  if (!own_fits(F, nrhs)) return false;
  const cholmod_factor *L = F->L;
  int64_t w = nrhs > 8 ? 4 * ((nrhs + 3) / 4) : 8;
  if (!F->ow || F->ow_w < w) {
    const SuiteSparse_long *pi = L->pi;
    int64_t mr = 0;
    for (size_t s = 0; s < L->nsuper; s++) mr = pi[s + 1] - pi[s] > mr ? pi[s + 1] - pi[s] : mr;
    ow_free(F);
    size_t bytes = (size_t)(F->n + mr) * (size_t)w * sizeof(double);
    void *p = fmbd_malloc(bytes);
    if (!p) return false;  // CHOLMOD's then (it reports its own failure)
    F->ow = p;
    F->ow_w = w;
  }
  return true;
}
#endif

// whether own_solve would take a block of nrhs columns (no workspace allocated here)
static bool own_could(const fmbd_chol *F, int64_t nrhs) {
#ifdef FMBD_OWN_SOLVE
  return own_fits(F, nrhs);
#else
  (void)F;
  (void)nrhs;
  return false;
#endif
}

// Our solve of nrhs <= 24 columns (8 without AVX-512) (FWD: X <- L^-1 P X; BWD: X <- P' L^-T X;
// both: the full solve); false when not available here (then CHOLMOD's).
static bool own_solve(fmbd_chol *F, int fwd, int bwd, int64_t nrhs, double *X, int64_t ldx) {
#ifdef FMBD_OWN_SOLVE
  if (!own_ready(F, nrhs)) return false;
  const cholmod_factor *L = F->L;
  int nv = (int)((nrhs + 3) / 4), w = 4 * nv;
  int64_t n = F->n;
  double *Z = F->ow, *G = F->ow + n * F->ow_w;
  const SuiteSparse_long *perm = L->Perm;
  for (int64_t k = 0; k < n; k++) {  // Z = P X (forward) or X (backward), rows of w
    int64_t r = fwd ? perm[k] : k;
    int64_t c = 0;
    for (; c < nrhs; c++) Z[k * w + c] = X[r + c * ldx];
    for (; c < w; c++) Z[k * w + c] = 0.0;
  }
  if (nv == 1)
    sn_sweeps_avx2_1(L, fwd, bwd, Z, G);
  else if (__builtin_cpu_supports("avx512f"))
    sn_sweeps_avx512(L, fwd, bwd, Z, G, w);
  else
    sn_sweeps_avx2_2(L, fwd, bwd, Z, G);
  for (int64_t k = 0; k < n; k++) {  // X = P' Z (backward) or Z (forward)
    int64_t r = bwd ? perm[k] : k;
    for (int64_t c = 0; c < nrhs; c++) X[r + c * ldx] = Z[k * w + c];
  }
  return true;
#else
  (void)F;
  (void)fwd;
  (void)bwd;
  (void)nrhs;
  (void)X;
  (void)ldx;
  return false;
#endif
}

// fmbd_chol_apply_op's own path, 2 to 4 columns: the rows of 4 stay in the workspace from the
// backward sweeps through the product with M to the forward sweeps (Z = X; Z <- L^-T Z;
// Xt = P' Z; Z = M Xt; Xt = P Z; Xt <- L^-1 Xt; W = Xt): the same operations as the two halves
// and fmbd_csr_matmat between them (so the same bits), without their column-major round trips
// and with one pass over M for the 4 columns (a lower-stored M took one per column)
static bool own_op(fmbd_chol *F, const fmbd_csr *M, int64_t nrhs, const double *X, int64_t ldx,
                   double *W, int64_t ldw, double *t_m) {
#ifdef FMBD_OWN_SOLVE
  if (nrhs > 4 || !own_ready(F, nrhs)) return false;
  const cholmod_factor *L = F->L;
  int64_t n = F->n;
  double *Z = F->ow, *Xt = F->ow + n * 4, *G = F->ow + n * F->ow_w;
  const SuiteSparse_long *perm = L->Perm;
  for (int64_t k = 0; k < n; k++) {
    int64_t c = 0;
    for (; c < nrhs; c++) Z[k * 4 + c] = X[k + c * ldx];
    for (; c < 4; c++) Z[k * 4 + c] = 0.0;
  }
  sn_sweeps_avx2_1(L, 0, 1, Z, G);
  for (int64_t k = 0; k < n; k++) memcpy(Xt + perm[k] * 4, Z + k * 4, 4 * sizeof(double));
  double t0 = fmbd_wall_s();
  fmbd_csr_matmat_rows4(M, Xt, Z);
  if (t_m) *t_m += fmbd_wall_s() - t0;
  for (int64_t k = 0; k < n; k++) memcpy(Xt + k * 4, Z + perm[k] * 4, 4 * sizeof(double));
  sn_sweeps_avx2_1(L, 1, 0, Xt, G);
  for (int64_t k = 0; k < n; k++) {
    for (int64_t c = 0; c < nrhs; c++) W[k + c * ldw] = Xt[k * 4 + c];
  }
  return true;
#else
  (void)F;
  (void)M;
  (void)nrhs;
  (void)X;
  (void)ldx;
  (void)W;
  (void)ldw;
  (void)t_m;
  return false;
#endif
}

// X <- the solves sys[0], then sys[1], ... (CHOLMOD_A, or CHOLMOD_P/L/Lt/Pt) applied in turn
static int solve_sys(fmbd_chol *F, int nsys, const int *sys, int64_t nrhs, double *X, int64_t ldx) {
  if (F->dropped) {
    // fmbd_chol_drop_numeric: factored again first (A's and B's arrays must be back)
    FMBD_CHECK(F->A->data && F->A->indices && (!F->B || (F->B->data && F->B->indices)),
               FMBD_ERR_INTERNAL, "solve after fmbd_chol_drop_numeric without the matrix");
    fmbd_log(FMBD_LOG_DEBUG, "LL': factored again after its values were dropped");
    F->dropped = 0;
    fmbd_free(F->kept);  // CHOLMOD makes its own block
    F->kept = NULL;
    F->kept_n = 0;
    FMBD_CALL(fmbd_chol_factor(F, F->sigma));
  }
  FMBD_CHECK(F->L && F->st.n_factor > 0 && F->failed_row < 0 && F->kind != FMBD_CHOL_LDLT,
             FMBD_ERR_INTERNAL, "solve without a valid factor (or with the inertia-only LDL')");
  FMBD_CHECK(ldx >= F->n, FMBD_ERR_VALUE, "leading dimension %lld < %lld", (long long)ldx,
             (long long)F->n);
  double t0 = fmbd_wall_s();
  // the own solve's workspace and CHOLMOD's are not kept side by side: each path gives back
  // the other's (fe2cb at 100 modes: the blocks of 16 by the own solve, the Ritz vectors' back
  // solve by CHOLMOD, 64 columns at a time; both kept measured a peak 16 MB higher)
  const int64_t block = F->solve_width > 0 ? F->solve_width : 64;
  bool split = block >= 4 && block <= 16 && nrhs > block;  // below: calls of <= block columns
  // 17-24 columns in one own pass only where the caller's width asks for it (the workspace is
  // n x 24: fe2cb's 23 Ritz vectors, fmbd_eig.c)
  bool one = nrhs <= 16 || nrhs <= F->solve_width;
  if (F->started && (F->X || F->Y || F->E) && own_could(F, split ? block : (one ? nrhs : 25))) {
    cholmod_l_free_dense(&F->X, &F->c);
    cholmod_l_free_dense(&F->Y, &F->c);
    cholmod_l_free_dense(&F->E, &F->c);
  }
  if (one && own_solve(F, sys[0] == CHOLMOD_A || sys[0] == CHOLMOD_P,
                       sys[0] == CHOLMOD_A || sys[0] == CHOLMOD_Lt, nrhs, X, ldx)) {
    F->st.t_solve_s += fmbd_wall_s() - t0;
    return FMBD_OK;
  }
  // bounded workspace: at most n x (solve width) extra doubles, twice (CHOLMOD's X and Y)
  if (split) {
    // a width the own solve takes (fe2cb's Ritz vectors' back solve without AVX-512's one
    // pass of 24: 8 + 8 + 7 columns):
    // calls of nearly equal widths (at least block / 2 >= 2 columns), each through own_solve
    // (12 columns 40 against CHOLMOD's 61 ms, bench/README.md "The sweeps' prefetch"), the
    // workspace n x 16 at most
    int64_t calls = (nrhs + block - 1) / block, c0 = 0;
    bool all = true;
    for (int64_t i = 0; i < calls && all; i++) {
      int64_t nc = nrhs / calls + (i < nrhs % calls);
      all = own_solve(F, sys[0] == CHOLMOD_A || sys[0] == CHOLMOD_P,
                      sys[0] == CHOLMOD_A || sys[0] == CHOLMOD_Lt, nc, X + c0 * ldx, ldx);
      c0 += all ? nc : 0;
    }
    if (all) {
      F->st.t_solve_s += fmbd_wall_s() - t0;
      return FMBD_OK;
    }
    FMBD_CHECK(c0 == 0, FMBD_ERR_INTERNAL, "own solve refused a block after taking one");
  }
  ow_free(F);         // CHOLMOD's solve from here (see above)
  double *pt = NULL;  // the permutations done here, a column at a time through pt (n)
  for (int k = 0; k < nsys; k++) {
    if (sys[k] == CHOLMOD_P || sys[k] == CHOLMOD_Pt) {
      pt = fmbd_malloc((size_t)F->n * sizeof(double));
      FMBD_CHECK(pt, FMBD_ERR_NOMEM, "out of memory");
      break;
    }
  }
  for (int64_t c0 = 0; c0 < nrhs; c0 += block) {
    int64_t nc = nrhs - c0 < block ? nrhs - c0 : block;
    for (int k = 0; k < nsys; k++) {
      if (sys[k] == CHOLMOD_P || sys[k] == CHOLMOD_Pt) {
        // CHOLMOD_Pt (cholmod_l_solve2, CHOLMOD 3.0.14) reads a right-hand side block with a
        // leading dimension above n as if it were n: columns after the first came out wrong
        // (tests/unit/t300, own_solves: its halves against the library's own)
        const SuiteSparse_long *perm = F->L->Perm;
        for (int64_t j = 0; j < nc; j++) {
          double *x = X + (c0 + j) * ldx;
          memcpy(pt, x, (size_t)F->n * sizeof(double));
          if (sys[k] == CHOLMOD_P) {
            for (int64_t i = 0; i < F->n; i++) x[i] = pt[perm[i]];
          } else {
            for (int64_t i = 0; i < F->n; i++) x[perm[i]] = pt[i];
          }
        }
        continue;
      }
      cholmod_dense Bw;
      memset(&Bw, 0, sizeof Bw);
      Bw.nrow = (size_t)F->n;
      Bw.ncol = (size_t)nc;
      Bw.d = (size_t)ldx;
      Bw.nzmax = (size_t)(ldx * nc);
      Bw.x = X + c0 * ldx;
      Bw.z = NULL;
      Bw.xtype = CHOLMOD_REAL;
      Bw.dtype = CHOLMOD_DOUBLE;
      g_cholmod_msg[0] = 0;
      if (!cholmod_l_solve2(sys[k], F->L, &Bw, NULL, &F->X, NULL, &F->Y, &F->E, &F->c)) {
        fmbd_free(pt);
        return cholmod_fail(F, "solve");
      }
      const double *x = F->X->x;
      int64_t ld = (int64_t)F->X->d;
      for (int64_t j = 0; j < nc; j++) {
        memcpy(X + (c0 + j) * ldx, x + j * ld, (size_t)F->n * sizeof(double));
      }
    }
  }
  fmbd_free(pt);
  F->st.t_solve_s += fmbd_wall_s() - t0;
  return FMBD_OK;
}

int fmbd_chol_solve(fmbd_chol *F, int64_t nrhs, double *X, int64_t ldx) {
  const int sys[1] = {CHOLMOD_A};
  int rc = solve_sys(F, 1, sys, nrhs, X, ldx);
  if (rc == FMBD_OK) F->st.n_solves += nrhs;
  return rc;
}

int fmbd_chol_solve_half(fmbd_chol *F, int which, int64_t nrhs, double *X, int64_t ldx) {
  FMBD_CHECK(F->kind == FMBD_CHOL_LLT && (which == FMBD_CHOL_FWD || which == FMBD_CHOL_BWD),
             FMBD_ERR_INTERNAL, "half solve needs an LL' factor and FWD or BWD");
  const int fwd[2] = {CHOLMOD_P, CHOLMOD_L}, bwd[2] = {CHOLMOD_Lt, CHOLMOD_Pt};
  int rc = solve_sys(F, 2, which == FMBD_CHOL_FWD ? fwd : bwd, nrhs, X, ldx);
  // a forward and a backward half make one solve
  if (rc == FMBD_OK && which == FMBD_CHOL_FWD) F->st.n_solves += nrhs;
  return rc;
}

int fmbd_chol_apply_op(fmbd_chol *F, const fmbd_csr *M, int64_t nrhs, const double *X, int64_t ldx,
                       double *W, int64_t ldw, double *Y, double *t_m) {
  FMBD_CHECK(F->kind == FMBD_CHOL_LLT && M->nrows == F->n && M->ncols == F->n, FMBD_ERR_INTERNAL,
             "operator L^-1 P M P' L^-T needs an LL' factor and M of its size");
  FMBD_CHECK(ldx >= F->n && ldw >= F->n, FMBD_ERR_VALUE, "leading dimension %lld or %lld < %lld",
             (long long)ldx, (long long)ldw, (long long)F->n);
  if (!F->dropped && F->L && F->st.n_factor > 0 && F->failed_row < 0) {
    double t0 = fmbd_wall_s(), tm = 0.0;
    if (own_op(F, M, nrhs, X, ldx, W, ldw, &tm)) {
      F->st.t_solve_s += fmbd_wall_s() - t0 - tm;
      F->st.n_solves += nrhs;
      if (t_m) *t_m += tm;
      return FMBD_OK;
    }
  }
  for (int64_t c = 0; c < nrhs; c++)
    memcpy(Y + c * F->n, X + c * ldx, (size_t)F->n * sizeof(double));
  FMBD_CALL(fmbd_chol_solve_half(F, FMBD_CHOL_BWD, nrhs, Y, F->n));
  double t0 = fmbd_wall_s();
  fmbd_csr_matmat(M, nrhs, Y, F->n, W, ldw);
  if (t_m) *t_m += fmbd_wall_s() - t0;
  return fmbd_chol_solve_half(F, FMBD_CHOL_FWD, nrhs, W, ldw);
}

void fmbd_chol_set_own_solve(fmbd_chol *F, bool on) {
  if (F) F->own_solve = on;
}

void fmbd_chol_set_own_llt(fmbd_chol *F, bool on) {
  if (F) F->own_llt = on;
}

const double *fmbd_chol_values(const fmbd_chol *F, int64_t *nvalues) {
  const cholmod_factor *L = F ? F->L : NULL;
  bool ok = L && L->is_super && L->xtype == CHOLMOD_REAL && L->x && !F->dropped;
  if (nvalues) *nvalues = ok ? (int64_t)L->xsize : 0;
  return ok ? L->x : NULL;
}

void fmbd_chol_set_solve_width(fmbd_chol *F, int64_t w) {
  if (F) F->solve_width = w > 0 ? w : 0;
}

int64_t fmbd_chol_solve_width(const fmbd_chol *F) {
  return F ? F->solve_width : 0;
}

int64_t fmbd_chol_own_width(const fmbd_chol *F) {
  if (!F || !F->L || !own_could(F, 2)) return 0;
  return own_could(F, 24) ? 24 : 8;
}

void fmbd_chol_release_workspace(fmbd_chol *F) {
  if (!F) return;
  ow_free(F);
  if (!F->started) return;
  cholmod_l_free_dense(&F->X, &F->c);
  cholmod_l_free_dense(&F->Y, &F->c);
  cholmod_l_free_dense(&F->E, &F->c);
}

int fmbd_chol_drop_numeric_keep(fmbd_chol *F, size_t give_back) {
  FMBD_CHECK(F && F->kind == FMBD_CHOL_LLT && F->L && F->L->is_super && F->st.n_factor > 0,
             FMBD_ERR_INTERNAL, "dropping the values of a factor that is not a supernodal LL'");
  if (F->dropped || !F->L->x || F->kept) return fmbd_chol_drop_numeric(F);
#ifdef MADV_DONTNEED
  long pg = sysconf(_SC_PAGESIZE);
  size_t bytes = (size_t)F->L->xsize * sizeof(double);
  if (pg > 0 && give_back > 0) {
    // the block's last pages back to the system (private anonymous memory: touched again, a
    // page is a fresh zero page; clear_block clears the block anyway)
    uintptr_t lo = (uintptr_t)F->L->x + (give_back < bytes ? bytes - give_back : 0);
    uintptr_t hi = ((uintptr_t)F->L->x + bytes) & ~(uintptr_t)(pg - 1);
    lo &= ~(uintptr_t)(pg - 1);
    if (lo < (uintptr_t)F->L->x) lo += (uintptr_t)pg;
    if (hi > lo) (void)madvise((void *)lo, hi - lo, MADV_DONTNEED);
  }
#else
  (void)give_back;
#endif
  // the block leaves CHOLMOD's factor (allocated through fmbd_malloc: route_suitesparse_memory)
  // and is F's until fmbd_chol_analyze_like takes it or fmbd_chol_destroy frees it
  // (cholmod_change_factor needs a block to free: a one-value stand-in)
  double *stand_in = fmbd_malloc(sizeof(double));
  FMBD_CHECK(stand_in, FMBD_ERR_NOMEM, "out of memory");
  F->kept = F->L->x;
  F->kept_n = (size_t)F->L->xsize;
  F->L->x = stand_in;
  return fmbd_chol_drop_numeric(F);
}

int fmbd_chol_drop_numeric(fmbd_chol *F) {
  FMBD_CHECK(F && F->kind == FMBD_CHOL_LLT && F->L && F->L->is_super && F->st.n_factor > 0,
             FMBD_ERR_INTERNAL, "dropping the values of a factor that is not a supernodal LL'");
  if (F->dropped) return FMBD_OK;
  ow_free(F);
  cholmod_l_free_dense(&F->X, &F->c);
  cholmod_l_free_dense(&F->Y, &F->c);
  cholmod_l_free_dense(&F->E, &F->c);
  // back to the symbolic supernodal factor (cholmod_change_factor: L->x freed)
  if (!cholmod_l_change_factor(CHOLMOD_PATTERN, 1, 1, 1, 1, F->L, &F->c))
    return cholmod_fail(F, "change_factor");
  F->dropped = 1;
#ifdef __GLIBC__
  malloc_trim(0);
#endif
  return FMBD_OK;
}

void fmbd_chol_release_matrix(fmbd_chol *F) {
  if (!F) return;
  F->released = 1;
  if (F->started) {
    cholmod_l_free_sparse(&F->S, &F->c);
    cholmod_l_free_work(&F->c);
  }
  fmbd_free(F->posA);
  fmbd_free(F->posB);
  F->posA = F->posB = NULL;
}

int64_t fmbd_chol_negative_pivots(const fmbd_chol *F) {
  return F->kind != FMBD_CHOL_LLT ? F->neg : -1;
}
int64_t fmbd_chol_failed_row(const fmbd_chol *F) {
  return F->failed_row;
}
double fmbd_chol_sigma(const fmbd_chol *F) {
  return F->sigma;
}
void fmbd_chol_set_pivot_rtol(fmbd_chol *F, double rtol) {
  F->pivot_rtol = rtol;
}
void fmbd_chol_get_stats(const fmbd_chol *F, fmbd_chol_stats *st) {
  *st = F->st;
}

void fmbd_chol_destroy(fmbd_chol **pF) {
  if (!pF || !*pF) return;
  fmbd_chol *F = *pF;
  if (F->started) {
    cholmod_l_free_dense(&F->X, &F->c);
    cholmod_l_free_dense(&F->Y, &F->c);
    cholmod_l_free_dense(&F->E, &F->c);
    cholmod_l_free_factor(&F->L, &F->c);
    cholmod_l_free_sparse(&F->S, &F->c);
    cholmod_l_finish(&F->c);
  }
  ow_free(F);
  fmbd_free(F->Lx);
  fmbd_free(F->kept);
  fmbd_free(F->iperm);
  fmbd_free(F->col2super);
  fmbd_free(F->map);
  fmbd_free(F->head);
  fmbd_free(F->next);
  fmbd_free(F->lpos);
  fmbd_free(F->runs);
  fmbd_free(F->wC);
  fmbd_free(F->wW);
  fmbd_free(F->posA);
  fmbd_free(F->posB);
  fmbd_free(F);
  *pF = NULL;
}

int fmbd_chol_create_llt(const fmbd_csr *A, fmbd_chol **out) {
  int rc = FMBD_OK;
  fmbd_chol *F = NULL;
  *out = NULL;
  FMBD_GCALL(fmbd_chol_analyze(A, NULL, FMBD_CHOL_LLT, &F));
  FMBD_GCALL(fmbd_chol_factor(F, 0.0));
  *out = F;
  F = NULL;
done:
  fmbd_chol_destroy(&F);
  return rc;
}

int fmbd_chol_count_below(const fmbd_csr *A, const fmbd_csr *B, double sigma, int64_t *count) {
  int rc = FMBD_OK;
  fmbd_chol *F = NULL;
  *count = -1;
  FMBD_GCALL(fmbd_chol_analyze(A, B, FMBD_CHOL_LDLT, &F));
  FMBD_GCALL(fmbd_chol_factor(F, sigma));
  *count = F->neg;
done:
  fmbd_chol_destroy(&F);
  return rc;
}

// OpenBLAS's thread count, found at run time (libblas.so.3 is whatever update-alternatives
// selects: docs/TOOLCHAIN.md section 3c); nothing happens with another BLAS
int fmbd_blas_set_threads(int n) {
  static int looked = 0;
  static void (*set)(int) = NULL;
  static int (*get)(void) = NULL;
  if (!looked) {
    looked = 1;
    void *self = dlopen(NULL, RTLD_LAZY);
    if (self) {
      *(void **)&set = dlsym(self, "openblas_set_num_threads");
      *(void **)&get = dlsym(self, "openblas_get_num_threads");
    }
  }
  if (!set || !get) return -1;
  int old = get();
  if (n > 0 && n != old) set(n);
  return old;
}
