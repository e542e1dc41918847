// tests/unit/t302-cb.c: the CB core on a small spring-mass chain: closed form against T0'KT0
// and T0'MT0 formed densely, extension of the mode set, file round trip, allocation failures
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_cb.h"
#include "fmbd_err.h"

// a free chain of n masses (consistent-mass bar elements, unit length) plus a weak second-
// neighbour spring, so that Mc and Kc are non-trivial: K singular (one rigid mode)
static void chain(int64_t n, fmbd_csr **K, fmbd_csr **M) {
  double *k = calloc((size_t)(n * n), sizeof(double)), *m = calloc((size_t)(n * n), sizeof(double));
  for (int64_t e = 0; e + 1 < n; e++) {
    double ke = 1000.0 * (1.0 + 0.1 * (double)(e % 3)), me = 1.0 + 0.05 * (double)(e % 5);
    int64_t a = e, b = e + 1;
    k[a * n + a] += ke, k[b * n + b] += ke, k[a * n + b] -= ke, k[b * n + a] -= ke;
    m[a * n + a] += me / 3, m[b * n + b] += me / 3, m[a * n + b] += me / 6, m[b * n + a] += me / 6;
  }
  for (int64_t a = 0; a + 2 < n; a++) {
    int64_t b = a + 2;
    k[a * n + a] += 50, k[b * n + b] += 50, k[a * n + b] -= 50, k[b * n + a] -= 50;
  }
  for (int t = 0; t < 2; t++) {
    double *d = t ? m : k;
    int64_t nnz = 0;
    for (int64_t i = 0; i < n * n; i++) nnz += d[i] != 0.0;
    fmbd_csr *A = NULL;
    fmbd_csr_create(n, n, nnz, &A);
    int64_t q = 0;
    for (int64_t i = 0; i < n; i++) {
      A->indptr[i] = q;
      for (int64_t j = 0; j < n; j++) {
        if (d[i * n + j] != 0.0) A->indices[q] = j, A->data[q++] = d[i * n + j];
      }
    }
    A->indptr[n] = q;
    *(t ? M : K) = A;
  }
  free(k);
  free(m);
}

// dense column-major copy of a CSR matrix
static double *dense(const fmbd_csr *A) {
  double *D = calloc((size_t)(A->nrows * A->ncols), sizeof(double));
  for (int64_t i = 0; i < A->nrows; i++)
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++)
      D[i + A->indices[p] * A->nrows] = A->data[p];
  return D;
}

// max |T0' A T0 - R| / max|R|
static double t0_err(const fmbd_cb *cb, const double *A, int64_t n, const double *R) {
  int64_t nr = cb->nr, nd = cb->nd, nb = cb->nb, ns = cb->ns;
  double *T = calloc((size_t)(n * nr), sizeof(double)), e = 0, rmax = 0;
  for (int64_t k = 0; k < nd; k++)
    for (int64_t i = 0; i < ns; i++) T[cb->interior[i] + k * n] = cb->Phi[i + k * ns];
  for (int64_t j = 0; j < nb; j++) {
    for (int64_t i = 0; i < ns; i++) T[cb->interior[i] + (nd + j) * n] = cb->Psi[i + j * ns];
    T[cb->boundary[j] + (nd + j) * n] = 1.0;
  }
  for (int64_t a = 0; a < nr; a++)
    for (int64_t b = 0; b < nr; b++) {
      double s = 0;
      for (int64_t i = 0; i < n; i++)
        for (int64_t j = 0; j < n; j++) s += T[i + a * n] * A[i + j * n] * T[j + b * n];
      e = fmax(e, fabs(s - R[a + b * nr]));
      rmax = fmax(rmax, fabs(R[a + b * nr]));
    }
  free(T);
  return e / rmax;
}

// K and M as an fmbd-fe file gives them (fmbd_h5_read_csr_like): M's values on K's pattern (zero
// where M has no entry), both on one pair of index arrays (*Mp's indptr and indices are *Kp's)
static void shared_pair(const fmbd_csr *K, const fmbd_csr *M, fmbd_csr **Kp, fmbd_csr **Mp) {
  int64_t n = K->nrows, nnz = K->indptr[n];
  fmbd_csr_create(n, n, nnz, Kp);
  memcpy((*Kp)->indptr, K->indptr, (size_t)(n + 1) * sizeof(int64_t));
  memcpy((*Kp)->indices, K->indices, (size_t)nnz * sizeof(int64_t));
  memcpy((*Kp)->data, K->data, (size_t)nnz * sizeof(double));
  *Mp = fmbd_calloc(1, sizeof **Mp);
  (*Mp)->nrows = (*Mp)->ncols = n;
  (*Mp)->indptr = (*Kp)->indptr;
  (*Mp)->indices = (*Kp)->indices;
  (*Mp)->data = fmbd_calloc((size_t)nnz, sizeof(double));
  for (int64_t i = 0; i < n; i++)
    for (int64_t p = K->indptr[i], q = M->indptr[i]; p < K->indptr[i + 1]; p++)
      if (q < M->indptr[i + 1] && M->indices[q] == K->indices[p]) (*Mp)->data[p] = M->data[q++];
}

// destroy a pair made by shared_pair (or what fmbd_cb_reduce_take left of it)
static void shared_free(fmbd_csr **K, fmbd_csr **M) {
  if (*M && *K && (*M)->indices == (*K)->indices) (*M)->indptr = (*M)->indices = NULL;
  fmbd_csr_destroy(M);
  fmbd_csr_destroy(K);
}

int main(void) {
  const int64_t n = 60;
  fmbd_csr *K = NULL, *M = NULL;
  chain(n, &K, &M);
  double *Kd = dense(K), *Md = dense(M);
  int64_t bnd[3] = {0, 29, 59};
  fmbd_cb_opts o;
  fmbd_cb_opts_defaults(&o);
  o.nmodes = 5;
  fmbd_cb *cb = NULL;
  int rc = fmbd_cb_reduce(K, M, NULL, 3, bnd, &o, &cb);
  EXPECT(rc == 0 && cb, "reduce: rc %d (%s)", rc, fmbd_err_get()->msg);
  if (!cb) return 1;
  EXPECT(cb->ns == 57 && cb->nb == 3 && cb->nd == 5 && cb->nr == 8, "sizes");
  // closed form equals T0' K T0 and T0' M T0 formed densely (round-off: 1e-12)
  double ek = t0_err(cb, Kd, n, cb->Kr), em = t0_err(cb, Md, n, cb->Mr);
  EXPECT(ek < 1e-12 && em < 1e-12, "closed form: K %.2e M %.2e", ek, em);
  // the sparse path (dense_max below ns: Lanczos with the LL' factor, then the Sturm check),
  // where fe2cb parks Ms's values during the LL', Ks's through the Lanczos run (back for the
  // residual check through fmbd_eig_opts.need_k, dropped again for the projections) and the
  // projection blocks during the Sturm check: the same constraint modes and projections bit
  // for bit (same factor, same operations), the same eigenvalues to the Lanczos accuracy
  // (ARPACK tol 1e-10 on the shift-inverted eigenvalues: relative 1e-9 leaves a margin),
  // residuals small, the Sturm count complete
  {
    fmbd_cb_opts o2 = o;
    o2.eig.dense_max = 10;
    fmbd_cb *cs = NULL;
    rc = fmbd_cb_reduce(K, M, NULL, 3, bnd, &o2, &cs);
    EXPECT(rc == 0 && cs && cs->nd == 5, "sparse-path reduce: rc %d (%s)", rc, fmbd_err_get()->msg);
    if (cs) {
      size_t bytes = (size_t)(cs->ns * cs->nb) * sizeof(double);
      EXPECT(!memcmp(cs->Psi, cb->Psi, bytes) && !memcmp(cs->A, cb->A, bytes) &&
                 !memcmp(cs->KsinvA, cb->KsinvA, bytes) &&
                 !memcmp(cs->KsinvMsKsinvA, cb->KsinvMsKsinvA, bytes),
             "sparse path: constraint modes and projections differ");
      double e = 0.0;
      for (int64_t k = 0; k < 5; k++) e = fmax(e, fabs(cs->kappa[k] / cb->kappa[k] - 1.0));
      EXPECT(e < 1e-9, "sparse path: eigenvalues differ by %.2e", e);
      EXPECT(cs->sturm_count == 5 && cs->max_residual < 1e-6,
             "sparse path: Sturm count %lld, residual %.2e", (long long)cs->sturm_count,
             cs->max_residual);
      fmbd_cb_destroy(&cs);
    }
  }
  // fmbd_cb_reduce_take on K and M on one pair of index arrays (fe2cb's case): the interior
  // blocks written over K's and M's arrays, which must give the same blocks as the reduction
  // of the same pair left to the caller (the same entries in the same order): the same factor,
  // so the same constraint modes and projections bit for bit on the dense and the sparse path,
  // and on the dense path the same modes bit for bit
  for (int sparse = 0; sparse < 2; sparse++) {
    fmbd_cb_opts o2 = o;
    if (sparse) o2.eig.dense_max = 10;
    fmbd_csr *K2 = NULL, *M2 = NULL;
    fmbd_cb *ref = NULL, *tk = NULL;
    shared_pair(K, M, &K2, &M2);
    rc = fmbd_cb_reduce(K2, M2, NULL, 3, bnd, &o2, &ref);
    EXPECT(rc == 0 && ref, "shared pattern reduce: rc %d (%s)", rc, fmbd_err_get()->msg);
    rc = fmbd_cb_reduce_take(&K2, &M2, NULL, 3, bnd, &o2, &tk);
    EXPECT(rc == 0 && tk && !K2 && !M2, "reduce_take: rc %d (%s)", rc, fmbd_err_get()->msg);
    if (ref && tk) {
      size_t bytes = (size_t)(ref->ns * ref->nb) * sizeof(double);
      // the sparse path's Lanczos run differs in the last bits between fmbd_cb_reduce and
      // fmbd_cb_reduce_take before this change too (relative 3e-16 here): its eigenvalues are
      // asked to the Lanczos accuracy, relative 1e-9 as above
      double e = 0.0;
      for (int64_t k = 0; k < ref->nd && k < tk->nd; k++)
        e = fmax(e, fabs(tk->kappa[k] / ref->kappa[k] - 1.0));
      EXPECT(tk->nd == ref->nd && e < 1e-9, "reduce_take (sparse %d): eigenvalues differ by %.2e",
             sparse, e);
      bool same_modes = !memcmp(tk->kappa, ref->kappa, (size_t)ref->nd * sizeof(double)) &&
                        !memcmp(tk->Phi, ref->Phi, (size_t)(ref->ns * ref->nd) * sizeof(double)) &&
                        !memcmp(tk->Kr, ref->Kr, (size_t)(ref->nr * ref->nr) * sizeof(double)) &&
                        !memcmp(tk->Mr, ref->Mr, (size_t)(ref->nr * ref->nr) * sizeof(double));
      EXPECT(tk->nr == ref->nr && (sparse || same_modes) && !memcmp(tk->Psi, ref->Psi, bytes) &&
                 !memcmp(tk->A, ref->A, bytes) && !memcmp(tk->KsinvA, ref->KsinvA, bytes) &&
                 !memcmp(tk->KsinvMsKsinvA, ref->KsinvMsKsinvA, bytes),
             "reduce_take (sparse %d): the body differs from fmbd_cb_reduce's", sparse);
      // and the pair is the chain's: the closed form as above
      double e1 = t0_err(tk, Kd, n, tk->Kr), e2 = t0_err(tk, Md, n, tk->Mr);
      EXPECT(e1 < 1e-12 && e2 < 1e-12, "reduce_take closed form: K %.2e M %.2e", e1, e2);
    }
    fmbd_cb_destroy(&ref);
    fmbd_cb_destroy(&tk);
    shared_free(&K2, &M2);
  }

  // one rigid mode of the free chain, flagged
  EXPECT(cb->n_rigid == 1 && cb->rigid[0] == 1 && cb->rigid[1] == 0, "rigid: %lld",
         (long long)cb->n_rigid);

  // --- extend 5 -> 9 modes: the old ones reproduced, PhitA and the reduced problem updated ---
  double k_old[5];
  memcpy(k_old, cb->kappa, sizeof k_old);
  rc = fmbd_cb_extend(K, M, cb, 9, NULL);
  EXPECT(rc == 0 && cb->nd == 9 && cb->nr == 12, "extend: rc %d nd %lld", rc, (long long)cb->nd);
  for (int k = 0; k < 5 && rc == 0; k++) {
    EXPECT(fabs(cb->kappa[k] - k_old[k]) <= 1e-10 * k_old[k], "extend: kappa %d moved", k);
  }
  ek = t0_err(cb, Kd, n, cb->Kr), em = t0_err(cb, Md, n, cb->Mr);
  EXPECT(ek < 1e-12 && em < 1e-12, "closed form after extend: K %.2e M %.2e", ek, em);
  EXPECT(cb->kappa_next > cb->kappa[8], "kappa_next %g", cb->kappa_next);
  double chib9 = cb->chibar[1];
  // truncation back to 4: no solve, and the reduced eigenvalue of the first flexible mode
  // cannot be lower than with 9 modes (nested Ritz spaces)
  rc = fmbd_cb_extend(K, M, cb, 4, NULL);
  EXPECT(rc == 0 && cb->nd == 4 && cb->chibar[1] >= chib9 * (1 - 1e-12), "truncate: rc %d", rc);
  ek = t0_err(cb, Kd, n, cb->Kr), em = t0_err(cb, Md, n, cb->Mr);
  EXPECT(ek < 1e-12 && em < 1e-12, "closed form after truncation: K %.2e M %.2e", ek, em);

  // --- file round trip ---
  char path[] = "/tmp/t302-cb-XXXXXX";
  int fd = mkstemp(path);
  if (fd >= 0) close(fd);
  fmbd_h5 *f = NULL;
  rc = fmbd_h5_create(path, FMBD_CB_FORMAT, FMBD_CB_FORMAT_VERSION, &f);
  rc = rc ? rc : fmbd_cb_write(f, cb);
  rc = rc ? rc : fmbd_h5_commit(&f, 0.0, 0.0);
  EXPECT(rc == 0, "write: rc %d %s", rc, fmbd_err_get()->msg);
  fmbd_cb *rd = NULL;
  rc = fmbd_h5_open(path, &f);
  rc = rc ? rc : fmbd_cb_read(f, &rd);
  EXPECT(rc == 0 && rd, "read: rc %d %s", rc, fmbd_err_get()->msg);
  if (rd) {
    EXPECT(rd->ns == cb->ns && rd->nb == cb->nb && rd->nd == cb->nd && rd->n_rigid == cb->n_rigid,
           "read sizes");
    double e = 0;
    for (int64_t i = 0; i < cb->ns * cb->nb; i++)
      e = fmax(e, fabs(rd->Psi[i] - cb->Psi[i]) + fabs(rd->KsinvA[i] - cb->KsinvA[i]));
    for (int64_t i = 0; i < cb->nr * cb->nr; i++)
      e = fmax(e, fabs(rd->Mr[i] - cb->Mr[i]) + fabs(rd->Xi[i] - cb->Xi[i]));
    for (int64_t i = 0; i < cb->ns * cb->nd; i++) e = fmax(e, fabs(rd->Phi[i] - cb->Phi[i]));
    EXPECT(e == 0.0, "round trip not bit-exact: %g", e);
    EXPECT(rd->kappa_next == cb->kappa_next, "kappa_next round trip");
  }
  fmbd_cb_destroy(&rd);
  fmbd_h5_close(&f);
  unlink(path);
  fmbd_cb_destroy(&cb);
  EXPECT(cb == NULL, "destroy");

  // --- errors: more modes than interior dofs; a floating interior (no boundary at all) ---
  o.nmodes = 58;
  rc = fmbd_cb_reduce(K, M, NULL, 3, bnd, &o, &cb);
  EXPECT(rc == FMBD_ERR_VALUE && !cb, "too many modes: rc %d", rc);
  o.nmodes = 3;
  rc = fmbd_cb_reduce(K, M, NULL, 0, bnd, &o, &cb);
  EXPECT(rc == FMBD_ERR_SINGULAR && !cb && strstr(fmbd_err_get()->msg, "singular at dof"),
         "floating: rc %d %s", rc, fmbd_err_get()->msg);

  // --- nm free-free: the rigid mode removed, flexible eigenvalues as the CB-free reference ---
  o.nm = true;
  o.nmodes = 4;
  rc = fmbd_cb_reduce(K, M, NULL, 3, bnd, &o, &cb);
  EXPECT(rc == 0 && cb && cb->n_rigid_removed == 1 && cb->nd == 4 && cb->kappa[0] > 1.0,
         "nm: rc %d", rc);
  fmbd_cb_destroy(&cb);

  // --- allocation countdown: every failure is clean (ASan/leak check under SANITIZE=1) ---
  o.nm = false;
  o.nmodes = 3;
  for (int64_t c = 0; c < 400; c += 7) {
    fmbd_alloc_fail_after(c);
    rc = fmbd_cb_reduce(K, M, NULL, 3, bnd, &o, &cb);
    fmbd_alloc_fail_after(-1);
    if (rc == 0) {
      fmbd_cb_destroy(&cb);
      continue;
    }
    EXPECT(cb == NULL && (rc == FMBD_ERR_NOMEM || rc == FMBD_ERR_EXTERNAL), "countdown %lld: rc %d",
           (long long)c, rc);
  }
  // the same with the matrices taken: whatever fails, what is left in K2, M2 is the caller's
  for (int64_t c = 0; c < 400; c += 7) {
    fmbd_csr *K2 = NULL, *M2 = NULL;
    shared_pair(K, M, &K2, &M2);
    fmbd_alloc_fail_after(c);
    rc = fmbd_cb_reduce_take(&K2, &M2, NULL, 3, bnd, &o, &cb);
    fmbd_alloc_fail_after(-1);
    shared_free(&K2, &M2);
    if (rc == 0) {
      fmbd_cb_destroy(&cb);
      continue;
    }
    EXPECT(cb == NULL && (rc == FMBD_ERR_NOMEM || rc == FMBD_ERR_EXTERNAL),
           "take countdown %lld: rc %d", (long long)c, rc);
  }
  fmbd_csr_destroy(&K);
  fmbd_csr_destroy(&M);
  free(Kd);
  free(Md);
  TEST_EXIT();
}
