// cbcheck/main.c: a posteriori eigenvalue error estimates of a Craig-Bampton body, mode
// selection to a tolerance, and the reduced flexible body (BODY.rflex.h5)
// SPDX-License-Identifier: MIT
//
// A thin command line over common/: fmbd_check (the cb file, the fe file it came from, the
// estimators, more fixed-interface modes, exact eigenvalues, the rflex file), fmbd_est
// (estimates, selection), fmbd_svg (plots). What stays here: the options, the report table, the
// CSV file and the plots.
// See docs/man/cbcheck.1.
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_cb.h"
#include "fmbd_check.h"
#include "fmbd_cli.h"
#include "fmbd_err.h"
#include "fmbd_est.h"
#include "fmbd_fe.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"
#include "fmbd_rflex.h"
#include "fmbd_svg.h"

// cbcheck-mpi compiles this file again under its own name, with a note in the help and main
// renamed (cbcheck-mpi/cbcheck.c): one program, two eigensolvers behind --exact
#ifndef CBCHECK_PROG
#define CBCHECK_PROG "cbcheck"
#define CBCHECK_USAGE_NOTE ""
#endif

static const char *usage_text =
    "Usage: cbcheck BODY.cb.h5 [--fe BODY.fe.h5] [--tol E] [--range NM] [--init N0]\n"
    "               [--exact] [--csv FILE|-] [--plot PREFIX] [-o BODY.rflex.h5]\n"
    "A posteriori relative eigenvalue error estimates of a Craig-Bampton body (lower: Boo\n"
    "et al. 2016; upper: Han et al. 2020, with kappa_n and with kappa_(Nd+1); second\n"
    "order; exact on request), iterative selection of the number of fixed-interface modes\n"
    "to a tolerance (Han et al. 2020, Figure 1), and the reduced flexible body: the NM\n"
    "flexible modes, interface modes, FFRF inertia invariants, modal stress (fmbd-rflex).\n"
    "\n"
    "BODY.cb.h5  an fmbd-cb file (fe2cb); \"-\" reads standard input\n"
    "\n"
    "Options:\n"
    "  --fe FILE        the body's fmbd-fe file (default: the one recorded by fe2cb in the\n"
    "                   /cb attribute fe_file, looked up as given and beside BODY.cb.h5).\n"
    "                   Needed for more modes than fe2cb computed and for --exact; checked\n"
    "                   against the SHA-256 fe2cb recorded. When present, it also gives\n"
    "                   estimates free of the round-off of A' Ks^-1 A (see the man page)\n"
    "  --tol E          select the number of fixed-interface modes Nd so that the upper\n"
    "                   estimate of flexible modes 1..NM is at most E (E >= 1e-10)\n"
    "  --range NM       flexible modes reported, and (with --tol) that must meet E\n"
    "                   (default: with --tol 10, else every flexible mode of the body)\n"
    "  --init N0        first Nd of the selection (default 5)\n"
    "  --estimator W    the estimate that drives the selection: upper (kappa_n, the\n"
    "                   paper's, default), upper-next (kappa_(Nd+1)), second, lower\n"
    "  --max-modes N    largest Nd the selection may reach (default: interior dofs - 1)\n"
    "  --hold NAME      the scene holds interface NAME (a fixed, revolute, universal,\n"
    "                   prismatic or cylindrical joint): estimate and select for the body\n"
    "                   held there, and keep the interface's constraint modes (repeatable;\n"
    "                   fmbd-run -M passes it)\n"
    "  --nd N           without --tol: the estimates of the body with N fixed-interface\n"
    "                   modes instead of the cb file's (more are computed from the fe file)\n"
    "  --exact          exact errors from a full eigensolution of the body (costly)\n"
    "  --csv FILE       the table as CSV (\"-\": standard output): mode,frequency_hz,\n"
    "                   eigenvalue,lower,second_order,upper,exact,upper_kappa_next,cluster\n"
    "  --plot PREFIX    PREFIX-estimates.svg (estimates and exact error per mode) and\n"
    "                   PREFIX-convergence.svg (error of chosen modes against Nd)\n"
    "  --plain          residual flexibility by the plain formula from the cb file alone,\n"
    "                   without reading the fe file (faster; the second-order estimate may\n"
    "                   lose digits, see the man page)\n"
    "  --no-stress      do not compute the modal stresses of the rflex file\n"
    "  --for-scene SCENE.yaml:BODY  the rflex body holds only what SCENE reads of its\n"
    "                   body BODY: the modal motion of its joint, load and output nodes,\n"
    "                   the stress of its stress outputs' nodes (fmbd-run -M passes it)\n"
    "  -o FILE          write the reduced flexible body (\"-\": standard output). With --tol\n"
    "                   and no -o: BODY.rflex.h5, or standard output when it is not a\n"
    "                   terminal. Without --tol and -o, no file is written\n"
    "  -q, --quiet      errors only\n"
    "  -v, --verbose    progress and details (-vv: debug)\n"
    "  -h, --help       this help\n"
    "  -V, --version    the version\n"
    "\n"
    "The report table goes to standard output, or to standard error when the rflex file or\n"
    "the CSV goes to standard output.\n"
    "\n"
    "Example:\n"
    "  cbcheck rod.cb.h5 --tol 1e-3 --range 10 -o rod.rflex.h5\n" CBCHECK_USAGE_NOTE;

// Smallest --tol accepted. The estimates compare eigenvalues that the Lanczos and the dense
// reduced solves give to about 1e-12..1e-9 relative (the fe2cb tests: 1e-9 against scipy),
// so a tolerance below 1e-10 would be "met" by round-off, or chased forever by adding modes.
// A body whose modes are less accurate than the tolerance (/cb/max_residual) gets a warning.
#define TOL_FLOOR 1e-10

typedef struct args {
  const char *input, *fe, *csv, *plot, *output, *for_scene;
  const char *hold[64];  // --hold: interfaces the scene holds
  int nhold;
  double tol;
  bool has_tol, exact, stress, plain;
  long range, init, max_modes, nd;
  int which;
  int quiet, verbose;
} args;

enum {
  OPT_OUTPUT = 1,
  OPT_FE,
  OPT_HOLD,
  OPT_CSV,
  OPT_PLOT,
  OPT_TOL,
  OPT_RANGE,
  OPT_INIT,
  OPT_MAX_MODES,
  OPT_ND,
  OPT_ESTIMATOR,
  OPT_EXACT,
  OPT_PLAIN,
  OPT_NO_STRESS,
  OPT_FOR_SCENE
};
static const fmbd_cli_option options[] = {
    {NULL, 'o', true, OPT_OUTPUT},           {"--fe", 0, true, OPT_FE},
    {"--hold", 0, true, OPT_HOLD},           {"--csv", 0, true, OPT_CSV},
    {"--plot", 0, true, OPT_PLOT},           {"--tol", 0, true, OPT_TOL},
    {"--range", 0, true, OPT_RANGE},         {"--init", 0, true, OPT_INIT},
    {"--max-modes", 0, true, OPT_MAX_MODES}, {"--nd", 0, true, OPT_ND},
    {"--estimator", 0, true, OPT_ESTIMATOR}, {"--exact", 0, false, OPT_EXACT},
    {"--plain", 0, false, OPT_PLAIN},        {"--no-stress", 0, false, OPT_NO_STRESS},
    {"--for-scene", 0, true, OPT_FOR_SCENE}, {0}};

static int parse_args(int argc, char **argv, args *a, bool *done) {
  *done = false;
  a->init = 5;
  a->range = -1;
  a->max_modes = -1;
  a->nd = -1;
  a->stress = true;
  a->which = FMBD_EST_UPPER;
  fmbd_cli_args p;
  fmbd_cli_args_init(&p, argc, argv, options, usage_text);
  for (int id; (id = fmbd_cli_next(&p)) != FMBD_CLI_END;) {
    const char *val = p.value;
    switch (id) {
      case FMBD_CLI_EXIT:
        *done = p.status == 0;
        return p.status;
      case FMBD_CLI_ARG:
        if (a->input) {
          return fmbd_cli_usage_error("one BODY.cb.h5 expected, got '%s' and '%s'", a->input, val);
        }
        a->input = val;
        break;
      case OPT_OUTPUT:
        a->output = val;
        break;
      case OPT_FE:
        a->fe = val;
        break;
      case OPT_HOLD:
        if (a->nhold >= 64) {
          return fmbd_cli_usage_error("--hold: at most 64 interfaces");
        }
        a->hold[a->nhold++] = val;
        break;
      case OPT_FOR_SCENE:
        a->for_scene = val;
        break;
      case OPT_CSV:
        a->csv = val;
        break;
      case OPT_PLOT:
        a->plot = val;
        break;
      case OPT_TOL:  // its floor is checked below, with the file named
        if (fmbd_cli_double(&p, -INFINITY, INFINITY, 0, &a->tol)) {
          return p.status;
        }
        a->has_tol = true;
        break;
      case OPT_RANGE:
        if (fmbd_cli_long(&p, 1, LONG_MAX, &a->range)) {
          return p.status;
        }
        break;
      case OPT_ND:
        if (fmbd_cli_long(&p, 0, LONG_MAX, &a->nd)) {
          return p.status;
        }
        break;
      case OPT_INIT:
        if (fmbd_cli_long(&p, 0, LONG_MAX, &a->init)) {
          return p.status;
        }
        break;
      case OPT_MAX_MODES:
        if (fmbd_cli_long(&p, 1, LONG_MAX, &a->max_modes)) {
          return p.status;
        }
        break;
      case OPT_ESTIMATOR:
        if (fmbd_est_which_parse(val, &a->which)) {
          return fmbd_cli_usage_error("--estimator: '%s' is not upper, upper-next, second or lower",
                                      val);
        }
        break;
      case OPT_EXACT:
        a->exact = true;
        break;
      case OPT_PLAIN:
        a->plain = true;
        break;
      case OPT_NO_STRESS:
        a->stress = false;
        break;
    }
  }
  a->quiet = p.quiet;
  a->verbose = p.verbose;
  if (!a->input) {
    return fmbd_cli_usage_error("no BODY.cb.h5 given");
  }
  if (a->has_tol && a->nd >= 0) {
    return fmbd_cli_usage_error("--nd and --tol are exclusive (the selection chooses Nd)");
  }
  if (a->has_tol && !(a->tol >= TOL_FLOOR)) {
    return fmbd_cli_usage_error(
        "%s: --tol %g: the relative eigenvalue error tolerance must be at "
        "least %g: below that the eigenvalues themselves are not resolved "
        "(double precision, the eigensolvers' accuracy)",
        a->input, a->tol, TOL_FLOOR);
  }
  if (a->nhold > 0 && a->exact) {
    return fmbd_cli_usage_error(
        "--exact compares with the free body's eigenvalues: not with --hold");
  }
  if (a->output && a->csv && !strcmp(a->output, "-") && !strcmp(a->csv, "-")) {
    return fmbd_cli_usage_error("-o - and --csv - cannot both use standard output");
  }
  return 0;
}

// --- report ------------------------------------------------------------------------------------
typedef struct table {
  int64_t nflex;                                                 // flexible modes listed
  double *freq, *chib, *lower, *second, *upper, *unext, *exact;  // (nflex)
  int64_t *cluster;  // flexible index (1-based) of the cluster's first member
} table;

static void table_free(table *t) {
  fmbd_free(t->freq);
  fmbd_free(t->chib);
  fmbd_free(t->lower);
  fmbd_free(t->second);
  fmbd_free(t->upper);
  fmbd_free(t->unext);
  fmbd_free(t->exact);
  fmbd_free(t->cluster);
  memset(t, 0, sizeof(*t));
}

// flexible modes 1..nflex of m into t; exact from chi (full eigenvalues, NULL: none)
static int table_fill(table *t, const fmbd_est_modes *m, int64_t nflex, const double *chi,
                      int64_t nchi) {
  table_free(t);
  size_t n = (size_t)(nflex > 0 ? nflex : 1);
  t->freq = fmbd_calloc(n, sizeof(double));
  t->chib = fmbd_calloc(n, sizeof(double));
  t->lower = fmbd_calloc(n, sizeof(double));
  t->second = fmbd_calloc(n, sizeof(double));
  t->upper = fmbd_calloc(n, sizeof(double));
  t->unext = fmbd_calloc(n, sizeof(double));
  t->exact = fmbd_calloc(n, sizeof(double));
  t->cluster = fmbd_calloc(n, sizeof(int64_t));
  FMBD_CHECK(
      t->freq && t->chib && t->lower && t->second && t->upper && t->unext && t->exact && t->cluster,
      FMBD_ERR_NOMEM, "out of memory");
  int64_t j = 0, *flexidx = fmbd_calloc((size_t)m->nmodes + 1, sizeof(int64_t));
  FMBD_CHECK(flexidx, FMBD_ERR_NOMEM, "out of memory");
  for (int64_t k = 0; k < m->nmodes; k++) {
    flexidx[k] = m->rigid[k] ? 0 : j + 1;
    if (m->rigid[k] || j >= nflex) {
      j += !m->rigid[k];
      continue;
    }
    double c = m->chibar[k];
    t->chib[j] = c;
    t->freq[j] = sqrt(fmax(c, 0)) / (2 * M_PI);
    t->lower[j] = m->lower[k];
    t->second[j] = m->second[k];
    t->upper[j] = m->upper[k];
    t->unext[j] = m->upper_next[k];
    t->cluster[j] = flexidx[m->cluster[k]];
    t->exact[j] = (chi && j < nchi) ? c / chi[j] - 1 : NAN;
    j++;
  }
  fmbd_free(flexidx);
  t->nflex = j < nflex ? j : nflex;
  return FMBD_OK;
}

static void print_table(FILE *fp, const table *t, bool exact) {
  fprintf(fp, "%5s %12s %13s %10s %10s %10s %10s%s\n", "mode", "freq_hz", "eigenvalue", "lower",
          "second", "upper", "upper_next", exact ? "      exact" : "");
  for (int64_t j = 0; j < t->nflex; j++) {
    fprintf(fp, "%5lld %12.5g %13.6e %10.3e %10.3e %10.3e %10.3e", (long long)j + 1, t->freq[j],
            t->chib[j], t->lower[j], t->second[j], t->upper[j], t->unext[j]);
    if (exact) {
      fprintf(fp, " %10.3e", t->exact[j]);
    }
    if (t->cluster[j] != j + 1 || (j + 1 < t->nflex && t->cluster[j + 1] == j + 1)) {
      fprintf(fp, "  cluster %lld", (long long)t->cluster[j]);
    }
    fputc('\n', fp);
  }
  bool any = false;
  for (int64_t j = 0; j < t->nflex; j++) {
    any = any || t->cluster[j] != j + 1;
  }
  if (any) {
    fprintf(
        fp,
        "clusters (eigenvalues within 1e-3, or overlapping intervals [chibar/(1+upper), chibar]):\n"
        "each member gets the cluster's largest upper and second-order estimates and its\n"
        "smallest lower estimate\n");
  }
  if (exact) {  // measured bounding rates over modes with exact error below 10 %
    int64_t n = 0, up = 0, lo = 0, un = 0;
    for (int64_t j = 0; j < t->nflex; j++) {
      if (isfinite(t->exact[j]) && t->exact[j] < 0.1) {
        n++;
        up += t->upper[j] >= t->exact[j];
        un += t->unext[j] >= t->exact[j];
        lo += t->lower[j] <= t->exact[j];
      }
    }
    if (n > 0) {
      fprintf(fp,
              "modes with exact error < 10%%: %lld; upper >= exact in %lld (%.1f%%), upper_next >= "
              "exact in %lld (%.1f%%), lower <= exact in %lld (%.1f%%)\n",
              (long long)n, (long long)up, 100.0 * up / n, (long long)un, 100.0 * un / n,
              (long long)lo, 100.0 * lo / n);
    }
  }
}

static void csv_num(FILE *fp, double v) {
  if (isfinite(v)) {
    fprintf(fp, ",%.10e", v);
  } else {
    fputc(',', fp);
  }
}

static int write_csv(const char *name, const table *t) {
  FILE *fp = strcmp(name, "-") ? NULL : stdout;
  char *tmp = NULL;
  if (!fp) {
    size_t n = strlen(name) + 6;
    tmp = fmbd_malloc(n);
    FMBD_CHECK(tmp, FMBD_ERR_NOMEM, "out of memory");
    snprintf(tmp, n, "%s.part", name);
    fp = fopen(tmp, "w");
    if (!fp) {
      fmbd_free(tmp);
      fmbd_err_context(name, "");
      FMBD_FAIL(FMBD_ERR_IO, "cannot write the CSV file");
    }
  }
  fprintf(fp,
          "mode,frequency_hz,eigenvalue,lower,second_order,upper,exact,upper_kappa_next,cluster\n");
  for (int64_t j = 0; j < t->nflex; j++) {
    fprintf(fp, "%lld", (long long)j + 1);
    csv_num(fp, t->freq[j]);
    csv_num(fp, t->chib[j]);
    csv_num(fp, t->lower[j]);
    csv_num(fp, t->second[j]);
    csv_num(fp, t->upper[j]);
    csv_num(fp, t->exact[j]);
    csv_num(fp, t->unext[j]);
    fprintf(fp, ",%lld\n", (long long)t->cluster[j]);
  }
  if (tmp) {
    int bad = ferror(fp) | fclose(fp);
    if (bad || rename(tmp, name) != 0) {
      remove(tmp);
      fmbd_free(tmp);
      fmbd_err_context(name, "");
      FMBD_FAIL(FMBD_ERR_IO, "cannot write the CSV file");
    }
    fmbd_free(tmp);
  } else {
    fflush(fp);
  }
  return FMBD_OK;
}

// --- plots -------------------------------------------------------------------------------------
static int plot_estimates(const char *prefix, const table *t, bool exact, int64_t nd) {
  int rc = FMBD_OK;
  char path[1024], title[200];
  double *x = fmbd_calloc((size_t)t->nflex + 1, sizeof(double));
  FMBD_CHECK(x, FMBD_ERR_NOMEM, "out of memory");
  for (int64_t j = 0; j < t->nflex; j++) {
    x[j] = (double)(j + 1);
  }
  fmbd_svg_plot p;
  fmbd_svg_plot_defaults(&p);
  snprintf(title, sizeof title, "Relative eigenvalue error, Nd = %lld", (long long)nd);
  p.title = title;
  p.xlabel = "flexible mode";
  p.ylabel = "relative eigenvalue error";
  p.ylog = true;
  p.ymax = 1;  // errors above 100 % say nothing: clipped
  fmbd_svg_series s[5] = {
      {"upper (kappa_n)", t->nflex, x, t->upper, "#d62728", FMBD_SVG_TRIANGLE, FMBD_SVG_DASHED},
      {"upper (kappa_Nd+1)", t->nflex, x, t->unext, "#ff7f0e", FMBD_SVG_DIAMOND, FMBD_SVG_DOTTED},
      {"second order", t->nflex, x, t->second, "#2ca02c", FMBD_SVG_SQUARE, FMBD_SVG_NOLINE},
      {"lower (Boo 2016)", t->nflex, x, t->lower, "#1f77b4", FMBD_SVG_CROSS, FMBD_SVG_DASHED},
      {"exact", t->nflex, x, t->exact, "#000000", FMBD_SVG_CIRCLE, FMBD_SVG_SOLID},
  };
  snprintf(path, sizeof path, "%s-estimates.svg", prefix);
  rc = fmbd_svg_write(path, &p, exact ? 5 : 4, s);
  fmbd_free(x);
  return rc;
}

// error of chosen flexible modes against nd = nd_lo..nd_hi (rank-one steps of the estimator)
static int plot_convergence(fmbd_est *E, const char *prefix, int64_t nflex, int64_t nd_lo,
                            int64_t nd_hi, const double *chi, int64_t nchi, int which, double tol) {
  int rc = FMBD_OK;
  enum { NPICK = 6 };
  int64_t pick[NPICK], npick = 0;
  double *xs = NULL, *ys = NULL, *ye = NULL;
  fmbd_est_modes m = {0};
  char path[1024], labels[2 * NPICK][48];
  int64_t nx = nd_hi - nd_lo + 1;
  if (nx < 1 || nflex < 1) {
    return FMBD_OK;
  }
  for (int k = 0; k < NPICK; k++) {  // modes 1, ..., nflex spread evenly, unique
    int64_t j = 1 + (int64_t)llround((double)k * (double)(nflex - 1) / (NPICK - 1));
    if (npick == 0 || pick[npick - 1] != j) {
      pick[npick++] = j;
    }
  }
  int64_t nd_save = fmbd_est_nd(E);
  FMBD_GALLOC(xs = fmbd_calloc((size_t)nx, sizeof(double)));
  FMBD_GALLOC(ys = fmbd_calloc((size_t)(nx * npick), sizeof(double)));
  FMBD_GALLOC(ye = fmbd_calloc((size_t)(nx * npick), sizeof(double)));
  for (int64_t i = 0; i < nx; i++) {
    int64_t nd = nd_lo + i;
    xs[i] = (double)nd;
    FMBD_GCALL(fmbd_est_set_nd(E, nd));
    FMBD_GCALL(fmbd_est_run(E, &m, NULL));
    fmbd_progress("convergence sweep: Nd = %lld", (long long)nd);
    for (int64_t q = 0; q < npick; q++) {
      ys[i + nx * q] = ye[i + nx * q] = NAN;
      int64_t seen = 0;
      for (int64_t k = 0; k < m.nmodes; k++) {
        if (!m.rigid[k] && ++seen == pick[q]) {
          ys[i + nx * q] = fmbd_est_pick(&m, which, k);
          if (chi && seen <= nchi) {
            ye[i + nx * q] = m.chibar[k] / chi[seen - 1] - 1;
          }
          break;
        }
      }
    }
  }
  fmbd_progress(NULL);
  FMBD_GCALL(fmbd_est_set_nd(E, nd_save));
  fmbd_svg_series s[2 * NPICK + 1];
  int ns = 0;
  static const char *const col[NPICK] = {"#1f77b4", "#d62728", "#2ca02c",
                                         "#ff7f0e", "#9467bd", "#8c564b"};
  for (int64_t q = 0; q < npick; q++) {
    snprintf(labels[2 * q], sizeof labels[0], "mode %lld estimate", (long long)pick[q]);
    s[ns++] = (fmbd_svg_series){labels[2 * q],  nx, xs, ys + nx * q, col[q], FMBD_SVG_NONE,
                                FMBD_SVG_DASHED};
    if (chi) {
      snprintf(labels[2 * q + 1], sizeof labels[0], "mode %lld exact", (long long)pick[q]);
      s[ns++] = (fmbd_svg_series){labels[2 * q + 1], nx, xs, ye + nx * q, col[q], FMBD_SVG_NONE,
                                  FMBD_SVG_SOLID};
    }
  }
  double tx[2] = {(double)nd_lo, (double)nd_hi}, ty[2] = {tol, tol};
  if (tol > 0) {
    s[ns++] = (fmbd_svg_series){"tolerance", 2, tx, ty, "#000000", FMBD_SVG_NONE, FMBD_SVG_DOTTED};
  }
  fmbd_svg_plot p;
  fmbd_svg_plot_defaults(&p);
  p.title = "Relative eigenvalue error against the number of fixed-interface modes";
  p.xlabel = "fixed-interface modes Nd";
  p.ylabel = "relative eigenvalue error";
  p.ylog = true;
  p.ymax = 1;  // errors above 100 % (few modes) say nothing: clipped
  snprintf(path, sizeof path, "%s-convergence.svg", prefix);
  FMBD_GCALL(fmbd_svg_write(path, &p, ns, s));
done:
  fmbd_est_modes_free(&m);
  fmbd_free(xs);
  fmbd_free(ys);
  fmbd_free(ye);
  return rc;
}

// --- main ----------------------------------------------------------------------------------------
int main(int argc, char **argv) {
  fmbd_cli_init(CBCHECK_PROG, argc, argv);
  args a = {0};
  bool done_early = false;
  int st = parse_args(argc, argv, &a, &done_early);
  if (st != 0 || done_early) {
    return st ? st : fmbd_cli_finish(0);
  }
  fmbd_cli_set_verbosity(a.quiet, a.verbose);
  int rc = FMBD_OK;
  fmbd_check *r = NULL;
  fmbd_est_modes m = {0};
  fmbd_est_select_result sel = {0};
  int64_t nkept_out = 0;
  table t = {0};
  double *chi = NULL, *Xi = NULL;
  int64_t nchi = 0;
  fmbd_rflex *rf = NULL;
  char *outname = NULL;
  FILE *rep = stdout;

  // --- the reduced body and its estimators (the fe file if available: exact arithmetic of the
  // residual blocks) ---
  double t0 = fmbd_wall_s(), c0 = fmbd_cpu_s(), t_sel = 0, c_sel = 0;
  fmbd_check_opts co;
  fmbd_check_opts_defaults(&co);
  co.fe = a.fe;
  co.plain = a.plain;
  co.nhold = a.nhold;
  co.hold = a.hold;
  co.max_modes = a.max_modes;
  FMBD_GCALL(fmbd_check_open(a.input, &co, &r));
  fmbd_cb *cb = r->cb;
  const char *cbname = fmbd_h5_name(r->cbf);
  int64_t nflex_body = cb->ndof - cb->n_rigid - cb->n_rigid_removed - cb->nheld;
  int64_t nflex_red = cb->nr - cb->n_rigid;
  int64_t nm = a.range > 0 ? a.range : (a.has_tol ? 10 : nflex_red);
  if (a.has_tol && a.tol < 10.0 * cb->max_residual) {
    fmbd_log(FMBD_LOG_WARN,
             "%s: --tol %g is within 10 times the largest relative residual of the "
             "fixed-interface modes (%.2g, /cb max_residual): the estimates cannot be trusted "
             "that far",
             cbname, a.tol, cb->max_residual);
  }
  if (a.has_tol && a.init > r->nd_max) {
    fmbd_err_context(cbname, "/cb/interior_dofs");
    FMBD_GFAIL(FMBD_ERR_VALUE,
               "--init %ld: at most %lld fixed-interface modes (%lld interior dofs%s)", a.init,
               (long long)r->nd_max, (long long)cb->ns,
               r->nd_max < cb->ns - 1 ? ", --max-modes" : "");
  }
  // the most flexible modes a reduced body can have: Nd <= ns - 1 (the eigensolver needs
  // nev < n) plus the boundary dofs, less the rigid-body modes
  if (r->nd_max + cb->nb - cb->n_rigid < nflex_body) {
    nflex_body = r->nd_max + cb->nb - cb->n_rigid;
  }
  if (nm > nflex_body) {
    fmbd_err_context(cbname, "/dofs");
    FMBD_GFAIL(FMBD_ERR_VALUE,
               "--range %lld: the body can have at most %lld flexible modes (%lld dofs, %lld "
               "rigid-body modes%s)",
               (long long)nm, (long long)nflex_body, (long long)cb->ndof, (long long)cb->n_rigid,
               r->nd_max < cb->ns - 1 ? ", --max-modes" : "");
  }
  if (a.nd >= 0 && !a.has_tol) {
    nflex_red = a.nd + cb->nb - cb->n_rigid;
    if (a.range <= 0) {
      nm = nflex_red;
    }
  }
  if (!a.has_tol && nm > nflex_red) {
    fmbd_err_context(cbname, "/reduced/eigenvalues");
    FMBD_GFAIL(
        FMBD_ERR_VALUE,
        "--range %lld: the reduced body has only %lld flexible modes (give --tol to add modes)",
        (long long)nm, (long long)nflex_red);
  }
  // output streams: the report leaves stdout to the rflex or the CSV
  bool want_rflex = a.output || a.has_tol;
  if (want_rflex) {
    static const char *const strip[] = {".cb.h5", ".h5", NULL};
    FMBD_GCALL(fmbd_cli_output_name(a.input, a.output, strip, ".rflex.h5", &outname));
    FMBD_GCALL(fmbd_cli_check_not_input(outname, a.fe));
  }
  if (a.csv) {
    FMBD_GCALL(fmbd_cli_check_not_input(a.csv, a.input));
    FMBD_GCALL(fmbd_cli_check_not_input(a.csv, a.fe));
  }
  if ((outname && !strcmp(outname, "-")) || (a.csv && !strcmp(a.csv, "-"))) {
    rep = stderr;
  }
  if (a.quiet) {
    rep = NULL;
  }
  fmbd_est *E = fmbd_check_estimator(r);  // the problem estimated and selected
  if (rep) {
    fprintf(rep,
            "cbcheck: %s: method %s, %lld dofs, %lld boundary dofs, %lld fixed-interface modes, "
            "%lld rigid-body modes\n",
            cbname, cb->method, (long long)cb->ndof, (long long)cb->nb, (long long)cb->nd,
            (long long)cb->n_rigid);
    fprintf(rep, "residual flexibility: %s\n",
            r->fe && !a.plain ? "projected with the FE matrices of the fe file (no cancellation)"
                              : "A' Ks^-1 A - (Phi'A)' Lambda^-1 (Phi'A) from the cb file alone "
                                "(may lose digits on slender bodies)");
  }

  // --- selection or plain estimates ---
  if (a.has_tol) {
    fmbd_est_select_opts so = {a.tol, nm, a.init, r->nd_max, a.which};
    double ts = fmbd_wall_s(), cs = fmbd_cpu_s();
    FMBD_GCALL(fmbd_est_select(E, &so, fmbd_check_extend, r, &sel));
    t_sel = fmbd_wall_s() - ts;
    c_sel = fmbd_cpu_s() - cs;
    if (rep) {
      fprintf(rep, "selection: tol %g on flexible modes 1..%lld, estimator %s, from Nd = %ld\n",
              a.tol, (long long)nm, fmbd_est_which_label(a.which), a.init);
      fprintf(rep, "%6s %14s %14s\n", "Nd", "first_failing", "largest");
      for (int64_t i = 0; i < sel.niter; i++) {
        fprintf(rep, "%6lld %14lld %14.4e\n", (long long)sel.log[i].nd,
                (long long)sel.log[i].first_failing, sel.log[i].largest);
      }
    }
  } else if (a.nd >= 0) {  // the estimates of another Nd (extended from the fe file if larger)
    if (a.nd > r->nd_max) {
      fmbd_err_context(cbname, "/cb/interior_dofs");
      FMBD_GFAIL(FMBD_ERR_VALUE, "--nd %ld: at most %lld fixed-interface modes", a.nd,
                 (long long)r->nd_max);
    }
    if (a.nd > fmbd_est_npool(r->est)) {
      FMBD_GCALL(fmbd_check_extend(r, E, a.nd));
    }
    FMBD_GCALL(fmbd_est_set_nd(E, a.nd));
  } else {
    FMBD_GCALL(fmbd_est_set_nd(E, cb->nd));
  }
  int64_t nd = fmbd_est_nd(E), nr = nd + fmbd_est_nb(E);
  if (r->est_held) {
    FMBD_GCALL(fmbd_est_set_nd(r->est, nd));  // the full problem at the same Nd (held modes)
  }
  FMBD_GALLOC(Xi = fmbd_malloc(sizeof(double) * (size_t)(nr * nr + 1)));
  FMBD_GCALL(fmbd_est_run(E, &m, Xi));
  double t_est = fmbd_wall_s() - t0 - t_sel;  // the selection is timed apart
  double c_est = fmbd_cpu_s() - c0 - c_sel;
  if (!a.has_tol && nd == r->nd_file) {  // the re-solved reduced problem must be the file's
    for (int64_t k = 0; k < m.nmodes && k < cb->nr; k++) {
      double d = fabs(m.chibar[k] - cb->chibar[k]);
      if (!m.rigid[k] && d > 1e-6 * fabs(cb->chibar[k])) {
        fmbd_log(FMBD_LOG_WARN,
                 "%s: /reduced/eigenvalues[%lld] = %.10g, the closed form gives %.10g", cbname,
                 (long long)k, cb->chibar[k], m.chibar[k]);
        break;
      }
    }
  }
  int64_t nrig = 0;
  for (int64_t k = 0; k < m.nmodes; k++) {
    nrig += m.rigid[k];
  }
  if (nrig != cb->n_rigid && !r->est_held) {
    fmbd_log(FMBD_LOG_WARN, "%s: %lld rigid-body modes found at Nd = %lld, /cb n_rigid = %lld",
             cbname, (long long)nrig, (long long)nd, (long long)cb->n_rigid);
  }
  int64_t nlist = nm < m.nmodes - nrig ? nm : m.nmodes - nrig;
  if (a.exact) {
    nchi = nlist;
    FMBD_GCALL(fmbd_check_exact(r, &m, nlist, &chi));
  }
  FMBD_GCALL(table_fill(&t, &m, nlist, chi, nchi));
  if (rep) {
    fprintf(rep, "Nd = %lld fixed-interface modes%s\n", (long long)nd,
            fmbd_est_knext_known(E) ? "" : " (kappa_(Nd+1) unknown: upper_next uses kappa_Nd)");
    print_table(rep, &t, a.exact);
  }
  // an unreached tolerance: the report above shows the best Nd; no file is written
  if (a.has_tol && !sel.reached) {
    fmbd_err_context(cbname, "/cb/kappa");
    FMBD_GFAIL(FMBD_ERR_CONVERGE,
               "tolerance %g not reached for flexible modes 1..%lld with up to Nd = %lld "
               "fixed-interface modes%s; best reached: largest estimate %.4g at Nd = %lld",
               a.tol, (long long)nm, (long long)(sel.nd > 0 ? sel.nd : 0),
               r->nd_max == cb->ns - 1 ? " (the body's interior dofs)" : " (--max-modes)",
               sel.best_largest, (long long)sel.best_nd);
  }

  if (a.csv) {
    FMBD_GCALL(write_csv(a.csv, &t));
  }
  if (a.plot) {
    FMBD_GCALL(plot_estimates(a.plot, &t, a.exact, nd));
    int64_t lo = a.has_tol ? (a.init > 0 ? a.init : 1) : 1;
    int64_t hi = nd > lo ? nd : lo;
    if (hi > fmbd_est_npool(r->est)) {
      hi = fmbd_est_npool(r->est);
    }
    FMBD_GCALL(
        plot_convergence(E, a.plot, nlist, lo, hi, chi, nchi, a.which, a.has_tol ? a.tol : 0));
  }
  // --- the reduced flexible body ---
  if (outname) {
    FMBD_GCHECK(nlist == nm, FMBD_ERR_VALUE, "the reduced body has only %lld flexible modes",
                (long long)nlist);
    FMBD_GCALL(fmbd_check_rflex(r, &m, Xi, nm, a.stress, &rf, &nkept_out));
    if (a.for_scene) FMBD_GCALL(fmbd_check_subset_for_scene(r, rf, a.for_scene));
    fmbd_check_record rec = {nd, 0, a.has_tol ? a.tol : 0};
    for (int64_t q = 0; q < t.nflex; q++) {
      rec.max_estimate = fmax(rec.max_estimate, a.which == FMBD_EST_UPPER_NEXT ? t.unext[q]
                                                : a.which == FMBD_EST_SECOND   ? t.second[q]
                                                : a.which == FMBD_EST_LOWER    ? t.lower[q]
                                                                               : t.upper[q]);
    }
    FMBD_GCALL(fmbd_check_write_rflex(r, outname, rf, &rec, fmbd_cli_wall_s(), fmbd_cli_cpu_s()));
  }
  if (rep) {
    fflush(rep);
  }
  if (a.verbose) {
    fmbd_log(FMBD_LOG_INFO,
             "time: estimates %.3f s (reading the fe file %.3f s), selection %.3f s for %lld "
             "iterations of which extensions %.3f s (%lld calls, %lld modes), exact %.3f s",
             t_est, r->t_load_s, t_sel, (long long)sel.niter, r->t_extend_s, (long long)r->nextend,
             (long long)(r->cb->nd - r->nd_file), r->t_exact_s);
    fmbd_log(FMBD_LOG_INFO,
             "cpu: estimates %.3f s (reading the fe file %.3f s), selection %.3f s, exact %.3f s",
             c_est, r->c_load_s, c_sel, r->c_exact_s);
  }
  if (a.has_tol) {
    fmbd_cli_summary(
        "%s: Nd = %lld meets %g on flexible modes 1..%lld%s (%lld iterations, %lld extensions), "
        "%lld modes kept",
        outname, (long long)nd, a.tol, (long long)nm, r->est_held ? " of the held body" : "",
        (long long)sel.niter, (long long)sel.nextend, (long long)nkept_out);
  } else if (outname) {
    fmbd_cli_summary("%s: %lld flexible modes of Nd = %lld", outname, (long long)nm, (long long)nd);
  } else {
    fmbd_cli_summary("%s: estimates of %lld flexible modes at Nd = %lld", cbname,
                     (long long)t.nflex, (long long)nd);
  }
done:
  if (rep) {
    fflush(rep);
  }
  fmbd_rflex_destroy(&rf);
  table_free(&t);
  fmbd_est_modes_free(&m);
  fmbd_free(sel.log);
  fmbd_free(chi);
  fmbd_free(Xi);
  fmbd_free(outname);
  fmbd_check_close(&r);
  return fmbd_cli_finish(rc);
}
