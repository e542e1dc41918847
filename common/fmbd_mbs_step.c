// common/fmbd_mbs_step.c: time stepping: index-3 generalized-alpha, Newton, step-size control
// SPDX-License-Identifier: MIT
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"

// ============================================================================================
// time stepping
// ============================================================================================
static void save_state(fmbd_mbs *m) {
  size_t nn = sizeof(double) * (size_t)m->n;
  memcpy(m->xn, m->x, nn), memcpy(m->xdn, m->xd, nn), memcpy(m->xddn, m->xdd, nn),
      memcpy(m->an, m->a, nn);
  memcpy(m->lamn, m->lam, sizeof(double) * (size_t)(m->m + 1));
}
static void restore_state(fmbd_mbs *m) {
  size_t nn = sizeof(double) * (size_t)m->n;
  memcpy(m->x, m->xn, nn), memcpy(m->xd, m->xdn, nn), memcpy(m->xdd, m->xddn, nn),
      memcpy(m->a, m->an, nn);
  memcpy(m->lam, m->lamn, sizeof(double) * (size_t)(m->m + 1));
}

// message naming the largest scaled residual of the last Newton iterate
static void worst_residual(const fmbd_mbs *m, char *buf, size_t len) {
  char what[512] = "?";
  int64_t wi = m->worst_i;
  if (wi >= m->n && wi < m->n + m->neq) {
    mbs_eq_describe(m, &m->eq[wi - m->n], what, sizeof what);
  } else if (wi >= 0 && wi < m->n) {
    for (int ib = 0; ib < m->nb; ib++) {
      const mbody *b = &m->b[ib];
      if (wi < b->off || wi >= b->off + b->gn) continue;
      int k = (int)(wi - b->off);
      if (k < 3)
        snprintf(what, sizeof what, "body '%s' translational equation of motion (%c)", b->name,
                 "xyz"[k]);
      else if (k < 7)
        snprintf(what, sizeof what, "body '%s' rotational equation of motion (row e%d)", b->name,
                 k - 3);
      else if (b->fe && b->fe->dofs)
        snprintf(what, sizeof what, "body '%s' equation of FE dof %d (node %lld, direction %lld)",
                 b->name, k - 6, (long long)b->fe->dofs[2 * (k - 7)],
                 (long long)b->fe->dofs[2 * (k - 7) + 1]);
      else
        snprintf(what, sizeof what, "body '%s' modal equation %d", b->name, k - 6);
    }
  }
  char dxw[300] = "?";
  if (m->worst_dx >= 0 && m->worst_dx < m->n) mbs_coord_describe(m, m->worst_dx, dxw, sizeof dxw);
  snprintf(buf, len, "%s (scaled residual %.3g); largest correction: %s", what, m->worst_v, dxw);
}

// At the smallest step: a dead point or singular position (the constraint rows dependent at
// the last accepted state, whatever the iterate or KLU's pivot order was) is named as such
// (the error set, true); `how` says what failed beyond it
static bool dead_point(fmbd_mbs *m, double h, const char *how) {
  char who[600];
  double smin;
  if (!mbs_constraints_singular(m, SINGULAR_TOL, &smin, who, sizeof who)) return false;
  fmbd_err_set(FMBD_ERR_CONVERGE, __FILE__, __LINE__, __func__,
               "t = %.9g s: the constraints are singular (a dead point or singular position): "
               "the equations of %s are dependent (smallest singular value %.2g of their "
               "unit-normalised rows); %s beyond it at h = %.3g s",
               m->t, who, smin, how, h);
  return true;
}

// Newton tolerance of the multipliers' increments (m->ity, their inverses). The unknown of
// kept equation k is y_k = lambda_k / beta' (lambda += beta' dy_k); an error dy_k acts on each
// coordinate i its equation touches as the generalized force J_ki dy_k, which the iteration
// matrix's diagonal A_ii (cm M + cc C + ck K, in the same units) turns into a coordinate error
// J_ki dy_k / A_ii. dy_k is within tolerance when that error is within coordinate i's own
// tolerance tx_i (1 / itx_i) for every coordinate of the row: ty_k = min_i A_ii tx_i / |J_ki|.
// As a force, beta' ty_k = min_i beta' A_ii tx_i / |J_ki|: a mass times the coordinate's
// acceleration tolerance newton_tol ascale_i (or beta' times its position tolerance or its
// round-off floor), so the multipliers converge to the accuracy the coordinates' accelerations
// are asked for, and their round-off floor is that of the coordinates (the 1e3 eps |x| floor
// times beta' A_ii; |lambda_k| of the step's start). A_ii / |J_ki| of the last evaluated matrix
// (the factored one: q->jw, formed once per matrix), tx_i of this attempt; coordinates whose
// diagonal is not formed in Ax (an eliminated body's modal block) are not used, and a row without
// any is not tested (ity 0). Formed only where the early stop is in reach (attempt): forming them
// at every attempt cost as much as the iterations they saved on the 100-link chain.
static void mult_tol(fmbd_mbs *m, double bp) {
  for (int64_t e = 0; e < m->neq; e++) {
    meq *q = &m->eq[e];
    if (!q->kept) continue;
    if (!m->jw_ok) {  // A_ii / |J_ki| of this matrix, infinite where unusable
      for (int i = 0; i < q->nj; i++) {
        int64_t p = m->dpos[q->cols[i]];
        double a = fabs(q->jac[i]);
        q->jw[i] = p >= 0 && a > 0 ? fabs(m->Ax[p]) / a : INFINITY;
      }
    }
    double t = INFINITY, fl = 1e3 * DBL_EPSILON * fabs(m->lamn[q->row]) / bp;
    for (int i = 0; i < q->nj; i++) {
      double v = q->jw[i] * m->tx[q->cols[i]];
      if (v < t) t = v;
    }
    if (fl > t) t = fl;
    m->ity[q->row] = t > 0 && t < INFINITY ? 1 / t : 0;
  }
  m->jw_ok = true;
}

// the largest multiplier increment dy_k in units of its tolerance (mult_tol)
static double mult_norm(fmbd_mbs *m, const double *dy) {
  double r = 0;
  for (int64_t k = 0; k < m->m; k++) {
    double v = fabs(dy[k]) * m->ity[k];
    if (!(v <= r)) r = v, m->worst_dy = k;
  }
  return r;
}

// The predictor's order (bench/README.md, "The predictor's order"): x''_n+1 and lambda_n+1
// are extrapolated by the polynomial through the last order + 1 accepted steps, order 2, 3 or
// 4, chosen per step for x'' and for lambda separately: after each accepted step the errors
// that each order's extrapolation would have made for it are formed (x'': the largest in units
// of the coordinates' Newton tolerances; lambda: the largest relative to the largest |lambda|),
// their logarithms averaged over the last steps (weight 1/4 to the newest), and the order with
// the smallest average extrapolates the next step. Measured: a rigid chain's x'' and lambda
// are smooth on the step (the fourth-order error 20 times below the quadratic's, the first
// Newton increment as much smaller); the quadruple pendulum's links carry the rod's 1 kHz
// mode, on which higher orders extrapolate worse (its iterations a step: quadratic 3.41,
// fourth order 3.53). FMBD_MBS_PRED = 2, 3 or 4 forces one order.
static int pred_forced(void) {
  static int o = -1;
  if (o < 0) {
    const char *e = getenv("FMBD_MBS_PRED");
    int v = e ? atoi(e) : 0;
    o = v >= PRED_MIN && v <= PRED_MAX ? v : 0;
  }
  return o;
}

// Lagrange weights w[0..np] of x(t_n), x(t_n-1), ... (the history m->hh) at t_n + h
static void pred_weights(const fmbd_mbs *m, double h, int np, double *w) {
  double s[PRED_NH + 1];
  s[0] = 0;
  for (int k = 0; k < np; k++) s[k + 1] = s[k] - m->hh[k];
  for (int j = 0; j <= np; j++) {
    w[j] = 1;
    for (int k = 0; k <= np; k++)
      if (k != j) w[j] *= (h - s[k]) / (s[j] - s[k]);
  }
}

// the order used for x'' (which 0) or lambda (1) in a step: the best average, at most what
// the history holds (linear after the first step, constant at it)
static int pred_order(const fmbd_mbs *m, int which, bool safe) {
  int o = pred_forced();
  if (!o) {
    o = PRED_MIN;
    for (int k = PRED_MIN + 1; k <= PRED_MAX && m->pred_rigid; k++)
      if (m->pred_lerr[which][k - PRED_MIN] < m->pred_lerr[which][o - PRED_MIN]) o = k;
  }
  if (safe && o > PRED_MIN) o = PRED_MIN;
  return m->nh < o ? m->nh : o;
}

// after an accepted step of size h (before the history moves on): the error each order would
// have made for it, averaged in the logarithm (pred_forced's comment)
static void pred_score(fmbd_mbs *m, double h) {
  if (pred_forced() || !m->pred_rigid || m->nh < PRED_MAX) return;
  double lmax = 0;
  for (int64_t k = 0; k < m->m; k++) lmax = fmax(lmax, fabs(m->lam[k]));
  for (int o = PRED_MIN; o <= PRED_MAX; o++) {
    double w[PRED_NH + 1], ex = 0, el = 0;
    pred_weights(m, h, o, w);
    for (int64_t i = 0; i < m->n; i++) {
      double p = w[0] * m->xddn[i];
      for (int j = 1; j <= o; j++) p += w[j] * m->xddh[j - 1][i];
      double v = fabs(m->xdd[i] - p) * m->itx[i];
      if (v > ex) ex = v;
    }
    for (int64_t k = 0; k < m->m; k++) {
      double p = w[0] * m->lamn[k];
      for (int j = 1; j <= o; j++) p += w[j] * m->lamh[j - 1][k];
      double v = fabs(m->lam[k] - p);
      if (v > el) el = v;
    }
    double e[2] = {ex, lmax > 0 ? el / lmax : 0};
    for (int c = 0; c < 2; c++) {
      double le = log(fmax(e[c], 1e-300));
      double *a = &m->pred_lerr[c][o - PRED_MIN];
      *a = m->pred_n ? 0.75 * *a + 0.25 * le : le;
    }
  }
  m->pred_n++;
}

// The REFRESH BY AGE: with a modal body of the size whose block fmbd_mbs_schur.c eliminates (at
// least SCHUR_NM_MIN modes; the rule is the same on either path, FMBD_MBS_SCHUR=0 too), the
// factor is formed anew at the start of a step once it is 3 steps old, or 2 where a body has
// full inertia coupling and the elastic coordinates are at least half the order of what remains
// (N - nm, the Schur complement's order), never where that order exceeds 16 nm; besides the
// refresh when Newton contracts slowly (THETA_REFACTOR) or h changed. Measured on the quadruple
// pendulum (bench/README.md, "Fewer Newton iterations: a fresh matrix by age"; 30 modes, full
// coupling, fixed 1.75e-3 s, `-vv`): a factor formed at an iterate of the step contracts by about
// 1e-4, one of the step before by 0.05 (median; 0.09 two steps before): the links' rotation (|w| h
// about 0.03 a step) and the velocity terms move the matrix, while the first increment is 1e3-3e3
// tolerances, mostly the elastic coordinates' predictor error, whose rows are constant. A fresh
// factor converges in 2.3 iterations a step, a stale one in 3.3-3.7; a factorisation (the
// elimination, nm nc^2, and KLU on the complement) with the matrix's evaluation costs about two
// iterations there, where an iteration evaluates the 12 nm^2 products of full coupling (SS q, SSx
// q') and the complement is of order 44. Run CPU (medians of 5), none / age 1 / 2 / 3: 0.0664 /
// 0.0630 / 0.0609 / 0.0631 s. Partial coupling (an iteration of a few nm products), 1.4e-3 s:
// 0.0572 / - / 0.0536 / 0.0503 s; 20 rigid links ending in the 30-mode rod (complement of order
// 231, fixed 1e-3 s, 1 s): 0.0352 / - / 0.0390 / 0.0319 s; 5 and 10 links: age 3 best too (7 %);
// 100 links (complement of order 1111, 0.3 s): main 0.0442 s, age 3 0.0452 s: where the rigid
// part's factorisation and evaluation outweigh the modal body's, a fresher factor no longer pays,
// so none beyond a complement of 16 times the elastic coordinates. Rigid and full FE bodies: none
// (the factor is the whole matrix's KLU). FMBD_MBS_REFRESH = N > 0 forces age N for any model, 0
// none.
static int refresh_age(const fmbd_mbs *m) {
  const char *e = getenv("FMBD_MBS_REFRESH");
  if (e && *e) {
    int v = atoi(e);
    return v > 0 ? v : -1;
  }
  int64_t nm = 0;
  bool full = false;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    if (b->fe || b->share >= 0 || b->nm < SCHUR_NM_MIN) continue;
    nm += b->nm;
    full = full || !b->partial;
  }
  if (nm == 0 || m->N - nm > 16 * nm) return -1;
  return full && 2 * nm >= m->N - nm ? 2 : 3;
}

// the contraction rate from which increments within tolerance are taken as round-off
// stagnation once a factor of the attempt is in use (attempt's convergence test)
#define STALL_THETA 0.5

// One attempt of a step of size h from the saved state. Returns FMBD_OK with *conv and *err
// (scaled local error, 0 for fixed steps) or an error code (singular matrix at the smallest
// step, KLU); *singular: not converged because the iteration matrix was singular.
// force_fresh (the retry of a failed attempt) also takes the quadratic predictor.
static int attempt(fmbd_mbs *m, double h, bool force_fresh, bool *conv, bool *fresh_out,
                   bool *singular, double *err) {
  const double am = m->am, af = m->af, be = m->beta, ga = m->gamma;
  const double bp = (1 - am) / (be * h * h * (1 - af)), gp = ga / (be * h);
  const double t1 = m->t + h;
  const int64_t n = m->n;
  *conv = false, *singular = false, *err = 0;
  // predictor: x''_{n+1} and lambda_{n+1} extrapolated from the last accepted steps
  // (pred_order; before: quadratically always). Measured (bench/README.md, the N-link
  // chain): with x'' linear and lambda_{n+1} = lambda_n the first Newton increment of a rigid
  // chain was 3e5 tolerances and the second nearly as large (the stale multipliers); with
  // both quadratic 2e3 and a contraction of 0.01-0.03 from the first iteration on
  const bool safe = force_fresh || m->after_reject;
  const int npx = pred_order(m, 0, safe), npl = pred_order(m, 1, safe);
  double w[PRED_NH + 1], wl[PRED_NH + 1];
  pred_weights(m, h, npx, w);
  pred_weights(m, h, npl, wl);
  // The elastic coordinates of modal bodies (m->qpar) by the line through x''_n-1 and x''_n-3,
  // the steps of t_n+1's parity: their modes above the step's resolution (the pendulum's rod,
  // 1-29 kHz at h = 1.75e-3 s: omega h 11-320) carry the generalized-alpha's step-to-step
  // sawtooth, x''_k = s(t_k) + (-1)^k a(t_k) with s and a smooth, which the quadratic
  // extrapolation (3, -3, 1) multiplies by 7 while the line over every other step follows both.
  // Measured offline on the converged x'' of the 30-mode pendulum (fixed 1.75e-3 s, error of
  // the extrapolation in units of the Newton tolerance, median over the steps of the largest
  // over the elastic coordinates): quadratic 360, linear 182, constant 96, x''_n-1 23, the
  // parity line 21; on the links' coordinates the quadratic stays best among these (55 against
  // 122 for the parity line). Iterations a step: 2.80 -> 2.73 (30 modes, full coupling, 1.75e-3
  // s), 2.95 -> 2.78 (partial, 1.4e-3 s), 2.68 -> 2.61 (100 modes); bench/README.md, "Fewer
  // Newton iterations: a fresh matrix by age". FMBD_MBS_PRED forces its order on them too.
  double wq[4] = {0, 0, 0, 0};
  const bool par = !safe && !pred_forced() && m->nh >= 3;
  if (par) {
    const double s1 = -m->hh[0], s3 = -(m->hh[0] + m->hh[1] + m->hh[2]);
    wq[1] = (h - s3) / (s1 - s3), wq[3] = (h - s1) / (s3 - s1);
  }
  for (int64_t i = 0; i < n; i++) {
    double an = m->an[i], xdd1;
    if (par && m->qpar[i]) {
      xdd1 = wq[1] * m->xddh[0][i] + wq[3] * m->xddh[2][i];
    } else {
      xdd1 = w[0] * m->xddn[i];
      for (int j = 1; j <= npx; j++) xdd1 += w[j] * m->xddh[j - 1][i];
    }
    double a1 = ((1 - af) * xdd1 + af * m->xddn[i] - am * an) / (1 - am);
    m->a[i] = a1;
    m->xdd[i] = xdd1;
    m->x[i] = m->xn[i] + h * m->xdn[i] + h * h * ((0.5 - be) * an + be * a1);
    m->xd[i] = m->xdn[i] + h * ((1 - ga) * an + ga * a1);
    // increments in units of the per-coordinate tolerance: position accuracy newton_tol *
    // nscale_i and acceleration accuracy newton_tol * ascale_i (an x error dx gives an x''
    // error beta' dx: without this bound the leftover of a modified-Newton iteration acts as
    // a spurious force that breaks momentum conservation at small steps), but never below
    // the round-off of x_i (at the predicted x_i: the iterates differ from it far below the
    // 1e3 eps of that floor). Once per attempt, not per iteration: 4 % of a chain's run
    // (fmin and fmax written out: the scales are positive and finite, a NaN |x_i| gives way
    // as in fmax; the library calls were 1 % of the pendulum's run)
    const double ns = m->nscale[i], as = m->ascale[i] / bp, rs = m->rscale[i], ax = fabs(m->x[i]);
    double tx = m->set.newton_tol * (as < ns ? as : ns);
    double fl = ns > rs ? ns : rs;
    fl = 1e3 * DBL_EPSILON * (ax > fl ? ax : fl);
    tx = fl > tx ? fl : tx;
    m->tx[i] = tx, m->itx[i] = 1 / tx;
  }
  for (int64_t k = 0; k < m->m; k++) {
    double l = wl[0] * m->lamn[k];
    for (int j = 1; j <= npl; j++) l += wl[j] * m->lamh[j - 1][k];
    m->lam[k] = l;
  }
  if (m->h_fact <= 0 || fabs(h / m->h_fact - 1) > 0.25) m->need_factor = true;
  if (force_fresh) m->need_factor = true;
  if (!m->refresh_age) m->refresh_age = refresh_age(m);
  if (m->refresh_age > 0 && m->st.steps - m->fact_steps >= m->refresh_age) m->need_factor = true;
  bool fresh = false;
  double prev = 0;
  bool ity_ok = false;  // m->ity formed for this attempt
  // clock readings between the phases (wall; fmbd_mbs_get_stats makes them CPU time)
  double clk = fmbd_wall_s(), clk1;
  const bool debug = fmbd_log_level() >= FMBD_LOG_DEBUG;
  for (int it = 0; it < m->set.newton_max; it++) {
    bool matrix = m->need_factor;
    mbs_eval_system(m, t1, m->xdd, matrix, 1, gp / bp, 1 / bp, true);
    const double ibp = 1 / bp;
    for (int64_t i = 0; i < n; i++) m->rhs[i] = -m->res[i] * ibp;
    for (int64_t e = 0; e < m->neq; e++) {
      const meq *q = &m->eq[e];
      if (q->kept) m->rhs[n + q->row] = -q->phi;
    }
    if (matrix) m->jw_ok = false;
    clk1 = fmbd_wall_s();
    m->tm_phase[2] += clk1 - clk;
    if (matrix) {
      int fr = mbs_factor(m);
      if (fr == FMBD_ERR_SINGULAR && h > m->set.min_step * (1 + 1e-9)) {
        // a singular iteration matrix at a Newton iterate of a step that can still be made
        // smaller: the iterate (off the constraint manifold, or past a fold the predictor
        // overshot) is no state of the mechanism, and whether KLU meets an exact zero pivot
        // there depends on its pivot order. Rejected as a Newton failure: the step is
        // reduced and, at the smallest step, the report is made at the last accepted state
        // (fmbd_mbs_step), the same for any ordering (bench/README.md, the chain, lever 1)
        if (debug)
          fmbd_log(FMBD_LOG_DEBUG, "t = %.9g h = %.3g Newton %d: %s", m->t, h, it,
                   fmbd_err_get()->msg);
        fmbd_err_clear();
        *singular = true;
        fresh = true;
        break;
      }
      FMBD_CALL(fr);
      m->need_factor = false;
      m->h_fact = h;
      m->fact_steps = m->st.steps;
      fresh = true;
      clk = clk1, clk1 = fmbd_wall_s();
      m->tm_phase[0] += clk1 - clk;
    }
    FMBD_CALL(mbs_solve(m, m->rhs));
    clk = fmbd_wall_s();
    m->tm_phase[1] += clk - clk1;
    m->st.newton_iterations++;
    // the largest increment in units of the tolerance (itx, the predictor's loop)
    double nrm = 0;
    const double *itx = m->itx;
    for (int64_t i = 0; i < n; i++) {
      double dx = m->rhs[i];
      m->x[i] += dx;
      m->xd[i] += gp * dx;
      m->xdd[i] += bp * dx;
      double v = fabs(dx) * itx[i];
      if (!(v <= nrm)) nrm = v, m->worst_dx = i;
    }
    for (int64_t k = 0; k < m->m; k++) m->lam[k] += bp * m->rhs[n + k];
    if (!isfinite(nrm)) break;
    // CONVERGED (the test on the coordinates): |dx| within tolerance in the first iteration
    // by a margin of 1e3 (theta unknown), or |dx| within tolerance with the estimated
    // remaining error theta/(1 - theta) |dx| (Hairer & Wanner II, sec. IV.8) within it too, or
    // |dx| within tolerance and theta >= 1 (round-off stagnation). Also converged (the EARLY
    // STOP) when the contraction is established, theta <= 0.1 from the third iteration on
    // (the first ratio |dx_1| / |dx_0| also holds the predictor's error in what the matrix
    // leaves out, below; stopping on it broke the h^2 momentum drift of t503's spinning
    // truss), and the remaining errors of both the coordinates and the multipliers are
    // estimated within tolerance, even if the last increment was not. The multipliers are
    // asked for in that stop only: in the index-3 scheme they do not feed the motion (the
    // residual is evaluated at t_n+1 with lambda_n+1 alone), only the reactions and the next
    // step's predictor; an early stop on the coordinates alone had left the Newton leftover
    // in the multipliers (a driving torque 2.2e-3 N m off, test_slider_crank_dynamics) and,
    // near a dead point, accepted steps past it (test_limits); there the multipliers contract
    // slowly, the early stop is not taken and the test on the coordinates decides as before.
    // Asking the multipliers in every stop gave the torque to 6.5e-6 N m but could not
    // converge near the dead point (bench/README.md, "Fewer Newton iterations")
    double theta = it > 0 ? nrm / prev : 0, est = theta / (1 - theta) * nrm;
    bool xok = nrm <= 1e-3 || (it > 0 && nrm <= 1 && (theta >= 1 || est <= 1));
    // ROUND-OFF STAGNATION also when the increment is within tolerance, a factor of this
    // attempt (Newton's matrix at an iterate of this step) has been used, and the increments
    // no longer contract (theta >= 1/2; below it est <= |dx| and the test above accepts): with
    // that matrix Newton contracts by 0.01-0.03 on these systems (the omitted position
    // derivatives), and only at a fold by 1/2; what remains is the solve's round-off, which
    // the tolerance's floor 1e3 eps |x| does not always cover: the 1000-link chain's top links
    // wandered at 0.6-1.2 tolerances with theta 0.7-1.1 for five iterations and the step was
    // rejected (bench/README.md, "The predictor's order")
    if (!xok && it > 0 && nrm <= 1 && fresh && theta >= STALL_THETA) xok = true;
    bool early = false;
    double nrl = -1, thl = -1;
    if (!xok && it > 1 && theta <= 0.1 && est <= 1) {  // the early stop in reach
      if (!ity_ok || !m->jw_ok) mult_tol(m, bp), ity_ok = true;
      double prevl = mult_norm(m, m->dyp);
      nrl = mult_norm(m, m->rhs + n);
      thl = nrl / prevl;
      double estl = thl / (1 - thl) * nrl;
      bool lok = nrl <= 1e-3 || ((nrl <= 1 || thl <= 0.1) && estl <= 1);
      early = lok;
    }
    if (debug) {  // the multipliers only where the early stop was in reach (the same decisions)
      char dxw[300], lw[200] = "";
      mbs_coord_describe(m, m->worst_dx, dxw, sizeof dxw);
      if (nrl >= 0)
        snprintf(lw, sizeof lw, "; |dlambda|/tol %.3g theta %.3g (kept equation %lld)%s", nrl, thl,
                 (long long)m->worst_dy, early ? ", early stop" : "");
      fmbd_log(FMBD_LOG_DEBUG, "t = %.9g h = %.3g Newton %d%s: |dx|/tol %.3g theta %.3g (%s)%s",
               m->t, h, it, matrix ? " (new matrix)" : "", nrm, theta, dxw, lw);
    }
    if (xok || early) {
      *conv = true;
      break;
    }
    // diverging with an up-to-date matrix: both increments from the fresh factor (the first
    // increment of a new factor is no measure: it follows one of the stale factor, which may
    // have stalled near the tolerance, bench/README.md: the quadruple pendulum's fixed steps)
    if (it > 0 && theta >= 1 && fresh && !matrix) break;
    // refresh a stale matrix when the contraction rate exceeds THETA_REFACTOR; with fixed steps
    // the first ratio |dx_1| / |dx_0| only when it does not contract at all. That ratio also
    // holds the predictor's error in what the matrix leaves out: on the planar slider-crank's
    // full FE rod (6741 dofs, fixed 1e-4 s, examples/slidercrank/README.md) it exceeded 0.1 on
    // every other step from t = 0.3 s even with a one-step-old matrix, while the second ratio
    // stayed below 0.01 with a 10-step-old one (at 0.29 s). Over 0.3..0.35 s (its dead point) that
    // rule refactored at 429 of 500 steps (0.35 s each against 8 ms an iteration): 150 s of CPU for
    // 1704 iterations; without it 176 factorisations, 1874 iterations, 78 s. Variable steps keep
    // it: there the Newton leftover enters the error estimate (tests/py/test_fm.py's spinning rod:
    // 60 % more steps without the first-ratio refresh)
    if (!matrix && theta > THETA_REFACTOR && (it > 1 || !m->set.fixed || theta >= 1))
      m->need_factor = true;
    memcpy(m->dyp, m->rhs + n, sizeof(double) * (size_t)m->m);
    prev = nrm;
  }
  m->tm_phase[2] += fmbd_wall_s() - clk;
  *fresh_out = fresh;
  if (!*conv) {
    // the largest scaled residual at the last iterate (for the failure message): evaluated
    // here, once, not at every iteration
    mbs_eval_system(m, t1, m->xdd, false, 1, gp / bp, 1 / bp, true);
    m->worst_v = -1;
    for (int64_t i = 0; i < n; i++) {
      double v = fabs(m->res[i] / bp) / m->nscale[i];
      if (!(v <= m->worst_v)) m->worst_v = v, m->worst_i = i;
    }
    for (int64_t e = 0; e < m->neq; e++) {
      const meq *q = &m->eq[e];
      if (!q->kept) continue;
      double v = mbs_eq_scaled(m, q);
      if (!(v <= m->worst_v)) m->worst_v = v, m->worst_i = m->n + e;
    }
    return FMBD_OK;
  }
  // pseudo-accelerations of the converged state
  for (int64_t i = 0; i < n; i++) {
    m->a[i] = ((1 - af) * m->xdd[i] + af * m->xddn[i] - am * m->an[i]) / (1 - am);
  }
  if (!m->set.fixed) {
    // local error estimate of the displacement update (Geradin & Cardona 2001, sec. 11.5):
    // e = h^2 |beta - 1/6| (a_{n+1} - a_n)
    double c = h * h * fabs(be - 1.0 / 6.0), e = 0;
    for (int64_t i = 0; i < n; i++) {
      double sc = fmax(m->scale[i], m->floor_[i]);
      double v = c * fabs(m->a[i] - m->an[i]) / (m->set.tolerance * sc);
      if (!(v <= e)) e = v;
    }
    *err = e;
  }
  return FMBD_OK;
}

int fmbd_mbs_step(fmbd_mbs *m, bool *at_output) {
  FMBD_CHECK(m->ready, FMBD_ERR_VALUE, "fmbd_mbs_step before fmbd_mbs_init");
  FMBD_CHECK(!m->set.linearise_only, FMBD_ERR_VALUE,
             "fmbd_mbs_step: the model was initialised to be linearised only");
  if (at_output) *at_output = false;
  const double tend = m->set.t_end;
  if (m->t >= tend * (1 - 1e-14)) return 1;
  FMBD_CHECK(m->set.max_steps <= 0 || m->st.steps < m->set.max_steps, FMBD_ERR_CONVERGE,
             "t = %.6g s: step limit %lld reached", m->t, (long long)m->set.max_steps);
  const double oe = m->set.output_every;
  if (m->st.steps % 8 == 0) {  // a window of the Newton phases' CPU time ends (mbs_cpu_share)
    double w = fmbd_wall_s(), c = fmbd_cpu_s(), f = mbs_cpu_share(m, w, c);
    for (int k = 0; k < 3; k++) m->tm_cpu[k] += f * m->tm_phase[k], m->tm_phase[k] = 0;
    m->tm_wall0 = w, m->tm_cpu0 = c;
  }
  save_state(m);
  bool retried_fresh = false;
  for (;;) {
    double h = m->h_next;
    if (m->set.fixed && h > m->set.step) h = m->set.step;
    if (!m->set.fixed && h > m->set.max_step) h = m->set.max_step;
    double lim = tend;
    bool out_lim = false;
    if (oe > 0) {
      double to = (double)(m->k_out + 1) * oe;
      if (to < lim) lim = to, out_lim = true;
    }
    bool clipped = false;
    if (m->t + h > lim - 0.01 * h) {
      if (lim - m->t < h) clipped = true;
      m->h_prop = h;
      h = lim - m->t;
    }
    bool conv, fresh, singular;
    double err;
    int arc = attempt(m, h, retried_fresh, &conv, &fresh, &singular, &err);
    if (arc != 0) {
      restore_state(m);  // the caller may still query (and write) the last accepted state
      // a singular matrix at the smallest step (attempt): a dead point is named as below
      if (arc == FMBD_ERR_SINGULAR && dead_point(m, h, "the iteration matrix is singular"))
        return FMBD_ERR_CONVERGE;
      return arc;
    }
    if (!conv) {
      if (fmbd_log_level() >= FMBD_LOG_DEBUG) {
        char buf[800];
        worst_residual(m, buf, sizeof buf);
        fmbd_log(FMBD_LOG_DEBUG,
                 "t = %.9g h = %.3g: Newton did not converge%s; largest residual: %s", m->t, h,
                 fresh ? "" : " (old matrix)", buf);
      }
      restore_state(m);
      if (!fresh && !retried_fresh) {
        retried_fresh = true;  // the old factor was too far off: same h, fresh matrix
        continue;
      }
      m->st.rejected++;
      double hmin = m->set.min_step;
      if (h <= hmin * (1 + 1e-9)) {
        char buf[800];
        worst_residual(m, buf, sizeof buf);
        if (!isfinite(m->worst_v)) {
          // overflow, not a convergence problem: say so rather than "singular" or "diverged"
          FMBD_FAIL(FMBD_ERR_CONVERGE,
                    "t = %.9g s: the equations are not finite (overflow: a load, stiffness, "
                    "mass or initial velocity of absurd magnitude?); first at %s",
                    m->t + h, buf);
        }
        if (dead_point(m, h, "Newton did not converge")) return FMBD_ERR_CONVERGE;
        FMBD_FAIL(FMBD_ERR_CONVERGE,
                  "t = %.9g s, h = %.3g s: Newton did not converge; largest residual: %s", m->t + h,
                  h, buf);
      }
      m->h_next = fmax(h / 4, hmin);
      m->after_reject = true;
      retried_fresh = false;
      continue;
    }
    if (fmbd_log_level() >= FMBD_LOG_DEBUG) {
      fmbd_log(FMBD_LOG_DEBUG, "t = %.9g h = %.3g err = %.3g%s", m->t, h, err,
               err > 1 ? " rejected" : "");
    }
    if (!m->set.fixed && err > 1 && h > m->set.min_step * (1 + 1e-9)) {
      restore_state(m);
      m->st.rejected++;
      m->after_reject = true;
      double f = fmax(0.2, 0.9 * pow(err, -1.0 / 3.0));
      m->h_next = fmax(h * f, m->set.min_step);
      retried_fresh = false;
      continue;
    }
    // --- accepted ---
    m->t += h;
    m->st.steps++;
    m->st.h_last = h;
    // x'' and lambda of the steps before (the predictor): the orders' errors for this step,
    // then the oldest buffer takes t_n's
    pred_score(m, h);
    {
      double *ox = m->xddh[PRED_NH - 1], *ol = m->lamh[PRED_NH - 1];
      for (int k = PRED_NH - 1; k > 0; k--)
        m->xddh[k] = m->xddh[k - 1], m->lamh[k] = m->lamh[k - 1], m->hh[k] = m->hh[k - 1];
      m->xddh[0] = ox, m->lamh[0] = ol, m->hh[0] = h;
      memcpy(ox, m->xddn, sizeof(double) * (size_t)m->n);
      memcpy(ol, m->lamn, sizeof(double) * (size_t)m->m);
      if (m->nh < PRED_NH) m->nh++;
    }
    mbs_update_scales(m);
    mbs_spin_check(m);  // docs/STABILITY.md, the spin-up beam (fmbd_mbs_spin.c)
    bool hit_out = oe <= 0;
    if (oe > 0 && clipped && out_lim) {
      m->k_out++;
      hit_out = true;
    } else if (oe > 0) {
      double to = (double)(m->k_out + 1) * oe;
      if (fabs(m->t - to) <= 1e-9 * fmax(1.0, fabs(to))) {
        m->k_out++;
        hit_out = true;
      }
    }
    if (oe > 0 && m->t >= tend * (1 - 1e-14)) hit_out = true;
    if (at_output) *at_output = hit_out;
    if (m->set.fixed) {
      m->h_next = m->set.step;
    } else {
      // elementary controller (order 2 method: local error ~ h^3) with a dead band that
      // keeps h (and the factorised matrix) unchanged for small proposed increases, and no
      // increase right after a rejection (Hairer, Norsett & Wanner I, sec. II.4)
      double f = err > 0 ? SAFETY * pow(err, -1.0 / 3.0) : 2.0;
      // an increase also by the largest error of the last three accepted steps: where the
      // estimate is noisy (the FE dofs' fast modes: 0.2 and 1.8 at one h on successive steps)
      // the last step alone raises h into a rejection, and each change refactors the matrix
      double eg = fmax(err, fmax(m->err_prev[0], m->err_prev[1]));
      if (f > 1 && eg > 0) f = fmin(f, fmax(1.0, SAFETY * pow(eg, -1.0 / 3.0)));
      m->err_prev[1] = m->err_prev[0], m->err_prev[0] = err;
      f = fmin(2.0, fmax(0.2, f));
      if (f > 1 && (f < 1.25 || m->after_reject)) f = 1;
      if (f < 1 && f > DEAD_LOW) f = 1;
      double hn = h * f;
      if (clipped && m->h_prop > hn) hn = m->h_prop;
      m->h_next = fmin(m->set.max_step, fmax(m->set.min_step, hn));
      m->after_reject = false;
    }
    return FMBD_OK;
  }
}

int fmbd_mbs_run(fmbd_mbs *m, fmbd_mbs_callback cb, void *user) {
  for (;;) {
    bool out;
    int rc = fmbd_mbs_step(m, &out);
    if (rc == 1) return FMBD_OK;
    if (rc != 0) return rc;
    if (cb) {
      int r = cb(m, out, user);
      if (r != 0) return r;
    }
  }
}
