// common/fmbd_fe.c: FE body assembly (checks, dof layout, CSR assembly, ties and clamps, mass
// properties), nodal stress, and the small helpers of fmbd_fe.h
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "fmbd_fe_impl.h"

// --- small helpers ----------------------------------------------------------------------------
void fmbd_mesh_destroy(fmbd_mesh *m) {
  if (!m) return;
  fmbd_free(m->xyz);
  fmbd_free(m->tet);
  fmbd_free(m->beam);
  if (m->group_name) {
    for (int g = 0; g < m->ngroups; g++) fmbd_free(m->group_name[g]);
  }
  fmbd_free(m->group_name);
  fmbd_free(m->group_ptr);
  fmbd_free(m->group_node);
  memset(m, 0, sizeof *m);
}

int fmbd_mesh_find_group(const fmbd_mesh *m, const char *name) {
  for (int g = 0; g < m->ngroups; g++) {
    if (m->group_name[g] && strcmp(m->group_name[g], name) == 0) return g;
  }
  return -1;
}

void fmbd_fe_options_defaults(fmbd_fe_options *o) {
  memset(o, 0, sizeof *o);
  o->E = 210e9;
  o->nu = 0.3;
  o->rho = 7850.0;
  o->mass = FMBD_FE_MASS_CONSISTENT;
}

void fmbd_fe_body_destroy(fmbd_fe_body **pb) {
  if (!pb || !*pb) return;
  fmbd_fe_body *b = *pb;
  fmbd_free(b->xyz);
  fmbd_free(b->tet);
  fmbd_free(b->beam);
  fmbd_free(b->beam_orientation);
  if (b->group_name) {
    for (int g = 0; g < b->ngroups; g++) fmbd_free(b->group_name[g]);
  }
  fmbd_free(b->group_name);
  fmbd_free(b->group_ptr);
  fmbd_free(b->group_node);
  fmbd_free(b->node_mass);
  fmbd_free(b->dofs);
  fmbd_free(b->node_dof);
  fmbd_csr_destroy(&b->K);
  fmbd_csr_destroy(&b->M);
  fmbd_csr_destroy(&b->expand);
  if (b->interfaces) {
    for (int i = 0; i < b->ninterfaces; i++) {
      fmbd_free(b->interfaces[i].name);
      fmbd_free(b->interfaces[i].nodes);
    }
  }
  fmbd_free(b->interfaces);
  if (b->clamped) {
    for (int i = 0; i < b->nclamped; i++) {
      fmbd_free(b->clamped[i].name);
      fmbd_free(b->clamped[i].nodes);
    }
  }
  fmbd_free(b->clamped);
  fmbd_free(b);
  *pb = NULL;
}

int64_t fmbd_fe_dof(const fmbd_fe_body *b, int64_t node, int direction) {
  if (!b->node_dof || node < 0 || node >= b->nnodes) return -1;
  for (int64_t i = b->node_dof[node]; i < b->node_dof[node + 1]; i++) {
    if (b->dofs[2 * i + 1] == direction) return i;
  }
  return -1;
}

int fmbd_fe_find_interface(const fmbd_fe_body *b, const char *name) {
  for (int i = 0; i < b->ninterfaces; i++) {
    if (strcmp(b->interfaces[i].name, name) == 0) return i;
  }
  return -1;
}

static int cmp_i64(const void *a, const void *b) {
  int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
  return (x > y) - (x < y);
}

// Sorted unique copy of a group's nodes. @param[out] out caller frees
static int group_nodes(const fmbd_mesh *m, int g, int64_t *n, int64_t **out) {
  int64_t k = m->group_ptr[g + 1] - m->group_ptr[g];
  int64_t *v = fmbd_malloc((size_t)(k ? k : 1) * sizeof *v);
  FMBD_CHECK(v, FMBD_ERR_NOMEM, "out of memory");
  memcpy(v, m->group_node + m->group_ptr[g], (size_t)k * sizeof *v);
  qsort(v, (size_t)k, sizeof *v, cmp_i64);
  int64_t u = 0;
  for (int64_t i = 0; i < k; i++) {
    if (u == 0 || v[i] != v[u - 1]) v[u++] = v[i];
  }
  *n = u;
  *out = v;
  return FMBD_OK;
}

// The automatic beam orientation: global Z, or global X within 0.1 rad of Z
static void auto_orientation(const double *x0, const double *x1, double v[3]) {
  double d[3] = {x1[0] - x0[0], x1[1] - x0[1], x1[2] - x0[2]};
  double L = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  v[0] = 0.0;
  v[1] = 0.0;
  v[2] = 1.0;
  if (L > 0.0 && fabs(d[2]) / L > cos(0.1)) {
    v[0] = 1.0;
    v[2] = 0.0;
  }
}

// --- input checks -----------------------------------------------------------------------------
static int check_inputs(const fmbd_mesh *m, const fmbd_fe_options *o) {
  FMBD_CHECK(isfinite(o->E) && o->E > 0.0, FMBD_ERR_VALUE,
             "Young's modulus E = %g: must be positive", o->E);
  FMBD_CHECK(isfinite(o->rho) && o->rho > 0.0, FMBD_ERR_VALUE,
             "density rho = %g: must be positive", o->rho);
  FMBD_CHECK(isfinite(o->nu) && o->nu > -1.0 && o->nu < 0.5, FMBD_ERR_VALUE,
             "Poisson's ratio nu = %g: must lie in (-1, 0.5)", o->nu);
  FMBD_CHECK(o->mass == FMBD_FE_MASS_CONSISTENT || o->mass == FMBD_FE_MASS_LUMPED, FMBD_ERR_VALUE,
             "unknown mass kind %d", (int)o->mass);
  FMBD_CHECK(m->nnodes > 0 && m->xyz, FMBD_ERR_VALUE, "mesh has no nodes");
  FMBD_CHECK(m->ntet >= 0 && m->nbeam >= 0, FMBD_ERR_VALUE, "negative element count");
  FMBD_CHECK(m->ntet + m->nbeam > 0, FMBD_ERR_VALUE,
             "mesh has no volume (tetrahedron) or beam elements");
  for (int64_t p = 0; p < 3 * m->nnodes; p++) {
    FMBD_CHECK(isfinite(m->xyz[p]), FMBD_ERR_VALUE, "node %lld: non-finite coordinate",
               (long long)(p / 3));
  }
  if (m->ntet > 0) {
    FMBD_CHECK(m->tet && (m->tet_nodes == 4 || m->tet_nodes == 10), FMBD_ERR_VALUE,
               "tetrahedra with %d nodes (4 or 10 supported)", m->tet_nodes);
    for (int64_t e = 0; e < m->ntet; e++) {
      for (int a = 0; a < m->tet_nodes; a++) {
        int64_t p = m->tet[e * m->tet_nodes + a];
        FMBD_CHECK(p >= 0 && p < m->nnodes, FMBD_ERR_VALUE,
                   "element %lld (tet%d): node %lld out of range (%lld nodes)", (long long)e,
                   m->tet_nodes, (long long)p, (long long)m->nnodes);
      }
    }
  }
  if (m->nbeam > 0) {
    FMBD_CHECK(m->beam, FMBD_ERR_VALUE, "beam elements without connectivity");
    FMBD_CHECK(o->area > 0.0 && o->Iy > 0.0 && o->Iz > 0.0 && o->J > 0.0 && isfinite(o->area) &&
                   isfinite(o->Iy) && isfinite(o->Iz) && isfinite(o->J),
               FMBD_ERR_VALUE,
               "the mesh has %lld beam elements: the section properties A, Iy, Iz, J must all be "
               "given and positive (A = %g, Iy = %g, Iz = %g, J = %g)",
               (long long)m->nbeam, o->area, o->Iy, o->Iz, o->J);
    for (int64_t e = 0; e < m->nbeam; e++) {
      for (int a = 0; a < 2; a++) {
        int64_t p = m->beam[2 * e + a];
        FMBD_CHECK(p >= 0 && p < m->nnodes, FMBD_ERR_VALUE,
                   "beam element %lld: node %lld out of range (%lld nodes)", (long long)e,
                   (long long)p, (long long)m->nnodes);
      }
    }
  }
  FMBD_CHECK(m->ngroups == 0 || (m->group_ptr && m->group_name), FMBD_ERR_VALUE,
             "groups without names or pointers");
  for (int g = 0; g < m->ngroups; g++) {
    FMBD_CHECK(m->group_name[g] && m->group_ptr[g] <= m->group_ptr[g + 1] && m->group_ptr[0] == 0,
               FMBD_ERR_VALUE, "group %d: bad name or pointer", g);
    for (int64_t i = m->group_ptr[g]; i < m->group_ptr[g + 1]; i++) {
      FMBD_CHECK(m->group_node[i] >= 0 && m->group_node[i] < m->nnodes, FMBD_ERR_VALUE,
                 "group %s: node %lld out of range (%lld nodes)", m->group_name[g],
                 (long long)m->group_node[i], (long long)m->nnodes);
    }
  }
  for (int i = 0; i < o->ninterfaces; i++) {
    const fmbd_fe_interface_spec *s = &o->interfaces[i];
    FMBD_CHECK(s->group && s->group[0], FMBD_ERR_VALUE, "interface %d has no group name", i);
    int g = fmbd_mesh_find_group(m, s->group);
    FMBD_CHECK(g >= 0, FMBD_ERR_VALUE, "interface %s: physical group \"%s\" not found in the mesh",
               s->group, s->group);
    FMBD_CHECK(m->group_ptr[g + 1] > m->group_ptr[g], FMBD_ERR_VALUE,
               "interface %s: the group has no nodes", s->group);
    FMBD_CHECK(s->kind == FMBD_FE_RBE2 || s->kind == FMBD_FE_RBE3, FMBD_ERR_VALUE,
               "interface %s: unknown tie kind %d", s->group, (int)s->kind);
    FMBD_CHECK(!s->has_point || (isfinite(s->point[0]) && isfinite(s->point[1]) &&
                                 isfinite(s->point[2])),
               FMBD_ERR_VALUE, "interface %s: non-finite point", s->group);
    for (int j = 0; j < i; j++) {
      FMBD_CHECK(strcmp(o->interfaces[j].group, s->group) != 0, FMBD_ERR_VALUE,
                 "interface %s given twice", s->group);
    }
  }
  for (int i = 0; i < o->nclamps; i++) {
    const char *name = o->clamps[i];
    FMBD_CHECK(name && name[0], FMBD_ERR_VALUE, "clamp %d has no group name", i);
    bool is_iface = false;
    for (int j = 0; j < o->ninterfaces; j++) is_iface |= strcmp(o->interfaces[j].group, name) == 0;
    FMBD_CHECK(is_iface || fmbd_mesh_find_group(m, name) >= 0, FMBD_ERR_VALUE,
               "clamp %s: physical group \"%s\" not found in the mesh", name, name);
    for (int j = 0; j < i; j++) {
      FMBD_CHECK(strcmp(o->clamps[j], name) != 0, FMBD_ERR_VALUE, "clamp %s given twice", name);
    }
  }
  return FMBD_OK;
}

// --- rigid-body accumulation --------------------------------------------------------------------
// Mr = sum_e R_e' M_e R_e (6x6, row-major) for the rigid modes u = u0 + theta x x (translations)
// and theta (rotations); tt = m I, tr = -[S1]x, rr = inertia about the origin.
static void rigid_solid(int nn, const int64_t *en, const double *xyz, const double *Me,
                        double Mr[36]) {
  double S0 = 0.0, S1[3] = {0, 0, 0}, S2[9] = {0};
  for (int a = 0; a < nn; a++) {
    const double *xa = xyz + 3 * en[a];
    for (int b = 0; b < nn; b++) {
      const double *xb = xyz + 3 * en[b];
      double mab = Me[a * nn + b];
      S0 += mab;
      for (int i = 0; i < 3; i++) {
        S1[i] += mab * xb[i];
        for (int j = 0; j < 3; j++) S2[i * 3 + j] += mab * xa[i] * xb[j];
      }
    }
  }
  // tr = -[S1]x ; rr = tr(S2) I - S2'
  double tr2 = S2[0] + S2[4] + S2[8];
  double X[9] = {0, -S1[2], S1[1], S1[2], 0, -S1[0], -S1[1], S1[0], 0}; // [S1]x
  for (int i = 0; i < 3; i++) {
    Mr[i * 6 + i] += S0;
    for (int j = 0; j < 3; j++) {
      Mr[i * 6 + 3 + j] -= X[i * 3 + j];
      Mr[(3 + i) * 6 + j] -= X[j * 3 + i];
      Mr[(3 + i) * 6 + 3 + j] += (i == j ? tr2 : 0.0) - S2[j * 3 + i];
    }
  }
}

static void rigid_beam(const double *x0, const double *x1, const double *Me, double Mr[36]) {
  // R (12 x 6): node a rows: [I, -[x_a]x ; 0, I]
  double R[72] = {0};
  const double *x[2] = {x0, x1};
  for (int a = 0; a < 2; a++) {
    double *r = R + a * 36;
    const double *p = x[a];
    for (int k = 0; k < 6; k++) r[k * 6 + k] = 1.0;
    // -[p]x = [[0, pz, -py], [-pz, 0, px], [py, -px, 0]]
    r[0 * 6 + 4] = p[2]; r[0 * 6 + 5] = -p[1];
    r[1 * 6 + 3] = -p[2]; r[1 * 6 + 5] = p[0];
    r[2 * 6 + 3] = p[1]; r[2 * 6 + 4] = -p[0];
  }
  double MR[72]; // Me R (12 x 6)
  for (int i = 0; i < 12; i++) {
    for (int j = 0; j < 6; j++) {
      double s = 0.0;
      for (int k = 0; k < 12; k++) s += Me[i * 12 + k] * R[k * 6 + j];
      MR[i * 6 + j] = s;
    }
  }
  for (int i = 0; i < 6; i++) {
    for (int j = 0; j < 6; j++) {
      double s = 0.0;
      for (int k = 0; k < 12; k++) s += R[k * 6 + i] * MR[k * 6 + j];
      Mr[i * 6 + j] += s;
    }
  }
}

static void body_properties(fmbd_fe_body *b, const double Mr[36]) {
  double m = (Mr[0] + Mr[7] + Mr[14]) / 3.0;
  // tr = -[S1]x: tr[0][1] = S1z, tr[1][2] = S1x, tr[2][0] = S1y
  double S1[3] = {Mr[1 * 6 + 5], Mr[2 * 6 + 3], Mr[0 * 6 + 4]};
  b->mass = m;
  double c[3];
  for (int k = 0; k < 3; k++) c[k] = m > 0.0 ? S1[k] / m : 0.0;
  memcpy(b->center_of_mass, c, sizeof c);
  double cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) {
      // parallel axis: I_c = I_o - m (|c|^2 I - c c'); symmetrised
      double io = 0.5 * (Mr[(3 + i) * 6 + 3 + j] + Mr[(3 + j) * 6 + 3 + i]);
      b->inertia[i * 3 + j] = io - m * ((i == j ? cc : 0.0) - c[i] * c[j]);
    }
  }
}

// --- assembly -----------------------------------------------------------------------------------
int fmbd_fe_assemble(const fmbd_mesh *m, const fmbd_fe_options *opt, fmbd_fe_body **out) {
  int rc = FMBD_OK;
  fmbd_fe_options defaults;
  if (!opt) {
    fmbd_fe_options_defaults(&defaults);
    opt = &defaults;
  }
  fmbd_fe_body *b = NULL;
  int8_t *on_solid = NULL, *on_beam = NULL;
  int64_t *fdof = NULL, *edofs = NULL, *ndofs = NULL;
  double *Ke = NULL, *Me = NULL, *Me3 = NULL;
  fmbd_csr *Kf = NULL, *Mf = NULL, *T = NULL, *Kr = NULL;
  int64_t *sel = NULL;
  FMBD_CALL(check_inputs(m, opt));
  FMBD_GALLOC(b = fmbd_calloc(1, sizeof *b));
  const int64_t nmesh = m->nnodes, nn = nmesh + opt->ninterfaces;
  b->nmesh_nodes = nmesh;
  b->nnodes = nn;
  b->E = opt->E;
  b->nu = opt->nu;
  b->rho = opt->rho;
  b->mass_kind = opt->mass;
  // --- copy the mesh ---
  FMBD_GALLOC(b->xyz = fmbd_malloc((size_t)(3 * nn) * sizeof *b->xyz));
  memcpy(b->xyz, m->xyz, (size_t)(3 * nmesh) * sizeof *b->xyz);
  b->ntet = m->ntet;
  b->tet_nodes = m->ntet > 0 ? m->tet_nodes : 0;
  if (m->ntet > 0) {
    size_t sz = (size_t)(m->ntet * m->tet_nodes) * sizeof *b->tet;
    FMBD_GALLOC(b->tet = fmbd_malloc(sz));
    memcpy(b->tet, m->tet, sz);
  }
  b->nbeam = m->nbeam;
  if (m->nbeam > 0) {
    b->has_section = true;
    b->area = opt->area;
    b->Iy = opt->Iy;
    b->Iz = opt->Iz;
    b->J = opt->J;
    FMBD_GALLOC(b->beam = fmbd_malloc((size_t)(2 * m->nbeam) * sizeof *b->beam));
    memcpy(b->beam, m->beam, (size_t)(2 * m->nbeam) * sizeof *b->beam);
    FMBD_GALLOC(b->beam_orientation = fmbd_malloc((size_t)(3 * m->nbeam) * sizeof(double)));
    for (int64_t e = 0; e < m->nbeam; e++) {
      double *v = b->beam_orientation + 3 * e;
      const double *x0 = m->xyz + 3 * m->beam[2 * e], *x1 = m->xyz + 3 * m->beam[2 * e + 1];
      if (opt->beam_orientation) {
        memcpy(v, opt->beam_orientation + 3 * e, 3 * sizeof *v);
      } else if (opt->orientation[0] != 0.0 || opt->orientation[1] != 0.0 ||
                 opt->orientation[2] != 0.0) {
        memcpy(v, opt->orientation, 3 * sizeof *v);
      } else {
        auto_orientation(x0, x1, v);
      }
    }
  }
  b->ngroups = m->ngroups;
  if (m->ngroups > 0) {
    int64_t ng = m->group_ptr[m->ngroups];
    FMBD_GALLOC(b->group_name = fmbd_calloc((size_t)m->ngroups, sizeof *b->group_name));
    FMBD_GALLOC(b->group_ptr = fmbd_malloc(((size_t)m->ngroups + 1) * sizeof *b->group_ptr));
    FMBD_GALLOC(b->group_node = fmbd_malloc((size_t)(ng ? ng : 1) * sizeof *b->group_node));
    for (int g = 0; g < m->ngroups; g++) FMBD_GALLOC(b->group_name[g] = fmbd_strdup(m->group_name[g]));
    memcpy(b->group_ptr, m->group_ptr, ((size_t)m->ngroups + 1) * sizeof *b->group_ptr);
    memcpy(b->group_node, m->group_node, (size_t)ng * sizeof *b->group_node);
  }
  // --- which nodes carry what ---
  FMBD_GALLOC(on_solid = fmbd_calloc((size_t)nn, 1));
  FMBD_GALLOC(on_beam = fmbd_calloc((size_t)nn, 1));
  for (int64_t i = 0; i < m->ntet * (int64_t)b->tet_nodes; i++) on_solid[m->tet[i]] = 1;
  for (int64_t i = 0; i < 2 * m->nbeam; i++) on_beam[m->beam[i]] = 1;
  for (int64_t p = 0; p < nmesh; p++) {
    FMBD_GCHECK(on_solid[p] || on_beam[p], FMBD_ERR_VALUE,
                "node %lld (0-based) at (%g, %g, %g) is attached to no element", (long long)p,
                m->xyz[3 * p], m->xyz[3 * p + 1], m->xyz[3 * p + 2]);
  }
  // --- interfaces: one new 6-dof node each ---
  b->ninterfaces = opt->ninterfaces;
  if (opt->ninterfaces > 0) {
    FMBD_GALLOC(b->interfaces = fmbd_calloc((size_t)opt->ninterfaces, sizeof *b->interfaces));
  }
  for (int i = 0; i < opt->ninterfaces; i++) {
    const fmbd_fe_interface_spec *s = &opt->interfaces[i];
    fmbd_fe_interface *it = &b->interfaces[i];
    FMBD_GALLOC(it->name = fmbd_strdup(s->group));
    it->kind = s->kind;
    it->node = nmesh + i;
    FMBD_GCALL(group_nodes(m, fmbd_mesh_find_group(m, s->group), &it->nnodes, &it->nodes));
    if (s->has_point) {
      memcpy(it->point, s->point, sizeof it->point);
    } else {
      for (int k = 0; k < 3; k++) {
        double sum = 0.0;
        for (int64_t j = 0; j < it->nnodes; j++) sum += m->xyz[3 * it->nodes[j] + k];
        it->point[k] = sum / (double)it->nnodes;
      }
    }
    memcpy(b->xyz + 3 * it->node, it->point, sizeof it->point);
    on_beam[it->node] = 1; // 6 dofs
  }
  // --- clamps ---
  b->nclamped = opt->nclamps;
  if (opt->nclamps > 0) {
    FMBD_GALLOC(b->clamped = fmbd_calloc((size_t)opt->nclamps, sizeof *b->clamped));
  }
  for (int i = 0; i < opt->nclamps; i++) {
    fmbd_fe_clamp *c = &b->clamped[i];
    FMBD_GALLOC(c->name = fmbd_strdup(opt->clamps[i]));
    int ii = -1;
    for (int j = 0; j < opt->ninterfaces; j++) {
      if (strcmp(opt->interfaces[j].group, c->name) == 0) ii = j;
    }
    if (ii >= 0) {
      c->nnodes = 1;
      FMBD_GALLOC(c->nodes = fmbd_malloc(sizeof *c->nodes));
      c->nodes[0] = b->interfaces[ii].node;
    } else {
      FMBD_GCALL(group_nodes(m, fmbd_mesh_find_group(m, c->name), &c->nnodes, &c->nodes));
    }
  }
  // --- full dof layout: 3 per solid-only node, 6 per beam or interface node ---
  FMBD_GALLOC(fdof = fmbd_malloc(((size_t)nn + 1) * sizeof *fdof));
  fdof[0] = 0;
  for (int64_t p = 0; p < nn; p++) fdof[p + 1] = fdof[p] + (on_beam[p] ? 6 : 3);
  const int64_t nfull = fdof[nn];
  // --- element dof lists (tets, then beams), padded with -1 to kmax ---
  const int tn = b->tet_nodes, kt = 3 * tn;
  const int kmax = m->nbeam > 0 && 12 > kt ? 12 : kt;
  const int64_t nel = m->ntet + m->nbeam;
  FMBD_GALLOC(edofs = fmbd_malloc((size_t)(nel * kmax) * sizeof *edofs));
  for (int64_t e = 0; e < m->ntet; e++) {
    int64_t *ed = edofs + e * kmax;
    for (int a = 0; a < tn; a++) {
      for (int k = 0; k < 3; k++) ed[3 * a + k] = fdof[m->tet[e * tn + a]] + k;
    }
    for (int a = kt; a < kmax; a++) ed[a] = -1;
  }
  for (int64_t e = 0; e < m->nbeam; e++) {
    int64_t *ed = edofs + (m->ntet + e) * kmax;
    for (int a = 0; a < 2; a++) {
      for (int k = 0; k < 6; k++) ed[6 * a + k] = fdof[m->beam[2 * e + a]] + k;
    }
    for (int a = 12; a < kmax; a++) ed[a] = -1;
  }
  FMBD_GALLOC(Ke = fmbd_malloc((size_t)(kmax * kmax) * sizeof *Ke));
  FMBD_GALLOC(Me = fmbd_malloc(144 * sizeof *Me));
  FMBD_GALLOC(Me3 = fmbd_malloc((size_t)(kmax * kmax) * sizeof *Me3));
  // --- stiffness ---
  FMBD_GCALL(fmbd_csr_pattern_from_elements(nfull, nel, kmax, edofs, &Kf));
  double vol_solid = 0.0, vol_beam = 0.0;
  for (int64_t e = 0; e < m->ntet; e++) {
    double xe[30];
    for (int a = 0; a < tn; a++) memcpy(xe + 3 * a, m->xyz + 3 * m->tet[e * tn + a], 3 * sizeof(double));
    FMBD_GCALL(fmbd_fe_tet_matrices(tn, xe, b->E, b->nu, b->rho, e, Ke, NULL, NULL));
    FMBD_GCALL(fmbd_csr_add_block(Kf, kt, edofs + e * kmax, Ke));
  }
  for (int64_t e = 0; e < m->nbeam; e++) {
    const double *x0 = m->xyz + 3 * m->beam[2 * e], *x1 = m->xyz + 3 * m->beam[2 * e + 1];
    FMBD_GCALL(fmbd_fe_beam_matrices(x0, x1, b->beam_orientation + 3 * e, b->E, b->nu, b->rho,
                                     b->area, b->Iy, b->Iz, b->J, e, Ke, NULL));
    FMBD_GCALL(fmbd_csr_add_block(Kf, 12, edofs + (m->ntet + e) * kmax, Ke));
  }
  // --- ties and clamps: T (full -> active), then K' = T' K T ---
  bool selection = false;
  FMBD_GCALL(fmbd_fe_tie_build(b, fdof, &T, &selection));
  if (selection) {
    FMBD_GALLOC(sel = fmbd_malloc((size_t)(b->ndof ? b->ndof : 1) * sizeof *sel));
    for (int64_t i = 0; i < b->ndof; i++) sel[i] = fdof[b->dofs[2 * i]] + b->dofs[2 * i + 1];
  }
#define REDUCE(A, OUT)                                                                      \
  do {                                                                                      \
    if (selection && b->ndof == nfull) {                                                    \
      OUT = A;                                                                              \
      A = NULL;                                                                             \
    } else if (selection) {                                                                 \
      FMBD_GCALL(fmbd_csr_submatrix(A, b->ndof, sel, b->ndof, sel, &OUT));                  \
    } else {                                                                                \
      FMBD_GCALL(fmbd_csr_ptap(A, T, &OUT));                                                \
      FMBD_GCALL(fmbd_fe_symmetrize(OUT));                                                  \
    }                                                                                       \
    fmbd_csr_destroy(&A);                                                                   \
  } while (0)
  REDUCE(Kf, Kr);
  b->K = Kr;
  Kr = NULL;
  // --- mass, node masses, rigid-body properties ---
  FMBD_GALLOC(b->node_mass = fmbd_calloc((size_t)nn, sizeof *b->node_mass));
  if (opt->mass == FMBD_FE_MASS_CONSISTENT) {
    FMBD_GCALL(fmbd_csr_pattern_from_elements(nfull, nel, kmax, edofs, &Mf));
  } else {
    // lumped: a diagonal pattern, plus the 3x3 rotational block of 6-dof nodes; "elements" of
    // 3 dofs: each translation alone (padded with -1), the rotations of a node together
    FMBD_GALLOC(ndofs = fmbd_malloc((size_t)(12 * nn) * sizeof *ndofs));
    int64_t ne = 0;
    for (int64_t p = 0; p < nn; p++) {
      for (int k = 0; k < 3; k++) {
        ndofs[3 * ne] = fdof[p] + k;
        ndofs[3 * ne + 1] = ndofs[3 * ne + 2] = -1;
        ne++;
      }
      if (fdof[p + 1] - fdof[p] == 6) {
        for (int k = 0; k < 3; k++) ndofs[3 * ne + k] = fdof[p] + 3 + k;
        ne++;
      }
    }
    FMBD_GCALL(fmbd_csr_pattern_from_elements(nfull, ne, 3, ndofs, &Mf));
  }
  double Mr[36] = {0};
  for (int64_t e = 0; e < m->ntet; e++) {
    double xe[30], vol, d[10];
    const int64_t *en = m->tet + e * tn;
    for (int a = 0; a < tn; a++) memcpy(xe + 3 * a, m->xyz + 3 * en[a], 3 * sizeof(double));
    FMBD_GCALL(fmbd_fe_tet_matrices(tn, xe, b->E, b->nu, b->rho, e, NULL, Me, &vol));
    vol_solid += vol;
    double me = 0.0;
    for (int i = 0; i < tn * tn; i++) me += Me[i];
    fmbd_fe_hrz_scalar(tn, Me, me, d);
    for (int a = 0; a < tn; a++) b->node_mass[en[a]] += d[a];
    rigid_solid(tn, en, m->xyz, Me, Mr);
    if (opt->mass == FMBD_FE_MASS_CONSISTENT) {
      memset(Me3, 0, (size_t)(kt * kt) * sizeof *Me3);
      for (int a = 0; a < tn; a++) {
        for (int c = 0; c < tn; c++) {
          for (int k = 0; k < 3; k++) Me3[(3 * a + k) * kt + 3 * c + k] = Me[a * tn + c];
        }
      }
      FMBD_GCALL(fmbd_csr_add_block(Mf, kt, edofs + e * kmax, Me3));
    } else { // the lumped pattern is diagonal on translations
      for (int a = 0; a < 3 * tn; a++) {
        FMBD_GCALL(fmbd_csr_add_block(Mf, 1, edofs + e * kmax + a, d + a / 3));
      }
    }
  }
  for (int64_t e = 0; e < m->nbeam; e++) {
    const double *x0 = m->xyz + 3 * m->beam[2 * e], *x1 = m->xyz + 3 * m->beam[2 * e + 1];
    const double *v = b->beam_orientation + 3 * e;
    double L = sqrt((x1[0] - x0[0]) * (x1[0] - x0[0]) + (x1[1] - x0[1]) * (x1[1] - x0[1]) +
                    (x1[2] - x0[2]) * (x1[2] - x0[2]));
    vol_beam += b->area * L;
    FMBD_GCALL(fmbd_fe_beam_matrices(x0, x1, v, b->E, b->nu, b->rho, b->area, b->Iy, b->Iz, b->J,
                                     e, NULL, Me));
    rigid_beam(x0, x1, Me, Mr);
    FMBD_GCALL(fmbd_fe_beam_lumped(x0, x1, v, b->rho, b->area, b->J, e, Me3));
    b->node_mass[m->beam[2 * e]] += Me3[0];
    b->node_mass[m->beam[2 * e + 1]] += Me3[6 * 12 + 6];
    if (opt->mass == FMBD_FE_MASS_CONSISTENT) {
      FMBD_GCALL(fmbd_csr_add_block(Mf, 12, edofs + (m->ntet + e) * kmax, Me));
    } else { // HRZ: translations diagonal (isotropic m/2), rotations a 3x3 block per node
      for (int a = 0; a < 2; a++) {
        const int64_t *nd = edofs + (m->ntet + e) * kmax + 6 * a;
        double B3[9];
        for (int i = 0; i < 3; i++) {
          FMBD_GCALL(fmbd_csr_add_block(Mf, 1, nd + i, Me3 + (6 * a + i) * 13));
          for (int j = 0; j < 3; j++) B3[i * 3 + j] = Me3[(6 * a + 3 + i) * 12 + 6 * a + 3 + j];
        }
        FMBD_GCALL(fmbd_csr_add_block(Mf, 3, nd + 3, B3));
      }
    }
  }
  b->volume = vol_solid + vol_beam;
  body_properties(b, Mr);
  REDUCE(Mf, b->M);
#undef REDUCE
  *out = b;
  b = NULL;
done:
  fmbd_fe_body_destroy(&b);
  fmbd_free(on_solid);
  fmbd_free(on_beam);
  fmbd_free(fdof);
  fmbd_free(edofs);
  fmbd_free(ndofs);
  fmbd_free(Ke);
  fmbd_free(Me);
  fmbd_free(Me3);
  fmbd_free(sel);
  fmbd_csr_destroy(&Kf);
  fmbd_csr_destroy(&Mf);
  fmbd_csr_destroy(&T);
  fmbd_csr_destroy(&Kr);
  return rc;
}

// --- nodal stress ---------------------------------------------------------------------------
int fmbd_fe_nodal_stress(const fmbd_fe_body *b, int64_t ncases, const double *q, double *sigma) {
  FMBD_CHECK(b->expand && b->expand->nrows == 6 * b->nnodes && b->expand->ncols == b->ndof,
             FMBD_ERR_VALUE, "nodal stress: the body has no expansion matrix of shape (%lld, %lld)",
             (long long)(6 * b->nnodes), (long long)b->ndof);
  int rc = FMBD_OK;
  double *u = NULL;
  int *count = NULL;
  const int nn = b->tet_nodes;
  const double nu = b->nu, E = b->E;
  const double lambda = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), mu = E / (2.0 * (1.0 + nu));
  static const double node_xi[10][3] = {{0, 0, 0},   {1, 0, 0},   {0, 1, 0},  {0, 0, 1},
                                        {.5, 0, 0},  {.5, .5, 0}, {0, .5, 0}, {0, 0, .5},
                                        {0, .5, .5}, {.5, 0, .5}};
  FMBD_GALLOC(u = fmbd_malloc((size_t)(6 * b->nnodes) * sizeof *u));
  FMBD_GALLOC(count = fmbd_calloc((size_t)b->nnodes, sizeof *count));
  memset(sigma, 0, (size_t)(b->nnodes * 6 * ncases) * sizeof *sigma);
  for (int64_t e = 0; e < b->ntet; e++) {
    for (int a = 0; a < nn; a++) count[b->tet[e * nn + a]]++;
  }
  for (int64_t c = 0; c < ncases; c++) {
    fmbd_csr_matvec(b->expand, q + c * b->ndof, u);
    double *sg = sigma + c * b->nnodes * 6;
    for (int64_t e = 0; e < b->ntet; e++) {
      const int64_t *en = b->tet + e * nn;
      double xe[30], ue[30], N[10], dN[30], J[9], Ji[9];
      for (int a = 0; a < nn; a++) {
        memcpy(xe + 3 * a, b->xyz + 3 * en[a], 3 * sizeof(double));
        memcpy(ue + 3 * a, u + 6 * en[a], 3 * sizeof(double));
      }
      for (int a = 0; a < nn; a++) {
        fmbd_fe_tet_shape(nn, node_xi[a], N, dN);
        memset(J, 0, sizeof J);
        for (int k = 0; k < nn; k++) {
          for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++) J[i * 3 + j] += dN[k * 3 + i] * xe[k * 3 + j];
          }
        }
        double det = J[0] * (J[4] * J[8] - J[5] * J[7]) - J[1] * (J[3] * J[8] - J[5] * J[6]) +
                     J[2] * (J[3] * J[7] - J[4] * J[6]);
        FMBD_GCHECK(det > 0.0, FMBD_ERR_VALUE,
                    "element %lld (tet%d): Jacobian determinant %g at node %d", (long long)e, nn,
                    det, a);
        Ji[0] = (J[4] * J[8] - J[5] * J[7]) / det;
        Ji[1] = (J[2] * J[7] - J[1] * J[8]) / det;
        Ji[2] = (J[1] * J[5] - J[2] * J[4]) / det;
        Ji[3] = (J[5] * J[6] - J[3] * J[8]) / det;
        Ji[4] = (J[0] * J[8] - J[2] * J[6]) / det;
        Ji[5] = (J[2] * J[3] - J[0] * J[5]) / det;
        Ji[6] = (J[3] * J[7] - J[4] * J[6]) / det;
        Ji[7] = (J[1] * J[6] - J[0] * J[7]) / det;
        Ji[8] = (J[0] * J[4] - J[1] * J[3]) / det;
        double gu[9] = {0}; // gu[i][j] = d u_i / d x_j
        for (int k = 0; k < nn; k++) {
          double g[3];
          for (int j = 0; j < 3; j++) {
            g[j] = Ji[j * 3 + 0] * dN[k * 3 + 0] + Ji[j * 3 + 1] * dN[k * 3 + 1] +
                   Ji[j * 3 + 2] * dN[k * 3 + 2];
          }
          for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++) gu[i * 3 + j] += ue[k * 3 + i] * g[j];
          }
        }
        double tr = gu[0] + gu[4] + gu[8];
        double s[6] = {lambda * tr + 2 * mu * gu[0], lambda * tr + 2 * mu * gu[4],
                       lambda * tr + 2 * mu * gu[8], mu * (gu[1] + gu[3]),
                       mu * (gu[5] + gu[7]),         mu * (gu[2] + gu[6])};
        double *dst = sg + en[a] * 6;
        for (int i = 0; i < 6; i++) dst[i] += s[i];
      }
    }
    for (int64_t p = 0; p < b->nnodes; p++) {
      if (count[p] > 1) {
        for (int i = 0; i < 6; i++) sg[p * 6 + i] /= count[p];
      }
    }
  }
done:
  fmbd_free(u);
  fmbd_free(count);
  return rc;
}
