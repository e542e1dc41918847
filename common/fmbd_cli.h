// common/fmbd_cli.h: what every program's main() shares: command line, names, exit, summary
// SPDX-License-Identifier: MIT
#ifndef FMBD_CLI_H
#define FMBD_CLI_H

#include <stdbool.h>

/// @brief The toolchain version (the VERSION file, via -DFMBD_VERSION).
const char *fmbd_version(void);

/// @brief Start of every main(): program name for messages, the command line (kept for the
/// command_line attribute), start of the wall/CPU timer, HDF5 error printing off.
void fmbd_cli_init(const char *prog, int argc, char **argv);
/// @brief Handle SIGINT, SIGTERM and SIGHUP with `handler` (fmbd_cli_init installs one that
/// removes the output being written and exits 1; fmbd_runfile_catch_signals one that only sets a
/// flag, so that a run keeps its valid prefix).
void fmbd_cli_on_signals(void (*handler)(int));
/// @brief The command line as one shell-quoted string (borrowed).
const char *fmbd_cli_command_line(void);
/// @brief Seconds of wall / CPU time since fmbd_cli_init.
double fmbd_cli_wall_s(void);
double fmbd_cli_cpu_s(void);

/// @brief Verbosity from counted -q / -v flags: sets the log level (fmbd_log_init).
void fmbd_cli_set_verbosity(int quiet, int verbose);

/// @brief Where output goes. opt_o given: that name ("-" = standard output). opt_o NULL:
/// "-" if standard output is not a terminal, else the input name with its ending replaced:
/// the longest of `strip` (NULL-terminated list, e.g. {".fe.h5", ".h5", NULL}) that ends the
/// input is cut (else the last ".ext"), then `suffix` appended ("rod.geo" -> "rod.fe.h5").
/// Input "-" with no -o and a terminal: usage error; so is a derived name equal to the input,
/// and so is an -o that names the input file itself (fmbd_cli_check_not_input).
/// @param[out] out caller frees with fmbd_free
int fmbd_cli_output_name(const char *input, const char *opt_o, const char *const *strip,
                         const char *suffix, char **out);

/// @brief The name fmbd_cli_output_name derives from a file name: the longest of `strip` that
/// ends it cut (else its last ".ext"), then `suffix` appended ("scene.yaml" -> "scene.run.h5",
/// "pend.run.h5" with {".h5"} -> "pend.run.xdmf"). A result equal to the input: usage error.
/// @param[out] out caller frees with fmbd_free
int fmbd_cli_derive_name(const char *input, const char *const *strip, const char *suffix,
                         char **out);

/// @brief True when a and b name the same existing file (same device and inode: also through
/// another path, a hard or a symbolic link). "-" (a stream) is never the same file.
bool fmbd_cli_same_file(const char *a, const char *b);
/// @brief FMBD_ERR_USAGE when the output name is the same file as an input: every program calls
/// it (through fmbd_cli_output_name for its main input, directly for others such as --fe or
/// --reference) so that -o can never overwrite what the run reads.
int fmbd_cli_check_not_input(const char *output, const char *input);

/// @brief Parse numbers of options; on failure FMBD_ERR_USAGE (recorded, not printed) naming
/// the option: "option --size: 'abc' is not a finite number". The whole text must be used.
int fmbd_cli_parse_double(const char *opt, const char *text, double *out);
int fmbd_cli_parse_int(const char *opt, const char *text, long *out);

/// @brief End of main(): for rc != 0, flush stdout and print "prog: error: FILE:WHERE:
/// message" (with the source location under -vv; "Try 'prog --help'." after a usage error);
/// return the exit status (0, 1 or 2). rc > 0 is an exit status already reported (the 2 of
/// fmbd_cli_usage_error) and is returned as is. Releases the command line.
int fmbd_cli_finish(int rc);
/// @brief Usage error: "prog: error: message" + "Try 'prog --help'." ; returns 2.
int fmbd_cli_usage_error(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/// @brief The closing summary: "prog: <message>, W s wall, C s cpu".
void fmbd_cli_summary(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/// @brief Text listing exit statuses, for the end of --help.
const char *fmbd_cli_exit_help(void);

/// What fmbd_cli_common_option did with an argument.
enum fmbd_cli_common { FMBD_CLI_OTHER = 0, FMBD_CLI_TAKEN = 1, FMBD_CLI_DONE = 2 };
/// @brief The options every program shares, in one place: -h/--help prints help_text, a blank
/// line and fmbd_cli_exit_help() on standard output; -V/--version prints "prog VERSION";
/// -q/--quiet, -v/--verbose and -vv are counted into *quiet and *verbose.
/// @return FMBD_CLI_DONE after help or version (the program exits 0), FMBD_CLI_TAKEN for
/// -q/-v/-vv, FMBD_CLI_OTHER for any other argument (the program's own options).
/// fmbd_cli_next calls it; a program rarely needs it directly.
int fmbd_cli_common_option(const char *arg, const char *help_text, int *quiet, int *verbose);

// --- the option parser of every program -----------------------------------------------------
// One loop for all programs. The program lists its options in a table ending with {0}; each
// fmbd_cli_next call returns the next one found on the command line, in order (options and
// arguments may be mixed, as with GNU getopt; "--" makes everything after it an argument, and
// "-" alone is an argument: standard input or output):
//
//   static const fmbd_cli_option opts[] = {
//       {"--output", 'o', true, OPT_OUTPUT}, {"--tol", 0, true, OPT_TOL},
//       {"--exact", 0, false, OPT_EXACT}, {0}};
//   fmbd_cli_args p;
//   fmbd_cli_args_init(&p, argc, argv, opts, usage_text);
//   for (int id; (id = fmbd_cli_next(&p)) != FMBD_CLI_END;) {
//     switch (id) {
//       case FMBD_CLI_EXIT: return p.status;  // --help/--version (0) or a usage error (2) said
//       case FMBD_CLI_ARG: input = p.value; break;  // an argument that is no option
//       case OPT_OUTPUT: output = p.value; break;
//       case OPT_TOL:  // a number in (0, 1]: else "option --tol: '2' is outside (0, 1]", exit 2
//         if (fmbd_cli_double(&p, 0, 1, FMBD_CLI_OPEN_LO, &tol)) return p.status;
//         break;
//       case OPT_EXACT: exact = true; break;
//     }
//   }
//   fmbd_cli_set_verbosity(p.quiet, p.verbose);
//
// Accepted forms: long options with a value as `--tol 1e-3` or `--tol=1e-3`; short options
// with a value as `-o FILE` or `-oFILE`; flags alone. Repeated options are returned each time
// (a program that keeps a list appends; one that keeps a value takes the last). Every program
// has the common options of fmbd_cli_common_option (-h/--help, -V/--version, -q/--quiet,
// -v/--verbose, -vv), handled inside fmbd_cli_next: they need no row in the table.
// Usage errors are printed at once as "prog: error: message" + "Try 'prog --help'." (exit
// status 2, fmbd_cli_usage_error): an unknown option, a missing value, a value given to a flag.

/// One option of a program: its long name with the dashes ("--tol", or NULL), its short letter
/// ('o', or 0), whether it takes a value, and the id (> 0) fmbd_cli_next returns for it.
typedef struct fmbd_cli_option {
  const char *name;
  char letter;
  bool value;
  int id;
} fmbd_cli_option;

/// What fmbd_cli_next returns besides an option's id (ids are > 0).
enum {
  FMBD_CLI_END = 0,   ///< no more arguments
  FMBD_CLI_ARG = -1,  ///< an argument that is not an option: p.value
  FMBD_CLI_EXIT = -2  ///< stop: help or version printed (p.status 0) or a usage error (2)
};

/// The parser's state; read p.value, p.opt, p.quiet, p.verbose, p.status (the rest is its own).
typedef struct fmbd_cli_args {
  const char *value;   ///< the current option's value (NULL for a flag), or the argument
  const char *opt;     ///< the current option as named on the command line, for messages
  int quiet, verbose;  ///< counted -q / -v (for fmbd_cli_set_verbosity)
  int status;          ///< after FMBD_CLI_EXIT or a failed fmbd_cli_double/long: exit status
  // private
  int argc, i;
  char **argv;
  const fmbd_cli_option *options;
  const char *help_text;
  bool only_args;
  char name[64];
} fmbd_cli_args;

/// @brief Start parsing argv[1..argc-1] against options (ending with a row of zeros);
/// help_text is what -h/--help prints (fmbd_cli_exit_help() is appended).
void fmbd_cli_args_init(fmbd_cli_args *p, int argc, char **argv, const fmbd_cli_option *options,
                        const char *help_text);
/// @brief The next option's id, FMBD_CLI_ARG, FMBD_CLI_END or FMBD_CLI_EXIT (see above).
int fmbd_cli_next(fmbd_cli_args *p);

/// Bounds of fmbd_cli_double / fmbd_cli_long: closed unless these flags open them.
enum { FMBD_CLI_OPEN_LO = 1, FMBD_CLI_OPEN_HI = 2 };
/// @brief The current option's value as a finite number within [lo, hi] (lo = -INFINITY or
/// hi = INFINITY: no bound on that side; FMBD_CLI_OPEN_LO / _HI make a bound strict). On a
/// bad value prints the usage error naming the program, the option and the rule ("option
/// --E: '0' must be > 0", "option --nu: '0.5' is outside (-1, 0.5)"), sets p->status = 2 and
/// returns 2; else 0.
int fmbd_cli_double(fmbd_cli_args *p, double lo, double hi, unsigned bounds, double *out);
/// @brief The same for an integer within [lo, hi] (LONG_MIN / LONG_MAX: no bound).
int fmbd_cli_long(fmbd_cli_args *p, long lo, long hi, long *out);
/// @brief Exactly n finite numbers separated by `sep` (',' for "1,2,3", ':' for "0:2.5") in
/// text; else a usage error (printed, returns 2) naming opt: "option --group: '1,2' is not a
/// list of 6 numbers separated by ','".
int fmbd_cli_numbers(const char *opt, const char *text, int n, char sep, double *v);

/// A comma-separated list of names from one option's value (e.g. `--boundary end0,end1`).
typedef struct fmbd_cli_names {
  int n;        ///< number of names (>= 1 after a successful parse)
  char **name;  ///< n names, pointing into text (owned by the struct)
  char *text;   ///< the value's copy, split in place
} fmbd_cli_names;
/// @brief Split text at ',' into l (replacing what l held: a repeated option keeps the last
/// value). Empty names are skipped; no name at all is a usage error naming opt (printed,
/// returns 2). l starts zeroed; release with fmbd_cli_names_free.
int fmbd_cli_names_parse(const char *opt, const char *text, fmbd_cli_names *l);
/// @brief Release l's arrays and zero it; a zeroed l is fine.
void fmbd_cli_names_free(fmbd_cli_names *l);

#endif
