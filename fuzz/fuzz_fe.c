// fuzz/fuzz_fe.c: an .fe.h5 file as fe2cb reads it: the format check, then fmbd_fe_read (mesh,
// material, dofs, K and M as CSR, expansion, interfaces, clamped dofs, body data).
// SPDX-License-Identifier: MIT
#include "fmbd_fe.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fuzz_quiet();
  const char *name = fuzz_tmp_name(".fe.h5");
  if (fuzz_write_tmp(data, size, name)) return 0;
  fmbd_h5 *f = NULL;
  fmbd_fe_body *b = NULL;
  if (fmbd_h5_open(name, &f) == FMBD_OK &&
      fmbd_h5_check_format(f, FMBD_FE_FORMAT, FMBD_FE_FORMAT_MAJOR) == FMBD_OK)
    (void)fmbd_fe_read(f, &b);
  fmbd_fe_body_destroy(&b);
  fmbd_h5_close(&f);
  unlink(name);
  fmbd_err_clear();
  return 0;
}
