// tests/unit/t110-h5.c: fmbd_h5 round trips, errors, atomic output, allocation countdown
// SPDX-License-Identifier: MIT
//
// Values written and read back must be bit-identical (HDF5 stores IEEE doubles and int64
// exactly), so every numeric comparison here is exact equality.
#include <fcntl.h>
#include <hdf5.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "check.h"
#include "fmbd.h"

static char g_dir[1024];

static const char *tmp(const char *name) {
  static char buf[4][1200];
  static int k = 0;
  k = (k + 1) % 4;
  snprintf(buf[k], sizeof buf[k], "%s/%s", g_dir, name);
  return buf[k];
}

static bool file_exists(const char *p) {
  struct stat st;
  return stat(p, &st) == 0;
}

static bool part_exists(const char *p) {
  char q[1300];
  snprintf(q, sizeof q, "%s.part", p);
  return file_exists(q);
}

// The error record names the file and contains `where` in its location.
static void expect_ctx(const char *file, const char *where, const char *what) {
  const fmbd_err *e = fmbd_err_get();
  EXPECT(strstr(e->file, file) != NULL, "%s: error file '%s', expected '%s'", what, e->file, file);
  EXPECT(strstr(e->where, where) != NULL, "%s: error where '%s', expected '%s'", what, e->where,
         where);
}

// --- dense datasets of every rank and type ----------------------------------------------
static void test_dense(void) {
  const char *name = tmp("dense.h5");
  fmbd_h5 *f = NULL;
  EXPECT(fmbd_h5_create(name, "fmbd-test", "1.0", &f) == FMBD_OK, "create");
  EXPECT(part_exists(name) && !file_exists(name), "writing goes to .part");
  int64_t dims[5][4] = {{0}, {5}, {200, 100}, {3, 4, 5}, {2, 3, 4, 5}};  // rank 2 is chunked
  double *x = malloc(20000 * sizeof *x);
  int64_t *ix = malloc(20000 * sizeof *ix);
  for (int i = 0; i < 20000; i++) {
    x[i] = sin(i) * 1e3 + 1.0 / (i + 1);
    ix[i] = (int64_t)i * 123456789 - 7;
  }
  char p[64];
  for (int r = 0; r <= 4; r++) {
    snprintf(p, sizeof p, "/g%d/f64", r);
    EXPECT(fmbd_h5_write_f64(f, p, r, dims[r], x) == FMBD_OK, "write f64 rank %d", r);
    snprintf(p, sizeof p, "/g%d/i64", r);
    EXPECT(fmbd_h5_write_i64(f, p, r, dims[r], ix) == FMBD_OK, "write i64 rank %d", r);
  }
  int64_t z[2] = {0, 3};
  EXPECT(fmbd_h5_write_f64(f, "/empty", 2, z, NULL) == FMBD_OK, "write (0, 3)");
  // overwrite replaces
  int64_t one = 1;
  double seven = 7.0;
  EXPECT(fmbd_h5_write_f64(f, "/g1/f64", 1, &one, &seven) == FMBD_OK, "overwrite");
  EXPECT(fmbd_h5_write_f64(f, "/g1/f64", 1, dims[1], x) == FMBD_OK, "overwrite back");
  // a NaN and a float dataset holding integers, and one holding a fraction
  double bad[3] = {1, NAN, 3}, ints[3] = {1, -2, 3}, frac[3] = {1, 2.5, 3};
  int64_t three = 3;
  EXPECT(fmbd_h5_write_f64(f, "/bad/nan", 1, &three, bad) == FMBD_OK, "write nan");
  EXPECT(fmbd_h5_write_f64(f, "/bad/ints", 1, &three, ints) == FMBD_OK, "write ints");
  EXPECT(fmbd_h5_write_f64(f, "/bad/frac", 1, &three, frac) == FMBD_OK, "write frac");
  EXPECT(fmbd_h5_make_group(f, "/a/b/c") == FMBD_OK && fmbd_h5_exists(f, "/a/b/c"), "group");
  EXPECT(fmbd_h5_make_group(f, "/g1/f64") == FMBD_ERR_FORMAT, "group over a dataset");
  EXPECT(fmbd_h5_commit(&f, 1.0, 2.0) == FMBD_OK && f == NULL, "commit");
  EXPECT(file_exists(name) && !part_exists(name), "renamed at commit");

  EXPECT(fmbd_h5_open(name, &f) == FMBD_OK, "open");
  EXPECT(fmbd_h5_check_format(f, "fmbd-test", 1) == FMBD_OK, "format");
  EXPECT(!strcmp(fmbd_h5_name(f), name), "name");
  EXPECT(strlen(fmbd_h5_sha256(f)) == 64, "sha");
  char hex[65];
  EXPECT(fmbd_sha256_file(name, hex) == FMBD_OK && !strcmp(hex, fmbd_h5_sha256(f)), "sha matches");
  {  // the SHA-256 deferred (fmbd_h5_open_unhashed): the same hash when asked for, refused once
     // the file changed after it was opened
    fmbd_h5 *u = NULL;
    const char *us = NULL;
    EXPECT(fmbd_h5_open_unhashed(name, &u) == FMBD_OK && !fmbd_h5_sha256(u)[0], "open unhashed");
    EXPECT(fmbd_h5_sha256_now(u, &us) == FMBD_OK && !strcmp(us, hex) &&
               !strcmp(fmbd_h5_sha256(u), hex),
           "deferred sha");
    fmbd_h5_close(&u);
    EXPECT(fmbd_h5_open_unhashed(name, &u) == FMBD_OK, "open unhashed again");
    struct timespec ts[2] = {{0, UTIME_OMIT}, {12345, 0}};  // another modification time
    EXPECT(utimensat(AT_FDCWD, name, ts, 0) == 0, "touch");
    EXPECT(fmbd_h5_sha256_now(u, &us) == FMBD_ERR_IO, "changed since it was opened");
    fmbd_h5_close(&u);
  }
  for (int r = 0; r <= 4; r++) {
    int64_t d[4] = {-1, -1, -1, -1}, n = 1;
    for (int k = 0; k < r; k++) n *= dims[r][k];
    double *y = NULL;
    int64_t *iy = NULL;
    snprintf(p, sizeof p, "/g%d/f64", r);
    EXPECT(fmbd_h5_read_f64(f, p, r, d, &y) == FMBD_OK, "read f64 rank %d", r);
    for (int k = 0; k < r; k++) EXPECT(d[k] == dims[r][k], "rank %d extent %d", r, k);
    EXPECT(y && !memcmp(y, x, (size_t)n * sizeof *y), "f64 rank %d values", r);
    snprintf(p, sizeof p, "/g%d/i64", r);
    for (int k = 0; k < 4; k++) d[k] = k < r ? dims[r][k] : -1;  // exact extents required
    EXPECT(fmbd_h5_read_i64(f, p, r, d, &iy) == FMBD_OK, "read i64 rank %d", r);
    EXPECT(iy && !memcmp(iy, ix, (size_t)n * sizeof *iy), "i64 rank %d values", r);
    // integers read as double: exact below 2^53
    fmbd_free(y);
    y = NULL;
    if (r == 1) {
      EXPECT(fmbd_h5_read_f64(f, p, r, d, &y) == FMBD_OK && y[4] == (double)ix[4], "i64 as f64");
    }
    fmbd_free(y);
    fmbd_free(iy);
  }
  // large datasets are chunked + compressed, small ones contiguous
  hid_t fid = H5Fopen(name, H5F_ACC_RDONLY, H5P_DEFAULT);
  hid_t d2 = H5Dopen2(fid, "/g2/f64", H5P_DEFAULT), d1 = H5Dopen2(fid, "/g1/f64", H5P_DEFAULT);
  hid_t pl2 = H5Dget_create_plist(d2), pl1 = H5Dget_create_plist(d1);
  EXPECT(H5Pget_layout(pl2) == H5D_CHUNKED && H5Pget_nfilters(pl2) == 2,
         "large: chunked, 2 filters");
  EXPECT(H5Pget_layout(pl1) == H5D_CONTIGUOUS, "small: contiguous");
  H5Pclose(pl1), H5Pclose(pl2), H5Dclose(d1), H5Dclose(d2), H5Fclose(fid);

  double *y = NULL;
  int64_t *iy = NULL;
  int64_t d[4] = {-1, -1, -1, -1};
  EXPECT(fmbd_h5_read_f64(f, "/empty", 2, d, &y) == FMBD_OK && d[0] == 0 && d[1] == 3, "(0,3)");
  fmbd_free(y);
  y = NULL;
  // --- errors: each names the file and the dataset ---
  fmbd_err_clear();
  EXPECT(fmbd_h5_read_f64(f, "/nope/x", 1, d, &y) == FMBD_ERR_FORMAT && !y, "missing dataset");
  expect_ctx(name, "/nope/x", "missing");
  EXPECT(strstr(fmbd_err_get()->msg, "missing dataset") != NULL, "msg %s", fmbd_err_get()->msg);
  d[0] = -1;
  EXPECT(fmbd_h5_read_f64(f, "/g2/f64", 1, d, &y) == FMBD_ERR_FORMAT, "wrong rank");
  expect_ctx(name, "/g2/f64", "rank");
  d[0] = 200, d[1] = 99;
  EXPECT(fmbd_h5_read_f64(f, "/g2/f64", 2, d, &y) == FMBD_ERR_FORMAT, "wrong extent");
  d[0] = -1;
  EXPECT(fmbd_h5_read_f64(f, "/bad/nan", 1, d, &y) == FMBD_ERR_VALUE, "NaN");
  expect_ctx(name, "/bad/nan", "nan");
  EXPECT(strstr(fmbd_err_get()->msg, "element 1") != NULL, "NaN position: %s", fmbd_err_get()->msg);
  EXPECT(fmbd_h5_read_i64(f, "/bad/ints", 1, d, &iy) == FMBD_OK && iy[1] == -2, "float ints");
  fmbd_free(iy);
  iy = NULL;
  EXPECT(fmbd_h5_read_i64(f, "/bad/frac", 1, d, &iy) == FMBD_ERR_FORMAT && !iy, "fraction");
  EXPECT(fmbd_h5_read_f64(f, "/a", 0, d, &y) == FMBD_ERR_FORMAT, "group as dataset");
  EXPECT(fmbd_h5_exists(f, "/g3/f64") && !fmbd_h5_exists(f, "/g3/nope") &&
             !fmbd_h5_exists(f, "/g3/f64/x") && !fmbd_h5_exists(f, "/zz/yy") &&
             fmbd_h5_exists(f, "/") && fmbd_h5_exists(f, "/g3/") && fmbd_h5_exists(f, "g3/f64"),
         "exists");
  // writing into a read handle is refused
  EXPECT(fmbd_h5_write_f64(f, "/w", 1, &one, &seven) != FMBD_OK, "write to read handle");
  int n = 0;
  char **names = NULL;
  EXPECT(fmbd_h5_list(f, "/", &n, &names) == FMBD_OK && n == 8, "list / gives %d", n);
  const char *want[] = {"a", "bad", "empty", "g0", "g1", "g2", "g3", "g4"};
  for (int i = 0; i < n && i < 8; i++)
    EXPECT(!strcmp(names[i], want[i]), "list[%d] %s", i, names[i]);
  for (int i = 0; i < n; i++) fmbd_free(names[i]);
  fmbd_free(names);
  EXPECT(fmbd_h5_list(f, "/none", &n, &names) == FMBD_OK && n == 0 && !names, "list missing");
  EXPECT(fmbd_h5_list(f, "/g1/f64", &n, &names) == FMBD_ERR_FORMAT, "list a dataset");
  fmbd_h5_close(&f);
  EXPECT(f == NULL, "close sets NULL");
  free(x);
  free(ix);
}

// --- column-major matrices --------------------------------------------------------------
static void test_cm(void) {
  const char *name = tmp("cm.h5");
  fmbd_h5 *f = NULL;
  // shapes: tiny, tall (several row blocks: 100000 x 3 is chunked at 43690 rows), wide
  const int64_t shapes[3][2] = {{2, 3}, {100000, 3}, {3, 50000}};
  double *A[3];
  EXPECT(fmbd_h5_create(name, "fmbd-test", "1.0", &f) == FMBD_OK, "create");
  char p[32];
  for (int s = 0; s < 3; s++) {
    int64_t m = shapes[s][0], n = shapes[s][1];
    A[s] = malloc((size_t)(m * n) * sizeof(double));
    for (int64_t i = 0; i < m * n; i++) A[s][i] = (double)i + 0.25;
    snprintf(p, sizeof p, "/cm%d", s);
    EXPECT(fmbd_h5_write_f64_cm(f, p, m, n, A[s]) == FMBD_OK, "write cm %d", s);
  }
  EXPECT(fmbd_h5_commit(&f, 0, 0) == FMBD_OK, "commit");
  EXPECT(fmbd_h5_open(name, &f) == FMBD_OK, "open");
  for (int s = 0; s < 3; s++) {
    int64_t m = shapes[s][0], n = shapes[s][1];
    snprintf(p, sizeof p, "/cm%d", s);
    // the row-major dataset has shape (m, n) and element (i, j) = A[i + j m]
    int64_t d[2] = {-1, -1};
    double *R = NULL, *B = NULL;
    EXPECT(fmbd_h5_read_f64(f, p, 2, d, &R) == FMBD_OK && d[0] == m && d[1] == n, "shape %d", s);
    int bad = 0;
    for (int64_t i = 0; i < m && R; i++) {
      for (int64_t j = 0; j < n; j++) bad += R[i * n + j] != A[s][i + j * m];
    }
    EXPECT(R && !bad, "cm %d: %d elements transposed wrongly", s, bad);
    int64_t rows = m, cols = -1;
    EXPECT(fmbd_h5_read_f64_cm(f, p, &rows, &cols, &B) == FMBD_OK && rows == m && cols == n,
           "read cm %d", s);
    EXPECT(B && !memcmp(B, A[s], (size_t)(m * n) * sizeof *B), "cm %d round trip", s);
    rows = m + 1;
    fmbd_free(B);
    B = NULL;
    EXPECT(fmbd_h5_read_f64_cm(f, p, &rows, &cols, &B) == FMBD_ERR_FORMAT && !B, "cm extent");
    fmbd_free(R);
    free(A[s]);
  }
  fmbd_h5_close(&f);
}

// --- CSR groups ---------------------------------------------------------------------------
static void test_csr(void) {
  const char *name = tmp("csr.h5");
  fmbd_h5 *f = NULL;
  fmbd_csr *A = NULL, *B = NULL, *E = NULL;
  // 4 x 5 with an empty row
  EXPECT(fmbd_csr_create(4, 5, 6, &A) == FMBD_OK, "csr");
  const int64_t ip[5] = {0, 2, 2, 5, 6}, ix[6] = {0, 4, 1, 2, 3, 0};
  const double v[6] = {1.5, -2, 3, 4e-300, 5e300, -6};
  memcpy(A->indptr, ip, sizeof ip), memcpy(A->indices, ix, sizeof ix), memcpy(A->data, v, sizeof v);
  EXPECT(fmbd_csr_create(0, 0, 0, &E) == FMBD_OK, "empty csr");
  EXPECT(fmbd_h5_create(name, "fmbd-test", "1.0", &f) == FMBD_OK, "create");
  EXPECT(fmbd_h5_write_csr(f, "/mats/A", A) == FMBD_OK, "write");
  EXPECT(fmbd_h5_write_csr(f, "/E", E) == FMBD_OK, "write empty");
  A->indices[3] = 1;  // row 2 now 1, 1: not increasing
  EXPECT(fmbd_h5_write_csr(f, "/bad", A) == FMBD_OK, "write bad");
  A->indices[3] = 2;
  EXPECT(fmbd_h5_write_csr(f, "/mats/A", A) == FMBD_OK, "rewrite");
  EXPECT(fmbd_h5_write_f64(f, "/bad2/data", 1, (int64_t[]){6}, v) == FMBD_OK, "bad2");
  // a matrix on A's pattern: its indices and indptr hard links to A's (fmbd_h5_write_csr_like),
  // and the same matrix written whole; a shape that is not A's is refused
  const double vc[6] = {7, 8, 9, 10, 11, 12};
  memcpy(A->data, vc, sizeof vc);
  EXPECT(fmbd_h5_write_csr_like(f, "/mats/C", A, "/mats/A") == FMBD_OK, "write like");
  EXPECT(fmbd_h5_write_csr(f, "/mats/D", A) == FMBD_OK, "write D");
  A->data[3] = NAN;  // row 2, column 2: refused by the shared read too (values checked alone)
  EXPECT(fmbd_h5_write_csr_like(f, "/mats/N", A, "/mats/A") == FMBD_OK, "write N");
  EXPECT(fmbd_h5_write_csr_like(f, "/mats/F", E, "/mats/A") == FMBD_ERR_INTERNAL,
         "write like with another shape");
  memcpy(A->data, v, sizeof v);
  EXPECT(fmbd_h5_commit(&f, 0, 0) == FMBD_OK, "commit");
  EXPECT(fmbd_h5_open(name, &f) == FMBD_OK, "open");
  EXPECT(fmbd_h5_read_csr(f, "/mats/A", &B) == FMBD_OK, "read");
  EXPECT(B && B->nrows == 4 && B->ncols == 5 && !memcmp(B->indptr, ip, sizeof ip) &&
             !memcmp(B->indices, ix, sizeof ix) && !memcmp(B->data, v, sizeof v),
         "csr round trip");
  {
    // /mats/C shares A's datasets: read "like" B it copies B's pattern instead of reading the
    // file's (shown by a B whose pattern was changed in memory after reading: C takes it), and
    // read alone it is an ordinary CSR group; /mats/D, the same values but its own datasets, is
    // read from the file either way
    fmbd_csr *C = NULL, *D = NULL;
    EXPECT(fmbd_h5_read_csr(f, "/mats/C", &C) == FMBD_OK && !memcmp(C->indptr, ip, sizeof ip) &&
               !memcmp(C->indices, ix, sizeof ix) && !memcmp(C->data, vc, sizeof vc),
           "linked csr read alone");
    fmbd_csr_destroy(&C);
    B->indices[0] = 1;  // row 0: 1, 4 (still increasing)
    EXPECT(fmbd_h5_read_csr_like(f, "/mats/C", B, "/mats/A", false, &C) == FMBD_OK &&
               C->indices != B->indices && C->indices[0] == 1 && !memcmp(C->data, vc, sizeof vc),
           "linked csr read like A: the pattern copied");
    fmbd_csr_destroy(&C);
    EXPECT(fmbd_h5_read_csr_like(f, "/mats/C", B, "/mats/A", true, &C) == FMBD_OK &&
               C->indices == B->indices && C->indptr == B->indptr && C->indices[0] == 1 &&
               !memcmp(C->data, vc, sizeof vc),
           "linked csr read like A, shared: A's pattern arrays themselves");
    for (int share = 0; share < 2; share++) {
      EXPECT(fmbd_h5_read_csr_like(f, "/mats/D", B, "/mats/A", share, &D) == FMBD_OK &&
                 D->indices[0] == 0 && D->indices != B->indices &&
                 !memcmp(D->indices, ix, sizeof ix) && !memcmp(D->data, vc, sizeof vc),
             "separate csr read like A: read from the file");
      fmbd_csr_destroy(&D);
    }
    C->indptr = C->indices = NULL;  // B's, freed with B
    fmbd_csr_destroy(&C);
    fmbd_err_clear();
    EXPECT(fmbd_h5_read_csr_like(f, "/mats/N", B, "/mats/A", true, &C) == FMBD_ERR_VALUE && !C,
           "NaN in a shared read");
    EXPECT(strstr(fmbd_err_get()->msg, "data: NaN at row 2, column 2") != NULL, "msg %s",
           fmbd_err_get()->msg);
    expect_ctx(name, "/mats/N", "NaN in a shared read");
  }
  fmbd_csr_destroy(&B);
  // row blocks (fmbd_h5_read_csr_rows): every r0 <= r1 gives rows r0..r1-1 of A, indptr from 0
  for (int64_t r0 = 0; r0 <= 4; r0++) {
    for (int64_t r1 = r0; r1 <= 4; r1++) {
      int64_t nall = -1;
      EXPECT(fmbd_h5_read_csr_rows(f, "/mats/A", r0, r1, &nall, &B) == FMBD_OK, "rows %lld..%lld",
             (long long)r0, (long long)r1);
      bool same = B && B->nrows == r1 - r0 && B->ncols == 5 && nall == 4;
      for (int64_t i = 0; same && i <= r1 - r0; i++) same = B->indptr[i] == ip[r0 + i] - ip[r0];
      for (int64_t p = ip[r0]; same && p < ip[r1]; p++) {
        same = B->indices[p - ip[r0]] == ix[p] && B->data[p - ip[r0]] == v[p];
      }
      EXPECT(same, "rows %lld..%lld equal to A's", (long long)r0, (long long)r1);
      fmbd_csr_destroy(&B);
    }
  }
  EXPECT(fmbd_h5_read_csr_rows(f, "/mats/A", 2, 5, NULL, &B) == FMBD_ERR_VALUE && !B,
         "rows beyond the matrix");
  EXPECT(fmbd_h5_read_csr_rows(f, "/bad", 0, 2, NULL, &B) == FMBD_OK, "rows before the defect");
  fmbd_csr_destroy(&B);
  EXPECT(fmbd_h5_read_csr_rows(f, "/bad", 1, 3, NULL, &B) == FMBD_ERR_FORMAT && !B,
         "rows with the defect");
  expect_ctx(name, "/bad", "bad rows");
  EXPECT(fmbd_h5_read_csr_rows(f, "/missing", 0, 1, NULL, &B) == FMBD_ERR_FORMAT, "missing rows");
  EXPECT(fmbd_h5_read_csr(f, "/E", &B) == FMBD_OK && B->nrows == 0 && fmbd_csr_nnz(B) == 0,
         "empty");
  fmbd_csr_destroy(&B);
  fmbd_err_clear();
  EXPECT(fmbd_h5_read_csr(f, "/bad", &B) == FMBD_ERR_FORMAT && !B, "bad csr");
  expect_ctx(name, "/bad", "bad csr");
  EXPECT(strstr(fmbd_err_get()->msg, "row 2") != NULL, "msg %s", fmbd_err_get()->msg);
  EXPECT(fmbd_h5_read_csr(f, "/bad2", &B) == FMBD_ERR_FORMAT, "no shape attribute");
  expect_ctx(name, "/bad2", "bad2");
  EXPECT(fmbd_h5_read_csr(f, "/missing", &B) == FMBD_ERR_FORMAT, "missing");
  EXPECT(fmbd_h5_read_csr(f, "/mats/A/data", &B) == FMBD_ERR_FORMAT, "dataset as csr");
  fmbd_h5_close(&f);
  fmbd_csr_destroy(&A);
  fmbd_csr_destroy(&E);
}

// --- attributes, inputs, format checks -------------------------------------------------------
static void test_attrs(void) {
  const char *name = tmp("attr.h5"), *in = tmp("input.bin");
  FILE *fp = fopen(in, "wb");
  fputs("abc", fp);
  fclose(fp);
  fmbd_h5 *f = NULL;
  EXPECT(fmbd_h5_create(name, "fmbd-test", "1.3", &f) == FMBD_OK, "create");
  double c[3] = {1, 2, 3}, m = 4.5;
  int64_t k[2] = {-5, 1LL << 60}, one = 9;
  const char *sv[3] = {"x", "", "ü-strings"};
  EXPECT(fmbd_h5_write_attr_f64(f, "/body", "center", 3, c) == FMBD_OK, "f64 attr (makes group)");
  EXPECT(fmbd_h5_write_attr_f64(f, "/body", "mass", 1, &m) == FMBD_OK, "scalar attr");
  EXPECT(fmbd_h5_write_attr_i64(f, "/body", "k", 2, k) == FMBD_OK, "i64 attr");
  EXPECT(fmbd_h5_write_attr_i64(f, "/body", "one", 1, &one) == FMBD_OK, "i64 scalar");
  EXPECT(fmbd_h5_write_attr_str(f, "/body", "kind", "rbe2") == FMBD_OK, "str attr");
  EXPECT(fmbd_h5_write_attr_str(f, "/body", "kind", "rbe3") == FMBD_OK, "str attr replaced");
  EXPECT(fmbd_h5_write_attr_strv(f, "/", "names", 3, sv) == FMBD_OK, "strv attr");
  EXPECT(fmbd_h5_add_input(f, in, NULL) == FMBD_OK, "input hashed here");
  EXPECT(fmbd_h5_add_input(f, "other.h5", "0123") == FMBD_OK, "input given");
  EXPECT(fmbd_h5_add_input(f, "-", NULL) != FMBD_OK, "stdin cannot be hashed again");
  EXPECT(fmbd_h5_commit(&f, 3.5, 4.5) == FMBD_OK, "commit");

  EXPECT(fmbd_h5_open(name, &f) == FMBD_OK, "open");
  EXPECT(fmbd_h5_check_format(f, "fmbd-test", 1) == FMBD_OK, "newer minor accepted");
  double c2[3], m2, w;
  int64_t k2[2], one2;
  char *s = NULL;
  EXPECT(fmbd_h5_read_attr_f64(f, "/body", "center", 3, c2) == FMBD_OK && !memcmp(c, c2, sizeof c),
         "f64");
  EXPECT(fmbd_h5_read_attr_f64(f, "/body", "mass", 1, &m2) == FMBD_OK && m2 == m, "mass");
  EXPECT(fmbd_h5_read_attr_i64(f, "/body", "k", 2, k2) == FMBD_OK && !memcmp(k, k2, sizeof k),
         "i64");
  EXPECT(fmbd_h5_read_attr_i64(f, "/body", "one", 1, &one2) == FMBD_OK && one2 == 9, "i64 scalar");
  EXPECT(fmbd_h5_read_attr_f64(f, "/body", "one", 1, &m2) == FMBD_OK && m2 == 9.0, "int as f64");
  EXPECT(fmbd_h5_read_attr_str(f, "/body", "kind", &s) == FMBD_OK && !strcmp(s, "rbe3"), "str");
  fmbd_free(s);
  EXPECT(fmbd_h5_read_attr_f64(f, "/", "wall_time_s", 1, &w) == FMBD_OK && w == 3.5, "wall");
  EXPECT(fmbd_h5_read_attr_f64(f, "/", "cpu_time_s", 1, &w) == FMBD_OK && w == 4.5, "cpu");
  EXPECT(fmbd_h5_read_attr_str(f, "/", "creator", &s) == FMBD_OK && strstr(s, fmbd_version()),
         "creator %s", s);
  fmbd_free(s);
  EXPECT(fmbd_h5_has_attr(f, "/", "command_line") && fmbd_h5_has_attr(f, "/body", "mass") &&
             !fmbd_h5_has_attr(f, "/body", "nope") && !fmbd_h5_has_attr(f, "/nope", "mass"),
         "has_attr");
  int64_t nv = 0;
  char **v = NULL;
  EXPECT(fmbd_h5_read_attr_strv(f, "/", "names", &nv, &v) == FMBD_OK && nv == 3, "strv");
  for (int i = 0; i < nv; i++) {
    EXPECT(!strcmp(v[i], sv[i]), "strv[%d] = %s", i, v[i]);
    fmbd_free(v[i]);
  }
  fmbd_free(v);
  int ni = 0;
  char **in_names = NULL, **in_sha = NULL;
  EXPECT(fmbd_h5_read_inputs(f, &ni, &in_names, &in_sha) == FMBD_OK && ni == 2, "inputs %d", ni);
  if (ni == 2) {
    EXPECT(
        !strcmp(in_names[0], in) &&
            !strcmp(in_sha[0], "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"),
        "input 0");
    EXPECT(!strcmp(in_names[1], "other.h5") && !strcmp(in_sha[1], "0123"), "input 1");
  }
  for (int i = 0; i < ni; i++) fmbd_free(in_names[i]), fmbd_free(in_sha[i]);
  fmbd_free(in_names), fmbd_free(in_sha);
  // --- attribute errors name file, object and attribute ---
  fmbd_err_clear();
  EXPECT(fmbd_h5_read_attr_f64(f, "/body", "center", 2, c2) == FMBD_ERR_FORMAT, "wrong count");
  expect_ctx(name, "/body", "count");
  EXPECT(strstr(fmbd_err_get()->msg, "center") != NULL, "msg %s", fmbd_err_get()->msg);
  EXPECT(fmbd_h5_read_attr_f64(f, "/body", "nope", 1, c2) == FMBD_ERR_FORMAT, "missing attr");
  EXPECT(strstr(fmbd_err_get()->msg, "nope") != NULL, "msg %s", fmbd_err_get()->msg);
  EXPECT(fmbd_h5_read_attr_i64(f, "/body", "mass", 1, k2) == FMBD_ERR_FORMAT, "float as int");
  EXPECT(fmbd_h5_read_attr_str(f, "/body", "mass", &s) == FMBD_ERR_FORMAT && !s, "number as str");
  EXPECT(fmbd_h5_read_attr_f64(f, "/body", "kind", 1, c2) == FMBD_ERR_FORMAT, "str as number");
  EXPECT(fmbd_h5_read_attr_str(f, "/nope", "x", &s) == FMBD_ERR_FORMAT, "missing object");
  expect_ctx(name, "/nope", "missing object");
  // --- format checks ---
  fmbd_err_clear();
  EXPECT(fmbd_h5_check_format(f, "fmbd-fe", 1) == FMBD_ERR_FORMAT, "foreign format");
  EXPECT(strstr(fmbd_err_get()->msg, "is a fmbd-test file, expected fmbd-fe") != NULL, "msg %s",
         fmbd_err_get()->msg);
  expect_ctx(name, "", "format");
  EXPECT(!fmbd_err_get()->where[0], "root-level error without a path: '%s'", fmbd_err_get()->where);
  EXPECT(fmbd_h5_check_format(f, "fmbd-test", 0) == FMBD_ERR_VERSION, "newer major");
  EXPECT(strstr(fmbd_err_get()->msg, "1.3") != NULL, "msg %s", fmbd_err_get()->msg);
  fmbd_h5_close(&f);

  // a plain HDF5 file without the root attributes, and one with a bad version string
  const char *plain = tmp("plain.h5");
  hid_t fid = H5Fcreate(plain, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  // a fixed-length string attribute (as other tools write) is read too
  hid_t t = H5Tcopy(H5T_C_S1), sp = H5Screate(H5S_SCALAR);
  H5Tset_size(t, 8);
  hid_t a = H5Acreate2(fid, "format_version", t, sp, H5P_DEFAULT, H5P_DEFAULT);
  H5Awrite(a, t, "1.x\0\0\0\0\0");
  H5Aclose(a), H5Sclose(sp), H5Tclose(t), H5Fclose(fid);
  EXPECT(fmbd_h5_open(plain, &f) == FMBD_OK, "open plain");
  fmbd_err_clear();
  EXPECT(fmbd_h5_check_format(f, "fmbd-fe", 1) == FMBD_ERR_FORMAT, "no format attribute");
  EXPECT(strstr(fmbd_err_get()->msg, "not a toolchain file") != NULL, "msg %s",
         fmbd_err_get()->msg);
  EXPECT(fmbd_h5_read_attr_str(f, "/", "format_version", &s) == FMBD_OK && !strcmp(s, "1.x"),
         "fixed-length string '%s'", s);
  fmbd_free(s);
  fmbd_h5_close(&f);
}

// --- opening errors ---------------------------------------------------------------------------
static void test_open_errors(void) {
  fmbd_h5 *f = NULL;
  fmbd_err_clear();
  const char *missing = tmp("missing.h5");
  EXPECT(fmbd_h5_open(missing, &f) == FMBD_ERR_IO && !f, "missing file");
  expect_ctx(missing, "", "missing");
  EXPECT(fmbd_h5_open(g_dir, &f) == FMBD_ERR_IO && !f, "directory");
  const char *text = tmp("text.h5");
  FILE *fp = fopen(text, "w");
  fputs("this is not HDF5\n", fp);
  fclose(fp);
  EXPECT(fmbd_h5_open(text, &f) == FMBD_ERR_FORMAT && !f, "text file");
  expect_ctx(text, "", "text");
  // truncated: the first half of a valid file
  const char *full = tmp("full.h5"), *cut = tmp("cut.h5");
  EXPECT(fmbd_h5_create(full, "fmbd-test", "1.0", &f) == FMBD_OK, "create");
  double x[4000];
  for (int i = 0; i < 4000; i++) x[i] = i;
  int64_t n = 4000;
  EXPECT(fmbd_h5_write_f64(f, "/x", 1, &n, x) == FMBD_OK, "write");
  EXPECT(fmbd_h5_commit(&f, 0, 0) == FMBD_OK, "commit");
  struct stat st;
  stat(full, &st);
  FILE *in = fopen(full, "rb"), *out = fopen(cut, "wb");
  for (off_t i = 0; i < st.st_size / 2; i++) fputc(fgetc(in), out);
  fclose(in), fclose(out);
  fmbd_err_clear();
  int rc = fmbd_h5_open(cut, &f);
  EXPECT(rc == FMBD_ERR_FORMAT && !f, "truncated file: rc %d", rc);
  expect_ctx(cut, "", "truncated");
  fmbd_h5_close(&f);
}

// --- atomic output ----------------------------------------------------------------------------
static void test_atomic(void) {
  fmbd_h5 *f = NULL;
  // closing an uncommitted handle discards everything
  const char *a = tmp("discard.h5");
  EXPECT(fmbd_h5_create(a, "fmbd-test", "1.0", &f) == FMBD_OK, "create");
  fmbd_h5_close(&f);
  EXPECT(!file_exists(a) && !part_exists(a), "close discards");
  // abandon keeps the .part, with what was flushed readable
  const char *b = tmp("abandon.h5");
  fmbd_h5_series *s = NULL, *s2 = NULL;
  EXPECT(fmbd_h5_create(b, "fmbd-run", "1.0", &f) == FMBD_OK, "create");
  EXPECT(fmbd_h5_series_create(f, "/time", 0, &s) == FMBD_OK, "series 1-D");
  EXPECT(fmbd_h5_series_create(f, "/out/p/position", 3, &s2) == FMBD_OK, "series 2-D");
  for (int step = 0; step < 50; step++) {
    double t = 0.01 * step, p[6] = {step, 2 * step, 3 * step, -step, -2 * step, -3 * step};
    EXPECT(fmbd_h5_series_append(s, 1, &t) == FMBD_OK, "append");
    if (step % 2 == 0) EXPECT(fmbd_h5_series_append(s2, 2, p) == FMBD_OK, "append 2 rows");
  }
  EXPECT(fmbd_h5_series_rows(s) == 50 && fmbd_h5_series_rows(s2) == 50, "rows");
  EXPECT(fmbd_h5_flush(f) == FMBD_OK, "flush");
  // read the .part while the writer still has it open (HDF5 file locking is per process)
  fmbd_h5_series_close(&s);
  fmbd_h5_series_close(&s2);
  fmbd_h5_abandon(&f);
  EXPECT(f == NULL && !file_exists(b) && part_exists(b), "abandon keeps .part only");
  char bp[1300];
  snprintf(bp, sizeof bp, "%s.part", b);
  EXPECT(fmbd_h5_open(bp, &f) == FMBD_OK, "open .part");
  int64_t d[2] = {-1, -1};
  double *t = NULL, *p = NULL;
  EXPECT(fmbd_h5_read_f64(f, "/time", 1, d, &t) == FMBD_OK && d[0] == 50 && t[49] == 0.49,
         "series");
  d[0] = 50, d[1] = 3;
  EXPECT(fmbd_h5_read_f64(f, "/out/p/position", 2, d, &p) == FMBD_OK, "2-D series");
  EXPECT(p && p[3 * 48 + 1] == 96.0 && p[3 * 49 + 2] == -144.0, "series values");
  fmbd_free(t), fmbd_free(p);
  EXPECT(!fmbd_h5_has_attr(f, "/", "wall_time_s"), "abandoned: no times");
  fmbd_h5_close(&f);
  unlink(bp);
  // a series left open is closed with the file at commit
  const char *c = tmp("series.h5");
  EXPECT(fmbd_h5_create(c, "fmbd-run", "1.0", &f) == FMBD_OK, "create");
  EXPECT(fmbd_h5_series_create(f, "/x", 2, &s) == FMBD_OK, "series");
  double rows[20000];
  for (int i = 0; i < 20000; i++) rows[i] = i;
  EXPECT(fmbd_h5_series_append(s, 10000, rows) == FMBD_OK, "append many (several chunks)");
  EXPECT(fmbd_h5_commit(&f, 0, 0) == FMBD_OK, "commit with an open series");
  fmbd_h5_series_close(&s);
  EXPECT(fmbd_h5_open(c, &f) == FMBD_OK, "open");
  d[0] = 10000, d[1] = 2;
  EXPECT(fmbd_h5_read_f64(f, "/x", 2, d, &t) == FMBD_OK && !memcmp(t, rows, sizeof rows), "rows");
  fmbd_free(t);
  fmbd_h5_close(&f);
  // unwritable destinations: nothing is left, the error names the file
  fmbd_err_clear();
  const char *bad = "/proc/version/x.h5";  // parent is not a directory (also as root)
  EXPECT(fmbd_h5_create(bad, "fmbd-test", "1.0", &f) == FMBD_ERR_IO && !f, "unwritable");
  expect_ctx(bad, "", "unwritable");
  // the target is a directory: refused when the file is created (before any work), nothing
  // made, the directory and its contents untouched
  const char *dir = tmp("adir.h5");
  mkdir(dir, 0755);
  char sub[1300];
  snprintf(sub, sizeof sub, "%s/keep", dir);
  fclose(fopen(sub, "w"));
  fmbd_err_clear();
  EXPECT(fmbd_h5_create(dir, "fmbd-test", "1.0", &f) == FMBD_ERR_IO && !f, "directory refused");
  expect_ctx(dir, "", "directory");
  EXPECT(!part_exists(dir) && access(sub, F_OK) == 0, "no .part, the directory kept");
  unlink(sub);
  rmdir(dir);
}

// --- copy between files ---------------------------------------------------------------------
static void test_copy(void) {
  const char *src = tmp("src.h5"), *dst = tmp("dst.h5");
  fmbd_h5 *f = NULL, *g = NULL;
  EXPECT(fmbd_h5_create(src, "fmbd-fe", "1.0", &f) == FMBD_OK, "create");
  double x[3] = {1, 2, 3};
  int64_t n = 3;
  EXPECT(fmbd_h5_write_f64(f, "/mesh/nodes", 1, &n, x) == FMBD_OK, "w");
  EXPECT(fmbd_h5_write_attr_str(f, "/interfaces/tip", "kind", "rbe2") == FMBD_OK, "w");
  EXPECT(fmbd_h5_write_f64(f, "/interfaces/tip/nodes", 1, &n, x) == FMBD_OK, "w");
  EXPECT(fmbd_h5_commit(&f, 0, 0) == FMBD_OK, "commit");
  EXPECT(fmbd_h5_open(src, &f) == FMBD_OK, "open");
  EXPECT(fmbd_h5_create(dst, "fmbd-cb", "1.0", &g) == FMBD_OK, "create dst");
  EXPECT(fmbd_h5_copy(f, "/mesh", g) == FMBD_OK, "copy group");
  EXPECT(fmbd_h5_copy(f, "/interfaces/tip", g) == FMBD_OK, "copy nested group");
  EXPECT(fmbd_h5_copy(f, "/mesh", g) == FMBD_OK, "copy again replaces");
  fmbd_err_clear();
  EXPECT(fmbd_h5_copy(f, "/nope", g) == FMBD_ERR_FORMAT, "copy missing");
  expect_ctx(src, "/nope", "copy missing");
  EXPECT(fmbd_h5_delete(g, "/mesh") == FMBD_OK && !fmbd_h5_exists(g, "/mesh"), "delete");
  EXPECT(fmbd_h5_copy(f, "/mesh", g) == FMBD_OK, "copy after delete");
  EXPECT(fmbd_h5_commit(&g, 0, 0) == FMBD_OK, "commit dst");
  fmbd_h5_close(&f);
  EXPECT(fmbd_h5_open(dst, &g) == FMBD_OK, "open dst");
  double *y = NULL;
  char *s = NULL;
  int64_t d[1] = {3};
  EXPECT(fmbd_h5_read_f64(g, "/mesh/nodes", 1, d, &y) == FMBD_OK && y[2] == 3.0, "copied data");
  fmbd_free(y);
  EXPECT(fmbd_h5_read_attr_str(g, "/interfaces/tip", "kind", &s) == FMBD_OK && !strcmp(s, "rbe2"),
         "copied attribute");
  fmbd_free(s);
  EXPECT(fmbd_h5_check_format(g, "fmbd-cb", 1) == FMBD_OK, "own root attributes kept");
  fmbd_h5_close(&g);
}

// --- allocation countdown: the Nth allocation fails, for N = 0, 1, ... until success ---------
static int write_read_cycle(const char *name) {
  int rc = FMBD_OK;
  fmbd_h5 *f = NULL;
  fmbd_csr *A = NULL, *B = NULL;
  fmbd_h5_series *s = NULL;
  double *y = NULL, *cm = NULL;
  int n = 0;
  char **names = NULL, *str = NULL, **in_n = NULL, **in_s = NULL;
  int64_t nv = 0;
  char **sv = NULL;
  int ni = 0;
  double x[6] = {1, 2, 3, 4, 5, 6};
  int64_t d[2] = {2, 3};
  FMBD_GCALL(fmbd_csr_create(2, 2, 2, &A));
  A->indptr[1] = 1, A->indptr[2] = 2, A->indices[0] = 0, A->indices[1] = 1;
  A->data[0] = A->data[1] = 1.0;
  FMBD_GCALL(fmbd_h5_create(name, "fmbd-test", "1.0", &f));
  FMBD_GCALL(fmbd_h5_write_f64(f, "/x", 2, d, x));
  FMBD_GCALL(fmbd_h5_write_f64_cm(f, "/cm", 2, 3, x));
  FMBD_GCALL(fmbd_h5_write_csr(f, "/A", A));
  FMBD_GCALL(fmbd_h5_write_attr_strv(f, "/", "names", 2, (const char *const[]){"a", "b"}));
  FMBD_GCALL(fmbd_h5_series_create(f, "/t", 0, &s));
  FMBD_GCALL(fmbd_h5_series_append(s, 3, x));
  fmbd_h5_series_close(&s);
  FMBD_GCALL(fmbd_h5_add_input(f, "in1", "00"));
  FMBD_GCALL(fmbd_h5_add_input(f, "in2", "11"));
  FMBD_GCALL(fmbd_h5_commit(&f, 0, 0));
  FMBD_GCALL(fmbd_h5_open(name, &f));
  FMBD_GCALL(fmbd_h5_check_format(f, "fmbd-test", 1));
  d[0] = d[1] = -1;
  FMBD_GCALL(fmbd_h5_read_f64(f, "/x", 2, d, &y));
  d[0] = d[1] = -1;
  FMBD_GCALL(fmbd_h5_read_f64_cm(f, "/cm", &d[0], &d[1], &cm));
  FMBD_GCALL(fmbd_h5_read_csr(f, "/A", &B));
  FMBD_GCALL(fmbd_h5_list(f, "/", &n, &names));
  FMBD_GCALL(fmbd_h5_read_attr_str(f, "/", "creator", &str));
  FMBD_GCALL(fmbd_h5_read_attr_strv(f, "/", "names", &nv, &sv));
  FMBD_GCALL(fmbd_h5_read_inputs(f, &ni, &in_n, &in_s));
  FMBD_GCHECK(n == 4 && nv == 2 && ni == 2 && cm[2] == 3.0, FMBD_ERR_INTERNAL, "wrong results");
done:
  fmbd_h5_series_close(&s);
  fmbd_h5_close(&f);
  fmbd_csr_destroy(&A);
  fmbd_csr_destroy(&B);
  fmbd_free(y);
  fmbd_free(cm);
  for (int i = 0; i < n; i++) fmbd_free(names[i]);
  fmbd_free(names);
  fmbd_free(str);
  for (int64_t i = 0; i < nv; i++) fmbd_free(sv[i]);
  fmbd_free(sv);
  for (int i = 0; i < ni; i++) fmbd_free(in_n[i]), fmbd_free(in_s[i]);
  fmbd_free(in_n);
  fmbd_free(in_s);
  return rc;
}

static void test_countdown(void) {
  const char *name = tmp("countdown.h5");
  int64_t k = 0;
  int rc;
  for (;; k++) {
    unlink(name);
    fmbd_alloc_fail_after(k);
    rc = write_read_cycle(name);
    fmbd_alloc_fail_after(-1);
    if (rc == FMBD_OK) break;
    EXPECT(rc == FMBD_ERR_NOMEM, "countdown %lld: rc %d (%s)", (long long)k, rc,
           fmbd_err_get()->msg);
    EXPECT(!part_exists(name), "countdown %lld: .part left behind", (long long)k);
    if (k > 1000) break;
  }
  EXPECT(rc == FMBD_OK && k > 20, "countdown ended at %lld with rc %d", (long long)k, rc);
}

// The filters of a CSR group's arrays (fmbd_h5.c, CSR_INDEX_LEVEL): indices and indptr shuffle +
// deflate 2; values like a consistent mass (whole doubles repeated) deflate 1 unshuffled; values
// that do not compress 2:1 either way (pseudo-random) plain. `filters` gives the dataset's
// filter count, whether shuffle is among them and the deflate level (0 when none)
static void filters(hid_t fid, const char *path, bool *shuffle, unsigned *level, int *n) {
  hid_t d = H5Dopen2(fid, path, H5P_DEFAULT), pl = d >= 0 ? H5Dget_create_plist(d) : -1;
  *shuffle = false;
  *level = 0;
  *n = pl >= 0 ? H5Pget_nfilters(pl) : -1;
  for (int i = 0; i < *n; i++) {
    unsigned flags, cd[4] = {0};
    size_t ncd = 4;
    H5Z_filter_t id = H5Pget_filter2(pl, (unsigned)i, &flags, &ncd, cd, 0, NULL, NULL);
    if (id == H5Z_FILTER_SHUFFLE) *shuffle = true;
    if (id == H5Z_FILTER_DEFLATE) *level = ncd > 0 ? cd[0] : 0;
  }
  if (pl >= 0) H5Pclose(pl);
  if (d >= 0) H5Dclose(d);
}

static void test_csr_filters(void) {
  const char *name = tmp("csrf.h5");
  const int64_t n = 20000;  // one entry a row: chunked (over CHUNK_MIN_ELEMS)
  fmbd_csr *A = NULL;
  fmbd_h5 *f = NULL;
  EXPECT(fmbd_csr_create(n, n, n, &A) == FMBD_OK, "csr");
  uint64_t s = 1;
  for (int64_t i = 0; i <= n; i++) A->indptr[i] = i;
  for (int64_t i = 0; i < n; i++) {
    A->indices[i] = i;
    A->data[i] = (double)(i % 7 == 0 ? 3 : 0) * 0.1;  // mass-like: repeated whole doubles
  }
  EXPECT(fmbd_h5_create(name, "fmbd-test", "1.0", &f) == FMBD_OK, "create");
  EXPECT(fmbd_h5_write_csr(f, "/M", A) == FMBD_OK, "write M");
  for (int64_t i = 0; i < n; i++) {
    s = s * 6364136223846793005ULL + 1442695040888963407ULL;
    A->data[i] = (double)(s >> 11) / 9007199254740992.0;  // random mantissas: ~1:1 either way
  }
  EXPECT(fmbd_h5_write_csr_like(f, "/K", A, "/M") == FMBD_OK, "write K");
  EXPECT(fmbd_h5_commit(&f, 0, 0) == FMBD_OK, "commit");
  hid_t fid = H5Fopen(name, H5F_ACC_RDONLY, H5P_DEFAULT);
  bool sh;
  unsigned lv;
  int nf;
  filters(fid, "/M/indices", &sh, &lv, &nf);
  EXPECT(nf == 2 && sh && lv == 2, "indices: %d filters, shuffle %d, deflate %u", nf, sh, lv);
  filters(fid, "/M/indptr", &sh, &lv, &nf);
  EXPECT(nf == 2 && sh && lv == 2, "indptr: %d filters, shuffle %d, deflate %u", nf, sh, lv);
  filters(fid, "/M/data", &sh, &lv, &nf);
  EXPECT(nf == 1 && !sh && lv == 1, "mass-like data: %d filters, shuffle %d, deflate %u", nf, sh,
         lv);
  filters(fid, "/K/data", &sh, &lv, &nf);
  EXPECT(nf == 0, "random data: %d filters, shuffle %d, deflate %u", nf, sh, lv);
  H5Fclose(fid);
  fmbd_csr *B = NULL;
  EXPECT(fmbd_h5_open(name, &f) == FMBD_OK && fmbd_h5_read_csr(f, "/K", &B) == FMBD_OK && B &&
             !memcmp(B->data, A->data, (size_t)n * sizeof *A->data),
         "filtered csr read back");
  fmbd_csr_destroy(&B);
  fmbd_h5_close(&f);
  fmbd_csr_destroy(&A);
}

// CSR arrays of several chunks, the last one partial (fmbd_h5.c read_chunks: each chunk
// decompressed into the array, shuffled ones through a scratch chunk): every filter layout the
// writer chooses (indices shuffle + deflate; values deflate, shuffle + deflate, none) read back
// bit for bit; chunk lengths that are and are not multiples of the unshuffle's 16-element
// blocks; a chunk with one byte changed on disk refused (Adler-32) with HDF5's message
static void test_csr_chunks(void) {
  const char *name = tmp("csrc.h5");
  const int64_t big = 300003, small = 20003;  // 131072-element chunks: 2 whole + 37859
  fmbd_csr *A[3] = {NULL, NULL, NULL}, *S = NULL;
  fmbd_h5 *f = NULL;
  EXPECT(fmbd_h5_create(name, "fmbd-test", "1.0", &f) == FMBD_OK, "create");
  const char *path[3] = {"/mass", "/smooth", "/random"};
  uint64_t s = 7;
  for (int k = 0; k < 3; k++) {
    EXPECT(fmbd_csr_create(big, big, big, &A[k]) == FMBD_OK, "csr");
    if (!A[k]) return;
    for (int64_t i = 0; i <= big; i++) A[k]->indptr[i] = i;
    for (int64_t i = 0; i < big; i++) {
      A[k]->indices[i] = (i * 7919) % big;  // any column: one entry a row
      s = s * 6364136223846793005ULL + 1442695040888963407ULL;
      A[k]->data[i] = k == 0   ? (double)(i % 7 == 0 ? 3 : 1) * 0.1  // whole doubles repeated
                      : k == 1 ? 1.0 + (double)i * 0x1p-20 +
                                     (double)(s >> 40) * 0x1p-52          // 1.5:1, shuffled 2.6:1
                               : (double)(s >> 11) / 9007199254740992.0;  // incompressible
    }
    EXPECT(fmbd_h5_write_csr(f, path[k], A[k]) == FMBD_OK, "write %s", path[k]);
  }
  EXPECT(fmbd_csr_create(small, small, small, &S) == FMBD_OK, "csr");
  for (int64_t i = 0; i <= small; i++) S->indptr[i] = i;
  for (int64_t i = 0; i < small; i++) S->indices[i] = small - 1 - i, S->data[i] = 0.5 * (i % 3);
  EXPECT(fmbd_h5_write_csr(f, "/small", S) == FMBD_OK, "write small");
  // a 2-D array in chunks of whole rows (43690 rows of 3: 2 whole chunks and 12623 rows)
  const int64_t nr = 100003;
  int64_t *rows = malloc((size_t)nr * 3 * sizeof *rows), rdims[2] = {nr, 3};
  for (int64_t q = 0; rows && q < nr * 3; q++) rows[q] = (q * 2654435761) % 1000003;
  EXPECT(rows && fmbd_h5_write_i64(f, "/rows", 2, rdims, rows) == FMBD_OK, "write rows");
  EXPECT(fmbd_h5_commit(&f, 0, 0) == FMBD_OK, "commit");
  hid_t fid = H5Fopen(name, H5F_ACC_RDONLY, H5P_DEFAULT);
  bool sh;
  unsigned lv;
  int nf;
  const int want_nf[3] = {1, 2, 0};
  const bool want_sh[3] = {false, true, false};
  char p[64];
  for (int k = 0; k < 3; k++) {
    snprintf(p, sizeof p, "%s/data", path[k]);
    filters(fid, p, &sh, &lv, &nf);
    EXPECT(nf == want_nf[k] && sh == want_sh[k], "%s: %d filters, shuffle %d", p, nf, sh);
  }
  filters(fid, "/mass/indices", &sh, &lv, &nf);
  EXPECT(nf == 2 && sh, "indices: %d filters, shuffle %d", nf, sh);
  filters(fid, "/rows", &sh, &lv, &nf);
  EXPECT(nf == 2 && sh, "rows: %d filters, shuffle %d", nf, sh);
  {
    hid_t d = H5Dopen2(fid, "/rows", H5P_DEFAULT), pl = H5Dget_create_plist(d);
    hsize_t cd[2] = {0, 0};
    EXPECT(H5Pget_chunk(pl, 2, cd) == 2 && cd[0] == 43690 && cd[1] == 3, "rows chunk %llu x %llu",
           (unsigned long long)cd[0], (unsigned long long)cd[1]);
    H5Pclose(pl);
    H5Dclose(d);
  }
  // the address of /mass/data's second chunk, for the corruption below
  haddr_t addr = HADDR_UNDEF;
  hsize_t csize = 0;
  {
    hid_t d = H5Dopen2(fid, "/mass/data", H5P_DEFAULT), sp = H5Dget_space(d);
    hsize_t off;
    unsigned mask;
    for (hsize_t c = 0; c < 3; c++) {
      if (H5Dget_chunk_info(d, sp, c, &off, &mask, &addr, &csize) >= 0 && off == 131072) break;
      addr = HADDR_UNDEF;
    }
    H5Sclose(sp);
    H5Dclose(d);
  }
  H5Fclose(fid);
  EXPECT(fmbd_h5_open(name, &f) == FMBD_OK, "open");
  for (int k = 0; k < 3; k++) {
    fmbd_csr *B = NULL;
    EXPECT(fmbd_h5_read_csr(f, path[k], &B) == FMBD_OK && B &&
               !memcmp(B->indptr, A[k]->indptr, (size_t)(big + 1) * sizeof(int64_t)) &&
               !memcmp(B->indices, A[k]->indices, (size_t)big * sizeof(int64_t)) &&
               !memcmp(B->data, A[k]->data, (size_t)big * sizeof(double)),
           "%s read back", path[k]);
    fmbd_csr_destroy(&B);
  }
  {
    fmbd_csr *B = NULL;
    EXPECT(fmbd_h5_read_csr(f, "/small", &B) == FMBD_OK && B &&
               !memcmp(B->indices, S->indices, (size_t)small * sizeof(int64_t)) &&
               !memcmp(B->data, S->data, (size_t)small * sizeof(double)),
           "small read back");
    fmbd_csr_destroy(&B);
  }
  {
    int64_t *back = NULL, bd[2] = {-1, -1};
    EXPECT(fmbd_h5_read_i64(f, "/rows", 2, bd, &back) == FMBD_OK && bd[0] == nr && bd[1] == 3 &&
               rows && !memcmp(back, rows, (size_t)nr * 3 * sizeof *rows),
           "rows read back");
    fmbd_free(back);
  }
  free(rows);
  fmbd_h5_close(&f);
  EXPECT(addr != HADDR_UNDEF && csize > 16, "chunk address");
  if (addr != HADDR_UNDEF && csize > 16) {
    int fd = open(name, O_RDWR);
    unsigned char byte = 0;
    off_t at = (off_t)(addr + csize / 2);
    EXPECT(fd >= 0 && pread(fd, &byte, 1, at) == 1, "read a byte");
    byte ^= 0x5a;
    EXPECT(pwrite(fd, &byte, 1, at) == 1, "change a byte");
    if (fd >= 0) close(fd);
    fmbd_csr *B = NULL;
    fmbd_err_clear();
    EXPECT(fmbd_h5_open_unhashed(name, &f) == FMBD_OK, "open");
    EXPECT(fmbd_h5_read_csr(f, "/mass", &B) == FMBD_ERR_FORMAT && !B, "corrupt chunk read");
    expect_ctx(name, "/mass/data", "corrupt chunk");
    EXPECT(strstr(fmbd_err_get()->msg, "cannot read dataset") != NULL, "msg %s",
           fmbd_err_get()->msg);
    fmbd_h5_close(&f);
  }
  for (int k = 0; k < 3; k++) fmbd_csr_destroy(&A[k]);
  fmbd_csr_destroy(&S);
}

int main(void) {
  const char *root = getenv("ROOT"), *build = getenv("BUILD");
  snprintf(g_dir, sizeof g_dir, "%s/%s/test-tmp/t110-h5", root ? root : ".",
           build ? build : "build");
  char cmd[2200];
  snprintf(cmd, sizeof cmd, "rm -rf '%s' && mkdir -p '%s'", g_dir, g_dir);
  if (system(cmd) != 0) return 1;
  fmbd_h5_debug(false);
  test_dense();
  test_cm();
  test_csr();
  test_csr_filters();
  test_csr_chunks();
  test_attrs();
  test_open_errors();
  test_atomic();
  test_copy();
  test_countdown();
  TEST_EXIT();
}
