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
  TEST_EXIT();
}
