// fe2cb-mpi/main.c: fe2cb's Craig-Bampton reduction on several MPI processes (PETSc, SLEPc,
// MUMPS): BODY.fe.h5 -> BODY.cb.h5, the same file as the serial fe2cb's. See docs/SCALE.md and
// docs/man/fe2cb-mpi.1.
// SPDX-License-Identifier: MIT
//
// A separate program, not a build variant of fe2cb: the serial fe2cb stays free of MPI (it
// runs without mpirun, links no MPI library, and keeps its ARPACK/CHOLMOD path and its own
// options); this one links PETSc/SLEPc and is built only where they are installed. The numerics
// of the distributed part are in mpi/fmbd_slepc.c; reading, the boundary, the reduced problem
// and the file are the library's (fmbd_fe_read, fmbd_cb_boundary, fmbd_cb_update_reduced,
// fmbd_cb_write).
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
#include "fmbd_slepc.h"

static const char *usage_text =
    "Usage: mpirun -np N fe2cb-mpi BODY.fe.h5 [-o BODY.cb.h5] [--modes N]\n"
    "                  [--boundary GROUP,...] [--no-sturm]\n"
    "fe2cb's Craig-Bampton reduction with the body's interior matrices distributed over the MPI\n"
    "processes: fixed-interface modes by SLEPc Krylov-Schur with shift-and-invert at 0, the\n"
    "factor of Ks by MUMPS (parallel Cholesky), constraint modes and projections with the same\n"
    "factor, a Sturm count by the inertia of Ks - s Ms. Process 0 writes the same fmbd-cb file\n"
    "as fe2cb. Runs without mpirun too (one process).\n"
    "\n"
    "BODY.fe.h5  an fmbd-fe file (mesh2fe): every process reads its description and its own\n"
    "            row block of /K and /M\n"
    "\n"
    "Options:\n"
    "  -o FILE            output. Default: BODY with .fe.h5 replaced by .cb.h5\n"
    "  --modes N          number of fixed-interface modes (default 20, at least 1)\n"
    "  --boundary G,...   more boundary nodes: every active dof of the named mesh groups\n"
    "                     (or interfaces) joins the interface dofs on the boundary\n"
    "  --no-sturm         skip the Sturm count (one more parallel LDL' factorisation)\n"
    "  -q, --quiet        errors only\n"
    "  -v, --verbose      where the time went and the memory of each process\n"
    "  -h, --help         this help\n"
    "  -V, --version      the version\n"
    "fe2cb's --fmax, --method nm and --hold are not offered here (use fe2cb). PETSc and SLEPc\n"
    "options (e.g. -eps_view, -log_view) go in the environment variable PETSC_OPTIONS.\n"
    "\n"
    "Example:\n"
    "  mpirun -np 2 fe2cb-mpi rod.fe.h5 --modes 24 -o rod.cb.h5\n";

typedef struct args {
  const char *input, *output;
  fmbd_slepc_opts o;
  fmbd_cli_names groups;  ///< --boundary
  int quiet, verbose;
} args;

enum { OPT_OUTPUT = 1, OPT_MODES, OPT_BOUNDARY, OPT_NO_STURM, OPT_SERIAL_ONLY };
static const fmbd_cli_option options[] = {
    {"--output", 'o', true, OPT_OUTPUT},   {"--modes", 0, true, OPT_MODES},
    {"--boundary", 0, true, OPT_BOUNDARY}, {"--no-sturm", 0, false, OPT_NO_STURM},
    {"--fmax", 0, true, OPT_SERIAL_ONLY},  {"--method", 0, true, OPT_SERIAL_ONLY},
    {"--hold", 0, false, OPT_SERIAL_ONLY}, {0}};

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
        if (fmbd_cli_long(&p, 1, LONG_MAX, &n)) return p.status;
        a->o.nmodes = n;
        break;
      }
      case OPT_BOUNDARY: {
        int st = fmbd_cli_names_parse("--boundary", val, &a->groups);
        if (st) return st;
        break;
      }
      case OPT_NO_STURM:
        a->o.sturm = false;
        break;
      case OPT_SERIAL_ONLY:
        return fmbd_cli_usage_error("%s is fe2cb's: fe2cb-mpi computes --modes N (method cb)",
                                    p.opt);
    }
  }
  a->quiet = p.quiet;
  a->verbose = p.verbose;
  if (!a->input) return fmbd_cli_usage_error("no BODY.fe.h5 given");
  if (!strcmp(a->input, "-")) return fmbd_cli_usage_error("every process reads BODY.fe.h5: no '-'");
  if (a->output && !strcmp(a->output, "-")) {
    return fmbd_cli_usage_error("-o -: fe2cb-mpi writes a file, not standard output");
  }
  return 0;
}

int main(int argc, char **argv) {
  fmbd_cli_init("fe2cb-mpi", argc, argv);
  args a;
  memset(&a, 0, sizeof a);
  fmbd_slepc_defaults(&a.o);
  // options first (every process the same; usage errors before MPI starts)
  int st = parse_args(argc, argv, &a);
  if (st != 0) {
    fmbd_cli_names_free(&a.groups);
    return fmbd_cli_finish(st < 0 ? 0 : st);
  }
  int rc = fmbd_slepc_init();
  if (rc) return fmbd_cli_finish(rc);
  const int rank = fmbd_slepc_rank(), nproc = fmbd_slepc_size();
  // only process 0 speaks (others: errors of their own only)
  if (rank == 0) {
    fmbd_cli_set_verbosity(a.quiet, a.verbose);
  } else {
    fmbd_cli_set_verbosity(1, 0);
  }

  fmbd_h5 *in = NULL, *out = NULL;
  fmbd_fe_body *body = NULL;
  fmbd_cb *cb = NULL;
  int64_t nb = 0, *boundary = NULL;
  char *oname = NULL;
  fmbd_slepc_timing tm;
  memset(&tm, 0, sizeof tm);
  static const char *const strip[] = {".fe.h5", ".h5", NULL};

  // --- read and check the body (every process) ---
  double t0 = fmbd_wall_s(), t_read = 0.0;
  FMBD_GCALL(fmbd_cli_output_name(a.input, a.output, strip, ".cb.h5", &oname));
  FMBD_GCALL(fmbd_h5_open(a.input, &in));
  fmbd_err_context(a.input, "/");
  FMBD_GCALL(fmbd_h5_check_format(in, FMBD_FE_FORMAT, FMBD_FE_FORMAT_MAJOR));
  // the description only: each process reads its own row block of /K and /M in the reduction
  FMBD_GCALL(fmbd_fe_read_description(in, &body));
  fmbd_err_context(a.input, "");
  fmbd_err_context(a.input, "/interfaces");
  FMBD_GCALL(
      fmbd_cb_boundary(body, a.groups.n, (const char *const *)a.groups.name, &nb, &boundary));
  if (nb == 0) {
    fmbd_log(FMBD_LOG_WARN,
             "%s: no interface and no --boundary group: the fixed-interface modes "
             "are the body's own (it must be clamped)",
             a.input);
  }
  fmbd_err_context(a.input, "");
  t_read = fmbd_wall_s() - t0;
done:
  rc = fmbd_slepc_agree(rc);  // a failed read anywhere stops every process here
  if (rc) goto finish;

  // --- reduce (collective) ---
  fmbd_err_context(a.input, "");
  rc = fmbd_slepc_cb_reduce(in, body->ndof, nb, boundary, &a.o, &cb, &tm);
  if (rc) goto finish;
  double mine = 0, largest = 0;
  fmbd_slepc_peak_mb(&mine, &largest);

  // --- write (process 0) ---
  if (rank == 0) {
    double t1 = fmbd_wall_s();
    cb->fe_file = fmbd_strdup(a.input);
    snprintf(cb->fe_sha256, sizeof cb->fe_sha256, "%s", fmbd_h5_sha256(in));
    fmbd_err_context(oname, "");
    rc = fmbd_h5_create(oname, FMBD_CB_FORMAT, FMBD_CB_FORMAT_VERSION, &out);
    if (!rc) rc = fmbd_h5_add_input(out, cb->fe_file, fmbd_h5_sha256(in));
    if (!rc) rc = fmbd_fe_copy_description(in, out);
    if (!rc) rc = fmbd_cb_write(out, cb);
    if (!rc) rc = fmbd_h5_commit(&out, fmbd_cli_wall_s(), fmbd_cli_cpu_s());
    double t_write = fmbd_wall_s() - t1;
    if (!rc) {
      fmbd_log(FMBD_LOG_INFO,
               "%d processes, %lld dofs: %lld interior, %lld boundary; MUMPS factor of Ks: "
               "%.4g entries, %.4g flops, %.0f MB on the largest process, %.0f MB in all",
               nproc, (long long)cb->ndof, (long long)cb->ns, (long long)cb->nb, tm.factor_entries,
               tm.factor_flops, tm.factor_mb_max, tm.factor_mb_sum);
      fmbd_log(
          FMBD_LOG_INFO,
          "time: read %.3g s, distribution %.3g s, MUMPS factorisation %.3g s (cpu %.3g s), "
          "Krylov-Schur %.3g s (%lld restarts, %lld converged), modes gathered %.3g s, "
          "constraint modes and projections %.3g s (cpu %.3g s, %lld solves), Sturm count %.3g s, "
          "reduced problem %.3g s, write %.3g s; %lld solves with the factor in all",
          t_read, tm.distribute, tm.factor, tm.factor_cpu, tm.modes, (long long)tm.its,
          (long long)tm.nconv, tm.gather, tm.constraint, tm.constraint_cpu, (long long)(3 * cb->nb),
          tm.sturm, tm.reduced, t_write, (long long)tm.solves);
      fmbd_log(FMBD_LOG_INFO,
               "modes: %.6g .. %.6g Hz, largest residual %.2g; Sturm count %lld below %.6g Hz; "
               "peak memory: process 0 %.0f MB, largest process %.0f MB (%.0f MB once the "
               "rows were distributed)",
               sqrt(cb->kappa[0]) / (2 * M_PI), sqrt(cb->kappa[cb->nd - 1]) / (2 * M_PI),
               cb->max_residual, (long long)cb->sturm_count,
               isnan(cb->sturm_shift) ? NAN : sqrt(fabs(cb->sturm_shift)) / (2 * M_PI), mine,
               largest, tm.read_peak_mb);
      fmbd_cli_summary("%s: %lld fixed-interface + %lld constraint modes (%d processes)", oname,
                       (long long)cb->nd, (long long)cb->nb, nproc);
    }
  }
  rc = fmbd_slepc_agree(rc);

finish:
  fmbd_h5_close(&out);  // an uncommitted write handle is discarded: no output left
  fmbd_h5_close(&in);
  fmbd_fe_body_destroy(&body);
  fmbd_cb_destroy(&cb);
  fmbd_free(boundary);
  fmbd_free(oname);
  fmbd_cli_names_free(&a.groups);
  fmbd_slepc_finalize();
  if (rank != 0) return fmbd_err_exit_status(rc);  // process 0 reports (PETSc: every one)
  return fmbd_cli_finish(rc);
}
