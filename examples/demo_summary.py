#!/usr/bin/python3
"""examples/demo_summary.py: the short report at the end of `make demo`.

Reads the files the demo made (h5py, as a user would) and prints: the FE body, the
reduction, the frequencies of the kept flexible modes, the estimator against the exact
error, and the cost and end state of the run.
Usage: demo_summary.py OUTDIR
"""
import csv
import os
import sys

import h5py
import numpy as np


def main(out):
    fe = os.path.join(out, "rod.fe.h5")
    cb = os.path.join(out, "rod.cb.h5")
    rf = os.path.join(out, "rod.rflex.h5")
    run = os.path.join(out, "quadpend.run.h5")
    est = os.path.join(out, "rod-estimates.csv")
    with h5py.File(fe, "r") as f:
        ndof = f["dofs"].shape[0]
        nodes = f["mesh/nodes"].shape[0]
        print(f"FE body     {fe}: {nodes} nodes, {ndof} dofs, mass {f['body'].attrs['mass']:.4f} kg")
    with h5py.File(cb, "r") as f:
        nd = f["cb/kappa"].shape[0]
        nb = f["cb/boundary_dofs"].shape[0]
        print(f"CB body     {cb}: {nd} fixed-interface + {nb} constraint modes")
    with h5py.File(rf, "r") as f:
        fr = f["modes/frequency_hz"][()]
        print(f"flex body   {rf}: {fr.size} flexible modes kept")
        print("            f (Hz): " + " ".join(f"{x:.1f}" for x in fr[:10]) + (" ..." if fr.size > 10 else ""))
    rows = list(csv.DictReader(open(est)))
    ok = [r for r in rows if r["exact"] and float(r["exact"]) < 0.1]
    up = sum(float(r["upper"]) >= float(r["exact"]) for r in ok)
    lo = sum(float(r["lower"]) <= float(r["exact"]) for r in ok)
    print(f"estimates   {est}: of {len(ok)} modes with exact error < 10 %, upper >= exact in {up}, "
          f"lower <= exact in {lo}")
    for r in rows[:5]:
        print(f"            mode {r['mode']:>3} {float(r['frequency_hz']):9.1f} Hz  lower {float(r['lower']):.3e}"
              f"  exact {float(r['exact']):.3e}  upper {float(r['upper']):.3e}")
    with h5py.File(run, "r") as f:
        st = f["stats"].attrs
        t = f["time"][()]
        a = f["outputs/A/position"][()]
        print(f"run         {run}: {int(st['steps'])} steps, {int(st['newton_iterations'])} Newton iterations, "
              f"{float(st['wall_time_s']):.2f} s wall for {t[-1]:.2f} s simulated "
              f"({t[-1] / max(float(st['wall_time_s']), 1e-9):.1f}x real time)")
        print(f"            node A at t = {t[-1]:.2f} s: ({a[-1, 0]:.4f}, {a[-1, 1]:.4f}, {a[-1, 2]:.4f}) m; "
              f"lowest y reached {np.min(a[:, 1]):.4f} m")
    print(f"pictures    {out}/rod-estimates.svg, rod-convergence.svg, quadpend-A-trajectory.svg")


if __name__ == "__main__":
    main(sys.argv[1])
