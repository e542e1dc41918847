#!/usr/bin/python3
# bench/eig_shift_model.py: a count model (numpy/scipy, not fe2cb's code) of issue 12's lever
# "the Sturm factorisation used twice" (bench/README.md "The Lanczos stage at 20 modes: the Sturm
# shift's factor as a second operator"): block Lanczos at sigma 0 as fmbd_eig.c's block_run
# runs it at 20 modes (blocks of 4, 20 wanted pairs to 1e-12 and 3 margin pairs to 1e-8; here
# with full reorthogonalisation and no restarts), against the same run switched after K1
# blocks to shift-invert at the Sturm shift s (midway between the 20th and 21st Ritz values)
# with splu's factor of Ks - s Ms, the converged pairs kept. Variants of the second phase:
#   A   block Krylov of (Ks - s Ms)^-1 Ms from the 4 unconverged Ritz vectors nearest s,
#       M-orthogonal to the converged ones;
#   B1  the unconverged Ritz vectors kept, each block (Ks - s Ms)^-1 Ms applied to the 4 with
#       the largest residual, Rayleigh-Ritz of (Ks, Ms) on the whole space;
#   B2  as B1 with the whole first-phase basis kept (the most the switch can keep).
# One criterion for every pair, whatever the space: the sigma-0 operator residual
# ||OP0 y - y / lam||_M lam, OP0 = Ks^-1 Ms, y M-normalised (block_run's ||B s|| <= tol theta).
# An x-space Rayleigh-Ritz of (Ks, Ms) reaches only about 1e-11..1e-10 in it (round-off:
# Ks^-1 of a residual of eps ||Ks||): read the second phase at that level ("level": every wanted
# pair at or below 5e-10, every margin pair below 5e-8), where it stops (below it the model's
# Gram-Schmidt of the growing x-space basis loses orthogonality and its Ritz values go astray).
#   eig_shift_model.py BODY.fe.h5 BODY.cb.h5 [MAXBLOCKS [K1,K1,... [VARIANTS]]]
# (BODY.cb.h5: fe2cb's output at 20 modes, for the partition and the reference eigenvalues)
import sys
import time

import h5py
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

fe, cbf = sys.argv[1], sys.argv[2]
NEV, NREQ, P = 20, 23, 4
with h5py.File(fe, "r") as f:
    K, M = (sp.csr_matrix((f[m]["data"][()], f[m]["indices"][()], f[m]["indptr"][()]),
                          shape=tuple(int(x) for x in f[m].attrs["shape"])) for m in ("K", "M"))
with h5py.File(cbf, "r") as f:
    s_i = f["cb/interior_dofs"][()]
    kap = f["cb/kappa"][()]
    kn = f["cb"].attrs["kappa_next"]
Ks, Ms = K[s_i][:, s_i].tocsc(), M[s_i][:, s_i].tocsc()
n = Ks.shape[0]
t0 = time.time()
lu0 = sla.splu(Ks, permc_spec="MMD_AT_PLUS_A")
print("splu %.1f s" % (time.time() - t0), flush=True)
OP0 = lambda X: lu0.solve(np.asarray(Ms @ X))


def mnorm(X):
    return np.sqrt(np.sum(X * (Ms @ X), axis=0))


def morth(U, MU, Z, passes=2):
    # Z M-orthogonal to U (MU = M U), then M-orthonormal within (Cholesky QR, twice)
    for _ in range(passes):
        if U is not None and U.shape[1]:
            Z = Z - U @ (MU.T @ Z)
    for _ in range(2):
        G = Z.T @ (Ms @ Z)
        R = np.linalg.cholesky(G).T
        Z = np.linalg.solve(R.T, Z.T).T
    return Z


def true_res(Y, lam):
    # ||OP0 y - y/lam||_M lam with y M-normalised
    Y = Y / mnorm(Y)
    R = OP0(Y) - Y / lam
    return mnorm(R) * lam


def ritz_pencil(U):
    # Rayleigh-Ritz of (Ks, Ms) on span U (U M-orthonormal): ascending lam, vectors
    A = U.T @ (Ks @ U)
    A = 0.5 * (A + A.T)
    w, S = np.linalg.eigh(A)
    return w, U @ S


def conv_count(w, Y):
    k = min(NREQ, len(w))
    r = np.full(NREQ, np.inf)
    r[:k] = true_res(Y[:, :k], w[:k])
    ok = [r[j] <= (1e-12 if j < NEV else 1e-8) for j in range(NREQ)]
    return r, ok


def at_level(r):
    return all(r[j] <= (5e-10 if j < NEV else 5e-8) for j in range(NREQ))


rng = np.random.default_rng(1)
Q = morth(None, None, rng.standard_normal((n, P)))
V = Q.copy()
MV = Ms @ V
WW = np.zeros((n, 0))
blocks = 0
hist = []
maxb = int(sys.argv[3]) if len(sys.argv) > 3 else 26
snap = {}
while blocks < maxb:
    W = OP0(Q)
    WW = np.hstack([WW, W])
    blocks += 1
    Q = morth(V, MV, W)
    V = np.hstack([V, Q])
    MV = np.hstack([MV, Ms @ Q])
    if V.shape[1] < NREQ + 4:
        continue
    # operator Rayleigh-Ritz on the basis before the new block: T = V' M OP0 V (the Lanczos
    # Ritz pairs of block_run), lam = 1/theta
    Vm = V[:, :-P]
    T = MV[:, :-P].T @ WW
    th, S = np.linalg.eigh(0.5 * (T + T.T))
    o = np.argsort(-th)
    w, Y = 1.0 / th[o], Vm @ S[:, o]
    r, ok = conv_count(w, Y)
    nconv = sum(ok)
    first_bad = ok.index(False) if False in ok else NREQ
    hist.append((blocks, nconv, first_bad))
    print("sigma0 block %d (%d solves): %d of %d converged, first unconverged %d; "
          "lam20 %.6e rel err %.1e, lam21 %.6e rel err %.1e; res %s" %
          (blocks, 4 * blocks, nconv, NREQ, first_bad + 1, w[19], w[19] / kap[19] - 1, w[20],
           w[20] / kn - 1, " ".join("%.0e" % x for x in r)), flush=True)
    if at_level(r) and "level" not in snap:
        snap["level"] = blocks
        print("sigma0: level reached at block %d" % blocks, flush=True)
    snap[blocks] = (V.copy(), w.copy(), Y.copy(), r.copy(), ok[:])
    if nconv == NREQ:
        break
base = blocks
print("BASE: %d blocks (%d solves)" % (base, 4 * base), flush=True)

# --- phase 2 from snapshot k1 ---
for k1 in [int(x) for x in sys.argv[4].split(",")] if len(sys.argv) > 4 else []:
    if k1 not in snap:
        continue
    V1, w, Y, r, ok = snap[k1]
    # s: the current Sturm rule on the Ritz values (midway between the 20th and 21st)
    s = 0.5 * (w[19] + w[20])
    t0 = time.time()
    lus = sla.splu((Ks - s * Ms).tocsc(), permc_spec="MMD_AT_PLUS_A")
    OPs = lambda X: lus.solve(np.asarray(Ms @ X))
    print("k1 %d: s %.6e (true between %.6e and %.6e), splu %.1f s" % (k1, s, kap[19], kn,
                                                                         time.time() - t0))
    locked = [j for j in range(NREQ) if ok[j]]
    unc = [j for j in range(NREQ) if not ok[j]]
    L = Y[:, locked]
    for variant in (sys.argv[5].split(",") if len(sys.argv) > 5 else ("A", "B1", "B2")):
        # A: block Krylov of OPs from the 4 unconverged Ritz vectors nearest s, deflated against
        #    the locked; B1: the unconverged Ritz vectors kept in the subspace, blocks of OPs
        #    applied to the 4 worst-residual unconverged Ritz vectors; B2: the whole phase-1
        #    basis kept, same blocks
        if variant == "A":
            near = sorted(unc, key=lambda j: abs(w[j] - s))[:P]
            U = L.copy()
            Q = morth(U, Ms @ U, Y[:, near])
            U = np.hstack([U, Q])
        elif variant == "B1":
            U = np.hstack([L, Y[:, unc]])
            U = morth(None, None, U)
            Q = None
        else:
            U = V1.copy()
            Q = None
        MU = Ms @ U
        b2 = 0
        cur_unc = unc
        while b2 < 20:
            if variant == "A":
                Z = OPs(Q)
            else:
                # the 4 unconverged with the largest residual
                wr, Yr = ritz_pencil(U)
                rr, okr = conv_count(wr, Yr)
                un = [j for j in range(NREQ) if not okr[j]]
                pick = sorted(un, key=lambda j: -rr[j])[:P]
                Z = OPs(Yr[:, pick])
            b2 += 1
            Q = morth(U, MU, Z)
            U = np.hstack([U, Q])
            MU = np.hstack([MU, Ms @ Q])
            wr, Yr = ritz_pencil(U)
            rr, okr = conv_count(wr, Yr)
            nc = sum(okr)
            print("  %s: phase-2 block %d: %d of %d converged; res %s" %
                  (variant, b2, nc, NREQ, " ".join("%.0e" % x for x in rr)), flush=True)
            if nc == NREQ or at_level(rr):
                break
        print("  %s: k1 %d + %d blocks at s = %d (base %d); lam rel to cb: %.1e" %
              (variant, k1, b2, k1 + b2, base, np.max(np.abs(wr[:NEV] / kap[:NEV] - 1))),
              flush=True)
