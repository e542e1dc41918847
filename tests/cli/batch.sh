#!/bin/bash
# tests/cli/batch.sh: the batch example (examples/batch/Makefile) on four tiny brackets, one of
# them broken (wall thickness 0: gmsh refuses the degenerate box). Checks the example's three
# rules: (1) make's jobs x BLAS threads never exceed the cores, whatever the environment says;
# (2) under make -k the broken body is named and the others complete, with no half-written
# file of the broken one; (3) a rerun rebuilds only the bodies whose parameters changed (none
# when none changed). Then the summary: one row per body, and the sample's exact error below
# the selected upper estimate.
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
T=$ROOT/$BUILD/test-tmp/cli-batch
rm -rf "$T" && mkdir -p "$T" || exit 1
cd "$ROOT" || exit 1
fail=0
bad() { echo "FAIL: $*"; fail=1; }
MK=(make --no-print-directory -f examples/batch/Makefile BUILD="$BUILD" OUT="$T/out"
    VARIANTS="$T/variants.csv" SAMPLE=t1 PYTHON="$PYTHON")
cores=$(env -u OMP_NUM_THREADS -u OMP_THREAD_LIMIT nproc)

# --- (1) cores --------------------------------------------------------------------------------
for j in -j1 -j2 -j -j4; do
  line=$(OPENBLAS_NUM_THREADS=8 OMP_NUM_THREADS=8 make -s -f examples/batch/Makefile $j threads)
  read -r _ c _ jobs _ ob _ omp <<< "$line"
  [ "$c" = "$cores" ] || bad "$j: cores $c, nproc says $cores"
  [ "$ob" = "$omp" ] || bad "$j: OPENBLAS_NUM_THREADS $ob != OMP_NUM_THREADS $omp"
  [ "$ob" -ge 1 ] || bad "$j: $ob threads"
  # more jobs than cores is the caller's choice; then one thread each
  if [ "$jobs" -le "$cores" ]; then
    [ $((jobs * ob)) -le "$cores" ] || bad "$j: $jobs jobs x $ob threads > $cores cores"
  else
    [ "$ob" -eq 1 ] || bad "$j: $jobs jobs > $cores cores but $ob threads each"
  fi
  case $j in
    -j1) [ "$jobs" -eq 1 ] && [ "$ob" -eq "$cores" ] || bad "-j1: $line" ;;
    -j) [ "$ob" -eq 1 ] || bad "-j (no limit): $line" ;;
  esac
done

# --- (2) a broken body under make -k ----------------------------------------------------------
cat > "$T/variants.csv" <<'EOF'
name,L,W,H,T,R,h
t1,0.05,0.02,0.03,0.004,0.004,0.008
t2,0.06,0.02,0.03,0.004,0.004,0.008
t3,0.05,0.02,0.04,0.004,0.004,0.008
t4,0.05,0.02,0.03,0,0.004,0.008
EOF
"${MK[@]}" -j2 -k > "$T/run1.txt" 2>&1
rc=$?
[ $rc -ne 0 ] || bad "make -k with a broken body exited 0"
grep -q "\*\*\* \[.*t4\.fe\.h5\] Error" "$T/run1.txt" || bad "make does not name the broken body t4: $(cat "$T/run1.txt")"
grep -q "mesh2fe: error: .*t4\.geo: .*Degenerate box" "$T/run1.txt" \
  || bad "mesh2fe's message does not name t4.geo and the cause: $(grep error "$T/run1.txt")"
for b in t1 t2 t3; do
  [ -s "$T/out/$b.rflex.h5" ] || bad "body $b not completed next to the broken t4"
done
ls "$T"/out/t4.fe.h5* > /dev/null 2>&1 && bad "half-written files of t4 left: $(ls "$T"/out/t4.fe.h5*)"
[ -e "$T/out/summary.csv" ] && bad "summary written although t4 failed"

# --- (3) reruns rebuild only what changed -----------------------------------------------------
stamp() { stat -c %Y.%y "$T/out/$1.rflex.h5" 2> /dev/null; }
sed -i 's/^t4,0.05,0.02,0.03,0,/t4,0.05,0.02,0.03,0.004,/' "$T/variants.csv"  # repaired
s1=$(stamp t1) s2=$(stamp t2) s3=$(stamp t3)
"${MK[@]}" -j2 -k > "$T/run2.txt" 2>&1 || bad "make after repairing t4 failed: $(tail -5 "$T/run2.txt")"
n=$(grep -c 'bin/mesh2fe ' "$T/run2.txt")
[ "$n" -eq 1 ] || bad "after repairing t4, mesh2fe ran $n times (expected once, for t4)"
grep -q 'bin/mesh2fe .*t4\.geo' "$T/run2.txt" || bad "t4 not rebuilt: $(cat "$T/run2.txt")"
[ "$(stamp t1)" = "$s1" ] && [ "$(stamp t2)" = "$s2" ] && [ "$(stamp t3)" = "$s3" ] \
  || bad "repairing t4 rebuilt other bodies"
[ -s "$T/out/summary.csv" ] && [ -s "$T/out/summary.svg" ] || bad "no summary after the full batch"

# nothing changed: no program runs
"${MK[@]}" -j2 -k > "$T/run3.txt" 2>&1 || bad "unchanged rerun failed"
grep -q 'bin/\(mesh2fe\|fe2cb\|cbcheck\) ' "$T/run3.txt" && bad "unchanged rerun ran a program: $(cat "$T/run3.txt")"

# one parameter of t2 changed: only t2's chain
sed -i 's/^t2,0.06,0.02,0.03,/t2,0.06,0.02,0.035,/' "$T/variants.csv"
s1=$(stamp t1) s3=$(stamp t3) s4=$(stamp t4)
sleep 1  # a rebuilt file must get a different time stamp (1 s resolution of some filesystems)
"${MK[@]}" -j2 -k > "$T/run4.txt" 2>&1 || bad "make after changing t2 failed: $(tail -5 "$T/run4.txt")"
progs=$(grep -o 'bin/\(mesh2fe\|fe2cb\|cbcheck\) [^ ]*' "$T/run4.txt" | sort | tr '\n' ' ')
[ "$progs" = "bin/cbcheck $T/out/t2.cb.h5 bin/fe2cb $T/out/t2.fe.h5 bin/mesh2fe $T/out/t2.geo " ] \
  || bad "changing t2's H ran: $progs"
[ "$(stamp t1)" = "$s1" ] && [ "$(stamp t3)" = "$s3" ] && [ "$(stamp t4)" = "$s4" ] \
  || bad "changing t2 touched other bodies"
grep -q '^H = 0.035;\|H = 0.035;' "$T/out/t2.geo" || bad "t2.geo does not carry the new H"

# --- the summary ------------------------------------------------------------------------------
"$PYTHON" - "$T/out/summary.csv" <<'PY' || fail=1
import csv, sys
rows = {r["name"]: r for r in csv.DictReader(open(sys.argv[1]))}
ok = True
def check(cond, msg):
    global ok
    if not cond:
        print("FAIL:", msg); ok = False
check(sorted(rows) == ["t1", "t2", "t3", "t4"], f"summary rows {sorted(rows)}")
for n, r in rows.items():
    check(int(r["dofs"]) > 1000 and int(r["nd"]) >= 5, f"{n}: dofs {r['dofs']}, Nd {r['nd']}")
    check(float(r["max_upper"]) <= 1e-3, f"{n}: upper estimate {r['max_upper']} above tol 1e-3")
    check(float(r["wall_s"]) > 0 and float(r["peak_mb"]) > 1, f"{n}: time/memory {r['wall_s']} {r['peak_mb']}")
check(float(rows["t2"]["H"]) == 0.035, "t2's new H not in the summary")
# the sample body t1 ran with --exact: the upper estimate bounds the exact error (Han et al.
# 2020: the upper estimate is an upper bound for well-separated modes; a few % of slack are not
# needed on this body, whose 6 modes are separated)
e, u = rows["t1"]["max_exact"], float(rows["t1"]["max_upper"])
check(e != "" and 0 < float(e) <= u, f"t1: exact {e!r} vs upper {u}")
check(all(rows[n]["max_exact"] == "" for n in ("t2", "t3", "t4")), "exact errors outside the sample")
sys.exit(0 if ok else 1)
PY
exit $fail
