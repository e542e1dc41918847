// common/fmbd_alloc.c: allocation with a failure countdown for tests
// SPDX-License-Identifier: MIT
#include "fmbd_alloc.h"

#include <stdlib.h>
#include <string.h>

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

void *fmbd_malloc(size_t n) {
  if (should_fail()) return NULL;
  return malloc(n ? n : 1);
}

void *fmbd_calloc(size_t count, size_t size) {
  if (size && count > SIZE_MAX / size) return NULL;
  if (should_fail()) return NULL;
  return calloc(count ? count : 1, size ? size : 1);
}

void *fmbd_realloc(void *p, size_t n) {
  if (should_fail()) return NULL;
  return realloc(p, n ? n : 1);
}

void fmbd_free(void *p) {
  free(p);
}

char *fmbd_strdup(const char *s) {
  size_t n = strlen(s) + 1;
  char *d = fmbd_malloc(n);
  if (d) memcpy(d, s, n);
  return d;
}
