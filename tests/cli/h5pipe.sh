#!/bin/bash
# tests/cli/h5pipe.sh: HDF5 files through pipes (stdin/stdout file images) and atomic output,
# with the test tool h5roundtrip (tests/tools/h5roundtrip.c), checked in h5py.
set -u
T=$ROOT/$BUILD/test-tmp/h5pipe
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
err() { echo "FAIL: $*"; fail=1; }

# --- a file made on stdout, through two programs on pipes, into a named file ---------------
h5roundtrip --make 30000 | h5roundtrip - /x | h5roundtrip - /x -o out.h5 2>log || err "pipeline failed: $(cat log)"
[ -f out.h5 ] && [ ! -e out.h5.part ] || err "out.h5 missing or .part left"
grep -q '^h5roundtrip: out.h5: /x copied, .* s wall, .* s cpu$' log || err "summary line: $(cat log)"
# the same, with -o - explicitly and a named input
h5roundtrip --make 30000 -o made.h5 2>/dev/null || err "--make -o"
h5roundtrip made.h5 /x -o - 2>/dev/null > viaout.h5 || err "-o -"
sha_made=$(sha256sum made.h5 | cut -d' ' -f1)

"$PYTHON" - "$sha_made" <<'EOF' || fail=1
import sys, h5py, numpy as np, scipy.sparse as sp
ok = True
def check(cond, what):
    global ok
    if not cond:
        print("FAIL:", what); ok = False
with h5py.File("out.h5", "r") as f:
    a = f.attrs
    check(a["format"] == "fmbd-test" and a["format_version"] == "1.0", "format %r" % dict(a))
    check(a["creator"].startswith("h5roundtrip "), "creator %r" % a["creator"])
    check(a["command_line"].endswith("h5roundtrip - /x -o out.h5"), "command_line %r" % a["command_line"])
    check(a["inputs"].shape == (1, 2) and a["inputs"][0, 0] == "-" and len(a["inputs"][0, 1]) == 64,
          "inputs %r" % a["inputs"])
    check(float(a["wall_time_s"]) >= 0 and float(a["cpu_time_s"]) >= 0, "times")
    x = f["x"][()]
    # values are written and read as IEEE doubles: exactly equal
    check(x.shape == (30000,) and np.array_equal(x, np.arange(30000.0)), "x")
    check(np.array_equal(f["copy"][()], x), "copy")
    check(f["x"].compression == "gzip" and f["x"].shuffle, "x chunked and compressed")
    check(np.array_equal(f["sub/m"][()], [[1, 2], [3, 4], [5, 6]]), "col-major matrix %r" % f["sub/m"][()])
    g = f["K"]
    K = sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
    check(g.attrs["encoding-type"] == "csr_matrix", "encoding-type")
    check(np.array_equal(K.toarray(), [[4, 0, -1], [0, 3, 0], [-1, 0, 5]]), "csr %r" % K.toarray())
with h5py.File("viaout.h5", "r") as f:
    check(f.attrs["inputs"][0, 0] == "made.h5" and f.attrs["inputs"][0, 1] == sys.argv[1],
          "named input and its sha256 %r" % f.attrs["inputs"])
    check(np.array_equal(f["x"][()], np.arange(30000.0)), "x via -o -")
print("h5py checks:", "ok" if ok else "FAILED")
sys.exit(0 if ok else 1)
EOF

# --- failures: exit status, a message naming file and path, no output left ----------------
expect_fail() {  # status, regex of the message, output that must not exist, command...
  local want=$1 re=$2 out=$3; shift 3
  "$@" >stdout.bin 2>err.txt; local st=$?
  [ $st -eq "$want" ] || err "$*: exit $st, expected $want"
  grep -Eq "$re" err.txt || err "$*: message '$(cat err.txt)' does not match '$re'"
  [ -n "$out" ] && { [ -e "$out" ] || [ -e "$out.part" ]; } && err "$*: $out or $out.part left behind"
  return 0
}
expect_fail 1 '^h5roundtrip: error: made.h5:/nope: missing dataset$' o1.h5 h5roundtrip made.h5 /nope -o o1.h5
# the output is created before the failing read: it must be removed
expect_fail 1 '^h5roundtrip: error: made.h5:/no/such/dataset: missing dataset$' o2.h5 \
  h5roundtrip made.h5 /x -o o2.h5 --fail
expect_fail 1 '^h5roundtrip: error: .*nodir/o3.h5: cannot create .*No such file or directory' "" \
  h5roundtrip made.h5 /x -o nodir/o3.h5
[ -e nodir ] && err "nodir created"
expect_fail 1 '^h5roundtrip: error: missing.h5: cannot open: No such file or directory$' o4.h5 \
  h5roundtrip missing.h5 /x -o o4.h5
echo "not hdf5" > text.h5
expect_fail 1 '^h5roundtrip: error: text.h5: not an HDF5 file' o5.h5 h5roundtrip text.h5 /x -o o5.h5
head -c 2000 made.h5 > cut.h5
expect_fail 1 '^h5roundtrip: error: <stdin>: not an HDF5 file, or truncated' o6.h5 \
  sh -c 'h5roundtrip - /x -o o6.h5 < cut.h5'
expect_fail 1 '^h5roundtrip: error: <stdin>: empty input' o7.h5 sh -c 'h5roundtrip - /x -o o7.h5 < /dev/null'
expect_fail 2 "^Try 'h5roundtrip --help'.$" "" h5roundtrip --bogus
expect_fail 2 "option --make: 'x' is not an integer" "" h5roundtrip --make x -o o8.h5
# a failed write to standard output writes nothing there
h5roundtrip made.h5 /x -o - --fail > piped.h5 2>/dev/null
[ $? -eq 1 ] && [ ! -s piped.h5 ] || err "--fail to stdout: status or output"
# -vv adds the source location of the failure
FMBD_LOG=debug h5roundtrip made.h5 /nope -o o9.h5 2>err.txt
grep -q 'debug: raised at common/fmbd_h5.c:[0-9]* in ' err.txt || err "no source location under debug: $(cat err.txt)"

# an output that exists and is not a regular file is written in place, never replaced by a
# renamed .part (-o /dev/null once turned /dev/null into a regular file): a FIFO read by cat
mkfifo fifo.h5
timeout 30 cat fifo.h5 > fromfifo.h5 &  # bounded: a program that never opens the FIFO
catpid=$!
h5roundtrip made.h5 /x -o fifo.h5 2>err.txt || err "-o a FIFO: $(cat err.txt)"
wait $catpid
[ -p fifo.h5 ] && [ ! -e fifo.h5.part ] || err "-o a FIFO: the FIFO was replaced or a .part left"
"$PYTHON" -c "import h5py, numpy as np, sys; f = h5py.File('fromfifo.h5', 'r'); sys.exit(0 if np.array_equal(f['x'][()], np.arange(30000.0)) else 1)" ||
  err "-o a FIFO: what came through is not the file"
mkdir adir
expect_fail 1 '^h5roundtrip: error: .*adir: cannot create adir: Is a directory' "" h5roundtrip made.h5 /x -o adir

exit $fail
