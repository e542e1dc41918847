#!/usr/bin/python3
# tests/py/test_cbcheck_hold.py: a reduced body keeps its accuracy where the scene holds it
# (cbcheck --hold; docs/THEORY.md section 12).
# SPDX-License-Identifier: MIT
#
# An aluminium rod (tet10, E 70 GPa, nu 0.33, rho 2710), RBE2 interfaces at both ends, clamped
# at end0 (a fixed joint in a scene), loaded by gravity along -y. Reference: the full FE model
# clamped at the interface node (scipy on the fe file's K and M). A reduced body in the floating
# frame clamped at the same node is the Ritz problem on [rigid motions, body modes] with the
# node's six dofs held; its static tip deflection and first frequency are compared.
# - free-interface modes (cbcheck --tol 1e-3 --range 8, as before --hold): far off (the setup
#   shows the defect: they cannot bend at a clamp; 37 % and 26 % measured);
# - held (--hold end0): within 0.5 % (the bar; 0.02 % measured): the held problem's
#   modes plus the constraint modes of the held dofs;
# - the held problem's eigenvalues (end1 still an interface, free) against scipy's clamped
#   eigensolution: the selection's upper estimates bound the exact errors and meet the tolerance.
import csv
import os
import subprocess
import sys

import h5py
import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp
import scipy.sparse.linalg as spl

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fegen  # noqa: E402

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_cbcheck_hold")
os.makedirs(TMP, exist_ok=True)
os.environ["PATH"] = os.path.join(ROOT, BUILD, "bin") + os.pathsep + os.environ["PATH"]
failures = []


def check(cond, msg):
    print(("ok    " if cond else "FAIL  ") + msg)
    if not cond:
        failures.append(msg)


def run(*cmd):
    r = subprocess.run(list(cmd), cwd=TMP, capture_output=True, text=True)
    if r.returncode != 0:
        print(r.stdout, r.stderr)
        raise SystemExit("command failed (%d): %s" % (r.returncode, " ".join(cmd)))
    return r


def csr(g):
    return sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))


TOL, NM = 1e-3, 8
geo = os.path.join(ROOT, "examples", "geometry", "rod.geo")
run("mesh2fe", geo, "--size", "0.01", "--E", "70e9", "--nu", "0.33", "--rho", "2710",
    "--interface", "end0", "--interface", "end1", "-o", "rod.fe.h5", "-q")
run("fe2cb", "rod.fe.h5", "--modes", "30", "-o", "rod.cb.h5", "-q")
run("cbcheck", "rod.cb.h5", "--tol", str(TOL), "--range", str(NM), "-o", "free.rflex.h5", "-q")
run("cbcheck", "rod.cb.h5", "--tol", str(TOL), "--range", str(NM), "--hold", "end0",
    "--csv", "held.csv", "-o", "held.rflex.h5", "-q")

with h5py.File(os.path.join(TMP, "rod.fe.h5")) as f:
    K, M = csr(f["K"]), csr(f["M"])
    dofs, nodes = f["dofs"][()], f["mesh/nodes"][()]
    inode = int(f["interfaces/end0"].attrs["node"])
n = K.shape[0]
g = np.zeros(n)
g[dofs[:, 1] == 1] = -9.81
fvec = M @ g
held = dofs[:, 0] == inode
fr = ~held
tipnode = int(np.argmax(nodes[:, 0]))
tip = int(np.where((dofs[:, 0] == tipnode) & (dofs[:, 1] == 1))[0][0])
Kf, Mf = K[fr][:, fr].tocsc(), M[fr][:, fr].tocsc()
u = np.zeros(n)
u[fr] = spl.spsolve(Kf, fvec[fr])
chi = np.sort(spl.eigsh(Kf, k=NM + 1, M=Mf, sigma=0, which="LM", tol=1e-12)[0])
w1 = np.sqrt(chi[0])

# rigid motions in the active dofs (translations; rotations about the origin)
R = fegen.rigid_modes(nodes, dofs)


def clamped(fn):
    """Static tip deflection and first frequency of the reduced body clamped at end0."""
    with h5py.File(os.path.join(TMP, fn)) as f:
        X = f["modes/shapes"][()]
        hi = f["modes"].attrs["held_interfaces"]
    B = np.hstack([R, X])
    KB, MB, fB = B.T @ (K @ B), B.T @ (M @ B), B.T @ fvec
    N = sl.null_space(B[held])
    a = N @ np.linalg.solve(N.T @ KB @ N, N.T @ fB)
    w = np.sqrt(sl.eigh(N.T @ KB @ N, N.T @ MB @ N, eigvals_only=True)[0])
    return (B @ a)[tip], w, X.shape[1], hi.decode() if isinstance(hi, bytes) else hi


ref = u[tip]
print("full model clamped at end0: tip deflection %.6e m, first frequency %.3f Hz" % (ref, w1 / 2 / np.pi))
res = {}
for fn in ("free.rflex.h5", "held.rflex.h5"):
    d, w, nm, hi = clamped(fn)
    res[fn] = (abs(d / ref - 1), abs(w / w1 - 1))
    print("%s (%d modes, held '%s'): tip %.6e m (%.3f %%), first frequency %.3f Hz (%.3f %%)"
          % (fn, nm, hi, d, 100 * (d / ref - 1), w / 2 / np.pi, 100 * (w / w1 - 1)))
check(res["free.rflex.h5"][0] > 0.05 and res["free.rflex.h5"][1] > 0.05,
      "free-interface modes at a clamp: the defect shows (%.1f %%, %.1f %%)"
      % (100 * res["free.rflex.h5"][0], 100 * res["free.rflex.h5"][1]))
check(res["held.rflex.h5"][0] < 5e-3 and res["held.rflex.h5"][1] < 5e-3,
      "--hold end0: static deflection and first frequency within 0.5 %% (%.3f %%, %.4f %%)"
      % (100 * res["held.rflex.h5"][0], 100 * res["held.rflex.h5"][1]))

# the held problem's reduced eigenvalues against scipy's clamped ones: zeta <= upper <= TOL
rows = list(csv.DictReader(open(os.path.join(TMP, "held.csv"))))
chibar = np.array([float(r["eigenvalue"]) for r in rows])[:NM]
upper = np.array([float(r["upper"]) for r in rows])[:NM]
zeta = chibar / chi[:NM] - 1
print("held problem: exact errors %s" % np.array2string(zeta, precision=2))
print("              upper        %s" % np.array2string(upper, precision=2))
check(np.all(zeta > -1e-9) and np.all(zeta <= upper * (1 + 1e-6) + 1e-12) and np.all(upper <= TOL),
      "held problem: Ritz values above the exact ones, upper estimates bound the errors and meet %g" % TOL)

# --- end to end in fmbd-run: the rod clamped by a fixed joint at end0 under gravity, 20 % modal
# damping, 0.3 s; the tip's mean deflection over the second half (the body's modes are
# M-orthogonal to rigid motion, so a clamped mode moves the frame too and is damped less than
# the modes: not settled at 0.05 s) against the full model's static one (within 0.5 %, the
# issue's bar); the free-interface body gets a warning
scene = """gravity: [0, -9.81, 0]
solver: {t_end: 0.3, step: 1e-4}
bodies:
  - {name: rod, type: flexible, file: %s, damping_ratio: 0.2}
joints:
  - {name: clamp, type: fixed, body1: ground, body2: rod, at2: {interface: end0}}
outputs:
  points:
    - {name: tip, body: rod, interface: end1, quantities: [position]}
"""
for fn in ("free.rflex.h5", "held.rflex.h5"):
    with open(os.path.join(TMP, "clamp-" + fn + ".yaml"), "w") as f:
        f.write(scene % fn)
    r = run("fmbd-run", "clamp-" + fn + ".yaml", "-o", "clamp-" + fn + ".run.h5")
    warned = "a joint holds interface 'end0', but %s was reduced with it free" % fn in r.stderr
    with h5py.File(os.path.join(TMP, "clamp-" + fn + ".run.h5")) as f:
        y = f["outputs/tip/position"][()][:, 1]
    d = np.mean(y[len(y) // 2:]) - y[0]
    print("fmbd-run, %s: tip deflection %.6e m (%.3f %% off the full model)%s"
          % (fn, d, 100 * (d / ref - 1), ", warned" if warned else ""))
    if fn == "held.rflex.h5":
        check(abs(d / ref - 1) < 5e-3 and not warned, "fmbd-run: held body's mean tip deflection within 0.5 %")
    else:
        check(warned and abs(d / ref - 1) > 0.05, "fmbd-run: free-interface body at a clamp warned and off")
# --- modal stress, recovered in the run, for the held rflex and for the .cb.h5 body (all its
# modes; stresses from the cb file's description): the mean von Mises stress at the top surface
# node nearest (0.06, 0.015, 0) (two diameters from the clamp: Saint-Venant) against beam
# theory, sigma_xx = w (L - x)^2 / 2 * y / I with w = rho A g; 3 % (shear, the nodal averaging
# of the element stresses, the 3-D section)
stress_scene = scene.replace("quantities: [position]", "quantities: [von_mises]").replace(
    "interface: end1", "nearest: [0.06, 0.015, 0]")
with h5py.File(os.path.join(TMP, "rod.fe.h5")) as f:
    xyz = f["mesh/nodes"][()]
node = xyz[int(np.argmin(np.linalg.norm(xyz - [0.06, 0.015, 0.0], axis=1)))]
L, rad = 0.3, 0.015
w = 2710 * np.pi * rad ** 2 * 9.81
beam = w * (L - node[0]) ** 2 / 2 * abs(node[1]) / (np.pi * rad ** 4 / 4)
vm = {}
for fn in ("held.rflex.h5", "rod.cb.h5"):
    with open(os.path.join(TMP, "stress-" + fn + ".yaml"), "w") as f:
        f.write(stress_scene % fn)
    run("fmbd-run", "stress-" + fn + ".yaml", "-o", "stress-" + fn + ".run.h5", "-q")
    with h5py.File(os.path.join(TMP, "stress-" + fn + ".run.h5")) as f:
        v = f["outputs/tip/von_mises"][()]
    vm[fn] = np.mean(v[len(v) // 2:])
    print("%s: mean von Mises at node (%.4f, %.4f, %.4f) %.5g Pa, beam theory %.5g Pa (%.2f %%)"
          % (fn, node[0], node[1], node[2], vm[fn], beam, 100 * (vm[fn] / beam - 1)))
    check(abs(vm[fn] / beam - 1) < 0.03, "%s: recovered stress within 3 %% of beam theory" % fn)
# stresses (derivatives of the displacements) converge more slowly with the modes than the
# deflection: 8 against 30 modes differ by 0.8 % here; 2 % leaves room, a missing static part
# (the free-interface body) is tens of per cent off
check(abs(vm["held.rflex.h5"] / vm["rod.cb.h5"] - 1) < 2e-2,
      "held rflex (8 modes) and cb body (all 30) agree on the stress to 2 %% (%.2f %%)"
      % (100 * (vm["held.rflex.h5"] / vm["rod.cb.h5"] - 1)))

# fmbd-run -M passes the holds of the scene's joints to cbcheck
mk = scene.replace("file: %s", "file: rod.rflex.h5,\n     make: {cb: rod.cb.h5, fe: rod.fe.h5, cbcheck: --tol 1e-3}")
with open(os.path.join(TMP, "mk.yaml"), "w") as f:
    f.write(mk)
r = run("fmbd-run", "-M", "mk.yaml")
check("cbcheck rod.cb.h5 --fe rod.fe.h5 --tol 1e-3 --hold end0 --for-scene mk.yaml:" in r.stdout,
      "fmbd-run -M passes --hold end0 for the fixed joint: %s" % r.stdout.split("\n")[3:5])

# bad input: an interface the body does not have
r = subprocess.run(["cbcheck", "rod.cb.h5", "--tol", "1e-2", "--hold", "middle", "-o", "bad.rflex.h5"],
                   cwd=TMP, capture_output=True, text=True)
check(r.returncode == 1 and "--hold middle: no such interface (the body has: end0, end1)" in r.stderr
      and not os.path.exists(os.path.join(TMP, "bad.rflex.h5")),
      "--hold of an unknown interface: exit 1 naming it (%s)" % r.stderr.strip())

print("\n%d failure(s)" % len(failures))
sys.exit(1 if failures else 0)
