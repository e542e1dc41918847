// tests/unit/t200-fe-elem.c: element level: quadrature exactness, tet4/tet10 shape functions,
// element stiffness and mass (rigid modes, rank, volume), HRZ, beams, Jacobian errors
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"

static double fact(int n) {
  return n <= 1 ? 1.0 : n * fact(n - 1);
}

// exact integral of xi^a eta^b zeta^c over the unit tetrahedron: a! b! c! / (a+b+c+3)!
static double mono_exact(int a, int b, int c) {
  return fact(a) * fact(b) * fact(c) / fact(a + b + c + 3);
}

static void test_rules(void) {
  const int degs[3] = {1, 2, 5};
  for (int r = 0; r < 3; r++) {
    int np;
    const double *pts, *w;
    EXPECT(fmbd_fe_tet_rule(degs[r], &np, &pts, &w) == FMBD_OK, "rule %d", degs[r]);
    double worst = 0.0;
    for (int a = 0; a <= degs[r]; a++) {
      for (int b = 0; a + b <= degs[r]; b++) {
        for (int c = 0; a + b + c <= degs[r]; c++) {
          double s = 0.0;
          for (int q = 0; q < np; q++) {
            s += w[q] * pow(pts[3 * q], a) * pow(pts[3 * q + 1], b) * pow(pts[3 * q + 2], c);
          }
          double ex = mono_exact(a, b, c), err = fabs(s - ex) / ex;
          if (err > worst) worst = err;
        }
      }
    }
    // 20 significant digits are given for the points and weights: exact to rounding (~1e-15
    // relative on moments down to 5!/8! = 3e-3 of the volume)
    EXPECT(worst < 1e-13, "rule of degree %d: worst relative monomial error %.3g", degs[r], worst);
    // and not exact one degree higher (the test can fail): some monomial of degree deg+1 is off
    double worst_next = 0.0;
    int d1 = degs[r] + 1;
    for (int a = 0; a <= d1; a++) {
      for (int b = 0; a + b <= d1; b++) {
        int c = d1 - a - b;
        double s = 0.0;
        for (int q = 0; q < np; q++)
          s += w[q] * pow(pts[3 * q], a) * pow(pts[3 * q + 1], b) * pow(pts[3 * q + 2], c);
        double err = fabs(s - mono_exact(a, b, c)) / mono_exact(a, b, c);
        if (err > worst_next) worst_next = err;
      }
    }
    EXPECT(worst_next > 1e-6, "rule of degree %d is also exact at degree %d (%.3g)?", degs[r], d1,
           worst_next);
  }
  int np;
  const double *pts, *w;
  EXPECT(fmbd_fe_tet_rule(3, &np, &pts, &w) == FMBD_ERR_VALUE, "degree 3 does not exist");
}

static const double node_xi[10][3] = {{0, 0, 0},   {1, 0, 0},   {0, 1, 0},  {0, 0, 1},
                                      {.5, 0, 0},  {.5, .5, 0}, {0, .5, 0}, {0, 0, .5},
                                      {0, .5, .5}, {.5, 0, .5}};

static void test_shape(void) {
  for (int nn = 4; nn <= 10; nn += 6) {
    double N[10], dN[30], Np[10], Nm[10], dd[30];
    // Kronecker property at the nodes (gmsh order: 4 on (0,1), 5 (1,2), 6 (2,0), 7 (3,0), 8 (3,2),
    // 9 (3,1))
    for (int b = 0; b < nn; b++) {
      fmbd_fe_tet_shape(nn, node_xi[b], N, dN);
      for (int a = 0; a < nn; a++) {
        EXPECT(fabs(N[a] - (a == b)) < 1e-15, "tet%d: N_%d(node %d) = %g", nn, a, b, N[a]);
      }
    }
    // partition of unity, derivatives against central differences (h = 1e-6: error ~h^2 = 1e-12
    // for these quadratics, rounding ~1e-16/1e-6 = 1e-10; tolerance 1e-8)
    const double xi[3] = {0.21, 0.17, 0.33};
    fmbd_fe_tet_shape(nn, xi, N, dN);
    double s = 0.0, sd[3] = {0, 0, 0};
    for (int a = 0; a < nn; a++) {
      s += N[a];
      for (int k = 0; k < 3; k++) sd[k] += dN[a * 3 + k];
    }
    EXPECT(fabs(s - 1) < 1e-15 && fabs(sd[0]) + fabs(sd[1]) + fabs(sd[2]) < 1e-14,
           "tet%d: partition of unity", nn);
    for (int k = 0; k < 3; k++) {
      double xp[3] = {xi[0], xi[1], xi[2]}, xm[3] = {xi[0], xi[1], xi[2]};
      xp[k] += 1e-6;
      xm[k] -= 1e-6;
      fmbd_fe_tet_shape(nn, xp, Np, dd);
      fmbd_fe_tet_shape(nn, xm, Nm, dd);
      for (int a = 0; a < nn; a++) {
        double fd = (Np[a] - Nm[a]) / 2e-6;
        EXPECT(fabs(fd - dN[a * 3 + k]) < 1e-8, "tet%d: dN_%d/dxi_%d = %g, difference quotient %g",
               nn, a, k, dN[a * 3 + k], fd);
      }
    }
  }
}

// a general straight tetrahedron, and its tet10 with straight mid-side nodes
static const double X4[12] = {0.1, 0.0, 0.05, 1.2, 0.1, -0.1, 0.3, 0.9, 0.2, 0.2, 0.3, 1.1};
static void make_tet10(const double *x4, double *x10) {
  static const int ed[6][2] = {{0, 1}, {1, 2}, {2, 0}, {3, 0}, {3, 2}, {3, 1}};
  memcpy(x10, x4, 12 * sizeof(double));
  for (int l = 0; l < 6; l++) {
    for (int d = 0; d < 3; d++)
      x10[3 * (4 + l) + d] = 0.5 * (x4[3 * ed[l][0] + d] + x4[3 * ed[l][1] + d]);
  }
}

static double det3(const double *x) {  // 6 * volume of the straight tet
  double a[3], b[3], c[3];
  for (int d = 0; d < 3; d++) {
    a[d] = x[3 + d] - x[d];
    b[d] = x[6 + d] - x[d];
    c[d] = x[9 + d] - x[d];
  }
  return a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
         a[2] * (b[0] * c[1] - b[1] * c[0]);
}

static void test_tet_element(void) {
  const double E = 70e9, nu = 0.33, rho = 2700;
  double x10[30];
  make_tet10(X4, x10);
  const double V = det3(X4) / 6.0;
  for (int nn = 4; nn <= 10; nn += 6) {
    const double *x = nn == 4 ? X4 : x10;
    int n3 = 3 * nn;
    double *K = fmbd_malloc(sizeof(double) * n3 * n3), *Kc = fmbd_malloc(sizeof(double) * n3 * n3);
    double Me[100], vol, w[30];
    EXPECT(fmbd_fe_tet_matrices(nn, x, E, nu, rho, 0, K, Me, &vol) == FMBD_OK, "tet%d matrices",
           nn);
    EXPECT(fabs(vol - V) < 1e-14 * V, "tet%d volume %.17g, det/6 %.17g", nn, vol, V);
    double m = 0.0;
    for (int i = 0; i < nn * nn; i++) m += Me[i];
    EXPECT(fabs(m - rho * V) < 1e-13 * rho * V, "tet%d: sum of Me %.17g, rho V %.17g", nn, m,
           rho * V);
    double asym = 0.0, kmax = 0.0;
    for (int i = 0; i < n3; i++) {
      for (int j = 0; j < n3; j++) {
        asym = fmax(asym, fabs(K[i * n3 + j] - K[j * n3 + i]));
        kmax = fmax(kmax, fabs(K[i * n3 + j]));
      }
    }
    EXPECT(asym <= 1e-14 * kmax, "tet%d: Ke asymmetry %.3g of %.3g", nn, asym, kmax);
    // six rigid modes: K r = 0 for r = translations and infinitesimal rotations theta x x
    for (int mode = 0; mode < 6; mode++) {
      double r[30], f = 0.0;
      for (int a = 0; a < nn; a++) {
        const double *p = x + 3 * a;
        double t[3] = {0, 0, 0};
        if (mode < 3) {
          t[mode] = 1.0;
        } else {  // e_k x p
          int k = mode - 3;
          double e[3] = {0, 0, 0};
          e[k] = 1.0;
          t[0] = e[1] * p[2] - e[2] * p[1];
          t[1] = e[2] * p[0] - e[0] * p[2];
          t[2] = e[0] * p[1] - e[1] * p[0];
        }
        memcpy(r + 3 * a, t, sizeof t);
      }
      for (int i = 0; i < n3; i++) {
        double s = 0.0;
        for (int j = 0; j < n3; j++) s += K[i * n3 + j] * r[j];
        f = fmax(f, fabs(s));
      }
      // |K r| relative to |K| |r| (|r| ~ 1.2): rounding level
      EXPECT(f < 1e-13 * kmax * 2, "tet%d: rigid mode %d gives force %.3g (K max %.3g)", nn, mode,
             f, kmax);
    }
    // rank 3nn - 6: exactly six eigenvalues below 1e-10 of the largest
    for (int i = 0; i < n3; i++) {
      for (int j = 0; j < n3; j++) Kc[i + n3 * j] = K[i * n3 + j];
    }
    EXPECT(fmbd_dense_syev(n3, Kc, w) == FMBD_OK, "syev");
    int nz = 0;
    for (int i = 0; i < n3; i++) nz += fabs(w[i]) < 1e-10 * w[n3 - 1];
    EXPECT(nz == 6, "tet%d: %d zero-energy modes, expected 6", nn, nz);
    fmbd_free(K);
    fmbd_free(Kc);
    // HRZ: tet4 all m/4; tet10 corners m/36 and mid-sides 4m/27 (consistent diagonal 6/420 and
    // 32/420 of rho V, Zienkiewicz-Taylor), sum m
    double d[10];
    fmbd_fe_hrz_scalar(nn, Me, m, d);
    for (int a = 0; a < nn; a++) {
      double ex = nn == 4 ? m / 4 : (a < 4 ? m / 36 : 4 * m / 27);
      EXPECT(fabs(d[a] - ex) < 1e-13 * m, "tet%d HRZ node %d: %.17g, expected %.17g", nn, a, d[a],
             ex);
    }
  }
  // tet4 consistent mass in closed form: rho V/20 (1 + delta_ab)
  double Me[16], vol;
  EXPECT(fmbd_fe_tet_matrices(4, X4, E, nu, rho, 0, NULL, Me, &vol) == FMBD_OK, "tet4 mass");
  for (int a = 0; a < 4; a++) {
    for (int b = 0; b < 4; b++) {
      double ex = rho * V / 20 * (1 + (a == b));
      EXPECT(fabs(Me[a * 4 + b] - ex) < 1e-13 * rho * V, "tet4 M[%d][%d] = %g, expected %g", a, b,
             Me[a * 4 + b], ex);
    }
  }
  // tet10 consistent mass in closed form (straight): corner-corner rho V/420 (6, off-diag 1),
  // corner-mid -4 (edges touching the corner) / -6 (opposite edges), mid-mid 32 / 16 (sharing a
  // corner) / 8 (opposite); here we check the row sums: corner rows -rho V/20, mid rows rho V/5
  double M10[100];
  EXPECT(fmbd_fe_tet_matrices(10, x10, E, nu, rho, 0, NULL, M10, &vol) == FMBD_OK, "tet10 mass");
  for (int a = 0; a < 10; a++) {
    double s = 0.0;
    for (int b = 0; b < 10; b++) s += M10[a * 10 + b];
    double ex = a < 4 ? -rho * V / 20 : rho * V / 5;  // int N_a dV: corners -V/20, mid-sides V/5
    EXPECT(fabs(s - ex) < 1e-13 * rho * V, "tet10 row %d sum %.17g, expected %.17g", a, s, ex);
  }
  // every entry against the closed form (units rho V / 420): corners 6 / 1; corner-mid -4 if the
  // edge holds the corner, else -6; mid-mid 32 / 16 (edges sharing a corner) / 8 (opposite)
  static const int ed[6][2] = {{0, 1}, {1, 2}, {2, 0}, {3, 0}, {3, 2}, {3, 1}};
  for (int a = 0; a < 10; a++) {
    for (int b = 0; b < 10; b++) {
      double ex;
      if (a < 4 && b < 4) {
        ex = a == b ? 6 : 1;
      } else if (a < 4 || b < 4) {
        int c = a < 4 ? a : b, l = (a < 4 ? b : a) - 4;
        ex = (ed[l][0] == c || ed[l][1] == c) ? -4 : -6;
      } else if (a == b) {
        ex = 32;
      } else {
        int l = a - 4, k = b - 4;
        bool share = ed[l][0] == ed[k][0] || ed[l][0] == ed[k][1] || ed[l][1] == ed[k][0] ||
                     ed[l][1] == ed[k][1];
        ex = share ? 16 : 8;
      }
      ex *= rho * V / 420;
      EXPECT(fabs(M10[a * 10 + b] - ex) < 1e-13 * rho * V,
             "tet10 M[%d][%d] = %.17g, closed form %.17g", a, b, M10[a * 10 + b], ex);
    }
  }
}

// K = sum_q w_q det J_q B' D B with the 6x6 Voigt D and the 6 x 3nn strain matrix B (engineering
// shears), the textbook form, for any rule: independent of the library's lambda/mu pair formula
static void ke_bdb(int nn, const double *x, double E, double nu, int degree, double *K) {
  int np;
  const double *pts, *w;
  fmbd_fe_tet_rule(degree, &np, &pts, &w);
  const int n3 = 3 * nn;
  double D[36] = {0}, f = E / ((1 + nu) * (1 - 2 * nu));
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) D[i * 6 + j] = f * (i == j ? 1 - nu : nu);
    D[(3 + i) * 6 + 3 + i] = f * (1 - 2 * nu) / 2;
  }
  memset(K, 0, sizeof(double) * n3 * n3);
  for (int q = 0; q < np; q++) {
    double N[10], dN[30], J[9] = {0}, Ji[9], B[6 * 30] = {0}, DB[6 * 30];
    fmbd_fe_tet_shape(nn, pts + 3 * q, N, dN);
    for (int a = 0; a < nn; a++) {
      for (int k = 0; k < 3; k++) {
        for (int j = 0; j < 3; j++) J[k * 3 + j] += dN[a * 3 + k] * x[a * 3 + j];
      }
    }
    double det = J[0] * (J[4] * J[8] - J[5] * J[7]) - J[1] * (J[3] * J[8] - J[5] * J[6]) +
                 J[2] * (J[3] * J[7] - J[4] * J[6]);
    // inverse by cofactors
    Ji[0] = (J[4] * J[8] - J[5] * J[7]) / det;
    Ji[1] = (J[2] * J[7] - J[1] * J[8]) / det;
    Ji[2] = (J[1] * J[5] - J[2] * J[4]) / det;
    Ji[3] = (J[5] * J[6] - J[3] * J[8]) / det;
    Ji[4] = (J[0] * J[8] - J[2] * J[6]) / det;
    Ji[5] = (J[2] * J[3] - J[0] * J[5]) / det;
    Ji[6] = (J[3] * J[7] - J[4] * J[6]) / det;
    Ji[7] = (J[1] * J[6] - J[0] * J[7]) / det;
    Ji[8] = (J[0] * J[4] - J[1] * J[3]) / det;
    for (int a = 0; a < nn; a++) {
      double g[3];
      for (int j = 0; j < 3; j++)
        g[j] =
            Ji[j * 3] * dN[a * 3] + Ji[j * 3 + 1] * dN[a * 3 + 1] + Ji[j * 3 + 2] * dN[a * 3 + 2];
      // strains xx yy zz, gamma yz xz xy (order only matters within D, which is isotropic)
      B[0 * n3 + 3 * a] = g[0];
      B[1 * n3 + 3 * a + 1] = g[1];
      B[2 * n3 + 3 * a + 2] = g[2];
      B[3 * n3 + 3 * a + 1] = g[2];
      B[3 * n3 + 3 * a + 2] = g[1];
      B[4 * n3 + 3 * a] = g[2];
      B[4 * n3 + 3 * a + 2] = g[0];
      B[5 * n3 + 3 * a] = g[1];
      B[5 * n3 + 3 * a + 1] = g[0];
    }
    for (int i = 0; i < 6; i++) {
      for (int c = 0; c < n3; c++) {
        double sum = 0.0;
        for (int k = 0; k < 6; k++) sum += D[i * 6 + k] * B[k * n3 + c];
        DB[i * n3 + c] = sum;
      }
    }
    for (int r = 0; r < n3; r++) {
      for (int c = 0; c < n3; c++) {
        double sum = 0.0;
        for (int k = 0; k < 6; k++) sum += B[k * n3 + r] * DB[k * n3 + c];
        K[r * n3 + c] += w[q] * det * sum;
      }
    }
  }
}

static double max_diff(int n, const double *A, const double *B, double *scale) {
  double d = 0.0, s = 0.0;
  for (int i = 0; i < n; i++) {
    d = fmax(d, fabs(A[i] - B[i]));
    s = fmax(s, fabs(B[i]));
  }
  *scale = s;
  return d;
}

static void test_stiffness_bdb(void) {
  const double E = 2e11, nu = 0.28;
  double x10[30], K[900], R[900], scale, vol;
  make_tet10(X4, x10);
  // tet4 (1-point rule in the library) against B'DB with the degree-5 rule: both exact
  EXPECT(fmbd_fe_tet_matrices(4, X4, E, nu, 1.0, 0, K, NULL, &vol) == FMBD_OK, "tet4");
  ke_bdb(4, X4, E, nu, 5, R);
  double d = max_diff(144, K, R, &scale);
  EXPECT(d < 1e-13 * scale, "tet4 K vs B'DB: %.3g of %.3g", d, scale);
  // straight tet10: the library's 4-point rule against B'DB with the degree-5 rule; both are
  // exact for the degree-2 integrand, so they agree to rounding
  EXPECT(fmbd_fe_tet_matrices(10, x10, E, nu, 1.0, 0, K, NULL, &vol) == FMBD_OK, "tet10");
  ke_bdb(10, x10, E, nu, 5, R);
  d = max_diff(900, K, R, &scale);
  EXPECT(d < 1e-13 * scale, "straight tet10 K vs B'DB (degree 5): %.3g of %.3g", d, scale);
  // curved tet10 (isoparametric path): against B'DB with the same 4-point rule
  x10[3 * 8 + 0] += 0.04;
  x10[3 * 5 + 2] -= 0.03;
  EXPECT(fmbd_fe_tet_matrices(10, x10, E, nu, 1.0, 0, K, NULL, &vol) == FMBD_OK, "curved tet10");
  ke_bdb(10, x10, E, nu, 2, R);
  d = max_diff(900, K, R, &scale);
  EXPECT(d < 1e-13 * scale, "curved tet10 K vs B'DB (4 points): %.3g of %.3g", d, scale);
}

static void test_bad_elements(void) {
  double x[30], K[900], Me[100], vol;
  // inverted tet4: swap nodes 1 and 2
  memcpy(x, X4, sizeof X4);
  for (int d = 0; d < 3; d++) {
    double t = x[3 + d];
    x[3 + d] = x[6 + d];
    x[6 + d] = t;
  }
  fmbd_err_clear();
  EXPECT(fmbd_fe_tet_matrices(4, x, 1e9, 0.3, 1000, 17, K, Me, &vol) == FMBD_ERR_VALUE,
         "inverted tet4");
  EXPECT(strstr(fmbd_err_get()->msg, "element 17") && strstr(fmbd_err_get()->msg, "inverted") &&
             strstr(fmbd_err_get()->msg, "Jacobian determinant -"),
         "message: %s", fmbd_err_get()->msg);
  // flat tet4: node 3 in the plane of 0, 1, 2
  memcpy(x, X4, sizeof X4);
  for (int d = 0; d < 3; d++) x[9 + d] = (X4[d] + X4[3 + d] + X4[6 + d]) / 3;
  fmbd_err_clear();
  EXPECT(fmbd_fe_tet_matrices(4, x, 1e9, 0.3, 1000, 5, K, Me, &vol) == FMBD_ERR_VALUE, "flat tet4");
  EXPECT(strstr(fmbd_err_get()->msg, "element 5") != NULL, "message: %s", fmbd_err_get()->msg);
  // curved tet10 folded near corner 0: mid-side node 4 (edge 0-1) pushed past corner 0
  make_tet10(X4, x);
  for (int d = 0; d < 3; d++) x[12 + d] = X4[d] - 0.3 * (X4[3 + d] - X4[d]);
  fmbd_err_clear();
  EXPECT(fmbd_fe_tet_matrices(10, x, 1e9, 0.3, 1000, 42, K, Me, &vol) == FMBD_ERR_VALUE,
         "folded tet10");
  EXPECT(strstr(fmbd_err_get()->msg, "element 42") && strstr(fmbd_err_get()->msg, "tet10"),
         "message: %s", fmbd_err_get()->msg);
  // a mildly curved tet10 is fine and keeps its volume sum rule: sum Me = rho * volume
  make_tet10(X4, x);
  x[3 * 5 + 2] += 0.05;
  EXPECT(fmbd_fe_tet_matrices(10, x, 1e9, 0.3, 1000, 0, K, Me, &vol) == FMBD_OK, "curved tet10");
  double m = 0.0;
  for (int i = 0; i < 100; i++) m += Me[i];
  EXPECT(fabs(m - 1000 * vol) < 1e-12 * m, "curved tet10: sum Me %.17g, rho vol %.17g", m,
         1000 * vol);
}

static void test_beam_element(void) {
  const double x0[3] = {0.1, -0.2, 0.3}, x1[3] = {0.9, 0.4, 0.8}, v[3] = {0, 0, 1};
  const double E = 2e11, nu = 0.3, rho = 7800, A = 3e-4, Iy = 2e-8, Iz = 5e-8, J = 4e-8;
  double R[9], L, K[144], M[144], Ml[144];
  EXPECT(fmbd_fe_beam_frame(x0, x1, v, 0, R, &L) == FMBD_OK, "frame");
  // R orthonormal, right-handed, x along the axis, z in the plane of x and v
  for (int i = 0; i < 3; i++) {
    for (int j = 0; j < 3; j++) {
      double s = 0.0;
      for (int k = 0; k < 3; k++) s += R[i * 3 + k] * R[j * 3 + k];
      EXPECT(fabs(s - (i == j)) < 1e-15, "R R' (%d, %d) = %g", i, j, s);
    }
  }
  double ez_cross = R[0] * (R[4] * R[8] - R[5] * R[7]) - R[1] * (R[3] * R[8] - R[5] * R[6]) +
                    R[2] * (R[3] * R[7] - R[4] * R[6]);
  EXPECT(fabs(ez_cross - 1) < 1e-14, "det R = %g", ez_cross);
  EXPECT(fabs(R[3 + 0] * v[0] + R[3 + 1] * v[1] + R[3 + 2] * v[2]) < 1e-15,
         "local y orthogonal to v");
  EXPECT(fmbd_fe_beam_matrices(x0, x1, v, E, nu, rho, A, Iy, Iz, J, 0, K, M) == FMBD_OK, "beam");
  // rigid modes: K r = 0; r' M r = rho A L for translations, rho J L for a rotation about the axis
  // (about its centre: Euler-Bernoulli mass has no rotary inertia of the section)
  double kmax = 0.0;
  for (int i = 0; i < 144; i++) kmax = fmax(kmax, fabs(K[i]));
  for (int mode = 0; mode < 6; mode++) {
    double r[12];
    const double *xs[2] = {x0, x1};
    for (int a = 0; a < 2; a++) {
      double e[3] = {0, 0, 0};
      for (int d = 0; d < 6; d++) r[6 * a + d] = 0.0;
      if (mode < 3) {
        r[6 * a + mode] = 1.0;
      } else {
        e[mode - 3] = 1.0;
        const double *p = xs[a];
        r[6 * a + 0] = e[1] * p[2] - e[2] * p[1];
        r[6 * a + 1] = e[2] * p[0] - e[0] * p[2];
        r[6 * a + 2] = e[0] * p[1] - e[1] * p[0];
        r[6 * a + mode] = 1.0;
      }
    }
    double f = 0.0;
    for (int i = 0; i < 12; i++) {
      double s = 0.0;
      for (int j = 0; j < 12; j++) s += K[i * 12 + j] * r[j];
      f = fmax(f, fabs(s));
    }
    EXPECT(f < 1e-12 * kmax, "beam rigid mode %d: force %.3g (K max %.3g)", mode, f, kmax);
    if (mode < 3) {
      double s = 0.0;
      for (int i = 0; i < 12; i++) {
        for (int j = 0; j < 12; j++) s += r[i] * M[i * 12 + j] * r[j];
      }
      EXPECT(fabs(s - rho * A * L) < 1e-13 * rho * A * L, "beam translation mass %.17g vs %.17g", s,
             rho * A * L);
    }
  }
  // torsion about the axis through the beam: r = theta along the axis at both nodes
  {
    double r[12] = {0}, s = 0.0;
    for (int a = 0; a < 2; a++) {
      for (int d = 0; d < 3; d++) r[6 * a + 3 + d] = R[d];
    }
    for (int i = 0; i < 12; i++) {
      for (int j = 0; j < 12; j++) s += r[i] * M[i * 12 + j] * r[j];
    }
    EXPECT(fabs(s - rho * J * L) < 1e-13 * rho * J * L, "torsional mass %.17g vs rho J L %.17g", s,
           rho * J * L);
  }
  // HRZ lumped: each node m/2 per translation, torsion rho J L/2, bending rotations m L^2/78
  EXPECT(fmbd_fe_beam_lumped(x0, x1, v, rho, A, J, 0, Ml) == FMBD_OK, "lumped");
  double m = rho * A * L;
  for (int a = 0; a < 2; a++) {
    for (int d = 0; d < 3; d++) {
      EXPECT(fabs(Ml[(6 * a + d) * 13] - m / 2) < 1e-13 * m, "lumped translation %d %d", a, d);
    }
    // rotational block = R' diag(rho J L/2, m L^2/78, m L^2/78) R: check its trace
    double tr = Ml[(6 * a + 3) * 13] + Ml[(6 * a + 4) * 13] + Ml[(6 * a + 5) * 13];
    double ex = rho * J * L / 2 + 2 * m * L * L / 78;
    EXPECT(fabs(tr - ex) < 1e-13 * ex, "lumped rotational trace %.17g vs %.17g", tr, ex);
  }
  // orientation vector parallel to the axis, zero length: errors naming the element
  const double par[3] = {x1[0] - x0[0], x1[1] - x0[1], x1[2] - x0[2]};
  fmbd_err_clear();
  EXPECT(fmbd_fe_beam_matrices(x0, x1, par, E, nu, rho, A, Iy, Iz, J, 9, K, M) == FMBD_ERR_VALUE,
         "parallel v");
  EXPECT(strstr(fmbd_err_get()->msg, "beam element 9") != NULL, "message: %s", fmbd_err_get()->msg);
  EXPECT(fmbd_fe_beam_matrices(x0, x0, v, E, nu, rho, A, Iy, Iz, J, 3, K, M) == FMBD_ERR_VALUE,
         "zero length");
  EXPECT(strstr(fmbd_err_get()->msg, "beam element 3") != NULL, "message: %s", fmbd_err_get()->msg);
}

int main(void) {
  test_rules();
  test_shape();
  test_tet_element();
  test_stiffness_bdb();
  test_bad_elements();
  test_beam_element();
  TEST_EXIT();
}
