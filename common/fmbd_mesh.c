// common/fmbd_mesh.c: the mesh: groups, checks, quality, order elevation (the readers:
// fmbd_mesh_read.c) SPDX-License-Identifier: MIT
#include "fmbd_mesh.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"  // fmbd_fe_tet_shape, fmbd_fe_tet_rule
#include "fmbd_log.h"
#include "fmbd_mesh_impl.h"

void fmbd_mesh_opts_defaults(fmbd_mesh_opts *o) {
  o->order = 0;
  o->size = 0.0;
  o->gmsh_verbose = 0;
  o->surface_mesher = NULL;
}

// --- small helpers ---------------------------------------------------------------------------

// does name end with ext (case-insensitive)?
static int ends_with(const char *name, const char *ext) {
  size_t n = strlen(name), k = strlen(ext);
  if (n < k) {
    return 0;
  }
  for (size_t i = 0; i < k; i++) {
    if (tolower((unsigned char)name[n - k + i]) != tolower((unsigned char)ext[i])) {
      return 0;
    }
  }
  return 1;
}

static int cmp_i64(const void *a, const void *b) {
  int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
  return (x > y) - (x < y);
}

// sort and remove duplicates; returns the new length
static int64_t sort_unique(int64_t *v, int64_t n) {
  if (n <= 1) {
    return n;
  }
  qsort(v, (size_t)n, sizeof *v, cmp_i64);
  int64_t k = 1;
  for (int64_t i = 1; i < n; i++) {
    if (v[i] != v[k - 1]) {
      v[k++] = v[i];
    }
  }
  return k;
}

// Append a group (nodes are copied, sorted, made unique). If a group of that name exists,
// the nodes are merged into it (gmsh allows one name on groups of several dimensions).
static int add_group(fmbd_mesh *m, const char *name, int64_t n, const int64_t *nodes) {
  int g = fmbd_mesh_find_group(m, name);
  int64_t old = 0;
  int64_t total = m->group_ptr ? m->group_ptr[m->ngroups] : 0;
  int64_t *buf = NULL;
  if (g >= 0) {
    old = m->group_ptr[g + 1] - m->group_ptr[g];
  }
  buf = fmbd_malloc((size_t)(old + n) * sizeof *buf);
  if (!buf) {
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  if (g >= 0) {
    memcpy(buf, m->group_node + m->group_ptr[g], (size_t)old * sizeof *buf);
  }
  memcpy(buf + old, nodes, (size_t)n * sizeof *buf);
  int64_t k = sort_unique(buf, old + n);
  if (g >= 0) {
    // rebuild: shift the later groups by (k - old)
    int64_t delta = k - old;
    int64_t *gn = fmbd_malloc((size_t)(total + (delta > 0 ? delta : 0) + 1) * sizeof *gn);
    if (!gn) {
      fmbd_free(buf);
      FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    }
    int64_t p = 0;
    for (int h = 0; h < m->ngroups; h++) {
      int64_t b0 = m->group_ptr[h], b1 = m->group_ptr[h + 1];
      if (h == g) {
        memcpy(gn + p, buf, (size_t)k * sizeof *gn);
        p += k;
      } else {
        memcpy(gn + p, m->group_node + b0, (size_t)(b1 - b0) * sizeof *gn);
        p += b1 - b0;
      }
    }
    for (int h = g + 1; h <= m->ngroups; h++) {
      m->group_ptr[h] += delta;
    }
    fmbd_free(m->group_node);
    m->group_node = gn;
    fmbd_free(buf);
    return FMBD_OK;
  }
  // new group at the end
  char *nm = fmbd_strdup(name);
  char **names = fmbd_realloc(m->group_name, (size_t)(m->ngroups + 1) * sizeof *names);
  if (names) {
    m->group_name = names;
  }
  int64_t *ptr = fmbd_realloc(m->group_ptr, (size_t)(m->ngroups + 2) * sizeof *ptr);
  if (ptr) {
    m->group_ptr = ptr;
  }
  int64_t *gn = fmbd_realloc(m->group_node, (size_t)(total + k + 1) * sizeof *gn);
  if (gn) {
    m->group_node = gn;
  }
  if (!nm || !names || !ptr || !gn) {
    fmbd_free(nm);
    fmbd_free(buf);
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  if (m->ngroups == 0) {
    m->group_ptr[0] = 0;
  }
  memcpy(m->group_node + total, buf, (size_t)k * sizeof *buf);
  m->group_name[m->ngroups] = nm;
  m->group_ptr[m->ngroups + 1] = total + k;
  m->ngroups++;
  fmbd_free(buf);
  return FMBD_OK;
}

// bounding-box diagonal of the nodes
static double bbox_diagonal(int64_t n, const double *xyz) {
  if (n == 0) {
    return 0.0;
  }
  double lo[3] = {xyz[0], xyz[1], xyz[2]}, hi[3] = {xyz[0], xyz[1], xyz[2]};
  for (int64_t i = 1; i < n; i++) {
    for (int k = 0; k < 3; k++) {
      double v = xyz[3 * i + k];
      lo[k] = v < lo[k] ? v : lo[k];
      hi[k] = v > hi[k] ? v : hi[k];
    }
  }
  return sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
              (hi[2] - lo[2]) * (hi[2] - lo[2]));
}

// --- element geometry ------------------------------------------------------------------------

// --- the mesh struct ---------------------------------------------------------------------------
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

// gmsh's tet10 mid-edge nodes 4..9 sit on the edges (0,1) (1,2) (0,2) (0,3) (2,3) (1,3)
static const int tet10_edge[6][2] = {{0, 1}, {1, 2}, {0, 2}, {0, 3}, {2, 3}, {1, 3}};

// det of dX/dxi of element `nodes` (nn of them) at reference point p
static double tet_detj(const double *xyz, int nn, const int64_t *nodes, const double p[3]) {
  double N[10], dN[10][3], J[3][3] = {{0}};
  fmbd_fe_tet_shape(nn, p, N, &dN[0][0]);  // the element library's shape functions
  for (int a = 0; a < nn; a++) {
    const double *x = xyz + 3 * nodes[a];
    for (int i = 0; i < 3; i++) {
      for (int k = 0; k < 3; k++) {
        J[i][k] += x[i] * dN[a][k];
      }
    }
  }
  return J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) -
         J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
         J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
}

// Check points of a tet: corners, mid-edges, centroid, 4 Gauss points (tet4: the centroid)
static int tet_check_points(int nn, double pts[15][3]) {
  if (nn == 4) {
    pts[0][0] = pts[0][1] = pts[0][2] = 0.25;
    return 1;
  }
  static const double corner[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  int n = 0;
  for (int a = 0; a < 4; a++, n++) {
    memcpy(pts[n], corner[a], sizeof pts[n]);
  }
  for (int e = 0; e < 6; e++, n++) {
    for (int k = 0; k < 3; k++) {
      pts[n][k] = 0.5 * (corner[tet10_edge[e][0]][k] + corner[tet10_edge[e][1]][k]);
    }
  }
  pts[n][0] = pts[n][1] = pts[n][2] = 0.25;
  n++;
  int ng;
  const double *gp, *gw;
  fmbd_fe_tet_rule(2, &ng, &gp, &gw);  // the 4-point rule of the element library
  for (int g = 0; g < ng; g++, n++) {
    memcpy(pts[n], gp + 3 * g, sizeof pts[n]);
  }
  return n;
}

static double tet_longest_edge(const double *xyz, const int64_t *nodes) {
  double h = 0.0;
  for (int a = 0; a < 4; a++) {
    for (int b = a + 1; b < 4; b++) {
      double d2 = 0.0;
      for (int k = 0; k < 3; k++) {
        double d = xyz[3 * nodes[a] + k] - xyz[3 * nodes[b] + k];
        d2 += d * d;
      }
      h = d2 > h ? d2 : h;
    }
  }
  return sqrt(h);
}

// Validation with optional gmsh tags for the messages (NULL: 0-based indices only).
static int check_mesh(const fmbd_mesh *m, const size_t *tet_tag, const size_t *beam_tag) {
  // --- elements ---
  if (m->ntet > 0 && m->tet_nodes != 4 && m->tet_nodes != 10) {
    FMBD_FAIL(FMBD_ERR_VALUE, "tetrahedra with %d nodes (4 or 10 expected)", m->tet_nodes);
  }
  if (m->ntet == 0 && m->nbeam == 0) {
    FMBD_FAIL(FMBD_ERR_FORMAT, "no volume (tetrahedron) or beam (line) elements");
  }
  double pts[15][3];
  int npts = m->ntet > 0 ? tet_check_points(m->tet_nodes, pts) : 0;
  for (int64_t e = 0; e < m->ntet; e++) {
    const int64_t *nd = m->tet + e * m->tet_nodes;
    for (int a = 0; a < m->tet_nodes; a++) {
      if (nd[a] < 0 || nd[a] >= m->nnodes) {
        FMBD_FAIL(FMBD_ERR_VALUE, "tet %lld: node index %lld out of range [0, %lld)", (long long)e,
                  (long long)nd[a], (long long)m->nnodes);
      }
    }
    double h = tet_longest_edge(m->xyz, nd);
    for (int q = 0; q < npts; q++) {
      double d = tet_detj(m->xyz, m->tet_nodes, nd, pts[q]);
      if (!(d > 1e-10 * h * h * h)) {
        char tag[64] = "";
        if (tet_tag) {
          snprintf(tag, sizeof tag, " (gmsh element tag %zu)", tet_tag[e]);
        }
        FMBD_FAIL(FMBD_ERR_VALUE,
                  "tet%d element %lld%s is %s: Jacobian determinant %.6g at reference point "
                  "(%.3g, %.3g, %.3g) (relative to its longest edge cubed: %.3g)",
                  m->tet_nodes, (long long)e, tag, d < 0 ? "inverted" : "degenerate", d, pts[q][0],
                  pts[q][1], pts[q][2], h > 0 ? d / (h * h * h) : 0.0);
      }
    }
  }
  for (int64_t e = 0; e < m->nbeam; e++) {
    const int64_t *nd = m->beam + 2 * e;
    for (int a = 0; a < 2; a++) {
      if (nd[a] < 0 || nd[a] >= m->nnodes) {
        FMBD_FAIL(FMBD_ERR_VALUE, "beam %lld: node index %lld out of range", (long long)e,
                  (long long)nd[a]);
      }
    }
    double L2 = 0.0;
    for (int k = 0; k < 3; k++) {
      double d = m->xyz[3 * nd[1] + k] - m->xyz[3 * nd[0] + k];
      L2 += d * d;
    }
    if (!(L2 > 0.0)) {
      char tag[64] = "";
      if (beam_tag) {
        snprintf(tag, sizeof tag, " (gmsh element tag %zu)", beam_tag[e]);
      }
      FMBD_FAIL(FMBD_ERR_VALUE, "beam element %lld%s has zero length", (long long)e, tag);
    }
  }
  // --- every node on an element ---
  unsigned char *used = fmbd_calloc((size_t)(m->nnodes > 0 ? m->nnodes : 1), 1);
  if (!used) {
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  for (int64_t i = 0; i < m->ntet * m->tet_nodes; i++) {
    used[m->tet[i]] = 1;
  }
  for (int64_t i = 0; i < 2 * m->nbeam; i++) {
    used[m->beam[i]] = 1;
  }
  for (int64_t p = 0; p < m->nnodes; p++) {
    if (!used[p]) {
      fmbd_free(used);
      FMBD_FAIL(FMBD_ERR_VALUE, "node %lld at (%g, %g, %g) is attached to no element", (long long)p,
                m->xyz[3 * p], m->xyz[3 * p + 1], m->xyz[3 * p + 2]);
    }
  }
  fmbd_free(used);
  // --- coordinates and groups ---
  for (int64_t i = 0; i < 3 * m->nnodes; i++) {
    if (!isfinite(m->xyz[i])) {
      FMBD_FAIL(FMBD_ERR_VALUE, "node %lld has a non-finite coordinate", (long long)(i / 3));
    }
  }
  for (int g = 0; g < m->ngroups; g++) {
    for (int64_t i = m->group_ptr[g]; i < m->group_ptr[g + 1]; i++) {
      if (m->group_node[i] < 0 || m->group_node[i] >= m->nnodes) {
        FMBD_FAIL(FMBD_ERR_VALUE, "group '%s': node index %lld out of range", m->group_name[g],
                  (long long)m->group_node[i]);
      }
    }
  }
  return FMBD_OK;
}

int fmbd_mesh_check(const fmbd_mesh *m) {
  return check_mesh(m, NULL, NULL);
}

// Shape measures of one tetrahedron (docs/STABILITY.md, "Element shape"): the aspect ratio
// h_max / (2 sqrt(6) r_in) of its corners (r_in = 3 V / total face area; 1 for the regular
// tetrahedron, large for needles, wedges and slivers alike) and the scaled Jacobian: the
// smallest over its corners of sqrt(2) 6V / (product of the corner's three edge lengths)
// (1 regular, -> 0 as a corner flattens); for tet10 the curvature's distortion cr: the
// smallest ratio of det J at the check points to its straight-sided value 6V (1 straight).
static void tet_quality(const fmbd_mesh *m, const int64_t *nd, const double pts[15][3], int npts,
                        double *ar, double *sj, double *cr) {
  const double *x[4];
  for (int a = 0; a < 4; a++) x[a] = m->xyz + 3 * nd[a];
  double L[4][4] = {{0}}, hmax = 0;
  for (int a = 0; a < 4; a++) {
    for (int b = a + 1; b < 4; b++) {
      double d2 = 0;
      for (int k = 0; k < 3; k++) d2 += (x[a][k] - x[b][k]) * (x[a][k] - x[b][k]);
      L[a][b] = L[b][a] = sqrt(d2);
      hmax = fmax(hmax, L[a][b]);
    }
  }
  double e[3][3];
  for (int i = 0; i < 3; i++) {
    for (int k = 0; k < 3; k++) e[i][k] = x[i + 1][k] - x[0][k];
  }
  double v6 = e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
              e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
              e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
  v6 = fabs(v6);
  static const int face[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  double area = 0;
  for (int f = 0; f < 4; f++) {
    const double *p0 = x[face[f][0]], *p1 = x[face[f][1]], *p2 = x[face[f][2]];
    double u[3], w[3], c[3];
    for (int k = 0; k < 3; k++) u[k] = p1[k] - p0[k], w[k] = p2[k] - p0[k];
    c[0] = u[1] * w[2] - u[2] * w[1], c[1] = u[2] * w[0] - u[0] * w[2],
    c[2] = u[0] * w[1] - u[1] * w[0];
    area += 0.5 * sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
  }
  double rin = area > 0 ? 0.5 * v6 / area : 0;  // 3 V / A, V = v6 / 6
  *ar = rin > 0 ? hmax / (2 * sqrt(6.0) * rin) : INFINITY;
  double s = INFINITY;
  for (int a = 0; a < 4; a++) {
    double p = 1;
    for (int b = 0; b < 4; b++) {
      if (b != a) p *= L[a][b];
    }
    s = fmin(s, p > 0 ? sqrt(2.0) * v6 / p : 0);
  }
  *sj = s;
  *cr = 1;
  if (m->tet_nodes == 10 && v6 > 0) {
    for (int q = 0; q < npts; q++) *cr = fmin(*cr, tet_detj(m->xyz, 10, nd, pts[q]) / v6);
  }
}

void fmbd_mesh_quality(const fmbd_mesh *m, fmbd_mesh_quality_stats *q) {
  memset(q, 0, sizeof *q);
  q->worst_ar = 0, q->min_sj = q->min_cr = INFINITY;
  q->worst_ar_elem = q->min_sj_elem = q->min_cr_elem = -1;
  if (m->ntet == 0) return;
  double pts[15][3];
  int npts = tet_check_points(m->tet_nodes, pts);
  for (int64_t e = 0; e < m->ntet; e++) {
    double ar, sj, cr;
    tet_quality(m, m->tet + e * m->tet_nodes, (const double(*)[3])pts, npts, &ar, &sj, &cr);
    if (!(cr >= q->min_cr)) q->min_cr = cr, q->min_cr_elem = e;
    if (!(ar <= q->worst_ar)) q->worst_ar = ar, q->worst_ar_sj = sj, q->worst_ar_elem = e;
    if (!(sj >= q->min_sj)) q->min_sj = sj, q->min_sj_ar = ar, q->min_sj_elem = e;
    if (!(ar <= FMBD_MESH_AR_WARN)) q->n_ar_bad++;
    if (!(sj >= FMBD_MESH_SJ_WARN)) q->n_sj_bad++;
  }
}

double fmbd_mesh_volume(const fmbd_mesh *m) {
  double v = 0.0;
  int ng;
  const double *gp, *gw;
  fmbd_fe_tet_rule(2, &ng, &gp, &gw);  // degree 2: exact for the quadratic geometry's det J
  for (int64_t e = 0; e < m->ntet; e++) {
    const int64_t *nd = m->tet + e * m->tet_nodes;
    for (int g = 0; g < ng; g++) {
      v += tet_detj(m->xyz, m->tet_nodes, nd, gp + 3 * g) * gw[g];
    }
  }
  return v;
}

int fmbd_mesh_group_affine_dim(const fmbd_mesh *m, int g) {
  const int64_t *nd = m->group_node + m->group_ptr[g];
  int64_t n = m->group_ptr[g + 1] - m->group_ptr[g];
  if (n < 2) {
    return 0;
  }
  // p0: the first node; p1: the farthest from p0; p2: the farthest from the line p0 p1
  const double *x0 = m->xyz + 3 * nd[0];
  double d1 = 0.0, u[3] = {0, 0, 0};
  for (int64_t i = 1; i < n; i++) {
    const double *x = m->xyz + 3 * nd[i];
    double d = 0.0;
    for (int k = 0; k < 3; k++) {
      d += (x[k] - x0[k]) * (x[k] - x0[k]);
    }
    if (d > d1) {
      d1 = d;
      for (int k = 0; k < 3; k++) {
        u[k] = x[k] - x0[k];
      }
    }
  }
  double ext = sqrt(d1);
  if (!(ext > 0.0)) {
    return 0;
  }
  for (int k = 0; k < 3; k++) {
    u[k] /= ext;
  }
  double d2 = 0.0, w[3] = {0, 0, 0};
  for (int64_t i = 1; i < n; i++) {
    const double *x = m->xyz + 3 * nd[i];
    double r[3], t = 0.0, d = 0.0;
    for (int k = 0; k < 3; k++) {
      r[k] = x[k] - x0[k];
      t += r[k] * u[k];
    }
    for (int k = 0; k < 3; k++) {
      r[k] -= t * u[k];
      d += r[k] * r[k];
    }
    if (d > d2) {
      d2 = d;
      memcpy(w, r, sizeof w);
    }
  }
  if (!(sqrt(d2) > 1e-8 * ext)) {
    return 1;
  }
  double nrm[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
  double nn = sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
  for (int64_t i = 1; i < n; i++) {
    const double *x = m->xyz + 3 * nd[i];
    double h = 0.0;
    for (int k = 0; k < 3; k++) {
      h += (x[k] - x0[k]) * nrm[k] / nn;
    }
    if (fabs(h) > 1e-8 * ext) {
      return 3;
    }
  }
  return 2;
}

// --- node compaction, elevation ---------------------------------------------------------------

// Keep the nodes with keep[p] != 0, renumbering elements and groups (elements must refer to
// kept nodes only; group members not kept are dropped).
static int compact_nodes(fmbd_mesh *m, const unsigned char *keep) {
  int64_t *newid = fmbd_malloc((size_t)(m->nnodes + 1) * sizeof *newid);
  if (!newid) {
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  int64_t n = 0;
  for (int64_t p = 0; p < m->nnodes; p++) {
    newid[p] = keep[p] ? n++ : -1;
    if (keep[p]) {
      memmove(m->xyz + 3 * newid[p], m->xyz + 3 * p, 3 * sizeof(double));
    }
  }
  m->nnodes = n;
  for (int64_t i = 0; i < m->ntet * m->tet_nodes; i++) {
    m->tet[i] = newid[m->tet[i]];
  }
  for (int64_t i = 0; i < 2 * m->nbeam; i++) {
    m->beam[i] = newid[m->beam[i]];
  }
  int64_t w = 0;
  for (int g = 0; g < m->ngroups; g++) {
    int64_t b0 = m->group_ptr[g], b1 = m->group_ptr[g + 1];
    m->group_ptr[g] = w;
    for (int64_t i = b0; i < b1; i++) {
      if (newid[m->group_node[i]] >= 0) {
        m->group_node[w++] = newid[m->group_node[i]];
      }
    }
  }
  if (m->ngroups > 0) {
    m->group_ptr[m->ngroups] = w;
  }
  fmbd_free(newid);
  return FMBD_OK;
}

typedef struct edge_slot {
  int64_t a, b, slot;  // a < b; slot = tet * 6 + local edge
} edge_slot;

static int cmp_edge(const void *x, const void *y) {
  const edge_slot *p = x, *q = y;
  if (p->a != q->a) {
    return (p->a > q->a) - (p->a < q->a);
  }
  return (p->b > q->b) - (p->b < q->b);
}

int fmbd_mesh_elevate(fmbd_mesh *m) {
  if (m->ntet == 0 || m->tet_nodes == 10) {
    return FMBD_OK;
  }
  int rc = FMBD_OK;
  int64_t ne6 = 6 * m->ntet;
  edge_slot *es = NULL;
  int64_t *tet10 = NULL, *mid = NULL, *gnew = NULL, *gptr = NULL;
  double *xyz = NULL;
  unsigned char *mark = NULL;
  FMBD_GALLOC(es = fmbd_malloc((size_t)ne6 * sizeof *es));
  for (int64_t t = 0; t < m->ntet; t++) {
    for (int e = 0; e < 6; e++) {
      int64_t a = m->tet[4 * t + tet10_edge[e][0]], b = m->tet[4 * t + tet10_edge[e][1]];
      es[6 * t + e] = (edge_slot){a < b ? a : b, a < b ? b : a, 6 * t + e};
    }
  }
  qsort(es, (size_t)ne6, sizeof *es, cmp_edge);
  int64_t nedge = 0;
  for (int64_t i = 0; i < ne6; i++) {
    if (i == 0 || cmp_edge(&es[i], &es[i - 1]) != 0) {
      nedge++;
    }
  }
  int64_t nn = m->nnodes + nedge;
  FMBD_GALLOC(xyz = fmbd_malloc((size_t)(3 * nn) * sizeof *xyz));
  FMBD_GALLOC(tet10 = fmbd_malloc((size_t)(10 * m->ntet) * sizeof *tet10));
  FMBD_GALLOC(mid = fmbd_malloc((size_t)(2 * nedge + 1) * sizeof *mid));  // edge ends
  memcpy(xyz, m->xyz, (size_t)(3 * m->nnodes) * sizeof *xyz);
  int64_t id = m->nnodes - 1;
  for (int64_t i = 0; i < ne6; i++) {
    if (i == 0 || cmp_edge(&es[i], &es[i - 1]) != 0) {
      id++;
      for (int k = 0; k < 3; k++) {
        xyz[3 * id + k] = 0.5 * (m->xyz[3 * es[i].a + k] + m->xyz[3 * es[i].b + k]);
      }
      mid[2 * (id - m->nnodes)] = es[i].a;
      mid[2 * (id - m->nnodes) + 1] = es[i].b;
    }
    int64_t t = es[i].slot / 6, e = es[i].slot % 6;
    tet10[10 * t + 4 + e] = id;
  }
  for (int64_t t = 0; t < m->ntet; t++) {
    for (int a = 0; a < 4; a++) {
      tet10[10 * t + a] = m->tet[4 * t + a];
    }
  }
  // groups gain the mid-edge nodes of edges with both ends in the group
  if (m->ngroups > 0) {
    int64_t cap = m->group_ptr[m->ngroups], w = 0;
    FMBD_GALLOC(mark = fmbd_calloc((size_t)m->nnodes, 1));
    FMBD_GALLOC(gptr = fmbd_malloc((size_t)(m->ngroups + 1) * sizeof *gptr));
    // count first
    int64_t total = 0;
    for (int g = 0; g < m->ngroups; g++) {
      for (int64_t i = m->group_ptr[g]; i < m->group_ptr[g + 1]; i++) {
        mark[m->group_node[i]] = 1;
      }
      int64_t c = 0;
      for (int64_t k = 0; k < nedge; k++) {
        c += mark[mid[2 * k]] && mark[mid[2 * k + 1]];
      }
      total += c;
      for (int64_t i = m->group_ptr[g]; i < m->group_ptr[g + 1]; i++) {
        mark[m->group_node[i]] = 0;
      }
    }
    FMBD_GALLOC(gnew = fmbd_malloc((size_t)(cap + total + 1) * sizeof *gnew));
    for (int g = 0; g < m->ngroups; g++) {
      gptr[g] = w;
      for (int64_t i = m->group_ptr[g]; i < m->group_ptr[g + 1]; i++) {
        mark[m->group_node[i]] = 1;
        gnew[w++] = m->group_node[i];
      }
      for (int64_t k = 0; k < nedge; k++) {
        if (mark[mid[2 * k]] && mark[mid[2 * k + 1]]) {
          gnew[w++] = m->nnodes + k;
        }
      }
      for (int64_t i = m->group_ptr[g]; i < m->group_ptr[g + 1]; i++) {
        mark[m->group_node[i]] = 0;
      }
    }
    gptr[m->ngroups] = w;
    fmbd_free(m->group_node);
    fmbd_free(m->group_ptr);
    m->group_node = gnew;
    m->group_ptr = gptr;
    gnew = gptr = NULL;
  }
  fmbd_free(m->xyz);
  fmbd_free(m->tet);
  m->xyz = xyz;
  m->tet = tet10;
  xyz = NULL;
  tet10 = NULL;
  m->nnodes = nn;
  m->tet_nodes = 10;
done:
  fmbd_free(es);
  fmbd_free(tet10);
  fmbd_free(mid);
  fmbd_free(gnew);
  fmbd_free(gptr);
  fmbd_free(xyz);
  fmbd_free(mark);
  return rc;
}

// tet10 -> tet4: keep the corners, drop the mid-edge nodes
static int reduce_to_tet4(fmbd_mesh *m) {
  if (m->ntet == 0 || m->tet_nodes == 4) {
    return FMBD_OK;
  }
  for (int64_t t = 0; t < m->ntet; t++) {
    memmove(m->tet + 4 * t, m->tet + 10 * t, 4 * sizeof(int64_t));
  }
  m->tet_nodes = 4;
  unsigned char *keep = fmbd_calloc((size_t)m->nnodes, 1);
  if (!keep) {
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  for (int64_t i = 0; i < 4 * m->ntet; i++) {
    keep[m->tet[i]] = 1;
  }
  for (int64_t i = 0; i < 2 * m->nbeam; i++) {
    keep[m->beam[i]] = 1;
  }
  int rc = compact_nodes(m, keep);
  fmbd_free(keep);
  return rc;
}

// --- box groups --------------------------------------------------------------------------------

int fmbd_mesh_add_box_group(fmbd_mesh *m, const char *name, const double lo[3],
                            const double hi[3]) {
  for (int k = 0; k < 3; k++) {
    if (!(lo[k] <= hi[k])) {
      FMBD_FAIL(FMBD_ERR_USAGE, "group '%s': box min %g > max %g in direction %c", name, lo[k],
                hi[k], "xyz"[k]);
    }
  }
  if (fmbd_mesh_find_group(m, name) >= 0) {
    FMBD_FAIL(FMBD_ERR_VALUE, "group '%s' exists already", name);
  }
  double tol = 1e-9 * bbox_diagonal(m->nnodes, m->xyz);
  int64_t *sel = fmbd_malloc((size_t)(m->nnodes + 1) * sizeof *sel), n = 0;
  if (!sel) {
    FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  }
  for (int64_t p = 0; p < m->nnodes; p++) {
    const double *x = m->xyz + 3 * p;
    int in = 1;
    for (int k = 0; k < 3; k++) {
      in = in && x[k] >= lo[k] - tol && x[k] <= hi[k] + tol;
    }
    if (in) {
      sel[n++] = p;
    }
  }
  int rc = FMBD_OK;
  if (n == 0) {
    rc = fmbd_err_set(FMBD_ERR_VALUE, __FILE__, __LINE__, __func__,
                      "group '%s': the box [%g, %g] x [%g, %g] x [%g, %g] holds no node", name,
                      lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]);
  } else {
    rc = add_group(m, name, n, sel);
  }
  fmbd_free(sel);
  return rc;
}

// --- for the readers in fmbd_mesh_read.c (fmbd_mesh_impl.h) --------------------------------------
int fmbd_mesh_ends_with(const char *name, const char *ext) {
  return ends_with(name, ext);
}
int fmbd_mesh_add_group_(fmbd_mesh *m, const char *name, int64_t n, const int64_t *nodes) {
  return add_group(m, name, n, nodes);
}
double fmbd_mesh_bbox_diagonal(int64_t n, const double *xyz) {
  return bbox_diagonal(n, xyz);
}
int fmbd_mesh_check_tagged(const fmbd_mesh *m, const size_t *tet_tag, const size_t *beam_tag) {
  return check_mesh(m, tet_tag, beam_tag);
}
int fmbd_mesh_compact_nodes(fmbd_mesh *m, const unsigned char *keep) {
  return compact_nodes(m, keep);
}
int fmbd_mesh_reduce_to_tet4(fmbd_mesh *m) {
  return reduce_to_tet4(m);
}
double fmbd_mesh_tet_detj(const double *xyz, int nn, const int64_t *nodes, const double p[3]) {
  return tet_detj(xyz, nn, nodes, p);
}
