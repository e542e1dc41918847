// fuzz/fuzz.h: what every fuzz target shares (docs/STABILITY.md, "Bad input").
// SPDX-License-Identifier: MIT
//
// A target is one file fuzz/fuzz_KIND.c that defines LLVMFuzzerTestOneInput(data, size): it
// hands the bytes to one reader of the library exactly as a program would, and returns 0
// whatever the reader says (an error is the right answer to bad input; a crash, a leak, a
// sanitizer report or a hang is the defect). Two builds of each target:
//   make fuzz        clang -fsanitize=fuzzer,address,undefined: libFuzzer's own main()
//                    (build-fuzz/fuzz/fuzz-KIND), FUZZ_SECONDS per target
//   make check       gcc, linked with fuzz/replay.c (BUILD/fuzz/replay-KIND): replays the
//                    inputs kept under fuzz/regress/KIND/ (tests/cli/fuzz-regress.sh)
// HDF5 readers take a file name: the bytes are written to a private temporary file first.
#ifndef FMBD_FUZZ_H
#define FMBD_FUZZ_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmbd_err.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

// The temporary file of this process (one per process: libFuzzer runs inputs one at a time).
static inline const char *fuzz_tmp_name(const char *suffix) {
  static char name[256];
  const char *dir = getenv("TMPDIR");
  snprintf(name, sizeof name, "%s/fmbd-fuzz-%ld%s", dir && dir[0] ? dir : "/tmp", (long)getpid(),
           suffix);
  return name;
}

// Write the bytes to the temporary file; 0 on success.
static inline int fuzz_write_tmp(const uint8_t *data, size_t size, const char *name) {
  FILE *fp = fopen(name, "wb");
  if (!fp) return -1;
  size_t w = size ? fwrite(data, 1, size, fp) : 0;
  int rc = fclose(fp);
  return (w == size && rc == 0) ? 0 : -1;
}

// Quiet logging (errors are expected by the thousand) and HDF5's own printing off.
static inline void fuzz_quiet(void) {
  static int done = 0;
  if (done) return;
  done = 1;
  fmbd_log_init("fuzz", FMBD_LOG_ERROR);
  fmbd_h5_debug(false);
}

#endif
