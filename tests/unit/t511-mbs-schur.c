// tests/unit/t511-mbs-schur.c: white-box check of the iteration matrix's solve with the modal
// blocks eliminated (common/fmbd_mbs_schur.c) against KLU on the whole matrix
// SPDX-License-Identifier: MIT
//
// A closed loop of two flexible bodies with random invariants (8 modes each, modal damping):
// ground -spherical- f0 -revolute- f1 -spherical- ground; each body has two attachment points
// with modal translations and rotations, and the revolute's rows couple the modal coordinates
// of both bodies. After a few steps (spinning, deformed) the iteration matrix is formed; the
// Schur path (forced by FMBD_MBS_SCHUR=1) solves it with each modal block replaced by its
// constant part cm Mff + cc Dff + ck Kff. Reference: KLU on the whole matrix with the same
// replacement. Also: the whole matrix with the gyroscopic part kept gives a solution that
// differs by far more than the tolerance (the check can tell the two matrices apart); the
// modal blocks the Schur path leaves out of the evaluation, formed apart, equal the whole
// evaluation's bit for bit; and when the elimination fails (C not positive definite) the
// whole matrix's KLU gets those blocks.
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

enum { NM = T5_NM_MAX };

// a point on body b at local x0 with random modal translation and rotation; world: its
// initial world position
static int add_point(fmbd_mbs *m, int b, const double *x0, const double *A, const double *R,
                     unsigned *seed, double *world, int *pid) {
  double T[3 * NM], Rr[3 * NM];
  for (int i = 0; i < 3 * NM; i++) T[i] = 0.3 * urand(seed), Rr[i] = urand(seed);
  for (int a = 0; a < 3; a++)
    world[a] = R[a] + A[3 * a] * x0[0] + A[3 * a + 1] * x0[1] + A[3 * a + 2] * x0[2];
  return fmbd_mbs_add_point(m, b, x0, T, Rr, pid);
}

static double maxabs(const double *a, int64_t n) {
  double v = 0;
  for (int64_t i = 0; i < n; i++) v = fmax(v, fabs(a[i]));
  return v;
}

int main(void) {
  fmbd_log_init("t511", FMBD_LOG_ERROR);
  setenv("FMBD_MBS_SCHUR", "1", 1);  // every modal body eliminated (8 modes < the automatic 20)
  unsigned seed = 5;
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m);
  int b0, b1, pa, pb, pc, pd, g0, g1, jid;
  double A0[9], A1[9], pos0[3] = {0, 0, 0}, pos1[3] = {0, 0, 0}, wa[3], wb[3], wc[3], wd[3];
  rc = rc ? rc : add_random_flex(m, "f0", NM, 11, pos0, 2e3, 3, A0, &b0);
  double xa[3] = {-0.05, 0.02, 0.01}, xb[3] = {0.45, -0.03, 0.02};
  rc = rc ? rc : add_point(m, b0, xa, A0, pos0, &seed, wa, &pa);
  rc = rc ? rc : add_point(m, b0, xb, A0, pos0, &seed, wb, &pb);
  // f1 placed so that its point c sits on f0's point b
  rc = rc ? rc : add_random_flex(m, "f1", NM, 23, pos1, 2e3, 3, A1, &b1);
  double xc[3] = {-0.02, 0.04, -0.03}, xd[3] = {0.41, 0.05, 0.0};
  for (int a = 0; a < 3; a++)
    pos1[a] = wb[a] - (A1[3 * a] * xc[0] + A1[3 * a + 1] * xc[1] + A1[3 * a + 2] * xc[2]);
  memcpy(m->b[b1].x0, pos1, sizeof pos1);
  rc = rc ? rc : add_point(m, b1, xc, A1, pos1, &seed, wc, &pc);
  rc = rc ? rc : add_point(m, b1, xd, A1, pos1, &seed, wd, &pd);
  rc = rc ? rc : fmbd_mbs_add_point(m, FMBD_MBS_GROUND, wa, NULL, NULL, &g0);
  rc = rc ? rc : fmbd_mbs_add_point(m, FMBD_MBS_GROUND, wd, NULL, NULL, &g1);
  fmbd_mbs_joint_desc j0 = {.name = "s0", .kind = FMBD_MBS_SPHERICAL, .point = {g0, pa}};
  fmbd_mbs_joint_desc j1 = {
      .name = "r", .kind = FMBD_MBS_REVOLUTE, .point = {pb, pc}, .axis = {0.2, 0.3, 0.93}};
  fmbd_mbs_joint_desc j2 = {.name = "s1", .kind = FMBD_MBS_SPHERICAL, .point = {pd, g1}};
  rc = rc ? rc : fmbd_mbs_add_joint(m, &j0, &jid);
  rc = rc ? rc : fmbd_mbs_add_joint(m, &j1, &jid);
  rc = rc ? rc : fmbd_mbs_add_joint(m, &j2, &jid);
  double g[3] = {0, -9.81, 0};
  fmbd_mbs_set_gravity(m, g);
  fmbd_mbs_settings s;
  fmbd_mbs_settings_defaults(&s);
  s.fixed = true, s.step = 1e-3, s.t_end = 0.01;
  rc = rc ? rc : fmbd_mbs_init(m, &s);
  EXPECT(rc == 0, "build and init: %s", fmbd_err_get()->msg);
  if (rc) TEST_EXIT();
  EXPECT(m->sc != NULL, "FMBD_MBS_SCHUR=1: the modal blocks are eliminated");
  for (int k = 0; k < 5 && !rc; k++) rc = fmbd_mbs_step(m, NULL);
  EXPECT(rc == 0, "5 steps: %s", fmbd_err_get()->msg);
  if (rc || !m->sc) TEST_EXIT();
  // the iteration matrix at this state, coefficients of a 1e-3 s step with stiffness weight
  // raised so that ck Kff matters against Mff
  const double cm = 1, cc = 2e-3, ck = 1e-4;
  mbs_eval_system(m, m->t, m->xdd, true, cm, cc, ck, true);
  // the evaluation leaves the eliminated modal blocks out of Ax; mbs_fill_modal_blocks writes
  // them (as for the whole matrix's KLU when the elimination fails). Together they must give
  // the whole block of mbs_body_eval with ff bit for bit (the same operations in the same
  // order: no tolerance), and the blocks left out must be there in the first place
  int nel = 0;
  int64_t nbad = 0, nnan = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *bd = &m->b[ib];
    if (!bd->elim) continue;
    nel++;
    for (int j = 7; j < bd->n; j++) {  // poison the modal block: filled below or caught
      for (int i = 7; i < bd->n; i++) m->Ax[m->bpos[ib][i + bd->n * j]] = NAN;
    }
  }
  mbs_fill_modal_blocks(m);
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *bd = &m->b[ib];
    if (!bd->elim) continue;
    double *B = fmbd_malloc(sizeof(double) * (size_t)(bd->n * bd->n));
    double *rr = fmbd_malloc(sizeof(double) * (size_t)bd->n);
    mbs_body_eval(m, ib, m->t, m->x, m->xd, m->xdd, rr, B, cm, cc, ck, true);
    for (int e = 0; e < bd->n * bd->n; e++) {
      double v = m->Ax[m->bpos[ib][e]];
      nnan += isnan(v);
      nbad += v != B[e];
    }
    fmbd_free(B), fmbd_free(rr);
  }
  EXPECT(nel == 2 && nbad == 0 && nnan == 0,
         "modal blocks formed apart: %d bodies eliminated (2 expected), %lld entries differ from "
         "the whole evaluation (%lld not written)",
         nel, (long long)nbad, (long long)nnan);
  const int64_t N = m->N, nnz = m->nnz;
  double *b = fmbd_malloc(sizeof(double) * (size_t)N),
         *xs = fmbd_malloc(sizeof(double) * (size_t)N);
  double *xk = fmbd_malloc(sizeof(double) * (size_t)N),
         *xe = fmbd_malloc(sizeof(double) * (size_t)N);
  double *Ax = fmbd_malloc(sizeof(double) * (size_t)nnz),
         *Ac = fmbd_malloc(sizeof(double) * (size_t)nnz);
  for (int64_t i = 0; i < N; i++) b[i] = urand(&seed);
  memcpy(Ax, m->Ax, sizeof(double) * (size_t)nnz);
  // Schur path
  memcpy(xs, b, sizeof(double) * (size_t)N);
  rc = mbs_factor(m);
  EXPECT(rc == 0 && mbs_schur_active(m), "Schur factorisation: %s", fmbd_err_get()->msg);
  rc = rc ? rc : mbs_solve(m, xs);
  // reference: the whole matrix with the modal blocks' constant part, KLU
  memcpy(Ac, Ax, sizeof(double) * (size_t)nnz);
  double gyr = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *bd = &m->b[ib];
    for (int l = 0; l < bd->nm; l++) {
      for (int k = 0; k < bd->nm; k++) {
        int64_t p = m->bpos[ib][(7 + k) + bd->n * (7 + l)];
        double v = cm * bd->Mff[k + bd->nm * l] + cc * bd->Dff[k + bd->nm * l] +
                   ck * bd->Kff[k + bd->nm * l];
        gyr = fmax(gyr, fabs(Ac[p] - v));
        Ac[p] = v;
      }
    }
  }
  memcpy(xk, b, sizeof(double) * (size_t)N);
  rc = rc ? rc : fmbd_klu_factor(m->klu, Ac);
  double rcond = fmbd_klu_rcond(m->klu);
  rc = rc ? rc : fmbd_klu_solve(m->klu, xk);
  memcpy(xe, b, sizeof(double) * (size_t)N);
  rc = rc ? rc : fmbd_klu_factor(m->klu, Ax);
  rc = rc ? rc : fmbd_klu_solve(m->klu, xe);
  EXPECT(rc == 0, "solves: %s", fmbd_err_get()->msg);
  double d = 0, de = 0;
  for (int64_t i = 0; i < N; i++)
    d = fmax(d, fabs(xs[i] - xk[i])), de = fmax(de, fabs(xe[i] - xk[i]));
  double sc = maxabs(xk, N);
  // two backward-stable solves of one matrix differ by about cond * eps (relative); KLU's
  // rcond estimates 1/cond (within a modest factor: 100 allowed)
  double tol = 100 * DBL_EPSILON / fmax(rcond, 1e-300);
  EXPECT(d <= tol * sc,
         "Schur vs whole-matrix solve: max difference %.3g (scale %.3g, tolerance %.3g)", d, sc,
         tol * sc);
  EXPECT(gyr > 0 && de > 10 * tol * sc,
         "the gyroscopic part (%.3g) changes the solution by %.3g, beyond the tolerance %.3g", gyr,
         de, tol * sc);
  printf(
      "t511: N %lld, S order %lld; Schur vs KLU %.2e (scale %.2e, tol %.2e); gyroscopic part %.2e "
      "moves it by %.2e\n",
      (long long)N, (long long)(N - 2 * NM), d, sc, tol * sc, gyr, de);
  // the fallback: with C not positive definite (cm = -1, cc = ck = 0: C = -Mff) the
  // elimination fails and mbs_factor factors the whole matrix with KLU; the modal blocks the
  // evaluation left out (poisoned with NaN here) must be written first. Reference: KLU on the
  // same whole matrix formed apart (mbs_fill_modal_blocks): the same matrix, the same solver,
  // so the same bits (no tolerance)
  mbs_eval_system(m, m->t, m->xdd, true, -1, 0, 0, true);
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *bd = &m->b[ib];
    for (int j = 7; bd->elim && j < bd->n; j++) {
      for (int i = 7; i < bd->n; i++) m->Ax[m->bpos[ib][i + bd->n * j]] = NAN;
    }
  }
  memcpy(xs, b, sizeof(double) * (size_t)N);
  rc = mbs_factor(m);
  EXPECT(rc == 0 && !mbs_schur_active(m), "fallback to the whole matrix: rc %d, %s", rc,
         fmbd_err_get()->msg);
  rc = rc ? rc : mbs_solve(m, xs);
  mbs_eval_system(m, m->t, m->xdd, true, -1, 0, 0, true);
  mbs_fill_modal_blocks(m);
  memcpy(Ac, m->Ax, sizeof(double) * (size_t)nnz);
  memcpy(xk, b, sizeof(double) * (size_t)N);
  rc = rc ? rc : fmbd_klu_factor(m->klu, Ac);
  rc = rc ? rc : fmbd_klu_solve(m->klu, xk);
  int64_t ndiff = 0;
  for (int64_t i = 0; i < N; i++) ndiff += !(xs[i] == xk[i]);
  EXPECT(rc == 0 && ndiff == 0,
         "fallback solve: %lld of %lld entries differ from KLU on the "
         "whole matrix (rc %d)",
         (long long)ndiff, (long long)N, rc);
  // the solution also continues: the remaining steps through the Schur path (fresh matrix)
  m->need_factor = true;
  for (int k = 0; k < 5 && rc == 0; k++) rc = fmbd_mbs_step(m, NULL);
  EXPECT(rc == 0, "steps after: %s", fmbd_err_get()->msg);
  fmbd_free(b), fmbd_free(xs), fmbd_free(xk), fmbd_free(xe), fmbd_free(Ax), fmbd_free(Ac);
  fmbd_mbs_destroy(&m);
  TEST_EXIT();
}
