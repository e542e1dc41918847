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
// An FE body's "block" is the iteration-matrix array Ax it was evaluated into (its positions).
static int blocks_to_csr(const fmbd_mbs *m, double *const *blk, fmbd_csr **out) {
  int64_t nnz = 0;
  for (int ib = 0; ib < m->nb; ib++)
    nnz += m->b[ib].fe ? mbs_fe_nnz(&m->b[ib]) : (int64_t)m->b[ib].n * m->b[ib].n;
  FMBD_CALL(fmbd_csr_create(m->n, m->n, nnz, out));
  fmbd_csr *A = *out;
  int64_t p = 0;
  A->indptr[0] = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (b->fe) {
      const mbs_fe *f = b->fe;
      const double *Ax = blk[ib];
      const int64_t nf = b->nm;
      for (int i = 0; i < 7; i++) {
        for (int j = 0; j < 7; j++)
          A->indices[p] = b->off + j, A->data[p++] = Ax[f->pos7[i + 7 * j]];
        for (int64_t k = 0; k < nf; k++)
          A->indices[p] = b->off + 7 + k, A->data[p++] = Ax[f->pu[i + 7 * k]];
        A->indptr[b->off + i + 1] = p;
      }
      for (int64_t k = 0; k < nf; k++) {
        for (int i = 0; i < 7; i++) A->indices[p] = b->off + i, A->data[p++] = Ax[f->pl[i + 7 * k]];
        for (int64_t e = f->P->indptr[k]; e < f->P->indptr[k + 1]; e++)
          A->indices[p] = b->off + 7 + f->P->indices[e], A->data[p++] = Ax[f->pff[e]];
        A->indptr[b->off + 7 + k + 1] = p;
      }
      continue;
    }
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

static int cmp_i64(const void *a, const void *b) {
  int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
  return x < y ? -1 : x > y;
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
  for (int ib = 0; ib < m->nb; ib++)  // blocks_to_csr: the bodies' blocks must not overlap
    FMBD_CHECK(m->b[ib].share < 0, FMBD_ERR_VALUE,
               "fmbd_mbs_linearise: body '%s' shares its modal coordinates (not supported)",
               m->b[ib].name);
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
      if (b->fe) {  // evaluated into an array laid out as the iteration matrix's
        FMBD_GALLOC(blk[k][ib] = fmbd_calloc((size_t)m->nnz, sizeof(double)));
        mbs_fe_eval(m, ib, t, m->x, m->xd, NULL, m->bres, blk[k][ib], k == 0, k == 1, k == 2);
      } else {
        FMBD_GALLOC(blk[k][ib] = fmbd_calloc((size_t)b->n * b->n, sizeof(double)));
        mbs_body_eval(m, ib, t, m->x, m->xd, NULL, m->bres, blk[k][ib], k == 0, k == 1, k == 2,
                      true);
      }
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
      int64_t p0 = p;
      for (int i = 0; i < q->nj; i++) C->indices[p++] = q->cols[i];
      qsort(C->indices + p0, (size_t)(p - p0), sizeof(int64_t), cmp_i64);
      for (int64_t e2 = p0; e2 < p; e2++) {
        C->data[e2] = row[C->indices[e2]];
        row[C->indices[e2]] = 0.0;
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
