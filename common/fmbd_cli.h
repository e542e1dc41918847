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
int fmbd_cli_common_option(const char *arg, const char *help_text, int *quiet, int *verbose);

#endif
