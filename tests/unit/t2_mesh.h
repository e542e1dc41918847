// tests/unit/t2_mesh.h: small meshes built in the FE unit tests (t2*)
// SPDX-License-Identifier: MIT
//
// box_mesh: the box [0,a]x[0,b]x[0,c] in nx x ny x nz cells, each cell split into the 6 Kuhn
// tetrahedra around its main diagonal (a conforming mesh); order 2 adds the edge mid-points in
// gmsh tet10 order. Groups: "xmin", "xmax" (the faces x = 0, x = a), "all" (every node).
// beam_mesh: a straight line of n beam2 elements from p0 to p1, groups "end0", "end1".
#ifndef T2_MESH_H
#define T2_MESH_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_fe.h"

typedef struct edge_map {
  int64_t cap, *key_a, *key_b, *val;
} edge_map;

static inline int64_t edge_get(edge_map *h, int64_t a, int64_t b, int64_t *next) {
  if (a > b) {
    int64_t t = a;
    a = b;
    b = t;
  }
  uint64_t k = ((uint64_t)a * 1000003u + (uint64_t)b) % (uint64_t)h->cap;
  while (h->key_a[k] >= 0) {
    if (h->key_a[k] == a && h->key_b[k] == b) return h->val[k];
    k = (k + 1) % (uint64_t)h->cap;
  }
  h->key_a[k] = a;
  h->key_b[k] = b;
  h->val[k] = (*next)++;
  return h->val[k];
}

static inline void add_groups(fmbd_mesh *m, int ng, const char *const *names,
                              int (*in)(const double *, int, void *), void *ctx) {
  m->ngroups = ng;
  m->group_name = fmbd_calloc((size_t)ng, sizeof *m->group_name);
  m->group_ptr = fmbd_calloc((size_t)ng + 1, sizeof *m->group_ptr);
  m->group_node = fmbd_malloc((size_t)(ng * m->nnodes + 1) * sizeof *m->group_node);
  int64_t k = 0;
  for (int g = 0; g < ng; g++) {
    m->group_name[g] = fmbd_strdup(names[g]);
    for (int64_t p = 0; p < m->nnodes; p++) {
      if (in(m->xyz + 3 * p, g, ctx)) m->group_node[k++] = p;
    }
    m->group_ptr[g + 1] = k;
  }
}

typedef struct box_ctx {
  double a;
} box_ctx;

static inline int box_in(const double *x, int g, void *ctx) {
  double a = ((box_ctx *)ctx)->a;
  if (g == 0) return fabs(x[0]) < 1e-12 * a;
  if (g == 1) return fabs(x[0] - a) < 1e-12 * a;
  return 1;
}

/// Box mesh of order 1 (tet4) or 2 (tet10, straight mid-side nodes).
static inline void box_mesh(fmbd_mesh *m, double a, double b, double c, int nx, int ny, int nz,
                            int order) {
  memset(m, 0, sizeof *m);
  int64_t nv = (int64_t)(nx + 1) * (ny + 1) * (nz + 1);
  int64_t ncell = (int64_t)nx * ny * nz, ntet = 6 * ncell;
  int64_t nedge_max = 7 * nv + 16;  // each vertex starts at most 7 Kuhn edges
  int64_t nmax = nv + (order == 2 ? nedge_max : 0);
  m->xyz = fmbd_malloc((size_t)(3 * nmax) * sizeof *m->xyz);
  for (int k = 0; k <= nz; k++) {
    for (int j = 0; j <= ny; j++) {
      for (int i = 0; i <= nx; i++) {
        int64_t p = ((int64_t)k * (ny + 1) + j) * (nx + 1) + i;
        m->xyz[3 * p] = a * i / nx;
        m->xyz[3 * p + 1] = b * j / ny;
        m->xyz[3 * p + 2] = c * k / nz;
      }
    }
  }
  int tn = order == 2 ? 10 : 4;
  m->ntet = ntet;
  m->tet_nodes = tn;
  m->tet = fmbd_malloc((size_t)(ntet * tn) * sizeof *m->tet);
  static const int perm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
  int64_t e = 0;
  for (int k = 0; k < nz; k++) {
    for (int j = 0; j < ny; j++) {
      for (int i = 0; i < nx; i++) {
        for (int t = 0; t < 6; t++) {
          int idx[3] = {i, j, k};
          int64_t node[4];
          for (int s = 0; s < 4; s++) {
            if (s > 0) idx[perm[t][s - 1]]++;
            node[s] = ((int64_t)idx[2] * (ny + 1) + idx[1]) * (nx + 1) + idx[0];
          }
          if (t >= 3) {  // odd permutation: negative orientation, swap two nodes
            int64_t tmp = node[1];
            node[1] = node[2];
            node[2] = tmp;
          }
          for (int s = 0; s < 4; s++) m->tet[e * tn + s] = node[s];
          e++;
        }
      }
    }
  }
  int64_t nn = nv;
  if (order == 2) {
    static const int ed[6][2] = {{0, 1}, {1, 2}, {2, 0}, {3, 0}, {3, 2}, {3, 1}};
    edge_map h;
    h.cap = 2 * nedge_max + 1;
    h.key_a = fmbd_malloc((size_t)h.cap * sizeof(int64_t));
    h.key_b = fmbd_malloc((size_t)h.cap * sizeof(int64_t));
    h.val = fmbd_malloc((size_t)h.cap * sizeof(int64_t));
    for (int64_t q = 0; q < h.cap; q++) h.key_a[q] = -1;
    for (e = 0; e < ntet; e++) {
      int64_t *t = m->tet + e * 10;
      for (int l = 0; l < 6; l++) {
        int64_t p0 = t[ed[l][0]], p1 = t[ed[l][1]], before = nn;
        int64_t q = edge_get(&h, p0, p1, &nn);
        if (q == before) {
          for (int d = 0; d < 3; d++)
            m->xyz[3 * q + d] = 0.5 * (m->xyz[3 * p0 + d] + m->xyz[3 * p1 + d]);
        }
        t[4 + l] = q;
      }
    }
    fmbd_free(h.key_a);
    fmbd_free(h.key_b);
    fmbd_free(h.val);
  }
  m->nnodes = nn;
  static const char *const names[3] = {"xmin", "xmax", "all"};
  box_ctx bc = {a};
  add_groups(m, 3, names, box_in, &bc);
}

static inline int beam_in(const double *x, int g, void *ctx) {
  (void)x;
  (void)g;
  (void)ctx;
  return 0;
}

/// Straight beam of n elements from p0 to p1; groups end0 = {0}, end1 = {n}.
static inline void beam_mesh(fmbd_mesh *m, const double p0[3], const double p1[3], int n) {
  memset(m, 0, sizeof *m);
  m->nnodes = n + 1;
  m->xyz = fmbd_malloc((size_t)(3 * (n + 1)) * sizeof *m->xyz);
  for (int i = 0; i <= n; i++) {
    for (int d = 0; d < 3; d++) m->xyz[3 * i + d] = p0[d] + (p1[d] - p0[d]) * i / n;
  }
  m->nbeam = n;
  m->beam = fmbd_malloc((size_t)(2 * n) * sizeof *m->beam);
  for (int i = 0; i < n; i++) {
    m->beam[2 * i] = i;
    m->beam[2 * i + 1] = i + 1;
  }
  static const char *const names[2] = {"end0", "end1"};
  add_groups(m, 2, names, beam_in, NULL);
  m->group_node[0] = 0;
  m->group_node[1] = n;
  m->group_ptr[1] = 1;
  m->group_ptr[2] = 2;
}

/// Dense copy (column-major n x n) of a CSR matrix.
static inline double *csr_dense(const fmbd_csr *A) {
  double *D = fmbd_calloc((size_t)(A->nrows * A->ncols), sizeof *D);
  for (int64_t i = 0; i < A->nrows; i++) {
    for (int64_t p = A->indptr[i]; p < A->indptr[i + 1]; p++)
      D[i + A->nrows * A->indices[p]] += A->data[p];
  }
  return D;
}

// options of a soft test material (E = 1 GPa, nu = 0.25, rho = 1000 kg/m^3), the rest defaults
static inline fmbd_fe_opts t2_soft_options(void) {
  fmbd_fe_opts o;
  fmbd_fe_opts_defaults(&o);
  o.E = 1e9;
  o.nu = 0.25;
  o.rho = 1000;
  return o;
}

#endif
