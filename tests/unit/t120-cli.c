// tests/unit/t120-cli.c: output names, option parsing, command-line quoting, error reports
// SPDX-License-Identifier: MIT
#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "fmbd.h"

static char g_dir[1024];

// Run f with standard error sent to a file; return what it printed (static buffer).
static const char *capture_stderr(int (*fn)(void *), void *arg, int *ret) {
  static char out[4096];
  char path[1200];
  snprintf(path, sizeof path, "%s/stderr.txt", g_dir);
  fflush(stderr);
  int saved = dup(STDERR_FILENO);
  int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
  dup2(fd, STDERR_FILENO);
  close(fd);
  *ret = fn(arg);
  fflush(stderr);
  dup2(saved, STDERR_FILENO);
  close(saved);
  FILE *fp = fopen(path, "r");
  size_t n = fp ? fread(out, 1, sizeof out - 1, fp) : 0;
  out[n] = '\0';
  if (fp) fclose(fp);
  return out;
}

// Make standard output a terminal (a pseudo-terminal) for fn, as when run interactively.
static int with_tty_stdout(int (*fn)(void *), void *arg) {
  int master = posix_openpt(O_RDWR | O_NOCTTY);
  if (master < 0 || grantpt(master) || unlockpt(master)) return -100;
  int slave = open(ptsname(master), O_RDWR | O_NOCTTY);
  if (slave < 0) return -100;
  fflush(stdout);
  int saved = dup(STDOUT_FILENO);
  dup2(slave, STDOUT_FILENO);
  int rc = fn(arg);
  dup2(saved, STDOUT_FILENO);
  close(saved);
  close(slave);
  close(master);
  return rc;
}

typedef struct name_case {
  const char *input, *opt_o, *suffix, *want;  // want NULL: a usage error
  char *got;
} name_case;

static const char *const STRIP[] = {".fe.h5", ".cb.h5", ".h5", NULL};

static int derive(void *arg) {
  name_case *c = arg;
  return fmbd_cli_output_name(c->input, c->opt_o, STRIP, c->suffix, &c->got);
}

static void test_output_name(void) {
  name_case tty[] = {
      {"rod.geo", NULL, ".fe.h5", "rod.fe.h5", NULL},
      {"dir.v2/rod", NULL, ".fe.h5", "dir.v2/rod.fe.h5", NULL},  // no extension in base name
      {"a/rod.fe.h5", NULL, ".cb.h5", "a/rod.cb.h5", NULL},      // longest strip wins
      {"rod.h5", NULL, ".cb.h5", "rod.cb.h5", NULL},
      {"rod.step", NULL, ".fe.h5", "rod.fe.h5", NULL},
      {".hidden", NULL, ".fe.h5", ".hidden.fe.h5", NULL},  // a dot file has no extension
      {"rod.geo", "out.h5", ".fe.h5", "out.h5", NULL},     // -o wins
      {"rod.geo", "-", ".fe.h5", "-", NULL},
      {"-", NULL, ".fe.h5", NULL, NULL},          // stdin to a terminal
      {"rod.cb.h5", NULL, ".cb.h5", NULL, NULL},  // would overwrite the input
      {"rod.geo", "", ".fe.h5", NULL, NULL},      // empty -o
  };
  for (size_t i = 0; i < sizeof tty / sizeof *tty; i++) {
    name_case *c = &tty[i];
    fmbd_err_clear();
    int rc = with_tty_stdout(derive, c);
    if (rc == -100) {
      fprintf(stderr, "t120: no pseudo-terminal available; terminal cases not run\n");
      test_failures++;
      return;
    }
    if (c->want) {
      EXPECT(rc == FMBD_OK && c->got && !strcmp(c->got, c->want), "'%s' -> '%s', expected '%s'",
             c->input, c->got ? c->got : "(null)", c->want);
    } else {
      EXPECT(rc == FMBD_ERR_USAGE && !c->got, "'%s' (-o %s): rc %d, expected a usage error",
             c->input, c->opt_o ? c->opt_o : "none", rc);
    }
    fmbd_free(c->got);
  }
  // standard output not a terminal (this test's is a log file or pipe): "-" without -o
  name_case pipe = {"rod.geo", NULL, ".fe.h5", "-", NULL};
  if (!isatty(STDOUT_FILENO)) {
    EXPECT(derive(&pipe) == FMBD_OK && !strcmp(pipe.got, "-"), "piped: '%s'", pipe.got);
    fmbd_free(pipe.got);
  }
}

static void test_parse(void) {
  double d = 0;
  long l = 0;
  EXPECT(fmbd_cli_parse_double("--size", "1.5e-3", &d) == FMBD_OK && d == 1.5e-3, "double");
  EXPECT(fmbd_cli_parse_double("--size", "-2", &d) == FMBD_OK && d == -2.0, "negative");
  const char *bad_d[] = {"abc", "1.5x", "", "inf", "nan", "1e999", " 1 2"};
  for (size_t i = 0; i < sizeof bad_d / sizeof *bad_d; i++) {
    fmbd_err_clear();
    EXPECT(fmbd_cli_parse_double("--size", bad_d[i], &d) == FMBD_ERR_USAGE, "'%s'", bad_d[i]);
    EXPECT(strstr(fmbd_err_get()->msg, "--size") && strstr(fmbd_err_get()->msg, bad_d[i]),
           "message names the option and text: %s", fmbd_err_get()->msg);
  }
  EXPECT(fmbd_cli_parse_double("--size", NULL, &d) == FMBD_ERR_USAGE, "missing value");
  EXPECT(fmbd_cli_parse_int("--modes", "42", &l) == FMBD_OK && l == 42, "int");
  EXPECT(fmbd_cli_parse_int("--modes", "-3", &l) == FMBD_OK && l == -3, "negative int");
  const char *bad_i[] = {"4.2", "x", "", "99999999999999999999999", "7 "};
  for (size_t i = 0; i < sizeof bad_i / sizeof *bad_i; i++) {
    fmbd_err_clear();
    EXPECT(fmbd_cli_parse_int("--modes", bad_i[i], &l) == FMBD_ERR_USAGE, "'%s'", bad_i[i]);
    EXPECT(strstr(fmbd_err_get()->msg, "--modes") != NULL, "msg %s", fmbd_err_get()->msg);
  }
}

static void test_command_line(void) {
  char *argv[] = {"prog", "plain-1.0/x_y:z,w@%+=", "a b", "it's", "", "$HOME", "*", "\"q\"", NULL};
  int argc = 8;
  fmbd_cli_init("t120", argc, argv);
  const char *cl = fmbd_cli_command_line();
  const char *want = "prog plain-1.0/x_y:z,w@%+= 'a b' 'it'\\''s' '' '$HOME' '*' '\"q\"'";
  EXPECT(!strcmp(cl, want), "command line:\n  %s\nexpected\n  %s", cl, want);
  // the shell splits it back into the same words
  char cmd[2048], path[1200];
  snprintf(path, sizeof path, "%s/words.txt", g_dir);
  snprintf(cmd, sizeof cmd, "set -- %s; for w in \"$@\"; do printf '%%s\\n' \"$w\"; done > '%s'",
           cl, path);
  EXPECT(system(cmd) == 0, "sh failed on: %s", cmd);
  FILE *fp = fopen(path, "r");
  char line[256];
  for (int i = 0; i < argc && fp; i++) {
    if (!fgets(line, sizeof line, fp)) {
      EXPECT(0, "word %d missing", i);
      break;
    }
    line[strcspn(line, "\n")] = '\0';
    EXPECT(!strcmp(line, argv[i]), "word %d: '%s', expected '%s'", i, line, argv[i]);
  }
  if (fp) fclose(fp);
  EXPECT(fmbd_cli_wall_s() >= 0 && fmbd_cli_cpu_s() >= 0, "timers");
  EXPECT(!strcmp(fmbd_version(), FMBD_VERSION), "version");
}

static int finish_format(void *arg) {
  (void)arg;
  fmbd_err_clear();
  fmbd_err_context("rod.fe.h5", "/K/indptr");
  int rc = fmbd_err_set(FMBD_ERR_FORMAT, "src.c", 12, "fn", "not increasing at row 3");
  return fmbd_cli_finish(rc);
}
static int finish_usage(void *arg) {
  (void)arg;
  double d;
  return fmbd_cli_finish(fmbd_cli_parse_double("--E", "x", &d));
}
static int usage_error(void *arg) {
  (void)arg;
  return fmbd_cli_usage_error("unknown option '%s'", "--bogus");
}
static int summary(void *arg) {
  (void)arg;
  fmbd_cli_summary("rod.fe.h5: %d dofs", 12);
  return 0;
}
static int finish_ok(void *arg) {
  (void)arg;
  return fmbd_cli_finish(FMBD_OK);
}
static int finish_passthrough(void *arg) {
  (void)arg;
  return fmbd_cli_finish(2);
}

static void test_reports(void) {
  char *argv[] = {"t120", NULL};
  int st;
  fmbd_cli_init("t120", 1, argv);
  const char *e = capture_stderr(finish_format, NULL, &st);
  EXPECT(st == 1 && !strcmp(e, "t120: error: rod.fe.h5:/K/indptr: not increasing at row 3\n"),
         "status %d, stderr '%s'", st, e);
  fmbd_cli_set_verbosity(0, 2);  // -vv: the source location too
  e = capture_stderr(finish_format, NULL, &st);
  EXPECT(st == 1 && strstr(e, "raised at src.c:12 in fn()"), "-vv: '%s'", e);
  fmbd_cli_set_verbosity(0, 0);
  e = capture_stderr(finish_usage, NULL, &st);
  EXPECT(st == 2 && strstr(e, "t120: error: option --E: 'x'") && strstr(e, "Try 't120 --help'."),
         "usage: %d '%s'", st, e);
  e = capture_stderr(usage_error, NULL, &st);
  EXPECT(st == 2 && !strcmp(e, "t120: error: unknown option '--bogus'\nTry 't120 --help'.\n"),
         "usage_error: %d '%s'", st, e);
  e = capture_stderr(finish_passthrough, NULL, &st);
  EXPECT(st == 2 && !*e, "finish(2): %d '%s'", st, e);
  e = capture_stderr(finish_ok, NULL, &st);
  EXPECT(st == 0 && !*e, "finish(0): %d '%s'", st, e);
  e = capture_stderr(summary, NULL, &st);
  EXPECT(!strncmp(e, "t120: rod.fe.h5: 12 dofs, ", 26) && strstr(e, " s wall, ") &&
             strstr(e, " s cpu\n"),
         "summary '%s'", e);
  fmbd_cli_set_verbosity(1, 0);  // -q: no summary
  e = capture_stderr(summary, NULL, &st);
  EXPECT(!*e, "-q summary '%s'", e);
  fmbd_cli_set_verbosity(0, 0);
  const char *h = fmbd_cli_exit_help();
  EXPECT(strstr(h, "Exit status") && strstr(h, "  0 ") && strstr(h, "  1 ") && strstr(h, "  2 "),
         "exit help: %s", h);
  // wrapping the previous message and context in a new one (arguments inside the record)
  fmbd_err_clear();
  fmbd_err_context("a.h5", "/x");
  fmbd_err_set(FMBD_ERR_VALUE, "s.c", 1, "f", "inner");
  fmbd_err_set(FMBD_ERR_VALUE, "s.c", 2, "f", "outer: %s", fmbd_err_get()->msg);
  fmbd_err_contextf(fmbd_err_get()->file, "%s/y", fmbd_err_get()->where);
  EXPECT(!strcmp(fmbd_err_get()->msg, "outer: inner") && !strcmp(fmbd_err_get()->where, "/x/y") &&
             !strcmp(fmbd_err_get()->file, "a.h5"),
         "wrapped: '%s' at '%s:%s'", fmbd_err_get()->msg, fmbd_err_get()->file,
         fmbd_err_get()->where);
  EXPECT(fmbd_err_exit_status(FMBD_ERR_USAGE) == 2 && fmbd_err_exit_status(FMBD_ERR_IO) == 1 &&
             fmbd_err_exit_status(FMBD_OK) == 0,
         "exit statuses");
}

// --- the option parser ------------------------------------------------------------------------
enum { O_OUT = 1, O_TOL, O_FLAG, O_LIST };
static const fmbd_cli_option OPTS[] = {{"--output", 'o', true, O_OUT},
                                       {"--tol", 0, true, O_TOL},
                                       {"--flag", 'f', false, O_FLAG},
                                       {"--list", 0, true, O_LIST},
                                       {0}};
typedef struct parse_case {
  int argc;
  char **argv;
  char got[512];  // "id:value|..." of every item, "EXIT<status>" at a stop
  fmbd_cli_args p;
} parse_case;
static int run_parser(void *arg) {
  parse_case *c = arg;
  fmbd_cli_args_init(&c->p, c->argc, c->argv, OPTS, "help text of t120\n");
  c->got[0] = '\0';
  size_t n = 0;
  for (int id; (id = fmbd_cli_next(&c->p)) != FMBD_CLI_END;) {
    if (id == FMBD_CLI_EXIT) {
      n += (size_t)snprintf(c->got + n, sizeof c->got - n, "EXIT%d", c->p.status);
      break;
    }
    n += (size_t)snprintf(c->got + n, sizeof c->got - n, "%d:%s:%s|", id, c->p.opt ? c->p.opt : "",
                          c->p.value ? c->p.value : "");
  }
  return 0;
}
static const char *parse_line(parse_case *c, const char *line, const char **err) {
  static char buf[512];
  static char *argv[32];
  snprintf(buf, sizeof buf, "t120 %s", line);
  c->argc = 0;
  for (char *s = buf, *save = NULL, *t; (t = strtok_r(s, " ", &save)); s = NULL)
    argv[c->argc++] = t;
  argv[c->argc] = NULL;
  c->argv = argv;
  int st;
  *err = capture_stderr(run_parser, c, &st);
  return c->got;
}

static void test_parser(void) {
  parse_case c;
  const char *e, *g;
  // forms of values: --opt v, --opt=v, -o v, -ov; flags; arguments anywhere; "-" and "--"
  g = parse_line(&c, "a --tol 1e-3 --tol=2 -o x -oy --flag -f - b -- --tol", &e);
  EXPECT(!strcmp(g,
                 "-1::a|2:--tol:1e-3|2:--tol:2|1:-o:x|1:-o:y|3:--flag:|3:-f:|-1::-|-1::b|"
                 "-1::--tol|") &&
             !*e,
         "forms: '%s' '%s'", g, e);
  // the common options: counted; --help prints the text and the exit statuses, status 0
  g = parse_line(&c, "-q -v -vv x", &e);
  EXPECT(!strcmp(g, "-1::x|") && c.p.quiet == 1 && c.p.verbose == 3, "counts: '%s' q %d v %d", g,
         c.p.quiet, c.p.verbose);
  fflush(stdout);
  // usage errors: exit status 2, the program, the option, and the way to help
  static const struct {
    const char *line, *msg;
  } bad[] = {{"--bogus", "t120: error: unknown option '--bogus'\nTry 't120 --help'.\n"},
             {"-x", "t120: error: unknown option '-x'\n"},
             {"-fz", "t120: error: unknown option '-fz'\n"},
             {"--tol", "t120: error: option --tol needs a value\n"},
             {"--flag=1", "t120: error: option --flag takes no value ('--flag=1')\n"},
             {"--tolerance 1", "t120: error: unknown option '--tolerance'\n"}};
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    g = parse_line(&c, bad[i].line, &e);
    EXPECT(!strcmp(g, "EXIT2") && !strncmp(e, bad[i].msg, strlen(bad[i].msg)), "'%s': '%s' '%s'",
           bad[i].line, g, e);
  }
}

static int number_case(void *arg) {
  fmbd_cli_args *p = arg;
  double d = 0;
  return fmbd_cli_double(p, 0, 1, FMBD_CLI_OPEN_LO, &d);
}
static int long_case(void *arg) {
  fmbd_cli_args *p = arg;
  long l = 0;
  return fmbd_cli_long(p, 1, LONG_MAX, &l);
}
static int list_case(void *arg) {
  double v[2];
  return fmbd_cli_numbers("--window", arg, 2, ':', v);
}

static int names_case(void *arg) {
  fmbd_cli_names *l = ((void **)arg)[0];
  return fmbd_cli_names_parse("--boundary", ((void **)arg)[1], l);
}

static void test_names(void) {
  fmbd_cli_names l = {0};
  int st;
  void *a[2] = {&l, "end0,,end1,"};
  const char *e = capture_stderr(names_case, a, &st);
  EXPECT(st == 0 && !*e && l.n == 2 && !strcmp(l.name[0], "end0") && !strcmp(l.name[1], "end1"),
         "names: %d '%s' n = %d", st, e, l.n);
  a[1] = "clamp";  // a repeated option keeps the last value
  e = capture_stderr(names_case, a, &st);
  EXPECT(st == 0 && l.n == 1 && !strcmp(l.name[0], "clamp"), "names again: %d n = %d", st, l.n);
  a[1] = ",,";
  e = capture_stderr(names_case, a, &st);
  EXPECT(st == 2 && strstr(e, "--boundary ',,': no name") && l.n == 0 && !l.name,
         "no name: %d '%s'", st, e);
  fmbd_cli_names_free(&l);
}

static void test_numbers(void) {
  fmbd_cli_args p = {.opt = "--tol"};
  int st;
  const char *e;
  static const struct {
    const char *text, *msg;  // msg NULL: accepted
  } dc[] = {{"1", NULL},
            {"0.5", NULL},
            {"0", "option --tol: '0' is outside (0, 1]"},
            {"1.5", "option --tol: '1.5' is outside (0, 1]"},
            {"nan", "option --tol: 'nan' is not a finite number"},
            {"1x", "option --tol: '1x' is not a finite number"}};
  for (size_t i = 0; i < sizeof dc / sizeof dc[0]; i++) {
    p.value = dc[i].text;
    e = capture_stderr(number_case, &p, &st);
    if (dc[i].msg) {
      EXPECT(st == 2 && p.status == 2 && strstr(e, dc[i].msg), "'%s': %d '%s'", dc[i].text, st, e);
    } else {
      EXPECT(st == 0 && !*e, "'%s': %d '%s'", dc[i].text, st, e);
    }
  }
  p.opt = "--modes";
  p.value = "0";
  e = capture_stderr(long_case, &p, &st);
  EXPECT(st == 2 && strstr(e, "option --modes: '0' must be >= 1"), "long: %d '%s'", st, e);
  p.value = "7";
  e = capture_stderr(long_case, &p, &st);
  EXPECT(st == 0 && !*e, "long 7: %d '%s'", st, e);
  e = capture_stderr(list_case, "0.5:2", &st);
  EXPECT(st == 0 && !*e, "list: %d '%s'", st, e);
  e = capture_stderr(list_case, "0.5,2", &st);
  EXPECT(
      st == 2 && strstr(e, "option --window: '0.5,2' is not a list of 2 numbers separated by ':'"),
      "list: %d '%s'", st, e);
  e = capture_stderr(list_case, "0.5:2:3", &st);
  EXPECT(st == 2, "list of 3: %d '%s'", st, e);
}

int main(void) {
  unsetenv("FMBD_LOG");
  const char *root = getenv("ROOT"), *build = getenv("BUILD");
  snprintf(g_dir, sizeof g_dir, "%s/%s/test-tmp/t120-cli", root ? root : ".",
           build ? build : "build");
  char cmd[2200];
  snprintf(cmd, sizeof cmd, "mkdir -p '%s'", g_dir);
  if (system(cmd) != 0) return 1;
  test_output_name();
  test_parse();
  test_command_line();
  test_reports();
  test_parser();
  test_numbers();
  test_names();
  fmbd_cli_finish(0);
  // the shared options: counted, and anything else left to the program
  {
    int q = 0, v = 0;
    EXPECT(fmbd_cli_common_option("-q", "", &q, &v) == FMBD_CLI_TAKEN && q == 1, "-q");
    EXPECT(fmbd_cli_common_option("--verbose", "", &q, &v) == FMBD_CLI_TAKEN && v == 1,
           "--verbose");
    EXPECT(fmbd_cli_common_option("-vv", "", &q, &v) == FMBD_CLI_TAKEN && v == 3, "-vv");
    EXPECT(fmbd_cli_common_option("--modes", "", &q, &v) == FMBD_CLI_OTHER && q == 1 && v == 3,
           "other");
    EXPECT(fmbd_cli_common_option("-vvv", "", &q, &v) == FMBD_CLI_OTHER, "-vvv is not ours");
  }
  TEST_EXIT();
}
