#!/usr/bin/python3
# tests/py/test_fmbd_run_fields.py: what fmbd-run reports beside its series, checked from
# outside: (1) --reference errors (RMS, largest, its instant, the reference's RMS) of every
# shared output series, also over a --window, against numpy on a synthetic reference whose
# values are linear in time (so that its linear interpolation is exact and the expected errors
# are known in closed form); (2) --xdmf read back by an independent reader (meshio's XDMF
# time-series reader, Debian python3-meshio): nodes, cells and one frame's displacement and von
# Mises stress against numpy from the run file's /fields/body/NAME/{pose,q} and the body
# file's /expand, /modes/shapes, /modes/stress; the frames' world positions (which meshio does
# not read: it takes the mesh of the first frame) by h5py + the XML; (3) the fields of a full
# FE body against those of the all-modes CB body of the same mesh.
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np

ROOT = os.environ.get("ROOT", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
BUILD = os.environ.get("BUILD", "build")
BIN = os.path.join(ROOT, BUILD, "bin")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_fmbd_run_fields")
shutil.rmtree(TMP, ignore_errors=True)
os.makedirs(TMP)
failures = []


def check(cond, msg):
    print(("ok    " if cond else "FAIL  ") + msg)
    if not cond:
        failures.append(msg)


def run(*args):
    p = subprocess.run([os.path.join(BIN, args[0])] + list(args[1:]), cwd=TMP, capture_output=True, text=True)
    if p.returncode != 0:
        print(p.stderr)
        sys.exit("FAIL: %s exited %d" % (" ".join(args), p.returncode))
    return p


# --- a coarse quadruple pendulum: the rod reduced with stresses, node A with every quantity ----
ex = os.path.join(ROOT, "examples")
run("mesh2fe", os.path.join(ex, "geometry", "rod.geo"), "--size", "0.02", "--E", "100e9", "--nu", "0.285",
    "--rho", "7850", "--interface", "end0@-0.05,0,0", "-o", "rod.fe.h5", "-q")
run("fe2cb", "rod.fe.h5", "--modes", "12", "-o", "rod.cb.h5", "-q")
run("cbcheck", "rod.cb.h5", "--tol", "0.1", "--range", "4", "-o", "rod.rflex.h5", "-q")
scene = open(os.path.join(ex, "quadpend", "quadpend.yaml")).read()
scene = scene.replace("quantities: [position, velocity, acceleration, von_mises, strain]",
                      "quantities: [position, velocity, acceleration, von_mises, stress, strain]")
check("stress, strain]" in scene, "scene: node A asks for every quantity")
with open(os.path.join(TMP, "qp.yaml"), "w") as f:
    f.write(scene)
T_END = 0.05
run("fmbd-run", "qp.yaml", "--t-end", str(T_END), "-o", "run.h5", "--xdmf", "-q")
# a run file whose name XML must escape, or would end a comment (&, <, --): the XDMF still parses
run("fmbd-run", "qp.yaml", "--t-end", "0.014", "-o", "a&b<c--d.run.h5", "--xdmf", "-q")
try:
    odd = ET.parse(os.path.join(TMP, "a&b<c--d.run.xdmf")).getroot()
    item = odd.find("Domain").find("Grid").find("Grid").find("Geometry").find("DataItem").text.strip()
    check(item == "a&b<c--d.run.h5:/fields/frames/0/position", f"XDMF of an odd run-file name: {item}")
except ET.ParseError as e:
    check(False, f"XDMF of an odd run-file name parses: {e}")

# --- 1. --reference against a synthetic reference linear in time -------------------------------
rng = np.random.default_rng(9)
ts = np.linspace(-0.001, T_END + 0.001, 7)  # covers the run; instants unlike the run's
shutil.copy(os.path.join(TMP, "run.h5"), os.path.join(TMP, "ref.run.h5"))
expect = {}  # (output, quantity) -> (a, b): the reference is a + b t
with h5py.File(os.path.join(TMP, "run.h5"), "r") as f, h5py.File(os.path.join(TMP, "ref.run.h5"), "r+") as g:
    t = f["time"][()]
    del g["time"]
    g["time"] = ts
    del g["fields"]  # not an output: the reference does not need it
    for name in f["outputs"]:
        for q in f["outputs"][name]:
            v = f["outputs"][name][q][()]
            w = 1 if v.ndim == 1 else v.shape[1]
            # a reference well away from the run (|a| ~ 10 times the values): the errors are of
            # the values' size and their round-off stays ~1e-15 relative
            scale = np.abs(v).max() + 1e-30
            a, b = 10 * scale * rng.standard_normal(w), scale / T_END * rng.standard_normal(w)
            vals = a[None, :] + ts[:, None] * b[None, :]
            del g["outputs"][name][q]
            g["outputs"][name][q] = vals[:, 0] if v.ndim == 1 else vals
            expect[(name, q)] = (a, b, v.reshape(len(t), w))
check(("A", "stress") in expect and ("A", "von_mises_strain") in expect and ("tip3", "position") in expect,
      "the run has position..strain series of A and position of tip3: %s" % sorted(expect))


def expected(a, b, v, mask):
    ref = a[None, :] + t[:, None] * b[None, :]  # the linear interpolation of a + b s is exact
    e = np.linalg.norm(v - ref, axis=1)[mask]
    r = np.linalg.norm(ref, axis=1)[mask]
    return np.sqrt(np.mean(e ** 2)), e.max(), t[mask][np.argmax(e)], np.sqrt(np.mean(r ** 2)), mask.sum()


for window in (None, (0.01, 0.03)):
    args = ["fmbd-run", "qp.yaml", "--t-end", str(T_END), "-o", "cmp.run.h5", "--reference", "ref.run.h5"]
    mask = np.ones(len(t), bool)
    if window:
        args += ["--window", "%g:%g" % window]
        mask = (t >= window[0]) & (t <= window[1])
    p = run(*args)
    tag = "window %s" % (window,) if window else "whole run"
    with h5py.File(os.path.join(TMP, "cmp.run.h5"), "r") as f:
        check(np.array_equal(f["time"][()], t), f"{tag}: the same run")
        if window:
            check(np.allclose(f["reference"].attrs["window"], window, rtol=0, atol=0), f"{tag}: /reference window")
        worst = 0.0
        for (name, q), (a, b, v) in expect.items():
            rms, mx, tmx, rref, n = expected(a, b, v, mask)
            at = f["reference"][name].attrs
            got = (at["rms_" + q], at["max_" + q], at["rms_ref_" + q])
            # the sums run in another order than numpy's; everything else is the same arithmetic
            # on values ~10 x the run's: 1e-10 relative is round-off with a wide margin
            rel = max(abs(g_ - w_) / w_ for g_, w_ in zip(got, (rms, mx, rref)))
            worst = max(worst, rel)
            ok = rel < 1e-10 and at["t_max_" + q] == tmx and at["instants"] == n
            check(ok, f"{tag}: {name}/{q}: rms {got[0]:.6e} (numpy {rms:.6e}), max {got[1]:.6e} at "
                  f"{at['t_max_' + q]:.4g} s (numpy {mx:.6e} at {tmx:.4g} s), {at['instants']} instants ({n})")
            row = re.search(r"^fmbd-run: +%s +%s +(\S+) +(\S+) +(\S+) +(\S+) +(\d+) " % (name, q), p.stderr, re.M)
            check(row is not None and abs(float(row.group(1)) / rms - 1) < 1e-4 and int(row.group(5)) == n,
                  f"{tag}: table row {name} {q}")
        print(f"       {tag}: largest relative difference from numpy {worst:.1e}")

# --- 2. XDMF, read back by meshio ----------------------------------------------------------------
try:
    import meshio
except ImportError:
    meshio = None
    check(False, "python3-meshio (scripts/install-deps.sh) is installed")
xdmf = os.path.join(TMP, "run.xdmf")
check(os.path.exists(xdmf) and not os.path.exists(xdmf + ".part"), "run.xdmf beside run.h5")
with h5py.File(os.path.join(TMP, "rod.rflex.h5"), "r") as b:
    x0 = b["mesh/nodes"][()]
    tets = b["mesh/elements/tet10"][()]
    e = b["expand"]
    import scipy.sparse as sp
    X = sp.csr_matrix((e["data"][()], e["indices"][()], e["indptr"][()]), shape=tuple(e.attrs["shape"]))
    shapes, stress = b["modes/shapes"][()], b["modes/stress"][()]
with h5py.File(os.path.join(TMP, "run.h5"), "r") as f:
    t = f["time"][()]
    pose, q = f["fields/body/rod/pose"][()], f["fields/body/rod/q"][()]
    node_a = f["outputs/A"].attrs["node"]
    pos_a = f["outputs/A/position"][()]
    nm = q.shape[1]
    frames = [f["fields/frames/%d/position" % k][()] for k in range(len(t))]
nn = len(x0)
U = (X @ shapes[:, :nm]).reshape(nn, 6, nm)[:, :3, :]  # translations of every node per mode
K = len(t) // 2  # a frame in the middle
u = U @ q[K]
sig = stress[:, :, :nm] @ q[K]
s = sig
vm = np.sqrt(0.5 * ((s[:, 0] - s[:, 1]) ** 2 + (s[:, 1] - s[:, 2]) ** 2 + (s[:, 2] - s[:, 0]) ** 2)
             + 3 * (s[:, 3] ** 2 + s[:, 4] ** 2 + s[:, 5] ** 2))
world = [pose[k, :3] + (x0 + U @ q[k]) @ pose[k, 3:].reshape(3, 3).T for k in range(len(t))]
# gmsh -> XDMF Tetrahedron_10 order: the fe file's local nodes 8 and 9 swap
cells = tets[:, [0, 1, 2, 3, 4, 5, 6, 7, 9, 8]]
if meshio is not None:
    with meshio.xdmf.TimeSeriesReader(xdmf) as r:
        points, blocks = r.read_points_cells()
        check(r.num_steps == len(t), f"meshio: {r.num_steps} frames, the run has {len(t)} rows")
        check(len(blocks) == 1 and blocks[0].type == "tetra10" and np.array_equal(blocks[0].data, cells),
              f"meshio: cells = /mesh/elements/tet10 in XDMF order ({len(cells)} tet10)")
        # positions are R + A (x0 + u): products of O(1) numbers summed in another order than
        # numpy's; 1e-12 m on a 1.5 m mechanism is round-off with margin
        check(points.shape == x0.shape and np.abs(points - world[0]).max() < 1e-12,
              f"meshio: nodes = world positions at t = 0 (max diff {np.abs(points - world[0]).max():.1e} m)")
        tk, pdata, _ = r.read_data(K)
        check(tk == t[K], f"meshio: frame {K} at t = {tk} (run {t[K]})")
        du = np.abs(pdata["displacement"] - u).max() / np.abs(u).max()
        dv = np.abs(pdata["von_mises"] - vm).max() / vm.max()
        # sums over the modes in another order: 1e-10 of the field's largest value
        check(du < 1e-10 and np.abs(u).max() > 0, f"meshio: frame {K} displacement = /expand shapes q "
              f"(max |u| {np.abs(u).max():.3e} m, rel diff {du:.1e})")
        check(dv < 1e-10 and vm.max() > 0, f"meshio: frame {K} von Mises = von Mises(/modes/stress q) "
              f"(max {vm.max():.4e} Pa, rel diff {dv:.1e})")
# every frame's geometry: the XML's HDF5 paths, read with h5py
root = ET.parse(xdmf).getroot()
grids = root.find("Domain").find("Grid").findall("Grid")
check(len(grids) == len(t), f"XML: {len(grids)} frames")
worst = 0.0
with h5py.File(os.path.join(TMP, "run.h5"), "r") as f:
    for k, g in enumerate(grids):
        tv = float(g.find("Time").attrib["Value"])
        path = g.find("Geometry").find("DataItem").text.strip().split(":")[1]
        worst = max(worst, np.abs(f[path][()] - world[k]).max(), abs(tv - t[k]))
check(worst < 1e-12, f"XML + h5py: every frame's world positions and time (max diff {worst:.1e})")
# the output point A is node A of the same body: its series and the field agree (fmbd_mbs's
# point position against the field's own product; round-off)
da = max(np.abs(frames[k][node_a] - pos_a[k]).max() for k in range(len(t)))
check(da < 1e-12, f"field position of node {node_a} = /outputs/A/position at every frame (max diff {da:.1e} m)")

# --- 2b. a full FE body (the full model) and the all-modes CB body of the same mesh: the same
# discrete system in other coordinates, so their fields agree (their elastic displacements
# differ by the frames' conventions, their world positions and stresses do not) -------------
run("mesh2fe", os.path.join(ex, "geometry", "rod.geo"), "--size", "0.03", "--order", "1", "--E", "210e9", "--nu",
    "0.3", "--rho", "7850", "--interface", "end0@-0.05,0,0", "-o", "fm.fe.h5", "-q")
with h5py.File(os.path.join(TMP, "fm.fe.h5"), "r") as f:
    nfree = f["dofs"].shape[0] - 6  # all but the interface node's 6
run("fe2cb", "fm.fe.h5", "--modes", str(nfree), "-o", "fm.cb.h5", "-q")
pend = """title: falling rod
gravity: [0, -9.81, 0]
solver: {t_end: 0.02, step: 1e-4, newton_tol: 1e-10}
bodies:
  - {name: rod, type: flexible, file: BODY}
joints:
  - {name: pin, type: spherical, body1: ground, body2: rod, at2: {interface: end0}}
outputs:
  every: 0.002
  points:
    - {name: tip, body: rod, nearest: [0.3, 0, 0], quantities: [position]}
"""
fields = {}
for kind in ("fe", "cb"):
    with open(os.path.join(TMP, f"fm_{kind}.yaml"), "w") as f:
        f.write(pend.replace("BODY", f"fm.{kind}.h5"))
    run("fmbd-run", f"fm_{kind}.yaml", "-o", f"fm_{kind}.run.h5", "--xdmf", "-q")
    with h5py.File(os.path.join(TMP, f"fm_{kind}.run.h5"), "r") as f:
        n = len(f["time"])
        fields[kind] = (np.array([f["fields/frames/%d/position" % k][()] for k in range(n)]),
                        f["fields/frames/%d/von_mises" % (n - 1)][()], f["fields/cells"][()])
pf, vf, cf = fields["fe"]
pc, vc, cc = fields["cb"]
# world positions: both runs converge Newton to 1e-10 of the 0.35 m reference; 1e-9 m
dp = np.abs(pf - pc).max()
check(np.array_equal(cf, cc) and dp < 1e-9, f"XDMF: full FE body vs all-modes CB body, every node and frame "
      f"within {dp:.1e} m")
# von Mises: the same nodal averaging of element stresses (fmbd_fe_nodal_stress) of displacements of
# ~1 um that agree to the Newton tolerance (~4e-11 m): ~1e-4 relative at most
dv = np.abs(vf - vc).max() / vc.max()
check(vc.max() > 0 and dv < 1e-4, f"XDMF: full FE vs CB von Mises at t_end: max {vf.max():.4e} Pa, rel diff {dv:.1e}")
if meshio is not None:
    with meshio.xdmf.TimeSeriesReader(os.path.join(TMP, "fm_fe.run.xdmf")) as r:
        points, blocks = r.read_points_cells()
        _, pdata, _ = r.read_data(r.num_steps - 1)
    check(blocks[0].type == "tetra" and np.array_equal(points, pf[0]) and np.array_equal(pdata["von_mises"], vf),
          "meshio reads the full FE body's XDMF (tetra, nodes, von Mises)")

# --- 3. usage: --window without --reference; a bad window -----------------------------------
for args, what in ((["--window", "0:1"], "needs --reference"), (["--reference", "ref.run.h5", "--window", "1:0"], "T0 must be below T1"),
                   (["--reference", "ref.run.h5", "--window", "1"], "list of 2 numbers")):
    p = subprocess.run([os.path.join(BIN, "fmbd-run"), "qp.yaml", "-o", "bad.run.h5"] + args, cwd=TMP,
                       capture_output=True, text=True)
    check(p.returncode == 2 and what in p.stderr and not os.path.exists(os.path.join(TMP, "bad.run.h5")),
          f"usage: {' '.join(args)}: exit {p.returncode}, '{what}'")

# --xdmf needs a run file beside it, and a flexible body with solid elements: else no output
p = subprocess.run([os.path.join(BIN, "fmbd-run"), "qp.yaml", "-o", "-", "--xdmf"], cwd=TMP,
                   capture_output=True)
check(p.returncode == 2 and b"--xdmf needs a named run file" in p.stderr and not p.stdout,
      f"--xdmf -o -: exit {p.returncode}")
p = subprocess.run([os.path.join(BIN, "fmbd-run"), os.path.join(ex, "scenes", "pendulum.yaml"), "-o", "rigid.run.h5",
                    "--xdmf"], cwd=TMP, capture_output=True, text=True)
left = [n for n in os.listdir(TMP) if n.startswith("rigid.")]
check(p.returncode == 1 and "no flexible body with solid elements" in p.stderr and not left,
      f"--xdmf on a rigid scene: exit {p.returncode}, nothing left ({left})")

if failures:
    print(f"{len(failures)} failure(s)")
    sys.exit(1)
