// common/fmbd_gm.c: global modes of a linearised mechanism (see fmbd_gm.h, docs/THEORY.md
// section 6)
// SPDX-License-Identifier: MIT
#include "fmbd_gm.h"

#include <klu.h>
#include <lapacke.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"

void fmbd_gm_opts_defaults(fmbd_gm_opts *o) {
  memset(o, 0, sizeof *o);
  o->nmodes = 10;
  o->lambda_max = 0.0;
  o->zero_tol = 1e-11;
  o->rank_tol = 1e-10;
  // dense LAPACK up to order 1000 (about a second): complete by construction, and backward
  // stable where shift-invert Lanczos with ARPACK's tol 1e-12 leaves relative residuals of
  // 1e-12 max(Kr_ii/Mr_ii) / w^2 (a 64-link chain of slender beams: 3e-4 on its soft modes,
  // which fmbd_eig's residual check refuses)
  o->dense_max = 1000;
}

void fmbd_gm_null_free(fmbd_gm_null *N) {
  if (!N) return;
  fmbd_csr_destroy(&N->Z);
  fmbd_free(N->dep);
  fmbd_free(N->ind);
  memset(N, 0, sizeof *N);
}

// Dense column-major copy of the rows of Cq restricted to the columns col[0..nc-1]
// (colpos[j] = position of column j or -1), each row scaled to unit norm over those columns.
static void dense_rows(const fmbd_csr *Cq, int64_t nc, const int64_t *colpos, double *A) {
  int64_t m = Cq->nrows;
  memset(A, 0, sizeof(double) * (size_t)(m * nc));
  for (int64_t i = 0; i < m; i++) {
    double s = 0.0;
    for (int64_t p = Cq->indptr[i]; p < Cq->indptr[i + 1]; p++) {
      int64_t c = colpos[Cq->indices[p]];
      if (c >= 0) {
        A[i + m * c] += Cq->data[p];
        s += Cq->data[p] * Cq->data[p];
      }
    }
    s = s > 0.0 ? 1.0 / sqrt(s) : 0.0;
    for (int64_t c = 0; c < nc; c++) A[i + m * c] *= s;
  }
}

// QR with column pivoting of the m x nc column-major A (destroyed); jp (nc) 0-based pivot
// order; rank with |R_kk| > tol |R_11|.
static int pivoted_qr(int64_t m, int64_t nc, double *A, int64_t *jp, double tol, int64_t *rank,
                      double *cond) {
  int rc = FMBD_OK;
  lapack_int *jpv = NULL;
  double *tau = NULL;
  *rank = 0;
  if (cond) *cond = 1.0;
  if (m == 0 || nc == 0) return FMBD_OK;
  FMBD_CHECK(m < 2147483647 && nc < 2147483647 && m * nc < 2147483647L, FMBD_ERR_VALUE,
             "constraint block %lld x %lld too large for LAPACK", (long long)m, (long long)nc);
  FMBD_GALLOC(jpv = fmbd_calloc((size_t)nc, sizeof(lapack_int)));
  FMBD_GALLOC(tau = fmbd_calloc((size_t)(m < nc ? m : nc), sizeof(double)));
  lapack_int info =
      LAPACKE_dgeqp3(LAPACK_COL_MAJOR, (lapack_int)m, (lapack_int)nc, A, (lapack_int)m, jpv, tau);
  FMBD_GCHECK(info == 0, FMBD_ERR_EXTERNAL, "LAPACK dgeqp3 failed (info %d)", (int)info);
  for (int64_t j = 0; j < nc; j++) jp[j] = jpv[j] - 1;
  int64_t k = m < nc ? m : nc;
  double r11 = fabs(A[0]);
  int64_t r = 0;
  while (r < k && fabs(A[r + m * r]) > tol * r11) r++;
  *rank = r;
  if (cond && r > 0) *cond = r11 / fabs(A[(r - 1) + m * (r - 1)]);
done:
  fmbd_free(jpv);
  fmbd_free(tau);
  return rc;
}

// One row of Cq (restricted to colpos) that depends on the others: pivoted QR of the rows.
static int dependent_row(const fmbd_csr *Cq, int64_t nc, const int64_t *colpos, double tol,
                         int64_t *row) {
  int rc = FMBD_OK;
  int64_t m = Cq->nrows, rank = 0;
  double *A = NULL, *At = NULL;
  int64_t *jp = NULL;
  *row = -1;
  FMBD_GALLOC(A = fmbd_malloc(sizeof(double) * (size_t)(m * nc + 1)));
  FMBD_GALLOC(At = fmbd_malloc(sizeof(double) * (size_t)(m * nc + 1)));
  FMBD_GALLOC(jp = fmbd_calloc((size_t)m + 1, sizeof(int64_t)));
  dense_rows(Cq, nc, colpos, A);
  for (int64_t i = 0; i < m; i++) {
    for (int64_t c = 0; c < nc; c++) At[c + nc * i] = A[i + m * c];
  }
  FMBD_GCALL(pivoted_qr(nc, m, At, jp, tol, &rank, NULL));
  // the rows pivoted last are the dependent ones; name the first of them in row order
  int64_t best = -1;
  for (int64_t k = rank; k < m; k++) {
    if (best < 0 || jp[k] < best) best = jp[k];
  }
  *row = best;
done:
  fmbd_free(A);
  fmbd_free(At);
  fmbd_free(jp);
  return rc;
}

int fmbd_gm_rank(const fmbd_csr *Cq, const bool *cols, double tol, int64_t *rank) {
  int rc = FMBD_OK;
  int64_t m = Cq->nrows, n = Cq->ncols, nc = 0;
  int64_t *colpos = NULL, *jp = NULL;
  double *A = NULL;
  *rank = 0;
  FMBD_GALLOC(colpos = fmbd_malloc(sizeof(int64_t) * (size_t)(n + 1)));
  for (int64_t j = 0; j < n; j++) colpos[j] = cols[j] ? nc++ : -1;
  FMBD_GALLOC(A = fmbd_malloc(sizeof(double) * (size_t)(m * nc + 1)));
  FMBD_GALLOC(jp = fmbd_calloc((size_t)nc + 1, sizeof(int64_t)));
  dense_rows(Cq, nc, colpos, A);
  FMBD_GCALL(pivoted_qr(m, nc, A, jp, tol, rank, NULL));
done:
  fmbd_free(colpos);
  fmbd_free(jp);
  fmbd_free(A);
  return rc;
}

int fmbd_gm_nullspace(const fmbd_csr *Cq, double rank_tol, fmbd_gm_null *N, int64_t *bad_row) {
  int rc = FMBD_OK;
  int64_t m = Cq->nrows, n = Cq->ncols;
  int64_t *colpos = NULL, *tc = NULL, *jp = NULL, *isdep = NULL, *zcol = NULL, *tind = NULL;
  double *A = NULL, *X = NULL;
  SuiteSparse_long *Ap = NULL, *Ai = NULL;
  double *Ax = NULL;
  klu_l_common kc;
  klu_l_symbolic *sym = NULL;
  klu_l_numeric *num = NULL;
  klu_l_defaults(&kc);
  memset(N, 0, sizeof *N);
  if (bad_row) *bad_row = -1;
  FMBD_CHECK(m <= n, FMBD_ERR_VALUE, "%lld constraint equations on %lld coordinates", (long long)m,
             (long long)n);
  N->n = n;
  N->m = m;
  // --- the touched columns ---
  FMBD_GALLOC(colpos = fmbd_malloc(sizeof(int64_t) * (size_t)(n + 1)));
  for (int64_t j = 0; j < n; j++) colpos[j] = -1;
  for (int64_t p = 0; p < fmbd_csr_nnz(Cq); p++) colpos[Cq->indices[p]] = 0;
  int64_t nt = 0;
  FMBD_GALLOC(tc = fmbd_malloc(sizeof(int64_t) * (size_t)(n + 1)));
  for (int64_t j = 0; j < n; j++) {
    if (colpos[j] == 0) {
      colpos[j] = nt;
      tc[nt++] = j;
    }
  }
  N->ntouched = nt;
  // --- the partition: QR with column pivoting of the touched block ---
  FMBD_GALLOC(A = fmbd_malloc(sizeof(double) * (size_t)(m * nt + 1)));
  FMBD_GALLOC(jp = fmbd_calloc((size_t)nt + 1, sizeof(int64_t)));
  dense_rows(Cq, nt, colpos, A);
  int64_t rank = 0;
  FMBD_GCALL(pivoted_qr(m, nt, A, jp, rank_tol, &rank, &N->cond_est));
  if (rank < m) {
    int64_t row = -1;
    FMBD_GCALL(dependent_row(Cq, nt, colpos, rank_tol, &row));
    if (bad_row) *bad_row = row;
    FMBD_GFAIL(FMBD_ERR_SINGULAR,
               "the constraint equations are dependent at this configuration (rank %lld of %lld; "
               "row %lld depends on the others)",
               (long long)rank, (long long)m, (long long)row);
  }
  fmbd_free(A);
  A = NULL;
  FMBD_GALLOC(N->dep = fmbd_malloc(sizeof(int64_t) * (size_t)(m + 1)));
  FMBD_GALLOC(N->ind = fmbd_malloc(sizeof(int64_t) * (size_t)(n - m + 1)));
  FMBD_GALLOC(isdep = fmbd_malloc(sizeof(int64_t) * (size_t)(n + 1)));
  for (int64_t j = 0; j < n; j++) isdep[j] = -1;
  for (int64_t i = 0; i < m; i++) {
    N->dep[i] = tc[jp[i]];
    isdep[N->dep[i]] = i;
  }
  FMBD_GALLOC(zcol = fmbd_malloc(sizeof(int64_t) * (size_t)(n + 1)));
  int64_t nz = 0, nti = 0;
  FMBD_GALLOC(tind = fmbd_malloc(sizeof(int64_t) * (size_t)(nt + 1)));
  for (int64_t j = 0; j < n; j++) {
    zcol[j] = -1;
    if (isdep[j] >= 0) continue;
    zcol[j] = nz;
    N->ind[nz++] = j;
    if (colpos[j] >= 0) tind[nti++] = j;  // touched independent: a solve each
  }
  // --- Cd in compressed columns (KLU), factored ---
  if (m > 0) {
    FMBD_GALLOC(Ap = fmbd_calloc((size_t)m + 1, sizeof(SuiteSparse_long)));
    int64_t nnzd = 0;
    for (int64_t p = 0; p < fmbd_csr_nnz(Cq); p++) {
      int64_t c = isdep[Cq->indices[p]];
      if (c >= 0) Ap[c + 1]++, nnzd++;
    }
    for (int64_t i = 0; i < m; i++) Ap[i + 1] += Ap[i];
    FMBD_GALLOC(Ai = fmbd_malloc(sizeof(SuiteSparse_long) * (size_t)(nnzd + 1)));
    FMBD_GALLOC(Ax = fmbd_malloc(sizeof(double) * (size_t)(nnzd + 1)));
    int64_t *fill = jp;  // reuse (nt >= m)
    for (int64_t i = 0; i < m; i++) fill[i] = Ap[i];
    for (int64_t r = 0; r < m; r++) {
      for (int64_t p = Cq->indptr[r]; p < Cq->indptr[r + 1]; p++) {
        int64_t c = isdep[Cq->indices[p]];
        if (c < 0) continue;
        Ai[fill[c]] = r;
        Ax[fill[c]++] = Cq->data[p];
      }
    }
    sym = klu_l_analyze(m, Ap, Ai, &kc);
    FMBD_GCHECK(sym, FMBD_ERR_EXTERNAL, "KLU analysis of the dependent block failed (status %d)",
                (int)kc.status);
    num = klu_l_factor(Ap, Ai, Ax, sym, &kc);
    FMBD_GCHECK(num && kc.status == KLU_OK, FMBD_ERR_SINGULAR,
                "the dependent block of the constraint Jacobian is singular (KLU status %d)",
                (int)kc.status);
  }
  // --- X = Cd^-1 Ci for the touched independent columns, in blocks of 32 ---
  FMBD_GALLOC(X = fmbd_calloc((size_t)(m * nti + 1), sizeof(double)));
  for (int64_t j0 = 0; j0 < nti && m > 0; j0 += 32) {
    int64_t nb = nti - j0 < 32 ? nti - j0 : 32;
    double *B = X + m * j0;
    for (int64_t r = 0; r < m; r++) {
      for (int64_t p = Cq->indptr[r]; p < Cq->indptr[r + 1]; p++) {
        int64_t c = Cq->indices[p];
        if (isdep[c] >= 0) continue;
        // position of c among tind[j0 .. j0+nb-1] (increasing): binary search
        int64_t lo = j0, hi = j0 + nb - 1;
        while (lo <= hi) {
          int64_t mid = (lo + hi) / 2;
          if (tind[mid] < c)
            lo = mid + 1;
          else if (tind[mid] > c)
            hi = mid - 1;
          else {
            B[r + m * (mid - j0)] += Cq->data[p];
            break;
          }
        }
      }
    }
    int ok = (int)klu_l_solve(sym, num, m, nb, B, &kc);
    FMBD_GCHECK(ok && kc.status == KLU_OK, FMBD_ERR_EXTERNAL, "KLU solve failed (status %d)",
                (int)kc.status);
  }
  // --- Z in rows: unit rows for the independent coordinates, -X rows for the dependent ---
  int64_t nnz = n - m;
  for (int64_t q = 0; q < m * nti; q++) nnz += X[q] != 0.0;
  FMBD_GCALL(fmbd_csr_create(n, n - m, nnz, &N->Z));
  {
    fmbd_csr *Z = N->Z;
    int64_t p = 0;
    Z->indptr[0] = 0;
    for (int64_t j = 0; j < n; j++) {
      if (isdep[j] < 0) {
        Z->indices[p] = zcol[j];
        Z->data[p++] = 1.0;
      } else {
        int64_t i = isdep[j];
        for (int64_t k = 0; k < nti; k++) {
          double v = X[i + m * k];
          if (v == 0.0) continue;
          Z->indices[p] = zcol[tind[k]];
          Z->data[p++] = -v;
        }
      }
      Z->indptr[j + 1] = p;
    }
  }
done:
  if (num) klu_l_free_numeric(&num, &kc);
  if (sym) klu_l_free_symbolic(&sym, &kc);
  fmbd_free(colpos);
  fmbd_free(tc);
  fmbd_free(jp);
  fmbd_free(isdep);
  fmbd_free(zcol);
  fmbd_free(tind);
  fmbd_free(A);
  fmbd_free(X);
  fmbd_free(Ap);
  fmbd_free(Ai);
  fmbd_free(Ax);
  if (rc) fmbd_gm_null_free(N);
  return rc;
}

void fmbd_gm_result_free(fmbd_gm_result *res) {
  if (!res) return;
  fmbd_free(res->lambda);
  fmbd_free(res->X);
  fmbd_free(res->resid);
  fmbd_eig_result_free(&res->eig);
  memset(res, 0, sizeof *res);
}

int fmbd_gm_solve(const fmbd_csr *M, const fmbd_csr *K, const fmbd_csr *Cq, const bool *rigid,
                  const fmbd_gm_opts *oin, fmbd_gm_result *res, int64_t *bad_row) {
  int rc = FMBD_OK;
  fmbd_gm_opts o;
  fmbd_gm_null N = {0};
  fmbd_csr *Kr = NULL, *Mr = NULL;
  fmbd_chol *Fs = NULL;
  double *w = NULL;
  if (oin) {
    o = *oin;
  } else {
    fmbd_gm_opts_defaults(&o);
  }
  memset(res, 0, sizeof *res);
  int64_t n = M->nrows, m = Cq->nrows;
  FMBD_CHECK(M->ncols == n && K->nrows == n && K->ncols == n && Cq->ncols == n, FMBD_ERR_VALUE,
             "M, K (%lld x %lld) and Cq (%lld x %lld) do not match", (long long)n,
             (long long)M->ncols, (long long)m, (long long)Cq->ncols);
  FMBD_CHECK(rigid, FMBD_ERR_VALUE, "the unstiffened coordinates are needed (mobility check)");
  res->n = n;
  res->m = m;
  res->mobility = -1;
  // --- null-space basis ---
  double t0 = fmbd_wall_s();
  FMBD_GCALL(fmbd_gm_nullspace(Cq, o.rank_tol, &N, bad_row));
  int64_t nz = res->nz = n - m;
  res->nnz_z = fmbd_csr_nnz(N.Z);
  // mobility: the strain-free motions the constraints allow
  {
    int64_t nr = 0, rk = 0;
    for (int64_t j = 0; j < n; j++) nr += rigid[j];
    FMBD_GCALL(fmbd_gm_rank(Cq, rigid, o.rank_tol, &rk));
    res->mobility = nr - rk;
  }
  res->t_null_s = fmbd_wall_s() - t0;
  fmbd_log(FMBD_LOG_INFO,
           "null space: %lld coordinates, %lld equations (%lld columns touched), Z %lld x %lld "
           "with %lld entries; mobility %lld",
           (long long)n, (long long)m, (long long)N.ntouched, (long long)n, (long long)nz,
           (long long)res->nnz_z, (long long)res->mobility);
  int64_t nflex_all = nz - res->mobility;
  FMBD_GCHECK(nflex_all > 0, FMBD_ERR_VALUE,
              "the mechanism has no flexible mode: its %lld independent coordinates are all "
              "rigid-reference motions (f = %lld)",
              (long long)nz, (long long)res->mobility);
  if (o.lambda_max <= 0.0) {
    FMBD_GCHECK(o.nmodes >= 1 && o.nmodes <= nflex_all, FMBD_ERR_VALUE,
                "%lld flexible modes asked for; the mechanism has %lld (%lld independent "
                "coordinates, f = %lld)",
                (long long)o.nmodes, (long long)nflex_all, (long long)nz, (long long)res->mobility);
  }
  // --- the reduced problem ---
  t0 = fmbd_wall_s();
  FMBD_GCALL(fmbd_csr_ptap(K, N.Z, &Kr));
  FMBD_GCALL(fmbd_csr_ptap(M, N.Z, &Mr));
  res->t_project_s = fmbd_wall_s() - t0;
  double scale = fmbd_eig_spectrum_scale(Kr, Mr);
  res->zero_bound = o.zero_tol * scale;
  fmbd_eig_opts eo;
  fmbd_eig_opts_defaults(&eo);
  eo.free_body = res->mobility > 0;
  eo.dense_max = o.dense_max;
  eo.progress = o.progress;
  eo.progress_ctx = o.progress_ctx;
  if (o.lambda_max > 0.0) {
    eo.lambda_max = o.lambda_max;
    eo.nev = res->mobility + 20;
  } else {
    eo.nev = res->mobility + o.nmodes;
  }
  t0 = fmbd_wall_s();
  bool sparse = !(nz <= eo.dense_max || (o.lambda_max <= 0.0 && eo.nev + 2 >= nz));
  if (sparse && res->mobility > 0) {
    // The shift for the zero modes, from Sturm counts: fmbd_eig's own estimate pass (12 pairs)
    // sees only zeros when f >= 12 and falls back to -1e-6 of the spectrum's scale, far below
    // the soft flexible modes of a long chain (they then cluster with the zeros and Lanczos does
    // not separate them). Here: LDL' inertia counts of Kr - s Mr at s = zero_bound, 10
    // zero_bound, ... until the count exceeds f: the first flexible eigenvalue lies in
    // (s / 10, s]; the shift -s / 20 maps zeros and flexible modes to operator eigenvalues of
    // the same order. The first count is also a Sturm check of f.
    FMBD_GCALL(fmbd_chol_analyze(Kr, Mr, FMBD_CHOL_LDLT, &Fs));
    double sb = res->zero_bound;
    int64_t c = 0;
    for (int it = 0;; it++) {
      FMBD_GCALL(fmbd_chol_factor(Fs, sb));
      c = fmbd_chol_negative_pivots(Fs);
      if (it == 0 && c != res->mobility) {
        FMBD_GFAIL(FMBD_ERR_VALUE,
                   "%lld eigenvalues below %.3g by the Sturm count, but the mobility of the "
                   "mechanism is %lld: the configuration is singular or the model inconsistent",
                   (long long)c, sb, (long long)res->mobility);
      }
      if (c > res->mobility || sb > 10.0 * scale) break;
      sb *= 10.0;
    }
    fmbd_chol_destroy(&Fs);
    double sigma = -sb / 20.0;
    fmbd_log(FMBD_LOG_DEBUG, "gm: first flexible eigenvalue below %.3g (Sturm counts): shift %.3g",
             sb, sigma);
    FMBD_GCALL(fmbd_chol_analyze(Kr, Mr, FMBD_CHOL_LLT, &Fs));
    FMBD_GCALL(fmbd_chol_factor(Fs, sigma));
    {  // the largest array of a large FE mechanism's run (bench/README.md, gmsolve)
      fmbd_chol_stats cs;
      fmbd_chol_get_stats(Fs, &cs);
      fmbd_log(FMBD_LOG_DEBUG, "gm: shift-invert factor of order %lld, %.4g entries in L (%s)",
               (long long)cs.n, cs.nnz_l, cs.ordering);
    }
    eo.free_body = false;  // the factor handed over is at a shift below every eigenvalue
  }
  rc = fmbd_eig_solve(Kr, Mr, Fs, &eo, &res->eig);
  if (rc == FMBD_ERR_SINGULAR) {
    char msg[1100];
    snprintf(msg, sizeof msg, "%s", fmbd_err_get()->msg);
    FMBD_GFAIL(rc,
               "the mass matrix on the constraints' null space is not positive definite (%s): a "
               "body's inertia invariants disagree with its modal mass (e.g. lumped-mass "
               "invariants of a beam with a nearly complete modal basis)",
               msg);
  }
  FMBD_GCALL(rc);
  res->t_eig_s = fmbd_wall_s() - t0;
  int64_t ne = res->eig.nev;
  int64_t f = 0;
  while (f < ne && res->eig.lambda[f] <= res->zero_bound) f++;
  res->f = f;
  FMBD_GCHECK(f == res->mobility, FMBD_ERR_VALUE,
              "%lld zero-frequency modes found (eigenvalues below %.3g; the next at %.3g), but the "
              "mobility of the mechanism is %lld: the configuration is singular or the model "
              "inconsistent",
              (long long)f, res->zero_bound, f < ne ? res->eig.lambda[f] : NAN,
              (long long)res->mobility);
  res->nflex = ne - f;
  FMBD_GCHECK(res->nflex > 0, FMBD_ERR_VALUE,
              "no flexible mode below the bound (the first is at %.6g rad^2/s^2)",
              res->eig.next_lambda);
  res->next_lambda = res->eig.next_lambda;
  // --- back to the mechanism's coordinates ---
  FMBD_GALLOC(res->X = fmbd_calloc((size_t)(n * ne + 1), sizeof(double)));
  fmbd_csr_matmat(N.Z, ne, res->eig.X, nz, res->X, n);
  res->lambda = res->eig.lambda;
  res->resid = res->eig.resid;
  res->eig.lambda = NULL;
  res->eig.resid = NULL;
  fmbd_free(res->eig.X);
  res->eig.X = NULL;
  {  // Cq X = 0 up to round-off
    double cn = 0.0;
    for (int64_t p = 0; p < fmbd_csr_nnz(Cq); p++) cn += Cq->data[p] * Cq->data[p];
    cn = sqrt(cn);
    FMBD_GALLOC(w = fmbd_malloc(sizeof(double) * (size_t)(m + 1)));
    for (int64_t k = 0; k < ne; k++) {
      const double *x = res->X + n * k;
      double xn = 0.0, r = 0.0;
      for (int64_t i = 0; i < n; i++) xn += x[i] * x[i];
      fmbd_csr_matvec(Cq, x, w);
      for (int64_t i = 0; i < m; i++) r += w[i] * w[i];
      double q = cn > 0 && xn > 0 ? sqrt(r) / (cn * sqrt(xn)) : 0.0;
      if (q > res->cq_resid) res->cq_resid = q;
    }
  }
done:
  fmbd_gm_null_free(&N);
  fmbd_chol_destroy(&Fs);
  fmbd_csr_destroy(&Kr);
  fmbd_csr_destroy(&Mr);
  fmbd_free(w);
  if (rc) {
    int64_t keep_mob = res->mobility, keep_nz = res->nz;
    fmbd_gm_result_free(res);
    res->mobility = keep_mob;
    res->nz = keep_nz;
  }
  return rc;
}

void fmbd_gm_participation(const fmbd_csr *M, int64_t nk, const double *X, const double *rt,
                           double *P) {
  int64_t n = M->nrows;
  double *Mr = fmbd_malloc(sizeof(double) * (size_t)(n + 1));
  if (!Mr) {
    for (int64_t q = 0; q < 3 * nk; q++) P[q] = NAN;
    return;
  }
  for (int a = 0; a < 3; a++) {
    const double *r = rt + n * a;
    fmbd_csr_matvec(M, r, Mr);
    double tot = 0.0;
    for (int64_t i = 0; i < n; i++) tot += r[i] * Mr[i];
    for (int64_t k = 0; k < nk; k++) {
      double g = 0.0;
      for (int64_t i = 0; i < n; i++) g += X[i + n * k] * Mr[i];
      P[k + nk * a] = tot > 0.0 ? g * g / tot : 0.0;
    }
  }
  fmbd_free(Mr);
}

int fmbd_gm_gmc(int64_t nq, int64_t nk, const double *Q, const fmbd_csr *W, double tol, double *B,
                int64_t *keep, int64_t *nkeep) {
  int rc = FMBD_OK;
  double *O = NULL, *WO = NULL, *v = NULL, *wv = NULL;
  *nkeep = 0;
  FMBD_CHECK(!W || (W->nrows == nq && W->ncols == nq), FMBD_ERR_VALUE,
             "GMc: the metric is %lld x %lld for %lld coordinates", (long long)(W ? W->nrows : 0),
             (long long)(W ? W->ncols : 0), (long long)nq);
  FMBD_GALLOC(O = fmbd_malloc(sizeof(double) * (size_t)(nq * nk + 1)));   // orthonormal kept
  FMBD_GALLOC(WO = fmbd_malloc(sizeof(double) * (size_t)(nq * nk + 1)));  // W times them
  FMBD_GALLOC(v = fmbd_malloc(sizeof(double) * (size_t)(nq + 1)));
  FMBD_GALLOC(wv = fmbd_malloc(sizeof(double) * (size_t)(nq + 1)));
#define WMUL(x, y)                                   \
  do {                                               \
    if (W) {                                         \
      fmbd_csr_matvec(W, (x), (y));                  \
    } else {                                         \
      memcpy((y), (x), sizeof(double) * (size_t)nq); \
    }                                                \
  } while (0)
  double big = 0.0;
  for (int64_t k = 0; k < nk; k++) {
    WMUL(Q + nq * k, wv);
    double s = 0.0;
    for (int64_t i = 0; i < nq; i++) s += Q[i + nq * k] * wv[i];
    big = fmax(big, sqrt(fmax(s, 0.0)));
  }
  int64_t nkp = 0;
  for (int64_t k = 0; k < nk; k++) {
    const double *q = Q + nq * k;
    WMUL(q, wv);
    double n0 = 0.0;
    for (int64_t i = 0; i < nq; i++) n0 += q[i] * wv[i];
    n0 = sqrt(fmax(n0, 0.0));
    if (!(n0 > tol * big) || n0 == 0.0) continue;
    memcpy(v, q, sizeof(double) * (size_t)nq);
    for (int pass = 0; pass < 2; pass++) {  // Gram-Schmidt twice (Kahan: enough)
      for (int64_t j = 0; j < nkp; j++) {
        double c = 0.0;
        for (int64_t i = 0; i < nq; i++) c += WO[i + nq * j] * v[i];
        for (int64_t i = 0; i < nq; i++) v[i] -= c * O[i + nq * j];
      }
    }
    WMUL(v, wv);
    double n1 = 0.0;
    for (int64_t i = 0; i < nq; i++) n1 += v[i] * wv[i];
    n1 = sqrt(fmax(n1, 0.0));
    if (!(n1 > tol * n0)) continue;
    for (int64_t i = 0; i < nq; i++) {
      O[i + nq * nkp] = v[i] / n1;
      WO[i + nq * nkp] = wv[i] / n1;
      B[i + nq * nkp] = v[i] / n1;  // orthonormal in W: the same span, Mff = I
    }
    keep[nkp++] = k;
  }
#undef WMUL
  *nkeep = nkp;
done:
  fmbd_free(O);
  fmbd_free(WO);
  fmbd_free(v);
  fmbd_free(wv);
  return rc;
}
