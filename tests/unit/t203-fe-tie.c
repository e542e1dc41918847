// tests/unit/t203-fe-tie.c: interface ties and clamps: RBE2 exact elimination (T' K T against a
// dense product, rigid motion, slave kinematics), RBE3 (weighted least-squares average, rigid
// motion, interface dofs active), clamped interfaces, conflicts and degenerate RBE3 groups
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "t2_mesh.h"

// append a group of the nodes satisfying pred
static void add_group(fmbd_mesh *m, const char *name, int (*pred)(const double *x)) {
  int g = m->ngroups;
  int64_t n0 = m->group_ptr[g], k = 0;
  m->group_name = fmbd_realloc(m->group_name, (g + 1) * sizeof *m->group_name);
  m->group_ptr = fmbd_realloc(m->group_ptr, (g + 2) * sizeof *m->group_ptr);
  m->group_node = fmbd_realloc(m->group_node, (n0 + m->nnodes) * sizeof *m->group_node);
  m->group_name[g] = fmbd_strdup(name);
  for (int64_t p = 0; p < m->nnodes; p++) {
    if (pred(m->xyz + 3 * p)) m->group_node[n0 + k++] = p;
  }
  m->group_ptr[g + 1] = n0 + k;
  m->ngroups = g + 1;
}
static int on_edge(const double *x) {
  return fabs(x[1]) < 1e-12 && fabs(x[2]) < 1e-12;
}
static int two_nodes(const double *x) {
  return fabs(x[1]) < 1e-12 && fabs(x[2]) < 1e-12 && x[0] < 0.4;
}
static int top_face(const double *x) {
  return fabs(x[2] - 0.5) < 1e-12;
}

// u = u0 + th x (x - x0) at every active dof; rotations th
static double *rigid_q(const fmbd_fe_body *b, const double u0[3], const double th[3],
                       const double x0[3]) {
  double *q = fmbd_malloc(b->ndof * sizeof *q);
  for (int64_t i = 0; i < b->ndof; i++) {
    int64_t p = b->dofs[2 * i], d = b->dofs[2 * i + 1];
    const double *x = b->xyz + 3 * p;
    double r[3] = {x[0] - x0[0], x[1] - x0[1], x[2] - x0[2]};
    double t[3] = {u0[0] + th[1] * r[2] - th[2] * r[1], u0[1] + th[2] * r[0] - th[0] * r[2],
                   u0[2] + th[0] * r[1] - th[1] * r[0]};
    q[i] = d < 3 ? t[d] : th[d - 3];
  }
  return q;
}

static double max_abs(const double *v, int64_t n) {
  double m = 0.0;
  for (int64_t i = 0; i < n; i++) m = fmax(m, fabs(v[i]));
  return m;
}

static int count_rigid(const fmbd_fe_body *b) {
  int64_t n = b->ndof;
  double *K = csr_dense(b->K), *M = csr_dense(b->M), *w = fmbd_malloc(n * sizeof *w);
  EXPECT(fmbd_dense_sygv(n, K, M, w) == FMBD_OK, "sygv");
  int nz = 0;
  // rounding ~1e-12 of the largest eigenvalue; flexible ones above 1e-4 of it on these meshes
  for (int64_t i = 0; i < n; i++) nz += fabs(w[i]) < 1e-8 * w[n - 1];
  fmbd_free(K);
  fmbd_free(M);
  fmbd_free(w);
  return nz;
}

// rigid motion about x0 gives zero force, and expands to the same rigid field at every node
static void rigid_checks(const fmbd_fe_body *b, const char *what, const double x0[3]) {
  const double u0[3] = {1e-3, -2e-3, 5e-4}, th[3] = {2e-3, 1e-3, -3e-3};
  double *q = rigid_q(b, u0, th, x0), *f = fmbd_malloc(b->ndof * sizeof *f);
  double *u = fmbd_malloc(6 * b->nnodes * sizeof *u);
  fmbd_csr_matvec(b->K, q, f);
  double fm = max_abs(f, b->ndof), ref = fmbd_csr_max_abs(b->K) * max_abs(q, b->ndof);
  // rounding: ~1e-16 per term, tens of terms per row (more on RBE3 rows): 1e-12 of |K||q|
  EXPECT(fm < 1e-12 * ref, "%s: rigid motion gives force %.3g (|K||q| = %.3g)", what, fm, ref);
  fmbd_csr_matvec(b->expand, q, u);
  double err = 0.0;
  for (int64_t p = 0; p < b->nmesh_nodes; p++) {
    const double *x = b->xyz + 3 * p;
    double r[3] = {x[0] - x0[0], x[1] - x0[1], x[2] - x0[2]};
    double t[3] = {u0[0] + th[1] * r[2] - th[2] * r[1], u0[1] + th[2] * r[0] - th[0] * r[2],
                   u0[2] + th[0] * r[1] - th[1] * r[0]};
    bool clamped = false;
    for (int k = 0; k < b->nclamped; k++) {
      for (int64_t i = 0; i < b->clamped[k].nnodes; i++) clamped |= b->clamped[k].nodes[i] == p;
    }
    if (!clamped) {
      for (int d = 0; d < 3; d++) err = fmax(err, fabs(u[6 * p + d] - t[d]));
    }
  }
  EXPECT(err < 1e-14, "%s: expanded rigid motion off by %.3g", what, err);
  // a unit translation carries the whole mass through the tie: q' M q = m (clamped bodies excepted)
  if (b->nclamped == 0) {
    const double ex[3] = {1, 0, 0}, zero[3] = {0, 0, 0};
    double *t = rigid_q(b, ex, zero, x0), mq = 0.0;
    fmbd_csr_matvec(b->M, t, f);
    for (int64_t i = 0; i < b->ndof; i++) mq += t[i] * f[i];
    EXPECT(fabs(mq - b->mass) < 1e-13 * b->mass, "%s: translational mass %.17g vs %.17g", what, mq,
           b->mass);
    fmbd_free(t);
  }
  fmbd_free(q);
  fmbd_free(f);
  fmbd_free(u);
}

// K_tied against the dense T' K_free T, T from the expansion rows of the full dofs
static void dense_ptap_check(const fmbd_fe_body *tied, const fmbd_fe_body *free_b,
                             const char *what) {
  int64_t nf = free_b->ndof, na = tied->ndof;   // free_b: every mesh node has 3 dofs
  double *T = fmbd_calloc(nf * na, sizeof *T);  // column-major nf x na
  for (int64_t i = 0; i < nf; i++) {
    int64_t p = free_b->dofs[2 * i], d = free_b->dofs[2 * i + 1], r = 6 * p + d;
    for (int64_t k = tied->expand->indptr[r]; k < tied->expand->indptr[r + 1]; k++) {
      T[i + nf * tied->expand->indices[k]] = tied->expand->data[k];
    }
  }
  for (int which = 0; which < 2; which++) {
    double *A = csr_dense(which ? free_b->M : free_b->K), *AT = fmbd_malloc(nf * na * sizeof *AT);
    double *R = fmbd_malloc(na * na * sizeof *R), *D = csr_dense(which ? tied->M : tied->K);
    fmbd_dense_gemm('N', 'N', nf, na, nf, 1.0, A, nf, T, nf, 0.0, AT, nf);
    fmbd_dense_gemm('T', 'N', na, na, nf, 1.0, T, nf, AT, nf, 0.0, R, na);
    double err = 0.0, scale = max_abs(R, na * na);
    for (int64_t i = 0; i < na * na; i++) err = fmax(err, fabs(R[i] - D[i]));
    // the same sums in another order: rounding of ~1e-15 of the largest entry
    EXPECT(err < 1e-13 * scale, "%s: %s differs from dense T'AT by %.3g of %.3g", what,
           which ? "M" : "K", err, scale);
    fmbd_free(A);
    fmbd_free(AT);
    fmbd_free(R);
    fmbd_free(D);
  }
  fmbd_free(T);
}

static void test_rbe2(fmbd_fe_mass_kind mass) {
  fmbd_mesh mesh;
  box_mesh(&mesh, 1.0, 0.5, 0.5, 3, 2, 2, 1);
  fmbd_fe_opts o = t2_soft_options();
  o.mass = mass;
  fmbd_fe_body *free_b = NULL, *b = NULL;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &free_b) == FMBD_OK, "free: %s", fmbd_err_get()->msg);
  fmbd_fe_interface_spec it = {.group = "xmin", .kind = FMBD_FE_RBE2};
  o.ninterfaces = 1;
  o.interfaces = &it;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &b) == FMBD_OK, "rbe2: %s", fmbd_err_get()->msg);
  if (b && free_b) {
    int g = fmbd_mesh_find_group(&mesh, "xmin");
    int64_t ng = mesh.group_ptr[g + 1] - mesh.group_ptr[g];
    EXPECT(b->nnodes == mesh.nnodes + 1 && b->nmesh_nodes == mesh.nnodes, "node counts");
    EXPECT(b->ndof == 3 * (mesh.nnodes - ng) + 6, "rbe2: %lld dofs", (long long)b->ndof);
    const fmbd_fe_interface *fi = &b->interfaces[0];
    EXPECT(fi->node == mesh.nnodes && fi->nnodes == ng && fi->kind == FMBD_FE_RBE2,
           "interface record");
    EXPECT(fabs(fi->point[0]) < 1e-15 && fabs(fi->point[1] - 0.25) < 1e-15 &&
               fabs(fi->point[2] - 0.25) < 1e-15,
           "centroid (%g %g %g)", fi->point[0], fi->point[1], fi->point[2]);
    for (int d = 0; d < 6; d++)
      EXPECT(fmbd_fe_dof(b, fi->node, d) >= 0, "interface dof %d active", d);
    EXPECT(b->node_mass[fi->node] == 0.0, "interface node mass");
    EXPECT(fabs(b->mass - free_b->mass) < 1e-14 * b->mass, "mass unchanged by the tie");
    dense_ptap_check(b, free_b, "rbe2");
    rigid_checks(b, "rbe2", fi->point);
    EXPECT(count_rigid(b) == 6, "rbe2: rigid-body modes");
    // slave kinematics for an arbitrary q: u_s = u_m + theta_m x (x_s - x_m)
    double *q = fmbd_malloc(b->ndof * sizeof *q), *u = fmbd_malloc(6 * b->nnodes * sizeof *u);
    for (int64_t i = 0; i < b->ndof; i++) q[i] = sin(1.0 + 3.7 * i);
    fmbd_csr_matvec(b->expand, q, u);
    const double *um = u + 6 * fi->node, *tm = um + 3;
    double err = 0.0;
    for (int64_t i = 0; i < fi->nnodes; i++) {
      int64_t p = fi->nodes[i];
      const double *x = b->xyz + 3 * p;
      double r[3] = {x[0] - fi->point[0], x[1] - fi->point[1], x[2] - fi->point[2]};
      double t[3] = {um[0] + tm[1] * r[2] - tm[2] * r[1], um[1] + tm[2] * r[0] - tm[0] * r[2],
                     um[2] + tm[0] * r[1] - tm[1] * r[0]};
      for (int d = 0; d < 3; d++) err = fmax(err, fabs(u[6 * p + d] - t[d]));
      EXPECT(fmbd_fe_dof(b, p, 0) < 0, "slave %lld has no active dof", (long long)p);
    }
    EXPECT(err < 1e-15, "rbe2 slave kinematics off by %.3g", err);
    fmbd_free(q);
    fmbd_free(u);
  }
  fmbd_fe_body_destroy(&b);
  // clamping the RBE2 interface equals clamping the group
  const char *cl[1] = {"xmin"};
  o.nclamps = 1;
  o.clamps = cl;
  fmbd_fe_body *bi = NULL, *bg = NULL;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &bi) == FMBD_OK, "rbe2 clamped: %s", fmbd_err_get()->msg);
  o.ninterfaces = 0;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &bg) == FMBD_OK, "group clamped: %s", fmbd_err_get()->msg);
  if (bi && bg) {
    EXPECT(bi->ndof == bg->ndof, "clamped dofs %lld vs %lld", (long long)bi->ndof,
           (long long)bg->ndof);
    EXPECT(bi->nclamped == 1 && bi->clamped[0].nnodes == 1 &&
               bi->clamped[0].nodes[0] == bi->interfaces[0].node,
           "clamped interface records its node");
    double *Ki = csr_dense(bi->K), *Kg = csr_dense(bg->K), err = 0.0;
    for (int64_t i = 0; i < bi->ndof * bi->ndof; i++) err = fmax(err, fabs(Ki[i] - Kg[i]));
    EXPECT(err < 1e-14 * fmbd_csr_max_abs(bg->K),
           "clamped RBE2 vs clamped group: K differs by %.3g", err);
    fmbd_free(Ki);
    fmbd_free(Kg);
    EXPECT(count_rigid(bi) == 0, "clamped: no rigid modes");
  }
  fmbd_fe_body_destroy(&bi);
  fmbd_fe_body_destroy(&bg);
  fmbd_fe_body_destroy(&free_b);
  fmbd_mesh_destroy(&mesh);
}

static void test_rbe3(void) {
  fmbd_mesh mesh;
  box_mesh(&mesh, 1.0, 0.5, 0.5, 3, 2, 2, 2);
  fmbd_fe_opts o = t2_soft_options();
  fmbd_fe_interface_spec it[2] = {
      {.group = "xmax", .kind = FMBD_FE_RBE3, .has_point = true, .point = {1.1, 0.3, 0.2}},
      {.group = "xmin", .kind = FMBD_FE_RBE2}};
  o.ninterfaces = 2;
  o.interfaces = it;
  fmbd_fe_body *b = NULL, *free_b = NULL;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &b) == FMBD_OK, "rbe3: %s", fmbd_err_get()->msg);
  o.ninterfaces = 0;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &free_b) == FMBD_OK, "free: %s", fmbd_err_get()->msg);
  if (b && free_b) {
    const fmbd_fe_interface *fi = &b->interfaces[0];
    int64_t ng2 = b->interfaces[1].nnodes;
    EXPECT(b->ndof == 3 * mesh.nnodes - 6 + 6 - 3 * ng2 + 6, "rbe3: %lld dofs", (long long)b->ndof);
    for (int d = 0; d < 6; d++)
      EXPECT(fmbd_fe_dof(b, fi->node, d) >= 0, "rbe3 interface dof %d active", d);
    dense_ptap_check(b, free_b, "rbe3 + rbe2");
    rigid_checks(b, "rbe3 + rbe2 (about the RBE2 master)", b->interfaces[1].point);
    EXPECT(count_rigid(b) == 6, "rbe3: rigid-body modes");
    // the reference node's motion is the least-squares rigid fit of the group's translations:
    // normal equations H [u; th] = sum A_i' u_i, solved here by Cholesky
    double *q = fmbd_malloc(b->ndof * sizeof *q), *u = fmbd_malloc(6 * b->nnodes * sizeof *u);
    for (int64_t i = 0; i < b->ndof; i++) q[i] = cos(0.3 + 1.9 * i);
    fmbd_csr_matvec(b->expand, q, u);
    double H[36] = {0}, rhs[6] = {0};
    for (int64_t i = 0; i < fi->nnodes; i++) {
      const double *x = b->xyz + 3 * fi->nodes[i], *ui = u + 6 * fi->nodes[i];
      double r[3] = {x[0] - fi->point[0], x[1] - fi->point[1], x[2] - fi->point[2]};
      // rows of A_i: u + th x r  ->  [I | -[r]x]
      double A[3][6] = {
          {1, 0, 0, 0, r[2], -r[1]}, {0, 1, 0, -r[2], 0, r[0]}, {0, 0, 1, r[1], -r[0], 0}};
      for (int p = 0; p < 6; p++) {
        for (int k = 0; k < 3; k++) rhs[p] += A[k][p] * ui[k];
        for (int s = 0; s < 6; s++) {
          for (int k = 0; k < 3; k++) H[p + 6 * s] += A[k][p] * A[k][s];
        }
      }
    }
    EXPECT(fmbd_dense_chol(6, H) == FMBD_OK, "H positive definite");
    fmbd_dense_chol_solve(6, H, 1, rhs, 6);
    double err = 0.0, scale = max_abs(rhs, 6);
    for (int d = 0; d < 6; d++) err = fmax(err, fabs(u[6 * fi->node + d] - rhs[d]));
    // two different solves of a 6x6 system with condition ~1e2: 1e-12 relative
    EXPECT(err < 1e-12 * scale,
           "rbe3: reference motion differs from the weighted average by %.3g (of %.3g)", err,
           scale);
    fmbd_free(q);
    fmbd_free(u);
  }
  fmbd_fe_body_destroy(&b);
  fmbd_fe_body_destroy(&free_b);
  fmbd_mesh_destroy(&mesh);
}

static void expect_error(const fmbd_mesh *mesh, const fmbd_fe_opts *o, const char *what,
                         const char *s1, const char *s2) {
  fmbd_fe_body *b = NULL;
  fmbd_err_clear();
  int rc = fmbd_fe_assemble(mesh, o, &b);
  EXPECT(rc == FMBD_ERR_VALUE && b == NULL, "%s: rc %d", what, rc);
  const char *msg = fmbd_err_get()->msg;
  EXPECT(strstr(msg, s1) && (!s2 || strstr(msg, s2)), "%s: message \"%s\" lacks \"%s\"/\"%s\"",
         what, msg, s1, s2 ? s2 : "");
  fmbd_fe_body_destroy(&b);
}

static void test_errors(void) {
  fmbd_mesh mesh;
  box_mesh(&mesh, 1.0, 0.5, 0.5, 3, 2, 2, 1);
  add_group(&mesh, "edge", on_edge);
  add_group(&mesh, "pair", two_nodes);
  add_group(&mesh, "top", top_face);
  fmbd_fe_opts o = t2_soft_options();
  fmbd_fe_interface_spec it[2] = {{.group = "edge", .kind = FMBD_FE_RBE3},
                                  {.group = "top", .kind = FMBD_FE_RBE2}};
  o.ninterfaces = 1;
  o.interfaces = it;
  expect_error(&mesh, &o, "collinear RBE3", "interface edge", "non-collinear");
  it[0].group = "pair";
  expect_error(&mesh, &o, "two-node RBE3", "interface pair", "2 nodes");
  it[0].group = "nosuch";
  expect_error(&mesh, &o, "missing group", "\"nosuch\" not found", NULL);
  // overlapping ties: the top face and the y = z = 0 edge do not meet, xmin and top do
  it[0].group = "xmin";
  it[0].kind = FMBD_FE_RBE2;
  o.ninterfaces = 2;
  expect_error(&mesh, &o, "overlap", "belongs to interfaces xmin and top", NULL);
  // a tied node clamped through another group
  o.ninterfaces = 1;
  const char *cl[1] = {"all"};
  o.nclamps = 1;
  o.clamps = cl;
  expect_error(&mesh, &o, "tied and clamped", "both clamped and tied to interface xmin", NULL);
  cl[0] = "ghost";
  expect_error(&mesh, &o, "clamp missing", "clamp ghost", "not found");
  // a clamped RBE3 group with the reference free is fine: the top face clamped, RBE3 on xmax:
  // the translations of the clamped nodes simply drop out
  o.nclamps = 0;
  fmbd_mesh_destroy(&mesh);
}

static void test_beam_tie(void) {
  // a beam whose end node is an RBE2 slave of an offset master: clamping the master clamps the
  // end (6-dof slave, rotations equal), so K equals the directly clamped cantilever
  const double p0[3] = {0, 0, 0}, p1[3] = {1, 0, 0};
  fmbd_mesh mesh;
  beam_mesh(&mesh, p0, p1, 8);
  fmbd_fe_opts o = t2_soft_options();
  o.area = 1e-4;
  o.Iy = 1e-9;
  o.Iz = 2e-9;
  o.J = 3e-9;
  const char *cl[1] = {"end0"};
  o.nclamps = 1;
  o.clamps = cl;
  fmbd_fe_body *bg = NULL, *bi = NULL;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &bg) == FMBD_OK, "beam clamped: %s", fmbd_err_get()->msg);
  fmbd_fe_interface_spec it = {
      .group = "end0", .kind = FMBD_FE_RBE2, .has_point = true, .point = {-0.2, 0.1, 0.0}};
  o.ninterfaces = 1;
  o.interfaces = &it;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &bi) == FMBD_OK, "beam rbe2 clamped: %s", fmbd_err_get()->msg);
  if (bg && bi) {
    EXPECT(bi->ndof == bg->ndof, "dofs %lld vs %lld", (long long)bi->ndof, (long long)bg->ndof);
    double *Ki = csr_dense(bi->K), *Kg = csr_dense(bg->K), err = 0.0;
    for (int64_t i = 0; i < bi->ndof * bi->ndof; i++) err = fmax(err, fabs(Ki[i] - Kg[i]));
    EXPECT(err < 1e-14 * fmbd_csr_max_abs(bg->K),
           "beam: clamped RBE2 vs clamped end: K differs by %.3g", err);
    fmbd_free(Ki);
    fmbd_free(Kg);
  }
  fmbd_fe_body_destroy(&bi);
  // free: the rigid motion about the master is stress-free, rotations of the slave follow
  o.nclamps = 0;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &bi) == FMBD_OK, "beam rbe2: %s", fmbd_err_get()->msg);
  if (bi) {
    rigid_checks(bi, "beam rbe2", it.point);
    EXPECT(count_rigid(bi) == 6, "beam rbe2: rigid modes");
  }
  fmbd_fe_body_destroy(&bi);
  o.mass = FMBD_FE_MASS_LUMPED;  // lumped beam mass through the tie (general element path)
  EXPECT(fmbd_fe_assemble(&mesh, &o, &bi) == FMBD_OK, "beam rbe2 lumped: %s", fmbd_err_get()->msg);
  if (bi) {
    rigid_checks(bi, "beam rbe2 lumped", it.point);
    EXPECT(count_rigid(bi) == 6, "beam rbe2 lumped: rigid modes");
  }
  fmbd_fe_body_destroy(&bi);
  fmbd_fe_body_destroy(&bg);
  fmbd_mesh_destroy(&mesh);
}

int main(void) {
  test_rbe2(FMBD_FE_MASS_CONSISTENT);
  test_rbe2(FMBD_FE_MASS_LUMPED);  // T' D T of the HRZ diagonal: no longer diagonal on the master
  test_rbe3();
  test_errors();
  test_beam_tie();
  TEST_EXIT();
}
