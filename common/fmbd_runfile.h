// common/fmbd_runfile.h: the run file (format fmbd-run): time series written as a run goes, its
// statistics and provenance, the valid prefix of an interrupted run, and the comparison with a
// reference run (errors of every shared output series)
// SPDX-License-Identifier: MIT
//
// Every program that integrates in time (fmbd-run, gmsolve, a benchmark driver) writes its
// results with this module, so that one format (docs/FORMAT.md, "fmbd-run") is written and
// compared by one piece of code. The file is written under RUN.h5.part and renamed to RUN.h5
// only when the run is complete (fmbd_runfile_commit); an interrupted run keeps RUN.h5.part, a
// valid HDF5 file whose series hold the rows written so far, all of one length, and whose
// /stats attribute `complete` is 0 (fmbd_runfile_abandon).
//
// A run in a few calls:
//
//   fmbd_runfile *rf = NULL;
//   int t_id, pos_id;
//   FMBD_CALL(fmbd_runfile_create("pend.run.h5", keep, &rf));   // keep: for compare / plot
//   fmbd_runfile_set_stats(rf, my_stats, my_solver);   // filled at every flush
//   FMBD_CALL(fmbd_runfile_scene(rf, "pend.yaml", title, text, t_end));   // /scene, provenance
//   FMBD_CALL(fmbd_h5_add_input(fmbd_runfile_h5(rf), "body.rflex.h5", sha));   // more inputs
//   FMBD_CALL(fmbd_runfile_series(rf, "/outputs/bob/position", 3, "m", FMBD_RUNFILE_COMPARED,
//                                 &pos_id));    // declare every series before the first row
//   fmbd_runfile_catch_signals();   // SIGINT/SIGTERM/SIGHUP: stop cleanly, keep the prefix
//   fmbd_runfile_start_clock(rf);   // run_wall_time_s / run_cpu_time_s count from here
//   for (each output instant t) {
//     FMBD_CALL(fmbd_runfile_row(rf, t));            // /time gets t
//     FMBD_CALL(fmbd_runfile_put(rf, pos_id, x));   // one row of each series
//     if (fmbd_runfile_signal()) break;              // then fmbd_runfile_abandon
//   }
//   FMBD_CALL(fmbd_runfile_finish(rf));        // every row on disk, /stats complete = 1
//   FMBD_CALL(fmbd_runfile_compare(rf, "ref.run.h5", NAN, NAN, NULL, NULL));  // optional
//   FMBD_CALL(fmbd_runfile_commit(&rf));       // RUN.h5.part -> RUN.h5
//   ... on an error: fmbd_runfile_abandon(&rf) keeps the prefix, fmbd_runfile_close(&rf) drops it.
//
// Rows are buffered (256 at a time) and appended as blocks to extendible datasets; each series
// is a dataset of shape (rows,) (ncols 0) or (rows, ncols). Every series must get exactly one
// row per fmbd_runfile_row (checked).
#ifndef FMBD_RUNFILE_H
#define FMBD_RUNFILE_H

#include <stdbool.h>
#include <stdint.h>

#include "fmbd_h5.h"

typedef struct fmbd_runfile fmbd_runfile;

/// The integrator's counters written as attributes of /stats (docs/FORMAT.md). A program
/// without some of them (a static or modal solution) leaves them 0.
typedef struct fmbd_runfile_stats {
  int64_t steps, rejected_steps, newton_iterations, factorizations;
  int64_t coordinates, equations, redundant_equations;
  double t_reached;    ///< s, time of the last accepted step
  double last_step_s;  ///< s, the last accepted step size
  /// s, CPU time of the Newton iterations: factorisations, solves, the rest (fmbd_mbs_stats)
  double factor_cpu_s, solve_cpu_s, eval_cpu_s;
} fmbd_runfile_stats;
/// Fills *st with the solver's counters now (called at every flush and at the end).
typedef void (*fmbd_runfile_stats_fn)(void *user, fmbd_runfile_stats *st);

/// @brief Create the run file `name` ("-": standard output at commit; then an interruption
/// keeps nothing) with the root attributes of the format, /time declared, /stats written.
/// keep_history: keep the rows of /time and of the series declared FMBD_RUNFILE_COMPARED in
/// memory, for fmbd_runfile_compare and fmbd_runfile_history (else those report nothing).
/// @param[out] out caller ends with fmbd_runfile_commit, _abandon or _close
int fmbd_runfile_create(const char *name, bool keep_history, fmbd_runfile **out);
/// @brief The HDF5 handle, for what the format adds beside the series (attributes of
/// /outputs/NAME, inputs with fmbd_h5_add_input).
fmbd_h5 *fmbd_runfile_h5(fmbd_runfile *rf);
/// @brief The name given at creation (borrowed).
const char *fmbd_runfile_name(const fmbd_runfile *rf);
/// @brief Where the counters of /stats come from (none set: zeros).
void fmbd_runfile_set_stats(fmbd_runfile *rf, fmbd_runfile_stats_fn fn, void *user);
/// @brief The /scene group (attributes file, title if not NULL, text, t_end) and the scene file
/// as an input (hashed here; not for "-", standard input).
int fmbd_runfile_scene(fmbd_runfile *rf, const char *file, const char *title, const char *text,
                       double t_end);

/// Flags of a series.
enum {
  FMBD_RUNFILE_COMPARED = 1  ///< an output: compared with a reference, kept for history
};
/// @brief Declare a series: an extendible dataset at path (parents created) of rows of ncols
/// values (0: one value per row), in `unit` (for the tables printed; "1" dimensionless).
/// Declare every series before the first row. A series compared with a reference must lie at
/// /outputs/NAME/QUANTITY (its errors go to /reference/NAME as attributes *_QUANTITY).
/// @param[out] id the series' number for fmbd_runfile_put
int fmbd_runfile_series(fmbd_runfile *rf, const char *path, int ncols, const char *unit,
                        unsigned flags, int *id);
/// @brief Start an output row at time t: /time gets t (FMBD_ERR_VALUE if a series missed the
/// previous row: a program error).
int fmbd_runfile_row(fmbd_runfile *rf, double t);
/// @brief The current row's values of series id (ncols values, or 1).
int fmbd_runfile_put(fmbd_runfile *rf, int id, const double *values);
/// @brief Rows started so far.
int64_t fmbd_runfile_rows(const fmbd_runfile *rf);
/// @brief Every row so far to disk, /stats rewritten (complete 0), the file flushed: what is
/// on disk is a valid prefix.
int fmbd_runfile_flush(fmbd_runfile *rf);
/// @brief Start the clock of run_wall_time_s / run_cpu_time_s (the time integration alone).
void fmbd_runfile_start_clock(fmbd_runfile *rf);
/// @brief The rows kept in memory (keep_history and FMBD_RUNFILE_COMPARED; id -1: /time):
/// *n rows of width ncols (or 1) at *v (borrowed, valid until the next row). *n = 0 when not kept.
void fmbd_runfile_history(const fmbd_runfile *rf, int id, int64_t *n, const double **v);

/// @brief End a complete run: every row on disk, /stats with complete = 1.
int fmbd_runfile_finish(fmbd_runfile *rf);
/// @brief fmbd_runfile_finish if not done, close the series, write the program's wall and CPU
/// time and rename RUN.h5.part to RUN.h5 (or write standard output). *rf is NULL afterwards,
/// also on failure (then no target is left).
int fmbd_runfile_commit(fmbd_runfile **rf);
/// @brief Keep the valid prefix of an interrupted run: rows so far on disk, /stats complete =
/// 0, RUN.h5.part kept (nothing for standard output), and a warning naming it and `t`, the
/// time reached. *rf is NULL afterwards.
void fmbd_runfile_abandon(fmbd_runfile **rf, double t);
/// @brief Drop the run file (no target, no .part). NULL and *rf == NULL are fine.
void fmbd_runfile_close(fmbd_runfile **rf);

// --- signals: stop cleanly and keep the prefix ---------------------------------------------
/// @brief From now on SIGINT, SIGTERM and SIGHUP only set a flag (fmbd_runfile_signal): the
/// loop stops at the next step and calls fmbd_runfile_abandon (fmbd_cli_init's handler, which
/// removes the output, is replaced).
void fmbd_runfile_catch_signals(void);
/// @brief The signal caught since fmbd_runfile_catch_signals, or 0.
int fmbd_runfile_signal(void);

// --- comparison with a reference run (docs/THEORY.md section 7) -----------------------------
/// The errors of one output series against a reference.
typedef struct fmbd_runfile_error {
  char name[200];     ///< the output (/outputs/NAME)
  char quantity[56];  ///< the series (position, velocity, von_mises, stress, ...)
  const char *unit;   ///< as declared (borrowed)
  int64_t instants;   ///< instants compared
  double rms;         ///< root mean square over the instants of the error's norm
  double max;         ///< the largest error norm
  double t_max;       ///< s, the instant of the largest error
  double rms_ref;     ///< root mean square of the reference's norm (the errors' scale)
} fmbd_runfile_error;

/// @brief Check that `name` is a usable reference before a run: a complete run file (format
/// fmbd-run, /stats complete = 1) whose /time is finite and strictly increasing with two
/// instants at least. Errors name the file and the object.
int fmbd_runfile_check_reference(const char *name);
/// @brief Compare this run (after fmbd_runfile_finish; keep_history) with the reference run
/// `ref`: for every series declared FMBD_RUNFILE_COMPARED that the reference has too (same
/// path, same width), the norm of the difference at each of this run's instants within the
/// reference's time span and within the window [t0, t1] (NaN: no bound), the reference
/// interpolated linearly in time there; its RMS and its largest value with the instant. The
/// norm is the Euclidean norm of the row's difference (stress and strain: of the 6 stored
/// components). Written to /reference (attributes file, sha256, window) and /reference/NAME
/// (rms_Q, max_Q, t_max_Q, rms_ref_Q per quantity Q, instants), printed as a table (summary
/// level), the reference recorded as an input.
/// @param[out] n, errors the errors, caller frees *errors with fmbd_free (both may be NULL)
int fmbd_runfile_compare(fmbd_runfile *rf, const char *ref, double t0, double t1, int *n,
                         fmbd_runfile_error **errors);

// --- pictures ----------------------------------------------------------------------------
/// @brief SVG plots of a kept 3-column series (a position): its components against time in
/// PREFIX<name>-position.svg and its path in the plane of its two largest ranges in
/// PREFIX<name>-trajectory.svg; `title` heads both (the scene's title or file name).
int fmbd_runfile_plot_position(const fmbd_runfile *rf, int id, const char *prefix, const char *name,
                               const char *title);

#endif
