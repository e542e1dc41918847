// tests/unit/t202-fe-beam.c: assembled Euler-Bernoulli beams on a skew line: cantilever and
// free-free bending (both planes), torsion and axial frequencies against closed form
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

// 10 elements: the bending discretisation error (~1e-6) stays far above the rounding of the dense
// eigensolver (~eps lambda_max / lambda_1 ~ 4e-9 here); at 40 elements it would not (the
// cantilever's 3e-9 is below the 4e-7 rounding of lambda_max ~ 1e11)
#define NEL 10
static const double E = 2.1e11, NU = 0.3, RHO = 7850;
// rectangle 0.02 (local y) x 0.01 (local z): Iy = b h^3/12, Iz = h b^3/12; J any positive value
// (torsion frequencies do not depend on it: stiffness G J, inertia rho J)
static const double A = 2e-4, IY = 0.02 * 1e-6 / 12, IZ = 0.01 * 8e-6 / 12, J = 4.58e-9;

// omega (rad/s) of every mode, and its class: 0 axial, 1 bending in local x-y (v, Iz),
// 2 bending in local x-z (w, Iy), 3 torsion: the largest share of the mode's amplitude
// (axial, local y, local z translations; axial rotation times L), -1 if no share exceeds 0.99
static double *frequencies(const fmbd_fe_body *b, const double R[9], double L, int **cls) {
  int64_t n = b->ndof;
  double *K = csr_dense(b->K), *M = csr_dense(b->M), *w = fmbd_malloc(n * sizeof *w);
  *cls = fmbd_malloc(n * sizeof **cls);
  EXPECT(fmbd_dense_sygv(n, K, M, w) == FMBD_OK, "sygv");
  for (int64_t k = 0; k < n; k++) {
    w[k] = w[k] > 0 ? sqrt(w[k]) : -sqrt(-w[k]);
    double share[4] = {0, 0, 0, 0}, tot = 0.0;
    for (int64_t i = 0; i < n; i += 6) {
      // K holds the eigenvectors; dofs of a free node come in groups of 6 (ux uy uz rx ry rz)
      const double *u = K + k * n + i, *t = u + 3;
      double ax = 0, y = 0, z = 0, ra = 0;
      for (int d = 0; d < 3; d++) {
        ax += u[d] * R[d];
        y += u[d] * R[3 + d];
        z += u[d] * R[6 + d];
        ra += t[d] * R[d] * L;
      }
      share[0] += ax * ax;
      share[1] += y * y;
      share[2] += z * z;
      share[3] += ra * ra;
    }
    for (int c = 0; c < 4; c++) tot += share[c];
    (*cls)[k] = -1;
    for (int c = 0; c < 4; c++) {
      if (share[c] > 0.99 * tot) (*cls)[k] = c;
    }
  }
  fmbd_free(K);
  fmbd_free(M);
  return w;
}

// discrete frequency of a uniform mesh of linear bar elements with consistent mass, for the
// wavenumber k (exact for the discrete system: cos/sin(k x_j) are its eigenvectors):
// omega_h^2 = (6 c^2 / h^2) (1 - cos kh) / (2 + cos kh)
static double bar_discrete(double c, double h, double k) {
  return sqrt(6 * c * c / (h * h) * (1 - cos(k * h)) / (2 + cos(k * h)));
}

static void run(bool cantilever, bool lumped) {
  const double p0[3] = {0.1, 0.2, -0.3}, dir[3] = {1.0 / 3, 2.0 / 3, 2.0 / 3}, L = 1.2;
  const double p1[3] = {p0[0] + L * dir[0], p0[1] + L * dir[1], p0[2] + L * dir[2]};
  const char *what = cantilever ? (lumped ? "cantilever lumped" : "cantilever") : "free-free";
  fmbd_mesh mesh;
  beam_mesh(&mesh, p0, p1, NEL);
  fmbd_fe_opts o;
  fmbd_fe_opts_defaults(&o);
  o.E = E;
  o.nu = NU;
  o.rho = RHO;
  o.area = A;
  o.Iy = IY;
  o.Iz = IZ;
  o.J = J;
  o.orientation[0] = 1.0;  // local z in the plane of the axis and global X
  o.mass = lumped ? FMBD_FE_MASS_LUMPED : FMBD_FE_MASS_CONSISTENT;
  const char *clamps[1] = {"end0"};
  if (cantilever) {
    o.nclamps = 1;
    o.clamps = clamps;
  }
  fmbd_fe_body *b = NULL;
  int rc = fmbd_fe_assemble(&mesh, &o, &b);
  EXPECT(rc == FMBD_OK, "%s: assemble: %s", what, fmbd_err_get()->msg);
  if (rc) {
    fmbd_mesh_destroy(&mesh);
    return;
  }
  EXPECT(b->ndof == 6 * (NEL + 1) - (cantilever ? 6 : 0), "%s: %lld dofs", what,
         (long long)b->ndof);
  const double m = RHO * A * L;
  EXPECT(fabs(b->mass - m) < 1e-13 * m, "%s: mass %.17g vs rho A L %.17g", what, b->mass, m);
  EXPECT(fabs(b->volume - A * L) < 1e-13 * A * L, "%s: volume", what);
  // inertia about the centre: m L^2/12 (I - d d') + rho J L d d' (Euler-Bernoulli: no rotary
  // inertia of the section in bending), exact for the cubic/linear element polynomials
  for (int i = 0; i < 3; i++) {
    EXPECT(fabs(b->center_of_mass[i] - 0.5 * (p0[i] + p1[i])) < 1e-14, "%s: centre of mass", what);
    for (int j = 0; j < 3; j++) {
      double ex = m * L * L / 12 * ((i == j) - dir[i] * dir[j]) + RHO * J * L * dir[i] * dir[j];
      EXPECT(fabs(b->inertia[i * 3 + j] - ex) < 1e-12 * m * L * L / 12,
             "%s: inertia[%d][%d] %.17g vs %.17g", what, i, j, b->inertia[i * 3 + j], ex);
    }
  }
  double nm = 0.0;
  for (int64_t p = 0; p < b->nnodes; p++) nm += b->node_mass[p];
  EXPECT(fabs(nm - m) < 1e-13 * m, "%s: HRZ node masses %.17g vs %.17g", what, nm, m);
  double R[9], Lb;
  EXPECT(fmbd_fe_beam_frame(p0, p1, o.orientation, 0, R, &Lb) == FMBD_OK, "frame");
  int *cls = NULL;
  double *w = frequencies(b, R, L, &cls);
  int64_t n = b->ndof;
  const double G = E / (2 * (1 + NU)), h = L / NEL, ca = sqrt(E / RHO), ct = sqrt(G / RHO);
  // Euler-Bernoulli: omega = (beta L)^2 sqrt(E I / (rho A L^4)); cantilever beta L = 1.8751040687,
  // free-free beta L = 4.7300407449 (Blevins, Formulas for natural frequency, table 8-1)
  const double bl = cantilever ? 1.8751040687119611 : 4.730040744862704;
  const double kax = cantilever ? M_PI / (2 * L) : M_PI / L;  // first axial/torsion wavenumber
  struct {
    const char *name;
    int cls;
    double exact, discrete;
  } cases[4] = {
      {"bending x-z (Iy)", 2, bl * bl / (L * L) * sqrt(E * IY / (RHO * A)), 0},
      {"bending x-y (Iz)", 1, bl * bl / (L * L) * sqrt(E * IZ / (RHO * A)), 0},
      {"axial", 0, kax * ca, bar_discrete(ca, h, kax)},
      {"torsion", 3, kax * ct, bar_discrete(ct, h, kax)},
  };
  // rigid-body modes: |omega| below 1e-3 of the first flexible frequency (rounding puts them
  // near sqrt(eps lambda_max) ~ 1e-2 rad/s; the first flexible one is 36 rad/s here)
  int nz = 0;
  for (int64_t i = 0; i < n; i++) nz += fabs(w[i]) < 1e-3 * cases[0].exact;
  EXPECT(nz == (cantilever ? 0 : 6), "%s: %d rigid-body modes", what, nz);
  const double lmax = w[n - 1] * w[n - 1];
  for (int k = 0; k < 4; k++) {
    double got = -1.0;
    for (int64_t i = 0; i < n && got < 0; i++) {
      if (cls[i] == cases[k].cls && fabs(w[i]) >= 1e-3 * cases[0].exact) got = w[i];
    }
    EXPECT(got > 0, "%s: no %s mode found", what, cases[k].name);
    // rounding of the dense eigenvalue: ~eps lambda_max absolute, i.e. eps lambda_max / (2 omega^2)
    // relative in omega; 50 times that is allowed on top of the discretisation error
    const double round = 50 * 2.2e-16 * lmax / (2 * got * got);
    double err = got / cases[k].exact - 1;
    if (k < 2) {
      if (!lumped) {
        // cubic Hermite elements with consistent mass: Rayleigh-Ritz from above, error
        // (beta h)^4 / 1440 to leading order (measured: 3.4e-9 cantilever, 1.4e-7 free-free
        // at 40 elements, ratio 16 per halving); allowed (beta h)^4 / 1000
        double bh = bl * h / L, tol = pow(bh, 4) / 1000 + round;
        EXPECT(err > -round && err < tol,
               "%s %s: %.10g rad/s vs %.10g: relative error %.3g, allowed (0, %.3g)", what,
               cases[k].name, got, cases[k].exact, err, tol);
      } else {
        // HRZ lumped mass: O(h^2) error from below (measured -0.15 (beta h)^2 = -5e-3 at 10
        // elements); allowed (beta h)^2 / 4
        double bh = bl * h / L;
        EXPECT(err < round && fabs(err) < bh * bh / 4, "%s %s: relative error %.3g, allowed %.3g",
               what, cases[k].name, err, bh * bh / 4);
      }
    } else if (!lumped) {
      // linear elements with consistent mass: the discrete value is exact to rounding (1e-10);
      // the continuum one is approached from above as (kh)^2/24
      double errd = got / cases[k].discrete - 1, kh = kax * h;
      EXPECT(fabs(errd) < 1e-10 + round, "%s %s: %.12g vs discrete %.12g (%.3g)", what,
             cases[k].name, got, cases[k].discrete, errd);
      EXPECT(err > 0 && err < 1.1 * kh * kh / 24, "%s %s: continuum error %.3g, (kh)^2/24 = %.3g",
             what, cases[k].name, err, kh * kh / 24);
    } else {
      // lumped linear bar: omega_h = (2c/h) sin(kh/2), from below
      double dl = 2 * (k == 2 ? ca : ct) / h * sin(kax * h / 2);
      EXPECT(fabs(got / dl - 1) < 1e-10 + round, "%s %s: %.12g vs lumped discrete %.12g", what,
             cases[k].name, got, dl);
    }
  }
  // the first flexible mode is the weaker bending plane (Iy < Iz)
  double w1 = w[cantilever ? 0 : 6];
  EXPECT(fabs(w1 / cases[0].exact - 1) < 1e-2,
         "%s: lowest flexible mode %.6g, expected bending x-z %.6g", what, w1, cases[0].exact);
  fmbd_free(w);
  fmbd_free(cls);
  fmbd_fe_body_destroy(&b);
  fmbd_mesh_destroy(&mesh);
}

int main(void) {
  run(true, false);
  run(false, false);
  run(true, true);
  TEST_EXIT();
}
