// common/fmbd_rflex.c: the reduced flexible body: secondary reduction, FFRF invariants,
// fmbd-rflex file I/O
// SPDX-License-Identifier: MIT
#include "fmbd_rflex.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"

static void *xcalloc(size_t n, size_t sz) {
  return fmbd_calloc(n ? n : 1, sz);
}

void fmbd_rflex_destroy(fmbd_rflex **pr) {
  if (!pr || !*pr) {
    return;
  }
  fmbd_rflex *r = *pr;
  fmbd_free(r->eigenvalue);
  fmbd_free(r->frequency_hz);
  fmbd_free(r->shapes);
  fmbd_free(r->stress);
  fmbd_free(r->node_xyz);
  fmbd_free(r->node_mass);
  fmbd_free(r->dofs);
  fmbd_free(r->held);
  fmbd_free(r->stress_row);
  fmbd_csr_destroy(&r->expand);
  for (int i = 0; i < r->ninterfaces && r->interfaces; i++) {
    fmbd_free(r->interfaces[i].name);
    fmbd_free(r->interfaces[i].kind);
    fmbd_free(r->interfaces[i].translation);
    fmbd_free(r->interfaces[i].rotation);
  }
  fmbd_free(r->interfaces);
  fmbd_free(r->S1);
  fmbd_free(r->XS);
  fmbd_free(r->SS);
  fmbd_free(r->Mff);
  fmbd_free(r->Kff);
  fmbd_free(r);
  *pr = NULL;
}

int fmbd_rflex_find_interface(const fmbd_rflex *r, const char *name) {
  for (int i = 0; i < r->ninterfaces; i++) {
    if (strcmp(r->interfaces[i].name, name) == 0) {
      return i;
    }
  }
  return -1;
}

int64_t fmbd_rflex_nearest_node(const fmbd_rflex *r, const double x[3], double *dist) {
  int64_t best = -1;
  double bd = INFINITY;
  for (int64_t p = 0; p < r->nnodes; p++) {
    const double *y = r->node_xyz + 3 * p;
    double d = (y[0] - x[0]) * (y[0] - x[0]) + (y[1] - x[1]) * (y[1] - x[1]) +
               (y[2] - x[2]) * (y[2] - x[2]);
    if (d < bd) {
      bd = d;
      best = p;
    }
  }
  if (dist) {
    *dist = sqrt(bd);
  }
  return best;
}

int fmbd_rflex_node_modes(const fmbd_rflex *r, int64_t node, double *x0, double *T, double *R) {
  FMBD_CHECK(node >= 0 && node < r->nnodes, FMBD_ERR_VALUE, "node %lld out of range (%lld nodes)",
             (long long)node, (long long)r->nnodes);
  FMBD_CHECK(!r->held || (r->held[node] & FMBD_RFLEX_HELD_MOTION), FMBD_ERR_VALUE,
             "node %lld is not in this subset body, which holds only the nodes its scene read "
             "(/subset); make the body for this scene (fmbd-run -M passes cbcheck --for-scene)",
             (long long)node);
  if (x0) {
    memcpy(x0, r->node_xyz + 3 * node, 3 * sizeof(double));
  }
  for (int d = 0; d < 6; d++) {
    double *out = d < 3 ? T : R;
    if (!out) {
      continue;
    }
    int a = d % 3;
    for (int64_t k = 0; k < r->nm; k++) {
      out[a + 3 * k] = 0;
    }
    const fmbd_csr *E = r->expand;
    int64_t row = 6 * node + d;
    for (int64_t q = E->indptr[row]; q < E->indptr[row + 1]; q++) {
      double w = E->data[q];
      const double *col = r->shapes + E->indices[q];
      for (int64_t k = 0; k < r->nm; k++) {
        out[a + 3 * k] += w * col[r->ndof * k];
      }
    }
  }
  return FMBD_OK;
}

int fmbd_rflex_node_stress(const fmbd_rflex *r, int64_t node, double *sigma) {
  FMBD_CHECK(r->stress, FMBD_ERR_VALUE, "the body has no modal stress (/modes/stress)");
  FMBD_CHECK(node >= 0 && node < r->nnodes, FMBD_ERR_VALUE, "node %lld out of range (%lld nodes)",
             (long long)node, (long long)r->nnodes);
  int64_t row = r->stress_row ? r->stress_row[node] : node;
  FMBD_CHECK(row >= 0 || !r->held, FMBD_ERR_VALUE,
             "this subset body holds no stress at node %lld: only where its scene asked for "
             "stress (/subset/stress_nodes); make the body for this scene (fmbd-run -M passes "
             "cbcheck --for-scene)",
             (long long)node);
  FMBD_CHECK(row >= 0, FMBD_ERR_VALUE,
             "the modal stress of this body was formed at %lld selected nodes only "
             "(fmbd_rflex_form_stress), not at node %lld",
             (long long)r->nstress, (long long)node);
  int64_t ns = r->stress_row ? r->nstress : r->nnodes;
  for (int64_t k = 0; k < r->nm; k++) {
    for (int i = 0; i < 6; i++) {
      sigma[i + 6 * k] = r->stress[i + 6 * row + 6 * ns * k];
    }
  }
  return FMBD_OK;
}

int fmbd_rflex_subset(fmbd_rflex *r, int64_t nmotion, const int64_t *motion, int64_t nstress,
                      const int64_t *stress) {
  int rc = FMBD_OK;
  int64_t nn = r->nnodes, nm = r->nm, nd = r->ndof;
  unsigned char *held = NULL;
  int64_t *dmap = NULL, *srow = NULL, *dofs = NULL;
  if (!r->held) r->whole_ndof = nd;
  double *shapes = NULL, *sig = NULL;
  fmbd_csr *E = NULL;
  FMBD_GALLOC(held = xcalloc((size_t)nn + 1, 1));
  for (int64_t i = 0; i < nmotion + nstress; i++) {
    int64_t p = i < nmotion ? motion[i] : stress[i - nmotion];
    FMBD_GCHECK(p >= 0 && p < nn, FMBD_ERR_VALUE, "node %lld out of range (%lld nodes)",
                (long long)p, (long long)nn);
    held[p] |=
        i < nmotion ? FMBD_RFLEX_HELD_MOTION : (FMBD_RFLEX_HELD_MOTION | FMBD_RFLEX_HELD_STRESS);
  }
  for (int i = 0; i < r->ninterfaces; i++) held[r->interfaces[i].node] |= FMBD_RFLEX_HELD_MOTION;
  for (int64_t p = 0; p < nn; p++) {  // a subset of a subset: what it holds, no more
    if (r->held) held[p] &= r->held[p];
    if ((held[p] & FMBD_RFLEX_HELD_STRESS) &&
        !(r->stress_row ? r->stress_row[p] >= 0 : !!r->stress))
      held[p] &= (unsigned char)~FMBD_RFLEX_HELD_STRESS;
  }
  FMBD_GCHECK(nstress == 0 || r->stress, FMBD_ERR_VALUE,
              "stress asked at %lld nodes, but the body has no modal stress", (long long)nstress);
  // the dofs the held nodes' /expand rows read, renumbered in their order
  const fmbd_csr *X = r->expand;
  FMBD_GALLOC(dmap = fmbd_malloc(sizeof(int64_t) * (size_t)(nd + 1)));
  for (int64_t i = 0; i < nd; i++) dmap[i] = -1;
  int64_t nnz = 0;
  for (int64_t p = 0; p < nn; p++) {
    if (!(held[p] & FMBD_RFLEX_HELD_MOTION)) continue;
    for (int64_t q = X->indptr[6 * p]; q < X->indptr[6 * p + 6]; q++) dmap[X->indices[q]] = 0;
    nnz += X->indptr[6 * p + 6] - X->indptr[6 * p];
  }
  int64_t nk = 0;
  for (int64_t i = 0; i < nd; i++) {
    if (dmap[i] == 0) dmap[i] = nk++;
  }
  FMBD_GALLOC(dofs = fmbd_malloc(sizeof(int64_t) * (size_t)(2 * nk + 1)));
  FMBD_GALLOC(shapes = fmbd_malloc(sizeof(double) * (size_t)(nk * nm + 1)));
  for (int64_t i = 0; i < nd; i++) {
    if (dmap[i] < 0) continue;
    dofs[2 * dmap[i]] = r->dofs[2 * i];
    dofs[2 * dmap[i] + 1] = r->dofs[2 * i + 1];
    for (int64_t k = 0; k < nm; k++) shapes[dmap[i] + nk * k] = r->shapes[i + nd * k];
  }
  FMBD_GCALL(fmbd_csr_create(6 * nn, nk, nnz, &E));
  int64_t e = 0;
  E->indptr[0] = 0;
  for (int64_t row = 0; row < 6 * nn; row++) {
    if (held[row / 6] & FMBD_RFLEX_HELD_MOTION) {
      for (int64_t q = X->indptr[row]; q < X->indptr[row + 1]; q++) {
        E->indices[e] = dmap[X->indices[q]];  // increasing: dmap keeps the order
        E->data[e++] = X->data[q];
      }
    }
    E->indptr[row + 1] = e;
  }
  // the stress rows of the nodes that keep it
  int64_t ns = 0;
  if (r->stress) {
    FMBD_GALLOC(srow = fmbd_malloc(sizeof(int64_t) * (size_t)(nn + 1)));
    for (int64_t p = 0; p < nn; p++) srow[p] = (held[p] & FMBD_RFLEX_HELD_STRESS) ? ns++ : -1;
    FMBD_GALLOC(sig = fmbd_malloc(sizeof(double) * (size_t)(6 * ns * nm + 1)));
    int64_t ns0 = r->stress_row ? r->nstress : nn;
    for (int64_t p = 0; p < nn; p++) {
      if (srow[p] < 0) continue;
      int64_t from = r->stress_row ? r->stress_row[p] : p;
      for (int64_t k = 0; k < nm; k++) {
        memcpy(sig + 6 * srow[p] + 6 * ns * k, r->stress + 6 * from + 6 * ns0 * k,
               6 * sizeof(double));
      }
    }
  }
  fmbd_free(r->held);
  fmbd_free(r->dofs);
  fmbd_free(r->shapes);
  fmbd_free(r->stress_row);
  fmbd_free(r->stress);
  fmbd_csr_destroy(&r->expand);
  r->held = held;
  r->dofs = dofs;
  r->shapes = shapes;
  r->expand = E;
  r->ndof = nk;
  r->stress = sig;
  r->stress_row = srow;
  r->nstress = ns;
  held = NULL;
  dofs = srow = NULL;
  shapes = sig = NULL;
  E = NULL;
done:
  fmbd_free(held);
  fmbd_free(dmap);
  fmbd_free(srow);
  fmbd_free(dofs);
  fmbd_free(shapes);
  fmbd_free(sig);
  fmbd_csr_destroy(&E);
  return rc;
}

double fmbd_von_mises(const double s[6]) {
  double a = s[0] - s[1], b = s[1] - s[2], c = s[2] - s[0];
  return sqrt(0.5 * (a * a + b * b + c * c) + 3 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]));
}

// --- the mass of the invariants -------------------------------------------------------------
// A solid body meshed with consistent mass: its translational mass is the scalar consistent
// mass of the elements repeated per direction, and the invariants use it too, so that modes
// M-orthogonal to rigid motion get S1 = 0 exactly. A consistent-mass body with beams (whose
// consistent mass couples translations and rotations, so that no scalar nodal mass reproduces
// it) gets its rigid-flexible coupling from the full consistent mass M instead
// (fmbd_rflex_beam_coupling below, docs/THEORY.md section 9): S1 = T' M S and the rotational
// coupling R' M S through the rigid-body fields T, R; the symmetric part of XS and SS (the
// deformation terms of J(q)) keep the lumped nodal masses. Lumped-mass bodies use the lumped
// nodal masses throughout.
bool fmbd_rflex_consistent_invariants(const fmbd_fe_body *b) {
  return b->mass_kind == FMBD_FE_MASS_CONSISTENT && b->ntet > 0 && b->tet && b->nbeam == 0;
}

// The scalar consistent mass of the solid elements, assembled (nnodes x nnodes): the mass of each
// translation direction, M = Mn (x) I3 on the translations of a tet mesh.
static int tet_scalar_mass(const fmbd_fe_body *b, fmbd_csr **out) {
  int rc = FMBD_OK;
  int k = b->tet_nodes;
  *out = NULL;
  FMBD_GCALL(fmbd_csr_pattern_from_elements(b->nnodes, b->ntet, k, b->tet, out));
  double xyz[30], Me[100], vol;
  for (int64_t e = 0; e < b->ntet; e++) {
    const int64_t *nd = b->tet + (int64_t)k * e;
    for (int i = 0; i < k; i++) memcpy(xyz + 3 * i, b->xyz + 3 * nd[i], 3 * sizeof(double));
    FMBD_GCALL(fmbd_fe_tet_matrices(k, xyz, b->E, b->nu, b->rho, e, NULL, Me, &vol));
    FMBD_GCALL(fmbd_csr_add_block(*out, k, nd, Me));
  }
done:
  if (rc) fmbd_csr_destroy(out);
  return rc;
}

int fmbd_rflex_nodal_mass(const fmbd_fe_body *b, fmbd_csr **out) {
  if (fmbd_rflex_consistent_invariants(b)) return tet_scalar_mass(b, out);
  int64_t nn = b->nnodes;
  FMBD_CALL(fmbd_csr_create(nn, nn, nn, out));
  for (int64_t p = 0; p < nn; p++) {
    (*out)->indptr[p + 1] = p + 1;
    (*out)->indices[p] = p;
    (*out)->data[p] = b->node_mass ? b->node_mass[p] : 0;
  }
  return FMBD_OK;
}

// m4 (4 nn) = [M_n 1, M_n x_0, M_n x_1, M_n x_2]: the nodal mass of fmbd_rflex_nodal_mass
// times the four fields by which S1 and XS weigh the motion (1 and the node coordinates x_a),
// summed element by element for the scalar consistent mass (no matrix assembled).
static int mass_moments(const fmbd_fe_body *b, double *m4) {
  int64_t nn = b->nnodes;
  memset(m4, 0, sizeof(double) * (size_t)(4 * nn));
  if (!fmbd_rflex_consistent_invariants(b)) {
    for (int64_t p = 0; p < nn; p++) {
      double m = b->node_mass ? b->node_mass[p] : 0;
      m4[p] = m;
      for (int a = 0; a < 3; a++) m4[nn * (1 + a) + p] = m * b->xyz[3 * p + a];
    }
    return FMBD_OK;
  }
  int k = b->tet_nodes;
  double xyz[30], Me[100], vol;
  for (int64_t e = 0; e < b->ntet; e++) {
    const int64_t *nd = b->tet + (int64_t)k * e;
    for (int i = 0; i < k; i++) memcpy(xyz + 3 * i, b->xyz + 3 * nd[i], 3 * sizeof(double));
    FMBD_CALL(fmbd_fe_tet_matrices(k, xyz, b->E, b->nu, b->rho, e, NULL, Me, &vol));
    for (int i = 0; i < k; i++) {
      double f[4] = {0, 0, 0, 0};
      for (int j = 0; j < k; j++) {
        f[0] += Me[k * i + j];
        for (int a = 0; a < 3; a++) f[1 + a] += Me[k * i + j] * xyz[3 * j + a];
      }
      for (int c = 0; c < 4; c++) m4[nn * c + nd[i]] += f[c];
    }
  }
  return FMBD_OK;
}

// True when the rigid-flexible coupling comes from the full consistent mass (beam elements).
bool fmbd_rflex_beam_coupling(const fmbd_fe_body *b) {
  return b->mass_kind == FMBD_FE_MASS_CONSISTENT && b->nbeam > 0 && b->beam &&
         b->beam_orientation && b->has_section;
}

// W = M U for the nm columns of U (6 nn x nm, column-major, the nodal motion from /expand),
// with M the unconstrained consistent mass of the mesh (never assembled): the scalar consistent
// mass of each tet on the translations, the 12x12 consistent mass of each beam. The body's
// active mass is expand' M expand (ties and clamps applied element by element), so that
// f' M U = (expand' f)' S for every field f of the nodes.
static int consistent_weighted_full(const fmbd_fe_body *b, int64_t nm, const double *U, double *W) {
  int64_t nnodes = b->nnodes;
  int64_t ld = 6 * nnodes;
  memset(W, 0, sizeof(double) * (size_t)(ld * nm));
  if (b->ntet > 0 && b->tet) {
    fmbd_csr *Mn = NULL;
    double *u = fmbd_malloc(sizeof(double) * (size_t)(2 * nnodes + 1)), *w = u + nnodes;
    if (!u) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    int rc = tet_scalar_mass(b, &Mn);
    for (int64_t k = 0; rc == FMBD_OK && k < nm; k++) {
      for (int a = 0; a < 3; a++) {
        for (int64_t p = 0; p < nnodes; p++) u[p] = U[ld * k + 6 * p + a];
        fmbd_csr_matvec(Mn, u, w);
        for (int64_t p = 0; p < nnodes; p++) W[ld * k + 6 * p + a] = w[p];
      }
    }
    fmbd_free(u);
    fmbd_csr_destroy(&Mn);
    FMBD_CALL(rc);
  }
  double Me[144];
  for (int64_t e = 0; e < b->nbeam; e++) {
    const int64_t *nd = b->beam + 2 * e;
    FMBD_CALL(fmbd_fe_beam_matrices(b->xyz + 3 * nd[0], b->xyz + 3 * nd[1],
                                    b->beam_orientation + 3 * e, b->E, b->nu, b->rho, b->area,
                                    b->Iy, b->Iz, b->J, e, NULL, Me));
    for (int64_t k = 0; k < nm; k++) {
      const double *u = U + ld * k;
      double *w = W + ld * k;
      for (int i = 0; i < 12; i++) {
        double acc = 0.0;
        for (int j = 0; j < 12; j++) acc += Me[12 * i + j] * u[6 * nd[j / 6] + j % 6];
        w[6 * nd[i / 6] + i % 6] += acc;
      }
    }
  }
  return FMBD_OK;
}

int fmbd_rflex_rigid_coupling(const fmbd_fe_body *b, double *C) {
  FMBD_CHECK(fmbd_rflex_beam_coupling(b), FMBD_ERR_VALUE,
             "the rigid coupling from the consistent mass is for consistent-mass beam bodies");
  const int64_t nn = b->nnodes, ld = 6 * nn, ndof = b->ndof;
  double *F = fmbd_calloc((size_t)(2 * 6 * ld) + 1, sizeof(double)), *W = F + 6 * ld;
  if (!F) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  for (int64_t p = 0; p < nn; p++) {
    const double *x = b->xyz + 3 * p;
    for (int a = 0; a < 3; a++) {
      F[6 * p + a + ld * a] = 1;  // T_a
      double e[3] = {0, 0, 0}, ex[3];
      e[a] = 1;
      ex[0] = e[1] * x[2] - e[2] * x[1], ex[1] = e[2] * x[0] - e[0] * x[2],
      ex[2] = e[0] * x[1] - e[1] * x[0];
      for (int c = 0; c < 3; c++) F[6 * p + c + ld * (3 + a)] = ex[c];  // R_a: e_a x x0
      F[6 * p + 3 + a + ld * (3 + a)] = 1;                              // and e_a
    }
  }
  int rc = consistent_weighted_full(b, 6, F, W);
  if (rc == FMBD_OK) {  // C = expand' W
    const fmbd_csr *X = b->expand;
    memset(C, 0, sizeof(double) * (size_t)(6 * ndof));
    for (int64_t r = 0; r < X->nrows; r++) {
      for (int64_t e = X->indptr[r]; e < X->indptr[r + 1]; e++) {
        for (int j = 0; j < 6; j++) C[X->indices[e] + ndof * j] += X->data[e] * W[r + ld * j];
      }
    }
  }
  fmbd_free(F);
  return rc;
}

// --- a body from its shapes: the one place of the nodal motion and the invariants ---------
// r already holds nm, ndof, nnodes and shapes (ndof x nm); Mff, Kff (nm x nm, column-major)
// and eig (nm Ritz eigenvalues, > 0) are copied. Everything else is derived here: the
// description, the nodal and interface motion through /expand, the FFRF invariants
// (docs/THEORY.md section 9) and the optional modal stress.
static int rflex_finish(const fmbd_fe_body *b, fmbd_rflex *r, const double *Mff, const double *Kff,
                        const double *eig, bool stress, bool no_ss) {
  int rc = FMBD_OK;
  double *U = NULL, *Wa = NULL, *Ub = NULL, *Sab = NULL, *WM = NULL, *Ui = NULL, *m4 = NULL;
  int64_t *rows = NULL, *cols = NULL;
  fmbd_csr *Mn = NULL, *E = NULL;
  int64_t nm = r->nm, ndof = r->ndof, nn = r->nnodes;
  FMBD_GALLOC(r->eigenvalue = xcalloc((size_t)nm, sizeof(double)));
  FMBD_GALLOC(r->frequency_hz = xcalloc((size_t)nm, sizeof(double)));
  FMBD_GALLOC(r->node_xyz = xcalloc((size_t)(3 * nn), sizeof(double)));
  FMBD_GALLOC(r->node_mass = xcalloc((size_t)nn, sizeof(double)));
  FMBD_GALLOC(r->dofs = xcalloc((size_t)(2 * ndof), sizeof(int64_t)));
  memcpy(r->node_xyz, b->xyz, sizeof(double) * (size_t)(3 * nn));
  if (b->node_mass) {
    memcpy(r->node_mass, b->node_mass, sizeof(double) * (size_t)nn);
  }
  memcpy(r->dofs, b->dofs, sizeof(int64_t) * (size_t)(2 * ndof));
  FMBD_GCALL(fmbd_csr_duplicate(b->expand, &r->expand));
  for (int64_t k = 0; k < nm; k++) {
    r->eigenvalue[k] = eig[k];
    r->frequency_hz[k] = sqrt(fmax(eig[k], 0.0)) / (2 * M_PI);
  }
  // --- nodal motion: the rows of U = expand * shapes ((6 nn) x nm) that are read: the
  // interface nodes' six, the translations of every node (Ub, below) and, for a beam body, all
  // of U. Each row is the same row product whatever rows are taken (fmbd_csr_matmat), so the
  // same bits as the whole U.
  FMBD_GALLOC(cols = fmbd_malloc(sizeof(int64_t) * (size_t)ndof + 1));
  FMBD_GALLOC(rows = fmbd_malloc(sizeof(int64_t) * (size_t)(6 * nn) + 1));
  for (int64_t j = 0; j < ndof; j++) cols[j] = j;
  FMBD_GALLOC(Ui = xcalloc((size_t)(6 * nm) + 1, sizeof(double)));
  // interfaces
  r->ninterfaces = b->ninterfaces;
  FMBD_GALLOC(r->interfaces = xcalloc((size_t)b->ninterfaces, sizeof(fmbd_rflex_interface)));
  for (int i = 0; i < b->ninterfaces; i++) {
    fmbd_rflex_interface *it = &r->interfaces[i];
    const fmbd_fe_interface *fi = &b->interfaces[i];
    FMBD_GALLOC(it->name = fmbd_strdup(fi->name));
    FMBD_GALLOC(it->kind = fmbd_strdup(fi->kind == FMBD_FE_RBE3 ? "rbe3" : "rbe2"));
    it->node = fi->node;
    FMBD_GCHECK(fi->node >= 0 && fi->node < nn, FMBD_ERR_VALUE,
                "interface %s: node %lld out of range", fi->name, (long long)fi->node);
    memcpy(it->x0, b->xyz + 3 * fi->node, sizeof it->x0);
    FMBD_GALLOC(it->translation = xcalloc((size_t)(3 * nm), sizeof(double)));
    FMBD_GALLOC(it->rotation = xcalloc((size_t)(3 * nm), sizeof(double)));
    for (int a = 0; a < 6; a++) rows[a] = 6 * fi->node + a;
    FMBD_GCALL(fmbd_csr_submatrix(b->expand, 6, rows, ndof, cols, &E));
    fmbd_csr_matmat(E, nm, r->shapes, ndof, Ui, 6);
    fmbd_csr_destroy(&E);
    for (int64_t k = 0; k < nm; k++) {
      for (int a = 0; a < 3; a++) {
        it->translation[a + 3 * k] = Ui[a + 6 * k];
        it->rotation[a + 3 * k] = Ui[3 + a + 6 * k];
      }
    }
  }
  // --- FFRF invariants (docs/THEORY.md section 9) ---
  r->mass = b->mass;
  for (int a = 0; a < 3; a++) {
    r->first_moment[a] = b->mass * b->center_of_mass[a];
  }
  {  // J = tr(Ic)/2 I - Ic + m c c'  (inertia Ic = tr(Jc) I - Jc about the centre of mass)
    const double *Ic = b->inertia, *c = b->center_of_mass;
    double tr = Ic[0] + Ic[4] + Ic[8];
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        r->second_moment[a + 3 * bb] = (a == bb ? 0.5 * tr : 0.0) -
                                       0.5 * (Ic[3 * a + bb] + Ic[3 * bb + a]) +
                                       b->mass * c[a] * c[bb];
      }
    }
  }
  FMBD_GALLOC(r->S1 = xcalloc((size_t)(3 * nm), sizeof(double)));
  FMBD_GALLOC(r->XS = xcalloc((size_t)(9 * nm), sizeof(double)));
  FMBD_GALLOC(r->SS = xcalloc((size_t)(9 * nm * nm), sizeof(double)));
  FMBD_GALLOC(r->Mff = xcalloc((size_t)(nm * nm), sizeof(double)));
  FMBD_GALLOC(r->Kff = xcalloc((size_t)(nm * nm), sizeof(double)));
  memcpy(r->Mff, Mff, sizeof(double) * (size_t)(nm * nm));
  memcpy(r->Kff, Kff, sizeof(double) * (size_t)(nm * nm));
  if (nm > 0) {
    // Ub: component b of the nodal motion (nn x nm per b); Wa = M_n Ua, the mass-weighted
    // motion (for SS only), with M_n the body's nodal mass: the scalar consistent mass of the solid
    // elements (the one the modes come from: M = M_n (x) I3 on the translations) for a
    // consistent-mass solid body, else the lumped nodal masses (docs/THEORY.md section 9). Then
    //   S1_k,b = 1' M_n Ub_k,  XS_k,ab = x_a' M_n Ub_k,  SS_kl,ab = Ua_k' M_n Ub_l = Wa_k' Ub_l.
    FMBD_GALLOC(Ub = xcalloc((size_t)(3 * nn * nm), sizeof(double)));
    if (!no_ss) FMBD_GALLOC(Wa = xcalloc((size_t)(3 * nn * nm), sizeof(double)));
    for (int a = 0; a < 3; a++) {  // Ua = the rows 6 p + a of expand, times the shapes
      for (int64_t p = 0; p < nn; p++) rows[p] = 6 * p + a;
      FMBD_GCALL(fmbd_csr_submatrix(b->expand, nn, rows, ndof, cols, &E));
      fmbd_csr_matmat(E, nm, r->shapes, ndof, Ub + nn * a * nm, nn);
      fmbd_csr_destroy(&E);
    }
    // S1 and XS weigh the motion by four fields (M_n symmetric): S1_k,b = (M_n 1)' Ub_k,
    // XS_k,ab = (M_n x_a)' Ub_k, formed element by element (mass_moments); the 3 nm products
    // M_n Ub only for SS
    FMBD_GALLOC(m4 = xcalloc((size_t)(4 * nn), sizeof(double)));
    FMBD_GCALL(mass_moments(b, m4));
    for (int bb = 0; bb < 3; bb++) {
      for (int64_t k = 0; k < nm; k++) {
        const double *u = Ub + nn * (bb * nm + k);
        double s1 = 0.0, xs[3] = {0.0, 0.0, 0.0};
        for (int64_t p = 0; p < nn; p++) {
          s1 += m4[p] * u[p];
          for (int a = 0; a < 3; a++) xs[a] += m4[nn * (1 + a) + p] * u[p];
        }
        r->S1[bb + 3 * k] = s1;
        for (int a = 0; a < 3; a++) r->XS[a + 3 * bb + 9 * k] = xs[a];
      }
    }
    if (!no_ss) {
      FMBD_GCALL(fmbd_rflex_nodal_mass(b, &Mn));
      fmbd_csr_matmat(Mn, 3 * nm, Ub, nn, Wa, nn);
    }
    if (fmbd_rflex_beam_coupling(b)) {
      // the rigid-flexible coupling from the consistent mass M the modes come from (docs/THEORY.md
      // section 9): with WM = M U, S1_k,a = T_a' WM_k (T_a: unit translation a at every node,
      // no rotation) and v_k,a = R_a' WM_k (R_a: rotation about axis a through the frame
      // origin, e_a x x0 at the translations, e_a at the rotations). v_k is M_wf[:,k] at q = 0,
      // eps_abc XS_bc,k: it replaces the antisymmetric part of XS_k; the symmetric part stays
      // the lumped one (it only enters J(q) - J0, at first order in q). (The same numbers as
      // fmbd_rflex_rigid_coupling's C' shapes, which the full FE bodies use; summed in this
      // order they keep the reduced bodies' round-off, to which the QZ reference of
      // tests/py/test_gmsolve.py is sensitive.)
      FMBD_GALLOC(U = xcalloc((size_t)(6 * nn * nm), sizeof(double)));
      fmbd_csr_matmat(b->expand, nm, r->shapes, ndof, U, 6 * nn);
      FMBD_GALLOC(WM = xcalloc((size_t)(6 * nn * nm), sizeof(double)));
      FMBD_GCALL(consistent_weighted_full(b, nm, U, WM));
      for (int64_t k = 0; k < nm; k++) {
        const double *w = WM + 6 * nn * k;
        double s1[3] = {0.0, 0.0, 0.0}, v[3] = {0.0, 0.0, 0.0};
        for (int64_t p = 0; p < nn; p++) {
          const double *x = r->node_xyz + 3 * p, *f = w + 6 * p;
          for (int a = 0; a < 3; a++) s1[a] += f[a];
          v[0] += x[1] * f[2] - x[2] * f[1] + f[3];
          v[1] += x[2] * f[0] - x[0] * f[2] + f[4];
          v[2] += x[0] * f[1] - x[1] * f[0] + f[5];
        }
        double *xs = r->XS + 9 * k;  // xs[a + 3 b] = XS_ab,k
        for (int a = 0; a < 3; a++) {
          r->S1[a + 3 * k] = s1[a];
          for (int bb = a + 1; bb < 3; bb++) {
            double sym = 0.5 * (xs[a + 3 * bb] + xs[bb + 3 * a]);
            // antisymmetric part A_ab = eps_cab v_c / 2
            int c = 3 - a - bb;
            double eps = ((a + 1) % 3 == bb) ? 1.0 : -1.0;  // eps_c a bb = eps_a bb c
            xs[a + 3 * bb] = sym + 0.5 * eps * v[c];
            xs[bb + 3 * a] = sym - 0.5 * eps * v[c];
          }
        }
      }
    }
    // SS: products of nm x nn by nn x nm, the largest part of the build with many modes; a
    // body for partial inertia coupling takes it as zero (fmbd_mbs_add_flex), so none is made.
    // M_n symmetric: SS_lk,ba = Ub_l' M_n Ua_k = SS_kl,ab, so the 6 products a <= b give all 9
    r->ss_omitted = no_ss;
    FMBD_GALLOC(Sab = xcalloc((size_t)(nm * nm), sizeof(double)));
    for (int a = 0; a < 3 && !no_ss; a++) {
      for (int bb = a; bb < 3; bb++) {
        fmbd_dense_gemm('T', 'N', nm, nm, nn, 1.0, Wa + nn * a * nm, nn, Ub + nn * bb * nm, nn, 0.0,
                        Sab, nm);
        for (int64_t l = 0; l < nm; l++) {
          for (int64_t k = 0; k < nm; k++) {
            r->SS[a + 3 * bb + 9 * k + 9 * nm * l] = Sab[k + nm * l];
            if (bb != a) r->SS[bb + 3 * a + 9 * l + 9 * nm * k] = Sab[k + nm * l];
          }
        }
      }
    }
  }
  // --- modal stress ---
  // from the solid elements only: without any (beams, springs, a lost /mesh/elements) it would
  // be zero everywhere, so none is made (r->stress = NULL; callers say so)
  if (stress) FMBD_GCALL(fmbd_rflex_form_stress(r, b, -1, NULL));
done:
  fmbd_free(U);
  fmbd_free(Ui);
  fmbd_free(m4);
  fmbd_free(rows);
  fmbd_free(cols);
  fmbd_csr_destroy(&E);
  fmbd_free(Wa);
  fmbd_free(Ub);
  fmbd_csr_destroy(&Mn);
  fmbd_free(Sab);
  fmbd_free(WM);
  return rc;
}

int fmbd_rflex_form_stress(fmbd_rflex *r, const fmbd_fe_body *b, int64_t nsel,
                           const int64_t *nodes) {
  int rc = FMBD_OK;
  int64_t nm = r->nm, nn = r->nnodes, ns = 0, *list = NULL, *srow = NULL;
  double *sig = NULL;
  FMBD_CHECK(!r->held && b->nnodes == nn && b->ndof == r->ndof, FMBD_ERR_VALUE,
             "modal stress: the body (%lld nodes, %lld dofs%s) is not the description's (%lld "
             "nodes, %lld dofs)",
             (long long)nn, (long long)r->ndof, r->held ? ", a subset" : "", (long long)b->nnodes,
             (long long)b->ndof);
  fmbd_free(r->stress);
  fmbd_free(r->stress_row);
  r->stress = NULL;
  r->stress_row = NULL;
  r->nstress = 0;
  // from the solid elements only: without any (beams, springs, a lost /mesh/elements) it would
  // be zero everywhere, so none is made (r->stress = NULL; callers say so)
  if (nm == 0 || b->ntet == 0) return FMBD_OK;
  if (!nodes) {
    FMBD_GALLOC(sig = xcalloc((size_t)(6 * nn * nm), sizeof(double)));
    FMBD_GCALL(fmbd_fe_nodal_stress(b, nm, r->shapes, sig));
    ns = nn;
  } else {  // rows in node order, each node once
    FMBD_GALLOC(srow = fmbd_malloc(sizeof(int64_t) * (size_t)(nn + 1)));
    FMBD_GALLOC(list = fmbd_malloc(sizeof(int64_t) * (size_t)(nsel + 1)));
    for (int64_t p = 0; p < nn; p++) srow[p] = -1;
    for (int64_t i = 0; i < nsel; i++) {
      FMBD_GCHECK(nodes[i] >= 0 && nodes[i] < nn, FMBD_ERR_VALUE,
                  "modal stress: node %lld out of range (%lld nodes)", (long long)nodes[i],
                  (long long)nn);
      srow[nodes[i]] = 0;
    }
    for (int64_t p = 0; p < nn; p++) {
      if (srow[p] == 0) list[ns] = p, srow[p] = ns++;
    }
    FMBD_GALLOC(sig = xcalloc((size_t)(6 * ns * nm), sizeof(double)));
    FMBD_GCALL(fmbd_fe_nodal_stress_at(b, nm, r->shapes, ns, list, sig));
  }
  r->stress = sig;
  r->stress_row = srow;
  r->nstress = ns;
  sig = NULL;
  srow = NULL;
done:
  fmbd_free(sig);
  fmbd_free(srow);
  fmbd_free(list);
  return rc;
}

// the description checks shared by both producers
static int check_body(const fmbd_fe_body *b) {
  FMBD_CHECK(b && b->expand, FMBD_ERR_VALUE, "the body description has no /expand");
  FMBD_CHECK(b->expand->nrows == 6 * b->nnodes && b->expand->ncols == b->ndof, FMBD_ERR_VALUE,
             "/expand is %lld x %lld, expected %lld x %lld", (long long)b->expand->nrows,
             (long long)b->expand->ncols, (long long)(6 * b->nnodes), (long long)b->ndof);
  return FMBD_OK;
}

// --- secondary reduction ------------------------------------------------------------------
// *release (in->release) freed and set NULL once the shapes are formed
static int rflex_build(const fmbd_rflex_input *in, double **release, fmbd_rflex **out) {
  int rc = FMBD_OK;
  fmbd_rflex *r = NULL;
  double *Wa = NULL, *Mff = NULL, *Kff = NULL;
  const fmbd_fe_body *b = in->body;
  int64_t ns = in->ns, nb = in->nb, nd = in->nd, nm = in->nm;
  *out = NULL;
  // --- check inputs ---
  FMBD_CALL(check_body(b));
  // ns + nb < ndof: the rest are held dofs (fe2cb --method nm --hold), zero in every mode
  FMBD_CHECK(ns + nb <= b->ndof, FMBD_ERR_VALUE,
             "%lld interior + %lld boundary dofs, but the body has %lld dofs", (long long)ns,
             (long long)nb, (long long)b->ndof);
  FMBD_CHECK(nm >= 0 && in->ldxi >= nd + nb && (nd == 0 || in->ldphi >= ns), FMBD_ERR_VALUE,
             "inconsistent sizes of the reduced modes");
  for (int64_t k = 0; k < nm; k++) {
    FMBD_CHECK(in->chibar[k] > 0, FMBD_ERR_VALUE, "flexible mode %lld has eigenvalue %g",
               (long long)k + 1, in->chibar[k]);
  }
  FMBD_GALLOC(r = fmbd_calloc(1, sizeof(*r)));
  int64_t ndof = b->ndof;
  r->nm = nm;
  r->ndof = ndof;
  r->nnodes = b->nnodes;
  FMBD_GALLOC(r->shapes = xcalloc((size_t)(ndof * nm), sizeof(double)));
  // --- shapes: qs = Phi_d Xi_d + Psi Xi_b, qb = Xi_b ---
  // interior dofs 0..ns-1 in order (fe2cb's usual partition): qs straight into the shapes' rows
  // (the same products, another leading dimension), else through an ns x nm copy
  bool direct = true;
  for (int64_t i = 0; i < ns && direct; i++) direct = in->interior_dofs[i] == i;
  if (!direct) FMBD_GALLOC(Wa = xcalloc((size_t)(ns * nm), sizeof(double)));
  double *Q = direct ? r->shapes : Wa;
  int64_t ldq = direct ? ndof : ns;
  if (nd > 0) {
    fmbd_dense_gemm('N', 'N', ns, nm, nd, 1.0, in->Phi, in->ldphi, in->Xi, in->ldxi, 0.0, Q, ldq);
  }
  if (nb > 0) {
    fmbd_dense_gemm('N', 'N', ns, nm, nb, 1.0, in->Psi, ns, in->Xi + nd, in->ldxi, 1.0, Q, ldq);
  }
  for (int64_t k = 0; k < nm; k++) {
    for (int64_t i = 0; i < ns && !direct; i++) {
      int64_t row = in->interior_dofs[i];
      FMBD_GCHECK(row >= 0 && row < ndof, FMBD_ERR_VALUE, "interior dof %lld out of range",
                  (long long)row);
      r->shapes[row + ndof * k] = Wa[i + ns * k];
    }
    for (int64_t j = 0; j < nb; j++) {
      int64_t row = in->boundary_dofs[j];
      FMBD_GCHECK(row >= 0 && row < ndof, FMBD_ERR_VALUE, "boundary dof %lld out of range",
                  (long long)row);
      r->shapes[row + ndof * k] = in->Xi[nd + j + in->ldxi * k];
    }
  }
  fmbd_free(Wa);  // not held through rflex_finish's arrays (ns x nm: the peak memory)
  Wa = NULL;
  fmbd_free(*release);  // Phi, when the caller hands it over
  *release = NULL;
  // mass-normalised modes of the reduced problem: Mff = I, Kff = diag(chibar)
  FMBD_GALLOC(Mff = xcalloc((size_t)(nm * nm), sizeof(double)));
  FMBD_GALLOC(Kff = xcalloc((size_t)(nm * nm), sizeof(double)));
  for (int64_t k = 0; k < nm; k++) {
    Mff[k + nm * k] = 1.0;
    Kff[k + nm * k] = in->chibar[k];
  }
  FMBD_GCALL(rflex_finish(b, r, Mff, Kff, in->chibar, in->stress, in->no_ss));
  *out = r;
  r = NULL;
done:
  fmbd_free(Wa);
  fmbd_free(Mff);
  fmbd_free(Kff);
  fmbd_rflex_destroy(&r);
  return rc;
}

int fmbd_rflex_build(const fmbd_rflex_input *in, fmbd_rflex **out) {
  double *release = in->release;
  int rc = rflex_build(in, &release, out);
  fmbd_free(release);
  return rc;
}

// --- any basis of displacement fields ---------------------------------------------------------
int fmbd_rflex_from_basis(const fmbd_rflex_basis *in, fmbd_rflex **out) {
  int rc = FMBD_OK;
  fmbd_rflex *r = NULL;
  double *Mff = NULL, *Kff = NULL, *W = NULL, *A = NULL, *B = NULL, *eig = NULL;
  const fmbd_fe_body *b = in->body;
  int64_t nm = in->nm;
  *out = NULL;
  FMBD_CALL(check_body(b));
  int64_t ndof = b->ndof;
  FMBD_CHECK(nm >= 0 && in->lds >= ndof && in->S, FMBD_ERR_VALUE,
             "a basis of %lld shapes with leading dimension %lld for a body of %lld dofs",
             (long long)nm, (long long)in->lds, (long long)ndof);
  bool sparse = in->M && in->K;
  FMBD_CHECK(sparse || (in->Mff && in->Kff), FMBD_ERR_VALUE,
             "a basis needs the body's M and K, or its projections Mff and Kff");
  if (sparse) {
    FMBD_CHECK(in->M->nrows == ndof && in->M->ncols == ndof && in->K->nrows == ndof &&
                   in->K->ncols == ndof,
               FMBD_ERR_VALUE, "M or K is not %lld x %lld", (long long)ndof, (long long)ndof);
  }
  FMBD_GALLOC(r = fmbd_calloc(1, sizeof(*r)));
  r->nm = nm;
  r->ndof = ndof;
  r->nnodes = b->nnodes;
  FMBD_GALLOC(r->shapes = xcalloc((size_t)(ndof * nm), sizeof(double)));
  for (int64_t k = 0; k < nm; k++) {
    memcpy(r->shapes + ndof * k, in->S + in->lds * k, sizeof(double) * (size_t)ndof);
  }
  FMBD_GALLOC(Mff = xcalloc((size_t)(nm * nm), sizeof(double)));
  FMBD_GALLOC(Kff = xcalloc((size_t)(nm * nm), sizeof(double)));
  if (sparse) {  // Mff = S' M S, Kff = S' K S
    FMBD_GALLOC(W = xcalloc((size_t)(ndof * nm), sizeof(double)));
    fmbd_csr_matmat(in->M, nm, r->shapes, ndof, W, ndof);
    fmbd_dense_gemm('T', 'N', nm, nm, ndof, 1.0, r->shapes, ndof, W, ndof, 0.0, Mff, nm);
    fmbd_csr_matmat(in->K, nm, r->shapes, ndof, W, ndof);
    fmbd_dense_gemm('T', 'N', nm, nm, ndof, 1.0, r->shapes, ndof, W, ndof, 0.0, Kff, nm);
  } else {
    memcpy(Mff, in->Mff, sizeof(double) * (size_t)(nm * nm));
    memcpy(Kff, in->Kff, sizeof(double) * (size_t)(nm * nm));
  }
  for (int64_t l = 0; l < nm; l++) {  // exact symmetry (round-off of the products)
    for (int64_t k = 0; k < l; k++) {
      double m = 0.5 * (Mff[k + nm * l] + Mff[l + nm * k]);
      double kk = 0.5 * (Kff[k + nm * l] + Kff[l + nm * k]);
      Mff[k + nm * l] = Mff[l + nm * k] = m;
      Kff[k + nm * l] = Kff[l + nm * k] = kk;
    }
  }
  // the body's eigenvalues in this basis (Ritz values of Kff x = w Mff x) for /modes/eigenvalue;
  // a dependent basis makes Mff singular: refused
  FMBD_GALLOC(A = xcalloc((size_t)(nm * nm), sizeof(double)));
  FMBD_GALLOC(B = xcalloc((size_t)(nm * nm), sizeof(double)));
  FMBD_GALLOC(eig = xcalloc((size_t)nm, sizeof(double)));
  memcpy(A, Kff, sizeof(double) * (size_t)(nm * nm));
  memcpy(B, Mff, sizeof(double) * (size_t)(nm * nm));
  if (in->semidefinite) {
    for (int64_t k = 0; k < nm; k++) {
      double mk = Mff[k + nm * k];
      eig[k] = mk > 0 ? Kff[k + nm * k] / mk : 0.0;
    }
  } else {
    rc = fmbd_dense_sygv(nm, A, B, eig);
  }
  if (rc == FMBD_ERR_SINGULAR) {
    FMBD_GFAIL(FMBD_ERR_VALUE,
               "the %lld shapes of the basis are linearly dependent (S'MS is not positive "
               "definite)",
               (long long)nm);
  }
  FMBD_GCALL(rc);
  FMBD_GCALL(rflex_finish(b, r, Mff, Kff, eig, in->stress, false));
  *out = r;
  r = NULL;
done:
  fmbd_free(Mff);
  fmbd_free(Kff);
  fmbd_free(W);
  fmbd_free(A);
  fmbd_free(B);
  fmbd_free(eig);
  fmbd_rflex_destroy(&r);
  return rc;
}

// --- file I/O --------------------------------------------------------------------------------
// /subset/{nodes,stress_nodes} and the subset's /dofs and /expand (docs/FORMAT.md)
static int write_subset(fmbd_h5 *f, const fmbd_rflex *r) {
  int rc = FMBD_OK;
  int64_t *list = NULL, n = 0, ns = 0;
  FMBD_GALLOC(list = fmbd_malloc(sizeof(int64_t) * (size_t)(r->nnodes + 1)));
  for (int64_t p = 0; p < r->nnodes; p++) {
    if (r->held[p] & FMBD_RFLEX_HELD_MOTION) list[n++] = p;
  }
  int64_t d1[1] = {n};
  FMBD_GCALL(fmbd_h5_write_i64(f, "/subset/nodes", 1, d1, list));
  for (int64_t p = 0; p < r->nnodes; p++) {
    if (r->stress_row && r->stress_row[p] >= 0) list[ns++] = p;  // rows in node order
  }
  d1[0] = ns;
  FMBD_GCALL(fmbd_h5_write_i64(f, "/subset/stress_nodes", 1, d1, list));
  FMBD_GCALL(fmbd_h5_write_attr_i64(f, "/subset", "whole_ndof", 1, &r->whole_ndof));
  int64_t dd[2] = {r->ndof, 2};
  FMBD_GCALL(fmbd_h5_write_i64(f, "/dofs", 2, dd, r->dofs));
  FMBD_GCALL(fmbd_h5_write_csr(f, "/expand", r->expand));
done:
  fmbd_free(list);
  return rc;
}

int fmbd_rflex_write(fmbd_h5 *f, const fmbd_rflex *r) {
  int rc = FMBD_OK;
  double *buf = NULL;
  int64_t nm = r->nm, nn = r->nnodes;
  char path[512];
  int64_t d1[1] = {nm};
  FMBD_GCHECK(!r->ss_omitted, FMBD_ERR_VALUE,
              "a body built for partial inertia coupling (SS not formed) is not written");
  FMBD_GCHECK(!r->stress_row || r->held, FMBD_ERR_VALUE,
              "a body whose modal stress was formed at %lld selected nodes only "
              "(fmbd_rflex_form_stress) is not written: form it at every node",
              (long long)r->nstress);
  FMBD_GCALL(fmbd_h5_write_f64(f, "/modes/eigenvalue", 1, d1, r->eigenvalue));
  FMBD_GCALL(fmbd_h5_write_f64(f, "/modes/frequency_hz", 1, d1, r->frequency_hz));
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/modes/shapes", r->ndof, nm, r->shapes));
  if (r->held) {  // a subset body: its own /dofs, /expand, and the nodes it holds
    nn = r->stress_row ? r->nstress : 0;
  }
  size_t big = (size_t)(9 * nm * nm);
  if (r->stress && (size_t)(6 * nn * nm) > big) {
    big = (size_t)(6 * nn * nm);
  }
  FMBD_GALLOC(buf = xcalloc(big, sizeof(double)));
  if (r->stress) {  // file (nnodes, 6, Nm): [(p*6 + i)*nm + k]
    for (int64_t k = 0; k < nm; k++) {
      for (int64_t p = 0; p < nn; p++) {
        for (int i = 0; i < 6; i++) {
          buf[(p * 6 + i) * nm + k] = r->stress[i + 6 * p + 6 * nn * k];
        }
      }
    }
    int64_t d3[3] = {nn, 6, nm};
    FMBD_GCALL(fmbd_h5_write_f64(f, "/modes/stress", 3, d3, buf));
  }
  if (r->held) FMBD_GCALL(write_subset(f, r));
  for (int i = 0; i < r->ninterfaces; i++) {
    const fmbd_rflex_interface *it = &r->interfaces[i];
    snprintf(path, sizeof path, "/interfaces/%s/translation", it->name);
    FMBD_GCALL(fmbd_h5_write_f64_cm(f, path, 3, nm, it->translation));
    snprintf(path, sizeof path, "/interfaces/%s/rotation", it->name);
    FMBD_GCALL(fmbd_h5_write_f64_cm(f, path, 3, nm, it->rotation));
  }
  int64_t d0[1] = {1};
  FMBD_GCALL(fmbd_h5_write_f64(f, "/ffrf/mass", 0, d0, &r->mass));
  int64_t d3v[1] = {3};
  FMBD_GCALL(fmbd_h5_write_f64(f, "/ffrf/first_moment", 1, d3v, r->first_moment));
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/ffrf/second_moment", 3, 3, r->second_moment));
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/ffrf/S1", 3, nm, r->S1));
  for (int64_t k = 0; k < nm; k++) {  // file (3, 3, Nm): [(a*3 + b)*nm + k]
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        buf[(a * 3 + bb) * nm + k] = r->XS[a + 3 * bb + 9 * k];
      }
    }
  }
  int64_t dxs[3] = {3, 3, nm};
  FMBD_GCALL(fmbd_h5_write_f64(f, "/ffrf/XS", 3, dxs, buf));
  for (int64_t l = 0; l < nm; l++) {  // file (3, 3, Nm, Nm): [((a*3 + b)*nm + k)*nm + l]
    for (int64_t k = 0; k < nm; k++) {
      for (int a = 0; a < 3; a++) {
        for (int bb = 0; bb < 3; bb++) {
          buf[((a * 3 + bb) * nm + k) * nm + l] = r->SS[a + 3 * bb + 9 * k + 9 * nm * l];
        }
      }
    }
  }
  int64_t dss[4] = {3, 3, nm, nm};
  FMBD_GCALL(fmbd_h5_write_f64(f, "/ffrf/SS", 4, dss, buf));
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/ffrf/Mff", nm, nm, r->Mff));
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/ffrf/Kff", nm, nm, r->Kff));
done:
  fmbd_free(buf);
  return rc;
}

int fmbd_rflex_read(fmbd_h5 *f, fmbd_rflex **out) {
  int rc = FMBD_OK;
  fmbd_rflex *r = NULL;
  double *buf = NULL, *tmp = NULL;
  int64_t *itmp = NULL;
  char **names = NULL;
  int nnames = 0;
  char path[512];
  *out = NULL;
  FMBD_GCALL(fmbd_h5_check_format(f, FMBD_RFLEX_FORMAT, FMBD_RFLEX_MAJOR));
  FMBD_GALLOC(r = fmbd_calloc(1, sizeof(*r)));
  // --- description ---
  int64_t dn[2] = {-1, 3};
  FMBD_GCALL(fmbd_h5_read_f64(f, "/mesh/nodes", 2, dn,
                              &r->node_xyz));  // row-major (nn,3) = 3 x nn col-major
  int64_t nn = r->nnodes = dn[0];
  int64_t dm[1] = {nn};
  FMBD_GCALL(fmbd_h5_read_f64(f, "/mesh/node_mass", 1, dm, &r->node_mass));
  int64_t dd[2] = {-1, 2};
  FMBD_GCALL(fmbd_h5_read_i64(f, "/dofs", 2, dd, &r->dofs));
  int64_t ndof = r->ndof = dd[0];
  FMBD_GCALL(fmbd_h5_read_csr(f, "/expand", &r->expand));
  if (r->expand->nrows != 6 * nn || r->expand->ncols != ndof) {
    fmbd_err_context(fmbd_h5_name(f), "/expand");
    FMBD_GFAIL(FMBD_ERR_FORMAT, "shape %lld x %lld, expected %lld x %lld",
               (long long)r->expand->nrows, (long long)r->expand->ncols, (long long)(6 * nn),
               (long long)ndof);
  }
  // --- modes ---
  int64_t de[1] = {-1};
  FMBD_GCALL(fmbd_h5_read_f64(f, "/modes/eigenvalue", 1, de, &r->eigenvalue));
  int64_t nm = r->nm = de[0];
  de[0] = nm;
  FMBD_GCALL(fmbd_h5_read_f64(f, "/modes/frequency_hz", 1, de, &r->frequency_hz));
  int64_t rows = ndof, cols = nm;
  FMBD_GCALL(fmbd_h5_read_f64_cm(f, "/modes/shapes", &rows, &cols, &r->shapes));
  int64_t nsr = nn;                    // rows of /modes/stress
  if (fmbd_h5_exists(f, "/subset")) {  // a subset body: the nodes it holds
    int64_t dk[1] = {-1};
    FMBD_GCALL(fmbd_h5_read_i64(f, "/subset/nodes", 1, dk, &itmp));
    FMBD_GALLOC(r->held = xcalloc((size_t)nn + 1, 1));
    for (int64_t i = 0; i < dk[0]; i++) {
      fmbd_err_context(fmbd_h5_name(f), "/subset/nodes");
      FMBD_GCHECK(itmp[i] >= 0 && itmp[i] < nn, FMBD_ERR_FORMAT, "node %lld out of range",
                  (long long)itmp[i]);
      r->held[itmp[i]] = FMBD_RFLEX_HELD_MOTION;
    }
    fmbd_free(itmp);
    itmp = NULL;
    dk[0] = -1;
    FMBD_GCALL(fmbd_h5_read_i64(f, "/subset/stress_nodes", 1, dk, &itmp));
    FMBD_GALLOC(r->stress_row = fmbd_malloc(sizeof(int64_t) * (size_t)(nn + 1)));
    for (int64_t p = 0; p < nn; p++) r->stress_row[p] = -1;
    for (int64_t i = 0; i < dk[0]; i++) {
      fmbd_err_context(fmbd_h5_name(f), "/subset/stress_nodes");
      FMBD_GCHECK(itmp[i] >= 0 && itmp[i] < nn && r->held[itmp[i]], FMBD_ERR_FORMAT,
                  "node %lld out of range or not in /subset/nodes", (long long)itmp[i]);
      r->stress_row[itmp[i]] = i;
      r->held[itmp[i]] |= FMBD_RFLEX_HELD_STRESS;
    }
    fmbd_err_context("", "");
    nsr = r->nstress = dk[0];
    FMBD_GCALL(fmbd_h5_read_attr_i64(f, "/subset", "whole_ndof", 1, &r->whole_ndof));
    fmbd_free(itmp);
    itmp = NULL;
  }
  if (fmbd_h5_exists(f, "/modes/stress")) {
    int64_t ds[3] = {nsr, 6, nm};
    FMBD_GCALL(fmbd_h5_read_f64(f, "/modes/stress", 3, ds, &buf));
    FMBD_GALLOC(r->stress = xcalloc((size_t)(6 * nsr * nm + 1), sizeof(double)));
    for (int64_t k = 0; k < nm; k++) {
      for (int64_t p = 0; p < nsr; p++) {
        for (int i = 0; i < 6; i++) {
          r->stress[i + 6 * p + 6 * nsr * k] = buf[(p * 6 + i) * nm + k];
        }
      }
    }
    fmbd_free(buf);
    buf = NULL;
  }
  // --- interfaces ---
  FMBD_GCALL(fmbd_h5_list(f, "/interfaces", &nnames, &names));
  FMBD_GALLOC(r->interfaces = xcalloc((size_t)nnames, sizeof(fmbd_rflex_interface)));
  for (int i = 0; i < nnames; i++) {
    fmbd_rflex_interface *it = &r->interfaces[i];
    r->ninterfaces = i + 1;
    snprintf(path, sizeof path, "/interfaces/%s", names[i]);
    FMBD_GALLOC(it->name = fmbd_strdup(names[i]));
    FMBD_GCALL(fmbd_h5_read_attr_i64(f, path, "node", 1, &it->node));
    if (it->node < 0 || it->node >= nn) {
      fmbd_err_context(fmbd_h5_name(f), path);
      FMBD_GFAIL(FMBD_ERR_FORMAT, "attribute node = %lld out of range (%lld nodes)",
                 (long long)it->node, (long long)nn);
    }
    if (fmbd_h5_has_attr(f, path, "kind")) {
      FMBD_GCALL(fmbd_h5_read_attr_str(f, path, "kind", &it->kind));
    } else {
      FMBD_GALLOC(it->kind = fmbd_strdup("rbe2"));
    }
    memcpy(it->x0, r->node_xyz + 3 * it->node, sizeof it->x0);
    snprintf(path, sizeof path, "/interfaces/%s/translation", names[i]);
    rows = 3;
    cols = nm;
    FMBD_GCALL(fmbd_h5_read_f64_cm(f, path, &rows, &cols, &it->translation));
    snprintf(path, sizeof path, "/interfaces/%s/rotation", names[i]);
    rows = 3;
    cols = nm;
    FMBD_GCALL(fmbd_h5_read_f64_cm(f, path, &rows, &cols, &it->rotation));
  }
  // --- ffrf ---
  int64_t d0[1] = {1};
  FMBD_GCALL(fmbd_h5_read_f64(f, "/ffrf/mass", 0, d0, &tmp));
  r->mass = tmp[0];
  fmbd_free(tmp);
  tmp = NULL;
  int64_t d3[1] = {3};
  FMBD_GCALL(fmbd_h5_read_f64(f, "/ffrf/first_moment", 1, d3, &tmp));
  memcpy(r->first_moment, tmp, sizeof r->first_moment);
  fmbd_free(tmp);
  tmp = NULL;
  rows = 3;
  cols = 3;
  FMBD_GCALL(fmbd_h5_read_f64_cm(f, "/ffrf/second_moment", &rows, &cols, &tmp));
  memcpy(r->second_moment, tmp, sizeof r->second_moment);
  fmbd_free(tmp);
  tmp = NULL;
  rows = 3;
  cols = nm;
  FMBD_GCALL(fmbd_h5_read_f64_cm(f, "/ffrf/S1", &rows, &cols, &r->S1));
  int64_t dxs[3] = {3, 3, nm};
  FMBD_GCALL(fmbd_h5_read_f64(f, "/ffrf/XS", 3, dxs, &buf));
  FMBD_GALLOC(r->XS = xcalloc((size_t)(9 * nm), sizeof(double)));
  for (int64_t k = 0; k < nm; k++) {
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        r->XS[a + 3 * bb + 9 * k] = buf[(a * 3 + bb) * nm + k];
      }
    }
  }
  fmbd_free(buf);
  buf = NULL;
  int64_t dss[4] = {3, 3, nm, nm};
  FMBD_GCALL(fmbd_h5_read_f64(f, "/ffrf/SS", 4, dss, &buf));
  FMBD_GALLOC(r->SS = xcalloc((size_t)(9 * nm * nm), sizeof(double)));
  for (int64_t l = 0; l < nm; l++) {
    for (int64_t k = 0; k < nm; k++) {
      for (int a = 0; a < 3; a++) {
        for (int bb = 0; bb < 3; bb++) {
          r->SS[a + 3 * bb + 9 * k + 9 * nm * l] = buf[((a * 3 + bb) * nm + k) * nm + l];
        }
      }
    }
  }
  rows = nm;
  cols = nm;
  FMBD_GCALL(fmbd_h5_read_f64_cm(f, "/ffrf/Mff", &rows, &cols, &r->Mff));
  rows = nm;
  cols = nm;
  FMBD_GCALL(fmbd_h5_read_f64_cm(f, "/ffrf/Kff", &rows, &cols, &r->Kff));
  // --- physical data, checked where it is read (a defect here surfaces much later as "Newton
  // did not converge" or a silently wrong motion) ---
  {
    const char *fn = fmbd_h5_name(f), *why = NULL;
    fmbd_err_context(fn, "/ffrf/mass");
    FMBD_GCHECK(r->mass > 0 && isfinite(r->mass), FMBD_ERR_VALUE, "mass %g must be positive",
                r->mass);
    double Ic[9], c[3], tr = r->second_moment[0] + r->second_moment[4] + r->second_moment[8];
    for (int a = 0; a < 3; a++) c[a] = r->first_moment[a] / r->mass;
    for (int a = 0; a < 3; a++) {  // inertia about the centre of mass: tr(Jc) 1 - Jc
      for (int bb = 0; bb < 3; bb++) {
        double jc = r->second_moment[a + 3 * bb] - r->mass * c[a] * c[bb];
        double trc = tr - r->mass * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        Ic[a + 3 * bb] = (a == bb ? trc : 0.0) - jc;
      }
    }
    fmbd_err_context(fn, "/ffrf/second_moment");
    FMBD_GCHECK(fmbd_dense_inertia_ok(Ic, &why), FMBD_ERR_VALUE,
                "the inertia it gives about the centre of mass is not physical: %s", why);
    double kmax = 0.0;
    for (int64_t k = 0; k < nm; k++) kmax = fmax(kmax, fabs(r->Kff[k + nm * k]));
    for (int64_t l = 0; l < nm; l++) {
      for (int64_t k = 0; k < nm; k++) {
        fmbd_err_context(fn, "/ffrf/Mff");
        FMBD_GCHECK(
            isfinite(r->Mff[k + nm * l]) && fabs(r->Mff[k + nm * l] - r->Mff[l + nm * k]) <= 1e-9,
            FMBD_ERR_VALUE, "not symmetric at (%lld, %lld)", (long long)k, (long long)l);
        fmbd_err_context(fn, "/ffrf/Kff");
        FMBD_GCHECK(isfinite(r->Kff[k + nm * l]) &&
                        fabs(r->Kff[k + nm * l] - r->Kff[l + nm * k]) <= 1e-9 * kmax,
                    FMBD_ERR_VALUE, "not symmetric at (%lld, %lld)", (long long)k, (long long)l);
      }
      fmbd_err_context(fn, "/ffrf/Mff");
      FMBD_GCHECK(r->Mff[l + nm * l] > 0, FMBD_ERR_VALUE, "diagonal entry %lld is %g: not positive",
                  (long long)l, r->Mff[l + nm * l]);
      fmbd_err_context(fn, "/ffrf/Kff");
      FMBD_GCHECK(r->Kff[l + nm * l] >= 0, FMBD_ERR_VALUE, "diagonal entry %lld is %g: negative",
                  (long long)l, r->Kff[l + nm * l]);
      // the modes are mass-normalised: Kff's diagonal is their eigenvalues
      FMBD_GCHECK(fabs(r->Mff[l + nm * l] - 1.0) > 1e-9 ||
                      fabs(r->Kff[l + nm * l] - r->eigenvalue[l]) <= 1e-9 * kmax,
                  FMBD_ERR_VALUE, "diagonal entry %lld is %.10g but /modes/eigenvalue says %.10g",
                  (long long)l, r->Kff[l + nm * l], r->eigenvalue[l]);
    }
    fmbd_err_context("", "");
  }
  *out = r;
  r = NULL;
done:
  for (int i = 0; i < nnames; i++) {
    fmbd_free(names[i]);
  }
  fmbd_free(names);
  fmbd_free(buf);
  fmbd_free(tmp);
  fmbd_free(itmp);
  fmbd_rflex_destroy(&r);
  return rc;
}
