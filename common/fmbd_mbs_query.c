// common/fmbd_mbs_query.c: queries of the state: points, bodies, energy, momentum, reactions
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
// queries
// ============================================================================================
double fmbd_mbs_time(const fmbd_mbs *m) {
  return m->t;
}
int fmbd_mbs_nbodies(const fmbd_mbs *m) {
  return m->nb;
}
int fmbd_mbs_body_nm(const fmbd_mbs *m, int body) {
  return body >= 0 && body < m->nb ? m->b[body].nm : 0;
}
int fmbd_mbs_find_body(const fmbd_mbs *m, const char *name) {
  for (int i = 0; i < m->nb; i++) {
    if (strcmp(m->b[i].name, name) == 0) return i;
  }
  return -1;
}

// body kinematics at the current state: A, wb (body), wbd (body)
static void mbs_body_kin(const fmbd_mbs *m, const mbody *b, double *A, double *wb, double *wbd) {
  const double *x = m->x + b->off, *xd = m->xd + b->off, *xdd = m->xdd + b->off;
  double G[12];
  quat_to_A(x + 3, A);
  quat_G(x + 3, G);
  for (int a = 0; a < 3; a++) {
    wb[a] =
        2 * (G[4 * a] * xd[3] + G[4 * a + 1] * xd[4] + G[4 * a + 2] * xd[5] + G[4 * a + 3] * xd[6]);
    if (wbd)
      wbd[a] = 2 * (G[4 * a] * xdd[3] + G[4 * a + 1] * xdd[4] + G[4 * a + 2] * xdd[5] +
                    G[4 * a + 3] * xdd[6]);
  }
}

// local position u, modal velocity and acceleration of a point (body frame)
static void point_local(const fmbd_mbs *m, const mpoint *P, double *u, double *ud, double *udd) {
  const mbody *b = &m->b[P->body];
  const double *q = m->x + b->qoff, *qd = m->xd + b->qoff, *qdd = m->xdd + b->qoff;
  memcpy(u, P->x0, 3 * sizeof(double));
  for (int a = 0; a < 3; a++) ud[a] = udd[a] = 0;
  const int nk = P->sup ? P->nsup : b->nm;  // FE body: the coordinates that move the point
  for (int k = 0; k < nk; k++) {
    int64_t kk = P->sup ? P->sup[k] : k;
    for (int a = 0; a < 3; a++) {
      u[a] += P->T[a + 3 * k] * q[kk];
      ud[a] += P->T[a + 3 * k] * qd[kk];
      udd[a] += P->T[a + 3 * k] * qdd[kk];
    }
  }
}

void fmbd_mbs_point_position(const fmbd_mbs *m, int pid, double x[3]) {
  const mpoint *P = &m->p[pid];
  if (P->body < 0) {
    memcpy(x, P->x0, 3 * sizeof(double));
    return;
  }
  const mbody *b = &m->b[P->body];
  double A[9], u[3], ud[3], udd[3], Au[3];
  quat_to_A(m->x + b->off + 3, A);
  point_local(m, P, u, ud, udd);
  mv3(A, u, Au);
  for (int a = 0; a < 3; a++) x[a] = m->x[b->off + a] + Au[a];
}

void fmbd_mbs_point_velocity(const fmbd_mbs *m, int pid, double v[3]) {
  const mpoint *P = &m->p[pid];
  if (P->body < 0) {
    v[0] = v[1] = v[2] = 0;
    return;
  }
  const mbody *b = &m->b[P->body];
  double A[9], w[3], u[3], ud[3], udd[3], l[3], g[3];
  mbs_body_kin(m, b, A, w, NULL);
  point_local(m, P, u, ud, udd);
  cross3(w, u, l);
  for (int a = 0; a < 3; a++) l[a] += ud[a];
  mv3(A, l, g);
  for (int a = 0; a < 3; a++) v[a] = m->xd[b->off + a] + g[a];
}

void fmbd_mbs_point_acceleration(const fmbd_mbs *m, int pid, double acc[3]) {
  const mpoint *P = &m->p[pid];
  if (P->body < 0) {
    acc[0] = acc[1] = acc[2] = 0;
    return;
  }
  const mbody *b = &m->b[P->body];
  double A[9], w[3], wd[3], u[3], ud[3], udd[3], t1[3], t2[3], t3[3], t4[3], l[3], g[3];
  mbs_body_kin(m, b, A, w, wd);
  point_local(m, P, u, ud, udd);
  cross3(wd, u, t1);
  cross3(w, u, t2);
  cross3(w, t2, t3);
  cross3(w, ud, t4);
  for (int a = 0; a < 3; a++) l[a] = t1[a] + t3[a] + 2 * t4[a] + udd[a];
  mv3(A, l, g);
  for (int a = 0; a < 3; a++) acc[a] = m->xdd[b->off + a] + g[a];
}

void fmbd_mbs_body_pose(const fmbd_mbs *m, int body, double R[3], double A[9]) {
  const mbody *b = &m->b[body];
  if (R) memcpy(R, m->x + b->off, 3 * sizeof(double));
  if (A) quat_to_A(m->x + b->off + 3, A);
}

void fmbd_mbs_body_velocity(const fmbd_mbs *m, int body, double v[3], double w[3]) {
  const mbody *b = &m->b[body];
  double A[9], wb[3];
  mbs_body_kin(m, b, A, wb, NULL);
  if (v) memcpy(v, m->xd + b->off, 3 * sizeof(double));
  if (w) mv3(A, wb, w);
}

int64_t fmbd_mbs_modal(const fmbd_mbs *m, int body, const double **q, const double **qd,
                       const double **qdd) {
  const mbody *b = &m->b[body];
  if (q) *q = m->x + b->qoff;
  if (qd) *qd = m->xd + b->qoff;
  if (qdd) *qdd = m->xdd + b->qoff;
  return b->nm;
}

// per-body inertia quantities at the current state (c, I, Mwf, velocities)
typedef struct binert {
  double A[9], w[3], c[3], I[9], S1qd[3], Mwfqd[3];
  double Tq, U;  // FE body: q' M q', q' K q / 2
} binert;
static void body_inert(const fmbd_mbs *m, int ib, binert *o) {
  const mbody *b = &m->b[ib];
  const double *q = m->x + b->qoff, *qd = m->xd + b->qoff;
  mbs_body_kin(m, b, o->A, o->w, NULL);
  if (b->fe) {
    mbs_fe_inert(m, ib, o->c, o->I, o->S1qd, o->Mwfqd, &o->Tq, &o->U);
    return;
  }
  const int nm = b->nm;
  double J[9];
  memcpy(o->c, b->c0, sizeof o->c);
  memcpy(J, b->J0, sizeof J);
  for (int a = 0; a < 3; a++) o->S1qd[a] = o->Mwfqd[a] = 0;
  for (int k = 0; k < nm; k++) {
    const double *X = b->XS + 9 * k;
    for (int a = 0; a < 3; a++) {
      o->c[a] += b->S1[a + 3 * k] * q[k];
      o->S1qd[a] += b->S1[a + 3 * k] * qd[k];
      for (int bb = 0; bb < 3; bb++) J[3 * a + bb] += q[k] * (X[a + 3 * bb] + X[bb + 3 * a]);
    }
  }
  // second-order terms: sum_kl SS_ab,kl q_k q_l; Mwf q' = sum_k q'_k (XSx_k + sum_l q_l SSx_lk)
  // (partial inertia coupling: SS and SSx are zero, their terms left out)
  mbs_body_inert2(b, q, qd, J, o->Mwfqd);
  double tr = J[0] + J[4] + J[8];
  for (int i = 0; i < 9; i++) o->I[i] = -0.5 * (J[i] + J[(i % 3) * 3 + i / 3]);
  o->I[0] += tr, o->I[4] += tr, o->I[8] += tr;
}

void fmbd_mbs_energy(const fmbd_mbs *m, double *kinetic, double *potential, double *strain) {
  double T = 0, V = 0, U = 0;
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    binert o;
    body_inert(m, ib, &o);
    const double *Rd = m->xd + b->off, *q = m->x + b->qoff, *qd = m->xd + b->qoff;
    const int nm = b->nm;
    // T = 1/2 [R'; w; q']' Mb [R'; w; q']
    double Iw[3], Ac[9], Sc[9], v1[3], AS[3];
    mv3(o.I, o.w, Iw);
    skew3(o.c, Sc);
    mm3(o.A, Sc, Ac);
    mv3(Ac, o.w, v1);
    mv3(o.A, o.S1qd, AS);
    double Tq = 0;
    for (int k = 0; k < nm && !b->fe; k++) {  // diagonal Mff: the same sum without its zeros
      if (b->mdiag) {
        Tq += qd[k] * b->Mff[k + (size_t)nm * k] * qd[k];
        continue;
      }
      for (int l = 0; l < nm; l++) Tq += qd[k] * b->Mff[k + (size_t)nm * l] * qd[l];
    }
    if (b->fe) Tq = o.Tq, U += o.U;
    T += 0.5 * (b->m * dot3(Rd, Rd) + dot3(o.w, Iw) + Tq) - dot3(Rd, v1) + dot3(Rd, AS) +
         dot3(o.w, o.Mwfqd);
    double Acw[3];
    mv3(o.A, o.c, Acw);
    V -= b->m * dot3(m->g, m->x + b->off) + dot3(m->g, Acw);
    for (int k = 0; k < nm && !b->fe; k++) {
      for (int l = 0; l < nm; l++) U += 0.5 * q[k] * b->Kff[k + (size_t)nm * l] * q[l];
    }
  }
  if (kinetic) *kinetic = T;
  if (potential) *potential = V;
  if (strain) *strain = U;
}

void fmbd_mbs_momentum(const fmbd_mbs *m, double L[3], double H[3]) {
  double Lt[3] = {0, 0, 0}, Ht[3] = {0, 0, 0};
  for (int ib = 0; ib < m->nb; ib++) {
    const mbody *b = &m->b[ib];
    binert o;
    body_inert(m, ib, &o);
    const double *R = m->x + b->off, *Rd = m->xd + b->off;
    double wc[3], lb[3], Lb[3];
    cross3(o.w, o.c, wc);
    for (int a = 0; a < 3; a++) lb[a] = wc[a] + o.S1qd[a];
    mv3(o.A, lb, Lb);
    for (int a = 0; a < 3; a++) Lb[a] += b->m * Rd[a];
    // H = R x Lb + (A c) x R' + A (I w + Mwf q')
    double t1[3], Acw[3], t2[3], hl[3], hw[3];
    cross3(R, Lb, t1);
    mv3(o.A, o.c, Acw);
    cross3(Acw, Rd, t2);
    mv3(o.I, o.w, hl);
    for (int a = 0; a < 3; a++) hl[a] += o.Mwfqd[a];
    mv3(o.A, hl, hw);
    for (int a = 0; a < 3; a++) Lt[a] += Lb[a], Ht[a] += t1[a] + t2[a] + hw[a];
  }
  if (L) memcpy(L, Lt, sizeof Lt);
  if (H) memcpy(H, Ht, sizeof Ht);
}

int fmbd_mbs_joint_reaction(const fmbd_mbs *m, int joint, double F[3], double T[3]) {
  FMBD_CHECK(m->ready, FMBD_ERR_VALUE, "joint reaction before fmbd_mbs_init");
  FMBD_CHECK(!m->set.linearise_only, FMBD_ERR_VALUE,
             "joint reaction: the model was initialised to be linearised only (no multipliers)");
  FMBD_CHECK(joint >= 0 && joint < m->nj, FMBD_ERR_VALUE, "unknown joint %d", joint);
  const mjoint *j = &m->j[joint];
  int side = j->body[0] >= 0 ? 0 : 1;
  int ib = j->body[side];
  const mbody *b = &m->b[ib];
  double *gf = m->res;  // scratch: generalized constraint force on all coordinates
  fmbd_mbs *mm = (fmbd_mbs *)m;
  memset(gf, 0, sizeof(double) * (size_t)m->n);
  mbs_eval_constraints(mm, m->x, m->t, true);
  for (int64_t e = 0; e < m->neq; e++) {
    const meq *q = &m->eq[e];
    if (!q->kept) continue;
    bool mine = (q->kind == EQ_JOINT && q->owner == joint) ||
                (q->kind == EQ_DRIVER && m->d[q->owner].joint == joint);
    if (mine) mbs_eq_jtv(m, q, -m->lam[q->row], gf);
  }
  const double *g = gf + b->off, *p = m->x + b->off + 3;
  double A[9], G[12], Nb[3], Nw[3];
  quat_to_A(p, A);
  quat_G(p, G);
  for (int a = 0; a < 3; a++)
    Nb[a] =
        0.5 * (G[4 * a] * g[3] + G[4 * a + 1] * g[4] + G[4 * a + 2] * g[5] + G[4 * a + 3] * g[6]);
  mv3(A, Nb, Nw);
  double rp[3], d[3], dxF[3];
  fmbd_mbs_point_position(m, j->pt[side], rp);
  for (int a = 0; a < 3; a++) d[a] = rp[a] - m->x[b->off + a];
  cross3(d, g, dxF);
  double sg = side == 0 ? 1 : -1;
  for (int a = 0; a < 3; a++) {
    F[a] = sg * g[a];
    T[a] = sg * (Nw[a] - dxF[a]);
  }
  return FMBD_OK;
}

int fmbd_mbs_joint_coordinate(const fmbd_mbs *m, int joint, double *value, double *rate) {
  FMBD_CHECK(m->ready, FMBD_ERR_VALUE, "joint coordinate before fmbd_mbs_init");
  FMBD_CHECK(joint >= 0 && joint < m->nj, FMBD_ERR_VALUE, "unknown joint %d", joint);
  const mjoint *j = &m->j[joint];
  FMBD_CHECK(j->kind == FMBD_MBS_REVOLUTE || j->kind == FMBD_MBS_PRISMATIC ||
                 j->kind == FMBD_MBS_CYLINDRICAL,
             FMBD_ERR_VALUE, "joint '%s' (%s) has no coordinate", j->name,
             mbs_joint_kind_name(j->kind));
  fmbd_mbs *mm = (fmbd_mbs *)m;
  side s1, s2;
  mbs_joint_sides(mm, j, m->x, &s1, &s2);
  double *buf = fmbd_malloc(sizeof(double) * (size_t)(s1.n + s2.n + 1));
  FMBD_CHECK(buf, FMBD_ERR_NOMEM, "out of memory");
  double v = mbs_joint_coord(j, &s1, &s2, buf);
  // the columns of the joint's equations (its first equation's)
  const meq *q = NULL;
  for (int64_t e = 0; e < m->neq && !q; e++) {
    if (m->eq[e].kind == EQ_JOINT && m->eq[e].owner == joint) q = &m->eq[e];
  }
  double r = 0;
  for (int i = 0; q && i < q->nj && i < s1.n + s2.n; i++) r += buf[i] * m->xd[q->cols[i]];
  fmbd_free(buf);
  if (value) *value = v;
  if (rate) *rate = r;
  return FMBD_OK;
}

void fmbd_mbs_constraint_residual(const fmbd_mbs *m, double *pos, double *vel) {
  fmbd_mbs *mm = (fmbd_mbs *)m;
  mbs_eval_constraints(mm, m->x, m->t, true);
  double p = 0, v = 0;
  for (int64_t e = 0; e < m->neq; e++) {
    const meq *q = &m->eq[e];
    if (q->kind == EQ_NORM) continue;
    double ft, ftt;
    mbs_eq_time_derivs(m, m->t, e, &ft, &ftt);
    p = fmax(p, fabs(q->phi));
    v = fmax(v, fabs(mbs_eq_jv(m, q, m->xd) + ft));
  }
  if (pos) *pos = p;
  if (vel) *vel = v;
}

double mbs_cpu_share(const fmbd_mbs *m, double wall, double cpu) {
  double dw = wall - m->tm_wall0;
  return m->tm_wall0 > 0 && dw > 0 ? fmin(1, (cpu - m->tm_cpu0) / dw) : 1;
}

void fmbd_mbs_get_stats(const fmbd_mbs *m, fmbd_mbs_stats *s) {
  *s = m->st;
  // the phases' wall time times the CPU share of the wall time of their window of 8 steps:
  // their CPU time when preemption falls on each phase in proportion to its length; a
  // preemption (milliseconds) inside a phase of microseconds then misplaces at most the
  // window's CPU time. A CPU-time clock is a system call (about 0.6 us on our VM, three
  // readings an iteration: +50 % on a 2-link NM run of 3 us iterations); the monotonic clock
  // reads in 65 ns, and the CPU clock is read once a window
  double f = mbs_cpu_share(m, fmbd_wall_s(), fmbd_cpu_s());
  s->factor_cpu_s = m->tm_cpu[0] + f * m->tm_phase[0];
  s->solve_cpu_s = m->tm_cpu[1] + f * m->tm_phase[1];
  s->eval_cpu_s = m->tm_cpu[2] + f * m->tm_phase[2];
}

int fmbd_mbs_redundant(const fmbd_mbs *m, int k, int *joint, int *eq, const char **text) {
  FMBD_CHECK(k >= 0 && k < m->nred, FMBD_ERR_VALUE, "no redundant equation %d", k);
  const meq *q = &m->eq[m->red[k]];
  if (joint) *joint = q->kind == EQ_JOINT ? q->owner : -1;
  if (eq) *eq = q->kind == EQ_JOINT ? q->sub + 1 : 1;
  if (text) *text = q->text;
  return FMBD_OK;
}
