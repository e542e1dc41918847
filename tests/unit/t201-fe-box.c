// tests/unit/t201-fe-box.c: assembled solid bodies (tet4, tet10, curved tet10): symmetry,
// positive mass, six rigid-body modes, mass = rho V, body properties, HRZ totals, patch tests
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "fmbd_rflex.h"
#include "t2_mesh.h"

static const double E = 70e9, NU = 0.33, RHO = 2700;

// exact moments of the sheared box z' = z + eps (x y + x^2) over [0,a]x[0,b]x[0,c] (det = 1),
// by a 3-point Gauss-Legendre tensor rule (exact to degree 5 per variable; the integrands here
// have degree <= 4): m, first moments S1 and second moments S2[i][j] = int rho x'_i x'_j
static void sheared_moments(double a, double b, double c, double eps, double *m, double S1[3],
                            double S2[9]) {
  const double g[3] = {-sqrt(0.6), 0.0, sqrt(0.6)}, w[3] = {5.0 / 9, 8.0 / 9, 5.0 / 9};
  *m = 0.0;
  memset(S1, 0, 3 * sizeof(double));
  memset(S2, 0, 9 * sizeof(double));
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) {
      for (int k = 0; k < 3; k++) {
        double x = a * (1 + g[i]) / 2, y = b * (1 + g[j]) / 2, z = c * (1 + g[k]) / 2;
        double p[3] = {x, y, z + eps * (x * y + x * x)};
        double ww = RHO * w[i] * w[j] * w[k] * a * b * c / 8;
        *m += ww;
        for (int s = 0; s < 3; s++) {
          S1[s] += ww * p[s];
          for (int t = 0; t < 3; t++) S2[s * 3 + t] += ww * p[s] * p[t];
        }
      }
    }
  }
}

static int count_rigid(const fmbd_fe_body *b, double *wmax_out) {
  int64_t n = b->ndof;
  double *K = csr_dense(b->K), *M = csr_dense(b->M), *w = fmbd_malloc(n * sizeof *w);
  int rc = fmbd_dense_sygv(n, K, M, w);
  EXPECT(rc == FMBD_OK, "sygv failed: %d", rc);
  int nz = 0;
  // rigid eigenvalues are rounding noise: |w| ~ 1e-16 * |K| / |M| ~ 1e-16 * w_max * (ratio of
  // the largest to the smallest eigenvalues' scales) ~ 1e-12 w_max here; flexible ones are above
  // 1e-4 w_max for these small meshes, so 1e-8 w_max separates them
  for (int64_t i = 0; i < n; i++) nz += fabs(w[i]) < 1e-8 * w[n - 1];
  if (wmax_out) *wmax_out = w[n - 1];
  fmbd_free(K);
  fmbd_free(M);
  fmbd_free(w);
  return nz;
}

// 1' M_d 1 for the translation in direction d
static double translation_mass(const fmbd_fe_body *b, int d) {
  double *u = fmbd_calloc(b->ndof, sizeof *u), *f = fmbd_malloc(b->ndof * sizeof *f), s = 0.0;
  for (int64_t i = 0; i < b->ndof; i++) u[i] = b->dofs[2 * i + 1] == d;
  fmbd_csr_matvec(b->M, u, f);
  for (int64_t i = 0; i < b->ndof; i++) s += u[i] * f[i];
  fmbd_free(u);
  fmbd_free(f);
  return s;
}

// patch test: u = s_c (G x) + t_c for 20 cases c (two blocks of the stress routine), s_c =
// 1 + c/10; nodal stresses equal s_c D eps(G) everywhere; with `interior`, K u = 0 on the dofs of
// nodes strictly inside the box
#define NCASES 20
static void patch_test(const fmbd_fe_body *b, const char *what, double a, double bb, double c,
                       bool interior) {
  const double G[9] = {1e-3, 2e-4, -3e-4, 5e-4, -7e-4, 1e-4, -2e-4, 6e-4, 4e-4};
  double *q = fmbd_malloc(NCASES * b->ndof * sizeof *q), *f = fmbd_malloc(b->ndof * sizeof *f);
  double *sig = fmbd_malloc(NCASES * b->nnodes * 6 * sizeof *sig);
  for (int cs = 0; cs < NCASES; cs++) {
    for (int64_t i = 0; i < b->ndof; i++) {
      int64_t p = b->dofs[2 * i], d = b->dofs[2 * i + 1];
      const double *x = b->xyz + 3 * p;
      q[cs * b->ndof + i] =
          (1 + 0.1 * cs) * (G[d * 3] * x[0] + G[d * 3 + 1] * x[1] + G[d * 3 + 2] * x[2]) +
          1e-3 * (d + 1) * cs;
    }
  }
  EXPECT(fmbd_fe_nodal_stress(b, NCASES, q, sig) == FMBD_OK, "%s: nodal stress", what);
  const double lam = E * NU / ((1 + NU) * (1 - 2 * NU)), mu = E / (2 * (1 + NU));
  double tr = G[0] + G[4] + G[8];
  double ex[6] = {lam * tr + 2 * mu * G[0], lam * tr + 2 * mu * G[4], lam * tr + 2 * mu * G[8],
                  mu * (G[1] + G[3]),       mu * (G[5] + G[7]),       mu * (G[2] + G[6])};
  double smax = 0.0, err = 0.0;
  for (int i = 0; i < 6; i++) smax = fmax(smax, fabs(ex[i]));
  for (int cs = 0; cs < NCASES; cs++) {
    for (int64_t p = 0; p < b->nnodes; p++) {
      for (int i = 0; i < 6; i++) {
        err = fmax(
            err, fabs(sig[(cs * b->nnodes + p) * 6 + i] - (1 + 0.1 * cs) * ex[i]) / (1 + 0.1 * cs));
      }
    }
  }
  // exact up to rounding: gradients of a linear field through J^-1 on unit-size elements
  EXPECT(err <= 1e-12 * smax, "%s: patch test stress error %.3g of %.3g", what, err, smax);
  if (interior) {
    fmbd_csr_matvec(b->K, q, f);
    double kmax = fmbd_csr_max_abs(b->K), qmax = 0.0, fmax_in = 0.0, fmax_all = 0.0;
    for (int64_t i = 0; i < b->ndof; i++) qmax = fmax(qmax, fabs(q[i]));
    for (int64_t i = 0; i < b->ndof; i++) {
      const double *x = b->xyz + 3 * b->dofs[2 * i];
      bool inside = x[0] > 1e-9 && x[0] < a - 1e-9 && x[1] > 1e-9 && x[1] < bb - 1e-9 &&
                    x[2] > 1e-9 && x[2] < c - 1e-9;
      if (inside) fmax_in = fmax(fmax_in, fabs(f[i]));
      fmax_all = fmax(fmax_all, fabs(f[i]));
    }
    // interior nodal forces of a constant stress vanish (exact quadrature on straight
    // elements); rounding ~ 1e-16 * 30 terms * |K| |q|
    EXPECT(fmax_in <= 1e-13 * kmax * qmax, "%s: interior force %.3g (|K||q| = %.3g)", what, fmax_in,
           kmax * qmax);
    EXPECT(fmax_all > 1e-6 * kmax * qmax, "%s: boundary forces missing?", what);
  }
  fmbd_free(q);
  fmbd_free(f);
  fmbd_free(sig);
}

// the stress at selected nodes (fmbd_fe_nodal_stress_at; fmbd_rflex_form_stress, which fmbd-run
// uses to form a body's modal stress at the nodes its outputs read only) is bitwise the whole
// field's rows: the same elements summed in the same order. NCASES pseudo-random fields (two
// blocks of the routine; independent, as a basis must be), so every element contributes.
static void selected_stress_test(const fmbd_fe_body *b, const char *what) {
  int64_t nn = b->nnodes, nd = b->ndof;
  double *q = fmbd_malloc(NCASES * nd * sizeof *q), *all = fmbd_malloc(NCASES * nn * 6 * 8);
  double *sel = fmbd_malloc(NCASES * 3 * 6 * sizeof *sel);
  uint64_t x = 12345;  // a linear congruential sequence (Knuth's MMIX constants): independent
  for (int64_t i = 0; i < NCASES * nd; i++) {
    x = x * 6364136223846793005ULL + 1442695040888963407ULL;
    q[i] = ((double)(x >> 11) / 9007199254740992.0 - 0.5) * 1e-3;
  }
  const int64_t nodes[3] = {nn - 1, 0, nn / 2};  // not in node order: rows follow the list
  EXPECT(fmbd_fe_nodal_stress(b, NCASES, q, all) == FMBD_OK, "%s: nodal stress", what);
  EXPECT(fmbd_fe_nodal_stress_at(b, NCASES, q, 3, nodes, sel) == FMBD_OK, "%s: selected: %s", what,
         fmbd_err_get()->msg);
  int differ = 0, nonzero = 0;
  for (int cs = 0; cs < NCASES; cs++) {
    for (int i = 0; i < 3; i++) {
      const double *x = all + (cs * nn + nodes[i]) * 6, *y = sel + (cs * 3 + i) * 6;
      differ += memcmp(x, y, 6 * sizeof(double)) != 0;
      for (int j = 0; j < 6; j++) nonzero += x[j] != 0.0;
    }
  }
  EXPECT(differ == 0 && nonzero > 0, "%s: %d selected rows differ from the whole field's", what,
         differ);
  const int64_t twice[2] = {1, 1}, out[1] = {nn};
  EXPECT(fmbd_fe_nodal_stress_at(b, 1, q, 2, twice, sel) == FMBD_ERR_VALUE &&
             strstr(fmbd_err_get()->msg, "selected twice"),
         "%s: a node selected twice: %s", what, fmbd_err_get()->msg);
  EXPECT(fmbd_fe_nodal_stress_at(b, 1, q, 1, out, sel) == FMBD_ERR_VALUE &&
             strstr(fmbd_err_get()->msg, "out of range"),
         "%s: a node out of range: %s", what, fmbd_err_get()->msg);
  // a modal body of these fields: its stress formed at every node, and at two nodes only
  fmbd_rflex_basis in = {b, b->M, b->K, NCASES, q, nd, NULL, NULL, true, false};
  fmbd_rflex *whole = NULL, *part = NULL;
  EXPECT(fmbd_rflex_from_basis(&in, &whole) == FMBD_OK, "%s: basis: %s", what, fmbd_err_get()->msg);
  in.stress = false;
  EXPECT(fmbd_rflex_from_basis(&in, &part) == FMBD_OK && part && !part->stress,
         "%s: basis without stress", what);
  if (whole && part) {
    const int64_t two[3] = {nn / 2, 0, nn / 2};  // a repeat is one row
    EXPECT(fmbd_rflex_form_stress(part, b, 3, two) == FMBD_OK && part->nstress == 2,
           "%s: form stress: %s", what, fmbd_err_get()->msg);
    double s1[6 * NCASES], s2[6 * NCASES];
    for (int i = 0; i < 2; i++) {
      EXPECT(fmbd_rflex_node_stress(whole, two[i], s1) == FMBD_OK &&
                 fmbd_rflex_node_stress(part, two[i], s2) == FMBD_OK && !memcmp(s1, s2, sizeof s1),
             "%s: modal stress at node %lld differs from the whole field's", what,
             (long long)two[i]);
    }
    EXPECT(fmbd_rflex_node_stress(part, nn - 1, s2) == FMBD_ERR_VALUE &&
               strstr(fmbd_err_get()->msg, "formed at 2 selected nodes only"),
           "%s: a node outside the selection: %s", what, fmbd_err_get()->msg);
  }
  fmbd_rflex_destroy(&whole);
  fmbd_rflex_destroy(&part);
  fmbd_free(q);
  fmbd_free(all);
  fmbd_free(sel);
}

static void check_body(const fmbd_fe_body *b, const char *what, double m, const double S1[3],
                       const double S2[9]) {
  // rigid-body properties from the consistent mass: exact for straight elements and for the
  // quadratic (sheared) geometry (integrands of degree <= 4 against the degree-5 rule)
  EXPECT(fabs(b->mass - m) < 1e-13 * m, "%s: mass %.17g, expected %.17g", what, b->mass, m);
  double c[3], I[9], L = 0.0;
  for (int i = 0; i < 3; i++) c[i] = S1[i] / m;
  for (int i = 0; i < 3; i++) L = fmax(L, fabs(c[i]));
  for (int i = 0; i < 3; i++) {
    EXPECT(fabs(b->center_of_mass[i] - c[i]) < 1e-13 * L, "%s: centre of mass %d: %.17g vs %.17g",
           what, i, b->center_of_mass[i], c[i]);
  }
  // I_c = tr(Jc) I - Jc with Jc = S2 - m c c'
  double Jc[9], tr = 0.0, imax = 0.0;
  for (int i = 0; i < 9; i++) Jc[i] = S2[i] - m * c[i / 3] * c[i % 3];
  tr = Jc[0] + Jc[4] + Jc[8];
  for (int i = 0; i < 9; i++) {
    I[i] = (i % 4 == 0 ? tr : 0.0) - Jc[i];
    imax = fmax(imax, fabs(I[i]));
  }
  for (int i = 0; i < 9; i++) {
    EXPECT(fabs(b->inertia[i] - I[i]) < 1e-12 * imax, "%s: inertia[%d] %.17g vs %.17g", what, i,
           b->inertia[i], I[i]);
  }
  double nm = 0.0;
  for (int64_t p = 0; p < b->nnodes; p++) nm += b->node_mass[p];
  EXPECT(fabs(nm - m) < 1e-13 * m, "%s: sum of HRZ node masses %.17g vs %.17g", what, nm, m);
  for (int d = 0; d < 3; d++) {
    double tm = translation_mass(b, d);
    EXPECT(fabs(tm - m) < 1e-13 * m, "%s: translation %d mass %.17g vs %.17g", what, d, tm, m);
  }
}

static void structure_checks(const fmbd_fe_body *b, const char *what) {
  int64_t bad = -1;
  EXPECT(fmbd_csr_check(b->K) == FMBD_OK && fmbd_csr_check(b->M) == FMBD_OK, "%s: CSR valid", what);
  // symmetric to rounding: K_ab[i][j] and K_ba[j][i] are the same products in another order
  EXPECT(fmbd_csr_is_symmetric(b->K, 1e-14, &bad), "%s: K not symmetric at row %lld", what,
         (long long)bad);
  EXPECT(fmbd_csr_is_symmetric(b->M, 1e-14, &bad), "%s: M not symmetric at row %lld", what,
         (long long)bad);
  double *M = csr_dense(b->M);
  EXPECT(fmbd_dense_chol(b->ndof, M) == FMBD_OK, "%s: M not positive definite", what);
  fmbd_free(M);
  // solid-only nodes: 3 dofs each, node-major; expand = identity on translations, empty rotations
  EXPECT(b->ndof == 3 * b->nnodes, "%s: %lld dofs for %lld nodes", what, (long long)b->ndof,
         (long long)b->nnodes);
  for (int64_t i = 0; i < b->ndof; i++) {
    EXPECT(b->dofs[2 * i] == i / 3 && b->dofs[2 * i + 1] == i % 3, "%s: dof %lld", what,
           (long long)i);
    int64_t r = 6 * (i / 3) + i % 3;
    EXPECT(b->expand->indptr[r + 1] - b->expand->indptr[r] == 1 &&
               b->expand->indices[b->expand->indptr[r]] == i &&
               b->expand->data[b->expand->indptr[r]] == 1.0,
           "%s: expand row %lld", what, (long long)r);
    if (i % 3 == 0) {
      EXPECT(b->expand->indptr[r + 6] == b->expand->indptr[r + 3],
             "%s: rotation rows of node %lld not empty", what, (long long)(i / 3));
    }
    EXPECT(fmbd_fe_dof(b, i / 3, (int)(i % 3)) == i, "fmbd_fe_dof");
  }
  EXPECT(fmbd_fe_dof(b, 0, 3) == -1, "no rotation dof on a solid node");
}

int main(void) {
  fmbd_fe_opts o;
  fmbd_fe_opts_defaults(&o);
  o.E = E;
  o.nu = NU;
  o.rho = RHO;
  const double a = 1.0, bb = 0.5, c = 0.8;
  double m, S1[3], S2[9];
  sheared_moments(a, bb, c, 0.0, &m, S1, S2);
  for (int order = 1; order <= 2; order++) {
    for (int lumped = 0; lumped <= 1; lumped++) {
      char what[64];
      snprintf(what, sizeof what, "tet%d box, %s mass", order == 1 ? 4 : 10,
               lumped ? "lumped" : "consistent");
      fmbd_mesh mesh;
      if (order == 1)
        box_mesh(&mesh, a, bb, c, 3, 2, 3, 1);
      else
        box_mesh(&mesh, a, bb, c, 2, 1, 2, 2);
      o.mass = lumped ? FMBD_FE_MASS_LUMPED : FMBD_FE_MASS_CONSISTENT;
      fmbd_fe_body *b = NULL;
      int rc = fmbd_fe_assemble(&mesh, &o, &b);
      EXPECT(rc == FMBD_OK, "%s: assemble: %s", what, fmbd_err_get()->msg);
      if (rc) continue;
      EXPECT(fabs(b->volume - a * bb * c) < 1e-14, "%s: volume %.17g", what, b->volume);
      structure_checks(b, what);
      check_body(b, what, m, S1, S2);
      int nr = count_rigid(b, NULL);
      EXPECT(nr == 6, "%s: %d rigid-body modes, expected 6", what, nr);
      if (lumped) {
        EXPECT(fmbd_csr_nnz(b->M) == b->ndof, "%s: lumped M has %lld entries for %lld dofs", what,
               (long long)fmbd_csr_nnz(b->M), (long long)b->ndof);
        // the lumped diagonal is the HRZ node mass per translation
        for (int64_t i = 0; i < b->ndof; i++) {
          double d = fmbd_csr_get(b->M, i, i), nmass = b->node_mass[b->dofs[2 * i]];
          EXPECT(fabs(d - nmass) < 1e-13 * m, "%s: M[%lld][%lld] = %g, node mass %g", what,
                 (long long)i, (long long)i, d, nmass);
        }
      }
      patch_test(b, what, a, bb, c, true);
      selected_stress_test(b, what);
      fmbd_fe_body_destroy(&b);
      fmbd_mesh_destroy(&mesh);
    }
  }
  // --- curved tet10: the quadratic shear z' = z + eps (x y + x^2) maps straight edges to parabolas
  {
    const double eps = 0.3;
    fmbd_mesh mesh;
    box_mesh(&mesh, a, bb, c, 2, 2, 2, 2);
    for (int64_t p = 0; p < mesh.nnodes; p++) {
      double *x = mesh.xyz + 3 * p;
      x[2] += eps * (x[0] * x[1] + x[0] * x[0]);
    }
    o.mass = FMBD_FE_MASS_CONSISTENT;
    fmbd_fe_body *b = NULL;
    int rc = fmbd_fe_assemble(&mesh, &o, &b);
    EXPECT(rc == FMBD_OK, "curved: assemble: %s", fmbd_err_get()->msg);
    if (!rc) {
      sheared_moments(a, bb, c, eps, &m, S1, S2);
      EXPECT(fabs(b->volume - a * bb * c) < 1e-14, "curved: volume %.17g (shear keeps %.17g)",
             b->volume, a * bb * c);
      check_body(b, "curved tet10", m, S1, S2);
      int nr = count_rigid(b, NULL);
      EXPECT(nr == 6, "curved: %d rigid-body modes", nr);
      // isoparametric: a linear field in x is reproduced exactly, so nodal stresses are exact
      // even on curved elements (K u = 0 inside does not hold exactly: the 4-point rule is not
      // exact for the curved integrand, so only the stresses are checked)
      patch_test(b, "curved tet10", a, bb, c + eps * (a * bb + a * a), false);
      selected_stress_test(b, "curved tet10");
      fmbd_fe_body_destroy(&b);
    }
    fmbd_mesh_destroy(&mesh);
  }
  // --- lumped mass with a clamped face: the diagonal of every active dof is its node's HRZ mass
  {
    fmbd_mesh mesh;
    box_mesh(&mesh, a, bb, c, 2, 1, 2, 2);
    const char *cl[1] = {"xmin"};
    o.mass = FMBD_FE_MASS_LUMPED;
    o.nclamps = 1;
    o.clamps = cl;
    fmbd_fe_body *b = NULL;
    int rc = fmbd_fe_assemble(&mesh, &o, &b);
    EXPECT(rc == FMBD_OK, "lumped clamped: %s", fmbd_err_get()->msg);
    if (!rc) {
      int g = fmbd_mesh_find_group(&mesh, "xmin");
      EXPECT(b->ndof == 3 * (mesh.nnodes - (mesh.group_ptr[g + 1] - mesh.group_ptr[g])),
             "lumped clamped: dofs");
      EXPECT(fmbd_csr_nnz(b->M) == b->ndof, "lumped clamped: M diagonal");
      double err = 0.0;
      for (int64_t i = 0; i < b->ndof; i++)
        err = fmax(err, fabs(fmbd_csr_get(b->M, i, i) - b->node_mass[b->dofs[2 * i]]));
      EXPECT(err < 1e-13 * b->mass, "lumped clamped: diagonal vs node mass off by %.3g", err);
      EXPECT(count_rigid(b, NULL) == 0, "lumped clamped: no rigid modes");
      fmbd_fe_body_destroy(&b);
    }
    o.nclamps = 0;
    fmbd_mesh_destroy(&mesh);
  }
  // --- mixed solid + beam: a beam of 4 elements sticking out of a box corner, sharing the corner
  // node (6 dofs there: the tets' 3 translations plus the beam's rotations). The shared node
  // passes no moment into the solid, so the beam can also swing rigidly about it: 6 rigid-body
  // modes + 3 mechanism modes
  {
    fmbd_mesh mesh;
    box_mesh(&mesh, a, bb, c, 2, 1, 2, 2);
    int64_t corner = -1, n0 = mesh.nnodes;
    for (int64_t p = 0; p < mesh.nnodes; p++) {
      const double *x = mesh.xyz + 3 * p;
      if (fabs(x[0] - a) + fabs(x[1] - bb) + fabs(x[2] - c) < 1e-12) corner = p;
    }
    mesh.xyz = fmbd_realloc(mesh.xyz, 3 * (n0 + 4) * sizeof(double));
    for (int i = 0; i < 4; i++) {
      mesh.xyz[3 * (n0 + i)] = a + 0.1 * (i + 1);
      mesh.xyz[3 * (n0 + i) + 1] = bb;
      mesh.xyz[3 * (n0 + i) + 2] = c;
    }
    mesh.nnodes = n0 + 4;
    mesh.nbeam = 4;
    mesh.beam = fmbd_malloc(8 * sizeof(int64_t));
    for (int i = 0; i < 4; i++) {
      mesh.beam[2 * i] = i == 0 ? corner : n0 + i - 1;
      mesh.beam[2 * i + 1] = n0 + i;
    }
    o.mass = FMBD_FE_MASS_CONSISTENT;
    o.area = 1e-3;
    o.Iy = 1e-7;
    o.Iz = 2e-7;
    o.J = 3e-7;
    fmbd_fe_body *b = NULL;
    int rc = fmbd_fe_assemble(&mesh, &o, &b);
    EXPECT(rc == FMBD_OK && corner >= 0, "mixed: assemble: %s", fmbd_err_get()->msg);
    if (!rc) {
      EXPECT(b->ndof == 3 * n0 + 3 + 6 * 4, "mixed: %lld dofs", (long long)b->ndof);
      EXPECT(fmbd_fe_dof(b, corner, 5) >= 0, "mixed: the shared node has rotations");
      double mexp = RHO * (a * bb * c + 0.4 * 1e-3);
      EXPECT(fabs(b->mass - mexp) < 1e-13 * mexp, "mixed: mass %.17g vs %.17g", b->mass, mexp);
      int64_t bad = -1;
      EXPECT(fmbd_csr_is_symmetric(b->K, 1e-14, &bad), "mixed: K symmetric (row %lld)",
             (long long)bad);
      int nr = count_rigid(b, NULL);
      EXPECT(nr == 9, "mixed: %d zero-energy modes, expected 6 rigid + 3 pin rotations", nr);
      fmbd_fe_body_destroy(&b);
    }
    fmbd_mesh_destroy(&mesh);
  }
  TEST_EXIT();
}
