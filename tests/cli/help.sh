#!/bin/bash
# tests/cli/help.sh: every program answers --help (ending with its exit statuses) and
# --version, rejects an unknown option with status 2, and has a man page that man can render.
set -u
fail=0
for p in mesh2fe fe2cb cbcheck gmsolve fmbd-run fe2cb-mpi cbcheck-mpi; do
  [ -f "$ROOT/$p/main.c" ] || continue
  case $p in *-mpi) [ -x "$ROOT/$BUILD/bin/$p" ] || continue ;; esac  # no PETSc here: tests/cli/mpi.sh says SKIP
  exe="$ROOT/$BUILD/bin/$p"
  # the MPI programs start Open MPI before parsing their options; its allocations at exit (in
  # components it has unloaded, which LeakSanitizer cannot name for a suppression) are not
  # ours: leak checks off for them, as in tests/cli/mpi.sh (the other sanitizer checks stay)
  case $p in *-mpi) export ASAN_OPTIONS=${ASAN_OPTIONS:+$ASAN_OPTIONS:}detect_leaks=0 ;; esac
  out=$("$exe" --help 2>&1) || { echo "$p --help: exit $?"; fail=1; }
  grep -q "Exit status" <<<"$out" || { echo "$p --help: no exit status list"; fail=1; }
  grep -q -- "$p" <<<"$out" || { echo "$p --help: does not name the program"; fail=1; }
  v=$("$exe" --version 2>&1) || { echo "$p --version: exit $?"; fail=1; }
  grep -q "$(cat "$ROOT/VERSION")" <<<"$v" || { echo "$p --version: '$v' lacks the version"; fail=1; }
  "$exe" --no-such-option >/dev/null 2>&1
  st=$?
  [ $st -eq 2 ] || { echo "$p --no-such-option: exit $st, expected 2"; fail=1; }
  page="$ROOT/docs/man/$p.1"
  if [ ! -f "$page" ]; then
    echo "$p: no man page docs/man/$p.1"; fail=1
  elif command -v man >/dev/null 2>&1; then
    MANWIDTH=80 man -l "$page" 2>&1 >/dev/null | grep -i -E 'warning|error' && { echo "$p: man page warnings"; fail=1; }
  else
    echo "$p: man (man-db, installed by make check) missing: the man page lint cannot run"; fail=1
  fi
done
exit $fail
