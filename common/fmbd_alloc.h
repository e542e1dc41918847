// common/fmbd_alloc.h: the one allocator of the project
// SPDX-License-Identifier: MIT
//
// All allocation goes through these, so that tests can make the Nth call fail
// (fmbd_alloc_fail_after) and check that every error path cleans up (CHOLMOD's my_tries).
// Memory from fmbd_malloc/calloc/realloc is released with fmbd_free (free() compatible).
#ifndef FMBD_ALLOC_H
#define FMBD_ALLOC_H

#include <stddef.h>
#include <stdint.h>

/// @brief malloc; returns NULL on failure or when the countdown hits zero. n == 0 gives a
/// valid unique pointer.
void *fmbd_malloc(size_t n);
/// @brief calloc with overflow check of count*size.
void *fmbd_calloc(size_t count, size_t size);
/// @brief realloc; on failure the old block stays valid.
void *fmbd_realloc(void *p, size_t n);
/// @brief free; NULL is fine.
void fmbd_free(void *p);
/// @brief Duplicate a string (caller frees with fmbd_free).
char *fmbd_strdup(const char *s);
/// @brief Make the allocation after n more succeed fail (n < 0: never fail, the default).
void fmbd_alloc_fail_after(int64_t n);
/// @brief Number of allocations made so far (for countdown tests).
int64_t fmbd_alloc_count(void);

#endif
