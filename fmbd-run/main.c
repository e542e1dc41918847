// fmbd-run/main.c: simulate a scene of rigid and reduced flexible bodies (docs/SCENE.md)
// SPDX-License-Identifier: MIT
//
//   fmbd-run SCENE [-o RUN.h5] [--reference REF.run.h5 [--window T0:T1]] [--plot PREFIX] [-M]
//
// A thin command line: the scene (common/fmbd_scene) becomes a multibody model
// (common/fmbd_scene_build, common/fmbd_mbs), which is integrated while its outputs go to the
// run file (common/fmbd_runfile: buffered series, statistics, the valid prefix of an
// interrupted run, the comparison with a reference run). See docs/man/fmbd-run.1.
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmbd_alloc.h"
#include "fmbd_cli.h"
#include "fmbd_err.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"
#include "fmbd_runfile.h"
#include "fmbd_scene.h"
#include "fmbd_scene_build.h"
#include "fmbd_scene_record.h"

static const char *usage_text =
    "Usage: fmbd-run SCENE [-o RUN.h5] [--reference REF.run.h5 [--window T0:T1]]\n"
    "                [--plot PREFIX] [--xdmf] [--t-end T] [--body-dir DIR] [-M] [-q] [-v]\n"
    "Simulate the mechanism of a scene file (YAML, docs/SCENE.md): rigid bodies, reduced\n"
    "flexible bodies (.rflex.h5, .cb.h5) and full FE bodies (.fe.h5) in the floating frame of\n"
    "reference, joints, drivers, loads, gravity; index-3 generalized-alpha with step-size\n"
    "control. Writes the run file (format fmbd-run, docs/FORMAT.md) as the run goes.\n\n"
    "  -o, --output RUN.h5     the run file (default: SCENE with .run.h5, or standard output\n"
    "                          when it is not a terminal; '-' = standard output)\n"
    "      --reference REF     the RMS and the largest error of every point output series\n"
    "                          this run shares with the run file REF (position, velocity,\n"
    "                          acceleration, stress, strain; docs/THEORY.md section 7),\n"
    "                          written to /reference and printed as a table\n"
    "      --window T0:T1      with --reference: the errors over T0 <= t <= T1 only (chaotic\n"
    "                          motion: before the trajectories separate)\n"
    "      --plot PREFIX       SVG plots PREFIX<output>-position.svg and -trajectory.svg\n"
    "      --xdmf              RUN.xdmf beside RUN.h5 (.h5 replaced): the deformed flexible\n"
    "                          bodies at every output instant, coloured by von Mises stress,\n"
    "                          for ParaView (fields in /fields of the run file)\n"
    "      --t-end T           end the run at T seconds instead of the scene's t_end\n"
    "      --body-dir DIR      body files (and the fe/cb files of -M rules) in DIR instead of\n"
    "                          the scene's folder (the geometry stays beside the scene)\n"
    "  -M                      print the make rules of the files the scene needs and exit\n"
    "  -q, --quiet             errors only\n"
    "  -v, --verbose           progress, details (-vv: debug); in a file: cost every 5 %\n"
    "  -h, --help              this help\n"
    "  -V, --version           the version\n\n"
    "An interrupted run (SIGINT, SIGTERM, SIGHUP, no Newton convergence at the smallest step)\n"
    "keeps its valid prefix in RUN.h5.part with /stats attribute complete = 0, and exits 1.\n";

typedef struct run {
  const fmbd_scene *s;
  fmbd_scene_recorder *rec;
  double last_progress_s, t0_wall, t0_cpu;
  int log_k;  // progress lines logged (-v without a terminal): one every 5 % of t_end
} run;

// A run stopped at a singular position names the joints and drivers whose equations are
// dependent: the scene line of the first driver named (the motion that drove it there), else of
// the first joint named; 0 when the message is not about a singular position.
static int singular_line(const fmbd_scene *s, const char *msg) {
  if (!strstr(msg, "constraints are singular")) return 0;
  const char *d = strstr(msg, " driver"), *j = strstr(msg, " joint");
  char q[300];
  for (int i = 0; d && i < s->ndrivers; i++) {
    snprintf(q, sizeof q, "'%s'", s->drivers[i].name);
    if (strstr(d, q)) return s->drivers[i].loc.line;
  }
  const char *best = NULL;
  int line = 0;
  for (int i = 0; j && i < s->njoints; i++) {
    snprintf(q, sizeof q, "'%s'", s->joints[i].name);
    const char *at = strstr(j, q);
    if (at && (!best || at < best)) best = at, line = s->joints[i].loc.line;
  }
  return line;
}

static int on_step(fmbd_mbs *mb, bool at_output, void *user) {
  run *r = user;
  if (at_output) FMBD_CALL(fmbd_scene_record(r->rec));
  double now = fmbd_wall_s();
  if (fmbd_progress_enabled() && now - r->last_progress_s > 0.25) {
    fmbd_mbs_stats st;
    fmbd_mbs_get_stats(mb, &st);
    double t = fmbd_mbs_time(mb), el = now - r->t0_wall;
    fmbd_progress("t = %.4f s (%3.0f%%), h = %.2e s, %lld steps, %.0f steps/s, %.2fx real time", t,
                  100 * t / r->s->solver.t_end, st.h_last, (long long)st.steps,
                  el > 0 ? st.steps / el : 0, el > 0 ? t / el : 0);
    r->last_progress_s = now;
  } else if (!fmbd_progress_enabled() && fmbd_log_level() >= FMBD_LOG_INFO &&
             fmbd_mbs_time(mb) >= (r->log_k + 1) * 0.05 * r->s->solver.t_end * (1 - 1e-12)) {
    // -v into a file (no terminal for the progress line): the cost so far, 20 lines a run
    fmbd_mbs_stats st;
    fmbd_mbs_get_stats(mb, &st);
    fmbd_log(FMBD_LOG_INFO,
             "t = %.6g s: %lld steps (%lld rejected), %lld Newton iterations, %lld "
             "factorisations, h = %.3g s, CPU %.2f s",
             fmbd_mbs_time(mb), (long long)st.steps, (long long)st.rejected,
             (long long)st.newton_iterations, (long long)st.factorizations, st.h_last,
             fmbd_cpu_s() - r->t0_cpu);
    while (fmbd_mbs_time(mb) >= (r->log_k + 1) * 0.05 * r->s->solver.t_end * (1 - 1e-12))
      r->log_k++;
  }
  return fmbd_runfile_signal() ? 2 : 0;  // stop: the caller reports the interruption
}

int main(int argc, char **argv) {
  fmbd_cli_init("fmbd-run", argc, argv);
  int rc = 0;
  bool make_rules = false, xdmf = false;
  const char *opt_o = NULL, *ref = NULL, *plot = NULL, *body_dir = NULL, *scene_file = NULL;
  double t_end = 0, window[2] = {NAN, NAN};
  char *out_name = NULL, *rules = NULL, *xdmf_name = NULL;
  fmbd_scene *s = NULL;
  fmbd_scene_model *m = NULL;
  run r = {0};
  fmbd_runfile *rf = NULL;
  enum {
    OPT_OUTPUT = 1,
    OPT_REFERENCE,
    OPT_WINDOW,
    OPT_PLOT,
    OPT_XDMF,
    OPT_T_END,
    OPT_BODY_DIR,
    OPT_RULES
  };
  static const fmbd_cli_option options[] = {{"--output", 'o', true, OPT_OUTPUT},
                                            {"--reference", 0, true, OPT_REFERENCE},
                                            {"--window", 0, true, OPT_WINDOW},
                                            {"--plot", 0, true, OPT_PLOT},
                                            {"--xdmf", 0, false, OPT_XDMF},
                                            {"--t-end", 0, true, OPT_T_END},
                                            {"--body-dir", 0, true, OPT_BODY_DIR},
                                            {NULL, 'M', false, OPT_RULES},
                                            {0}};
  fmbd_cli_args p;
  fmbd_cli_args_init(&p, argc, argv, options, usage_text);
  for (int id; (id = fmbd_cli_next(&p)) != FMBD_CLI_END;) {
    switch (id) {
      case FMBD_CLI_EXIT:
        return fmbd_cli_finish(p.status);
      case FMBD_CLI_ARG:
        if (scene_file) {
          return fmbd_cli_finish(
              fmbd_cli_usage_error("one scene file, not '%s' and '%s'", scene_file, p.value));
        }
        scene_file = p.value;
        break;
      case OPT_OUTPUT:
        opt_o = p.value;
        break;
      case OPT_REFERENCE:
        ref = p.value;
        break;
      case OPT_WINDOW:
        if (fmbd_cli_numbers(p.opt, p.value, 2, ':', window)) return fmbd_cli_finish(2);
        if (!(window[0] < window[1])) {
          return fmbd_cli_finish(
              fmbd_cli_usage_error("option --window: '%s': T0 must be below T1", p.value));
        }
        break;
      case OPT_PLOT:
        plot = p.value;
        break;
      case OPT_XDMF:
        xdmf = true;
        break;
      case OPT_T_END:
        if (fmbd_cli_double(&p, 0, INFINITY, FMBD_CLI_OPEN_LO, &t_end)) return fmbd_cli_finish(2);
        break;
      case OPT_BODY_DIR:
        body_dir = p.value;
        break;
      case OPT_RULES:
        make_rules = true;
        break;
    }
  }
  fmbd_cli_set_verbosity(p.quiet, p.verbose);
  if (!scene_file) return fmbd_cli_finish(fmbd_cli_usage_error("no scene file given"));
  if (!isnan(window[0]) && !ref) {
    return fmbd_cli_finish(fmbd_cli_usage_error("--window needs --reference"));
  }
  FMBD_GCALL(fmbd_scene_read_dir(scene_file, body_dir, &s));
  if (t_end > 0) s->solver.t_end = t_end;

  // --- -M: make rules (the derived name even when standard output is a pipe: the rules go there)
  static const char *const strip[] = {".yaml", ".yml", NULL};
  if (make_rules) {
    if (opt_o) {
      FMBD_GALLOC(out_name = fmbd_strdup(opt_o));
    } else {
      FMBD_GCALL(fmbd_cli_derive_name(scene_file, strip, ".run.h5", &out_name));
    }
    FMBD_GCALL(fmbd_scene_make_rules(s, out_name, &rules));
    fputs(rules, stdout);
    goto done;
  }
  FMBD_GCALL(fmbd_cli_output_name(scene_file, opt_o, strip, ".run.h5", &out_name));
  FMBD_GCALL(fmbd_cli_check_not_input(out_name, ref));
  if (ref) FMBD_GCALL(fmbd_runfile_check_reference(ref));  // before the work
  if (xdmf) {
    static const char *const h5[] = {".h5", NULL};
    FMBD_GCHECK(strcmp(out_name, "-"), FMBD_ERR_USAGE,
                "--xdmf needs a named run file beside it, not standard output: give -o RUN.h5");
    FMBD_GCALL(fmbd_cli_derive_name(out_name, h5, ".xdmf", &xdmf_name));
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
    // a fixed step that does not divide outputs.every: each output interval ends with a shorter
    // step (fmbd_mbs_step lands on the instants), and every change of step costs accuracy and
    // Newton iterations (the quadruple pendulum at 1.5e-3 s, every 0.014 s: node A 2.6e-3 m, 37
    // steps rejected; every 0.042 s: 5.4e-4 m, none; bench/README.md, "Fixed steps and the
    // output interval")
    const double ratio = s->solver.fixed ? s->solver.output_every / s->solver.step : 0;
    if (ratio > 1 && fabs(ratio - nearbyint(ratio)) > 1e-6 * ratio) {
      fmbd_log(FMBD_LOG_WARN,
               "%s: the fixed step %g s does not divide outputs.every %g s: each output "
               "interval ends with a step of %.3g s, and each change of step costs accuracy and "
               "Newton iterations; give every as a multiple of step (or step as every / n)",
               scene_file, s->solver.step, s->solver.output_every,
               s->solver.output_every - floor(ratio) * s->solver.step);
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
  fmbd_mbs_stats st;
  fmbd_mbs_get_stats(m->mbs, &st);
  fmbd_log(FMBD_LOG_INFO,
           "%s: %d bodies, %lld coordinates, %lld constraint equations (%lld redundant removed)",
           scene_file, s->nbodies, (long long)st.coordinates, (long long)st.equations,
           (long long)st.redundant);

  // --- the run file -------------------------------------------------------------------------
  for (int i = 0; i < m->ninputs; i++)
    FMBD_GCALL(fmbd_cli_check_not_input(out_name, m->input_name[i]));
  r.s = s;
  FMBD_GCALL(fmbd_runfile_create(out_name, plot || ref, &rf));
  FMBD_GCALL(fmbd_runfile_scene(rf, scene_file, s->title, s->text, s->solver.t_end));
  for (int i = 0; i < m->ninputs; i++)
    FMBD_GCALL(fmbd_h5_add_input(fmbd_runfile_h5(rf), m->input_name[i], m->input_sha[i]));
  FMBD_GCALL(fmbd_scene_recorder_create(s, m, rf, xdmf_name, &r.rec));

  // --- run ------------------------------------------------------------------------------------
  fmbd_runfile_catch_signals();
  fmbd_runfile_start_clock(rf);
  r.t0_wall = fmbd_wall_s();
  double c0 = fmbd_cpu_s();
  r.t0_cpu = c0;
  FMBD_GCALL(fmbd_scene_record(r.rec));  // the initial (consistent) state
  rc = fmbd_mbs_run(m->mbs, on_step, &r);
  fmbd_progress(NULL);
  double t_stop = fmbd_mbs_time(m->mbs);
  if (rc == 2 && fmbd_runfile_signal()) {
    fmbd_err_context(out_name, "");
    fmbd_err_set(FMBD_ERR_IO, __FILE__, __LINE__, __func__, "interrupted by signal %d at t = %g s",
                 fmbd_runfile_signal(), t_stop);
    rc = FMBD_ERR_IO;
    fmbd_runfile_abandon(&rf, t_stop);
  } else if (rc == FMBD_ERR_CONVERGE || rc == FMBD_ERR_SINGULAR) {
    fmbd_err_context(scene_file, "");  // a failure on the way: keep the prefix computed so far
    int line = singular_line(s, fmbd_err_get()->msg);
    if (line > 0) fmbd_err_contextf(scene_file, "%d", line);
    fmbd_runfile_abandon(&rf, t_stop);
  }
  if (rc) goto done;
  double run_cpu = fmbd_cpu_s() - c0;
  FMBD_GCALL(fmbd_runfile_finish(rf));
  if (ref) FMBD_GCALL(fmbd_runfile_compare(rf, ref, window[0], window[1], NULL, NULL));
  for (int o = 0; plot && o < s->noutputs; o++) {
    int id = fmbd_scene_recorder_position(r.rec, o);
    if (id < 0) continue;
    FMBD_GCALL(fmbd_runfile_plot_position(rf, id, plot, s->outputs[o].name,
                                          s->title ? s->title : s->file));
  }
  int64_t rows = fmbd_runfile_rows(rf);
  FMBD_GCALL(fmbd_runfile_commit(&rf));
  FMBD_GCALL(fmbd_scene_recorder_commit(r.rec));
  fmbd_mbs_get_stats(m->mbs, &st);
  fmbd_log(FMBD_LOG_INFO,
           "CPU of the Newton iterations: %.3g s in %lld factorisations, %.3g s in %lld solves, "
           "%.3g s in the system evaluation and updates (of %.3g s for the time integration)",
           st.factor_cpu_s, (long long)st.factorizations, st.solve_cpu_s,
           (long long)st.newton_iterations, st.eval_cpu_s, run_cpu);
  fmbd_cli_summary(
      "%s: %lld steps, %lld rejected, %lld Newton iterations, %lld rows to t = %g s (%.3gx real "
      "time on CPU time)",
      strcmp(out_name, "-") ? out_name : "standard output", (long long)st.steps,
      (long long)st.rejected, (long long)st.newton_iterations, (long long)rows, t_stop,
      run_cpu > 0 ? t_stop / run_cpu : INFINITY);
done:
  fmbd_runfile_close(&rf);  // a failure before the run's end: no target
  fmbd_scene_recorder_destroy(&r.rec);
  fmbd_free(xdmf_name);
  fmbd_scene_model_destroy(&m);
  fmbd_scene_destroy(&s);
  fmbd_free(out_name);
  fmbd_free(rules);
  return fmbd_cli_finish(rc);
}
