#!/usr/bin/python3
# examples/nlink/nlink.py: the N-link pendulum of Cammarata 2021 (section 5.2) with the toolchain:
# n_b links of spatial Euler-Bernoulli beams (mesh2fe's beam elements) on revolute joints about y,
# the first driven, theta_1(t) = -pi/2 - (pi/6) sin(2 pi t) (here: the chain starts hanging along
# -z, theta_1 = -pi/2, and the driver prescribes -(pi/6) sin(2 pi t) from there), under gravity.
# Our choices (the paper's copy we have gives none): link length 0.5 m, solid circular section of
# radius 0.01 m, steel (E = 210 GPa, nu = 0.3, rho = 7850 kg/m^3), NE elements per link (10).
#
# Bases of every link, m = number of modes:
#   NM   fe2cb --method nm --modes m           (free-free normal modes, rigid ones removed)
#   NM-held  fe2cb --method nm --hold --modes m of a link whose only interface is end0: the
#        link's modes held at its joint end0 (cantilever modes; the frame at the joint node)
#   CB   fe2cb --modes m                       (m fixed-interface + the 12 constraint modes:
#                                               m + 6 flexible modes)
#   GMc  gmsolve --keep-drivers on the reference scene (the global modes of the chain with the
#        driven joint held), the body's rows of the first m global modes
#   GMc-free  the same with the driven joint free in the global modes (gmsolve's default)
#   GMc-nbm   GMc of the first n_b m global modes (up to m columns per link, as the paper's GMc)
#   GMs  the GMs basis of the same file (driven joint held): m coordinates shared by all links
#        (basis_kind: gms; fmbd-run reads it since wip/gmshared)
# Reference: each link as the modal body of all its 6 NE free-free flexible modes (fe2cb --method
# nm): a complete basis, which spans every FE dof, i.e. the full model in modal coordinates with
# the consistent rigid-flexible coupling (THEORY section 9). The full model as .fe.h5 beam bodies
# (FM, --ref fm) runs too (THEORY section 4b); its frame is the end0 node's, not mean axes, so it
# differs from the complete modal basis at second order in the deformation (u^2 / L).
# Initial state: the rigid chain's motion under the driver at t = 0 (see scene()).
# Error: eps_RMS of each link's end point over the run (docs/THEORY.md section 7), the largest
# over the links; CPU: the run's /stats cpu_time_s; linear-solve CPU: the Newton increments
# alone, /stats factor_cpu_time_s + solve_cpu_time_s (the iteration matrix's factorisations and
# solves; the paper's Figure 12).
#
#   /usr/bin/python3 examples/nlink/nlink.py [--links 2,4] [--modes 1,2,4,6] [--t-end 0.5]
#       [--ne 10] [--step H] [--methods NM,NM-held,CB,GMc,GMc-free,GMc-nbm,GMs] [--ref complete|fm]
#       [--plot PREFIX] [--out build/nlink]
#       (programs from build/bin)
import argparse
import math
import os
import subprocess
import sys

import h5py
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
L = 0.5


def sh(out, *args, may_fail=False):
    p = subprocess.run(list(args), cwd=out, capture_output=True, text=True)
    if p.returncode and not may_fail:
        sys.exit("failed: %s\n%s" % (" ".join(args), p.stderr))
    if p.returncode:
        print("failed: %s: %s" % (" ".join(args), p.stderr.strip().splitlines()[-1]), file=sys.stderr)
    return p


def scene(path, nb, t_end, step, body_file, basis=None, keep=None, kind="gmc", end1="interface: end1"):
    """end1: the place of a link's far end (a link file without that interface: its end node)."""
    lines = ["title: %d-link pendulum of beams" % nb, "gravity: [0, 0, -9.81]",
             ("solver: {t_end: %g, step: %g}" % (t_end, step) if step else
              "solver: {t_end: %g, max_step: 1e-3}" % t_end), "bodies:"]
    # the initial velocities are the rigid chain's under the driver, theta_1'(0) = -(pi/6) 2 pi about y
    # (link k's frame origin at (0, 0, -k L) moves at w x r): the driver starts at full speed, and
    # bodies started at rest would be set moving by fmbd-run's least-change projection, which
    # puts part of the velocity jump into the modal velocities, differently in every basis
    # (README.md: that made NM and GMc stall at 5.5e-3 m)
    w = -math.pi / 6 * 2 * math.pi
    for k in range(nb):
        extra = ""
        if basis:
            extra = ", basis: %s, modes: %d" % (basis, keep)
            if kind == "gms":
                extra += ", basis_kind: gms"
        lines.append("  - {name: link%d, type: flexible, file: %s, position: [0, 0, %g], "
                     "orientation: {axis: y, angle: 1.5707963267948966}, velocity: [%.17g, 0, 0], "
                     "angular_velocity: [0, %.17g, 0]%s}" % (k, body_file, -k * L, -w * k * L, w, extra))
    lines.append("joints:")
    lines.append("  - {name: j0, type: revolute, body1: ground, body2: link0, point: [0, 0, 0], axis: y, "
                 "at2: {interface: end0}}")
    for k in range(1, nb):
        lines.append("  - {name: j%d, type: revolute, body1: link%d, body2: link%d, point: [0, 0, %g], axis: y, "
                     "at1: {%s}, at2: {interface: end0}}" % (k, k - 1, k, -k * L, end1))
    lines.append("drivers:")
    lines.append("  - {name: theta1, joint: j0, function: {type: sine, amplitude: %.17g, frequency_hz: 1}}"
                 % (-math.pi / 6))
    lines.append("outputs:\n  every: 0.005\n  points:")
    for k in range(nb):
        lines.append("    - {name: end%d, body: link%d, %s, quantities: [position]}" % (k, k, end1))
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def result(path, nb):
    with h5py.File(path, "r") as f:
        pos = [f["outputs/end%d/position" % k][()] for k in range(nb)]
        st = f["stats"].attrs
        cpu, lin = float(st["cpu_time_s"]), float(st["factor_cpu_time_s"] + st["solve_cpu_time_s"])
    return pos, cpu, lin


def plot(prefix, rows):
    """PREFIX-cpu.svg: CPU time against n_tot (the paper's Figure 10), PREFIX-solve.svg: the
    linear solves' CPU time against n_tot (Figure 12), PREFIX-error.svg: the largest eps_RMS of
    the link ends against n_b (Table 5), one line per basis."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    series = {}
    for nb, meth, nf, cpu, eps, nt, each, lin in rows:
        if not math.isnan(cpu):
            series.setdefault(meth, []).append((nb, nt, cpu, eps, lin))
    for what, xi, yi, xlabel, ylabel in (("cpu", 1, 2, "n_tot", "CPU time of the run (s)"),
                                         ("solve", 1, 4, "n_tot",
                                          "CPU time of the linear solves (factorisations + solves) (s)"),
                                         ("error", 0, 3, "n_b", "eps_RMS, largest over the link ends (m)")):
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for meth, pts in series.items():
            if what == "error" and meth.startswith("ref"):
                continue
            ax.semilogy([p[xi] for p in pts], [p[yi] for p in pts], "o-", label=meth)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig("%s-%s.svg" % (prefix, what))
        plt.close(fig)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--links", default="2,4")
    ap.add_argument("--modes", default="1,2,4,6")
    ap.add_argument("--t-end", type=float, default=0.5)
    ap.add_argument("--step", type=float, default=0, help="fixed step (s); 0: variable, max 1e-3 s")
    ap.add_argument("--methods", default="NM,CB,GMc", help="of NM, NM-held, CB, GMc, GMc-free, GMc-nbm, GMs")
    ap.add_argument("--ref", choices=("complete", "fm"), default="complete",
                    help="reference: all free-free modes of each link, or the full .fe.h5 links")
    ap.add_argument("--plot", metavar="PREFIX", help="PREFIX-cpu.svg and PREFIX-error.svg")
    ap.add_argument("--ne", type=int, default=10, help="beam elements per link")
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "nlink"))
    a = ap.parse_args()
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    os.environ["PATH"] = os.path.join(ROOT, "build", "bin") + os.pathsep + os.environ["PATH"]
    links = [int(x) for x in a.links.split(",")]
    modes = [int(x) for x in a.modes.split(",")]
    methods = a.methods.split(",")
    sh(out, "mesh2fe", os.path.join(HERE, "link.geo"), "--size", "%.12g" % (L / a.ne), "--circle", "0.01",
       "--E", "210e9", "--nu", "0.3",
       "--rho", "7850", "--interface", "end0", "--interface", "end1", "-o", "link.fe.h5", "-q")
    if "NM-held" in methods:
        sh(out, "mesh2fe", os.path.join(HERE, "link.geo"), "--size", "%.12g" % (L / a.ne), "--circle", "0.01",
           "--E", "210e9", "--nu", "0.3", "--rho", "7850", "--interface", "end0", "-o", "link0.fe.h5", "-q")
    # reference: every link as the modal body of all its 6 NE free-free flexible modes, a complete
    # basis (every FE dof: the full model in modal coordinates, with the consistent coupling)
    nfull = 6 * a.ne
    # (--ref fm: the links as full .fe.h5 beam bodies)
    sh(out, "fe2cb", "link.fe.h5", "--method", "nm", "--modes", str(nfull), "-o", "ref.cb.h5", "-q")
    reffile, refname = ("link.fe.h5", "FM") if a.ref == "fm" else ("ref.cb.h5", "NM all %d" % nfull)
    for m in modes:
        sh(out, "fe2cb", "link.fe.h5", "--method", "nm", "--modes", str(m), "-o", "nm%d.cb.h5" % m, "-q")
        if "NM-held" in methods:
            sh(out, "fe2cb", "link0.fe.h5", "--method", "nm", "--hold", "--modes", str(m), "-o", "nmh%d.cb.h5" % m, "-q")
        sh(out, "fe2cb", "link.fe.h5", "--modes", str(m), "-o", "cb%d.cb.h5" % m, "-q")
    rows = []
    for nb in links:
        scene(os.path.join(out, "ref%d.yaml" % nb), nb, a.t_end, a.step, reffile)
        # GMc: the global modes with the driven joint held (--keep-drivers: the boundary condition
        # the prescribed motion imposes); GMc-free: with it left free (gmsolve's default)
        kmax = max(modes) * (nb if "GMc-nbm" in methods else 1)
        sh(out, "gmsolve", "ref%d.yaml" % nb, "--modes", str(kmax), "--keep-drivers", "-o", "ref%d.gm.h5" % nb, "-q")
        if "GMc-free" in methods:
            sh(out, "gmsolve", "ref%d.yaml" % nb, "--modes", str(max(modes)), "-o", "free%d.gm.h5" % nb, "-q")
        sh(out, "fmbd-run", "ref%d.yaml" % nb, "-o", "ref%d.run.h5" % nb, "-q")
        ref, cref, lref = result(os.path.join(out, "ref%d.run.h5" % nb), nb)
        rows.append((nb, "ref (%s)" % refname, str(nfull), cref, 0.0, 12 * nb + nb * nfull + 1, [], lref))
        for m in modes:
            # (method, body file, basis file, flexible coordinates per link, global modes kept)
            for meth, body, basis, nflex, keep in (("NM", "nm%d.cb.h5" % m, None, m, 0),
                                                   ("NM-held", "nmh%d.cb.h5" % m, None, m, 0),
                                                   ("GMc-free", reffile, "free%d.gm.h5" % nb, m, m),
                                                   ("CB", "cb%d.cb.h5" % m, None, m + 6, 0),
                                                   ("GMc", reffile, "ref%d.gm.h5" % nb, m, m),
                                                   ("GMc-nbm", reffile, "ref%d.gm.h5" % nb, m, m * nb),
                                                   ("GMs", reffile, "ref%d.gm.h5" % nb, m, m)):
                if meth not in methods:
                    continue
                nfl, shown_f = [nflex] * nb, str(nflex)
                if meth == "GMs":       # keep coordinates shared by all links
                    nfl, shown_f = [keep] + [0] * (nb - 1), "%d shared" % keep
                elif basis:             # the GMc columns each link has from the first keep global modes
                    with h5py.File(os.path.join(out, basis), "r") as f:
                        nfl = [int(np.sum(f["gmc/link%d/global_mode" % k][()] <= keep)) for k in range(nb)]
                    shown_f = "%d..%d" % (min(nfl), max(nfl))
                # the paper's n_tot: 7 n_b + sum f_i coordinates, 5 n_b + 1 constraint equations
                ntot = 12 * nb + sum(nfl) + 1
                name = "%s%d_%d" % (meth, nb, m)
                label = "%s m=%d" % (meth, m) + (" (%d global modes)" % keep if meth == "GMc-nbm" else "")
                scene(os.path.join(out, name + ".yaml"), nb, a.t_end, a.step, body, basis, keep,
                      "gms" if meth == "GMs" else "gmc",
                      "nearest: [%g, 0, 0]" % L if meth == "NM-held" else "interface: end1")
                if sh(out, "fmbd-run", name + ".yaml", "-o", name + ".run.h5", "-q", may_fail=True).returncode:
                    rows.append((nb, label, shown_f, math.nan, math.nan, ntot, [], math.nan))
                    continue
                pos, cpu, lin = result(os.path.join(out, name + ".run.h5"), nb)
                each = [math.sqrt(np.mean(np.sum((p - r) ** 2, axis=1))) for p, r in zip(pos, ref)]
                rows.append((nb, label, shown_f, cpu, max(each), ntot, each, lin))
    if a.plot:
        plot(a.plot, rows)
    print("| n_b | basis | flexible coordinates per link | n_tot | CPU (s) | linear-solve CPU (s) "
          "| eps_RMS, largest over the link ends (m) | eps_RMS of P1 .. Pn_b (m) |")
    print("|---|---|---|---|---|---|---|---|")
    for nb, meth, nf, cpu, eps, nt, each, lin in rows:
        shown = "-" if meth.startswith("ref") else ("run failed" if math.isnan(eps) else "%.2e" % eps)
        print("| %d | %s | %s | %d | %s | %s | %s | %s |" % (
            nb, meth, nf, nt, "-" if math.isnan(cpu) else "%.2f" % cpu, "-" if math.isnan(lin) else "%.3f" % lin,
            shown, " / ".join("%.1e" % e for e in each)))


if __name__ == "__main__":
    main()
