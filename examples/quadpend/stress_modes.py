#!/usr/bin/python3
# examples/quadpend/stress_modes.py: the modal make-up of a modal body's stress at one node
# (the quadruple pendulum's README, "RFlex's stress at A"). SPDX-License-Identifier: MIT
#
#   examples/quadpend/stress_modes.py BODY.rflex.h5 RUN.h5 [--ref REF.run.h5] [--output A]
#       [--point 0.3,0.015,0] [--t-end T]
#
# BODY: a whole rflex body (cbcheck without --for-scene: /modes/stress at every node); RUN: its
# run with fmbd-run --xdmf (the modal coordinates q(t) in /fields/body/NAME/q). For the node
# nearest POINT (the output's), per mode k: the frequency, the static stress influence
# |sigma_k| / w_k^2 (Pa per unit modal load: how much the mode's quasi-static response
# stresses the node; it falls with k where the modal series of the stress converges), the RMS
# over 0..T of |sigma_k q_k(t)| (Pa, the 6 stress components' Euclidean norm), and the
# displacement's analogue |u_k| RMS |q_k| (m). With --ref: the von Mises error of the run at
# OUTPUT against the reference over 0..T (the run's own /outputs, recomputed from sigma q), and
# that of each partial sum sum_(k<=n) sigma_k q_k (how the truncated modal series converges).
import argparse
import sys

import h5py
import numpy as np


def vm(s):
    xx, yy, zz, xy, yz, zx = s
    return np.sqrt(0.5 * ((xx - yy) ** 2 + (yy - zz) ** 2 + (zz - xx) ** 2) + 3 * (xy ** 2 + yz ** 2 + zx ** 2))


def main():
    ap = argparse.ArgumentParser(prog="stress_modes.py")
    ap.add_argument("body")
    ap.add_argument("run")
    ap.add_argument("--ref")
    ap.add_argument("--output", default="A")
    ap.add_argument("--point", default="0.3,0.015,0")
    ap.add_argument("--t-end", type=float, default=np.inf)
    a = ap.parse_args()
    with h5py.File(a.body, "r") as f:
        if "subset" in f:
            sys.exit(f"stress_modes.py: error: {a.body}: a subset body; make the whole body "
                     "(cbcheck without --for-scene)")
        xyz = f["mesh/nodes"][()]
        p = np.array([float(x) for x in a.point.split(",")])
        node = int(np.argmin(np.linalg.norm(xyz - p, axis=1)))
        S = f["modes/stress"][node]  # (6, Nm)
        fr = f["modes/frequency_hz"][()]
        shapes = f["modes/shapes"][()]
        dofs = f["dofs"][()]
    # the node's translations: rows of /dofs with this node (dofs: (ndof, 2) node, component)
    rows = [i for i in range(dofs.shape[0]) if dofs[i, 0] == node and dofs[i, 1] < 3]
    U = shapes[rows] if rows else np.zeros((0, shapes.shape[1]))
    with h5py.File(a.run, "r") as g:
        t = g["time"][()]
        body = [k for k in g["fields/body"]][0]
        q = g[f"fields/body/{body}/q"][()]
        vrun = g[f"outputs/{a.output}/von_mises"][()]
    k = t <= a.t_end + 1e-12
    t, q, vrun = t[k], q[k], vrun[k]
    w2 = (2 * np.pi * fr) ** 2
    print(f"node {node} at {np.round(xyz[node], 4).tolist()}, {len(t)} instants over 0..{t[-1]:.4g} s")
    vref = None
    if a.ref:
        with h5py.File(a.ref, "r") as g:
            vref = np.interp(t, g["time"][()], g[f"outputs/{a.output}/von_mises"][()])
    print(" mode   freq_hz  |sigma_k|/w^2  RMS|sigma_k q_k| Pa  RMS|u_k q_k| m" +
          ("  vm error RMS, modes 1..k Pa" if a.ref else ""))
    for m in range(S.shape[1]):
        c = np.sqrt(np.mean((np.linalg.norm(S[:, m]) * q[:, m]) ** 2))
        u = np.sqrt(np.mean((np.linalg.norm(U[:, m]) * q[:, m]) ** 2)) if len(rows) else np.nan
        part = ""
        if vref is not None:
            e = vm((q[:, :m + 1] @ S[:, :m + 1].T).T) - vref
            part = f" {np.sqrt(np.mean(e ** 2)):28.1f}"
        print(f"{m + 1:5d} {fr[m]:9.1f} {np.linalg.norm(S[:, m]) / w2[m]:12.1f} {c:18.1f} {u:14.3e}{part}")
    sig = q @ S.T
    v = vm(sig.T)
    print(f"von Mises at the node: RMS {np.sqrt(np.mean(v ** 2)):.1f} Pa, largest {v.max():.1f} Pa "
          f"(the run's output: largest {vrun.max():.1f} Pa)")
    if vref is not None:
        e = v - vref
        print(f"von Mises error against {a.ref}: RMS {np.sqrt(np.mean(e ** 2)):.1f} Pa, "
              f"largest {np.abs(e).max():.1f} Pa")


if __name__ == "__main__":
    main()
