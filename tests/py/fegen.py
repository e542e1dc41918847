#!/usr/bin/python3
# tests/py/fegen.py: fmbd-fe files of simple bodies, written with h5py/numpy/scipy
# SPDX-License-Identifier: MIT
#
# An independent writer of the fmbd-fe format (docs/FORMAT.md, section fmbd-fe) for tests
# of fe2cb and cbcheck that must not depend on mesh2fe: a 3-D Euler-Bernoulli beam or frame
# (6 dofs per node; consistent mass, translational rho*A and torsional rho*J, no section rotary
# inertia: the convention of common/fmbd_fe.h) and a 3-D spring-mass lattice (3 dofs per node,
# lumped mass). Interfaces are RBE2 ties: a new 6-dof node (at the group's centroid unless a
# point is given) whose motion the group's nodes follow rigidly,
#     u_s = u_m + theta_m x (x_s - x_m),  theta_s = theta_m (6-dof slaves),
# eliminated exactly: K = T' K_full T, M = T' M_full T with T = /expand (6 nnodes x ndof).
#
#   import fegen
#   b = fegen.beam(n_el=100, length=0.3, radius=0.015, interfaces={"end0": [0], "end1": [100]})
#   fegen.write(path, b)
#   K, M = fegen.read_km(path)            # scipy CSR
import h5py
import numpy as np
import scipy.sparse as sp


class Body:
    """Everything an fmbd-fe file holds, before elimination (full 6-dof-per-node matrices)."""

    def __init__(self):
        self.nodes = None          # (nmesh, 3)
        self.ndir = None           # (nmesh,) 3 or 6 directions per mesh node
        self.beams = None          # (ne, 2) or None
        self.beam_orient = None
        self.groups = {}
        self.Kf = None             # (6 nall, 6 nall) full, interface nodes included (zero)
        self.Mf = None
        self.node_mass = None      # (nmesh,)
        self.material = {}
        self.mass_kind = "consistent"
        self.interfaces = {}       # name -> (group nodes, point or None)
        self.clamped = {}          # name -> nodes


def _beam_local(E, G, rho, A, Iy, Iz, J, L):
    """12x12 local stiffness and consistent mass (Przemieniecki), dofs u v w rx ry rz per node."""
    K = np.zeros((12, 12))
    M = np.zeros((12, 12))
    ax = np.array([[1, -1], [-1, 1]], float)
    for (i, j), k, m in (((0, 6), E * A / L, rho * A * L), ((3, 9), G * J / L, rho * J * L)):
        idx = [i, j]
        K[np.ix_(idx, idx)] += k * ax
        M[np.ix_(idx, idx)] += m / 6 * np.array([[2, 1], [1, 2]])
    kb = lambda EI: EI / L**3 * np.array([[12, 6 * L, -12, 6 * L], [6 * L, 4 * L * L, -6 * L, 2 * L * L],
                                         [-12, -6 * L, 12, -6 * L], [6 * L, 2 * L * L, -6 * L, 4 * L * L]])
    mb = rho * A * L / 420 * np.array([[156, 22 * L, 54, -13 * L], [22 * L, 4 * L * L, 13 * L, -3 * L * L],
                                      [54, 13 * L, 156, -22 * L], [-13 * L, -3 * L * L, -22 * L, 4 * L * L]])
    # bending in the x-y plane: (v, rz); in the x-z plane: (w, ry) with rotation -dw/dx
    vy = [1, 5, 7, 11]
    wz = [2, 4, 8, 10]
    sgn = np.diag([1, -1, 1, -1])
    K[np.ix_(vy, vy)] += kb(E * Iz)
    M[np.ix_(vy, vy)] += mb
    K[np.ix_(wz, wz)] += sgn @ kb(E * Iy) @ sgn
    M[np.ix_(wz, wz)] += sgn @ mb @ sgn
    return K, M


def _frame(x0, x1, v):
    ex = (x1 - x0) / np.linalg.norm(x1 - x0)
    ez = v - v.dot(ex) * ex
    ez /= np.linalg.norm(ez)
    ey = np.cross(ez, ex)
    return np.array([ex, ey, ez])


def beam(n_el=100, length=0.3, radius=0.015, E=100e9, nu=0.285, rho=7850.0, section=None,
         path=None, interfaces=None, clamped=None, orientation=(0.0, 0.0, 1.0), skip=()):
    """A straight beam along x (or a polyline frame `path`: list of corner points, n_el elements
    per segment). Circular section of `radius` unless section=(A, Iy, Iz, J). interfaces:
    {name: [mesh node indices] or ([nodes], point)}; clamped: {name: [nodes]}."""
    b = Body()
    if path is None:
        path = [(0.0, 0.0, 0.0), (length, 0.0, 0.0)]
    path = [np.asarray(p, float) for p in path]
    pts = [path[0]]
    for a, c in zip(path[:-1], path[1:]):
        for k in range(1, n_el + 1):
            pts.append(a + (c - a) * k / n_el)
    b.nodes = np.array(pts)
    nm = len(pts)
    b.ndir = np.full(nm, 6)
    b.beams = np.array([[i, i + 1] for i in range(nm - 1)], dtype=np.int64)
    if section is None:
        A = np.pi * radius**2
        Iy = Iz = np.pi * radius**4 / 4
        J = np.pi * radius**4 / 2
    else:
        A, Iy, Iz, J = section
    G = E / (2 * (1 + nu))
    b.material = dict(E=E, nu=nu, rho=rho, area=A, Iy=Iy, Iz=Iz, J=J)
    b.interfaces = _norm_interfaces(interfaces)
    b.clamped = dict(clamped or {})
    nall = nm + len(b.interfaces)
    rows, cols, kv, mv = [], [], [], []
    v = np.asarray(orientation, float)
    orient = []
    node_mass = np.zeros(nm)
    for e, (i, j) in enumerate(b.beams):
        x0, x1 = b.nodes[i], b.nodes[j]
        L = np.linalg.norm(x1 - x0)
        ve = v if abs(np.dot(v, (x1 - x0) / L)) < 0.99 else np.array([1.0, 0, 0])
        orient.append(ve)
        if e in skip:  # left out of K and M (bad-input tests: a floating part)
            continue
        R = _frame(x0, x1, ve)
        T = np.kron(np.eye(4), R)
        Kl, Ml = _beam_local(E, G, rho, A, Iy, Iz, J, L)
        Kg, Mg = T.T @ Kl @ T, T.T @ Ml @ T
        d = np.r_[6 * i + np.arange(6), 6 * j + np.arange(6)]
        rr, cc = np.meshgrid(d, d, indexing="ij")
        rows.append(rr.ravel()), cols.append(cc.ravel()), kv.append(Kg.ravel()), mv.append(Mg.ravel())
        node_mass[[i, j]] += rho * A * L / 2
    b.beam_orient = np.array(orient)
    n6 = 6 * nall
    r, c = np.concatenate(rows), np.concatenate(cols)
    b.Kf = sp.csr_matrix((np.concatenate(kv), (r, c)), shape=(n6, n6))
    b.Mf = sp.csr_matrix((np.concatenate(mv), (r, c)), shape=(n6, n6))
    b.node_mass = node_mass
    b.groups = {name: np.asarray(g[0], np.int64) for name, g in b.interfaces.items()}
    for name, g in b.clamped.items():
        b.groups[name] = np.asarray(g, np.int64)
    b.groups["all"] = np.arange(nm, dtype=np.int64)
    return b


def lattice(nx=8, ny=3, nz=3, h=0.01, k=1e6, kd=None, m=0.01, interfaces=None, clamped=None):
    """A 3-D lattice of point masses m (lumped) joined by axial springs k to the 6 neighbours
    and kd (default k/2) along the face diagonals, nodes on a grid of spacing h. Groups x0, x1
    (the end faces) and all."""
    b = Body()
    g = np.array([(i * h, j * h, l * h) for i in range(nx) for j in range(ny) for l in range(nz)])
    idx = lambda i, j, l: (i * ny + j) * nz + l
    b.nodes = g
    nm = len(g)
    b.ndir = np.full(nm, 3)
    kd = k / 2 if kd is None else kd
    faces = {"x0": [idx(0, j, l) for j in range(ny) for l in range(nz)],
             "x1": [idx(nx - 1, j, l) for j in range(ny) for l in range(nz)]}
    # an interface given as a face name ("x0", "x1") ties that face
    interfaces = {n: (faces[s] if isinstance(s, str) else s) for n, s in (interfaces or {}).items()}
    clamped = {n: (faces[s] if isinstance(s, str) else s) for n, s in (clamped or {}).items()}
    b.interfaces = _norm_interfaces(interfaces)
    b.clamped = dict(clamped or {})
    nall = nm + len(b.interfaces)
    n6 = 6 * nall
    rows, cols, vals = [], [], []
    offs = [((1, 0, 0), k), ((0, 1, 0), k), ((0, 0, 1), k),
            ((1, 1, 0), kd), ((1, -1, 0), kd), ((1, 0, 1), kd), ((1, 0, -1), kd), ((0, 1, 1), kd), ((0, 1, -1), kd)]
    for i in range(nx):
        for j in range(ny):
            for l in range(nz):
                a = idx(i, j, l)
                for (di, dj, dl), kk in offs:
                    i2, j2, l2 = i + di, j + dj, l + dl
                    if not (0 <= i2 < nx and 0 <= j2 < ny and 0 <= l2 < nz):
                        continue
                    c = idx(i2, j2, l2)
                    e = g[c] - g[a]
                    e = e / np.linalg.norm(e)
                    ke = kk * np.outer(e, e)
                    blk = np.block([[ke, -ke], [-ke, ke]])
                    d = np.r_[6 * a + np.arange(3), 6 * c + np.arange(3)]
                    rr, cc = np.meshgrid(d, d, indexing="ij")
                    rows.append(rr.ravel()), cols.append(cc.ravel()), vals.append(blk.ravel())
    r, c = np.concatenate(rows), np.concatenate(cols)
    b.Kf = sp.csr_matrix((np.concatenate(vals), (r, c)), shape=(n6, n6))
    md = np.zeros(n6)
    for a in range(nm):
        md[6 * a:6 * a + 3] = m
    b.Mf = sp.diags(md).tocsr()
    b.node_mass = np.full(nm, m)
    b.mass_kind = "lumped"
    b.material = dict(E=1.0, nu=0.3, rho=1.0)
    b.groups = {"x0": np.array(faces["x0"], np.int64), "x1": np.array(faces["x1"], np.int64),
                "all": np.arange(nm, dtype=np.int64)}
    for name, gg in b.interfaces.items():
        b.groups.setdefault(name, np.asarray(gg[0], np.int64))
    for name, gg in b.clamped.items():
        b.groups.setdefault(name, np.asarray(gg, np.int64))
    return b


def _norm_interfaces(interfaces):
    out = {}
    for name, spec in (interfaces or {}).items():
        if isinstance(spec, tuple):
            out[name] = (np.asarray(spec[0], np.int64), spec[1])
        else:
            out[name] = (np.asarray(spec, np.int64), None)
    return out


def _skew(r):
    return np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])


def assemble(b):
    """Eliminate ties and clamps: returns dict with xyz (all nodes), dofs, K, M, expand, ifaces."""
    nm = len(b.nodes)
    names = sorted(b.interfaces)
    xyz = [b.nodes]
    inode = {}
    for q, name in enumerate(names):
        nodes, point = b.interfaces[name]
        p = np.mean(b.nodes[nodes], axis=0) if point is None else np.asarray(point, float)
        xyz.append(p[None, :])
        inode[name] = nm + q
    xyz = np.vstack(xyz)
    nall = len(xyz)
    ndir = np.r_[b.ndir, np.full(len(names), 6)]
    slave = {}
    for name in names:
        for s in b.interfaces[name][0]:
            if s in slave:
                raise ValueError("node %d in two interfaces" % s)
            slave[int(s)] = inode[name]
    clamped = set(int(n) for g in b.clamped.values() for n in g)
    # active dofs, node-major
    dofs = [(p, d) for p in range(nall) for d in range(ndir[p]) if p not in slave and p not in clamped]
    col = {pd: k for k, pd in enumerate(dofs)}
    n6 = 6 * nall
    r, c, v = [], [], []
    for p in range(nall):
        for d in range(ndir[p]):
            row = 6 * p + d
            if p in clamped:
                continue
            if p in slave:
                m = slave[p]
                if m in clamped:
                    continue
                if d < 3:
                    # u_s = u_m + theta_m x (x_s - x_m) = u_m - skew(x_s - x_m) theta_m
                    r.append(row), c.append(col[(m, d)]), v.append(1.0)
                    S = -_skew(xyz[p] - xyz[m])
                    for e in range(3):
                        if S[d, e] != 0:
                            r.append(row), c.append(col[(m, 3 + e)]), v.append(S[d, e])
                else:
                    r.append(row), c.append(col[(m, d)]), v.append(1.0)
            else:
                r.append(row), c.append(col[(p, d)]), v.append(1.0)
    T = sp.csr_matrix((v, (r, c)), shape=(n6, len(dofs)))
    K = (T.T @ b.Kf @ T).tocsr()
    M = (T.T @ b.Mf @ T).tocsr()
    for A in (K, M):
        A.sum_duplicates()
        A.sort_indices()
    K = ((K + K.T) * 0.5).tocsr()
    M = ((M + M.T) * 0.5).tocsr()
    K.sort_indices(), M.sort_indices()
    return dict(xyz=xyz, dofs=np.array(dofs, np.int64).reshape(-1, 2), K=K, M=M, expand=T.tocsr(),
                inode=inode, names=names)


def _write_csr(g, name, A):
    A = sp.csr_matrix(A)
    A.sort_indices()
    s = g.create_group(name)
    s.create_dataset("data", data=A.data.astype(np.float64))
    s.create_dataset("indices", data=A.indices.astype(np.int64))
    s.create_dataset("indptr", data=A.indptr.astype(np.int64))
    s.attrs["encoding-type"] = "csr_matrix"
    s.attrs["shape"] = np.array(A.shape, np.int64)


def write(path, b, K=None, M=None, format_version="1.0", fmt="fmbd-fe"):
    """Write the body. K, M override the assembled matrices (for bad-input tests)."""
    a = assemble(b)
    Ka = a["K"] if K is None else K
    Ma = a["M"] if M is None else M
    with h5py.File(path, "w") as f:
        f.attrs["format"] = fmt
        f.attrs["format_version"] = format_version
        f.attrs["creator"] = "fegen.py (tests)"
        f.attrs["command_line"] = "fegen.py"
        f.create_dataset("/mesh/nodes", data=a["xyz"])
        if b.beams is not None:
            f.create_dataset("/mesh/elements/beam2", data=b.beams)
            f.create_dataset("/mesh/beam2_orientation", data=b.beam_orient)
        f.create_group("/mesh/groups")
        for name, g in b.groups.items():
            f.create_dataset("/mesh/groups/" + name, data=np.asarray(g, np.int64))
        f.create_dataset("/mesh/node_mass", data=np.r_[b.node_mass, np.zeros(len(a["names"]))])
        mat = f.create_group("/material")
        for k, v in b.material.items():
            mat.attrs[k] = float(v)
        mat.attrs["mass"] = b.mass_kind
        f.create_dataset("/dofs", data=a["dofs"])
        _write_csr(f, "K", Ka)
        _write_csr(f, "M", Ma)
        _write_csr(f, "expand", a["expand"])
        f.create_group("/interfaces")
        for name in a["names"]:
            g = f.create_group("/interfaces/" + name)
            g.attrs["node"] = np.int64(a["inode"][name])
            g.attrs["kind"] = "rbe2"
            g.attrs["point"] = a["xyz"][a["inode"][name]]
            g.create_dataset("nodes", data=np.asarray(b.interfaces[name][0], np.int64))
        f.create_group("/clamped")
        for name, g in b.clamped.items():
            f.create_dataset("/clamped/" + name, data=np.asarray(g, np.int64))
        # rigid-body properties r' M r with the 6 rigid motions of the active dofs about the origin
        R = rigid_modes(a["xyz"], a["dofs"])
        M6 = R.T @ (a["M"] @ R)
        mass = M6[0, 0]
        com = np.array([M6[1, 5], M6[2, 3], M6[0, 4]]) / mass if mass > 0 else np.zeros(3)
        Io = M6[3:, 3:]
        Ic = Io - mass * (np.dot(com, com) * np.eye(3) - np.outer(com, com))
        body = f.create_group("/body")
        body.attrs["mass"] = mass
        body.attrs["center_of_mass"] = com
        body.attrs["inertia"] = Ic.ravel()
        body.attrs["volume"] = mass / b.material.get("rho", 1.0)
    return a


def rigid_modes(xyz, dofs):
    """(ndof, 6): translations x y z, rotations about x y z through the origin."""
    R = np.zeros((len(dofs), 6))
    for k, (p, d) in enumerate(dofs):
        if d < 3:
            R[k, d] = 1.0
            # rotation e_j x r: component d
            x = xyz[p]
            for j in range(3):
                e = np.zeros(3)
                e[j] = 1.0
                R[k, 3 + j] = np.cross(e, x)[d]
        else:
            R[k, d] = 1.0
    return R


def read_km(path):
    with h5py.File(path, "r") as f:
        out = []
        for name in ("K", "M"):
            g = f[name]
            out.append(sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]),
                                     shape=tuple(int(x) for x in g.attrs["shape"])))
    return out


def read_cb(path):
    """The fmbd-cb file as a dict of numpy arrays (h5py shapes: row-major as stored)."""
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and (name.startswith("cb") or name.startswith("reduced")):
                out[name] = obj[()]
        f.visititems(visit)
        out["attrs"] = dict(f["cb"].attrs)
        out["root"] = dict(f.attrs)
    return out


def write_ccx_deck(fe, path, nfreq, clamp_groups):
    """A CalculiX deck of the tet10 mesh of an fmbd-fe file, the tied nodes of an interface
    clamped (docs/TOOLCHAIN.md section 3g)."""
    with h5py.File(fe, "r") as f:
        xyz = f["/mesh/nodes"][()]
        tet = f["/mesh/elements/tet10"][()]
        if isinstance(clamp_groups, str):
            clamp_groups = [clamp_groups]
        fix = np.concatenate([f["/interfaces/%s/nodes" % g][()] for g in clamp_groups])
        E, nu, rho = (float(f["/material"].attrs[k]) for k in ("E", "nu", "rho"))
    nmesh = tet.max() + 1
    with open(path, "w") as d:
        d.write("*NODE, NSET=NALL\n")
        for i in range(nmesh):
            # %.12e keeps every field within ccx's 20 characters (gotcha 10)
            d.write("%d, %.12e, %.12e, %.12e\n" % (i + 1, *xyz[i]))
        d.write("*ELEMENT, TYPE=C3D10, ELSET=EALL\n")
        for e, t in enumerate(tet):
            t = t[[0, 1, 2, 3, 4, 5, 6, 7, 9, 8]] + 1
            d.write("%d, %s\n" % (e + 1, ", ".join(str(x) for x in t)))
        d.write("*NSET, NSET=FIX\n")
        for k in range(0, len(fix), 8):
            d.write(", ".join(str(x + 1) for x in fix[k:k + 8]) + ",\n")
        d.write("*BOUNDARY\nFIX, 1, 3\n*MATERIAL, NAME=M\n*ELASTIC\n%.9e, %.9e\n*DENSITY\n%.9e\n"
                % (E, nu, rho))
        d.write("*SOLID SECTION, ELSET=EALL, MATERIAL=M\n*STEP\n*FREQUENCY\n%d\n*END STEP\n" % nfreq)


def read_ccx_freq(dat):
    f = []
    lines = open(dat).read().splitlines()
    for k, line in enumerate(lines):
        if "E I G E N V A L U E   O U T P U T" in line:
            for row in lines[k + 1:]:
                parts = row.split()
                if len(parts) == 5 and parts[0].isdigit():
                    f.append(float(parts[3]))
                elif f and not row.strip():
                    break
            break
    return np.array(f)
