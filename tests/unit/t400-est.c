// tests/unit/t400-est.c: the estimator algebra of common/fmbd_est against a dense reference
// built from the FULL fixed-interface eigensolution of a small random body (residual modes
// known explicitly, so Xb = sum over residual modes, independent of the Ks^-1 identities)
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_alloc.h"
#include "fmbd_csr.h"
#include "fmbd_dense.h"
#include "fmbd_est.h"

enum { N = 40, NB = 5, NS = N - NB, NPOOL = 12 };

static double rnd(unsigned *s) {
  *s = *s * 1103515245u + 12345u;
  return ((*s >> 8) & 0xffff) / 65536.0 - 0.5;
}

// random SPD matrix: B'B + shift I (col-major n x n)
static void spd(int n, unsigned seed, double shift, double *A) {
  double *B = malloc(sizeof(double) * n * n);
  for (int i = 0; i < n * n; i++) {
    B[i] = rnd(&seed);
  }
  fmbd_dense_gemm('T', 'N', n, n, n, 1.0, B, n, B, n, 0.0, A, n);
  for (int i = 0; i < n; i++) {
    A[i + n * i] += shift;
  }
  free(B);
}

static fmbd_csr *to_csr(int n, const double *A) {
  fmbd_csr *C = NULL;
  fmbd_csr_create(n, n, (int64_t)n * n, &C);
  int64_t p = 0;
  for (int i = 0; i < n; i++) {
    C->indptr[i] = p;
    for (int j = 0; j < n; j++) {
      C->indices[p] = j;
      C->data[p++] = A[i + n * j];
    }
  }
  C->indptr[n] = p;
  return C;
}

static double maxabs(int n, const double *a) {
  double m = 0;
  for (int i = 0; i < n; i++) {
    m = fmax(m, fabs(a[i]));
  }
  return m;
}

static double reldiff(int n, const double *a, const double *b) {
  double d = 0;
  for (int i = 0; i < n; i++) {
    d = fmax(d, fabs(a[i] - b[i]));
  }
  return d / fmax(maxabs(n, b), 1e-300);
}

int main(void) {
  static double K[N * N], M[N * N], Ks[NS * NS], Ms[NS * NS], Kc[NS * NB], Mc[NS * NB];
  static double Phi[NS * NS], kap[NS], tmpK[NS * NS], tmpM[NS * NS], L[NS * NS];
  static double Psi[NS * NB], A[NS * NB], KsA[NS * NB], KsMsKsA[NS * NB], P[NS * NB];
  spd(N, 7u, 1.0, K);
  spd(N, 11u, 5.0, M);
  for (int j = 0; j < NS; j++) {
    for (int i = 0; i < NS; i++) {
      Ks[i + NS * j] = K[i + N * j];
      Ms[i + NS * j] = M[i + N * j];
    }
  }
  for (int j = 0; j < NB; j++) {
    for (int i = 0; i < NS; i++) {
      Kc[i + NS * j] = K[i + N * (NS + j)];
      Mc[i + NS * j] = M[i + N * (NS + j)];
    }
  }
  // full fixed-interface eigensolution: Ks phi = kappa Ms phi
  memcpy(tmpK, Ks, sizeof Ks);
  memcpy(tmpM, Ms, sizeof Ms);
  EXPECT(fmbd_dense_sygv(NS, tmpK, tmpM, kap) == 0, "sygv");
  memcpy(Phi, tmpK, sizeof Phi);
  // Psi = -Ks^-1 Kc, A = Ms Psi + Mc, Ks^-1 A, Ks^-1 Ms Ks^-1 A
  memcpy(L, Ks, sizeof Ks);
  EXPECT(fmbd_dense_chol(NS, L) == 0, "chol");
  for (int i = 0; i < NS * NB; i++) {
    Psi[i] = -Kc[i];
  }
  fmbd_dense_chol_solve(NS, L, NB, Psi, NS);
  memcpy(A, Mc, sizeof Mc);
  fmbd_dense_gemm('N', 'N', NS, NB, NS, 1.0, Ms, NS, Psi, NS, 1.0, A, NS);
  memcpy(KsA, A, sizeof A);
  fmbd_dense_chol_solve(NS, L, NB, KsA, NS);
  fmbd_dense_gemm('N', 'N', NS, NB, NS, 1.0, Ms, NS, KsA, NS, 0.0, KsMsKsA, NS);
  fmbd_dense_chol_solve(NS, L, NB, KsMsKsA, NS);
  // P = Phi' A (all NS modes); the pool is its first NPOOL rows
  fmbd_dense_gemm('T', 'N', NS, NB, NS, 1.0, Phi, NS, A, NS, 0.0, P, NS);
  double PhitA[NPOOL * NB];
  for (int j = 0; j < NB; j++) {
    for (int k = 0; k < NPOOL; k++) {
      PhitA[k + NPOOL * j] = P[k + NS * j];
    }
  }
  // reference residual blocks for nd dominant modes: sums over the residual modes
  double Xref[NB * NB], Gref[NB * NB];
#define RESIDUAL(nd)                                                             \
  do {                                                                           \
    memset(Xref, 0, sizeof Xref);                                                \
    memset(Gref, 0, sizeof Gref);                                                \
    for (int k = (nd); k < NS; k++) {                                            \
      for (int j = 0; j < NB; j++) {                                             \
        for (int i = 0; i < NB; i++) {                                           \
          Xref[i + NB * j] += P[k + NS * i] * P[k + NS * j] / kap[k];            \
          Gref[i + NB * j] += P[k + NS * i] * P[k + NS * j] / (kap[k] * kap[k]); \
        }                                                                        \
      }                                                                          \
    }                                                                            \
  } while (0)
  // The random body is well conditioned (cond(Ks) ~ 1e2, residual ~ 1e-1 of the total), so
  // both evaluations agree with the residual-mode sums to ~1e-14; 1e-10 leaves room for the
  // dense eigensolver's error in the reference without hiding a wrong formula (those are O(1)).
  RESIDUAL(NPOOL);
  double Xb[NB * NB], Gb[NB * NB], noise = -1;
  EXPECT(fmbd_est_base_plain(NS, NB, NPOOL, A, KsA, KsMsKsA, kap, PhitA, Xb, Gb, &noise) == 0,
         "plain");
  EXPECT(reldiff(NB * NB, Xb, Xref) < 1e-10, "plain Xb off by %g", reldiff(NB * NB, Xb, Xref));
  EXPECT(reldiff(NB * NB, Gb, Gref) < 1e-10, "plain Gb off by %g", reldiff(NB * NB, Gb, Gref));
  EXPECT(noise >= 0 && noise < 1e-10 * maxabs(NB * NB, Xref), "noise %g", noise);
  fmbd_csr *cK = to_csr(NS, Ks), *cM = to_csr(NS, Ms);
  double Xp[NB * NB], Gp[NB * NB];
  EXPECT(fmbd_est_base_projected(cK, cM, NS, NULL, NB, NPOOL, A, KsA, Phi, kap, PhitA, Xp, Gp) == 0,
         "proj");
  EXPECT(reldiff(NB * NB, Xp, Xref) < 1e-10, "projected Xb off by %g", reldiff(NB * NB, Xp, Xref));
  EXPECT(reldiff(NB * NB, Gp, Gref) < 1e-10, "projected Gb off by %g", reldiff(NB * NB, Gp, Gref));
  {  // the same from the full matrices and the interior rows (last NB rows are the boundary)
    fmbd_csr *fK = to_csr(N, K), *fM = to_csr(N, M);
    int64_t inter[NS];
    for (int i = 0; i < NS; i++) {
      inter[i] = i;
    }
    double Xq[NB * NB], Gq[NB * NB];
    EXPECT(
        fmbd_est_base_projected(fK, fM, NS, inter, NB, NPOOL, A, KsA, Phi, kap, PhitA, Xq, Gq) == 0,
        "proj full");
    // same arithmetic up to summation order: 1e-12
    EXPECT(reldiff(NB * NB, Xq, Xp) < 1e-12 && reldiff(NB * NB, Gq, Gp) < 1e-12,
           "interior rows of K, M");
    fmbd_csr_destroy(&fK);
    fmbd_csr_destroy(&fM);
  }

  // --- the estimator state: downdates and updates -----------------------------------------
  double Mbb[NB * NB], Kbb[NB * NB];
  {  // Mb_ = Psi' Ms Psi + Psi' Mc + Mc' Psi + Mb ; Kb_ = Kb + Kc' Psi
    double T[NS * NB];
    fmbd_dense_gemm('N', 'N', NS, NB, NS, 1.0, Ms, NS, Psi, NS, 0.0, T, NS);
    for (int j = 0; j < NB; j++) {
      for (int i = 0; i < NB; i++) {
        Mbb[i + NB * j] = M[(NS + i) + N * (NS + j)];
        Kbb[i + NB * j] = K[(NS + i) + N * (NS + j)];
      }
    }
    fmbd_dense_gemm('T', 'N', NB, NB, NS, 1.0, Psi, NS, T, NS, 1.0, Mbb, NB);
    fmbd_dense_gemm('T', 'N', NB, NB, NS, 1.0, Psi, NS, Mc, NS, 1.0, Mbb, NB);
    fmbd_dense_gemm('T', 'N', NB, NB, NS, 1.0, Mc, NS, Psi, NS, 1.0, Mbb, NB);
    fmbd_dense_gemm('T', 'N', NB, NB, NS, 1.0, Kc, NS, Psi, NS, 1.0, Kbb, NB);
  }
  // per-mode values of the formulas: no clusters (the random body's errors are large, so the
  // overlap clusters would merge its modes); the cluster rule is tested on its own below
  fmbd_est_opts eo;
  fmbd_est_opts_defaults(&eo);
  eo.cluster_rtol = 0;
  eo.cluster_overlap = false;
  fmbd_est *e = NULL;
  EXPECT(fmbd_est_create(NB, Mbb, Kbb, &eo, &e) == 0, "create");
  EXPECT(fmbd_est_set_pool(e, NPOOL, kap, PhitA, Xp, Gp) == 0, "pool");
  int nds[] = {5, 9, 0, 12, 3};
  for (int t = 0; t < 5; t++) {
    int nd = nds[t];
    EXPECT(fmbd_est_set_nd(e, nd) == 0, "set_nd %d", nd);
    RESIDUAL(nd);
    EXPECT(reldiff(NB * NB, fmbd_est_xb(e), Xref) < 1e-10, "nd %d: Xb off by %g", nd,
           reldiff(NB * NB, fmbd_est_xb(e), Xref));
    EXPECT(reldiff(NB * NB, fmbd_est_gb(e), Gref) < 1e-10, "nd %d: Gb off by %g", nd,
           reldiff(NB * NB, fmbd_est_gb(e), Gref));
  }
  EXPECT(fmbd_est_set_nd(e, NPOOL + 1) != 0, "nd beyond the pool must fail");

  // --- reduced eigensolution against T0' K T0, T0' M T0 (nd = 5) ----------------------------
  int nd = 5, n = nd + NB;
  fmbd_est_set_nd(e, nd);
  double chib[n], Xi[n * n];
  EXPECT(fmbd_est_solve(e, chib, Xi) == 0, "solve");
  {
    double T0[N * n], KT[N * n], Kr[n * n], Mr[n * n], w[n];
    memset(T0, 0, sizeof T0);
    for (int k = 0; k < nd; k++) {
      for (int i = 0; i < NS; i++) {
        T0[i + N * k] = Phi[i + NS * k];
      }
    }
    for (int j = 0; j < NB; j++) {
      for (int i = 0; i < NS; i++) {
        T0[i + N * (nd + j)] = Psi[i + NS * j];
      }
      T0[(NS + j) + N * (nd + j)] = 1.0;
    }
    fmbd_dense_gemm('N', 'N', N, n, N, 1.0, K, N, T0, N, 0.0, KT, N);
    fmbd_dense_gemm('T', 'N', n, n, N, 1.0, T0, N, KT, N, 0.0, Kr, n);
    fmbd_dense_gemm('N', 'N', N, n, N, 1.0, M, N, T0, N, 0.0, KT, N);
    fmbd_dense_gemm('T', 'N', n, n, N, 1.0, T0, N, KT, N, 0.0, Mr, n);
    EXPECT(fmbd_dense_sygv(n, Kr, Mr, w) == 0, "sygv reduced");
    EXPECT(reldiff(n, chib, w) < 1e-10, "reduced eigenvalues off by %g", reldiff(n, chib, w));
  }
  // --- estimates against the formulas written out here ---------------------------------------
  fmbd_est_modes m;
  EXPECT(fmbd_est_modes_alloc(n, &m) == 0, "alloc");
  EXPECT(fmbd_est_estimate(e, chib, Xi, n, &m) == 0, "estimate");
  RESIDUAL(nd);
  for (int k = 0; k < n; k++) {
    const double *b = Xi + n * k + nd;
    double x = 0, g = 0;
    for (int i = 0; i < NB; i++) {
      for (int j = 0; j < NB; j++) {
        x += b[i] * Xref[i + NB * j] * b[j];
        g += b[i] * Gref[i + NB * j] * b[j];
      }
    }
    double c = chib[k], kn = k < nd ? kap[k] : kap[nd - 1];
    EXPECT(!m.rigid[k], "mode %d flagged rigid", k);
    // 1e-9: quadratic forms of matrices equal to 1e-10 (above), no cancellation
    EXPECT(fabs(m.lower[k] - c * x) <= 1e-9 * fabs(c * x), "lower %d", k);
    EXPECT(fabs(m.second[k] - (c * x + c * c * g)) <= 1e-9 * fabs(c * x + c * c * g), "second %d",
           k);
    EXPECT(fabs(m.upper[k] - (c + c * c / kn) * x) <= 1e-9 * fabs((c + c * c / kn) * x), "upper %d",
           k);
    EXPECT(
        fabs(m.upper_next[k] - (c + c * c / kap[nd]) * x) <= 1e-9 * fabs((c + c * c / kap[nd]) * x),
        "upper_next %d", k);
  }
  // --- rigid modes and a repeated cluster (synthetic eigenpairs) ----------------------------
  {
    double cb[3] = {0.0, 2.0, 2.0 * (1 + 1e-5)};
    double X3[3 * n];
    memset(X3, 0, sizeof X3);
    for (int i = 0; i < NB; i++) {
      X3[n * 1 + nd + i] = (i == 0);
      X3[n * 2 + nd + i] = (i == 1) * 3.0;
    }
    fmbd_est *e2 = NULL;  // default options: clusters on
    fmbd_est_create(NB, Mbb, Kbb, NULL, &e2);
    fmbd_est_set_pool(e2, NPOOL, kap, PhitA, Xp, Gp);
    fmbd_est_set_nd(e2, nd);
    fmbd_est_modes m3;
    fmbd_est_modes_alloc(3, &m3);
    fmbd_est_estimate(e2, cb, X3, n, &m3);
    fmbd_est_destroy(&e2);
    EXPECT(m3.rigid[0] && m3.upper[0] == 0 && m3.lower[0] == 0, "zero eigenvalue is rigid");
    EXPECT(m3.cluster[1] == 1 && m3.cluster[2] == 1, "pair not clustered");
    EXPECT(m3.upper[1] == m3.upper[2] && m3.lower[1] == m3.lower[2] && m3.second[1] == m3.second[2],
           "cluster values differ");
    double x1 = fmbd_est_xb(e)[0], x2 = 9 * fmbd_est_xb(e)[1 + NB];
    EXPECT(fabs(m3.lower[1] - fmin(2 * x1, 2 * (1 + 1e-5) * x2)) <= 1e-12 * m3.lower[1],
           "cluster lower is not the smallest");
    EXPECT(m3.upper[1] >= m3.lower[1], "bracket");
    fmbd_est_modes_free(&m3);
  }
  fmbd_est_modes_free(&m);
  fmbd_est_destroy(&e);
  fmbd_csr_destroy(&cK);
  fmbd_csr_destroy(&cM);
  TEST_EXIT();
}
