// fuzz/fuzz_cb.c: a .cb.h5 file read both ways it is read: by cbcheck (fmbd_check_open with the
// cb file alone: /cb, /reduced, the body description, the estimators built from them) and by
// fmbd-run (a cb body: fmbd_scene_rflex_from_cb with modal stress, which reads /mesh).
// SPDX-License-Identifier: MIT
#include "fmbd_check.h"
#include "fmbd_scene_build.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fuzz_quiet();
  const char *name = fuzz_tmp_name(".cb.h5");
  if (fuzz_write_tmp(data, size, name)) return 0;
  fmbd_check_opts o;
  fmbd_check_opts_defaults(&o);
  o.plain = true;  // never look for the fe file: only these bytes are read
  fmbd_check *c = NULL;
  (void)fmbd_check_open(name, &o, &c);
  fmbd_check_close(&c);
  fmbd_err_clear();
  fmbd_h5 *f = NULL;
  fmbd_rflex *r = NULL;
  if (fmbd_h5_open(name, &f) == FMBD_OK &&
      fmbd_h5_check_format(f, FMBD_CB_FORMAT, FMBD_CB_FORMAT_MAJOR) == FMBD_OK)
    (void)fmbd_scene_rflex_from_cb(f, true, &r);
  fmbd_rflex_destroy(&r);
  fmbd_h5_close(&f);
  unlink(name);
  fmbd_err_clear();
  return 0;
}
