#!/usr/bin/python3
# examples/slidercrank/floor.py: what sets the floor of the held CB bodies' error against the
# full FE model (FM) in the planar slider-crank (README.md, "What sets the held bodies' error
# floor").
# SPDX-License-Identifier: MIT
#
#   floor.py [--size H] [--t-end T] [--variants 1e-4:1e-8,1e-4:1e-10,5e-5:1e-8] [--ranges 10,20,40]
#            [--out DIR] [--prog FMBD_RUN --tag=TAG]
#
# For each variant STEP:NEWTON_TOL it runs the scene (its solver block's `step` and `newton_tol`
# replaced, t_end = T) with the rod as the FM (`file: rod.fe.h5`), as the held RFlex bodies
# with Nm = each range (cbcheck --tol 1e-2 --range Nm --hold bore0 --hold bore1: the scene's
# rule) and as the CB body of the scene's fe2cb file (120 fixed-interface modes and the 12
# constraint modes of the two RBE2 bores), all on the scene's mesh2fe chain at --size H. Then
# it prints, by 0.1 s window, the RMS of |A - A_FM| (node A's position, on the output grid of
# 1e-3 s shared by all runs) of every body against the FM of the same variant, and of the FM
# and the first Nm body against the first variant's: a floor set by the integration moves
# with the step, one set by the Newton leftover with newton_tol. --prog runs another build of
# fmbd-run (README.md: one whose Newton test stops at 30 eps instead of 1e3 eps of each
# coordinate's scale), its run files named with TAG, and compares its runs with fmbd-run's
# where those exist. Writes DIR/floor[TAG].md; made files are reused when present.
# Programs are taken from PATH (make puts build/bin first).
import argparse
import os
import re
import subprocess
import sys

import h5py
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SCENE = os.path.join(HERE, "slidercrank.yaml")
WINDOWS = ((0.0, 0.1), (0.1, 0.2), (0.2, 0.3), (0.3, 0.4), (0.4, 0.5))


def sh(cmd, cwd):
    p = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("floor.py: failed (%d): %s\n%s" % (p.returncode, " ".join(cmd), p.stderr))
    return p


def variant(text, body_file, t_end, step, ntol):
    """The scene with the rod's file, the solver's step, newton_tol and t_end replaced, no make chain."""
    out, skip = [], False
    for line in text.splitlines():
        if skip:
            if line.startswith("      "):
                continue
            skip = False
        if line.strip() == "make:" and line.startswith("    "):
            skip = True
            continue
        if line.strip() == "file: rod.rflex.h5":
            line = "    file: " + body_file
        if line.startswith("  step:"):
            line = "  step: %s\n  newton_tol: %s" % (step, ntol)
        if line.startswith("  t_end:"):
            line = "  t_end: %g" % t_end
        out.append(line)
    return "\n".join(out) + "\n"


def track(run):
    with h5py.File(run, "r") as f:
        return f["time"][()], f["outputs/A/position"][()], float(f["stats"].attrs["run_cpu_time_s"])


def windows(t, d, t_end):
    cols = []
    for a, b in WINDOWS:
        if a >= t_end - 1e-9:
            break
        s = (t > a + 1e-9) & (t <= b + 1e-9)
        cols.append("%.1e" % np.sqrt(np.mean(d[s] ** 2)))
    return cols


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=float, default=0.012)
    ap.add_argument("--t-end", type=float, default=0.3)
    ap.add_argument("--variants", default="1e-4:1e-8,1e-4:1e-10,5e-5:1e-8")
    ap.add_argument("--ranges", default="10,20,40")
    ap.add_argument("--out", default="build/reports/slidercrank-floor")
    ap.add_argument("--only-fm", action="store_true", help="run the FMs only (the long part)")
    ap.add_argument("--prog", default="fmbd-run", help="the fmbd-run to use (an experimental build)")
    ap.add_argument("--tag", default="", help="appended to the run files' names (runs of --prog)")
    a = ap.parse_args()
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    text = open(SCENE).read()
    m2f = re.search(r"mesh2fe: *(.*)", text).group(1)
    m2f = re.sub(r"--size +\S+", "--size %g" % a.size, m2f).split()
    fe2cb = re.search(r"fe2cb: *(.*)", text).group(1).split()
    fe, cb = os.path.join(out, "rod.fe.h5"), os.path.join(out, "rod.cb.h5")
    if not os.path.exists(fe):
        sh(["mesh2fe", os.path.join(HERE, "rod.geo")] + m2f + ["-o", fe, "-q"], out)
    if not os.path.exists(cb):
        sh(["fe2cb", fe] + fe2cb + ["-o", cb, "-q"], out)
    ranges = [int(x) for x in a.ranges.split(",")]
    bodies = [("FM", "rod.fe.h5")]
    for r in ranges:
        rf = "rod-nm%d.rflex.h5" % r
        if not os.path.exists(os.path.join(out, rf)):
            sh(["cbcheck", cb, "--fe", fe, "--tol", "1e-2", "--range", str(r), "--hold", "bore0",
                "--hold", "bore1", "-o", rf, "-q"], out)
        bodies.append(("Nm %d" % r, rf))
    bodies.append(("CB %s" % fe2cb[-1], "rod.cb.h5"))  # every mode fe2cb computed (the scene's --modes 120)
    if a.only_fm:
        bodies = bodies[:1]
    runs = {}
    for v in a.variants.split(","):
        step, ntol = v.split(":")
        for name, f in bodies:
            tag = "%s-h%s-n%s%s" % (name.replace(" ", "").lower(), step, ntol, a.tag)
            run = os.path.join(out, tag + ".run.h5")
            if not os.path.exists(run):
                y = os.path.join(out, tag + ".yaml")
                open(y, "w").write(variant(text, f, a.t_end, step, ntol))
                sh([a.prog, y, "-o", run, "-q"], out)
            runs[(v, name)] = track(run)
    if a.only_fm:
        return
    vs = a.variants.split(",")
    head = ["%.1f..%.1f s" % w for w in WINDOWS if w[0] < a.t_end - 1e-9]
    lines = ["RMS of |A - A_ref| by window (m); mesh %g m, t = 0..%g s; variant = step:newton_tol" % (a.size, a.t_end),
             "", "| variant | body | reference | " + " | ".join(head) + " | CPU s |",
             "|---" * (len(head) + 4) + "|"]

    def row(v, name, rv, rname):
        t, x, cpu = runs[(v, name)]
        t0, x0, _ = runs[(rv, rname)]
        if len(t) != len(t0) or np.max(np.abs(t - t0)) > 1e-9:
            sys.exit("floor.py: output grids differ")
        d = np.linalg.norm(x - x0, axis=1)
        lines.append("| %s | %s | %s %s | %s | %.3g |" % (v, name, rname, rv, " | ".join(windows(t, d, a.t_end)), cpu))

    for v in vs:
        for name, _ in bodies[1:]:
            row(v, name, v, "FM")
    for v in vs[1:]:
        row(v, "FM", vs[0], "FM")
        row(v, bodies[1][0], vs[0], bodies[1][0])
    if a.tag:  # each run of --prog against the same run of fmbd-run, when that was made
        for v in vs:
            step, ntol = v.split(":")
            for name, _ in bodies[:2]:
                base = os.path.join(out, "%s-h%s-n%s.run.h5" % (name.replace(" ", "").lower(), step, ntol))
                if os.path.exists(base):
                    runs[(v + " (fmbd-run)", name)] = track(base)
                    row(v, name, v + " (fmbd-run)", name)
    open(os.path.join(out, "floor%s.md" % a.tag), "w").write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
