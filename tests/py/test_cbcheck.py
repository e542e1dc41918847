#!/usr/bin/python3
# tests/py/test_cbcheck.py: cbcheck's estimates, bounds, selection and reduced body
# SPDX-License-Identifier: MIT
#
# 1. docs/THEORY.md section 8's worked example (free-free beam, 200 Euler-Bernoulli elements, one
#    6-dof end interface, Nd = 20): cbcheck reproduces the table's lower, upper (kappa_(Nd+1)),
#    upper (kappa_n) and second-order values.
# 2. The papers' quadruple-pendulum body (tet10 cylinder 0.3 x 0.015 m, E 100 GPa, nu 0.285,
#    rho 7850, free-free, one RBE2 interface at one end face; coarse mesh) and the same rod
#    with two interfaces, consistent and lumped mass: for the modes whose exact error is below
#    10 %, upper >= exact and lower <= exact in at least 95 % of them (rates printed);
#    selection with E = 1e-3, NM = 10 gives exact errors of modes 1..10 all <= E.
# 3. The estimates equal a direct dense numpy/scipy evaluation of the formulas to round-off.
# Exits nonzero on failure; prints what it measured.
import csv
import os
import subprocess
import sys

import h5py
import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp
import scipy.sparse.linalg as spl

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_cbcheck")
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


def read_csv(path):
    with open(os.path.join(TMP, path)) as f:
        rows = list(csv.DictReader(f))
    num = lambda v: float(v) if v != "" else float("nan")
    return {k: np.array([num(r[k]) for r in rows]) for k in rows[0]}


def rates(t, label):
    ok = t["exact"] < 0.1
    n = int(ok.sum())
    up = int((t["upper"][ok] >= t["exact"][ok]).sum())
    un = int((t["upper_kappa_next"][ok] >= t["exact"][ok]).sum())
    lo = int((t["lower"][ok] <= t["exact"][ok]).sum())
    print("%s: %d modes with exact error < 10%%: upper >= exact %d (%.1f%%), upper(kappa_Nd+1) >= exact "
          "%d (%.1f%%), lower <= exact %d (%.1f%%)" % (label, n, up, 100 * up / n, un, 100 * un / n, lo,
                                                        100 * lo / n))
    return n, up, lo


def read_fe_km(path):
    with h5py.File(path, "r") as f:
        def csr(g):
            return sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
        return csr(f["K"]), csr(f["M"])


# --- 1. docs/THEORY.md section 8 ------------------------------------------------------------------
with open(os.path.join(TMP, "beam.geo"), "w") as f:
    f.write("Point(1) = {0, 0, 0, 0.01}; Point(2) = {0.3, 0, 0, 0.01};\nLine(1) = {1, 2};\n"
            "Transfinite Curve{1} = 201;\nPhysical Curve(\"rod\") = {1};\nPhysical Point(\"end\") = {2};\n")
run("mesh2fe", "beam.geo", "--circle", "0.015", "--E", "100e9", "--nu", "0.285", "--rho", "7850",
    "--interface", "end", "-o", "beam.fe.h5", "-q")
run("fe2cb", "beam.fe.h5", "--modes", "20", "-o", "beam.cb.h5", "-q")
run("cbcheck", "beam.cb.h5", "--exact", "--range", "16", "--csv", "beam.csv", "-q")
t = read_csv("beam.csv")
# docs/THEORY.md section 8: mode -> (f Hz, exact, lower, second, upper kappa_(Nd+1), upper kappa_n);
# the table's frequencies are the full model's (chi), cbcheck's are the reduced chibar.
table = {1: ("1059.1", "1.322e-4", "1.320e-4", "1.323e-4", "1.324e-4", "1.49e-4"),
         3: ("2919.4", "6.972e-4", "6.892e-4", "7.035e-4", "7.043e-4", "8.79e-4"),
         5: ("3710.7", "1.086e-3", "1.061e-3", "1.086e-3", "1.099e-3", "1.51e-3"),
         8: ("5948.6", "5.110e-3", "4.809e-3", "5.108e-3", "5.248e-3", "6.72e-3"),
         12: ("11132.9", "1.251e-2", "9.834e-3", "1.192e-2", "1.300e-2", "1.60e-2")}


def tol_digits(s):
    # half a unit of the last printed digit, relative: the table's own rounding
    mant = s.split("e")[0]
    dec = len(mant.split(".")[1]) if "." in mant else 0
    return 0.5 * 10 ** (-dec) / abs(float(mant)) + 1e-12


for mode, row in table.items():
    j = mode - 1
    fex = np.sqrt(t["eigenvalue"][j] / (1 + t["exact"][j])) / (2 * np.pi)
    for name, val, got in (("f", row[0], fex), ("exact", row[1], t["exact"][j]), ("lower", row[2], t["lower"][j]),
                           ("upper_next", row[4], t["upper_kappa_next"][j]), ("upper", row[5], t["upper"][j])):
        rel = abs(got / float(val) - 1)
        check(rel <= tol_digits(val), "beam mode %d %s: %.5g, docs/THEORY.md %s (rel %.1e)" % (mode, name, got, val, rel))
    # second order: docs/THEORY.md notes the pairs' values depend on the basis inside the pair
    # (modes 1, 3 are pairs); cbcheck reports the cluster maximum, so compare single modes only
    if mode in (5, 8, 12):
        rel = abs(t["second_order"][j] / float(row[3]) - 1)
        check(rel <= tol_digits(row[3]), "beam mode %d second: %.5g, docs/THEORY.md %s" % (mode, t["second_order"][j], row[3]))
n, up, lo = rates(t, "beam (docs/THEORY.md section 8)")
check(up == n and lo == n, "beam: docs/THEORY.md says lower <= exact <= upper for all 16 modes under 10 %")
print("beam: docs/THEORY.md section 8 table reproduced (%d modes checked)" % len(table))

# --- 2. quadruple-pendulum body: bounds and selection --------------------------------------
geo = os.path.join(ROOT, "examples", "geometry", "rod.geo")
bodies = [("rod1", ["--interface", "end1"], "consistent"),
          ("rod2", ["--interface", "end0", "--interface", "end1"], "consistent"),
          ("rod2l", ["--interface", "end0", "--interface", "end1"], "lumped")]
allrates = {}
for name, itf, mass in bodies:
    # coarse mesh (h = 15 mm, ~3000 dofs) to stay fast; the paper used 3528 tets
    run("mesh2fe", geo, "--size", "0.015", "--E", "100e9", "--nu", "0.285", "--rho", "7850", "--mass", mass,
        *itf, "-o", name + ".fe.h5", "-q")
    run("fe2cb", name + ".fe.h5", "--modes", "30", "-o", name + ".cb.h5", "-q")
    # bounds at Nd = 30 (fe2cb's modes) and Nd = 50 (extended from the fe file), every flexible
    # mode of the reduced body; the rates pool both (the paper's Figure 3 used Nd = 50, 100)
    run("cbcheck", name + ".cb.h5", "--exact", "--csv", name + ".csv", "-q")
    t = read_csv(name + ".csv")
    n, up, lo = rates(t, "%s (%s mass, Nd = 30)" % (name, mass))
    run("cbcheck", name + ".cb.h5", "--exact", "--nd", "50", "--csv", name + "-50.csv", "-q")
    n2, up2, lo2 = rates(read_csv(name + "-50.csv"), "%s (%s mass, Nd = 50)" % (name, mass))
    n, up, lo = n + n2, up + up2, lo + lo2
    print("%s: pooled: upper >= exact in %d of %d (%.1f%%), lower <= exact in %d of %d (%.1f%%)"
          % (name, up, n, 100 * up / n, lo, n, 100 * lo / n))
    allrates[name] = (n, up, lo)
    # the paper's requirement: at least 95 % of the modes under 10 % error bracketed
    check(n >= 10, "%s: only %d modes under 10 %% error" % (name, n))
    check(up >= 0.95 * n, "%s: upper >= exact in %d of %d modes (< 95 %%)" % (name, up, n))
    check(lo >= 0.95 * n, "%s: lower <= exact in %d of %d modes (< 95 %%)" % (name, lo, n))
    # selection: E = 1e-3 on flexible modes 1..10 from N0 = 5, with exact errors
    r = run("cbcheck", name + ".cb.h5", "--tol", "1e-3", "--range", "10", "--exact", "--csv", name + "-sel.csv",
            "-o", name + ".rflex.h5")
    ts = read_csv(name + "-sel.csv")
    with h5py.File(os.path.join(TMP, name + ".rflex.h5"), "r") as f:
        nd = int(f["modes"].attrs["n_fixed_interface_modes"])
    print("%s: selection E = 1e-3, NM = 10: Nd = %d, largest upper %.3g, largest exact %.3g" %
          (name, nd, ts["upper"].max(), ts["exact"].max()))
    check(len(ts["exact"]) == 10, "%s: %d modes reported" % (name, len(ts["exact"])))
    check(np.all(ts["upper"] <= 1e-3), "%s: selected upper estimates above E" % name)
    check(np.all(ts["exact"] <= 1e-3), "%s: exact errors after selection above E: %s" % (name, ts["exact"]))

# --- 3. estimates against a dense numpy/scipy evaluation of the formulas -----------------------
def numpy_estimates(fe, cbf):
    K, M = read_fe_km(os.path.join(TMP, fe))
    with h5py.File(os.path.join(TMP, cbf), "r") as f:
        s = f["cb/interior_dofs"][()]
        b = f["cb/boundary_dofs"][()]
        Phi = f["cb/Phi"][()]
        kap = f["cb/kappa"][()]
    Ks, Kc, Kb = K[s][:, s].tocsc(), K[s][:, b].toarray(), K[b][:, b].toarray()
    Ms, Mc, Mb = M[s][:, s].tocsc(), M[s][:, b].toarray(), M[b][:, b].toarray()
    lu = spl.splu(Ks)                      # SuperLU: independent of fe2cb's CHOLMOD
    Psi = -lu.solve(Kc)
    A = Ms @ Psi + Mc
    KsA = lu.solve(A)
    PtA = Phi.T @ A
    nd, nb = len(kap), len(b)
    # the brief's formula, and its cancellation-free form (fmbd_est.h, ROUND-OFF)
    X_plain = A.T @ KsA - PtA.T @ (PtA / kap[:, None])
    W = KsA - Phi @ (PtA / kap[:, None])
    W -= Phi @ (Phi.T @ (Ms @ W))
    Xb, Gb = W.T @ (Ks @ W), W.T @ (Ms @ W)
    Mbb = Psi.T @ (Ms @ Psi) + Psi.T @ Mc + Mc.T @ Psi + Mb
    Kbb = Kb + Kc.T @ Psi
    Mr = np.block([[np.eye(nd), PtA], [PtA.T, Mbb]])
    Kr = sl.block_diag(np.diag(kap), Kbb)
    chib, Xi = sl.eigh((Kr + Kr.T) / 2, (Mr + Mr.T) / 2)
    rigid = np.abs(chib) <= 1e-6 * kap[0]
    est = {k: [] for k in ("eig", "lower", "second", "upper", "upper_next", "plain_lower")}
    for n in np.nonzero(~rigid)[0]:
        c, bv = chib[n], Xi[nd:, n]
        x, g = bv @ Xb @ bv, bv @ Gb @ bv
        kn = kap[n] if n < nd else kap[nd - 1]
        est["eig"].append(c)
        est["lower"].append(c * x)
        est["second"].append(c * x + c * c * g)
        est["upper"].append((c + c * c / kn) * x)
        est["plain_lower"].append(c * (bv @ X_plain @ bv))
    est = {k: np.array(v) for k, v in est.items()}
    # clusters as cbcheck reports them (fmbd_est.h): relative gap <= 1e-3, or the interval
    # [chibar / (1 + upper), chibar] of a mode reaching the previous eigenvalue; members get the
    # max of upper/second and the min of lower
    e = est["eig"]
    raw_up = est["upper"].copy()
    i = 0
    while i < len(e):
        j = i
        while j + 1 < len(e) and (abs(e[j + 1] - e[j]) <= 1e-3 * abs(e[j + 1]) or
                                  abs(e[j + 1] - e[j]) <= e[j + 1] - e[j + 1] / (1 + max(raw_up[j + 1], 0))):
            j += 1
        for k, fn in (("lower", np.min), ("second", np.max), ("upper", np.max)):
            est[k][i:j + 1] = fn(est[k][i:j + 1])
        i = j + 1
    return est


est = numpy_estimates("rod1.fe.h5", "rod1.cb.h5")
t = read_csv("rod1.csv")
worst = 0.0
for k, col in (("eig", "eigenvalue"), ("lower", "lower"), ("second", "second_order"), ("upper", "upper")):
    rel = np.max(np.abs(t[col] - est[k]) / np.abs(est[k]))
    worst = max(worst, rel)
    print("rod1: %-6s cbcheck vs numpy/scipy: largest relative difference %.2e" % (k, rel))
# Round-off here: both sides solve with Ks (CHOLMOD vs SuperLU, each backward stable), so the
# residual blocks agree to ~eps * cond(Ks) ~ 1e-16 * 1e5 = 1e-11; the per-mode quadratic forms
# b' Xb b amplify that at most by 1/gap of the near-degenerate pairs of the tet mesh (~1e-4
# relative), giving ~1e-7 in the worst case (3e-9 measured): 1e-7, that bound; a wrong formula
# or index (kappa_n of the wrong mode, a missing term) moves the values by more than 1e-3.
check(worst <= 1e-7, "rod1: estimates differ from the numpy evaluation by %.2e > 1e-7" % worst)
# cbcheck without the fe file evaluates the brief's plain formula A'Ks^-1A - (Phi'A)'Lambda^-1(Phi'A)
# from the cb file alone (a warning says so). On this well-conditioned solid (cond(Ks) ~ 1e5,
# A'Ks^-1A / Xb ~ 1e3) it loses ~8 digits at most: 1e-5 relative is its expected accuracy.
# On the slender beam of part 1 (cond ~ 4e11, ratio ~ 3e5) the plain formula evaluated with
# dense LAPACK solves lost every digit of the bending modes (fmbd_est.h ROUND-OFF); with fe2cb's
# CHOLMOD solves it fares better: printed, not asserted.
for body, tol in (("rod1", 1e-5), ("beam", None)):
    run("cbcheck", body + ".cb.h5", "--plain", "--csv", body + "-plain.csv", "-q")
    tp, tq = read_csv(body + "-plain.csv"), read_csv(body + ".csv")
    n = min(len(tp["lower"]), len(tq["lower"]))
    rel = np.abs(tp["lower"][:n] / tq["lower"][:n] - 1)
    print("%s: plain formula (cb file alone) vs projected: lower estimates differ by %.1e (largest relative)"
          % (body, rel.max()))
    if tol is not None:
        check(rel.max() <= tol, "%s: plain formula differs by %.1e > %g" % (body, rel.max(), tol))

if failures:
    print("%d failure(s)" % len(failures))
    sys.exit(1)
print("test_cbcheck: all checks passed")
