#!/usr/bin/python3
# examples/report.py: the error-against-run-time report of one benchmark (issue 9, section 3).
# SPDX-License-Identifier: MIT
#
#   examples/report.py SCENE --body rod --output A --out DIR [--tols 0.1,0.01,0.001]
#       [--paper-nd 35,58,446] [--size H] [--fe2cb-modes N] [--t-end T] [--step H] [--window]
#       [--window-end T] [--no-fm] [--cb-nd LIST] [--nm-modes LIST] [--ranges LIST] [--only fm|bodies]
#       [--jobs N] [--title TEXT]
#
# From the scene's own make chain (fmbd-run -M: mesh2fe, fe2cb, cbcheck and the --hold options
# the scene's joints ask for), it builds and runs the benchmark's family of models of the
# flexible body BODY, the scene otherwise unchanged:
#   REF    the reference: the full FE model (the body's .fe.h5) when fmbd-run accepts it;
#          otherwise the CB body with every mode of the fe2cb file (all fixed-interface modes
#          fe2cb computed, the constraint modes; labelled "CB all" in table and plot);
#   CB     for each tolerance E: the Craig-Bampton body with the Nd fixed-interface modes that
#          cbcheck --tol E selects (fe2cb --modes Nd, every mode of the reduced problem);
#   RFlex  for each tolerance E: cbcheck's reduced body (.rflex.h5) at that Nd;
#   NM     the free body's normal modes (fe2cb --method nm), as many as the RFlex body has;
#   RFlex free  when the scene holds interfaces (cbcheck --hold from fmbd-run -M): the body
#          reduced and selected for free interfaces, as the papers do (their Nd is for that).
# Every run has the scene's solver settings, so the integrator's error is the same in all and
# the differences are those of the models. Errors of the point output OUTPUT against REF:
# RMS and largest over the run of position, velocity, acceleration, von Mises stress and
# equivalent strain (those the output records), from
# fmbd-run --reference (/reference/OUTPUT). Run time: the CPU time of the
# integration (/stats run_cpu_time_s), beside the whole run's; speed-up = the reference's
# integration CPU time over the model's, at the same integrator settings (equal accuracy of the
# integration; the error column says what the model costs in accuracy).
#
# --step H: every run with a fixed step H instead of the scene's step control (one time grid
# for all, so that the differences are the models', not the step controller's).
# --window (chaotic motion): the loosest tolerance's CB body run again with finer steps (the
# tolerance / 10, or half the fixed step) finds where the trajectories separate: the first
# instant at which the two runs' OUTPUT positions differ by more than 1 % of the motion's size
# (the RMS distance of OUTPUT from its mean position over the run). Each model is run again to
# that instant and its error over it (fmbd-run --reference --window) reported beside the whole
# run's. --window-end T: the window 0..T instead (an output instant, so that the reference is not
# interpolated at its end): chaos grows a difference long before 1 % of the motion (the
# quadruple pendulum: 1e-8 m at 1 s, 6e-5 m at 2.5 s, separation at 2.8 s), and a window that
# ends at the separation measures that growth more than the models.
#
# More models on request (--cb-nd, --nm-modes, --ranges): CB bodies with given numbers of
# fixed-interface modes, NM bodies with given numbers of modes, RFlex bodies at the tightest
# tolerance with given Nm (cbcheck --range): the levers the tolerance does not move.
#
# Writes DIR/report.md, DIR/report.csv and DIR/report.svg (error against run time, one point
# per model, labelled with its modes). Made files are reused when present (named after what
# they hold), so a second call only redoes the runs.
import argparse
import csv
import hashlib
import os
import re
import shlex
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import h5py
import numpy as np

PROG = "report.py"
QUANT = ("position", "velocity", "acceleration", "von_mises", "von_mises_strain")
UNIT = {"position": "m", "velocity": "m/s", "acceleration": "m/s^2", "von_mises": "Pa",
        "von_mises_strain": "1"}


def die(msg):
    print(f"{PROG}: error: {msg}", file=sys.stderr)
    sys.exit(1)


LOG_LOCK = threading.Lock()


def sh(cmd, log, check=True):
    """Run a command (list); it and its output appended to the log together (runs may go side
    by side: --jobs); the CompletedProcess."""
    p = subprocess.run(cmd, capture_output=True, text=True)
    with LOG_LOCK, open(log, "a") as f:
        f.write("$ " + " ".join(shlex.quote(c) for c in cmd) + "\n" + p.stdout + p.stderr)
    if check and p.returncode:
        die(f"{' '.join(cmd[:2])} failed (exit {p.returncode}):\n{p.stderr.strip()}")
    return p


def make_chain(scene, body_dir):
    """The recipes of the scene's -M rules: {program: [args...]} with $@ dropped."""
    p = subprocess.run(["fmbd-run", "-M", scene, "--body-dir", body_dir,
                        "-o", os.path.join(body_dir, "scene.run.h5")], capture_output=True, text=True)
    if p.returncode:
        die(f"fmbd-run -M {scene}: {p.stderr.strip()}")
    chain = {}
    for line in p.stdout.splitlines():
        if line.startswith("\t"):
            w = shlex.split(line.strip())
            if w and w[0] in ("mesh2fe", "fe2cb", "cbcheck"):
                chain[w[0]] = w[1:]
    for prog in ("mesh2fe", "fe2cb", "cbcheck"):
        if prog not in chain:
            die(f"{scene}: the body's make chain has no {prog} step (fmbd-run -M prints no rule)")
    return chain


def drop_opt(args, name, nval=1):
    """args without option `name` and its nval values (every occurrence)."""
    out, i = [], 0
    while i < len(args):
        if args[i] == name:
            i += 1 + nval
            continue
        out.append(args[i])
        i += 1
    return out


def opt_value(args, name):
    return args[args.index(name) + 1] if name in args else None


def body_scene(text, body, path, modes=None):
    """The scene text with BODY's file replaced by `path` (and its make chain dropped)."""
    m = re.search(r"^(\s*)- name: %s\s*(#.*)?\n" % re.escape(body), text, re.M)
    if not m:
        die(f"no body named '{body}' in the scene (as a '- name: {body}' line)")
    ind = len(m.group(1)) + 2
    lines = text[m.end():].split("\n")
    out, i, done = [], 0, False
    while i < len(lines):
        ln = lines[i]
        lead = len(ln) - len(ln.lstrip())
        if ln.strip() and lead < ind:
            out.extend(lines[i:])
            break
        if lead == ind and re.match(r"\s*(file|modes):", ln):
            if not done:
                out.append(" " * ind + f"file: {path}")
                if modes:
                    out.append(" " * ind + f"modes: {modes}")
                done = True
        elif lead == ind and re.match(r"\s*make:", ln):
            i += 1
            while i < len(lines) and (not lines[i].strip() or
                                      len(lines[i]) - len(lines[i].lstrip()) > ind):
                i += 1
            continue
        else:
            out.append(ln)
        i += 1
    if not done:
        die(f"body '{body}' has no 'file:' line")
    return text[:m.end()] + "\n".join(out)


def fixed_step(text, h):
    """The scene with a fixed step h instead of its step control (the solver block's
    first_step/max_step/tolerance/step lines and their continued comments dropped)."""
    lines, out, skip = text.split("\n"), [], False
    for ln in lines:
        if re.match(r"  (first_step|max_step|min_step|tolerance|step):", ln):
            skip = True
            continue
        if skip and re.match(r"\s{3,}#", ln):
            continue
        skip = False
        out.append(ln)
        if re.match(r"solver:\s*(#.*)?$", ln):
            out.append(f"  step: {h}")
    return "\n".join(out)


def tighter(text):
    """The scene with 10x tighter step control: tolerance / 10, or half the fixed step."""
    m = re.search(r"^(\s*)tolerance:\s*([0-9.eE+-]+)", text, re.M)
    if m:
        return text[:m.start(2)] + "%g" % (float(m.group(2)) / 10) + text[m.end(2):]
    m = re.search(r"^(\s*)step:\s*([0-9.eE+-]+)", text, re.M)
    if m:
        return text[:m.start(2)] + "%g" % (float(m.group(2)) / 2) + text[m.end(2):]
    return re.sub(r"^solver:\s*\n", "solver:\n  tolerance: 1e-5\n", text, flags=re.M)


def tighter_what(text):
    m = re.search(r"^\s*tolerance:\s*([0-9.eE+-]+)", text, re.M)
    if m:
        return "tolerance %g" % (float(m.group(1)) / 10)
    m = re.search(r"^\s*step:\s*([0-9.eE+-]+)", text, re.M)
    return "fixed step %g s" % (float(m.group(1)) / 2) if m else "tolerance 1e-5"


def errors(run, out):
    """{quantity: (rms, max)} of output `out` of run against its reference (/reference/OUT,
    written by fmbd-run --reference)."""
    res = {}
    with h5py.File(run, "r") as f:
        a = dict(f[f"reference/{out}"].attrs) if f"reference/{out}" in f else {}
    for q in QUANT:
        if f"rms_{q}" in a:
            res[q] = (float(a[f"rms_{q}"]), float(a.get(f"max_{q}", np.nan)))
    return res


def stats(run):
    with h5py.File(run, "r") as f:
        s = f["stats"].attrs
        return float(s["run_cpu_time_s"]), float(s["cpu_time_s"]), int(s["steps"])


def nmodes(path):
    with h5py.File(path, "r") as f:
        if "modes/eigenvalue" in f:
            return int(f["modes/eigenvalue"].shape[0])
        if "reduced/eigenvalues" in f:  # a cb body: the flexible modes of the reduced problem
            return int(f["reduced/eigenvalues"].shape[0]) - int(f["cb"].attrs["n_rigid"])
    return None


def separation(r1, r2, out):
    """First instant at which out's positions in r1 and r2 differ by more than 1 % of the
    motion's size (RMS distance from the mean position); None if they never do."""
    with h5py.File(r1, "r") as f, h5py.File(r2, "r") as g:
        t, x = f["time"][()], f[f"outputs/{out}/position"][()]
        t2, x2 = g["time"][()], g[f"outputs/{out}/position"][()]
    size = np.sqrt(np.mean(np.sum((x - x.mean(axis=0)) ** 2, axis=1)))
    k = (t >= t2[0]) & (t <= t2[-1])
    r = np.stack([np.interp(t[k], t2, x2[:, a]) for a in range(3)], axis=1)
    d = np.linalg.norm(x[k] - r, axis=1)
    bad = np.nonzero(d > 0.01 * size)[0]
    return (float(t[k][bad[0]]) if bad.size else None), float(size)


def fm_stamp(out, fe, scene, trun, write=False):
    """The stamp of an FM run: the hash of its scene, its end time and the body file's size and
    modification time (ref.stamp beside ref.run.h5); written when `write`."""
    st = os.stat(fe)
    h = hashlib.sha256((open(scene).read() + repr(trun) + f"{st.st_size} {st.st_mtime_ns}").encode()).hexdigest()
    if write:
        open(os.path.join(out, "ref.stamp"), "w").write(h)
    return h


def fm_reused(out, fe, scene, trun, ref, log):
    """Whether ref is the FM run of this scene, body and end time (its stamp matches)."""
    sfile = os.path.join(out, "ref.stamp")
    if os.path.exists(ref) and os.path.exists(sfile) and open(sfile).read() == fm_stamp(out, fe, scene, trun):
        with open(log, "a") as f:
            f.write(f"# {ref}: the FM run of the same scene, body and end time, reused ({sfile})\n")
        return True
    if os.path.exists(sfile):
        os.remove(sfile)
    return False


def main():
    ap = argparse.ArgumentParser(prog=PROG, description="the error-against-run-time report of one benchmark")
    ap.add_argument("scene")
    ap.add_argument("--body", required=True, help="the flexible body whose models are compared")
    ap.add_argument("--output", required=True, help="the point output whose errors are reported")
    ap.add_argument("--out", required=True, help="folder of the made files and the report")
    ap.add_argument("--tols", default="0.1,0.01,0.001", help="cbcheck --tol values")
    ap.add_argument("--paper-nd", default="", help="the paper's Nd at each tolerance")
    ap.add_argument("--size", help="mesh2fe --size instead of the scene's (small versions)")
    ap.add_argument("--fe2cb-modes", help="fe2cb --modes of the reference cb file instead of the scene's")
    ap.add_argument("--t-end", help="end time instead of the scene's")
    ap.add_argument("--step", help="a fixed step for every run instead of the scene's step control")
    ap.add_argument("--window", action="store_true", help="chaotic motion: error before separation")
    ap.add_argument("--window-end", help="with --window: the window's errors over 0..T instead of up to the "
                    "separation (T an output instant)")
    ap.add_argument("--no-fm", action="store_true", help="do not try the .fe.h5 body as reference")
    ap.add_argument("--cb-nd", default="", help="more CB bodies: these numbers of fixed-interface modes")
    ap.add_argument("--nm-modes", default="", help="more NM bodies: these numbers of free-body modes")
    ap.add_argument("--ranges", default="", help="more RFlex bodies at the tightest tolerance: "
                    "these cbcheck --range values (Nm) instead of the scene's")
    ap.add_argument("--only", choices=("fm", "bodies"), help="only run the FM reference (fm) or only "
                    "make the reduced bodies (bodies), and stop: the two can run side by side, and a "
                    "later call reuses both")
    ap.add_argument("--jobs", type=int, default=1, help="fmbd-run runs side by side (default 1)")
    ap.add_argument("--title", default="")
    a = ap.parse_args()
    w0, c0 = time.time(), time.process_time()
    tols = [float(x) for x in a.tols.split(",")]
    paper = [x for x in a.paper_nd.split(",")] if a.paper_nd else [""] * len(tols)
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    log = os.path.join(out, f"report-{a.only}.log" if a.only else "report.log")
    open(log, "w").close()
    scene = os.path.abspath(a.scene)
    text = open(scene).read()
    if a.step:
        text = fixed_step(text, a.step)
    chain = make_chain(scene, out)
    title = a.title or (re.search(r"^title:\s*(.*)$", text, re.M) or [None, os.path.basename(scene)])[1]
    trun = ["--t-end", a.t_end] if a.t_end else []

    # --- the body's files: fe, the reference cb (the scene's fe2cb options) ------------------
    m2f = chain["mesh2fe"]
    geo, m2f_opts = m2f[0], drop_opt(m2f[1:], "-o")
    if a.size:
        m2f_opts = drop_opt(m2f_opts, "--size") + ["--size", a.size]
    fe = os.path.join(out, f"{a.body}.fe.h5")
    if not os.path.exists(fe):
        sh(["mesh2fe", geo] + m2f_opts + ["-o", fe, "-q"], log)
    ref = os.path.join(out, "ref.run.h5")
    if a.only == "fm":
        fmscene = os.path.join(out, "fm.yaml")
        with open(fmscene, "w") as f:
            f.write(body_scene(text, a.body, fe))
        if not fm_reused(out, fe, fmscene, trun, ref, log):
            sh(["fmbd-run", fmscene, "-o", ref, "-q"] + trun, log)
            fm_stamp(out, fe, fmscene, trun, write=True)
        print(f"{PROG}: {ref}: the FM reference", file=sys.stderr)
        return
    f2c = drop_opt(chain["fe2cb"][1:], "-o")
    if a.fe2cb_modes:
        f2c = drop_opt(f2c, "--modes") + ["--modes", a.fe2cb_modes]
    cb = os.path.join(out, f"{a.body}.cb.h5")
    if not os.path.exists(cb):
        sh(["fe2cb", fe] + f2c + ["-o", cb, "-q"], log)
    cbc = drop_opt(drop_opt(drop_opt(chain["cbcheck"][1:], "-o"), "--fe"), "--tol")
    nm_range = opt_value(cbc, "--range")

    models = []  # dicts: name, family, tol, nd, paper, modes, body file

    def variant(name, path, modes=None):
        p = os.path.join(out, name + ".yaml")
        with open(p, "w") as f:
            f.write(body_scene(text, a.body, path, modes))
        return p

    # --- the family -----------------------------------------------------------------------------
    rflex_modes = None
    for tol, pnd in zip(tols, paper):
        tag = "%g" % tol
        rf = os.path.join(out, f"{a.body}-tol{tag}.rflex.h5")
        txt = os.path.join(out, f"{a.body}-tol{tag}.cbcheck.txt")
        if not os.path.exists(rf) or not os.path.exists(txt):
            p = sh(["cbcheck", cb, "--fe", fe, "--tol", tag] + cbc + ["-o", rf], log)
            open(txt, "w").write(p.stdout + p.stderr)
        m = re.search(r"Nd = (\d+) meets", open(txt).read())
        if not m:
            die(f"cbcheck --tol {tag}: no 'Nd = N meets' in its summary ({txt})")
        nd = int(m.group(1))
        k = nmodes(rf)
        rflex_modes = k
        cbnd = os.path.join(out, f"{a.body}-nd{nd}.cb.h5")
        if not os.path.exists(cbnd):
            sh(["fe2cb", fe] + drop_opt(f2c, "--modes") + ["--modes", str(nd), "-o", cbnd, "-q"], log)
        models.append(dict(name=f"CB {tag}", family="CB", tol=tol, nd=nd, paper=pnd,
                           modes=nmodes(cbnd), file=cbnd, label=f"CB {tag:s} (Nd {nd})"))
        models.append(dict(name=f"RFlex {tag}", family="RFlex", tol=tol, nd=nd, paper=pnd,
                           modes=k, file=rf, label=f"RFlex {tag} ({k} modes, Nd {nd})"))
        if "--hold" in cbc:
            # the scene holds interfaces (fmbd-run -M passed --hold): the paper's selection is
            # for the free interface; its body, too, so that both are seen
            cbf = drop_opt(cbc, "--hold")
            rff = os.path.join(out, f"{a.body}-free-tol{tag}.rflex.h5")
            txf = os.path.join(out, f"{a.body}-free-tol{tag}.cbcheck.txt")
            if not os.path.exists(rff) or not os.path.exists(txf):
                p = sh(["cbcheck", cb, "--fe", fe, "--tol", tag] + cbf + ["-o", rff], log)
                open(txf, "w").write(p.stdout + p.stderr)
            m = re.search(r"Nd = (\d+) meets", open(txf).read())
            if not m:
                die(f"cbcheck --tol {tag} (free interfaces): no 'Nd = N meets' in its summary ({txf})")
            ndf, kf = int(m.group(1)), nmodes(rff)
            models.append(dict(name=f"RFlex free {tag}", family="RFlex free", tol=tol, nd=ndf,
                               paper=pnd, modes=kf, file=rff,
                               label=f"RFlex free {tag} ({kf} modes, Nd {ndf})"))
    nmf = os.path.join(out, f"{a.body}-nm{rflex_modes}.cb.h5")
    if not os.path.exists(nmf):
        sh(["fe2cb", fe, "--method", "nm", "--modes", str(rflex_modes), "-o", nmf, "-q"], log)
    models.append(dict(name="NM", family="NM", tol=None, nd=None, paper="", modes=nmodes(nmf),
                       file=nmf, label=f"NM ({nmodes(nmf)} modes)"))
    # --- more models on request: the levers that the tolerance does not move ---------------------
    for k in [int(x) for x in a.nm_modes.split(",") if x]:
        f = os.path.join(out, f"{a.body}-nm{k}.cb.h5")
        if not os.path.exists(f):
            sh(["fe2cb", fe, "--method", "nm", "--modes", str(k), "-o", f, "-q"], log)
        models.append(dict(name=f"NM {k}", family="NM", tol=None, nd=None, paper="", modes=nmodes(f),
                           file=f, label=f"NM ({nmodes(f)} modes)"))
    for nd in [int(x) for x in a.cb_nd.split(",") if x]:
        f = os.path.join(out, f"{a.body}-nd{nd}.cb.h5")
        if not os.path.exists(f):
            sh(["fe2cb", fe] + drop_opt(f2c, "--modes") + ["--modes", str(nd), "-o", f, "-q"], log)
        models.append(dict(name=f"CB Nd {nd}", family="CB", tol=None, nd=nd, paper="", modes=nmodes(f),
                           file=f, label=f"CB Nd {nd} ({nmodes(f)} modes)"))
    for nm in [int(x) for x in a.ranges.split(",") if x]:
        tag = "%g" % tols[-1]
        rf = os.path.join(out, f"{a.body}-tol{tag}-range{nm}.rflex.h5")
        txt = os.path.join(out, f"{a.body}-tol{tag}-range{nm}.cbcheck.txt")
        if not os.path.exists(rf) or not os.path.exists(txt):
            p = sh(["cbcheck", cb, "--fe", fe, "--tol", tag] + drop_opt(cbc, "--range") +
                   ["--range", str(nm), "-o", rf], log)
            open(txt, "w").write(p.stdout + p.stderr)
        m = re.search(r"Nd = (\d+) meets", open(txt).read())
        if not m:
            die(f"cbcheck --tol {tag} --range {nm}: no 'Nd = N meets' in its summary ({txt})")
        nd, k = int(m.group(1)), nmodes(rf)
        models.append(dict(name=f"RFlex {tag} Nm {nm}", family="RFlex", tol=tols[-1], nd=nd, paper="",
                           modes=k, file=rf, label=f"RFlex {tag} Nm {nm} ({k} modes, Nd {nd})"))

    if a.only == "bodies":
        print(f"{PROG}: {out}: {len(models)} reduced bodies made", file=sys.stderr)
        return

    # --- the reference ------------------------------------------------------------------------
    # the FM when fmbd-run takes the .fe.h5 body; otherwise a CB body with every mode of a cb
    # file that has more fixed-interface modes than any model (1.5 x the largest selected Nd,
    # at least the scene's fe2cb --modes), so that no model is richer than its reference
    ref_label, fm_why = None, None
    if not a.no_fm:
        # the FM run is the report's costly part: reused when the same scene, body file and end
        # time made it (its stamp, ref.stamp, beside it)
        fmscene = variant("fm", fe)
        if fm_reused(out, fe, fmscene, trun, ref, log):
            p = subprocess.CompletedProcess([], 0)
        else:
            p = sh(["fmbd-run", fmscene, "-o", ref, "-q"] + trun, log, check=False)
            if p.returncode == 0:
                fm_stamp(out, fe, fmscene, trun, write=True)
        if p.returncode == 0:
            ref_label, ref_modes, ref_scene = "FM (full FE model)", "all FE dofs", os.path.join(out, "fm.yaml")
        else:
            fm_why = (p.stderr.strip().splitlines() or ["?"])[-1]
    if ref_label is None:
        nref = max(int(opt_value(f2c, "--modes") or 20), -(-3 * max(mo["nd"] or 0 for mo in models) // 2))
        cbref = os.path.join(out, f"{a.body}-nd{nref}.cb.h5")
        if not os.path.exists(cbref):
            sh(["fe2cb", fe] + drop_opt(f2c, "--modes") + ["--modes", str(nref), "-o", cbref, "-q"], log)
        sh(["fmbd-run", variant("cball", cbref), "-o", ref, "-q"] + trun, log)
        ref_label = f"CB all, Nd {nref} (stand-in for the FM)"
        ref_modes = f"{nmodes(cbref)} modes"
        ref_scene = os.path.join(out, "cball.yaml")
    ref_cpu, ref_tot, ref_steps = stats(ref)

    def slugof(mo):
        return re.sub(r"[^A-Za-z0-9.]+", "_", mo["name"])

    for mo in models:
        variant(slugof(mo), mo["file"])

    def run_model(mo):
        run = os.path.join(out, slugof(mo) + ".run.h5")
        sh(["fmbd-run", os.path.join(out, slugof(mo) + ".yaml"), "-o", run, "-q", "--reference", ref] + trun, log)
        mo["cpu"], mo["cpu_total"], mo["steps"] = stats(run)
        mo["err"] = errors(run, a.output)
        mo["speedup"] = ref_cpu / mo["cpu"] if mo["cpu"] > 0 else float("nan")

    # --- chaotic motion: the window before the trajectories separate ---------------------------
    # found from the cheapest CB body (the loosest tolerance's) run at the run's steps and at
    # finer ones: chaos separates any two solutions, and the first instant at which these two
    # differ says how long a trajectory means anything at this step size. Each model is run
    # again to that instant, its errors over the window from fmbd-run --reference --window.
    def run_window(mo, tsep):
        run = os.path.join(out, slugof(mo) + "-window.run.h5")
        sh(["fmbd-run", os.path.join(out, slugof(mo) + ".yaml"), "-o", run, "-q", "--t-end", "%.6g" % tsep,
            "--reference", ref, "--window", "0:%.6g" % tsep], log)
        mo["werr"] = errors(run, a.output)

    # side by side with --jobs (each run's CPU time is its own, the table's, whatever runs beside
    # it): the separation's two runs first, then the costliest models first
    window = None
    order = sorted(models, key=lambda mo: -(mo["modes"] or 0))
    with ThreadPoolExecutor(max_workers=a.jobs) as ex:
        if a.window:
            sep = next(mo for mo in models if mo["family"] == "CB")
            t2 = os.path.join(out, slugof(sep) + "-finer.yaml")
            with open(t2, "w") as f:
                f.write(tighter(open(os.path.join(out, slugof(sep) + ".yaml")).read()))
            run2 = os.path.join(out, slugof(sep) + "-finer.run.h5")
            first = [ex.submit(run_model, sep), ex.submit(sh, ["fmbd-run", t2, "-o", run2, "-q"] + trun, log)]
            rest = [ex.submit(run_model, mo) for mo in order if mo is not sep]
            for f in first:
                f.result()
            tsep, size = separation(os.path.join(out, slugof(sep) + ".run.h5"), run2, a.output)
            window = dict(t=tsep, size=size, finer=tighter_what(open(os.path.join(out, slugof(sep) + ".yaml")).read()),
                          model=sep["name"], sep=tsep)
            if a.window_end:  # a window of the user's instead (an output instant: no interpolation at its end)
                tsep = window["t"] = float(a.window_end)
            if tsep is not None:
                rest += [ex.submit(run_window, mo, tsep) for mo in order]
        else:
            rest = [ex.submit(run_model, mo) for mo in order]
        for f in rest:
            f.result()

    write_report(a, out, title, ref_label, ref_modes, ref_cpu, ref_tot, ref_steps, models,
                 window, nm_range, locals().get("fm_why"))
    print(f"{PROG}: {out}/report.md: {len(models)} models against {ref_label}, "
          f"{time.time() - w0:.1f} s wall, {time.process_time() - c0:.2f} s cpu (this script; "
          f"the programs' time is in the report)", file=sys.stderr)


def fmt(x):
    return "" if x is None or (isinstance(x, float) and np.isnan(x)) else "%.3g" % x


def write_report(a, out, title, ref_label, ref_modes, ref_cpu, ref_tot, ref_steps, models,
                 window, nm_range, fm_why):
    qs = [q for q in QUANT if any(q in mo["err"] for mo in models)]
    # CSV
    cols = ["model", "family", "tol", "nd_selected", "nd_paper", "modes", "cpu_s", "cpu_total_s",
            "speedup"] + [f"{s}_{q}" for q in qs for s in ("rms", "max")]
    if window and window["t"] is not None:
        cols += [f"window_{s}_{q}" for q in qs for s in ("rms", "max")]
    with open(os.path.join(out, "report.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        w.writerow([ref_label, "REF", "", "", "", ref_modes, "%.6g" % ref_cpu, "%.6g" % ref_tot, 1]
                   + ["0"] * (len(cols) - 9))
        for mo in models:
            row = [mo["name"], mo["family"], "" if mo["tol"] is None else "%g" % mo["tol"],
                   mo["nd"] or "", mo["paper"], mo["modes"], "%.6g" % mo["cpu"],
                   "%.6g" % mo["cpu_total"], "%.4g" % mo["speedup"]]
            row += ["%.6g" % mo["err"].get(q, (np.nan, np.nan))[i] for q in qs for i in (0, 1)]
            if window and window["t"] is not None:
                row += ["%.6g" % mo["werr"].get(q, (np.nan, np.nan))[i] for q in qs for i in (0, 1)]
            w.writerow(row)
    # Markdown
    L = [f"# Error against run time: {title}", ""]
    L.append(f"Reference: **{ref_label}** ({ref_modes}), {ref_steps} steps, integration "
             f"{ref_cpu:.3g} s CPU ({ref_tot:.3g} s the whole run). Errors of output "
             f"`{a.output}` against it over the whole run; CPU: the integration's (one core); "
             f"speed-up: the reference's integration CPU time over the model's, at the same "
             f"integrator settings. Nm (cbcheck --range) = {nm_range}.")
    if fm_why:
        L += ["", f"The full FE model was not used: fmbd-run refused the .fe.h5 body ({fm_why})."]
    L.append("")
    hdr = ["model", "Nd (paper)", "modes", "CPU s", "speed-up"]
    for q in qs:
        hdr += [f"RMS {q} ({UNIT[q]})", f"max {q}"]
    if window and window["t"] is not None:
        hdr += ["window RMS position (m)", "window max position"]
    L.append("| " + " | ".join(hdr) + " |")
    L.append("|" + "---|" * len(hdr))
    for mo in models:
        nd = "" if mo["nd"] is None else (f"{mo['nd']} ({mo['paper']})" if mo["paper"] else str(mo["nd"]))
        r = [mo["label"], nd, str(mo["modes"]), "%.3g" % mo["cpu"], "%.3g" % mo["speedup"]]
        for q in qs:
            e = mo["err"].get(q)
            r += [fmt(e[0]) if e else "", fmt(e[1]) if e else ""]
        if window and window["t"] is not None:
            e = mo["werr"].get("position")
            r += [fmt(e[0]) if e else "", fmt(e[1]) if e else ""]
        L.append("| " + " | ".join(r) + " |")
    L += ["", "Errors: fmbd-run --reference (/reference/OUTPUT: rms_*, max_*)."]
    if window:
        if window["t"] is None:
            L += ["", f"Window: the {window['model']} body at the run's steps and at finer ones "
                  f"never differ by more than 1 % of the motion's size ({window['size']:.3g} m): "
                  f"no separation within the run."]
        else:
            L += ["", f"Window: the {window['model']} body at the run's steps and at finer ones never "
                  f"differ by more than 1 % of the motion's size ({window['size']:.3g} m); the window "
                  f"errors are over 0..{window['t']:.4g} s (--window-end)."] if window["sep"] is None else \
                 ["", f"Window: the {window['model']} body run at the run's steps and at finer ones "
                  f"({window['finer']}) first differ at `{a.output}` by more than 1 % of the motion's size "
                  f"({window['size']:.3g} m) at t = {window['sep']:.4g} s: the trajectories "
                  f"separate there, and the window errors are over 0..{window['t']:.4g} s (each model "
                  f"run again to there, fmbd-run --reference --window"
                  + (", --window-end" if a.window_end else "") + ")."]
    L += ["", f"Plot: report.svg. Reproduce: `{' '.join(shlex.quote(x) for x in sys.argv)}`", ""]
    open(os.path.join(out, "report.md"), "w").write("\n".join(L))
    plot(a, out, title, ref_label, ref_cpu, models, qs, window)


def plot(a, out, title, ref_label, ref_cpu, models, qs, window):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = len(qs)
    fig, axs = plt.subplots(1, n, figsize=(4.2 * n, 4.4), squeeze=False)
    style = {"CB": ("s", "C0"), "RFlex": ("o", "C1"), "RFlex free": ("D", "C3"), "NM": ("^", "C2")}
    for ax, q in zip(axs[0], qs):
        for fam, (mk, c) in style.items():
            pts = [(mo["cpu"], mo["err"][q][0], mo) for mo in models
                   if mo["family"] == fam and q in mo["err"] and mo["err"][q][0] > 0]
            if not pts:
                continue
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], mk, color=c, label=fam, ls="")
            for x, y, mo in pts:
                lab = (f"{mo['tol']:g}: {mo['modes']}" if mo["tol"] is not None else f"{mo['modes']}")
                ax.annotate(lab, (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7)
            if q == "position" and window and window.get("t") is not None:
                wp = [(mo["cpu"], mo["werr"]["position"][0]) for mo in models
                      if mo["family"] == fam and "position" in mo.get("werr", {})
                      and mo["werr"]["position"][0] > 0]
                if wp:
                    ax.loglog([p[0] for p in wp], [p[1] for p in wp], mk, mfc="none", color=c,
                              label=f"{fam}, 0..{window['t']:.3g} s")
        ax.axvline(ref_cpu, color="grey", lw=0.8, ls=":")
        ax.text(ref_cpu, 0.02, " " + ref_label.split(" (")[0], color="grey", fontsize=7,
                rotation=90, transform=ax.get_xaxis_transform(), va="bottom")
        ax.set_xlabel("CPU time of the integration (s)")
        ax.set_ylabel(f"RMS error of {a.output}: {q.replace('_', ' ')} ({UNIT[q]})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"{title}: error against run time (labels: tolerance: modes)", fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "report.svg"))
    plt.close(fig)


if __name__ == "__main__":
    main()
