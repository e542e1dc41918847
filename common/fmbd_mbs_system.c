// common/fmbd_mbs_system.c: the iteration matrix: system evaluation, sparse pattern, factorisation
// (fmbd_klu) SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"

// ============================================================================================
// system evaluation, sparse matrix, KLU
// ============================================================================================
// name of coordinate i of x
void mbs_coord_describe(const fmbd_mbs *m, int64_t i, char *buf, size_t len) {
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (i >= b->off && i < b->off + b->gn) {
      int k = (int)(i - b->off);
      static const char *nm[] = {"R_x",
                                 "R_y",
                                 "R_z",
                                 "Euler parameter e0",
                                 "Euler parameter e1",
                                 "Euler parameter e2",
                                 "Euler parameter e3"};
      if (k < 7)
        snprintf(buf, len, "body '%s' coordinate %s", b->name, nm[k]);
      else if (b->fe && b->fe->dofs)
        snprintf(buf, len, "body '%s' FE dof %d (node %lld, direction %lld)", b->name, k - 7 + 1,
                 (long long)b->fe->dofs[2 * (k - 7)], (long long)b->fe->dofs[2 * (k - 7) + 1]);
      else if (b->fe)
        snprintf(buf, len, "body '%s' FE dof %d", b->name, k - 7 + 1);
      else if (b->share >= 0)
        snprintf(buf, len, "shared modal coordinate %d (of body '%s' and others)", k - 7 + 1,
                 b->name);
      else
        snprintf(buf, len, "body '%s' modal coordinate %d", b->name, k - 7 + 1);
      return;
    }
  }
  snprintf(buf, len, "coordinate %lld", (long long)i);
}
// name of unknown i of the matrix (coordinate or kept equation)
static void unknown_describe(const fmbd_mbs *m, int64_t i, char *buf, size_t len) {
  if (i < m->n) {
    mbs_coord_describe(m, i, buf, len);
    return;
  }
  for (int64_t e = 0; e < m->neq; e++) {
    if (m->eq[e].kept && m->eq[e].row == i - m->n) {
      mbs_eq_describe(m, &m->eq[e], buf, len);
      return;
    }
  }
  snprintf(buf, len, "unknown %lld", (long long)i);
}

// res = body residuals (+ Phi_x' lam when add_lam), eq phi, and with `matrix` the equations'
// jac and the matrix Ax = [cm M + cc C + ck K, Phi_x'; Phi_x, 0] (dynamics block as
// mbs_body_eval; without `matrix` the joints' jac are not evaluated and stay stale).
void mbs_eval_system(fmbd_mbs *m, double t, const double *xdd, bool matrix, double cm, double cc,
                     double ck, bool add_lam) {
  if (matrix) {
    if (m->sc)
      mbs_schur_clear(m);
    else
      memset(m->Ax, 0, sizeof(double) * (size_t)m->nnz);
    m->mcoef[0] = cm, m->mcoef[1] = cc, m->mcoef[2] = ck;
  }
  for (int ib = 0; ib < m->nb; ib++) {  // shared sets' elastic rows are sums: zeroed first
    const mbody *b = &m->b[ib];
    if (b->share == ib) memset(m->res + b->qoff, 0, sizeof(double) * (size_t)b->nm);
  }
  for (int ib = 0; ib < m->nb; ib++) {
    mbody *b = &m->b[ib];
    if (b->share >= 0) {  // shared elastic coordinates: residual rows added into the set's
      mbs_body_eval(m, ib, t, m->x, m->xd, xdd, m->bres, matrix ? m->bblk : NULL, cm, cc, ck, true);
      memcpy(m->res + b->off, m->bres, sizeof(double) * 7);
      for (int k = 0; k < b->nm; k++) m->res[b->qoff + k] += m->bres[7 + k];
      if (matrix) {
        const int64_t *pos = m->bpos[ib];
        for (int i = 0; i < b->n * b->n; i++) m->Ax[pos[i]] += m->bblk[i];
      }
      continue;
    }
    if (b->fe) {
      mbs_fe_eval(m, ib, t, m->x, m->xd, xdd, m->res + b->off, matrix ? m->Ax : NULL, cm, cc, ck);
      continue;
    }
    mbs_body_eval(m, ib, t, m->x, m->xd, xdd, m->res + b->off, matrix ? m->bblk : NULL, cm, cc, ck,
                  !b->elim);
    if (matrix) {  // an eliminated body: its modal-modal block is not formed (mbs_body_ff)
      const int64_t *pos = m->bpos[ib];
      const int n = b->n;
      for (int j = 0; j < n; j++) {
        const int ni = b->elim && j >= 7 ? 7 : n;
        for (int i = 0; i < ni; i++) m->Ax[pos[i + n * j]] += m->bblk[i + n * j];
      }
    }
  }
  if (!matrix) {  // the residual alone: Phi_x' lambda without the Jacobians
    mbs_eval_constraints_res(m, m->x, t, add_lam ? m->res : NULL);
    return;
  }
  mbs_eval_constraints(m, m->x, t, true);
  for (int64_t e = 0; e < m->neq; e++) {
    meq *q = &m->eq[e];
    if (!q->kept) continue;
    if (add_lam) mbs_eq_jtv(m, q, m->lam[q->row], m->res);
    for (int i = 0; i < q->nj; i++) {
      m->Ax[q->pr[i]] += q->jac[i];
      m->Ax[q->pc[i]] += q->jac[i];
    }
  }
}

typedef struct slot {
  int64_t key, id;
} slot;
static int slot_cmp(const void *a, const void *b) {
  int64_t x = ((const slot *)a)->key, y = ((const slot *)b)->key;
  return x < y ? -1 : x > y;
}

// compressed-column pattern of the iteration matrix, the maps of the body blocks and equation
// rows into it, KLU symbolic analysis
int mbs_build_pattern(fmbd_mbs *m) {
  int rc = FMBD_OK;
  slot *sl = NULL;
  int64_t *Ap = NULL, *Ai = NULL, *where = NULL;
  int64_t N = m->N, cnt = 0, nz = 0;
  for (int ib = 0; ib < m->nb; ib++)
    cnt += m->b[ib].fe ? mbs_fe_nnz(&m->b[ib]) : (int64_t)m->b[ib].n * m->b[ib].n;
  for (int64_t e = 0; e < m->neq; e++) {
    if (m->eq[e].kept) cnt += 2 * m->eq[e].nj;
  }
  m->nnz = cnt;
  FMBD_GALLOC(sl = fmbd_malloc(sizeof(slot) * (size_t)(cnt ? cnt : 1)));
  FMBD_GALLOC(m->bpos = fmbd_calloc((size_t)m->nb, sizeof(int64_t *)));
  int64_t s = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (b->fe) {  // its sparse block (mbs_fe_entries), positions kept by the body
      int64_t ne = mbs_fe_nnz(b);
      int64_t *r = NULL, *c = NULL;
      r = fmbd_malloc(sizeof(int64_t) * (size_t)ne);
      c = fmbd_malloc(sizeof(int64_t) * (size_t)ne);
      if (!r || !c) {
        fmbd_free(r), fmbd_free(c);
        FMBD_GFAIL(FMBD_ERR_NOMEM, "out of memory");
      }
      mbs_fe_entries(b, r, c);
      for (int64_t k = 0; k < ne; k++, s++) {
        sl[s].key = (b->off + c[k]) * N + (b->off + r[k]);
        sl[s].id = s;
      }
      fmbd_free(r), fmbd_free(c);
      continue;
    }
    FMBD_GALLOC(m->bpos[ib] = fmbd_malloc(sizeof(int64_t) * (size_t)(b->n * b->n)));
    for (int j = 0; j < b->n; j++) {
      for (int i = 0; i < b->n; i++, s++) {
        sl[s].key = mbs_col(b, j) * N + mbs_col(b, i);  // shared sets: repeated keys
        sl[s].id = s;
      }
    }
  }
  for (int64_t e = 0; e < m->neq; e++) {
    meq *q = &m->eq[e];
    if (!q->kept) continue;
    FMBD_GALLOC(q->pr = fmbd_malloc(sizeof(int64_t) * (size_t)q->nj));
    FMBD_GALLOC(q->pc = fmbd_malloc(sizeof(int64_t) * (size_t)q->nj));
    FMBD_GALLOC(q->jw = fmbd_malloc(sizeof(double) * (size_t)q->nj));
    int64_t row = m->n + q->row;
    for (int i = 0; i < q->nj; i++) {
      int64_t col = q->cols[i];
      sl[s].key = col * N + row, sl[s].id = s, s++;
      sl[s].key = row * N + col, sl[s].id = s, s++;
    }
  }
  qsort(sl, (size_t)cnt, sizeof(slot), slot_cmp);
  FMBD_GALLOC(Ap = fmbd_calloc((size_t)N + 1, sizeof(int64_t)));
  FMBD_GALLOC(Ai = fmbd_malloc(sizeof(int64_t) * (size_t)(cnt ? cnt : 1)));
  FMBD_GALLOC(m->Ax = fmbd_calloc((size_t)(cnt ? cnt : 1), sizeof(double)));
  FMBD_GALLOC(where = fmbd_malloc(sizeof(int64_t) * (size_t)(cnt ? cnt : 1)));
  for (int64_t k = 0; k < cnt; k++) {  // one entry per key: a shared set's bodies add into it
    int64_t col = sl[k].key / N, row = sl[k].key % N;
    if (k == 0 || sl[k].key != sl[k - 1].key) {
      Ai[nz++] = row;
      Ap[col + 1]++;
    }
    where[sl[k].id] = nz - 1;
  }
  m->nnz = nz;
  for (int64_t c = 0; c < N; c++) Ap[c + 1] += Ap[c];
  s = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    mbody *b = &m->b[ib];
    if (b->fe) {
      mbs_fe_set_positions(b, where + s);
      s += mbs_fe_nnz(b);
      continue;
    }
    for (int i = 0; i < b->n * b->n; i++, s++) m->bpos[ib][i] = where[s];
  }
  for (int64_t e = 0; e < m->neq; e++) {
    meq *q = &m->eq[e];
    if (!q->kept) continue;
    for (int i = 0; i < q->nj; i++) {
      q->pr[i] = where[s++];
      q->pc[i] = where[s++];
    }
  }
  FMBD_GCALL(fmbd_klu_analyze(N, Ap, Ai, &m->klu));
  FMBD_GCALL(mbs_schur_setup(m, Ap, Ai));
  // each coordinate's diagonal entry (the multipliers' Newton tolerance, fmbd_mbs_step.c); an
  // eliminated body's modal-modal block is not formed in Ax (fmbd_mbs_schur.c): none there
  FMBD_GALLOC(m->dpos = fmbd_malloc(sizeof(int64_t) * (size_t)(m->n ? m->n : 1)));
  FMBD_GALLOC(m->ity = fmbd_calloc((size_t)m->m + 1, sizeof(double)));
  FMBD_GALLOC(m->tx = fmbd_calloc((size_t)m->n + 1, sizeof(double)));
  FMBD_GALLOC(m->dyp = fmbd_calloc((size_t)m->m + 1, sizeof(double)));
  for (int64_t c = 0; c < m->n; c++) {
    m->dpos[c] = -1;
    for (int64_t k = Ap[c]; k < Ap[c + 1]; k++) {
      if (Ai[k] == c) m->dpos[c] = k;
    }
  }
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (!b->elim) continue;
    for (int k = 7; k < b->n; k++) m->dpos[mbs_col(b, k)] = -1;
  }
  // the elastic coordinates of the modal bodies (not full FE bodies, not shared sets): their
  // predictor extrapolates over every other step (fmbd_mbs_step.c, attempt)
  FMBD_GALLOC(m->qpar = fmbd_calloc((size_t)m->n + 1, 1));
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (b->fe || b->share >= 0) continue;
    for (int k = 0; k < b->nm; k++) m->qpar[b->qoff + k] = 1;
  }
done:
  fmbd_free(sl), fmbd_free(where), fmbd_free(Ap), fmbd_free(Ai);
  return rc;
}

void mbs_fill_modal_blocks(fmbd_mbs *m) {
  for (int ib = 0; ib < m->nb; ib++) {
    if (m->b[ib].elim) mbs_body_ff(m, ib);
  }
}

// numeric factorisation of Ax (fmbd_klu: a refactor with the old pivoting when possible); a
// singular matrix is reported with the coordinate or equation of KLU's zero pivot
int mbs_factor(fmbd_mbs *m) {
  if (m->sc) {  // the modal blocks eliminated; on failure the whole matrix's KLU below
    int rs = mbs_schur_factor(m);
    if (rs == FMBD_OK) {
      m->st.factorizations++;
      return FMBD_OK;
    }
    if (rs == FMBD_ERR_NOMEM) return rs;
    fmbd_err_clear();
    mbs_fill_modal_blocks(m);  // the whole matrix needs the blocks the evaluation left out
  }
  int rc = fmbd_klu_factor(m->klu, m->Ax);
  if (rc == FMBD_ERR_SINGULAR) {
    char what[400];
    int64_t col = fmbd_klu_singular_col(m->klu);
    if (col >= 0 && col < m->N)
      unknown_describe(m, col, what, sizeof what);
    else
      snprintf(what, sizeof what, "unknown column");
    char who[600];
    double smin;
    if (mbs_constraints_singular(m, SINGULAR_TOL, &smin, who, sizeof who)) {
      FMBD_FAIL(FMBD_ERR_SINGULAR,
                "t = %.6g s: the constraints are singular (a dead point or singular position): "
                "the equations of %s are dependent (smallest singular value %.2g of their "
                "unit-normalised rows); singular iteration matrix at %s",
                m->t, who, smin, what);
    }
    FMBD_FAIL(FMBD_ERR_SINGULAR,
              "t = %.6g s: singular iteration matrix (mass matrix or constraint Jacobian) at %s",
              m->t, what);
  }
  FMBD_CALL(rc);
  m->st.factorizations++;
  return FMBD_OK;
}

int mbs_solve(fmbd_mbs *m, double *rhs) {
  if (mbs_schur_active(m)) return mbs_schur_solve(m, rhs);
  return fmbd_klu_solve(m->klu, rhs);
}
