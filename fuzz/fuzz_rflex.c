// fuzz/fuzz_rflex.c: a .rflex.h5 file as fmbd-run reads a flexible body (fmbd_rflex_read: modes,
// interfaces, the invariants of /ffrf, optional modal stress), then a node's modal motion and
// stress at the first and the last node, as outputs ask.
// SPDX-License-Identifier: MIT
#include "fmbd_rflex.h"
#include "fuzz.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fuzz_quiet();
  const char *name = fuzz_tmp_name(".rflex.h5");
  if (fuzz_write_tmp(data, size, name)) return 0;
  fmbd_h5 *f = NULL;
  fmbd_rflex *r = NULL;
  if (fmbd_h5_open(name, &f) == FMBD_OK && fmbd_rflex_read(f, &r) == FMBD_OK) {
    int64_t nodes[2] = {0, r->nnodes - 1};
    double *T = malloc(sizeof(double) * (size_t)(3 * (r->nm > 0 ? r->nm : 1)));
    double *R = malloc(sizeof(double) * (size_t)(3 * (r->nm > 0 ? r->nm : 1)));
    double *S = malloc(sizeof(double) * (size_t)(6 * (r->nm > 0 ? r->nm : 1)));
    for (int k = 0; k < 2 && T && R && S; k++) {
      if (nodes[k] < 0) continue;
      double x0[3];
      (void)fmbd_rflex_node_modes(r, nodes[k], x0, T, R);
      if (r->stress) (void)fmbd_rflex_node_stress(r, nodes[k], S);
    }
    free(T);
    free(R);
    free(S);
  }
  fmbd_rflex_destroy(&r);
  fmbd_h5_close(&f);
  unlink(name);
  fmbd_err_clear();
  return 0;
}
