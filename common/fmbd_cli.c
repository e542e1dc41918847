// common/fmbd_cli.c: what every program's main() shares: command line, names, exit, summary
// SPDX-License-Identifier: MIT
#include "fmbd_cli.h"

#include <errno.h>
#include <limits.h>
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

void fmbd_cli_on_signals(void (*handler)(int)) {
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = handler;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
  sigaction(SIGHUP, &sa, NULL);
}

void fmbd_cli_init(const char *prog, int argc, char **argv) {
  fmbd_cli_on_signals(on_fatal_signal);
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
  return fmbd_cli_derive_name(input, strip, suffix, out);
}

int fmbd_cli_derive_name(const char *input, const char *const *strip, const char *suffix,
                         char **out) {
  *out = NULL;
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

// --- the option parser ------------------------------------------------------------------------
void fmbd_cli_args_init(fmbd_cli_args *p, int argc, char **argv, const fmbd_cli_option *options,
                        const char *help_text) {
  memset(p, 0, sizeof *p);
  p->argc = argc;
  p->argv = argv;
  p->i = 1;
  p->options = options;
  p->help_text = help_text;
}

static int cli_stop(fmbd_cli_args *p, int status) {
  p->status = status;
  return FMBD_CLI_EXIT;
}

int fmbd_cli_next(fmbd_cli_args *p) {
  p->value = NULL;
  p->opt = NULL;
  if (p->i >= p->argc) return FMBD_CLI_END;
  const char *arg = p->argv[p->i++];
  if (p->only_args || arg[0] != '-' || arg[1] == '\0') {
    p->value = arg;
    return FMBD_CLI_ARG;
  }
  if (!strcmp(arg, "--")) {
    p->only_args = true;
    return fmbd_cli_next(p);
  }
  int common = fmbd_cli_common_option(arg, p->help_text, &p->quiet, &p->verbose);
  if (common == FMBD_CLI_DONE) return cli_stop(p, 0);
  if (common == FMBD_CLI_TAKEN) return fmbd_cli_next(p);
  const fmbd_cli_option *o = NULL;
  const char *inline_value = NULL;
  if (arg[1] == '-') {  // --name or --name=value
    const char *eq = strchr(arg, '=');
    size_t n = eq ? (size_t)(eq - arg) : strlen(arg);
    if (n >= sizeof p->name) n = sizeof p->name - 1;
    memcpy(p->name, arg, n);
    p->name[n] = '\0';
    for (const fmbd_cli_option *q = p->options; q && (q->name || q->letter); q++) {
      if (q->name && !strcmp(q->name, p->name)) o = q;
    }
    if (eq) inline_value = eq + 1;
  } else {  // -x, or -xVALUE for an option with a value
    for (const fmbd_cli_option *q = p->options; q && (q->name || q->letter); q++) {
      if (q->letter == arg[1]) o = q;
    }
    if (o && arg[2] != '\0') {
      if (!o->value) o = NULL;  // "-Mx": not an option of ours
      inline_value = arg + 2;
    }
    snprintf(p->name, sizeof p->name, "-%c", arg[1]);
  }
  if (!o) return cli_stop(p, fmbd_cli_usage_error("unknown option '%s'", arg));
  p->opt = p->name;
  if (!o->value) {
    if (inline_value) {
      return cli_stop(p, fmbd_cli_usage_error("option %s takes no value ('%s')", p->name, arg));
    }
    return o->id;
  }
  if (inline_value) {
    p->value = inline_value;
  } else if (p->i < p->argc) {
    p->value = p->argv[p->i++];
  } else {
    return cli_stop(p, fmbd_cli_usage_error("option %s needs a value", p->name));
  }
  return o->id;
}

// "%g" of a bound, "inf" for an infinite one.
static void fmt_bound(char *buf, size_t n, double v) {
  if (isinf(v)) {
    snprintf(buf, n, "%sinf", v < 0 ? "-" : "");
  } else {
    snprintf(buf, n, "%.17g", v);
    double back = strtod(buf, NULL);
    for (int prec = 1; prec < 17; prec++) {  // the shortest text that reads back as v
      snprintf(buf, n, "%.*g", prec, v);
      if (strtod(buf, NULL) == back) break;
    }
  }
}

// The usage error of a value outside [lo, hi] (bounds: FMBD_CLI_OPEN_*).
static int range_error(fmbd_cli_args *p, double lo, double hi, unsigned bounds) {
  char a[40], b[40];
  fmt_bound(a, sizeof a, lo);
  fmt_bound(b, sizeof b, hi);
  bool open_lo = bounds & FMBD_CLI_OPEN_LO, open_hi = bounds & FMBD_CLI_OPEN_HI;
  if (isinf(hi)) {
    p->status = fmbd_cli_usage_error("option %s: '%s' must be %s %s", p->opt, p->value,
                                     open_lo ? ">" : ">=", a);
  } else if (isinf(lo)) {
    p->status = fmbd_cli_usage_error("option %s: '%s' must be %s %s", p->opt, p->value,
                                     open_hi ? "<" : "<=", b);
  } else {
    p->status = fmbd_cli_usage_error("option %s: '%s' is outside %c%s, %s%c", p->opt, p->value,
                                     open_lo ? '(' : '[', a, b, open_hi ? ')' : ']');
  }
  return p->status;
}

int fmbd_cli_double(fmbd_cli_args *p, double lo, double hi, unsigned bounds, double *out) {
  const char *opt = p->opt ? p->opt : "?";
  if (fmbd_cli_parse_double(opt, p->value, out)) {
    p->status = fmbd_cli_usage_error("%s", fmbd_err_get()->msg);
    return p->status;
  }
  double v = *out;
  bool ok = (bounds & FMBD_CLI_OPEN_LO ? v > lo : v >= lo) &&
            (bounds & FMBD_CLI_OPEN_HI ? v < hi : v <= hi);
  return ok ? 0 : range_error(p, lo, hi, bounds);
}

int fmbd_cli_long(fmbd_cli_args *p, long lo, long hi, long *out) {
  const char *opt = p->opt ? p->opt : "?";
  if (fmbd_cli_parse_int(opt, p->value, out)) {
    p->status = fmbd_cli_usage_error("%s", fmbd_err_get()->msg);
    return p->status;
  }
  if (*out >= lo && *out <= hi) return 0;
  return range_error(p, lo == LONG_MIN ? -INFINITY : (double)lo,
                     hi == LONG_MAX ? INFINITY : (double)hi, 0);
}

int fmbd_cli_numbers(const char *opt, const char *text, int n, char sep, double *v) {
  const char *s = text;
  for (int i = 0; i < n; i++) {
    char *end;
    errno = 0;
    v[i] = strtod(s, &end);
    bool last = i == n - 1;
    if (end == s || errno == ERANGE || !isfinite(v[i]) || (!last && *end != sep) ||
        (last && *end)) {
      return fmbd_cli_usage_error("option %s: '%s' is not a list of %d numbers separated by '%c'",
                                  opt, text, n, sep);
    }
    s = end + 1;
  }
  return 0;
}

void fmbd_cli_names_free(fmbd_cli_names *l) {
  if (!l) return;
  fmbd_free(l->name);
  fmbd_free(l->text);
  memset(l, 0, sizeof *l);
}

int fmbd_cli_names_parse(const char *opt, const char *text, fmbd_cli_names *l) {
  fmbd_cli_names_free(l);
  int cap = 1;
  for (const char *p = text; *p; p++) cap += *p == ',';
  l->text = fmbd_strdup(text);
  l->name = fmbd_calloc((size_t)cap, sizeof(char *));
  if (!l->text || !l->name) {
    fmbd_cli_names_free(l);
    return fmbd_cli_usage_error("out of memory");
  }
  for (char *s = l->text, *save = NULL, *t; (t = strtok_r(s, ",", &save)); s = NULL) {
    l->name[l->n++] = t;
  }
  if (l->n == 0) {
    fmbd_cli_names_free(l);
    return fmbd_cli_usage_error("%s '%s': no name", opt, text);
  }
  return 0;
}
