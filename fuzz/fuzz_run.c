// fuzz/fuzz_run.c: a .run.h5 file as `fmbd-run --reference` reads it: the format check, /stats
// complete, /time (finite, strictly increasing, two instants at least), then every point
// output's series under /outputs/NAME/{position,velocity,acceleration} with the (instants, 3)
// shape the comparison requires. The checks are those of fmbd-run/main.c check_reference and
// compare_reference (static there), made with the same library calls.
// SPDX-License-Identifier: MIT
#include <math.h>

#include "fmbd_alloc.h"
#include "fuzz.h"

static void read_run(fmbd_h5 *g) {
  int64_t complete = 0, dt[1] = {-1};
  double *t = NULL;
  int n = 0;
  char **names = NULL;
  if (fmbd_h5_check_format(g, FMBD_RUN_FORMAT, FMBD_RUN_FORMAT_MAJOR)) return;
  if (fmbd_h5_read_attr_i64(g, "/stats", "complete", 1, &complete) || complete != 1) return;
  if (fmbd_h5_read_f64(g, "/time", 1, dt, &t) || dt[0] < 2) goto done;
  for (int64_t i = 0; i < dt[0]; i++)
    if (!isfinite(t[i]) || (i > 0 && !(t[i] > t[i - 1]))) goto done;
  if (fmbd_h5_list(g, "/outputs", &n, &names)) goto done;
  static const char *const q[3] = {"position", "velocity", "acceleration"};
  for (int o = 0; o < n; o++) {
    for (int k = 0; k < 3; k++) {
      char path[512];
      snprintf(path, sizeof path, "/outputs/%s/%s", names[o], q[k]);
      if (!fmbd_h5_exists(g, path)) continue;
      int64_t dv[2] = {dt[0], 3};
      double *v = NULL;
      (void)fmbd_h5_read_f64(g, path, 2, dv, &v);
      fmbd_free(v);
      fmbd_err_clear();
    }
  }
done:
  for (int o = 0; o < n; o++) fmbd_free(names[o]);
  fmbd_free(names);
  fmbd_free(t);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fuzz_quiet();
  const char *name = fuzz_tmp_name(".run.h5");
  if (fuzz_write_tmp(data, size, name)) return 0;
  fmbd_h5 *g = NULL;
  if (fmbd_h5_open(name, &g) == FMBD_OK) read_run(g);
  fmbd_h5_close(&g);
  unlink(name);
  fmbd_err_clear();
  return 0;
}
