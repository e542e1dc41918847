// common/fmbd_klu.c: sparse LU through KLU or UMFPACK (fmbd_klu.h)
// SPDX-License-Identifier: MIT
#include "fmbd_klu.h"

#include <klu.h>
#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <umfpack.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"

// refactor with the old pivoting while KLU's rcond estimate stays above this; below it the
// pivot order no longer suits the values and a full factorisation pivots afresh
#define RCOND_MIN 1e-13

// order from which the automatic choice takes UMFPACK. Measured (bench/README.md, "fmbd-run:
// full FE bodies"): on the tet10 rod's [M Cq'; Cq 0], KLU and UMFPACK tie at 3 k unknowns with
// fixed steps and KLU's refactor wins by 30 % with variable steps (a factorisation at every
// other step); from 6.7 k on UMFPACK wins (fixed steps 1.3x at 6.7 k, 1.8x at 14.7 k; gmsolve's
// total CPU 3.2x at 38 k). Only for matrices as dense as a solid mesh's (tet10: 72 entries a
// column): a 1000-link rigid chain (13 k unknowns, 16 entries a column, little fill) is
// refactored and solved 2.4 times faster by KLU (bench/README.md, the N-link chain)
#define UMF_MIN_N 5000
#define UMF_MIN_COLNNZ 30

struct fmbd_klu {
  int64_t n;
  SuiteSparse_long *Ap, *Ai;
  int umf;  // 1: UMFPACK is the engine, 0: KLU
  int btf;  // KLU's analysis with (1) or without (0) its block triangular form (klu_sym)
  // KLU (the engine, or UMFPACK's fallback on a singular factor: analysed on first use)
  klu_l_common kc;
  klu_l_symbolic *sym;
  klu_l_numeric *num;
  // UMFPACK
  void *usym, *unum;
  double uctl[UMFPACK_CONTROL], uinfo[UMFPACK_INFO];
  double urcond;
  SuiteSparse_long *uWi;
  double *uW, *uX;
  int64_t singular_col;
  // own triangular solves on the extracted factor (own_extract): valid while `own`
  int own;
  SuiteSparse_long *oLp, *oLi, *oUp, *oUi, *oP, *oQ;
  double *oLx, *oUx, *oUi_d, *oy;  // oUi_d: 1 / U's diagonal; oy: work
  // the triangles own_solve reads: the o arrays, or own_refactor's f arrays (own_from_rf)
  const SuiteSparse_long *sLp, *sLi, *sUp, *sUi;
  const double *sLx, *sUx;
  int64_t ocap_l, ocap_u;  // capacities of the L and U arrays
  // own refactorisation (own_refactor): the pattern of the last full factorisation's L and U in
  // KLU's stored order (fLp ... fUx, exact zeros kept; the values those of the last
  // refactorisation), its row permutation's inverse fPinv and column order fQ, the work vector
  // fX (zero between calls); valid while `rf`; frcond: min / max |U_kk| of the last one
  int rf, rf_off;  // rf_off: KLU's refactorisation instead (fmbd_klu_set_own_refactor)
  SuiteSparse_long *fLp, *fLi, *fUp, *fUi, *fPinv, *fQ;
  double *fLx, *fUx, *fX, frcond;
  int64_t fzeros;  // exact zeros off the diagonals in the last own_refactor's L and U
  int64_t fcap_l, fcap_u;
  // the pattern without the entries found exactly zero (red_prepare): KLU's analysis and
  // factor are of it while red > 0 (kAp, kAi then point to rAp, rAi; Ap, Ai stay the
  // caller's); red 0: not yet decided, -1: the caller's pattern for good; nred: analyses
  // since the first
  int red, nred;
  SuiteSparse_long *kAp, *kAi;  // the pattern KLU is given: Ap, Ai or rAp, rAi
  SuiteSparse_long *rAp, *rAi;
  int64_t *rmap;          // the kept entries' positions in the caller's Ax
  double *rAx;            // their values
  unsigned char *rkeep;   // per caller's entry: kept
  int64_t *rdrop, ndrop;  // the dropped entries' positions in the caller's Ax (red_build)
};

// FMBD_SPARSE_LU = klu | umfpack | auto (unset or empty: auto)
static int engine_umf(int64_t n, int64_t nnz) {
  const char *e = getenv("FMBD_SPARSE_LU");
  if (e && !strcmp(e, "klu")) return 0;
  if (e && !strcmp(e, "umfpack")) return 1;
  return n >= UMF_MIN_N && nnz >= UMF_MIN_COLNNZ * n;
}

// the size of the factor KLU's symbolic analysis predicts (AMD's estimates of L and U within
// the diagonal blocks and the entries of the blocks above them): what a solve reads
static double sym_size(const klu_l_symbolic *S) {
  return S->lnz + S->unz + (double)S->nzoff;
}

// KLU's symbolic analysis, with and without its block triangular form (BTF: a maximum
// transversal, then AMD on each diagonal block); the one whose predicted factor is smaller is
// kept (FMBD_KLU_BTF = 0 / 1 forces one). On the KKT matrices [M Cq'; Cq 0] of the multibody
// systems, one irreducible block, the transversal moves entries onto the zero diagonal of
// the constraint rows before AMD and spoils its ordering: the 100-link chain's L + U is 34.0 k
// entries with BTF, 26.7 k without (bench/README.md, the chain's lever 1)
static int klu_sym(fmbd_klu *F) {
  if (F->sym) return FMBD_OK;
  const char *e = getenv("FMBD_KLU_BTF");
  int force = e && (!strcmp(e, "0") || !strcmp(e, "1")) ? e[0] - '0' : -1;
  // the pattern without its zeros (red_prepare): the form chosen for the whole pattern. Both
  // tried, BTF's maximum transversal on the 1000-link chain's reduced pattern took 9 % of the
  // run (three analyses over 0.4 s) and was not chosen
  if (force < 0 && F->red > 0) force = F->btf;
  klu_l_symbolic *best = NULL;
  for (int btf = 1; btf >= 0; btf--) {
    if (force >= 0 && btf != force) continue;
    klu_l_defaults(&F->kc);
    F->kc.halt_if_singular = 1;
    F->kc.btf = btf;
    klu_l_symbolic *S = klu_l_analyze((SuiteSparse_long)F->n, F->kAp, F->kAi, &F->kc);
    if (!S) {
      if (best) klu_l_free_symbolic(&best, &F->kc);
      FMBD_FAIL(F->kc.status == KLU_OUT_OF_MEMORY ? FMBD_ERR_NOMEM : FMBD_ERR_EXTERNAL,
                "KLU symbolic analysis failed (status %ld)", (long)F->kc.status);
    }
    if (!best || sym_size(S) < sym_size(best)) {
      if (best) klu_l_free_symbolic(&best, &F->kc);
      best = S, F->btf = btf;
    } else {
      klu_l_free_symbolic(&S, &F->kc);
    }
  }
  F->sym = best;
  F->kc.btf = F->btf;
  return FMBD_OK;
}

static bool own_rf_off(void);

int fmbd_klu_analyze(int64_t n, const int64_t *Ap, const int64_t *Ai, fmbd_klu **out) {
  int rc = FMBD_OK;
  *out = NULL;
  fmbd_klu *F = NULL;
  FMBD_CHECK(n >= 0 && Ap && Ai, FMBD_ERR_VALUE, "KLU: bad matrix pattern");
  int64_t nnz = Ap[n];
  FMBD_GALLOC(F = fmbd_calloc(1, sizeof *F));
  F->n = n, F->singular_col = -1;
  FMBD_GALLOC(F->Ap = fmbd_malloc(sizeof(SuiteSparse_long) * (size_t)(n + 1)));
  FMBD_GALLOC(F->Ai = fmbd_malloc(sizeof(SuiteSparse_long) * (size_t)(nnz ? nnz : 1)));
  for (int64_t i = 0; i <= n; i++) F->Ap[i] = (SuiteSparse_long)Ap[i];
  for (int64_t i = 0; i < nnz; i++) F->Ai[i] = (SuiteSparse_long)Ai[i];
  F->kAp = F->Ap, F->kAi = F->Ai;
  F->rf_off = own_rf_off();
  F->umf = n > 0 && engine_umf(n, nnz);
  if (!F->umf) {
    FMBD_GCALL(klu_sym(F));
  } else {
    size_t m = (size_t)n;
    FMBD_GALLOC(F->uWi = fmbd_malloc(sizeof(SuiteSparse_long) * m));
    FMBD_GALLOC(F->uW = fmbd_malloc(sizeof(double) * 5 * m));
    FMBD_GALLOC(F->uX = fmbd_malloc(sizeof(double) * m));
    umfpack_dl_defaults(F->uctl);
    F->uctl[UMFPACK_PRL] = 0;     // never prints
    F->uctl[UMFPACK_IRSTEP] = 0;  // no iterative refinement, as with KLU (Ax is not kept)
    // the pattern only (values NULL): AMD on A + A' for the symmetric-pattern systems here,
    // COLAMD otherwise (UMFPACK's automatic strategy)
    long st = umfpack_dl_symbolic((SuiteSparse_long)n, (SuiteSparse_long)n, F->Ap, F->Ai, NULL,
                                  &F->usym, F->uctl, F->uinfo);
    FMBD_GCHECK(st == UMFPACK_OK,
                st == UMFPACK_ERROR_out_of_memory ? FMBD_ERR_NOMEM : FMBD_ERR_EXTERNAL,
                "UMFPACK symbolic analysis failed (status %ld)", st);
  }
  *out = F;
  F = NULL;
done:
  fmbd_klu_destroy(&F);
  return rc;
}

static void umf_free_numeric(fmbd_klu *F) {
  if (F->unum) umfpack_dl_free_numeric(&F->unum);
  F->unum = NULL;
}

// KLU's full factorisation with fresh pivoting (the KLU engine's fallback from a refactor,
// and UMFPACK's on a singular factor, where it finds the zero pivot's column)
static int klu_full(fmbd_klu *F, double *ax) {
  FMBD_CALL(klu_sym(F));
  F->num = klu_l_factor(F->kAp, F->kAi, ax, F->sym, &F->kc);
  if (!F->num || F->kc.status != KLU_OK) {
    int64_t col = (int64_t)F->kc.singular_col;
    F->singular_col = col >= 0 && col < F->n ? col : -1;
    if (F->num) klu_l_free_numeric(&F->num, &F->kc);
    FMBD_CHECK(F->kc.status != KLU_OUT_OF_MEMORY, FMBD_ERR_NOMEM, "out of memory in KLU");
    FMBD_FAIL(FMBD_ERR_SINGULAR, "KLU: singular matrix (status %ld, column %lld)",
              (long)F->kc.status, (long long)F->singular_col);
  }
  return FMBD_OK;
}

// The factor of a refactorisation in compressed columns of our own, for solves that multiply
// by the inverted diagonal of U instead of dividing (own_solve): KLU's usolve divides by U's
// diagonal at each column, a division on the critical path of the back substitution (half of
// usolve's time in perf annotate on the 100-link chain; bench/README.md, "The predictor's
// order"). Only for one diagonal block (no block triangular form: no off-diagonal part) and
// no row scaling (a refactorisation without it, above): x = Q U^-1 L^-1 P b exactly as KLU
// solves it, but for round-off. FMBD_KLU_OWN_SOLVE=0: KLU's own solve.
// the index and value arrays of one triangle grown to nz entries (*cap: their capacity, 0
// when an allocation failed); false when they could not be
static bool own_grow(SuiteSparse_long **i, double **x, int64_t *cap, int64_t nz) {
  if (nz <= *cap) return true;
  fmbd_free(*i), fmbd_free(*x);
  *i = fmbd_malloc(sizeof(SuiteSparse_long) * (size_t)nz);
  *x = fmbd_malloc(sizeof(double) * (size_t)nz);
  *cap = *i && *x ? nz : 0;
  return *cap > 0;
}

// a triangle's columns compacted in place without their exactly zero entries, the diagonal
// kept (first in each column when diag_first, else last)
static void own_drop0(int64_t n, SuiteSparse_long *Xp, SuiteSparse_long *Xi, double *Xx,
                      int diag_first) {
  SuiteSparse_long w = 0, p0 = Xp[0];
  for (int64_t k = 0; k < n; k++) {
    const SuiteSparse_long p1 = Xp[k + 1], d = diag_first ? p0 : p1 - 1;
    Xp[k] = w;
    for (SuiteSparse_long p = p0; p < p1; p++) {
      if (Xx[p] == 0 && p != d) continue;
      Xi[w] = Xi[p], Xx[w] = Xx[p], w++;
    }
    p0 = p1;
  }
  Xp[n] = w;
}

// FMBD_KLU_DROP0=0: the exact zeros kept, in the pattern KLU analyses (red_prepare) and in the
// own solves' factor (own_extract)
static bool keep_zeros(void) {
  static int keep = -1;
  if (keep < 0) keep = getenv("FMBD_KLU_DROP0") && !strcmp(getenv("FMBD_KLU_DROP0"), "0");
  return keep;
}

// the own solves' per-column arrays (n + 1 each), at the first use: all or none (a failed
// allocation leaves none behind, and the next call tries again); false when out of memory
static bool own_cols(fmbd_klu *F) {
  if (F->oy) return true;
  size_t m1 = (size_t)F->n + 1;
  F->oLp = fmbd_malloc(sizeof(SuiteSparse_long) * m1);
  F->oUp = fmbd_malloc(sizeof(SuiteSparse_long) * m1);
  F->oP = fmbd_malloc(sizeof(SuiteSparse_long) * m1);
  F->oQ = fmbd_malloc(sizeof(SuiteSparse_long) * m1);
  F->oUi_d = fmbd_malloc(sizeof(double) * m1);
  F->oy = fmbd_malloc(sizeof(double) * m1);
  if (F->oLp && F->oUp && F->oP && F->oQ && F->oUi_d && F->oy) return true;
  fmbd_free(F->oLp), fmbd_free(F->oUp), fmbd_free(F->oP), fmbd_free(F->oQ);
  fmbd_free(F->oUi_d), fmbd_free(F->oy);
  F->oLp = F->oUp = F->oP = F->oQ = NULL, F->oUi_d = F->oy = NULL;
  return false;
}

static void own_extract(fmbd_klu *F) {
  static int off = -1;
  if (off < 0) off = getenv("FMBD_KLU_OWN_SOLVE") && !strcmp(getenv("FMBD_KLU_OWN_SOLVE"), "0");
  F->own = 0;
  if (off || !F->num || !F->sym || F->sym->nblocks != 1 || F->num->Rs) return;
  const int64_t n = F->n, lnz = F->num->lnz, unz = F->num->unz;
  if (!own_cols(F)) return;
  if (!own_grow(&F->oLi, &F->oLx, &F->ocap_l, lnz) || !own_grow(&F->oUi, &F->oUx, &F->ocap_u, unz))
    return;
  if (!klu_l_extract(F->num, F->sym, F->oLp, F->oLi, F->oLx, F->oUp, F->oUi, F->oUx, NULL, NULL,
                     NULL, F->oP, F->oQ, NULL, NULL, &F->kc))
    return;
  // klu_l_extract puts L's unit diagonal first in each column and U's diagonal last: checked
  // here, the solve skips them (U's inverted)
  for (int64_t k = 0; k < n; k++) {
    SuiteSparse_long l0 = F->oLp[k], u1 = F->oUp[k + 1];
    if (l0 >= F->oLp[k + 1] || F->oLi[l0] != k || u1 <= F->oUp[k] || F->oUi[u1 - 1] != k ||
        F->oUx[u1 - 1] == 0)
      return;
    F->oUi_d[k] = 1 / F->oUx[u1 - 1];
  }
  // the entries that are exactly zero in this factor dropped (kept: L's unit diagonal first and
  // U's diagonal last, which the solve skips): subtracting 0 y_k changes no value, so the solve
  // gives the same numbers (but the sign of a zero) with fewer operations. A mechanism moving in
  // a plane (every chain of the bench: revolute joints about z) leaves its out-of-plane
  // unknowns (R_z, e1, e2, the joints' z and axis equations) decoupled from the in-plane ones,
  // and all the fill that would couple them is zero: 53-56 % of L + U at 2, 10 and 100 links
  // analysed on the whole pattern (bench/README.md, "Exact zeros of the planar chains"; fewer
  // once the analysis is of the pattern without A's zeros, red_prepare below, which a motion
  // leaving the plane can undo). The zeros are found again at each refactorisation, so a value
  // turning nonzero keeps its entry. FMBD_KLU_DROP0=0 keeps them.
  if (!keep_zeros()) {
    own_drop0(n, F->oLp, F->oLi, F->oLx, 1);
    own_drop0(n, F->oUp, F->oUi, F->oUx, 0);
  }
  F->sLp = F->oLp, F->sLi = F->oLi, F->sLx = F->oLx, F->sUp = F->oUp, F->sUi = F->oUi;
  F->sUx = F->oUx;
  F->own = 1;
}

// A triangle's columns copied from (Xp, Xi, Xx) into (Yp, Yi, Yx) without their exactly zero
// entries, the diagonal kept (first in each column when diag_first, else last): own_drop0 into
// other arrays
static void own_copy0(int64_t n, const SuiteSparse_long *Xp, const SuiteSparse_long *Xi,
                      const double *Xx, SuiteSparse_long *Yp, SuiteSparse_long *Yi, double *Yx,
                      int diag_first) {
  SuiteSparse_long w = 0;
  for (int64_t k = 0; k < n; k++) {
    const SuiteSparse_long p0 = Xp[k], p1 = Xp[k + 1], d = diag_first ? p0 : p1 - 1;
    Yp[k] = w;
    for (SuiteSparse_long p = p0; p < p1; p++) {
      if (Xx[p] == 0 && p != d) continue;
      Yi[w] = Xi[p], Yx[w] = Xx[p], w++;
    }
  }
  Yp[n] = w;
}

// After a full factorisation (KLU's, with its pivoting and row scaling): the pattern of its L
// and U in the order KLU stores them, for own_refactor (F->rf). One diagonal block only, as
// own_extract; the values extracted are not used (they are of the scaled matrix)
static void rf_capture(fmbd_klu *F) {
  F->rf = 0;
  if (!F->num || !F->sym || F->sym->nblocks != 1) return;
  const int64_t n = F->n, lnz = F->num->lnz, unz = F->num->unz;
  if (!F->fX) {
    size_t m1 = (size_t)n + 1;
    F->fLp = fmbd_malloc(sizeof(SuiteSparse_long) * m1);
    F->fUp = fmbd_malloc(sizeof(SuiteSparse_long) * m1);
    F->fPinv = fmbd_malloc(sizeof(SuiteSparse_long) * m1);
    F->fQ = fmbd_malloc(sizeof(SuiteSparse_long) * m1);
    F->fX = fmbd_calloc(m1, sizeof(double));
    if (!F->fLp || !F->fUp || !F->fPinv || !F->fQ || !F->fX) {
      fmbd_free(F->fLp), fmbd_free(F->fUp), fmbd_free(F->fPinv), fmbd_free(F->fQ);
      fmbd_free(F->fX);
      F->fLp = F->fUp = F->fPinv = F->fQ = NULL, F->fX = NULL;
      return;
    }
  }
  if (!own_grow(&F->fLi, &F->fLx, &F->fcap_l, lnz) || !own_grow(&F->fUi, &F->fUx, &F->fcap_u, unz))
    return;
  SuiteSparse_long *P = (SuiteSparse_long *)F->fX;  // n longs fit in n + 1 doubles
  if (!klu_l_extract(F->num, F->sym, F->fLp, F->fLi, F->fLx, F->fUp, F->fUi, F->fUx, NULL, NULL,
                     NULL, P, F->fQ, NULL, NULL, &F->kc)) {
    memset(F->fX, 0, sizeof(double) * (size_t)(n + 1));
    return;
  }
  bool ok = true;
  for (int64_t k = 0; k < n; k++) {
    F->fPinv[P[k]] = k;
    SuiteSparse_long l0 = F->fLp[k], u1 = F->fUp[k + 1];
    if (l0 >= F->fLp[k + 1] || F->fLi[l0] != k || u1 <= F->fUp[k] || F->fUi[u1 - 1] != k)
      ok = false;
  }
  memset(F->fX, 0, sizeof(double) * (size_t)(n + 1));
  F->rf = ok;
}

// The refactorisation of ax (KLU's pattern kAp, kAi) with the pivots of the last full
// factorisation, without row scaling: KLU's refactorisation (klu_refactor.c, its unscaled
// branch: the column scattered, U's column by the updates of the earlier columns of L in the
// order KLU stores them, L's column divided by the pivot) with the same operations in the same
// order, so the same bits, on arrays of our own: no packed storage to walk, and the factor is
// then in the form the own solves read (no klu_l_extract at each refactorisation; bench/README,
// "Fewer Newton iterations with a fresh matrix"). Returns false at a zero or non-finite pivot or
// when min / max |U_kk| <= RCOND_MIN (KLU's cheap rcond, the test of fmbd_klu_factor): the caller
// factorises afresh with pivoting
static bool own_refactor(fmbd_klu *F, const double *ax) {
  const int64_t n = F->n;
  const SuiteSparse_long *Ap = F->kAp, *Ai = F->kAi, *Lp = F->fLp, *Li = F->fLi, *Up = F->fUp,
                         *Ui = F->fUi, *Pinv = F->fPinv, *Q = F->fQ;
  double *Lx = F->fLx, *Ux = F->fUx, *X = F->fX, umin = INFINITY, umax = 0;
  bool ok = true;
  int64_t z = 0;
  for (int64_t k = 0; k < n; k++) {
    const SuiteSparse_long c = Q[k];
    for (SuiteSparse_long p = Ap[c]; p < Ap[c + 1]; p++) X[Pinv[Ai[p]]] = ax[p];
    const SuiteSparse_long u1 = Up[k + 1] - 1;  // U's diagonal last
    for (SuiteSparse_long up = Up[k]; up < u1; up++) {
      const SuiteSparse_long j = Ui[up];
      const double ujk = X[j];
      X[j] = 0;
      Ux[up] = ujk;
      z += ujk == 0;
      for (SuiteSparse_long p = Lp[j] + 1; p < Lp[j + 1]; p++) X[Li[p]] -= Lx[p] * ujk;
    }
    const double ukk = X[k];
    X[k] = 0;
    Ux[u1] = ukk;
    const double a = fabs(ukk);
    if (!(a > 0) || !isfinite(a)) ok = false;  // the rest still computed: X left zero
    if (a < umin) umin = a;
    if (a > umax) umax = a;
    for (SuiteSparse_long p = Lp[k] + 1; p < Lp[k + 1]; p++) {
      const SuiteSparse_long i = Li[p];
      Lx[p] = X[i] / ukk;
      z += Lx[p] == 0;
      X[i] = 0;
    }
  }
  F->fzeros = z;
  F->frcond = ok && umax > 0 ? umin / umax : 0;
  return ok && F->frcond > RCOND_MIN;
}

// the own solves' factor from own_refactor's: its exact zeros dropped as own_extract does
// (into the o arrays) where they are at least 1/8 of the entries (a planar chain's, "Exact zeros
// of the planar chains"), else solved on the f arrays as they are: subtracting the few 0 y_k
// costs less than a copy of the factor at each refactorisation (the pendulum's order-44
// complement: 7 zeros in 493 entries), and gives the same numbers but the sign of a zero
static void own_from_rf(fmbd_klu *F) {
  const int64_t n = F->n;
  F->own = 0;
  if (!own_cols(F)) return;
  const int64_t lnz = F->fLp[n], unz = F->fUp[n];
  for (int64_t k = 0; k < n; k++) {
    F->oP[F->fPinv[k]] = k;
    F->oQ[k] = F->fQ[k];
    F->oUi_d[k] = 1 / F->fUx[F->fUp[k + 1] - 1];
  }
  if (keep_zeros() || 8 * F->fzeros < lnz + unz) {
    F->sLp = F->fLp, F->sLi = F->fLi, F->sLx = F->fLx, F->sUp = F->fUp, F->sUi = F->fUi;
    F->sUx = F->fUx;
  } else {
    if (!own_grow(&F->oLi, &F->oLx, &F->ocap_l, lnz) ||
        !own_grow(&F->oUi, &F->oUx, &F->ocap_u, unz))
      return;
    own_copy0(n, F->fLp, F->fLi, F->fLx, F->oLp, F->oLi, F->oLx, 1);
    own_copy0(n, F->fUp, F->fUi, F->fUx, F->oUp, F->oUi, F->oUx, 0);
    F->sLp = F->oLp, F->sLi = F->oLi, F->sLx = F->oLx, F->sUp = F->oUp, F->sUi = F->oUi;
    F->sUx = F->oUx;
  }
  F->own = 1;
}

// x = Q U^-1 L^-1 P b in place (own_extract)
static void own_solve(fmbd_klu *F, double *b) {
  const int64_t n = F->n;
  double *y = F->oy;
  const SuiteSparse_long *Lp = F->sLp, *Li = F->sLi, *Up = F->sUp, *Ui = F->sUi;
  const double *Lx = F->sLx, *Ux = F->sUx, *Ud = F->oUi_d;
  for (int64_t k = 0; k < n; k++) y[k] = b[F->oP[k]];
  for (int64_t k = 0; k < n; k++) {
    double yk = y[k];
    for (SuiteSparse_long p = Lp[k] + 1; p < Lp[k + 1]; p++) y[Li[p]] -= Lx[p] * yk;
  }
  for (int64_t k = n - 1; k >= 0; k--) {
    double yk = y[k] * Ud[k];
    y[k] = yk;
    for (SuiteSparse_long p = Up[k]; p < Up[k + 1] - 1; p++) y[Ui[p]] -= Ux[p] * yk;
  }
  for (int64_t k = 0; k < n; k++) b[F->oQ[k]] = y[k];
}

// The pattern without its exactly zero entries. The caller's pattern is that of every state; at a
// given one many of its entries may be exactly zero for good: a mechanism moving in a plane (every
// chain of the bench: revolute joints about z) has its out-of-plane unknowns (R_z, e1, e2 and
// the joints' z and axis equations) decoupled from the in-plane ones, the entries coupling them
// exactly zero; with a rigid body's own zeros (the off-diagonal of its m 1 block, ...) two thirds
// of A's entries at 10 and 100 links, and through the fill 53-56 % of L + U's (bench/README.md,
// "Exact zeros of the planar chains"). KLU's analysis and its factorisations then work on the
// entries that are not zero: at the first factorisation the entries of Ax found exactly zero (but
// the diagonal) are dropped, if they are at least RED_MIN of them, and KLU analyses what remains.
// At each later factorisation the dropped entries are checked: one that is no longer zero is taken
// back and the kept pattern analysed again (a motion leaving the plane, or the velocity terms of a
// start from rest); after RED_MAX such analyses the caller's pattern serves for good. The values
// factorised are the caller's, the dropped ones being zero: the same matrix, another ordering.
// FMBD_KLU_DROP0=0: the caller's pattern always
#define RED_MIN 0.1
#define RED_MAX 4

// the kept pattern (rkeep) in rAp, rAi, rmap
static void red_build(fmbd_klu *F) {
  int64_t w = 0;
  F->ndrop = 0;
  for (int64_t c = 0; c < F->n; c++) {
    F->rAp[c] = (SuiteSparse_long)w;
    for (SuiteSparse_long p = F->Ap[c]; p < F->Ap[c + 1]; p++)
      if (F->rkeep[p])
        F->rAi[w] = F->Ai[p], F->rmap[w] = p, w++;
      else
        F->rdrop[F->ndrop++] = p;
  }
  F->rAp[F->n] = (SuiteSparse_long)w;
  F->kAp = F->rAp, F->kAi = F->rAi;
}

// the analysis and factor of another pattern: forgotten
static void red_forget(fmbd_klu *F) {
  if (F->num) klu_l_free_numeric(&F->num, &F->kc);
  if (F->sym) klu_l_free_symbolic(&F->sym, &F->kc);
  F->own = 0, F->rf = 0;
}

// before a KLU factorisation of Ax: the pattern's reduction decided or checked; *kax the
// values KLU is given
static void red_prepare(fmbd_klu *F, const double *Ax, double **kax) {
  *kax = (double *)Ax;
  if (F->red < 0) return;
  const int64_t n = F->n, nnz = F->Ap[n];
  if (F->red == 0) {
    F->red = -1;
    if (keep_zeros()) return;
    int64_t z = 0;
    for (int64_t c = 0; c < n; c++)
      for (SuiteSparse_long p = F->Ap[c]; p < F->Ap[c + 1]; p++) z += Ax[p] == 0 && F->Ai[p] != c;
    if (nnz == 0 || z < RED_MIN * (double)nnz) return;
    F->rAp = fmbd_malloc(sizeof(SuiteSparse_long) * (size_t)(n + 1));
    F->rAi = fmbd_malloc(sizeof(SuiteSparse_long) * (size_t)nnz);
    F->rmap = fmbd_malloc(sizeof(int64_t) * (size_t)nnz);
    F->rAx = fmbd_malloc(sizeof(double) * (size_t)nnz);
    F->rkeep = fmbd_malloc((size_t)nnz);
    F->rdrop = fmbd_malloc(sizeof(int64_t) * (size_t)nnz);
    if (!F->rAp || !F->rAi || !F->rmap || !F->rAx || !F->rkeep || !F->rdrop)
      return;  // freed at destroy
    for (int64_t c = 0; c < n; c++)
      for (SuiteSparse_long p = F->Ap[c]; p < F->Ap[c + 1]; p++)
        F->rkeep[p] = Ax[p] != 0 || F->Ai[p] == c;
    F->red = 1;
    red_build(F);
    red_forget(F);
  } else {
    bool grow = false;  // only the dropped entries read (rdrop)
    for (int64_t e = 0; e < F->ndrop; e++) {
      const int64_t p = F->rdrop[e];
      if (Ax[p] != 0) F->rkeep[p] = 1, grow = true;
    }
    if (grow) {
      red_forget(F);
      if (++F->nred > RED_MAX) {
        F->red = -1, F->kAp = F->Ap, F->kAi = F->Ai;
        return;
      }
      red_build(F);
    }
  }
  const int64_t nk = F->rAp[n];
  for (int64_t k = 0; k < nk; k++) F->rAx[k] = Ax[F->rmap[k]];
  *kax = F->rAx;
}

// FMBD_KLU_OWN_REFACTOR=0: KLU's refactorisation and klu_l_extract (own_refactor's comment)
static bool own_rf_off(void) {
  static int off = -1;
  if (off < 0)
    off = getenv("FMBD_KLU_OWN_REFACTOR") && !strcmp(getenv("FMBD_KLU_OWN_REFACTOR"), "0");
  return off;
}

void fmbd_klu_set_own_refactor(fmbd_klu *F, int on) {
  if (F) F->rf_off = !on;
}

int fmbd_klu_factor(fmbd_klu *F, const double *Ax) {
  double *ax = (double *)Ax;  // KLU's prototypes are not const-qualified; it only reads Ax
  F->singular_col = -1;
  if (F->umf) {
    // a fresh numeric factorisation on the fixed symbolic analysis (UMFPACK has no refactor
    // with the old pivots; its supernodal kernel is BLAS-3 and pivots anew each time)
    umf_free_numeric(F);
    if (F->num) klu_l_free_numeric(&F->num, &F->kc);
    F->own = 0;
    long st = umfpack_dl_numeric(F->Ap, F->Ai, Ax, F->usym, &F->unum, F->uctl, F->uinfo);
    if (st == UMFPACK_OK) {
      double r = F->uinfo[UMFPACK_RCOND];
      F->urcond = r == r ? r : 0;
      return FMBD_OK;
    }
    umf_free_numeric(F);
    FMBD_CHECK(st != UMFPACK_ERROR_out_of_memory, FMBD_ERR_NOMEM, "out of memory in UMFPACK");
    FMBD_CHECK(st == UMFPACK_WARNING_singular_matrix, FMBD_ERR_EXTERNAL,
               "UMFPACK numeric factorisation failed (status %ld)", st);
    // singular (rare): KLU finds the zero pivot's column; should KLU's partial pivoting find a
    // nonsingular factor after all, that factor serves the solves until the next factorisation
    return klu_full(F, ax);
  }
  red_prepare(F, Ax, &ax);
  if (F->num && F->rf && !F->rf_off) {
    if (own_refactor(F, ax)) {
      own_from_rf(F);
      if (F->own) return FMBD_OK;
    }
    klu_l_free_numeric(&F->num, &F->kc);  // a full factorisation below, with pivoting
  }
  if (F->num) {
    // the refactorisation without KLU's row scaling (scale -1: no scale factors, no checks of
    // the fixed pattern). Scaling serves the choice of pivots, which a refactorisation does
    // not make (it keeps those of the last full factorisation, made with KLU's default
    // scaling); elimination in a fixed order is invariant to row scaling but for round-off.
    // Saves the scale pass over A (klu_l_scale, 4 % of the 100-link chain's run) and the
    // scaling in each solve (bench/README.md, "The predictor's order"). The rcond test below
    // then reads the unscaled U. FMBD_KLU_RESCALE=1: KLU's default (rescale at each one)
    static int resc = -1;
    if (resc < 0) resc = getenv("FMBD_KLU_RESCALE") && !strcmp(getenv("FMBD_KLU_RESCALE"), "1");
    int sc = F->kc.scale;
    if (!resc) F->kc.scale = -1;
    int ok = (int)klu_l_refactor(F->kAp, F->kAi, ax, F->sym, F->num, &F->kc);
    F->kc.scale = sc;
    if (ok && F->kc.status == KLU_OK) ok = (int)klu_l_rcond(F->sym, F->num, &F->kc);
    if (!ok || F->kc.status != KLU_OK || !(F->kc.rcond > RCOND_MIN))
      klu_l_free_numeric(&F->num, &F->kc);
    else
      own_extract(F);
  }
  if (!F->num) {
    F->own = 0;
    F->rf = 0;
    FMBD_CALL(klu_full(F, ax));
    rf_capture(F);
  }
  return FMBD_OK;
}

int fmbd_klu_solve(fmbd_klu *F, double *b) {
  if (F->unum) {
    long st = umfpack_dl_wsolve(UMFPACK_A, F->Ap, F->Ai, NULL, F->uX, b, F->unum, F->uctl, F->uinfo,
                                F->uWi, F->uW);
    FMBD_CHECK(st == UMFPACK_OK, FMBD_ERR_EXTERNAL, "UMFPACK solve failed (status %ld)", st);
    memcpy(b, F->uX, sizeof(double) * (size_t)F->n);
    return FMBD_OK;
  }
  FMBD_CHECK(F->num, FMBD_ERR_VALUE, "KLU solve without a factor");
  if (F->own) {
    own_solve(F, b);
    return FMBD_OK;
  }
  int ok = (int)klu_l_solve(F->sym, F->num, (SuiteSparse_long)F->n, 1, b, &F->kc);
  FMBD_CHECK(ok && F->kc.status == KLU_OK, FMBD_ERR_EXTERNAL, "KLU solve failed (status %ld)",
             (long)F->kc.status);
  return FMBD_OK;
}

double fmbd_klu_rcond(fmbd_klu *F) {
  if (F->unum) return F->urcond;
  if (!F->num) return 0;
  if (F->rf && F->own) return F->frcond;  // own_refactor's (KLU's numeric object is older)
  if (!klu_l_rcond(F->sym, F->num, &F->kc)) return 0;
  return F->kc.rcond;
}

int64_t fmbd_klu_singular_col(const fmbd_klu *F) {
  return F->singular_col;
}

int fmbd_klu_own_solves(const fmbd_klu *F) {
  return F && F->own;
}
int64_t fmbd_klu_dropped(const fmbd_klu *F) {
  return F && F->red > 0 ? (int64_t)(F->Ap[F->n] - F->rAp[F->n]) : 0;
}
int fmbd_klu_is_umfpack(const fmbd_klu *F) {
  return F && F->umf;
}

void fmbd_klu_drop_factor(fmbd_klu *F) {
  if (!F) return;
  if (F->num) klu_l_free_numeric(&F->num, &F->kc);
  umf_free_numeric(F);
  F->own = 0, F->rf = 0;
}

void fmbd_klu_destroy(fmbd_klu **Fp) {
  if (!Fp || !*Fp) return;
  fmbd_klu *F = *Fp;
  if (F->num) klu_l_free_numeric(&F->num, &F->kc);
  if (F->sym) klu_l_free_symbolic(&F->sym, &F->kc);
  umf_free_numeric(F);
  if (F->usym) umfpack_dl_free_symbolic(&F->usym);
  fmbd_free(F->Ap), fmbd_free(F->Ai);
  fmbd_free(F->rAp), fmbd_free(F->rAi), fmbd_free(F->rmap), fmbd_free(F->rAx), fmbd_free(F->rkeep);
  fmbd_free(F->rdrop);
  fmbd_free(F->uWi), fmbd_free(F->uW), fmbd_free(F->uX);
  fmbd_free(F->oLp), fmbd_free(F->oLi), fmbd_free(F->oLx), fmbd_free(F->oUp), fmbd_free(F->oUi);
  fmbd_free(F->oUx), fmbd_free(F->oP), fmbd_free(F->oQ), fmbd_free(F->oUi_d), fmbd_free(F->oy);
  fmbd_free(F->fLp), fmbd_free(F->fLi), fmbd_free(F->fLx), fmbd_free(F->fUp), fmbd_free(F->fUi);
  fmbd_free(F->fUx), fmbd_free(F->fPinv), fmbd_free(F->fQ), fmbd_free(F->fX);
  fmbd_free(F);
  *Fp = NULL;
}
