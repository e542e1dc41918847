// common/fmbd_mbs_spin.c: the spin warning (docs/STABILITY.md, "The spin-up beam")
// SPDX-License-Identifier: MIT
//
// A flexible body spinning at Omega carries centrifugal forces whose geometric stiffness, of
// order Omega^2 in every modal eigenvalue, the floating frame's linear modes do not have: a
// mode of eigenvalue lambda is off by up to about Omega^2 / lambda (Southwell's coefficient 1.193
// for a cantilever's first flapwise mode; the conventional linear model softens in the plane of
// rotation and diverges at Omega^2 = lambda_1, Kane, Ryan and Banerjee 1987; what fmbd-run does
// is measured in tests/extreme/test_spin_up.py). The lambda that
// matters is the body's lowest elastic eigenvalue as the scene holds it, not the free body's
// (a beam pinned at one end: the cantilever's, 40 times below the free-free one). It is found
// once, at the first accepted step, from the linearised equations (fmbd_mbs_linearise): for each
// flexible body, its block of M and K on the null space of the constraint rows that involve it,
// the other bodies held where they are; the lowest eigenvalue above round-off of the rigid
// motions left free. A warning, once per body, when |Omega|^2 > SPIN_RATIO lambda. Modal bodies
// of at most SPIN_MAX_N coordinates only (not full FE bodies: their dense block would be huge).
//
// Also, for every body, the step's rotation against the numerical damping (docs/STABILITY.md,
// "rho_inf and rotation"): the index-3 scheme has a parasitic mode (root -rho_inf, the
// Euler parameters' p . p' alternating step by step) that rotation amplifies by about
// 1 + h Omega / 2 per step; rho_inf damps it only while h Omega stays below about
// 1 - rho_inf (measured: 0.9 stable at h Omega = 0.08, not at 0.2; 0.99 at 0.01, not at
// 0.02). A warning, once per body, when h |Omega| > 1 - rho_inf (rho_inf < 1: at 1 the
// settings' warning has said it).
#include <math.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"

#define SPIN_RATIO 0.01
#define SPIN_MAX_N 1000  // bodies of more coordinates (7 + modes) are not checked

// Lowest elastic eigenvalue of body ib held by its constraint rows (INFINITY: none).
static double held_lambda(const fmbd_mbs_linear *L, int64_t off, int64_t nb) {
  double lam = INFINITY;
  int64_t nr = 0;
  double *C = NULL, *G = NULL, *w = NULL, *K = NULL, *M = NULL, *T = NULL, *Kr = NULL, *Mr = NULL;
  for (int64_t r = 0; r < L->Cq->nrows; r++) {
    for (int64_t k = L->Cq->indptr[r]; k < L->Cq->indptr[r + 1]; k++) {
      if (L->Cq->indices[k] >= off && L->Cq->indices[k] < off + nb) {
        nr++;
        break;
      }
    }
  }
  C = fmbd_calloc((size_t)(nr * nb) + 1, sizeof *C);  // nr x nb, column-major
  G = fmbd_calloc((size_t)(nb * nb), sizeof *G);
  w = fmbd_calloc((size_t)nb, sizeof *w);
  K = fmbd_calloc((size_t)(nb * nb), sizeof *K);
  M = fmbd_calloc((size_t)(nb * nb), sizeof *M);
  T = fmbd_calloc((size_t)(nb * nb), sizeof *T);
  Kr = fmbd_calloc((size_t)(nb * nb), sizeof *Kr);
  Mr = fmbd_calloc((size_t)(nb * nb), sizeof *Mr);
  if (!C || !G || !w || !K || !M || !T || !Kr || !Mr) goto done;
  for (int64_t r = 0, i = 0; r < L->Cq->nrows; r++) {
    bool in = false;
    for (int64_t k = L->Cq->indptr[r]; k < L->Cq->indptr[r + 1]; k++) {
      int64_t c = L->Cq->indices[k];
      if (c >= off && c < off + nb) C[i + nr * (c - off)] = L->Cq->data[k], in = true;
    }
    if (in) i++;
  }
  const fmbd_csr *S[2] = {L->K, L->M};
  double *D[2] = {K, M};
  for (int s = 0; s < 2; s++) {
    for (int64_t r = off; r < off + nb; r++) {
      for (int64_t k = S[s]->indptr[r]; k < S[s]->indptr[r + 1]; k++) {
        int64_t c = S[s]->indices[k];
        if (c >= off && c < off + nb) D[s][(r - off) + nb * (c - off)] = S[s]->data[k];
      }
    }
  }
  // null space of C: eigenvectors of C'C with eigenvalues below 1e-10 of the largest
  fmbd_dense_gemm('T', 'N', nb, nb, nr, 1.0, C, nr > 0 ? nr : 1, C, nr > 0 ? nr : 1, 0.0, G, nb);
  if (fmbd_dense_syev(nb, G, w) != FMBD_OK) goto done;
  int64_t nn = 0;
  for (int64_t k = 0; k < nb; k++) nn += w[k] <= 1e-10 * fmax(w[nb - 1], 1e-300);
  if (nn == 0) goto done;
  // N = G(:, 0:nn) (ascending: the null space first); Kr = N'KN, Mr = N'MN
  fmbd_dense_gemm('N', 'N', nb, nn, nb, 1.0, K, nb, G, nb, 0.0, T, nb);
  fmbd_dense_gemm('T', 'N', nn, nn, nb, 1.0, G, nb, T, nb, 0.0, Kr, nn);
  fmbd_dense_gemm('N', 'N', nb, nn, nb, 1.0, M, nb, G, nb, 0.0, T, nb);
  fmbd_dense_gemm('T', 'N', nn, nn, nb, 1.0, G, nb, T, nb, 0.0, Mr, nn);
  if (fmbd_dense_sygv(nn, Kr, Mr, w) != FMBD_OK) goto done;
  for (int64_t k = 0; k < nn; k++) {
    if (w[k] > 1e-9 * fabs(w[nn - 1])) {  // above the round-off of the free rigid motions
      lam = w[k];
      break;
    }
  }
done:
  fmbd_err_clear();  // a failure only leaves lam unknown (no warning), never stops a run
  fmbd_free(C), fmbd_free(G), fmbd_free(w), fmbd_free(K), fmbd_free(M);
  fmbd_free(T), fmbd_free(Kr), fmbd_free(Mr);
  return lam;
}

void mbs_spin_check(fmbd_mbs *m) {
  const double h = m->st.h_last, rho = m->set.rho_inf;
  for (int i = 0; i < m->nb && rho < 1; i++) {
    mbody *b = &m->b[i];
    if (b->rate_warned) continue;
    double w[3];
    fmbd_mbs_body_velocity(m, i, NULL, w);
    double hw = h * sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    if (!(hw > 1 - rho)) continue;
    b->rate_warned = true;
    fmbd_log(FMBD_LOG_WARN,
             "t = %.6g s: body '%s' turns %.3g rad in a step (h = %.3g s), more than 1 - rho_inf "
             "= %.3g: the scheme's parasitic mode of its Euler parameters can grow and the "
             "rotation's energy collapse; use steps (step, max_step) below %.3g s or a smaller "
             "rho_inf (docs/STABILITY.md, rho_inf and rotation)",
             m->t, b->name, hw, h, 1 - rho, (1 - rho) / (hw / h));
  }
  if (!m->spin_ready) {
    m->spin_ready = true;
    bool any = false;
    for (int i = 0; i < m->nb; i++) {
      m->b[i].spin_lam = INFINITY;
      any |= m->b[i].nm > 0 && !m->b[i].fe && m->b[i].n <= SPIN_MAX_N;
    }
    if (!any) return;
    fmbd_mbs_linear L;
    memset(&L, 0, sizeof L);
    if (fmbd_mbs_linearise(m, m->t, NULL, NULL, &L) != FMBD_OK) {
      fmbd_err_clear();
      return;
    }
    for (int i = 0; i < m->nb; i++) {
      // modal bodies only: a full FE body's dense block would be (7 + its FE dofs)^2
      if (m->b[i].nm > 0 && !m->b[i].fe && m->b[i].n <= SPIN_MAX_N)
        m->b[i].spin_lam = held_lambda(&L, m->b[i].off, m->b[i].n);
      fmbd_log(FMBD_LOG_DEBUG, "body '%s': lowest elastic eigenvalue as held %.6g rad^2/s^2",
               m->b[i].name, m->b[i].spin_lam);
    }
    fmbd_mbs_linear_free(&L);
  }
  for (int i = 0; i < m->nb; i++) {
    mbody *b = &m->b[i];
    if (b->nm == 0 || b->spin_warned || !isfinite(b->spin_lam)) continue;
    double w[3];
    fmbd_mbs_body_velocity(m, i, NULL, w);
    double w2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    if (w2 <= SPIN_RATIO * b->spin_lam) continue;
    b->spin_warned = true;
    fmbd_log(FMBD_LOG_WARN,
             "t = %.6g s: flexible body '%s' spins at %.4g rad/s, Omega^2 = %.2g of its lowest "
             "elastic eigenvalue as held (%.4g Hz): its linear modes lack the geometric "
             "stiffening of the centrifugal forces, worth up to about that fraction of the "
             "mode's stiffness (docs/STABILITY.md, the spin-up beam)",
             m->t, b->name, sqrt(w2), w2 / b->spin_lam, sqrt(b->spin_lam) / (2 * M_PI));
  }
}
