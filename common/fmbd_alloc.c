// common/fmbd_alloc.c: allocation with a failure countdown for tests, and an opt-in pool of
// the large blocks' pages
// SPDX-License-Identifier: MIT
#define _GNU_SOURCE  // mremap, MREMAP_MAYMOVE, MREMAP_FIXED (the pool; Linux)
#include "fmbd_alloc.h"

#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#if defined(__linux__)
#include <fcntl.h>
#include <pthread.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>
#if defined(MREMAP_MAYMOVE) && defined(MREMAP_FIXED)
#define FMBD_POOL 1
#endif
#endif

static int64_t g_countdown = -1;
static int64_t g_count = 0;

static int should_fail(void) {
  g_count++;
  if (g_countdown < 0) return 0;
  if (g_countdown == 0) return 1;
  g_countdown--;
  return 0;
}

void fmbd_alloc_fail_after(int64_t n) {
  g_countdown = n;
}
int64_t fmbd_alloc_count(void) {
  return g_count;
}

// --- the pool (fmbd_alloc_pool) -----------------------------------------------------------------
// A block of at least g_min bytes is a private anonymous mapping of whole pages (page-aligned:
// glibc's pointers never are, its mmapped chunks start 16 bytes into a page, so an unaligned
// pointer is glibc's without a look-up), listed in `g_live` (pointer -> mapped length). Freed,
// its pages are kept (ranges in `g_free`) instead of unmapped, and the next large allocation
// takes them: the smallest range that holds it whole (its first pages; no system call), else a
// fresh mapping into whose first pages the ranges are moved, largest first (mremap moves the
// page table entries: the pages stay resident, nothing is copied or faulted). calloc clears
// only the reused bytes (the fresh ones are the kernel's zero pages). The kept bytes never
// exceed g_cap (beyond it, what does not fit is unmapped, the smallest ranges first) nor the
// peak bound (pool_bound).
#ifdef FMBD_POOL
#define LIVE_SLOTS 4096  // open addressing, a power of two (live large blocks: a few hundred)
#define FREE_MAX 64
static pthread_mutex_t g_mu = PTHREAD_MUTEX_INITIALIZER;
static size_t g_min = 0;  // 0: the pool is off
static size_t g_cap = 0;
static size_t g_page = 4096;
static struct {
  char *p;
  size_t len;
} g_live[LIVE_SLOTS];
static struct {
  char *p;
  size_t len, res;  // bytes, and of them resident (mincore) when they came to the pool
} g_free[FREE_MAX];
static int g_nlive = 0, g_nfree = 0;
static size_t g_free_bytes = 0, g_free_res = 0;
static fmbd_alloc_pool_stats g_st;

static size_t slot_of(const void *p) {
  uintptr_t h = (uintptr_t)p / g_page;
  return (size_t)((h * 0x9E3779B97F4A7C15ull) >> 20) & (LIVE_SLOTS - 1);
}
// the slot holding p; -1 if none
static long live_find(const void *p) {
  size_t i = slot_of(p);
  for (size_t k = 0; k < LIVE_SLOTS && g_live[i].p; k++, i = (i + 1) & (LIVE_SLOTS - 1)) {
    if (g_live[i].p == p) return (long)i;
  }
  return -1;
}
static bool live_add(char *p, size_t len) {
  if (2 * (g_nlive + 1) > LIVE_SLOTS) return false;
  size_t i = slot_of(p);
  while (g_live[i].p) i = (i + 1) & (LIVE_SLOTS - 1);
  g_live[i].p = p;
  g_live[i].len = len;
  g_nlive++;
  return true;
}
static void live_remove(long i) {
  // backward-shift deletion (the probe sequences stay unbroken)
  size_t j = (size_t)i;
  g_live[j].p = NULL;
  g_nlive--;
  for (size_t k = (j + 1) & (LIVE_SLOTS - 1); g_live[k].p; k = (k + 1) & (LIVE_SLOTS - 1)) {
    size_t h = slot_of(g_live[k].p);
    // the entry at k may move to the hole at j if j lies on its probe path (h .. k, cyclic)
    if ((k > j && (h <= j || h > k)) || (k < j && h <= j && h > k)) {
      g_live[j] = g_live[k];
      g_live[k].p = NULL;
      j = k;
    }
  }
}

// /proc/self/statm (resident pages, its second field), open while the pool is on; -1 if not
static int g_statm = -1;
static size_t g_live_peak = 0;  // the largest resident total less the pool's pages seen so far

static size_t resident_bytes(void) {
  char buf[128];
  if (g_statm < 0) return 0;
  ssize_t n = pread(g_statm, buf, sizeof buf - 1, 0);
  if (n <= 0) return 0;
  buf[n] = 0;
  char *e;
  (void)strtoull(buf, &e, 10);
  return (size_t)strtoull(e, NULL, 10) * g_page;
}

// the resident bytes of the pages [p, p + len) (mincore; all of them if it fails): a block's
// pages never touched (the upper triangles of a factor's diagonal blocks, a workspace's unused
// tail) are not memory, and reused they would be faulted as fresh ones
static size_t resident_in(const char *p, size_t len) {
  static unsigned char vec[4096];
  size_t res = 0, npg = len / g_page;
  for (size_t k = 0; k < npg; k += sizeof vec) {
    size_t m = npg - k < sizeof vec ? npg - k : sizeof vec;
    if (mincore((void *)(p + k * g_page), m * g_page, vec) != 0) return len;
    for (size_t i = 0; i < m; i++) res += vec[i] & 1;
  }
  return res * g_page;
}

// range k loses its first (front) or last bytes: cut bytes, of them res resident
static void range_cut(int k, size_t cut, size_t res, bool front) {
  if (res > g_free[k].res) res = g_free[k].res;
  if (front) g_free[k].p += cut;
  g_free[k].len -= cut;
  g_free[k].res -= res;
  g_free_bytes -= cut;
  g_free_res -= res;
  if (g_free[k].len == 0) {
    g_free_res -= g_free[k].res;
    g_free[k] = g_free[--g_nfree];
  }
}
static void range_unmap_tail(int k, size_t cut) {
  char *t = g_free[k].p + (g_free[k].len - cut);
  size_t res = resident_in(t, cut);
  munmap(t, cut);
  g_st.unmapped_bytes += cut;
  range_cut(k, cut, res, false);
}

// pages [p, p + len) into the pool, or back to the system beyond the cap (the smallest ranges
// first); pages never touched are not kept (only a block wholly untouched is seen as such)
static void pool_put(char *p, size_t len) {
  if (len == 0) return;
  size_t res = resident_in(p, len);
  while (g_nfree > 0 && (g_free_bytes + len > g_cap || g_nfree == FREE_MAX)) {
    // make room by unmapping the smallest range, if smaller than this one
    int s = 0;
    for (int k = 1; k < g_nfree; k++)
      if (g_free[k].len < g_free[s].len) s = k;
    if (g_free[s].len >= len) break;
    range_unmap_tail(s, g_free[s].len);
  }
  if (res == 0 || g_free_bytes + len > g_cap || g_nfree == FREE_MAX) {
    // what fits the cap is kept, the rest unmapped
    size_t keep = res && g_nfree < FREE_MAX && g_cap > g_free_bytes ? (g_cap - g_free_bytes) : 0;
    keep -= keep % g_page;
    if (keep > len) keep = len;
    munmap(p + keep, len - keep);
    g_st.unmapped_bytes += len - keep;
    len = keep;
    if (len == 0) return;
    res = resident_in(p, len);
  }
  g_free[g_nfree].p = p;
  g_free[g_nfree].len = len;
  g_free[g_nfree].res = res;
  g_nfree++;
  g_free_bytes += len;
  g_free_res += res;
}

// The pool never holds more than the run's memory has already come down from its peak: with
// `live` the resident total less the pool's resident pages (now), the pool keeps at most the
// largest live seen so far less live, so that resident = live + pool stays at or below that
// earlier peak; what is above goes back to the system (the largest range's tail first).
// Looked at each large allocation, reallocation and free (between two looks, small blocks and
// memory not allocated here can raise live while the pool holds pages: the resident total may
// pass the earlier peak by that growth until the next look).
static size_t live_seen(void) {
  // the pool changes only here and in the calls that follow: empty now, it was empty since the
  // last look, so the process's peak (VmHWM) since then was live memory alone
  struct rusage ru;
  if (g_free_bytes == 0 && getrusage(RUSAGE_SELF, &ru) == 0 &&
      (size_t)ru.ru_maxrss * 1024 > g_live_peak)
    g_live_peak = (size_t)ru.ru_maxrss * 1024;
  size_t rss = resident_bytes();
  size_t live = rss > g_free_res ? rss - g_free_res : 0;
  if (live > g_live_peak) g_live_peak = live;
  return rss ? live : SIZE_MAX;
}
static void pool_bound(void) {
  size_t live = live_seen();
  if (live == SIZE_MAX) return;
  size_t room = g_live_peak - live;
  while (g_free_res > room && g_nfree > 0) {
    int s = 0;
    for (int k = 1; k < g_nfree; k++)
      if (g_free[k].len > g_free[s].len) s = k;
    size_t over = g_free_res - room, cut = g_free[s].len;
    if (cut > over) cut = (over + g_page - 1) / g_page * g_page;
    range_unmap_tail(s, cut);
  }
}

// The pages [src, src + len) moved to dst (inside a mapping of this process): one mremap where
// the range is one mapping; one that earlier moves made of several (each moved piece stays its
// own mapping), which mremap cannot move at once, piece by piece (a failing piece halved). A
// failed MREMAP_FIXED has already unmapped its destination (Linux mremap_to unmaps it before it
// looks at the source), which is mapped again, fresh. Returns the bytes moved from the start;
// SIZE_MAX if a destination could not be mapped again (a hole in dst).
static size_t g_test_piece = 0;  // fmbd_alloc_pool_test_pieces
static size_t move_pages(char *src, size_t len, char *dst) {
  size_t done = 0, piece = len;
  while (done < len) {
    if (piece > len - done) piece = len - done;
    bool fail = g_test_piece && piece > g_test_piece;
    if (fail) munmap(dst + done, piece);  // as a failed MREMAP_FIXED leaves it
    if (!fail &&
        mremap(src + done, piece, piece, MREMAP_MAYMOVE | MREMAP_FIXED, dst + done) != MAP_FAILED) {
      done += piece;
      piece = len - done;
      continue;
    }
    if (mmap(dst + done, piece, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_FIXED, -1,
             0) == MAP_FAILED)
      return SIZE_MAX;
    if (piece <= g_page) break;  // a page that does not move: the rest stays fresh
    piece = (piece / 2 + g_page - 1) / g_page * g_page;
  }
  return done;
}

// a block of len bytes (whole pages); *reused: how many of its first bytes are pool pages
static char *pool_take(size_t len, size_t *reused) {
  *reused = 0;
  int best = -1;
  for (int k = 0; k < g_nfree; k++)
    if (g_free[k].len >= len && (best < 0 || g_free[k].len < g_free[best].len)) best = k;
  if (best >= 0) {
    char *p = g_free[best].p;
    range_cut(best, len, resident_in(p, len), true);
    *reused = len;
    return p;
  }
  char *p = mmap(NULL, len, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) return NULL;
  while (g_nfree > 0 && *reused < len) {
    int big = 0;
    for (int k = 1; k < g_nfree; k++)
      if (g_free[k].len > g_free[big].len) big = k;
    size_t take = g_free[big].len < len - *reused ? g_free[big].len : len - *reused;
    char *src = g_free[big].p;
    size_t res = resident_in(src, take), moved = move_pages(src, take, p + *reused);
    if (moved == SIZE_MAX) {
      // no memory to map the hole again: the block given up (the moved pages with it)
      munmap(p, len);
      range_unmap_tail(big, g_free[big].len);
      *reused = 0;
      return NULL;
    }
    if (moved < take) {
      size_t left = resident_in(src + moved, take - moved);  // not moved: still in the range
      res = res > left ? res - left : 0;
    }
    range_cut(big, moved, res, true);
    *reused += moved;
    if (moved < take) break;  // the rest of the block is fresh
  }
  return p;
}

static size_t round_pages(size_t n) {
  return (n + g_page - 1) / g_page * g_page;
}

// a pool block of n >= g_min bytes (zero: cleared; else its first *dirty bytes are reused
// pages, if dirty), NULL if none could be made or listed
static void *pool_alloc(size_t n, bool zero, size_t *dirty) {
  size_t len = round_pages(n), reused = 0;
  pthread_mutex_lock(&g_mu);
  (void)live_seen();  // the peak of the live memory, before it changes
  char *p = pool_take(len, &reused);
  if (p && !live_add(p, len)) {
    pool_put(p, len);
    p = NULL;
  }
  if (p) {
    g_st.blocks++;
    g_st.reused_bytes += reused;
    g_st.fresh_bytes += len - reused;
  }
  pthread_mutex_unlock(&g_mu);
  if (p && zero && reused) memset(p, 0, reused < n ? reused : n);
  if (dirty) *dirty = p ? (reused < n ? reused : n) : 0;
  return p;
}

// the pool's block p (page-aligned), its length in *len; false if p is not one
static bool pool_owned(const void *p, long *slot, size_t *len) {
  if (!p || ((uintptr_t)p & (g_page - 1)) || g_nlive == 0) return false;
  *slot = live_find(p);
  if (*slot < 0) return false;
  *len = g_live[*slot].len;
  return true;
}
#endif

int fmbd_alloc_pool(size_t min_block, size_t cap) {
#ifdef FMBD_POOL
  long pg = sysconf(_SC_PAGESIZE);
  pthread_mutex_lock(&g_mu);
  if (pg > 0) g_page = (size_t)pg;
  g_min = min_block ? (min_block < g_page ? g_page : min_block) : 0;
  g_cap = g_min ? cap : 0;
  if (g_min && g_statm < 0) g_statm = open("/proc/self/statm", O_RDONLY | O_CLOEXEC);
  if (!g_min && g_statm >= 0) {
    close(g_statm);
    g_statm = -1;
  }
  while (g_nfree > 0 && g_free_bytes > g_cap)
    range_unmap_tail(g_nfree - 1, g_free[g_nfree - 1].len);
  pthread_mutex_unlock(&g_mu);
  return 1;
#else
  (void)min_block;
  (void)cap;
  return 0;
#endif
}

void fmbd_alloc_pool_test_pieces(size_t bytes) {
#ifdef FMBD_POOL
  g_test_piece = bytes;
#else
  (void)bytes;
#endif
}

void fmbd_alloc_pool_trim(void) {
#ifdef FMBD_POOL
  pthread_mutex_lock(&g_mu);
  while (g_nfree > 0) range_unmap_tail(g_nfree - 1, g_free[g_nfree - 1].len);
  pthread_mutex_unlock(&g_mu);
#endif
}

void fmbd_alloc_pool_get_stats(fmbd_alloc_pool_stats *st) {
#ifdef FMBD_POOL
  pthread_mutex_lock(&g_mu);
  *st = g_st;
  st->kept_bytes = g_free_bytes;
  st->kept_resident_bytes = g_free_res;
  pthread_mutex_unlock(&g_mu);
#else
  memset(st, 0, sizeof *st);
#endif
}

void *fmbd_malloc(size_t n) {
  if (should_fail()) return NULL;
#ifdef FMBD_POOL
  if (g_min && n >= g_min) {
    void *p = pool_alloc(n, false, NULL);
    if (p) return p;
  }
#endif
  return malloc(n ? n : 1);
}

// calloc, or (dirty not NULL) a block whose first *dirty bytes are reused pool pages left as
// they were
static void *calloc_impl(size_t count, size_t size, size_t *dirty) {
  if (dirty) *dirty = 0;
  if (size && count > SIZE_MAX / size) return NULL;
  if (should_fail()) return NULL;
#ifdef FMBD_POOL
  if (g_min && count * size >= g_min) {
    void *p = pool_alloc(count * size, !dirty, dirty);
    if (p) return p;
  }
#endif
  return calloc(count ? count : 1, size ? size : 1);
}

void *fmbd_calloc(size_t count, size_t size) {
  return calloc_impl(count, size, NULL);
}

void *fmbd_calloc_dirty(size_t count, size_t size, size_t *dirty) {
  return calloc_impl(count, size, dirty);
}

void *fmbd_realloc(void *p, size_t n) {
  if (should_fail()) return NULL;
#ifdef FMBD_POOL
  long slot;
  size_t len;
  if (g_nlive) {
    pthread_mutex_lock(&g_mu);
    if (pool_owned(p, &slot, &len)) {
      (void)live_seen();  // the peak since the last look, before the pool changes
      size_t nl = round_pages(n ? n : 1);
      char *q = p;
      if (nl < len) {
        // shrunk in place: the tail's pages into the pool
        pool_put(q + nl, len - nl);
        pool_bound();
      } else if (nl > len) {
        // grown by the kernel (pages moved, not copied; the new pages fresh) where the block
        // is one mapping; one made of moved ranges is several: copied into a new block then
        q = mremap(p, len, nl, MREMAP_MAYMOVE);
        if (q == MAP_FAILED) {
          size_t reused;
          q = pool_take(nl, &reused);
          if (!q) {
            pthread_mutex_unlock(&g_mu);
            return NULL;
          }
          g_st.reused_bytes += reused;
          g_st.fresh_bytes += nl - reused;
          memcpy(q, p, len);
          pool_put(p, len);
          pool_bound();
        }
      }
      live_remove(slot);
      (void)live_add(q, nl);  // a slot was just freed
      pthread_mutex_unlock(&g_mu);
      return q;
    }
    pthread_mutex_unlock(&g_mu);
  }
#endif
  return realloc(p, n ? n : 1);
}

void fmbd_free(void *p) {
#ifdef FMBD_POOL
  long slot;
  size_t len;
  if (g_nlive && p && !((uintptr_t)p & (g_page - 1))) {
    pthread_mutex_lock(&g_mu);
    if (pool_owned(p, &slot, &len)) {
      live_remove(slot);
      if (g_min) {
        (void)live_seen();  // the peak since the last look, before the pool changes
        pool_put(p, len);
        pool_bound();
      } else {
        munmap(p, len);
      }
      pthread_mutex_unlock(&g_mu);
      return;
    }
    pthread_mutex_unlock(&g_mu);
  }
#endif
  free(p);
}

char *fmbd_strdup(const char *s) {
  size_t n = strlen(s) + 1;
  char *d = fmbd_malloc(n);
  if (d) memcpy(d, s, n);
  return d;
}
