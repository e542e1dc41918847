// tests/unit/t131-klu.c: fmbd_klu's two engines (KLU and UMFPACK, chosen by FMBD_SPARSE_LU) on
// a bordered system [K C'; C 0] of the multibody kind: K an unsymmetric tridiagonal matrix of
// order 190 (diagonal 4, off-diagonals -1 and -1.5), C 10 rows picking single unknowns. Each
// engine solves A x = b for a known x (b = A x computed here), again after new values (a second
// factorisation on the same analysis), reports a numerically zero column as singular with that
// column's index, and refuses to solve once the factor is dropped; KLU again with its analysis
// forced with and without the block triangular form (FMBD_KLU_BTF). The second factorisation
// is KLU's refactorisation, unscaled, whose factor fmbd_klu solves by its own triangular
// solves where it is one block (checked where BTF is forced off: with BTF, KLU splits this
// matrix into blocks and solves it itself); a full factorisation (the first, and the recovery
// after a singular one) is solved by KLU. A refactorisation whose values hold exact zeros in the
// pattern (K's off-diagonals in 15 of 16 columns: fill of the factor that is exactly zero) is
// solved by the own solves with those entries dropped, to the same residual bound. A first
// factorisation with those zeros has KLU analyse the pattern without them (fmbd_klu_dropped);
// each later one that has some of them nonzero again takes those back (the dropped count falls),
// and after five such the caller's whole pattern is used (none dropped): every solve to the
// same bound. And fmbd_klu's own refactorisation gives KLU's klu_l_refactor's factor bit for bit
// (same_bits: the solutions compared bitwise after each way on the same values).
// SPDX-License-Identifier: MIT
//
// Tolerance: LU with partial (threshold) pivoting is backward stable, |A x^ - b| <= c n eps
// |A| |x^| with modest growth here (diagonally dominant K, unit entries in C); the relative
// residual |A x^ - b|_inf / (|A|_inf |x^|_inf) is then a few 1e-16 times a small constant;
// 1e-13 leaves a factor of 100 and catches any wrong solve (O(1)).
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmbd_err.h"
#include "fmbd_klu.h"

#define NK 190
#define NC 10
#define N (NK + NC)

static int64_t Ap[N + 1], Ai[5 * N];
static double Ax[5 * N];

// build: K's off-diagonals exactly zero (pattern kept) in the columns c with c % 16 >= holes
// (0: none)
static int holes;

// pattern and values by columns (rows sorted); scale multiplies K's values
static void build(double scale) {
  int64_t nz = 0;
  for (int64_t c = 0; c < N; c++) {
    Ap[c] = nz;
    if (c < NK) {
      if (c > 0) Ai[nz] = c - 1, Ax[nz++] = -1.5 * scale;
      Ai[nz] = c, Ax[nz++] = 4 * scale;
      if (c + 1 < NK) Ai[nz] = c + 1, Ax[nz++] = -1 * scale;
      if (c % 19 == 7) Ai[nz] = NK + c / 19, Ax[nz++] = 1;  // C's entry (row NK + k)
    } else {
      Ai[nz] = (c - NK) * 19 + 7, Ax[nz++] = 1;  // C' in column NK + k
    }
  }
  Ap[N] = nz;
  for (int64_t c = 0; c < NK && holes; c++)
    for (int64_t p = Ap[c]; p < Ap[c + 1] && c % 16 >= holes; p++)
      if (Ai[p] != c && Ai[p] < NK) Ax[p] = 0;
}

static double residual(const double *x, const double *b) {
  double r[N] = {0}, anorm = 0, xn = 0, rn = 0, rows[N] = {0};
  for (int64_t c = 0; c < N; c++)
    for (int64_t p = Ap[c]; p < Ap[c + 1]; p++) {
      r[Ai[p]] += Ax[p] * x[c];
      rows[Ai[p]] += fabs(Ax[p]);
    }
  for (int i = 0; i < N; i++) {
    anorm = fmax(anorm, rows[i]);
    xn = fmax(xn, fabs(x[i]));
    rn = fmax(rn, fabs(r[i] - b[i]));
  }
  return rn / (anorm * xn);
}

static void solve_check(fmbd_klu *F, const char *eng, double scale) {
  build(scale);
  EXPECT(fmbd_klu_factor(F, Ax) == FMBD_OK, "%s: factor (scale %g)", eng, scale);
  EXPECT(fmbd_klu_rcond(F) > 1e-3, "%s: rcond %g of a well-conditioned matrix", eng,
         fmbd_klu_rcond(F));
  double xt[N], b[N] = {0}, x[N];
  for (int i = 0; i < N; i++) xt[i] = sin(0.37 * i + 1);
  for (int64_t c = 0; c < N; c++)
    for (int64_t p = Ap[c]; p < Ap[c + 1]; p++) b[Ai[p]] += Ax[p] * xt[c];
  for (int i = 0; i < N; i++) x[i] = b[i];
  EXPECT(fmbd_klu_solve(F, x) == FMBD_OK, "%s: solve", eng);
  double res = residual(x, b);
  EXPECT(res < 1e-13, "%s: relative residual %g (scale %g)", eng, res, scale);
}

static void engine(const char *name, int umf, int own) {
  setenv("FMBD_SPARSE_LU", name, 1);
  build(1);
  fmbd_klu *F = NULL;
  EXPECT(fmbd_klu_analyze(N, Ap, Ai, &F) == FMBD_OK && F, "%s: analyze", name);
  if (!F) return;
  EXPECT(fmbd_klu_is_umfpack(F) == umf, "%s: engine %d", name, fmbd_klu_is_umfpack(F));
  solve_check(F, name, 1);
  EXPECT(!fmbd_klu_own_solves(F), "%s: own solves after a full factorisation", name);
  solve_check(F, name, 2.5);  // new values, same analysis (KLU: the refactorisation)
  if (own >= 0)
    EXPECT(fmbd_klu_own_solves(F) == own, "%s: own solves %d after a refactorisation", name,
           fmbd_klu_own_solves(F));
  solve_check(F, name, 0.7);  // and another
  EXPECT(fmbd_klu_dropped(F) == 0, "%s: %lld entries dropped without zeros in the values", name,
         (long long)fmbd_klu_dropped(F));
  holes = 1;  // a refactorisation with exact zeros in its values (own solves: dropped)
  solve_check(F, name, 1.3);
  if (own >= 0)
    EXPECT(fmbd_klu_own_solves(F) == own, "%s: own solves %d with zeros in the values", name,
           fmbd_klu_own_solves(F));
  holes = 0;
  // a numerically zero column (pattern kept): singular, at that column
  const int64_t zc = 42;
  build(1);
  for (int64_t p = Ap[zc]; p < Ap[zc + 1]; p++) Ax[p] = 0;
  int rc = fmbd_klu_factor(F, Ax);
  EXPECT(rc == FMBD_ERR_SINGULAR, "%s: zero column: rc %d", name, rc);
  EXPECT(fmbd_klu_singular_col(F) == zc, "%s: singular column %lld, expected %lld", name,
         (long long)fmbd_klu_singular_col(F), (long long)zc);
  double x[N] = {0};
  EXPECT(fmbd_klu_solve(F, x) != FMBD_OK, "%s: solve after a singular factorisation", name);
  solve_check(F, name, 1);  // recovers
  fmbd_klu_drop_factor(F);
  EXPECT(fmbd_klu_rcond(F) == 0, "%s: rcond without a factor", name);
  EXPECT(fmbd_klu_solve(F, x) == FMBD_ERR_VALUE, "%s: solve without a factor", name);
  fmbd_klu_destroy(&F);
  EXPECT(!F, "%s: destroy", name);
}

// the pattern without the first factorisation's zeros, taken back where they turn nonzero
static void reduced(void) {
  setenv("FMBD_SPARSE_LU", "klu", 1);
  build(1);
  fmbd_klu *F = NULL;
  EXPECT(fmbd_klu_analyze(N, Ap, Ai, &F) == FMBD_OK && F, "reduced: analyze");
  if (!F) return;
  holes = 1;
  solve_check(F, "reduced", 1);
  int64_t d = fmbd_klu_dropped(F);
  // K's off-diagonals in the columns c % 16 >= 1: 2 each but at the ends
  EXPECT(d >= 2 * (NK * 15 / 16 - 2) && d <= 2 * (NK * 15 / 16 + 1),
         "reduced: %lld entries dropped", (long long)d);
  solve_check(F, "reduced", 2.5);  // the same zeros: refactorised on the reduced pattern
  EXPECT(fmbd_klu_dropped(F) == d, "reduced: %lld dropped after a refactorisation",
         (long long)fmbd_klu_dropped(F));
  for (int h = 2; h <= 6; h++) {  // the columns c % 16 == h - 1 nonzero again: taken back
    holes = h;
    solve_check(F, "reduced", 1 + 0.1 * h);
    int64_t dn = fmbd_klu_dropped(F);
    if (h < 6)
      EXPECT(dn < d && dn > 0, "reduced: holes %d: %lld dropped (before %lld)", h, (long long)dn,
             (long long)d);
    else
      EXPECT(dn == 0, "reduced: the whole pattern after five analyses: %lld dropped",
             (long long)dn);
    d = dn;
  }
  holes = 0;
  solve_check(F, "reduced", 1);
  fmbd_klu_destroy(&F);
  unsetenv("FMBD_SPARSE_LU");
}

// fmbd_klu's own refactorisation against KLU's klu_l_refactor on the same values: the same
// factor bit for bit (KLU's operations in KLU's order; fmbd_klu.c, own_refactor), so the same
// solution bit for bit (the sine right-hand side has no exact zero in its solution, whose sign
// the own solves on a factor with exact zeros may give otherwise); with and without exact
// zeros in the values (K's fill zero in 15 of 16 columns: solved with them dropped)
static void same_bits(void) {
  setenv("FMBD_SPARSE_LU", "klu", 1);
  setenv("FMBD_KLU_BTF", "0", 1);  // one diagonal block: the own refactorisation's case
  build(1);
  fmbd_klu *F = NULL;
  EXPECT(fmbd_klu_analyze(N, Ap, Ai, &F) == FMBD_OK && F, "same bits: analyze");
  if (!F) return;
  EXPECT(fmbd_klu_factor(F, Ax) == FMBD_OK, "same bits: first factorisation");
  const double scales[4] = {2.5, 0.7, 1.3, 3.1};
  for (int s = 0; s < 4; s++) {
    holes = s >= 2;
    build(scales[s]);
    double x[2][N];
    for (int own = 1; own >= 0; own--) {
      fmbd_klu_set_own_refactor(F, own);
      EXPECT(fmbd_klu_factor(F, Ax) == FMBD_OK, "same bits: refactorisation (own %d)", own);
      EXPECT(fmbd_klu_own_solves(F), "same bits: own solves after a refactorisation (own %d)", own);
      for (int i = 0; i < N; i++) x[own][i] = sin(0.37 * i + 1);
      EXPECT(fmbd_klu_solve(F, x[own]) == FMBD_OK, "same bits: solve (own %d)", own);
    }
    int diff = 0;
    for (int i = 0; i < N; i++) diff += memcmp(&x[0][i], &x[1][i], sizeof(double)) != 0;
    EXPECT(diff == 0, "same bits: %d of %d solution entries differ (scale %g, zeros %d)", diff, N,
           scales[s], holes);
  }
  holes = 0;
  fmbd_klu_set_own_refactor(F, 1);
  fmbd_klu_destroy(&F);
  unsetenv("FMBD_KLU_BTF");
}

int main(void) {
  same_bits();
  reduced();
  engine("klu", 0, -1);
  engine("umfpack", 1, 0);
  engine("", 0, -1);  // automatic: order 200 is below the UMFPACK threshold
  // KLU's analysis with and without its block triangular form, each forced (the automatic
  // choice, the smaller predicted factor, ran above): the same checks on both orderings
  setenv("FMBD_KLU_BTF", "1", 1);
  engine("klu", 0, 0);
  setenv("FMBD_KLU_BTF", "0", 1);
  engine("klu", 0, 1);
  unsetenv("FMBD_KLU_BTF");
  unsetenv("FMBD_SPARSE_LU");
  TEST_EXIT();
}
