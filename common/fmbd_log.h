// common/fmbd_log.h: logging to standard error, progress on a terminal, wall and CPU timers
// SPDX-License-Identifier: MIT
//
// Standard output is data; everything else goes to standard error through fmbd_log.
// Levels: -q -> ERROR only, default -> WARN (+ the summary line), -v -> INFO (progress),
// -vv -> DEBUG. The environment variable FMBD_LOG (error|warn|info|debug) overrides.
#ifndef FMBD_LOG_H
#define FMBD_LOG_H

#include <stdbool.h>

enum fmbd_log_level {
  FMBD_LOG_ERROR = 0,
  FMBD_LOG_WARN = 1,
  FMBD_LOG_INFO = 2,
  FMBD_LOG_DEBUG = 3
};

/// @brief Set the program name used as message prefix and the level (FMBD_LOG env wins).
void fmbd_log_init(const char *prog, int level);
/// @brief The program name given to fmbd_log_init ("fmbd" before).
const char *fmbd_log_prog(void);
/// @brief Current level.
int fmbd_log_level(void);
/// @brief Print "prog: [warning: ]message\n" on stderr when level <= the current level.
void fmbd_log(int level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/// @brief The summary line: printed unless -q (level ERROR), "prog: message\n".
void fmbd_log_summary(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/// @brief True when progress should be shown: stderr is a terminal and the level is not -q.
bool fmbd_progress_enabled(void);
/// @brief Progress of long work: "\rprog: message" on a terminal, overwriting itself; a
/// call with fmt == NULL ends the line. Nothing when !fmbd_progress_enabled().
void fmbd_progress(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

/// A wall and CPU clock pair.
typedef struct fmbd_timer {
  double wall0_s, cpu0_s;
} fmbd_timer;
/// @brief Start (or restart) a timer.
void fmbd_timer_start(fmbd_timer *t);
/// @brief Seconds of wall time since start.
double fmbd_timer_wall_s(const fmbd_timer *t);
/// @brief Seconds of process CPU time (all threads) since start.
double fmbd_timer_cpu_s(const fmbd_timer *t);
/// @brief Monotonic wall clock in seconds.
double fmbd_wall_s(void);
/// @brief Process CPU time in seconds.
double fmbd_cpu_s(void);

#endif
