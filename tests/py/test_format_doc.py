#!/usr/bin/python3
"""tests/py/test_format_doc.py: every HDF5 object the programs write is documented.

Makes one file of each kind with the programs (a coarse quadruple-pendulum rod through mesh2fe,
fe2cb and cbcheck, then a short run of the quadruple pendulum with energies and a reference
run), walks every group, dataset and attribute in h5py, and checks that docs/FORMAT.md names
each: an object by its path in backquotes (`/cb/Phi`; members of named collections such as
`/interfaces/<name>` or `/outputs/NAME` by the placeholder; a group is documented by its
documented members; CSR members data/indices/indptr by the CSR convention), an attribute by its
name in backquotes. Fails listing what is missing, so a writer cannot add an object without
documenting it.
"""
import os
import re
import subprocess
import sys

import h5py

ROOT = os.environ.get("ROOT", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
BUILD = os.environ.get("BUILD", "build")
BIN = os.path.join(ROOT, BUILD, "bin")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_format_doc")
# collections whose member names are the user's: the placeholder FORMAT.md uses for a member
COLLECTIONS = {"interfaces": "<name>", "clamped": "<name>", "groups": "<name>", "outputs": "NAME",
               "reactions": "JOINT", "reference": "NAME", "body": "NAME", "frames": "K", "gms": "<body>",
               "gmc": "<body>"}
CSR_MEMBERS = ("data", "indices", "indptr")


def run(*args):
    r = subprocess.run([os.path.join(BIN, args[0])] + list(args[1:]), cwd=TMP, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("FAIL: %s exited %d: %s" % (" ".join(args), r.returncode, r.stderr[-2000:]))


def normalise(path):
    parts = path.strip("/").split("/")
    out = [COLLECTIONS.get(parts[i - 1], p) if i > 0 else p for i, p in enumerate(parts)]
    return "/" + "/".join(out)


def main():
    os.makedirs(TMP, exist_ok=True)
    ex = os.path.join(ROOT, "examples")
    run("mesh2fe", os.path.join(ex, "geometry", "rod.geo"), "--size", "0.02", "--E", "100e9", "--nu", "0.285",
        "--rho", "7850", "--interface", "end0@-0.05,0,0", "-o", "rod.fe.h5", "-q")
    run("fe2cb", "rod.fe.h5", "--modes", "12", "-o", "rod.cb.h5", "-q")
    run("cbcheck", "rod.cb.h5", "--tol", "0.1", "--range", "4", "-o", "rod.rflex.h5", "-q")
    scene = os.path.join(ex, "quadpend", "quadpend.yaml")
    run("cbcheck", "rod.cb.h5", "--tol", "0.1", "--range", "4", "--for-scene", scene + ":rod",
        "-o", "rodsub.rflex.h5", "-q")  # a subset body (/subset)
    run("fmbd-run", scene, "--body-dir", ".", "--t-end", "0.02", "-o", "ref.run.h5", "-q")
    run("fmbd-run", scene, "--body-dir", ".", "--t-end", "0.02", "--reference", "ref.run.h5", "-o", "run.h5",
        "--xdmf", "-q")
    run("gmsolve", scene, "--body-dir", ".", "--modes", "4", "--matrices", "-o", "quadpend.gm.h5", "-q")

    doc = open(os.path.join(ROOT, "docs", "FORMAT.md")).read()
    paths = set(re.findall(r"`(/[^`\s]*)`", doc))
    words = set(re.findall(r"`([^`\s/]+)`", doc))
    missing = []
    for name in ("rod.fe.h5", "rod.cb.h5", "rod.rflex.h5", "rodsub.rflex.h5", "run.h5", "quadpend.gm.h5"):
        with h5py.File(os.path.join(TMP, name), "r") as f:
            objects = ["/"]
            f.visit(lambda n: objects.append("/" + n))
            seen = 0
            for p in objects:
                obj = f[p]
                for a in obj.attrs:
                    if a not in words:
                        missing.append("%s: attribute `%s` of %s" % (name, a, p))
                if p == "/":
                    continue
                seen += 1
                q = normalise(p)
                leaf = q.rsplit("/", 1)[1]
                if q in paths:
                    continue
                if isinstance(obj, h5py.Dataset) and leaf in CSR_MEMBERS and obj.parent.attrs.get("encoding-type") == "csr_matrix":
                    continue
                if isinstance(obj, h5py.Group) and any(d.startswith(q + "/") for d in paths):
                    continue
                missing.append("%s: %s %s" % (name, "group" if isinstance(obj, h5py.Group) else "dataset", q))
            print("%-14s %4d objects checked" % (name, seen))
    for m in missing:
        print("undocumented in docs/FORMAT.md: " + m)
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
