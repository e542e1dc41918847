// common/fmbd_runfile.c: the run file (format fmbd-run): buffered series, statistics,
// provenance, the valid prefix of an interrupted run, comparison with a reference run
// SPDX-License-Identifier: MIT
#include "fmbd_runfile.h"

#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_cli.h"
#include "fmbd_err.h"
#include "fmbd_log.h"
#include "fmbd_svg.h"

enum { BLOCK_ROWS = 256 };  // rows buffered per series before an append

// A growable array of doubles (the rows kept for a comparison or a plot).
typedef struct hist {
  double *v;
  int64_t n, cap;
} hist;

static int hist_push(hist *h, const double *x, int k) {
  if (h->n + k > h->cap) {
    int64_t cap = h->cap ? 2 * h->cap : 4096;
    while (cap < h->n + k) cap *= 2;
    double *p = fmbd_realloc(h->v, sizeof(double) * (size_t)cap);
    if (!p) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    h->v = p;
    h->cap = cap;
  }
  memcpy(h->v + h->n, x, sizeof(double) * (size_t)k);
  h->n += k;
  return FMBD_OK;
}

typedef struct series {
  char *path, *unit;
  fmbd_h5_series *s;
  int ncols;  // 0: scalar series
  int width;  // values per row (ncols, or 1)
  unsigned flags;
  int64_t rows;  // rows put
  int nbuf;      // rows buffered
  double *buf;
  hist h;  // kept rows (keep_history and FMBD_RUNFILE_COMPARED)
} series;

struct fmbd_runfile {
  fmbd_h5 *f;
  char *name;
  bool keep, finished;
  int n, cap;
  series *ser;  // ser[0] is /time
  int64_t rows;
  fmbd_runfile_stats_fn stats_fn;
  void *stats_user;
  double t0_wall, t0_cpu;  // start of the time integration (0: not started)
};

static int series_flush(series *c) {
  if (!c->s || !c->nbuf) return FMBD_OK;
  int rc = fmbd_h5_series_append(c->s, c->nbuf, c->buf);
  c->nbuf = 0;
  return rc;
}

static void series_free(series *c) {
  fmbd_h5_series_close(&c->s);
  fmbd_free(c->buf);
  fmbd_free(c->h.v);
  fmbd_free(c->path);
  fmbd_free(c->unit);
  memset(c, 0, sizeof *c);
}

fmbd_h5 *fmbd_runfile_h5(fmbd_runfile *rf) {
  return rf->f;
}
const char *fmbd_runfile_name(const fmbd_runfile *rf) {
  return rf->name;
}
int64_t fmbd_runfile_rows(const fmbd_runfile *rf) {
  return rf->rows;
}
void fmbd_runfile_set_stats(fmbd_runfile *rf, fmbd_runfile_stats_fn fn, void *user) {
  rf->stats_fn = fn;
  rf->stats_user = user;
}
void fmbd_runfile_start_clock(fmbd_runfile *rf) {
  rf->t0_wall = fmbd_wall_s();
  rf->t0_cpu = fmbd_cpu_s();
}

static int write_stats(fmbd_runfile *rf, bool complete) {
  fmbd_runfile_stats st = {0};
  if (rf->stats_fn) rf->stats_fn(rf->stats_user, &st);
  fmbd_h5 *f = rf->f;
  FMBD_CALL(fmbd_h5_make_group(f, "/stats"));
  int64_t iv[] = {st.steps,         st.rejected_steps,      st.newton_iterations,
                  complete ? 1 : 0, st.factorizations,      st.coordinates,
                  st.equations,     st.redundant_equations, rf->rows};
  const char *in[] = {"steps",     "rejected_steps",      "newton_iterations",
                      "complete",  "factorizations",      "coordinates",
                      "equations", "redundant_equations", "output_rows"};
  for (size_t i = 0; i < sizeof iv / sizeof iv[0]; i++)
    FMBD_CALL(fmbd_h5_write_attr_i64(f, "/stats", in[i], 1, &iv[i]));
  double rw = rf->t0_wall > 0 ? fmbd_wall_s() - rf->t0_wall : 0,
         rc = rf->t0_wall > 0 ? fmbd_cpu_s() - rf->t0_cpu : 0;
  double dv[] = {fmbd_cli_wall_s(), fmbd_cli_cpu_s(), st.t_reached, st.last_step_s, rw, rc,
                 st.factor_cpu_s,   st.solve_cpu_s,   st.eval_cpu_s};
  const char *dn[] = {"wall_time_s",       "cpu_time_s",       "t_reached",
                      "last_step_s",       "run_wall_time_s",  "run_cpu_time_s",
                      "factor_cpu_time_s", "solve_cpu_time_s", "eval_cpu_time_s"};
  for (size_t i = 0; i < sizeof dv / sizeof dv[0]; i++)
    FMBD_CALL(fmbd_h5_write_attr_f64(f, "/stats", dn[i], 1, &dv[i]));
  return FMBD_OK;
}

int fmbd_runfile_series(fmbd_runfile *rf, const char *path, int ncols, const char *unit,
                        unsigned flags, int *id) {
  FMBD_CHECK(rf->rows == 0, FMBD_ERR_VALUE, "%s: series declared after the first row", path);
  FMBD_CHECK(ncols >= 0, FMBD_ERR_VALUE, "%s: %d columns", path, ncols);
  if (rf->n == rf->cap) {
    int cap = rf->cap ? 2 * rf->cap : 16;
    series *p = fmbd_realloc(rf->ser, sizeof(series) * (size_t)cap);
    if (!p) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
    rf->ser = p;
    rf->cap = cap;
  }
  series *c = &rf->ser[rf->n];
  memset(c, 0, sizeof *c);
  c->ncols = ncols;
  c->width = ncols ? ncols : 1;
  c->flags = flags;
  c->path = fmbd_strdup(path);
  c->unit = fmbd_strdup(unit ? unit : "");
  c->buf = fmbd_malloc(sizeof(double) * (size_t)(BLOCK_ROWS * c->width));
  rf->n++;  // counted now: released with the others whatever happens below
  if (!c->path || !c->unit || !c->buf) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  FMBD_CALL(fmbd_h5_series_create(rf->f, path, ncols, &c->s));
  *id = rf->n - 1;
  return FMBD_OK;
}

int fmbd_runfile_create(const char *name, bool keep_history, fmbd_runfile **out) {
  int rc = FMBD_OK;
  *out = NULL;
  fmbd_runfile *rf = fmbd_calloc(1, sizeof *rf);
  FMBD_CHECK(rf, FMBD_ERR_NOMEM, "out of memory");
  rf->keep = keep_history;
  FMBD_GALLOC(rf->name = fmbd_strdup(name));
  FMBD_GCALL(fmbd_h5_create(name, FMBD_RUN_FORMAT, FMBD_RUN_FORMAT_VERSION, &rf->f));
  int tid;
  FMBD_GCALL(fmbd_runfile_series(rf, "/time", 0, "s", FMBD_RUNFILE_COMPARED, &tid));
  FMBD_GCALL(write_stats(rf, false));
  *out = rf;
  return FMBD_OK;
done:
  fmbd_runfile_close(&rf);
  return rc;
}

int fmbd_runfile_scene(fmbd_runfile *rf, const char *file, const char *title, const char *text,
                       double t_end) {
  fmbd_h5 *f = rf->f;
  if (strcmp(file, "-")) FMBD_CALL(fmbd_h5_add_input(f, file, NULL));
  FMBD_CALL(fmbd_h5_make_group(f, "/scene"));
  FMBD_CALL(fmbd_h5_write_attr_str(f, "/scene", "file", file));
  if (title) FMBD_CALL(fmbd_h5_write_attr_str(f, "/scene", "title", title));
  FMBD_CALL(fmbd_h5_write_attr_str(f, "/scene", "text", text ? text : ""));
  FMBD_CALL(fmbd_h5_write_attr_f64(f, "/scene", "t_end", 1, &t_end));
  return FMBD_OK;
}

static int flush_series(fmbd_runfile *rf) {
  for (int i = 0; i < rf->n; i++) FMBD_CALL(series_flush(&rf->ser[i]));
  return FMBD_OK;
}

// Every series has the same rows now: when due, put them and /stats on disk together, so that
// a run killed at any moment (SIGKILL included) leaves a .part whose series are of equal length
// and whose /stats describe them (fmbd_h5_series_append holds the metadata until a flush)
static int flush_block(fmbd_runfile *rf) {
  FMBD_CALL(flush_series(rf));
  if (!fmbd_h5_flush_due(rf->f)) return FMBD_OK;
  FMBD_CALL(write_stats(rf, false));
  return fmbd_h5_flush(rf->f);
}

int fmbd_runfile_put(fmbd_runfile *rf, int id, const double *values) {
  FMBD_CHECK(id >= 0 && id < rf->n, FMBD_ERR_VALUE, "no series %d", id);
  series *c = &rf->ser[id];
  FMBD_CHECK(c->rows < rf->rows, FMBD_ERR_VALUE, "%s: two values in row %lld", c->path,
             (long long)rf->rows - 1);
  memcpy(c->buf + (size_t)c->nbuf * (size_t)c->width, values, sizeof(double) * (size_t)c->width);
  c->nbuf++;
  c->rows++;
  if (rf->keep && (c->flags & FMBD_RUNFILE_COMPARED)) FMBD_CALL(hist_push(&c->h, values, c->width));
  return FMBD_OK;
}

int fmbd_runfile_row(fmbd_runfile *rf, double t) {
  for (int i = 1; i < rf->n; i++) {
    FMBD_CHECK(rf->ser[i].rows == rf->rows, FMBD_ERR_VALUE, "%s: no value in row %lld",
               rf->ser[i].path, (long long)rf->rows - 1);
  }
  if (rf->ser[0].nbuf == BLOCK_ROWS) FMBD_CALL(flush_block(rf));
  rf->rows++;
  return fmbd_runfile_put(rf, 0, &t);
}

int fmbd_runfile_flush(fmbd_runfile *rf) {
  FMBD_CALL(flush_series(rf));
  FMBD_CALL(write_stats(rf, false));
  return fmbd_h5_flush(rf->f);
}

void fmbd_runfile_history(const fmbd_runfile *rf, int id, int64_t *n, const double **v) {
  if (id < 0) id = 0;
  *n = 0;
  *v = NULL;
  if (id >= rf->n) return;
  const series *c = &rf->ser[id];
  *n = c->h.n / c->width;
  *v = c->h.v;
}

int fmbd_runfile_finish(fmbd_runfile *rf) {
  for (int i = 1; i < rf->n; i++) {
    FMBD_CHECK(rf->ser[i].rows == rf->rows, FMBD_ERR_VALUE, "%s: no value in row %lld",
               rf->ser[i].path, (long long)rf->rows - 1);
  }
  FMBD_CALL(fmbd_runfile_flush(rf));
  FMBD_CALL(write_stats(rf, true));
  rf->finished = true;
  return FMBD_OK;
}

static void free_all(fmbd_runfile *rf) {
  for (int i = 0; i < rf->n; i++) series_free(&rf->ser[i]);
  fmbd_free(rf->ser);
  fmbd_free(rf->name);
  fmbd_free(rf);
}

int fmbd_runfile_commit(fmbd_runfile **rfp) {
  fmbd_runfile *rf = *rfp;
  int rc = FMBD_OK;
  if (!rf->finished) FMBD_GCALL(fmbd_runfile_finish(rf));
  for (int i = 0; i < rf->n; i++) fmbd_h5_series_close(&rf->ser[i].s);
  rc = fmbd_h5_commit(&rf->f, fmbd_cli_wall_s(), fmbd_cli_cpu_s());
done:
  for (int i = 0; i < rf->n; i++) fmbd_h5_series_close(&rf->ser[i].s);  // before the file
  fmbd_h5_close(&rf->f);
  free_all(rf);
  *rfp = NULL;
  return rc;
}

void fmbd_runfile_abandon(fmbd_runfile **rfp, double t) {
  fmbd_runfile *rf = *rfp;
  if (!rf) return;
  if (strcmp(rf->name, "-")) {
    // the rows computed so far (each series has the same number), marked incomplete
    for (int i = 1; i < rf->n; i++) {  // a row started but not filled: drop it everywhere
      series *c = &rf->ser[i];
      if (c->rows < rf->rows) {
        for (int k = 0; k < rf->n; k++) {
          series *d = &rf->ser[k];
          if (d->rows == rf->rows && d->nbuf > 0) {
            d->nbuf--;
            d->rows--;
          }
        }
        rf->rows--;
        break;
      }
    }
    int keep_rc = fmbd_runfile_flush(rf);
    (void)keep_rc;  // what could be written is written; the run's own error is reported
    for (int i = 0; i < rf->n; i++) fmbd_h5_series_close(&rf->ser[i].s);
    fmbd_h5_abandon(&rf->f);
    fmbd_log(FMBD_LOG_WARN,
             "the run stopped at t = %g s; its valid prefix is kept in %s.part (/stats complete = "
             "0)",
             t, rf->name);
  }
  fmbd_runfile_close(rfp);
}

void fmbd_runfile_close(fmbd_runfile **rfp) {
  fmbd_runfile *rf = *rfp;
  if (!rf) return;
  for (int i = 0; i < rf->n; i++) fmbd_h5_series_close(&rf->ser[i].s);
  fmbd_h5_close(&rf->f);
  free_all(rf);
  *rfp = NULL;
}

// --- signals ---------------------------------------------------------------------------------
static volatile sig_atomic_t g_signal = 0;
static void on_signal(int sig) {
  g_signal = sig;
}
void fmbd_runfile_catch_signals(void) {
  fmbd_cli_on_signals(on_signal);
}
int fmbd_runfile_signal(void) {
  return (int)g_signal;
}

// --- the reference ---------------------------------------------------------------------------
// Check an open reference; its /time (nr values) is returned in *rt when rt is not NULL.
static int check_reference(fmbd_h5 *g, const char *ref_name, double **rt, int64_t *nr) {
  int rc = FMBD_OK;
  double *t = NULL;
  FMBD_GCALL(fmbd_h5_check_format(g, FMBD_RUN_FORMAT, FMBD_RUN_FORMAT_MAJOR));
  int64_t complete = 0;
  fmbd_err_context(ref_name, "/stats");
  FMBD_GCALL(fmbd_h5_read_attr_i64(g, "/stats", "complete", 1, &complete));
  FMBD_GCHECK(complete == 1, FMBD_ERR_FORMAT,
              "attribute complete = %lld: the reference is an "
              "interrupted run (a valid prefix only); give a complete run",
              (long long)complete);
  int64_t dt[1] = {-1};
  FMBD_GCALL(fmbd_h5_read_f64(g, "/time", 1, dt, &t));
  fmbd_err_context(ref_name, "/time");
  FMBD_GCHECK(dt[0] >= 2, FMBD_ERR_FORMAT, "the reference run has %lld instants (2 at least)",
              (long long)dt[0]);
  for (int64_t i = 0; i < dt[0]; i++) {
    FMBD_GCHECK(isfinite(t[i]), FMBD_ERR_FORMAT, "instant %lld is not finite", (long long)i);
    FMBD_GCHECK(i == 0 || t[i] > t[i - 1], FMBD_ERR_FORMAT,
                "not strictly increasing at "
                "instant %lld (%.17g after %.17g)",
                (long long)i, t[i], t[i - 1]);
  }
  fmbd_err_context("", "");
  *nr = dt[0];
  if (rt) {
    *rt = t;
    t = NULL;
  }
done:
  fmbd_free(t);
  return rc;
}

int fmbd_runfile_check_reference(const char *name) {
  fmbd_h5 *g = NULL;
  int64_t nr = 0;
  int rc = fmbd_h5_open(name, &g);
  if (!rc) rc = check_reference(g, name, NULL, &nr);
  fmbd_h5_close(&g);
  return rc;
}

// Linear interpolation of a (n, w) history at time t (t within [tt[0], tt[n-1]]).
static void interp(const double *tt, const double *v, int64_t n, int w, double t, double *out) {
  int64_t lo = 0, hi = n - 1;
  while (hi - lo > 1) {
    int64_t mid = (lo + hi) / 2;
    if (tt[mid] <= t) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  double a = tt[hi] > tt[lo] ? (t - tt[lo]) / (tt[hi] - tt[lo]) : 0;
  if (a < 0) a = 0;
  if (a > 1) a = 1;
  for (int i = 0; i < w; i++) out[i] = (1 - a) * v[lo * w + i] + a * v[hi * w + i];
}

// Splits "/outputs/NAME/QUANTITY" into NAME and QUANTITY; false for another path.
static bool output_parts(const char *path, char *name, size_t nn, char *q, size_t nq) {
  static const char pre[] = "/outputs/";
  if (strncmp(path, pre, sizeof pre - 1)) return false;
  const char *s = path + sizeof pre - 1, *slash = strrchr(s, '/');
  if (!slash || slash == s || (size_t)(slash - s) >= nn || strlen(slash + 1) >= nq) return false;
  memcpy(name, s, (size_t)(slash - s));
  name[slash - s] = '\0';
  strcpy(q, slash + 1);
  return true;
}

// The errors of one series against the reference's (nr rows of width w at rt, rv).
static void series_errors(const double *tt, const double *v, int64_t n, const double *rt,
                          const double *rv, int64_t nr, int w, double t0, double t1,
                          fmbd_runfile_error *e) {
  double sum = 0, sum_ref = 0, worst = 0, t_worst = NAN;
  int64_t k = 0;
  // this run's instants within the reference's span: a relative 1e-12 of the span lets the
  // last instants of two runs to the same t_end match although their sums of steps differ in
  // the last bits
  double slack = 1e-12 * fmax(1.0, fabs(rt[nr - 1]));
  for (int64_t i = 0; i < n; i++) {
    if (tt[i] < rt[0] - slack || tt[i] > rt[nr - 1] + slack) continue;
    if (!isnan(t0) && tt[i] < t0) continue;
    if (!isnan(t1) && tt[i] > t1) continue;
    double x[64];
    interp(rt, rv, nr, w, tt[i], x);
    double d2 = 0, r2 = 0;
    for (int a = 0; a < w; a++) {
      d2 += (v[w * i + a] - x[a]) * (v[w * i + a] - x[a]);
      r2 += x[a] * x[a];
    }
    sum += d2;
    sum_ref += r2;
    if (sqrt(d2) > worst || isnan(t_worst)) {
      worst = sqrt(d2);
      t_worst = tt[i];
    }
    k++;
  }
  e->instants = k;
  e->rms = k ? sqrt(sum / (double)k) : NAN;
  e->rms_ref = k ? sqrt(sum_ref / (double)k) : NAN;
  e->max = k ? worst : NAN;
  e->t_max = t_worst;
}

int fmbd_runfile_compare(fmbd_runfile *rf, const char *ref, double t0, double t1, int *nerr,
                         fmbd_runfile_error **errors) {
  int rc = FMBD_OK;
  fmbd_h5 *g = NULL;
  double *rt = NULL, *rv = NULL;
  fmbd_runfile_error *err = NULL;
  int ne = 0;
  int64_t nr = 0;
  if (nerr) *nerr = 0;
  if (errors) *errors = NULL;
  FMBD_CHECK(rf->keep, FMBD_ERR_VALUE,
             "%s: compared with a reference, but created without keep_history", rf->name);
  FMBD_GCALL(fmbd_h5_open(ref, &g));
  FMBD_GCALL(check_reference(g, ref, &rt, &nr));
  FMBD_GALLOC(err = fmbd_calloc((size_t)rf->n + 1, sizeof *err));
  fmbd_h5 *f = rf->f;
  FMBD_GCALL(fmbd_h5_make_group(f, "/reference"));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, "/reference", "file", ref));
  FMBD_GCALL(fmbd_h5_write_attr_str(f, "/reference", "sha256", fmbd_h5_sha256(g)));
  if (!isnan(t0) || !isnan(t1)) {
    double win[2] = {isnan(t0) ? -INFINITY : t0, isnan(t1) ? INFINITY : t1};
    FMBD_GCALL(fmbd_h5_write_attr_f64(f, "/reference", "window", 2, win));
  }
  FMBD_GCALL(fmbd_h5_add_input(f, ref, fmbd_h5_sha256(g)));
  const series *tc = &rf->ser[0];
  for (int id = 1; id < rf->n; id++) {
    const series *c = &rf->ser[id];
    fmbd_runfile_error *e = &err[ne];
    if (!(c->flags & FMBD_RUNFILE_COMPARED) || !c->h.n || c->width > 64) continue;
    if (!output_parts(c->path, e->name, sizeof e->name, e->quantity, sizeof e->quantity)) continue;
    if (!fmbd_h5_exists(g, c->path)) continue;
    int64_t dv[2] = {nr, c->ncols};
    fmbd_free(rv);
    rv = NULL;
    FMBD_GCALL(fmbd_h5_read_f64(g, c->path, c->ncols ? 2 : 1, dv, &rv));
    series_errors(tc->h.v, c->h.v, tc->h.n, rt, rv, nr, c->width, t0, t1, e);
    if (!e->instants) continue;
    e->unit = c->unit;
    char grp[512], an[128];
    snprintf(grp, sizeof grp, "/reference/%s", e->name);
    FMBD_GCALL(fmbd_h5_make_group(f, grp));
    const char *pre[] = {"rms", "max", "t_max", "rms_ref"};
    double val[] = {e->rms, e->max, e->t_max, e->rms_ref};
    for (int k = 0; k < 4; k++) {
      snprintf(an, sizeof an, "%s_%s", pre[k], e->quantity);
      FMBD_GCALL(fmbd_h5_write_attr_f64(f, grp, an, 1, &val[k]));
    }
    FMBD_GCALL(fmbd_h5_write_attr_i64(f, grp, "instants", 1, &e->instants));
    ne++;
  }
  if (!ne) {
    fmbd_log(FMBD_LOG_WARN, "%s: no output of this run has a counterpart in the reference", ref);
  } else {
    char win[96] = "";
    if (!isnan(t0) || !isnan(t1))
      snprintf(win, sizeof win, " in the window %g..%g s", isnan(t0) ? -INFINITY : t0,
               isnan(t1) ? INFINITY : t1);
    fmbd_log_summary("errors against %s%s:", ref, win);
    fmbd_log_summary("  %-12s %-18s %12s %12s %10s %12s %9s  %s", "output", "quantity", "RMS",
                     "largest", "at t (s)", "RMS of ref", "instants", "unit");
    for (int i = 0; i < ne; i++) {
      const fmbd_runfile_error *e = &err[i];
      fmbd_log_summary("  %-12s %-18s %12.4e %12.4e %10.4g %12.4e %9lld  %s", e->name, e->quantity,
                       e->rms, e->max, e->t_max, e->rms_ref, (long long)e->instants, e->unit);
    }
  }
  if (nerr) *nerr = ne;
  if (errors) {
    *errors = err;
    err = NULL;
  }
done:
  fmbd_free(err);
  fmbd_free(rt);
  fmbd_free(rv);
  fmbd_h5_close(&g);
  return rc;
}

// --- pictures --------------------------------------------------------------------------------
int fmbd_runfile_plot_position(const fmbd_runfile *rf, int id, const char *prefix, const char *name,
                               const char *title) {
  int rc = FMBD_OK;
  char path[1024], head[512];
  double *x = NULL, *y = NULL, *z = NULL;
  int64_t n = 0, nt = 0;
  const double *v = NULL, *tt = NULL;
  fmbd_runfile_history(rf, id, &n, &v);
  fmbd_runfile_history(rf, -1, &nt, &tt);
  if (!n || nt != n || rf->ser[id].width != 3) return FMBD_OK;
  FMBD_GALLOC(x = fmbd_malloc(sizeof(double) * (size_t)n));
  FMBD_GALLOC(y = fmbd_malloc(sizeof(double) * (size_t)n));
  FMBD_GALLOC(z = fmbd_malloc(sizeof(double) * (size_t)n));
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int64_t i = 0; i < n; i++) {
    x[i] = v[3 * i];
    y[i] = v[3 * i + 1];
    z[i] = v[3 * i + 2];
    for (int a = 0; a < 3; a++) {
      lo[a] = fmin(lo[a], v[3 * i + a]);
      hi[a] = fmax(hi[a], v[3 * i + a]);
    }
  }
  // components against time
  fmbd_svg_plot p;
  fmbd_svg_plot_defaults(&p);
  snprintf(head, sizeof head, "%s: position of '%s'", title, name);
  p.title = head;
  p.xlabel = "time (s)";
  p.ylabel = "position (m)";
  fmbd_svg_series ser[3] = {{.label = "x", .n = n, .x = tt, .y = x},
                            {.label = "y", .n = n, .x = tt, .y = y},
                            {.label = "z", .n = n, .x = tt, .y = z}};
  snprintf(path, sizeof path, "%s%s-position.svg", prefix, name);
  FMBD_GCALL(fmbd_svg_write(path, &p, 3, ser));
  // the path in the plane of the two largest ranges
  int a = 0, b = 1, c = 2;
  double rg[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
  if (rg[2] > rg[a] && rg[2] > rg[b]) {
    if (rg[0] < rg[1])
      a = 2;
    else
      b = 2;
  }
  if (a > b) {
    c = a;
    a = b;
    b = c;
  }
  const double *comp[3] = {x, y, z};
  static const char *const axn[3] = {"x (m)", "y (m)", "z (m)"};
  fmbd_svg_plot_defaults(&p);
  snprintf(head, sizeof head, "%s: trajectory of '%s'", title, name);
  p.title = head;
  p.xlabel = axn[a];
  p.ylabel = axn[b];
  p.legend = 0;
  fmbd_svg_series tr = {.label = name, .n = n, .x = comp[a], .y = comp[b]};
  snprintf(path, sizeof path, "%s%s-trajectory.svg", prefix, name);
  FMBD_GCALL(fmbd_svg_write(path, &p, 1, &tr));
done:
  fmbd_free(x);
  fmbd_free(y);
  fmbd_free(z);
  return rc;
}
