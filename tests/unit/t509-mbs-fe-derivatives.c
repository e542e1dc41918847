// tests/unit/t509-mbs-fe-derivatives.c: white-box check of a full FE body (fmbd_mbs_add_fe,
// common/fmbd_mbs_fe.c) on a small random body spinning, deformed and loaded:
// (1) its residual equals that of a modal body whose modes are the FE dofs (S_k = E e_k) and
//     whose dense invariants S1, XS, SS, Mff, Kff are formed here from the same E, Mn, M, K
//     (docs/THEORY.md section 9): the sparse evaluation is the modal equations, term by term;
// (2) its iteration block, evaluated into the KLU matrix, against central finite differences
//     of the residual: the mass part d r / d x'' and the velocity part d r / d x' (complete:
//     the rigid and coupling terms and the deformation-deformation gyroscopic block
//     2 w . int rho S_l x S_k, plus the damping D). The stiffness part is K alone by design
//     (fmbd_mbs.h, the position derivatives of the inertia and load terms are not in the
//     tangent), so it is checked against K, not against finite differences;
// (3) fmbd_mbs_linearise with the FE body: its M, C, K rows are those blocks, in CSR.
// All three twice: with the coupling from Mn, and with a given S1 and Mw0 (a beam body's
// consistent coupling, docs/THEORY.md section 4b; random here), against the modal body with
// that S1 and the antisymmetric part of its XS_k set from Mw0 (section 9, as fmbd_rflex does).
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"

static double urand(unsigned *s) {
  *s = *s * 1103515245u + 12345u;
  return ((*s >> 8) & 0xffff) / 65535.0 - 0.5;
}

// a dense matrix (column-major) as CSR (all entries stored)
static fmbd_csr *dense_csr(int64_t nr, int64_t nc, const double *A) {
  fmbd_csr *C = NULL;
  if (fmbd_csr_create(nr, nc, nr * nc, &C)) return NULL;
  int64_t p = 0;
  for (int64_t i = 0; i < nr; i++) {
    for (int64_t j = 0; j < nc; j++) C->indices[p] = j, C->data[p++] = A[i + nr * j];
    C->indptr[i + 1] = p;
  }
  return C;
}

static double maxabs(const double *a, int64_t n) {
  double v = 0;
  for (int64_t i = 0; i < n; i++) v = fmax(v, fabs(a[i]));
  return v;
}

enum { NN = 5, NF = 10 };  // nodes; FE coordinates

static void one(int beam) {
  unsigned seed = 5;
  // --- a random body: nodes, SPD scalar mass Mn, map E (mostly a selection, one column that
  // moves several nodes in several directions as an interface's rotation does), SPD M, K ---
  double xyz[3 * NN], Mn[NN * NN] = {0}, E[3 * NN * NF] = {0}, M[NF * NF] = {0}, K[NF * NF] = {0};
  for (int i = 0; i < 3 * NN; i++) xyz[i] = 0.3 * urand(&seed) + (i % 3 == 0 ? 0.2 : 0);
  {
    double L[NN * NN];
    for (int i = 0; i < NN * NN; i++) L[i] = urand(&seed);
    for (int i = 0; i < NN; i++) {
      for (int j = 0; j < NN; j++) {
        double s = i == j ? 1.0 : 0.0;
        for (int k = 0; k < NN; k++) s += 0.2 * L[i + NN * k] * L[j + NN * k];
        Mn[i + NN * j] = s;
      }
    }
  }
  for (int k = 0; k < NF - 1; k++) {  // coordinate k: node 1 + k / 3, direction k % 3
    int p = 1 + k / 3, a = k % 3;
    E[(a * NN + p) + 3 * NN * k] = 1;
  }
  for (int r = 0; r < 3 * NN; r++) E[r + 3 * NN * (NF - 1)] = 0.5 * urand(&seed);
  {
    double A1[NF * NF], A2[NF * NF];
    for (int i = 0; i < NF * NF; i++) A1[i] = urand(&seed), A2[i] = urand(&seed);
    for (int i = 0; i < NF; i++) {
      for (int j = 0; j < NF; j++) {
        double s1 = i == j ? 1.0 : 0.0, s2 = i == j ? 50.0 : 0.0;
        for (int k = 0; k < NF; k++) s1 += 0.3 * A1[i + NF * k] * A1[j + NF * k];
        for (int k = 0; k < NF; k++) s2 += 20 * A2[i + NF * k] * A2[j + NF * k];
        M[i + NF * j] = s1, K[i + NF * j] = s2;
      }
    }
  }
  double mass = 0, c0[3] = {0}, J0[9] = {0}, ones[NN];
  for (int p = 0; p < NN; p++) ones[p] = 1;
  for (int p = 0; p < NN; p++) {
    for (int q = 0; q < NN; q++) {
      double mpq = Mn[p + NN * q];
      mass += mpq;
      for (int a = 0; a < 3; a++) {
        c0[a] += mpq * xyz[a + 3 * q];
        for (int b = 0; b < 3; b++) J0[a + 3 * b] += xyz[a + 3 * p] * mpq * xyz[b + 3 * q];
      }
    }
  }
  (void)ones;
  // --- the same body as modal invariants: S_k,a(node p) = E[(a NN + p), k] ---
  double S1[3 * NF] = {0}, XS[9 * NF] = {0}, SS[9 * NF * NF] = {0};
  for (int k = 0; k < NF; k++) {
    for (int a = 0; a < 3; a++) {
      for (int p = 0; p < NN; p++) {
        for (int q = 0; q < NN; q++) {
          double w = Mn[p + NN * q] * E[(a * NN + q) + 3 * NN * k];
          S1[a + 3 * k] += w;
          for (int b = 0; b < 3; b++) XS[b + 3 * a + 9 * k] += xyz[b + 3 * p] * w;
        }
      }
    }
    for (int l = 0; l < NF; l++) {
      for (int a = 0; a < 3; a++) {
        for (int b = 0; b < 3; b++) {
          double s = 0;
          for (int p = 0; p < NN; p++) {
            for (int q = 0; q < NN; q++)
              s += E[(a * NN + p) + 3 * NN * k] * Mn[p + NN * q] * E[(b * NN + q) + 3 * NN * l];
          }
          SS[a + 3 * b + 9 * k + 9 * NF * l] = s;
        }
      }
    }
  }
  // a given coupling: S1c, Mw0 random; the modal body's S1 = S1c, XS_k's antisymmetric part
  // from Mw0 (eps_abc XS_bc,k = Mw0_a,k: H_k,ab = XS_ba,k and Mw_a = eps_abc H_k,cb)
  double S1c[3 * NF], Mw0[3 * NF];
  for (int i = 0; i < 3 * NF; i++) S1c[i] = urand(&seed), Mw0[i] = 0.3 * urand(&seed);
  if (beam) {
    memcpy(S1, S1c, sizeof S1);
    for (int k = 0; k < NF; k++) {
      double *X = XS + 9 * k;
      for (int a = 0; a < 3; a++) {
        for (int b = a + 1; b < 3; b++) {
          double sym = 0.5 * (X[a + 3 * b] + X[b + 3 * a]);
          int c = 3 - a - b;
          double eps = (a + 1) % 3 == b ? 1.0 : -1.0;  // eps_abc
          X[a + 3 * b] = sym + 0.5 * eps * Mw0[c + 3 * k];
          X[b + 3 * a] = sym - 0.5 * eps * Mw0[c + 3 * k];
        }
      }
    }
  }
  fmbd_csr *cM = dense_csr(NF, NF, M), *cK = dense_csr(NF, NF, K), *cMn = dense_csr(NN, NN, Mn),
           *cE = dense_csr(3 * NN, NF, E), *cD = NULL;
  // damping D = 0.01 K (the modal body's damping is diagonal modal damping: set 0 there and
  // compare the residuals without it, below)
  double Dd[NF * NF];
  for (int i = 0; i < NF * NF; i++) Dd[i] = 0.01 * K[i];
  cD = dense_csr(NF, NF, Dd);
  fmbd_mbs *m = NULL;
  int rc = fmbd_mbs_create(&m), bf = -1, bm = -1, pf = -1;
  fmbd_mbs_state0 s0 = fmbd_mbs_state0_default();
  double ax[3] = {0.3, -0.5, 0.8};
  fmbd_mbs_rotation_axis_angle(ax, 0.7, s0.rotation);
  fmbd_mbs_fe_data fd = {.n = NF,
                         .mass = mass,
                         .M = cM,
                         .K = cK,
                         .D = NULL,
                         .nnodes = NN,
                         .node_xyz = xyz,
                         .Mn = cMn,
                         .E = cE,
                         .S1 = beam ? S1c : NULL,
                         .Mw0 = beam ? Mw0 : NULL};
  memcpy(fd.first_moment, c0, sizeof c0);
  memcpy(fd.second_moment, J0, sizeof J0);
  rc = rc ? rc : fmbd_mbs_add_fe(m, "fe", &fd, &s0, &bf);
  fmbd_mbs_flex_data md = {
      .nm = NF, .mass = mass, .S1 = S1, .XS = XS, .SS = SS, .Mff = M, .Kff = K};
  memcpy(md.first_moment, c0, sizeof c0);
  memcpy(md.second_moment, J0, sizeof J0);
  rc = rc ? rc : fmbd_mbs_add_flex(m, "modal", &md, &s0, &bm);
  // a load point on each (node 2's translation and the general column), and a follower force
  double T[3 * NF] = {0}, R[3 * NF] = {0}, x0[3];
  for (int k = 0; k < NF; k++) {
    for (int a = 0; a < 3; a++) T[a + 3 * k] = E[(a * NN + 2) + 3 * NN * k];
  }
  memcpy(x0, xyz + 6, sizeof x0);
  R[1 + 3 * (NF - 1)] = 0.7;
  int pm = -1;
  rc = rc ? rc : fmbd_mbs_add_point(m, bf, x0, T, R, &pf);
  rc = rc ? rc : fmbd_mbs_add_point(m, bm, x0, T, R, &pm);
  double dir[3] = {1, -2, 0.5};
  fmbd_mbs_fn fn = fmbd_mbs_fn_constant(3);
  rc = rc ? rc : fmbd_mbs_add_load(m, "ff", FMBD_MBS_FORCE, pf, true, dir, &fn, NULL);
  rc = rc ? rc : fmbd_mbs_add_load(m, "fm", FMBD_MBS_FORCE, pm, true, dir, &fn, NULL);
  rc = rc ? rc : fmbd_mbs_add_load(m, "tf", FMBD_MBS_TORQUE, pf, false, dir, &fn, NULL);
  rc = rc ? rc : fmbd_mbs_add_load(m, "tm", FMBD_MBS_TORQUE, pm, false, dir, &fn, NULL);
  double g[3] = {0.5, -9.81, 1.0};
  fmbd_mbs_set_gravity(m, g);
  fmbd_mbs_settings st;
  fmbd_mbs_settings_defaults(&st);
  rc = rc ? rc : fmbd_mbs_init(m, &st);
  EXPECT(rc == 0, "build: %s", fmbd_err_get()->msg);
  if (rc) return;
  // --- a spinning, deformed state, the same on both bodies ---
  const mbody *b0 = &m->b[bf], *b1 = &m->b[bm];
  int64_t n = m->n, nb = b0->n;
  double *x = fmbd_calloc((size_t)n, 8), *xd = fmbd_calloc((size_t)n, 8),
         *xdd = fmbd_calloc((size_t)n, 8), *r0 = fmbd_calloc((size_t)n, 8),
         *r1 = fmbd_calloc((size_t)n, 8);
  memcpy(x, m->x, sizeof(double) * (size_t)n);
  for (int64_t i = 0; i < nb; i++) {
    int64_t k = b0->off + i;
    if (i >= 7) x[k] = 0.05 * urand(&seed);
    if (i >= 3 && i < 7) x[k] += 0.05 * urand(&seed);  // |p| != 1: A(p/|p|) is used
    xd[k] = i >= 7 ? 0.5 * urand(&seed) : 3 * urand(&seed);
    xdd[k] = 10 * urand(&seed);
  }
  for (int64_t i = 0; i < nb; i++) {
    x[b1->off + i] = x[b0->off + i], xd[b1->off + i] = xd[b0->off + i];
    xdd[b1->off + i] = xdd[b0->off + i];
  }
  // (1) residuals, undamped (the modal body has none)
  mbs_fe_eval(m, bf, 0.2, x, xd, xdd, r0 + b0->off, NULL, 0, 0, 0);
  mbs_body_eval(m, bm, 0.2, x, xd, xdd, r1 + b1->off, NULL, 0, 0, 0, true);
  double err = 0, sc = maxabs(r1 + b1->off, nb);
  for (int64_t i = 0; i < nb; i++) err = fmax(err, fabs(r0[b0->off + i] - r1[b1->off + i]));
  // the same sums in another order: round-off, 1e-12 of the largest term
  EXPECT(err <= 1e-11 * fmax(1, sc), "FE residual vs modal residual: max diff %.3g (scale %.3g)",
         err, sc);
  // (2) the block against finite differences, damped (D replaced in the body's values)
  {
    mbs_fe *f = m->b[bf].fe;
    int64_t nnz = f->P->indptr[NF];
    for (int64_t e = 0; e < nnz; e++) f->Dv[e] = 0.01 * f->Kv[e];
  }
  double *Ax = fmbd_calloc((size_t)m->nnz, 8), *B = fmbd_calloc((size_t)(nb * nb), 8),
         *Bfd = fmbd_calloc((size_t)(nb * nb), 8), *e = fmbd_calloc((size_t)nb, 8);
  for (int which = 0; which < 3; which++) {
    memset(Ax, 0, sizeof(double) * (size_t)m->nnz);
    mbs_fe_eval(m, bf, 0.2, x, xd, xdd, r0 + b0->off, Ax, which == 0, which == 1, which == 2);
    for (int64_t j = 0; j < nb; j++) {  // column j of the block: B e_j
      memset(e, 0, sizeof(double) * (size_t)nb);
      e[j] = 1;
      memset(B + nb * j, 0, sizeof(double) * (size_t)nb);
      mbs_fe_block_mul(&m->b[bf], Ax, e, B + nb * j);
    }
    if (which == 2) {  // K on the flexible block, nothing else
      double d = 0;
      for (int64_t j = 0; j < nb; j++) {
        for (int64_t i = 0; i < nb; i++) {
          double ref = i >= 7 && j >= 7 ? K[(i - 7) + NF * (j - 7)] : 0;
          d = fmax(d, fabs(B[i + nb * j] - ref));
        }
      }
      EXPECT(d <= 1e-12 * maxabs(K, NF * NF), "stiffness block vs K: max diff %.3g", d);
      continue;
    }
    double *v = which == 0 ? xdd : xd;
    for (int64_t j = 0; j < nb; j++) {
      double h = 1e-6, keep = v[b0->off + j];
      v[b0->off + j] = keep + h;
      mbs_fe_eval(m, bf, 0.2, x, xd, xdd, r1 + b0->off, NULL, 0, 0, 0);
      v[b0->off + j] = keep - h;
      mbs_fe_eval(m, bf, 0.2, x, xd, xdd, r0 + b0->off, NULL, 0, 0, 0);
      v[b0->off + j] = keep;
      for (int64_t i = 0; i < nb; i++)
        Bfd[i + nb * j] = (r1[b0->off + i] - r0[b0->off + i]) / (2 * h);
    }
    double d = 0;
    for (int64_t i = 0; i < nb * nb; i++) d = fmax(d, fabs(B[i] - Bfd[i]));
    // the residual is linear in x'' and quadratic in x': central differences are exact up to
    // round-off (~1e-10 of the scale with h = 1e-6)
    EXPECT(d < 1e-6 * fmax(1, maxabs(Bfd, nb * nb)), "%s: max |analytic - FD| %.3g (scale %.3g)",
           which == 0 ? "mass matrix" : "velocity tangent", d, maxabs(Bfd, nb * nb));
  }
  // (3) fmbd_mbs_linearise at (x, x'): the FE body's rows of M, C, K (CSR, the body's sparse
  // block, never dense) equal its blocks above, and Q = -(residual at zero accelerations)
  {
    fmbd_mbs_linear L;
    rc = fmbd_mbs_linearise(m, 0.2, x, xd, &L);
    EXPECT(rc == 0, "linearise: %s", fmbd_err_get()->msg);
    const fmbd_csr *LM[3] = {L.M, L.C, L.K};
    const char *nm3[3] = {"M", "C", "K"};
    int64_t nnz_fe = L.M ? L.M->indptr[b0->off + nb] - L.M->indptr[b0->off] : -1;
    EXPECT(nnz_fe == mbs_fe_nnz(b0),
           "linearise: the FE body's rows hold %lld entries, its block %lld", (long long)nnz_fe,
           (long long)mbs_fe_nnz(b0));
    mbs_fe_eval(m, bf, 0.2, x, xd, NULL, r0 + b0->off, NULL, 0, 0, 0);
    double dq = 0;
    for (int64_t i = 0; !rc && i < nb; i++) dq = fmax(dq, fabs(L.Q[b0->off + i] + r0[b0->off + i]));
    EXPECT(dq <= 1e-12 * fmax(1, maxabs(r0 + b0->off, nb)), "linearise: Q vs -residual %.3g", dq);
    for (int which = 0; which < 3 && !rc; which++) {
      memset(Ax, 0, sizeof(double) * (size_t)m->nnz);
      mbs_fe_eval(m, bf, 0.2, x, xd, NULL, r0 + b0->off, Ax, which == 0, which == 1, which == 2);
      double d = 0, s2 = 0;
      for (int64_t j = 0; j < nb; j++) {
        memset(e, 0, sizeof(double) * (size_t)nb);
        e[j] = 1;
        memset(B, 0, sizeof(double) * (size_t)nb);
        mbs_fe_block_mul(&m->b[bf], Ax, e, B);
        for (int64_t i = 0; i < nb; i++) {
          double v = fmbd_csr_get(LM[which], b0->off + i, b0->off + j);
          d = fmax(d, fabs(v - B[i])), s2 = fmax(s2, fabs(B[i]));
        }
      }
      EXPECT(d <= 1e-14 * fmax(1, s2), "linearise: %s block vs the iteration block %.3g",
             nm3[which], d);
    }
    fmbd_mbs_linear_free(&L);
  }
  fmbd_free(x), fmbd_free(xd), fmbd_free(xdd), fmbd_free(r0), fmbd_free(r1), fmbd_free(Ax),
      fmbd_free(B), fmbd_free(Bfd), fmbd_free(e);
  fmbd_csr_destroy(&cM), fmbd_csr_destroy(&cK), fmbd_csr_destroy(&cMn), fmbd_csr_destroy(&cE),
      fmbd_csr_destroy(&cD);
  fmbd_mbs_destroy(&m);
}

int main(void) {
  fmbd_log_init("t509", FMBD_LOG_ERROR);
  one(0);
  one(1);
  TEST_EXIT();
}
