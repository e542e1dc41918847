// common/fmbd_gm_scene.c: the global modes of a scene's mechanism: the rigid-reference
// configuration, the equations named as the scene names them, and each flexible body's GMs and
// GMc bases written to the fmbd-gm file (docs/THEORY.md section 6; docs/FORMAT.md)
// SPDX-License-Identifier: MIT
#include "fmbd_gm_scene.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_gm.h"
#include "fmbd_log.h"

// --- the mechanism's equations, named as the scene names them --------------------------------
// fmbd_mbs numbers its equations: the joints' (in the order added: the scene's), the drivers'
// (scene order), one Euler-parameter normalisation per body.
typedef struct eqmap {
  int64_t njeq, neq;  // joint equations, all equations
} eqmap;

static void eq_map(const fmbd_scene *s, eqmap *q) {
  q->njeq = 0;
  for (int j = 0; j < s->njoints; j++) q->njeq += fmbd_mbs_joint_equations(s->joints[j].kind);
  q->neq = q->njeq + s->ndrivers + s->nbodies;
}

// "joint 'J' (scene line L) equation k", "driver 'D' (line L)", "normalisation of body 'B'"
static void eq_name(const fmbd_scene *s, const fmbd_scene_model *md, const eqmap *q, int64_t e,
                    char *buf, size_t len) {
  if (e < q->njeq) {
    int64_t k = e;
    for (int j = 0; j < s->njoints; j++) {
      int ne = fmbd_mbs_joint_equations(s->joints[j].kind);
      if (k < ne) {
        snprintf(buf, len, "%s:%d: joint '%s' (%s) equation %lld", s->file, s->joints[j].loc.line,
                 s->joints[j].name, fmbd_scene_joint_name(s->joints[j].kind), (long long)k + 1);
        return;
      }
      k -= ne;
    }
  }
  int64_t d = e - q->njeq;
  if (d >= 0 && d < s->ndrivers) {
    snprintf(buf, len, "%s:%d: driver '%s'", s->file, s->drivers[d].loc.line, s->drivers[d].name);
    return;
  }
  int64_t b = d - s->ndrivers;
  for (int i = 0; i < s->nbodies; i++) {
    if (md->body_id[i] == b) {
      snprintf(buf, len, "%s:%d: the Euler-parameter normalisation of body '%s'", s->file,
               s->bodies[i].loc.line, s->bodies[i].name);
      return;
    }
  }
  snprintf(buf, len, "%s: equation %lld", s->file, (long long)e);
}

// --- the rigid-reference configuration -----------------------------------------------------------
// Elastic coordinates zero, the frame coordinates moved (least change) onto Phi(x, T) = 0 by
// Gauss-Newton steps dx_r = -Cr' (Cr Cr')^+ phi on the frame coordinates (Cr: Cq's frame
// columns; pseudo-inverse: rows dependent on the frames alone are allowed).
int fmbd_gm_rigid_reference(fmbd_mbs *mbs, const fmbd_scene *s, const fmbd_scene_model *md,
                            const bool *rigid, double T, double *x) {
  eqmap qm_;
  eq_map(s, &qm_);
  const eqmap *qm = &qm_;
  int rc = FMBD_OK;
  int64_t n = fmbd_mbs_ncoordinates(mbs);
  double *xd = NULL, *G = NULL, *y = NULL, *ev = NULL, *tmp = NULL;
  fmbd_mbs_linear L = {0};
  memcpy(x, fmbd_mbs_state(mbs), sizeof(double) * (size_t)n);
  for (int64_t i = 0; i < n; i++) {
    if (!rigid[i]) x[i] = 0.0;
  }
  FMBD_GALLOC(xd = fmbd_calloc((size_t)n + 1, sizeof(double)));
  double xs = 1.0;  // size of the mechanism: the tolerance on positions
  for (int64_t i = 0; i < n; i++) {
    if (rigid[i]) xs = fmax(xs, fabs(x[i]));
  }
  // 1e-12 of the mechanism's size: round-off of the constraint functions is ~1e-16 of it
  double tol = 1e-12 * xs;
  for (int it = 0;; it++) {
    fmbd_mbs_linear_free(&L);
    FMBD_GCALL(fmbd_mbs_linearise(mbs, T, x, xd, &L));
    int64_t m = L.nc, worst = 0;
    double big = 0.0;
    for (int64_t r = 0; r < m; r++) {
      if (fabs(L.phi[r]) > big) big = fabs(L.phi[r]), worst = r;
    }
    if (big <= tol) break;
    if (it >= 30) {
      char name[600];
      eq_name(s, md, qm, L.eq[worst], name, sizeof name);
      fmbd_err_context(s->file, "");
      FMBD_GFAIL(FMBD_ERR_CONVERGE,
                 "the constraints cannot be satisfied at t = %g s with the elastic coordinates "
                 "zero: %s keeps a residual %.3g",
                 T, name, L.phi[worst]);
    }
    // G = Cr Cr' (dense m x m), y = G^-1 phi, dx = -Cr' y
    fmbd_free(G);
    fmbd_free(y);
    FMBD_GALLOC(G = fmbd_calloc((size_t)(m * m + 1), sizeof(double)));
    FMBD_GALLOC(y = fmbd_calloc((size_t)(m + 1), sizeof(double)));
    fmbd_free(ev);
    fmbd_free(tmp);
    FMBD_GALLOC(ev = fmbd_calloc((size_t)(m + 1), sizeof(double)));
    FMBD_GALLOC(tmp = fmbd_calloc((size_t)(m + 1), sizeof(double)));
    const fmbd_csr *C = L.Cq;
    for (int64_t a = 0; a < m; a++) {
      for (int64_t b = a; b < m; b++) {
        double g = 0.0;
        int64_t p = C->indptr[a], q = C->indptr[b];
        while (p < C->indptr[a + 1] && q < C->indptr[b + 1]) {
          if (C->indices[p] < C->indices[q]) {
            p++;
          } else if (C->indices[p] > C->indices[q]) {
            q++;
          } else {
            if (rigid[C->indices[p]]) g += C->data[p] * C->data[q];
            p++, q++;
          }
        }
        G[a + m * b] = G[b + m * a] = g;
      }
    }
    // y = G^+ phi by the eigen-decomposition of G: the equations may be dependent on the
    // frame coordinates alone (kept because the elastic coordinates make them independent)
    FMBD_GCALL(fmbd_dense_syev(m, G, ev));
    double top = m > 0 ? fabs(ev[m - 1]) : 0.0;
    for (int64_t k = 0; k < m; k++) {
      double c = 0.0;
      for (int64_t r = 0; r < m; r++) c += G[r + m * k] * L.phi[r];
      // eigenvalues below 1e-12 of the largest: round-off of a zero singular value squared
      tmp[k] = ev[k] > 1e-12 * top ? c / ev[k] : 0.0;
    }
    for (int64_t r = 0; r < m; r++) {
      double c = 0.0;
      for (int64_t k = 0; k < m; k++) c += G[r + m * k] * tmp[k];
      y[r] = c;
    }
    for (int64_t r = 0; r < m; r++) {
      for (int64_t p = C->indptr[r]; p < C->indptr[r + 1]; p++) {
        if (rigid[C->indices[p]]) x[C->indices[p]] -= C->data[p] * y[r];
      }
    }
  }
done:
  fmbd_mbs_linear_free(&L);
  fmbd_free(xd);
  fmbd_free(G);
  fmbd_free(y);
  fmbd_free(ev);
  fmbd_free(tmp);
  return rc;
}

// --- the file ----------------------------------------------------------------------------------
// A dense nq x nq column-major matrix as CSR (the modal mass of a modal body, for fmbd_gm_gmc).
static int dense_csr(int64_t nq, const double *A, fmbd_csr **out) {
  FMBD_CALL(fmbd_csr_create(nq, nq, nq * nq, out));
  fmbd_csr *C = *out;
  for (int64_t i = 0, p = 0; i < nq; i++) {
    for (int64_t j = 0; j < nq; j++, p++) {
      C->indices[p] = j;
      C->data[p] = A[i + nq * j];
    }
    C->indptr[i + 1] = p;
  }
  return FMBD_OK;
}

// /KIND/<name>/Mff and Kff of a basis of nc columns C: S'MS and S'KS with the FE matrices of a
// full body (C: the shapes on its dofs, ndof x nc), else with the file's modal Mff, Kff (C: the
// elastic coordinates' columns, nq x nc)
static int gm_project(const fmbd_fe_body *fe, const fmbd_rflex *r, int64_t ndof, int64_t nq,
                      int64_t nc, const double *C, fmbd_h5 *f, const char *kind, const char *name) {
  int rc = FMBD_OK;
  double *Mc = NULL, *Kc = NULL, *W = NULL;
  char path[600];
  int64_t nr = fe ? ndof : nq;
  FMBD_GALLOC(Mc = fmbd_calloc((size_t)(nc * nc + 1), sizeof(double)));
  FMBD_GALLOC(Kc = fmbd_calloc((size_t)(nc * nc + 1), sizeof(double)));
  FMBD_GALLOC(W = fmbd_calloc((size_t)(nr * nc + 1), sizeof(double)));
  if (fe) {
    fmbd_csr_matmat(fe->M, nc, C, ndof, W, ndof);
    fmbd_dense_gemm('T', 'N', nc, nc, ndof, 1.0, C, ndof, W, ndof, 0.0, Mc, nc);
    fmbd_csr_matmat(fe->K, nc, C, ndof, W, ndof);
    fmbd_dense_gemm('T', 'N', nc, nc, ndof, 1.0, C, ndof, W, ndof, 0.0, Kc, nc);
  } else {
    fmbd_dense_gemm('N', 'N', nq, nc, nq, 1.0, r->Mff, nq, C, nq, 0.0, W, nq);
    fmbd_dense_gemm('T', 'N', nc, nc, nq, 1.0, C, nq, W, nq, 0.0, Mc, nc);
    fmbd_dense_gemm('N', 'N', nq, nc, nq, 1.0, r->Kff, nq, C, nq, 0.0, W, nq);
    fmbd_dense_gemm('T', 'N', nc, nc, nq, 1.0, C, nq, W, nq, 0.0, Kc, nc);
  }
  snprintf(path, sizeof path, "/%s/%s/Mff", kind, name);
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, path, nc, nc, Mc));
  snprintf(path, sizeof path, "/%s/%s/Kff", kind, name);
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, path, nc, nc, Kc));
done:
  fmbd_free(Mc);
  fmbd_free(Kc);
  fmbd_free(W);
  return rc;
}

// The GMs and GMc bases of flexible scene body bi. Its elastic coordinates in the mechanism
// start at off + 7: the modal coordinates of a modal body (shapes on the FE dofs through the
// file's modes), or the FE dofs of a full FE body other than its frame node's (fe_col).
int fmbd_gm_write_body(fmbd_h5 *f, const fmbd_scene *s, const fmbd_scene_model *md, int bi,
                       int64_t off, int64_t nq, int64_t n, const double *Xf, int64_t nk,
                       double rank_tol, const char *sha, int64_t *ncols) {
  int rc = FMBD_OK;
  const fmbd_rflex *r = md->flex[bi];
  const fmbd_fe_body *fe = md->fe ? md->fe[bi] : NULL;
  const int64_t *col = fe ? md->fe_col[bi] : NULL;
  const char *name = s->bodies[bi].name;
  int64_t ndof = fe ? fe->ndof : r->ndof;
  double *Q = NULL, *S = NULL, *B = NULL;
  int64_t *keep = NULL, *kept = NULL;
  fmbd_csr *Wm = NULL;
  char path[600];
  FMBD_GALLOC(Q = fmbd_calloc((size_t)(nq * nk + 1), sizeof(double)));
  FMBD_GALLOC(S = fmbd_calloc((size_t)(ndof * nk + 1), sizeof(double)));
  for (int64_t k = 0; k < nk; k++) {
    for (int64_t i = 0; i < nq; i++) Q[i + nq * k] = Xf[off + 7 + i + n * k];
  }
  // shapes on the FE dofs of elastic-coordinate columns C (nq x nc) into S (ndof x nc)
#define TO_DOFS(C, nc)                                                                        \
  do {                                                                                        \
    if (fe) {                                                                                 \
      for (int64_t k_ = 0; k_ < (nc); k_++) {                                                 \
        for (int64_t i_ = 0; i_ < ndof; i_++) {                                               \
          S[i_ + ndof * k_] = col[i_] >= 0 ? (C)[col[i_] + nq * k_] : 0.0;                    \
        }                                                                                     \
      }                                                                                       \
    } else {                                                                                  \
      fmbd_dense_gemm('N', 'N', ndof, (nc), nq, 1.0, r->shapes, ndof, (C), nq, 0.0, S, ndof); \
    }                                                                                         \
  } while (0)
  // GMs: the elastic blocks of the modes, one set of coordinates shared by all bodies
  TO_DOFS(Q, nk);
  snprintf(path, sizeof path, "/gms/%s/modal", name);
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, path, nq, nk, Q));
  snprintf(path, sizeof path, "/gms/%s/shapes", name);
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, path, ndof, nk, S));
  // its mass and stiffness, S'MS and S'KS (nk x nk; singular when the body's rows of the modes
  // are dependent: the set's sum over the bodies is regular), as for GMc below
  FMBD_GCALL(gm_project(fe, r, ndof, nq, nk, fe ? S : Q, f, "gms", name));
  snprintf(path, sizeof path, "/gms/%s", name);
  FMBD_GCALL(fmbd_h5_write_attr_str(f, path, "file", s->bodies[bi].file));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, path, "file_sha256", sha ? sha : ""));
  // GMc: the body's own basis, dependent columns removed, in the body's mass metric
  if (fe) {
    FMBD_GALLOC(kept = fmbd_calloc((size_t)nq + 1, sizeof(int64_t)));
    for (int64_t i = 0; i < ndof; i++) {
      if (col[i] >= 0) kept[col[i]] = i;
    }
    FMBD_GCALL(fmbd_csr_submatrix(fe->M, nq, kept, nq, kept, &Wm));
  } else {
    FMBD_GCALL(dense_csr(nq, r->Mff, &Wm));
  }
  FMBD_GALLOC(B = fmbd_calloc((size_t)(nq * nk + 1), sizeof(double)));
  FMBD_GALLOC(keep = fmbd_calloc((size_t)nk + 1, sizeof(int64_t)));
  int64_t nc = 0;
  FMBD_GCALL(fmbd_gm_gmc(nq, nk, Q, Wm, rank_tol, B, keep, &nc));
  *ncols = nc;
  TO_DOFS(B, nc);
#undef TO_DOFS
  FMBD_GCALL(gm_project(fe, r, ndof, nq, nc, fe ? S : B, f, "gmc", name));
  for (int64_t j = 0; j < nc; j++) keep[j] += 1;  // 1-based flexible mode numbers
  snprintf(path, sizeof path, "/gmc/%s/modal", name);
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, path, nq, nc, B));
  snprintf(path, sizeof path, "/gmc/%s/shapes", name);
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, path, ndof, nc, S));
  snprintf(path, sizeof path, "/gmc/%s/global_mode", name);
  int64_t d1[1] = {nc};
  FMBD_GCALL(fmbd_h5_write_i64(f, path, 1, d1, keep));
  snprintf(path, sizeof path, "/gmc/%s", name);
  FMBD_GCALL(fmbd_h5_write_attr_str(f, path, "file", s->bodies[bi].file));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, path, "file_sha256", sha ? sha : ""));
  FMBD_GCALL(fmbd_h5_write_attr_f64(f, path, "rank_tolerance", 1, &rank_tol));
  int64_t removed = nk - nc;
  FMBD_GCALL(fmbd_h5_write_attr_i64(f, path, "columns_removed", 1, &removed));
  if (nc == 0) {
    fmbd_log(FMBD_LOG_WARN,
             "%s:%d: body '%s' does not deform in any of the %lld global modes: "
             "its GMc basis is empty",
             s->file, s->bodies[bi].loc.line, name, (long long)nk);
  }
done:
  fmbd_free(Q);
  fmbd_free(S);
  fmbd_free(B);
  fmbd_free(keep);
  fmbd_free(kept);
  fmbd_csr_destroy(&Wm);
  return rc;
}

void fmbd_gm_equation_name(const fmbd_scene *s, const fmbd_scene_model *md, int64_t e, char *buf,
                           size_t len) {
  eqmap q;
  eq_map(s, &q);
  eq_name(s, md, &q, e, buf, len);
}

int64_t fmbd_gm_equation_count(const fmbd_scene *s) {
  eqmap q;
  eq_map(s, &q);
  return q.neq;
}

bool fmbd_gm_equation_is_driver(const fmbd_scene *s, int64_t e) {
  eqmap q;
  eq_map(s, &q);
  return e >= q.njeq && e < q.njeq + s->ndrivers;
}
