// tests/unit/t513-mbs-matvec.c: the multibody core's small dense product y += alpha A x
// (mbs_matvec_add: the AVX2 form where the processor has it, fmbd_mbs_body.c) gives the same
// bits as the portable form (mbs_matvec_add_portable) for every shape the core uses: odd and
// even row counts (the portable form sums an odd last row in another order), column counts
// below, at and past the 4- and 8-column passes, a leading dimension above the row count.
// SPDX-License-Identifier: MIT
//
// Bitwise, not within a tolerance: the two forms do the same operations in the same order per
// entry (no FMA), and the modal bodies' results are promised the same bits on every processor
// (bench/README.md). The entries span 2^-20..2^20 so that any other order of the additions
// changes the last bits; the check that it does: a sum of each four columns' products added to
// y as one (the odd row's order used for every row) differs from the portable form somewhere.
//
// The same for full inertia coupling's P = SS q (mbs_ssq: from SS's upper triangle at 40 modes
// and more, the whole SS below; mbs_ss_pack): the AVX2 and portable forms the same bits at 1-13,
// 30 and 39 modes (the whole SS) and 40-47, 64 and 100 (the triangle: every padding of the 4-row
// blocks); both within the round-off bound of a sum of nm products, nm eps sum_l |SS_ab,kl q_l|
// (Higham's gamma_n; SS here exactly symmetric, so the triangle's mean of the two copies is
// exact), of the sum taken in long double; and the sum in the order of l (double) differs from
// them somewhere (the check is not trivially met).
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_mbs_impl.h"

static double rnd(unsigned *s) {
  *s = *s * 1103515245u + 12345u;
  double u = (double)((*s >> 8) & 0xffff) / 65536.0 - 0.5;
  *s = *s * 1103515245u + 12345u;
  return ldexp(u, (int)((*s >> 8) % 41) - 20);
}

int main(void) {
  unsigned seed = 12345u;
  enum { MMAX = 41, NMAX = 21, PAD = 3 };
  static double A[(MMAX + PAD) * NMAX], x[NMAX], y0[MMAX], y1[MMAX], y2[MMAX];
  const double alphas[3] = {1.0, -1.0, 0.7};
  int checked = 0, reordered = 0;
  for (int m = 1; m <= MMAX; m++) {
    for (int n = 1; n <= NMAX; n++) {
      const int lda = m + (n % 2 ? PAD : 0);
      for (int ia = 0; ia < 3; ia++) {
        for (int i = 0; i < lda * n; i++) A[i] = rnd(&seed);
        for (int j = 0; j < n; j++) x[j] = rnd(&seed);
        for (int i = 0; i < m; i++) y0[i] = y1[i] = y2[i] = rnd(&seed);
        mbs_matvec_add(m, n, A, lda, x, alphas[ia], y0);
        mbs_matvec_add_portable(m, n, A, lda, x, alphas[ia], y1);
        EXPECT(memcmp(y0, y1, sizeof(double) * (size_t)m) == 0,
               "m %d n %d lda %d alpha %g: the two forms differ", m, n, lda, alphas[ia]);
        // another order: each four columns' products summed, then added
        for (int j = 0; j + 4 <= n; j += 4) {
          for (int i = 0; i < m; i++) {
            double s = 0;
            for (int c = j; c < j + 4; c++) s += alphas[ia] * x[c] * A[i + (size_t)lda * c];
            y2[i] += s;
          }
        }
        for (int j = n - n % 4; j < n; j++) {
          for (int i = 0; i < m; i++) y2[i] += alphas[ia] * x[j] * A[i + (size_t)lda * j];
        }
        reordered += memcmp(y2, y1, sizeof(double) * (size_t)m) != 0;
        checked++;
      }
    }
  }
  EXPECT(reordered > checked / 2, "another order of the sums changed only %d of %d products",
         reordered, checked);
  const int nms[] = {1,  2,  3,  4,  5,  6,  7,  8,  9,  10, 11, 12, 13,
                     30, 39, 40, 41, 42, 43, 44, 45, 46, 47, 64, 100};
  int sdiff = 0, scount = 0;
  for (size_t in = 0; in < sizeof nms / sizeof nms[0]; in++) {
    const int nm = nms[in], nmp = (nm + 3) & ~3;
    const size_t n1 = (size_t)nm;
    double *SS = malloc(sizeof(double) * 9 * n1 * n1),
           *St = malloc(sizeof(double) * mbs_ss_size(nm));
    double *q = malloc(sizeof(double) * n1), *P0 = malloc(sizeof(double) * 9 * (size_t)nmp);
    double *P1 = malloc(sizeof(double) * 9 * (size_t)nmp),
           *qp = malloc(sizeof(double) * (size_t)nmp);
    if (!SS || !St || !q || !P0 || !P1 || !qp) {
      EXPECT(0, "out of memory");
      TEST_EXIT();
    }
    // SS_ab,kl = SS_ba,lk exactly: each pair of entries drawn once
    for (size_t k = 0; k < n1; k++) {
      for (size_t l = 0; l < n1; l++) {
        for (int a = 0; a < 3; a++) {
          for (int b = 0; b < 3; b++) {
            if (a * n1 + k > b * n1 + l) continue;
            const double v = rnd(&seed);
            SS[a + 3 * b + 9 * k + 9 * n1 * l] = SS[b + 3 * a + 9 * l + 9 * n1 * k] = v;
          }
        }
      }
    }
    for (int k = 0; k < nm; k++) q[k] = rnd(&seed);
    mbs_ss_pack(nm, SS, St);
    mbs_ssq(nm, St, q, P0, qp);
    mbs_ssq_portable(nm, St, q, P1, qp);
    EXPECT(memcmp(P0, P1, sizeof(double) * 9 * (size_t)nmp) == 0,
           "SS q, %d modes: the two forms differ", nm);
    double worst = 0;
    int other = 0;
    for (int k = 0; k < nm; k++) {
      for (int i = 0; i < 9; i++) {
        long double r = 0;
        double bound = 0, lo = 0;
        for (int l = 0; l < nm; l++) {
          const double t = SS[i + 9 * k + 9 * n1 * l] * q[l];
          r += (long double)SS[i + 9 * k + 9 * n1 * l] * q[l];
          lo += t;
          bound += fabs(t);
        }
        bound *= nm * 0x1p-53;
        const double e = fabs((double)(P1[k + nmp * i] - r));
        if (bound > 0) worst = fmax(worst, e / bound);
        EXPECT(e <= bound, "SS q, %d modes, P_%d,%d: %.3g from the long double sum (bound %.3g)",
               nm, k, i, e, bound);
        other += lo != P1[k + nmp * i];
      }
    }
    sdiff += other > 0, scount += nm >= 40;
    printf(
        "t513: SS q, %d modes: bitwise equal forms, worst error %.2f of the bound, %d of %d "
        "entries differ from the sum in the order of l\n",
        nm, worst, other, 9 * nm);
    free(SS), free(St), free(q), free(P0), free(P1), free(qp);
  }
  EXPECT(sdiff >= scount, "the sum in the order of l differed for only %d sizes", sdiff);
  TEST_EXIT();
}
