// common/fmbd_fe_elem.c: element matrices: tet4, tet10 (isoparametric), 2-node spatial
// Euler-Bernoulli beam; quadrature rules; HRZ lumping
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>

#include "fmbd_err.h"
#include "fmbd_fe.h"

// --- quadrature on the unit tetrahedron (volume 1/6) ------------------------------------------
// Points are given as (xi, eta, zeta) = (L1, L2, L3), L0 = 1 - xi - eta - zeta.
//
// degree 1: centroid, weight 1/6.
// degree 2: 4 points (a, a, a) permutations with a = (5 - sqrt 5)/20, b = 1 - 3a, weights 1/24
//   (Zienkiewicz, Taylor, The Finite Element Method, vol. 1, table 5.4).
// degree 5: 14 points with positive weights: two 4-point orbits (a, a, a, 1-3a) and one 6-point
//   orbit (b, b, 1/2-b, 1/2-b), the rule listed by C. A. Felippa, Advanced Finite Element Methods
//   (Univ. of Colorado lecture notes), section 17.4, "14-point rule", and by N. Walkington,
//   Quadrature on simplices of arbitrary dimension (CMU report, 2000). Its exactness for every
//   monomial of degree <= 5 is checked in tests/unit/t200-fe-elem.c.
#define Q2A 0.13819660112501051518  // (5 - sqrt 5)/20
#define Q2B 0.58541019662496845446  // 1 - 3 a
static const double q1_pts[3] = {0.25, 0.25, 0.25};
static const double q1_w[1] = {1.0 / 6.0};
static const double q2_pts[12] = {Q2A, Q2A, Q2A, Q2B, Q2A, Q2A, Q2A, Q2B, Q2A, Q2A, Q2A, Q2B};
static const double q2_w[4] = {1.0 / 24, 1.0 / 24, 1.0 / 24, 1.0 / 24};
#define Q5A1 0.09273525031089122640  // orbit 1: (a, a, a, 1 - 3a)
#define Q5C1 0.72179424906732632079  // 1 - 3 a1
#define Q5W1 0.01224884051939365826
#define Q5A2 0.31088591926330060980  // orbit 2
#define Q5C2 0.06734224221009817061  // 1 - 3 a2
#define Q5W2 0.01878132095300264180
#define Q5B 0.04550370412564964949  // orbit 3: (b, b, 1/2 - b, 1/2 - b)
#define Q5D 0.45449629587435035051  // 1/2 - b
#define Q5W3 0.00709100346284689436
static const double q5_pts[42] = {
    // orbit 1 (L1, L2, L3); the fourth barycentric is L0
    Q5A1, Q5A1, Q5A1, Q5C1, Q5A1, Q5A1, Q5A1, Q5C1, Q5A1, Q5A1, Q5A1, Q5C1,
    // orbit 2
    Q5A2, Q5A2, Q5A2, Q5C2, Q5A2, Q5A2, Q5A2, Q5C2, Q5A2, Q5A2, Q5A2, Q5C2,
    // orbit 3: the pairs of barycentrics (L0..L3) equal to b: (0,1) (0,2) (0,3) (1,2) (1,3) (2,3)
    Q5B, Q5D, Q5D, Q5D, Q5B, Q5D, Q5D, Q5D, Q5B, Q5B, Q5B, Q5D, Q5B, Q5D, Q5B, Q5D, Q5B, Q5B};
static const double q5_w[14] = {Q5W1, Q5W1, Q5W1, Q5W1, Q5W2, Q5W2, Q5W2,
                                Q5W2, Q5W3, Q5W3, Q5W3, Q5W3, Q5W3, Q5W3};

int fmbd_fe_tet_rule(int degree, int *npts, const double **pts, const double **w) {
  switch (degree) {
    case 1:
      *npts = 1;
      *pts = q1_pts;
      *w = q1_w;
      return FMBD_OK;
    case 2:
      *npts = 4;
      *pts = q2_pts;
      *w = q2_w;
      return FMBD_OK;
    case 5:
      *npts = 14;
      *pts = q5_pts;
      *w = q5_w;
      return FMBD_OK;
    default:
      FMBD_FAIL(FMBD_ERR_VALUE, "no tetrahedron rule of degree %d (1, 2, 5 exist)", degree);
  }
}

// gmsh tet10 edges (MTetrahedron::edges_tetra): mid-side node 4+l sits on edge l
static const int tet_edge[6][2] = {{0, 1}, {1, 2}, {2, 0}, {3, 0}, {3, 2}, {3, 1}};
// reference coordinates of the tet10 nodes (gmsh order)
static const double tet_node_xi[10][3] = {{0, 0, 0},   {1, 0, 0},   {0, 1, 0},  {0, 0, 1},
                                          {.5, 0, 0},  {.5, .5, 0}, {0, .5, 0}, {0, 0, .5},
                                          {0, .5, .5}, {.5, 0, .5}};

void fmbd_fe_tet_shape(int nn, const double xi[3], double *N, double *dN) {
  const double L[4] = {1.0 - xi[0] - xi[1] - xi[2], xi[0], xi[1], xi[2]};
  // dL_a/dxi_k: L0 -> (-1,-1,-1), L1 -> e1, L2 -> e2, L3 -> e3
  static const double dL[4][3] = {{-1, -1, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  if (nn == 4) {
    for (int a = 0; a < 4; a++) {
      N[a] = L[a];
      for (int k = 0; k < 3; k++) dN[a * 3 + k] = dL[a][k];
    }
    return;
  }
  for (int a = 0; a < 4; a++) {  // corner: L (2L - 1)
    N[a] = L[a] * (2.0 * L[a] - 1.0);
    for (int k = 0; k < 3; k++) dN[a * 3 + k] = (4.0 * L[a] - 1.0) * dL[a][k];
  }
  for (int l = 0; l < 6; l++) {  // mid-side: 4 Li Lj
    int i = tet_edge[l][0], j = tet_edge[l][1];
    N[4 + l] = 4.0 * L[i] * L[j];
    for (int k = 0; k < 3; k++) dN[(4 + l) * 3 + k] = 4.0 * (dL[i][k] * L[j] + L[i] * dL[j][k]);
  }
}

// det J of a row-major 3x3 matrix; Jinv = J^-1 when Jinv is given and det != 0
static double inv3(const double J[9], double Jinv[9]) {
  double det = J[0] * (J[4] * J[8] - J[5] * J[7]) - J[1] * (J[3] * J[8] - J[5] * J[6]) +
               J[2] * (J[3] * J[7] - J[4] * J[6]);
  if (Jinv && det != 0.0) {
    Jinv[0] = (J[4] * J[8] - J[5] * J[7]) / det;
    Jinv[1] = (J[2] * J[7] - J[1] * J[8]) / det;
    Jinv[2] = (J[1] * J[5] - J[2] * J[4]) / det;
    Jinv[3] = (J[5] * J[6] - J[3] * J[8]) / det;
    Jinv[4] = (J[0] * J[8] - J[2] * J[6]) / det;
    Jinv[5] = (J[2] * J[3] - J[0] * J[5]) / det;
    Jinv[6] = (J[3] * J[7] - J[4] * J[6]) / det;
    Jinv[7] = (J[1] * J[6] - J[0] * J[7]) / det;
    Jinv[8] = (J[0] * J[4] - J[1] * J[3]) / det;
  }
  return det;
}

// Jacobian J[k][j] = d x_j / d xi_k at a point; returns det; Jinv = J^-1 (row-major)
static double jacobian(int nn, const double *xyz, const double *dN, double J[9], double Jinv[9]) {
  memset(J, 0, 9 * sizeof(double));
  for (int a = 0; a < nn; a++) {
    for (int k = 0; k < 3; k++) {
      for (int j = 0; j < 3; j++) J[k * 3 + j] += dN[a * 3 + k] * xyz[a * 3 + j];
    }
  }
  return inv3(J, Jinv);
}

// Scale for the degeneracy test: largest corner-to-corner distance cubed
static double edge_scale3(const double *xyz) {
  double h2 = 0.0;
  for (int a = 0; a < 4; a++) {
    for (int b = a + 1; b < 4; b++) {
      double d2 = 0.0;
      for (int k = 0; k < 3; k++)
        d2 += (xyz[a * 3 + k] - xyz[b * 3 + k]) * (xyz[a * 3 + k] - xyz[b * 3 + k]);
      if (d2 > h2) h2 = d2;
    }
  }
  return h2 * sqrt(h2);
}

// A Jacobian determinant below this fraction of h^3 (h = longest corner edge) marks the element
// degenerate. A regular tetrahedron has det J = h^3/sqrt 2; gmsh's worst accepted slivers stay
// orders of magnitude above 1e-12.
#define DEGENERATE_REL 1e-12

static int check_det(double det, double h3, int64_t elem, int nn, const char *where,
                     const double xi[3]) {
  if (!(det > DEGENERATE_REL * h3)) {
    FMBD_FAIL(FMBD_ERR_VALUE,
              "element %lld (tet%d): %s: Jacobian determinant %.6g at %s (xi, eta, zeta) = "
              "(%.4g, %.4g, %.4g) (element size^3 %.3g)",
              (long long)elem, nn, det <= 0.0 ? "inverted" : "degenerate", det, where, xi[0], xi[1],
              xi[2], h3);
  }
  return FMBD_OK;
}

// Shape functions at the quadrature points and nodes, computed once (the programs are single
// threaded; the tables are filled on the first call)
typedef struct tet_tables {
  bool ready;
  double N[2][3][14][10];  // [tet4, tet10][rule deg 1, 2, 5][point][node]
  double dN[2][3][14][30];
  double Nnode[10][30];  // tet10 derivatives at its nodes
  double Mref[2][100];   // int N_a N_b over the unit tetrahedron (degree-5 rule: exact)
} tet_tables;
static tet_tables tt;

static void tables_init(void) {
  if (tt.ready) return;
  const int degs[3] = {1, 2, 5};
  for (int o = 0; o < 2; o++) {
    int nn = o ? 10 : 4;
    for (int r = 0; r < 3; r++) {
      int np;
      const double *pts, *w;
      fmbd_fe_tet_rule(degs[r], &np, &pts, &w);
      for (int q = 0; q < np; q++)
        fmbd_fe_tet_shape(nn, pts + 3 * q, tt.N[o][r][q], tt.dN[o][r][q]);
      if (r == 2) {
        for (int a = 0; a < nn; a++) {
          for (int b = 0; b < nn; b++) {
            double sum = 0.0;
            for (int q = 0; q < np; q++) sum += w[q] * tt.N[o][r][q][a] * tt.N[o][r][q][b];
            tt.Mref[o][a * nn + b] = sum;
          }
        }
      }
    }
  }
  double Nn[10];
  for (int a = 0; a < 10; a++) fmbd_fe_tet_shape(10, tet_node_xi[a], Nn, tt.Nnode[a]);
  tt.ready = true;
}

// K += (stiffness integrand at one point) for gradients g (nn x 3) and weight wd, b >= a only
static void stiffness_point(int nn, const double *g, double wd, double lambda, double mu,
                            double *Ke) {
  const int n3 = 3 * nn;
  for (int a = 0; a < nn; a++) {
    const double *ga = g + 3 * a;
    const double la[3] = {wd * lambda * ga[0], wd * lambda * ga[1], wd * lambda * ga[2]};
    const double ma[3] = {wd * mu * ga[0], wd * mu * ga[1], wd * mu * ga[2]};
    for (int b = a; b < nn; b++) {
      const double *gb = g + 3 * b;
      const double dot = ma[0] * gb[0] + ma[1] * gb[1] + ma[2] * gb[2];
      double *blk = Ke + (size_t)(3 * a) * n3 + 3 * b;
      for (int i = 0; i < 3; i++) {
        double *row = blk + (size_t)i * n3;
        row[0] += la[i] * gb[0] + ma[0] * gb[i];
        row[1] += la[i] * gb[1] + ma[1] * gb[i];
        row[2] += la[i] * gb[2] + ma[2] * gb[i];
        row[i] += dot;
      }
    }
  }
}

// global gradients g_a = J^-1 dN_a (J[k][j] = dx_j/dxi_k, so dN/dx_j = sum_k Jinv[j][k] dN/dxi_k)
static void gradients(int nn, const double *Jinv, const double *dN, double *g) {
  for (int a = 0; a < nn; a++) {
    for (int j = 0; j < 3; j++) {
      g[a * 3 + j] = Jinv[j * 3 + 0] * dN[a * 3 + 0] + Jinv[j * 3 + 1] * dN[a * 3 + 1] +
                     Jinv[j * 3 + 2] * dN[a * 3 + 2];
    }
  }
}

int fmbd_fe_tet_matrices(int nn, const double *xyz, double E, double nu, double rho, int64_t elem,
                         double *Ke, double *Me, double *volume) {
  FMBD_CHECK(nn == 4 || nn == 10, FMBD_ERR_VALUE, "tetrahedron with %d nodes (4 or 10)", nn);
  tables_init();
  const int o = nn == 10, n3 = 3 * nn;
  const double lambda = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), mu = E / (2.0 * (1.0 + nu));
  const double h3 = edge_scale3(xyz);
  double g[30], J[9], Jinv[9];
  int np;
  const double *pts, *w;
  // --- affine element: tet4, or a tet10 whose mid-side nodes sit at the edge midpoints (to
  // 1e-10 of the element size, i.e. the rounding of a mesh file): one constant Jacobian
  bool affine = true;
  if (nn == 10) {
    const double tol2 = 1e-20 * cbrt(h3 * h3);
    for (int l = 0; l < 6 && affine; l++) {
      const double *xa = xyz + 3 * tet_edge[l][0], *xb = xyz + 3 * tet_edge[l][1],
                   *xm = xyz + 3 * (4 + l);
      double d2 = 0.0;
      for (int k = 0; k < 3; k++)
        d2 += (xm[k] - 0.5 * (xa[k] + xb[k])) * (xm[k] - 0.5 * (xa[k] + xb[k]));
      affine = d2 <= tol2;
    }
  }
  if (Ke) memset(Ke, 0, (size_t)n3 * n3 * sizeof(double));
  if (affine) {
    // J rows: x1 - x0, x2 - x0, x3 - x0
    for (int k = 0; k < 3; k++) {
      for (int j = 0; j < 3; j++) J[k * 3 + j] = xyz[3 * (k + 1) + j] - xyz[j];
    }
    double det = inv3(J, Jinv);
    const double centroid[3] = {0.25, 0.25, 0.25};
    FMBD_CALL(check_det(det, h3, elem, nn, "every point (straight element)", centroid));
    if (Ke) {  // degree 0 (tet4, 1 point) or 2 (tet10, 4 points): exact
      const int r = nn == 4 ? 0 : 1;
      FMBD_CALL(fmbd_fe_tet_rule(nn == 4 ? 1 : 2, &np, &pts, &w));
      for (int q = 0; q < np; q++) {
        gradients(nn, Jinv, tt.dN[o][r][q], g);
        stiffness_point(nn, g, w[q] * det, lambda, mu, Ke);
      }
    }
    if (Me) {  // rho det int N_a N_b (exact reference table)
      for (int i = 0; i < nn * nn; i++) Me[i] = rho * det * tt.Mref[o][i];
    }
    if (volume) *volume = det / 6.0;
  } else {
    // --- curved tet10: isoparametric Jacobian at every point; det J > 0 also at the nodes (a
    // curved element may fold near a corner between quadrature points)
    for (int a = 0; a < 10; a++) {
      double det = jacobian(nn, xyz, tt.Nnode[a], J, NULL);
      if (!(det > DEGENERATE_REL * h3)) {
        char where[32];
        snprintf(where, sizeof where, "node %d", a);
        FMBD_CALL(check_det(det, h3, elem, nn, where, tet_node_xi[a]));
      }
    }
    if (Ke) {  // 4-point degree-2 rule (exact on straight elements; CalculiX C3D10 uses the same)
      FMBD_CALL(fmbd_fe_tet_rule(2, &np, &pts, &w));
      for (int q = 0; q < np; q++) {
        double det = jacobian(nn, xyz, tt.dN[o][1][q], J, Jinv);
        FMBD_CALL(check_det(det, h3, elem, nn, "quadrature point", pts + 3 * q));
        gradients(nn, Jinv, tt.dN[o][1][q], g);
        stiffness_point(nn, g, w[q] * det, lambda, mu, Ke);
      }
    }
    // mass and volume with the degree-5 rule
    FMBD_CALL(fmbd_fe_tet_rule(5, &np, &pts, &w));
    if (Me) memset(Me, 0, (size_t)nn * nn * sizeof(double));
    double vol = 0.0;
    for (int q = 0; q < np; q++) {
      const double *N = tt.N[o][2][q];
      double det = jacobian(nn, xyz, tt.dN[o][2][q], J, NULL);
      FMBD_CALL(check_det(det, h3, elem, nn, "quadrature point", pts + 3 * q));
      vol += w[q] * det;
      if (Me) {
        const double wr = w[q] * det * rho;
        for (int a = 0; a < nn; a++) {
          const double wa = wr * N[a];
          for (int b = a; b < nn; b++) Me[a * nn + b] += wa * N[b];
        }
      }
    }
    if (Me) {
      for (int a = 0; a < nn; a++) {
        for (int b = 0; b < a; b++) Me[a * nn + b] = Me[b * nn + a];
      }
    }
    if (volume) *volume = vol;
  }
  if (Ke) {  // mirror the upper block triangle; diagonal blocks made exactly symmetric
    for (int a = 0; a < nn; a++) {
      for (int i = 0; i < 3; i++) {
        for (int j = i + 1; j < 3; j++) {
          double *x = Ke + (size_t)(3 * a + i) * n3 + 3 * a + j,
                 *y = Ke + (size_t)(3 * a + j) * n3 + 3 * a + i;
          *x = *y = 0.5 * (*x + *y);
        }
      }
      for (int b = a + 1; b < nn; b++) {
        for (int i = 0; i < 3; i++) {
          for (int j = 0; j < 3; j++)
            Ke[(size_t)(3 * b + j) * n3 + 3 * a + i] = Ke[(size_t)(3 * a + i) * n3 + 3 * b + j];
        }
      }
    }
  }
  return FMBD_OK;
}

void fmbd_fe_rigid_rows(const double r[3], double A[18]) {
  memset(A, 0, 18 * sizeof *A);
  for (int k = 0; k < 3; k++) A[k * 6 + k] = 1.0;
  // -[r]x = [[0, rz, -ry], [-rz, 0, rx], [ry, -rx, 0]]
  A[0 * 6 + 4] = r[2];
  A[0 * 6 + 5] = -r[1];
  A[1 * 6 + 3] = -r[2];
  A[1 * 6 + 5] = r[0];
  A[2 * 6 + 3] = r[1];
  A[2 * 6 + 4] = -r[0];
}

void fmbd_fe_hrz_scalar(int n, const double *Me, double m, double *d) {
  double s = 0.0;
  for (int a = 0; a < n; a++) s += Me[a * n + a];
  for (int a = 0; a < n; a++) d[a] = s > 0.0 ? m * Me[a * n + a] / s : 0.0;
}

// --- beams ------------------------------------------------------------------------------------
int fmbd_fe_beam_frame(const double x0[3], const double x1[3], const double v[3], int64_t elem,
                       double R[9], double *L) {
  double ex[3] = {x1[0] - x0[0], x1[1] - x0[1], x1[2] - x0[2]};
  double len = sqrt(ex[0] * ex[0] + ex[1] * ex[1] + ex[2] * ex[2]);
  FMBD_CHECK(len > 0.0, FMBD_ERR_VALUE, "beam element %lld has zero length", (long long)elem);
  for (int k = 0; k < 3; k++) ex[k] /= len;
  double vv = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  double d = v[0] * ex[0] + v[1] * ex[1] + v[2] * ex[2];
  double ez[3] = {v[0] - d * ex[0], v[1] - d * ex[1], v[2] - d * ex[2]};
  double nz = sqrt(ez[0] * ez[0] + ez[1] * ez[1] + ez[2] * ez[2]);
  FMBD_CHECK(vv > 0.0 && nz > 1e-8 * vv, FMBD_ERR_VALUE,
             "beam element %lld: orientation vector (%g, %g, %g) is zero or parallel to the beam "
             "axis (%g, %g, %g)",
             (long long)elem, v[0], v[1], v[2], ex[0], ex[1], ex[2]);
  for (int k = 0; k < 3; k++) ez[k] /= nz;
  double ey[3] = {ez[1] * ex[2] - ez[2] * ex[1], ez[2] * ex[0] - ez[0] * ex[2],
                  ez[0] * ex[1] - ez[1] * ex[0]};  // z cross x
  for (int k = 0; k < 3; k++) {
    R[0 * 3 + k] = ex[k];
    R[1 * 3 + k] = ey[k];
    R[2 * 3 + k] = ez[k];
  }
  *L = len;
  return FMBD_OK;
}

static void sym12(double *A, int i, int j, double v) {
  A[i * 12 + j] = v;
  A[j * 12 + i] = v;
}

// Local 12x12 matrices, dofs (u v w rx ry rz) of node 0 then node 1; Przemieniecki, Theory of
// Matrix Structural Analysis (1968), eqs. 5.115 (stiffness) and 11.42 (consistent mass).
// Bending in the x-y plane (v, rz) uses Iz; in the x-z plane (w, ry) uses Iy, with ry = -dw/dx.
static void beam_local(double L, double E, double G, double rho, double A, double Iy, double Iz,
                       double J, double *K, double *M) {
  memset(K, 0, 144 * sizeof(double));
  memset(M, 0, 144 * sizeof(double));
#define KS(i, j, val) sym12(K, i, j, val)
#define MS(i, j, val) sym12(M, i, j, val)
  const double L2 = L * L, L3 = L2 * L;
  double ea = E * A / L, gj = G * J / L;
  KS(0, 0, ea);
  KS(6, 6, ea);
  KS(0, 6, -ea);
  KS(3, 3, gj);
  KS(9, 9, gj);
  KS(3, 9, -gj);
  double a = 12 * E * Iz / L3, b = 6 * E * Iz / L2, c = 4 * E * Iz / L, d = 2 * E * Iz / L;
  KS(1, 1, a);
  KS(1, 5, b);
  KS(1, 7, -a);
  KS(1, 11, b);
  KS(5, 5, c);
  KS(5, 7, -b);
  KS(5, 11, d);
  KS(7, 7, a);
  KS(7, 11, -b);
  KS(11, 11, c);
  a = 12 * E * Iy / L3;
  b = 6 * E * Iy / L2;
  c = 4 * E * Iy / L;
  d = 2 * E * Iy / L;
  KS(2, 2, a);
  KS(2, 4, -b);
  KS(2, 8, -a);
  KS(2, 10, -b);
  KS(4, 4, c);
  KS(4, 8, b);
  KS(4, 10, d);
  KS(8, 8, a);
  KS(8, 10, b);
  KS(10, 10, c);
  const double m = rho * A * L, mt = rho * J * L, f = m / 420.0;
  MS(0, 0, m / 3);
  MS(6, 6, m / 3);
  MS(0, 6, m / 6);
  MS(3, 3, mt / 3);
  MS(9, 9, mt / 3);
  MS(3, 9, mt / 6);
  MS(1, 1, 156 * f);
  MS(1, 5, 22 * L * f);
  MS(1, 7, 54 * f);
  MS(1, 11, -13 * L * f);
  MS(5, 5, 4 * L2 * f);
  MS(5, 7, 13 * L * f);
  MS(5, 11, -3 * L2 * f);
  MS(7, 7, 156 * f);
  MS(7, 11, -22 * L * f);
  MS(11, 11, 4 * L2 * f);
  MS(2, 2, 156 * f);
  MS(2, 4, -22 * L * f);
  MS(2, 8, 54 * f);
  MS(2, 10, 13 * L * f);
  MS(4, 4, 4 * L2 * f);
  MS(4, 8, -13 * L * f);
  MS(4, 10, -3 * L2 * f);
  MS(8, 8, 156 * f);
  MS(8, 10, 22 * L * f);
  MS(10, 10, 4 * L2 * f);
#undef KS
#undef MS
}

// G = T' L T with T = blockdiag(R, R, R, R) (u_local = R u_global): per 3x3 block R' L_IJ R
static void rotate12(const double R[9], const double *Lm, double *G) {
  for (int I = 0; I < 4; I++) {
    for (int Jb = 0; Jb < 4; Jb++) {
      double t[9] = {0};
      for (int i = 0; i < 3; i++) {  // t = L_IJ R
        for (int j = 0; j < 3; j++) {
          double s = 0.0;
          for (int k = 0; k < 3; k++) s += Lm[(3 * I + i) * 12 + 3 * Jb + k] * R[k * 3 + j];
          t[i * 3 + j] = s;
        }
      }
      for (int i = 0; i < 3; i++) {  // G_IJ = R' t
        for (int j = 0; j < 3; j++) {
          double s = 0.0;
          for (int k = 0; k < 3; k++) s += R[k * 3 + i] * t[k * 3 + j];
          G[(3 * I + i) * 12 + 3 * Jb + j] = s;
        }
      }
    }
  }
}

int fmbd_fe_beam_matrices(const double x0[3], const double x1[3], const double v[3], double E,
                          double nu, double rho, double A, double Iy, double Iz, double J,
                          int64_t elem, double *Ke, double *Me) {
  double R[9], L, Kl[144], Ml[144];
  FMBD_CALL(fmbd_fe_beam_frame(x0, x1, v, elem, R, &L));
  beam_local(L, E, E / (2.0 * (1.0 + nu)), rho, A, Iy, Iz, J, Kl, Ml);
  if (Ke) rotate12(R, Kl, Ke);
  if (Me) rotate12(R, Ml, Me);
  return FMBD_OK;
}

// HRZ lumped beam mass (global 12x12, block diagonal per node). In the local frame the
// consistent diagonal is scaled per direction so that it sums to the element's total:
// translations (and the bending rotation paired with each transverse translation: rz with v,
// ry with w) by m / (sum of that translation's two diagonal entries), as HRZ prescribe; the
// torsional rotations, which have no translational partner, so that they sum to rho*J*L.
// Result in the local frame: translations m/2, rx rho J L/2, ry rz m L^2/78.
int fmbd_fe_beam_lumped(const double x0[3], const double x1[3], const double v[3], double rho,
                        double A, double J, int64_t elem, double *Me) {
  double R[9], L, Kl[144], Ml[144], D[144];
  FMBD_CALL(fmbd_fe_beam_frame(x0, x1, v, elem, R, &L));
  beam_local(L, 1.0, 1.0, rho, A, 1.0, 1.0, J, Kl, Ml);
  const double m = rho * A * L, mt = rho * J * L;
  double f[6];
  for (int d = 0; d < 3; d++) f[d] = m / (Ml[d * 12 + d] + Ml[(6 + d) * 12 + 6 + d]);
  f[3] = mt > 0.0 ? mt / (Ml[3 * 12 + 3] + Ml[9 * 12 + 9]) : 0.0;
  f[4] = f[2];  // ry pairs with w
  f[5] = f[1];  // rz pairs with v
  memset(D, 0, sizeof D);
  for (int i = 0; i < 12; i++) D[i * 12 + i] = f[i % 6] * Ml[i * 12 + i];
  rotate12(R, D, Me);
  return FMBD_OK;
}
