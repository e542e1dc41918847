// tests/unit/t502-mbs-cantilever.c: a flexible cantilever (one reduced modal body clamped to
// ground with a fixed joint) built in the test from a small Euler-Bernoulli FE beam (lumped
// masses, rotations condensed, clamped modes by fmbd_dense_sygv): static tip deflection under
// a tip load against the FE static solution (= P L^3 / 3 EI); free oscillation at the first
// modal frequency
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_dense.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs.h"

// steel beam along x, square 20 mm section
static const double LEN = 1.0, EE = 2.1e11, RHO = 7800, HS = 0.02;
#define NE 8         // elements; nodes 0..NE, node 0 clamped
#define NT (3 * NE)  // free translations (ux uy uz per free node)
#define NR (2 * NE)  // free rotations (th_y th_z), condensed

typedef struct beam {
  double Kc[NT * NT];   // condensed stiffness on the translations (col-major)
  double mass[NE + 1];  // lumped node masses
  double x[NE + 1];
  double w2[NT];        // eigenvalues, ascending
  double Phi[NT * NT];  // mass-normalised modes (col-major)
} beam;

// element stiffness of a 2-node Euler-Bernoulli beam in one plane, dofs (v1, t1, v2, t2)
static void eb(double EI, double l, double k[16]) {
  double c = EI / (l * l * l);
  double v[16] = {12,  6 * l,  -12, 6 * l,  6 * l, 4 * l * l, -6 * l, 2 * l * l,
                  -12, -6 * l, 12,  -6 * l, 6 * l, 2 * l * l, -6 * l, 4 * l * l};
  for (int i = 0; i < 16; i++) k[i] = c * v[i];
}

static int build_beam(beam *B) {
  const double A = HS * HS, I = HS * HS * HS * HS / 12, le = LEN / NE;
  // full free-dof stiffness: translations t(node, a) = 3 (node - 1) + a, rotations
  // r(node, b) = NT + 2 (node - 1) + b (b = 0: th_y, 1: th_z)
  const int n = NT + NR;
  double *K = fmbd_calloc((size_t)(n * n), sizeof(double));
  if (!K) return FMBD_ERR_NOMEM;
  for (int e = 0; e < NE; e++) {
    int nd[2] = {e, e + 1};
    // axial
    double ka = EE * A / le;
    // bending in x-y: (uy, th_z); in x-z: (uz, -th_y) (sign absorbed: same matrix with th_y)
    double kb[16];
    eb(EE * I, le, kb);
    int dof[3][4];
    for (int s = 0; s < 2; s++) {
      int node = nd[s];
      bool fr = node > 0;
      dof[0][s] = fr ? 3 * (node - 1) + 0 : -1;               // ux
      dof[1][2 * s] = fr ? 3 * (node - 1) + 1 : -1;           // uy
      dof[1][2 * s + 1] = fr ? NT + 2 * (node - 1) + 1 : -1;  // th_z
      dof[2][2 * s] = fr ? 3 * (node - 1) + 2 : -1;           // uz
      dof[2][2 * s + 1] = fr ? NT + 2 * (node - 1) + 0 : -1;  // -th_y
    }
    int ax[2] = {dof[0][0], dof[0][1]};
    double kax[4] = {ka, -ka, -ka, ka};
    for (int i = 0; i < 2; i++)
      for (int j = 0; j < 2; j++)
        if (ax[i] >= 0 && ax[j] >= 0) K[ax[i] + n * ax[j]] += kax[i + 2 * j];
    for (int p = 1; p < 3; p++)
      for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
          if (dof[p][i] >= 0 && dof[p][j] >= 0) K[dof[p][i] + n * dof[p][j]] += kb[i + 4 * j];
  }
  // condense rotations: Kc = Ktt - Ktr Krr^-1 Krt
  double *Krr = fmbd_malloc(sizeof(double) * NR * NR), *X = fmbd_malloc(sizeof(double) * NR * NT);
  int rc = (Krr && X) ? 0 : FMBD_ERR_NOMEM;
  if (!rc) {
    for (int i = 0; i < NR; i++)
      for (int j = 0; j < NR; j++) Krr[i + NR * j] = K[(NT + i) + n * (NT + j)];
    for (int i = 0; i < NR; i++)
      for (int j = 0; j < NT; j++) X[i + NR * j] = K[(NT + i) + n * j];
    rc = fmbd_dense_lu_solve(NR, Krr, NT, X, NR);  // X = Krr^-1 Krt
  }
  if (!rc) {
    for (int i = 0; i < NT; i++)
      for (int j = 0; j < NT; j++) {
        double s = K[i + n * j];
        for (int k = 0; k < NR; k++) s -= K[i + n * (NT + k)] * X[k + NR * j];
        B->Kc[i + NT * j] = s;
      }
    for (int i = 0; i <= NE; i++) {
      B->x[i] = i * le;
      B->mass[i] = RHO * A * le * ((i == 0 || i == NE) ? 0.5 : 1.0);
    }
    // eigenproblem Kc phi = w2 M phi
    double *Ms = fmbd_calloc(NT * NT, sizeof(double));
    if (!Ms)
      rc = FMBD_ERR_NOMEM;
    else {
      for (int i = 1; i <= NE; i++)
        for (int a = 0; a < 3; a++) Ms[(3 * (i - 1) + a) * (NT + 1)] = B->mass[i];
      memcpy(B->Phi, B->Kc, sizeof B->Phi);
      rc = fmbd_dense_sygv(NT, B->Phi, Ms, B->w2);
      fmbd_free(Ms);
    }
  }
  fmbd_free(K), fmbd_free(Krr), fmbd_free(X);
  return rc;
}

// invariants of the first nm modes (point masses at the nodes; clamped node 0 included)
typedef struct inv {
  int nm;
  double S1[3 * NT], XS[9 * NT], SS[9 * NT * NT], Mff[NT * NT], Kff[NT * NT];
  double J[9], c[3], mass;
} inv;
static void invariants(const beam *B, int nm, inv *v) {
  memset(v, 0, sizeof *v);
  v->nm = nm;
  for (int i = 0; i <= NE; i++) {
    double x[3] = {B->x[i], 0, 0}, mi = B->mass[i];
    v->mass += mi;
    for (int a = 0; a < 3; a++) {
      v->c[a] += mi * x[a];
      for (int b = 0; b < 3; b++) v->J[a + 3 * b] += mi * x[a] * x[b];
    }
    if (i == 0) continue;
    for (int k = 0; k < nm; k++) {
      const double *pk = B->Phi + NT * k + 3 * (i - 1);
      for (int a = 0; a < 3; a++) {
        v->S1[a + 3 * k] += mi * pk[a];
        for (int b = 0; b < 3; b++) v->XS[a + 3 * b + 9 * k] += mi * x[a] * pk[b];
      }
      for (int l = 0; l < nm; l++) {
        const double *pl = B->Phi + NT * l + 3 * (i - 1);
        for (int a = 0; a < 3; a++)
          for (int b = 0; b < 3; b++) v->SS[a + 3 * b + 9 * k + 9 * nm * l] += mi * pk[a] * pl[b];
        v->Mff[k + nm * l] += mi * (pk[0] * pl[0] + pk[1] * pl[1] + pk[2] * pl[2]);
      }
    }
  }
  for (int k = 0; k < nm; k++) v->Kff[k + nm * k] = B->w2[k];
}

// cantilever system: body frame at the clamp, fixed joint to ground, tip point
static int build_sys(const beam *B, const inv *v, double zeta, const double *q0, double P,
                     fmbd_mbs **out, int *tip) {
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  if (rc) return rc;
  fmbd_mbs_flex_data d = {.nm = v->nm,
                          .mass = v->mass,
                          .S1 = v->S1,
                          .XS = v->XS,
                          .SS = v->SS,
                          .Mff = v->Mff,
                          .Kff = v->Kff,
                          .damping_ratio = zeta,
                          .q0 = q0};
  memcpy(d.first_moment, v->c, sizeof v->c);
  memcpy(d.second_moment, v->J, sizeof v->J);
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  int body, pg, pb, pt;
  double o[3] = {0, 0, 0}, xt[3] = {LEN, 0, 0};
  double T[3 * NT];
  for (int k = 0; k < v->nm; k++)
    for (int a = 0; a < 3; a++) T[a + 3 * k] = B->Phi[NT * k + 3 * (NE - 1) + a];
  if ((rc = fmbd_mbs_add_flex(m, "beam", &d, &s0, &body)) ||
      (rc = fmbd_mbs_add_point(m, FMBD_MBS_GROUND, o, NULL, NULL, &pg)) ||
      (rc = fmbd_mbs_add_point(m, body, o, NULL, NULL, &pb)) ||
      (rc = fmbd_mbs_add_point(m, body, xt, T, NULL, &pt)))
    goto fail;
  fmbd_mbs_joint_desc jd = {.name = "clamp", .kind = FMBD_MBS_FIXED, .point = {pg, pb}};
  if ((rc = fmbd_mbs_add_joint(m, &jd, NULL))) goto fail;
  if (P != 0) {
    double dir[3] = {0, -1, 0};
    fmbd_mbs_fn f = fmbd_mbs_fn_constant(P);
    if ((rc = fmbd_mbs_add_load(m, "tip_load", FMBD_MBS_FORCE, pt, false, dir, &f, NULL)))
      goto fail;
  }
  *out = m, *tip = pt;
  return 0;
fail:
  fmbd_mbs_destroy(&m);
  return rc;
}

typedef struct osc {
  int tip;
  double d[2], yp, tp;
  int n;
  double tc[16];
} osc;
static int osc_cb(fmbd_mbs *m, bool out, void *u) {
  osc *o = u;
  double x[3], t = fmbd_mbs_time(m);
  fmbd_mbs_point_position(m, o->tip, x);
  double y = x[1] * o->d[0] + x[2] * o->d[1];  // tip displacement along the mode
  if (o->yp < 0 && y >= 0 && o->n < 16)
    o->tc[o->n++] = o->tp + (t - o->tp) * (-o->yp) / (y - o->yp);
  o->yp = y, o->tp = t;
  (void)out;
  return 0;
}

int main(void) {
  fmbd_log_init("t502", FMBD_LOG_WARN);
  static beam B;
  static inv V;
  int rc = build_beam(&B);
  EXPECT(rc == 0, "beam: %s", fmbd_err_get()->msg);
  if (rc) TEST_EXIT();
  const double P = 10, EI = EE * HS * HS * HS * HS / 12;
  const double d_exact = P * LEN * LEN * LEN / (3 * EI);  // EB cubic elements: nodally exact
  // FE static solution (condensed) at the tip: Kc u = f
  double Kc[NT * NT], f[NT] = {0};
  memcpy(Kc, B.Kc, sizeof Kc);
  f[3 * (NE - 1) + 1] = -P;
  rc = fmbd_dense_lu_solve(NT, Kc, 1, f, NT);
  double d_fe = -f[3 * (NE - 1) + 1];
  EXPECT(rc == 0 && fabs(d_fe / d_exact - 1) < 1e-10, "FE static tip %.9g, P L^3/3EI %.9g", d_fe,
         d_exact);
  // --- static deflection by damped dynamics, with nm modes ---
  int nms[3] = {2, 8, NT};
  double dsim[3];
  for (int c = 0; c < 3; c++) {
    int nm = nms[c];
    invariants(&B, nm, &V);
    fmbd_mbs *m = NULL;
    int tip;
    rc = build_sys(&B, &V, 0.7, NULL, P, &m, &tip);
    EXPECT(rc == 0, "build: %s", fmbd_err_get()->msg);
    if (rc) continue;
    fmbd_mbs_settings s;
    fmbd_mbs_settings_defaults(&s);
    // damping ratio 0.7: the transient decays like exp(-0.7 w1 t), w1 = 105 rad/s: 1e-14 by 0.45 s
    s.t_end = 0.45, s.tolerance = 1e-5, s.max_step = 5e-3;
    rc = fmbd_mbs_init(m, &s);
    if (!rc) rc = fmbd_mbs_run(m, NULL, NULL);
    EXPECT(rc == 0, "run nm = %d: %s", nm, fmbd_err_get()->msg);
    double x[3];
    fmbd_mbs_point_position(m, tip, x);
    dsim[c] = -x[1];
    // the modal static solution with nm modes: sum_k phi_k(tip) phi_k(tip) P / w_k^2
    double dm = 0;
    for (int k = 0; k < nm; k++) {
      double ph = B.Phi[NT * k + 3 * (NE - 1) + 1];
      dm += ph * ph * P / B.w2[k];
    }
    // the simulated equilibrium is the modal static solution up to the decayed transient and
    // the Newton tolerance: 1e-7 relative
    EXPECT(fabs(dsim[c] / dm - 1) < 1e-7,
           "nm = %d: simulated tip deflection %.9g, modal static %.9g", nm, dsim[c], dm);
    // clamp reaction, reported on side 1 (ground) = minus the force and moment on the beam:
    // the beam needs +P y and +P L z at the clamp to balance the tip load -P y at (L, 0, 0)
    double F[3], Tq[3];
    rc = fmbd_mbs_joint_reaction(m, 0, F, Tq);
    EXPECT(rc == 0 && fabs(F[1] + P) < 1e-6 * P && fabs(F[0]) + fabs(F[2]) < 1e-6 * P &&
               fabs(Tq[2] + P * LEN) < 1e-6 * P * LEN && fabs(Tq[0]) + fabs(Tq[1]) < 1e-6 * P * LEN,
           "nm = %d: clamp reaction F = (%g %g %g), T = (%g %g %g)", nm, F[0], F[1], F[2], Tq[0],
           Tq[1], Tq[2]);
    fmbd_mbs_stats st;
    fmbd_mbs_get_stats(m, &st);
    if (getenv("FMBD_TEST_VERBOSE"))
      fprintf(stderr, "t502: nm %d tip %.9g m (FE %.9g) steps %lld rej %lld newton %lld\n", nm,
              dsim[c], d_fe, (long long)st.steps, (long long)st.rejected,
              (long long)st.newton_iterations);
    fmbd_mbs_destroy(&m);
  }
  // modal truncation: with all NT modes the FE static solution is reproduced (1e-7 as above);
  // with 8 modes (the 4 lowest bending pairs) the missing modes carry ~ (w1/w5)^2 of the
  // deflection: < 1e-3; with 2 modes (first pair) ~ 3 %; errors decrease with modes
  EXPECT(fabs(dsim[2] / d_fe - 1) < 1e-7, "all modes: %.9g vs FE %.9g", dsim[2], d_fe);
  EXPECT(fabs(dsim[1] / d_fe - 1) < 1e-3, "8 modes: %.9g vs FE %.9g", dsim[1], d_fe);
  EXPECT(fabs(dsim[0] / d_fe - 1) > fabs(dsim[1] / d_fe - 1),
         "truncation error does not decrease with modes");
  // --- free oscillation at the first modal frequency ---
  {
    int nm = 8;
    invariants(&B, nm, &V);
    // mode 1 is one member of the repeated bending pair of the square section: its tip
    // motion lies along dir in the y-z plane; 1 mm initial tip amplitude
    double dir[2] = {B.Phi[3 * (NE - 1) + 1], B.Phi[3 * (NE - 1) + 2]};
    double nd = hypot(dir[0], dir[1]);
    double q0[NT] = {0};
    q0[0] = 1e-3 / nd;
    fmbd_mbs *m = NULL;
    int tip;
    rc = build_sys(&B, &V, 0, q0, 0, &m, &tip);
    EXPECT(rc == 0, "build: %s", fmbd_err_get()->msg);
    fmbd_mbs_settings s;
    fmbd_mbs_settings_defaults(&s);
    const double w1 = sqrt(B.w2[0]), T1 = 2 * M_PI / w1;
    s.fixed = true, s.step = 5e-5, s.t_end = 3.2 * T1, s.rho_inf = 1;
    osc o;
    memset(&o, 0, sizeof o);
    o.tip = tip, o.d[0] = dir[0] / nd, o.d[1] = dir[1] / nd;
    if (!rc) rc = fmbd_mbs_init(m, &s);
    if (!rc) rc = fmbd_mbs_run(m, osc_cb, &o);
    EXPECT(rc == 0, "free oscillation run: %s", fmbd_err_get()->msg);
    // rho_inf = 1: relative period error ~ (w1 h)^2 / 12 = 2.3e-6; allow 1e-5
    double Tm = o.n >= 3 ? (o.tc[2] - o.tc[0]) / 2 : NAN;
    EXPECT(fabs(Tm / T1 - 1) < 1e-5, "period %.9g s, first mode %.9g s (%d crossings)", Tm, T1,
           o.n);
    if (getenv("FMBD_TEST_VERBOSE"))
      fprintf(stderr, "t502: period %.9g vs %.9g (f1 = %.4f Hz)\n", Tm, T1, 1 / T1);
    fmbd_mbs_destroy(&m);
  }
  TEST_EXIT();
}
