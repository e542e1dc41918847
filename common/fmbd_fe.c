// common/fmbd_fe.c: FE body assembly (checks, dof layout, CSR assembly, ties and clamps, mass
// properties), nodal stress, and the small helpers of fmbd_fe.h
// SPDX-License-Identifier: MIT
#define _DEFAULT_SOURCE  // madvise, MADV_HUGEPAGE (Linux); guarded below
#include "fmbd_fe.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_fe_impl.h"
#include "fmbd_log.h"

// --- small helpers ----------------------------------------------------------------------------
void fmbd_fe_opts_defaults(fmbd_fe_opts *o) {
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
  if (b->M && b->K && b->M->indices == b->K->indices) {  // pattern shared (fmbd_fe_assemble)
    b->M->indptr = NULL;
    b->M->indices = NULL;
  }
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
static int check_inputs(const fmbd_mesh *m, const fmbd_fe_opts *o) {
  FMBD_CHECK(isfinite(o->E) && o->E > 0.0, FMBD_ERR_VALUE,
             "Young's modulus E = %g: must be positive", o->E);
  FMBD_CHECK(isfinite(o->rho) && o->rho > 0.0, FMBD_ERR_VALUE, "density rho = %g: must be positive",
             o->rho);
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
  FMBD_CHECK(o->ninterfaces >= 0 && (o->ninterfaces == 0 || o->interfaces), FMBD_ERR_VALUE,
             "%d interfaces but no interface list", o->ninterfaces);
  FMBD_CHECK(o->nclamps >= 0 && (o->nclamps == 0 || o->clamps), FMBD_ERR_VALUE,
             "%d clamps but no clamp list", o->nclamps);
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
    FMBD_CHECK(
        !s->has_point || (isfinite(s->point[0]) && isfinite(s->point[1]) && isfinite(s->point[2])),
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
static void rigid_solid_sums(int nn, const int64_t *en, const double *xyz, const double *Me,
                             double S[13]) {
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
  S[0] = S0;
  memcpy(S + 1, S1, sizeof S1);
  memcpy(S + 4, S2, sizeof S2);
}

// Mr += the element's part from its sums S = (S0, S1, S2) (rigid_solid_sums)
static void rigid_solid_add(const double S[13], double Mr[36]) {
  const double S0 = S[0], *S1 = S + 1, *S2 = S + 4;
  // tr = -[S1]x ; rr = tr(S2) I - S2'
  double tr2 = S2[0] + S2[4] + S2[8];
  double X[9] = {0, -S1[2], S1[1], S1[2], 0, -S1[0], -S1[1], S1[0], 0};  // [S1]x
  for (int i = 0; i < 3; i++) {
    Mr[i * 6 + i] += S0;
    for (int j = 0; j < 3; j++) {
      Mr[i * 6 + 3 + j] -= X[i * 3 + j];
      Mr[(3 + i) * 6 + j] -= X[j * 3 + i];
      Mr[(3 + i) * 6 + 3 + j] += (i == j ? tr2 : 0.0) - S2[j * 3 + i];
    }
  }
}

// the beam's part of Mr, R' Me R (R: 12 x 6, node a rows [I, -[x_a]x ; 0, I])
static void rigid_beam(const double *x0, const double *x1, const double *Me, double Rb[36]) {
  double R[72] = {0};
  const double *x[2] = {x0, x1};
  for (int a = 0; a < 2; a++) {
    double *r = R + a * 36;
    fmbd_fe_rigid_rows(x[a], r);  // rows 0..2 (row stride 6)
    for (int k = 3; k < 6; k++) r[k * 6 + k] = 1.0;
  }
  double MR[72];  // Me R (12 x 6)
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
      Rb[i * 6 + j] = s;
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

// --- assembly straight into the reduced CSR ------------------------------------------------------
// The ties and clamps are applied element by element: u_e = T_e q (T_e the rows of T for the
// element's dofs), so the element adds T_e' K_e T_e to K' = T' K T. An element on untied nodes
// (nearly all) has T_e = a selection and adds K_e itself. The sparsity pattern is built on the
// node graph (fmbd_csr_pattern_from_elements over node lists: 9 times less work than over dofs
// for 3-dof nodes) and expanded to the dofs, whose rows of one node share their columns; each
// element then finds a node pair once (binary search in the node graph) and adds the dof block
// to consecutive entries. No full (untied) matrix and no coordinate list is ever formed.
typedef struct asm_ctx {
  const fmbd_mesh *m;
  fmbd_fe_body *b;
  int64_t nn;
  const int64_t *fdof;  // full dofs of node p: fdof[p] .. fdof[p+1]-1
  const int8_t *tied;   // per node
  const fmbd_csr *T;    // full -> active
  bool any_tied;
  int64_t *eptr, *enode;  // reduced node list of each element (CSR)
  // node graph: row p holds pairs (neighbour q, offset of q's dofs within a dof row of p) at
  // gq[2 G_ptr[p]] ..: the offset of a found neighbour is on the cache line just read
  int64_t *G_ptr;
  int32_t *gq;
  int64_t *stamp, *pos;   // scratch per node
  double *Te, *W, *R;     // scratch for tied elements
  int64_t cap;            // capacity of the scratch (in dofs)
  int32_t *nset;          // set of each node (node_sets), NULL: one set
  int32_t nsets, cur;     // number of sets, the set being visited
  int64_t *sptr, *selem;  // elements that touch each set, increasing (CSR)
} asm_ctx;

static void asm_free(asm_ctx *c) {
  fmbd_free(c->eptr);
  fmbd_free(c->enode);
  fmbd_free(c->G_ptr);
  fmbd_free(c->gq);
  fmbd_free(c->stamp);
  fmbd_free(c->pos);
  fmbd_free(c->Te);
  fmbd_free(c->W);
  fmbd_free(c->R);
  fmbd_free(c->nset);
  fmbd_free(c->sptr);
  fmbd_free(c->selem);
}

// are the rows of node p added in this visit (all rows when there is one set)
static inline bool in_set(const asm_ctx *c, int64_t p) {
  return !c->nset || c->nset[p] == c->cur;
}

// element e's nodes and the number of its dofs per node (3 tet, 6 beam)
static int elem_nodes(const asm_ctx *c, int64_t e, const int64_t **nodes, int *per) {
  const fmbd_mesh *m = c->m;
  if (e < m->ntet) {
    *nodes = m->tet + e * m->tet_nodes;
    *per = 3;
    return m->tet_nodes;
  }
  *nodes = m->beam + 2 * (e - m->ntet);
  *per = 6;
  return 2;
}

static inline int64_t nact(const fmbd_fe_body *b, int64_t p) {
  return b->node_dof[p + 1] - b->node_dof[p];
}

// an element adds its own matrix (no T_e product) when its nodes are untied and carry exactly
// the element's dofs per node (or none: clamped)
static bool elem_plain(const asm_ctx *c, int nen, const int64_t *nodes, int per) {
  for (int a = 0; a < nen; a++) {
    int64_t p = nodes[a];
    if (c->tied[p] || (nact(c->b, p) != 0 && c->fdof[p + 1] - c->fdof[p] != per)) return false;
  }
  return true;
}

// Ask for transparent huge pages on a large array about to be filled: first touches of 4 KiB
// pages dominated assembly on the benchmark machine (a VM: ~10 ms per MB); huge pages halve it.
// A hint only: failure is harmless, and other systems simply skip it.
static void hugepage_hint(void *p, size_t n) {
#ifdef MADV_HUGEPAGE
  const size_t page = 4096;
  if (n < (size_t)(8u << 20)) return;
  uintptr_t a = ((uintptr_t)p + page - 1) & ~(uintptr_t)(page - 1),
            e = ((uintptr_t)p + n) & ~(uintptr_t)(page - 1);
  if (e > a) (void)madvise((void *)a, e - a, MADV_HUGEPAGE);
#else
  (void)p;
  (void)n;
#endif
}

// the reduced node list of element e into list (returns its length): plain elements keep their
// active nodes; others take the nodes of the active dofs their T rows refer to
static int64_t elem_list(asm_ctx *c, int64_t e, int64_t *list) {
  const int64_t *nodes;
  int per, nen = elem_nodes(c, e, &nodes, &per);
  int64_t n = 0;
  if (elem_plain(c, nen, nodes, per)) {
    for (int a = 0; a < nen; a++) {
      if (nact(c->b, nodes[a]) > 0) list[n++] = nodes[a];
    }
    return n;
  }
  for (int a = 0; a < nen; a++) {
    for (int k = 0; k < per; k++) {
      int64_t f = c->fdof[nodes[a]] + k;
      for (int64_t t = c->T->indptr[f]; t < c->T->indptr[f + 1]; t++) {
        int64_t q = c->b->dofs[2 * c->T->indices[t]];
        if (c->stamp[q] != e) {
          c->stamp[q] = e;
          c->pos[q] = n;
          list[n++] = q;
        }
      }
    }
  }
  return n;
}

static int element_lists(asm_ctx *c) {
  const int64_t nel = c->m->ntet + c->m->nbeam;
  int64_t *tmp = NULL;
  int rc = FMBD_OK;
  FMBD_GALLOC(c->stamp = fmbd_malloc((size_t)c->nn * sizeof *c->stamp));
  FMBD_GALLOC(c->pos = fmbd_malloc((size_t)c->nn * sizeof *c->pos));
  for (int64_t p = 0; p < c->nn; p++) c->stamp[p] = -1;
  FMBD_GALLOC(tmp = fmbd_malloc((size_t)c->nn * sizeof *tmp));
  FMBD_GALLOC(c->eptr = fmbd_malloc(((size_t)nel + 1) * sizeof *c->eptr));
  c->eptr[0] = 0;
  for (int64_t e = 0; e < nel; e++) c->eptr[e + 1] = c->eptr[e] + elem_list(c, e, tmp);
  FMBD_GALLOC(c->enode = fmbd_malloc((size_t)(c->eptr[nel] + 1) * sizeof *c->enode));
  for (int64_t p = 0; p < c->nn; p++) c->stamp[p] = -1;
  for (int64_t e = 0; e < nel; e++) elem_list(c, e, c->enode + c->eptr[e]);
  for (int64_t p = 0; p < c->nn; p++) c->any_tied |= c->tied[p] != 0;
  // scratch for tied elements: the longest reduced dof list
  int64_t cap = 12;
  for (int64_t e = 0; e < nel; e++) {
    int64_t k = 0;
    for (int64_t i = c->eptr[e]; i < c->eptr[e + 1]; i++) k += nact(c->b, c->enode[i]);
    if (k > cap) cap = k;
  }
  c->cap = cap;
  FMBD_GALLOC(c->Te = fmbd_malloc((size_t)(30 * cap) * sizeof *c->Te));
  FMBD_GALLOC(c->W = fmbd_malloc((size_t)(30 * cap) * sizeof *c->W));
  FMBD_GALLOC(c->R = fmbd_malloc((size_t)(cap * cap) * sizeof *c->R));
done:
  fmbd_free(tmp);
  return rc;
}

// node graph from the element lists (pattern_from_elements on padded lists; the few long lists
// of RBE3 elements separately, then merged), expanded to the dof pattern of K
static int build_pattern(asm_ctx *c, fmbd_csr **out) {
  int rc = FMBD_OK;
  const fmbd_fe_body *b = c->b;
  const int64_t nel = c->m->ntet + c->m->nbeam, nn = c->nn;
  const int kshort = c->m->ntet > 0 && c->m->tet_nodes > 2 ? c->m->tet_nodes : 2;
  int64_t *lists = NULL;
  fmbd_csr *G1 = NULL, *G2 = NULL, *A = NULL;
  int64_t nlong = 0, klong = 0;
  FMBD_CHECK(nn < INT32_MAX && b->ndof < INT32_MAX, FMBD_ERR_VALUE,
             "%lld nodes, %lld dofs: more than the assembly's 32-bit node graph holds",
             (long long)nn, (long long)b->ndof);
  for (int64_t e = 0; e < nel; e++) {
    int64_t len = c->eptr[e + 1] - c->eptr[e];
    if (len > kshort) {
      nlong++;
      if (len > klong) klong = len;
    }
  }
  for (int pass = 0; pass < 2; pass++) {
    int64_t k = pass ? klong : kshort, ne = pass ? nlong : nel - nlong, i = 0;
    if (ne == 0) continue;
    FMBD_GALLOC(lists = fmbd_malloc((size_t)(ne * k) * sizeof *lists));
    for (int64_t e = 0; e < nel; e++) {
      int64_t len = c->eptr[e + 1] - c->eptr[e];
      if ((len > kshort) != (pass == 1)) continue;
      for (int64_t a = 0; a < k; a++) lists[i * k + a] = a < len ? c->enode[c->eptr[e] + a] : -1;
      i++;
    }
    FMBD_GCALL(fmbd_csr_pattern_from_elements(nn, ne, (int)k, lists, pass ? &G2 : &G1));
    fmbd_free(lists);
    lists = NULL;
  }
  // --- merge the two node graphs (sorted rows) ---
  FMBD_GALLOC(c->G_ptr = fmbd_calloc((size_t)nn + 1, sizeof *c->G_ptr));
  for (int merge = 0; merge < 2; merge++) {
    int64_t k = 0;
    for (int64_t p = 0; p < nn; p++) {
      int64_t i1 = G1 ? G1->indptr[p] : 0, e1 = G1 ? G1->indptr[p + 1] : 0;
      int64_t i2 = G2 ? G2->indptr[p] : 0, e2 = G2 ? G2->indptr[p + 1] : 0;
      while (i1 < e1 || i2 < e2) {
        int64_t v;
        if (i2 >= e2 || (i1 < e1 && G1->indices[i1] < G2->indices[i2])) {
          v = G1->indices[i1++];
        } else if (i1 >= e1 || G2->indices[i2] < G1->indices[i1]) {
          v = G2->indices[i2++];
        } else {
          v = G1->indices[i1++];
          i2++;
        }
        if (merge) c->gq[2 * k] = (int32_t)v;
        k++;
      }
      if (!merge) c->G_ptr[p + 1] = k;
    }
    if (!merge) {
      FMBD_GALLOC(c->gq = fmbd_malloc((size_t)(2 * k + 2) * sizeof *c->gq));
    }
  }
  fmbd_csr_destroy(&G1);
  fmbd_csr_destroy(&G2);
  // --- expand to dofs: every row of node p holds the active dofs of p's neighbours ---
  int64_t nnz = 0;
  for (int64_t p = 0; p < nn; p++) {
    int64_t len = 0;
    for (int64_t t = c->G_ptr[p]; t < c->G_ptr[p + 1]; t++) {
      c->gq[2 * t + 1] = (int32_t)len;
      len += nact(b, c->gq[2 * t]);
    }
    nnz += nact(b, p) * len;
  }
  FMBD_GCALL(fmbd_csr_create(b->ndof, b->ndof, nnz, &A));
  hugepage_hint(A->indices, (size_t)nnz * sizeof *A->indices);
  hugepage_hint(A->data, (size_t)nnz * sizeof *A->data);
  int64_t at = 0;
  for (int64_t p = 0; p < nn; p++) {
    for (int64_t r = b->node_dof[p]; r < b->node_dof[p + 1]; r++) {
      A->indptr[r] = at;
      for (int64_t t = c->G_ptr[p]; t < c->G_ptr[p + 1]; t++) {
        int64_t q = c->gq[2 * t];
        for (int64_t j = b->node_dof[q]; j < b->node_dof[q + 1]; j++) A->indices[at++] = j;
      }
    }
  }
  A->indptr[b->ndof] = at;  // A->data is zero already (fmbd_csr_create callocs it)
  *out = A;
  A = NULL;
done:
  fmbd_free(lists);
  fmbd_csr_destroy(&G1);
  fmbd_csr_destroy(&G2);
  fmbd_csr_destroy(&A);
  return rc;
}

// diagonal pattern for a lumped mass without ties, plus the 3x3 rotational block of 6-dof nodes
static int lumped_pattern(const fmbd_fe_body *b, fmbd_csr **out) {
  int rc = FMBD_OK;
  int64_t *el = NULL, ne = 0;
  FMBD_GALLOC(el = fmbd_malloc((size_t)(3 * b->ndof + 1) * sizeof *el));
  for (int64_t p = 0; p < b->nnodes; p++) {
    int64_t r0 = b->node_dof[p], n = nact(b, p);
    for (int64_t k = 0; k < n && k < 3; k++) {
      el[3 * ne] = r0 + k;
      el[3 * ne + 1] = el[3 * ne + 2] = -1;
      ne++;
    }
    if (n == 6) {
      for (int k = 0; k < 3; k++) el[3 * ne + k] = r0 + 3 + k;
      ne++;
    }
  }
  FMBD_GCALL(fmbd_csr_pattern_from_elements(b->ndof, ne, 3, el, out));
done:
  fmbd_free(el);
  return rc;
}

// A(r0+k, r0+k) += v for k < n (no-op for a clamped node: r0 is then the next node's row, so
// callers pass only active nodes; a clamped node has node_dof[p] == node_dof[p+1])
static int add_diag(fmbd_csr *A, int64_t r0, int n, double v) {
  for (int k = 0; k < n; k++) {
    int64_t pos = fmbd_csr_find(A, r0 + k, r0 + k);
    FMBD_CHECK(pos >= 0, FMBD_ERR_INTERNAL, "diagonal entry %lld not in the pattern",
               (long long)(r0 + k));
    A->data[pos] += v;
  }
  return FMBD_OK;
}

// position of node q in the sorted node row (pairs, the node first: row[2 t]), or -1.
// Branch-free halving (the compiler makes the step a conditional move): the branches of a plain
// binary search mispredicted about every other step, a quarter of the scatter's time.
static inline int64_t node_pos(const int32_t *row, int64_t len, int64_t q) {
  if (len <= 0) return -1;
  const int32_t *base = row;
  int64_t n = len;
  while (n > 1) {
    const int64_t half = n / 2;
    base = base[2 * half] <= q ? base + 2 * half : base;
    n -= half;
  }
  return *base == q ? (base - row) / 2 : -1;
}

// add the blocks of the element matrices Ae (and Be, may be NULL) for the nodes of list: block
// (a, b) is Ae[(eoff[a] + i) * stride + eoff[b] + j], i < nact(list[a]), j < nact(list[b]);
// only the rows of the nodes in the set being visited
static int add_blocks(asm_ctx *c, int64_t nl, const int64_t *list, const int64_t *eoff,
                      int64_t stride, const double *Ae, const double *Be) {
  fmbd_fe_body *b = c->b;
  fmbd_csr *K = b->K, *M = b->M;
  for (int64_t a = 0; a < nl; a++) {
    int64_t p = list[a], np = nact(b, p), r0 = b->node_dof[p];
    if (!in_set(c, p)) continue;
    const int32_t *row = c->gq + 2 * c->G_ptr[p];
    int64_t len = c->G_ptr[p + 1] - c->G_ptr[p];
    for (int64_t bb = 0; bb < nl; bb++) {
      int64_t q = list[bb], nq = nact(b, q);
      int64_t t = node_pos(row, len, q);
      FMBD_CHECK(t >= 0, FMBD_ERR_INTERNAL, "node pair (%lld, %lld) not in the pattern",
                 (long long)p, (long long)q);
      int64_t o = row[2 * t + 1];
      for (int64_t i = 0; i < np; i++) {
        int64_t base = K->indptr[r0 + i] + o;
        const double *ar = Ae + (eoff[a] + i) * stride + eoff[bb];
        for (int64_t j = 0; j < nq; j++) K->data[base + j] += ar[j];
        if (Be) {
          const double *br = Be + (eoff[a] + i) * stride + eoff[bb];
          for (int64_t j = 0; j < nq; j++) M->data[base + j] += br[j];
        }
      }
    }
  }
  return FMBD_OK;
}

// A plain tetrahedron (elem_plain: its active nodes carry 3 dofs each): K gets the 3 x 3 blocks
// of Ke (3 tn x 3 tn), M (when Ms is given) Ms[a][b] on the diagonal of block (a, b): the
// element mass is Ms (x) I3, whose other entries are zeros, and adding a zero leaves an entry
// bit for bit as it was (an entry starts +0.0 and a sum is -0.0 only when both terms are, so no
// entry is ever -0.0). Only the rows of the nodes in the set being visited.
static int add_tet(asm_ctx *c, int64_t e, int tn, const double *Ke, const double *Ms) {
  const fmbd_fe_body *b = c->b;
  const int64_t *en = c->m->tet + e * tn, *list = c->enode + c->eptr[e];
  const int64_t nl = c->eptr[e + 1] - c->eptr[e], kt = 3 * tn;
  const int64_t *indptr = b->K->indptr;
  double *Kd = b->K->data, *Md = b->M->data;
  int ea[10];  // the element node of each list entry (the list: active nodes in element order)
  for (int a = 0, i = 0; a < tn; a++) {
    if (nact(b, en[a]) > 0) ea[i++] = a;
  }
  for (int64_t i = 0; i < nl; i++) {
    const int64_t p = list[i];
    if (!in_set(c, p)) continue;
    const int64_t r0 = b->node_dof[p], g0 = c->G_ptr[p], len = c->G_ptr[p + 1] - g0;
    const int64_t k0 = indptr[r0], k1 = indptr[r0 + 1], k2 = indptr[r0 + 2];
    const double *kr = Ke + 3 * ea[i] * kt, *mr = Ms ? Ms + ea[i] * tn : NULL;
    for (int64_t j = 0; j < nl; j++) {
      const int64_t t = node_pos(c->gq + 2 * g0, len, list[j]);
      FMBD_CHECK(t >= 0, FMBD_ERR_INTERNAL, "node pair (%lld, %lld) not in the pattern",
                 (long long)p, (long long)list[j]);
      const int64_t o = c->gq[2 * (g0 + t) + 1];
      const double *k = kr + 3 * ea[j];
      double *d0 = Kd + k0 + o, *d1 = Kd + k1 + o, *d2 = Kd + k2 + o;
      d0[0] += k[0];
      d0[1] += k[1];
      d0[2] += k[2];
      d1[0] += k[kt];
      d1[1] += k[kt + 1];
      d1[2] += k[kt + 2];
      d2[0] += k[2 * kt];
      d2[1] += k[2 * kt + 1];
      d2[2] += k[2 * kt + 2];
      if (mr) {
        const double v = mr[ea[j]];
        Md[k0 + o] += v;
        Md[k1 + o + 1] += v;
        Md[k2 + o + 2] += v;
      }
    }
  }
  return FMBD_OK;
}

// R = Te' X Te (ka x ka, symmetrised) for the k x k element matrix X
static void reduce_matrix(asm_ctx *c, int k, int64_t ka, const double *X) {
  double *Te = c->Te, *W = c->W, *R = c->R;
  for (int i = 0; i < k; i++) {  // W = X Te (k x ka)
    for (int64_t j = 0; j < ka; j++) W[i * ka + j] = 0.0;
    for (int l = 0; l < k; l++) {
      double x = X[i * k + l];
      if (x == 0.0) continue;
      for (int64_t j = 0; j < ka; j++) W[i * ka + j] += x * Te[l * ka + j];
    }
  }
  for (int64_t i = 0; i < ka * ka; i++) R[i] = 0.0;
  for (int l = 0; l < k; l++) {  // R = Te' W
    for (int64_t i = 0; i < ka; i++) {
      double t = Te[l * ka + i];
      if (t == 0.0) continue;
      for (int64_t j = 0; j < ka; j++) R[i * ka + j] += t * W[l * ka + j];
    }
  }
  for (int64_t i = 0; i < ka; i++) {
    for (int64_t j = i + 1; j < ka; j++) {
      double v = 0.5 * (R[i * ka + j] + R[j * ka + i]);
      R[i * ka + j] = R[j * ka + i] = v;
    }
  }
}

// add element e's stiffness Ke and mass Me (k x k over its own dofs, row-major; Me may be NULL)
static int add_element(asm_ctx *c, int64_t e, int k, const double *Ke, const double *Me) {
  const int64_t *nodes;
  int per, nen = elem_nodes(c, e, &nodes, &per);
  const int64_t *list = c->enode + c->eptr[e];
  int64_t nl = c->eptr[e + 1] - c->eptr[e], eoff[32];
  if (elem_plain(c, nen, nodes, per)) {
    // the list is the element's active nodes in element order
    for (int a = 0, i = 0; a < nen; a++) {
      if (nact(c->b, nodes[a]) > 0) eoff[i++] = (int64_t)per * a;
    }
    return add_blocks(c, nl, list, eoff, k, Ke, Me);
  }
  // --- tied element: Te (k x ka) from the T rows, then Te' Ke Te and Te' Me Te ---
  int64_t ka = 0;
  int rc = FMBD_OK;
  int64_t *off = NULL;
  FMBD_GALLOC(off = fmbd_malloc((size_t)nl * sizeof *off));
  for (int64_t a = 0; a < nl; a++) {
    off[a] = ka;
    c->stamp[list[a]] = -2 - e;  // position lookups below
    c->pos[list[a]] = a;
    ka += nact(c->b, list[a]);
  }
  for (int64_t i = 0; i < k * ka; i++) c->Te[i] = 0.0;
  for (int a = 0; a < nen; a++) {
    for (int kk = 0; kk < per; kk++) {
      int64_t f = c->fdof[nodes[a]] + kk, row = (int64_t)per * a + kk;
      for (int64_t t = c->T->indptr[f]; t < c->T->indptr[f + 1]; t++) {
        int64_t col = c->T->indices[t], q = c->b->dofs[2 * col];
        FMBD_GCHECK(c->stamp[q] == -2 - e, FMBD_ERR_INTERNAL,
                    "element %lld: node %lld missing from its list", (long long)e, (long long)q);
        c->Te[row * ka + off[c->pos[q]] + (col - c->b->node_dof[q])] += c->T->data[t];
      }
    }
  }
  reduce_matrix(c, k, ka, Ke);
  double *RK = NULL;
  FMBD_GALLOC(RK = fmbd_malloc((size_t)(ka * ka) * sizeof *RK));
  memcpy(RK, c->R, (size_t)(ka * ka) * sizeof *RK);
  if (Me) reduce_matrix(c, k, ka, Me);
  rc = add_blocks(c, nl, list, off, ka, RK, Me ? c->R : NULL);
  fmbd_free(RK);
done:
  fmbd_free(off);
  return rc;
}

// --- the order of the element loop ------------------------------------------------------------
// Every K and M entry must take its elements' terms in element order (then the matrices are bit
// for bit those of a plain loop over the elements), but gmsh numbers elements and nodes in no
// spatial order: the elements of one node of the 946 k-dof rod spread over half the element
// list, and a plain loop found nearly every entry it added to out of cache. So the nodes are cut
// into sets of nearby nodes (runs of their Morton order), each small enough that its rows of K
// and M stay in cache, and the loop visits set by set the elements that touch the set, in
// element order, adding only the set's rows. Each row still takes its elements in element
// order. A tetrahedron on several sets is computed at its first visit and kept in a pool until
// its last one; a beam is computed at each visit (cheap).
#define SET_BYTES ((double)(4 << 20))  // K and M values of one set's rows

static uint64_t spread3(uint64_t v) {  // the low 21 bits of v to every third bit
  v &= 0x1fffffULL;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}

typedef struct node_key {
  uint64_t key;
  int64_t node;
} node_key;

static int cmp_node_key(const void *a, const void *b) {
  const node_key *x = a, *y = b;
  if (x->key != y->key) return x->key < y->key ? -1 : 1;
  return (x->node > y->node) - (x->node < y->node);
}

// c->nset (NULL when all nodes make one set), c->nsets, and the element list of each set
fmbd_fe_asm_hook fmbd_fe_asm_test = {0, 0};

static int node_sets(asm_ctx *c) {
  int rc = FMBD_OK;
  const fmbd_fe_body *b = c->b;
  const int64_t nn = c->nn, nel = c->m->ntet + c->m->nbeam;
  node_key *keys = NULL;
  int32_t *tmp = NULL, *cur = NULL;
  const double per = 16.0 * (double)fmbd_csr_nnz(b->K) / (double)nn;  // bytes per node
  int64_t S = (int64_t)(SET_BYTES / (per > 1.0 ? per : 1.0));
  if (S < 64) S = 64;
  if (fmbd_fe_asm_test.set_nodes > 0) S = fmbd_fe_asm_test.set_nodes;
  c->nsets = 1;
  if (nn > S) {
    double lo[3], hi[3];
    for (int k = 0; k < 3; k++) lo[k] = hi[k] = b->xyz[k];
    for (int64_t p = 0; p < nn; p++) {
      for (int k = 0; k < 3; k++) {
        double x = b->xyz[3 * p + k];
        lo[k] = x < lo[k] ? x : lo[k];
        hi[k] = x > hi[k] ? x : hi[k];
      }
    }
    // one scale for the three axes: cubic cells, compact sets on long bodies too
    double ext = 0.0;
    for (int k = 0; k < 3; k++) ext = hi[k] - lo[k] > ext ? hi[k] - lo[k] : ext;
    FMBD_GALLOC(keys = fmbd_malloc((size_t)nn * sizeof *keys));
    for (int64_t p = 0; p < nn; p++) {
      uint64_t key = 0;
      for (int k = 0; k < 3; k++) {
        double f = ext > 0.0 ? (b->xyz[3 * p + k] - lo[k]) / ext : 0.0;
        key |= spread3((uint64_t)(f * 2097151.0)) << k;
      }
      keys[p].key = key;
      keys[p].node = p;
    }
    qsort(keys, (size_t)nn, sizeof *keys, cmp_node_key);
    FMBD_GALLOC(c->nset = fmbd_malloc((size_t)nn * sizeof *c->nset));
    for (int64_t i = 0; i < nn; i++) c->nset[keys[i].node] = (int32_t)(i / S);
    c->nsets = (int32_t)((nn + S - 1) / S);
  }
  fmbd_fe_asm_test.sets_used = c->nsets;
  // the sets of each element: of its mesh nodes (node masses) and of its reduced list (rows)
  int64_t maxl = 0;
  for (int64_t e = 0; e < nel; e++) {
    if (c->eptr[e + 1] - c->eptr[e] > maxl) maxl = c->eptr[e + 1] - c->eptr[e];
  }
  FMBD_GALLOC(tmp = fmbd_malloc((size_t)(maxl + 10) * sizeof *tmp));
  FMBD_GALLOC(c->sptr = fmbd_calloc((size_t)c->nsets + 1, sizeof *c->sptr));
  FMBD_GALLOC(cur = fmbd_calloc((size_t)c->nsets, sizeof *cur));
  for (int pass = 0; pass < 2; pass++) {
    for (int64_t e = 0; e < nel; e++) {
      int n = 0;
      if (c->nset) {
        const int64_t *nodes;
        int per_node, nen = elem_nodes(c, e, &nodes, &per_node);
        for (int64_t i = -nen; i < c->eptr[e + 1] - c->eptr[e]; i++) {
          int32_t s = c->nset[i < 0 ? nodes[nen + i] : c->enode[c->eptr[e] + i]];
          int j = 0;
          while (j < n && tmp[j] != s) j++;
          if (j == n) tmp[n++] = s;
        }
      } else {
        tmp[n++] = 0;
      }
      for (int j = 0; j < n; j++) {
        if (pass == 0) {
          c->sptr[tmp[j] + 1]++;
        } else {
          c->selem[c->sptr[tmp[j]] + cur[tmp[j]]++] = e;
        }
      }
    }
    if (pass == 0) {
      for (int32_t s = 0; s < c->nsets; s++) c->sptr[s + 1] += c->sptr[s];
      FMBD_GALLOC(c->selem = fmbd_malloc((size_t)(c->sptr[c->nsets] + 1) * sizeof *c->selem));
    }
  }
done:
  fmbd_free(keys);
  fmbd_free(tmp);
  fmbd_free(cur);
  return rc;
}

// the first element, in element order, whose matrices fail (its error recorded), up to and
// including `last` (the element that failed in the set-wise loop): the error the plain loop
// reported
static int first_failure(const fmbd_mesh *m, const fmbd_fe_body *b, int64_t last, double *Ke,
                         double *Me) {
  for (int64_t e = 0; e <= last && e < m->ntet; e++) {
    double xe[30], Ms[100], vol;
    const int64_t *en = m->tet + e * m->tet_nodes;
    for (int a = 0; a < m->tet_nodes; a++) memcpy(xe + 3 * a, m->xyz + 3 * en[a], 3 * sizeof *xe);
    FMBD_CALL(fmbd_fe_tet_matrices(m->tet_nodes, xe, b->E, b->nu, b->rho, e, Ke, Ms, &vol));
  }
  for (int64_t e = 0; e + m->ntet <= last && e < m->nbeam; e++) {
    const double *x0 = m->xyz + 3 * m->beam[2 * e], *x1 = m->xyz + 3 * m->beam[2 * e + 1];
    const double *v = b->beam_orientation + 3 * e;
    FMBD_CALL(fmbd_fe_beam_matrices(x0, x1, v, b->E, b->nu, b->rho, b->area, b->Iy, b->Iz, b->J, e,
                                    Ke, Me));
    FMBD_CALL(fmbd_fe_beam_lumped(x0, x1, v, b->rho, b->area, b->J, e, Me));
  }
  return FMBD_OK;  // not reached: element `last` failed
}

// --- assembly -----------------------------------------------------------------------------------
int fmbd_fe_assemble(const fmbd_mesh *m, const fmbd_fe_opts *opt, fmbd_fe_body **out) {
  int rc = FMBD_OK;
  fmbd_fe_opts defaults;
  if (!opt) {
    fmbd_fe_opts_defaults(&defaults);
    opt = &defaults;
  }
  fmbd_fe_body *b = NULL;
  int8_t *on_solid = NULL, *on_beam = NULL, *tied = NULL;
  int64_t *fdof = NULL;
  double *Ke = NULL, *Me = NULL, *Ml = NULL, *once = NULL, *pool = NULL;
  uint8_t *seen = NULL;
  int32_t *slot = NULL, *vleft = NULL, *freel = NULL;
  fmbd_csr *T = NULL;
  asm_ctx c = {0};
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
    for (int g = 0; g < m->ngroups; g++)
      FMBD_GALLOC(b->group_name[g] = fmbd_strdup(m->group_name[g]));
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
    on_beam[it->node] = 1;  // 6 dofs
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
  // --- ties and clamps first: T (full -> active dofs), /dofs, /expand ---
  FMBD_GALLOC(tied = fmbd_malloc((size_t)nn));
  FMBD_GCALL(fmbd_fe_tie_build(b, fdof, &T, tied));
  c.m = m;
  c.b = b;
  c.nn = nn;
  c.fdof = fdof;
  c.tied = tied;
  c.T = T;
  FMBD_GCALL(element_lists(&c));
  FMBD_GCALL(build_pattern(&c, &b->K));
  const bool diag_mass = opt->mass == FMBD_FE_MASS_LUMPED && !c.any_tied;
  if (diag_mass) {
    FMBD_GCALL(lumped_pattern(b, &b->M));
  } else {
    // K's pattern, shared: M->indptr and M->indices are K's arrays (fmbd_fe_body_destroy frees
    // them once). A copy was a quarter of the assembly's memory and of its first page touches.
    int64_t nnz = fmbd_csr_nnz(b->K);
    FMBD_GALLOC(b->M = fmbd_calloc(1, sizeof *b->M));
    b->M->nrows = b->M->ncols = b->ndof;
    b->M->indptr = b->K->indptr;
    b->M->indices = b->K->indices;
    // calloc: large blocks come zeroed from the kernel, no zero-fill pass of our own
    FMBD_GALLOC(b->M->data = fmbd_calloc((size_t)(nnz ? nnz : 1), sizeof(double)));
    hugepage_hint(b->M->data, (size_t)nnz * sizeof(double));
  }
  FMBD_GALLOC(b->node_mass = fmbd_calloc((size_t)nn, sizeof *b->node_mass));
  // --- element loop, set by set (node_sets): matrices, reduction, addition; node masses. The
  // sums over all elements (volume, rigid-body mass) are kept per element at its first visit and
  // added in element order after the loop, as the plain loop added them.
  FMBD_GCALL(node_sets(&c));
  const int tn = b->tet_nodes, kt = 3 * tn;
  const int64_t nel = m->ntet + m->nbeam;
  FMBD_GALLOC(Ke = fmbd_malloc(900 * sizeof *Ke));
  FMBD_GALLOC(Me = fmbd_malloc(900 * sizeof *Me));
  FMBD_GALLOC(Ml = fmbd_malloc(900 * sizeof *Ml));
  FMBD_GALLOC(once = fmbd_malloc((size_t)(14 * m->ntet + 37 * m->nbeam + 1) * sizeof *once));
  FMBD_GALLOC(seen = fmbd_calloc((size_t)nel + 1, 1));
  FMBD_GALLOC(slot = fmbd_malloc(((size_t)m->ntet + 1) * sizeof *slot));
  FMBD_GALLOC(vleft = fmbd_calloc((size_t)m->ntet + 1, sizeof *vleft));
  for (int64_t e = 0; e < m->ntet; e++) slot[e] = -1;
  for (int64_t i = 0; i < c.sptr[c.nsets]; i++) {
    if (c.selem[i] < m->ntet) vleft[c.selem[i]]++;
  }
  const int64_t csz = kt * kt + tn * tn + tn;  // Ke, Ms, d of one element in the pool
  int32_t pcap = 0, nfree = 0;
  double Mr[36] = {0}, vol_solid = 0.0, vol_beam = 0.0;
  const bool progress = fmbd_progress_enabled() && nel > 200000;
  const int64_t nvisit = c.sptr[c.nsets];
  for (c.cur = 0; c.cur < c.nsets; c.cur++) {
    for (int64_t iv = c.sptr[c.cur]; iv < c.sptr[c.cur + 1]; iv++) {
      const int64_t e = c.selem[iv];
      const bool first = !seen[e];
      seen[e] = 1;
      if (progress && iv % 65536 == 0) {
        fmbd_progress("assembling: %lld of %lld element visits", (long long)iv, (long long)nvisit);
      }
      if (e < m->ntet) {
        // the element's Ke, Ms and HRZ masses: computed at its first visit, kept in the pool
        // for its later visits
        double Ms0[100], d0[10], Ld[100], *Kx = Ke, *Ms = Ms0, *d = d0;
        const int64_t *en = m->tet + e * tn;
        int32_t sl = slot[e];
        if (sl < 0 && vleft[e] > 1) {
          if (nfree == 0) {  // grow the pool
            const int32_t ncap2 = 2 * pcap + 64;
            double *pool2 = fmbd_realloc(pool, (size_t)ncap2 * (size_t)csz * sizeof *pool);
            FMBD_GCHECK(pool2, FMBD_ERR_NOMEM, "out of memory");
            pool = pool2;
            int32_t *fl2 = fmbd_realloc(freel, (size_t)ncap2 * sizeof *freel);
            FMBD_GCHECK(fl2, FMBD_ERR_NOMEM, "out of memory");
            freel = fl2;
            for (int32_t k = ncap2 - 1; k >= pcap; k--) freel[nfree++] = k;
            pcap = ncap2;
          }
          sl = slot[e] = freel[--nfree];
          Kx = pool + (size_t)sl * (size_t)csz;
          Ms = Kx + kt * kt;
          d = Ms + tn * tn;
        } else if (sl >= 0) {
          Kx = pool + (size_t)sl * (size_t)csz;
          Ms = Kx + kt * kt;
          d = Ms + tn * tn;
        }
        if (first) {
          double xe[30], vol;
          for (int a = 0; a < tn; a++) memcpy(xe + 3 * a, m->xyz + 3 * en[a], 3 * sizeof(double));
          rc = fmbd_fe_tet_matrices(tn, xe, b->E, b->nu, b->rho, e, Kx, Ms, &vol);
          if (rc != FMBD_OK) {
            int rc2 = first_failure(m, b, e, Ke, Me);
            if (rc2 != FMBD_OK) rc = rc2;
            goto done;
          }
          double me = 0.0;
          for (int i = 0; i < tn * tn; i++) me += Ms[i];
          fmbd_fe_hrz_scalar(tn, Ms, me, d);
          once[14 * e] = vol;
          rigid_solid_sums(tn, en, m->xyz, Ms, once + 14 * e + 1);
        }
        if (--vleft[e] == 0 && sl >= 0) freel[nfree++] = sl;  // used below, before any reuse
        for (int a = 0; a < tn; a++) {
          if (in_set(&c, en[a])) b->node_mass[en[a]] += d[a];
        }
        if (elem_plain(&c, tn, en, 3)) {
          // the element mass Ms (x) I3: consistent, or the HRZ diagonal
          const double *Mx = Ms;
          if (opt->mass != FMBD_FE_MASS_CONSISTENT) {
            memset(Ld, 0, (size_t)(tn * tn) * sizeof *Ld);
            for (int a = 0; a < tn; a++) Ld[a * tn + a] = d[a];
            Mx = Ld;
          }
          FMBD_GCALL(add_tet(&c, e, tn, Kx, diag_mass ? NULL : Mx));
        } else {
          // the 3D element mass: consistent Ms (x) I3, or the HRZ diagonal
          memset(Me, 0, (size_t)(kt * kt) * sizeof *Me);
          for (int a = 0; a < tn; a++) {
            for (int k = 0; k < 3; k++) {
              if (opt->mass == FMBD_FE_MASS_CONSISTENT) {
                for (int bb = 0; bb < tn; bb++) Me[(3 * a + k) * kt + 3 * bb + k] = Ms[a * tn + bb];
              } else {
                Me[(3 * a + k) * kt + 3 * a + k] = d[a];
              }
            }
          }
          FMBD_GCALL(add_element(&c, e, kt, Kx, diag_mass ? NULL : Me));
        }
        if (diag_mass) {
          for (int a = 0; a < tn; a++) {
            if (nact(b, en[a]) > 0 && in_set(&c, en[a]))
              FMBD_GCALL(add_diag(b->M, b->node_dof[en[a]], 3, d[a]));
          }
        }
        continue;
      }
      const int64_t eb = e - m->ntet;
      const int64_t *bn = m->beam + 2 * eb;
      const double *x0 = m->xyz + 3 * bn[0], *x1 = m->xyz + 3 * bn[1];
      const double *v = b->beam_orientation + 3 * eb;
      rc = fmbd_fe_beam_matrices(x0, x1, v, b->E, b->nu, b->rho, b->area, b->Iy, b->Iz, b->J, eb,
                                 Ke, Me);
      if (rc == FMBD_OK) rc = fmbd_fe_beam_lumped(x0, x1, v, b->rho, b->area, b->J, eb, Ml);
      if (rc != FMBD_OK) {
        int rc2 = first_failure(m, b, e, Ke, Ml);
        if (rc2 != FMBD_OK) rc = rc2;
        goto done;
      }
      if (first) {
        double *o = once + 14 * m->ntet + 37 * eb;
        o[0] = sqrt((x1[0] - x0[0]) * (x1[0] - x0[0]) + (x1[1] - x0[1]) * (x1[1] - x0[1]) +
                    (x1[2] - x0[2]) * (x1[2] - x0[2]));
        rigid_beam(x0, x1, Me, o + 1);
      }
      if (in_set(&c, bn[0])) b->node_mass[bn[0]] += Ml[0];
      if (in_set(&c, bn[1])) b->node_mass[bn[1]] += Ml[6 * 12 + 6];
      const double *Mb = opt->mass == FMBD_FE_MASS_CONSISTENT ? Me : Ml;
      FMBD_GCALL(add_element(&c, e, 12, Ke, diag_mass ? NULL : Mb));
      if (diag_mass) {  // translations on the diagonal (isotropic m/2), rotations a 3x3 block
        for (int a = 0; a < 2; a++) {
          int64_t r0 = b->node_dof[bn[a]];
          if (b->node_dof[bn[a] + 1] == r0 || !in_set(&c, bn[a])) continue;  // clamped, or later
          FMBD_GCALL(add_diag(b->M, r0, 3, Ml[(6 * a) * 13]));
          for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++) {
              int64_t pos = fmbd_csr_find(b->M, r0 + 3 + i, r0 + 3 + j);
              FMBD_GCHECK(pos >= 0, FMBD_ERR_INTERNAL,
                          "lumped rotational block not in the pattern");
              b->M->data[pos] += Ml[(6 * a + 3 + i) * 12 + 6 * a + 3 + j];
            }
          }
        }
      }
    }
  }
  if (progress) fmbd_progress(NULL);
  for (int64_t e = 0; e < m->ntet; e++) {
    vol_solid += once[14 * e];
    rigid_solid_add(once + 14 * e + 1, Mr);
  }
  for (int64_t eb = 0; eb < m->nbeam; eb++) {
    const double *o = once + 14 * m->ntet + 37 * eb;
    vol_beam += b->area * o[0];
    for (int i = 0; i < 36; i++) Mr[i] += o[1 + i];
  }
  b->volume = vol_solid + vol_beam;
  body_properties(b, Mr);
  *out = b;
  b = NULL;
done:
  fmbd_fe_body_destroy(&b);
  fmbd_free(on_solid);
  fmbd_free(on_beam);
  fmbd_free(fdof);
  fmbd_free(tied);
  fmbd_free(Ke);
  fmbd_free(Me);
  fmbd_free(Ml);
  fmbd_free(once);
  fmbd_free(seen);
  fmbd_free(slot);
  fmbd_free(vleft);
  fmbd_free(pool);
  fmbd_free(freel);
  fmbd_csr_destroy(&T);
  asm_free(&c);
  return rc;
}

// --- nodal stress ---------------------------------------------------------------------------
int fmbd_fe_nodal_stress(const fmbd_fe_body *b, int64_t ncases, const double *q, double *sigma) {
  return fmbd_fe_nodal_stress_at(b, ncases, q, -1, NULL, sigma);
}

// One computation for the whole field and for a selection of nodes: only the elements around
// the selected nodes, in the same increasing order, each with the same arithmetic (its
// displacements are the same /expand rows times q, through the same product), so a selected
// node's stress is bitwise the whole field's row.
int fmbd_fe_nodal_stress_at(const fmbd_fe_body *b, int64_t ncases, const double *q, int64_t nsel,
                            const int64_t *sel, double *sigma) {
  FMBD_CHECK(b->expand && b->expand->nrows == 6 * b->nnodes && b->expand->ncols == b->ndof,
             FMBD_ERR_VALUE, "nodal stress: the body has no expansion matrix of shape (%lld, %lld)",
             (long long)(6 * b->nnodes), (long long)b->ndof);
  int rc = FMBD_OK;
  double *u = NULL;
  int *count = NULL;
  int64_t *orow = NULL, *urow = NULL;
  unsigned char *etouch = NULL;
  fmbd_csr *Xs = NULL;
  const fmbd_csr *X = b->expand;
  const int nn = b->tet_nodes;
  const int64_t nno = b->nnodes, nout = sel ? nsel : nno;
  const double nu = b->nu, E = b->E;
  const double lambda = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), mu = E / (2.0 * (1.0 + nu));
  static const double node_xi[10][3] = {{0, 0, 0},   {1, 0, 0},   {0, 1, 0},  {0, 0, 1},
                                        {.5, 0, 0},  {.5, .5, 0}, {0, .5, 0}, {0, 0, .5},
                                        {0, .5, .5}, {.5, 0, .5}};
  double dNn[10][30], Nn[10];
  for (int a = 0; a < nn; a++) fmbd_fe_tet_shape(nn, node_xi[a], Nn, dNn[a]);
  FMBD_GALLOC(count = fmbd_calloc((size_t)nno + 1, sizeof *count));
  for (int64_t e = 0; e < b->ntet; e++) {
    for (int a = 0; a < nn; a++) count[b->tet[e * nn + a]]++;
  }
  // orow: a node's row in sigma (-1: not asked); urow: its row block in the displacements
  // (-1: not needed); etouch: the elements around a selected node
  int64_t nu_rows = nno;
  if (sel) {
    FMBD_GCHECK(nsel >= 0, FMBD_ERR_VALUE, "nodal stress: %lld selected nodes", (long long)nsel);
    FMBD_GALLOC(orow = fmbd_malloc(sizeof(int64_t) * (size_t)(nno + 1)));
    FMBD_GALLOC(urow = fmbd_malloc(sizeof(int64_t) * (size_t)(nno + 1)));
    FMBD_GALLOC(etouch = fmbd_calloc((size_t)b->ntet + 1, 1));
    for (int64_t p = 0; p < nno; p++) orow[p] = urow[p] = -1;
    for (int64_t i = 0; i < nsel; i++) {
      FMBD_GCHECK(sel[i] >= 0 && sel[i] < nno, FMBD_ERR_VALUE,
                  "nodal stress: selected node %lld out of range (%lld nodes)", (long long)sel[i],
                  (long long)nno);
      FMBD_GCHECK(orow[sel[i]] < 0, FMBD_ERR_VALUE, "nodal stress: node %lld selected twice",
                  (long long)sel[i]);
      orow[sel[i]] = i;
    }
    for (int64_t e = 0; e < b->ntet; e++) {
      for (int a = 0; a < nn; a++) etouch[e] |= orow[b->tet[e * nn + a]] >= 0;
      if (etouch[e]) {
        for (int a = 0; a < nn; a++) urow[b->tet[e * nn + a]] = 0;
      }
    }
    // the /expand rows of the needed nodes, in node order, entries as they are
    nu_rows = 0;
    int64_t nnz = 0;
    for (int64_t p = 0; p < nno; p++) {
      if (urow[p] < 0) continue;
      urow[p] = nu_rows++;
      nnz += X->indptr[6 * p + 6] - X->indptr[6 * p];
    }
    FMBD_GCALL(fmbd_csr_create(6 * nu_rows, b->ndof, nnz, &Xs));
    int64_t k = 0, row = 0;
    Xs->indptr[0] = 0;
    for (int64_t p = 0; p < nno; p++) {
      if (urow[p] < 0) continue;
      for (int d = 0; d < 6; d++, row++) {
        for (int64_t e = X->indptr[6 * p + d]; e < X->indptr[6 * p + d + 1]; e++, k++) {
          Xs->indices[k] = X->indices[e];
          Xs->data[k] = X->data[e];
        }
        Xs->indptr[row + 1] = k;
      }
    }
    X = Xs;
  }
  // cases in blocks: the displacements of a block of cases at the needed nodes, U = expand * q
  const int64_t nb = ncases < 16 ? ncases : 16, ld = 6 * nu_rows;
  FMBD_GALLOC(u = fmbd_malloc((size_t)(ld * (nb ? nb : 1) + 1) * sizeof *u));
  memset(sigma, 0, (size_t)(nout * 6 * ncases) * sizeof *sigma);
  for (int64_t c0 = 0; c0 < ncases; c0 += nb) {
    const int64_t ncb = ncases - c0 < nb ? ncases - c0 : nb;
    fmbd_csr_matmat(X, ncb, q + c0 * b->ndof, b->ndof, u, ld);
    for (int64_t e = 0; e < b->ntet; e++) {
      if (etouch && !etouch[e]) continue;
      const int64_t *en = b->tet + e * nn;
      double G[10][30];  // global gradients of the shape functions at each node of the element
      for (int a = 0; a < nn; a++) {
        double J[9] = {0}, Ji[9];
        for (int k = 0; k < nn; k++) {
          const double *x = b->xyz + 3 * en[k];
          for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++) J[i * 3 + j] += dNn[a][k * 3 + i] * x[j];
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
        for (int k = 0; k < nn; k++) {
          for (int j = 0; j < 3; j++) {
            G[a][k * 3 + j] = Ji[j * 3 + 0] * dNn[a][k * 3 + 0] +
                              Ji[j * 3 + 1] * dNn[a][k * 3 + 1] + Ji[j * 3 + 2] * dNn[a][k * 3 + 2];
          }
        }
      }
      for (int64_t c = 0; c < ncb; c++) {
        const double *uc = u + c * ld;
        double *sg = sigma + (c0 + c) * nout * 6;
        for (int a = 0; a < nn; a++) {
          int64_t oa = orow ? orow[en[a]] : en[a];
          if (oa < 0) continue;  // a node of the element that is not asked
          double gu[9] = {0};    // gu[i][j] = d u_i / d x_j
          for (int k = 0; k < nn; k++) {
            const double *uk = uc + 6 * (urow ? urow[en[k]] : en[k]), *g = G[a] + 3 * k;
            for (int i = 0; i < 3; i++) {
              gu[i * 3 + 0] += uk[i] * g[0];
              gu[i * 3 + 1] += uk[i] * g[1];
              gu[i * 3 + 2] += uk[i] * g[2];
            }
          }
          double tr = gu[0] + gu[4] + gu[8];
          double *dst = sg + oa * 6;
          dst[0] += lambda * tr + 2 * mu * gu[0];
          dst[1] += lambda * tr + 2 * mu * gu[4];
          dst[2] += lambda * tr + 2 * mu * gu[8];
          dst[3] += mu * (gu[1] + gu[3]);
          dst[4] += mu * (gu[5] + gu[7]);
          dst[5] += mu * (gu[2] + gu[6]);
        }
      }
    }
  }
  for (int64_t c = 0; c < ncases; c++) {
    double *sg = sigma + c * nout * 6;
    for (int64_t i = 0; i < nout; i++) {
      int64_t p = sel ? sel[i] : i;
      if (count[p] > 1) {
        for (int j = 0; j < 6; j++) sg[i * 6 + j] /= count[p];
      }
    }
  }
done:
  fmbd_free(u);
  fmbd_free(count);
  fmbd_free(orow);
  fmbd_free(urow);
  fmbd_free(etouch);
  fmbd_csr_destroy(&Xs);
  return rc;
}
