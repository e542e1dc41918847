#!/usr/bin/python3
"""tests/py/test_mesh2fe_cgal.py: mesh2fe's CGAL path (closed triangulated surfaces).

1. examples/geometry/rod_faceted.stl (a 24-sided prism, L = 0.3 m, circumradius 15 mm; ASCII
   STL) meshed at 6 mm: every mesh vertex lies on the input surface and the part is convex, so
   the mesh volume is at most the exact prism volume, and it falls short by at most
   facet_distance (= size / 10, mesh2fe's CGAL criterion) times the surface area. Free-free:
   exactly six rigid-body modes; K symmetric. A --group box names the end face x = 0; clamping
   it leaves no rigid-body mode.
2. A cube as an OFF file with quadrilateral faces (fan-triangulated by the reader), and as a
   binary STL: its sharp edges are protected by Mesh_3, its faces are planar, so the volume is
   exact to roundoff (for the binary STL, the cube of its float32 side).
"""
import math
import os
import subprocess
import sys

import h5py
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_mesh2fe_cgal")
fails = []


def check(ok, what):
    print(("ok    " if ok else "FAIL  ") + what)
    if not ok:
        fails.append(what)


def mesh2fe(*args):
    r = subprocess.run([os.path.join(ROOT, BUILD, "bin", "mesh2fe"), *args], capture_output=True, text=True)
    if r.returncode != 0:
        print(r.stderr)
        raise SystemExit("mesh2fe %s: exit %d" % (" ".join(args), r.returncode))
    print(r.stderr.strip())


def csr(g):
    return sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))


def freqs(K, M, k):
    w = sla.eigsh(K.tocsc(), k=k, M=M.tocsc(), sigma=-(2 * math.pi * 100) ** 2, which="LM",
                  return_eigenvectors=False)
    w = np.sort(w)
    return np.sign(w) * np.sqrt(np.abs(w)) / (2 * math.pi)


def main():
    os.makedirs(TMP, exist_ok=True)
    os.chdir(TMP)
    # ---- 1. the faceted rod ----
    N, L, R, size = 24, 0.3, 0.015, 0.006
    v_exact = L * N / 2 * R**2 * math.sin(2 * math.pi / N)
    side = 2 * R * math.sin(math.pi / N)
    area = N * side * L + 2 * N / 2 * R**2 * math.sin(2 * math.pi / N)
    stl = os.path.join(ROOT, "examples", "geometry", "rod_faceted.stl")
    mesh2fe(stl, "--size", str(size), "-o", "free.fe.h5")
    f = h5py.File("free.fe.h5", "r")
    vol = f["body"].attrs["volume"]
    bound = size / 10 * area
    check(vol <= v_exact * (1 + 1e-12) and v_exact - vol <= bound,
          "faceted rod volume %.6e vs exact %.6e: short by %.2f %% (bound facet_distance x area "
          "= %.2f %%)" % (vol, v_exact, 100 * (v_exact - vol) / v_exact, 100 * bound / v_exact))
    check("tet10" in f["mesh/elements"], "CGAL tet4 mesh elevated to tet10 (default order 2)")
    K, M = csr(f["K"]), csr(f["M"])
    check(abs(K - K.T).max() / abs(K).max() < 1e-12, "K symmetric")
    fr = freqs(K, M, 8)
    nrigid = int(np.sum(np.abs(fr) < 1.0))
    check(nrigid == 6 and fr[6] > 1000,
          "free-free: %d rigid-body modes (|f| < 1 Hz), first flexible %.1f Hz" % (nrigid, fr[6]))
    # ---- box group, clamp ----
    mesh2fe(stl, "--size", str(size), "--group", "end0:-1,-1,-1,0,1,1", "--clamp", "end0", "-o", "cant.fe.h5")
    f = h5py.File("cant.fe.h5", "r")
    g = f["mesh/groups/end0"][()]
    X = f["mesh/nodes"][()]
    # the end face has 25 input vertices and, at 6 mm, more on its edges and inside
    check(len(g) >= 25 and np.all(np.abs(X[g, 0]) < 1e-12),
          "--group box end0: %d nodes, all at x = 0" % len(g))
    fr = freqs(csr(f["K"]), csr(f["M"]), 2)
    check(fr[0] > 100, "clamped at the box group: first frequency %.1f Hz (no rigid mode)" % fr[0])

    # ---- 2. a cube as OFF with quadrilateral faces ----
    a = 0.05
    with open("cube.off", "w") as o:
        o.write("OFF\n# a cube of side %g m, quadrilateral faces\n8 6 12\n" % a)
        for k in range(8):
            o.write("%g %g %g\n" % (a * (k & 1), a * ((k >> 1) & 1), a * ((k >> 2) & 1)))
        for q in ([0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]):
            o.write("4 %d %d %d %d\n" % tuple(q))
    mesh2fe("cube.off", "--size", "0.02", "--order", "1", "-o", "cube.fe.h5")
    f = h5py.File("cube.fe.h5", "r")
    vol = f["body"].attrs["volume"]
    check("tet4" in f["mesh/elements"] and abs(vol - a**3) < 1e-12 * a**3 * 100,
          "OFF cube, tet4: volume %.12e vs %.12e" % (vol, a**3))
    # ---- 3. the same cube as a binary STL (12 triangles, outward normals) ----
    import struct
    X = np.array([[a * (k & 1), a * ((k >> 1) & 1), a * ((k >> 2) & 1)] for k in range(8)])
    tris = []
    for q in ([0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]):
        tris += [(q[0], q[1], q[2]), (q[0], q[2], q[3])]
    with open("cube.stl", "wb") as o:
        o.write(b"binary STL cube".ljust(80, b" ") + struct.pack("<I", len(tris)))
        for t in tris:
            nrm = np.cross(X[t[1]] - X[t[0]], X[t[2]] - X[t[0]])
            o.write(struct.pack("<12fH", *nrm, *X[t[0]], *X[t[1]], *X[t[2]], 0))
    mesh2fe("cube.stl", "--size", "0.02", "-o", "cubestl.fe.h5")
    f = h5py.File("cubestl.fe.h5", "r")
    vol = f["body"].attrs["volume"]
    a32 = float(np.float32(a))  # the side as stored in float32
    check(abs(vol - a32**3) < 1e-10 * a32**3, "binary STL cube, tet10: volume %.12e vs %.12e" % (vol, a32**3))
    print("%d failure(s)" % len(fails))
    return 1 if fails else 0


if __name__ == "__main__":
    sys.exit(main())
