// fmbd-run/main.c: simulate a scene of rigid and reduced flexible bodies (docs/SCENE.md)
// SPDX-License-Identifier: MIT
//
//   fmbd-run SCENE [-o RUN.h5] [--reference REF.run.h5] [--plot PREFIX] [-M] [-q] [-v]
//
// The run file is written as the run goes (extendible series, flushed), under RUN.h5.part;
// it is renamed to RUN.h5 only when the run is complete. An interrupted run (SIGINT,
// SIGTERM, SIGHUP, Newton failure) keeps RUN.h5.part, a valid prefix with /stats complete = 0, and
// exits 1: make never sees a target it could trust.
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_cli.h"
#include "fmbd_err.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"
#include "fmbd_scene.h"
#include "fmbd_scene_build.h"
#include "fmbd_svg.h"

static volatile sig_atomic_t g_signal = 0;
static void on_signal(int sig) {
  g_signal = sig;
}

// --- a buffered series: rows kept in memory, appended in blocks ---------------------------
enum { BLOCK_ROWS = 256 };
typedef struct col {
  fmbd_h5_series *s;
  int ncols;  // 0: scalar series
  int nbuf;
  double *buf;
} col;

static int col_open(fmbd_h5 *f, const char *path, int ncols, col *c) {
  c->ncols = ncols;
  c->nbuf = 0;
  c->buf = fmbd_malloc(sizeof(double) * (size_t)(BLOCK_ROWS * (ncols ? ncols : 1)));
  if (!c->buf) FMBD_FAIL(FMBD_ERR_NOMEM, "out of memory");
  return fmbd_h5_series_create(f, path, ncols, &c->s);
}
static int col_flush(col *c) {
  if (!c->s || !c->nbuf) return 0;
  int rc = fmbd_h5_series_append(c->s, c->nbuf, c->buf);
  c->nbuf = 0;
  return rc;
}
static int col_push(col *c, const double *row) {
  int w = c->ncols ? c->ncols : 1;
  memcpy(c->buf + (size_t)c->nbuf * (size_t)w, row, sizeof(double) * (size_t)w);
  if (++c->nbuf == BLOCK_ROWS) return col_flush(c);
  return 0;
}
static void col_close(col *c) {
  fmbd_h5_series_close(&c->s);
  fmbd_free(c->buf);
  c->buf = NULL;
}

// A growable history of doubles (for --plot and --reference).
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
  return 0;
}

// Per output: which series, and their history.
enum { Q_POS, Q_VEL, Q_ACC, Q_VM, Q_STRESS, Q_STRAIN, Q_VMSTRAIN, NQ };
static const char *const q_name[NQ] = {"position", "velocity", "acceleration",    "von_mises",
                                       "stress",   "strain",   "von_mises_strain"};
static const int q_cols[NQ] = {3, 3, 3, 0, 6, 6, 0};

typedef struct run {
  const fmbd_scene *s;
  fmbd_scene_model *m;
  fmbd_h5 *f;
  col time;
  col (*out)[NQ];  // noutputs x NQ (s == NULL: not asked)
  col energy[3];
  col momentum[2];
  col (*react)[2];  // reactions x {force, torque}
  hist t_hist;
  hist *h[3];      // per output: position, velocity, acceleration history (NULL arrays unused)
  bool keep_hist;  // --plot or --reference
  double last_progress_s;
  double t0_wall, t0_cpu;  // start of the integration (after reading and initialising)
  int64_t rows;
} run;

static int write_stats(run *r, bool complete) {
  fmbd_mbs_stats st;
  fmbd_mbs_get_stats(r->m->mbs, &st);
  fmbd_h5 *f = r->f;
  FMBD_CALL(fmbd_h5_make_group(f, "/stats"));
  int64_t iv[] = {st.steps,         st.rejected,       st.newton_iterations,
                  complete ? 1 : 0, st.factorizations, st.coordinates,
                  st.equations,     st.redundant,      r->rows};
  const char *in[] = {"steps",     "rejected_steps",      "newton_iterations",
                      "complete",  "factorizations",      "coordinates",
                      "equations", "redundant_equations", "output_rows"};
  for (size_t i = 0; i < sizeof iv / sizeof iv[0]; i++)
    FMBD_CALL(fmbd_h5_write_attr_i64(f, "/stats", in[i], 1, &iv[i]));
  double rw = r->t0_wall > 0 ? fmbd_wall_s() - r->t0_wall : 0,
         rc = r->t0_wall > 0 ? fmbd_cpu_s() - r->t0_cpu : 0;
  double dv[] = {fmbd_cli_wall_s(), fmbd_cli_cpu_s(), fmbd_mbs_time(r->m->mbs), st.h_last, rw, rc};
  const char *dn[] = {"wall_time_s", "cpu_time_s",      "t_reached",
                      "last_step_s", "run_wall_time_s", "run_cpu_time_s"};
  for (size_t i = 0; i < sizeof dv / sizeof dv[0]; i++)
    FMBD_CALL(fmbd_h5_write_attr_f64(f, "/stats", dn[i], 1, &dv[i]));
  return 0;
}

static int flush_all(run *r) {
  FMBD_CALL(col_flush(&r->time));
  for (int o = 0; o < r->s->noutputs; o++) {
    for (int q = 0; q < NQ; q++) FMBD_CALL(col_flush(&r->out[o][q]));
  }
  for (int e = 0; e < 3; e++) FMBD_CALL(col_flush(&r->energy[e]));
  for (int e = 0; e < 2; e++) FMBD_CALL(col_flush(&r->momentum[e]));
  for (int k = 0; k < r->s->nreactions; k++) {
    FMBD_CALL(col_flush(&r->react[k][0]));
    FMBD_CALL(col_flush(&r->react[k][1]));
  }
  FMBD_CALL(write_stats(r, false));
  return fmbd_h5_flush(r->f);
}

// One output row: time, the asked quantities, energies, reactions.
static int record(run *r) {
  const fmbd_scene *s = r->s;
  fmbd_mbs *mb = r->m->mbs;
  double t = fmbd_mbs_time(mb);
  FMBD_CALL(col_push(&r->time, &t));
  if (r->keep_hist) FMBD_CALL(hist_push(&r->t_hist, &t, 1));
  for (int o = 0; o < s->noutputs; o++) {
    unsigned qs = s->outputs[o].quantities;
    int pid = r->m->out_point[o];
    double v[3];
    if (qs & FMBD_OUT_POSITION) {
      fmbd_mbs_point_position(mb, pid, v);
      FMBD_CALL(col_push(&r->out[o][Q_POS], v));
      if (r->keep_hist) FMBD_CALL(hist_push(&r->h[0][o], v, 3));
    }
    if (qs & FMBD_OUT_VELOCITY) {
      fmbd_mbs_point_velocity(mb, pid, v);
      FMBD_CALL(col_push(&r->out[o][Q_VEL], v));
      if (r->keep_hist) FMBD_CALL(hist_push(&r->h[1][o], v, 3));
    }
    if (qs & FMBD_OUT_ACCELERATION) {
      fmbd_mbs_point_acceleration(mb, pid, v);
      FMBD_CALL(col_push(&r->out[o][Q_ACC], v));
      if (r->keep_hist) FMBD_CALL(hist_push(&r->h[2][o], v, 3));
    }
    if (qs & (FMBD_OUT_VON_MISES | FMBD_OUT_STRESS | FMBD_OUT_STRAIN)) {
      double sg[6], ep[6];
      FMBD_CALL(fmbd_scene_output_stress(r->m, o, sg));
      if (qs & FMBD_OUT_VON_MISES) {
        double vm = fmbd_von_mises(sg);
        FMBD_CALL(col_push(&r->out[o][Q_VM], &vm));
      }
      if (qs & FMBD_OUT_STRESS) FMBD_CALL(col_push(&r->out[o][Q_STRESS], sg));
      if (qs & FMBD_OUT_STRAIN) {
        int b = r->m->out_body[o];
        double ev = fmbd_scene_strain(r->m->E[b], r->m->nu[b], sg, ep);
        FMBD_CALL(col_push(&r->out[o][Q_STRAIN], ep));
        FMBD_CALL(col_push(&r->out[o][Q_VMSTRAIN], &ev));
      }
    }
  }
  if (s->energy) {
    double e[3];
    fmbd_mbs_energy(mb, &e[0], &e[1], &e[2]);
    for (int k = 0; k < 3; k++) FMBD_CALL(col_push(&r->energy[k], &e[k]));
  }
  if (s->momentum) {
    double L[3], H[3];
    fmbd_mbs_momentum(mb, L, H);
    FMBD_CALL(col_push(&r->momentum[0], L));
    FMBD_CALL(col_push(&r->momentum[1], H));
  }
  for (int k = 0; k < s->nreactions; k++) {
    double F[3], T[3];
    FMBD_CALL(fmbd_mbs_joint_reaction(mb, r->m->joint_id[s->reactions[k]], F, T));
    FMBD_CALL(col_push(&r->react[k][0], F));
    FMBD_CALL(col_push(&r->react[k][1], T));
  }
  r->rows++;
  return 0;
}

static int on_step(fmbd_mbs *mb, bool at_output, void *user) {
  run *r = user;
  if (at_output) {
    int rc = record(r);
    if (rc) return rc;
  }
  double now = fmbd_wall_s();
  if (fmbd_progress_enabled() && now - r->last_progress_s > 0.25) {
    fmbd_mbs_stats st;
    fmbd_mbs_get_stats(mb, &st);
    double t = fmbd_mbs_time(mb), el = now - r->t0_wall;
    fmbd_progress("t = %.4f s (%3.0f%%), h = %.2e s, %lld steps, %.0f steps/s, %.2fx real time", t,
                  100 * t / r->s->solver.t_end, st.h_last, (long long)st.steps,
                  el > 0 ? st.steps / el : 0, el > 0 ? t / el : 0);
    r->last_progress_s = now;
  }
  if (g_signal) return 2;  // stop: the caller reports the interruption
  return 0;
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

// RMS error of each point output against a reference run (docs/THEORY.md section 7, eq. [C17]),
// at this run's output instants within the reference's time span, the reference linearly
// interpolated there. Written to /reference and printed.
// A reference must be a complete run whose /time is finite and strictly increasing with two
// instants at least: an interrupted run (complete = 0), a constant or a non-monotone time
// would give errors against nothing or against the wrong instants. *rt (nr values) is returned
// when rt is not NULL.
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

static int compare_reference(run *r, const char *ref_name) {
  int rc = 0;
  fmbd_h5 *g = NULL;
  double *rt = NULL, *rv = NULL;
  char *fmt = NULL;
  int64_t nr = 0;
  FMBD_GCALL(fmbd_h5_open(ref_name, &g));
  FMBD_GCALL(check_reference(g, ref_name, &rt, &nr));
  FMBD_GCALL(fmbd_h5_make_group(r->f, "/reference"));
  FMBD_GCALL(fmbd_h5_write_attr_str(r->f, "/reference", "file", ref_name));
  FMBD_GCALL(fmbd_h5_write_attr_str(r->f, "/reference", "sha256", fmbd_h5_sha256(g)));
  FMBD_GCALL(fmbd_h5_add_input(r->f, ref_name, fmbd_h5_sha256(g)));
  int compared = 0;
  for (int o = 0; o < r->s->noutputs; o++) {
    const char *name = r->s->outputs[o].name;
    for (int q = 0; q < 3; q++) {
      char path[512];
      snprintf(path, sizeof path, "/outputs/%s/%s", name, q_name[q]);
      if (!r->h[q][o].n || !fmbd_h5_exists(g, path)) continue;
      int64_t dv[2] = {nr, 3};
      fmbd_free(rv);
      rv = NULL;
      FMBD_GCALL(fmbd_h5_read_f64(g, path, 2, dv, &rv));
      double sum = 0, worst = 0;
      int64_t n = 0;
      const double *tt = r->t_hist.v, *v = r->h[q][o].v;
      for (int64_t i = 0; i < r->t_hist.n; i++) {
        if (tt[i] < rt[0] - 1e-12 || tt[i] > rt[nr - 1] + 1e-12) continue;
        double x[3];
        interp(rt, rv, nr, 3, tt[i], x);
        double d2 = 0;
        for (int a = 0; a < 3; a++) d2 += (v[3 * i + a] - x[a]) * (v[3 * i + a] - x[a]);
        sum += d2;
        worst = fmax(worst, sqrt(d2));
        n++;
      }
      if (!n) continue;
      double rms = sqrt(sum / (double)n);
      char grp[512], an[64];
      snprintf(grp, sizeof grp, "/reference/%s", name);
      FMBD_GCALL(fmbd_h5_make_group(r->f, grp));
      snprintf(an, sizeof an, "rms_%s", q_name[q]);
      FMBD_GCALL(fmbd_h5_write_attr_f64(r->f, grp, an, 1, &rms));
      snprintf(an, sizeof an, "max_%s", q_name[q]);
      FMBD_GCALL(fmbd_h5_write_attr_f64(r->f, grp, an, 1, &worst));
      FMBD_GCALL(fmbd_h5_write_attr_i64(r->f, grp, "instants", 1, &n));
      static const char *const unit[3] = {"m", "m/s", "m/s^2"};
      fmbd_log_summary("%s: RMS %s error %.4e %s (max %.4e) against %s over %lld instants", name,
                       q_name[q], rms, unit[q], worst, ref_name, (long long)n);
      compared++;
    }
  }
  if (!compared)
    fmbd_log(FMBD_LOG_WARN, "%s: no output of this run has a counterpart in the reference",
             ref_name);
done:
  fmbd_free(fmt);
  fmbd_free(rt);
  fmbd_free(rv);
  fmbd_h5_close(&g);
  return rc;
}

static int write_plots(run *r, const char *prefix) {
  int rc = 0;
  char path[1024], title[512];
  double *x = NULL, *y = NULL, *z = NULL;
  for (int o = 0; o < r->s->noutputs; o++) {
    const hist *h = &r->h[0][o];
    int64_t n = h->n / 3;
    if (!n) continue;
    FMBD_GALLOC(x = fmbd_malloc(sizeof(double) * (size_t)n));
    FMBD_GALLOC(y = fmbd_malloc(sizeof(double) * (size_t)n));
    FMBD_GALLOC(z = fmbd_malloc(sizeof(double) * (size_t)n));
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int64_t i = 0; i < n; i++) {
      x[i] = h->v[3 * i];
      y[i] = h->v[3 * i + 1];
      z[i] = h->v[3 * i + 2];
      for (int a = 0; a < 3; a++) {
        lo[a] = fmin(lo[a], h->v[3 * i + a]);
        hi[a] = fmax(hi[a], h->v[3 * i + a]);
      }
    }
    const char *name = r->s->outputs[o].name;
    // components against time
    fmbd_svg_plot p;
    fmbd_svg_plot_defaults(&p);
    snprintf(title, sizeof title, "%s: position of '%s'", r->s->title ? r->s->title : r->s->file,
             name);
    p.title = title;
    p.xlabel = "time (s)";
    p.ylabel = "position (m)";
    fmbd_svg_series ser[3] = {{.label = "x", .n = n, .x = r->t_hist.v, .y = x},
                              {.label = "y", .n = n, .x = r->t_hist.v, .y = y},
                              {.label = "z", .n = n, .x = r->t_hist.v, .y = z}};
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
    snprintf(title, sizeof title, "%s: trajectory of '%s'", r->s->title ? r->s->title : r->s->file,
             name);
    p.title = title;
    p.xlabel = axn[a];
    p.ylabel = axn[b];
    p.legend = 0;
    fmbd_svg_series tr = {.label = name, .n = n, .x = comp[a], .y = comp[b]};
    snprintf(path, sizeof path, "%s%s-trajectory.svg", prefix, name);
    FMBD_GCALL(fmbd_svg_write(path, &p, 1, &tr));
    fmbd_free(x);
    fmbd_free(y);
    fmbd_free(z);
    x = y = z = NULL;
  }
done:
  fmbd_free(x);
  fmbd_free(y);
  fmbd_free(z);
  return rc;
}

static const char *usage_text =
    "Usage: fmbd-run SCENE [-o RUN.h5] [--reference REF.run.h5] [--plot PREFIX] [-M] [-q] [-v]\n"
    "Simulate the mechanism of a scene file (YAML, docs/SCENE.md): rigid and reduced flexible\n"
    "bodies (.rflex.h5, .cb.h5) in the floating frame of reference, joints, drivers, loads,\n"
    "gravity; index-3 generalized-alpha with step-size control. Writes the run file\n"
    "(format fmbd-run, docs/FORMAT.md) as the run goes.\n\n"
    "  -o, --output RUN.h5     the run file (default: SCENE with .run.h5, or standard output\n"
    "                          when it is not a terminal; '-' = standard output)\n"
    "      --reference REF     RMS error of every point output against the run file REF\n"
    "                          (docs/THEORY.md section 7), written to /reference and printed\n"
    "      --plot PREFIX       SVG plots PREFIX<output>-position.svg and -trajectory.svg\n"
    "      --t-end T           end the run at T seconds instead of the scene's t_end\n"
    "      --body-dir DIR      body files (and the fe/cb files of -M rules) in DIR instead of\n"
    "                          the scene's folder (the geometry stays beside the scene)\n"
    "  -M                      print the make rules of the files the scene needs and exit\n"
    "  -q, --quiet             errors only\n"
    "  -v, --verbose           progress and details (-vv: debug)\n"
    "  -h, --help              this help\n"
    "  -V, --version           the version\n\n"
    "An interrupted run (SIGINT, SIGTERM, SIGHUP, no Newton convergence at the smallest step) "
    "keeps\n"
    "its valid prefix in RUN.h5.part with /stats attribute complete = 0, and exits 1.\n\n";

int main(int argc, char **argv) {
  fmbd_cli_init("fmbd-run", argc, argv);
  int rc = 0, quiet = 0, verbose = 0;
  bool make_rules = false, interrupted = false;
  const char *opt_o = NULL, *ref = NULL, *plot = NULL, *body_dir = NULL;
  double t_end = 0;
  char *out_name = NULL, *rules = NULL;
  fmbd_scene *s = NULL;
  fmbd_scene_model *m = NULL;
  run r = {0};
  enum { OPT_OUTPUT = 1, OPT_REFERENCE, OPT_PLOT, OPT_T_END, OPT_BODY_DIR, OPT_RULES };
  static const fmbd_cli_option options[] = {{"--output", 'o', true, OPT_OUTPUT},
                                            {"--reference", 0, true, OPT_REFERENCE},
                                            {"--plot", 0, true, OPT_PLOT},
                                            {"--t-end", 0, true, OPT_T_END},
                                            {"--body-dir", 0, true, OPT_BODY_DIR},
                                            {NULL, 'M', false, OPT_RULES},
                                            {0}};
  const char *scene_file = NULL;
  fmbd_cli_args p;
  fmbd_cli_args_init(&p, argc, argv, options, usage_text);
  for (int id; (id = fmbd_cli_next(&p)) != FMBD_CLI_END;) {
    switch (id) {
      case FMBD_CLI_EXIT:
        return fmbd_cli_finish(p.status);
      case FMBD_CLI_ARG:
        if (scene_file) {
          rc = fmbd_cli_usage_error("one scene file, not '%s' and '%s'", scene_file, p.value);
          goto out;
        }
        scene_file = p.value;
        break;
      case OPT_OUTPUT:
        opt_o = p.value;
        break;
      case OPT_REFERENCE:
        ref = p.value;
        break;
      case OPT_PLOT:
        plot = p.value;
        break;
      case OPT_BODY_DIR:
        body_dir = p.value;
        break;
      case OPT_T_END:
        if (fmbd_cli_double(&p, 0, INFINITY, FMBD_CLI_OPEN_LO, &t_end)) return fmbd_cli_finish(2);
        break;
      case OPT_RULES:
        make_rules = true;
        break;
    }
  }
  quiet = p.quiet;
  verbose = p.verbose;
  fmbd_cli_set_verbosity(quiet, verbose);
  if (!scene_file) {
    rc = fmbd_cli_usage_error("no scene file given");
    goto out;
  }
  FMBD_GCALL(fmbd_scene_read_dir(scene_file, body_dir, &s));
  if (t_end > 0) s->solver.t_end = t_end;

  // --- -M: make rules --------------------------------------------------------------------
  static const char *const strip[] = {".yaml", ".yml", NULL};
  if (make_rules) {
    if (opt_o) {
      FMBD_GALLOC(out_name = fmbd_strdup(opt_o));
    } else {
      // the derived name even when standard output is a pipe: the rules go there
      size_t n = strlen(scene_file), cut = n;
      for (int i = 0; strip[i]; i++) {
        size_t k = strlen(strip[i]);
        if (n > k && !strcmp(scene_file + n - k, strip[i])) cut = n - k;
      }
      FMBD_GALLOC(out_name = fmbd_malloc(cut + 8));
      memcpy(out_name, scene_file, cut);
      strcpy(out_name + cut, ".run.h5");
    }
    FMBD_GCALL(fmbd_scene_make_rules(s, out_name, &rules));
    fputs(rules, stdout);
    goto done;
  }
  FMBD_GCALL(fmbd_cli_output_name(scene_file, opt_o, strip, ".run.h5", &out_name));
  FMBD_GCALL(fmbd_cli_check_not_input(out_name, ref));

  // --- the reference run, checked before the work ------------------------------------------
  if (ref) {
    fmbd_h5 *g = NULL;
    int64_t nr = 0;
    rc = fmbd_h5_open(ref, &g);
    if (!rc) rc = check_reference(g, ref, NULL, &nr);
    fmbd_h5_close(&g);
    if (rc) goto done;
  }

  // --- runaway runs: say so before the work (a 1e-12 s step to 1e3 s is 1e15 steps) ------------
  {
    double steps =
        s->solver.fixed ? s->solver.t_end / s->solver.step : s->solver.t_end / s->solver.max_step;
    double rows = s->solver.output_every > 0 ? s->solver.t_end / s->solver.output_every : steps;
    if (steps > 1e8) {
      fmbd_log(FMBD_LOG_WARN, "%s: %s %.3g steps (t_end %g s, %s %g s): this run may take days",
               scene_file, s->solver.fixed ? "fixed step:" : "at least", steps, s->solver.t_end,
               s->solver.fixed ? "step" : "max_step",
               s->solver.fixed ? s->solver.step : s->solver.max_step);
    }
    if (rows > 1e7 && s->noutputs > 0) {
      fmbd_log(FMBD_LOG_WARN,
               "%s: about %.3g output rows (t_end %g s, every %g s): the run file may be "
               "very large; set outputs.every",
               scene_file, rows, s->solver.t_end, s->solver.output_every);
    }
  }

  // --- build and initialise -----------------------------------------------------------------
  FMBD_GCALL(fmbd_scene_build(s, &m));
  rc = fmbd_mbs_init(m->mbs, &s->solver);
  if (rc) {
    fmbd_err_context(scene_file, "");  // the message names joint/body; the file is the scene
    goto done;
  }
  {
    fmbd_mbs_stats st;
    fmbd_mbs_get_stats(m->mbs, &st);
    fmbd_log(FMBD_LOG_INFO,
             "%s: %d bodies, %lld coordinates, %lld constraint equations (%lld redundant removed)",
             scene_file, s->nbodies, (long long)st.coordinates, (long long)st.equations,
             (long long)st.redundant);
  }

  // --- the run file -------------------------------------------------------------------------
  for (int i = 0; i < m->ninputs; i++)
    FMBD_GCALL(fmbd_cli_check_not_input(out_name, m->input_name[i]));
  r.s = s;
  r.m = m;
  r.keep_hist = plot || ref;
  FMBD_GCALL(fmbd_h5_create(out_name, FMBD_RUN_FORMAT, FMBD_RUN_FORMAT_VERSION, &r.f));
  if (strcmp(scene_file, "-")) FMBD_GCALL(fmbd_h5_add_input(r.f, scene_file, NULL));
  for (int i = 0; i < m->ninputs; i++)
    FMBD_GCALL(fmbd_h5_add_input(r.f, m->input_name[i], m->input_sha[i]));
  FMBD_GCALL(fmbd_h5_make_group(r.f, "/scene"));
  FMBD_GCALL(fmbd_h5_write_attr_str(r.f, "/scene", "file", scene_file));
  if (s->title) FMBD_GCALL(fmbd_h5_write_attr_str(r.f, "/scene", "title", s->title));
  FMBD_GCALL(fmbd_h5_write_attr_str(r.f, "/scene", "text", s->text));
  FMBD_GCALL(fmbd_h5_write_attr_f64(r.f, "/scene", "t_end", 1, &s->solver.t_end));
  FMBD_GCALL(col_open(r.f, "/time", 0, &r.time));
  FMBD_GALLOC(r.out = fmbd_calloc((size_t)s->noutputs + 1, sizeof *r.out));
  for (int k = 0; k < 3; k++)
    FMBD_GALLOC(r.h[k] = fmbd_calloc((size_t)s->noutputs + 1, sizeof(hist)));
  for (int o = 0; o < s->noutputs; o++) {
    const fmbd_scene_output *op = &s->outputs[o];
    char path[600];
    snprintf(path, sizeof path, "/outputs/%s", op->name);
    FMBD_GCALL(fmbd_h5_make_group(r.f, path));
    FMBD_GCALL(fmbd_h5_write_attr_str(r.f, path, "body", s->bodies[op->body].name));
    FMBD_GCALL(fmbd_h5_write_attr_i64(r.f, path, "node", 1, &m->out_node[o]));
    for (int q = 0; q < NQ; q++) {
      unsigned bit = q == Q_VMSTRAIN ? FMBD_OUT_STRAIN : 1u << q;
      if (!(op->quantities & bit)) continue;
      snprintf(path, sizeof path, "/outputs/%s/%s", op->name, q_name[q]);
      FMBD_GCALL(col_open(r.f, path, q_cols[q], &r.out[o][q]));
    }
  }
  if (s->energy) {
    static const char *const en[3] = {"/energy/kinetic", "/energy/potential", "/energy/strain"};
    for (int k = 0; k < 3; k++) FMBD_GCALL(col_open(r.f, en[k], 0, &r.energy[k]));
  }
  if (s->momentum) {
    FMBD_GCALL(col_open(r.f, "/momentum/linear", 3, &r.momentum[0]));
    FMBD_GCALL(col_open(r.f, "/momentum/angular", 3, &r.momentum[1]));
  }
  FMBD_GALLOC(r.react = fmbd_calloc((size_t)s->nreactions + 1, sizeof *r.react));
  for (int k = 0; k < s->nreactions; k++) {
    char path[600];
    const char *jn = s->joints[s->reactions[k]].name;
    snprintf(path, sizeof path, "/reactions/%s/force", jn);
    FMBD_GCALL(col_open(r.f, path, 3, &r.react[k][0]));
    snprintf(path, sizeof path, "/reactions/%s/torque", jn);
    FMBD_GCALL(col_open(r.f, path, 3, &r.react[k][1]));
  }
  FMBD_GCALL(write_stats(&r, false));

  // --- run ------------------------------------------------------------------------------------
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
  sigaction(SIGHUP, &sa, NULL);
  r.t0_wall = fmbd_wall_s();
  r.t0_cpu = fmbd_cpu_s();
  FMBD_GCALL(record(&r));  // the initial (consistent) state
  rc = fmbd_mbs_run(m->mbs, on_step, &r);
  fmbd_progress(NULL);
  if (rc == 2 && g_signal) {
    interrupted = true;
    fmbd_err_context(out_name, "");
    fmbd_err_set(FMBD_ERR_IO, __FILE__, __LINE__, __func__, "interrupted by signal %d at t = %g s",
                 (int)g_signal, fmbd_mbs_time(m->mbs));
    rc = FMBD_ERR_IO;
  } else if (rc == FMBD_ERR_CONVERGE || rc == FMBD_ERR_SINGULAR) {
    interrupted = true;  // a failure on the way: keep the prefix computed so far
    fmbd_err_context(scene_file, "");
  }
  if (rc) goto done;
  FMBD_GCALL(flush_all(&r));
  FMBD_GCALL(write_stats(&r, true));
  if (ref) FMBD_GCALL(compare_reference(&r, ref));
  if (plot) FMBD_GCALL(write_plots(&r, plot));
  {
    fmbd_mbs_stats st;
    fmbd_mbs_get_stats(m->mbs, &st);
    // close the series before committing
    col_close(&r.time);
    for (int o = 0; o < s->noutputs; o++) {
      for (int q = 0; q < NQ; q++) col_close(&r.out[o][q]);
    }
    for (int k = 0; k < 3; k++) col_close(&r.energy[k]);
    for (int k = 0; k < 2; k++) col_close(&r.momentum[k]);
    for (int k = 0; k < s->nreactions; k++) {
      col_close(&r.react[k][0]);
      col_close(&r.react[k][1]);
    }
    double wall = fmbd_cli_wall_s(), cpu = fmbd_cli_cpu_s();
    FMBD_GCALL(fmbd_h5_commit(&r.f, wall, cpu));
    double run_cpu = fmbd_cpu_s() - r.t0_cpu;
    fmbd_cli_summary(
        "%s: %lld steps, %lld rejected, %lld Newton iterations, %lld rows to t = %g s (%.3gx real "
        "time on CPU time)",
        strcmp(out_name, "-") ? out_name : "standard output", (long long)st.steps,
        (long long)st.rejected, (long long)st.newton_iterations, (long long)r.rows,
        fmbd_mbs_time(m->mbs), run_cpu > 0 ? fmbd_mbs_time(m->mbs) / run_cpu : INFINITY);
  }
done:
  if (r.f) {
    if (interrupted && strcmp(out_name, "-")) {
      // keep the valid prefix under NAME.part, marked incomplete
      int keep_rc = flush_all(&r);
      if (!keep_rc) keep_rc = write_stats(&r, false);
      (void)keep_rc;
      for (int o = 0; o < s->noutputs; o++) {
        for (int q = 0; q < NQ; q++) col_close(&r.out[o][q]);
      }
      col_close(&r.time);
      for (int k = 0; k < 3; k++) col_close(&r.energy[k]);
      for (int k = 0; k < 2; k++) col_close(&r.momentum[k]);
      for (int k = 0; k < s->nreactions; k++) {
        col_close(&r.react[k][0]);
        col_close(&r.react[k][1]);
      }
      fmbd_h5_abandon(&r.f);
      fmbd_log(
          FMBD_LOG_WARN,
          "the run stopped at t = %g s; its valid prefix is kept in %s.part (/stats complete = 0)",
          fmbd_mbs_time(m->mbs), out_name);
    } else {
      fmbd_h5_close(&r.f);
    }
  }
  col_close(&r.time);
  if (r.out) {
    for (int o = 0; o < s->noutputs; o++) {
      for (int q = 0; q < NQ; q++) col_close(&r.out[o][q]);
    }
  }
  for (int k = 0; k < 3; k++) col_close(&r.energy[k]);
  for (int k = 0; k < 2; k++) col_close(&r.momentum[k]);
  if (r.react) {
    for (int k = 0; k < s->nreactions; k++) {
      col_close(&r.react[k][0]);
      col_close(&r.react[k][1]);
    }
  }
  for (int k = 0; k < 3; k++) {
    if (r.h[k]) {
      for (int o = 0; o < s->noutputs; o++) fmbd_free(r.h[k][o].v);
    }
    fmbd_free(r.h[k]);
  }
  fmbd_free(r.t_hist.v);
  fmbd_free(r.out);
  fmbd_free(r.react);
  fmbd_scene_model_destroy(&m);
  fmbd_scene_destroy(&s);
  fmbd_free(out_name);
  fmbd_free(rules);
out:
  return fmbd_cli_finish(rc);
}
