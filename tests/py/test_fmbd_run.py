#!/usr/bin/python3
# tests/py/test_fmbd_run.py: fmbd-run on rigid scenes through the whole program, the run file
# read with h5py: the pendulum period against the elliptic integral, energy drift order with
# rho_inf = 1, the spatial slider-crank against closed-form kinematics, -M rules, --reference,
# --plot, and every complete scene of docs/SCENE.md.
import os
import re
import shutil
import subprocess
import sys

import h5py
import numpy as np
from scipy.special import ellipk

ROOT = os.environ.get("ROOT", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_fmbd_run")
shutil.rmtree(TMP, ignore_errors=True)  # fresh: make must not trust files of an older build
os.makedirs(TMP)
EXE = os.path.join(ROOT, BUILD, "bin", "fmbd-run")
failures = []


def check(cond, msg):
    print(("ok    " if cond else "FAIL  ") + msg)
    if not cond:
        failures.append(msg)


def run(args, **kw):
    p = subprocess.run([EXE] + args, capture_output=True, text=True, cwd=TMP, **kw)
    if p.returncode != 0:
        print(p.stderr)
    return p


def write(name, text):
    path = os.path.join(TMP, name)
    with open(path, "w") as f:
        f.write(text)
    return path


# --- 1. rigid pendulum period at 90 degrees amplitude ----------------------------------------
scene = os.path.join(ROOT, "examples", "scenes", "pendulum.yaml")
out = os.path.join(TMP, "pendulum.run.h5")
p = run([scene, "-o", out, "--plot", os.path.join(TMP, "pend-")])
check(p.returncode == 0, "pendulum runs")
check(re.search(r"fmbd-run: .*pendulum.run.h5: \d+ steps, \d+ rejected, \d+ Newton iterations", p.stderr) is not None,
      "summary line: " + p.stderr.strip().splitlines()[-1] if p.stderr.strip() else "no summary")
with h5py.File(out, "r") as f:
    t = f["time"][()]
    x = f["outputs/bob/position"][()]
    st = f["stats"].attrs
    check(st["complete"] == 1 and st["steps"] > 0 and "rejected_steps" in st and st["wall_time_s"] >= 0,
          f"/stats complete={st['complete']} steps={st['steps']} newton={st['newton_iterations']}")
    check(f.attrs["format"] in (b"fmbd-run", "fmbd-run"), "format attribute fmbd-run")
    # the Newton iterations' CPU split: each phase measured (> 0: every iteration solves, the
    # first one factors) and together within the integration's CPU time (the phases' wall time
    # scaled by the CPU share of the wall time since the first step cannot exceed it; 1 ms for
    # the clock readings between the end of the run and the write)
    ph = [st[k] for k in ("factor_cpu_time_s", "solve_cpu_time_s", "eval_cpu_time_s")]
    check(min(ph) > 0 and sum(ph) <= st["run_cpu_time_s"] + 1e-3,
          "/stats factor, solve, eval CPU %s s within run_cpu_time_s %.4g s" % (ph, st["run_cpu_time_s"]))
    E = f["energy/kinetic"][()] + f["energy/potential"][()]
    check(f["reactions/pivot/force"].shape == (len(t), 3), "reaction series")
theta = np.arctan2(x[:, 0], -x[:, 1])  # from the downward vertical
# zero crossings of theta, linearly interpolated
idx = np.where(np.sign(theta[:-1]) != np.sign(theta[1:]))[0]
tc = t[idx] - theta[idx] * (t[idx + 1] - t[idx]) / (theta[idx + 1] - theta[idx])
T_num = 2 * np.mean(np.diff(tc))
I_O, m, g, L = 1e-3 + 1.0, 1.0, 9.81, 1.0
T_exact = 4 * np.sqrt(I_O / (m * g * L)) * ellipk(np.sin(np.pi / 4) ** 2)
# tolerance 2e-4 relative: the period error of generalized-alpha is O((omega h)^2) with
# h <= 0.01, omega = 2.65 rad/s, and the local error tolerance 1e-6 keeps the steps far below
# that; the crossing interpolation on a 5 ms grid adds O(1e-5)
check(abs(T_num / T_exact - 1) < 2e-4, f"pendulum period {T_num:.6f} s vs elliptic integral {T_exact:.6f} s "
      f"(rel {T_num / T_exact - 1:.2e}, small-angle {2 * np.pi * np.sqrt(I_O / (m * g * L)):.4f} s)")
check(np.max(np.abs(np.hypot(x[:, 0], x[:, 1]) - 1)) < 1e-7, "bob stays on the unit circle (constraint at Newton tolerance)")
for k in ("bob-position.svg", "bob-trajectory.svg"):
    pth = os.path.join(TMP, "pend-" + k)
    check(os.path.exists(pth) and open(pth).read().startswith("<"), "--plot wrote " + k)

# --- 2. energy drift with rho_inf = 1 shrinks at second order as the step halves --------------
drift = []
for h in (4e-3, 2e-3, 1e-3):
    s = open(scene).read()
    # newton_tol 1e-12: the drift measured must be the scheme's truncation error, not the
    # Newton residual (with the default 1e-8 the latter dominates below h = 4e-3)
    s = re.sub(r"solver:\n(  .*\n)+", f"solver:\n  t_end: 3\n  rho_inf: 1\n  step: {h}\n  newton_tol: 1e-12\n", s)
    s = s.replace("every: 0.005", "every: 0.004")
    path = write(f"pend_h{h}.yaml", s)
    o = os.path.join(TMP, f"pend_h{h}.run.h5")
    p = run([path, "-o", o, "-q"])
    check(p.returncode == 0, f"fixed step {h} runs")
    with h5py.File(o, "r") as f:
        E = f["energy/kinetic"][()] + f["energy/potential"][()]
    drift.append(np.max(np.abs(E - E[0])))
rates = [np.log2(drift[i] / drift[i + 1]) for i in range(2)]
# order 2 of the scheme: a rate above 1.7 (halving the step divides the drift by > 3.2);
# the drift is an energy error, bounded (no secular growth) for rho_inf = 1
check(min(rates) > 1.7, f"energy drift {['%.3e' % d for d in drift]} J, observed orders {['%.2f' % r for r in rates]}")

# --- 3. spatial slider-crank against closed-form kinematics ----------------------------------
scene = os.path.join(ROOT, "examples", "scenes", "slider_crank.yaml")
out = os.path.join(TMP, "slider_crank.run.h5")
p = run([scene, "-o", out])
check(p.returncode == 0, "slider-crank runs")
with h5py.File(out, "r") as f:
    t = f["time"][()]
    s = f["outputs/slider/position"][()]
    v = f["outputs/slider/velocity"][()]
    pin = f["outputs/pin/position"][()]
ph = 2 * np.pi * t
Cy, Cz = 0.1 + 0.08 * np.cos(ph), 0.12 + 0.08 * np.sin(ph)
s_exact = np.sqrt(0.09 - Cy ** 2 - Cz ** 2)
ds_exact = -(Cy * (-0.08 * np.sin(ph)) + Cz * (0.08 * np.cos(ph))) * 2 * np.pi / s_exact
# positions satisfy the constraints to the Newton tolerance (1e-8 relative of coordinates of
# 0.3 m: 3e-9 m; 9e-12 m measured): 1e-8 m
err = np.max(np.abs(s[:, 0] - s_exact))
check(err < 1e-8, f"slider position vs closed form: max error {err:.2e} m over {len(t)} instants")
check(np.max(np.abs(s[:, 1:])) < 1e-8, "slider stays on the x axis")
# velocities: the index-3 scheme gives x' from the Newmark update, O(h^2) = 1e-6 relative
errv = np.max(np.abs(v[:, 0] - ds_exact)) / np.max(np.abs(ds_exact))
check(errv < 1e-3, f"slider velocity vs closed form: max relative error {errv:.2e}")
errp = np.max(np.abs(pin - np.stack([0 * t, Cy, Cz], axis=1)))
check(errp < 1e-8, f"crank pin on its circle: {errp:.2e} m")  # the same bound (5e-15 measured)

# --- 3b. four-bar linkage: a closed loop whose redundant equations are found and named -------
fourbar = os.path.join(ROOT, "examples", "scenes", "fourbar.yaml")
out = os.path.join(TMP, "fourbar.run.h5")
p = run([fourbar, "-o", out])
red = re.findall(r"warning: redundant constraint removed: joint '(\w+)' equation (\d)", p.stderr)
check(p.returncode == 0 and len(red) == 3, f"four-bar runs, redundant equations named: {red}")
with h5py.File(out, "r") as f:
    t = f["time"][()]
    B = f["outputs/B/position"][()]
    check(f["stats"].attrs["redundant_equations"] == 3, "/stats redundant_equations = 3")
th = 2 * np.pi * t
A = np.stack([-0.1 * np.sin(th), 0.1 * np.cos(th)], axis=1)
# the loop closes: |B - C| = 0.3 and |B - A| = 0.4 at the Newton tolerance (1e-8 relative of
# 0.4 m) and the 9-digit initial coordinates of the scene (1e-9 m): 1e-8 m (1.8e-9 measured)
eC = np.max(np.abs(np.linalg.norm(B[:, :2] - [0.4, 0], axis=1) - 0.3))
eA = np.max(np.abs(np.linalg.norm(B[:, :2] - A, axis=1) - 0.4))
check(max(eC, eA) < 1e-8 and np.max(np.abs(B[:, 2])) < 1e-9, f"four-bar loop closed: {eC:.1e} m, {eA:.1e} m")

# --- 3c. the rigid quadruple pendulum against a minimal-coordinate solution (scipy) -----------
# the planar chain's four angles from the downward vertical; link: joint-to-joint 0.4 m,
# centre of mass 0.2 m from its joint, solid cylinder L = 0.3, r = 0.015, rho = 7850
from scipy.integrate import solve_ivp
n, l, c, g = 4, 0.4, 0.2, 9.806
mq = 7850 * np.pi * 0.015 ** 2 * 0.3
Iq = mq * (3 * 0.015 ** 2 + 0.3 ** 2) / 12
lev = np.array([[l if j < k else (c if j == k else 0) for j in range(n)] for k in range(n)])
Aq, Gq = mq * lev.T @ lev, mq * lev.sum(axis=0)


def rhs(t, y):
    th, w = y[:n], y[n:]
    d = th[:, None] - th[None, :]
    return np.concatenate([w, np.linalg.solve(Aq * np.cos(d) + Iq * np.eye(n),
                                              -(Aq * np.sin(d)) @ w ** 2 - g * Gq * np.sin(th))])


sol = solve_ivp(rhs, (0, 1.5), np.r_[np.full(n, np.pi / 2), np.zeros(n)], method="DOP853", rtol=1e-11,
                atol=1e-12, dense_output=True)
out = os.path.join(TMP, "quadrigid.run.h5")
p = run([os.path.join(ROOT, "examples/quadpend/quadpend_rigid.yaml"), "-o", out, "--t-end", "1.5", "-q"])
with h5py.File(out, "r") as f:
    t, x = f["time"][()], f["outputs/tip3/position"][()]
th = sol.sol(t)[:3]
tip = np.stack([l * np.sin(th).sum(axis=0), -l * np.cos(th).sum(axis=0)], axis=1)
rms = np.sqrt(np.mean(np.sum((x[:, :2] - tip) ** 2, axis=1)))
# measured 1.4e-4 m with the scene's local error tolerance 1e-5; the chain is chaotic, so the
# bound is loose (5e-4 m) but a wrong joint, inertia or gravity term gives centimetres
check(p.returncode == 0 and rms < 5e-4 and np.max(np.abs(x[:, 2])) < 1e-9,
      f"rigid quadruple pendulum vs minimal coordinates over 1.5 s: RMS {rms:.2e} m (link 3 tip)")

# --- 4. -M: a rigid-only scene depends on itself; the quadruple pendulum on its chain ----------
p = run(["-M", os.path.join(ROOT, "examples/scenes/pendulum.yaml"), "-o", "p.run.h5"])
check(p.returncode == 0 and p.stdout == "p.run.h5: %s\n" % os.path.join(ROOT, "examples/scenes/pendulum.yaml"),
      "-M rigid-only: " + repr(p.stdout))
q = os.path.join(ROOT, "examples/quadpend/quadpend.yaml")
p = run(["-M", q, "--body-dir", "out"])
rules = p.stdout
check(rules.startswith("%s: %s \\\n  out/rod.rflex.h5\n" % (q[:-5] + ".run.h5", q)), "-M quadpend run rule")
check("\nout/rod.rflex.h5: out/rod.cb.h5 out/rod.fe.h5 %s\n\tcbcheck out/rod.cb.h5 --fe out/rod.fe.h5 --init 5" % q in rules,
      "-M cbcheck rule")
check("\nout/rod.cb.h5: out/rod.fe.h5\n\tfe2cb out/rod.fe.h5 --modes 60 -o $@\n" in rules, "-M fe2cb rule")
geo = os.path.join(ROOT, "examples/quadpend/../geometry/rod.geo")
check("\nout/rod.fe.h5: %s\n\tmesh2fe %s --size 0.0075" % (geo, geo) in rules, "-M mesh2fe rule")
# make accepts the rules (dry run: the rules parse and name the chain)
mk = write("rules.mk", rules + "\nall: %s\n" % (q[:-5] + ".run.h5"))
d = subprocess.run(["make", "-n", "-f", mk, "out/rod.rflex.h5"], capture_output=True, text=True, cwd=TMP)
check(d.returncode == 0 and "mesh2fe" in d.stdout and "fe2cb" in d.stdout and "cbcheck" in d.stdout,
      "make -n builds the chain geometry -> fe -> cb -> rflex")

# --- 5. --reference: a run against itself has zero error; against a coarser run a small one --
ref = os.path.join(TMP, "slider_crank.run.h5")
out2 = os.path.join(TMP, "slider_crank_self.run.h5")
p = run([scene, "-o", out2, "--reference", ref])
check(p.returncode == 0 and re.search(r"\n?fmbd-run: +slider +position +0\.0000e\+00 +0\.0000e\+00 ", p.stderr) is not None,
      "--reference against itself: zero RMS")
with h5py.File(out2, "r") as f:
    check(f["reference/slider"].attrs["rms_position"] == 0 and f["reference/slider"].attrs["instants"] == len(f["time"]),
          "/reference/slider attributes")

# --- 6. the scenes of docs/SCENE.md run ---------------------------------------------------------
doc = open(os.path.join(ROOT, "docs", "SCENE.md")).read()
blocks = re.findall(r"```yaml\n(.*?)```", doc, re.S)
full = [b for b in blocks if b.startswith("title:") or "\nsolver:" in b or b.startswith("solver:")]
check(len(full) >= 1, f"docs/SCENE.md has {len(full)} complete scene(s)")
for i, b in enumerate(full):
    path = write(f"doc{i}.yaml", b)
    p = run([path, "-o", os.path.join(TMP, f"doc{i}.run.h5"), "-q"])
    check(p.returncode == 0, f"docs/SCENE.md scene {i + 1} runs")

if failures:
    print(f"{len(failures)} failure(s)")
    sys.exit(1)
