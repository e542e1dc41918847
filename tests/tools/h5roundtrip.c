// tests/tools/h5roundtrip.c: test tool for fmbd_h5 files through pipes (stdin/stdout images)
// SPDX-License-Identifier: MIT
//
//   h5roundtrip --make [N] [-o OUT]       write a fmbd-test 1.0 file: /x (N,) f64 = 0..N-1 (N
//                                         default 20000: chunked), /sub/m (3, 2) col-major
//                                         matrix [[1,2],[3,4],[5,6]], /K a 3x3 CSR matrix
//   h5roundtrip INPUT PATH [-o OUT]       read INPUT ("-" = stdin), copy the dataset PATH as
//                                         f64 to PATH and to /copy (fmbd_h5_copy keeps all of
//                                         /sub and /K), record INPUT in `inputs`
//   --fail                                after creating the output, read a missing dataset
//                                         of the input: exit 1 and no output left
// The output is standard output when -o is absent and standard output is not a terminal.
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd.h"

static int make(int64_t n, const char *out) {
  int rc = FMBD_OK;
  fmbd_h5 *f = NULL;
  double *x = NULL;
  fmbd_csr *K = NULL;
  FMBD_GALLOC(x = fmbd_malloc((size_t)n * sizeof *x));
  for (int64_t i = 0; i < n; i++) x[i] = (double)i;
  FMBD_GCALL(fmbd_h5_create(out, "fmbd-test", "1.0", &f));
  FMBD_GCALL(fmbd_h5_write_f64(f, "/x", 1, &n, x));
  const double m[6] = {1, 3, 5, 2, 4, 6};  // column-major 3 x 2
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/sub/m", 3, 2, m));
  FMBD_GCALL(fmbd_csr_create(3, 3, 5, &K));
  const int64_t ip[4] = {0, 2, 3, 5}, ix[5] = {0, 2, 1, 0, 2};
  const double v[5] = {4, -1, 3, -1, 5};
  memcpy(K->indptr, ip, sizeof ip);
  memcpy(K->indices, ix, sizeof ix);
  memcpy(K->data, v, sizeof v);
  FMBD_GCALL(fmbd_h5_write_csr(f, "/K", K));
  FMBD_GCALL(fmbd_h5_commit(&f, fmbd_cli_wall_s(), fmbd_cli_cpu_s()));
  fmbd_cli_summary("%s: %lld values", strcmp(out, "-") ? out : "<stdout>", (long long)n);
done:
  fmbd_h5_close(&f);
  fmbd_csr_destroy(&K);
  fmbd_free(x);
  return rc;
}

static int roundtrip(const char *in, const char *path, const char *out, int fail) {
  int rc = FMBD_OK;
  fmbd_h5 *r = NULL, *w = NULL;
  char *format = NULL, *version = NULL;
  double *x = NULL, *y = NULL;
  int64_t dims[4] = {-1, -1, -1, -1};
  FMBD_GCALL(fmbd_h5_open(in, &r));
  FMBD_GCALL(fmbd_h5_check_format(r, "fmbd-test", 1));
  FMBD_GCALL(fmbd_h5_read_attr_str(r, "/", "format", &format));
  FMBD_GCALL(fmbd_h5_read_attr_str(r, "/", "format_version", &version));
  FMBD_GCALL(fmbd_h5_read_f64(r, path, 1, dims, &x));
  FMBD_GCALL(fmbd_h5_create(out, format, version, &w));
  if (fail) FMBD_GCALL(fmbd_h5_read_f64(r, "/no/such/dataset", 1, dims, &y));
  FMBD_GCALL(fmbd_h5_write_f64(w, path, 1, dims, x));
  FMBD_GCALL(fmbd_h5_write_f64(w, "/copy", 1, dims, x));
  FMBD_GCALL(fmbd_h5_copy(r, "/sub", w));
  FMBD_GCALL(fmbd_h5_copy(r, "/K", w));
  FMBD_GCALL(fmbd_h5_add_input(w, in, fmbd_h5_sha256(r)));
  FMBD_GCALL(fmbd_h5_commit(&w, fmbd_cli_wall_s(), fmbd_cli_cpu_s()));
  fmbd_cli_summary("%s: %s copied", strcmp(out, "-") ? out : "<stdout>", path);
done:
  fmbd_h5_close(&w);
  fmbd_h5_close(&r);
  fmbd_free(format);
  fmbd_free(version);
  fmbd_free(x);
  fmbd_free(y);
  return rc;
}

int main(int argc, char **argv) {
  fmbd_cli_init("h5roundtrip", argc, argv);
  const char *opt_o = NULL, *pos[2] = {NULL, NULL};
  int npos = 0, do_make = 0, fail = 0;
  for (int i = 1; i < argc; i++) {
    if (!strcmp(argv[i], "-o")) {
      if (++i == argc) return fmbd_cli_usage_error("-o needs a file name");
      opt_o = argv[i];
    } else if (!strcmp(argv[i], "--make")) {
      do_make = 1;
    } else if (!strcmp(argv[i], "--fail")) {
      fail = 1;
    } else if (!strcmp(argv[i], "--help")) {
      printf(
          "usage: h5roundtrip --make [N] [-o OUT] | h5roundtrip INPUT PATH [-o OUT] [--fail]\n%s",
          fmbd_cli_exit_help());
      return fmbd_cli_finish(0);
    } else if (argv[i][0] == '-' && argv[i][1]) {
      return fmbd_cli_usage_error("unknown option '%s'", argv[i]);
    } else if (npos < 2) {
      pos[npos++] = argv[i];
    } else {
      return fmbd_cli_usage_error("too many arguments");
    }
  }
  int rc = FMBD_OK;
  char *out = NULL;
  if (do_make) {
    long n = 20000;
    if (npos >= 1) rc = fmbd_cli_parse_int("--make", pos[0], &n);
    if (!rc && n < 0) return fmbd_cli_usage_error("--make: negative size");
    if (!rc) rc = fmbd_cli_output_name("test", opt_o, NULL, ".h5", &out);
    if (!rc) rc = make((int64_t)n, out);
  } else {
    if (npos != 2) return fmbd_cli_usage_error("expected INPUT and PATH");
    const char *strip[] = {".rt.h5", ".h5", NULL};
    rc = fmbd_cli_output_name(pos[0], opt_o, strip, ".rt.h5", &out);
    if (!rc) rc = roundtrip(pos[0], pos[1], out, fail);
  }
  fmbd_free(out);
  return fmbd_cli_finish(rc);
}
