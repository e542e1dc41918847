// tests/unit/t507-mbs-sarrus.c: the overconstrained Sarrus mechanism of Cammarata (2021,
// section 3.3) with rigid links: two 3R limbs (axes along x and along y) between the fixed
// frame and a platform; 5 bodies, 6 revolute joints (30 equations), one degree of freedom,
// so one equation is redundant. The platform, falling under gravity, must move along z only
// and keep its orientation. fmbd_mbs_check_removed finds the removed equation holding at a
// consistent state and violated at a moved one; a linearise_only init finds the same redundancy.
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs.h"

// a link body from a to b: frame at a, x along b - a
static int link(fmbd_mbs *m, const char *name, const double *a, const double *b, int *id) {
  double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
  double L = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  double ex[3] = {d[0] / L, d[1] / L, d[2] / L};
  // ey: any unit normal to ex
  double t[3] = {fabs(ex[0]) < 0.9 ? 1 : 0, fabs(ex[0]) < 0.9 ? 0 : 1, 0};
  double k = t[0] * ex[0] + t[1] * ex[1] + t[2] * ex[2];
  double ey[3] = {t[0] - k * ex[0], t[1] - k * ex[1], t[2] - k * ex[2]};
  double ny = sqrt(ey[0] * ey[0] + ey[1] * ey[1] + ey[2] * ey[2]);
  for (int i = 0; i < 3; i++) ey[i] /= ny;
  double ez[3] = {ex[1] * ey[2] - ex[2] * ey[1], ex[2] * ey[0] - ex[0] * ey[2],
                  ex[0] * ey[1] - ex[1] * ey[0]};
  fmbd_mbs_state0 s = fmbd_mbs_state0_default();
  for (int i = 0; i < 3; i++) {
    s.rotation[3 * i] = ex[i], s.rotation[3 * i + 1] = ey[i], s.rotation[3 * i + 2] = ez[i];
    s.position[i] = a[i];
  }
  double com[3] = {L / 2, 0, 0}, I[9] = {1e-5, 0, 0, 0, L * L / 12, 0, 0, 0, L * L / 12};
  return fmbd_mbs_add_rigid(m, name, 1.0, com, I, &s, id);
}

static int revolute(fmbd_mbs *m, const char *name, int b1, int b2, const double *at,
                    const double *axis) {
  int p1, p2, rc;
  if ((rc = fmbd_mbs_add_point_world(m, b1, at, &p1)) ||
      (rc = fmbd_mbs_add_point_world(m, b2, at, &p2)))
    return rc;
  fmbd_mbs_joint_desc jd = {.name = name, .kind = FMBD_MBS_REVOLUTE, .point = {p1, p2}};
  memcpy(jd.axis, axis, sizeof jd.axis);
  return fmbd_mbs_add_joint(m, &jd, NULL);
}

int main(void) {
  fmbd_log_init("t507", FMBD_LOG_ERROR);
  const double h = 0.4;
  // limb 1 in the y-z plane (axes x), limb 2 in the x-z plane (axes y)
  double A1[3] = {0, -0.3, 0}, K1[3] = {0, -0.45, h / 2}, P1[3] = {0, -0.3, h};
  double A2[3] = {0.3, 0, 0}, K2[3] = {0.45, 0, h / 2}, P2[3] = {0.3, 0, h};
  double ax[3] = {1, 0, 0}, ay[3] = {0, 1, 0};
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  int l1a, l1b, l2a, l2b, plat;
  fmbd_mbs_state0 sp = fmbd_mbs_state0_default();
  sp.position[2] = h;
  double Ip[9] = {0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.02}, c0[3] = {0, 0, 0};
  rc = rc ? rc : link(m, "proximal1", A1, K1, &l1a);
  rc = rc ? rc : link(m, "distal1", K1, P1, &l1b);
  rc = rc ? rc : link(m, "proximal2", A2, K2, &l2a);
  rc = rc ? rc : link(m, "distal2", K2, P2, &l2b);
  rc = rc ? rc : fmbd_mbs_add_rigid(m, "platform", 2.0, c0, Ip, &sp, &plat);
  rc = rc ? rc : revolute(m, "g1", FMBD_MBS_GROUND, l1a, A1, ax);
  rc = rc ? rc : revolute(m, "k1", l1a, l1b, K1, ax);
  rc = rc ? rc : revolute(m, "p1", l1b, plat, P1, ax);
  rc = rc ? rc : revolute(m, "g2", FMBD_MBS_GROUND, l2a, A2, ay);
  rc = rc ? rc : revolute(m, "k2", l2a, l2b, K2, ay);
  rc = rc ? rc : revolute(m, "p2", l2b, plat, P2, ay);
  int pc;
  double pcw[3] = {0, 0, h};
  rc = rc ? rc : fmbd_mbs_add_point_world(m, plat, pcw, &pc);
  EXPECT(rc == 0, "build: %s", fmbd_err_get()->msg);
  double g[3] = {0, 0, -9.81};
  fmbd_mbs_set_gravity(m, g);
  fmbd_mbs_settings s;
  fmbd_mbs_settings_defaults(&s);
  s.t_end = 0.15, s.tolerance = 1e-5;
  if (!rc) rc = fmbd_mbs_init(m, &s);
  EXPECT(rc == 0, "init: %s", fmbd_err_get()->msg);
  fmbd_mbs_stats st;
  fmbd_mbs_get_stats(m, &st);
  // 5 bodies (30 coordinates of motion), 30 joint equations, one degree of freedom
  EXPECT(st.redundant == 1, "redundant equations: %lld, expected 1", (long long)st.redundant);
  if (!rc) rc = fmbd_mbs_run(m, NULL, NULL);
  EXPECT(rc == 0, "run: %s", fmbd_err_get()->msg);
  double x[3], R[3], A[9], pos, vel;
  fmbd_mbs_point_position(m, pc, x);
  fmbd_mbs_body_pose(m, plat, R, A);
  fmbd_mbs_constraint_residual(m, &pos, &vel);
  // the platform moved down (0.15 s under gravity, slowed by the links' inertia) ...
  EXPECT(x[2] < h - 0.02, "platform did not fall: z = %.6f", x[2]);
  // ... along z only, without turning (the mechanism's kinematics), to the Newton tolerance
  EXPECT(fabs(x[0]) < 1e-8 && fabs(x[1]) < 1e-8, "platform drifted sideways: %.3g %.3g", x[0],
         x[1]);
  double dev =
      fabs(A[0] - 1) + fabs(A[4] - 1) + fabs(A[8] - 1) + fabs(A[1]) + fabs(A[2]) + fabs(A[5]);
  EXPECT(dev < 1e-8, "platform turned: |A - 1| = %.3g", dev);
  EXPECT(pos < 1e-8, "constraint residual %.3g (all 30 equations, the redundant one included)",
         pos);
  // the removed equation holds at the consistent state; every coordinate moved by a few
  // 1e-3 (the links are 0.2-0.3 m: residuals of that order, far above 1e-8) it does not
  EXPECT(fmbd_mbs_check_removed(m, fmbd_mbs_time(m), NULL) == 0, "check_removed: %s",
         fmbd_err_get()->msg);
  {
    int64_t n = fmbd_mbs_ncoordinates(m);
    double *xp = malloc(sizeof(double) * (size_t)n), *x0 = malloc(sizeof(double) * (size_t)n);
    memcpy(x0, fmbd_mbs_state(m), sizeof(double) * (size_t)n);
    for (int64_t i = 0; i < n; i++) xp[i] = x0[i] + 1e-3 * (double)(i % 7 + 1);
    EXPECT(fmbd_mbs_check_removed(m, fmbd_mbs_time(m), xp) == FMBD_ERR_CONVERGE &&
               strstr(fmbd_err_get()->msg, "redundant"),
           "check_removed at a moved state: %s", fmbd_err_get()->msg);
    EXPECT(memcmp(x0, fmbd_mbs_state(m), sizeof(double) * (size_t)n) == 0, "state changed");
    free(xp), free(x0);
  }
  // linearise_only (gmsolve's): the same redundant equation found, nothing else done
  {
    fmbd_mbs *m2 = NULL;
    int rc2 = fmbd_mbs_create(&m2);
    int q1a, q1b, q2a, q2b, qp;
    rc2 = rc2 ? rc2 : link(m2, "proximal1", A1, K1, &q1a);
    rc2 = rc2 ? rc2 : link(m2, "distal1", K1, P1, &q1b);
    rc2 = rc2 ? rc2 : link(m2, "proximal2", A2, K2, &q2a);
    rc2 = rc2 ? rc2 : link(m2, "distal2", K2, P2, &q2b);
    rc2 = rc2 ? rc2 : fmbd_mbs_add_rigid(m2, "platform", 2.0, c0, Ip, &sp, &qp);
    rc2 = rc2 ? rc2 : revolute(m2, "g1", FMBD_MBS_GROUND, q1a, A1, ax);
    rc2 = rc2 ? rc2 : revolute(m2, "k1", q1a, q1b, K1, ax);
    rc2 = rc2 ? rc2 : revolute(m2, "p1", q1b, qp, P1, ax);
    rc2 = rc2 ? rc2 : revolute(m2, "g2", FMBD_MBS_GROUND, q2a, A2, ay);
    rc2 = rc2 ? rc2 : revolute(m2, "k2", q2a, q2b, K2, ay);
    rc2 = rc2 ? rc2 : revolute(m2, "p2", q2b, qp, P2, ay);
    s.linearise_only = true;
    rc2 = rc2 ? rc2 : fmbd_mbs_init(m2, &s);
    EXPECT(rc2 == 0, "init, linearise only: %s", fmbd_err_get()->msg);
    fmbd_mbs_stats st2;
    fmbd_mbs_get_stats(m2, &st2);
    EXPECT(st2.redundant == 1, "linearise only: %lld redundant", (long long)st2.redundant);
    EXPECT(fmbd_mbs_check_removed(m2, 0.0, NULL) == 0, "check_removed (linearise only): %s",
           fmbd_err_get()->msg);
    fmbd_mbs_destroy(&m2);
  }
  fmbd_mbs_get_stats(m, &st);
  if (getenv("FMBD_TEST_VERBOSE"))
    fprintf(stderr, "t507: z %.6f, redundant %lld, residual %.3g, steps %lld\n", x[2],
            (long long)st.redundant, pos, (long long)st.steps);
  fmbd_mbs_destroy(&m);
  TEST_EXIT();
}
