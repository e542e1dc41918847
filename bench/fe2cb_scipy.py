#!/usr/bin/python3
# bench/fe2cb_scipy.py: the peer of fe2cb in bench/fe2cb.sh: what a Python user would write on
# the same matrices: eigsh shift-invert for the fixed-interface modes + constraint modes with
# splu; the partition is fe2cb's (/cb/interior_dofs, /cb/boundary_dofs of its output).
#   fe2cb_scipy.py BODY.fe.h5 BODY.cb.h5 NMODES
import sys
import time

import h5py
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

fe, cbf, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
t0 = time.time()
with h5py.File(fe, "r") as f:
    K, M = (sp.csr_matrix((f[m]["data"][()], f[m]["indices"][()], f[m]["indptr"][()]),
                          shape=tuple(int(x) for x in f[m].attrs["shape"])) for m in ("K", "M"))
with h5py.File(cbf, "r") as f:
    s, b = f["cb/interior_dofs"][()], f["cb/boundary_dofs"][()]
    kappa = f["cb/kappa"][()]
t1 = time.time()
Ks, Ms = K[s][:, s].tocsc(), M[s][:, s].tocsc()
Kc = K[s][:, b].toarray()
t2 = time.time()
w, V = sla.eigsh(Ks, M=Ms, k=n, sigma=0.0, which="LM")
t3 = time.time()
lu = sla.splu(Ks)
Psi = -lu.solve(Kc)
t4 = time.time()
w = np.sort(w)
print("scipy: read %.2f s, partition %.2f s, eigsh %.2f s, constraint modes (splu) %.2f s; "
      "max rel diff to fe2cb's kappa %.1e" % (t1 - t0, t2 - t1, t3 - t2, t4 - t3,
                                              np.max(np.abs(w - kappa[:n]) / kappa[:n])))
print("scipy_compute_s %.3f" % (t4 - t1))
