#!/usr/bin/python3
# tests/py/test_cbcheck_rflex.py: the reduced flexible body written by cbcheck (fmbd-rflex)
# SPDX-License-Identifier: MIT
#
# A tet10 rod with two RBE2 interfaces, reduced by fe2cb and selected by cbcheck to 1e-3 on 8
# flexible modes, then the /ffrf invariants against identities with the fe file's consistent M
# (S1 = 0 for free-free modes), a lumped-mass rod's against a direct numpy evaluation from its
# /mesh/node_mass, /expand and /modes/shapes (docs/THEORY.md section 9), the rigid-body
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

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fegen  # noqa: E402

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

# --- FFRF invariants (docs/THEORY.md section 9) ------------------------------------------------
# This rod is meshed with consistent mass: the invariants use the mass the modes come from. They
# are checked against the fe file's own M (assembled by mesh2fe, the RBE2 ties eliminated) by
# identities that hold exactly, the rigid motions being in the span of the active dofs:
#   S1_a,k = r_a' M X_k          r_a: unit rigid translation along a
#   eps_cab XS_ab,k = w_c' M X_k  w_c: unit rigid rotation about axis c through the origin
#   sum_a SS_aa,kl = X_k' M X_l   (= delta_kl: mass-normalised)
# and S1 and the antisymmetric part of XS vanish for free-free modes, M-orthogonal to rigid
# motion: no spurious rigid-flexible coupling. With the lumped nodal masses they did not
# (|S1| / sqrt(m) = 1.6e-3 here). Round-off: sums of ~1e3 products of O(1) terms scaled by
# sqrt(m) (the bound |S1_k| <= sqrt(m) |X_k|_M): 1e-10 is far above it, 1e-3 far below.
U = (E @ X).reshape(nn, 6, nm)          # row 6p+d of /expand: component d of node p
with h5py.File(os.path.join(TMP, "rod.rflex.h5"), "r") as f:
    dofs = f["dofs"][()]
R = fegen.rigid_modes(nodes, dofs)
RMX = R.T @ (M @ X)
msq = np.sqrt(float(body["mass"]))
eps = np.zeros((3, 3, 3))
eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
xs_anti = np.einsum("cab,abk->ck", eps, ff["XS"])
d_s1 = np.max(np.abs(ff["S1"] - RMX[:3])) / msq
d_xs = np.max(np.abs(xs_anti - RMX[3:])) / msq
d_ss = np.max(np.abs(np.einsum("aakl->kl", ff["SS"]) - mm))
print("consistent invariants: S1 vs r'MX %.1e, eps XS vs w'MX %.1e, tr SS vs X'MX %.1e; "
      "|S1| / sqrt(m) = %.1e, |eps XS| / sqrt(m) = %.1e" %
      (d_s1, d_xs, d_ss, np.abs(ff["S1"]).max() / msq, np.abs(xs_anti).max() / msq))
check(ff["S1"].shape == (3, nm) and ff["XS"].shape == (3, 3, nm) and ff["SS"].shape == (3, 3, nm, nm),
      "invariant shapes")
check(d_s1 < 1e-10 and d_xs < 1e-10 and d_ss < 1e-10, "consistent invariants off the identities")
check(np.abs(ff["S1"]).max() / msq < 1e-10, "S1 of free-free modes of a consistent-mass body is not 0")
check(np.abs(xs_anti).max() / msq < 1e-10, "rotational coupling of free-free modes is not 0")

# a lumped-mass rod keeps the lumped nodal masses (the mass its modes come from): every
# invariant against a direct numpy evaluation from its /mesh/node_mass (1e-12: round-off of
# sums over ~1000 nodes; an index mix-up is O(1))
run("mesh2fe", geo, "--size", "0.02", "--mass", "lumped", "--interface", "end0", "-o", "rodl.fe.h5", "-q")
run("fe2cb", "rodl.fe.h5", "--modes", "10", "-o", "rodl.cb.h5", "-q")
run("cbcheck", "rodl.cb.h5", "--tol", "1e-2", "--range", "4", "-o", "rodl.rflex.h5", "-q")
with h5py.File(os.path.join(TMP, "rodl.rflex.h5"), "r") as f:
    XL, EL = f["modes/shapes"][()], csr(f["expand"])
    nodesL, massL = f["mesh/nodes"][()], f["mesh/node_mass"][()]
    ffL = {k: f["ffrf"][k][()] for k in f["ffrf"]}
TL = (EL @ XL).reshape(len(nodesL), 6, XL.shape[1])[:, :3, :]
for name, ref in (("S1", np.einsum("p,pak->ak", massL, TL)),
                  ("XS", np.einsum("p,pa,pbk->abk", massL, nodesL, TL)),
                  ("SS", np.einsum("p,pak,pbl->abkl", massL, TL, TL))):
    d = np.max(np.abs(ffL[name] - ref)) / np.max(np.abs(ref))
    print("lumped rod: /ffrf/%s vs numpy: %.1e (shape %s)" % (name, d, ffL[name].shape))
    check(ffL[name].shape == ref.shape and d < 1e-12, "lumped rod: /ffrf/%s differs by %.1e" % (name, d))
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
