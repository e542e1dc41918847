// common/fmbd_est.c: a posteriori relative eigenvalue error estimates (docs/THEORY.md section 2)
// SPDX-License-Identifier: MIT
#include "fmbd_est.h"

#include <float.h>
#include <math.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_log.h"

struct fmbd_est {
  int64_t nb, npool, nd;
  fmbd_est_opts opt;
  double *Mbb, *Kbb;  // nb x nb
  double *kappa;      // npool
  double *PhitA;      // npool x nb (column-major, leading dimension npool)
  double *Xb, *Gb;    // current, nb x nb
  double kappa_next;  // kappa_(npool+1) or NAN
};

void fmbd_est_opts_defaults(fmbd_est_opts *o) {
  o->rigid_rtol = 1e-6;
  o->cluster_rtol = 1e-3;
  o->cluster_overlap = true;
}

static void symmetrize(int64_t n, double *X) {
  for (int64_t j = 0; j < n; j++) {
    for (int64_t i = j + 1; i < n; i++) {
      double v = 0.5 * (X[i + n * j] + X[j + n * i]);
      X[i + n * j] = X[j + n * i] = v;
    }
  }
}

// X -= sum_k w_k p_k' p_k over the npool rows of P (npool x nb), w_k = kappa_k^-pw
static int subtract_modal(int64_t nb, int64_t npool, const double *kappa, const double *P, int pw,
                          double *X) {
  if (npool == 0 || nb == 0) {
    return FMBD_OK;
  }
  double *S = fmbd_malloc(sizeof(double) * (size_t)(npool * nb));
  if (!S) {
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  for (int64_t j = 0; j < nb; j++) {
    for (int64_t k = 0; k < npool; k++) {
      S[k + npool * j] = P[k + npool * j] / (pw == 1 ? kappa[k] : kappa[k] * kappa[k]);
    }
  }
  fmbd_dense_gemm('T', 'N', nb, nb, npool, -1.0, P, npool, S, npool, 1.0, X, nb);
  fmbd_free(S);
  return FMBD_OK;
}

int fmbd_est_base_plain(int64_t ns, int64_t nb, int64_t npool, const double *A,
                        const double *KsinvA, const double *KsinvMsKsinvA, const double *kappa,
                        const double *PhitA, double *Xb, double *Gb, double *noise) {
  FMBD_CHECK(ns >= 0 && nb >= 0 && npool >= 0, FMBD_ERR_VALUE, "negative sizes");
  for (int64_t k = 0; k < npool; k++) {
    FMBD_CHECK(kappa[k] > 0, FMBD_ERR_VALUE, "fixed-interface eigenvalue %lld is %g, not positive",
               (long long)k + 1, kappa[k]);
  }
  fmbd_dense_gemm('T', 'N', nb, nb, ns, 1.0, A, ns, KsinvA, ns, 0.0, Xb, nb);
  if (noise) {
    // A' Ks^-1 A is symmetric: its computed asymmetry measures the error of the solves
    double asym = 0, big = 0;
    for (int64_t j = 0; j < nb; j++) {
      for (int64_t i = 0; i < nb; i++) {
        asym = fmax(asym, fabs(Xb[i + nb * j] - Xb[j + nb * i]));
        big = fmax(big, fabs(Xb[i + nb * j]));
      }
    }
    *noise = asym + 64 * DBL_EPSILON * big;
  }
  symmetrize(nb, Xb);
  FMBD_CALL(subtract_modal(nb, npool, kappa, PhitA, 1, Xb));
  if (KsinvMsKsinvA) {
    fmbd_dense_gemm('T', 'N', nb, nb, ns, 1.0, A, ns, KsinvMsKsinvA, ns, 0.0, Gb, nb);
    symmetrize(nb, Gb);
    FMBD_CALL(subtract_modal(nb, npool, kappa, PhitA, 2, Gb));
  } else {
    memset(Gb, 0, sizeof(double) * (size_t)(nb * nb));
  }
  return FMBD_OK;
}

// Y (ns x nb) = Ks X for X (ns x nb): K X0 restricted to the interior rows (X0 = X scattered to
// the interior rows of an n x nb block Z that is zero elsewhere); Z, KZ are n x nb scratch. With
// M (not NULL), also V = Ms X, in the same pass over the pattern when K and M share it
// (fmbd_csr_matmat_pair); MZ is then n x nb scratch too.
static void interior_matmat(const fmbd_csr *K, const fmbd_csr *M, int64_t ns,
                            const int64_t *interior, int64_t nb, const double *X, double *Y,
                            double *V, double *Z, double *KZ, double *MZ) {
  if (!interior) {
    if (M)
      fmbd_csr_matmat_pair(K, M, nb, X, ns, Y, V, ns);
    else
      fmbd_csr_matmat(K, nb, X, ns, Y, ns);
    return;
  }
  int64_t n = K->nrows;
  memset(Z, 0, sizeof(double) * (size_t)(n * nb));
  for (int64_t j = 0; j < nb; j++) {
    for (int64_t i = 0; i < ns; i++) {
      Z[interior[i] + n * j] = X[i + ns * j];
    }
  }
  if (M)
    fmbd_csr_matmat_pair(K, M, nb, Z, n, KZ, MZ, n);
  else
    fmbd_csr_matmat(K, nb, Z, n, KZ, n);
  for (int64_t j = 0; j < nb; j++) {
    for (int64_t i = 0; i < ns; i++) {
      Y[i + ns * j] = KZ[interior[i] + n * j];
      if (M) V[i + ns * j] = MZ[interior[i] + n * j];
    }
  }
}

int fmbd_est_base_projected(const fmbd_csr *K, const fmbd_csr *M, int64_t ns,
                            const int64_t *interior, int64_t nb, int64_t npool, const double *A,
                            const double *KsinvA, const double *Phi, const double *kappa,
                            const double *PhitA, double *Xb, double *Gb) {
  int rc = FMBD_OK;
  int64_t n = K->nrows;
  double *W = NULL, *C = NULL, *Y = NULL, *V = NULL, *Z = NULL, *KZ = NULL, *MZ = NULL;
  FMBD_GCHECK(K->ncols == n && M->nrows == n && M->ncols == n && (interior ? ns <= n : ns == n),
              FMBD_ERR_VALUE, "K and M must be square of the same order, with %lld interior rows",
              (long long)ns);
  for (int64_t k = 0; k < npool; k++) {
    FMBD_GCHECK(kappa[k] > 0, FMBD_ERR_VALUE, "fixed-interface eigenvalue %lld is %g, not positive",
                (long long)k + 1, kappa[k]);
  }
  size_t nsb = (size_t)(ns * nb) + 1, nb_n = interior ? (size_t)(n * nb) + 1 : 1;
  FMBD_GALLOC(W = fmbd_malloc(sizeof(double) * nsb));
  FMBD_GALLOC(Y = fmbd_malloc(sizeof(double) * nsb));
  FMBD_GALLOC(V = fmbd_malloc(sizeof(double) * nsb));
  FMBD_GALLOC(Z = fmbd_malloc(sizeof(double) * nb_n));
  FMBD_GALLOC(KZ = fmbd_malloc(sizeof(double) * nb_n));
  FMBD_GALLOC(MZ = fmbd_malloc(sizeof(double) * nb_n));
  FMBD_GALLOC(C = fmbd_malloc(sizeof(double) * (size_t)(npool * nb + 1)));
  memcpy(W, KsinvA, sizeof(double) * (nsb - 1));
  // W = Ks^-1 A - Phi Lambda^-1 PhitA
  for (int64_t j = 0; j < nb; j++) {
    for (int64_t k = 0; k < npool; k++) {
      C[k + npool * j] = PhitA[k + npool * j] / kappa[k];
    }
  }
  fmbd_dense_gemm('N', 'N', ns, nb, npool, -1.0, Phi, ns, C, npool, 1.0, W, ns);
  // W -= Phi (Phi' Ms W), twice (classical Gram-Schmidt, reorthogonalised)
  for (int pass = 0; pass < 2 && npool > 0; pass++) {
    interior_matmat(M, NULL, ns, interior, nb, W, Y, NULL, Z, KZ, NULL);
    fmbd_dense_gemm('T', 'N', npool, nb, ns, 1.0, Phi, ns, Y, ns, 0.0, C, npool);
    fmbd_dense_gemm('N', 'N', ns, nb, npool, -1.0, Phi, ns, C, npool, 1.0, W, ns);
  }
  // Ks W and Ms W in one pass over the pattern that K and M share (an fe file's, read once)
  interior_matmat(K, M, ns, interior, nb, W, Y, V, Z, KZ, MZ);
  fmbd_dense_gemm('T', 'N', nb, nb, ns, 1.0, W, ns, Y, ns, 0.0, Xb, nb);
  symmetrize(nb, Xb);
  fmbd_dense_gemm('T', 'N', nb, nb, ns, 1.0, W, ns, V, ns, 0.0, Gb, nb);
  symmetrize(nb, Gb);
done:
  fmbd_free(W);
  fmbd_free(Y);
  fmbd_free(V);
  fmbd_free(Z);
  fmbd_free(KZ);
  fmbd_free(MZ);
  fmbd_free(C);
  return rc;
}

int fmbd_est_create(int64_t nb, const double *Mbb, const double *Kbb, const fmbd_est_opts *opt,
                    fmbd_est **out) {
  int rc = FMBD_OK;
  *out = NULL;
  FMBD_CHECK(nb >= 0, FMBD_ERR_VALUE, "negative number of boundary dofs");
  fmbd_est *e = fmbd_calloc(1, sizeof(*e));
  FMBD_CHECK(e, FMBD_ERR_NOMEM, "out of memory");
  e->nb = nb;
  e->kappa_next = NAN;
  if (opt) {
    e->opt = *opt;
  } else {
    fmbd_est_opts_defaults(&e->opt);
  }
  size_t nn = (size_t)(nb * nb) + 1;
  FMBD_GALLOC(e->Mbb = fmbd_malloc(sizeof(double) * nn));
  FMBD_GALLOC(e->Kbb = fmbd_malloc(sizeof(double) * nn));
  FMBD_GALLOC(e->Xb = fmbd_calloc(nn, sizeof(double)));
  FMBD_GALLOC(e->Gb = fmbd_calloc(nn, sizeof(double)));
  FMBD_GALLOC(e->kappa = fmbd_malloc(sizeof(double)));
  FMBD_GALLOC(e->PhitA = fmbd_malloc(sizeof(double)));
  if (nb > 0) {
    memcpy(e->Mbb, Mbb, sizeof(double) * (nn - 1));
    memcpy(e->Kbb, Kbb, sizeof(double) * (nn - 1));
  }
  *out = e;
  e = NULL;
done:
  fmbd_est_destroy(&e);
  return rc;
}

void fmbd_est_destroy(fmbd_est **pe) {
  if (!pe || !*pe) {
    return;
  }
  fmbd_est *e = *pe;
  fmbd_free(e->Mbb);
  fmbd_free(e->Kbb);
  fmbd_free(e->kappa);
  fmbd_free(e->PhitA);
  fmbd_free(e->Xb);
  fmbd_free(e->Gb);
  fmbd_free(e);
  *pe = NULL;
}

int fmbd_est_set_pool(fmbd_est *e, int64_t npool, const double *kappa, const double *PhitA,
                      const double *Xb, const double *Gb) {
  FMBD_CHECK(npool >= 0, FMBD_ERR_VALUE, "negative pool size");
  for (int64_t k = 0; k < npool; k++) {
    FMBD_CHECK(kappa[k] > 0 && isfinite(kappa[k]), FMBD_ERR_VALUE,
               "fixed-interface eigenvalue %lld is %g, not positive", (long long)k + 1, kappa[k]);
    FMBD_CHECK(k == 0 || kappa[k] >= kappa[k - 1], FMBD_ERR_VALUE,
               "fixed-interface eigenvalues not ascending at %lld", (long long)k + 1);
  }
  double *kp = fmbd_malloc(sizeof(double) * (size_t)(npool + 1));
  double *pa = fmbd_malloc(sizeof(double) * (size_t)(npool * e->nb + 1));
  if (!kp || !pa) {
    fmbd_free(kp);
    fmbd_free(pa);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  if (npool > 0) {
    memcpy(kp, kappa, sizeof(double) * (size_t)npool);
  }
  if (npool > 0 && e->nb > 0) {
    memcpy(pa, PhitA, sizeof(double) * (size_t)(npool * e->nb));
  }
  fmbd_free(e->kappa);
  fmbd_free(e->PhitA);
  e->kappa = kp;
  e->PhitA = pa;
  e->npool = npool;
  e->nd = npool;
  e->kappa_next = NAN;
  if (e->nb > 0) {
    memcpy(e->Xb, Xb, sizeof(double) * (size_t)(e->nb * e->nb));
    memcpy(e->Gb, Gb, sizeof(double) * (size_t)(e->nb * e->nb));
  }
  return FMBD_OK;
}

// X += s * w p' p for mode k (row k of PhitA), w = kappa^-1 (Xb) or kappa^-2 (Gb)
static void rank_one(fmbd_est *e, int64_t k, double s) {
  int64_t nb = e->nb, np = e->npool;
  double w1 = s / e->kappa[k], w2 = s / (e->kappa[k] * e->kappa[k]);
  for (int64_t j = 0; j < nb; j++) {
    double pj = e->PhitA[k + np * j];
    for (int64_t i = 0; i < nb; i++) {
      double pp = e->PhitA[k + np * i] * pj;
      e->Xb[i + nb * j] += w1 * pp;
      e->Gb[i + nb * j] += w2 * pp;
    }
  }
}

int fmbd_est_set_nd(fmbd_est *e, int64_t nd) {
  FMBD_CHECK(nd >= 0 && nd <= e->npool, FMBD_ERR_VALUE,
             "%lld dominant modes asked, %lld fixed-interface modes known", (long long)nd,
             (long long)e->npool);
  // add modes: Xb(nd+1) = Xb(nd) - p' p / kappa (downdate); remove: the update
  while (e->nd < nd) {
    rank_one(e, e->nd, -1.0);
    e->nd++;
  }
  while (e->nd > nd) {
    e->nd--;
    rank_one(e, e->nd, +1.0);
  }
  return FMBD_OK;
}

int64_t fmbd_est_nd(const fmbd_est *e) {
  return e->nd;
}
int64_t fmbd_est_npool(const fmbd_est *e) {
  return e->npool;
}
int64_t fmbd_est_nb(const fmbd_est *e) {
  return e->nb;
}
const double *fmbd_est_xb(const fmbd_est *e) {
  return e->Xb;
}
const double *fmbd_est_gb(const fmbd_est *e) {
  return e->Gb;
}
bool fmbd_est_knext_known(const fmbd_est *e) {
  return e->nd < e->npool || (e->nd == e->npool && isfinite(e->kappa_next));
}
void fmbd_est_set_kappa_next(fmbd_est *e, double kappa_next) {
  e->kappa_next = kappa_next;
}

int fmbd_est_solve(fmbd_est *e, double *chibar, double *Xi) {
  int rc = FMBD_OK;
  int64_t nd = e->nd, nb = e->nb, n = nd + nb, np = e->npool;
  double *Mr = NULL;
  if (n == 0) {
    return FMBD_OK;
  }
  FMBD_GALLOC(Mr = fmbd_calloc((size_t)(n * n), sizeof(double)));
  memset(Xi, 0, sizeof(double) * (size_t)(n * n));
  for (int64_t k = 0; k < nd; k++) {
    Mr[k + n * k] = 1.0;
    Xi[k + n * k] = e->kappa[k];
  }
  for (int64_t j = 0; j < nb; j++) {
    for (int64_t k = 0; k < nd; k++) {
      Mr[k + n * (nd + j)] = Mr[(nd + j) + n * k] = e->PhitA[k + np * j];
    }
    for (int64_t i = 0; i < nb; i++) {
      Mr[(nd + i) + n * (nd + j)] = e->Mbb[i + nb * j];
      Xi[(nd + i) + n * (nd + j)] = e->Kbb[i + nb * j];
    }
  }
  FMBD_GCALL(fmbd_dense_sygv(n, Xi, Mr, chibar));
done:
  fmbd_free(Mr);
  return rc;
}

int fmbd_est_modes_alloc(int64_t n, fmbd_est_modes *m) {
  memset(m, 0, sizeof(*m));
  size_t nn = (size_t)(n > 0 ? n : 1);
  m->chibar = fmbd_calloc(nn, sizeof(double));
  m->rigid = fmbd_calloc(nn, sizeof(bool));
  m->cluster = fmbd_calloc(nn, sizeof(int64_t));
  m->lower = fmbd_calloc(nn, sizeof(double));
  m->second = fmbd_calloc(nn, sizeof(double));
  m->upper = fmbd_calloc(nn, sizeof(double));
  m->upper_next = fmbd_calloc(nn, sizeof(double));
  m->x = fmbd_calloc(nn, sizeof(double));
  m->g = fmbd_calloc(nn, sizeof(double));
  if (!m->chibar || !m->rigid || !m->cluster || !m->lower || !m->second || !m->upper ||
      !m->upper_next || !m->x || !m->g) {
    fmbd_est_modes_free(m);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  m->nmodes = n;
  return FMBD_OK;
}

void fmbd_est_modes_free(fmbd_est_modes *m) {
  if (!m) {
    return;
  }
  fmbd_free(m->chibar);
  fmbd_free(m->rigid);
  fmbd_free(m->cluster);
  fmbd_free(m->lower);
  fmbd_free(m->second);
  fmbd_free(m->upper);
  fmbd_free(m->upper_next);
  fmbd_free(m->x);
  fmbd_free(m->g);
  memset(m, 0, sizeof(*m));
}

// b' X b for the nb-vector b
static double quad(int64_t nb, const double *X, const double *b) {
  double s = 0;
  for (int64_t j = 0; j < nb; j++) {
    double t = 0;
    for (int64_t i = 0; i < nb; i++) {
      t += X[i + nb * j] * b[i];
    }
    s += t * b[j];
  }
  return s;
}

int fmbd_est_estimate(const fmbd_est *e, const double *chibar, const double *Xi, int64_t ldxi,
                      fmbd_est_modes *m) {
  int64_t nd = e->nd, nb = e->nb, nm = m->nmodes;
  FMBD_CHECK(ldxi >= nd + nb, FMBD_ERR_VALUE, "eigenvector leading dimension %lld < %lld",
             (long long)ldxi, (long long)(nd + nb));
  // scale of the spectrum for the rigid-body test: kappa_1, else the largest |chibar|
  double scale = 0;
  if (e->npool > 0) {
    scale = e->kappa[0];
  } else {
    for (int64_t n = 0; n < nm; n++) {
      scale = fmax(scale, fabs(chibar[n]));
    }
  }
  // kappa_(nd+1); unknown: kappa_nd (smaller, so the estimate stays above [H36])
  double knext = e->npool > nd             ? e->kappa[nd]
                 : isfinite(e->kappa_next) ? e->kappa_next
                 : nd > 0                  ? e->kappa[nd - 1]
                                           : INFINITY;
  for (int64_t n = 0; n < nm; n++) {
    double c = chibar[n];
    const double *b = Xi + ldxi * n + nd;
    m->chibar[n] = c;
    m->rigid[n] = fabs(c) <= e->opt.rigid_rtol * scale;
    m->cluster[n] = n;
    if (m->rigid[n]) {
      m->x[n] = m->g[n] = m->lower[n] = m->second[n] = m->upper[n] = m->upper_next[n] = 0;
      continue;
    }
    double x = quad(nb, e->Xb, b), g = quad(nb, e->Gb, b);
    // kappa_n: n counts the rigid-body modes (docs/THEORY.md section 8); kappa_n must be among the
    // dominant eigenvalues [H37] (n <= nd), so modes beyond nd take kappa_nd, the largest
    // dominant one (smaller than kappa_(nd+1): a larger, conservative estimate)
    double kn = n < nd ? e->kappa[n] : (nd > 0 ? e->kappa[nd - 1] : knext);
    m->x[n] = x;
    m->g[n] = g;
    m->lower[n] = c * x;                         // [H45]
    m->second[n] = c * x + c * c * g;            // [H36]
    m->upper[n] = (c + c * c / kn) * x;          // [H42]
    m->upper_next[n] = (c + c * c / knext) * x;  // [H38] with kappa_(nd+1)
  }
  // clusters: consecutive flexible modes within cluster_rtol (repeated eigenvalues), or whose
  // uncertainty intervals [chibar / (1 + upper), chibar] overlap: the full body's eigenvalues
  // of such modes may come in another order, so a per-mode value would be arbitrary
  int64_t n = 0;
  while (n < nm) {
    if (m->rigid[n]) {
      n++;
      continue;
    }
    int64_t last = n;
    while (last + 1 < nm && !m->rigid[last + 1]) {
      double c1 = chibar[last + 1], gap = fabs(c1 - chibar[last]);
      double unc = c1 - c1 / (1 + fmax(m->upper[last + 1], 0));  // before the clusters' max
      if (!(gap <= e->opt.cluster_rtol * fabs(c1) || (e->opt.cluster_overlap && gap <= unc))) {
        break;
      }
      last++;
    }
    if (last > n) {
      double lo = INFINITY, se = -INFINITY, up = -INFINITY, un = -INFINITY;
      for (int64_t k = n; k <= last; k++) {
        lo = fmin(lo, m->lower[k]);
        se = fmax(se, m->second[k]);
        up = fmax(up, m->upper[k]);
        un = fmax(un, m->upper_next[k]);
      }
      for (int64_t k = n; k <= last; k++) {
        m->cluster[k] = n;
        m->lower[k] = lo;
        m->second[k] = se;
        m->upper[k] = up;
        m->upper_next[k] = un;
      }
    }
    n = last + 1;
  }
  return FMBD_OK;
}

int fmbd_est_run(fmbd_est *e, fmbd_est_modes *m, double *Xi) {
  int rc = FMBD_OK;
  int64_t n = e->nd + e->nb;
  double *chib = NULL, *X = Xi;
  fmbd_est_modes_free(m);
  FMBD_GALLOC(chib = fmbd_malloc(sizeof(double) * (size_t)(n + 1)));
  if (!X) {
    FMBD_GALLOC(X = fmbd_malloc(sizeof(double) * (size_t)(n * n + 1)));
  }
  FMBD_GCALL(fmbd_est_solve(e, chib, X));
  FMBD_GCALL(fmbd_est_modes_alloc(n, m));
  FMBD_GCALL(fmbd_est_estimate(e, chib, X, n, m));
done:
  fmbd_free(chib);
  if (X != Xi) {
    fmbd_free(X);
  }
  return rc;
}

double fmbd_est_pick(const fmbd_est_modes *m, int which, int64_t n) {
  switch (which) {
    case FMBD_EST_UPPER_NEXT:
      return m->upper_next[n];
    case FMBD_EST_SECOND:
      return m->second[n];
    case FMBD_EST_LOWER:
      return m->lower[n];
    default:
      return m->upper[n];
  }
}

static const char *const which_word[4] = {"upper", "upper-next", "second", "lower"};
static const char *const which_label[4] = {"upper (kappa_n)", "upper (kappa_(Nd+1))",
                                           "second order", "lower"};

const char *fmbd_est_which_word(int which) {
  return which >= 0 && which < 4 ? which_word[which] : "?";
}

const char *fmbd_est_which_label(int which) {
  return which >= 0 && which < 4 ? which_label[which] : "?";
}

int fmbd_est_which_parse(const char *word, int *which) {
  for (int k = 0; k < 4; k++) {
    if (!strcmp(word, which_word[k])) {
      *which = k;
      return 0;
    }
  }
  return -1;
}

// estimate of flexible mode j (1-based) of m, INFINITY if the body has fewer flexible modes
static double flex_estimate(const fmbd_est_modes *m, int which, int64_t j) {
  int64_t seen = 0;
  for (int64_t n = 0; n < m->nmodes; n++) {
    if (!m->rigid[n] && ++seen == j) {
      return fmbd_est_pick(m, which, n);
    }
  }
  return INFINITY;
}

int fmbd_est_select(fmbd_est *e, const fmbd_est_select_opts *o, fmbd_est_extend_fn extend,
                    void *ctx, fmbd_est_select_result *res) {
  int rc = FMBD_OK;
  fmbd_est_modes m = {0};
  memset(res, 0, sizeof(*res));
  res->best_largest = INFINITY;
  res->best_nd = -1;
  FMBD_CHECK(o->tol > 0 && o->nm >= 1 && o->n0 >= 0, FMBD_ERR_VALUE,
             "selection needs tol > 0, nm >= 1, n0 >= 0 (got %g, %lld, %lld)", o->tol,
             (long long)o->nm, (long long)o->n0);
  int64_t cap = 16;
  FMBD_CHECK(res->log = fmbd_malloc(sizeof(fmbd_est_iter) * (size_t)cap), FMBD_ERR_NOMEM,
             "out of memory");
  int64_t nd = o->n0, nfirst = 1;
  for (;;) {
    if (nd > o->nd_max || (nd > e->npool && !extend)) {
      res->reached = false;
      res->nd = nd - 1;
      break;
    }
    if (nd > e->npool) {
      FMBD_GCALL(extend(ctx, e, nd));
      res->nextend++;
      FMBD_GCHECK(e->npool >= nd, FMBD_ERR_INTERNAL, "the pool did not grow to %lld modes",
                  (long long)nd);
    }
    FMBD_GCALL(fmbd_est_set_nd(e, nd));
    FMBD_GCALL(fmbd_est_run(e, &m, NULL));
    double largest = 0;
    int64_t ff = 0, ffall = 0;
    for (int64_t j = 1; j <= o->nm; j++) {
      double v = flex_estimate(&m, o->which, j);
      largest = fmax(largest, v);
      if (!(v <= o->tol)) {
        if (!ffall) {
          ffall = j;
        }
        if (!ff && j >= nfirst) {
          ff = j;
        }
      }
    }
    if (!ff && ffall) {  // the final pass over 1..nm found a mode that got worse
      ff = ffall;
    }
    if (res->niter == cap) {
      cap *= 2;
      fmbd_est_iter *nl = fmbd_realloc(res->log, sizeof(fmbd_est_iter) * (size_t)cap);
      FMBD_GCHECK(nl, FMBD_ERR_NOMEM, "out of memory");
      res->log = nl;
    }
    res->log[res->niter++] = (fmbd_est_iter){nd, ff, largest};
    if (largest < res->best_largest) {
      res->best_largest = largest;
      res->best_nd = nd;
    }
    fmbd_progress("selection: Nd = %lld, first failing mode %lld, largest estimate %.3g",
                  (long long)nd, (long long)ff, largest);
    if (!ff) {
      res->reached = true;
      res->nd = nd;
      break;
    }
    nfirst = ff;
    nd++;
  }
  fmbd_progress(NULL);
  if (!res->reached && res->best_nd >= 0) {
    FMBD_GCALL(fmbd_est_set_nd(e, res->best_nd));
  }
done:
  fmbd_est_modes_free(&m);
  return rc;
}

// --- bodies held at some boundary dofs (docs/THEORY.md section 12) -----------------------------
// The held problem is the CB body with the held boundary dofs removed: its estimator is the same
// one over the free boundary dofs F, with the F rows and columns of Mbb, Kbb, Xb, Gb and the F
// columns of PhitA (Frs, hence Xb and Gb, do not depend on the boundary set).
static void take_sub(int64_t n, const double *X, int64_t nf, const int64_t *f, double *Y) {
  for (int64_t j = 0; j < nf; j++) {
    for (int64_t i = 0; i < nf; i++) Y[i + nf * j] = X[f[i] + n * f[j]];
  }
}

int fmbd_est_set_pool_subset(fmbd_est *sub, const fmbd_est *full, int64_t nfree,
                             const int64_t *free_idx) {
  int rc = FMBD_OK;
  double *pa = NULL, *xb = NULL, *gb = NULL;
  FMBD_CHECK(sub->nb == nfree && full->nd == full->npool, FMBD_ERR_INTERNAL,
             "subset estimator: sizes or state do not match");
  int64_t np = full->npool, nb = full->nb;
  FMBD_GALLOC(pa = fmbd_malloc(sizeof(double) * (size_t)(np * nfree + 1)));
  FMBD_GALLOC(xb = fmbd_malloc(sizeof(double) * (size_t)(nfree * nfree + 1)));
  FMBD_GALLOC(gb = fmbd_malloc(sizeof(double) * (size_t)(nfree * nfree + 1)));
  for (int64_t j = 0; j < nfree; j++) {
    FMBD_GCHECK(free_idx[j] >= 0 && free_idx[j] < nb, FMBD_ERR_VALUE, "free boundary index %lld",
                (long long)free_idx[j]);
    if (np > 0) memcpy(pa + np * j, full->PhitA + np * free_idx[j], sizeof(double) * (size_t)np);
  }
  take_sub(nb, full->Xb, nfree, free_idx, xb);
  take_sub(nb, full->Gb, nfree, free_idx, gb);
  FMBD_GCALL(fmbd_est_set_pool(sub, np, full->kappa, pa, xb, gb));
  fmbd_est_set_kappa_next(sub, full->kappa_next);
done:
  fmbd_free(pa);
  fmbd_free(xb);
  fmbd_free(gb);
  return rc;
}

int fmbd_est_create_subset(const fmbd_est *full, int64_t nfree, const int64_t *free_idx,
                           fmbd_est **out) {
  int rc = FMBD_OK;
  double *mbb = NULL, *kbb = NULL;
  *out = NULL;
  FMBD_GALLOC(mbb = fmbd_malloc(sizeof(double) * (size_t)(nfree * nfree + 1)));
  FMBD_GALLOC(kbb = fmbd_malloc(sizeof(double) * (size_t)(nfree * nfree + 1)));
  take_sub(full->nb, full->Mbb, nfree, free_idx, mbb);
  take_sub(full->nb, full->Kbb, nfree, free_idx, kbb);
  FMBD_GCALL(fmbd_est_create(nfree, mbb, kbb, &full->opt, out));
  rc = fmbd_est_set_pool_subset(*out, full, nfree, free_idx);
  if (rc) fmbd_est_destroy(out);
done:
  fmbd_free(mbb);
  fmbd_free(kbb);
  return rc;
}

int fmbd_est_held_modes(const fmbd_est *full, int64_t nheld, const int64_t *held, int64_t nm,
                        const double *XiF, int64_t ldxi, int64_t *nout, double **chibar,
                        double **Xi) {
  int rc = FMBD_OK;
  int64_t nd = full->nd, nb = full->nb, np = full->npool, n = nd + nb, k = nm + nheld;
  double *Mr = NULL, *Kr = NULL, *V = NULL, *W = NULL, *Mv = NULL, *Kv = NULL, *w = NULL;
  bool *is_held = NULL;
  *nout = 0;
  *chibar = *Xi = NULL;
  FMBD_CHECK(nheld >= 0 && nheld <= nb && nm >= 0, FMBD_ERR_VALUE, "held modes: bad sizes");
  FMBD_GALLOC(is_held = fmbd_calloc((size_t)(nb + 1), sizeof(bool)));
  for (int64_t i = 0; i < nheld; i++) {
    FMBD_GCHECK(held[i] >= 0 && held[i] < nb && !is_held[held[i]], FMBD_ERR_VALUE,
                "held boundary index %lld", (long long)held[i]);
    is_held[held[i]] = true;
  }
  // the full reduced matrices at nd (closed form, docs/THEORY.md section 1)
  FMBD_GALLOC(Mr = fmbd_calloc((size_t)(n * n + 1), sizeof(double)));
  FMBD_GALLOC(Kr = fmbd_calloc((size_t)(n * n + 1), sizeof(double)));
  for (int64_t i = 0; i < nd; i++) {
    Mr[i + n * i] = 1.0;
    Kr[i + n * i] = full->kappa[i];
  }
  for (int64_t j = 0; j < nb; j++) {
    for (int64_t i = 0; i < nd; i++)
      Mr[i + n * (nd + j)] = Mr[(nd + j) + n * i] = full->PhitA[i + np * j];
    for (int64_t i = 0; i < nb; i++) {
      Mr[(nd + i) + n * (nd + j)] = full->Mbb[i + nb * j];
      Kr[(nd + i) + n * (nd + j)] = full->Kbb[i + nb * j];
    }
  }
  // V = [held-problem eigenvectors, zero on the held rows | unit vectors of the held dofs]
  FMBD_GALLOC(V = fmbd_calloc((size_t)(n * k + 1), sizeof(double)));
  for (int64_t c = 0; c < nm; c++) {
    for (int64_t i = 0; i < nd; i++) V[i + n * c] = XiF[i + ldxi * c];
    for (int64_t j = 0, f = 0; j < nb; j++) {
      if (!is_held[j]) V[nd + j + n * c] = XiF[nd + (f++) + ldxi * c];
    }
  }
  // the held dofs' constraint modes with the free boundary dofs F free: unit displacement of
  // held dof i, F statically condensed (K_ is block diagonal: the modal part stays 0):
  // v_F = -Kbb_FF^-1 Kbb_Fi. With a whole interface held Kbb_FF is positive definite; for one
  // held interface these are the rigid-body motions (removed below)
  int64_t nfr = nb - nheld;
  for (int64_t i = 0; i < nheld; i++) V[nd + held[i] + n * (nm + i)] = 1.0;
  if (nfr > 0 && nheld > 0) {
    int64_t *fr = NULL;
    double *Kff = NULL, *B = NULL;
    fr = fmbd_malloc(sizeof(int64_t) * (size_t)nfr);
    Kff = fmbd_malloc(sizeof(double) * (size_t)(nfr * nfr));
    B = fmbd_malloc(sizeof(double) * (size_t)(nfr * nheld));
    if (!fr || !Kff || !B) {
      fmbd_free(fr), fmbd_free(Kff), fmbd_free(B);
      FMBD_GFAIL(FMBD_ERR_NOMEM, "out of memory");
    }
    for (int64_t j = 0, f = 0; j < nb; j++) {
      if (!is_held[j]) fr[f++] = j;
    }
    take_sub(nb, full->Kbb, nfr, fr, Kff);
    for (int64_t c = 0; c < nheld; c++) {
      for (int64_t i = 0; i < nfr; i++) B[i + nfr * c] = -full->Kbb[fr[i] + nb * held[c]];
    }
    rc = fmbd_dense_chol(nfr, Kff);
    if (!rc) rc = fmbd_dense_chol_solve(nfr, Kff, nheld, B, nfr);
    if (!rc) {
      for (int64_t c = 0; c < nheld; c++) {
        for (int64_t i = 0; i < nfr; i++) V[nd + fr[i] + n * (nm + c)] = B[i + nfr * c];
      }
    }
    fmbd_free(fr), fmbd_free(Kff), fmbd_free(B);
    if (rc) {
      FMBD_GFAIL(FMBD_ERR_SINGULAR,
                 "the held interfaces do not hold the body: its stiffness at "
                 "the free boundary dofs is singular");
    }
  }
  // Rayleigh-Ritz: (V' K_ V) y = chibar (V' M_ V) y
  FMBD_GALLOC(W = fmbd_calloc((size_t)(n * k + 1), sizeof(double)));
  FMBD_GALLOC(Mv = fmbd_calloc((size_t)(k * k + 1), sizeof(double)));
  FMBD_GALLOC(Kv = fmbd_calloc((size_t)(k * k + 1), sizeof(double)));
  FMBD_GALLOC(w = fmbd_calloc((size_t)(k + 1), sizeof(double)));
  if (k > 0 && n > 0) {
    fmbd_dense_gemm('N', 'N', n, k, n, 1.0, Mr, n, V, n, 0.0, W, n);
    fmbd_dense_gemm('T', 'N', k, k, n, 1.0, V, n, W, n, 0.0, Mv, k);
    fmbd_dense_gemm('N', 'N', n, k, n, 1.0, Kr, n, V, n, 0.0, W, n);
    fmbd_dense_gemm('T', 'N', k, k, n, 1.0, V, n, W, n, 0.0, Kv, k);
    symmetrize(k, Mv);
    symmetrize(k, Kv);
    FMBD_GCALL(fmbd_dense_sygv(k, Kv, Mv, w));  // Kv <- y, M_v-orthonormal
  }
  // drop the rigid-body modes (the frame carries them), keep the rest ascending
  double scale = nd > 0 ? full->kappa[0] : (k > 0 ? fabs(w[k - 1]) : 0.0);
  int64_t nf = 0;
  for (int64_t c = 0; c < k; c++) nf += !(fabs(w[c]) <= full->opt.rigid_rtol * scale);
  FMBD_GALLOC(*chibar = fmbd_malloc(sizeof(double) * (size_t)(nf + 1)));
  FMBD_GALLOC(*Xi = fmbd_calloc((size_t)(n * nf + 1), sizeof(double)));
  for (int64_t c = 0, o = 0; c < k; c++) {
    if (fabs(w[c]) <= full->opt.rigid_rtol * scale) continue;
    (*chibar)[o] = w[c];
    fmbd_dense_gemm('N', 'N', n, 1, k, 1.0, V, n, Kv + k * c, k, 0.0, *Xi + n * o, n);
    o++;
  }
  *nout = nf;
done:
  if (rc) {
    fmbd_free(*chibar);
    fmbd_free(*Xi);
    *chibar = *Xi = NULL;
  }
  fmbd_free(is_held), fmbd_free(Mr), fmbd_free(Kr), fmbd_free(V), fmbd_free(W);
  fmbd_free(Mv), fmbd_free(Kv), fmbd_free(w);
  return rc;
}
