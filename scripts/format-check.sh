#!/bin/bash
# scripts/format-check.sh: the project's .clang-format holds in every C and C++ source.
# Run by `make check` (tests/run.sh, as lint/clang-format) and so by CI; `make format` fixes.
# With --fix, reformat in place instead of checking.
set -u
cd "$(dirname "$0")/.."
if git rev-parse --is-inside-work-tree > /dev/null 2>&1; then
  mapfile -t files < <(git ls-files '*.c' '*.h' '*.cpp')
else
  mapfile -t files < <(find common mesh2fe fe2cb cbcheck gmsolve fmbd-run tests -name '*.[ch]' -o -name '*.cpp' 2>/dev/null)
fi
command -v clang-format > /dev/null || { echo "clang-format not installed (scripts/install-deps.sh)"; exit 1; }
if [ "${1:-}" = --fix ]; then
  clang-format -i "${files[@]}"
  exit 0
fi
err=$(mktemp)
trap 'rm -f "$err"' EXIT
if clang-format --dry-run --Werror "${files[@]}" 2> "$err"; then
  echo "${#files[@]} files follow .clang-format"
  exit 0
fi
grep -E '^[^ ]+:[0-9]+:[0-9]+: error' "$err" | sed 's/: error: code should be clang-formatted.*//' | head -40
echo "$(grep -c ': error' "$err") places in $(grep -E ': error' "$err" | cut -d: -f1 | sort -u | wc -l) files differ from .clang-format; 'make format' fixes them"
exit 1
