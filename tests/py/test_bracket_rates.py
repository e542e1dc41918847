#!/usr/bin/python3
# tests/py/test_bracket_rates.py: how often cbcheck's error estimates bracket the exact error,
# measured on the RAW per-mode estimates and after the cluster rule, with the exact eigenvalues
# from scipy on the same matrices (not the library's eigensolver).
# SPDX-License-Identifier: MIT
#
# Bodies: the quadruple pendulum's rod (tet10, E 100 GPa, nu 0.285, rho 7850, coarse h = 15 mm),
# one and two RBE2 end interfaces, consistent and lumped mass; Nd = 30 fixed-interface modes.
# For each flexible mode n of the reduced body (chibar_n), the exact relative error is
# e_n = chibar_n / chi_n - 1 with chi_n the n-th flexible eigenvalue of the full (K, M) from
# scipy.sparse.linalg.eigsh (shift-invert, SuperLU: independent of fe2cb's CHOLMOD and ARPACK).
# The estimates (docs/THEORY.md sections 2-3) are evaluated here per mode from the cb file and
# the FE matrices (lower = chibar b'Xb b, upper = (chibar + chibar^2/kappa_n) b'Xb b), raw, and
# then with cbcheck's cluster rule (fmbd_est.h: members of a cluster take the cluster's min of
# lower and max of upper); the clustered values are checked against cbcheck's own CSV, which
# ties the raw values to cbcheck's formulas too. Printed: the rates raw and clustered. Asserted:
#  - scipy's exact errors equal cbcheck --exact's (library eigensolver) to 1e-6 relative
#    (both converge eigenvalues to ~1e-12 relative; e_n ~ 1e-5..1e-1 amplifies that by 1/e_n);
#  - the clustered rates meet the papers' 95 % (upper >= exact, lower <= exact, modes < 10 %);
#  - the cluster rule never lowers a rate (it only widens the interval);
#  - the raw rates are at least 90 %: the per-mode estimates are bounds only to first order
#    (docs/THEORY.md section 3) and the basis inside a near-degenerate pair is arbitrary, so a
#    few raw misses are expected; measured over 77 modes: upper raw 98.7 % = clustered 98.7 %
#    (rod1 mode 25, an isolated mode near the top of the reduced spectrum, is missed by both),
#    lower raw 98.7 % -> clustered 100 % (one member of a bending pair of rod2). A rate below
#    90 % would mean a wrong formula, not the method's expected misses.
import csv
import os
import subprocess
import sys

import h5py
import numpy as np
import scipy.linalg as sl
import scipy.sparse.linalg as spl

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fegen  # noqa: E402

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_bracket_rates")
os.makedirs(TMP, exist_ok=True)
os.environ["PATH"] = os.path.join(ROOT, BUILD, "bin") + os.pathsep + os.environ["PATH"]
failures = []


def check(cond, msg):
    print(("ok:   " if cond else "FAIL: ") + msg)
    if not cond:
        failures.append(msg)


def run(*cmd):
    r = subprocess.run(list(cmd), cwd=TMP, capture_output=True, text=True)
    if r.returncode != 0:
        print(r.stdout, r.stderr)
        raise SystemExit("command failed (%d): %s" % (r.returncode, " ".join(cmd)))
    return r


def read_csv(path):
    with open(os.path.join(TMP, path)) as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) if r[k] != "" else np.nan for r in rows]) for k in rows[0]}


def raw_estimates(fe, cbf):
    """Per-mode eigenvalues, lower and upper estimates of the reduced body (no clusters)."""
    K, M = fegen.read_km(os.path.join(TMP, fe))
    with h5py.File(os.path.join(TMP, cbf), "r") as f:
        s, b = f["cb/interior_dofs"][()], f["cb/boundary_dofs"][()]
        Phi, kap = f["cb/Phi"][()], f["cb/kappa"][()]
    Ks, Kc, Kb = K[s][:, s].tocsc(), K[s][:, b].toarray(), K[b][:, b].toarray()
    Ms, Mc, Mb = M[s][:, s].tocsc(), M[s][:, b].toarray(), M[b][:, b].toarray()
    lu = spl.splu(Ks)
    Psi = -lu.solve(Kc)
    A = Ms @ Psi + Mc
    PtA = Phi.T @ A
    nd = len(kap)
    W = lu.solve(A) - Phi @ (PtA / kap[:, None])
    W -= Phi @ (Phi.T @ (Ms @ W))
    Xb = W.T @ (Ks @ W)
    Mbb = Psi.T @ (Ms @ Psi) + Psi.T @ Mc + Mc.T @ Psi + Mb
    Kr = sl.block_diag(np.diag(kap), Kb + Kc.T @ Psi)
    Mr = np.block([[np.eye(nd), PtA], [PtA.T, Mbb]])
    chib, Xi = sl.eigh((Kr + Kr.T) / 2, (Mr + Mr.T) / 2)
    flex = np.nonzero(np.abs(chib) > 1e-6 * kap[0])[0]
    eig, lower, upper = [], [], []
    for n in flex:
        c, bv = chib[n], Xi[nd:, n]
        x = bv @ Xb @ bv
        kn = kap[n] if n < nd else kap[nd - 1]
        eig.append(c)
        lower.append(c * x)
        upper.append((c + c * c / kn) * x)
    return np.array(eig), np.array(lower), np.array(upper), K, M, len(chib) - len(flex)


def cluster(eig, lower, upper):
    """cbcheck's cluster rule (fmbd_est.h): relative gap <= 1e-3, or the interval
    [chibar / (1 + upper), chibar] of a mode reaching the previous eigenvalue."""
    lo, up = lower.copy(), upper.copy()
    i = 0
    while i < len(eig):
        j = i
        while j + 1 < len(eig) and (abs(eig[j + 1] - eig[j]) <= 1e-3 * abs(eig[j + 1]) or
                                    abs(eig[j + 1] - eig[j]) <= eig[j + 1] - eig[j + 1] / (1 + max(upper[j + 1], 0))):
            j += 1
        lo[i:j + 1] = lower[i:j + 1].min()
        up[i:j + 1] = upper[i:j + 1].max()
        i = j + 1
    return lo, up


geo = os.path.join(ROOT, "examples", "geometry", "rod.geo")
bodies = [("rod1", ["--interface", "end1"], "consistent"),
          ("rod2", ["--interface", "end0", "--interface", "end1"], "consistent"),
          ("rod2l", ["--interface", "end0", "--interface", "end1"], "lumped")]
tot = {"n": 0, "up_raw": 0, "lo_raw": 0, "up_cl": 0, "lo_cl": 0}
for name, itf, mass in bodies:
    run("mesh2fe", geo, "--size", "0.015", "--E", "100e9", "--nu", "0.285", "--rho", "7850", "--mass", mass,
        *itf, "-o", name + ".fe.h5", "-q")
    run("fe2cb", name + ".fe.h5", "--modes", "30", "-o", name + ".cb.h5", "-q")
    run("cbcheck", name + ".cb.h5", "--exact", "--csv", name + ".csv", "-q")
    t = read_csv(name + ".csv")
    eig, lower, upper, K, M, nrig = raw_estimates(name + ".fe.h5", name + ".cb.h5")
    nf = len(eig)
    # exact: the full body's lowest nrig + nf eigenvalues, shift-invert below the first one
    # (sigma = -chibar_1 / 10: K - sigma M is positive definite for a free body)
    lam = np.sort(spl.eigsh(K.tocsc(), k=nrig + nf, M=M.tocsc(), sigma=-0.1 * eig[0], which="LM",
                            return_eigenvectors=False))
    chi = lam[nrig:]
    exact = eig / chi - 1
    lo_cl, up_cl = cluster(eig, lower, upper)
    # ties: the clustered numpy values are cbcheck's (1e-7: test_cbcheck.py's derivation), and
    # scipy's exact errors are cbcheck's --exact (1e-6 relative, see the header)
    m = min(nf, len(t["upper"]))
    d_est = max(np.max(np.abs(t["upper"][:m] / up_cl[:m] - 1)), np.max(np.abs(t["lower"][:m] / lo_cl[:m] - 1)))
    d_ex = np.max(np.abs(t["exact"][:m] / exact[:m] - 1))
    check(d_est <= 1e-7, "%s: clustered estimates equal cbcheck's CSV (%.1e)" % (name, d_est))
    check(d_ex <= 1e-6, "%s: scipy's exact errors equal cbcheck --exact's (%.1e)" % (name, d_ex))
    ok = exact < 0.1
    n = int(ok.sum())
    r = {"n": n,
         "up_raw": int((upper[ok] >= exact[ok]).sum()), "lo_raw": int((lower[ok] <= exact[ok]).sum()),
         "up_cl": int((up_cl[ok] >= exact[ok]).sum()), "lo_cl": int((lo_cl[ok] <= exact[ok]).sum())}
    miss = np.nonzero(ok & (upper < exact))[0] + 1
    print("%s (%s mass, Nd = 30, %d flexible modes, %d under 10 %%): upper >= exact raw %d (%.1f %%), "
          "clustered %d (%.1f %%); lower <= exact raw %d (%.1f %%), clustered %d (%.1f %%); raw upper misses "
          "modes %s" % (name, mass, nf, n, r["up_raw"], 100 * r["up_raw"] / n, r["up_cl"], 100 * r["up_cl"] / n,
                        r["lo_raw"], 100 * r["lo_raw"] / n, r["lo_cl"], 100 * r["lo_cl"] / n, list(miss)))
    for k in tot:
        tot[k] += r[k]
    check(r["up_cl"] >= r["up_raw"] and r["lo_cl"] >= r["lo_raw"], "%s: the cluster rule never lowers a rate" % name)
n = tot["n"]
print("pooled over %d modes: upper >= exact raw %.1f %%, clustered %.1f %%; lower <= exact raw %.1f %%, "
      "clustered %.1f %%" % (n, 100 * tot["up_raw"] / n, 100 * tot["up_cl"] / n, 100 * tot["lo_raw"] / n,
                            100 * tot["lo_cl"] / n))
check(n >= 30, "at least 30 modes under 10 %% error (%d)" % n)
check(tot["up_cl"] >= 0.95 * n and tot["lo_cl"] >= 0.95 * n, "clustered rates at least 95 %")
check(tot["up_raw"] >= 0.90 * n and tot["lo_raw"] >= 0.90 * n, "raw rates at least 90 %")
if failures:
    print("%d failure(s)" % len(failures))
    sys.exit(1)
