#!/usr/bin/python3
# tests/py/test_gms.py: fmbd-run with GMs bases (one set of global-mode coordinates shared by
# all flexible bodies, scene key basis_kind: gms; Cammarata 2021, docs/THEORY.md section 6):
# 1. ONE flexible body (a beam clamped by the scene, held.cb.h5: its 20 exact held normal
#    modes): its 20 global modes are its held normal modes, so GMs, GMc and the body's own
#    modes span one space and the tip moves the same in the three runs; with 4 global modes
#    GMs = GMc (for one body they are the same span, GMc merely orthonormalised);
# 2. TWO flexible bodies (a double pendulum of tet10 rods, full FE bodies): GMs runs with 1, 3,
#    6, 12 global modes converge to the run of the full FE model (FM), and the run has
#    7 per body + K coordinates (the K shared once); a chain of four modal (CB) beams converges
#    to the run with their own modes;
# 3. bad input: GMs bodies asking for different numbers of modes, more modes than the file has,
#    an unknown basis_kind: refused naming the scene line, nothing written;
# 4. fmbd-run -M and gmsolve: a scene whose bodies name `basis: X.gm.h5` with make: gm_scene
#    gets gmsolve's rule for X.gm.h5 and the reference scene's own rules (its FE body's mesh2fe
#    rule, once); make -n orders them, a real make builds the run, a touched reference scene
#    remakes the basis only;
# 5. the spatial slider-crank on a coarse mesh: the global frequencies = scipy's solution of the
#    same constrained problem; GMs = GMc on the mid-span node (one flexible body); the rod held
#    to ground by the mechanism's spherical and universal joints (NM S-U, the paper's NM): f = 0,
#    its frequencies = scipy's, interlacing the mechanism's, and its modes run as a GMc basis;
# 6. gmsolve --xdmf read back by meshio (python3-meshio): nodes, cells and one mode's
#    displacement against /gms/<body>/shapes in the h5.
import os
import re
import shutil
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fegen  # noqa: E402
from harness import ROOT, check, finish, runner, tmpdir  # noqa: E402
import subprocess  # noqa: E402

TMP = tmpdir("test_gms")
run = runner(TMP)


def write(name, text):
    with open(os.path.join(TMP, name), "w") as f:
        f.write(text)
    return name


def point(name, out):
    with h5py.File(os.path.join(TMP, name), "r") as f:
        return f["outputs/%s/position" % out][()]


# --- 1. one clamped body -----------------------------------------------------------------------
fegen.write(os.path.join(TMP, "held.fe.h5"), fegen.beam(n_el=8, length=0.4, radius=0.01, interfaces={"end0": [0]}))
run("fe2cb", "held.fe.h5", "--method", "nm", "--hold", "--modes", "20", "-o", "held.cb.h5", "-q")
CLAMP = """title: clamped beam, tip load
solver: {t_end: 0.01, step: 5e-5}
bodies:
  - {name: beam, type: flexible, file: held.cb.h5, damping_ratio: 0.05BASIS}
joints:
  - {name: clamp, type: fixed, body1: ground, body2: beam, at2: {interface: end0}}
loads:
  - {name: tip, type: force, body: beam, node: 8, direction: [0, -1, 0], function: {type: ramp, t1: 0.005, v1: 50}}
outputs:
  every: 0.001
  points:
    - {name: tip, body: beam, node: 8, quantities: [position]}
"""
write("clamp.yaml", CLAMP.replace("BASIS", ""))
run("gmsolve", "clamp.yaml", "--modes", "20", "-o", "clamp.gm.h5", "-q")
run("fmbd-run", "clamp.yaml", "-o", "own.run.h5", "-q")
for kind in ("gms", "gmc"):
    for k in (4, 20):
        write("clamp_%s%d.yaml" % (kind, k),
              CLAMP.replace("BASIS", ", basis: clamp.gm.h5, basis_kind: %s, modes: %d" % (kind, k)))
        run("fmbd-run", "clamp_%s%d.yaml" % (kind, k), "-o", "%s%d.run.h5" % (kind, k), "-q")
own = point("own.run.h5", "tip")
d = np.max(np.abs(own[:, 1] - own[0, 1]))
e_s = np.max(np.abs(point("gms20.run.h5", "tip") - own))
e_c = np.max(np.abs(point("gmc20.run.h5", "tip") - own))
# the same equations in three bases of one space: the Newton tolerance (1e-8 relative) of the
# deflection and the round-off of the basis change: 1e-6 of the deflection
check(d > 0 and e_s < 1e-6 * d and e_c < 1e-6 * d,
      f"one body, 20 global modes: GMs and GMc tip motion = own modes' ({e_s:.1e}, {e_c:.1e} m of {d:.2e} m)")
e4 = np.max(np.abs(point("gms4.run.h5", "tip") - point("gmc4.run.h5", "tip")))
d4 = np.max(np.abs(point("gms4.run.h5", "tip") - own))
check(e4 < 1e-6 * d and d4 > 10 * e4,
      f"one body, 4 global modes: GMs = GMc ({e4:.1e} m), both {d4:.1e} m from the 20-mode motion")
with h5py.File(os.path.join(TMP, "clamp.gm.h5"), "r") as f:
    Q, M = f["gms/beam/modal"][()], f["gms/beam/Mff"][()]
# a clamped body's global modes are its own: the body's rows of them are M-orthonormal in its
# modal mass (x'Mx = 1 with the frame fixed), so /gms/beam/Mff is the identity to round-off
check(np.allclose(M, np.eye(M.shape[0]), atol=1e-10), "one clamped body: /gms/beam/Mff = I (its own modes)")

# the clamped body's modes are exact eigenvectors: its global modes' rows are unit vectors and
# the three runs agree to the last bit. A full FE rod on a pin (a pendulum) is not so special:
# its GMs columns are the FE rows of its pinned modes, its GMc columns those orthonormalised in
# the FE mass, one span in two sets of coordinates
run("mesh2fe", os.path.join(ROOT, "examples", "geometry", "rod.geo"), "--size", "0.02", "--E", "100e9", "--nu",
    "0.285", "--rho", "7850", "--interface", "end0", "--interface", "end1", "-o", "rodfe.fe.h5", "-q")
PEND = """title: solid rod pendulum
gravity: [0, -9.81, 0]
solver: {t_end: 0.05, step: 2e-4}
bodies:
  - {name: rod, type: flexible, file: rodfe.fe.h5BASIS}
joints:
  - {name: pin, type: revolute, body1: ground, body2: rod, axis: z, at2: {interface: end0}}
outputs:
  every: 0.005
  points:
    - {name: tip, body: rod, interface: end1, quantities: [position]}
"""
write("pend.yaml", PEND.replace("BASIS", ""))
run("gmsolve", "pend.yaml", "--modes", "3", "-o", "pend.gm.h5", "-q")
for kind in ("gms", "gmc"):
    write("pend_%s.yaml" % kind, PEND.replace("BASIS", ", basis: pend.gm.h5, basis_kind: " + kind))
    run("fmbd-run", "pend_%s.yaml" % kind, "-o", "pend_%s.run.h5" % kind, "-q")
a, b = point("pend_gms.run.h5", "tip"), point("pend_gmc.run.h5", "tip")
d = np.max(np.abs(a - a[0]))
e = np.max(np.abs(a - b))
with h5py.File(os.path.join(TMP, "pend.gm.h5"), "r") as f:
    off = np.max(np.abs(f["gms/rod/Mff"][()] - np.eye(3)))
# one span, two coordinate sets: the Newton tolerance (1e-8 relative) of the motion and the
# round-off of the basis change: 1e-6 of the motion; the GMs columns are not orthonormal in the
# body's own mass (off-diagonal Mff: the frame moves in the global modes too)
check(d > 0 and e < 1e-6 * d and off > 1e-6,
      f"one FE rod on a pin, 3 global modes: GMs tip = GMc tip ({e:.1e} m of {d:.2e} m; GMs Mff - I {off:.1e})")

# --- 2. two flexible bodies: GMs converges to the full model ---------------------------------
TWO = """title: double pendulum of solid rods
gravity: [0, -9.81, 0]
solver: {t_end: 0.05, step: 2e-4}
bodies:
  - {name: l1, type: flexible, file: rodfe.fe.h5B1}
  - {name: l2, type: flexible, file: rodfe.fe.h5, position: [0.3, 0, 0]B2}
joints:
  - {name: pin, type: revolute, body1: ground, body2: l1, axis: z, at2: {interface: end0}}
  - {name: knee, type: revolute, body1: l1, body2: l2, axis: z, at1: {interface: end1}, at2: {interface: end0}}
outputs:
  every: 0.005
  points:
    - {name: tip, body: l2, interface: end1, quantities: [position]}
"""


def two(name, b1="", b2=""):
    return write(name, TWO.replace("B1", b1).replace("B2", b2))


two("fm.yaml")
run("gmsolve", "fm.yaml", "--modes", "12", "-o", "fm.gm.h5", "-q")
run("fmbd-run", "fm.yaml", "-o", "fm.run.h5", "-q")
ref = point("fm.run.h5", "tip")
errs, ncoord = [], []
for k in (1, 3, 6, 12):
    g = ", basis: fm.gm.h5, basis_kind: gms, modes: %d" % k
    two("gms%d.yaml" % k, g, g)
    run("fmbd-run", "gms%d.yaml" % k, "-o", "two%d.run.h5" % k, "-q")
    errs.append(np.max(np.linalg.norm(point("two%d.run.h5" % k, "tip") - ref, axis=1)))
    with h5py.File(os.path.join(TMP, "two%d.run.h5" % k), "r") as f:
        ncoord.append(int(f["stats"].attrs["coordinates"]))
# measured 5.3e-7, 1.4e-7, 3.2e-8, 3.3e-9 m (the tip moves 1.1e-2 m in 0.05 s): each step of
# modes at least a factor 2 (the truncation error of the global basis), and with 12 modes
# below 1e-8 m (1e-6 of the motion, as the GMc runs of test_gmsolve)
check(errs[0] > 2 * errs[1] > 4 * errs[2] > 8 * errs[3] and errs[3] < 1e-8,
      "two FE rods: GMs with 1, 3, 6, 12 global modes against the full model: tip error "
      + ", ".join("%.1e" % e for e in errs) + " m")
check(ncoord == [14 + k for k in (1, 3, 6, 12)],
      f"two FE rods: a GMs run has 7 per body + K coordinates ({ncoord})")

# modal bodies too: a chain of four CB beams (fe2cb, 6 fixed-interface modes each) under
# gravity, GMs with 4, 12, 20 global modes against the run with the beams' own modes
fegen.write(os.path.join(TMP, "coupler.fe.h5"),
            fegen.beam(n_el=8, length=0.4, radius=0.01, interfaces={"end0": [0], "end1": [8]}))
run("fe2cb", "coupler.fe.h5", "--modes", "6", "-o", "coupler.cb.h5", "-q")
CH = ["title: chain of four CB beams", "gravity: [0, -9.81, 0]", "solver: {t_end: 0.1, step: 2e-4}", "bodies:"]
for i in range(4):
    CH.append("  - {name: b%d, type: flexible, file: coupler.cb.h5, position: [%g, 0, 0]X}" % (i, 0.4 * i))
CH.append("joints:")
CH.append("  - {name: j0, type: revolute, body1: ground, body2: b0, point: [0, 0, 0], axis: z, at2: {interface: end0}}")
for i in range(1, 4):
    CH.append("  - {name: j%d, type: revolute, body1: b%d, body2: b%d, point: [%g, 0, 0], axis: z, "
              "at1: {interface: end1}, at2: {interface: end0}}" % (i, i - 1, i, 0.4 * i))
CH += ["outputs:", "  every: 0.01", "  points:", "    - {name: tip, body: b3, node: 8, quantities: [position]}"]
CH = "\n".join(CH) + "\n"
write("chain.yaml", CH.replace("X}", "}"))
run("gmsolve", "chain.yaml", "--modes", "20", "-o", "chain.gm.h5", "-q")
run("fmbd-run", "chain.yaml", "-o", "chain.run.h5", "-q")
own = point("chain.run.h5", "tip")
errs = []
for k in (4, 12, 20):
    write("chain%d.yaml" % k, CH.replace("X}", ", basis: chain.gm.h5, basis_kind: gms, modes: %d}" % k))
    run("fmbd-run", "chain%d.yaml" % k, "-o", "chain%d.run.h5" % k, "-q")
    errs.append(np.max(np.abs(point("chain%d.run.h5" % k, "tip") - own)))
d = np.max(np.abs(own - own[0]))
# measured 1.9e-6, 4.5e-7, 1.0e-8 m (the tip falls 4.9e-2 m): each step a factor 2 at least, and
# 20 global modes within 1e-7 m (2e-6 of the motion)
check(errs[0] > 2 * errs[1] > 4 * errs[2] and errs[2] < 1e-7,
      "four CB beams: GMs with 4, 12, 20 global modes against their own modes: tip error "
      + ", ".join("%.1e" % e for e in errs) + " m (motion %.1e m)" % d)

# --- 3. bad input ----------------------------------------------------------------------------
def refused(name, line, what):
    p = subprocess.run(["fmbd-run", name, "-o", "bad.run.h5"], cwd=TMP, capture_output=True, text=True)
    check(p.returncode == 1 and ("%s:%d:" % (name, line)) in p.stderr and what in p.stderr
          and not os.path.exists(os.path.join(TMP, "bad.run.h5")),
          f"{name}: refused at line {line} ({p.stderr.strip().splitlines()[-1] if p.stderr.strip() else ''})")


two("bad_n.yaml", ", basis: fm.gm.h5, basis_kind: gms, modes: 3", ", basis: fm.gm.h5, basis_kind: gms, modes: 4")
refused("bad_n.yaml", 6, "one number")
two("bad_k.yaml", ", basis: fm.gm.h5, basis_kind: gms, modes: 13", ", basis: fm.gm.h5, basis_kind: gms, modes: 13")
refused("bad_k.yaml", 5, "asks for 13 global modes")
two("bad_kind.yaml", ", basis: fm.gm.h5, basis_kind: gmx")
refused("bad_kind.yaml", 5, "gmc or gms")
# --- 4. fmbd-run -M makes the basis: gmsolve's rule from make: gm_scene, and that scene's rules --
shutil.copy(os.path.join(ROOT, "examples", "geometry", "rod.geo"), os.path.join(TMP, "rod.geo"))
REF = """title: double pendulum of solid rods, full FE bodies
gravity: [0, -9.81, 0]
solver: {t_end: 0.01, step: 2e-4}
bodies:
  - name: l1
    type: flexible
    file: rod.fe.h5
    make: {geometry: rod.geo, mesh2fe: --size 0.03 --interface end0 --interface end1}
  - {name: l2, type: flexible, file: rod.fe.h5, position: [0.3, 0, 0]}
joints:
  - {name: pin, type: revolute, body1: ground, body2: l1, axis: z, at2: {interface: end0}}
  - {name: knee, type: revolute, body1: l1, body2: l2, axis: z, at1: {interface: end1}, at2: {interface: end0}}
outputs:
  every: 0.005
  points:
    - {name: tip, body: l2, interface: end1, quantities: [position]}
"""
write("ref.yaml", REF)
write("gmsmk.yaml", REF.replace(
    "make: {geometry: rod.geo, mesh2fe: --size 0.03 --interface end0 --interface end1}",
    "basis: ref.gm.h5\n    basis_kind: gms\n    make: {geometry: rod.geo, mesh2fe: --size 0.03 --interface end0 "
    "--interface end1, gm_scene: ref.yaml, gmsolve: --modes 4}").replace(
    "position: [0.3, 0, 0]}", "position: [0.3, 0, 0], basis: ref.gm.h5, basis_kind: gms}"))
os.makedirs(os.path.join(TMP, "mk"), exist_ok=True)
rules = run("fmbd-run", "-M", "gmsmk.yaml", "--body-dir", "mk", "-o", "mk/gms.run.h5").stdout
write("gms.d", rules)
write("Makefile", "mk/gms.run.h5:\n\tfmbd-run gmsmk.yaml --body-dir mk -o $@ -q\ninclude gms.d\n")
check("mk/ref.gm.h5: ref.yaml" in rules and "\tgmsolve ref.yaml --body-dir mk --modes 4 -o $@" in rules
      and rules.count("mk/rod.fe.h5: rod.geo") == 1,
      "fmbd-run -M: gmsolve's rule for the basis from gm_scene, the FE body's rule once")
dry = subprocess.run(["make", "-n", "mk/gms.run.h5"], cwd=TMP, capture_output=True, text=True).stdout
order = [dry.find(w) for w in ("mesh2fe rod.geo", "gmsolve ref.yaml", "fmbd-run gmsmk.yaml")]
check(min(order) >= 0 and order == sorted(order), "make -n: mesh2fe, gmsolve, fmbd-run in that order")
mk = subprocess.run(["make", "mk/gms.run.h5"], cwd=TMP, capture_output=True, text=True)
check(mk.returncode == 0 and os.path.exists(os.path.join(TMP, "mk", "gms.run.h5")),
      "a real make builds the FE body, its GMs basis and the run")
with h5py.File(os.path.join(TMP, "mk", "ref.gm.h5"), "r") as f:
    check(int(f["gms"].attrs["modes"]) == 4, "the basis made with the scene's gmsolve options (4 modes)")
os.utime(os.path.join(TMP, "ref.yaml"))
dry = subprocess.run(["make", "-n", "mk/gms.run.h5"], cwd=TMP, capture_output=True, text=True).stdout
check("gmsolve ref.yaml" in dry and "mesh2fe" not in dry, "ref.yaml touched: make remakes the basis, not the body")
# without make: gm_scene, the existing basis file says how it was made (its recorded scene and
# the options that fix its content)
write("gmsrec.yaml", open(os.path.join(TMP, "gmsmk.yaml")).read().replace(", gm_scene: ref.yaml, gmsolve: --modes 4", ""))
rec = run("fmbd-run", "-M", "gmsrec.yaml", "--body-dir", "mk", "-o", "mk/rec.run.h5").stdout
check("mk/ref.gm.h5: ref.yaml" in rec and "\tgmsolve ref.yaml --body-dir mk --modes 4 --rank-tol 0.001 -o $@" in rec,
      "fmbd-run -M without gm_scene: gmsolve's rule from the scene and options the basis file records")
write("badmk.yaml", REF.replace("mesh2fe: --size 0.03 --interface end0 --interface end1",
                                "gm_scene: ref.yaml"))
p = subprocess.run(["fmbd-run", "-M", "badmk.yaml"], cwd=TMP, capture_output=True, text=True)
check(p.returncode == 1 and "badmk.yaml:8:" in p.stderr and "needs 'basis'" in p.stderr,
      "make: gm_scene without basis: refused naming the line")
# --- 5. the spatial slider-crank (one flexible rod; examples/spatial-slidercrank) ------------------
# coarse mesh (12 mm), 0.02 s. Its global flexible modes are the rod's normal modes as the
# mechanism holds it (its joints, the rigid crank's and slider's inertia; the driver left out):
# their frequencies against scipy's dense solution of the same constrained problem (null space
# of Cq, /linear of gmsolve --matrices), and GMs = GMc (one body: one span) on the mid-span node
sys.path.insert(0, os.path.join(ROOT, "examples", "spatial-slidercrank"))
import gmtable  # noqa: E402

ssc = open(gmtable.SCENE).read()
m2f = re.sub(r"--size +\S+", "--size 0.012", re.search(r"mesh2fe: *(.*)", ssc).group(1)).split()
run("mesh2fe", os.path.join(ROOT, "examples", "spatial-slidercrank", "rod.geo"), *m2f, "-o", "sscrod.fe.h5", "-q")
write("ssc_fm.yaml", gmtable.scene_variant(ssc, "file: sscrod.fe.h5", 0.02))
run("gmsolve", "ssc_fm.yaml", "--modes", "4", "--matrices", "-o", "ssc.gm.h5", "-q")
# the dense check on the rod's CB body (fe2cb, 6 fixed-interface modes: 18 coordinates; the FE
# rod's 3000 make scipy's dense SVD take minutes)
run("fe2cb", "sscrod.fe.h5", "--modes", "6", "-o", "sscrod.cb.h5", "-q")
write("ssc_cb.yaml", gmtable.scene_variant(ssc, "file: sscrod.cb.h5", 0.02))
run("gmsolve", "ssc_cb.yaml", "--modes", "4", "--matrices", "-o", "sscb.gm.h5", "-q")


def dense(gmfile):
    """gmsolve's eigenvalues against scipy's dense solution of the same constrained problem."""
    import scipy.linalg as sl
    import scipy.sparse as sp

    with h5py.File(os.path.join(TMP, gmfile), "r") as f:
        def csr(g):
            return sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
        M, K, C = (csr(f["linear/" + k]).toarray() for k in ("M", "K", "Cq"))
        got, fz = f["global/eigenvalue"][()], int(f["global"].attrs["f"])
    N = sl.null_space(C)
    wall = sl.eigh(N.T @ K @ N, N.T @ M @ N, eigvals_only=True)
    w = wall[fz:fz + len(got)]
    # both dense symmetric-definite solutions of one problem (gmsolve: coordinate partitioning,
    # scipy: SVD null space): an eigenvalue's backward error is eps times the largest of the
    # reduced pencil, relative to itself eps * wmax / w; 100 times that for the two solutions'
    # different operations
    return fz, got, np.max(np.abs(got / w - 1)), 100 * np.finfo(float).eps * wall[-1] / w[0]


fz, got, err, tol = dense("sscb.gm.h5")
check(fz == 1 and err < tol, f"spatial slider-crank: f = {fz}, 4 global frequencies "
      f"{np.sqrt(got[0]) / 2 / np.pi:.1f} .. {np.sqrt(got[-1]) / 2 / np.pi:.1f} Hz = scipy on the same M, K, Cq (rel {err:.1e}, bound {tol:.1e})")
for kind in ("gms", "gmc"):
    write("ssc_%s.yaml" % kind, gmtable.scene_variant(
        ssc, "file: sscrod.fe.h5, basis: ssc.gm.h5, basis_kind: %s, modes: 2" % kind, 0.02))
    run("fmbd-run", "ssc_%s.yaml" % kind, "-o", "ssc_%s.run.h5" % kind, "-q")
a, b = point("ssc_gms.run.h5", "mid"), point("ssc_gmc.run.h5", "mid")
d, e = np.max(np.abs(a - a[0])), np.max(np.abs(a - b))
# one span in two coordinate sets: the Newton tolerance (1e-8 relative) of the motion, 1e-6
check(d > 0 and e < 1e-6 * d, f"spatial slider-crank, 2 global modes: GMs mid-span = GMc ({e:.1e} m of {d:.2e} m)")
# NM S-U (the paper's NM; gmtable.su_scene): the rod alone, held to ground by the mechanism's
# spherical and universal joints where gmsolve linearised the mechanism (its /linear/x). f = 0,
# and its frequencies = scipy on its own /linear matrices (the CB rod, as above)
for tag, body, gmf in (("cb", "sscrod.cb.h5", "sscb.gm.h5"), ("fe", "sscrod.fe.h5", "ssc.gm.h5")):
    with h5py.File(os.path.join(TMP, gmf), "r") as f:
        frame = f["linear/x"][7:14]
    write("ssu_%s.yaml" % tag, gmtable.su_scene(ssc, "file: " + body, frame))
    run("gmsolve", "ssu_%s.yaml" % tag, "--modes", "4", "--matrices", "-o", "ssu%s.gm.h5" % tag, "-q")
fz, got, err, tol = dense("ssucb.gm.h5")
check(fz == 0 and err < tol, f"S-U-held rod: f = {fz}, 4 frequencies {np.sqrt(got[0]) / 2 / np.pi:.1f} .. "
      f"{np.sqrt(got[-1]) / 2 / np.pi:.1f} Hz = scipy on the same M, K, Cq (rel {err:.1e}, bound {tol:.1e})")
# The S-U-held rod's admissible motions are the mechanism's with the crank and slider still: a
# subspace of codimension 2 (the hold removes the rigid swing, f = 1, and the ends' motion along
# the rod against the crank's and slider's inertia) with the same mass and stiffness on it. So by
# Cauchy interlacing (the mechanism's eigenvalues counting its zero) GM_{k-1} <= SU_k <= GM_{k+1}
# for the flexible frequencies; 1e-9 relative: the eigensolutions' residual checks
with h5py.File(os.path.join(TMP, "ssc.gm.h5"), "r") as f:
    gm = f["global/frequency_hz"][()]
    dim = int(f["global"].attrs["coordinates"]) - int(f["global"].attrs["constraints"])
with h5py.File(os.path.join(TMP, "ssufe.gm.h5"), "r") as f:
    su, sfz = f["global/frequency_hz"][()], int(f["global"].attrs["f"])
    dim -= int(f["global"].attrs["coordinates"]) - int(f["global"].attrs["constraints"])
ok = sfz == 0 and dim == 2 and all(gm[k - 1] <= su[k] * (1 + 1e-9) for k in range(1, 4)) and \
    all(su[k] <= gm[k + 1] * (1 + 1e-9) for k in range(0, 3))
check(ok, "S-U-held FE rod: its frequencies " + ", ".join("%.1f" % x for x in su) + " Hz interlace the mechanism's "
      + ", ".join("%.1f" % x for x in gm) + " Hz (GM_k-1 <= SU_k <= GM_k+1; codimension %d)" % dim)
# and NM S-U runs as the rod's basis in the mechanism (GMc basis of that file): 2 modes, 7 + 2
# coordinates for the rod; its mid-span within 2e-5 m (the paper's two-mode accuracy) of the
# GMc run's, both two-mode approximations of the FM (examples/spatial-slidercrank/README.md:
# 7.2e-6 and 9.8e-6 m from the FM at 6 mm, largest over 0.02 s)
write("ssc_su.yaml", gmtable.scene_variant(ssc, "file: sscrod.fe.h5, basis: ssufe.gm.h5, modes: 2", 0.02))
run("fmbd-run", "ssc_su.yaml", "-o", "ssc_su.run.h5", "-q")
with h5py.File(os.path.join(TMP, "ssc_su.run.h5"), "r") as f:
    nc = int(f["stats"].attrs["coordinates"])
c = point("ssc_su.run.h5", "mid")
e = np.max(np.linalg.norm(c - b, axis=1))
check(nc == 23 and e < 2e-5, f"spatial slider-crank, NM S-U basis with 2 modes: {nc} coordinates, mid-span "
      f"{e:.1e} m from the 2-mode GMc run")
# --- 6. gmsolve --xdmf: the global modes on the bodies' meshes, read back by meshio ------------
# a tet10 rod clamped at end0, turned 90 degrees about z and moved: the frame does not move in the
# modes (f = 0), so mode k's displacement is A (/expand /gms/rod/shapes[:, k]) at every node,
# times the display scale /fields/mode_scale[k]
write("xclamp.yaml", """title: clamped solid rod, turned
solver: {t_end: 0.01}
bodies:
  - name: rod
    type: flexible
    file: rodfe.fe.h5
    position: [0.1, 0.2, 0.3]
    orientation: {matrix: [0, -1, 0, 1, 0, 0, 0, 0, 1]}
joints:
  - {name: clamp, type: fixed, body1: ground, body2: rod, at2: {interface: end0}}
""")
run("gmsolve", "xclamp.yaml", "--modes", "3", "--xdmf", "-o", "xclamp.gm.h5", "-q")
xd = os.path.join(TMP, "xclamp.gm.xdmf")
check(os.path.exists(xd) and not os.path.exists(xd + ".part"), "gmsolve --xdmf: xclamp.gm.xdmf beside xclamp.gm.h5")
try:
    import meshio
except ImportError:
    meshio = None
    check(False, "python3-meshio (scripts/install-deps.sh) is installed")
import scipy.sparse as sp  # noqa: E402
with h5py.File(os.path.join(TMP, "rodfe.fe.h5"), "r") as b:
    x0, tets = b["mesh/nodes"][()], b["mesh/elements/tet10"][()]
    e = b["expand"]
    E = sp.csr_matrix((e["data"][()], e["indices"][()], e["indptr"][()]), shape=tuple(e.attrs["shape"]))
with h5py.File(os.path.join(TMP, "xclamp.gm.h5"), "r") as f:
    S, sc = f["gms/rod/shapes"][()], f["fields/mode_scale"][()]
Arot = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
world = np.array([0.1, 0.2, 0.3]) + x0 @ Arot.T
if meshio is not None:
    with meshio.xdmf.TimeSeriesReader(xd) as r:
        points, blocks = r.read_points_cells()
        check(r.num_steps == 3, f"meshio: {r.num_steps} frames = 3 global modes")
        check(len(blocks) == 1 and blocks[0].type == "tetra10"
              and np.array_equal(blocks[0].data, tets[:, [0, 1, 2, 3, 4, 5, 6, 7, 9, 8]]),
              f"meshio: cells = /mesh/elements/tet10 in XDMF order ({len(tets)} tet10)")
        k = 1
        tk, pdata, _ = r.read_data(k)
        u = sc[k] * (E @ S[:, k]).reshape(-1, 6)[:, :3] @ Arot.T
        du = np.abs(pdata["displacement"] - u).max() / np.abs(u).max()
        # the same products in another order: round-off, 1e-12 relative
        check(tk == k + 1 and du < 1e-12, f"meshio: mode {k + 1} (time {tk}) displacement = A E shapes x scale "
              f"(rel {du:.1e}; largest {np.abs(u).max():.3g} m, 10 % of the rod)")
    with h5py.File(os.path.join(TMP, "xclamp.gm.h5"), "r") as f:
        pos = f["fields/frames/%d/position" % k][()]
    dpos = np.abs(pos - (world + u)).max()
    check(dpos < 1e-12, f"frame {k}: positions = the reference world positions + the displacement ({dpos:.1e} m)")
finish()
print("all passed")
