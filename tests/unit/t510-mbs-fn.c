// tests/unit/t510-mbs-fn.c: the time derivatives of the drivers' and loads' functions
// (fmbd_mbs_fn_eval's dfdt and d2fdt2, which the drivers' velocity and acceleration equations
// use) against central finite differences of the returned values, for every kind: constant,
// linear, ramp (linear and smooth), sine, table, spinup; at points inside each piece and, for the
// piecewise kinds, the documented right-hand derivative just after each kink.
// SPDX-License-Identifier: MIT
//
// Tolerance: a central difference with step h has truncation error f''' h^2 / 6 and round-off
// eps |f| / h; with h = 1e-4 s on these functions (|f| <= 10, |f'''| <= (2 pi 3)^3 x 2 ~ 1.3e4)
// the first derivative is good to ~2e-5 and the second (h = 1e-3: error f'''' h^2 / 12 +
// eps |f| / h^2 ~ 4e-3 + 2e-9) to ~5e-3 absolute; a wrong factor (2 pi, 6 s(1 - s) / T, a
// missing chain-rule term) is off by O(1).
#include <math.h>

#include "check.h"
#include "fmbd_mbs.h"

static void check_fn(const char *name, const fmbd_mbs_fn *f, double t) {
  double d = 0, dd = 0;
  (void)fmbd_mbs_fn_eval(f, t, &d, &dd);
  const double h1 = 1e-4, h2 = 1e-3;
  double fd1 = (fmbd_mbs_fn_eval(f, t + h1, NULL, NULL) - fmbd_mbs_fn_eval(f, t - h1, NULL, NULL)) /
               (2 * h1);
  double fd2 = (fmbd_mbs_fn_eval(f, t + h2, NULL, NULL) - 2 * fmbd_mbs_fn_eval(f, t, NULL, NULL) +
                fmbd_mbs_fn_eval(f, t - h2, NULL, NULL)) /
               (h2 * h2);
  EXPECT(fabs(d - fd1) <= 2e-5 * fmax(1, fabs(fd1)),
         "%s at t = %g: dfdt %.9g, finite difference %.9g", name, t, d, fd1);
  EXPECT(fabs(dd - fd2) <= 5e-3 * fmax(1, fabs(fd2)),
         "%s at t = %g: d2fdt2 %.9g, finite difference %.9g", name, t, dd, fd2);
}

// right-hand derivative at a kink t0: one-sided differences from t0 (second order)
static void check_right(const char *name, const fmbd_mbs_fn *f, double t0) {
  double d = 0;
  (void)fmbd_mbs_fn_eval(f, t0, &d, NULL);
  const double h = 1e-5;
  double f0 = fmbd_mbs_fn_eval(f, t0, NULL, NULL), f1 = fmbd_mbs_fn_eval(f, t0 + h, NULL, NULL),
         f2 = fmbd_mbs_fn_eval(f, t0 + 2 * h, NULL, NULL);
  double fd = (-3 * f0 + 4 * f1 - f2) / (2 * h);
  EXPECT(fabs(d - fd) <= 1e-4 * fmax(1, fabs(fd)),
         "%s: right-hand dfdt at the kink t = %g: %.9g, %.9g", name, t0, d, fd);
}

int main(void) {
  fmbd_mbs_fn c = fmbd_mbs_fn_constant(3.5);
  fmbd_mbs_fn l = fmbd_mbs_fn_linear(0.2, -1.0, 2.5);
  fmbd_mbs_fn r = fmbd_mbs_fn_ramp(0.5, 1.0, 1.5, 4.0, false);
  fmbd_mbs_fn rs = fmbd_mbs_fn_ramp(0.5, 1.0, 1.5, 4.0, true);
  fmbd_mbs_fn s = fmbd_mbs_fn_sine(0.5, 2.0, 3.0, 0.7);
  const double tt[] = {0.0, 0.5, 1.0, 2.0}, vv[] = {0.0, 2.0, 1.0, 5.0};
  fmbd_mbs_fn tb = fmbd_mbs_fn_table(4, tt, vv);
  // Kane's spin-up from t0 = 0.5 to t1 = 1.5 (T = 1) to speed 4 from v0 = 1: |f| <= 10 and
  // |f''''| = (W/T)(2 pi/T)^3 <= 1e3 on [-1, 2.6], inside the tolerances above
  fmbd_mbs_fn su = fmbd_mbs_fn_spinup(0.5, 1.0, 1.5, 4.0);
  const double ts[] = {-1.0, 0.1, 0.37, 0.8, 1.2, 1.49, 1.7, 2.6};
  for (size_t k = 0; k < sizeof ts / sizeof ts[0]; k++) {
    double t = ts[k];
    check_fn("constant", &c, t);
    check_fn("linear", &l, t);
    check_fn("sine", &s, t);
    if (fabs(t - 0.5) > 2e-3 && fabs(t - 1.5) > 2e-3) {  // not across a kink
      check_fn("ramp", &r, t);
      check_fn("smooth ramp", &rs, t);
    }
    check_fn("spinup", &su, t);  // C2: the differences hold across t0 and t1 too
    if (fabs(t) > 2e-3 && fabs(t - 0.5) > 2e-3 && fabs(t - 1.0) > 2e-3 && fabs(t - 2.0) > 2e-3)
      check_fn("table", &tb, t);
  }
  // the smooth ramp is C1: its derivative is continuous through both ends
  check_fn("smooth ramp (C1 at its start)", &rs, 0.5 + 0.3);
  check_right("ramp", &r, 0.5);
  check_right("smooth ramp", &rs, 0.5);
  check_right("table", &tb, 0.5);
  check_right("table", &tb, 1.0);
  // spinup is C2 through both ends: the derivatives straddling t0 and t1 (h2 = 1e-3 across the
  // join: the third derivative jumps by (W/T)(2 pi/T) sin(0) = 0 there, so no kink term)
  check_fn("spinup (across t0)", &su, 0.5);
  check_fn("spinup (across t1)", &su, 1.5);
  // values at the documented places: a slip of a sign or a phase shows here
  double d, dd;
  // spinup: theta(T/2) = (W/T)[T^2/8 + (T/2pi)^2 (cos(pi) - 1)] = W T (1/8 - 1/(2 pi^2)),
  // speed W/2, acceleration 2 W/T; at t1: W T/2, W, 0 (closed form, to round-off)
  double v0 = fmbd_mbs_fn_eval(&su, 1.0, &d, &dd);
  EXPECT(fabs(v0 - (1.0 + 4.0 * (0.125 - 0.5 / (M_PI * M_PI)))) < 1e-14 && fabs(d - 2.0) < 1e-14 &&
             fabs(dd - 8.0) < 1e-13,
         "spinup at its middle: %.17g %.17g %.17g", v0, d, dd);
  v0 = fmbd_mbs_fn_eval(&su, 1.5, &d, &dd);
  EXPECT(fabs(v0 - 3.0) < 1e-14 && fabs(d - 4.0) < 1e-14 && fabs(dd) < 1e-14,
         "spinup at t1: %.17g %.17g %.17g (3, 4, 0)", v0, d, dd);
  v0 = fmbd_mbs_fn_eval(&su, 1.5 - 1e-9, &d, &dd);
  EXPECT(fabs(v0 - 3.0) < 1e-8 && fabs(d - 4.0) < 1e-8 && fabs(dd) < 1e-6,
         "spinup just before t1: %.17g %.17g %.17g (continuous)", v0, d, dd);
  v0 = fmbd_mbs_fn_eval(&su, 0.5 + 1e-4, &d, &dd);
  EXPECT(fabs(v0 - 1.0) < 1e-10 && fabs(d) < 1e-6 && fabs(dd) < 1e-5,
         "spinup just after t0: %.17g %.17g %.17g (continuous)", v0, d, dd);
  double v = fmbd_mbs_fn_eval(&s, 0.0, &d, &dd);
  EXPECT(fabs(v - (0.5 + 2.0 * sin(0.7))) < 1e-15, "sine value %.17g", v);
  EXPECT(fabs(d - 2.0 * 2 * M_PI * 3.0 * cos(0.7)) < 1e-12, "sine derivative %.17g", d);
  EXPECT(fabs(dd + 2.0 * pow(2 * M_PI * 3.0, 2) * sin(0.7)) < 1e-10, "sine second derivative %.17g",
         dd);
  v = fmbd_mbs_fn_eval(&rs, 1.0, &d, &dd);
  EXPECT(fabs(v - 2.5) < 1e-15 && fabs(d - 4.5) < 1e-12 && fabs(dd) < 1e-12,
         "smooth ramp at its middle: %.17g %.17g %.17g (2.5, 1.5 x 3 / 1, 0)", v, d, dd);
  TEST_EXIT();
}
