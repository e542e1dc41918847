// tests/unit/t204-fe-io.c: fmbd-fe files: write + read round trip (bit-identical), the
// description copied into a downstream file, read errors naming the file and path, allocation
// countdown through assembly and reading
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "fmbd_h5.h"
#include "t2_mesh.h"

static char g_dir[1024];

static const char *tmp(const char *name) {
  static char buf[4][1200];
  static int k = 0;
  k = (k + 1) % 4;
  snprintf(buf[k], sizeof buf[k], "%s/%s", g_dir, name);
  return buf[k];
}

static bool same_csr(const fmbd_csr *a, const fmbd_csr *b) {
  if (!a || !b) return a == b;
  if (a->nrows != b->nrows || a->ncols != b->ncols) return false;
  int64_t nnz = fmbd_csr_nnz(a);
  return !memcmp(a->indptr, b->indptr, (a->nrows + 1) * sizeof(int64_t)) &&
         nnz == fmbd_csr_nnz(b) && !memcmp(a->indices, b->indices, nnz * sizeof(int64_t)) &&
         !memcmp(a->data, b->data, nnz * sizeof(double));
}

// everything but the matrices (and K/M when `matrices`) bit-identical
static void compare(const fmbd_fe_body *a, const fmbd_fe_body *b, bool matrices, const char *what) {
  EXPECT(a->nnodes == b->nnodes && a->nmesh_nodes == b->nmesh_nodes, "%s: node counts", what);
  EXPECT(!memcmp(a->xyz, b->xyz, 3 * a->nnodes * sizeof(double)), "%s: nodes", what);
  EXPECT(a->ntet == b->ntet && a->tet_nodes == b->tet_nodes &&
             (a->ntet == 0 || !memcmp(a->tet, b->tet, a->ntet * a->tet_nodes * sizeof(int64_t))),
         "%s: tets", what);
  EXPECT(a->nbeam == b->nbeam &&
             (a->nbeam == 0 ||
              (!memcmp(a->beam, b->beam, 2 * a->nbeam * sizeof(int64_t)) &&
               !memcmp(a->beam_orientation, b->beam_orientation, 3 * a->nbeam * sizeof(double)))),
         "%s: beams", what);
  EXPECT(a->ngroups == b->ngroups, "%s: %d groups vs %d", what, a->ngroups, b->ngroups);
  // groups are read back sorted by name; compare by name
  for (int g = 0; g < a->ngroups && a->ngroups == b->ngroups; g++) {
    int h = -1;
    for (int k = 0; k < b->ngroups; k++) {
      if (!strcmp(a->group_name[g], b->group_name[k])) h = k;
    }
    EXPECT(h >= 0, "%s: group %s lost", what, a->group_name[g]);
    if (h < 0) continue;
    int64_t n = a->group_ptr[g + 1] - a->group_ptr[g];
    EXPECT(n == b->group_ptr[h + 1] - b->group_ptr[h] &&
               !memcmp(a->group_node + a->group_ptr[g], b->group_node + b->group_ptr[h],
                       n * sizeof(int64_t)),
           "%s: group %s nodes", what, a->group_name[g]);
  }
  EXPECT(!memcmp(a->node_mass, b->node_mass, a->nnodes * sizeof(double)), "%s: node_mass", what);
  EXPECT(a->E == b->E && a->nu == b->nu && a->rho == b->rho && a->mass_kind == b->mass_kind,
         "%s: material", what);
  EXPECT(a->has_section == b->has_section && a->area == b->area && a->Iy == b->Iy &&
             a->Iz == b->Iz && a->J == b->J,
         "%s: section", what);
  EXPECT(a->ndof == b->ndof && !memcmp(a->dofs, b->dofs, 2 * a->ndof * sizeof(int64_t)) &&
             !memcmp(a->node_dof, b->node_dof, (a->nnodes + 1) * sizeof(int64_t)),
         "%s: dofs", what);
  EXPECT(same_csr(a->expand, b->expand), "%s: expand", what);
  if (matrices) {
    EXPECT(same_csr(a->K, b->K) && same_csr(a->M, b->M), "%s: K, M", what);
  } else {
    EXPECT(b->K == NULL && b->M == NULL, "%s: description only, no K/M", what);
  }
  EXPECT(a->ninterfaces == b->ninterfaces, "%s: interfaces", what);
  for (int i = 0; i < a->ninterfaces && a->ninterfaces == b->ninterfaces; i++) {
    int j = fmbd_fe_find_interface(b, a->interfaces[i].name);
    EXPECT(j >= 0, "%s: interface %s lost", what, a->interfaces[i].name);
    if (j < 0) continue;
    const fmbd_fe_interface *x = &a->interfaces[i], *y = &b->interfaces[j];
    EXPECT(x->kind == y->kind && x->node == y->node &&
               !memcmp(x->point, y->point, sizeof x->point) && x->nnodes == y->nnodes &&
               !memcmp(x->nodes, y->nodes, x->nnodes * sizeof(int64_t)),
           "%s: interface %s", what, x->name);
  }
  EXPECT(a->nclamped == b->nclamped, "%s: clamps", what);
  for (int i = 0; i < a->nclamped && a->nclamped == b->nclamped; i++) {
    EXPECT(!strcmp(a->clamped[i].name, b->clamped[i].name) &&
               a->clamped[i].nnodes == b->clamped[i].nnodes &&
               !memcmp(a->clamped[i].nodes, b->clamped[i].nodes,
                       a->clamped[i].nnodes * sizeof(int64_t)),
           "%s: clamp %d", what, i);
  }
  EXPECT(a->mass == b->mass &&
             !memcmp(a->center_of_mass, b->center_of_mass, sizeof a->center_of_mass) &&
             !memcmp(a->inertia, b->inertia, sizeof a->inertia) && a->volume == b->volume,
         "%s: body", what);
}

static fmbd_fe_body *solid_body(void) {
  fmbd_mesh mesh;
  box_mesh(&mesh, 1.0, 0.5, 0.5, 2, 1, 1, 2);
  fmbd_fe_opts o;
  fmbd_fe_opts_defaults(&o);
  fmbd_fe_interface_spec it[2] = {
      {.group = "xmin", .kind = FMBD_FE_RBE2},
      {.group = "xmax", .kind = FMBD_FE_RBE3, .has_point = true, .point = {1.2, 0.2, 0.3}}};
  const char *cl[1] = {"xmin"};
  o.ninterfaces = 2;
  o.interfaces = it;
  o.nclamps = 1;
  o.clamps = cl;
  fmbd_fe_body *b = NULL;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &b) == FMBD_OK, "assemble: %s", fmbd_err_get()->msg);
  fmbd_mesh_destroy(&mesh);
  return b;
}

static fmbd_fe_body *beam_body(void) {
  const double p0[3] = {0, 0, 0}, p1[3] = {0.3, 0.4, 0};
  fmbd_mesh mesh;
  beam_mesh(&mesh, p0, p1, 5);
  fmbd_fe_opts o;
  fmbd_fe_opts_defaults(&o);
  o.area = 1e-4;
  o.Iy = 1e-9;
  o.Iz = 2e-9;
  o.J = 3e-9;
  o.mass = FMBD_FE_MASS_LUMPED;
  fmbd_fe_body *b = NULL;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &b) == FMBD_OK, "assemble beam: %s", fmbd_err_get()->msg);
  fmbd_mesh_destroy(&mesh);
  return b;
}

static void round_trip(fmbd_fe_body *a, const char *name) {
  if (!a) return;
  fmbd_h5 *f = NULL, *g = NULL, *d = NULL;
  EXPECT(fmbd_h5_create(tmp(name), "fmbd-fe", "1.0", &f) == FMBD_OK, "create");
  EXPECT(fmbd_fe_write(f, a) == FMBD_OK, "write: %s", fmbd_err_get()->msg);
  EXPECT(fmbd_h5_commit(&f, 0.0, 0.0) == FMBD_OK, "commit: %s", fmbd_err_get()->msg);
  fmbd_fe_body *b = NULL;
  EXPECT(fmbd_h5_open(tmp(name), &g) == FMBD_OK, "open");
  EXPECT(fmbd_h5_check_format(g, "fmbd-fe", 1) == FMBD_OK, "format");
  EXPECT(fmbd_fe_read(g, &b) == FMBD_OK, "read: %s", fmbd_err_get()->msg);
  if (b) compare(a, b, true, name);
  fmbd_fe_body_destroy(&b);
  // the selection of /K and /M only: the same matrices, nothing else read
  EXPECT(fmbd_fe_read_matrices(g, &b) == FMBD_OK, "read matrices: %s", fmbd_err_get()->msg);
  if (b) {
    EXPECT(b->ndof == a->ndof && same_csr(a->K, b->K) && same_csr(a->M, b->M),
           "%s: K and M read alone differ", name);
    EXPECT(!b->xyz && !b->dofs && !b->expand && b->ninterfaces == 0,
           "%s: the matrices-only read read more", name);
  }
  fmbd_fe_body_destroy(&b);
  // description copied into a downstream file: read back without K and M
  char dname[256];
  snprintf(dname, sizeof dname, "desc-%s", name);
  EXPECT(fmbd_h5_create(tmp(dname), "fmbd-cb", "1.0", &d) == FMBD_OK, "create downstream");
  EXPECT(fmbd_fe_copy_description(g, d) == FMBD_OK, "copy: %s", fmbd_err_get()->msg);
  EXPECT(!fmbd_h5_exists(d, "/K") && !fmbd_h5_exists(d, "/M"), "K and M not copied");
  EXPECT(fmbd_h5_commit(&d, 0.0, 0.0) == FMBD_OK, "commit downstream");
  fmbd_h5_close(&g);
  EXPECT(fmbd_h5_open(tmp(dname), &g) == FMBD_OK, "open downstream");
  EXPECT(fmbd_fe_read(g, &b) == FMBD_OK, "read downstream: %s", fmbd_err_get()->msg);
  if (b) compare(a, b, false, dname);
  fmbd_fe_body_destroy(&b);
  EXPECT(fmbd_fe_read_matrices(g, &b) != FMBD_OK && !b, "%s: no /K, yet matrices read", dname);
  fmbd_err_clear();
  fmbd_h5_close(&g);
}

// a file lacking one object, or with a bad one: the error names the file and the path
static void read_errors(const fmbd_fe_body *a) {
  if (!a) return;
  struct {
    const char *drop, *where;
  } cases[] = {{"/dofs", "/dofs"},
               {"/expand", "/expand"},
               {"/mesh/node_mass", "/mesh/node_mass"},
               {"/body", "/body"}};
  for (size_t k = 0; k < sizeof cases / sizeof *cases; k++) {
    fmbd_h5 *f = NULL;
    const char *name = tmp("broken.fe.h5");
    EXPECT(fmbd_h5_create(name, "fmbd-fe", "1.0", &f) == FMBD_OK, "create");
    EXPECT(fmbd_fe_write(f, a) == FMBD_OK, "write");
    EXPECT(fmbd_h5_delete(f, cases[k].drop) == FMBD_OK, "delete %s", cases[k].drop);
    EXPECT(fmbd_h5_commit(&f, 0, 0) == FMBD_OK, "commit");
    fmbd_fe_body *b = NULL;
    EXPECT(fmbd_h5_open(name, &f) == FMBD_OK, "open");
    fmbd_err_clear();
    int rc = fmbd_fe_read(f, &b);
    const fmbd_err *e = fmbd_err_get();
    EXPECT(rc != FMBD_OK && b == NULL, "missing %s accepted", cases[k].drop);
    EXPECT(strstr(e->file, "broken.fe.h5") && strstr(e->where, cases[k].where),
           "missing %s: error at %s:%s (%s)", cases[k].drop, e->file, e->where, e->msg);
    fmbd_h5_close(&f);
  }
  // out-of-range node in an element, a /dofs not node-major
  {
    fmbd_h5 *f = NULL;
    const char *name = tmp("badidx.fe.h5");
    EXPECT(fmbd_h5_create(name, "fmbd-fe", "1.0", &f) == FMBD_OK, "create");
    EXPECT(fmbd_fe_write(f, a) == FMBD_OK, "write");
    int64_t *t = fmbd_malloc(a->ntet * 10 * sizeof *t), dims[2] = {a->ntet, 10};
    memcpy(t, a->tet, a->ntet * 10 * sizeof *t);
    t[13] = a->nnodes + 5;
    EXPECT(fmbd_h5_write_i64(f, "/mesh/elements/tet10", 2, dims, t) == FMBD_OK, "overwrite tets");
    int64_t *dd = fmbd_malloc(2 * a->ndof * sizeof *dd), dd_dims[2] = {a->ndof, 2};
    memcpy(dd, a->dofs, 2 * a->ndof * sizeof *dd);
    int64_t tmpv = dd[2];
    dd[2] = dd[4];
    dd[4] = tmpv;
    dd[3] = 2;
    dd[5] = 1;
    EXPECT(fmbd_h5_write_i64(f, "/dofs", 2, dd_dims, dd) == FMBD_OK, "overwrite dofs");
    EXPECT(fmbd_h5_commit(&f, 0, 0) == FMBD_OK, "commit");
    fmbd_free(t);
    fmbd_free(dd);
    fmbd_fe_body *b = NULL;
    EXPECT(fmbd_h5_open(name, &f) == FMBD_OK, "open");
    fmbd_err_clear();
    EXPECT(fmbd_fe_read(f, &b) == FMBD_ERR_FORMAT, "bad tet index accepted");
    const fmbd_err *e = fmbd_err_get();
    EXPECT(strstr(e->where, "/mesh/elements/tet10") && strstr(e->msg, "entry 13"),
           "bad index: %s: %s", e->where, e->msg);
    fmbd_h5_close(&f);
  }
}

// fail the n-th allocation for n = 0, 1, ... until assembly succeeds: every failure is a clean
// FMBD_ERR_NOMEM (leaks show under SANITIZE=1)
static void countdown(void) {
  fmbd_mesh mesh;
  box_mesh(&mesh, 1.0, 0.5, 0.5, 2, 1, 1, 1);
  fmbd_fe_opts o;
  fmbd_fe_opts_defaults(&o);
  fmbd_fe_interface_spec it[2] = {{.group = "xmin", .kind = FMBD_FE_RBE2},
                                  {.group = "xmax", .kind = FMBD_FE_RBE3}};
  const char *cl[1] = {"xmin"};
  o.ninterfaces = 2;
  o.interfaces = it;
  o.nclamps = 1;
  o.clamps = cl;
  int n, ok = 0;
  for (n = 0; n < 5000 && !ok; n++) {
    fmbd_fe_body *b = NULL;
    fmbd_alloc_fail_after(n);
    int rc = fmbd_fe_assemble(&mesh, &o, &b);
    fmbd_alloc_fail_after(-1);
    if (rc == FMBD_OK) {
      ok = 1;
    } else {
      EXPECT(rc == FMBD_ERR_NOMEM && b == NULL, "countdown %d: rc %d (%s)", n, rc,
             fmbd_err_get()->msg);
    }
    fmbd_fe_body_destroy(&b);
  }
  EXPECT(ok && n > 20, "assembly never succeeded in the countdown (%d)", n);
  fmbd_mesh_destroy(&mesh);
}

int main(void) {
  const char *root = getenv("ROOT"), *build = getenv("BUILD");
  snprintf(g_dir, sizeof g_dir, "%s/%s/test-tmp/t204-fe-io", root ? root : ".",
           build ? build : "build");
  char cmd[2200];
  snprintf(cmd, sizeof cmd, "rm -rf '%s' && mkdir -p '%s'", g_dir, g_dir);
  if (system(cmd) != 0) return 1;
  fmbd_h5_debug(false);
  fmbd_fe_body *a = solid_body(), *c = beam_body();
  round_trip(a, "solid.fe.h5");
  round_trip(c, "beam.fe.h5");
  read_errors(a);
  countdown();
  fmbd_fe_body_destroy(&a);
  fmbd_fe_body_destroy(&c);
  TEST_EXIT();
}
