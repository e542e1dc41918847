// tests/unit/t303-eig-nevermiss.c: the eigensolver's never-miss paths, forced to run
// SPDX-License-Identifier: MIT
//
// Two uncoupled held bars (block-diagonal K and M; linear FE, consistent mass, same element
// length h, N1 = 2 N2 elements). Their exact discrete eigenvalues are
//   lambda(k, N) = 6/h^2 (1 - cos(k pi / N)) / (2 + cos(k pi / N)),  k = 1 .. N-1,
// so bar 2's lambda(k, N2) equals bar 1's lambda(2k, N1): every second eigenvalue of the
// union is an exactly repeated pair. A start vector that is zero on bar 2 (fmbd_eig_opts.v0,
// a documented option) keeps single-vector Lanczos inside bar 1: the solver's factor of a
// block-diagonal matrix is block-diagonal, so the zeros stay exact and bar 2's modes are
// missed for certain. That forces:
//   - the in-loop Sturm check to fail (its error with no pass left; its repeat, which starts
//     afresh without v0, to succeed);
//   - fmbd_eig_sturm_check after a solve without the check to report the miss;
//   - fmbd_cb_reduce's re-solve (the path fe2cb takes), and its failure.
// A tiny Krylov space with a loose ARPACK tolerance (ncv = nreq + 1, tol 0.9: Ritz pairs
// accepted after one Lanczos factorisation of 16 vectors, while 15 pairs of a 199-dof bar
// cannot be resolved to 1e-6 from 16 vectors) forces the residual check to fail.
// The block method (fmbd_eig_opts.block) is checked on the same repeated spectrum and against
// ARPACK on the square membrane.
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_cb.h"
#include "fmbd_eig.h"
#include "fmbd_err.h"

static double lam(int k, int N, double h) {
  return 6.0 / (h * h) * (1 - cos(k * M_PI / N)) / (2 + cos(k * M_PI / N));
}

static int cmpd(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

// block-diagonal tridiagonal matrices of bars with nb[b] dofs each: diagonal d, off-diagonal o
static fmbd_csr *bars(int nbars, const int64_t *nb, double d, double o) {
  int64_t n = 0;
  for (int b = 0; b < nbars; b++) n += nb[b];
  fmbd_csr *A = NULL;
  if (fmbd_csr_create(n, n, 3 * n, &A)) return NULL;
  int64_t k = 0, r = 0;
  for (int b = 0; b < nbars; b++) {
    for (int64_t i = 0; i < nb[b]; i++, r++) {
      A->indptr[r] = k;
      if (i > 0) A->indices[k] = r - 1, A->data[k++] = o;
      A->indices[k] = r, A->data[k++] = d;
      if (i < nb[b] - 1) A->indices[k] = r + 1, A->data[k++] = o;
    }
  }
  A->indptr[n] = k;
  return A;
}

static bool msg_has(const char *what) {
  return strstr(fmbd_err_get()->msg, what) != NULL;
}

int main(void) {
  const int N1 = 120, N2 = 60;
  const double h = 1.0 / N1;
  const int64_t nb2[2] = {N1 - 1, N2 - 1};  // held bars: interior nodes
  const int64_t n = nb2[0] + nb2[1];
  fmbd_csr *K = bars(2, nb2, 2.0 / h, -1.0 / h), *M = bars(2, nb2, 4 * h / 6, h / 6);
  // exact spectrum of the union, ascending
  double *ex = malloc((size_t)n * sizeof(double));
  for (int k = 1; k < N1; k++) ex[k - 1] = lam(k, N1, h);
  for (int k = 1; k < N2; k++) ex[N1 - 2 + k] = lam(k, N2, h);
  qsort(ex, (size_t)n, sizeof(double), cmpd);
  // start vector on bar 1 only
  double *v0 = calloc((size_t)n, sizeof(double));
  for (int64_t i = 0; i < nb2[0]; i++) v0[i] = 1.0 + 0.01 * (double)i;
  const int64_t nev = 10;
  // an eigenvalue agrees to 1e-9 relative: ARPACK's tol 1e-12 on the Ritz values of OP and
  // the accepted residual 1e-6 give an eigenvalue error of order resid^2 (symmetric problem,
  // Rayleigh quotient) far below; 1e-9 leaves room for round-off in K's 1/h^2 = 1.4e4 scale
  const double etol = 1e-9;

  // --- the miss is real: without the check, bar 2's modes are absent --------------------------
  {
    fmbd_eig_opts o;
    fmbd_eig_defaults(&o);
    o.nev = nev;
    o.dense_max = 10;  // Lanczos on this small problem
    o.block = 1;
    o.v0 = v0;
    o.sturm = false;
    fmbd_eig_result r;
    int rc = fmbd_eig_solve(K, M, NULL, &o, &r);
    EXPECT(rc == 0 && r.nev == nev, "no check: rc %d", rc);
    // the returned set is bar 1's lowest: lambda(k, N1), k = 1..nev
    for (int64_t k = 0; rc == 0 && k < nev; k++) {
      double e1 = lam((int)k + 1, N1, h);
      EXPECT(fabs(r.lambda[k] - e1) <= etol * e1, "bar-1 mode %lld: %.15g vs %.15g",
             (long long)k + 1, r.lambda[k], e1);
    }
    // ex[1] = ex[2] is the first repeated pair (bar 1's 2nd, bar 2's 1st): one copy is missed
    EXPECT(rc || r.lambda[2] > ex[2] * (1 + 1e-6), "mode 3 should have been missed: %.15g",
           rc ? 0.0 : r.lambda[2]);
    // the check afterwards (fe2cb's way) sees the miss
    bool ok = true;
    rc = rc ? rc : fmbd_eig_sturm_check(K, M, NULL, &r, &ok);
    EXPECT(rc == 0 && !ok && r.sturm_count > r.nev, "sturm_check: rc %d ok %d count %lld", rc,
           (int)ok, (long long)r.sturm_count);
    // its count is the exact number of eigenvalues below the shift
    int64_t below = 0;
    for (int64_t i = 0; i < n; i++) below += ex[i] < r.sturm_shift;
    EXPECT(r.sturm_count == below, "Sturm count %lld, exact %lld below %.9g",
           (long long)r.sturm_count, (long long)below, r.sturm_shift);
    fmbd_eig_result_free(&r);
  }

  // --- in-loop Sturm check: fails with no pass left, succeeds on the fresh repeat ------------
  {
    fmbd_eig_opts o;
    fmbd_eig_defaults(&o);
    o.nev = nev;
    o.dense_max = 10;
    o.block = 1;
    o.v0 = v0;
    o.max_passes = 0;
    fmbd_eig_result r;
    int rc = fmbd_eig_solve(K, M, NULL, &o, &r);
    EXPECT(rc == FMBD_ERR_CONVERGE && msg_has("Sturm check failed"), "rc %d: %s", rc,
           fmbd_err_get()->msg);
    fmbd_eig_result_free(&r);
    o.max_passes = 4;
    rc = fmbd_eig_solve(K, M, NULL, &o, &r);
    EXPECT(rc == 0 && r.nev == nev && r.passes >= 2 && r.sturm_count == nev,
           "repeat: rc %d nev %lld passes %d count %lld", rc, (long long)r.nev, r.passes,
           (long long)r.sturm_count);
    for (int64_t k = 0; rc == 0 && k < nev; k++) {
      EXPECT(fabs(r.lambda[k] - ex[k]) <= etol * ex[k], "mode %lld: %.15g vs %.15g",
             (long long)k + 1, r.lambda[k], ex[k]);
    }
    fmbd_eig_result_free(&r);
  }

  // --- the repeated spectrum, block method and ARPACK, no start vector -------------------------
  for (int64_t blk = 1; blk <= 8; blk *= 2) {
    fmbd_eig_opts o;
    fmbd_eig_defaults(&o);
    o.nev = 24;
    o.dense_max = 10;
    o.block = blk;
    fmbd_eig_result r;
    int rc = fmbd_eig_solve(K, M, NULL, &o, &r);
    EXPECT(rc == 0 && r.nev == 24 && r.sturm_count == 24 && r.block == blk,
           "block %lld: rc %d nev %lld count %lld block %lld", (long long)blk, rc, (long long)r.nev,
           (long long)r.sturm_count, (long long)r.block);
    for (int64_t k = 0; rc == 0 && k < r.nev; k++) {
      EXPECT(fabs(r.lambda[k] - ex[k]) <= etol * ex[k], "block %lld mode %lld: %.15g vs %.15g",
             (long long)blk, (long long)k + 1, r.lambda[k], ex[k]);
      EXPECT(r.resid[k] <= o.resid_tol, "block %lld residual %.3g", (long long)blk, r.resid[k]);
    }
    fmbd_eig_result_free(&r);
  }

  // --- residual check: a tiny Krylov space with a loose tolerance ------------------------------
  {
    const int64_t one[1] = {N1 * 5 / 3 - 1};  // one held bar of 199 dofs, h as above
    fmbd_csr *K1 = bars(1, one, 2.0 / h, -1.0 / h), *M1 = bars(1, one, 4 * h / 6, h / 6);
    const int Nb = (int)one[0] + 1;
    fmbd_eig_opts o;
    fmbd_eig_defaults(&o);
    o.nev = 12;
    o.dense_max = 10;
    o.block = 1;
    o.tol = 0.9;
    o.ncv = 16;  // nreq = nev + 3 = 15: ncv = nreq + 1
    o.max_passes = 0;
    fmbd_eig_result r;
    int rc = fmbd_eig_solve(K1, M1, NULL, &o, &r);
    EXPECT(rc == FMBD_ERR_CONVERGE && msg_has("relative residual"), "rc %d: %s", rc,
           fmbd_err_get()->msg);
    fmbd_eig_result_free(&r);
    // with passes left, the tolerance tightens and the basis grows until every residual passes
    o.max_passes = 6;
    rc = fmbd_eig_solve(K1, M1, NULL, &o, &r);
    EXPECT(rc == 0 && r.nev == 12 && r.passes >= 2, "repeat: rc %d passes %d", rc, r.passes);
    for (int64_t k = 0; rc == 0 && k < r.nev; k++) {
      double e = lam((int)k + 1, Nb, h);
      // the accepted residual 1e-6 bounds the eigenvalue error by about resid^2 relative
      EXPECT(fabs(r.lambda[k] - e) <= 1e-9 * e, "mode %lld: %.15g vs %.15g", (long long)k + 1,
             r.lambda[k], e);
      EXPECT(r.resid[k] <= o.resid_tol, "residual %.3g", r.resid[k]);
    }
    fmbd_eig_result_free(&r);
    // the dense path reports (and enforces) its residuals: LAPACK's backward-stable solve
    // leaves about eps lambda_top / lambda, at most 1.4e4 * 4 / 1e1 * eps ~ 1e-12 here
    fmbd_eig_defaults(&o);
    o.nev = 12;
    rc = fmbd_eig_solve(K1, M1, NULL, &o, &r);
    EXPECT(rc == 0 && r.dense && r.nev == 12, "dense: rc %d", rc);
    for (int64_t k = 0; rc == 0 && k < r.nev; k++) {
      EXPECT(r.resid[k] > 0.0 && r.resid[k] <= 1e-10, "dense residual %lld: %.3g", (long long)k + 1,
             r.resid[k]);
    }
    fmbd_eig_result_free(&r);
    fmbd_csr_destroy(&K1);
    fmbd_csr_destroy(&M1);
  }

  // --- fmbd_cb_reduce: the re-solve after a failed Sturm check (fe2cb's path) -----------------
  {
    // the two bars with both end nodes as boundary dofs: the interior is the held pair above
    const int64_t nf[2] = {N1 + 1, N2 + 1};
    fmbd_csr *Kf = bars(2, nf, 2.0 / h, -1.0 / h), *Mf = bars(2, nf, 4 * h / 6, h / 6);
    // free ends: half the diagonal at each bar's end nodes
    int64_t ends[4] = {0, N1, N1 + 1, N1 + 1 + N2};
    for (int e = 0; e < 4; e++) {
      int64_t i = ends[e], p = fmbd_csr_find(Kf, i, i), q = fmbd_csr_find(Mf, i, i);
      Kf->data[p] *= 0.5;
      Mf->data[q] *= 0.5;
    }
    fmbd_cb_opts o;
    fmbd_cb_defaults(&o);
    o.nmodes = nev;
    o.eig.dense_max = 10;
    o.eig.block = 1;
    o.eig.v0 = v0;  // the interior is ordered bar 1, bar 2 as above
    fmbd_cb *cb = NULL;
    int rc = fmbd_cb_reduce(Kf, Mf, NULL, 4, ends, &o, &cb);
    // the first solve misses, the check after it fails, the re-solve's first pass misses
    // again (v0), its in-loop check fails, its second pass starts afresh: >= 3 passes
    EXPECT(rc == 0 && cb->nd == nev && cb->sturm_count == nev && cb->time.eig_passes >= 3,
           "cb re-solve: rc %d nd %lld count %lld passes %d", rc, rc ? 0LL : (long long)cb->nd,
           rc ? 0LL : (long long)cb->sturm_count, rc ? 0 : cb->time.eig_passes);
    for (int64_t k = 0; rc == 0 && k < nev; k++) {
      EXPECT(fabs(cb->kappa[k] - ex[k]) <= etol * ex[k], "cb mode %lld: %.15g vs %.15g",
             (long long)k + 1, cb->kappa[k], ex[k]);
    }
    EXPECT(rc || cb->max_residual <= o.eig.resid_tol, "cb max_residual %.3g",
           rc ? 0.0 : cb->max_residual);
    fmbd_cb_destroy(&cb);
    // and with no pass left the re-solve's failure is the error
    o.eig.max_passes = 0;
    rc = fmbd_cb_reduce(Kf, Mf, NULL, 4, ends, &o, &cb);
    EXPECT(rc == FMBD_ERR_CONVERGE && msg_has("Sturm check failed"), "cb: rc %d: %s", rc,
           fmbd_err_get()->msg);
    fmbd_cb_destroy(&cb);
    fmbd_csr_destroy(&Kf);
    fmbd_csr_destroy(&Mf);
  }

  free(ex);
  free(v0);
  fmbd_csr_destroy(&K);
  fmbd_csr_destroy(&M);
  TEST_EXIT();
}
