// common/fmbd_csr.h: compressed sparse row matrices (0-based, int64 indices)
// SPDX-License-Identifier: MIT
//
// The storage of docs/DESIGN.md: symmetric matrices are stored in full (both triangles), rows
// sorted by column. The struct is public: its arrays are owned by the matrix and released
// by fmbd_csr_destroy. One exception, for memory (fe2cb's interior Ks and Ms): a symmetric
// matrix may keep only its lower triangle (lower = true, fmbd_csr_keep_lower); fmbd_csr_matvec,
// fmbd_csr_matmat, fmbd_csr_get and fmbd_chol read it as the full matrix, nothing else
// accepts it.
#ifndef FMBD_CSR_H
#define FMBD_CSR_H

#include <stdbool.h>
#include <stdint.h>

typedef struct fmbd_csr {
  int64_t nrows, ncols;
  int64_t *indptr;   ///< nrows+1 row starts into indices/data
  int64_t *indices;  ///< column of each stored entry, increasing within a row
  double *data;      ///< value of each stored entry
  bool lower;        ///< symmetric, only columns <= row stored (fmbd_csr_keep_lower)
} fmbd_csr;

/// @brief Number of stored entries.
static inline int64_t fmbd_csr_nnz(const fmbd_csr *A) {
  return A->indptr[A->nrows];
}

/// @brief Keep only the lower triangle (columns <= row) of the symmetric square matrix A, in
/// place (the arrays shrink: about half the memory), and mark it lower. B (may be NULL): a
/// matrix sharing A's indptr and indices arrays (the same pointers), compacted with them.
int fmbd_csr_keep_lower(fmbd_csr *A, fmbd_csr *B);

/// @brief Allocate an nrows x ncols matrix with room for nnz entries; indptr zeroed.
/// @param[out] out caller destroys with fmbd_csr_destroy
int fmbd_csr_create(int64_t nrows, int64_t ncols, int64_t nnz, fmbd_csr **out);
/// @brief Release A and set *A = NULL. NULL and *A == NULL are fine.
void fmbd_csr_destroy(fmbd_csr **A);
/// @brief Deep copy.
int fmbd_csr_duplicate(const fmbd_csr *A, fmbd_csr **out);

/// @brief Build the square n x n pattern (values zero) of an assembly of `nelem` elements
/// with `k` dofs each: edofs[e*k + a] is the global dof of local dof a of element e, or a
/// negative number to skip it. Every pair of dofs of one element is a stored entry. Works
/// row by row through a dof->element incidence, never a coordinate list of all pairs.
/// @param[out] out caller destroys
int fmbd_csr_pattern_from_elements(int64_t n, int64_t nelem, int k, const int64_t *edofs,
                                   fmbd_csr **out);
/// @brief A(dofs[a], dofs[b]) += Ke[a*k + b] (Ke row-major k x k); negative dofs skipped.
/// @return FMBD_ERR_INTERNAL if an entry is not in the pattern.
int fmbd_csr_add_block(fmbd_csr *A, int k, const int64_t *dofs, const double *Ke);
/// @brief Position of entry (i, j) in indices/data, or -1 (binary search).
int64_t fmbd_csr_find(const fmbd_csr *A, int64_t i, int64_t j);
/// @brief Value of entry (i, j) (0 if not stored).
double fmbd_csr_get(const fmbd_csr *A, int64_t i, int64_t j);

/// @brief y = A x.
void fmbd_csr_matvec(const fmbd_csr *A, const double *x, double *y);
/// @brief Y = A X for a column-major block X (ncols x nrhs, leading dim ldx) into Y (nrows
/// x nrhs, leading dim ldy).
void fmbd_csr_matmat(const fmbd_csr *A, int64_t nrhs, const double *X, int64_t ldx, double *Y,
                     int64_t ldy);
/// @brief yt = A xt for 4 columns held row-major (row i at xt + 4 i; nrows x 4 into ncols x 4
/// of the caller's memory, no allocation): the same bits as fmbd_csr_matmat / fmbd_csr_matvec
/// column by column (fmbd_chol_apply_op's M product on its own workspace).
void fmbd_csr_matmat_rows4(const fmbd_csr *A, const double *xt, double *yt);
/// @brief Y = A X and Z = B X, the same bits as two fmbd_csr_matmat calls. When A and B are
/// stored in full on one pattern in memory (the same indptr and indices arrays: an fe body's K
/// and M), one pass over the pattern serves both; otherwise two passes.
void fmbd_csr_matmat_pair(const fmbd_csr *A, const fmbd_csr *B, int64_t nrhs, const double *X,
                          int64_t ldx, double *Y, double *Z, int64_t ldy);
/// @brief A(rows, cols) as a new matrix. rows/cols are increasing-free index lists.
int fmbd_csr_submatrix(const fmbd_csr *A, int64_t nr, const int64_t *rows, int64_t nc,
                       const int64_t *cols, fmbd_csr **out);
/// @brief Transpose.
int fmbd_csr_transpose(const fmbd_csr *A, fmbd_csr **out);
/// @brief C = A B (sparse times sparse), sorted rows, explicit zeros dropped only if exact.
int fmbd_csr_matmul(const fmbd_csr *A, const fmbd_csr *B, fmbd_csr **out);
/// @brief C = P' A P.
int fmbd_csr_ptap(const fmbd_csr *A, const fmbd_csr *P, fmbd_csr **out);

/// @brief Validate structure: indptr starts at 0 and never decreases, indices in range and
/// strictly increasing within each row, all values finite. On failure the error's `where`
/// names the array and row (e.g. "indptr: not increasing at row 12"); the caller adds the
/// file and group via fmbd_err_context before.
int fmbd_csr_check(const fmbd_csr *A);
/// @brief fmbd_csr_check's test of the values alone (all finite), for a matrix whose pattern
/// arrays are those of one already checked (fmbd_h5_read_csr_like's shared read).
int fmbd_csr_check_values(const fmbd_csr *A);
/// @brief Whether |A(i,j) - A(j,i)| <= rtol * max|A| for all entries (pattern symmetric
/// too). *bad_row gets the first offending row, or -1.
bool fmbd_csr_is_symmetric(const fmbd_csr *A, double rtol, int64_t *bad_row);
/// @brief fmbd_csr_is_symmetric of A and of B (bad[0], bad[1]: each one's first offending row,
/// or -1), in one walk where B holds A's indptr and indices arrays (fmbd_fe_body's M).
bool fmbd_csr_is_symmetric_pair(const fmbd_csr *A, const fmbd_csr *B, double rtol, int64_t bad[2]);
/// @brief max |A(i,j)|.
double fmbd_csr_max_abs(const fmbd_csr *A);
/// @brief Diagonal into d (length min(nrows, ncols)).
void fmbd_csr_diagonal(const fmbd_csr *A, double *d);

#endif
