// tests/unit/check.h: the one assertion macro of the unit tests (silent when right)
// SPDX-License-Identifier: MIT
#ifndef FMBD_TEST_CHECK_H
#define FMBD_TEST_CHECK_H
#include <stdio.h>
static int test_failures = 0;
/// EXPECT(cond, printf-args): one line per failure, the test exits nonzero at the end.
#define EXPECT(cond, ...)                                               \
  do {                                                                  \
    if (!(cond)) {                                                      \
      fprintf(stderr, "%s:%d: FAILED %s: ", __FILE__, __LINE__, #cond); \
      fprintf(stderr, __VA_ARGS__);                                     \
      fputc('\n', stderr);                                              \
      test_failures++;                                                  \
    }                                                                   \
  } while (0)
#define TEST_EXIT() return test_failures ? 1 : 0
#endif
