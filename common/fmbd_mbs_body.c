// common/fmbd_mbs_body.c: the equations of motion of one floating-frame body (fmbd_mbs.h,
// EQUATIONS) SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_mbs_impl.h"
#include "fmbd_vec.h"
#ifdef FMBD_HAVE_V4D
#include <immintrin.h>
#endif

// ============================================================================================
// body equations (fmbd_mbs.h, EQUATIONS)
// ============================================================================================

// y = alpha A x, A m x n column-major: four columns at a time (one load and store of y for four
// products: the loop is bound by y's traffic otherwise) on pairs of rows (GCC/clang vector
// extension: packed SSE2 on x86-64, which -O2 does not vectorise by itself here). Together 2.1x
// (30 modes) to 3x (100 modes) faster than one column at a time on the quadruple pendulum's
// rod (bench/README.md). BLAS dgemv was slower (OpenBLAS threads and packs these small products).
// This portable form is what a processor without AVX2 runs; matvec_add below chooses.
#if defined(__GNUC__)
typedef double v2d __attribute__((vector_size(16)));
static inline v2d ld2(const double *p) {
  v2d v;
  memcpy(&v, p, sizeof v);
  return v;
}
#endif
// y += alpha A x (leading dimension lda): the portable form
static void matvec_add_base(int m, int n, const double *restrict A, int lda,
                            const double *restrict x, double alpha, double *restrict y) {
  int j = 0;
  for (; j + 4 <= n; j += 4) {
    double x0 = alpha * x[j], x1 = alpha * x[j + 1], x2 = alpha * x[j + 2], x3 = alpha * x[j + 3];
    const double *restrict a0 = A + (size_t)lda * j, *restrict a1 = a0 + lda,
                           *restrict a2 = a1 + lda, *restrict a3 = a2 + lda;
    int i = 0;
#if defined(__GNUC__)
    const v2d X0 = {x0, x0}, X1 = {x1, x1}, X2 = {x2, x2}, X3 = {x3, x3};
    for (; i + 2 <= m; i += 2) {
      v2d t =
          ld2(y + i) + X0 * ld2(a0 + i) + X1 * ld2(a1 + i) + X2 * ld2(a2 + i) + X3 * ld2(a3 + i);
      memcpy(y + i, &t, sizeof t);
    }
#endif
    for (; i < m; i++) y[i] += x0 * a0[i] + x1 * a1[i] + x2 * a2[i] + x3 * a3[i];
  }
  for (; j < n; j++) {
    double xj = alpha * x[j];
    const double *restrict a = A + (size_t)lda * j;
    for (int i = 0; i < m; i++) y[i] += xj * a[i];
  }
}

// The same sums four rows to a vector (AVX, 4 doubles) and eight columns to a pass (y loaded and
// stored once per eight columns instead of four), chosen when called where the processor has
// AVX2 (__builtin_cpu_supports; fmbd_csr.c's 8-column kernels do the same): the full-coupling
// products SS q (9 nm x nm) and SSx q' (3 nm x nm) are most of a full-coupling evaluation
// (bench/README.md, "The modal body's per-step cost"). Every entry gets the portable form's
// operations in its order, so the results are the same bits: y_i + x0 a0_i, then + x1 a1_i, ...
// in column order for the rows the portable form takes in pairs (every row but an odd last
// one), y_i + (x0 a0_i + ... + x3 a3_i) per four columns for an odd last row, y_i + xj aj_i for
// the columns after the last four; alpha x_j formed as there; no FMA (GCC compiles -std=c11 with
// -ffp-contract=off and the target attribute names no FMA; clang is told so below)
#ifdef FMBD_HAVE_V4D  // fmbd_vec.h: x86-64, GCC or clang, not FMBD_NO_VECTOR
#define MBS_VEC4 1
#ifdef __clang__
#pragma clang fp contract(off)
#endif
// column j + c of a pass: alpha x_j+c, the column and alpha x_j+c broadcast
#define MV_COL(c)                                                                   \
  const double x##c = alpha * x[j + c], *restrict a##c = A + (size_t)lda * (j + c); \
  const v4d X##c = {x##c, x##c, x##c, x##c}
#define MV_T(c) +X##c *LD4(a##c + i)
#define MV_S(c) +x##c *a##c[i]
// eight columns at j: the rows in fours, then in ones (a pair), then an odd last row
__attribute__((target("avx2"))) static void mv_cols8(int m, int j, const double *restrict A,
                                                     int lda, const double *restrict x,
                                                     double alpha, double *restrict y) {
  MV_COL(0);
  MV_COL(1);
  MV_COL(2);
  MV_COL(3);
  MV_COL(4);
  MV_COL(5);
  MV_COL(6);
  MV_COL(7);
  const int me = m & ~1, m4 = m & ~3;
  int i = 0;
  for (; i < m4; i += 4)
    ST4(y + i, LD4(y + i) MV_T(0) MV_T(1) MV_T(2) MV_T(3) MV_T(4) MV_T(5) MV_T(6) MV_T(7));
  for (; i < me; i++) y[i] = y[i] MV_S(0) MV_S(1) MV_S(2) MV_S(3) MV_S(4) MV_S(5) MV_S(6) MV_S(7);
  if (m & 1) {
    i = m - 1;
    y[i] += x0 * a0[i] + x1 * a1[i] + x2 * a2[i] + x3 * a3[i];
    y[i] += x4 * a4[i] + x5 * a5[i] + x6 * a6[i] + x7 * a7[i];
  }
}
// the same, four columns
__attribute__((target("avx2"))) static void mv_cols4(int m, int j, const double *restrict A,
                                                     int lda, const double *restrict x,
                                                     double alpha, double *restrict y) {
  MV_COL(0);
  MV_COL(1);
  MV_COL(2);
  MV_COL(3);
  const int me = m & ~1, m4 = m & ~3;
  int i = 0;
  for (; i < m4; i += 4) ST4(y + i, LD4(y + i) MV_T(0) MV_T(1) MV_T(2) MV_T(3));
  for (; i < me; i++) y[i] = y[i] MV_S(0) MV_S(1) MV_S(2) MV_S(3);
  if (m & 1) {
    i = m - 1;
    y[i] += x0 * a0[i] + x1 * a1[i] + x2 * a2[i] + x3 * a3[i];
  }
}
__attribute__((target("avx2"))) static void matvec_add_avx2(int m, int n, const double *restrict A,
                                                            int lda, const double *restrict x,
                                                            double alpha, double *restrict y) {
  const int m4 = m & ~3;
  int j = 0;
  for (; j + 8 <= n; j += 8) mv_cols8(m, j, A, lda, x, alpha, y);
  for (; j + 4 <= n; j += 4) mv_cols4(m, j, A, lda, x, alpha, y);
  // the last 1-3 columns, one at a time in the portable form (every row y_i + xj aj_i), here
  // together in one pass over the rows (y stored once, not once per column)
  if (j + 3 == n) {
    MV_COL(0);
    MV_COL(1);
    MV_COL(2);
    int i = 0;
    for (; i < m4; i += 4) ST4(y + i, LD4(y + i) MV_T(0) MV_T(1) MV_T(2));
    for (; i < m; i++) y[i] = y[i] MV_S(0) MV_S(1) MV_S(2);
  } else if (j + 2 == n) {
    MV_COL(0);
    MV_COL(1);
    int i = 0;
    for (; i < m4; i += 4) ST4(y + i, LD4(y + i) MV_T(0) MV_T(1));
    for (; i < m; i++) y[i] = y[i] MV_S(0) MV_S(1);
  } else if (j + 1 == n) {
    MV_COL(0);
    int i = 0;
    for (; i < m4; i += 4) ST4(y + i, LD4(y + i) MV_T(0));
    for (; i < m; i++) y[i] = y[i] MV_S(0);
  }
}
#undef MV_COL
#undef MV_T
#undef MV_S
#endif
// y += alpha A x (leading dimension lda)
static void matvec_add(int m, int n, const double *restrict A, int lda, const double *restrict x,
                       double alpha, double *restrict y) {
#ifdef MBS_VEC4
  if (m >= 4 && __builtin_cpu_supports("avx2")) {
    matvec_add_avx2(m, n, A, lda, x, alpha, y);
    return;
  }
#endif
  matvec_add_base(m, n, A, lda, x, alpha, y);
}
// the same, for the other files of the multibody core (fmbd_mbs_impl.h)
void mbs_matvec_add(int m, int n, const double *A, int lda, const double *x, double alpha,
                    double *y) {
  matvec_add(m, n, A, lda, x, alpha, y);
}
void mbs_matvec_add_portable(int m, int n, const double *A, int lda, const double *x, double alpha,
                             double *y) {
  matvec_add_base(m, n, A, lda, x, alpha, y);
}
// --- P = SS q from SS's upper triangle (full inertia coupling) -------------------------------
// SS as one symmetric matrix St of order 3 nm, row (a, k) = a nm + k: St[(a,k),(b,l)] = int rho
// S_k,a S_l,b = SS[a + 3b + 9k + 9 nm l] = St[(b,l),(a,k)] (docs/THEORY.md). P_k,ab = sum_l
// St[(a,k),(b,l)] q_l is formed from St's upper triangle alone: each entry read once gives both
// its products, St_ij q_l into P's row i of column b (an axpy) and St_ij q_k into P's row j of
// column a (a dot product), so half the bytes of the full (9 nm) x nm product for the same
// multiply-adds (the full product ran at about 14 multiply-adds a ns from L2, its 65 kB at 30
// modes exceeding L1's 32 kB; the same loop from L1 at 21-23: bench/README.md).
//
// Layout (mbs_ss_pack): every block padded to nmp = nm rounded up to 4 rows and columns (zeros),
// row (a, k) at a nmp + k; the columns j = b nmp + l in groups of four (g = j / 4), each column of
// group g holding the rows 0..4g+3 (the upper triangle and the group's whole 4 x 4 diagonal block),
// at ss_off(j). P (mbs_ssq) is 3 nmp x 3: P_k,ab at P[k + nmp (a + 3b)].
//
// The order of the operations (the portable form; the AVX2 form does the same per lane): groups
// in order; per group and segment a <= b (rows a nmp + k, k < nmp, or k < l0 in the group's own
// block) four rows a pass: P_i = (((P_i + q_l0 St_i,l0) + q_l0+1 St_i,l0+1) + ...), and a dot
// product per column in four lanes (lane e: rows k = e mod 4), reduced as ((lane 0 + lane 1) +
// (lane 2 + lane 3)) and added to P[(b, l), a]; then the group's diagonal block as the axpy alone
static size_t ss_off(size_t j) {
  const size_t g = j / 4;
  return 8 * g * (g + 1) + (j % 4) * (4 * g + 4);
}
// Below MBS_SS_TRI modes the full (9 nmp) x nm product is faster (the loops over a block's 4 x 4
// groups have short runs: measured one evaluation's SS q at 30 modes 0.67 us packed against 0.62
// full, 40 modes 0.98 against 1.09, 100 modes 5.9 against 10.6): there St holds SS whole, row
// k + nm (a + 3b), column l (not padded: the product reads SS from L2 at 30 modes, and padding
// the rows to 4 modes cost 1 % of the pendulum's run), and P = St q is spread to its rows of nmp
#define MBS_SS_TRI 40
size_t mbs_ss_size(int nm) {
  const size_t nmp = (size_t)((nm + 3) & ~3);
  return nm >= MBS_SS_TRI ? ss_off(3 * nmp) : 9 * (size_t)nm * (size_t)nm;
}
// rows of n entries at stride n (9 of them) to stride np, zeros after each (in place: the last
// row first)
static void spread_rows(int rows, int n, int np, double *P) {
  for (int i = rows - 1; i >= 0; i--) {
    memmove(P + (size_t)np * i, P + (size_t)n * i, sizeof(double) * (size_t)n);
    for (int k = n; k < np; k++) P[(size_t)np * i + k] = 0;
  }
}
void mbs_ss_pack(int nm, const double *SS, double *St) {
  const size_t n1 = (size_t)nm;
  const int nmp = (nm + 3) & ~3;
  if (nm < MBS_SS_TRI) {
    for (size_t l = 0; l < n1; l++) {
      for (int i = 0; i < 9; i++) {
        for (int k = 0; k < nm; k++) St[k + nm * i + 9 * n1 * l] = SS[i + 9 * k + 9 * n1 * l];
      }
    }
    return;
  }
  for (int j = 0; j < 3 * nmp; j++) {
    const int bb = j / nmp, l = j % nmp, rows = (j | 3) + 1;
    double *col = St + ss_off((size_t)j);
    for (int i = 0; i < rows; i++) {
      const int a = i / nmp, k = i % nmp;
      if (k >= nm || l >= nm) {
        col[i] = 0;
        continue;
      }
      // the two stored copies of the entry (equal up to the invariant's own round-off)
      double u = SS[a + 3 * bb + 9 * k + 9 * n1 * l], v = SS[bb + 3 * a + 9 * l + 9 * n1 * k];
      col[i] = 0.5 * (u + v);
    }
  }
}

// the portable form: the lanes as arrays; qp: q padded with zeros to nmp
static void ssq_base(int nm, const double *restrict St, const double *restrict qp,
                     double *restrict P) {
  const int nmp = (nm + 3) & ~3, N = 3 * nmp;
  memset(P, 0, sizeof(double) * 3 * (size_t)N);
  for (int bb = 0; bb < 3; bb++) {
    double *Pb = P + (size_t)N * bb;
    for (int l0 = 0; l0 < nmp; l0 += 4) {
      const double *s[4];
      for (int t = 0; t < 4; t++) s[t] = St + ss_off((size_t)(bb * nmp + l0 + t));
      const double *X = qp + l0;
      for (int a = 0; a <= bb; a++) {
        const int ka = a < bb ? nmp : l0, i0 = a * nmp;
        double d[4][4] = {{0}};
        for (int k = 0; k < ka; k += 4) {
          for (int e = 0; e < 4; e++) {
            const int i = i0 + k + e;
            Pb[i] = Pb[i] + ((X[0] * s[0][i] + X[1] * s[1][i]) + (X[2] * s[2][i] + X[3] * s[3][i]));
            for (int t = 0; t < 4; t++) d[t][e] = d[t][e] + s[t][i] * qp[k + e];
          }
        }
        for (int t = 0; t < 4; t++)
          P[bb * nmp + l0 + t + (size_t)N * a] += (d[t][0] + d[t][1]) + (d[t][2] + d[t][3]);
      }
      for (int e = 0; e < 4; e++) {
        const int i = bb * nmp + l0 + e;
        Pb[i] = Pb[i] + X[0] * s[0][i] + X[1] * s[1][i] + X[2] * s[2][i] + X[3] * s[3][i];
      }
    }
  }
}

#ifdef MBS_VEC4
// the same, four rows to a vector
__attribute__((target("avx2"))) static void ssq_avx2(int nm, const double *restrict St,
                                                     const double *restrict qp,
                                                     double *restrict P) {
  const int nmp = (nm + 3) & ~3, N = 3 * nmp;
  memset(P, 0, sizeof(double) * 3 * (size_t)N);
  for (int bb = 0; bb < 3; bb++) {
    double *Pb = P + (size_t)N * bb;
    for (int l0 = 0; l0 < nmp; l0 += 4) {
      const double *s0 = St + ss_off((size_t)(bb * nmp + l0)), *s1 = s0 + (bb * nmp + l0 + 4),
                   *s2 = s1 + (bb * nmp + l0 + 4), *s3 = s2 + (bb * nmp + l0 + 4);
      const v4d X0 = {qp[l0], qp[l0], qp[l0], qp[l0]},
                X1 = {qp[l0 + 1], qp[l0 + 1], qp[l0 + 1], qp[l0 + 1]},
                X2 = {qp[l0 + 2], qp[l0 + 2], qp[l0 + 2], qp[l0 + 2]},
                X3 = {qp[l0 + 3], qp[l0 + 3], qp[l0 + 3], qp[l0 + 3]};
      for (int a = 0; a <= bb; a++) {
        const int ka = a < bb ? nmp : l0, i0 = a * nmp;
        v4d d0 = {0, 0, 0, 0}, d1 = d0, d2 = d0, d3 = d0;
        for (int k = 0; k < ka; k += 4) {
          const int i = i0 + k;
          v4d a0 = LD4(s0 + i), a1 = LD4(s1 + i), a2 = LD4(s2 + i), a3 = LD4(s3 + i);
          // each column's four entries loaded once (GCC otherwise reads them again for the dots)
          __asm__("" : "+x"(a0), "+x"(a1), "+x"(a2), "+x"(a3));
          const v4d qk = LD4(qp + k);
          ST4(Pb + i, LD4(Pb + i) + ((X0 * a0 + X1 * a1) + (X2 * a2 + X3 * a3)));
          d0 = d0 + a0 * qk, d1 = d1 + a1 * qk, d2 = d2 + a2 * qk, d3 = d3 + a3 * qk;
        }
        // lane sums of the four: h01 = (d0_0 + d0_1, d1_0 + d1_1, d0_2 + d0_3, d1_2 + d1_3), h23
        // the same of d2, d3; their halves added: ((lane 0 + lane 1) + (lane 2 + lane 3)) each
        const __m256d h01 = _mm256_hadd_pd(d0, d1), h23 = _mm256_hadd_pd(d2, d3);
        const v4d r =
            _mm256_permute2f128_pd(h01, h23, 0x20) + _mm256_permute2f128_pd(h01, h23, 0x31);
        double *o = P + bb * nmp + l0 + (size_t)N * a;
        ST4(o, LD4(o) + r);
      }
      const int i = bb * nmp + l0;
      ST4(Pb + i,
          LD4(Pb + i) + X0 * LD4(s0 + i) + X1 * LD4(s1 + i) + X2 * LD4(s2 + i) + X3 * LD4(s3 + i));
    }
  }
}
#endif
// P (3 nmp x 3) = St q (St packed by mbs_ss_pack); qp: nmp doubles of workspace; vec: the
// vector kernels where the processor has them (else the portable forms, the same bits)
static void ssq(int nm, const double *St, const double *q, double *P, double *qp, bool vec) {
  const int nmp = (nm + 3) & ~3;
  if (nm < MBS_SS_TRI) {
    memset(P, 0, sizeof(double) * 9 * (size_t)nm);
    if (vec)
      matvec_add(9 * nm, nm, St, 9 * nm, q, 1.0, P);
    else
      matvec_add_base(9 * nm, nm, St, 9 * nm, q, 1.0, P);
    spread_rows(9, nm, nmp, P);
    return;
  }
  memcpy(qp, q, sizeof(double) * (size_t)nm);
  for (int k = nm; k < nmp; k++) qp[k] = 0;
#ifdef MBS_VEC4
  if (vec && __builtin_cpu_supports("avx2")) {
    ssq_avx2(nm, St, qp, P);
    return;
  }
#endif
  ssq_base(nm, St, qp, P);
}
void mbs_ssq(int nm, const double *St, const double *q, double *P, double *qp) {
  ssq(nm, St, q, P, qp, true);
}
void mbs_ssq_portable(int nm, const double *St, const double *q, double *P, double *qp) {
  ssq(nm, St, q, P, qp, false);
}
static void matvec(int m, int n, const double *restrict A, const double *restrict x, double alpha,
                   double *restrict y) {
  for (int i = 0; i < m; i++) y[i] = 0;
  matvec_add(m, n, A, m, x, alpha, y);
}
// --- full coupling: the sums over the modes four modes to a vector ----------------------------
// The body's full-coupling arrays in b->pk (mbs_body_consts; nmp = nm rounded up to 4, every
// array over the modes padded with zeros to nmp, "i-major": entry i of mode k at k + nmp i):
// SS (mbs_ss_pack), P = SS q (9), XX_k, XT_k (9 each), S1_k (3), the rows of SSx (3 nm x nm,
// not padded: row k + nm a, column l, SSx[a + 3k + 3 nm l]), cor (3), H_k = XT_k + P_k (9), q,
// q', q'' padded (3), the modal rows' inertia terms (1)
typedef struct full_ws {
  double *St, *P, *XX, *XT, *S1, *SX, *cor, *H, *q, *qd, *qdd, *v;
  int nmp;
} full_ws;
static size_t full_size(int nm) {
  const size_t nmp = (size_t)((nm + 3) & ~3);
  return mbs_ss_size(nm) + (9 + 18 + 3 + 3 + 9 + 3 + 1) * nmp + 3 * (size_t)nm * (size_t)nm;
}
static full_ws full_at(const mbody *b) {
  full_ws f;
  const size_t nmp = (size_t)((b->nm + 3) & ~3);
  f.nmp = (int)nmp;
  f.St = b->pk, f.P = f.St + mbs_ss_size(b->nm);
  f.XX = f.P + 9 * nmp, f.XT = f.XX + 9 * nmp, f.S1 = f.XT + 9 * nmp, f.SX = f.S1 + 3 * nmp;
  f.cor = f.SX + 3 * (size_t)b->nm * (size_t)b->nm, f.H = f.cor + 3 * nmp, f.q = f.H + 9 * nmp;
  f.qd = f.q + nmp, f.qdd = f.qd + nmp, f.v = f.qdd + nmp;
  return f;
}
static void full_consts(const mbody *b) {
  const full_ws f = full_at(b);
  const int nm = b->nm, nmp = f.nmp;
  const size_t n1 = (size_t)nm;
  mbs_ss_pack(nm, b->SS, f.St);
  memset(f.XX, 0, sizeof(double) * (21 * (size_t)nmp + 3 * n1 * n1));  // XX, XT, S1, SX
  for (int k = 0; k < nm; k++) {
    for (int i = 0; i < 9; i++)
      f.XX[k + nmp * i] = b->XX[i + 9 * k], f.XT[k + nmp * i] = b->XT[i + 9 * k];
    for (int a = 0; a < 3; a++) f.S1[k + nmp * a] = b->S1[a + 3 * k];
    // SSx[a + 3k + 3 nm l] = (int rho S_k x S_l)_a = eps_abc SS_bc,kl, as fmbd_mbs.c forms it
    for (size_t l = 0; l < n1; l++) {
      const double *S = b->SS + 9 * (size_t)k + 9 * n1 * l;
      double *o = f.SX + k + 3 * n1 * l;
      o[0] = S[1 + 3 * 2] - S[2 + 3 * 1];
      o[nm] = S[2 + 3 * 0] - S[0 + 3 * 2];
      o[2 * nm] = S[0 + 3 * 1] - S[1 + 3 * 0];
    }
  }
  memset(f.cor, 0, sizeof(double) * 16 * (size_t)nmp);  // cor, H, the padded q, q', q'', v
}

// The sums of a full-coupling evaluation over the modes, in lanes of four modes (lane e: the
// modes k = e mod 4, zero padding past nm), each sum's lanes added as ((0 + 1) + (2 + 3)):
// fs_inertia: J_i = sum q_k (XX_k,i + P_k,i), H_i = sum q'_k H_k,i with H_k = XT_k + P_k (stored
// in f.H for the modal rows and the block), c_a = sum q_k S1_k,a, s1qd_a = sum q'_k S1_k,a;
// fs_rows: the modal rows' inertia terms v_k = y . H_k + ag . S1_k + w2 . cor_k (y: 9 weights, ag
// and w2: 3), the rigid rows' s1a_a = sum q''_k S1_k,a and hq_i = sum q''_k H_k,i (the
// antisymmetric entries 1, 2, 3, 5, 6, 7: Mwf q''). One body each for the forms below: GCC's and
// clang's vector extension (four doubles: two SSE2 operations where the processor has no AVX,
// the same operations per lane, so the same bits), chosen when called as matvec_add is, or plain
// C per lane where there is no vector extension
#define FS_RED(v) (((v)[0] + (v)[1]) + ((v)[2] + (v)[3]))
#if defined(__GNUC__)
typedef double v4g __attribute__((vector_size(32), aligned(sizeof(double)), may_alias));
#define G4(p) (*(const v4g *)(p))
__attribute__((always_inline)) static inline void fs_inertia_body(const full_ws *f, double *J,
                                                                  double *H, double *c,
                                                                  double *s1qd) {
  const int nmp = f->nmp;
  v4g aj[9], ah[9], ac[3], as[3];
  _Pragma("GCC unroll 9") for (int i = 0; i < 9; i++) aj[i] = ah[i] = (v4g){0, 0, 0, 0};
  _Pragma("GCC unroll 9") for (int a = 0; a < 3; a++) ac[a] = as[a] = (v4g){0, 0, 0, 0};
  for (int k = 0; k < nmp; k += 4) {
    const v4g q = G4(f->q + k), qd = G4(f->qd + k);
    _Pragma("GCC unroll 9") for (int i = 0; i < 9; i++) {
      const v4g p = G4(f->P + k + nmp * i), h = G4(f->XT + k + nmp * i) + p;
      aj[i] += q * (G4(f->XX + k + nmp * i) + p);
      *(v4g *)(f->H + k + nmp * i) = h;
      ah[i] += qd * h;
    }
    _Pragma("GCC unroll 9") for (int a = 0; a < 3; a++) {
      const v4g s = G4(f->S1 + k + nmp * a);
      ac[a] += q * s, as[a] += qd * s;
    }
  }
  _Pragma("GCC unroll 9") for (int i = 0; i < 9; i++) J[i] = FS_RED(aj[i]), H[i] = FS_RED(ah[i]);
  _Pragma("GCC unroll 9") for (int a = 0; a < 3; a++) c[a] = FS_RED(ac[a]), s1qd[a] = FS_RED(as[a]);
}
__attribute__((always_inline)) static inline void fs_rows_body(const full_ws *f, const double *y,
                                                               const double *ag, const double *w2,
                                                               bool acc, double *s1a, double *hq) {
  const int nmp = f->nmp;
  v4g a1[3] = {{0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 0}}, a2[9];
  _Pragma("GCC unroll 9") for (int i = 0; i < 9; i++) a2[i] = (v4g){0, 0, 0, 0};
  for (int k = 0; k < nmp; k += 4) {
    v4g v = (v4g){0, 0, 0, 0};
    _Pragma("GCC unroll 9") for (int i = 0; i < 9; i++) v += y[i] * G4(f->H + k + nmp * i);
    _Pragma("GCC unroll 9") for (int a = 0; a < 3; a++) v += ag[a] * G4(f->S1 + k + nmp * a);
    _Pragma("GCC unroll 9") for (int a = 0; a < 3; a++) v += w2[a] * G4(f->cor + k + nmp * a);
    *(v4g *)(f->v + k) = v;
    if (acc) {
      const v4g qdd = G4(f->qdd + k);
      _Pragma("GCC unroll 9") for (int a = 0; a < 3; a++) a1[a] += qdd * G4(f->S1 + k + nmp * a);
      _Pragma("GCC unroll 9") for (int i = 0; i < 9; i++) a2[i] += qdd * G4(f->H + k + nmp * i);
    }
  }
  _Pragma("GCC unroll 9") for (int a = 0; a < 3; a++) s1a[a] = FS_RED(a1[a]);
  _Pragma("GCC unroll 9") for (int i = 0; i < 9; i++) hq[i] = FS_RED(a2[i]);
}
#else
static void fs_inertia_body(const full_ws *f, double *J, double *H, double *c, double *s1qd) {
  const int nmp = f->nmp;
  double aj[9][4] = {{0}}, ah[9][4] = {{0}}, ac[3][4] = {{0}}, as[3][4] = {{0}};
  for (int k = 0; k < nmp; k++) {
    const int e = k & 3;
    const double q = f->q[k], qd = f->qd[k];
    for (int i = 0; i < 9; i++) {
      const double p = f->P[k + nmp * i], h = f->XT[k + nmp * i] + p;
      aj[i][e] += q * (f->XX[k + nmp * i] + p);
      f->H[k + nmp * i] = h;
      ah[i][e] += qd * h;
    }
    for (int a = 0; a < 3; a++) {
      const double s = f->S1[k + nmp * a];
      ac[a][e] += q * s, as[a][e] += qd * s;
    }
  }
  for (int i = 0; i < 9; i++) J[i] = FS_RED(aj[i]), H[i] = FS_RED(ah[i]);
  for (int a = 0; a < 3; a++) c[a] = FS_RED(ac[a]), s1qd[a] = FS_RED(as[a]);
}
static void fs_rows_body(const full_ws *f, const double *y, const double *ag, const double *w2,
                         bool acc, double *s1a, double *hq) {
  const int nmp = f->nmp;
  double a1[3][4] = {{0}}, a2[9][4] = {{0}};
  for (int k = 0; k < nmp; k++) {
    const int e = k & 3;
    double v = 0;
    for (int i = 0; i < 9; i++) v += y[i] * f->H[k + nmp * i];
    for (int a = 0; a < 3; a++) v += ag[a] * f->S1[k + nmp * a];
    for (int a = 0; a < 3; a++) v += w2[a] * f->cor[k + nmp * a];
    f->v[k] = v;
    if (acc) {
      for (int a = 0; a < 3; a++) a1[a][e] += f->qdd[k] * f->S1[k + nmp * a];
      for (int i = 0; i < 9; i++) a2[i][e] += f->qdd[k] * f->H[k + nmp * i];
    }
  }
  for (int a = 0; a < 3; a++) s1a[a] = FS_RED(a1[a]);
  for (int i = 0; i < 9; i++) hq[i] = FS_RED(a2[i]);
}
#endif
static void fs_inertia_base(const full_ws *f, double *J, double *H, double *c, double *s1qd) {
  fs_inertia_body(f, J, H, c, s1qd);
}
static void fs_rows_base(const full_ws *f, const double *y, const double *ag, const double *w2,
                         bool acc, double *s1a, double *hq) {
  fs_rows_body(f, y, ag, w2, acc, s1a, hq);
}
#ifdef MBS_VEC4
__attribute__((target("avx2"))) static void fs_inertia_avx2(const full_ws *f, double *J, double *H,
                                                            double *c, double *s1qd) {
  fs_inertia_body(f, J, H, c, s1qd);
}
__attribute__((target("avx2"))) static void fs_rows_avx2(const full_ws *f, const double *y,
                                                         const double *ag, const double *w2,
                                                         bool acc, double *s1a, double *hq) {
  fs_rows_body(f, y, ag, w2, acc, s1a, hq);
}
#endif
static void fs_inertia(const full_ws *f, double *J, double *H, double *c, double *s1qd) {
#ifdef MBS_VEC4
  if (__builtin_cpu_supports("avx2")) {
    fs_inertia_avx2(f, J, H, c, s1qd);
    return;
  }
#endif
  fs_inertia_base(f, J, H, c, s1qd);
}
static void fs_rows(const full_ws *f, const double *y, const double *ag, const double *w2, bool acc,
                    double *s1a, double *hq) {
#ifdef MBS_VEC4
  if (__builtin_cpu_supports("avx2")) {
    fs_rows_avx2(f, y, ag, w2, acc, s1a, hq);
    return;
  }
#endif
  fs_rows_base(f, y, ag, w2, acc, s1a, hq);
}
static void pad_copy(int nm, int nmp, const double *x, double *y) {
  memcpy(y, x, sizeof(double) * (size_t)nm);
  for (int k = nm; k < nmp; k++) y[k] = 0;
}

// --- parts shared by modal bodies (mbs_body_eval) and full FE bodies (mbs_fe_eval) -------
// the frame's kinematics: A(p/|p|), G(p), |p| into the body's workspace, body angular velocity
// w = 2 G p' (also b->wb) and acceleration wd = 2 G p'' (zero without pdd)
void mbs_frame_kin(mbody *b, const double *p, const double *pd, const double *pdd, double *w,
                   double *wd) {
  double *A = b->A, *G = b->G;
  quat_to_A(p, A);
  quat_G(p, G);
  b->pn = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]);
  wd[0] = wd[1] = wd[2] = 0;
  for (int a = 0; a < 3; a++) {
    w[a] =
        2 * (G[4 * a] * pd[0] + G[4 * a + 1] * pd[1] + G[4 * a + 2] * pd[2] + G[4 * a + 3] * pd[3]);
    if (pdd) {
      wd[a] = 2 * (G[4 * a] * pdd[0] + G[4 * a + 1] * pdd[1] + G[4 * a + 2] * pdd[2] +
                   G[4 * a + 3] * pdd[3]);
    }
  }
  memcpy(b->wb, w, 3 * sizeof(double));
}

// the rigid rows of r in x coordinates: r[0..2] = rb[0..2], r[3..6] = 2 G' rb[3..5], plus the
// mass mu p p' on the Euler parameters (see fmbd_mbs.h): G p = 0, so the physical equations
// are unchanged; the normalisation multiplier absorbs mu p (p . p'')
void mbs_rigid_rows(const mbody *b, const double *rb, const double *p, const double *pdd,
                    double *r) {
  const double *G = b->G;
  r[0] = rb[0], r[1] = rb[1], r[2] = rb[2];
  for (int c4 = 0; c4 < 4; c4++)
    r[3 + c4] = 2 * (G[c4] * rb[3] + G[4 + c4] * rb[4] + G[8 + c4] * rb[5]);
  const double mu = PMASS * b->snorm;
  if (pdd) {
    double ppdd = p[0] * pdd[0] + p[1] * pdd[1] + p[2] * pdd[2] + p[3] * pdd[3];
    for (int c4 = 0; c4 < 4; c4++) r[3 + c4] += mu * p[c4] * ppdd;
  }
}

// rigid rows of the quadratic velocity vector: rb[0..2] = A[w x (w x c) + 2 w x S1 q'],
// rb[3..5] = w x I w + 2 (tr(H) w - H w); Iw = I w
void mbs_rigid_qv(const double *A, const double *w, const double *c, const double *s1qd,
                  const double *I, const double *H, double trH, double *rb, double *Iw) {
  double t1[3], t2[3];
  cross3(w, c, t1);
  cross3(w, t1, t2);  // w x (w x c)
  double t3[3];
  cross3(w, s1qd, t3);
  for (int a = 0; a < 3; a++) t2[a] += 2 * t3[a];
  mv3(A, t2, rb);
  mv3(I, w, Iw);
  cross3(w, Iw, rb + 3);
  double Hw[3];  // (H w)_a = sum_b H[a + 3b] w_b
  for (int a = 0; a < 3; a++) Hw[a] = H[a] * w[0] + H[a + 3] * w[1] + H[a + 6] * w[2];
  for (int a = 0; a < 3; a++) rb[3 + a] += 2 * (trH * w[a] - Hw[a]);
}

// its derivatives with respect to wb: AM (rows R), WW (rows wb), both row-major 3 x 3
void mbs_rigid_vel_tangent(const double *A, const double *w, const double *c, const double *Sc,
                           const double *s1qd, const double *I, const double *Iw, const double *H,
                           double trH, double *AM, double *WW) {
  double S1[9], S2[9], S3[9], M1[9];
  double wc[3];
  cross3(w, c, wc);
  skew3(wc, S1);
  double Sw[9];
  skew3(w, Sw);
  mm3(Sw, Sc, S2);
  skew3(s1qd, S3);
  for (int i = 0; i < 9; i++) M1[i] = -(S1[i] + S2[i] + 2 * S3[i]);
  mm3(A, M1, AM);
  double IwS[9], SwI[9];
  skew3(Iw, IwS);
  mm3(Sw, I, SwI);
  for (int a = 0; a < 3; a++) {
    for (int bb = 0; bb < 3; bb++)
      WW[3 * a + bb] =
          SwI[3 * a + bb] - IwS[3 * a + bb] + 2 * ((a == bb ? trH : 0) - H[a + 3 * bb]);
  }
}

// the loads on body ib's points: subtracted from the rigid rows rb (6) and the flexible rows
// rf (indexed by flexible coordinate; a point's T, Rr over its support, or all modes)
void mbs_body_loads(const fmbd_mbs *m, int ib, double t, const double *A, const double *q,
                    double *rb, double *rf) {
  for (int il = 0; il < m->nl; il++) {
    const mload *L = &m->l[il];
    const mpoint *P = &m->p[L->pt];
    if (P->body != ib) continue;
    const int nk = P->sup ? P->nsup : m->b[ib].nm;
    double fv = fmbd_mbs_fn_eval(&L->f, t, NULL, NULL);
    double Fw[3], Fl[3];
    if (L->body_frame) {
      for (int a = 0; a < 3; a++) Fl[a] = fv * L->dir[a];
      mv3(A, Fl, Fw);
    } else {
      for (int a = 0; a < 3; a++) Fw[a] = fv * L->dir[a];
      mtv3(A, Fw, Fl);
    }
    if (L->kind == FMBD_MBS_FORCE) {
      double u[3];
      memcpy(u, P->x0, sizeof u);
      for (int k = 0; k < nk; k++) {
        double qk = q[P->sup ? P->sup[k] : k];
        for (int a = 0; a < 3; a++) u[a] += P->T[a + 3 * k] * qk;
      }
      double nn[3];
      cross3(u, Fl, nn);
      for (int a = 0; a < 3; a++) rb[a] -= Fw[a], rb[3 + a] -= nn[a];
      for (int k = 0; k < nk; k++) rf[P->sup ? P->sup[k] : k] -= dot3(P->T + 3 * k, Fl);
    } else {
      for (int a = 0; a < 3; a++) rb[3 + a] -= Fl[a];
      for (int k = 0; k < nk; k++) rf[P->sup ? P->sup[k] : k] -= dot3(P->Rr + 3 * k, Fl);
    }
  }
}

// the constants of a modal body's inertia at load (after XS and b->partial are set; XX
// allocated 9 nm): XX_k = XS_k + XS_k' (the linear part of J, for a partial body's loop),
// and with partial coupling (P = SS q = 0) H_k = XS_k' + P_k and Mwf, which mbs_body_eval then no
// longer forms (each with the operations of mbs_body_eval's full loop, P_k's zeros included), and
// b->pk, the arrays of its residual by products over the modes (mbs_body_eval, PK_*)
int mbs_body_consts(mbody *b) {
  const double zero = 0;  // P_k of a partial body
  const int nm = b->nm;
  for (int k = 0; k < nm; k++) {
    const double *X = b->XS + 9 * k;
    double *XX = b->XX + 9 * k, *Hk = b->Hk + 9 * k, *Mw = b->Mwf + 3 * k;
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        XX[a + 3 * bb] = X[a + 3 * bb] + X[bb + 3 * a];
        b->XT[9 * k + a + 3 * bb] = X[bb + 3 * a];
        if (b->partial) XX[a + 3 * bb] += zero, Hk[a + 3 * bb] = X[bb + 3 * a] + zero;
      }
    }
    if (b->partial) Mw[0] = Hk[5] - Hk[7], Mw[1] = Hk[6] - Hk[2], Mw[2] = Hk[1] - Hk[3];
  }
  if (nm == 0) return FMBD_OK;
  if (!b->partial) {  // full coupling: SS packed, the arrays of its sums (full_ws)
    FMBD_CHECK(b->pk = fmbd_malloc(sizeof(double) * full_size(nm)), FMBD_ERR_NOMEM,
               "out of memory");
    full_consts(b);
    return FMBD_OK;
  }
  FMBD_CHECK(b->pk = fmbd_malloc(sizeof(double) * PK_SIZE * (size_t)nm), FMBD_ERR_NOMEM,
             "out of memory");
  double *E1 = b->pk, *E2 = E1 + 9 * (size_t)nm, *E3 = E2 + 12 * (size_t)nm,
         *G = E3 + 6 * (size_t)nm;
  for (int k = 0; k < nm; k++) {
    const double *S1 = b->S1 + 3 * k, *XX = b->XX + 9 * k, *Hk = b->Hk + 9 * k,
                 *Mw = b->Mwf + 3 * k;
    double *e1 = E1 + 9 * k, *e2 = E2 + 12 * k, *e3 = E3 + 6 * k;
    for (int a = 0; a < 3; a++) e1[a] = e2[a] = e3[a] = S1[a], e3[3 + a] = Mw[a];
    // J's upper triangle (0,0) (0,1) (0,2) (1,1) (1,2) (2,2) from XX[a + 3 b]
    e1[3] = XX[0], e1[4] = XX[3], e1[5] = XX[6], e1[6] = XX[4], e1[7] = XX[7], e1[8] = XX[8];
    for (int i = 0; i < 9; i++) e2[3 + i] = Hk[i];
    // the modal row: w' (H_k - tr H_k 1) w on [w0^2, w1^2, w2^2, w0 w1, w0 w2, w1 w2],
    // S1_k . A'(R'' - g), Mwf_k . wd
    const double tr = Hk[0] + Hk[4] + Hk[8];
    const double g6[6] = {Hk[0] - tr,    Hk[4] - tr,    Hk[8] - tr,
                          Hk[1] + Hk[3], Hk[2] + Hk[6], Hk[5] + Hk[7]};
    for (int i = 0; i < 6; i++) G[k + (size_t)nm * i] = g6[i];
    for (int a = 0; a < 3; a++) {
      G[k + (size_t)nm * (6 + a)] = S1[a];
      G[k + (size_t)nm * (9 + a)] = Mw[a];
    }
  }
  return FMBD_OK;
}

// mbs_body_inert2 (fmbd_mbs_impl.h). Full coupling: sum_kl q_k q_l SS_kl = sum_k q_k P_k with
// P = SS q, and sum_kl q'_k q_l SSx_lk = sum_l q_l (SSx q')_l, by the evaluation's products
// (mbs_ssq; SSx's rows of full_ws) in its workspace (the outputs are formed between steps): the
// loops over the pairs (k, l) took 1-2 us an output at 30 modes, 10,000 pairs at 100
void mbs_body_inert2(const mbody *b, const double *q, const double *qd, double *J, double *Mwfqd) {
  const int nm = b->nm;
  if (!b->partial && nm > 0) {
    const full_ws f = full_at(b);
    const int nmp = f.nmp;
    mbs_ssq(nm, f.St, q, f.P, f.v);
    matvec(3 * nm, nm, f.SX, qd, 1.0, f.cor);
    spread_rows(3, nm, nmp, f.cor);
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        const double *P = f.P + (size_t)nmp * (a + 3 * bb);
        double t = 0;
        for (int k = 0; k < nm; k++) t += q[k] * P[k];
        J[3 * a + bb] += t;
      }
      const double *t3 = f.cor + (size_t)nmp * a;
      double t = 0;
      for (int l = 0; l < nm; l++) t += q[l] * t3[l];
      Mwfqd[a] += t;
    }
  }
  for (int k = 0; k < nm; k++) {
    for (int a = 0; a < 3; a++) Mwfqd[a] += qd[k] * b->XSx[a + 3 * k];
  }
}

// mbs_body_eval: the body's residual r (n = 7 + nm) in x coordinates, r = T'(Mb acc + v - f) (+ Kq
// + Dq' in the modal rows), and optionally the block B = T'(cm Mb + cc Cb)T + ck Kx (n x n,
// column-major), T = diag(1, 2G, 1) mapping x' to [R'; wb; q'].
// xdd may be NULL (zero accelerations). Without ff the modal-modal part of B (rows and columns
// 7..) is neither formed nor written (the Schur path eliminates it: mbs_body_ff forms it alone).
void mbs_body_eval(fmbd_mbs *m, int ib, double t, const double *xg, const double *xdg,
                   const double *xddg, double *r, double *B, double cm, double cc, double ck,
                   bool ff) {
  mbody *b = &m->b[ib];
  const int nm = b->nm, n6 = 6 + nm, n = b->n;
  const double *x = xg + b->off, *xd = xdg + b->off, *xdd = xddg ? xddg + b->off : NULL;
  // elastic coordinates at qoff (off + 7, or a shared set's block)
  const double *p = x + 3, *q = xg + b->qoff, *pd = xd + 3, *qd = xdg + b->qoff;
  const double *qdd = xddg ? xddg + b->qoff : NULL;
  double *A = b->A, *G = b->G, w[3], wd[3];
  mbs_frame_kin(b, p, pd, xdd ? xdd + 3 : NULL, w, wd);
  // --- inertia at q: c, J, H_k, Mwf, H ---
  // c, J and s1qd accumulated in locals (registers: the sums over the modes are chains of
  // dependent additions, which through b->c, b->J in memory waited on each store; the same
  // operations in the same order), copied to the body below
  double *c = b->c, *J = b->J, *I = b->I, H[9] = {0};
  double cl[3], Jl[9];
  memcpy(cl, b->c0, sizeof cl);
  memcpy(Jl, b->J0, sizeof Jl);
  double s1qd[3] = {0, 0, 0};
  // a partial body with diagonal Mff and Kff (the usual one): its residual by products over the
  // modes with the constant arrays b->pk (mbs_body_consts): other round-off than the loops below
  const bool fast = b->partial && b->pk && b->mdiag && b->kdiag;
  const double *E1 = b->pk, *E2 = E1 + 9 * (size_t)nm, *E3 = E2 + 12 * (size_t)nm,
               *PG = E3 + 6 * (size_t)nm;
  if (fast) {
    double u1[9], u2[12];
    matvec(9, nm, E1, q, 1.0, u1);
    matvec(12, nm, E2, qd, 1.0, u2);
    for (int a = 0; a < 3; a++) cl[a] += u1[a], s1qd[a] = u2[a];
    Jl[0] += u1[3], Jl[1] += u1[4], Jl[2] += u1[5], Jl[4] += u1[6], Jl[5] += u1[7], Jl[8] += u1[8];
    Jl[3] = Jl[1], Jl[6] = Jl[2], Jl[7] = Jl[5];
    for (int i = 0; i < 9; i++) H[i] = u2[3 + i];
  } else if (nm > 0 && b->partial) {
    // partial coupling: H_k, Mwf constant (mbs_body_consts) and J symmetric term by term (J0 is,
    // and each term is q_k XX_k, XX_k = XS_k + XS_k' + 0 as the full loop below adds P_k = 0):
    // its upper triangle mirrored, the same bits as the full loop and its symmetrisation
    for (int k = 0; k < nm; k++) {
      const double *XX = b->XX + 9 * k, *Hk = b->Hk + 9 * k;
      for (int a = 0; a < 3; a++) {
        cl[a] += b->S1[a + 3 * k] * q[k];
        s1qd[a] += b->S1[a + 3 * k] * qd[k];
        for (int bb = a; bb < 3; bb++) Jl[3 * a + bb] += q[k] * XX[a + 3 * bb];
      }
      for (int i = 0; i < 9; i++) H[i] += qd[k] * Hk[i];
    }
    Jl[3] = Jl[1], Jl[6] = Jl[2], Jl[7] = Jl[5];
  } else if (nm > 0) {
    // full coupling: P = SS q (mbs_ssq), then c, J, H, S1 q' and H_k in lanes of four modes
    const full_ws f = full_at(b);
    pad_copy(nm, f.nmp, q, f.q);
    pad_copy(nm, f.nmp, qd, f.qd);
    mbs_ssq(nm, f.St, q, f.P, f.v);  // f.v: mbs_ssq's workspace (the modal rows' come later)
    double Ju[9], cu[3];
    fs_inertia(&f, Ju, H, cu, s1qd);
    for (int a = 0; a < 3; a++) {
      cl[a] += cu[a];
      for (int bb = 0; bb < 3; bb++) Jl[3 * a + bb] += Ju[a + 3 * bb];
    }
    // symmetrise J (round-off)
    for (int a = 0; a < 3; a++) {
      for (int bb = a + 1; bb < 3; bb++) {
        double s = 0.5 * (Jl[3 * a + bb] + Jl[3 * bb + a]);
        Jl[3 * a + bb] = Jl[3 * bb + a] = s;
      }
    }
  }
  memcpy(c, cl, sizeof cl);
  memcpy(J, Jl, sizeof Jl);
  double trJ = J[0] + J[4] + J[8];
  for (int i = 0; i < 9; i++) I[i] = -J[i];
  I[0] += trJ, I[4] += trJ, I[8] += trJ;
  double trH = H[0] + H[4] + H[8];
  // --- Mb (n6 x n6, column-major) in bwork ---
  double *Mb = m->bwork, *Cb = m->bwork + (size_t)n6 * n6, *rb = m->bwork + 2 * (size_t)n6 * n6;
#define MB(i, j) Mb[(i) + (size_t)n6 * (j)]
#define CB(i, j) Cb[(i) + (size_t)n6 * (j)]
  // every entry of the columns 0..5 and the rows 0..5 is written below but the off-diagonal
  // of the first 3 x 3; the modal-modal part (the constant Mff) only where the block needs it
  for (int j = 0; j < 6; j++) memset(&MB(0, j), 0, sizeof(double) * 6);
  double Sc[9], Ac[9];
  skew3(c, Sc);
  mm3(A, Sc, Ac);  // A c~
  for (int a = 0; a < 3; a++) {
    MB(a, a) = b->m;
    for (int bb = 0; bb < 3; bb++) {
      MB(a, 3 + bb) = -Ac[3 * a + bb];
      MB(3 + bb, a) = -Ac[3 * a + bb];
      MB(3 + a, 3 + bb) = I[3 * a + bb];
    }
  }
  if (B && nm > 0 && !b->partial) {  // H_k and Mwf_k per mode for the block (partial: constant)
    const full_ws f = full_at(b);
    for (int k = 0; k < nm; k++) {
      double *Hk = b->Hk + 9 * k, *Mw = b->Mwf + 3 * k;
      for (int i = 0; i < 9; i++) Hk[i] = f.H[k + (size_t)f.nmp * i];
      Mw[0] = Hk[5] - Hk[7], Mw[1] = Hk[6] - Hk[2], Mw[2] = Hk[1] - Hk[3];
    }
  }
  // the coupling columns of Mb (A S1_k, Mwf_k and their transposes) only for the block: the
  // residual takes their products from S1, H_k and P directly below
  for (int k = 0; k < nm && B; k++) {
    double as[3];
    mv3(A, b->S1 + 3 * k, as);
    for (int a = 0; a < 3; a++) {
      MB(a, 6 + k) = MB(6 + k, a) = as[a];
      MB(3 + a, 6 + k) = MB(6 + k, 3 + a) = b->Mwf[a + 3 * k];
    }
  }
  if (B && ff) {
    for (int l = 0; l < nm; l++)  // the constant modal mass, column by column
      memcpy(&MB(6, 6 + l), b->Mff + (size_t)nm * l, sizeof(double) * (size_t)nm);
  }
  // --- quadratic velocity vector v and forces f: rb = v - f (+ K q + D q') ---
  double Iw[3];
  mbs_rigid_qv(A, w, c, s1qd, I, H, trH, rb, Iw);
  double ww = dot3(w, w);
  // cor_k = sum_l q'_l SSx[l,k] = -sum_l SSx[k,l] q'_l (antisymmetry), in full_ws's rows (per
  // mode for the block); partial: SSx = 0, cor stays zero
  double *cor = b->cor;
  if (nm > 0 && !b->partial) {
    const full_ws f = full_at(b);
    matvec(3 * nm, nm, f.SX, qd, -1.0, f.cor);
    spread_rows(3, nm, f.nmp, f.cor);
    for (int k = 0; k < nm && B; k++) {
      for (int a = 0; a < 3; a++) cor[a + 3 * k] = f.cor[k + (size_t)f.nmp * a];
    }
  }
  // gravity
  double gl[3];
  mtv3(A, m->g, gl);
  double cg[3];
  cross3(c, gl, cg);
  for (int a = 0; a < 3; a++) rb[a] -= b->m * m->g[a], rb[3 + a] -= cg[a];
  // ag = A'(R'' - g): the modal rows' S1_k . A'R'' (Mb's coupling row) and - S1_k . A'g (gravity)
  double ag[3], ra[3];
  for (int a = 0; a < 3; a++) ra[a] = (xdd ? xdd[a] : 0) - m->g[a];
  mtv3(A, ra, ag);
  if (fast) {  // the inertia terms of the modal rows below (PG)
    for (int k = 0; k < nm; k++)
      rb[6 + k] = b->Kff[k + (size_t)nm * k] * q[k] + b->Dff[k + (size_t)nm * k] * qd[k];
  } else if (nm > 0) {  // (a rigid body has no modal rows)
    // each modal row: w'H_k w - |w|^2 tr H_k = Y : H_k with Y = w w' - |w|^2 1, the Coriolis
    // term 2 w . cor_k, Mb's coupling row S1_k . A'R'' + Mwf_k . wd with the gravity S1_k . A'g
    // (ag), the elastic and damping forces; and the rigid rows' sum_k [S1_k; Mwf_k] q''_k (Mb's
    // coupling columns times q'', added below with its 6 x 6 block)
    double Y[9];
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) Y[a + 3 * bb] = w[a] * w[bb] - (a == bb ? ww : 0);
    }
    double s1a[3] = {0, 0, 0}, mwa[3] = {0, 0, 0};
    if (!b->partial) {
      // full coupling: Y : H_k + Mwf_k . wd with wd's antisymmetric part in Y (Mwf_k = (H_k,21 -
      // H_k,12, H_k,02 - H_k,20, H_k,10 - H_k,01), entry a + 3b of H_k its (a, b)), S1_k . ag and
      // 2 w . cor_k in lanes of four modes (fs_rows), the rigid rows' sums over q'' with them
      const full_ws f = full_at(b);
      Y[5] += wd[0], Y[7] -= wd[0], Y[6] += wd[1], Y[2] -= wd[1], Y[1] += wd[2], Y[3] -= wd[2];
      const double w2[3] = {2 * w[0], 2 * w[1], 2 * w[2]};
      double hq[9];
      if (xdd) pad_copy(nm, f.nmp, qdd, f.qdd);
      fs_rows(&f, Y, ag, w2, xdd != NULL, s1a, hq);
      for (int k = 0; k < nm; k++) rb[6 + k] = f.v[k];
      if (b->kdiag) {
        for (int k = 0; k < nm; k++)
          rb[6 + k] += b->Kff[k + (size_t)nm * k] * q[k] + b->Dff[k + (size_t)nm * k] * qd[k];
      } else {
        matvec_add(nm, nm, b->Kff, nm, q, 1.0, rb + 6);
        matvec_add(nm, nm, b->Dff, nm, qd, 1.0, rb + 6);
      }
      mwa[0] = hq[5] - hq[7], mwa[1] = hq[6] - hq[2], mwa[2] = hq[1] - hq[3];
    }
    for (int k = 0; k < nm && b->partial; k++) {  // partial coupling: H_k, Mwf_k constant
      const double *Hk = b->Hk + 9 * k, *S1 = b->S1 + 3 * k, *Mw = b->Mwf + 3 * k;
      double v = Y[0] * Hk[0] + Y[1] * Hk[1] + Y[2] * Hk[2] + Y[3] * Hk[3] + Y[4] * Hk[4] +
                 Y[5] * Hk[5] + Y[6] * Hk[6] + Y[7] * Hk[7] + Y[8] * Hk[8];
      v += S1[0] * ag[0] + S1[1] * ag[1] + S1[2] * ag[2];
      v += Mw[0] * wd[0] + Mw[1] * wd[1] + Mw[2] * wd[2];
      if (b->kdiag) {
        v += b->Kff[k + (size_t)nm * k] * q[k] + b->Dff[k + (size_t)nm * k] * qd[k];
      } else {
        for (int l = 0; l < nm; l++)
          v += b->Kff[k + (size_t)nm * l] * q[l] + b->Dff[k + (size_t)nm * l] * qd[l];
      }
      rb[6 + k] = v;
      if (xdd) {
        for (int a = 0; a < 3; a++) s1a[a] += S1[a] * qdd[k], mwa[a] += Mw[a] * qdd[k];
      }
    }
    if (xdd) {  // rb += [A S1 q''; Mwf q''] and Mff q''
      double au[3];
      mv3(A, s1a, au);
      for (int a = 0; a < 3; a++) rb[a] += au[a], rb[3 + a] += mwa[a];
      if (b->mdiag) {
        for (int k = 0; k < nm; k++) rb[6 + k] += b->Mff[k + (size_t)nm * k] * qdd[k];
      } else {
        matvec_add(nm, nm, b->Mff, nm, qdd, 1.0, rb + 6);
      }
    }
  }
  mbs_body_loads(m, ib, t, A, q, rb, rb + 6);
  if (fast) {  // rb_k += w' (H_k - tr H_k) w + S1_k . A'(R'' - g) + Mwf_k . wd (+ Mff_kk q''_k)
    double z[12] = {w[0] * w[0], w[1] * w[1], w[2] * w[2], w[0] * w[1], w[0] * w[2], w[1] * w[2]};
    for (int a = 0; a < 3; a++) z[6 + a] = ag[a];
    z[9] = wd[0], z[10] = wd[1], z[11] = wd[2];
    matvec_add(nm, 12, PG, nm, z, 1.0, rb + 6);
  }
  // rb += Mb acc_b: the rigid rows' 6 x 6 block (the coupling: above, or A S1 q'' and Mwf q'')
  if (xdd) {
    double acc6[6] = {xdd[0], xdd[1], xdd[2], wd[0], wd[1], wd[2]};
    matvec_add(6, 6, Mb, n6, acc6, 1.0, rb);
  }
  if (xdd && fast) {
    double u3[6], au[3];
    matvec(6, nm, E3, qdd, 1.0, u3);
    mv3(A, u3, au);
    for (int a = 0; a < 3; a++) rb[a] += au[a], rb[3 + a] += u3[3 + a];
    for (int k = 0; k < nm; k++) rb[6 + k] += b->Mff[k + (size_t)nm * k] * qdd[k];
  }
  // r = T' rb
  for (int k = 0; k < nm; k++) r[7 + k] = rb[6 + k];
  mbs_rigid_rows(b, rb, p, xdd ? xdd + 3 : NULL, r);
  const double mu = PMASS * b->snorm;
  if (!B) return;
  memcpy(b->wB, w, sizeof b->wB);
  // --- velocity tangent Cb (d v / d [R', wb, q']) ---
  // without ff only columns 0..5 and rows 0..5 of columns 6.. are formed (and read below)
  if (ff) {
    memset(Cb, 0, sizeof(double) * (size_t)n6 * n6);
  } else {
    memset(Cb, 0, sizeof(double) * (size_t)n6 * 6);
    for (int l = 0; l < nm; l++) memset(&CB(0, 6 + l), 0, sizeof(double) * 6);
  }
  if (cc != 0) {
    double AM[9], WW[9];
    mbs_rigid_vel_tangent(A, w, c, Sc, s1qd, I, Iw, H, trH, AM, WW);
    for (int a = 0; a < 3; a++) {
      for (int bb = 0; bb < 3; bb++) {
        CB(a, 3 + bb) = AM[3 * a + bb];
        CB(3 + a, 3 + bb) = WW[3 * a + bb];
      }
    }
    for (int k = 0; k < nm; k++) {
      const double *Hk = b->Hk + 9 * k;
      double ws[3], aws[3];
      cross3(w, b->S1 + 3 * k, ws);
      mv3(A, ws, aws);
      double trk = Hk[0] + Hk[4] + Hk[8];
      double hkw[3], hktw[3];
      for (int a = 0; a < 3; a++) {
        hkw[a] = Hk[a] * w[0] + Hk[a + 3] * w[1] + Hk[a + 6] * w[2];
        hktw[a] = Hk[3 * a] * w[0] + Hk[3 * a + 1] * w[1] + Hk[3 * a + 2] * w[2];
      }
      const double *cor = b->cor + 3 * k;
      if (ff) {
        for (int l = 0; l < nm; l++) {
          const double *sx = b->SSx + 3 * l + 3 * (size_t)nm * k;
          CB(6 + k, 6 + l) = 2 * dot3(w, sx) + b->Dff[k + (size_t)nm * l];
        }
      }
      for (int a = 0; a < 3; a++) {
        CB(a, 6 + k) = 2 * aws[a];
        CB(3 + a, 6 + k) = 2 * (trk * w[a] - hkw[a]);
        CB(6 + k, 3 + a) = hkw[a] + hktw[a] - 2 * trk * w[a] + 2 * cor[a];
      }
    }
  }
  // Z = cm Mb + cc Cb (into Mb)
  if (ff) {
    for (size_t i = 0; i < (size_t)n6 * n6; i++) Mb[i] = cm * Mb[i] + cc * Cb[i];
  } else {
    for (size_t i = 0; i < (size_t)n6 * 6; i++) Mb[i] = cm * Mb[i] + cc * Cb[i];
    for (int l = 0; l < nm; l++) {
      for (int i = 0; i < 6; i++) MB(i, 6 + l) = cm * MB(i, 6 + l) + cc * CB(i, 6 + l);
    }
  }
  // B = T' Z T
  // rows/cols map: x index i -> b index (R: i; p: via 2G; q: i - 1)
  // first Y = Z T (n6 x n): its columns of R and q are Z's own (read in place), those of p
  // (Z's columns 3..5 times 2 G) formed in Cb (without ff: rows 0..5 of the columns 7..)
  double *Y = Cb;
  for (int c4 = 0; c4 < 4; c4++) {
    double *yc = Y + (size_t)n6 * c4;
    double g0 = 2 * G[c4], g1 = 2 * G[4 + c4], g2 = 2 * G[8 + c4];
    const double *z3 = Mb + (size_t)n6 * 3, *z4 = Mb + (size_t)n6 * 4, *z5 = Mb + (size_t)n6 * 5;
    for (int i = 0; i < n6; i++) yc[i] = z3[i] * g0 + z4[i] * g1 + z5[i] * g2;
  }
  for (int j = 0; j < n; j++) {
    const double *yc = j < 3 ? Mb + (size_t)n6 * j
                             : (j < 7 ? Y + (size_t)n6 * (j - 3) : Mb + (size_t)n6 * (j - 1));
    double *bc = B + (size_t)n * j;
    bc[0] = yc[0], bc[1] = yc[1], bc[2] = yc[2];
    for (int c4 = 0; c4 < 4; c4++)
      bc[3 + c4] = 2 * (G[c4] * yc[3] + G[4 + c4] * yc[4] + G[8 + c4] * yc[5]);
    if (ff || j < 7) {
      for (int k = 0; k < nm; k++) bc[7 + k] = yc[6 + k];
    }
  }
  for (int i = 0; i < 4; i++) {
    for (int j = 0; j < 4; j++) B[(3 + i) + (size_t)n * (3 + j)] += cm * mu * p[i] * p[j];
  }
  if (ck != 0 && ff) {
    for (int k = 0; k < nm; k++) {
      for (int l = 0; l < nm; l++)
        B[(7 + k) + (size_t)n * (7 + l)] += ck * b->Kff[k + (size_t)nm * l];
    }
  }
#undef MB
#undef CB
}

// the modal-modal block of body ib's iteration block, cm Mff + cc (2 w . SSx + Dff) + ck Kff
// with (cm, cc, ck) of the matrix in Ax (m->mcoef) and w of the body's last block evaluation
// (b->wB), written into Ax at its positions: the entries mbs_body_eval leaves out without ff,
// with the same operations in the same order (the same bits as mbs_body_eval with ff)
void mbs_body_ff(fmbd_mbs *m, int ib) {
  const mbody *b = &m->b[ib];
  const int nm = b->nm, n = b->n;
  const double cm = m->mcoef[0], cc = m->mcoef[1], ck = m->mcoef[2], *w = b->wB;
  const int64_t *pos = m->bpos[ib];
  for (int l = 0; l < nm; l++) {
    for (int k = 0; k < nm; k++) {
      const size_t e = k + (size_t)nm * l;
      double cb = 0;
      if (cc != 0) cb = 2 * dot3(w, b->SSx + 3 * l + 3 * (size_t)nm * k) + b->Dff[e];
      double z = cm * b->Mff[e] + cc * cb;
      if (ck != 0) z += ck * b->Kff[e];
      m->Ax[pos[(7 + k) + (size_t)n * (7 + l)]] = z;
    }
  }
}
