#!/usr/bin/python3
# tests/py/test_cbcheck_rflex.py: the reduced flexible body written by cbcheck (fmbd-rflex)
# SPDX-License-Identifier: MIT
#
# A tet10 rod with two RBE2 interfaces, reduced by fe2cb and selected by cbcheck to 1e-3 on 8
# flexible modes, then every /ffrf invariant against a direct numpy evaluation from the file's
# own /mesh/node_mass, /expand and /modes/shapes (docs/THEORY.md section 9), the rigid-body
# moments against /body, the modes against the FE matrices (mass-normalised, Rayleigh
# quotients = eigenvalues, eigenvalues within the tolerance of scipy's full eigensolution),
# the interface modes against /expand rows, and the modal stress layout.
import os
import subprocess
import sys

import h5py
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_cbcheck_rflex")
os.makedirs(TMP, exist_ok=True)
failures = []


def check(cond, msg):
    if not cond:
        failures.append(msg)
        print("FAIL:", msg)


def run(*cmd):
    r = subprocess.run(list(cmd), cwd=TMP, capture_output=True, text=True)
    if r.returncode != 0:
        print(r.stdout, r.stderr)
        raise SystemExit("command failed (%d): %s" % (r.returncode, " ".join(cmd)))
    return r


def rel(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b))) / max(np.max(np.abs(b)), 1e-300)


geo = os.path.join(ROOT, "examples", "geometry", "rod.geo")
run("mesh2fe", geo, "--size", "0.02", "--E", "100e9", "--nu", "0.285", "--rho", "7850",
    "--interface", "end0", "--interface", "end1", "-o", "rod.fe.h5", "-q")
run("fe2cb", "rod.fe.h5", "--modes", "10", "-o", "rod.cb.h5", "-q")
TOL, NM = 1e-3, 8
run("cbcheck", "rod.cb.h5", "--tol", str(TOL), "--range", str(NM), "-o", "rod.rflex.h5", "-q")

with h5py.File(os.path.join(TMP, "rod.fe.h5"), "r") as f:
    csr = lambda g: sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
    K, M = csr(f["K"]), csr(f["M"])
with h5py.File(os.path.join(TMP, "rod.rflex.h5"), "r") as f:
    check(f.attrs["format"] in ("fmbd-rflex", b"fmbd-rflex"), "format attribute")
    X = f["modes/shapes"][()]
    lam = f["modes/eigenvalue"][()]
    fhz = f["modes/frequency_hz"][()]
    E = csr(f["expand"])
    nodes = f["mesh/nodes"][()]
    mass = f["mesh/node_mass"][()]
    body = dict(f["body"].attrs)
    ff = {k: f["ffrf"][k][()] for k in f["ffrf"]}
    itf = {n: (int(f["interfaces"][n].attrs["node"]), f["interfaces"][n]["translation"][()],
               f["interfaces"][n]["rotation"][()]) for n in f["interfaces"]}
    stress = f["modes/stress"][()] if "stress" in f["modes"] else None
    nd = int(f["modes"].attrs["n_fixed_interface_modes"])
nn, nm = len(nodes), len(lam)
print("rflex: %d dofs, %d nodes, %d modes (Nd = %d), interfaces %s" % (X.shape[0], nn, nm, nd, sorted(itf)))
check(nm == NM and X.shape == (K.shape[0], NM), "shapes (%s), expected (%d, %d)" % (X.shape, K.shape[0], NM))
check(np.all(np.diff(lam) >= 0) and lam[0] > 0, "eigenvalues ascending and positive (rigid modes excluded)")
check(rel(fhz, np.sqrt(lam) / (2 * np.pi)) < 1e-14, "frequency_hz = sqrt(eigenvalue) / 2 pi")

# --- modes against the FE matrices ----------------------------------------------------------
# T0 Xi with Xi' M_ Xi = I gives X' M X = I up to the round-off of the reduction (~1e-12:
# solves with cond(Ks) ~ 1e5); 1e-9 leaves margin, a wrong secondary reduction is O(1).
mm = X.T @ (M @ X)
kk = X.T @ (K @ X)
e1, e2 = rel(mm, np.eye(nm)), rel(kk, np.diag(lam))
print("X'MX - I: %.1e, X'KX - diag(eigenvalue): %.1e (relative)" % (e1, e2))
check(e1 < 1e-9, "modes not mass-normalised: %.1e" % e1)
check(e2 < 1e-9, "Rayleigh quotients differ from the eigenvalues: %.1e" % e2)
# the kept modes meet the tolerance against the full body (scipy shift-invert, independent)
sig = -0.5 * lam[0]
chi = np.sort(spl.eigsh(K, k=6 + NM, M=M, sigma=sig, which="LM", tol=1e-12)[0])[6:]
err = lam / chi - 1
print("exact relative errors of the kept modes: max %.2e (tolerance %g)" % (err.max(), TOL))
check(np.all(err <= TOL) and np.all(err > -1e-9), "kept eigenvalues off the full ones: %s" % err)

# --- FFRF invariants (docs/THEORY.md section 9) against numpy on the file's own arrays -------------------
U = (E @ X).reshape(nn, 6, nm)          # row 6p+d of /expand: component d of node p
T = U[:, :3, :]                          # translations (nn, 3, nm)
S1 = np.einsum("p,pak->ak", mass, T)
XS = np.einsum("p,pa,pbk->abk", mass, nodes, T)
SS = np.einsum("p,pak,pbl->abkl", mass, T, T)
# sums over ~1000 nodes of products: 1e-12 relative is round-off; an index mix-up is O(1)
for name, ref in (("S1", S1), ("XS", XS), ("SS", SS)):
    d = np.max(np.abs(ff[name] - ref)) / np.max(np.abs(ref))
    print("/ffrf/%s vs numpy: %.1e (shape %s)" % (name, d, ff[name].shape))
    check(ff[name].shape == ref.shape and d < 1e-12, "/ffrf/%s differs by %.1e" % (name, d))
# S1 is the mean-axis condition: ~0 for free-free modes (lumped vs consistent mass: not exact)
s1 = np.max(np.abs(S1)) / (np.sqrt(mass.sum()) * 1.0)
print("mean-axis residual |S1| / sqrt(m): %.1e" % s1)
check(rel(ff["Mff"], np.eye(nm)) < 1e-15 and rel(ff["Kff"], np.diag(lam)) < 1e-15, "Mff = I, Kff = diag")
# rigid-body moments equal /body: m, m c, J = tr(Ic)/2 I - Ic + m c c' (Ic = tr(J) I - J)
m, c, Ic = float(body["mass"]), np.asarray(body["center_of_mass"]), np.asarray(body["inertia"]).reshape(3, 3)
J = np.trace(Ic) / 2 * np.eye(3) - Ic + m * np.outer(c, c)
check(abs(ff["mass"] - m) <= 1e-14 * m, "/ffrf/mass %.15g vs /body %.15g" % (ff["mass"], m))
check(rel(ff["first_moment"], m * c) < 1e-14, "/ffrf/first_moment vs /body")
check(rel(ff["second_moment"], J) < 1e-14, "/ffrf/second_moment vs /body")
check(rel(np.trace(ff["second_moment"]) * np.eye(3) - ff["second_moment"] - m * (c @ c * np.eye(3) - np.outer(c, c)), Ic) < 1e-12,
      "inertia from second_moment")
# the lumped nodal masses describe the same rigid body (HRZ keeps the mass exactly; moments
# within the lumping error, ~1e-3 for this mesh)
print("lumped: mass %.6g (body %.6g), second moment rel. diff %.1e" %
      (mass.sum(), m, rel(np.einsum("p,pa,pb->ab", mass, nodes, nodes), J)))
check(abs(mass.sum() / m - 1) < 1e-10, "sum of node masses %.10g vs /body mass %.10g" % (mass.sum(), m))

# --- interface modes ---------------------------------------------------------------------------
for name, (node, tr, ro) in sorted(itf.items()):
    d = max(rel(tr, U[node, :3, :]), rel(ro, U[node, 3:, :]))
    check(tr.shape == (3, nm) and d < 1e-14, "interface %s translation/rotation differ by %.1e" % (name, d))
    print("interface %s: node %d, modal translation/rotation = rows of /expand x shapes (%.1e)" % (name, node, d))

# --- modal stress ------------------------------------------------------------------------------
check(stress is not None and stress.shape == (nn, 6, nm), "/modes/stress shape")
if stress is not None:
    check(np.all(np.isfinite(stress)), "stress not finite")
    vm = np.sqrt(0.5 * ((stress[:, 0] - stress[:, 1]) ** 2 + (stress[:, 1] - stress[:, 2]) ** 2 +
                        (stress[:, 2] - stress[:, 0]) ** 2) + 3 * (stress[:, 3:] ** 2).sum(axis=1))
    # a unit modal coordinate of a mass-normalised mode of a 1.7 kg rod: displacements ~ 1 m,
    # strains ~ 1 m / 0.3 m: stresses of order E ~ 1e10..1e12 Pa; zero would mean no stress at all
    print("largest modal von Mises stress per mode: %s Pa" % np.array2string(vm.max(axis=0), precision=2))
    check(np.all(vm.max(axis=0) > 1e8), "modal stress missing or tiny")

if failures:
    print("%d failure(s)" % len(failures))
    sys.exit(1)
print("test_cbcheck_rflex: all checks passed")
