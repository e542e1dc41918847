// tests/unit/t500-mbs-pendulum.c: rigid compound pendulum on a revolute joint: period at finite
// amplitude against the exact elliptic-integral value; energy error of generalized-alpha with
// rho_inf = 1 shrinking at second order as the step halves; variable steps
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs.h"

static const double G0 = 9.81, LEN = 1.0, MASS = 2.0, RAD = 0.01;

// complete elliptic integral of the first kind K(k) = pi / (2 AGM(1, sqrt(1 - k^2)))
static double ellipk(double k) {
  double a = 1, b = sqrt(1 - k * k);
  for (int i = 0; i < 40 && fabs(a - b) > 1e-16 * a; i++) {
    double an = 0.5 * (a + b);
    b = sqrt(a * b);
    a = an;
  }
  return M_PI / (2 * a);
}

typedef struct run {
  fmbd_mbs *m;
  int tip;
  double th_prev, t_prev, thd_prev;
  int ncross;
  double tcross[8];
  double E0, dEmax;
} run;

static double angle(const fmbd_mbs *m, int tip, double *rate) {
  double x[3], v[3];
  fmbd_mbs_point_position(m, tip, x);
  fmbd_mbs_point_velocity(m, tip, v);
  double r2 = x[0] * x[0] + x[1] * x[1];
  if (rate) *rate = (-x[1] * v[0] + x[0] * v[1]) / r2;
  return atan2(x[0], -x[1]);
}

static int cb(fmbd_mbs *m, bool out, void *user) {
  run *r = user;
  double thd, th = angle(m, r->tip, &thd), t = fmbd_mbs_time(m);
  // upward zero crossing: cubic Hermite interpolation between the two states
  if (r->th_prev < 0 && th >= 0 && r->ncross < 8) {
    double h = t - r->t_prev, lo = 0, hi = 1;
    for (int it = 0; it < 60; it++) {
      double s = 0.5 * (lo + hi);
      double h00 = 2 * s * s * s - 3 * s * s + 1, h10 = s * s * s - 2 * s * s + s;
      double h01 = -2 * s * s * s + 3 * s * s, h11 = s * s * s - s * s;
      double v = h00 * r->th_prev + h10 * h * r->thd_prev + h01 * th + h11 * h * thd;
      if (v < 0)
        lo = s;
      else
        hi = s;
    }
    r->tcross[r->ncross++] = r->t_prev + 0.5 * (lo + hi) * h;
  }
  r->th_prev = th, r->thd_prev = thd, r->t_prev = t;
  double T, V, U;
  fmbd_mbs_energy(m, &T, &V, &U);
  double dE = fabs(T + V + U - r->E0);
  if (dE > r->dEmax) r->dEmax = dE;
  (void)out;
  return 0;
}

// build and run; returns measured period (from the first two upward crossings) and energy error
static int pendulum(double th0, const fmbd_mbs_settings *s, double *period, double *dE,
                    fmbd_mbs_stats *st) {
  run r;
  memset(&r, 0, sizeof r);
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  if (rc) return rc;
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  double z[3] = {0, 0, 1};
  fmbd_mbs_rotation_axis_angle(z, th0 - M_PI / 2, s0.rotation);  // body x along the rod
  double com[3] = {LEN / 2, 0, 0};
  double Ic[9] = {MASS * RAD * RAD / 2, 0, 0, 0, MASS * LEN * LEN / 12, 0, 0, 0,
                  MASS * LEN * LEN / 12};
  int body, pg, pb, tip, j;
  double o[3] = {0, 0, 0}, xt[3] = {LEN, 0, 0};
  fmbd_mbs_joint_desc jd = {.name = "hinge", .kind = FMBD_MBS_REVOLUTE, .axis = {0, 0, 1}};
  if ((rc = fmbd_mbs_add_rigid(m, "rod", MASS, com, Ic, &s0, &body)) ||
      (rc = fmbd_mbs_add_point(m, FMBD_MBS_GROUND, o, NULL, NULL, &pg)) ||
      (rc = fmbd_mbs_add_point(m, body, o, NULL, NULL, &pb)) ||
      (rc = fmbd_mbs_add_point(m, body, xt, NULL, NULL, &tip)))
    goto done;
  jd.point[0] = pg, jd.point[1] = pb;
  if ((rc = fmbd_mbs_add_joint(m, &jd, &j))) goto done;
  double g[3] = {0, -G0, 0};
  fmbd_mbs_set_gravity(m, g);
  if ((rc = fmbd_mbs_init(m, s))) goto done;
  r.m = m, r.tip = tip;
  r.th_prev = angle(m, tip, &r.thd_prev);
  double T, V, U;
  fmbd_mbs_energy(m, &T, &V, &U);
  r.E0 = T + V + U;
  if ((rc = fmbd_mbs_run(m, cb, &r))) goto done;
  *period = r.ncross >= 2 ? r.tcross[1] - r.tcross[0] : NAN;
  *dE = r.dEmax / fabs(MASS * G0 * LEN / 2);  // relative to m g L/2
  fmbd_mbs_get_stats(m, st);
done:
  fmbd_mbs_destroy(&m);
  return rc;
}

int main(void) {
  fmbd_log_init("t5", FMBD_LOG_WARN);
  const double th0 = 2.0;  // rad: large amplitude, K(k) far from pi/2
  // I_O = m L^2/12 + m (L/2)^2 = m L^2/3 about the hinge (z): w0^2 = m g (L/2) / I_O
  const double w0 = sqrt(3 * G0 / (2 * LEN));
  const double Texact = 4 * ellipk(sin(th0 / 2)) / w0;
  fmbd_mbs_settings s;
  fmbd_mbs_stats st;
  // --- fixed steps, rho_inf = 1: period ---
  fmbd_mbs_settings_defaults(&s);
  s.rho_inf = 1, s.fixed = true, s.step = 1e-3, s.t_end = 2.6 * Texact;
  double P, dE;
  int rc = pendulum(th0, &s, &P, &dE, &st);
  EXPECT(rc == 0, "fixed-step run failed: %s", fmbd_err_get()->msg);
  // trapezoidal-type generalized alpha (rho_inf = 1) has a relative period error of about
  // (w h)^2 / 12 for a linear oscillator; the largest local frequency here is w0, so
  // (w0 h)^2 / 12 = 1.2e-6; allow 5e-6 (crossing interpolation is O(h^3) on top)
  double tolP = 4 * (w0 * s.step) * (w0 * s.step) / 12 + 1e-7;
  EXPECT(fabs(P / Texact - 1) < tolP, "period %.9f s, exact %.9f s, rel. error %.3g > %.3g", P,
         Texact, P / Texact - 1, tolP);
  // --- energy error order with rho_inf = 1 ---
  double e[3];
  double hs[3] = {4e-3, 2e-3, 1e-3};
  // the Newton tolerance (default 1e-8) bounds the iteration error in accelerations too
  // (fmbd_mbs.h, NEWTON): with rho_inf = 1 nothing damps errors left in the algebraic
  // directions, and a looser bound shows up as an h-independent energy error floor
  s.newton_tol = 1e-8;
  for (int i = 0; i < 3; i++) {
    s.step = hs[i], s.t_end = 1.2 * Texact;
    rc = pendulum(th0, &s, &P, &e[i], &st);
    EXPECT(rc == 0, "energy run h = %g failed: %s", hs[i], fmbd_err_get()->msg);
  }
  // generalized alpha is second-order accurate: the energy error (a smooth function of the
  // solution error) scales with h^2; measured order log2(e(h)/e(h/2)) must lie in [1.8, 2.2]
  // (the asymptotic range: the error ratio of an O(h^2) quantity with an O(h^3) remainder at
  // w0 h <= 0.015)
  for (int i = 0; i < 2; i++) {
    double order = log2(e[i] / e[i + 1]);
    EXPECT(order > 1.8 && order < 2.2,
           "energy error order %.3f between h = %g (%.3g) and %g (%.3g)", order, hs[i], e[i],
           hs[i + 1], e[i + 1]);
  }
  // energy error itself small: O((w0 h)^2) relative to m g L/2
  EXPECT(e[2] < 1e-4, "energy error %.3g at h = 1e-3", e[2]);
  // --- variable steps, default rho_inf ---
  fmbd_mbs_settings_defaults(&s);
  s.t_end = 2.6 * Texact, s.tolerance = 1e-6, s.max_step = 1e-2;
  rc = pendulum(th0, &s, &P, &dE, &st);
  EXPECT(rc == 0, "variable-step run failed: %s", fmbd_err_get()->msg);
  // local error tolerance 1e-6 relative on positions of size 1 per step, ~1e3 steps: the period
  // is expected within about 1e-4 relative
  EXPECT(fabs(P / Texact - 1) < 1e-4,
         "variable steps: period %.9f s, exact %.9f s, rel. error %.3g", P, Texact, P / Texact - 1);
  EXPECT(st.steps > 10 && st.steps < 20000, "variable steps: %lld steps", (long long)st.steps);
  if (getenv("FMBD_TEST_VERBOSE"))
    fprintf(stderr,
            "t500: fixed P/T-1 tested; variable: P/T-1 = %.3g, %lld steps, %lld rejected, %lld "
            "newton, %lld factor, energy err %.3g, orders e = %.3g %.3g %.3g\n",
            P / Texact - 1, (long long)st.steps, (long long)st.rejected,
            (long long)st.newton_iterations, (long long)st.factorizations, dE, e[0], e[1], e[2]);
  TEST_EXIT();
}
