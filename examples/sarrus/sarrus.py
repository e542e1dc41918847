#!/usr/bin/python3
# examples/sarrus/sarrus.py: the Sarrus-type six-link mechanism of Cammarata 2021 (section 5.3)
# with the toolchain: a fixed frame (ground), two 3R limbs of a flexible proximal and a flexible
# distal link each, and a rigid moving platform. The three revolute axes of limb 1 are parallel
# to x, those of limb 2 to y: the platform can only translate along z (mobility 1, one of the
# 30 joint equations redundant for rigid links). It falls from rest under gravity (-z) from
# p0 = (0.282, 0.282, 0); the global modes are taken at p = (0.282, 0.282, -0.031).
#
# Our choices (the paper's Table 6 is not in our copy), README.md:
#   links: L = 0.15 m, solid circular steel section of radius 4 mm (E = 210 GPa, nu = 0.3,
#          rho = 7850 kg/m^3), NE 2-node beam elements (mesh2fe, link.geo);
#   platform: a rigid aluminium plate 0.2 x 0.2 x 0.01 m (1.08 kg) centred at E;
#   limb 1 in the plane x = 0.282: ground joint A1 = (0.282, 0, 0), platform joint
#          C1 = E - (0, 0.1, 0); limb 2 in the plane y = 0.282: A2 = (0, 0.282, 0),
#          C2 = E - (0.1, 0, 0); the knees B1, B2 above the line A-C (the "roof" branch).
#
# Models (each link the same basis; m = the number asked):
#   FM   the links as full .fe.h5 beam bodies (all 6 (NE + 1) - 6 FE dofs)
#   NM   fe2cb --method nm --modes m         free-free normal modes
#   CB   fe2cb --modes m                     m fixed-interface + 12 constraint modes (m + 6)
#   GMc  gmsolve on the linearisation scene (links as in the reference), basis: GMc, modes m
#   GMs  the same file's GMs basis: m coordinates shared by the four links (basis_kind: gms)
#   reference (--ref complete, the default): NM with all 6 NE flexible modes, a complete basis
#        (the FM in modal coordinates), checked against CB with all 6 NE - 6 fixed-interface modes;
#        --ref fm: the links as full .fe.h5 beam bodies
# Error: the RMS distance of the platform centre E from the reference's over the run
# (fmbd-run --reference; docs/THEORY.md section 7).
#
#   /usr/bin/python3 examples/sarrus/sarrus.py [--ne 10] [--modes 2,4,7,9] [--t-end 0.15]
#       [--step 1e-4] [--ref fm|complete] [--methods NM,CB,GMc,GMs] [--z0 Z] [--table8]
#       [--write-scene YAML] [--out build/sarrus]
import argparse
import math
import os
import subprocess
import sys

import h5py
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
L = 0.15            # link length (m)
E_XY = 0.282        # the platform centre's x and y (the paper's p0)
HALF = 0.1          # platform joints at 0.1 m from its centre
PLATE = (0.2, 0.2, 0.01)
RHO_PLATE = 2700.0
RADIUS = 0.004      # the links' solid circular section (m)
RHO = 7850.0
LINKS = ("prox1", "dist1", "prox2", "dist2")


def sh(out, *args, may_fail=False):
    p = subprocess.run(list(args), cwd=out, capture_output=True, text=True)
    if p.returncode and not may_fail:
        sys.exit("failed: %s\n%s" % (" ".join(args), p.stderr))
    if p.returncode:
        tail = (p.stderr.strip().splitlines() or ["?"])[-1]
        print("failed: %s: %s" % (" ".join(args), tail), file=sys.stderr)
    return p


def frame(d, axis):
    """Body frame -> world rotation: body x along d, body y along the joint axis."""
    ex = d / np.linalg.norm(d)
    ey = np.asarray(axis, float)
    ez = np.cross(ex, ey)
    return np.column_stack([ex, ey, ez])


def poses(ze):
    """The rigid configuration with the platform centre at (E_XY, E_XY, ze)."""
    e = np.array([E_XY, E_XY, ze])
    limbs = []
    for k, (axis, a, c) in enumerate((((1, 0, 0), np.array([E_XY, 0, 0]), e - [0, HALF, 0]),
                                      ((0, 1, 0), np.array([0, E_XY, 0]), e - [HALF, 0, 0]))):
        chord = c - a
        n = np.linalg.norm(chord)
        if n >= 2 * L:
            sys.exit("sarrus.py: the limbs cannot reach z = %g" % ze)
        perp = np.cross(axis, chord / n)        # in the limb's plane, normal to the chord
        if perp[2] < 0:
            perp = -perp                          # the knee above the chord
        b = a + chord / 2 + perp * math.sqrt(L * L - n * n / 4)
        limbs.append((axis, a, b, c))
    return e, limbs


def scene(path, ze, t_end, step, files, basis=None, keep=None, kind="gmc", make=None, header=""):
    """files: the body file of each link (dict; None: a rigid link); basis: a .gm.h5 (GMc, first
    keep modes; kind gms: the GMs basis, one set of keep coordinates shared by the links); make: the
    make chain of the links' file (on the first link: fmbd-run -M); header: comment lines."""
    e, limbs = poses(ze)
    lines = header.splitlines() + ["title: Sarrus six-link mechanism, platform at z = %g" % ze,
             "gravity: [0, 0, -9.81]",
             "solver: {t_end: %g, step: %g, rho_inf: 0.9}" % (t_end, step), "bodies:"]

    def vec(v):
        return "[%.12g, %.12g, %.12g]" % tuple(v)
    for k, (axis, a, b, c) in enumerate(limbs):
        for name, p0, p1 in (("prox%d" % (k + 1), a, b), ("dist%d" % (k + 1), b, c)):
            r = frame(p1 - p0, axis)
            extra = ", basis: %s, modes: %d" % (basis, keep) if basis else ""
            if basis and kind == "gms":
                extra += ", basis_kind: gms"
            if files[name] is None:     # a rigid link (the rigid twin of the mechanism)
                what = "geometry: {shape: cylinder, length: %g, radius: %g, density: %g, axis: x, center: [%g, 0, 0]}" \
                    % (L, RADIUS, RHO, L / 2)
            else:
                what = "type: flexible, file: %s" % files[name]
            lines.append("  - {name: %s, %s, position: %s, orientation: {matrix: [%s]}%s}"
                         % (name, what, vec(p0), ", ".join("%.15g" % x for x in r.ravel()), extra))
            if make and name == LINKS[0]:
                lines[-1] = lines[-1][:-1] + ",\n     make: {%s}}" % ", ".join("%s: %s" % kv for kv in make.items())
    lines.append("  - {name: platform, geometry: {shape: box, size: [%g, %g, %g], density: %g}, position: %s}"
                 % (PLATE + (RHO_PLATE, vec(e))))
    lines.append("joints:")
    for k, (axis, a, b, c) in enumerate(limbs):
        ax = "xy"[k]
        prox, dist = files["prox%d" % (k + 1)], files["dist%d" % (k + 1)]
        at = (", at2: {interface: end0}" if prox else "",
              (", at1: {interface: end1}" if prox else "") + (", at2: {interface: end0}" if dist else ""),
              ", at1: {interface: end1}" if dist else "")
        lines.append("  - {name: A%d, type: revolute, body1: ground, body2: prox%d, point: %s, axis: %s%s}"
                     % (k + 1, k + 1, vec(a), ax, at[0]))
        lines.append("  - {name: B%d, type: revolute, body1: prox%d, body2: dist%d, point: %s, axis: %s%s}"
                     % (k + 1, k + 1, k + 1, vec(b), ax, at[1]))
        lines.append("  - {name: C%d, type: revolute, body1: dist%d, body2: platform, point: %s, axis: %s%s}"
                     % (k + 1, k + 1, vec(c), ax, at[2]))
    lines.append("outputs:\n  every: %g\n  points:" % max(step, 1e-3))
    lines.append("    - {name: E, body: platform, quantities: [position]}")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def files_of(f):
    return {n: f for n in LINKS}


def rms(path, ref):
    with h5py.File(path, "r") as f:
        p = f["outputs/E/position"][()]
        t = f["time"][()] if "time" in f else None
        cpu = float(f["stats"].attrs["cpu_time_s"])
    with h5py.File(ref, "r") as f:
        r = f["outputs/E/position"][()]
    n = min(len(p), len(r))
    return math.sqrt(np.mean(np.sum((p[:n] - r[:n]) ** 2, axis=1))), cpu, n == len(r), t


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ne", type=int, default=10, help="beam elements per link")
    ap.add_argument("--modes", default="1,2,4,7,9")
    ap.add_argument("--t-end", type=float, default=0.15)
    ap.add_argument("--step", type=float, default=1e-4)
    ap.add_argument("--ref", choices=("fm", "complete"), default="complete")
    ap.add_argument("--methods", default="NM,CB,GMc", help="of NM, CB, GMc, GMs")
    ap.add_argument("--table8", action="store_true", help="print the first 20 global modes")
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "sarrus"))
    ap.add_argument("--z0", type=float, default=0.0,
                    help="the platform centre's initial height (m); -0.031: start at the linearisation configuration")
    ap.add_argument("--write-scene", metavar="YAML", help="write the scene (NM all modes, make chain) and exit")
    a = ap.parse_args()
    if a.write_scene:
        mesh = "--size %.12g --circle %g --E 210e9 --nu 0.3 --rho %g --interface end0 --interface end1" % (
            L / a.ne, RADIUS, RHO)
        head = ("# examples/sarrus/sarrus.yaml: the Sarrus six-link mechanism falling from p0 = (0.282, 0.282, 0)\n"
                "# (README.md), each link the modal body of all its %d free-free modes (the full model in\n"
                "# modal coordinates). Written by: sarrus.py --write-scene sarrus.yaml. Run:\n"
                "#   fmbd-run -M sarrus.yaml --body-dir out > out/sarrus.mk\n"
                "#   make -f out/sarrus.mk out/link.cb.h5\n"
                "#   fmbd-run sarrus.yaml --body-dir out -o out/sarrus.run.h5\n" % (6 * a.ne))
        scene(a.write_scene, 0.0, a.t_end, a.step, files_of("link.cb.h5"), header=head,
              make={"geometry": "link.geo", "mesh2fe": mesh, "fe": "link.fe.h5",
                    "fe2cb": "--method nm --modes %d" % (6 * a.ne)})
        return
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    os.environ["PATH"] = os.path.join(ROOT, "build", "bin") + os.pathsep + os.environ["PATH"]
    modes = [int(x) for x in a.modes.split(",")]
    methods = a.methods.split(",")
    sh(out, "mesh2fe", os.path.join(HERE, "link.geo"), "--size", "%.12g" % (L / a.ne), "--circle", "%g" % RADIUS,
       "--E", "210e9", "--nu", "0.3", "--rho", "%g" % RHO, "--interface", "end0", "--interface", "end1",
       "-o", "link.fe.h5", "-q")
    # the reference model: the links as full FE bodies (FM, --ref fm), or (--ref complete, the
    # default) as modal bodies of all 6 NE of their free-free flexible modes: a complete basis,
    # which spans every FE dof, so the same model as the FM in other coordinates; checked against
    # the other complete basis, CB with all 6 NE - 6 fixed-interface modes
    nfull = 6 * a.ne
    if a.ref == "fm":
        refname, reffile = "FM", "link.fe.h5"
    else:
        sh(out, "fe2cb", "link.fe.h5", "--method", "nm", "--modes", str(nfull), "-o", "nmall.cb.h5", "-q")
        sh(out, "fe2cb", "link.fe.h5", "--modes", str(nfull - 6), "-o", "cball.cb.h5", "-q")
        refname, reffile = "NM all %d (complete)" % nfull, "nmall.cb.h5"
    reffiles = files_of(reffile)
    # the global modes at the linearisation point, the links as in the reference
    scene(os.path.join(out, "lin.yaml"), -0.031, a.t_end, a.step, reffiles)
    kmax = max(max(modes), 20 if a.table8 else 0)
    p = sh(out, "gmsolve", "lin.yaml", "--modes", str(kmax), "--plot", "sarrus", "-o", "lin.gm.h5", "-v")
    for line in p.stderr.splitlines():
        if "mobility" in line or "redundan" in line or line.startswith("gmsolve: lin"):
            print(line)
    if a.table8:
        with h5py.File(os.path.join(out, "lin.gm.h5"), "r") as f:
            g = f["global"]
            fr = g["frequency_hz"][()]
            pm = g["participation_mass"][()]
            print("| mode | frequency (Hz) | participation x | y | z |")
            print("|---|---|---|---|---|")
            for i in range(min(20, len(fr))):
                print("| %d | %.2f | %.3e | %.3e | %.3e |" % ((i + 1, fr[i]) + tuple(pm[i])))
    scene(os.path.join(out, "ref.yaml"), a.z0, a.t_end, a.step, reffiles)
    sh(out, "fmbd-run", "ref.yaml", "-o", "ref.run.h5", "-q")
    with h5py.File(os.path.join(out, "ref.run.h5"), "r") as f:
        cref = float(f["stats"].attrs["cpu_time_s"])
        pe = f["outputs/E/position"][()]
    if a.ref == "complete":
        scene(os.path.join(out, "cball.yaml"), a.z0, a.t_end, a.step, files_of("cball.cb.h5"))
        sh(out, "fmbd-run", "cball.yaml", "-o", "cball.run.h5", "-q")
        eps, cpu, _, _ = rms(os.path.join(out, "cball.run.h5"), os.path.join(out, "ref.run.h5"))
        print("the other complete basis, CB all %d + 6: eps_RMS of E %.2e m, CPU %.2f s" % (nfull - 6, eps, cpu))
    print("| model | flexible coordinates per link | CPU (s) | eps_RMS of E (m) |")
    print("|---|---|---|---|")
    print("| reference: %s | | %.2f | (E falls %.4f m; |E_xy - p0_xy| up to %.2e m) |"
          % (refname, cref, pe[0, 2] - pe[-1, 2], np.max(np.hypot(pe[:, 0] - E_XY, pe[:, 1] - E_XY))))
    for m in modes:
        for meth in methods:
            if meth == "NM":
                body, basis, nf = "nm%d.cb.h5" % m, None, str(m)
                sh(out, "fe2cb", "link.fe.h5", "--method", "nm", "--modes", str(m), "-o", body, "-q")
            elif meth == "CB":
                body, basis, nf = "cb%d.cb.h5" % m, None, "%d + 6" % m
                sh(out, "fe2cb", "link.fe.h5", "--modes", str(m), "-o", body, "-q")
            elif meth == "GMs":
                body, basis, nf = reffile, "lin.gm.h5", "%d shared" % m
            else:
                body, basis = reffile, "lin.gm.h5"
                with h5py.File(os.path.join(out, "lin.gm.h5"), "r") as f:
                    nk = [int(np.sum(f["gmc/%s/global_mode" % n][()] <= m)) for n in LINKS]
                nf = "/".join(str(x) for x in nk)
            name = "%s%d" % (meth, m)
            scene(os.path.join(out, name + ".yaml"), a.z0, a.t_end, a.step, files_of(body), basis, m, meth.lower())
            if sh(out, "fmbd-run", name + ".yaml", "-o", name + ".run.h5", "-q", may_fail=True).returncode:
                print("| %s m=%d | %s | - | run failed |" % (meth, m, nf))
                continue
            eps, cpu, _, _ = rms(os.path.join(out, name + ".run.h5"), os.path.join(out, "ref.run.h5"))
            print("| %s m=%d | %s | %.2f | %.3e |" % (meth, m, nf, cpu, eps))
            sys.stdout.flush()


if __name__ == "__main__":
    main()
