// tests/unit/t205-fe-input.c: bad inputs to fmbd_fe_assemble: material, section, mesh
// connectivity, unused nodes, inverted elements; each a FMBD_ERR_VALUE with a message naming
// the quantity, element or node
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "t2_mesh.h"

static void expect_error(const fmbd_mesh *mesh, const fmbd_fe_opts *o, const char *what,
                         const char *s1, const char *s2) {
  fmbd_fe_body *b = NULL;
  fmbd_err_clear();
  int rc = fmbd_fe_assemble(mesh, o, &b);
  EXPECT(rc == FMBD_ERR_VALUE && b == NULL, "%s: rc %d", what, rc);
  const char *msg = fmbd_err_get()->msg;
  EXPECT(strstr(msg, s1) && (!s2 || strstr(msg, s2)), "%s: message \"%s\" lacks \"%s\" / \"%s\"",
         what, msg, s1, s2 ? s2 : "");
  fmbd_fe_body_destroy(&b);
}

int main(void) {
  fmbd_mesh mesh;
  box_mesh(&mesh, 1.0, 1.0, 1.0, 2, 2, 2, 2);
  fmbd_fe_opts o;
  // --- material ---
  const struct {
    double E, nu, rho;
    const char *s1, *s2;
  } mat[] = {
      {0.0, 0.3, 1000, "E = 0", "positive"},     {-1e9, 0.3, 1000, "E = -1e+09", "positive"},
      {NAN, 0.3, 1000, "E = nan", "positive"},   {1e9, 0.3, 0.0, "rho = 0", "positive"},
      {1e9, 0.3, -5, "rho = -5", "positive"},    {1e9, 0.5, 1000, "nu = 0.5", "(-1, 0.5)"},
      {1e9, -1.0, 1000, "nu = -1", "(-1, 0.5)"}, {1e9, 0.7, 1000, "nu = 0.7", "(-1, 0.5)"},
  };
  for (size_t k = 0; k < sizeof mat / sizeof *mat; k++) {
    fmbd_fe_opts_defaults(&o);
    o.E = mat[k].E;
    o.nu = mat[k].nu;
    o.rho = mat[k].rho;
    expect_error(&mesh, &o, mat[k].s1, mat[k].s1, mat[k].s2);
  }
  // nu just inside the bounds is accepted (nearly incompressible, auxetic)
  fmbd_fe_opts_defaults(&o);
  o.nu = 0.499;
  fmbd_fe_body *b = NULL;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &b) == FMBD_OK, "nu = 0.499: %s", fmbd_err_get()->msg);
  fmbd_fe_body_destroy(&b);
  o.nu = -0.9;
  EXPECT(fmbd_fe_assemble(&mesh, &o, &b) == FMBD_OK, "nu = -0.9: %s", fmbd_err_get()->msg);
  fmbd_fe_body_destroy(&b);
  // --- inverted element: swap two corner nodes (and the matching mid-side nodes stay: the
  // element is inside out) of element 5 ---
  fmbd_fe_opts_defaults(&o);
  {
    int64_t *t = mesh.tet + 5 * 10, s = t[1];
    t[1] = t[2];
    t[2] = s;
    expect_error(&mesh, &o, "inverted", "element 5 (tet10)", "Jacobian determinant");
    t[2] = t[1];
    t[1] = s;
  }
  // --- connectivity ---
  mesh.tet[7] = mesh.nnodes + 3;
  expect_error(&mesh, &o, "node out of range", "element 0 (tet10)", "out of range");
  mesh.tet[7] = mesh.tet[17];
  {
    // a node appended at the end (a copy of node 0's position) that no element uses
    double *x = fmbd_realloc(mesh.xyz, 3 * (mesh.nnodes + 1) * sizeof *x);
    mesh.xyz = x;
    memcpy(x + 3 * mesh.nnodes, x, 3 * sizeof *x);
    mesh.nnodes++;
    fmbd_mesh m2 = mesh;  // shallow: same arrays
    fmbd_fe_body *bb = NULL;
    fmbd_err_clear();
    EXPECT(fmbd_fe_assemble(&m2, &o, &bb) == FMBD_ERR_VALUE, "unused node accepted");
    char want[64];
    snprintf(want, sizeof want, "node %lld", (long long)(mesh.nnodes - 1));
    EXPECT(
        strstr(fmbd_err_get()->msg, want) && strstr(fmbd_err_get()->msg, "attached to no element"),
        "unused node: %s", fmbd_err_get()->msg);
    fmbd_fe_body_destroy(&bb);
    mesh.nnodes--;
  }
  {
    int saved = mesh.tet_nodes;
    mesh.tet_nodes = 8;
    expect_error(&mesh, &o, "tet8", "tetrahedra with 8 nodes", NULL);
    mesh.tet_nodes = saved;
    int64_t nt = mesh.ntet;
    mesh.ntet = 0;
    expect_error(&mesh, &o, "no elements", "no volume (tetrahedron) or beam elements", NULL);
    mesh.ntet = nt;
  }
  fmbd_mesh_destroy(&mesh);
  // --- beams without a section, and a bad orientation ---
  const double p0[3] = {0, 0, 0}, p1[3] = {0, 0, 1};
  beam_mesh(&mesh, p0, p1, 4);
  fmbd_fe_opts_defaults(&o);
  expect_error(&mesh, &o, "no section", "section properties A, Iy, Iz, J", "4 beam elements");
  o.area = 1e-4;
  o.Iy = 1e-9;
  o.Iz = 1e-9;
  expect_error(&mesh, &o, "no J", "section properties", "J = 0");
  o.J = 1e-9;
  o.orientation[2] = 1.0;  // parallel to the beam
  expect_error(&mesh, &o, "parallel orientation", "beam element 0", "parallel");
  o.orientation[2] = 0.0;  // automatic: global X for a beam along Z
  EXPECT(fmbd_fe_assemble(&mesh, &o, &b) == FMBD_OK, "automatic orientation: %s",
         fmbd_err_get()->msg);
  if (b)
    EXPECT(b->beam_orientation[0] == 1.0 && b->beam_orientation[2] == 0.0,
           "orientation X for a Z beam");
  fmbd_fe_body_destroy(&b);
  fmbd_fe_interface_spec it = {.group = "end0", .kind = FMBD_FE_RBE3};
  o.ninterfaces = 1;
  o.interfaces = &it;
  expect_error(&mesh, &o, "RBE3 on one node", "interface end0", "non-collinear");
  fmbd_mesh_destroy(&mesh);
  TEST_EXIT();
}
