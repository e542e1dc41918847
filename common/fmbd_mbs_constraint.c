// common/fmbd_mbs_constraint.c: joint, driver and normalisation equations and their Jacobians
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
// constraints
// ============================================================================================

// d(A v)/dp = -2/|p| A v~ G (3x4 row-major) into out. A is a rotation, so A (v x g) =
// (A v) x (A g): column c is -2/|p| (A v) x (A G)_c, from Av = A v (at hand where this is
// called) and AG = A G (once per side): 12 products and 4 cross products instead of the
// 27 + 36 of A v~ G (the largest single cost of a rigid chain's step, bench/README.md)
static void dA_dp(const double *AG, double pn, const double *Av, double *out) {
  double f = -2.0 / pn;
  for (int c = 0; c < 4; c++) {
    const double g0 = AG[c], g1 = AG[4 + c], g2 = AG[8 + c];
    out[c] = f * (Av[1] * g2 - Av[2] * g1);
    out[4 + c] = f * (Av[2] * g0 - Av[0] * g2);
    out[8 + c] = f * (Av[0] * g1 - Av[1] * g0);
  }
}

// g = A (e + th x e): a direction vector e of the point's frame, turned by the point's small
// elastic rotation th, in global axes; th NULL: a rigid point's (g = A e, the same values)
static inline void side_dir(const double *A, const double *th, const double *e, double *g) {
  if (!th) {
    mv3(A, e, g);
    return;
  }
  double wv[3], tc[3];
  cross3(th, e, tc);
  for (int a = 0; a < 3; a++) wv[a] = e[a] + tc[a];
  mv3(A, wv, g);
}

// e: nv local direction vectors (3 each), of which only those in the bit mask `want` (bit i:
// direction i) are evaluated, with their derivatives and dr when deriv (without: r, g and
// what side_force needs)
static void side_eval(const fmbd_mbs *m, int pt, const double (*e)[3], int nv, unsigned want,
                      const double *xg, bool deriv, side *s) {
  const mpoint *P = &m->p[pt];
  s->body = P->body;
  if (P->body < 0) {
    s->n = 0;
    memcpy(s->r, P->x0, sizeof s->r);
    for (int i = 0; i < nv; i++) memcpy(s->g[i], e[i], sizeof s->g[i]);
    return;
  }
  const mbody *b = &m->b[P->body];
  // the flexible coordinates that move the point: all (modal body) or its support (FE body)
  const int nm = P->sup ? P->nsup : b->nm, n = 7 + nm;
  const int64_t *sup = P->sup;
  s->n = n;
  const double *x = xg + b->off, *p = x + 3, *q = xg + b->qoff;
  double *A = s->A, pn = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]);
  quat_to_A(p, A);
  // A G (3 x 4 row-major) = E(p) = [-e, e~ + e0 1], exactly for any p: A = R(p) / |p|^2 with R
  // quadratic and G linear in p, and R(q) G(q) = E(q) for a unit q (the global-frame form of
  // G, Nikravesh's E; at p = (1, 0, 0, 0): [0 1]): R(p) G(p) = |p|^3 E(p / |p|) = |p|^2 E(p).
  // No products, and no round-off (the product A G had 36 multiplications per side)
  double *AG = s->AG;
  const double e0 = p[0], e1 = p[1], e2 = p[2], e3 = p[3];
  AG[0] = -e1, AG[1] = e0, AG[2] = -e3, AG[3] = e2;
  AG[4] = -e2, AG[5] = e3, AG[6] = e0, AG[7] = -e1;
  AG[8] = -e3, AG[9] = -e2, AG[10] = e1, AG[11] = e0;
  s->f = -2.0 / pn;
  double u[3];
  memcpy(u, P->x0, sizeof u);
  double th[3] = {0, 0, 0};
  for (int k = 0; k < nm; k++) {
    double qk = q[sup ? sup[k] : k];
    for (int a = 0; a < 3; a++) u[a] += P->T[a + 3 * k] * qk, th[a] += P->Rr[a + 3 * k] * qk;
  }
  double *Au = s->Au;
  mv3(A, u, Au);
  for (int a = 0; a < 3; a++) s->r[a] = x[a] + Au[a];
  if (!deriv) {
    for (int i = 0; i < nv; i++) {
      if (want >> i & 1) side_dir(A, nm ? th : NULL, e[i], s->g[i]);
    }
    return;
  }
  double D[12];
  memset(s->dr, 0, sizeof(double) * 3 * (size_t)n);
  for (int a = 0; a < 3; a++) s->dr[a + 3 * a] = 1;
  dA_dp(AG, pn, Au, D);
  for (int a = 0; a < 3; a++) {
    for (int c4 = 0; c4 < 4; c4++) s->dr[a + 3 * (3 + c4)] = D[4 * a + c4];
  }
  for (int k = 0; k < nm; k++) mv3(A, P->T + 3 * k, s->dr + 3 * (7 + k));
  for (int i = 0; i < nv; i++) {
    if (!(want >> i & 1)) continue;
    side_dir(A, nm ? th : NULL, e[i], s->g[i]);
    double *dg = s->dg[i];
    memset(dg, 0, sizeof(double) * 3 * (size_t)n);
    dA_dp(AG, pn, s->g[i], D);
    for (int a = 0; a < 3; a++) {
      for (int c4 = 0; c4 < 4; c4++) dg[a + 3 * (3 + c4)] = D[4 * a + c4];
    }
    for (int k = 0; k < nm; k++) {
      double rc[3];
      cross3(P->Rr + 3 * k, e[i], rc);
      mv3(A, rc, dg + 3 * (7 + k));
    }
  }
}

// jac[0..n1) += sum_a v_a d[a + 3 i]  (v' d for a 3 x n derivative)
static void vtd(const double *v, const double *d, int n, double f, double *jac) {
  for (int i = 0; i < n; i++)
    jac[i] += f * (v[0] * d[3 * i] + v[1] * d[3 * i + 1] + v[2] * d[3 * i + 2]);
}

// equation primitives; jac has s1->n + s2->n entries (side 1 first)
static double eq_pos(const side *s1, const side *s2, int a, double *jac) {
  if (jac) {
    memset(jac, 0, sizeof(double) * (size_t)(s1->n + s2->n));
    for (int i = 0; i < s1->n; i++) jac[i] = s1->dr[a + 3 * i];
    for (int i = 0; i < s2->n; i++) jac[s1->n + i] = -s2->dr[a + 3 * i];
  }
  return s1->r[a] - s2->r[a];
}
static double eq_dot(const side *s1, int i1, const side *s2, int i2, double *jac) {
  if (jac) {
    memset(jac, 0, sizeof(double) * (size_t)(s1->n + s2->n));
    vtd(s2->g[i2], s1->dg[i1], s1->n, 1, jac);
    vtd(s1->g[i1], s2->dg[i2], s2->n, 1, jac + s1->n);
  }
  return dot3(s1->g[i1], s2->g[i2]);
}
// (r2 - r1) . g1[i1]
static double eq_dd(const side *s1, int i1, const side *s2, double *jac) {
  double d[3] = {s2->r[0] - s1->r[0], s2->r[1] - s1->r[1], s2->r[2] - s1->r[2]};
  if (jac) {
    memset(jac, 0, sizeof(double) * (size_t)(s1->n + s2->n));
    vtd(d, s1->dg[i1], s1->n, 1, jac);
    vtd(s1->g[i1], s1->dr, s1->n, -1, jac);
    vtd(s1->g[i1], s2->dr, s2->n, 1, jac + s1->n);
  }
  return dot3(d, s1->g[i1]);
}

// the meaning of joint equation k (0-based)
static const char *joint_eq_meaning(int kind, int k) {
  static const char *sph[] = {"x of r1 - r2", "y of r1 - r2", "z of r1 - r2"};
  static const char *rev[] = {"x of r1 - r2", "y of r1 - r2", "z of r1 - r2", "axis z1 . x2",
                              "axis z1 . y2"};
  static const char *uni[] = {"x of r1 - r2", "y of r1 - r2", "z of r1 - r2", "cross axes a1 . a2"};
  static const char *cyl[] = {"axis z1 . x2", "axis z1 . y2", "offset d . x1", "offset d . y1"};
  static const char *pri[] = {"axis z1 . x2", "axis z1 . y2", "offset d . x1", "offset d . y1",
                              "twist x1 . y2"};
  static const char *fix[] = {"x of r1 - r2", "y of r1 - r2", "z of r1 - r2",
                              "z1 . x2",      "z1 . y2",      "x1 . y2"};
  switch (kind) {
    case FMBD_MBS_SPHERICAL:
      return k < 3 ? sph[k] : "?";
    case FMBD_MBS_REVOLUTE:
      return k < 5 ? rev[k] : "?";
    case FMBD_MBS_UNIVERSAL:
      return k < 4 ? uni[k] : "?";
    case FMBD_MBS_CYLINDRICAL:
      return k < 4 ? cyl[k] : "?";
    case FMBD_MBS_PRISMATIC:
      return k < 5 ? pri[k] : "?";
    case FMBD_MBS_FIXED:
      return k < 6 ? fix[k] : "?";
    default:
      return "?";
  }
}

void mbs_eq_describe(const fmbd_mbs *m, const meq *e, char *buf, size_t len) {
  if (e->kind == EQ_JOINT) {
    const mjoint *j = &m->j[e->owner];
    snprintf(buf, len, "joint '%s' equation %d (%s %s)", j->name, e->sub + 1,
             mbs_joint_kind_name(j->kind), joint_eq_meaning(j->kind, e->sub));
  } else if (e->kind == EQ_DRIVER) {
    const mdriver *d = &m->d[e->owner];
    if (d->joint >= 0) {
      snprintf(buf, len, "driver '%s' (coordinate of joint '%s')", d->name, m->j[d->joint].name);
    } else {
      snprintf(buf, len, "driver '%s' (coordinate %d of body '%s')", d->name, d->coord,
               m->b[d->body].name);
    }
  } else {
    snprintf(buf, len, "Euler-parameter normalisation of body '%s'", m->b[e->owner].name);
  }
}

static void side_bind(fmbd_mbs *m, side *s, int which) {
  double *w = m->wk + (size_t)which * 15 * (size_t)m->maxn;
  s->dr = w;
  for (int i = 0; i < 4; i++) s->dg[i] = w + (size_t)(3 + 3 * i) * (size_t)m->maxn;
}

// the joint's two sides, with the directions of the masks w1, w2 (side_eval)
static void joint_sides(fmbd_mbs *m, const mjoint *j, const double *x, unsigned w1, unsigned w2,
                        bool deriv, side *s1, side *s2) {
  side_bind(m, s1, 0);
  side_bind(m, s2, 1);
  double e2[4][3];
  memcpy(e2, j->e[1], sizeof(double) * 9);
  memcpy(e2[3], j->a2, sizeof(double) * 3);
  side_eval(m, j->pt[0], (const double(*)[3])j->e[0], 3, w1, x, deriv, s1);
  side_eval(m, j->pt[1], (const double(*)[3])e2, j->kind == FMBD_MBS_UNIVERSAL ? 4 : 3, w2, x,
            deriv, s2);
}
void mbs_joint_sides(fmbd_mbs *m, const mjoint *j, const double *x, side *s1, side *s2) {
  joint_sides(m, j, x, 15, 15, true, s1, s2);
}

// The generalized force of one side, (dr/dx)' F + sum_i (dg_i/dx)' M_i over the side's n
// coordinates into gf (directions in the mask want; e: their local vectors), from the side's
// kinematics alone (side_eval without deriv): R: F; p_c: -2/|p| (A G)_c . tau with
// tau = F x (A u) + sum_i M_i x g_i (side_eval's d(A v)/dp = -2/|p| (A v) x (A G)_c and
// a . (b x c) = c . (a x b)); modal k: (A'F) . T_k + sum_i (A'M_i) . (Rr_k x e_i)
static void side_force(const fmbd_mbs *m, int pt, const side *s, const double (*e)[3], int nv,
                       unsigned want, const double *F, const double (*M)[3], double *gf) {
  if (s->n == 0) return;
  const mpoint *P = &m->p[pt];
  const int nm = s->n - 7;
  double tau[3], t[3];
  cross3(F, s->Au, tau);
  for (int i = 0; i < nv; i++) {
    if (!(want >> i & 1)) continue;
    cross3(M[i], s->g[i], t);
    for (int a = 0; a < 3; a++) tau[a] += t[a];
  }
  for (int a = 0; a < 3; a++) gf[a] = F[a];
  for (int c = 0; c < 4; c++)
    gf[3 + c] = s->f * (s->AG[c] * tau[0] + s->AG[4 + c] * tau[1] + s->AG[8 + c] * tau[2]);
  if (nm <= 0) return;
  double AF[3], AM[4][3];
  mtv3(s->A, F, AF);
  for (int i = 0; i < nv; i++) {
    if (want >> i & 1) mtv3(s->A, M[i], AM[i]);
  }
  for (int k = 0; k < nm; k++) {
    double v = dot3(AF, P->T + 3 * k);
    for (int i = 0; i < nv; i++) {
      if (!(want >> i & 1)) continue;
      double rc[3];
      cross3(P->Rr + 3 * k, e[i], rc);
      v += dot3(AM[i], rc);
    }
    gf[7 + k] = v;
  }
}

// the directions each kind's equations use (mbs_eval_constraints), as side_eval masks: side 1
// in the low, side 2 in the high 4 bits. A revolute joint needs 3 of the 6: half the
// derivatives d(A g)/dp of the rigid chain's constraint evaluation
static unsigned joint_dirs(int kind) {
  switch (kind) {
    case FMBD_MBS_SPHERICAL:
      return 0;
    case FMBD_MBS_REVOLUTE:
      return 4 | 3 << 4;  // z1; x2, y2
    case FMBD_MBS_UNIVERSAL:
      return 4 | 8 << 4;  // z1; a2
    case FMBD_MBS_FIXED:
      return 5 | 3 << 4;  // x1, z1; x2, y2
    default:
      return 15 | 15 << 4;  // cylindrical, prismatic: x1, y1, z1; x2, y2
  }
}

// joint coordinate (revolute angle or slide) and its jacobian (may be NULL)
double mbs_joint_coord(const mjoint *j, const side *s1, const side *s2, double *jac) {
  if (j->kind == FMBD_MBS_REVOLUTE) {
    // theta = atan2(y1 . x2, x1 . x2)
    double sn = dot3(s1->g[1], s2->g[0]), cs = dot3(s1->g[0], s2->g[0]);
    double th = atan2(sn, cs);
    if (jac) {
      int nt = s1->n + s2->n;
      memset(jac, 0, sizeof(double) * (size_t)nt);
      double r2 = sn * sn + cs * cs;
      double fs = cs / r2, fc = -sn / r2;
      vtd(s2->g[0], s1->dg[1], s1->n, fs, jac);
      vtd(s1->g[1], s2->dg[0], s2->n, fs, jac + s1->n);
      vtd(s2->g[0], s1->dg[0], s1->n, fc, jac);
      vtd(s1->g[0], s2->dg[0], s2->n, fc, jac + s1->n);
    }
    return th;
  }
  return eq_dd(s1, 2, s2, jac);
}

// The form of joint equation k of a kind: EQ_POS (r1 - r2)_a with a = i1; EQ_DOT g1[i1] . g2[i2];
// EQ_DD (r2 - r1) . g1[i1]
enum { EQ_POS, EQ_DOT, EQ_DD };
static int joint_eq_form(int kind, int k, int *i1, int *i2) {
  *i1 = k, *i2 = 0;
  switch (kind) {
    case FMBD_MBS_SPHERICAL:
      return EQ_POS;
    case FMBD_MBS_REVOLUTE:
      if (k < 3) return EQ_POS;
      *i1 = 2, *i2 = k - 3;
      return EQ_DOT;
    case FMBD_MBS_UNIVERSAL:
      if (k < 3) return EQ_POS;
      *i1 = 2, *i2 = 3;
      return EQ_DOT;
    case FMBD_MBS_CYLINDRICAL:
    case FMBD_MBS_PRISMATIC:
      if (k < 2) {
        *i1 = 2, *i2 = k;
        return EQ_DOT;
      }
      if (k < 4) {
        *i1 = k - 2;
        return EQ_DD;
      }
      *i1 = 0, *i2 = 1;
      return EQ_DOT;
    case FMBD_MBS_FIXED:
      if (k < 3) return EQ_POS;
      if (k < 5) {
        *i1 = 2, *i2 = k - 3;
        return EQ_DOT;
      }
      *i1 = 0, *i2 = 1;
      return EQ_DOT;
    default:
      return -1;
  }
}

// Every equation's value and, with want_jac, its Jacobian at (x, t); with res, Phi_x' lambda
// of the kept equations added into res. Without want_jac the joints' part is formed without
// their Jacobians: an equation depends on x only through its sides' points r_s and directions
// g_s,i, so sum_k lam_k dPhi_k/dx = sum_s (dr_s/dx)' F_s + sum_i (dg_s,i/dx)' M_s,i with
// F_s = sum_k lam_k dPhi_k/dr_s and M_s,i = sum_k lam_k dPhi_k/dg_s,i (side_force): the
// residual of a Newton iteration without a new matrix needs no derivative arrays (a rigid
// chain: 3 x 4 products per side instead of 5 Jacobian rows of 14 entries and their scatter)
static void eval_eqs(fmbd_mbs *m, const double *x, double t, bool want_jac, double *res) {
  side s1, s2;
  int64_t e = 0;
  const bool force = res && !want_jac;
  for (int ij = 0; ij < m->nj; ij++) {
    const mjoint *j = &m->j[ij];
    unsigned dirs = joint_dirs(j->kind);
    joint_sides(m, j, x, dirs & 15, dirs >> 4, !force, &s1, &s2);
    double F1[3] = {0, 0, 0}, F2[3] = {0, 0, 0}, M1[4][3] = {{0}}, M2[4][3] = {{0}};
    const int64_t e0 = e;
    for (int k = 0; k < j->neq; k++, e++) {
      meq *q = &m->eq[e];
      double *jac = want_jac ? q->jac : NULL;
      int i1, i2, form = joint_eq_form(j->kind, k, &i1, &i2);
      double v = 0;
      if (form == EQ_POS)
        v = eq_pos(&s1, &s2, i1, jac);
      else if (form == EQ_DOT)
        v = eq_dot(&s1, i1, &s2, i2, jac);
      else if (form == EQ_DD)
        v = eq_dd(&s1, i1, &s2, jac);
      q->phi = v;
      if (!res || !q->kept) continue;
      const double lam = m->lam[q->row];
      if (!force) {
        mbs_eq_jtv(m, q, lam, res);
      } else if (form == EQ_POS) {
        F1[i1] += lam, F2[i1] -= lam;
      } else if (form == EQ_DOT) {
        for (int a = 0; a < 3; a++) M1[i1][a] += lam * s2.g[i2][a], M2[i2][a] += lam * s1.g[i1][a];
      } else if (form == EQ_DD) {
        for (int a = 0; a < 3; a++) {
          double lg = lam * s1.g[i1][a];
          F1[a] -= lg, F2[a] += lg;
          M1[i1][a] += lam * (s2.r[a] - s1.r[a]);
        }
      }
    }
    if (force && j->neq > 0) {  // the sides' forces (dr: scratch of 3 maxn >= n entries)
      double e2[4][3];
      memcpy(e2, j->e[1], sizeof(double) * 9);
      memcpy(e2[3], j->a2, sizeof(double) * 3);
      side_force(m, j->pt[0], &s1, (const double(*)[3])j->e[0], 3, dirs & 15, F1,
                 (const double(*)[3])M1, s1.dr);
      side_force(m, j->pt[1], &s2, (const double(*)[3])e2, j->kind == FMBD_MBS_UNIVERSAL ? 4 : 3,
                 dirs >> 4, F2, (const double(*)[3])M2, s2.dr);
      const int64_t *cols = m->eq[e0].cols;
      for (int i = 0; i < s1.n; i++) res[cols[i]] += s1.dr[i];
      for (int i = 0; i < s2.n; i++) res[cols[s1.n + i]] += s2.dr[i];
    }
  }
  const bool jac_all = want_jac || res != NULL;  // drivers and normalisation: through jac
  const int64_t ed = e;
  for (int id = 0; id < m->nd; id++, e++) {
    const mdriver *d = &m->d[id];
    meq *q = &m->eq[e];
    double f = fmbd_mbs_fn_eval(&d->f, t, NULL, NULL);
    if (d->joint >= 0) {
      const mjoint *j = &m->j[d->joint];
      mbs_joint_sides(m, j, x, &s1, &s2);
      double v = mbs_joint_coord(j, &s1, &s2, jac_all ? q->jac : NULL);
      q->phi = j->kind == FMBD_MBS_REVOLUTE ? remainder(v - f, 2 * M_PI) : v - f;
    } else {
      const mbody *b = &m->b[d->body];
      int c = d->coord < 3 ? d->coord : 7 + (d->coord - 3);
      q->phi = x[mbs_col(b, c)] - f;
      if (jac_all) {
        memset(q->jac, 0, sizeof(double) * (size_t)q->nj);
        for (int i = 0; i < q->nj; i++) {
          if (q->cols[i] == mbs_col(b, c)) q->jac[i] = 1;
        }
      }
    }
  }
  for (int ib = 0; ib < m->nb; ib++, e++) {
    const mbody *b = &m->b[ib];
    meq *q = &m->eq[e];
    const double *p = x + b->off + 3;
    q->phi = 0.5 * b->snorm * (p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3] - 1);
    if (jac_all) {
      memset(q->jac, 0, sizeof(double) * (size_t)q->nj);
      for (int c = 0; c < 4; c++) q->jac[3 + c] = b->snorm * p[c];
    }
  }
  if (!res) return;
  for (int64_t k = ed; k < m->neq; k++) {  // the drivers' and normalisations' Phi_x' lambda
    const meq *q = &m->eq[k];
    if (q->kept) mbs_eq_jtv(m, q, m->lam[q->row], res);
  }
}

void mbs_eval_constraints(fmbd_mbs *m, const double *x, double t, bool want_jac) {
  eval_eqs(m, x, t, want_jac, NULL);
}
void mbs_eval_constraints_res(fmbd_mbs *m, const double *x, double t, double *res) {
  eval_eqs(m, x, t, false, res);
}

// time derivatives of the prescribed part: Phi_t and Phi_tt of each equation
void mbs_eq_time_derivs(const fmbd_mbs *m, double t, int64_t e, double *ft, double *ftt) {
  const meq *q = &m->eq[e];
  *ft = 0, *ftt = 0;
  if (q->kind == EQ_DRIVER) {
    double d1, d2;
    fmbd_mbs_fn_eval(&m->d[q->owner].f, t, &d1, &d2);
    *ft = -d1, *ftt = -d2;
  }
}

// jac . v over the equation's coordinates
double mbs_eq_jv(const fmbd_mbs *m, const meq *q, const double *v) {
  double s = 0;
  for (int i = 0; i < q->nj; i++) s += q->jac[i] * v[q->cols[i]];
  return s;
}
// v[cols] += f * jac
void mbs_eq_jtv(const fmbd_mbs *m, const meq *q, double f, double *v) {
  for (int i = 0; i < q->nj; i++) v[q->cols[i]] += f * q->jac[i];
}
