// tests/unit/t504-mbs-fourbar.c: a closed loop with redundant constraints: a planar four-bar
// modelled in 3-D with four revolute joints (17 independent of 20 equations); the redundant
// ones are detected at the start, named (the closing joint's out-of-plane equations),
// removed, and still hold during the motion under gravity
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs.h"

static void frame_along(const double *a, const double *b, fmbd_mbs_state0 *s, double *len) {
  double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
  double L = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  double z[3] = {0, 0, 1};
  *s = fmbd_mbs_state0_default();
  fmbd_mbs_rotation_axis_angle(z, atan2(d[1], d[0]), s->rotation);
  memcpy(s->position, a, 3 * sizeof(double));
  *len = L;
}

int main(void) {
  fmbd_log_init("t504", FMBD_LOG_ERROR);  // the WARN naming the redundant equations is expected
  // ground pivots A, D; crank AB; coupler BC; rocker DC (lengths 0.15, 0.35, 0.3)
  const double A[3] = {0, 0, 0}, D[3] = {0.4, 0, 0}, lab = 0.15, lbc = 0.35, ldc = 0.3;
  double B[3] = {lab * cos(M_PI / 3), lab * sin(M_PI / 3), 0};
  // C: intersection of circles |C - B| = lbc, |C - D| = ldc (upper solution)
  double dx = D[0] - B[0], dy = D[1] - B[1], d = hypot(dx, dy);
  double aa = (lbc * lbc - ldc * ldc + d * d) / (2 * d), hh = sqrt(lbc * lbc - aa * aa);
  double C[3] = {B[0] + aa * dx / d - hh * dy / d, B[1] + aa * dy / d + hh * dx / d, 0};
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  EXPECT(rc == 0, "create");
  const char *nm[3] = {"crank", "coupler", "rocker"};
  const double *from[3] = {A, B, D}, *to[3] = {B, C, C};
  int body[3];
  for (int i = 0; i < 3 && !rc; i++) {
    fmbd_mbs_state0 s;
    double L;
    frame_along(from[i], to[i], &s, &L);
    double com[3] = {L / 2, 0, 0}, I[9] = {1e-5, 0, 0, 0, L * L / 12, 0, 0, 0, L * L / 12};
    rc = fmbd_mbs_add_rigid(m, nm[i], 1.0, com, I, &s, &body[i]);
  }
  // joints (side 1, side 2): A ground-crank, B crank-coupler, C coupler-rocker, D rocker-ground
  const double *at[4] = {A, B, C, D};
  int side[4][2] = {{FMBD_MBS_GROUND, body[0]},
                    {body[0], body[1]},
                    {body[1], body[2]},
                    {body[2], FMBD_MBS_GROUND}};
  const char *jn[4] = {"A", "B", "C", "D"};
  int jid[4];
  for (int j = 0; j < 4 && !rc; j++) {
    int p1, p2;
    rc = fmbd_mbs_add_point_world(m, side[j][0], at[j], &p1);
    if (!rc) rc = fmbd_mbs_add_point_world(m, side[j][1], at[j], &p2);
    fmbd_mbs_joint_desc jd = {
        .name = jn[j], .kind = FMBD_MBS_REVOLUTE, .point = {p1, p2}, .axis = {0, 0, 1}};
    if (!rc) rc = fmbd_mbs_add_joint(m, &jd, &jid[j]);
  }
  EXPECT(rc == 0, "build: %s", fmbd_err_get()->msg);
  double g[3] = {0, -9.81, 0};
  fmbd_mbs_set_gravity(m, g);
  fmbd_mbs_settings s;
  fmbd_mbs_settings_defaults(&s);
  s.t_end = 1.0, s.tolerance = 1e-5;
  if (!rc) rc = fmbd_mbs_init(m, &s);
  EXPECT(rc == 0, "init: %s", fmbd_err_get()->msg);
  fmbd_mbs_stats st;
  fmbd_mbs_get_stats(m, &st);
  // 3 bodies: 18 coordinates of motion, 20 joint equations, mobility 1 -> rank 17: 3 redundant
  EXPECT(st.redundant == 3, "redundant equations: %lld, expected 3", (long long)st.redundant);
  for (int k = 0; k < st.redundant && k < 3; k++) {
    int j, eq;
    const char *text;
    fmbd_mbs_redundant(m, k, &j, &eq, &text);
    // the loop is closed by joint D (added last): its z translation and two tilt equations
    EXPECT(j == jid[3] && eq >= 3 && eq <= 5, "redundant %d: joint %d equation %d (%s)", k, j, eq,
           text);
    EXPECT(text && strstr(text, "joint 'D'"), "redundant equation not named: %s",
           text ? text : "(null)");
  }
  double th0 = 0, th1 = 0, pos = 1, vel = 1;
  if (!rc) {
    fmbd_mbs_joint_coordinate(m, jid[0], &th0, NULL);
    rc = fmbd_mbs_run(m, NULL, NULL);
    EXPECT(rc == 0, "run: %s", fmbd_err_get()->msg);
    fmbd_mbs_joint_coordinate(m, jid[0], &th1, NULL);
    fmbd_mbs_constraint_residual(m, &pos, &vel);
  }
  // the mechanism moved, and all 20 joint equations, the removed ones included, hold to the
  // Newton tolerance (1e-8 relative to the 0.4 m size: 1e-9 m; allow 1e-8)
  EXPECT(fabs(th1 - th0) > 0.05, "the crank did not move: %.3g rad", th1 - th0);
  EXPECT(pos < 1e-8, "constraint residual %.3g after the run", pos);
  // velocity-level residual: not enforced by the index-3 scheme, second order in h
  EXPECT(vel < 1e-3, "velocity constraint residual %.3g", vel);
  fmbd_mbs_destroy(&m);
  TEST_EXIT();
}
