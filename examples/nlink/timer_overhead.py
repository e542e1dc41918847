#!/usr/bin/python3
# examples/nlink/timer_overhead.py: the cost of fmbd-run's own clock readings around the Newton
# phases (/stats factor_cpu_time_s, solve_cpu_time_s, eval_cpu_time_s): runs scenes with two
# fmbd-run binaries, interleaved, and prints each one's run_cpu_time_s (min and median of REPS)
# and the spread of the timed runs' linear-solve CPU (factor_cpu_time_s + solve_cpu_time_s).
# PLAIN is fmbd-run built with the readings in attempt() removed, for instance
#   sed -i.orig 's/fmbd_wall_s()/0.0/' common/fmbd_mbs_step.c && make && cp build/bin/fmbd-run /tmp/plain
#   mv common/fmbd_mbs_step.c.orig common/fmbd_mbs_step.c && make
#
#   /usr/bin/python3 examples/nlink/timer_overhead.py PLAIN TIMED DIR REPS SCENE [SCENE ...]
#       (SCENE: a scene of DIR without .yaml, e.g. the runs of nlink.py --out DIR)
import os
import statistics
import subprocess
import sys
import tempfile

import h5py


def main():
    if len(sys.argv) < 6:
        sys.exit(__doc__ or "usage: timer_overhead.py PLAIN TIMED DIR REPS SCENE [SCENE ...]")
    plain, timed, d, reps, scenes = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5:]
    res = {}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(reps):
            for sc in scenes:
                for tag, exe in (("without", plain), ("with", timed)):
                    out = os.path.join(tmp, "%s_%s.run.h5" % (sc, tag))
                    subprocess.run([os.path.abspath(exe), sc + ".yaml", "-o", out, "-q"], cwd=d, check=True)
                    with h5py.File(out, "r") as f:
                        a = f["stats"].attrs
                        lin = float(a["factor_cpu_time_s"] + a["solve_cpu_time_s"]) if tag == "with" else 0
                        res.setdefault((sc, tag), []).append((float(a["run_cpu_time_s"]), int(a["newton_iterations"]),
                                                              lin))
    print("| scene | Newton iterations | run CPU without (min / median, s) | with (min / median, s) | ratio of the minima "
          "| linear-solve CPU (min / median / max, s) |")
    print("|---|---|---|---|---|---|")
    for sc in scenes:
        a, b = [x[0] for x in res[(sc, "without")]], [x[0] for x in res[(sc, "with")]]
        c = [x[2] for x in res[(sc, "with")]]
        print("| %s | %d | %.4f / %.4f | %.4f / %.4f | %.3f | %.4f / %.4f / %.4f |" % (
            sc, res[(sc, "with")][0][1], min(a), statistics.median(a), min(b), statistics.median(b), min(b) / min(a),
            min(c), statistics.median(c), max(c)))


if __name__ == "__main__":
    main()
