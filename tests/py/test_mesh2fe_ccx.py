#!/usr/bin/python3
"""tests/py/test_mesh2fe_ccx.py: mesh2fe's tet10 matrices against CalculiX on the same mesh.

The rod of examples/geometry/rod.geo (h = 7.5 mm, 2.7 k tet10), clamped at end0, through
mesh2fe; the same nodes and elements written as a CalculiX C3D10 deck (gmsh local nodes 8 and 9
swapped, coordinates %.12e: docs/TOOLCHAIN.md gotchas 8-10), `ccx *FREQUENCY` in a scratch folder.
The first ten frequencies of mesh2fe's K, M (scipy eigsh, shift-invert) must agree with ccx's.

Tolerance: the stiffness is the same element (isoparametric C3D10, 4-point rule) so it agrees to
roundoff; the mass differs: mesh2fe integrates N_a N_b with a 14-point degree-5 rule (exact on
straight elements), CalculiX with its own rule. Measured at this mesh: 1.2e-4 for the torsion
mode (mode 5, whose kinetic energy sits at the outer radius, in the curved boundary elements),
<= 1.5e-5 for the bending and axial modes. Tolerance 5e-4: above the mass-rule
difference, two orders below the discretisation error (docs/TOOLCHAIN.md: mode 1 moves 3e-4
between h = 5 and 2.5 mm), so a wrong element (e.g. a mis-ordered mid-side node) fails.
"""
import math
import os
import shutil
import subprocess
import sys

import h5py
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_mesh2fe_ccx")
NMODES = 10
TOL = 5e-4


def csr(g):
    return sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]),
                         shape=tuple(g.attrs["shape"]))


def write_deck(f, path, clamp):
    X = f["mesh/nodes"][()]
    T = f["mesh/elements/tet10"][()]
    mat = f["material"].attrs
    with open(path, "w") as o:
        o.write("*NODE, NSET=NALL\n")
        for i in np.unique(T):  # mesh nodes only (interface nodes are not in elements)
            o.write("%d, %.12e, %.12e, %.12e\n" % (i + 1, X[i, 0], X[i, 1], X[i, 2]))
        o.write("*ELEMENT, TYPE=C3D10, ELSET=EALL\n")
        for e, t in enumerate(T):
            t = t[[0, 1, 2, 3, 4, 5, 6, 7, 9, 8]] + 1  # gmsh -> C3D10: swap nodes 8 and 9
            o.write("%d, %s\n" % (e + 1, ", ".join(str(int(n)) for n in t)))
        o.write("*NSET, NSET=FIX\n")
        o.write("".join("%d,\n" % (i + 1) for i in f["mesh/groups/" + clamp][()]))
        o.write("*BOUNDARY\nFIX, 1, 3\n")
        o.write("*MATERIAL, NAME=MAT\n*ELASTIC\n%.12e, %.12e\n*DENSITY\n%.12e\n"
                % (mat["E"], mat["nu"], mat["rho"]))
        o.write("*SOLID SECTION, ELSET=EALL, MATERIAL=MAT\n*STEP\n*FREQUENCY\n%d\n*END STEP\n"
                % NMODES)


def ccx_frequencies(workdir):
    r = subprocess.run(["ccx", "-i", "rod"], cwd=workdir, capture_output=True, text=True)
    if r.returncode != 0 or "*ERROR" in r.stdout:
        print(r.stdout[-3000:])
        raise SystemExit("ccx failed (exit %d)" % r.returncode)
    text = open(os.path.join(workdir, "rod.dat")).read()
    i = text.index("E I G E N V A L U E   O U T P U T")
    freqs = []
    for line in text[i:].splitlines()[1:]:
        p = line.split()
        if len(p) == 5 and p[0].isdigit():
            freqs.append(float(p[3]))  # mode, eigenvalue, omega, f (cycles/s), imag
            if len(freqs) == NMODES:
                break
    return np.array(freqs)


def main():
    if shutil.which("ccx") is None:
        print("ccx not found (calculix-ccx is installed by scripts/install-deps.sh)")
        return 1
    shutil.rmtree(TMP, ignore_errors=True)
    os.makedirs(TMP)
    exe = os.path.join(ROOT, BUILD, "bin", "mesh2fe")
    fe = os.path.join(TMP, "rod.fe.h5")
    r = subprocess.run([exe, os.path.join(ROOT, "examples", "geometry", "rod.geo"), "--size", "0.0075",
                        "--clamp", "end0", "-o", fe], capture_output=True, text=True)
    if r.returncode != 0:
        print(r.stderr)
        return 1
    f = h5py.File(fe, "r")
    K, M = csr(f["K"]), csr(f["M"])
    w = sla.eigsh(K.tocsc(), k=NMODES, M=M.tocsc(), sigma=-(2 * math.pi * 100) ** 2,
                  which="LM", return_eigenvectors=False)
    ours = np.sqrt(np.sort(w)) / (2 * math.pi)
    write_deck(f, os.path.join(TMP, "rod.inp"), "end0")
    theirs = ccx_frequencies(TMP)
    print("%d nodes, %d tet10, %d dofs" % (f["mesh/nodes"].shape[0], f["mesh/elements/tet10"].shape[0],
                                          K.shape[0]))
    print("mode   mesh2fe (Hz)   ccx (Hz)      rel. diff")
    worst = 0.0
    for k in range(NMODES):
        d = (ours[k] - theirs[k]) / theirs[k]
        worst = max(worst, abs(d))
        print("%4d  %12.4f  %12.4f  %+10.2e" % (k + 1, ours[k], theirs[k], d))
    ok = len(theirs) == NMODES and worst < TOL
    print("%s: largest relative difference %.2e (tolerance %.0e)" % ("ok" if ok else "FAIL", worst, TOL))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
