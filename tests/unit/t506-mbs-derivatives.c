// tests/unit/t506-mbs-derivatives.c: white-box check of the derivatives the Newton iteration
// uses, against central finite differences: the body mass matrix (d r / d x'') and velocity
// tangent (d r / d x') of a flexible body with non-trivial invariants in a spinning, deformed
// state, and the constraint Jacobians of every joint kind and driver between two flexible
// bodies whose attachment points carry modal translations and rotations
// SPDX-License-Identifier: MIT
//
// It reaches mbs_body_eval and mbs_eval_constraints through the core's internal header.
//
// WHAT IT COVERS: the complete mass matrix d r / d x'' and velocity tangent d r / d x' of a
// body's equations (every inertia, gyroscopic, Coriolis and modal damping term, at a random
// spinning, deformed state), and the position Jacobian Cq of every joint kind and driver
// equation (flexible attachments with modal translations and rotations). WHAT IT DOES NOT:
// the position tangent d r / d x. The iteration matrix keeps only the modal stiffness Kff
// there and drops by design the position dependence of the inertia forces (centrifugal and
// Coriolis terms through the orientation and the modal coordinates), of gravity and follower
// loads, and the constraint forces' geometric stiffness (lambda' Phi_qq); Newton then
// converges linearly, not quadratically, and the step is the same (the residual is complete).
// So no finite-difference check of d r / d x is asserted here: it would test a matrix the
// code does not claim. The drivers' time derivatives (Phi_t = -f'(t), Phi_tt = -f''(t) in the
// velocity and acceleration equations) are checked in t510-mbs-fn.
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"
#include "t5_flex.h"

static double maxabs(const double *a, int n) {
  double v = 0;
  for (int i = 0; i < n; i++) v = fmax(v, fabs(a[i]));
  return v;
}

int main(void) {
  fmbd_log_init("t506", FMBD_LOG_ERROR);
  const int nm = 4;
  unsigned seed = 7;
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  int b0, b1;
  double pos0[3] = {0, 0, 0}, pos1[3] = {0.5, 0.1, -0.1};
  rc = rc ? rc : add_random_flex(m, "f0", nm, 11, pos0, 100, 0, NULL, &b0);
  rc = rc ? rc : add_random_flex(m, "f1", nm, 23, pos1, 100, 0, NULL, &b1);
  // one attachment point per body with modal translation and rotation, and joints of every kind
  double T[3 * 8], R[3 * 8];
  int pa, pb;
  for (int i = 0; i < 3 * nm; i++) T[i] = urand(&seed), R[i] = urand(&seed);
  double xa[3] = {0.45, 0.02, 0.01}, xb[3] = {-0.05, -0.08, 0.11};
  rc = rc ? rc : fmbd_mbs_add_point(m, b0, xa, T, R, &pa);
  for (int i = 0; i < 3 * nm; i++) T[i] = urand(&seed), R[i] = urand(&seed);
  rc = rc ? rc : fmbd_mbs_add_point(m, b1, xb, T, R, &pb);
  int kinds[6] = {FMBD_MBS_SPHERICAL, FMBD_MBS_REVOLUTE,    FMBD_MBS_UNIVERSAL,
                  FMBD_MBS_PRISMATIC, FMBD_MBS_CYLINDRICAL, FMBD_MBS_FIXED};
  const char *names[6] = {"sph", "rev", "uni", "pri", "cyl", "fix"};
  int jid[6];
  for (int k = 0; k < 6 && !rc; k++) {
    fmbd_mbs_joint_desc jd = {.name = names[k],
                              .kind = kinds[k],
                              .point = {pa, pb},
                              .axis = {0.2, 0.3, 0.93},
                              .ref = {1, 0, 0}};
    // universal: cross axes orthogonal
    jd.axis2[0] = jd.axis[1], jd.axis2[1] = -jd.axis[0], jd.axis2[2] = 0;
    rc = fmbd_mbs_add_joint(m, &jd, &jid[k]);
  }
  fmbd_mbs_fn f = fmbd_mbs_fn_sine(0.1, 0.2, 1, 0.3);
  rc = rc ? rc : fmbd_mbs_add_driver_joint(m, "drv_rev", jid[1], &f, NULL);
  rc = rc ? rc : fmbd_mbs_add_driver_joint(m, "drv_pri", jid[3], &f, NULL);
  rc = rc ? rc : fmbd_mbs_add_driver_body(m, "drv_q", b1, 4, &f, NULL);
  EXPECT(rc == 0, "build: %s", fmbd_err_get()->msg);
  if (rc) TEST_EXIT();
  // --- set up the internal state by hand (fmbd_mbs_init would project onto the constraints,
  // which over-constrain these two bodies) ---
  int64_t n = 0;
  m->maxn = 7;
  for (int ib = 0; ib < m->nb; ib++)
    m->b[ib].off = n, m->b[ib].qoff = n + 7, m->b[ib].gn = m->b[ib].n, n += m->b[ib].n,
    m->maxn = m->b[ib].n > m->maxn ? m->b[ib].n : m->maxn;
  m->n = n;
  double *x = fmbd_calloc((size_t)n, 8), *xd = fmbd_calloc((size_t)n, 8),
         *xdd = fmbd_calloc((size_t)n, 8);
  double *r0 = fmbd_calloc((size_t)n, 8), *r1 = fmbd_calloc((size_t)n, 8);
  size_t mx = (size_t)m->maxn, n6 = mx - 1;
  m->wk = fmbd_calloc(30 * mx, 8);
  m->bwork = fmbd_calloc(2 * n6 * n6 + n6, 8);
  double *B = fmbd_calloc(mx * mx, 8), *Bfd = fmbd_calloc(mx * mx, 8);
  double g[3] = {0.5, -9.81, 1.0};
  fmbd_mbs_set_gravity(m, g);
  for (int ib = 0; ib < m->nb; ib++) {
    mbody *b = &m->b[ib];
    for (int i = 0; i < b->n; i++) {
      x[b->off + i] = (i < 7 ? b->x0[i] : 0.05 * urand(&seed));
      xd[b->off + i] = 2 * urand(&seed);
      xdd[b->off + i] = 5 * urand(&seed);
    }
  }
  // --- body blocks: M = d r / d x'', C = d r / d x' (complete velocity tangent) ---
  for (int ib = 0; ib < m->nb; ib++) {
    mbody *b = &m->b[ib];
    int nb = b->n;
    for (int which = 0; which < 2; which++) {
      mbs_body_eval(m, ib, 0.3, x, xd, xdd, r0, B, which == 0 ? 1 : 0, which == 1 ? 1 : 0, 0, true);
      double *v = which == 0 ? xdd : xd;
      for (int j = 0; j < nb; j++) {
        double h = 1e-6, keep = v[b->off + j];
        v[b->off + j] = keep + h;
        mbs_body_eval(m, ib, 0.3, x, xd, xdd, r1 + b->off, NULL, 0, 0, 0, true);
        v[b->off + j] = keep - h;
        mbs_body_eval(m, ib, 0.3, x, xd, xdd, r0 + b->off, NULL, 0, 0, 0, true);
        v[b->off + j] = keep;
        for (int i = 0; i < nb; i++) Bfd[i + nb * j] = (r1[b->off + i] - r0[b->off + i]) / (2 * h);
      }
      double err = 0;
      for (int i = 0; i < nb * nb; i++) err = fmax(err, fabs(B[i] - Bfd[i]));
      // central differences of a quadratic (exact up to round-off ~1e-10 relative)
      EXPECT(err < 1e-6 * fmax(1, maxabs(Bfd, nb * nb)),
             "body %d %s: max |analytic - FD| %.3g (scale %.3g)", ib,
             which == 0 ? "mass matrix" : "velocity tangent", err, maxabs(Bfd, nb * nb));
    }
  }
  // --- constraint Jacobians ---
  int64_t neq = 0;
  for (int j = 0; j < m->nj; j++) neq += m->j[j].neq;
  neq += m->nd + m->nb;
  m->neq = neq;
  m->eq = fmbd_calloc((size_t)neq, sizeof(meq));
  int64_t e = 0;
  for (int ij = 0; ij < m->nj; ij++)
    for (int k = 0; k < m->j[ij].neq; k++, e++)
      m->eq[e].kind = EQ_JOINT, m->eq[e].owner = ij, m->eq[e].sub = k;
  for (int id = 0; id < m->nd; id++, e++) m->eq[e].kind = EQ_DRIVER, m->eq[e].owner = id;
  for (int ib = 0; ib < m->nb; ib++, e++) m->eq[e].kind = EQ_NORM, m->eq[e].owner = ib;
  for (e = 0; e < neq; e++) {
    meq *q = &m->eq[e];
    q->b[0] = q->b[1] = -1;
    if (q->kind == EQ_JOINT || (q->kind == EQ_DRIVER && m->d[q->owner].joint >= 0)) {
      q->b[0] = b0, q->b[1] = b1;
    } else {
      q->b[0] = q->kind == EQ_DRIVER ? m->d[q->owner].body : q->owner;
    }
    q->nj = m->b[q->b[0]].n + (q->b[1] >= 0 ? m->b[q->b[1]].n : 0);
    q->jac = fmbd_calloc((size_t)q->nj, 8);
    q->cols = fmbd_calloc((size_t)q->nj, 8);  // all coordinates of its bodies (modal bodies)
    for (int k = 0, o = 0; k < 2; k++) {
      if (q->b[k] < 0) continue;
      for (int i = 0; i < m->b[q->b[k]].n; i++) q->cols[o++] = m->b[q->b[k]].off + i;
    }
  }
  double *phi0 = fmbd_calloc((size_t)neq, 8), *jfd = fmbd_calloc((size_t)neq * (size_t)n, 8);
  mbs_eval_constraints(m, x, 0.3, true);
  for (int64_t i = 0; i < n; i++) {
    double h = 1e-6, keep = x[i];
    x[i] = keep + h;
    mbs_eval_constraints(m, x, 0.3, false);
    for (e = 0; e < neq; e++) phi0[e] = m->eq[e].phi;
    x[i] = keep - h;
    mbs_eval_constraints(m, x, 0.3, false);
    for (e = 0; e < neq; e++) jfd[e + neq * i] = (phi0[e] - m->eq[e].phi) / (2 * h);
    x[i] = keep;
  }
  mbs_eval_constraints(m, x, 0.3, true);
  for (e = 0; e < neq; e++) {
    const meq *q = &m->eq[e];
    double err = 0, sc = 0;
    int o = 0;
    for (int k = 0; k < 2; k++) {
      if (q->b[k] < 0) continue;
      const mbody *b = &m->b[q->b[k]];
      for (int i = 0; i < b->n; i++) {
        double fd = jfd[e + neq * (b->off + i)];
        err = fmax(err, fabs(q->jac[o + i] - fd));
        sc = fmax(sc, fabs(fd));
      }
      o += b->n;
    }
    char buf[256];
    mbs_eq_describe(m, q, buf, sizeof buf);
    // the Jacobians use A(p/|p|) at |p| = 1 exactly; FD error O(h^2) ~ 1e-12 relative
    EXPECT(err < 1e-7 * fmax(1, sc), "%s: max |analytic - FD| %.3g (scale %.3g)", buf, err, sc);
  }
  // --- Phi_x' lambda without the Jacobians (mbs_eval_constraints_res, the residual of a
  // Newton iteration without a new matrix) against sum_e lambda_e jac_e (one joint equation not
  // kept: its multiplier must not enter). Both sum the same products in another order: the
  // difference is round-off, a few eps times sum_e |lambda_e| |jac_e|; 64 eps of it is the bound
  m->lam = fmbd_calloc((size_t)neq, 8);
  double lsc = 0;
  for (e = 0; e < neq; e++) {
    meq *q = &m->eq[e];
    q->kept = e != 4, q->row = e;  // not kept: the revolute joint's second equation
    m->lam[e] = 10 * urand(&seed);
    lsc += fabs(m->lam[e]) * maxabs(q->jac, q->nj);
  }
  memset(r0, 0, sizeof(double) * (size_t)n), memset(r1, 0, sizeof(double) * (size_t)n);
  for (e = 0; e < neq; e++) {
    if (m->eq[e].kept) mbs_eq_jtv(m, &m->eq[e], m->lam[e], r0);
  }
  mbs_eval_constraints_res(m, x, 0.3, r1);
  double derr = 0;
  for (int64_t i = 0; i < n; i++) derr = fmax(derr, fabs(r1[i] - r0[i]));
  if (getenv("FMBD_TEST_VERBOSE"))
    fprintf(stderr, "t506: Phi_x' lambda: %.3g of %.3g\n", derr, lsc);
  EXPECT(derr <= 64 * DBL_EPSILON * lsc,
         "Phi_x' lambda without Jacobians: max diff %.3g (scale %.3g)", derr, lsc);
  fmbd_free(x), fmbd_free(xd), fmbd_free(xdd), fmbd_free(r0), fmbd_free(r1), fmbd_free(B),
      fmbd_free(Bfd);
  fmbd_free(phi0), fmbd_free(jfd);
  fmbd_mbs_destroy(&m);
  TEST_EXIT();
}
