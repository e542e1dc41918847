// common/fmbd_fe_tie.c: interface ties (RBE2, RBE3) and clamps as an exact elimination
// u_full = T q; the dof list and the expansion matrix of the fmbd-fe file
// SPDX-License-Identifier: MIT
//
// Every full dof (3 per solid node, 6 per beam or interface node) is one of
//   active     a column of T (identity row);
//   clamped    an empty row (u = 0);
//   RBE2 slave u_s = u_m + theta_m x (x_s - x_m), theta_s = theta_m (6-dof slaves), with m the
//              interface node: rows with the master's active dofs (rigid spider, exact);
//   RBE3 dependent (see below).
// K' = T' K T and M' = T' M T are then the exact reduced matrices (fmbd_fe_assemble).
//
// RBE3 (weighted-average connection). Group nodes i = 1..n with weights w_i = 1, positions x_i,
// reference (interface) node r at x_r, rho_i = x_i - x_r. The reference motion (u_r, theta_r)
// is the least-squares rigid fit of the group's translations (MSC Nastran RBE3; Abaqus/CalculiX
// distributing coupling):
//     minimise  sum_i w_i | u_i - u_r - theta_r x rho_i |^2,
// i.e. with A_i = [ I3, -[rho_i]x ] (3x6) and H = sum_i w_i A_i' A_i (6x6, nonsingular iff the
// group has at least three non-collinear nodes),
//     [u_r; theta_r] = sum_i G_i u_i,   G_i = H^-1 w_i A_i'   (6x3),   C = [G_1 .. G_n] (6 x 3n).
// These six equations C u_g - u_r = 0 are the constraint. To keep the interface node's 6 dofs
// active (a boundary node for Craig-Bampton), six group translations S are made dependent instead,
// as Nastran's RBE3 "UM" option does:
//     u_S = C_S^-1 ( u_r - C_R u_R )       (R = the other group translations),
// which satisfies the constraint exactly for every q. S is chosen by greedy column pivoting on C
// (the column of largest norm after orthogonalising against the chosen ones), which keeps C_S
// well conditioned. The rows of u_S couple all the group's dofs: K' gets a dense (3n+6)^2 block
// per RBE3 group, fine for the faces of joints (hundreds of nodes). Translations of clamped group
// nodes are zero and drop out; rotations of beam nodes in an RBE3 group are not involved.
#include <math.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_fe_impl.h"
#include "fmbd_log.h"

enum { ST_ACTIVE = 0, ST_CLAMPED = 1, ST_RBE2 = 2, ST_RBE3 = 3 };

typedef struct rbe3_data {
  int64_t dep[6];  // the dependent full dofs
  int64_t ncol;    // independent full dofs in the rows
  int64_t *col;    // (ncol,) full dofs
  double *coef;    // (6, ncol) row-major: u_dep[r] = sum_c coef[r][c] u_full[col[c]]
} rbe3_data;

typedef struct tie_ctx {
  const fmbd_fe_body *b;
  const int64_t *fdof;
  int8_t *status;    // per full dof
  int *owner;        // per full dof: interface index (RBE2 slave, RBE3 dependent), else -1
  int64_t *act;      // per full dof: active dof index, or -1
  int64_t *node_of;  // per full dof: its node
  rbe3_data *r3;     // per interface (used for RBE3 only)
} tie_ctx;

// Row of full dof fd as (active column, value) pairs sorted by column; returns the count.
// cols/vals need room for the longest row (6 or an RBE3 row).
static int64_t row_entries(const tie_ctx *c, int64_t fd, int64_t *cols, double *vals) {
  int64_t n = 0;
  switch (c->status[fd]) {
    case ST_ACTIVE:
      cols[0] = c->act[fd];
      vals[0] = 1.0;
      return 1;
    case ST_CLAMPED:
      return 0;
    case ST_RBE2: {
      const fmbd_fe_interface *it = &c->b->interfaces[c->owner[fd]];
      int64_t p = c->node_of[fd], m = it->node, d = fd - c->fdof[p], m0 = c->fdof[m];
      const double *xs = c->b->xyz + 3 * p, *xm = c->b->xyz + 3 * m;
      double r[3] = {xs[0] - xm[0], xs[1] - xm[1], xs[2] - xm[2]};
      int64_t md[3];
      double mv[3];
      int k = 0;
      // u_s = u_m + theta_m x r:  x: u + ty rz - tz ry;  y: v + tz rx - tx rz;  z: w + tx ry - ty
      // rx
      if (d == 0) {
        md[0] = 0;
        mv[0] = 1;
        md[1] = 4;
        mv[1] = r[2];
        md[2] = 5;
        mv[2] = -r[1];
        k = 3;
      } else if (d == 1) {
        md[0] = 1;
        mv[0] = 1;
        md[1] = 5;
        mv[1] = r[0];
        md[2] = 3;
        mv[2] = -r[2];
        k = 3;
      } else if (d == 2) {
        md[0] = 2;
        mv[0] = 1;
        md[1] = 3;
        mv[1] = r[1];
        md[2] = 4;
        mv[2] = -r[0];
        k = 3;
      } else {
        md[0] = d;
        mv[0] = 1;
        k = 1;
      }
      for (int j = 0; j < k; j++) {
        int64_t a = c->act[m0 + md[j]];
        if (a >= 0 && mv[j] != 0.0) {
          cols[n] = a;
          vals[n] = mv[j];
          n++;
        }
      }
      break;
    }
    case ST_RBE3: {
      const rbe3_data *r3 = &c->r3[c->owner[fd]];
      int row = 0;
      while (r3->dep[row] != fd) row++;
      for (int64_t j = 0; j < r3->ncol; j++) {
        int64_t a = c->act[r3->col[j]];
        double v = r3->coef[row * r3->ncol + j];
        if (a >= 0 && v != 0.0) {
          cols[n] = a;
          vals[n] = v;
          n++;
        }
      }
      break;
    }
  }
  // sort by column (insertion sort on pairs; rows are short or already nearly sorted)
  for (int64_t i = 1; i < n; i++) {
    int64_t cc = cols[i];
    double vv = vals[i];
    int64_t j = i - 1;
    while (j >= 0 && cols[j] > cc) {
      cols[j + 1] = cols[j];
      vals[j + 1] = vals[j];
      j--;
    }
    cols[j + 1] = cc;
    vals[j + 1] = vv;
  }
  return n;
}

// Choose the dependent dofs of one RBE3 tie and its coefficients (see the file comment).
static int rbe3_setup(tie_ctx *c, int ii) {
  const fmbd_fe_body *b = c->b;
  const fmbd_fe_interface *it = &b->interfaces[ii];
  rbe3_data *r3 = &c->r3[ii];
  const int64_t n = it->nnodes, n3 = 3 * n;
  int rc = FMBD_OK;
  double *Cm = NULL, *W = NULL;
  int64_t *cand = NULL;
  bool *chosen = NULL;
  const double *xr = b->xyz + 3 * it->node;
  // --- collinearity: the point set's inertia about its centroid must be nonsingular ---
  {
    double cen[3] = {0, 0, 0}, S[9] = {0}, ev[3];
    for (int64_t i = 0; i < n; i++) {
      for (int k = 0; k < 3; k++) cen[k] += b->xyz[3 * it->nodes[i] + k] / (double)n;
    }
    for (int64_t i = 0; i < n; i++) {
      double d[3];
      for (int k = 0; k < 3; k++) d[k] = b->xyz[3 * it->nodes[i] + k] - cen[k];
      double dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
      for (int j = 0; j < 3; j++) {
        for (int k = 0; k < 3; k++) S[j + 3 * k] += (j == k ? dd : 0.0) - d[j] * d[k];
      }
    }
    FMBD_GCALL(fmbd_dense_syev(3, S, ev));
    // ev ascending; collinear points have ev[0] = 0 exactly (up to rounding of ~1e-16 * ev[2])
    FMBD_GCHECK(n >= 3 && ev[0] > 1e-9 * ev[2], FMBD_ERR_VALUE,
                "interface %s: an RBE3 tie needs at least three non-collinear nodes to carry "
                "rotation; group %s has %lld node%s%s",
                it->name, it->name, (long long)n, n == 1 ? "" : "s",
                n >= 2 ? ", all on one line" : "");
  }
  if (n > 1000) {
    fmbd_log(FMBD_LOG_WARN,
             "interface %s: the RBE3 tie over %lld nodes couples all of them: K and M gain a dense "
             "block of %lld x %lld entries (an RBE2 tie, or a coarser group, keeps them sparse)",
             it->name, (long long)n, (long long)(3 * n + 6), (long long)(3 * n + 6));
  }
  // --- H = sum A_i' A_i, C = H^-1 [A_1' .. A_n'] (column-major 6 x 3n) ---
  double H[36] = {0};
  FMBD_GALLOC(Cm = fmbd_calloc((size_t)(6 * n3), sizeof *Cm));
  for (int64_t i = 0; i < n; i++) {
    const double *x = b->xyz + 3 * it->nodes[i];
    double r[3] = {x[0] - xr[0], x[1] - xr[1], x[2] - xr[2]};
    double A[18];  // A_i = [I, -[r]x], row-major 3 x 6
    fmbd_fe_rigid_rows(r, A);
    for (int p = 0; p < 6; p++) {
      for (int q = 0; q < 6; q++) {
        double s = 0.0;
        for (int k = 0; k < 3; k++) s += A[k * 6 + p] * A[k * 6 + q];
        H[p + 6 * q] += s;
      }
      for (int k = 0; k < 3; k++) Cm[p + 6 * (3 * i + k)] = A[k * 6 + p];  // A_i' column 3i+k
    }
  }
  {
    double Hc[36];
    memcpy(Hc, H, sizeof Hc);
    FMBD_GCALL(fmbd_dense_lu_solve(6, Hc, n3, Cm, 6));
  }
  // --- greedy column pivoting among the translations of unclamped group nodes ---
  FMBD_GALLOC(W = fmbd_malloc((size_t)(6 * n3) * sizeof *W));
  FMBD_GALLOC(chosen = fmbd_calloc((size_t)n3, sizeof *chosen));
  memcpy(W, Cm, (size_t)(6 * n3) * sizeof *W);
  int64_t S[6];
  double norm0 = 0.0;
  for (int s = 0; s < 6; s++) {
    int64_t best = -1;
    double bn = 0.0;
    for (int64_t j = 0; j < n3; j++) {
      int64_t fd = c->fdof[it->nodes[j / 3]] + j % 3;
      if (chosen[j] || c->status[fd] != ST_ACTIVE) continue;
      double nn = 0.0;
      for (int p = 0; p < 6; p++) nn += W[p + 6 * j] * W[p + 6 * j];
      if (nn > bn) {
        bn = nn;
        best = j;
      }
    }
    if (s == 0) norm0 = bn;
    FMBD_GCHECK(best >= 0 && bn > 1e-20 * norm0, FMBD_ERR_VALUE,
                "interface %s: the RBE3 tie has too few unclamped nodes to determine the "
                "interface node's 6 dofs",
                it->name);
    chosen[best] = true;
    S[s] = best;
    double q[6], qn = sqrt(bn);
    for (int p = 0; p < 6; p++) q[p] = W[p + 6 * best] / qn;
    for (int64_t j = 0; j < n3; j++) {
      double d = 0.0;
      for (int p = 0; p < 6; p++) d += q[p] * W[p + 6 * j];
      for (int p = 0; p < 6; p++) W[p + 6 * j] -= d * q[p];
    }
  }
  // --- X = C_S^-1; rows: u_S = X u_r - X C_R u_R ---
  double X[36] = {0}, CS[36];
  for (int p = 0; p < 6; p++) X[p + 6 * p] = 1.0;
  for (int s = 0; s < 6; s++) {
    for (int p = 0; p < 6; p++) CS[p + 6 * s] = Cm[p + 6 * S[s]];
  }
  FMBD_GCALL(fmbd_dense_lu_solve(6, CS, 6, X, 6));
  FMBD_GALLOC(cand = fmbd_malloc((size_t)(n3 + 6) * sizeof *cand));
  int64_t nc = 0;
  for (int d = 0; d < 6; d++) cand[nc++] = c->fdof[it->node] + d;
  for (int64_t j = 0; j < n3; j++) {
    int64_t fd = c->fdof[it->nodes[j / 3]] + j % 3;
    if (!chosen[j] && c->status[fd] == ST_ACTIVE) cand[nc++] = j;  // group column index for now
  }
  r3->ncol = nc;
  FMBD_GALLOC(r3->col = fmbd_malloc((size_t)nc * sizeof *r3->col));
  FMBD_GALLOC(r3->coef = fmbd_calloc((size_t)(6 * nc), sizeof *r3->coef));
  for (int64_t k = 0; k < nc; k++) {
    if (k < 6) {
      r3->col[k] = cand[k];
      for (int r = 0; r < 6; r++) r3->coef[r * nc + k] = X[r + 6 * k];
    } else {
      int64_t j = cand[k];
      r3->col[k] = c->fdof[it->nodes[j / 3]] + j % 3;
      for (int r = 0; r < 6; r++) {
        double s = 0.0;
        for (int p = 0; p < 6; p++) s += X[r + 6 * p] * Cm[p + 6 * j];
        r3->coef[r * nc + k] = -s;
      }
    }
  }
  for (int s = 0; s < 6; s++) {
    int64_t fd = c->fdof[it->nodes[S[s] / 3]] + S[s] % 3;
    r3->dep[s] = fd;
    c->status[fd] = ST_RBE3;
    c->owner[fd] = ii;
  }
done:
  fmbd_free(Cm);
  fmbd_free(W);
  fmbd_free(cand);
  fmbd_free(chosen);
  return rc;
}

// CSR from rows generated by row_entries: row i of the result is full dof rowfd[i] (or empty
// if rowfd[i] < 0)
static int rows_to_csr(const tie_ctx *c, int64_t nrows, const int64_t *rowfd, int64_t ncols,
                       int64_t maxrow, fmbd_csr **out) {
  int rc = FMBD_OK;
  int64_t *cols = NULL;
  double *vals = NULL;
  fmbd_csr *A = NULL;
  int64_t *cnt = NULL;
  FMBD_GALLOC(cols = fmbd_malloc((size_t)maxrow * sizeof *cols));
  FMBD_GALLOC(vals = fmbd_malloc((size_t)maxrow * sizeof *vals));
  FMBD_GALLOC(cnt = fmbd_calloc((size_t)nrows + 1, sizeof *cnt));
  for (int64_t i = 0; i < nrows; i++) {
    cnt[i + 1] = cnt[i] + (rowfd[i] >= 0 ? row_entries(c, rowfd[i], cols, vals) : 0);
  }
  FMBD_GCALL(fmbd_csr_create(nrows, ncols, cnt[nrows], &A));
  memcpy(A->indptr, cnt, (size_t)(nrows + 1) * sizeof *cnt);
  for (int64_t i = 0; i < nrows; i++) {
    if (rowfd[i] < 0) continue;
    int64_t k = row_entries(c, rowfd[i], A->indices + cnt[i], A->data + cnt[i]);
    FMBD_ASSERT(k == cnt[i + 1] - cnt[i]);
  }
  *out = A;
  A = NULL;
done:
  fmbd_free(cols);
  fmbd_free(vals);
  fmbd_free(cnt);
  fmbd_csr_destroy(&A);
  return rc;
}

int fmbd_fe_tie_build(fmbd_fe_body *b, const int64_t *fdof, fmbd_csr **T, int8_t *node_tied) {
  int rc = FMBD_OK;
  const int64_t nn = b->nnodes, nfull = fdof[nn];
  tie_ctx c = {.b = b, .fdof = fdof};
  int *tie_of = NULL;
  int64_t *rowfd = NULL;
  FMBD_GALLOC(c.status = fmbd_calloc((size_t)nfull + 1, sizeof *c.status));
  FMBD_GALLOC(c.owner = fmbd_malloc(((size_t)nfull + 1) * sizeof *c.owner));
  FMBD_GALLOC(c.act = fmbd_malloc(((size_t)nfull + 1) * sizeof *c.act));
  FMBD_GALLOC(c.node_of = fmbd_malloc(((size_t)nfull + 1) * sizeof *c.node_of));
  FMBD_GALLOC(c.r3 = fmbd_calloc((size_t)b->ninterfaces + 1, sizeof *c.r3));
  FMBD_GALLOC(tie_of = fmbd_malloc((size_t)nn * sizeof *tie_of));
  for (int64_t p = 0; p < nn; p++) {
    tie_of[p] = -1;
    for (int64_t fd = fdof[p]; fd < fdof[p + 1]; fd++) c.node_of[fd] = p;
  }
  for (int64_t fd = 0; fd < nfull; fd++) c.owner[fd] = -1;
  // --- clamps ---
  for (int k = 0; k < b->nclamped; k++) {
    for (int64_t i = 0; i < b->clamped[k].nnodes; i++) {
      int64_t p = b->clamped[k].nodes[i];
      for (int64_t fd = fdof[p]; fd < fdof[p + 1]; fd++) c.status[fd] = ST_CLAMPED;
    }
  }
  // --- tie membership: one interface per node ---
  for (int ii = 0; ii < b->ninterfaces; ii++) {
    const fmbd_fe_interface *it = &b->interfaces[ii];
    for (int64_t i = 0; i < it->nnodes; i++) {
      int64_t p = it->nodes[i];
      FMBD_GCHECK(tie_of[p] < 0, FMBD_ERR_VALUE,
                  "node %lld belongs to interfaces %s and %s; a node may be tied to one "
                  "interface only",
                  (long long)p, b->interfaces[tie_of[p] < 0 ? ii : tie_of[p]].name, it->name);
      tie_of[p] = ii;
      if (it->kind == FMBD_FE_RBE2) {
        for (int64_t fd = fdof[p]; fd < fdof[p + 1]; fd++) {
          FMBD_GCHECK(c.status[fd] != ST_CLAMPED, FMBD_ERR_VALUE,
                      "node %lld is both clamped and tied to interface %s (RBE2); clamp the "
                      "interface instead",
                      (long long)p, it->name);
          c.status[fd] = ST_RBE2;
          c.owner[fd] = ii;
        }
      }
    }
  }
  for (int ii = 0; ii < b->ninterfaces; ii++) {
    if (b->interfaces[ii].kind == FMBD_FE_RBE3) FMBD_GCALL(rbe3_setup(&c, ii));
  }
  // --- number the active dofs node-major ---
  int64_t nact = 0;
  for (int64_t fd = 0; fd < nfull; fd++) c.act[fd] = c.status[fd] == ST_ACTIVE ? nact++ : -1;
  b->ndof = nact;
  FMBD_GALLOC(b->dofs = fmbd_malloc((size_t)(2 * nact + 1) * sizeof *b->dofs));
  for (int64_t fd = 0; fd < nfull; fd++) {
    if (c.act[fd] >= 0) {
      b->dofs[2 * c.act[fd]] = c.node_of[fd];
      b->dofs[2 * c.act[fd] + 1] = fd - fdof[c.node_of[fd]];
    }
  }
  FMBD_GCALL(fmbd_fe_index_dofs(b));
  // --- T and the expansion ---
  int64_t maxrow = 6;
  for (int ii = 0; ii < b->ninterfaces; ii++) {
    if (c.r3[ii].ncol > maxrow) maxrow = c.r3[ii].ncol;
  }
  FMBD_GALLOC(rowfd = fmbd_malloc((size_t)(6 * nn > nfull ? 6 * nn : nfull) * sizeof *rowfd));
  for (int64_t fd = 0; fd < nfull; fd++) rowfd[fd] = fd;
  FMBD_GCALL(rows_to_csr(&c, nfull, rowfd, nact, maxrow, T));
  for (int64_t p = 0; p < nn; p++) {
    for (int d = 0; d < 6; d++) rowfd[6 * p + d] = fdof[p] + d < fdof[p + 1] ? fdof[p] + d : -1;
  }
  FMBD_GCALL(rows_to_csr(&c, 6 * nn, rowfd, nact, maxrow, &b->expand));
  for (int64_t p = 0; p < nn; p++) {
    node_tied[p] = 0;
    for (int64_t fd = fdof[p]; fd < fdof[p + 1]; fd++) node_tied[p] |= c.status[fd] >= ST_RBE2;
  }
done:
  fmbd_free(c.status);
  fmbd_free(c.owner);
  fmbd_free(c.act);
  fmbd_free(c.node_of);
  if (c.r3) {
    for (int ii = 0; ii < b->ninterfaces; ii++) {
      fmbd_free(c.r3[ii].col);
      fmbd_free(c.r3[ii].coef);
    }
  }
  fmbd_free(c.r3);
  fmbd_free(tie_of);
  fmbd_free(rowfd);
  return rc;
}

int fmbd_fe_index_dofs(fmbd_fe_body *b) {
  fmbd_free(b->node_dof);
  b->node_dof = fmbd_malloc(((size_t)b->nnodes + 1) * sizeof *b->node_dof);
  FMBD_CHECK(b->node_dof, FMBD_ERR_NOMEM, "out of memory");
  int64_t prev_node = -1, prev_dir = -1, k = 0;
  for (int64_t i = 0; i < b->ndof; i++) {
    int64_t p = b->dofs[2 * i], d = b->dofs[2 * i + 1];
    FMBD_CHECK(p >= 0 && p < b->nnodes && d >= 0 && d < 6, FMBD_ERR_FORMAT,
               "/dofs row %lld: (%lld, %lld) out of range (%lld nodes, directions 0..5)",
               (long long)i, (long long)p, (long long)d, (long long)b->nnodes);
    FMBD_CHECK(p > prev_node || (p == prev_node && d > prev_dir), FMBD_ERR_FORMAT,
               "/dofs row %lld: (%lld, %lld) not in node-major order", (long long)i, (long long)p,
               (long long)d);
    while (k <= p) b->node_dof[k++] = i;
    prev_node = p;
    prev_dir = d;
  }
  while (k <= b->nnodes) b->node_dof[k++] = b->ndof;
  return FMBD_OK;
}
