// tests/unit/t5_flex.h: a modal flexible body with random invariants, built in the multibody
// unit tests (t506, t511)
// SPDX-License-Identifier: MIT
//
// t5_invariants: the invariants of point masses with given modes. add_random_flex: nm (<=
// T5_NM_MAX) random modes over a cloud of 12 point masses of 0.3 kg; its invariants (S1, XS, SS,
// Mff) summed over the points, Kff = diag(kdiag (k + 1)), 2 % modal damping; turned by 0.7 + seed %
// 7 rad about (0.3, -0.5, 0.8); with wscale != 0 an initial angular velocity of components wscale *
// urand. Arot (may be NULL): the rotation (row-major).
#ifndef T5_FLEX_H
#define T5_FLEX_H

#include <string.h>

#include "fmbd_mbs.h"

enum { T5_NP = 12, T5_NM_MAX = 8 };

static double urand(unsigned *s) {
  *s = *s * 1103515245u + 12345u;
  return ((*s >> 8) & 0xffff) / 65535.0 - 0.5;
}

// the invariants of NP point masses of mi kg at X (3 NP) with the nm modes Ph (Ph[3 NP k + 3 p
// + a]: component a of mode k at point p): mass, first and second moments, S1, XS, SS, Mff
typedef struct t5_inv {
  double mass, c[3], J[9];
  double S1[3 * T5_NM_MAX], XS[9 * T5_NM_MAX], SS[9 * T5_NM_MAX * T5_NM_MAX],
      Mff[T5_NM_MAX * T5_NM_MAX];
} t5_inv;
static inline void t5_invariants(int np, const double *X, double mi, const double *Ph, int nm,
                                 t5_inv *v) {
  memset(v, 0, sizeof *v);
  for (int p = 0; p < np; p++) {
    const double *x = X + 3 * p;
    v->mass += mi;
    for (int a = 0; a < 3; a++) {
      v->c[a] += mi * x[a];
      for (int b = 0; b < 3; b++) v->J[a + 3 * b] += mi * x[a] * x[b];
    }
    for (int k = 0; k < nm; k++) {
      const double *pk = Ph + 3 * np * k + 3 * p;
      for (int a = 0; a < 3; a++) {
        v->S1[a + 3 * k] += mi * pk[a];
        for (int b = 0; b < 3; b++) v->XS[a + 3 * b + 9 * k] += mi * x[a] * pk[b];
      }
      for (int l = 0; l < nm; l++) {
        const double *pl = Ph + 3 * np * l + 3 * p;
        for (int a = 0; a < 3; a++)
          for (int b = 0; b < 3; b++) v->SS[a + 3 * b + 9 * k + 9 * nm * l] += mi * pk[a] * pl[b];
        v->Mff[k + nm * l] += mi * (pk[0] * pl[0] + pk[1] * pl[1] + pk[2] * pl[2]);
      }
    }
  }
}

static inline int add_random_flex(fmbd_mbs *m, const char *name, int nm, unsigned seed,
                                  const double *pos, double kdiag, double wscale, double *Arot,
                                  int *id) {
  enum { NP = T5_NP, NMX = T5_NM_MAX };
  double X[3 * NP], Ph[3 * NP * NMX];
  static t5_inv v;
  static double Kff[NMX * NMX];
  memset(Kff, 0, sizeof Kff);
  for (int i = 0; i < 3 * NP; i++) X[i] = 0.4 * urand(&seed) + (i % 3 == 0 ? 0.2 : 0);
  for (int i = 0; i < 3 * NP * nm; i++) Ph[i] = urand(&seed);
  t5_invariants(NP, X, 0.3, Ph, nm, &v);
  for (int k = 0; k < nm; k++) Kff[k + nm * k] = kdiag * (k + 1);
  fmbd_mbs_flex_data d = {.nm = nm,
                          .mass = v.mass,
                          .S1 = v.S1,
                          .XS = v.XS,
                          .SS = v.SS,
                          .Mff = v.Mff,
                          .Kff = Kff,
                          .damping_ratio = 0.02};
  memcpy(d.first_moment, v.c, sizeof v.c);
  memcpy(d.second_moment, v.J, sizeof v.J);
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  double ax[3] = {0.3, -0.5, 0.8};
  fmbd_mbs_rotation_axis_angle(ax, 0.7 + seed % 7, s0.rotation);
  if (Arot) memcpy(Arot, s0.rotation, 9 * sizeof(double));
  memcpy(s0.position, pos, 3 * sizeof(double));
  if (wscale != 0) {
    for (int a = 0; a < 3; a++) s0.angular_velocity[a] = wscale * urand(&seed);
  }
  return fmbd_mbs_add_flex(m, name, &d, &s0, id);
}

#endif
