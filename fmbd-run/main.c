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
#include "fmbd_xdmf.h"

static const char *usage_text =
    "Usage: fmbd-run SCENE [-o RUN.h5] [--reference REF.run.h5 [--window T0:T1]]\n"
    "                [--plot PREFIX] [--xdmf] [--t-end T] [--body-dir DIR] [-M] [-q] [-v]\n"
    "Simulate the mechanism of a scene file (YAML, docs/SCENE.md): rigid and reduced flexible\n"
    "bodies (.rflex.h5, .cb.h5) in the floating frame of reference, joints, drivers, loads,\n"
    "gravity; index-3 generalized-alpha with step-size control. Writes the run file\n"
    "(format fmbd-run, docs/FORMAT.md) as the run goes.\n\n"
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
    "  -v, --verbose           progress and details (-vv: debug)\n"
    "  -h, --help              this help\n"
    "  -V, --version           the version\n\n"
    "An interrupted run (SIGINT, SIGTERM, SIGHUP, no Newton convergence at the smallest step)\n"
    "keeps its valid prefix in RUN.h5.part with /stats attribute complete = 0, and exits 1.\n";

// The series of each point output, by quantity (FMBD_OUT_* bit order), and their units.
enum { Q_POS, Q_VEL, Q_ACC, Q_VM, Q_STRESS, Q_STRAIN, Q_VMSTRAIN, NQ };
static const char *const q_name[NQ] = {"position", "velocity", "acceleration",    "von_mises",
                                       "stress",   "strain",   "von_mises_strain"};
static const int q_cols[NQ] = {3, 3, 3, 0, 6, 6, 0};
static const char *const q_unit[NQ] = {"m", "m/s", "m/s^2", "Pa", "Pa", "1", "1"};

typedef struct run {
  const fmbd_scene *s;
  fmbd_scene_model *m;
  fmbd_runfile *rf;
  int (*out)[NQ];  // per output: series id, -1 when not asked
  int energy[3], momentum[2];
  int (*react)[2];  // per reaction: force, torque
  double last_progress_s, t0_wall;
  fmbd_xdmf *xdmf;  // --xdmf: the fields of the flexible bodies
  int nx, *xbody;   // their mbs body ids
} run;

static void get_stats(void *user, fmbd_runfile_stats *st) {
  const run *r = user;
  fmbd_mbs_stats ms;
  fmbd_mbs_get_stats(r->m->mbs, &ms);
  *st = (fmbd_runfile_stats){.steps = ms.steps,
                             .rejected_steps = ms.rejected,
                             .newton_iterations = ms.newton_iterations,
                             .factorizations = ms.factorizations,
                             .coordinates = ms.coordinates,
                             .equations = ms.equations,
                             .redundant_equations = ms.redundant,
                             .t_reached = fmbd_mbs_time(r->m->mbs),
                             .last_step_s = ms.h_last};
}

// The run file's series, in the order of docs/FORMAT.md.
static int declare(run *r) {
  const fmbd_scene *s = r->s;
  fmbd_h5 *f = fmbd_runfile_h5(r->rf);
  char path[600];
  for (int o = 0; o < s->noutputs; o++) {
    const fmbd_scene_output *op = &s->outputs[o];
    snprintf(path, sizeof path, "/outputs/%s", op->name);
    FMBD_CALL(fmbd_h5_make_group(f, path));
    FMBD_CALL(fmbd_h5_write_attr_str(f, path, "body", s->bodies[op->body].name));
    FMBD_CALL(fmbd_h5_write_attr_i64(f, path, "node", 1, &r->m->out_node[o]));
    for (int q = 0; q < NQ; q++) {
      unsigned bit = q == Q_VMSTRAIN ? FMBD_OUT_STRAIN : 1u << q;
      r->out[o][q] = -1;
      if (!(op->quantities & bit)) continue;
      snprintf(path, sizeof path, "/outputs/%s/%s", op->name, q_name[q]);
      FMBD_CALL(fmbd_runfile_series(r->rf, path, q_cols[q], q_unit[q], FMBD_RUNFILE_COMPARED,
                                    &r->out[o][q]));
    }
  }
  if (s->energy) {
    static const char *const en[3] = {"/energy/kinetic", "/energy/potential", "/energy/strain"};
    for (int k = 0; k < 3; k++)
      FMBD_CALL(fmbd_runfile_series(r->rf, en[k], 0, "J", 0, &r->energy[k]));
  }
  if (s->momentum) {
    FMBD_CALL(fmbd_runfile_series(r->rf, "/momentum/linear", 3, "N s", 0, &r->momentum[0]));
    FMBD_CALL(fmbd_runfile_series(r->rf, "/momentum/angular", 3, "N m s", 0, &r->momentum[1]));
  }
  for (int k = 0; k < s->nreactions; k++) {
    const char *jn = s->joints[s->reactions[k]].name;
    snprintf(path, sizeof path, "/reactions/%s/force", jn);
    FMBD_CALL(fmbd_runfile_series(r->rf, path, 3, "N", 0, &r->react[k][0]));
    snprintf(path, sizeof path, "/reactions/%s/torque", jn);
    FMBD_CALL(fmbd_runfile_series(r->rf, path, 3, "N m", 0, &r->react[k][1]));
  }
  return FMBD_OK;
}

// One output row: time, the asked quantities, energies, momenta, reactions.
static int record(run *r) {
  const fmbd_scene *s = r->s;
  fmbd_mbs *mb = r->m->mbs;
  FMBD_CALL(fmbd_runfile_row(r->rf, fmbd_mbs_time(mb)));
  for (int o = 0; o < s->noutputs; o++) {
    const int *id = r->out[o];
    int pid = r->m->out_point[o];
    double v[6], ep[6], vm, ev;
    if (id[Q_POS] >= 0) {
      fmbd_mbs_point_position(mb, pid, v);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_POS], v));
    }
    if (id[Q_VEL] >= 0) {
      fmbd_mbs_point_velocity(mb, pid, v);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_VEL], v));
    }
    if (id[Q_ACC] >= 0) {
      fmbd_mbs_point_acceleration(mb, pid, v);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_ACC], v));
    }
    if (id[Q_VM] < 0 && id[Q_STRESS] < 0 && id[Q_STRAIN] < 0) continue;
    FMBD_CALL(fmbd_scene_output_stress(r->m, o, v));
    if (id[Q_VM] >= 0) {
      vm = fmbd_von_mises(v);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_VM], &vm));
    }
    if (id[Q_STRESS] >= 0) FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_STRESS], v));
    if (id[Q_STRAIN] >= 0) {
      int b = r->m->out_body[o];
      ev = fmbd_scene_strain(r->m->E[b], r->m->nu[b], v, ep);
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_STRAIN], ep));
      FMBD_CALL(fmbd_runfile_put(r->rf, id[Q_VMSTRAIN], &ev));
    }
  }
  if (s->energy) {
    double e[3];
    fmbd_mbs_energy(mb, &e[0], &e[1], &e[2]);
    for (int k = 0; k < 3; k++) FMBD_CALL(fmbd_runfile_put(r->rf, r->energy[k], &e[k]));
  }
  if (s->momentum) {
    double L[3], H[3];
    fmbd_mbs_momentum(mb, L, H);
    FMBD_CALL(fmbd_runfile_put(r->rf, r->momentum[0], L));
    FMBD_CALL(fmbd_runfile_put(r->rf, r->momentum[1], H));
  }
  for (int k = 0; k < s->nreactions; k++) {
    double F[3], T[3];
    FMBD_CALL(fmbd_mbs_joint_reaction(mb, r->m->joint_id[s->reactions[k]], F, T));
    FMBD_CALL(fmbd_runfile_put(r->rf, r->react[k][0], F));
    FMBD_CALL(fmbd_runfile_put(r->rf, r->react[k][1], T));
  }
  if (r->xdmf) {
    double R[64][3], A[64][9];
    const double *Rp[64], *Ap[64], *qp[64];
    for (int i = 0; i < r->nx; i++) {
      fmbd_mbs_body_pose(mb, r->xbody[i], R[i], A[i]);
      fmbd_mbs_modal(mb, r->xbody[i], &qp[i], NULL, NULL);
      Rp[i] = R[i];
      Ap[i] = A[i];
    }
    FMBD_CALL(fmbd_xdmf_frame(r->xdmf, fmbd_mbs_time(mb), Rp, Ap, qp));
  }
  return FMBD_OK;
}

// --xdmf: every flexible body with solid elements, its modal stresses read again (the model
// keeps them only where an output asks).
static int add_fields(run *r, const char *xdmf_name) {
  const fmbd_scene *s = r->s;
  const fmbd_scene_model *m = r->m;
  int rc = FMBD_OK;
  fmbd_h5 *f = NULL;
  fmbd_rflex *rf = NULL;
  FMBD_CALL(fmbd_xdmf_create(r->rf, xdmf_name, &r->xdmf));
  FMBD_GALLOC(r->xbody = fmbd_calloc((size_t)s->nbodies + 1, sizeof(int)));
  for (int b = 0; b < s->nbodies; b++) {
    if (!m->flex[b]) continue;
    const char *file = s->bodies[b].file;
    FMBD_GCALL(fmbd_h5_open(file, &f));
    fmbd_err_context(file, "");
    if (!fmbd_h5_exists(f, "/mesh/elements/tet4") && !fmbd_h5_exists(f, "/mesh/elements/tet10")) {
      fmbd_log(FMBD_LOG_WARN, "--xdmf: body '%s' (%s) has no solid elements: not in the fields",
               s->bodies[b].name, file);
    } else {
      FMBD_GCHECK(r->nx < 64, FMBD_ERR_VALUE, "--xdmf: more than 64 flexible bodies");
      if (!strcmp(m->file_kind[b], FMBD_RFLEX_FORMAT)) {
        FMBD_GCALL(fmbd_rflex_read(f, &rf));
      } else {
        FMBD_GCALL(fmbd_scene_rflex_from_cb(f, true, &rf));
      }
      int id = m->body_id[b];
      FMBD_GCALL(fmbd_xdmf_add_body(r->xdmf, s->bodies[b].name, file, rf, f,
                                    fmbd_mbs_body_nm(m->mbs, id)));
      r->xbody[r->nx++] = id;
      fmbd_rflex_destroy(&rf);
    }
    fmbd_h5_close(&f);
  }
  fmbd_err_context(s->file, "");
  FMBD_GCHECK(r->nx > 0, FMBD_ERR_VALUE,
              "--xdmf: the scene has no flexible body with solid elements");
done:
  fmbd_rflex_destroy(&rf);
  fmbd_h5_close(&f);
  return rc;
}

static int on_step(fmbd_mbs *mb, bool at_output, void *user) {
  run *r = user;
  if (at_output) FMBD_CALL(record(r));
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
  if (ref) FMBD_GCALL(fmbd_runfile_check_reference(ref));  // before the work

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
  r.m = m;
  FMBD_GCALL(fmbd_runfile_create(out_name, plot || ref, &r.rf));
  fmbd_runfile_set_stats(r.rf, get_stats, &r);
  FMBD_GCALL(fmbd_runfile_scene(r.rf, scene_file, s->title, s->text, s->solver.t_end));
  for (int i = 0; i < m->ninputs; i++)
    FMBD_GCALL(fmbd_h5_add_input(fmbd_runfile_h5(r.rf), m->input_name[i], m->input_sha[i]));
  FMBD_GALLOC(r.out = fmbd_calloc((size_t)s->noutputs + 1, sizeof *r.out));
  FMBD_GALLOC(r.react = fmbd_calloc((size_t)s->nreactions + 1, sizeof *r.react));
  FMBD_GCALL(declare(&r));
  if (xdmf) {
    size_t n = strlen(out_name);
    if (n > 3 && !strcmp(out_name + n - 3, ".h5")) n -= 3;
    FMBD_GALLOC(xdmf_name = fmbd_malloc(n + 6));
    memcpy(xdmf_name, out_name, n);
    strcpy(xdmf_name + n, ".xdmf");
    FMBD_GCALL(add_fields(&r, xdmf_name));
  }

  // --- run ------------------------------------------------------------------------------------
  fmbd_runfile_catch_signals();
  fmbd_runfile_start_clock(r.rf);
  r.t0_wall = fmbd_wall_s();
  double c0 = fmbd_cpu_s();
  FMBD_GCALL(record(&r));  // the initial (consistent) state
  rc = fmbd_mbs_run(m->mbs, on_step, &r);
  fmbd_progress(NULL);
  double t_stop = fmbd_mbs_time(m->mbs);
  if (rc == 2 && fmbd_runfile_signal()) {
    fmbd_err_context(out_name, "");
    fmbd_err_set(FMBD_ERR_IO, __FILE__, __LINE__, __func__, "interrupted by signal %d at t = %g s",
                 fmbd_runfile_signal(), t_stop);
    rc = FMBD_ERR_IO;
    fmbd_runfile_abandon(&r.rf, t_stop);
  } else if (rc == FMBD_ERR_CONVERGE || rc == FMBD_ERR_SINGULAR) {
    fmbd_err_context(scene_file, "");  // a failure on the way: keep the prefix computed so far
    fmbd_runfile_abandon(&r.rf, t_stop);
  }
  if (rc) goto done;
  double run_cpu = fmbd_cpu_s() - c0;
  FMBD_GCALL(fmbd_runfile_finish(r.rf));
  if (ref) FMBD_GCALL(fmbd_runfile_compare(r.rf, ref, window[0], window[1], NULL, NULL));
  for (int o = 0; plot && o < s->noutputs; o++) {
    if (r.out[o][Q_POS] < 0) continue;
    FMBD_GCALL(fmbd_runfile_plot_position(r.rf, r.out[o][Q_POS], plot, s->outputs[o].name,
                                          s->title ? s->title : s->file));
  }
  int64_t rows = fmbd_runfile_rows(r.rf);
  FMBD_GCALL(fmbd_runfile_commit(&r.rf));
  if (r.xdmf) FMBD_GCALL(fmbd_xdmf_commit(&r.xdmf));
  fmbd_mbs_get_stats(m->mbs, &st);
  fmbd_cli_summary(
      "%s: %lld steps, %lld rejected, %lld Newton iterations, %lld rows to t = %g s (%.3gx real "
      "time on CPU time)",
      strcmp(out_name, "-") ? out_name : "standard output", (long long)st.steps,
      (long long)st.rejected, (long long)st.newton_iterations, (long long)rows, t_stop,
      run_cpu > 0 ? t_stop / run_cpu : INFINITY);
done:
  fmbd_runfile_close(&r.rf);  // a failure before the run's end: no target
  fmbd_xdmf_close(&r.xdmf);
  fmbd_free(r.xbody);
  fmbd_free(xdmf_name);
  fmbd_free(r.out);
  fmbd_free(r.react);
  fmbd_scene_model_destroy(&m);
  fmbd_scene_destroy(&s);
  fmbd_free(out_name);
  fmbd_free(rules);
  return fmbd_cli_finish(rc);
}
