#!/bin/bash
# tests/cli/readme.sh: the README's examples run as written: every indented command line of
# the "A tour of the pipeline" section that starts with a program name, in order, in a scratch
# folder that sees the repository's examples/, then the README's h5py snippet on the files
# they made. Fails on the first command that fails or on a file the snippet cannot read.
set -u
T=$ROOT/$BUILD/test-tmp/readme
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
ln -s "$ROOT/examples" examples
tour=$(sed -n '/^## A tour of the pipeline/,/^## /p' "$ROOT/README.md" |
       grep -E '^    (mesh2fe|fe2cb|cbcheck|fmbd-run) ' | sed 's/^    //')
n=$(grep -c . <<<"$tour")
[ "$n" -ge 6 ] || { echo "README tour: found $n commands, expected at least 6"; exit 1; }
while IFS= read -r cmd; do
  echo "\$ $cmd"
  bash -o pipefail -c "$cmd" || { echo "README command failed: $cmd"; exit 1; }
done <<<"$tour"
for f in rod.fe.h5 rod.cb.h5 rod.rflex.h5 rod-pipe.rflex.h5 quadpend.run.h5 rod.csv rod-estimates.svg \
         rod-convergence.svg quadpend-A-trajectory.svg; do
  [ -s "$f" ] || { echo "README tour did not make $f"; exit 1; }
done
# the h5py snippet, verbatim
sed -n '/^## Reading the files in h5py/,/^## /p' "$ROOT/README.md" |
  sed -n '/^```python$/,/^```$/p' | sed '1d;$d' > snippet.py
[ -s snippet.py ] || { echo "README: no python snippet found"; exit 1; }
"$PYTHON" snippet.py || { echo "README h5py snippet failed"; exit 1; }
echo "README: $n commands and the h5py snippet ran"
