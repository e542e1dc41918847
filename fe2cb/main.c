// fe2cb/main.c: FE body (BODY.fe.h5) -> Craig-Bampton reduced body (BODY.cb.h5)
// SPDX-License-Identifier: MIT
//
// A thin command line over common/fmbd_cb (docs/THEORY.md section 1): read the body, partition,
// reduce, write. See docs/man/fe2cb.1.
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_cb.h"
#include "fmbd_cli.h"
#include "fmbd_err.h"
#include "fmbd_fe.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"

static const char *usage_text =
    "Usage: fe2cb BODY.fe.h5 [-o BODY.cb.h5] [--modes N | --fmax HZ] [--method cb|nm]\n"
    "             [--boundary GROUP,...] [--hold] [--no-sturm]\n"
    "Craig-Bampton reduction of a finite-element body: fixed-interface normal modes (shift-\n"
    "invert Lanczos, checked so that no mode is skipped), constraint modes, reduced mass and\n"
    "stiffness matrices and their eigensolution (an fmbd-cb HDF5 file).\n"
    "\n"
    "BODY.fe.h5  an fmbd-fe file (mesh2fe); \"-\" reads it from standard input.\n"
    "\n"
    "Options:\n"
    "  -o FILE            output (\"-\": standard output). Default: BODY with .fe.h5\n"
    "                     replaced by .cb.h5, or standard output when that is not a terminal\n"
    "  --modes N          number of fixed-interface modes (default 20; 0: static condensation\n"
    "                     only)\n"
    "  --fmax HZ          every fixed-interface mode up to HZ instead of a count\n"
    "  --method cb|nm     cb: Craig-Bampton (default). nm: normal modes for comparison, free-\n"
    "                     free with the rigid-body modes removed (or held, with --hold)\n"
    "  --boundary G,...   more boundary nodes: every active dof of the named mesh groups\n"
    "                     (or interfaces) joins the interface dofs on the boundary\n"
    "  --hold             with --method nm: the modes with the boundary dofs held\n"
    "  --no-sturm         skip the Sturm-sequence count (an LDL' factorisation of Ks - s Ms\n"
    "                     that proves no mode below the last one was skipped; costs about\n"
    "                     one more factorisation of Ks)\n"
    "  -q, --quiet        errors only\n"
    "  -v, --verbose      progress and where the time went (-vv: debug)\n"
    "  -h, --help         this help\n"
    "  -V, --version      the version\n"
    "\n"
    "Example:\n"
    "  fe2cb rod.fe.h5 --modes 24 -o rod.cb.h5\n";

typedef struct args {
  const char *input, *output;
  fmbd_cb_opts cb;
  fmbd_cli_names groups;  ///< --boundary
  int quiet, verbose;
  bool modes_given;
  const char *method;
} args;

enum { OPT_OUTPUT = 1, OPT_MODES, OPT_FMAX, OPT_METHOD, OPT_BOUNDARY, OPT_HOLD, OPT_NO_STURM };
static const fmbd_cli_option options[] = {
    {"--output", 'o', true, OPT_OUTPUT},    {"--modes", 0, true, OPT_MODES},
    {"--fmax", 0, true, OPT_FMAX},          {"--method", 0, true, OPT_METHOD},
    {"--boundary", 0, true, OPT_BOUNDARY},  {"--hold", 0, false, OPT_HOLD},
    {"--no-sturm", 0, false, OPT_NO_STURM}, {0}};

// 0: go on; -1: done (help/version printed); > 0: exit status (usage error)
static int parse_args(int argc, char **argv, args *a) {
  fmbd_cli_args p;
  fmbd_cli_args_init(&p, argc, argv, options, usage_text);
  for (int id; (id = fmbd_cli_next(&p)) != FMBD_CLI_END;) {
    const char *val = p.value;
    switch (id) {
      case FMBD_CLI_EXIT:
        return p.status ? p.status : -1;
      case FMBD_CLI_ARG:
        if (a->input)
          return fmbd_cli_usage_error("one BODY.fe.h5 expected, got '%s' and '%s'", a->input, val);
        a->input = val;
        break;
      case OPT_OUTPUT:
        a->output = val;
        break;
      case OPT_MODES: {
        long n = 0;
        if (fmbd_cli_long(&p, 0, LONG_MAX, &n)) return p.status;
        a->cb.nmodes = n;
        a->modes_given = true;
        break;
      }
      case OPT_FMAX:
        if (fmbd_cli_double(&p, 0, INFINITY, FMBD_CLI_OPEN_LO, &a->cb.fmax_hz)) return p.status;
        break;
      case OPT_METHOD:
        if (strcmp(val, "cb") && strcmp(val, "nm")) {
          return fmbd_cli_usage_error("--method: '%s' is not cb or nm", val);
        }
        a->method = val;
        a->cb.nm = !strcmp(val, "nm");
        break;
      case OPT_BOUNDARY: {
        int st = fmbd_cli_names_parse("--boundary", val, &a->groups);
        if (st) return st;
        break;
      }
      case OPT_HOLD:
        a->cb.hold = true;
        break;
      case OPT_NO_STURM:
        a->cb.eig.sturm = false;
        break;
    }
  }
  a->quiet = p.quiet;
  a->verbose = p.verbose;
  if (!a->input) return fmbd_cli_usage_error("no BODY.fe.h5 given");
  if (a->modes_given && a->cb.fmax_hz > 0.0) {
    return fmbd_cli_usage_error("--modes and --fmax are exclusive");
  }
  if (a->cb.hold && !a->cb.nm) return fmbd_cli_usage_error("--hold needs --method nm");
  if (a->cb.fmax_hz > 0.0) a->cb.nmodes = 0;
  return 0;
}

// peak resident memory so far in MB (Linux /proc; -1 elsewhere), for the -vv log
static double peak_mb(void) {
  FILE *f = fopen("/proc/self/status", "r");
  if (!f) return -1.0;
  char line[256];
  double kb = -1.0;
  while (fgets(line, sizeof line, f)) {
    if (!strncmp(line, "VmHWM:", 6)) kb = atof(line + 6);
  }
  fclose(f);
  return kb / 1024.0;
}

// relative residual above which the modes' eigenvalues are reported as uncertain
#define FE2CB_RESID_WARN 1e-4

static void residual_warning(const fmbd_cb *cb) {
  // the eigensolver accepts residuals up to round-off's floor, 1e3 eps lambda_top / lambda:
  // on an ill-conditioned stiffness (slivers, aspect ratios of 100) that floor lets a
  // relative residual of 1e-4 .. 1e-1 through; the residual bounds the relative eigenvalue
  // error to first order (measured: the error is 1-3 % of it; docs/STABILITY.md, element
  // shape), so above 1e-4 the frequencies are not what the usual 1e-6 promises: say so
  if (cb->nd > 0 && cb->max_residual > FE2CB_RESID_WARN) {
    fmbd_log(FMBD_LOG_WARN,
             "the fixed-interface modes were accepted with relative residuals up to %.2g (the "
             "round-off floor of an ill-conditioned stiffness: badly shaped elements? see "
             "mesh2fe's element shape): their eigenvalues are certain only to about that "
             "(docs/STABILITY.md, element shape)",
             cb->max_residual);
  }
}

static void breakdown(const fmbd_cb *cb, double t_read, double t_write) {
  const fmbd_cb_timing *t = &cb->time;
  fmbd_log(FMBD_LOG_INFO,
           "%lld dofs: %lld interior, %lld boundary; factor of Ks: %s ordering, "
           "%.3g entries in L",
           (long long)cb->ndof, (long long)cb->ns, (long long)(cb->nb + cb->nheld),
           t->ordering_name ? t->ordering_name : "-", t->nnz_l);
  fmbd_log(FMBD_LOG_INFO,
           "time: read %.3g s, partition %.3g s, ordering %.3g s, factorisation "
           "%.3g s, Lanczos %.3g s (%d runs, %lld solves), Sturm check %.3g s, residuals %.3g s, "
           "constraint modes %.3g s, projections %.3g s, reduced eigensolution %.3g s, "
           "write %.3g s",
           t_read, t->partition, t->ordering, t->factor, t->lanczos, t->eig_passes,
           (long long)t->solves, t->sturm, t->residuals, t->constraint, t->projection,
           t->reduced_eig, t_write);
  if (cb->nd > 0) {
    fmbd_log(FMBD_LOG_INFO,
             "modes: %.6g .. %.6g Hz, largest residual %.2g; Sturm count %lld "
             "below %.6g Hz",
             sqrt(cb->kappa[0]) / (2 * M_PI), sqrt(cb->kappa[cb->nd - 1]) / (2 * M_PI),
             cb->max_residual, (long long)cb->sturm_count,
             isnan(cb->sturm_shift) ? NAN : sqrt(fabs(cb->sturm_shift)) / (2 * M_PI));
  }
}

int main(int argc, char **argv) {
  fmbd_cli_init("fe2cb", argc, argv);
  args a;
  memset(&a, 0, sizeof a);
  fmbd_cb_opts_defaults(&a.cb);
  int st = parse_args(argc, argv, &a);
  if (st != 0) {
    fmbd_cli_names_free(&a.groups);
    return fmbd_cli_finish(st < 0 ? 0 : st);
  }
  fmbd_cli_set_verbosity(a.quiet, a.verbose);
  // the large blocks' pages reused from one stage to the next instead of unmapped and faulted
  // again (fmbd_alloc_pool, bounded by the peak the run's memory has reached: bench/README.md
  // "The large blocks' pages"); FMBD_POOL=0 leaves it off (side-by-side runs)
  const char *pool_env = getenv("FMBD_POOL");
  if (!(pool_env && !strcmp(pool_env, "0"))) fmbd_alloc_pool((size_t)1 << 20, SIZE_MAX);

  int rc = FMBD_OK;
  fmbd_h5 *in = NULL, *out = NULL;
  fmbd_fe_body *body = NULL;
  fmbd_cb *cb = NULL;
  int64_t nb = 0, *boundary = NULL;
  char *oname = NULL;
  static const char *const strip[] = {".fe.h5", ".h5", NULL};

  // --- read and check the body ---
  double t0 = fmbd_wall_s();
  FMBD_GCALL(fmbd_cli_output_name(a.input, a.output, strip, ".cb.h5", &oname));
  FMBD_GCALL(fmbd_h5_open(a.input, &in));
  fmbd_err_context(a.input, "/");
  FMBD_GCALL(fmbd_h5_check_format(in, FMBD_FE_FORMAT, FMBD_FE_FORMAT_MAJOR));
  FMBD_GCALL(fmbd_fe_read(in, &body));
  fmbd_err_context(a.input, "");
  FMBD_GCALL(fmbd_cb_check_body(body, a.cb.sym_rtol));
  fmbd_err_context(a.input, "/interfaces");
  FMBD_GCALL(
      fmbd_cb_boundary(body, a.groups.n, (const char *const *)a.groups.name, &nb, &boundary));
  double t_read = fmbd_wall_s() - t0;
  fmbd_log(FMBD_LOG_DEBUG, "peak memory after reading: %.0f MB", peak_mb());
  if (nb == 0 && !(a.cb.nm && !a.cb.hold)) {
    fmbd_log(FMBD_LOG_WARN,
             "%s: no interface and no --boundary group: the fixed-interface modes "
             "are the body's own (it must be clamped)",
             a.input);
  }

  // --- reduce ---
  fmbd_err_context(a.input, "");
  // the body's K and M are handed over: freed once the blocks are extracted (peak memory)
  FMBD_GCALL(fmbd_cb_reduce_take(&body->K, &body->M, body->dofs, nb, boundary, &a.cb, &cb));
  fmbd_progress(NULL);
  fmbd_log(FMBD_LOG_DEBUG, "peak memory after the reduction: %.0f MB", peak_mb());
  {
    fmbd_alloc_pool_stats ps;
    fmbd_alloc_pool_get_stats(&ps);
    fmbd_log(FMBD_LOG_DEBUG,
             "large blocks: %lld, %.0f MB of their pages reused, %.0f MB fresh; %.0f MB given "
             "back, %.0f MB kept (%.0f MB resident)",
             (long long)ps.blocks, ps.reused_bytes / 1048576.0, ps.fresh_bytes / 1048576.0,
             ps.unmapped_bytes / 1048576.0, ps.kept_bytes / 1048576.0,
             ps.kept_resident_bytes / 1048576.0);
  }
  cb->fe_file = fmbd_strdup(strcmp(a.input, "-") ? a.input : "(stdin)");
  snprintf(cb->fe_sha256, sizeof cb->fe_sha256, "%s", fmbd_h5_sha256(in));

  // --- write ---
  double t1 = fmbd_wall_s();
  fmbd_err_context(oname, "");
  FMBD_GCALL(fmbd_h5_create(oname, FMBD_CB_FORMAT, FMBD_CB_FORMAT_VERSION, &out));
  FMBD_GCALL(fmbd_h5_add_input(out, cb->fe_file, fmbd_h5_sha256(in)));
  FMBD_GCALL(fmbd_fe_copy_description(in, out));
  FMBD_GCALL(fmbd_cb_write(out, cb));
  FMBD_GCALL(fmbd_h5_commit(&out, fmbd_cli_wall_s(), fmbd_cli_cpu_s()));
  double t_write = fmbd_wall_s() - t1;
  if (fmbd_log_level() >= FMBD_LOG_INFO) breakdown(cb, t_read, t_write);
  residual_warning(cb);
  const char *shown = strcmp(oname, "-") ? oname : "(stdout)";
  if (!strcmp(cb->method, "cb")) {
    fmbd_cli_summary("%s: %lld fixed-interface + %lld constraint modes", shown, (long long)cb->nd,
                     (long long)cb->nb);
  } else {
    fmbd_cli_summary("%s: %lld %s normal modes%s", shown, (long long)cb->nd,
                     cb->nheld ? "held-interface" : "free-free", "");
  }
done:
  fmbd_progress(NULL);
  fmbd_h5_close(&out);  // an uncommitted write handle is discarded: no output left
  fmbd_h5_close(&in);
  fmbd_fe_body_destroy(&body);
  fmbd_cb_destroy(&cb);
  fmbd_free(boundary);
  fmbd_free(oname);
  fmbd_cli_names_free(&a.groups);
  return fmbd_cli_finish(rc);
}
