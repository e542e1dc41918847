#!/usr/bin/python3
# examples/spatial-slidercrank/gmtable.py: the second paper's Table 4 for our spatial
# slider-crank: the error of the rod's mid-span node (output `mid`) and of its spherical-joint
# node (interface end0, output `sph`) against the full FE model (FM), for global modes (GMs and
# GMc: gmsolve), normal modes (NM: the free rod's, fe2cb --method nm; NM held: the rod's with
# both end interfaces clamped, --hold; NM S-U: the paper's NM, the rod's modes with the
# mechanism's spherical and universal joints to ground, the global modes of that one-body scene,
# su_scene, used as a GMc basis) and Craig-Bampton bodies (CB: fe2cb --modes m, every mode
# of the reduced problem), against the number of modes m.
# SPDX-License-Identifier: MIT
#
#   gmtable.py [--size H] [--t-end T] [--modes 1,2,3,4,6] [--out DIR]
#
# Every model runs the scene's solver settings (fixed step 1e-4 s) to T (default 0.054 s: the
# window before runs at two step sizes part, README.md); the mesh is the scene's mesh2fe chain
# with --size H (default the scene's 4 mm). Writes DIR/table.md and DIR/table.csv; made files are
# reused when present. Programs are taken from PATH (make puts build/bin first).
import argparse
import csv
import os
import re
import subprocess
import sys

import h5py
import numpy as np
import scipy.sparse as sp

HERE = os.path.dirname(os.path.abspath(__file__))
SCENE = os.path.join(HERE, "spatial-slidercrank.yaml")


def sh(cmd, cwd):
    p = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("gmtable.py: failed (%d): %s\n%s" % (p.returncode, " ".join(cmd), p.stderr))
    return p


def scene_variant(text, body_line, t_end):
    """The scene with the rod's file line replaced, its make chain dropped, the end-node output."""
    out, skip = [], False
    for line in text.splitlines():
        if skip:
            if line.startswith("      "):
                continue
            skip = False
        if line.strip() == "make:" and line.startswith("    "):
            skip = True
            continue
        if line.strip() == "file: rod.rflex.h5":  # "key: v, key: v" -> one key per line
            line = "\n".join("    " + kv for kv in body_line.split(", "))
        out.append(line)
        if line.strip() == "points:":
            out.append("    - {name: sph, body: rod, interface: end0, quantities: [position]}")
    s = "\n".join(out) + "\n"
    return re.sub(r"t_end: *[0-9.e+-]+", "t_end: %g" % t_end, s)


def su_scene(text, body_line, frame):
    """The rod alone, held to ground as the mechanism holds it: the spherical joint `pin` at end0
    (the crank side made ground) and the universal joint `cross` at end1 with the same two axes
    (the slider side made ground), the rod placed where gmsolve linearises the mechanism: its
    frame coordinates `frame` (R, Euler parameters p) from the mechanism's /linear/x, written
    to the last digit (the scene's 10-digit matrix is a rotation to 1e-10 only, and the two
    ground points must be the rigid rod's length apart to round-off: the rod held at both ends
    has no rigid motion to absorb a difference). Its global modes (f = 0) are the rod's
    S-U-held normal modes (NM S-U)."""
    R, (e0, e1, e2, e3) = frame[:3], frame[3:7]
    e = np.array([e1, e2, e3])
    til = np.array([[0, -e3, e2], [e3, 0, -e1], [-e2, e1, 0]])
    A = (2 * e0 * e0 - 1) * np.eye(3) + 2 * (np.outer(e, e) + e0 * til)
    lines = text.splitlines()
    i = next(k for k, x in enumerate(lines) if x.startswith("  - name: rod"))
    j = next(k for k, x in enumerate(lines) if x.startswith("  - name: slider"))
    rod = [x for x in scene_variant("\n".join(lines[i:j]), body_line, 1).splitlines()
           if not re.match(r" +(velocity|angular_velocity|position|orientation|matrix):|      +[-0-9]", x)]
    rod += ["    position: [%s]" % ", ".join("%.17g" % v for v in R),
            "    orientation: {matrix: [%s]}" % ", ".join("%.17g" % v for v in A.ravel())]
    k = next(k for k, x in enumerate(lines) if x.startswith("joints:"))
    joints, keep = [], False
    for x in lines[k + 1:]:
        if not x.startswith(" "):
            break
        if x.startswith("  - "):
            keep = "name: pin" in x or "name: cross" in x
        if keep:
            joints.append(x.replace("body1: crank", "body1: ground").replace("body2: slider", "body2: ground")
                          .replace("# on the slider", "# on ground"))
    solver = re.search(r"\nsolver:\n(?:  .*\n)+", text).group(0)
    return ("title: the spatial slider-crank's rod held by the mechanism's spherical and universal joints"
            " (ground on their other sides)" + solver + "bodies:\n" + "\n".join(rod) + "\njoints:\n"
            + "\n".join(joints) + "\n")


def position(run, name):
    with h5py.File(run, "r") as f:
        return f["outputs/%s/position" % name][()]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=float, default=0.004)
    ap.add_argument("--t-end", type=float, default=0.054)
    ap.add_argument("--modes", default="1,2,3,4,6")
    ap.add_argument("--out", default="build/reports/spatial-slidercrank-gm")
    a = ap.parse_args()
    modes = [int(x) for x in a.modes.split(",")]
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    text = open(SCENE).read()
    m2f = re.search(r"mesh2fe: *(.*)", text).group(1)
    m2f = re.sub(r"--size +\S+", "--size %g" % a.size, m2f).split()
    fe = os.path.join(out, "rod.fe.h5")
    if not os.path.exists(fe):
        sh(["mesh2fe", os.path.join(HERE, "rod.geo")] + m2f + ["-o", fe, "-q"], out)

    def scene(name, body):
        p = os.path.join(out, name + ".yaml")
        open(p, "w").write(scene_variant(text, body, a.t_end))
        return p

    def runit(name, body):
        run = os.path.join(out, name + ".run.h5")
        p = sh(["fmbd-run", scene(name, body), "-o", run, "-q"], out)
        with h5py.File(run, "r") as f:
            cpu = float(f["stats"].attrs.get("run_cpu_time_s", np.nan))
        return run, cpu, p

    fm, fm_cpu, _ = runit("fm", "file: rod.fe.h5")
    gm = os.path.join(out, "rod.gm.h5")
    if not os.path.exists(gm):
        sh(["gmsolve", os.path.join(out, "fm.yaml"), "--modes", str(max(modes)), "--matrices", "-o", gm, "-q"], out)
    with h5py.File(gm, "r") as f:
        gfreq = f["global/frequency_hz"][()]
        frame = f["linear/x"][7:14]  # the rod's frame coordinates (the crank's 7 come first)
        # each global mode's share of its modal mass (x'Mx = 1) in the crank's and the slider's
        # coordinates (the first and the last 7): what the S-U hold forbids them
        g, X = f["linear/M"], f["global/shapes"][()]
        M = sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
        share = []
        for x in X.T:
            y = x.copy()
            y[7:-7] = 0
            share.append(float(y @ (M @ y) / (x @ (M @ x))))
    # NM S-U: the rod held to ground by the mechanism's spherical and universal joints (f = 0)
    su = os.path.join(out, "rod-su.gm.h5")
    if not os.path.exists(su):
        p = os.path.join(out, "su.yaml")
        open(p, "w").write(su_scene(text, "file: rod.fe.h5", frame))
        sh(["gmsolve", p, "--modes", str(max(modes)), "-o", su, "-q"], out)
    with h5py.File(su, "r") as f:
        sufreq = f["global/frequency_hz"][()]
        if int(f["global"].attrs["f"]) != 0:
            sys.exit("gmtable.py: the S-U-held rod has rigid-reference modes")
    ref = {k: position(fm, k) for k in ("mid", "sph")}
    rows = []

    def err(run):
        e = {}
        for k in ("mid", "sph"):
            d = np.linalg.norm(position(run, k) - ref[k], axis=1)
            e[k] = (float(np.max(d)), float(np.sqrt(np.mean(d * d))))
        return e

    for m in modes:
        files = {}
        for kind, args in (("NM", ["--method", "nm"]), ("NM held", ["--method", "nm", "--hold"]), ("CB", [])):
            tag = kind.replace(" ", "").lower()
            cb = os.path.join(out, "rod-%s%d.cb.h5" % (tag, m))
            if not os.path.exists(cb):
                sh(["fe2cb", fe] + args + ["--modes", str(m), "-o", cb, "-q"], out)
            files[kind] = cb
        models = [("GMs", "file: rod.fe.h5, basis: rod.gm.h5, basis_kind: gms, modes: %d" % m),
                  ("GMc", "file: rod.fe.h5, basis: rod.gm.h5, modes: %d" % m),
                  ("NM S-U", "file: rod.fe.h5, basis: rod-su.gm.h5, modes: %d" % m)]
        models += [(k, "file: " + os.path.basename(f)) for k, f in files.items()]
        for kind, body in models:
            run, cpu, _ = runit("%s-%d" % (kind.replace(" ", "").replace("-", "").lower(), m), body)
            with h5py.File(run, "r") as f:
                nq = int(f["stats"].attrs["coordinates"]) - 21  # 3 bodies x 7 frame coordinates
            e = err(run)
            rows.append(dict(model=kind, m=m, coords=nq, mid_max=e["mid"][0], mid_rms=e["mid"][1],
                             sph_max=e["sph"][0], sph_rms=e["sph"][1], cpu=cpu))
    with open(os.path.join(out, "table.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    with h5py.File(fm, "r") as f:
        fm_coords = int(f["stats"].attrs["coordinates"]) - 21
    lines = ["FM: %d elastic coordinates (mesh %g m), %.3g s integration CPU; t = 0 .. %g s, step of the scene."
             % (fm_coords, a.size, fm_cpu, a.t_end),
             "Global flexible frequencies (Hz): " + ", ".join("%.1f" % x for x in gfreq),
             "S-U-held rod's frequencies (NM S-U, Hz): " + ", ".join("%.1f" % x for x in sufreq),
             "Crank's and slider's share of each global mode's modal mass: " + ", ".join("%.1e" % x for x in share), "",
             "| model | m | elastic coordinates | mid: max error (m) | mid: RMS (m) | sph: max error (m) | sph: RMS (m) | integration CPU s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append("| %s | %d | %d | %.2e | %.2e | %.2e | %.2e | %.3g |" % (
            r["model"], r["m"], r["coords"], r["mid_max"], r["mid_rms"], r["sph_max"], r["sph_rms"], r["cpu"]))
    open(os.path.join(out, "table.md"), "w").write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
