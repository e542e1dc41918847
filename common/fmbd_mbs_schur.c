// common/fmbd_mbs_schur.c: the iteration matrix solved by eliminating the modal coordinates of
// each modal flexible body (Schur complement; fmbd_mbs_impl.h, mbs_schur_*)
// SPDX-License-Identifier: MIT
//
// The iteration matrix (fmbd_mbs_system.c) ordered as [R; F], F the modal coordinates q of the
// modal bodies (.cb.h5 / .rflex.h5: not full FE bodies, not shared GM sets), R the rest (all
// frame coordinates, rigid bodies, other bodies, the constraint rows):
//   [A_RR A_RF; A_FR A_FF] [x_R; x_F] = [r_R; r_F].
// A_FF is block diagonal by body (the constraints touch q only through their rows, which are
// in R), and a body's block is cm Mff + cc (Dff + 2 w . int rho S_l x S_k) + ck Kff
// (fmbd_mbs_body.c). Its constant part C = cm Mff + cc Dff + ck Kff (symmetric positive
// definite: Mff is, Dff and Kff are semi-definite) is factored by dense Cholesky once per set of
// coefficients (per step size); the gyroscopic part cc 2 w . SSx is left out (relative size
// about 2 h |w| against Mff: 2e-2 at |w| = 10 rad/s, h = 1e-3 s). Then
//   W = C^-1 A_FR (per body, nm x nc, nc = its coupled unknowns: its 7 frame coordinates and
//   the constraint rows at its points), S = A_RR - sum A_RF W (sparse, KLU),
// and a solve is y = C^-1 r_F, S x_R = r_R - A_RF y, x_F = y - W x_R.
// This is Newton with a modified matrix (the exact one less the gyroscopic part of A_FF), as
// the whole iteration already is (fmbd_mbs.h: the position derivatives of the inertia terms
// are left out too): the residual is evaluated exactly at every iterate, and fmbd_mbs_step.c's
// test bounds the remaining error of the actual increments (theta / (1 - theta) |dx| within
// the tolerance), so the converged state is the one the equations define, to the same
// tolerance as with the exact matrix; the matrix only sets the contraction rate theta.
// Cost per factorisation: a Cholesky nm^3/3 when h changed, 2 nm^2 nc for W, nm nc^2 for
// A_RF W, KLU on S (order N - sum nm); per solve 2 nm^2 + 4 nm nc per body plus S's solve.
// A body with diagonal Mff and Kff (M-orthonormal modes, the usual modal body: b->mdiag,
// b->kdiag; Dff is diagonal by construction) has C diagonal: no Cholesky, W = C^-1 A_FR and
// y = C^-1 r_F by division, nm nc and nm operations.
// Against KLU's LU of the whole matrix (about (7 + nm)^3 2/3 per body with dense blocks) this
// gains from about 10 modes on (bench/README.md, "Schur complement of the modal blocks").
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"
// after fmbd_mbs_impl.h: OpenBLAS's cblas.h may include <complex.h> (the macro I)
#include <cblas.h>

typedef struct sbody {
  int ib, nm, nc;
  int64_t qoff;      // first modal coordinate (global)
  int64_t *cs;       // nc: S indices of the coupled unknowns
  int64_t *pu, *pv;  // Ax positions of (q_k, c_j) at pu[k + nm j], (c_j, q_k) at pv[j + nc k]
                     // (-1: structurally zero)
  int64_t *ps;       // Sx positions of (cs[i], cs[j]) at ps[i + nc j]
  double *L;         // nm x nm: Cholesky factor (lower) of C; diag: C's diagonal (nm), then
                     // its inverse (nm)
  double cf[3];      // (cm, cc, ck) of L
  bool have_L;
  bool diag;  // Mff, Kff (and Dff) diagonal (b->mdiag, b->kdiag): C diagonal, O(nm nc) and O(nm)
  double *W, *V, *VW;  // nm x nc: A_FR, then C^-1 A_FR; nc x nm: A_RF; nc x nc: A_RF W
  double *y, *t;       // nm, nc workspace
} sbody;

struct mbs_schur {
  int nsb;
  sbody *sb;
  int64_t nR, nnzS, nrr;
  int64_t *gidx;       // nR: global unknown of each S index
  int64_t *rrA, *rrS;  // the R x R entries: Ax position, Sx position
  double *Sx, *r;
  int64_t nz0, *z0;  // the runs [z0[2i], z0[2i + 1]) of Ax outside the eliminated modal blocks
  fmbd_klu *klu;
  bool active;  // the current factor is this one (else the whole matrix's, fmbd_mbs_system.c)
};

void mbs_schur_free(mbs_schur **sp) {
  if (!sp || !*sp) return;
  mbs_schur *s = *sp;
  for (int k = 0; k < s->nsb; k++) {
    sbody *b = &s->sb[k];
    fmbd_free(b->cs), fmbd_free(b->pu), fmbd_free(b->pv), fmbd_free(b->ps), fmbd_free(b->L);
    fmbd_free(b->W), fmbd_free(b->V), fmbd_free(b->VW), fmbd_free(b->y), fmbd_free(b->t);
  }
  fmbd_free(s->sb), fmbd_free(s->gidx), fmbd_free(s->rrA), fmbd_free(s->rrS);
  fmbd_free(s->Sx), fmbd_free(s->r), fmbd_free(s->z0);
  fmbd_klu_destroy(&s->klu);
  fmbd_free(s);
  *sp = NULL;
}

// FMBD_MBS_SCHUR: "0" / "off" forces the whole matrix's KLU, "1" / "on" the elimination of
// every modal body's block (any nm >= 1); unset or anything else: automatic (SCHUR_NM_MIN)
static int schur_env(void) {
  const char *e = getenv("FMBD_MBS_SCHUR");
  if (!e) return -1;
  if (!strcmp(e, "0") || !strcmp(e, "off")) return 0;
  if (!strcmp(e, "1") || !strcmp(e, "on")) return 1;
  return -1;
}

static int key_cmp(const void *a, const void *b) {
  int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
  return x < y ? -1 : x > y;
}
static int64_t key_find(const int64_t *keys, int64_t n, int64_t key) {
  const int64_t *f = bsearch(&key, keys, (size_t)n, sizeof key, key_cmp);
  return f ? f - keys : -1;
}

int mbs_schur_setup(fmbd_mbs *m, const int64_t *Ap, const int64_t *Ai) {
  int rc = FMBD_OK;
  mbs_schur *s = NULL;
  int64_t *owner = NULL, *rmap = NULL, *mark = NULL, *keys = NULL, *SAp = NULL, *SAi = NULL;
  const int64_t N = m->N;
  const int force = schur_env();
  if (force == 0) return FMBD_OK;
  const int nmin = force == 1 ? 1 : SCHUR_NM_MIN;
  int ne = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (!b->fe && b->share < 0 && b->nm >= nmin) ne++;
  }
  if (ne == 0) return FMBD_OK;
  FMBD_GALLOC(s = fmbd_calloc(1, sizeof *s));
  FMBD_GALLOC(s->sb = fmbd_calloc((size_t)ne, sizeof(sbody)));
  FMBD_GALLOC(owner = fmbd_malloc(sizeof(int64_t) * (size_t)N));
  FMBD_GALLOC(rmap = fmbd_malloc(sizeof(int64_t) * (size_t)N));
  FMBD_GALLOC(mark = fmbd_malloc(sizeof(int64_t) * (size_t)N));
  for (int64_t i = 0; i < N; i++) owner[i] = -1, mark[i] = -1;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (b->fe || b->share >= 0 || b->nm < nmin) continue;
    sbody *sb = &s->sb[s->nsb];
    sb->ib = ib, sb->nm = b->nm, sb->qoff = b->qoff;
    sb->diag = b->mdiag && b->kdiag;  // Dff is diagonal by construction (fmbd_mbs_add_flex)
    for (int k = 0; k < b->nm; k++) owner[b->qoff + k] = s->nsb;
    s->nsb++;
  }
  for (int64_t i = 0; i < N; i++) rmap[i] = owner[i] < 0 ? s->nR++ : -1;
  FMBD_GALLOC(s->gidx = fmbd_malloc(sizeof(int64_t) * (size_t)(s->nR ? s->nR : 1)));
  for (int64_t i = 0; i < N; i++) {
    if (rmap[i] >= 0) s->gidx[rmap[i]] = i;
  }
  // the entries: R x R, or one body's F with R; an F entry of two bodies (not met: the
  // constraints couple q through their rows) leaves the whole matrix to KLU
  for (int64_t j = 0; j < N; j++) {
    for (int64_t p = Ap[j]; p < Ap[j + 1]; p++) {
      int64_t i = Ai[p], oi = owner[i], oj = owner[j];
      if (oi >= 0 && oj >= 0 && oi != oj) {
        fmbd_log(FMBD_LOG_INFO, "iteration matrix: modal blocks coupled directly, not eliminated");
        goto done;  // rc = FMBD_OK, s freed: the KLU path
      }
      if (oi < 0 && oj < 0) s->nrr++;
    }
  }
  int64_t nkeys = s->nrr;
  for (int k = 0; k < s->nsb; k++) {  // coupled unknowns of each body
    sbody *sb = &s->sb[k];
    int nc = 0;
    for (int64_t j = 0; j < N; j++) {
      for (int64_t p = Ap[j]; p < Ap[j + 1]; p++) {
        int64_t i = Ai[p], c = -1;
        if (owner[i] == k && owner[j] < 0) c = j;
        if (owner[j] == k && owner[i] < 0) c = i;
        if (c >= 0 && mark[c] != k) mark[c] = k, nc++;
      }
    }
    sb->nc = nc;
    const size_t nm = (size_t)sb->nm, ncs = (size_t)(nc ? nc : 1);
    FMBD_GALLOC(sb->cs = fmbd_malloc(sizeof(int64_t) * ncs));
    FMBD_GALLOC(sb->pu = fmbd_malloc(sizeof(int64_t) * nm * ncs));
    FMBD_GALLOC(sb->pv = fmbd_malloc(sizeof(int64_t) * nm * ncs));
    FMBD_GALLOC(sb->ps = fmbd_malloc(sizeof(int64_t) * ncs * ncs));
    FMBD_GALLOC(sb->L = fmbd_malloc(sizeof(double) * nm * nm));
    FMBD_GALLOC(sb->W = fmbd_malloc(sizeof(double) * nm * ncs));
    FMBD_GALLOC(sb->V = fmbd_malloc(sizeof(double) * nm * ncs));
    FMBD_GALLOC(sb->VW = fmbd_malloc(sizeof(double) * ncs * ncs));
    FMBD_GALLOC(sb->y = fmbd_malloc(sizeof(double) * nm));
    FMBD_GALLOC(sb->t = fmbd_malloc(sizeof(double) * ncs));
    nc = 0;
    for (int64_t i = 0; i < N; i++) {  // increasing global order; mark[i] = local index
      if (mark[i] == k) sb->cs[nc] = rmap[i], mark[i] = -2 - nc, nc++;
    }
    for (size_t e = 0; e < nm * (size_t)nc; e++) sb->pu[e] = sb->pv[e] = -1;
    for (int64_t j = 0; j < N; j++) {
      for (int64_t p = Ap[j]; p < Ap[j + 1]; p++) {
        int64_t i = Ai[p];
        if (owner[i] == k && owner[j] < 0)
          sb->pu[(i - sb->qoff) + (int64_t)nm * (-2 - mark[j])] = p;
        if (owner[j] == k && owner[i] < 0)
          sb->pv[(-2 - mark[i]) + (int64_t)nc * (j - sb->qoff)] = p;
      }
    }
    for (int64_t i = 0; i < N; i++) {
      if (mark[i] <= -2) mark[i] = -1;
    }
    nkeys += (int64_t)nc * nc;
  }
  // S's pattern: A_RR's entries and each body's coupled block (key col * nR + row)
  FMBD_GALLOC(keys = fmbd_malloc(sizeof(int64_t) * (size_t)(nkeys ? nkeys : 1)));
  FMBD_GALLOC(s->rrA = fmbd_malloc(sizeof(int64_t) * (size_t)(s->nrr ? s->nrr : 1)));
  FMBD_GALLOC(s->rrS = fmbd_malloc(sizeof(int64_t) * (size_t)(s->nrr ? s->nrr : 1)));
  int64_t nk = 0, nr = 0;
  for (int64_t j = 0; j < N; j++) {
    for (int64_t p = Ap[j]; p < Ap[j + 1]; p++) {
      int64_t i = Ai[p];
      if (owner[i] >= 0 || owner[j] >= 0) continue;
      s->rrA[nr] = p;
      s->rrS[nr++] = keys[nk++] = rmap[j] * s->nR + rmap[i];  // its key until sorted
    }
  }
  for (int k = 0; k < s->nsb; k++) {
    const sbody *sb = &s->sb[k];
    for (int b = 0; b < sb->nc; b++) {
      for (int a = 0; a < sb->nc; a++) keys[nk++] = sb->cs[b] * s->nR + sb->cs[a];
    }
  }
  qsort(keys, (size_t)nk, sizeof(int64_t), key_cmp);
  int64_t nu = 0;
  for (int64_t e = 0; e < nk; e++) {
    if (nu == 0 || keys[e] != keys[nu - 1]) keys[nu++] = keys[e];
  }
  s->nnzS = nu;
  FMBD_GALLOC(SAp = fmbd_calloc((size_t)s->nR + 1, sizeof(int64_t)));
  FMBD_GALLOC(SAi = fmbd_malloc(sizeof(int64_t) * (size_t)(nu ? nu : 1)));
  for (int64_t e = 0; e < nu; e++) {
    SAi[e] = keys[e] % s->nR;
    SAp[keys[e] / s->nR + 1]++;
  }
  for (int64_t c = 0; c < s->nR; c++) SAp[c + 1] += SAp[c];
  for (int64_t e = 0; e < nr; e++) s->rrS[e] = key_find(keys, nu, s->rrS[e]);
  for (int k = 0; k < s->nsb; k++) {
    sbody *sb = &s->sb[k];
    for (int b = 0; b < sb->nc; b++) {
      for (int a = 0; a < sb->nc; a++)
        sb->ps[a + sb->nc * b] = key_find(keys, nu, sb->cs[b] * s->nR + sb->cs[a]);
    }
  }
  FMBD_GALLOC(s->Sx = fmbd_malloc(sizeof(double) * (size_t)(nu ? nu : 1)));
  FMBD_GALLOC(s->r = fmbd_malloc(sizeof(double) * (size_t)(s->nR ? s->nR : 1)));
  FMBD_GCALL(fmbd_klu_analyze(s->nR, SAp, SAi, &s->klu));
  {  // the modal-modal blocks are not formed in Ax (mbs_eval_system, b->elim): the runs of
     // the other entries, zeroed before each evaluation (mbs_schur_clear)
    fmbd_free(mark);
    FMBD_GALLOC(mark = fmbd_calloc((size_t)(m->nnz ? m->nnz : 1), sizeof(int64_t)));
    for (int k = 0; k < s->nsb; k++) {
      const mbody *b = &m->b[s->sb[k].ib];
      for (int j = 7; j < b->n; j++) {
        for (int i = 7; i < b->n; i++) mark[m->bpos[s->sb[k].ib][i + (int64_t)b->n * j]] = 1;
      }
    }
    int64_t nz = 0;
    for (int64_t e = 0; e < m->nnz; e++) nz += !mark[e] && (e == 0 || mark[e - 1]);
    FMBD_GALLOC(s->z0 = fmbd_malloc(sizeof(int64_t) * 2 * (size_t)(nz ? nz : 1)));
    for (int64_t e = 0; e < m->nnz; e++) {
      if (!mark[e] && (e == 0 || mark[e - 1])) s->z0[2 * s->nz0] = e;
      if (!mark[e] && (e == m->nnz - 1 || mark[e + 1])) s->z0[2 * s->nz0++ + 1] = e + 1;
    }
  }
  for (int k = 0; k < s->nsb; k++) m->b[s->sb[k].ib].elim = true;
  {
    int64_t nf = 0;
    for (int k = 0; k < s->nsb; k++) nf += s->sb[k].nm;
    fmbd_log(FMBD_LOG_INFO,
             "iteration matrix: the %lld modal coordinates of %d bod%s eliminated (Schur "
             "complement): order %lld instead of %lld",
             (long long)nf, s->nsb, s->nsb == 1 ? "y" : "ies", (long long)s->nR, (long long)N);
  }
  m->sc = s;
  s = NULL;
done:
  mbs_schur_free(&s);
  fmbd_free(owner), fmbd_free(rmap), fmbd_free(mark), fmbd_free(keys), fmbd_free(SAp),
      fmbd_free(SAi);
  return rc;
}

void mbs_schur_clear(fmbd_mbs *m) {
  const mbs_schur *s = m->sc;
  for (int64_t e = 0; e < s->nz0; e++)
    memset(m->Ax + s->z0[2 * e], 0, sizeof(double) * (size_t)(s->z0[2 * e + 1] - s->z0[2 * e]));
}

bool mbs_schur_active(const fmbd_mbs *m) {
  return m->sc && m->sc->active;
}

int mbs_schur_factor(fmbd_mbs *m) {
  mbs_schur *s = m->sc;
  s->active = false;
  const double cm = m->mcoef[0], cc = m->mcoef[1], ck = m->mcoef[2];
  for (int k = 0; k < s->nsb; k++) {
    sbody *sb = &s->sb[k];
    const mbody *b = &m->b[sb->ib];
    const int nm = sb->nm, nc = sb->nc;
    const size_t nn = (size_t)nm * nm;
    if (sb->diag && (!sb->have_L || sb->cf[0] != cm || sb->cf[1] != cc || sb->cf[2] != ck)) {
      sb->have_L = false;
      for (int k = 0; k < nm; k++) {
        const size_t e = k + (size_t)nm * k;
        const double d = cm * b->Mff[e] + cc * b->Dff[e] + ck * b->Kff[e];
        FMBD_CHECK(d > 0 && isfinite(d), FMBD_ERR_SINGULAR,
                   "body '%s': modal block not positive definite (coordinate %d: %g)", b->name,
                   k + 1, d);
        sb->L[k] = d, sb->L[nm + k] = 1 / d;
      }
      sb->cf[0] = cm, sb->cf[1] = cc, sb->cf[2] = ck;
      sb->have_L = true;
    } else if (!sb->have_L || sb->cf[0] != cm || sb->cf[1] != cc || sb->cf[2] != ck) {
      for (size_t e = 0; e < nn; e++) sb->L[e] = cm * b->Mff[e] + cc * b->Dff[e] + ck * b->Kff[e];
      sb->have_L = false;
      FMBD_CALL(fmbd_dense_chol(nm, sb->L));
      sb->cf[0] = cm, sb->cf[1] = cc, sb->cf[2] = ck;
      sb->have_L = true;
    }
    if (nc == 0) continue;
    for (size_t e = 0; e < (size_t)nm * nc; e++) {
      sb->W[e] = sb->pu[e] >= 0 ? m->Ax[sb->pu[e]] : 0;
      sb->V[e] = sb->pv[e] >= 0 ? m->Ax[sb->pv[e]] : 0;
    }
    if (sb->diag) {  // by the inverted diagonal (no division in the loop)
      const double *iL = sb->L + nm;
      for (int j = 0; j < nc; j++) {
        for (int k = 0; k < nm; k++) sb->W[k + (size_t)nm * j] *= iL[k];
      }
    } else {
      cblas_dtrsm(CblasColMajor, CblasLeft, CblasLower, CblasNoTrans, CblasNonUnit, nm, nc, 1.0,
                  sb->L, nm, sb->W, nm);
      cblas_dtrsm(CblasColMajor, CblasLeft, CblasLower, CblasTrans, CblasNonUnit, nm, nc, 1.0,
                  sb->L, nm, sb->W, nm);
    }
    for (int j = 0; j < nc; j++) {  // VW = A_RF W, column by column
      double *vw = sb->VW + (size_t)nc * j;
      for (int i = 0; i < nc; i++) vw[i] = 0;
      mbs_matvec_add(nc, nm, sb->V, nc, sb->W + (size_t)nm * j, 1.0, vw);
    }
  }
  memset(s->Sx, 0, sizeof(double) * (size_t)s->nnzS);
  for (int64_t e = 0; e < s->nrr; e++) s->Sx[s->rrS[e]] += m->Ax[s->rrA[e]];
  for (int k = 0; k < s->nsb; k++) {
    const sbody *sb = &s->sb[k];
    for (int e = 0; e < sb->nc * sb->nc; e++) s->Sx[sb->ps[e]] -= sb->VW[e];
  }
  FMBD_CALL(fmbd_klu_factor(s->klu, s->Sx));
  s->active = true;
  return FMBD_OK;
}

int mbs_schur_solve(fmbd_mbs *m, double *rhs) {
  mbs_schur *s = m->sc;
  for (int64_t e = 0; e < s->nR; e++) s->r[e] = rhs[s->gidx[e]];
  for (int k = 0; k < s->nsb; k++) {  // y = C^-1 r_F; r_R -= A_RF y
    sbody *sb = &s->sb[k];
    const int nm = sb->nm, nc = sb->nc;
    if (sb->diag) {
      const double *iL = sb->L + nm;
      for (int k = 0; k < nm; k++) sb->y[k] = rhs[sb->qoff + k] * iL[k];
    } else {
      memcpy(sb->y, rhs + sb->qoff, sizeof(double) * (size_t)nm);
      cblas_dtrsv(CblasColMajor, CblasLower, CblasNoTrans, CblasNonUnit, nm, sb->L, nm, sb->y, 1);
      cblas_dtrsv(CblasColMajor, CblasLower, CblasTrans, CblasNonUnit, nm, sb->L, nm, sb->y, 1);
    }
    if (nc == 0) continue;
    for (int j = 0; j < nc; j++) sb->t[j] = 0;  // (small products: no BLAS call, bench/README)
    mbs_matvec_add(nc, nm, sb->V, nc, sb->y, 1.0, sb->t);
    for (int j = 0; j < nc; j++) s->r[sb->cs[j]] -= sb->t[j];
  }
  FMBD_CALL(fmbd_klu_solve(s->klu, s->r));
  for (int k = 0; k < s->nsb; k++) {  // x_F = y - W x_R
    sbody *sb = &s->sb[k];
    const int nm = sb->nm, nc = sb->nc;
    for (int j = 0; j < nc; j++) sb->t[j] = s->r[sb->cs[j]];
    if (nc > 0) mbs_matvec_add(nm, nc, sb->W, nm, sb->t, -1.0, sb->y);
    memcpy(rhs + sb->qoff, sb->y, sizeof(double) * (size_t)nm);
  }
  for (int64_t e = 0; e < s->nR; e++) rhs[s->gidx[e]] = s->r[e];
  return FMBD_OK;
}
