#!/usr/bin/python3
# tests/py/test_fm_beam.py: full FE bodies of beam elements (a `.fe.h5` of mesh2fe's 2-node
# beams: every dof, translations and rotations, in the floating frame), whose rigid-flexible
# coupling comes from the consistent M (docs/THEORY.md section 4b), against what nobody here
# wrote:
#  (a) gmsolve's linearised mass matrix of a beam pendulum is positive definite, and its
#      frame-flexible block is A S1 with S1 = T'M S formed here from the file's /M;
#  (b) the beam clamped by a fixed joint: gmsolve's global modes equal scipy's eigenvalues of
#      the file's K, M without the frame node's dofs;
#  (c) a pinned beam falling from the horizontal: the full model (FM) against a `.cb.h5` body
#      that keeps every mode (fe2cb --modes = all interior dofs);
#  (d) the driven beam pendulum of examples/nlink (large motion): the FM against the modal body
#      of the complete GMc basis (gmsolve: all 60 global modes, the FE dofs' span in the FM's own
#      frame), and the two-link chain of FM links runs.
import os

import h5py
import numpy as np
import scipy.linalg as sl
import subprocess

import scipy.sparse as sp

from harness import ROOT, check, finish, runner, tmpdir

TMP = tmpdir("test_fm_beam")
run = runner(TMP)
LINK = os.path.join(ROOT, "examples", "nlink", "link.geo")


def write(name, text):
    with open(os.path.join(TMP, name), "w") as f:
        f.write(text)


def csr(g):
    return sp.csr_matrix((g["data"][:], g["indices"][:], g["indptr"][:]), shape=tuple(g.attrs["shape"]))


def tip(path, name="tip"):
    with h5py.File(os.path.join(TMP, path), "r") as f:
        return f[f"outputs/{name}/position"][:]


# the link of examples/nlink: L 0.5 m, 10 beam elements, steel, round section r 0.01 m; one
# rbe2 interface end0 at x = 0 (the frame node): 66 dofs, 60 in the floating frame
run("mesh2fe", LINK, "--circle", "0.01", "--E", "210e9", "--nu", "0.3", "--rho", "7850", "--interface", "end0",
    "-o", "link.fe.h5", "-q")
with h5py.File(os.path.join(TMP, "link.fe.h5"), "r") as f:
    K, M = csr(f["K"]), csr(f["M"])
    dofs = f["dofs"][:]
    nfr = int(f["interfaces/end0"].attrs["node"])
    xyz = f["mesh/nodes"][:]
kept = np.flatnonzero(dofs[:, 0] != nfr)
n = len(kept)
tipnode = int(np.argmin(np.linalg.norm(xyz - [0.5, 0, 0], axis=1)))
run("fe2cb", "link.fe.h5", "--modes", str(n), "-o", "link.cb.h5", "-q")

pend = """title: one-link beam pendulum
gravity: [0, 0, -9.81]
solver: SOLVER
bodies:
  - {name: link0, type: flexible, file: BODY, orientation: ORIENT}
joints:
  - {name: j0, type: JOINT, body1: ground, body2: link0, point: [0, 0, 0], at2: {interface: end0}}
DRIVERS
outputs:
  every: 0.001
  points:
    - {name: tip, body: link0, node: TIP, quantities: [position]}
""".replace("TIP", str(tipnode))
hanging = "{axis: y, angle: 1.5707963267948966}"
driver = "drivers:\n  - {name: theta1, joint: j0, function: {type: sine, amplitude: -0.5235987755982988, " \
         "frequency_hz: 1}}"


def scene(name, body, solver, joint="revolute, axis: y", orient=hanging, drivers=driver, basis=""):
    write(name, pend.replace("BODY", body + basis).replace("SOLVER", solver).replace("JOINT", joint)
          .replace("ORIENT", orient).replace("DRIVERS", drivers))


# --- (a) the mass matrix of the linearised pendulum -----------------------------------------
scene("drv.yaml", "link.fe.h5", "{t_end: 0.2, step: 1e-4}")
p = run("gmsolve", "drv.yaml", "--modes", str(n), "--rank-tol", "1e-10", "--matrices", "-o", "drv.gm.h5", "-q")
check(p.returncode == 0, "gmsolve accepts the beam FM pendulum")
with h5py.File(os.path.join(TMP, "drv.gm.h5"), "r") as f:
    ML = csr(f["linear/M"]).toarray()
    nglob = len(f["global/eigenvalue"][()])
lmin = np.linalg.eigvalsh(ML).min()
# 7 frame coordinates (Euler parameters with their normalisation term) and the 60 FE dofs: the
# floating-frame mass matrix at q = 0 is [T R S]' M [T R S] (THEORY 4b), positive definite; the
# smallest eigenvalue is a beam's nodal rotary inertia (rho I L_e ~ 1e-7 kg m^2), far above
# round-off (1e-16 of the largest, ~1 kg)
check(lmin > 1e-10, f"the beam FM's linearised mass matrix is positive definite (smallest eigenvalue {lmin:.2e})")
check(nglob == n, f"all {n} flexible global modes of the FM ({nglob})")
# frame-flexible block: rows R (0..2), columns 7 + k: A S1_k, S1_a = (M t_a)[kept] with t_a the
# rigid translation along a of the active dofs; A is the hanging link's orientation (90 deg
# about y). The same sums over the same element matrices: round-off, 1e-12 of the mass (1.2 kg)
A = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], dtype=float)
S1 = np.zeros((3, n))
for a in range(3):
    t = (dofs[:, 1] == a).astype(float)
    S1[a] = (M @ t)[kept]
mass = (M @ (dofs[:, 1] == 0).astype(float)) @ (dofs[:, 1] == 0).astype(float)
d = np.abs(ML[0:3, 7:7 + n] - A @ S1).max()
check(d < 1e-12 * mass, f"M_Rf = A S1, S1 = T'MS of the file's consistent M (max diff {d:.1e}, m {mass:.4f} kg)")
# S1 has the end moments of a uniform load on the consistent beam mass (rho A L_e^2 / 12 on the
# rotations): the lumped nodal masses have none, so this is where the consistent coupling shows
rot = np.isin(dofs[kept, 1], [3, 4, 5])
check(np.abs(S1[:, rot]).max() > 1e-4, f"S1 on the nodal rotations is not zero ({np.abs(S1[:, rot]).max():.2e} kg m)")

# --- (b) clamped: the global modes are the clamped beam's normal modes ----------------------
scene("clamp.yaml", "link.fe.h5", "{t_end: 0.01, step: 1e-4}", joint="fixed", drivers="")
run("gmsolve", "clamp.yaml", "--modes", "12", "-o", "clamp.gm.h5", "-q")
with h5py.File(os.path.join(TMP, "clamp.gm.h5"), "r") as f:
    got = f["global/eigenvalue"][()]
    fz = int(f["global"].attrs["f"])
Kf, Mf = K[kept][:, kept].toarray(), M[kept][:, kept].toarray()
ref = sl.eigh(Kf, Mf, eigvals_only=True)[:len(got)]
err = np.max(np.abs(got / ref - 1))
# both dense symmetric-definite solutions of one 60 x 60 problem (gmsolve on its null-space
# basis, the identity here): a backward-stable solver errs on the lowest eigenvalue by about
# eps lambda_max / lambda_1 = 2.2e-16 (98.6 kHz / 57.9 Hz)^2 = 6.4e-10 (measured 1.7e-10): 1e-8
check(fz == 0 and err < 1e-8, f"clamped beam FM: f = {fz}, 12 global eigenvalues = scipy eigh of the clamped "
      f"K, M (rel {err:.1e}; {np.sqrt(ref[0]) / 2 / np.pi:.3f} Hz first)")

# --- (c) pinned, falling from the horizontal: FM against the all-modes CB body --------------
for kind in ("fe", "cb"):
    scene(f"fall_{kind}.yaml", f"link.{kind}.h5", "{t_end: 0.01, step: 1e-4}", joint="spherical",
          orient="{axis: z, angle: 0}", drivers="")
    p = run("fmbd-run", f"fall_{kind}.yaml", "-o", f"fall_{kind}.run.h5", "-q")
    check(p.returncode == 0 and "warning" not in p.stderr, f"falling beam with the {kind} body runs, no warning")
xf, xc = tip("fall_fe.run.h5"), tip("fall_cb.run.h5")
d, drop = np.abs(xf - xc).max(), np.abs(xf - xf[0]).max()
# The same FE model in two floating frames (the interface node's; the free-free modes' mean
# axes): linear FFRF theory gives the same motion to first order in the deformation, so they
# differ by its second order, u^2 / L (u ~ 1e-6 m here: 1e-12 m), and by the Newton tolerance
# (1e-8 of the 0.5 m reference length: 5e-9 m): 1e-8 m. (The driven pendulum below deflects
# 5 mm: there the two frames differ by 5.4e-5 m ~ u^2/L, measured, falling as 1/E with E.)
check(d < 1e-8, f"FM vs all-modes CB, falling beam: tip within {d:.1e} m (drop {drop:.2e} m)")

# --- (d) driven pendulum (large motion): FM against the complete GMc basis, same frame -------
p = run("fmbd-run", "drv.yaml", "-o", "drv.run.h5", "-q")
check(p.returncode == 0, "the driven one-link beam FM runs (nlink's link: failed at 6.3 ms with the lumped coupling)")
scene("gmc.yaml", "link.fe.h5", "{t_end: 0.2, step: 1e-4}", basis=", basis: drv.gm.h5")
run("fmbd-run", "gmc.yaml", "-o", "gmc.run.h5", "-q")
xf, xg = tip("drv.run.h5"), tip("gmc.run.h5")
d = np.abs(xf - xg).max()
# the GMc columns of all 60 flexible global modes span the FE dofs relative to the frame node:
# the modal body (fmbd_rflex_from_basis: S1 and R'MS from the consistent M, the rest from the
# lumped nodal masses, THEORY 9) is the FM's model in other coordinates (THEORY 4b); what differs
# is the Newton tolerance (5e-9 m, above): 1e-8 m (measured 1.5e-11 m). The lumped coupling
# of before differed by 5.4e-5 m here.
check(d < 1e-8, f"driven beam pendulum: FM vs the complete GMc basis within {d:.1e} m "
      f"(tip travel {np.abs(xf - xf[0]).max():.3f} m)")

# the two-link chain of FM links (the N-link example's reference), driven, both end points
write("two.yaml", """title: two-link beam pendulum, full models
gravity: [0, 0, -9.81]
solver: {t_end: 0.1, step: 1e-4}
bodies:
  - {name: link0, type: flexible, file: link2.fe.h5, orientation: {axis: y, angle: 1.5707963267948966}}
  - {name: link1, type: flexible, file: link2.fe.h5, position: [0, 0, -0.5],
     orientation: {axis: y, angle: 1.5707963267948966}}
joints:
  - {name: j0, type: revolute, body1: ground, body2: link0, point: [0, 0, 0], axis: y, at2: {interface: end0}}
  - {name: j1, type: revolute, body1: link0, body2: link1, point: [0, 0, -0.5], axis: y,
     at1: {interface: end1}, at2: {interface: end0}}
drivers:
  - {name: theta1, joint: j0, function: {type: sine, amplitude: -0.5235987755982988, frequency_hz: 1}}
outputs:
  every: 0.001
  points:
    - {name: mid, body: link0, interface: end1, quantities: [position]}
    - {name: end1, body: link1, interface: end1, quantities: [position]}
""")
run("mesh2fe", LINK, "--circle", "0.01", "--E", "210e9", "--nu", "0.3", "--rho", "7850", "--interface", "end0",
    "--interface", "end1", "-o", "link2.fe.h5", "-q")
p = run("gmsolve", "two.yaml", "--modes", "10", "--matrices", "-o", "two.gm.h5", "-q")
with h5py.File(os.path.join(TMP, "two.gm.h5"), "r") as f:
    lmin = np.linalg.eigvalsh(csr(f["linear/M"]).toarray()).min()
check(lmin > 1e-10, f"two-link beam FM: gmsolve accepts it, mass matrix positive definite ({lmin:.2e})")
p = run("fmbd-run", "two.yaml", "-o", "two.run.h5", "-q")
x0, x1 = tip("two.run.h5", "mid"), tip("two.run.h5", "end1")
# each link's end stays 0.5 m from its pin to within its elastic deformation: a transverse
# nodal displacement u (up to ~7 mm here) lengthens the chord by u^2 / 2L (linear deformation
# in the frame: 5e-5 m), the axial stretch is ~1e-8 m: 1e-3 m
r0, r1 = np.linalg.norm(x0, axis=1), np.linalg.norm(x1 - x0, axis=1)
swing = np.abs(x1 - x1[0]).max()
check(np.abs(r0 - 0.5).max() < 1e-3 and np.abs(r1 - 0.5).max() < 1e-3 and swing > 0.01,
      f"the two-link beam FM runs to 0.1 s: links' chords {r0.min():.6f} .. {r0.max():.6f}, "
      f"{r1.min():.6f} .. {r1.max():.6f} m; the end moves {swing:.3f} m")

# --- (f) lumped-mass beams: not one mass (THEORY 4b): refused at load, naming the cure ------
# (before: a falling link's mass matrix turned indefinite at t = 1.1 ms, "singular iteration matrix")
run("mesh2fe", LINK, "--circle", "0.01", "--E", "210e9", "--nu", "0.3", "--rho", "7850", "--interface", "end0",
    "--mass", "lumped", "-o", "linkl.fe.h5", "-q")
scene("fall_lumped.yaml", "linkl.fe.h5", "{t_end: 0.002, step: 1e-4}", joint="spherical",
      orient="{axis: z, angle: 0}", drivers="")
p = subprocess.run(["fmbd-run", "fall_lumped.yaml", "-o", "fall_lumped.run.h5", "-q"], cwd=TMP,
                   capture_output=True, text=True)
check(p.returncode != 0 and "fall_lumped.yaml:5" in p.stderr and "--mass consistent" in p.stderr
      and not os.path.exists(os.path.join(TMP, "fall_lumped.run.h5")),
      "a lumped-mass beam FE body is refused, naming the scene line and the cure: " + p.stderr.strip()[:160])

finish()
