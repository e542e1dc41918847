// common/fmbd_log.c: logging, progress and timers
// SPDX-License-Identifier: MIT
#include "fmbd_log.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <unistd.h>

static const char *g_prog = "fmbd";
static int g_level = FMBD_LOG_WARN;
static bool g_progress_open = false;

void fmbd_log_init(const char *prog, int level) {
  if (prog) g_prog = prog;
  g_level = level;
  const char *env = getenv("FMBD_LOG");
  if (env && *env) {
    if (!strcasecmp(env, "error"))
      g_level = FMBD_LOG_ERROR;
    else if (!strcasecmp(env, "warn"))
      g_level = FMBD_LOG_WARN;
    else if (!strcasecmp(env, "info"))
      g_level = FMBD_LOG_INFO;
    else if (!strcasecmp(env, "debug"))
      g_level = FMBD_LOG_DEBUG;
  }
}

const char *fmbd_log_prog(void) {
  return g_prog;
}
int fmbd_log_level(void) {
  return g_level;
}

static void end_progress_line(void) {
  if (g_progress_open) {
    fputc('\n', stderr);
    g_progress_open = false;
  }
}

void fmbd_log(int level, const char *fmt, ...) {
  if (level > g_level) return;
  end_progress_line();
  static const char *tag[] = {"error: ", "warning: ", "", "debug: "};
  fprintf(stderr, "%s: %s", g_prog, tag[level < 0 ? 0 : level > 3 ? 3 : level]);
  va_list ap;
  va_start(ap, fmt);
  vfprintf(stderr, fmt, ap);
  va_end(ap);
  fputc('\n', stderr);
}

void fmbd_log_summary(const char *fmt, ...) {
  if (g_level < FMBD_LOG_WARN) return;
  end_progress_line();
  fprintf(stderr, "%s: ", g_prog);
  va_list ap;
  va_start(ap, fmt);
  vfprintf(stderr, fmt, ap);
  va_end(ap);
  fputc('\n', stderr);
}

bool fmbd_progress_enabled(void) {
  return g_level >= FMBD_LOG_WARN && isatty(STDERR_FILENO);
}

void fmbd_progress(const char *fmt, ...) {
  if (!fmbd_progress_enabled()) return;
  if (!fmt) {
    end_progress_line();
    return;
  }
  fprintf(stderr, "\r\033[K%s: ", g_prog);
  va_list ap;
  va_start(ap, fmt);
  vfprintf(stderr, fmt, ap);
  va_end(ap);
  fflush(stderr);
  g_progress_open = true;
}

double fmbd_wall_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

double fmbd_cpu_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void fmbd_timer_start(fmbd_timer *t) {
  t->wall0_s = fmbd_wall_s();
  t->cpu0_s = fmbd_cpu_s();
}
double fmbd_timer_wall_s(const fmbd_timer *t) {
  return fmbd_wall_s() - t->wall0_s;
}
double fmbd_timer_cpu_s(const fmbd_timer *t) {
  return fmbd_cpu_s() - t->cpu0_s;
}
