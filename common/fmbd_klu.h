// common/fmbd_klu.h: sparse LU of a square unsymmetric matrix through KLU (SuiteSparse klu_l_*)
// or UMFPACK (umfpack_dl_*)
// SPDX-License-Identifier: MIT
//
// The matrix is given in compressed columns (Ap[n + 1], Ai[nnz] with sorted row indices in each
// column, values Ax[nnz]). An fmbd_klu object holds a copy of the pattern and KLU's symbolic
// analysis of it (done once by fmbd_klu_analyze: AMD ordering, with or without KLU's block
// triangular form, whichever predicts the smaller factor; the environment variable
// FMBD_KLU_BTF = 0 or 1 forces one), and the numeric factor
// of the values given to the last fmbd_klu_factor. That factor is reused across calls where
// possible: fmbd_klu_factor refactors with the previous pivot order (klu_l_refactor) and
// falls back to a full factorisation with fresh partial pivoting (klu_l_factor) when the
// refactor fails or KLU's reciprocal condition estimate drops below rcond_min (default 1e-13).
// Entries of the pattern that the first factorisation's values hold exactly zero (a mechanism
// moving in a plane: the coupling of its in-plane and out-of-plane unknowns) are left out of
// KLU's analysis while they stay zero, and taken back when they do not (fmbd_klu_dropped);
// FMBD_KLU_DROP0=0 keeps the whole pattern.
//
// Two engines behind this interface. KLU (left-looking, no supernodes) suits the small,
// circuit-like multibody matrices; for large systems (a full FE body's [M Cq'; Cq 0], order
// n >= 5000 with at least 30 entries a column, as a solid mesh has) UMFPACK takes over: symbolic
// analysis once per pattern (AMD/COLAMD), a fresh numeric factorisation at every fmbd_klu_factor
// (multifrontal, BLAS-3 supernodes), its rcond estimate Info[UMFPACK_RCOND] (min/max |diag U|,
// cruder than KLU's). On a singular UMFPACK factor KLU's factorisation is run to find the zero
// pivot's column. The environment variable FMBD_SPARSE_LU forces the engine: "klu" or "umfpack"
// (unset, empty or anything else: the automatic choice by n and nnz), read at fmbd_klu_analyze. KLU
// and UMFPACK allocate with malloc, outside fmbd_malloc (the allocation countdown of the tests does
// not reach it); it never prints.
#ifndef FMBD_KLU_H
#define FMBD_KLU_H

#include <stdint.h>

typedef struct fmbd_klu fmbd_klu;

/// @brief Copy the pattern and run KLU's symbolic analysis.
/// @param[in] n order; Ap (n + 1) column pointers; Ai (Ap[n]) row indices; borrowed
/// @param[out] out caller destroys with fmbd_klu_destroy
/// @return FMBD_OK, FMBD_ERR_NOMEM, FMBD_ERR_EXTERNAL (the analysis failed)
int fmbd_klu_analyze(int64_t n, const int64_t *Ap, const int64_t *Ai, fmbd_klu **out);

/// @brief Numeric factorisation of the values Ax (Ap[n] entries in the analysed pattern):
/// a refactor with the old pivoting when a factor exists and stays well conditioned, else a
/// full factorisation. Ax is read only during the call.
/// @return FMBD_OK; FMBD_ERR_SINGULAR (a structurally or numerically zero pivot: the column
/// is fmbd_klu_singular_col; the message is KLU's, a caller names the unknown); NOMEM
int fmbd_klu_factor(fmbd_klu *F, const double *Ax);

/// @brief Solve A x = b in place (b: n values) with the current factor.
/// @return FMBD_OK, FMBD_ERR_VALUE (no factor), FMBD_ERR_EXTERNAL
int fmbd_klu_solve(fmbd_klu *F, double *b);

/// @brief KLU's reciprocal condition estimate of the current factor (klu_l_rcond; 0 before a
/// factorisation).
double fmbd_klu_rcond(fmbd_klu *F);

/// @brief The column at which the last failed factorisation met a zero pivot (0-based, in the
/// caller's numbering), or -1.
int64_t fmbd_klu_singular_col(const fmbd_klu *F);

/// @brief 1 when the engine is UMFPACK, 0 for KLU.
int fmbd_klu_is_umfpack(const fmbd_klu *F);

/// @brief 1 when the current factor is solved by fmbd_klu's own triangular solves (a KLU
/// refactorisation of one diagonal block, unscaled), 0 when by KLU's or UMFPACK's.
int fmbd_klu_own_solves(const fmbd_klu *F);

/// @brief Refactorisations by fmbd_klu's own code (on: the default, unless FMBD_KLU_OWN_REFACTOR=0)
/// or by KLU's klu_l_refactor (off): the same factor bit for bit (tests/unit/t131).
void fmbd_klu_set_own_refactor(fmbd_klu *F, int on);

/// @brief The entries of the analysed pattern that KLU does not see: those found exactly zero at
/// the first factorisation and zero since (0: the whole pattern; fmbd_klu.c, red_prepare).
int64_t fmbd_klu_dropped(const fmbd_klu *F);

/// @brief Forget the numeric factor (the next fmbd_klu_factor factors afresh).
void fmbd_klu_drop_factor(fmbd_klu *F);

/// @brief Release everything; *F = NULL. NULL and *F == NULL are fine.
void fmbd_klu_destroy(fmbd_klu **F);

#endif
