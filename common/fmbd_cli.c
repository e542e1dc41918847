// common/fmbd_cli.c: what every program's main() shares: command line, names, exit, summary
// SPDX-License-Identifier: MIT
#include "fmbd_cli.h"

#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "fmbd_alloc.h"
#include "fmbd_err.h"
#include "fmbd_h5.h"
#include "fmbd_log.h"

#ifndef FMBD_VERSION
#define FMBD_VERSION "unknown"
#endif

static char *g_cmdline = NULL;  // shell-quoted command line (fmbd_malloc), "" before init
static fmbd_timer g_timer;
static bool g_timer_started = false;

const char *fmbd_version(void) {
  return FMBD_VERSION;
}

// Whether a word needs no quoting for a POSIX shell.
static bool shell_safe(const char *s) {
  if (!*s) return false;
  for (const char *p = s; *p; p++) {
    char c = *p;
    bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
              strchr("_@%+=:,./-", c) != NULL;
    if (!ok) return false;
  }
  return true;
}

// Length of the quoted form of s (without NUL): safe words as is, else '...' with each ' as '\''.
static size_t quoted_len(const char *s) {
  if (shell_safe(s)) return strlen(s);
  size_t n = 2;
  for (const char *p = s; *p; p++) n += *p == '\'' ? 4 : 1;
  return n;
}

static char *append_quoted(char *out, const char *s) {
  if (shell_safe(s)) {
    size_t n = strlen(s);
    memcpy(out, s, n);
    return out + n;
  }
  *out++ = '\'';
  for (const char *p = s; *p; p++) {
    if (*p == '\'') {
      memcpy(out, "'\\''", 4);
      out += 4;
    } else {
      *out++ = *p;
    }
  }
  *out++ = '\'';
  return out;
}

// SIGINT, SIGTERM, SIGHUP: remove the output being written, say so, exit 1. Only
// async-signal-safe calls (unlink, write, _exit). fmbd-run replaces it while it steps, to keep
// its valid prefix instead.
static void on_fatal_signal(int sig) {
  fmbd_h5_signal_cleanup();
  const char *prog = fmbd_log_prog();
  static const char msg[] = ": error: interrupted by a signal; no output written\n";
  if (prog) {
    ssize_t w = write(STDERR_FILENO, prog, strlen(prog));
    (void)w;
  }
  ssize_t w = write(STDERR_FILENO, msg, sizeof msg - 1);
  (void)w;
  (void)sig;
  _exit(1);
}

void fmbd_cli_init(const char *prog, int argc, char **argv) {
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_fatal_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
  sigaction(SIGHUP, &sa, NULL);
  fmbd_timer_start(&g_timer);
  g_timer_started = true;
  fmbd_log_init(prog, FMBD_LOG_WARN);
  fmbd_h5_debug(false);
  fmbd_free(g_cmdline);
  g_cmdline = NULL;
  size_t n = 1;
  for (int i = 0; i < argc; i++) n += quoted_len(argv[i]) + 1;
  g_cmdline = fmbd_malloc(n);
  fmbd_h5_set_provenance(fmbd_version(), "");
  if (!g_cmdline) return;  // fmbd_cli_command_line then gives "" (out of memory at start)
  char *p = g_cmdline;
  for (int i = 0; i < argc; i++) {
    if (i) *p++ = ' ';
    p = append_quoted(p, argv[i]);
  }
  *p = '\0';
  fmbd_h5_set_provenance(fmbd_version(), g_cmdline);
}

const char *fmbd_cli_command_line(void) {
  return g_cmdline ? g_cmdline : "";
}

double fmbd_cli_wall_s(void) {
  return g_timer_started ? fmbd_timer_wall_s(&g_timer) : 0.0;
}
double fmbd_cli_cpu_s(void) {
  return g_timer_started ? fmbd_timer_cpu_s(&g_timer) : 0.0;
}

void fmbd_cli_set_verbosity(int quiet, int verbose) {
  int level = FMBD_LOG_WARN - quiet + verbose;
  if (level < FMBD_LOG_ERROR) level = FMBD_LOG_ERROR;
  if (level > FMBD_LOG_DEBUG) level = FMBD_LOG_DEBUG;
  fmbd_log_init(NULL, level);
}

static bool ends_with(const char *s, const char *end) {
  size_t n = strlen(s), m = strlen(end);
  return m <= n && !strcmp(s + n - m, end);
}

bool fmbd_cli_same_file(const char *a, const char *b) {
  struct stat sa, sb;
  if (!a || !b || !strcmp(a, "-") || !strcmp(b, "-")) return false;
  if (stat(a, &sa) != 0 || stat(b, &sb) != 0) return false;
  return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

int fmbd_cli_check_not_input(const char *output, const char *input) {
  if (!fmbd_cli_same_file(output, input)) return FMBD_OK;
  fmbd_err_context("", "");
  if (!strcmp(output, input)) {
    FMBD_FAIL(FMBD_ERR_USAGE, "the output '%s' is an input of this run: refusing to overwrite it",
              output);
  }
  FMBD_FAIL(FMBD_ERR_USAGE,
            "the output '%s' is the input '%s' (the same file): refusing to "
            "overwrite it",
            output, input);
}

int fmbd_cli_output_name(const char *input, const char *opt_o, const char *const *strip,
                         const char *suffix, char **out) {
  *out = NULL;
  const char *name = NULL;
  if (opt_o) {
    FMBD_CHECK(*opt_o, FMBD_ERR_USAGE, "empty output name (-o)");
    name = opt_o;
  } else if (!isatty(STDOUT_FILENO)) {
    name = "-";
  }
  if (name) {
    FMBD_CALL(fmbd_cli_check_not_input(name, input));
    *out = fmbd_strdup(name);
    FMBD_CHECK(*out, FMBD_ERR_NOMEM, "out of memory");
    return FMBD_OK;
  }
  FMBD_CHECK(input && strcmp(input, "-") != 0, FMBD_ERR_USAGE,
             "reading standard input: give the output name with -o (or pipe the output)");
  // --- cut the longest matching ending of `strip`, else the last ".ext" of the base name ---
  size_t n = strlen(input), cut = n;
  size_t best = 0;
  for (int i = 0; strip && strip[i]; i++) {
    size_t m = strlen(strip[i]);
    if (m > best && m < n && ends_with(input, strip[i])) best = m;
  }
  if (best) {
    cut = n - best;
  } else {
    const char *base = strrchr(input, '/');
    base = base ? base + 1 : input;
    const char *dot = strrchr(base, '.');
    if (dot && dot > base) cut = (size_t)(dot - input);  // ".hidden" has no extension
  }
  size_t m = strlen(suffix);
  char *s = fmbd_malloc(cut + m + 1);
  FMBD_CHECK(s, FMBD_ERR_NOMEM, "out of memory");
  memcpy(s, input, cut);
  memcpy(s + cut, suffix, m + 1);
  if (!strcmp(s, input)) {
    fmbd_free(s);
    fmbd_err_context("", "");
    FMBD_FAIL(FMBD_ERR_USAGE, "the output name derived from '%s' is the input itself; give -o",
              input);
  }
  *out = s;
  return FMBD_OK;
}

int fmbd_cli_parse_double(const char *opt, const char *text, double *out) {
  char *end = NULL;
  errno = 0;
  double v = text ? strtod(text, &end) : 0.0;
  if (!text || end == text || *end != '\0' || errno == ERANGE || !isfinite(v)) {
    fmbd_err_context("", "");
    FMBD_FAIL(FMBD_ERR_USAGE, "option %s: '%s' is not a finite number", opt,
              text ? text : "(missing)");
  }
  *out = v;
  return FMBD_OK;
}

int fmbd_cli_parse_int(const char *opt, const char *text, long *out) {
  char *end = NULL;
  errno = 0;
  long v = text ? strtol(text, &end, 10) : 0;
  if (!text || end == text || *end != '\0' || errno == ERANGE) {
    fmbd_err_context("", "");
    FMBD_FAIL(FMBD_ERR_USAGE, "option %s: '%s' is not an integer", opt, text ? text : "(missing)");
  }
  *out = v;
  return FMBD_OK;
}

int fmbd_cli_finish(int rc) {
  fmbd_h5_set_provenance(fmbd_version(), "");  // the command line is released below
  if (rc > 0) {  // an exit status already reported (fmbd_cli_usage_error's 2): as is
    fmbd_free(g_cmdline);
    g_cmdline = NULL;
    return rc;
  }
  if (rc != FMBD_OK) {
    fflush(stdout);
    const fmbd_err *e = fmbd_err_get();
    char buf[2200];
    if (e->code == rc) {
      fmbd_err_format(buf, (int)sizeof buf);
    } else {  // a code returned without a record (should not happen): its generic message
      snprintf(buf, sizeof buf, "%s", fmbd_err_string(rc));
    }
    const char *prog = fmbd_log_prog();
    fprintf(stderr, "%s: error: %s\n", prog, buf);
    if (fmbd_log_level() >= FMBD_LOG_DEBUG && e->code == rc && e->src) {
      fprintf(stderr, "%s: debug: raised at %s:%d in %s()\n", prog, e->src, e->line,
              e->func ? e->func : "?");
    }
    if (rc == FMBD_ERR_USAGE) fprintf(stderr, "Try '%s --help'.\n", prog);
  }
  fmbd_free(g_cmdline);
  g_cmdline = NULL;
  return fmbd_err_exit_status(rc);
}

int fmbd_cli_usage_error(const char *fmt, ...) {
  fflush(stdout);
  const char *prog = fmbd_log_prog();
  fprintf(stderr, "%s: error: ", prog);
  va_list ap;
  va_start(ap, fmt);
  vfprintf(stderr, fmt, ap);
  va_end(ap);
  fprintf(stderr, "\nTry '%s --help'.\n", prog);
  return 2;
}

// Seconds with three significant digits, without an exponent below 10^5 s.
static void fmt_seconds(char *buf, size_t n, double t) {
  if (t >= 100.0) {
    snprintf(buf, n, "%.0f", t);
  } else {
    snprintf(buf, n, "%.3g", t);
  }
}

void fmbd_cli_summary(const char *fmt, ...) {
  char msg[1024], w[32], c[32];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  fmt_seconds(w, sizeof w, fmbd_cli_wall_s());
  fmt_seconds(c, sizeof c, fmbd_cli_cpu_s());
  fmbd_log_summary("%s, %s s wall, %s s cpu", msg, w, c);
}

const char *fmbd_cli_exit_help(void) {
  return "Exit status:\n"
         "  0  success\n"
         "  1  failure on the data (missing, bad or foreign input, no convergence, write error)\n"
         "  2  usage error (unknown option, bad option value, missing argument)\n";
}

int fmbd_cli_common_option(const char *arg, const char *help_text, int *quiet, int *verbose) {
  if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) {
    fputs(help_text, stdout);
    fputs("\n", stdout);
    fputs(fmbd_cli_exit_help(), stdout);
    return FMBD_CLI_DONE;
  }
  if (!strcmp(arg, "-V") || !strcmp(arg, "--version")) {
    printf("%s %s\n", fmbd_log_prog(), fmbd_version());
    return FMBD_CLI_DONE;
  }
  if (!strcmp(arg, "-q") || !strcmp(arg, "--quiet")) {
    ++*quiet;
  } else if (!strcmp(arg, "-v") || !strcmp(arg, "--verbose")) {
    ++*verbose;
  } else if (!strcmp(arg, "-vv")) {
    *verbose += 2;
  } else {
    return FMBD_CLI_OTHER;
  }
  return FMBD_CLI_TAKEN;
}
