// tests/unit/t102-alloc-pool.c: fmbd_alloc's pool of large blocks (fmbd_alloc_pool): pages
// reused, calloc's zeroing of reused pages, realloc of pool blocks, the cap and the peak bound,
// switched off, the failure countdown; fmbd_chol's factors in reused (dirty) pages
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd.h"

#define MIB ((size_t)1 << 20)

static fmbd_alloc_pool_stats stats(void) {
  fmbd_alloc_pool_stats st;
  fmbd_alloc_pool_get_stats(&st);
  return st;
}

// every byte of p[0..n) equal to v
static int all(const unsigned char *p, size_t n, unsigned char v) {
  for (size_t i = 0; i < n; i++)
    if (p[i] != v) return 0;
  return 1;
}

// the 7-point Laplacian of an m x m x m grid (Dirichlet), full storage: eigenvalues
// 6 - 2 cos(i pi h) - 2 cos(j pi h) - 2 cos(k pi h), h = 1 / (m + 1), i, j, k = 1..m
static fmbd_csr *laplace7(int64_t m) {
  int64_t n = m * m * m;
  fmbd_csr *A = NULL;
  if (fmbd_csr_create(n, n, 7 * n, &A)) return NULL;
  int64_t q = 0;
  for (int64_t i = 0; i < m; i++)
    for (int64_t j = 0; j < m; j++)
      for (int64_t k = 0; k < m; k++) {
        int64_t r = (i * m + j) * m + k;
        A->indptr[r] = q;
        const int64_t nb[7] = {
            i > 0 ? r - m * m : -1, j > 0 ? r - m : -1,     k > 0 ? r - 1 : -1,        r,
            k < m - 1 ? r + 1 : -1, j < m - 1 ? r + m : -1, i < m - 1 ? r + m * m : -1};
        for (int t = 0; t < 7; t++) {
          if (nb[t] < 0) continue;
          A->indices[q] = nb[t];
          A->data[q++] = nb[t] == r ? 6.0 : -1.0;
        }
      }
  A->indptr[n] = q;
  return A;
}

// the pool filled with NaN bytes: whatever a factor takes from it holds old values
static void dirty_pool(void) {
  unsigned char *g = fmbd_malloc(64 * MIB);
  if (g) memset(g, 0xFF, 64 * MIB);
  fmbd_free(g);
}

// The supernodal LL' (our own, into a block from fmbd_calloc_dirty) and the Sturm LDL' with a
// pool full of NaNs: a place of the factor not cleared would spread NaN into the solution or
// the count. The solve's error against A x = b with x known: the Laplacian's condition number
// is below 4 (m + 1)^2 / pi^2 + 1 = 118 for m = 16, so a backward-stable Cholesky gives a
// relative error of order 118 * n^(1/2) * 1e-16 ~ 1e-12; 1e-10 leaves room and still fails on
// any wrong entry (O(1) errors). The count is exact (integers) against the formula above.
static void factors_in_reused_pages(void) {
  const int64_t m = 16, n = m * m * m;
  fmbd_csr *A = laplace7(m);
  EXPECT(A != NULL, "Laplacian");
  if (!A) return;
  double *x = malloc((size_t)n * sizeof(double)), *b = malloc((size_t)n * sizeof(double));
  for (int64_t i = 0; i < n; i++) x[i] = sin(0.37 * (double)i) + 0.5;
  for (int64_t i = 0; i < n; i++) {
    b[i] = 0.0;
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++) b[i] += A->data[p] * x[A->indices[p]];
  }
  fmbd_alloc_pool(64 * 1024, SIZE_MAX);
  dirty_pool();
  fmbd_alloc_pool_stats s0 = stats();
  fmbd_chol *F = NULL;
  int rc = fmbd_chol_analyze(A, NULL, FMBD_CHOL_LLT, &F);
  rc = rc ? rc : fmbd_chol_factor(F, 0.0);
  rc = rc ? rc : fmbd_chol_solve(F, 1, b, n);
  EXPECT(rc == 0, "LL' in reused pages: rc %d", rc);
  double err = 0.0, nx = 0.0;
  for (int64_t i = 0; i < n; i++) {
    err = fmax(err, fabs(b[i] - x[i]));
    nx = fmax(nx, fabs(x[i]));
  }
  EXPECT(err <= 1e-10 * nx, "LL' in reused pages: solve error %.3g (|x| %.3g)", err, nx);
  EXPECT(stats().reused_bytes > s0.reused_bytes, "the factor took no reused pages");
  fmbd_chol_destroy(&F);
  // the LDL' of A - I: 60 eigenvalues below 1, the nearest 0.036 away (counted exactly)
  fmbd_csr *I = NULL;
  rc = fmbd_csr_create(n, n, n, &I);
  for (int64_t i = 0; rc == 0 && i < n; i++) {
    I->indptr[i] = i;
    I->indices[i] = i;
    I->data[i] = 1.0;
  }
  if (I) I->indptr[n] = n;
  const double h = 1.0 / (double)(m + 1), sigma = 1.0;
  int64_t exact = 0;
  for (int64_t i = 1; i <= m; i++)
    for (int64_t j = 1; j <= m; j++)
      for (int64_t k = 1; k <= m; k++)
        exact += 6.0 - 2.0 * cos((double)i * M_PI * h) - 2.0 * cos((double)j * M_PI * h) -
                     2.0 * cos((double)k * M_PI * h) <
                 sigma;
  dirty_pool();
  rc = rc ? rc : fmbd_chol_analyze(A, I, FMBD_CHOL_LDLT, &F);
  rc = rc ? rc : fmbd_chol_factor(F, sigma);
  EXPECT(rc == 0 && fmbd_chol_negative_pivots(F) == exact,
         "LDL' in reused pages: rc %d, %lld negative pivots, exact %lld", rc,
         (long long)(F ? fmbd_chol_negative_pivots(F) : -1), (long long)exact);
  fmbd_chol_destroy(&F);
  fmbd_csr_destroy(&I);
  fmbd_csr_destroy(&A);
  free(x);
  free(b);
  fmbd_alloc_pool_trim();
}

int main(void) {
  // a small block first: whatever the pool does, the ordinary path stays as it was
  char *small = fmbd_malloc(100);
  EXPECT(small != NULL, "small block");
  if (!fmbd_alloc_pool(MIB, SIZE_MAX)) {
    printf("no pool on this system: the ordinary allocator only\n");
    fmbd_free(small);
    TEST_EXIT();
  }

  // --- the peak bound: memory that grows outside the pool while it holds pages takes its
  // room; at the next look the pool gives back what would put the resident total above the
  // earlier peak ---
  // first, while the process's peak is its start-up's
  unsigned char *p = fmbd_malloc(16 * MIB);
  memset(p, 9, 16 * MIB);
  fmbd_free(p);  // 16 MiB kept: resident = live + 16 MiB = the peak
  // (less the few pages by which the process's own memory grew since the last look: under
  // valgrind, 12 pages)
  EXPECT(stats().kept_bytes >= 15 * MIB, "kept %zu", stats().kept_bytes);
  // 12 MiB touched outside the pool (blocks below its size, from the C library)
  enum { NB = 48 };
  char *out[NB];
  for (int i = 0; i < NB; i++) {
    out[i] = malloc(256 * 1024);
    if (out[i]) memset(out[i], 1, 256 * 1024);
  }
  // the next look (a large free): live rose by 12 MiB, so about 4 MiB may stay (less where
  // the C library's blocks cost more pages: shadow memory under ASan or valgrind); without
  // the bound, all 16 MiB would (6 MiB of slack for the process's own movements)
  unsigned char *q = fmbd_malloc(MIB);  // from the pool
  memset(q, 2, MIB);
  fmbd_free(q);
  size_t kept = stats().kept_bytes;
  EXPECT(kept <= 10 * MIB, "after 12 MiB grew outside: %zu kept (about 4 MiB)", kept);
  printf("peak bound: %.2f MiB kept after 12 MiB grew outside the pool (16 MiB before)\n",
         (double)kept / (double)MIB);
  for (int i = 0; i < NB; i++) free(out[i]);

  fmbd_alloc_pool_trim();

  // --- reuse: a freed block's pages go to the next large allocation ---
  unsigned char *a = fmbd_malloc(4 * MIB);
  EXPECT(a && ((uintptr_t)a & 4095) == 0, "a 4 MiB pool block is page-aligned");
  memset(a, 0xAB, 4 * MIB);  // resident
  fmbd_free(a);
  fmbd_alloc_pool_stats s1 = stats();
  // the peak bound keeps what the run came down from: here all of it (nothing grew since)
  EXPECT(s1.kept_bytes == 4 * MIB, "kept %zu bytes after freeing 4 MiB", s1.kept_bytes);
  unsigned char *b = fmbd_malloc(3 * MIB);
  fmbd_alloc_pool_stats s2 = stats();
  EXPECT(b == a, "best fit: the range's first pages (%p, %p)", (void *)b, (void *)a);
  EXPECT(s2.reused_bytes - s1.reused_bytes == 3 * MIB, "reused %zu",
         s2.reused_bytes - s1.reused_bytes);
  EXPECT(s2.kept_bytes == MIB, "1 MiB left in the pool, %zu", s2.kept_bytes);
  // the pages are the old ones (the pool does not clear a malloc), and usable
  EXPECT(b && all(b, 3 * MIB, 0xAB), "malloc from the pool: the pages reused as they were");
  memset(b, 0x11, 3 * MIB);

  // --- calloc of reused pages is cleared ---
  unsigned char *c = fmbd_calloc(MIB / 8, 8);  // the 1 MiB left, filled with 0xAB
  EXPECT(c && all(c, MIB, 0), "calloc from reused pages: not all zero");
  fmbd_free(c);
  fmbd_free(b);
  EXPECT(stats().kept_bytes == 4 * MIB, "4 MiB kept again, %zu", stats().kept_bytes);

  // --- a block made of several ranges (moved pages) and fresh ones; calloc zero throughout ---
  unsigned char *d = fmbd_malloc(2 * MIB);  // from the 4 MiB range: 2 MiB left there
  memset(d, 0x5A, 2 * MIB);
  fmbd_free(d);  // two ranges of 2 MiB
  fmbd_alloc_pool_stats s3 = stats();
  EXPECT(s3.kept_bytes == 4 * MIB, "kept %zu", s3.kept_bytes);
  size_t n = 6 * MIB + 123;  // not a whole number of pages
  unsigned char *e = fmbd_calloc(n, 1);
  fmbd_alloc_pool_stats s4 = stats();
  EXPECT(e != NULL, "6 MiB calloc");
  EXPECT(s4.reused_bytes - s3.reused_bytes == 4 * MIB, "both ranges moved in: %zu",
         s4.reused_bytes - s3.reused_bytes);
  EXPECT(s4.kept_bytes == 0, "the pool emptied, %zu", s4.kept_bytes);
  EXPECT(e && all(e, n, 0), "calloc over moved and fresh pages: not all zero");
  if (e) memset(e, 0x77, n);

  // --- realloc of a pool block: grown and shrunk, the contents kept ---
  unsigned char *f = fmbd_realloc(e, 9 * MIB);
  EXPECT(f && all(f, n, 0x77), "grown: the first %zu bytes kept", n);
  if (f) memset(f + n, 0x66, 9 * MIB - n);
  unsigned char *g = fmbd_realloc(f ? f : e, 2 * MIB + 5);
  EXPECT(g && all(g, n < 2 * MIB + 5 ? n : 2 * MIB + 5, 0x77), "shrunk: the first bytes kept");
  unsigned char *h = fmbd_realloc(g, 10);  // below the pool's size: stays a pool block
  EXPECT(h && all(h, 10, 0x77), "shrunk to 10 bytes: kept");
  fmbd_free(h);

  // --- a realloc of an ordinary block to a large size stays ordinary, and works ---
  char *sm = fmbd_realloc(small, 3 * MIB);
  EXPECT(sm != NULL, "ordinary block grown");
  if (sm) memset(sm, 1, 3 * MIB);
  fmbd_free(sm);

  // --- the cap: what does not fit is given back ---
  fmbd_alloc_pool_trim();
  EXPECT(stats().kept_bytes == 0, "trim: %zu kept", stats().kept_bytes);
  fmbd_alloc_pool(MIB, 2 * MIB);
  unsigned char *k = fmbd_malloc(5 * MIB);
  memset(k, 3, 5 * MIB);
  fmbd_alloc_pool_stats s5 = stats();
  fmbd_free(k);
  fmbd_alloc_pool_stats s6 = stats();
  EXPECT(s6.kept_bytes == 2 * MIB, "cap 2 MiB: kept %zu", s6.kept_bytes);
  EXPECT(s6.unmapped_bytes - s5.unmapped_bytes == 3 * MIB, "cap: %zu given back",
         s6.unmapped_bytes - s5.unmapped_bytes);

  // --- switched off: the pool empties, a block made before is freed as before ---
  unsigned char *r = fmbd_malloc(2 * MIB);
  fmbd_alloc_pool(0, 0);
  EXPECT(stats().kept_bytes == 0, "off: %zu kept", stats().kept_bytes);
  if (r) memset(r, 4, 2 * MIB);
  fmbd_free(r);
  EXPECT(stats().kept_bytes == 0, "off: a pool block freed is unmapped, %zu kept",
         stats().kept_bytes);
  fmbd_alloc_pool_stats s7 = stats();
  unsigned char *t = fmbd_malloc(2 * MIB);  // the C library's now
  EXPECT(t && stats().blocks == s7.blocks, "off: no pool block");
  fmbd_free(t);

  factors_in_reused_pages();

  // --- the failure countdown reaches the pool's allocations too ---
  fmbd_alloc_pool(MIB, SIZE_MAX);
  fmbd_alloc_fail_after(0);
  void *z = fmbd_malloc(2 * MIB);
  EXPECT(z == NULL, "countdown at zero: the large allocation fails");
  fmbd_alloc_fail_after(-1);
  z = fmbd_calloc(2, MIB);
  EXPECT(z && all(z, 2 * MIB, 0), "countdown off: calloc again");
  fmbd_free(z);
  fmbd_alloc_pool(0, 0);
  TEST_EXIT();
}
