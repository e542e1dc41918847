// common/fmbd_mbs_fn.c: functions of time of the multibody core (drivers, loads)
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"

// ============================================================================================
// functions of time
// ============================================================================================
double fmbd_mbs_fn_eval(const fmbd_mbs_fn *f, double t, double *dfdt, double *d2fdt2) {
  double v = 0, d = 0, dd = 0;
  switch (f->kind) {
    case FMBD_MBS_FN_CONSTANT:
      v = f->value;
      break;
    case FMBD_MBS_FN_LINEAR:
      v = f->v0 + f->rate * (t - f->t0);
      d = f->rate;
      break;
    case FMBD_MBS_FN_RAMP: {
      double T = f->t1 - f->t0;
      if (t < f->t0 || T <= 0) {
        v = t < f->t0 ? f->v0 : f->v1;
      } else if (t >= f->t1) {
        v = f->v1;
      } else {
        double s = (t - f->t0) / T, dv = f->v1 - f->v0;
        if (f->smooth) {
          v = f->v0 + dv * s * s * (3 - 2 * s);
          d = dv * 6 * s * (1 - s) / T;
          dd = dv * (6 - 12 * s) / (T * T);
        } else {
          v = f->v0 + dv * s;
          d = dv / T;
        }
      }
      break;
    }
    case FMBD_MBS_FN_SINE: {
      double w = 2 * M_PI * f->frequency_hz, arg = w * t + f->phase;
      v = f->offset + f->amplitude * sin(arg);
      d = f->amplitude * w * cos(arg);
      dd = -f->amplitude * w * w * sin(arg);
      break;
    }
    case FMBD_MBS_FN_TABLE: {
      int64_t n = f->n;
      if (n <= 0 || !f->t || !f->v) break;
      if (t < f->t[0]) {
        v = f->v[0];
      } else if (t >= f->t[n - 1]) {
        v = f->v[n - 1];
      } else {
        int64_t lo = 0, hi = n - 1;  // t[lo] <= t < t[hi]
        while (hi - lo > 1) {
          int64_t mid = (lo + hi) / 2;
          if (f->t[mid] <= t)
            lo = mid;
          else
            hi = mid;
        }
        double sl = (f->v[hi] - f->v[lo]) / (f->t[hi] - f->t[lo]);
        v = f->v[lo] + sl * (t - f->t[lo]);
        d = sl;
      }
      break;
    }
    case FMBD_MBS_FN_SPINUP: {
      // Kane, Ryan and Banerjee (1987), eq. of the spin-up: with tau = t - t0, T = t1 - t0,
      // W = rate: theta = (W/T) [tau^2/2 + (T/2pi)^2 (cos(2 pi tau/T) - 1)] for 0 <= tau < T,
      // W (tau - T/2) after; speed (W/T) [tau - (T/2pi) sin(2 pi tau/T)], acceleration
      // (W/T) (1 - cos(2 pi tau/T)): value, speed and acceleration continuous at 0 and T
      double T = f->t1 - f->t0, tau = t - f->t0, W = f->rate;
      if (tau < 0 || !(T > 0)) {
        v = f->v0;
      } else if (tau >= T) {
        v = f->v0 + W * (tau - T / 2);
        d = W;
      } else {
        double c = T / (2 * M_PI), a = tau / c;
        v = f->v0 + W / T * (tau * tau / 2 + c * c * (cos(a) - 1));
        d = W / T * (tau - c * sin(a));
        dd = W / T * (1 - cos(a));
      }
      break;
    }
    default:
      break;
  }
  if (dfdt) *dfdt = d;
  if (d2fdt2) *d2fdt2 = dd;
  return v;
}

fmbd_mbs_fn fmbd_mbs_fn_constant(double value) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_CONSTANT, f.value = value;
  return f;
}
fmbd_mbs_fn fmbd_mbs_fn_linear(double t0, double v0, double rate) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_LINEAR, f.t0 = t0, f.v0 = v0, f.rate = rate;
  return f;
}
fmbd_mbs_fn fmbd_mbs_fn_ramp(double t0, double v0, double t1, double v1, bool smooth) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_RAMP, f.t0 = t0, f.v0 = v0, f.t1 = t1, f.v1 = v1, f.smooth = smooth;
  return f;
}
fmbd_mbs_fn fmbd_mbs_fn_sine(double offset, double amplitude, double frequency_hz, double phase) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_SINE, f.offset = offset, f.amplitude = amplitude;
  f.frequency_hz = frequency_hz, f.phase = phase;
  return f;
}
fmbd_mbs_fn fmbd_mbs_fn_table(int64_t n, const double *t, const double *v) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_TABLE, f.n = n, f.t = t, f.v = v;
  return f;
}

fmbd_mbs_fn fmbd_mbs_fn_spinup(double t0, double v0, double t1, double speed) {
  fmbd_mbs_fn f = {0};
  f.kind = FMBD_MBS_FN_SPINUP, f.t0 = t0, f.v0 = v0, f.t1 = t1, f.rate = speed;
  return f;
}

// copy a function (table arrays owned by the copy)
int mbs_fn_copy(const fmbd_mbs_fn *src, fmbd_mbs_fn *dst, const char *what) {
  *dst = *src;
  dst->t = dst->v = NULL;
  FMBD_CHECK(src->kind >= FMBD_MBS_FN_CONSTANT && src->kind <= FMBD_MBS_FN_SPINUP, FMBD_ERR_VALUE,
             "%s: unknown function kind %d", what, src->kind);
  if (src->kind == FMBD_MBS_FN_RAMP) {
    FMBD_CHECK(src->t1 > src->t0, FMBD_ERR_VALUE, "%s: ramp needs t1 > t0", what);
  }
  if (src->kind == FMBD_MBS_FN_SPINUP) {
    FMBD_CHECK(isfinite(src->t0) && isfinite(src->v0) && isfinite(src->rate) && isfinite(src->t1) &&
                   src->t1 > src->t0,
               FMBD_ERR_VALUE, "%s: spinup needs finite t0, v0, speed and t1 > t0", what);
  }
  if (src->kind == FMBD_MBS_FN_TABLE) {
    FMBD_CHECK(src->n >= 1 && src->t && src->v, FMBD_ERR_VALUE, "%s: empty table", what);
    for (int64_t i = 1; i < src->n; i++) {
      FMBD_CHECK(src->t[i] > src->t[i - 1], FMBD_ERR_VALUE,
                 "%s: table times not increasing at point %lld", what, (long long)i);
    }
    double *t = fmbd_malloc(sizeof(double) * (size_t)src->n);
    double *v = fmbd_malloc(sizeof(double) * (size_t)src->n);
    if (!t || !v) {
      fmbd_free(t), fmbd_free(v);
      FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    }
    memcpy(t, src->t, sizeof(double) * (size_t)src->n);
    memcpy(v, src->v, sizeof(double) * (size_t)src->n);
    dst->t = t, dst->v = v;
  }
  return FMBD_OK;
}
void mbs_fn_free(fmbd_mbs_fn *f) {
  if (f->kind == FMBD_MBS_FN_TABLE) {
    fmbd_free((void *)f->t), fmbd_free((void *)f->v);
  }
  f->t = f->v = NULL;
}
