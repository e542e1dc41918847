// tests/unit/t508-mbs-linearise.c: the mechanism's equations outside the integrator
// (fmbd_mbs_linearise, for gmsolve): a double pendulum (a rigid link on a revolute joint, a
// second on a spherical joint) and a free flexible body with two modes, checked against what
// they must be independently of the integrator:
// - M is symmetric, the translational block of each body is its mass times the identity, and
//   the modal block of the flexible body is its Mff;
// - K's modal block is Kff, C's modal block the modal damping 2 zeta sqrt(Kff);
// - Q at rest is the weight (m g on the translations);
// - Cq equals central finite differences of the returned constraint values phi (h = 1e-6:
//   truncation ~1e-12, cancellation ~1e-10 of entries of order 1: compared at 1e-7);
// - the constraints hold at the initial configuration (phi ~ 0) and the model's state is left
//   unchanged; before fmbd_mbs_init the call is refused;
// - initialised to be linearised only (settings.linearise_only, gmsolve's), the model gives the
//   same linearisation bit for bit at the same positions, and refuses to step or give reactions.
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs.h"

static double get(const fmbd_csr *A, int64_t i, int64_t j) {
  return fmbd_csr_get(A, i, j);
}

static const double g[3] = {0, -9.81, 0};
static double Mff[4] = {1, 0, 0, 1}, Kff[4] = {4e4, 0, 0, 9e4};

// the model: two rigid links on a revolute and a spherical joint, a free flexible body
static fmbd_mbs *build(void) {
  fmbd_mbs *m = NULL;
  EXPECT(fmbd_mbs_create(&m) == 0, "create");
  fmbd_mbs_set_gravity(m, g);
  // link a: mass 2 about (0.5, 0, 0) on a revolute joint about z at the origin; link b: mass 1
  // about (1.3, 0, 0) on a spherical joint at (1, 0, 0); frames at the centres of mass
  double Ia[9] = {1e-3, 0, 0, 0, 0.2, 0, 0, 0, 0.2}, Ib[9] = {1e-3, 0, 0, 0, 0.1, 0, 0, 0, 0.1};
  double zero[3] = {0, 0, 0};
  fmbd_mbs_state0 sa = fmbd_mbs_state0_default(), sb = fmbd_mbs_state0_default();
  sa.position[0] = 0.5;
  sb.position[0] = 1.3;
  int a, b;
  EXPECT(fmbd_mbs_add_rigid(m, "a", 2.0, zero, Ia, &sa, &a) == 0, "rigid a");
  EXPECT(fmbd_mbs_add_rigid(m, "b", 1.0, zero, Ib, &sb, &b) == 0, "rigid b");
  // a free flexible body, two modes
  double S1[6] = {0}, XS[18] = {0}, SS[36] = {0};
  for (int k = 0; k < 2; k++) {
    for (int c = 0; c < 3; c++) SS[c + 3 * c + 9 * k + 18 * k] = 1.0 / 3;  // tr SS_kk = 1
  }
  fmbd_mbs_flex_data fd = {.nm = 2,
                           .mass = 0.5,
                           .first_moment = {0, 0, 0},
                           .second_moment = {0.01, 0, 0, 0, 0.02, 0, 0, 0, 0.03},
                           .S1 = S1,
                           .XS = XS,
                           .SS = SS,
                           .Mff = Mff,
                           .Kff = Kff,
                           .damping_ratio = 0.05};
  fmbd_mbs_state0 sf = fmbd_mbs_state0_default();
  sf.position[1] = 3.0;
  int f;
  EXPECT(fmbd_mbs_add_flex(m, "f", &fd, &sf, &f) == 0, "flex");
  int p0, p1, p2, p3;
  const double o[3] = {0, 0, 0}, k1[3] = {1, 0, 0};
  EXPECT(fmbd_mbs_add_point_world(m, FMBD_MBS_GROUND, o, &p0) == 0, "p0");
  EXPECT(fmbd_mbs_add_point_world(m, a, o, &p1) == 0, "p1");
  EXPECT(fmbd_mbs_add_point_world(m, a, k1, &p2) == 0, "p2");
  EXPECT(fmbd_mbs_add_point_world(m, b, k1, &p3) == 0, "p3");
  fmbd_mbs_joint_desc j1 = {
      .name = "pivot", .kind = FMBD_MBS_REVOLUTE, .point = {p0, p1}, .axis = {0, 0, 1}};
  fmbd_mbs_joint_desc j2 = {.name = "ball", .kind = FMBD_MBS_SPHERICAL, .point = {p2, p3}};
  int jid;
  EXPECT(fmbd_mbs_add_joint(m, &j1, &jid) == 0, "revolute");
  EXPECT(fmbd_mbs_add_joint(m, &j2, &jid) == 0, "spherical");
  return m;
}

int main(void) {
  fmbd_log_init("t508", FMBD_LOG_ERROR);
  fmbd_mbs *m = build();
  fmbd_mbs_linear L;
  EXPECT(fmbd_mbs_linearise(m, 0.0, NULL, NULL, &L) != 0, "linearise before init must fail");
  fmbd_mbs_settings s;
  fmbd_mbs_settings_defaults(&s);
  s.t_end = 1.0;
  EXPECT(fmbd_mbs_init(m, &s) == 0, "init");
  int64_t n = fmbd_mbs_ncoordinates(m);
  EXPECT(n == 7 + 7 + 9, "%lld coordinates, expected 23", (long long)n);
  double *x0 = fmbd_malloc(sizeof(double) * (size_t)n);
  memcpy(x0, fmbd_mbs_state(m), sizeof(double) * (size_t)n);
  EXPECT(fmbd_mbs_linearise(m, 0.0, NULL, NULL, &L) == 0, "linearise");
  EXPECT(L.n == n && L.nc == 5 + 3 + 3, "sizes n %lld nc %lld (5 + 3 + 3 normalisations)",
         (long long)L.n, (long long)L.nc);
  EXPECT(memcmp(x0, fmbd_mbs_state(m), sizeof(double) * (size_t)n) == 0, "state changed");
  // --- M: symmetric, mass blocks, Mff ---
  double mmax = 0;
  for (int64_t i = 0; i < n; i++) {
    for (int64_t j = 0; j < n; j++) mmax = fmax(mmax, fabs(get(L.M, i, j)));
  }
  for (int64_t i = 0; i < n; i++) {
    for (int64_t j = 0; j < n; j++) {
      EXPECT(fabs(get(L.M, i, j) - get(L.M, j, i)) <= 1e-14 * mmax, "M not symmetric at %lld %lld",
             (long long)i, (long long)j);
    }
  }
  const double mass[3] = {2.0, 1.0, 0.5};
  for (int bi = 0; bi < 3; bi++) {
    int64_t off = 7 * bi;
    for (int i = 0; i < 3; i++) {
      for (int j = 0; j < 3; j++) {
        EXPECT(fabs(get(L.M, off + i, off + j) - (i == j ? mass[bi] : 0)) <= 1e-14,
               "body %d: M translational block (%d,%d) = %g", bi, i, j, get(L.M, off + i, off + j));
      }
      // Q at rest: the weight
      EXPECT(fabs(L.Q[off + i] - mass[bi] * g[i]) <= 1e-12, "body %d: Q[%d] = %g, weight %g", bi, i,
             L.Q[off + i], mass[bi] * g[i]);
    }
  }
  for (int k = 0; k < 2; k++) {
    for (int l = 0; l < 2; l++) {
      int64_t r = 21 + k, c = 21 + l;
      EXPECT(fabs(get(L.M, r, c) - Mff[k + 2 * l]) <= 1e-14, "Mff block (%d,%d)", k, l);
      EXPECT(fabs(get(L.K, r, c) - Kff[k + 2 * l]) <= 1e-9 * Kff[3], "Kff block (%d,%d) = %g", k, l,
             get(L.K, r, c));
      double d = k == l ? 2 * 0.05 * sqrt(Kff[k + 2 * k]) : 0;
      EXPECT(fabs(get(L.C, r, c) - d) <= 1e-12 * 30, "damping block (%d,%d) = %g, expected %g", k,
             l, get(L.C, r, c), d);
    }
  }
  // --- the constraints hold at the initial configuration; Cq against finite differences ---
  double pmax = 0, cmax = 0;
  for (int64_t r = 0; r < L.nc; r++) pmax = fmax(pmax, fabs(L.phi[r]));
  EXPECT(pmax < 1e-10, "constraints violated at the initial configuration by %g", pmax);
  for (int64_t r = 0; r < L.nc; r++) {
    for (int64_t j = 0; j < n; j++) cmax = fmax(cmax, fabs(get(L.Cq, r, j)));
  }
  double *xp = fmbd_malloc(sizeof(double) * (size_t)n);
  const double h = 1e-6;
  double worst = 0;
  for (int64_t j = 0; j < n; j++) {
    fmbd_mbs_linear Lp, Lm;
    memcpy(xp, x0, sizeof(double) * (size_t)n);
    xp[j] += h;
    EXPECT(fmbd_mbs_linearise(m, 0.0, xp, NULL, &Lp) == 0, "linearise +");
    xp[j] -= 2 * h;
    EXPECT(fmbd_mbs_linearise(m, 0.0, xp, NULL, &Lm) == 0, "linearise -");
    for (int64_t r = 0; r < L.nc; r++) {
      double fd = (Lp.phi[r] - Lm.phi[r]) / (2 * h);
      worst = fmax(worst, fabs(fd - get(L.Cq, r, j)));
    }
    fmbd_mbs_linear_free(&Lp);
    fmbd_mbs_linear_free(&Lm);
  }
  EXPECT(worst <= 1e-7 * cmax, "Cq vs finite differences: %g (max entry %g)", worst, cmax);
  EXPECT(memcmp(x0, fmbd_mbs_state(m), sizeof(double) * (size_t)n) == 0,
         "state changed by evaluations at other states");
  // --- linearise_only (gmsolve's init: no initial conditions): linearised at the positions the
  // full init made consistent, the same matrices bit for bit (velocities, accelerations and
  // multipliers are not read by fmbd_mbs_linearise); stepping and joint reactions are refused ---
  fmbd_mbs *m2 = build();
  s.linearise_only = true;
  EXPECT(fmbd_mbs_init(m2, &s) == 0, "init, linearise only");
  EXPECT(fmbd_mbs_check_removed(m2, 0.0, x0) == 0, "check_removed: %s", fmbd_err_get()->msg);
  fmbd_mbs_linear L2;
  EXPECT(fmbd_mbs_linearise(m2, 0.0, x0, NULL, &L2) == 0, "linearise, linearise only");
  const fmbd_csr *A1[4] = {L.M, L.C, L.K, L.Cq}, *A2[4] = {L2.M, L2.C, L2.K, L2.Cq};
  for (int k = 0; k < 4; k++) {
    int64_t nz = A1[k]->indptr[A1[k]->nrows];
    EXPECT(A2[k]->nrows == A1[k]->nrows && A2[k]->indptr[A2[k]->nrows] == nz &&
               memcmp(A1[k]->indices, A2[k]->indices, sizeof(int64_t) * (size_t)nz) == 0 &&
               memcmp(A1[k]->data, A2[k]->data, sizeof(double) * (size_t)nz) == 0,
           "linearise only: matrix %d (M, C, K, Cq) differs", k);
  }
  EXPECT(memcmp(L.Q, L2.Q, sizeof(double) * (size_t)n) == 0, "linearise only: Q differs");
  EXPECT(memcmp(L.phi, L2.phi, sizeof(double) * (size_t)L.nc) == 0, "linearise only: phi differs");
  bool out = false;
  EXPECT(fmbd_mbs_step(m2, &out) == FMBD_ERR_VALUE, "linearise only: a step must be refused");
  double F[3], T[3];
  EXPECT(fmbd_mbs_joint_reaction(m2, 0, F, T) == FMBD_ERR_VALUE,
         "linearise only: a joint reaction must be refused");
  fmbd_mbs_linear_free(&L2);
  fmbd_mbs_destroy(&m2);
  fmbd_free(xp);
  fmbd_free(x0);
  fmbd_mbs_linear_free(&L);
  fmbd_mbs_destroy(&m);
  TEST_EXIT();
}
