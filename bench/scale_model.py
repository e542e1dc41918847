#!/usr/bin/python3
"""bench/scale_model.py: the scaling model of docs/SCALE.md from the figures bench/mpi.sh measured.

Reads fe2cb-mpi's -v logs of the one-process runs (BENCH_OUT/mpi-work/p1-H.err): dofs, MUMPS
factor entries nnz(L) (INFOG(29)), factor flops (RINFOG(3)), MUMPS memory (INFOG(22)), the
factorisation time, and the time of the 3 nb constraint/projection solves (CPU seconds where
the log has them: on a shared machine the wall time measures the load; the rates then are
those of a dedicated core). The rates come from the largest size measured. Fits
nnz(L) = a n^alpha and flops = b n^beta over the measured sizes (alpha = 4/3, beta = 2, the
nested-dissection orders of 3-D meshes, George 1973, when only one size was measured), and
prints memory and time per process for 1 M to 20 M dofs on P processes:

  memory/process = ovh 8 nnz(L) / P                         (MUMPS factor, measured overhead ovh)
                 + 3 x 12 x r n / P                         (Ks, Ms in PETSc, MUMPS's copy of Ks)
                 (each process reads its row block of K, M, 2 x 12 x r n / P, freed before
                 the factor; before the row-block reader every process read all of K and M,
                 2 x 12 x r n: printed apart)
  process 0 in addition: 8 ns (nd + 4 nb) bytes (the dense blocks of the .cb.h5, gathered)
  time           = flops / (P r_f e_f)  +  S c_s nnz(L) / (P e_s)
with r (entries per row of K, measured), r_f (factor flop rate of one process, measured), c_s
(seconds per factor entry per solve, measured), S = 2.7 nd + 3 nb solves (measured: Krylov-
Schur with purification and the constraint solves), and e_f, e_s the parallel efficiencies of
the factorisation and of the triangular solves: NOT measured here (2 shared cores); the values
below are assumptions, stated in the output.

Usage: scale_model.py [MPI_WORK_DIR] [--nd 100 --nb 60]
"""
import argparse
import glob
import math
import os
import re

import numpy as np


def parse(path):
    t = open(path).read()
    m = re.search(r"(\d+) dofs: (\d+) interior, (\d+) boundary; MUMPS factor of Ks: ([\d.e+]+) entries, "
                  r"([\d.e+]+) flops, (\d+) MB on the largest process, (\d+) MB in all", t)
    # the CPU seconds when logged (a loaded machine inflates the wall time), else the wall
    f = re.search(r"MUMPS factorisation ([\d.e+-]+) s(?: \(cpu ([\d.e+-]+) s\))?", t)
    c = re.search(r"constraint modes and projections ([\d.e+-]+) s \((?:cpu ([\d.e+-]+) s, )?(\d+) solves\)", t)
    if not (m and f and c):
        return None
    return dict(n=int(m[1]), nb=int(m[3]), nnzl=float(m[4]), flops=float(m[5]), mb_sum=float(m[7]),
                t_factor=float(f[2] or f[1]), t_cons=float(c[2] or c[1]), cons_solves=int(c[3]),
                clock="cpu" if f[2] else "wall")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("work", nargs="?", default=os.path.join("build", "bench", "mpi-work"))
    ap.add_argument("--nd", type=int, default=100)
    ap.add_argument("--nb", type=int, default=60)
    ap.add_argument("--rows", type=float, default=76.3, help="entries per row of K (tet10: 76)")
    a = ap.parse_args()
    runs = [r for r in (parse(p) for p in sorted(glob.glob(os.path.join(a.work, "p1-*.err")))) if r]
    if not runs:
        raise SystemExit(f"scale_model.py: no fe2cb-mpi -v logs p1-*.err in {a.work} (run bench/mpi.sh)")
    runs.sort(key=lambda r: r["n"])
    n = np.array([r["n"] for r in runs], float)
    L = np.array([r["nnzl"] for r in runs])
    F = np.array([r["flops"] for r in runs])
    if len(runs) >= 2:
        alpha, la = np.polyfit(np.log(n), np.log(L), 1)
        beta, lb = np.polyfit(np.log(n), np.log(F), 1)
        fit = "fitted"
    else:
        alpha, beta = 4 / 3, 2.0
        la, lb = math.log(L[0] / n[0] ** alpha), math.log(F[0] / n[0] ** beta)
        fit = "nested-dissection orders, one size measured"
    big = runs[-1]
    r_f = big["flops"] / big["t_factor"]
    c_s = big["t_cons"] / big["cons_solves"] / big["nnzl"]
    ovh = big["mb_sum"] * 1e6 / (8 * big["nnzl"])
    print("measured (fe2cb-mpi, one process):")
    for r in runs:
        print(f"  n = {r['n']:>9,d}: nnz(L) {r['nnzl']:.3e} ({r['nnzl'] / r['n']:.0f} per dof), "
              f"{r['flops']:.3e} flops, factor {r['t_factor']:.2f} s = {r['flops'] / r['t_factor'] / 1e9:.2f} "
              f"GFlop/s, {r['t_cons'] / r['cons_solves'] * 1e3:.1f} ms per solve ({r['clock']} time), "
              f"MUMPS {r['mb_sum']:.0f} MB")
    print(f"model ({fit}): nnz(L) = {math.exp(la):.3g} n^{alpha:.3f}, flops = {math.exp(lb):.3g} n^{beta:.3f}; "
          f"r_f = {r_f / 1e9:.2f} GFlop/s, c_s = {c_s * 1e9:.2f} ns per entry per solve, "
          f"MUMPS memory {ovh:.2f} x 8 nnz(L) (from n = {big['n']:,d})")
    nd, nb = a.nd, a.nb
    S = 2.7 * nd + 3 * nb
    eff = {1: (1.0, 1.0), 8: (0.6, 0.4), 32: (0.4, 0.25), 128: (0.25, 0.12)}
    print(f"assumed parallel efficiencies (factor, solve) by P: {eff} -- assumptions, not measured")
    print(f"nd = {nd} modes, nb = {nb} boundary dofs, S = {S:.0f} solves\n")
    print("| dofs | nnz(L) | factor flops | P | memory/process: factor + matrices | whole K, M (before the row-block reader) | process 0: dense blocks | time/process: factor + solves |")
    print("|---|---|---|---|---|---|---|---|")
    for N in (1e6, 2e6, 5e6, 1e7, 2e7):
        l = math.exp(la) * N ** alpha
        fl = math.exp(lb) * N ** beta
        for P in (8, 32, 128):
            ef, es = eff[P]
            mem = ovh * 8 * l / P + 3 * 12 * a.rows * N / P
            read = 2 * 12 * a.rows * N
            dense = 8 * N * (nd + 4 * nb)
            tf = fl / (P * r_f * ef)
            ts = S * c_s * l / (P * es)
            print(f"| {N / 1e6:g} M | {l:.2e} | {fl:.2e} | {P} | {mem / 1e9:.1f} GB | {read / 1e9:.1f} GB | "
                  f"{dense / 1e9:.1f} GB | {tf / 60:.1f} + {ts / 60:.1f} min |")


if __name__ == "__main__":
    main()
