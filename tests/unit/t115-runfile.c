// tests/unit/t115-runfile.c: the run-file writer as a new program would use it: series across
// block boundaries, the row check, /stats, commit, the valid prefix of an abandoned run, a dropped
// file, and the comparison with a reference whose error is known exactly
// SPDX-License-Identifier: MIT
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "check.h"
#include "fmbd.h"
#include "fmbd_runfile.h"

static char g_dir[1024];

static const char *tmp(const char *name) {
  static char buf[4][1200];
  static int k = 0;
  k = (k + 1) % 4;
  snprintf(buf[k], sizeof buf[k], "%s/%s", g_dir, name);
  return buf[k];
}

static bool exists(const char *p) {
  struct stat st;
  return stat(p, &st) == 0;
}

static void stats(void *user, fmbd_runfile_stats *st) {
  st->steps = *(int64_t *)user;
  st->t_reached = 1.5;
}

// A run of n rows: position (t, 2t, 3t) + offset, energy t^2; 0 on success.
static int write_run(const char *name, int64_t n, double offset, bool keep, fmbd_runfile **out) {
  static int64_t steps = 7;
  int pos, en;
  fmbd_runfile *rf = NULL;
  int rc = fmbd_runfile_create(name, keep, &rf);
  if (rc) return rc;
  fmbd_runfile_set_stats(rf, stats, &steps);
  rc = fmbd_runfile_series(rf, "/outputs/p/position", 3, "m", FMBD_RUNFILE_COMPARED, &pos);
  if (!rc) rc = fmbd_runfile_series(rf, "/energy/kinetic", 0, "J", 0, &en);
  for (int64_t i = 0; i < n && !rc; i++) {
    double t = 0.01 * (double)i, x[3] = {t + offset, 2 * t, 3 * t}, e = t * t;
    rc = fmbd_runfile_row(rf, t);
    if (!rc) rc = fmbd_runfile_put(rf, pos, x);
    if (!rc) rc = fmbd_runfile_put(rf, en, &e);
  }
  if (rc) {
    fmbd_runfile_close(&rf);
    return rc;
  }
  *out = rf;
  return FMBD_OK;
}

int main(void) {
  const char *root = getenv("ROOT"), *build = getenv("BUILD");
  snprintf(g_dir, sizeof g_dir, "%s/%s/test-tmp/t115-runfile", root ? root : ".",
           build ? build : "build");
  char cmd[2200];
  snprintf(cmd, sizeof cmd, "rm -rf '%s' && mkdir -p '%s'", g_dir, g_dir);
  if (system(cmd) != 0) return 1;
  fmbd_log_init("t115", FMBD_LOG_ERROR);
  fmbd_runfile *rf = NULL;

  // --- the reference: 600 rows (two block boundaries of 256), committed -----------------------
  EXPECT(write_run(tmp("ref.run.h5"), 600, 0.0, false, &rf) == FMBD_OK, "reference run");
  if (rf) EXPECT(fmbd_runfile_commit(&rf) == FMBD_OK && !rf, "commit");
  EXPECT(exists(tmp("ref.run.h5")) && !exists(tmp("ref.run.h5.part")), "committed: target only");
  EXPECT(fmbd_runfile_check_reference(tmp("ref.run.h5")) == FMBD_OK, "a usable reference");
  fmbd_h5 *f = NULL;
  if (fmbd_h5_open(tmp("ref.run.h5"), &f) == FMBD_OK) {
    int64_t dt[1] = {-1}, dp[2] = {-1, 3}, c = -1, steps = -1, rows = -1;
    double *t = NULL, *p = NULL;
    EXPECT(fmbd_h5_read_f64(f, "/time", 1, dt, &t) == FMBD_OK && dt[0] == 600, "/time rows");
    EXPECT(fmbd_h5_read_f64(f, "/outputs/p/position", 2, dp, &p) == FMBD_OK && dp[0] == 600,
           "position rows");
    bool same = t && p;
    for (int64_t i = 0; same && i < 600; i++) {
      double ti = 0.01 * (double)i;  // the values written, bit for bit
      same = t[i] == ti && p[3 * i] == ti && p[3 * i + 1] == 2 * ti && p[3 * i + 2] == 3 * ti;
    }
    EXPECT(same, "series values bit-identical");
    fmbd_h5_read_attr_i64(f, "/stats", "complete", 1, &c);
    fmbd_h5_read_attr_i64(f, "/stats", "steps", 1, &steps);
    fmbd_h5_read_attr_i64(f, "/stats", "output_rows", 1, &rows);
    EXPECT(c == 1 && steps == 7 && rows == 600, "/stats complete %lld steps %lld rows %lld",
           (long long)c, (long long)steps, (long long)rows);
    fmbd_free(t);
    fmbd_free(p);
    fmbd_h5_close(&f);
  }

  // --- a run 0.25 m off in x, compared: every error is 0.25 m (round-off of t + 0.25 - t) ------
  EXPECT(write_run(tmp("run.h5"), 301, 0.25, true, &rf) == FMBD_OK, "compared run");
  if (rf) {
    int n = 0;
    fmbd_runfile_error *e = NULL;
    EXPECT(fmbd_runfile_finish(rf) == FMBD_OK, "finish");
    fmbd_log_init(NULL, FMBD_LOG_ERROR);  // no table on the test's output
    EXPECT(fmbd_runfile_compare(rf, tmp("ref.run.h5"), NAN, NAN, &n, &e) == FMBD_OK && n == 1,
           "compare: %d series", n);
    if (n == 1) {
      // rms_ref: sqrt(mean |(t, 2t, 3t)|^2) = sqrt(14 mean t^2), t = 0.01 i, i = 0..300
      double m2 = 0;
      for (int i = 0; i <= 300; i++) m2 += 1e-4 * i * i / 301.0;
      EXPECT(!strcmp(e[0].name, "p") && !strcmp(e[0].quantity, "position") &&
                 e[0].instants == 301 && fabs(e[0].rms - 0.25) < 1e-14 &&
                 fabs(e[0].max - 0.25) < 1e-14 && fabs(e[0].rms_ref / sqrt(14 * m2) - 1) < 1e-13,
             "errors: %s/%s rms %.17g max %.17g rms_ref %.17g (%.17g) instants %lld", e[0].name,
             e[0].quantity, e[0].rms, e[0].max, e[0].rms_ref, sqrt(14 * m2),
             (long long)e[0].instants);
    }
    fmbd_free(e);
    e = NULL;
    EXPECT(fmbd_runfile_compare(rf, tmp("ref.run.h5"), 1.0, 2.0, &n, &e) == FMBD_OK && n == 1 &&
               e[0].instants == 101,
           "window 1..2 s: %lld instants", n ? (long long)e[0].instants : -1LL);
    fmbd_free(e);
    EXPECT(fmbd_runfile_commit(&rf) == FMBD_OK, "commit compared run");
  }

  // --- a missing value in a row is a program error; the file is dropped ------------------------
  if (fmbd_runfile_create(tmp("bad.run.h5"), false, &rf) == FMBD_OK) {
    int a, b;
    double x = 1;
    fmbd_runfile_series(rf, "/a", 0, "1", 0, &a);
    fmbd_runfile_series(rf, "/b", 0, "1", 0, &b);
    fmbd_runfile_row(rf, 0.0);
    fmbd_runfile_put(rf, a, &x);
    EXPECT(fmbd_runfile_row(rf, 0.1) == FMBD_ERR_VALUE, "row with /b missing");
    EXPECT(fmbd_runfile_put(rf, a, &x) == FMBD_ERR_VALUE, "two values of /a in one row");
    EXPECT(fmbd_runfile_series(rf, "/c", 0, "1", 0, &b) == FMBD_ERR_VALUE, "series after a row");
    fmbd_runfile_close(&rf);
    EXPECT(!rf && !exists(tmp("bad.run.h5")) && !exists(tmp("bad.run.h5.part")), "dropped");
  }

  // --- an abandoned run keeps its valid prefix, marked incomplete --------------------------------
  EXPECT(write_run(tmp("cut.run.h5"), 300, 0.0, false, &rf) == FMBD_OK, "cut run");
  if (rf) {
    fmbd_runfile_abandon(&rf, 2.99);
    EXPECT(!rf && !exists(tmp("cut.run.h5")) && exists(tmp("cut.run.h5.part")), "prefix kept");
    EXPECT(fmbd_runfile_check_reference(tmp("cut.run.h5.part")) == FMBD_ERR_FORMAT,
           "an interrupted run is no reference");
    if (fmbd_h5_open(tmp("cut.run.h5.part"), &f) == FMBD_OK) {
      int64_t dt[1] = {-1}, dp[2] = {-1, 3}, c = -1;
      double *t = NULL, *p = NULL;
      fmbd_h5_read_f64(f, "/time", 1, dt, &t);
      fmbd_h5_read_f64(f, "/outputs/p/position", 2, dp, &p);
      fmbd_h5_read_attr_i64(f, "/stats", "complete", 1, &c);
      EXPECT(dt[0] == 300 && dp[0] == 300 && c == 0, "prefix: %lld, %lld rows, complete %lld",
             (long long)dt[0], (long long)dp[0], (long long)c);
      fmbd_free(t);
      fmbd_free(p);
      fmbd_h5_close(&f);
    }
  }
  TEST_EXIT();
}
