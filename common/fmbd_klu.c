// common/fmbd_klu.c: sparse LU through KLU (fmbd_klu.h)
// SPDX-License-Identifier: MIT
#include "fmbd_klu.h"

#include <klu.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"

// refactor with the old pivoting while KLU's rcond estimate stays above this; below it the
// pivot order no longer suits the values and a full factorisation pivots afresh
#define RCOND_MIN 1e-13

struct fmbd_klu {
  int64_t n;
  SuiteSparse_long *Ap, *Ai;
  klu_l_common kc;
  klu_l_symbolic *sym;
  klu_l_numeric *num;
  int64_t singular_col;
};

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
  klu_l_defaults(&F->kc);
  F->kc.halt_if_singular = 1;
  F->sym = klu_l_analyze((SuiteSparse_long)n, F->Ap, F->Ai, &F->kc);
  FMBD_GCHECK(F->sym, FMBD_ERR_EXTERNAL, "KLU symbolic analysis failed (status %ld)",
              (long)F->kc.status);
  *out = F;
  F = NULL;
done:
  fmbd_klu_destroy(&F);
  return rc;
}

int fmbd_klu_factor(fmbd_klu *F, const double *Ax) {
  double *ax = (double *)Ax;  // KLU's prototypes are not const-qualified; it only reads Ax
  F->singular_col = -1;
  if (F->num) {
    int ok = (int)klu_l_refactor(F->Ap, F->Ai, ax, F->sym, F->num, &F->kc);
    if (ok && F->kc.status == KLU_OK) ok = (int)klu_l_rcond(F->sym, F->num, &F->kc);
    if (!ok || F->kc.status != KLU_OK || !(F->kc.rcond > RCOND_MIN))
      klu_l_free_numeric(&F->num, &F->kc);
  }
  if (!F->num) {
    F->num = klu_l_factor(F->Ap, F->Ai, ax, F->sym, &F->kc);
    if (!F->num || F->kc.status != KLU_OK) {
      int64_t col = (int64_t)F->kc.singular_col;
      F->singular_col = col >= 0 && col < F->n ? col : -1;
      if (F->num) klu_l_free_numeric(&F->num, &F->kc);
      FMBD_CHECK(F->kc.status != KLU_OUT_OF_MEMORY, FMBD_ERR_NOMEM, "out of memory in KLU");
      FMBD_FAIL(FMBD_ERR_SINGULAR, "KLU: singular matrix (status %ld, column %lld)",
                (long)F->kc.status, (long long)F->singular_col);
    }
  }
  return FMBD_OK;
}

int fmbd_klu_solve(fmbd_klu *F, double *b) {
  FMBD_CHECK(F->num, FMBD_ERR_VALUE, "KLU solve without a factor");
  int ok = (int)klu_l_solve(F->sym, F->num, (SuiteSparse_long)F->n, 1, b, &F->kc);
  FMBD_CHECK(ok && F->kc.status == KLU_OK, FMBD_ERR_EXTERNAL, "KLU solve failed (status %ld)",
             (long)F->kc.status);
  return FMBD_OK;
}

double fmbd_klu_rcond(fmbd_klu *F) {
  if (!F->num) return 0;
  if (!klu_l_rcond(F->sym, F->num, &F->kc)) return 0;
  return F->kc.rcond;
}

int64_t fmbd_klu_singular_col(const fmbd_klu *F) {
  return F->singular_col;
}

void fmbd_klu_drop_factor(fmbd_klu *F) {
  if (F && F->num) klu_l_free_numeric(&F->num, &F->kc);
}

void fmbd_klu_destroy(fmbd_klu **Fp) {
  if (!Fp || !*Fp) return;
  fmbd_klu *F = *Fp;
  if (F->num) klu_l_free_numeric(&F->num, &F->kc);
  if (F->sym) klu_l_free_symbolic(&F->sym, &F->kc);
  fmbd_free(F->Ap), fmbd_free(F->Ai);
  fmbd_free(F);
  *Fp = NULL;
}
