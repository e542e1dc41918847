// common/fmbd_mbs_fe.c: full finite-element bodies in the floating frame of reference (every FE
// dof a coordinate; docs/THEORY.md section 4b), sparse throughout
// SPDX-License-Identifier: MIT
//
// The equations are those of a modal body (fmbd_mbs.h, EQUATIONS; mbs_body_eval) with the
// modes replaced by the FE dofs, S_k = the nodal interpolation of dof k. The invariants are
// never stored: with U = E q (nodal translations, nn x 3), W = Mn U, Y = Mn (x + U) the
// mass-weighted deformed positions and Vd = Mn E q',
//   c = c0 + 1'Mn U,  J = J0 + x'Mn U + U'Mn x + U'Mn U,  H_k,ab = (E_a' Y_b)_k,
//   H = sum_k q'_k H_k (H_ab = U'_a . Y_b),  M_wf q'' = sum_p Y_p x U''_p,
//   (M_wf' wd)_k = (E' (wd x Y))_k,  (w'H_k w - |w|^2 tr H_k)_k = (E' (w x (w x Y)))_k,
//   (2 w . sum_l q'_l int rho S_l x S_k)_k = (E' (2 w x Vd))_k,
// where E' z for a nodal field z (nn x 3) is sum_a E_a' z_a. Cost per evaluation: a few
// sparse products with E, E' and Mn, O(nnz); the n x n block is M, K, D on their pattern.
// Beams (fe_data S1, Mw0; docs/THEORY.md section 4b): the coupling that is linear in the
// accelerations at q = 0 comes from the body's consistent M instead: S1 = T'MS replaces 1'Mn U
// (c, S1 q', the rigid rows' and the flexible rows' translational coupling, gravity), and
// dv = R'MS - E'(e_a x Mn x) is added to the antisymmetric part of each H_k (M_wf, the rigid
// rows' H, the flexible rows' M_wf' wd); the symmetric part of H_k (J(q), the centrifugal
// terms) and the terms in U'Mn U keep Mn, as a modal body's XS and SS do (section 9).
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"

void mbs_fe_free(mbs_fe **pf) {
  if (!pf || !*pf) return;
  mbs_fe *f = *pf;
  fmbd_csr_destroy(&f->E), fmbd_csr_destroy(&f->Et), fmbd_csr_destroy(&f->Mn);
  fmbd_csr_destroy(&f->P);
  fmbd_free(f->Gv);
  double *arrs[] = {f->x,   f->m1, f->mx, f->S1, f->dv, f->Mv, f->Kv, f->Dv, f->U, f->Ud,
                    f->Udd, f->W,  f->Vd, f->Y,  f->z,  f->v1, f->h,  f->cu, f->cl};
  for (size_t i = 0; i < sizeof arrs / sizeof arrs[0]; i++) fmbd_free(arrs[i]);
  fmbd_free(f->dofs), fmbd_free(f->pu), fmbd_free(f->pl), fmbd_free(f->pff);
  fmbd_free(f);
  *pf = NULL;
}

// y = E' z: z a nodal field (nn x 3, column-major), y (n)
static void et_apply(const mbs_fe *f, const double *z, double *y) {
  fmbd_csr_matvec(f->Et, z, y);
}
// y_a = E_a' z for a nodal scalar z (nn): three n-vectors y[k + n a]
static void et_split(const mbs_fe *f, int64_t n, const double *z, double *y) {
  const fmbd_csr *A = f->Et;
  const int64_t nn = f->nn;
  for (int64_t k = 0; k < n; k++) {
    double s[3] = {0, 0, 0};
    for (int64_t e = A->indptr[k]; e < A->indptr[k + 1]; e++) {
      int64_t c = A->indices[e], a = c / nn;
      s[a] += A->data[e] * z[c - a * nn];
    }
    y[k] = s[0], y[k + n] = s[1], y[k + 2 * n] = s[2];
  }
}
// z = u x v node by node (nn x 3 fields; u may be a constant 3-vector with ldu 0)
static void field_cross(int64_t nn, const double *u, int64_t ldu, const double *v, double *z) {
  for (int64_t p = 0; p < nn; p++) {
    const double *up = u + (ldu ? p : 0);
    double a0 = up[0], a1 = up[ldu], a2 = up[2 * ldu];
    if (!ldu) a1 = u[1], a2 = u[2];
    double b0 = v[p], b1 = v[p + nn], b2 = v[p + 2 * nn];
    z[p] = a1 * b2 - a2 * b1;
    z[p + nn] = a2 * b0 - a0 * b2;
    z[p + 2 * nn] = a0 * b1 - a1 * b0;
  }
}
static double dotn(int64_t n, const double *a, const double *b) {
  double s = 0;
  for (int64_t i = 0; i < n; i++) s += a[i] * b[i];
  return s;
}
// y = P-matrix with values v times x (n)
static void pat_mv(const fmbd_csr *P, const double *v, const double *x, double *y) {
  for (int64_t i = 0; i < P->nrows; i++) {
    double s = 0;
    for (int64_t e = P->indptr[i]; e < P->indptr[i + 1]; e++) s += v[e] * x[P->indices[e]];
    y[i] = s;
  }
}

// nodal fields of the state: U = E q, Ud = E q', (Udd = E q''), W = Mn U, Vd = Mn Ud,
// Y = Mn x + W
static void fe_fields(mbs_fe *f, const double *q, const double *qd, const double *qdd) {
  const int64_t nn = f->nn;
  fmbd_csr_matvec(f->E, q, f->U);
  fmbd_csr_matvec(f->E, qd, f->Ud);
  if (qdd) fmbd_csr_matvec(f->E, qdd, f->Udd);
  fmbd_csr_matmat(f->Mn, 3, f->U, nn, f->W, nn);
  fmbd_csr_matmat(f->Mn, 3, f->Ud, nn, f->Vd, nn);
  for (int64_t i = 0; i < 3 * nn; i++) f->Y[i] = f->mx[i] + f->W[i];
}

// y = sum_k v_k u_k for a 3 x n array v (v[a + 3k]), n-vector u
static void sum3(int64_t n, const double *v, const double *u, double *y) {
  y[0] = y[1] = y[2] = 0;
  for (int64_t k = 0; k < n; k++) {
    y[0] += v[3 * k] * u[k], y[1] += v[3 * k + 1] * u[k], y[2] += v[3 * k + 2] * u[k];
  }
}

// c, J (symmetrised), S1 q', H (a + 3b) of the state (fields computed)
static void fe_inertia(const mbody *b, const double *q, const double *qd, double *c, double *J,
                       double *s1qd, double *H) {
  const mbs_fe *f = b->fe;
  const int64_t nn = f->nn, n = b->nm;
  double s1q[3];
  sum3(n, f->S1, q, s1q);
  sum3(n, f->S1, qd, s1qd);
  for (int a = 0; a < 3; a++) {
    c[a] = b->c0[a] + s1q[a];
    for (int bb = 0; bb < 3; bb++) H[a + 3 * bb] = dotn(nn, f->Ud + nn * a, f->Y + nn * bb);
  }
  if (f->dv) {  // + skew(sum_k q'_k dv_k) / 2: eps_abc H_cb gains sum_k q'_k dv_k,a
    double u[3];
    sum3(n, f->dv, qd, u);
    H[1] += 0.5 * u[2], H[3] -= 0.5 * u[2];  // H_10, H_01
    H[6] += 0.5 * u[1], H[2] -= 0.5 * u[1];  // H_02, H_20
    H[5] += 0.5 * u[0], H[7] -= 0.5 * u[0];  // H_21, H_12
  }
  for (int a = 0; a < 3; a++) {
    for (int bb = a; bb < 3; bb++) {
      double v =
          dotn(nn, f->mx + nn * a, f->U + nn * bb) + dotn(nn, f->mx + nn * bb, f->U + nn * a) +
          0.5 * (dotn(nn, f->U + nn * a, f->W + nn * bb) + dotn(nn, f->U + nn * bb, f->W + nn * a));
      J[3 * a + bb] = J[3 * bb + a] = 0.5 * (b->J0[3 * a + bb] + b->J0[3 * bb + a]) + v;
    }
  }
}

void mbs_fe_eval(fmbd_mbs *m, int ib, double t, const double *xg, const double *xdg,
                 const double *xddg, double *r, double *Ax, double cm, double cc, double ck) {
  mbody *b = &m->b[ib];
  mbs_fe *f = b->fe;
  const int64_t n = b->nm, nn = f->nn;
  const double *x = xg + b->off, *xd = xdg + b->off, *xdd = xddg ? xddg + b->off : NULL;
  const double *p = x + 3, *q = x + 7, *pd = xd + 3, *qd = xd + 7, *qdd = xdd ? xdd + 7 : NULL;
  double *A = b->A, *G = b->G, w[3], wd[3];
  mbs_frame_kin(b, p, pd, xdd ? xdd + 3 : NULL, w, wd);
  fe_fields(f, q, qd, qdd);
  double *c = b->c, *J = b->J, *I = b->I, H[9], s1qd[3];
  fe_inertia(b, q, qd, c, J, s1qd, H);
  double trJ = J[0] + J[4] + J[8];
  for (int i = 0; i < 9; i++) I[i] = -J[i];
  I[0] += trJ, I[4] += trJ, I[8] += trJ;
  double trH = H[0] + H[4] + H[8];
  double Sc[9], Ac[9];
  skew3(c, Sc);
  mm3(A, Sc, Ac);  // A c~
  // --- rigid rows rb (6): quadratic velocity terms, gravity, loads, mass terms ---
  double rb[6], Iw[3];
  mbs_rigid_qv(A, w, c, s1qd, I, H, trH, rb, Iw);
  double gl[3], cg[3];
  mtv3(A, m->g, gl);
  cross3(c, gl, cg);
  for (int a = 0; a < 3; a++) rb[a] -= b->m * m->g[a], rb[3 + a] -= cg[a];
  double Rdd[3] = {0, 0, 0}, Rddl[3] = {0, 0, 0};
  if (xdd) {
    memcpy(Rdd, xdd, sizeof Rdd);
    mtv3(A, Rdd, Rddl);
    // m R'' - A c~ wd + A S1 q''; c~ A' R'' + I wd + Mwf q''
    double Acw[3], s1qdd[3], as[3], cA[3], Iwd[3], mwq[3] = {0, 0, 0};
    mv3(Ac, wd, Acw);
    sum3(n, f->S1, qdd, s1qdd);
    mv3(A, s1qdd, as);
    cross3(c, Rddl, cA);
    mv3(I, wd, Iwd);
    for (int64_t pp = 0; pp < nn; pp++) {
      double y0 = f->Y[pp], y1 = f->Y[pp + nn], y2 = f->Y[pp + 2 * nn];
      double u0 = f->Udd[pp], u1 = f->Udd[pp + nn], u2 = f->Udd[pp + 2 * nn];
      mwq[0] += y1 * u2 - y2 * u1, mwq[1] += y2 * u0 - y0 * u2, mwq[2] += y0 * u1 - y1 * u0;
    }
    if (f->dv) {
      double dq[3];
      sum3(n, f->dv, qdd, dq);
      for (int a = 0; a < 3; a++) mwq[a] += dq[a];
    }
    for (int a = 0; a < 3; a++) {
      rb[a] += b->m * Rdd[a] - Acw[a] + as[a];
      rb[3 + a] += cA[a] + Iwd[a] + mwq[a];
    }
  }
  // --- flexible rows: E' z + M q'' + K q + D q' - loads ---
  double *rf = r + 7;
  {
    double *z = f->z, *tmp = f->W;  // W is no longer needed: reuse for w x Y
    field_cross(nn, w, 0, f->Y, tmp);
    field_cross(nn, w, 0, tmp, z);  // w x (w x Y)
    field_cross(nn, w, 0, f->Vd, tmp);
    for (int64_t i = 0; i < 3 * nn; i++) z[i] += 2 * tmp[i];
    if (xdd) {
      field_cross(nn, wd, 0, f->Y, tmp);
      for (int64_t i = 0; i < 3 * nn; i++) z[i] += tmp[i];
    }
    et_apply(f, z, rf);
    // + S1' (R''_l - g_l) (+ dv' wd)
    double s[3];
    for (int a = 0; a < 3; a++) s[a] = Rddl[a] - gl[a];
    for (int64_t k = 0; k < n; k++) {
      rf[k] += dot3(f->S1 + 3 * k, s);
      if (f->dv && xdd) rf[k] += dot3(f->dv + 3 * k, wd);
    }
    // + K q + D q' + M q'' in one pass over the pattern
    const fmbd_csr *P = f->P;
    for (int64_t i = 0; i < n; i++) {
      double sk = 0, sd = 0, sm = 0;
      for (int64_t e = P->indptr[i]; e < P->indptr[i + 1]; e++) {
        int64_t j = P->indices[e];
        sk += f->Kv[e] * q[j];
        sd += f->Dv[e] * qd[j];
        if (qdd) sm += f->Mv[e] * qdd[j];
      }
      rf[i] += sk + sd + sm;
    }
  }
  mbs_body_loads(m, ib, t, A, q, rb, rf);
  mbs_rigid_rows(b, rb, p, xdd ? xdd + 3 : NULL, r);
  const double mu = PMASS * b->snorm;
  if (!Ax) return;
  // --- the block: Z = cm Mb + cc Cb + ck K in [R, wb, q'] (6 + n), then B = T' Z T ---
  double Z6[36] = {0};  // 6 x 6 column-major
#define Z(i, j) Z6[(i) + 6 * (j)]
  for (int a = 0; a < 3; a++) {
    Z(a, a) = cm * b->m;
    for (int bb = 0; bb < 3; bb++) {
      Z(a, 3 + bb) = -cm * Ac[3 * a + bb];
      Z(3 + bb, a) = -cm * Ac[3 * a + bb];
      Z(3 + a, 3 + bb) = cm * I[3 * a + bb];
    }
  }
  double *cu = f->cu, *cl = f->cl;  // cu[i + 6k] = Z(i, 6 + k), cl[i + 6k] = Z(6 + k, i)
  // mass coupling: Z(a, 6+k) = (A S1_k)_a, Z(3+a, 6+k) = Mw_k,a = (E'(e_a x Y))_k, symmetric
  for (int64_t k = 0; k < n; k++) {
    double as[3];
    mv3(A, f->S1 + 3 * k, as);
    for (int a = 0; a < 3; a++) cu[a + 6 * k] = cm * as[a];
  }
  for (int a = 0; a < 3; a++) {
    double e[3] = {0, 0, 0};
    e[a] = 1;
    field_cross(nn, e, 0, f->Y, f->z);
    et_apply(f, f->z, f->v1);
    for (int64_t k = 0; k < n; k++)
      cu[3 + a + 6 * k] = cm * (f->v1[k] + (f->dv ? f->dv[a + 3 * k] : 0.0));
  }
  memcpy(cl, cu, sizeof(double) * (size_t)(6 * n));
  if (cc != 0) {
    // rigid velocity tangent (as mbs_body_eval)
    double AM[9], WW[9];
    mbs_rigid_vel_tangent(A, w, c, Sc, s1qd, I, Iw, H, trH, AM, WW);
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        Z(a, 3 + bb) += cc * AM[3 * a + bb];
        Z(3 + a, 3 + bb) += cc * WW[3 * a + bb];
      }
    }
    // coupling (mbs_body_eval's, with H_k from the fields): trk = tr H_k = (E'Y)_k,
    // hkw_a = (H_k w)_a = (E_a'(Y w))_k, hktw_a = (H_k' w)_a = (E'(w Y_a))_k,
    // cor_a = (E'(e_a x Vd))_k
    double *trk = f->h, *hkw = f->h + n, *hktw = f->h + 4 * n, *cor = f->h + 7 * n;
    et_apply(f, f->Y, trk);
    for (int64_t pp = 0; pp < nn; pp++)
      f->z[pp] = f->Y[pp] * w[0] + f->Y[pp + nn] * w[1] + f->Y[pp + 2 * nn] * w[2];
    et_split(f, n, f->z, hkw);
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        for (int64_t pp = 0; pp < nn; pp++) f->z[pp + nn * bb] = w[bb] * f->Y[pp + nn * a];
      }
      et_apply(f, f->z, hktw + n * a);
      double e[3] = {0, 0, 0};
      e[a] = 1;
      field_cross(nn, e, 0, f->Vd, f->z);
      et_apply(f, f->z, cor + n * a);
    }
    for (int64_t k = 0; k < n; k++) {
      double ws[3], aws[3], dw[3] = {0, 0, 0};
      cross3(w, f->S1 + 3 * k, ws);
      mv3(A, ws, aws);
      if (f->dv) cross3(f->dv + 3 * k, w, dw);  // H_k w gains (dv_k x w) / 2; H_k' w loses it
      for (int a = 0; a < 3; a++) {
        double hk = hkw[k + n * a], ht = hktw[k + n * a], co = cor[k + n * a];
        cu[a + 6 * k] += cc * 2 * aws[a];
        cu[3 + a + 6 * k] += cc * (2 * (trk[k] * w[a] - hk) - dw[a]);
        cl[3 + a + 6 * k] += cc * (hk + ht - 2 * trk[k] * w[a] + 2 * co);
      }
    }
  }
  // --- B = T' Z T into Ax (T = diag(1, 2G, 1)) ---
  double B7[49];  // column-major 7 x 7
  for (int j = 0; j < 7; j++) {
    double zc[6];  // column j of Z T
    if (j < 3) {
      for (int i = 0; i < 6; i++) zc[i] = Z(i, j);
    } else {
      int c4 = j - 3;
      for (int i = 0; i < 6; i++)
        zc[i] = 2 * (Z(i, 3) * G[c4] + Z(i, 4) * G[4 + c4] + Z(i, 5) * G[8 + c4]);
    }
    B7[0 + 7 * j] = zc[0], B7[1 + 7 * j] = zc[1], B7[2 + 7 * j] = zc[2];
    for (int c4 = 0; c4 < 4; c4++)
      B7[3 + c4 + 7 * j] = 2 * (G[c4] * zc[3] + G[4 + c4] * zc[4] + G[8 + c4] * zc[5]);
  }
  for (int i = 0; i < 4; i++) {
    for (int j = 0; j < 4; j++) B7[(3 + i) + 7 * (3 + j)] += cm * mu * p[i] * p[j];
  }
  for (int i = 0; i < 49; i++) Ax[f->pos7[i]] += B7[i];
  for (int64_t k = 0; k < n; k++) {
    const double *u = cu + 6 * k, *l = cl + 6 * k;
    int64_t *pu = f->pu + 7 * k, *pl = f->pl + 7 * k;
    for (int a = 0; a < 3; a++) Ax[pu[a]] += u[a], Ax[pl[a]] += l[a];
    for (int c4 = 0; c4 < 4; c4++) {
      Ax[pu[3 + c4]] += 2 * (G[c4] * u[3] + G[4 + c4] * u[4] + G[8 + c4] * u[5]);
      Ax[pl[3 + c4]] += 2 * (G[c4] * l[3] + G[4 + c4] * l[4] + G[8 + c4] * l[5]);
    }
  }
  const int64_t nnz = f->P->indptr[n];
  const double g0 = 2 * cc * w[0], g1 = 2 * cc * w[1], g2 = 2 * cc * w[2];
  const double *G0 = f->Gv, *G1 = f->Gv + nnz, *G2 = f->Gv + 2 * nnz;
  for (int64_t e = 0; e < nnz; e++)
    Ax[f->pff[e]] +=
        cm * f->Mv[e] + cc * f->Dv[e] + ck * f->Kv[e] + g0 * G0[e] + g1 * G1[e] + g2 * G2[e];
#undef Z
}

int64_t mbs_fe_nnz(const mbody *b) {
  return 49 + 14 * b->nm + b->fe->P->indptr[b->nm];
}

void mbs_fe_entries(const mbody *b, int64_t *rows, int64_t *cols) {
  const mbs_fe *f = b->fe;
  const int64_t n = b->nm;
  int64_t s = 0;
  for (int j = 0; j < 7; j++) {
    for (int i = 0; i < 7; i++, s++) rows[s] = i, cols[s] = j;
  }
  for (int64_t k = 0; k < n; k++) {
    for (int i = 0; i < 7; i++, s++) rows[s] = i, cols[s] = 7 + k;
    for (int i = 0; i < 7; i++, s++) rows[s] = 7 + k, cols[s] = i;
  }
  for (int64_t i = 0; i < n; i++) {
    for (int64_t e = f->P->indptr[i]; e < f->P->indptr[i + 1]; e++, s++)
      rows[s] = 7 + i, cols[s] = 7 + f->P->indices[e];
  }
}

void mbs_fe_set_positions(mbody *b, const int64_t *pos) {
  mbs_fe *f = b->fe;
  const int64_t n = b->nm;
  int64_t s = 0;
  for (int i = 0; i < 49; i++) f->pos7[i] = pos[s++];
  for (int64_t k = 0; k < n; k++) {
    for (int i = 0; i < 7; i++) f->pu[i + 7 * k] = pos[s++];
    for (int i = 0; i < 7; i++) f->pl[i + 7 * k] = pos[s++];
  }
  const int64_t nnz = f->P->indptr[n];
  for (int64_t e = 0; e < nnz; e++) f->pff[e] = pos[s++];
}

void mbs_fe_block_mul(const mbody *b, const double *Ax, const double *v, double *y) {
  const mbs_fe *f = b->fe;
  const int64_t n = b->nm;
  for (int j = 0; j < 7; j++) {
    for (int i = 0; i < 7; i++) y[i] += Ax[f->pos7[i + 7 * j]] * v[j];
  }
  for (int64_t k = 0; k < n; k++) {
    for (int i = 0; i < 7; i++) {
      y[i] += Ax[f->pu[i + 7 * k]] * v[7 + k];
      y[7 + k] += Ax[f->pl[i + 7 * k]] * v[i];
    }
  }
  for (int64_t i = 0; i < n; i++) {
    double s = 0;
    for (int64_t e = f->P->indptr[i]; e < f->P->indptr[i + 1]; e++)
      s += Ax[f->pff[e]] * v[7 + f->P->indices[e]];
    y[7 + i] += s;
  }
}

void mbs_fe_inert(const fmbd_mbs *m, int ib, double *c, double *I, double *S1qd, double *Mwfqd,
                  double *Tq, double *strain) {
  mbody *b = (mbody *)&m->b[ib];
  mbs_fe *f = b->fe;
  const int64_t n = b->nm, nn = f->nn;
  const double *q = m->x + b->off + 7, *qd = m->xd + b->off + 7;
  fe_fields(f, q, qd, NULL);
  double J[9], H[9];
  fe_inertia(b, q, qd, c, J, S1qd, H);
  double tr = J[0] + J[4] + J[8];
  for (int i = 0; i < 9; i++) I[i] = -J[i];
  I[0] += tr, I[4] += tr, I[8] += tr;
  // Mwf q' = sum_p Y_p x U'_p
  Mwfqd[0] = Mwfqd[1] = Mwfqd[2] = 0;
  for (int64_t pp = 0; pp < nn; pp++) {
    double y0 = f->Y[pp], y1 = f->Y[pp + nn], y2 = f->Y[pp + 2 * nn];
    double u0 = f->Ud[pp], u1 = f->Ud[pp + nn], u2 = f->Ud[pp + 2 * nn];
    Mwfqd[0] += y1 * u2 - y2 * u1, Mwfqd[1] += y2 * u0 - y0 * u2, Mwfqd[2] += y0 * u1 - y1 * u0;
  }
  if (f->dv) {
    double dq[3];
    sum3(n, f->dv, qd, dq);
    for (int a = 0; a < 3; a++) Mwfqd[a] += dq[a];
  }
  pat_mv(f->P, f->Mv, qd, f->v1);
  *Tq = dotn(n, qd, f->v1);
  pat_mv(f->P, f->Kv, q, f->v1);
  *strain = 0.5 * dotn(n, q, f->v1);
}

// values of A on the pattern P (rows merged): v[e] = A(i, P->indices[e])
static void on_pattern(const fmbd_csr *P, const fmbd_csr *A, double *v) {
  for (int64_t i = 0; i < P->nrows; i++) {
    int64_t ea = A->indptr[i];
    for (int64_t e = P->indptr[i]; e < P->indptr[i + 1]; e++) {
      while (ea < A->indptr[i + 1] && A->indices[ea] < P->indices[e]) ea++;
      v[e] = ea < A->indptr[i + 1] && A->indices[ea] == P->indices[e] ? A->data[ea] : 0.0;
    }
  }
}

// the union of the patterns of up to three n x n matrices (NULL skipped)
static int union_pattern(int64_t n, const fmbd_csr *const *A, int na, fmbd_csr **out) {
  int64_t nnz = 0;
  for (int i = 0; i < na; i++) nnz += A[i] ? A[i]->indptr[n] : 0;
  FMBD_CALL(fmbd_csr_create(n, n, nnz, out));
  fmbd_csr *P = *out;
  int64_t s = 0;
  P->indptr[0] = 0;
  for (int64_t r = 0; r < n; r++) {
    int64_t e[3] = {0, 0, 0};
    for (int i = 0; i < na; i++) e[i] = A[i] ? A[i]->indptr[r] : 0;
    for (;;) {
      int64_t next = INT64_MAX;
      for (int i = 0; i < na; i++) {
        if (A[i] && e[i] < A[i]->indptr[r + 1] && A[i]->indices[e[i]] < next)
          next = A[i]->indices[e[i]];
      }
      if (next == INT64_MAX) break;
      for (int i = 0; i < na; i++) {
        if (A[i] && e[i] < A[i]->indptr[r + 1] && A[i]->indices[e[i]] == next) e[i]++;
      }
      P->indices[s] = next;
      P->data[s++] = 0;
    }
    P->indptr[r + 1] = s;
  }
  return FMBD_OK;
}

// Gv[. + nnz a] = sum_bc eps_abc X^cb on the pattern P, X^cb = E_c' Mn E_b (entries of X off
// P are dropped: for solids and beams X's pattern lies within K's)
static int gyro_values(mbs_fe *f, int64_t n, int64_t nnz) {
  int rc = FMBD_OK;
  const int64_t nn = f->nn;
  fmbd_csr *Ec[3] = {NULL, NULL, NULL}, *Ect[3] = {NULL, NULL, NULL}, *B = NULL, *X = NULL;
  int64_t *rows = NULL, *cols = NULL;
  double *v = NULL;
  FMBD_GALLOC(f->Gv = fmbd_calloc((size_t)(3 * nnz) + 1, sizeof(double)));
  FMBD_GALLOC(rows = fmbd_malloc(sizeof(int64_t) * (size_t)nn));
  FMBD_GALLOC(cols = fmbd_malloc(sizeof(int64_t) * (size_t)n));
  FMBD_GALLOC(v = fmbd_malloc(sizeof(double) * (size_t)(nnz + 1)));
  for (int64_t k = 0; k < n; k++) cols[k] = k;
  for (int a = 0; a < 3; a++) {
    for (int64_t p = 0; p < nn; p++) rows[p] = a * nn + p;
    FMBD_GCALL(fmbd_csr_submatrix(f->E, nn, rows, n, cols, &Ec[a]));
    FMBD_GCALL(fmbd_csr_transpose(Ec[a], &Ect[a]));
  }
  for (int b = 0; b < 3; b++) {
    FMBD_GCALL(fmbd_csr_matmul(f->Mn, Ec[b], &B));  // Mn E_b
    for (int c = 0; c < 3; c++) {
      if (c == b) continue;
      FMBD_GCALL(fmbd_csr_matmul(Ect[c], B, &X));  // E_c' Mn E_b
      on_pattern(f->P, X, v);
      // eps_abc: a is the third index of (b, c)
      int a = 3 - b - c;
      double sg = ((a + 1) % 3 == b) ? 1.0 : -1.0;
      for (int64_t e = 0; e < nnz; e++) f->Gv[e + nnz * a] += sg * v[e];
      fmbd_csr_destroy(&X);
    }
    fmbd_csr_destroy(&B);
  }
done:
  for (int a = 0; a < 3; a++) fmbd_csr_destroy(&Ec[a]), fmbd_csr_destroy(&Ect[a]);
  fmbd_csr_destroy(&B), fmbd_csr_destroy(&X);
  fmbd_free(rows), fmbd_free(cols), fmbd_free(v);
  return rc;
}

int mbs_fe_create(const fmbd_mbs_fe_data *d, mbs_fe **out) {
  int rc = FMBD_OK;
  mbs_fe *f = NULL;
  *out = NULL;
  const int64_t n = d->n, nn = d->nnodes;
  FMBD_GALLOC(f = fmbd_calloc(1, sizeof *f));
  f->nn = nn;
  FMBD_GCALL(fmbd_csr_duplicate(d->E, &f->E));
  FMBD_GCALL(fmbd_csr_transpose(d->E, &f->Et));
  FMBD_GCALL(fmbd_csr_duplicate(d->Mn, &f->Mn));
  const fmbd_csr *mats[3] = {d->M, d->K, d->D};
  FMBD_GCALL(union_pattern(n, mats, 3, &f->P));
  int64_t nnz = f->P->indptr[n];
  size_t n3 = (size_t)(3 * nn);
  double **fields[] = {&f->x, &f->mx, &f->U, &f->Ud, &f->Udd, &f->W, &f->Vd, &f->Y, &f->z};
  for (size_t i = 0; i < sizeof fields / sizeof fields[0]; i++)
    FMBD_GALLOC(*fields[i] = fmbd_calloc(n3 + 1, sizeof(double)));
  FMBD_GALLOC(f->m1 = fmbd_calloc((size_t)nn + 1, sizeof(double)));
  FMBD_GALLOC(f->S1 = fmbd_calloc((size_t)(3 * n), sizeof(double)));
  FMBD_GALLOC(f->Mv = fmbd_calloc((size_t)nnz + 1, sizeof(double)));
  FMBD_GALLOC(f->Kv = fmbd_calloc((size_t)nnz + 1, sizeof(double)));
  FMBD_GALLOC(f->Dv = fmbd_calloc((size_t)nnz + 1, sizeof(double)));
  FMBD_GALLOC(f->v1 = fmbd_calloc((size_t)n, sizeof(double)));
  FMBD_GALLOC(f->h = fmbd_calloc((size_t)(10 * n), sizeof(double)));
  FMBD_GALLOC(f->cu = fmbd_calloc((size_t)(6 * n), sizeof(double)));
  FMBD_GALLOC(f->cl = fmbd_calloc((size_t)(6 * n), sizeof(double)));
  FMBD_GALLOC(f->pu = fmbd_calloc((size_t)(7 * n), sizeof(int64_t)));
  FMBD_GALLOC(f->pl = fmbd_calloc((size_t)(7 * n), sizeof(int64_t)));
  FMBD_GALLOC(f->pff = fmbd_calloc((size_t)nnz + 1, sizeof(int64_t)));
  on_pattern(f->P, d->M, f->Mv);
  on_pattern(f->P, d->K, f->Kv);
  if (d->D) on_pattern(f->P, d->D, f->Dv);
  FMBD_GCALL(gyro_values(f, n, nnz));
  if (d->dofs) {
    FMBD_GALLOC(f->dofs = fmbd_malloc(sizeof(int64_t) * (size_t)(2 * n)));
    memcpy(f->dofs, d->dofs, sizeof(int64_t) * (size_t)(2 * n));
  }
  for (int64_t p = 0; p < nn; p++) {
    for (int a = 0; a < 3; a++) f->x[p + nn * a] = d->node_xyz[a + 3 * p];
  }
  for (int64_t p = 0; p < nn; p++) f->z[p] = 1;
  fmbd_csr_matvec(f->Mn, f->z, f->m1);
  fmbd_csr_matmat(f->Mn, 3, f->x, nn, f->mx, nn);
  et_split(f, n, f->m1, f->h);
  for (int64_t k = 0; k < n; k++) {
    for (int a = 0; a < 3; a++) f->S1[a + 3 * k] = f->h[k + n * a];
  }
  if (d->S1) {  // the consistent coupling: S1 as given, dv = Mw0 - E'(e_a x Mn x)
    memcpy(f->S1, d->S1, sizeof(double) * (size_t)(3 * n));
    FMBD_GALLOC(f->dv = fmbd_malloc(sizeof(double) * (size_t)(3 * n)));
    for (int a = 0; a < 3; a++) {
      double e[3] = {0, 0, 0};
      e[a] = 1;
      field_cross(nn, e, 0, f->mx, f->z);
      et_apply(f, f->z, f->v1);
      for (int64_t k = 0; k < n; k++) f->dv[a + 3 * k] = d->Mw0[a + 3 * k] - f->v1[k];
    }
  }
  *out = f;
  f = NULL;
done:
  mbs_fe_free(&f);
  return rc;
}
