// tests/unit/t206-fe-order.c: the assembly's set-wise element loop (fmbd_fe.c, "the order of
// the element loop") gives K, M, the node masses and the mass properties bit for bit as with
// one set, for tet10 and tet4, ties (RBE2, RBE3), clamps, beams on solid nodes, consistent and
// lumped mass; the free bodies also bit for bit as a plain loop over the elements written here;
// and the element order does change K's and M's bits on these meshes (nodes off the grid), so
// the comparisons see an addition out of order
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "fmbd_fe_impl.h"
#include "t2_mesh.h"

// the tetrahedra in a scrambled order (a fixed permutation), as gmsh numbers them: no locality
static void scramble(fmbd_mesh *m, uint64_t seed) {
  const int k = m->tet_nodes;
  int64_t tmp[10];
  for (int64_t e = m->ntet - 1; e > 0; e--) {
    seed = seed * 6364136223846793005ULL + 1442695040888963407ULL;
    int64_t j = (int64_t)((seed >> 33) % (uint64_t)(e + 1));
    memcpy(tmp, m->tet + e * k, (size_t)k * sizeof *tmp);
    memcpy(m->tet + e * k, m->tet + j * k, (size_t)k * sizeof *tmp);
    memcpy(m->tet + j * k, tmp, (size_t)k * sizeof *tmp);
  }
}

// move the nodes off the grid (by up to 3 % of a cell, boundary faces kept plane): elements of
// many shapes, so that the terms added to one entry differ and their order shows in the bits
static void jitter(fmbd_mesh *m, uint64_t seed) {
  const double hi[3] = {1.0, 0.5, 0.5}, h = 0.03 * 0.5 / 3;
  for (int64_t p = 0; p < m->nnodes; p++) {
    for (int k = 0; k < 3; k++) {
      seed = seed * 6364136223846793005ULL + 1442695040888963407ULL;
      double x = m->xyz[3 * p + k], r = (double)(seed >> 11) / 9007199254740992.0 - 0.5;
      if (x > 1e-12 && x < hi[k] - 1e-12) m->xyz[3 * p + k] = x + 2.0 * h * r;
    }
  }
}

static bool same_csr(const fmbd_csr *a, const fmbd_csr *b) {
  if (a->nrows != b->nrows || fmbd_csr_nnz(a) != fmbd_csr_nnz(b)) return false;
  size_t n = (size_t)fmbd_csr_nnz(a);
  return memcmp(a->indptr, b->indptr, ((size_t)a->nrows + 1) * sizeof *a->indptr) == 0 &&
         memcmp(a->indices, b->indices, n * sizeof *a->indices) == 0 &&
         memcmp(a->data, b->data, n * sizeof *a->data) == 0;
}

// every assembled number of a and b equal bit for bit
static bool same_body(const fmbd_fe_body *a, const fmbd_fe_body *b) {
  return a->ndof == b->ndof && a->nnodes == b->nnodes && same_csr(a->K, b->K) &&
         same_csr(a->M, b->M) &&
         memcmp(a->node_mass, b->node_mass, (size_t)a->nnodes * sizeof *a->node_mass) == 0 &&
         memcmp(&a->mass, &b->mass, sizeof a->mass) == 0 &&
         memcmp(&a->volume, &b->volume, sizeof a->volume) == 0 &&
         memcmp(a->center_of_mass, b->center_of_mass, sizeof a->center_of_mass) == 0 &&
         memcmp(a->inertia, b->inertia, sizeof a->inertia) == 0;
}

// A free tet body assembled here by the plain loop, element by element in element order, into
// copies of b's patterns: K, M (consistent Ms (x) I3, or the HRZ diagonal) and the node masses
// must equal b's bit for bit. Independent of the set-wise code, so it also sees an order that
// is wrong the same way in one set and in many.
static bool plain_loop_equal(const fmbd_mesh *m, const fmbd_fe_opts *o, const fmbd_fe_body *b) {
  fmbd_csr *K = NULL, *M = NULL;
  if (fmbd_csr_duplicate(b->K, &K) != FMBD_OK || fmbd_csr_duplicate(b->M, &M) != FMBD_OK)
    return false;
  double *nm = fmbd_calloc((size_t)b->nnodes, sizeof *nm);
  memset(K->data, 0, (size_t)fmbd_csr_nnz(K) * sizeof *K->data);
  memset(M->data, 0, (size_t)fmbd_csr_nnz(M) * sizeof *M->data);
  const int tn = m->tet_nodes;
  bool ok = b->ndof == 3 * m->nnodes;
  for (int64_t e = 0; e < m->ntet && ok; e++) {
    double xe[30], Ke[900], Ms[100], d[10], vol, me = 0.0;
    const int64_t *en = m->tet + e * tn;
    for (int a = 0; a < tn; a++) memcpy(xe + 3 * a, m->xyz + 3 * en[a], 3 * sizeof *xe);
    ok = fmbd_fe_tet_matrices(tn, xe, o->E, o->nu, o->rho, e, Ke, Ms, &vol) == FMBD_OK;
    for (int i = 0; i < tn * tn; i++) me += Ms[i];
    fmbd_fe_hrz_scalar(tn, Ms, me, d);
    for (int a = 0; a < tn && ok; a++) {
      nm[en[a]] += d[a];
      for (int bb = 0; bb < tn && ok; bb++) {
        for (int i = 0; i < 3; i++) {
          for (int j = 0; j < 3; j++) {
            int64_t pos = fmbd_csr_find(K, 3 * en[a] + i, 3 * en[bb] + j);
            ok = ok && pos >= 0;
            if (!ok) break;
            K->data[pos] += Ke[(3 * a + i) * 3 * tn + 3 * bb + j];
            if (i != j) continue;
            if (o->mass == FMBD_FE_MASS_CONSISTENT) {
              M->data[pos] += Ms[a * tn + bb];
            } else if (a == bb) {
              int64_t pm = fmbd_csr_find(M, 3 * en[a] + i, 3 * en[a] + i);
              ok = pm >= 0;
              if (ok) M->data[pm] += d[a];
            }
          }
        }
      }
    }
  }
  ok = ok && same_csr(K, b->K) && same_csr(M, b->M) &&
       memcmp(nm, b->node_mass, (size_t)b->nnodes * sizeof *nm) == 0;
  fmbd_csr_destroy(&K);
  fmbd_csr_destroy(&M);
  fmbd_free(nm);
  return ok;
}

// assemble with one set and with sets of 3, 11 and 40 nodes: all equal to the one-set body
static void check_sets(const char *what, const fmbd_mesh *mesh, const fmbd_fe_opts *o) {
  fmbd_fe_body *ref = NULL;
  fmbd_fe_asm_test.set_nodes = INT64_MAX;
  EXPECT(fmbd_fe_assemble(mesh, o, &ref) == FMBD_OK, "%s: %s", what, fmbd_err_get()->msg);
  EXPECT(fmbd_fe_asm_test.sets_used == 1, "%s: %d sets, not one", what, fmbd_fe_asm_test.sets_used);
  const int64_t sizes[3] = {3, 11, 40};
  for (int i = 0; i < 3 && ref; i++) {
    fmbd_fe_body *b = NULL;
    fmbd_fe_asm_test.set_nodes = sizes[i];
    EXPECT(fmbd_fe_assemble(mesh, o, &b) == FMBD_OK, "%s: %s", what, fmbd_err_get()->msg);
    EXPECT(fmbd_fe_asm_test.sets_used >= (int32_t)((mesh->nnodes + sizes[i] - 1) / sizes[i]),
           "%s: %d sets of %lld nodes", what, fmbd_fe_asm_test.sets_used, (long long)sizes[i]);
    EXPECT(b && same_body(ref, b), "%s: sets of %lld nodes: not bit for bit the plain loop's", what,
           (long long)sizes[i]);
    fmbd_fe_body_destroy(&b);
  }
  fmbd_fe_asm_test.set_nodes = 0;
  fmbd_fe_body_destroy(&ref);
}

static int edge_y0z0(const double *x) {
  return fabs(x[1]) < 1e-12 && fabs(x[2]) < 1e-12;
}

// beams along the box edge y = z = 0 between consecutive nodes there (6-dof solid nodes)
static void add_edge_beams(fmbd_mesh *m) {
  int64_t on[64], n = 0;
  for (int64_t p = 0; p < m->nnodes && n < 64; p++) {
    if (edge_y0z0(m->xyz + 3 * p)) on[n++] = p;
  }
  for (int64_t i = 1; i < n; i++) {  // sort by x
    for (int64_t j = i; j > 0 && m->xyz[3 * on[j]] < m->xyz[3 * on[j - 1]]; j--) {
      int64_t t = on[j];
      on[j] = on[j - 1];
      on[j - 1] = t;
    }
  }
  m->nbeam = n - 1;
  m->beam = fmbd_malloc((size_t)(2 * n) * sizeof *m->beam);
  for (int64_t i = 0; i + 1 < n; i++) {
    m->beam[2 * i] = on[i];
    m->beam[2 * i + 1] = on[i + 1];
  }
}

int main(void) {
  for (int order = 1; order <= 2; order++) {
    fmbd_mesh mesh;
    box_mesh(&mesh, 1.0, 0.5, 0.5, 5, 3, 3, order);
    jitter(&mesh, 99);
    scramble(&mesh, 12345);
    char what[96];
    fmbd_fe_opts o = t2_soft_options();
    // the element order matters: two orders of the same elements give K's differing in bits
    {
      fmbd_mesh m2;
      box_mesh(&m2, 1.0, 0.5, 0.5, 5, 3, 3, order);
      jitter(&m2, 99);
      scramble(&m2, 777);
      fmbd_fe_body *a = NULL, *b = NULL;
      EXPECT(fmbd_fe_assemble(&mesh, &o, &a) == FMBD_OK && fmbd_fe_assemble(&m2, &o, &b) == FMBD_OK,
             "order check: %s", fmbd_err_get()->msg);
      EXPECT(a && b && !same_csr(a->K, b->K) && !same_csr(a->M, b->M),
             "tet%d: two element orders gave K or M with the same bits", order == 1 ? 4 : 10);
      fmbd_fe_body_destroy(&a);
      fmbd_fe_body_destroy(&b);
      fmbd_mesh_destroy(&m2);
    }
    for (int lumped = 0; lumped < 2; lumped++) {
      o.mass = lumped ? FMBD_FE_MASS_LUMPED : FMBD_FE_MASS_CONSISTENT;
      const char *mk = lumped ? "lumped" : "consistent";
      o.ninterfaces = 0;
      o.nclamps = 0;
      snprintf(what, sizeof what, "tet%d %s, free", order == 1 ? 4 : 10, mk);
      check_sets(what, &mesh, &o);
      fmbd_fe_body *b = NULL;
      fmbd_fe_asm_test.set_nodes = 7;
      EXPECT(fmbd_fe_assemble(&mesh, &o, &b) == FMBD_OK, "%s: %s", what, fmbd_err_get()->msg);
      fmbd_fe_asm_test.set_nodes = 0;
      EXPECT(b && plain_loop_equal(&mesh, &o, b), "%s: not bit for bit the plain loop in the test",
             what);
      fmbd_fe_body_destroy(&b);
      fmbd_fe_interface_spec it[2] = {
          {.group = "xmax", .kind = FMBD_FE_RBE3, .has_point = true, .point = {1.1, 0.3, 0.2}},
          {.group = "xmin", .kind = FMBD_FE_RBE2}};
      o.ninterfaces = 2;
      o.interfaces = it;
      snprintf(what, sizeof what, "tet%d %s, RBE3 and RBE2", order == 1 ? 4 : 10, mk);
      check_sets(what, &mesh, &o);
      const char *cl[1] = {"xmin"};
      o.ninterfaces = 1;
      o.nclamps = 1;
      o.clamps = cl;
      snprintf(what, sizeof what, "tet%d %s, RBE3, xmin clamped", order == 1 ? 4 : 10, mk);
      check_sets(what, &mesh, &o);
    }
    // beams on the solid's edge: 6-dof solid nodes, elements through the general path
    add_edge_beams(&mesh);
    o = t2_soft_options();
    o.area = 1e-4;
    o.Iy = 1e-9;
    o.Iz = 2e-9;
    o.J = 3e-9;
    snprintf(what, sizeof what, "tet%d and beams", order == 1 ? 4 : 10);
    check_sets(what, &mesh, &o);
    o.mass = FMBD_FE_MASS_LUMPED;
    snprintf(what, sizeof what, "tet%d and beams, lumped", order == 1 ? 4 : 10);
    check_sets(what, &mesh, &o);
    fmbd_fe_interface_spec it = {.group = "xmin", .kind = FMBD_FE_RBE2};
    o.ninterfaces = 1;
    o.interfaces = &it;
    snprintf(what, sizeof what, "tet%d and beams, lumped, RBE2", order == 1 ? 4 : 10);
    check_sets(what, &mesh, &o);
    fmbd_mesh_destroy(&mesh);
  }
  TEST_EXIT();
}
