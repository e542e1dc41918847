// common/fmbd_mbs_linear.c: the mechanism's equations outside the integrator (linearisation, global
// modes) SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"

// ============================================================================================
// the mechanism's equations outside the integrator (linearisation, global modes)
// ============================================================================================
// One CSR matrix from per-body dense blocks (the bodies' coordinates are contiguous and their
// blocks do not overlap): block diagonal, column-major blocks.
static int blocks_to_csr(const fmbd_mbs *m, double *const *blk, fmbd_csr **out) {
  int64_t nnz = 0;
  for (int ib = 0; ib < m->nb; ib++) nnz += (int64_t)m->b[ib].n * m->b[ib].n;
  FMBD_CALL(fmbd_csr_create(m->n, m->n, nnz, out));
  fmbd_csr *A = *out;
  int64_t p = 0;
  A->indptr[0] = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    for (int i = 0; i < b->n; i++) {
      for (int j = 0; j < b->n; j++) {
        A->indices[p] = b->off + j;
        A->data[p++] = blk[ib][i + (size_t)b->n * j];
      }
      A->indptr[b->off + i + 1] = p;
    }
  }
  return FMBD_OK;
}

void fmbd_mbs_linear_free(fmbd_mbs_linear *L) {
  if (!L) return;
  fmbd_csr_destroy(&L->M);
  fmbd_csr_destroy(&L->C);
  fmbd_csr_destroy(&L->K);
  fmbd_csr_destroy(&L->Cq);
  fmbd_free(L->Q);
  fmbd_free(L->phi);
  fmbd_free(L->eq);
  memset(L, 0, sizeof *L);
}

int fmbd_mbs_linearise(fmbd_mbs *m, double t, const double *x, const double *xd,
                       fmbd_mbs_linear *L) {
  int rc = FMBD_OK;
  double **blk[3] = {NULL, NULL, NULL}, *row = NULL, *xs = NULL, *xds = NULL;
  memset(L, 0, sizeof *L);
  FMBD_CHECK(m->ready, FMBD_ERR_VALUE, "fmbd_mbs_linearise before fmbd_mbs_init");
  int64_t n = m->n;
  // evaluate at (x, xd): the model's own state is saved and restored
  FMBD_GALLOC(xs = fmbd_malloc(sizeof(double) * (size_t)n));
  FMBD_GALLOC(xds = fmbd_malloc(sizeof(double) * (size_t)n));
  memcpy(xs, m->x, sizeof(double) * (size_t)n);
  memcpy(xds, m->xd, sizeof(double) * (size_t)n);
  if (x) memcpy(m->x, x, sizeof(double) * (size_t)n);
  if (xd) memcpy(m->xd, xd, sizeof(double) * (size_t)n);
  L->n = n;
  FMBD_GALLOC(L->Q = fmbd_calloc((size_t)(n + 1), sizeof(double)));
  // --- M, C, K: the body blocks with (cm, cc, ck) = (1,0,0), (0,1,0), (0,0,1) ---
  for (int k = 0; k < 3; k++) {
    FMBD_GALLOC(blk[k] = fmbd_calloc((size_t)(m->nb + 1), sizeof(double *)));
    for (int ib = 0; ib < m->nb; ib++) {
      const mbody *b = &m->b[ib];
      FMBD_GALLOC(blk[k][ib] = fmbd_calloc((size_t)b->n * b->n, sizeof(double)));
      mbs_body_eval(m, ib, t, m->x, m->xd, NULL, m->bres, blk[k][ib], k == 0, k == 1, k == 2);
      if (k == 0) {  // Q = -(residual at zero accelerations)
        for (int i = 0; i < b->n; i++) L->Q[b->off + i] = -m->bres[i];
      }
    }
  }
  FMBD_GCALL(blocks_to_csr(m, blk[0], &L->M));
  FMBD_GCALL(blocks_to_csr(m, blk[1], &L->C));
  FMBD_GCALL(blocks_to_csr(m, blk[2], &L->K));
  // --- the kept constraint equations: values and Jacobian rows ---
  mbs_eval_constraints(m, m->x, t, true);
  int64_t nc = 0, nnz = 0;
  FMBD_GALLOC(row = fmbd_calloc((size_t)(n + 1), sizeof(double)));
  for (int64_t e = 0; e < m->neq; e++) {
    if (!m->eq[e].kept) continue;
    nc++;
    nnz += m->eq[e].nj;
  }
  L->nc = nc;
  FMBD_GALLOC(L->phi = fmbd_calloc((size_t)(nc + 1), sizeof(double)));
  FMBD_GALLOC(L->eq = fmbd_calloc((size_t)(nc + 1), sizeof(int64_t)));
  FMBD_GCALL(fmbd_csr_create(nc, n, nnz, &L->Cq));
  {
    fmbd_csr *C = L->Cq;
    int64_t r = 0, p = 0;
    C->indptr[0] = 0;
    for (int64_t e = 0; e < m->neq; e++) {
      const meq *q = &m->eq[e];
      if (!q->kept) continue;
      mbs_eq_jtv(m, q, 1.0, row);  // the row, dense; gathered in column order, then cleared
      int bo[2] = {q->b[0], q->b[1]};
      if (bo[0] >= 0 && bo[1] >= 0 && m->b[bo[1]].off < m->b[bo[0]].off) {
        int s = bo[0];
        bo[0] = bo[1], bo[1] = s;
      }
      for (int k = 0; k < 2; k++) {
        if (bo[k] < 0 || (k == 1 && bo[1] == bo[0])) continue;
        const mbody *b = &m->b[bo[k]];
        for (int i = 0; i < b->n; i++) {
          C->indices[p] = b->off + i;
          C->data[p++] = row[b->off + i];
          row[b->off + i] = 0.0;
        }
      }
      L->phi[r] = q->phi;
      L->eq[r] = e;
      C->indptr[++r] = p;
    }
  }
done:
  if (xs) memcpy(m->x, xs, sizeof(double) * (size_t)n);
  if (xds) memcpy(m->xd, xds, sizeof(double) * (size_t)n);
  for (int k = 0; k < 3; k++) {
    if (blk[k]) {
      for (int ib = 0; ib < m->nb; ib++) fmbd_free(blk[k][ib]);
    }
    fmbd_free(blk[k]);
  }
  fmbd_free(row);
  fmbd_free(xs);
  fmbd_free(xds);
  if (rc) fmbd_mbs_linear_free(L);
  return rc;
}

int64_t fmbd_mbs_ncoordinates(const fmbd_mbs *m) {
  return m->n;
}

const double *fmbd_mbs_state(const fmbd_mbs *m) {
  return m->x;
}
