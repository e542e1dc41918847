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

/// @brief Counters of the pool of large blocks (fmbd_alloc_pool), in bytes.
typedef struct {
  int64_t blocks;         ///< large blocks handed out
  size_t reused_bytes;    ///< of their pages, taken from the pool (resident, not faulted again)
  size_t fresh_bytes;     ///< newly mapped (each page faulted on its first touch)
  size_t unmapped_bytes;  ///< given back to the system (beyond the cap, or trimmed)
  size_t kept_bytes;      ///< held by the pool now
  size_t kept_resident_bytes;  ///< of them resident when they came to the pool
} fmbd_alloc_pool_stats;
/// @brief Opt-in pool of large blocks (Linux; a program that wants it switches it on, the
/// default is off): from then on each allocation of at least min_block bytes is its own
/// mapping of whole pages, whose pages are kept when it is freed, at most cap bytes in all,
/// and handed to the next large allocation (the page table entries moved, the pages resident:
/// no page fault, no zeroing by the kernel; calloc clears the reused bytes). min_block 0
/// switches it off and unmaps what it keeps (blocks still allocated are freed as before).
/// Returns 1 where the pool exists, 0 where it does not (then nothing changes).
int fmbd_alloc_pool(size_t min_block, size_t cap);
/// @brief calloc for a block whose caller clears only what it uses: its first *dirty bytes
/// (pages reused from the pool) hold old values, the rest is zero; *dirty is 0 where the pool
/// is off or the block is small (then it is fmbd_calloc). A large block's parts that the caller
/// never touches then stay unresident, where fmbd_calloc would clear (and so keep) them.
void *fmbd_calloc_dirty(size_t count, size_t size, size_t *dirty);
/// @brief Give every page the pool keeps back to the system (it stays on).
void fmbd_alloc_pool_trim(void);
/// @brief The pool's counters since the start of the process.
void fmbd_alloc_pool_get_stats(fmbd_alloc_pool_stats *st);

#endif
