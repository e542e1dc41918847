#!/usr/bin/python3
"""examples/batch/summary.py: the one summary of the batch example (examples/batch/Makefile).

Reads, for every body NAME, the files the batch made in OUT (h5py and csv, as a user would):
NAME.fe.h5 (dofs), NAME.rflex.h5 (/modes: the selected Nd, the largest upper estimate),
NAME.est.csv (the estimates, and the exact errors for the sample bodies run with --exact) and
NAME.{mesh2fe,fe2cb,cbcheck}.time (wall seconds and peak kB of each step, /usr/bin/time), and
writes OUT/summary.csv (a row per body) and OUT/summary.svg (the selected Nd against the dofs,
and the estimated against the exact error of the sample).

Usage: summary.py --out OUT --variants VARIANTS.csv --tol E --range NM [--jobs J --threads T]
                  NAME...
"""
import argparse
import csv
import os
import sys

import h5py

STEPS = ("mesh2fe", "fe2cb", "cbcheck")


def read_time(path):
    """(wall s, peak kB) from a /usr/bin/time -f '%e %M' file (its last line)."""
    with open(path) as f:
        lines = [ln.split() for ln in f if ln.strip()]
    wall, kb = lines[-1][:2]
    return float(wall), int(kb)


def body_row(out, name, params):
    fe = os.path.join(out, f"{name}.fe.h5")
    rf = os.path.join(out, f"{name}.rflex.h5")
    est = os.path.join(out, f"{name}.est.csv")
    row = {"name": name}
    row.update({k: params[k] for k in ("L", "W", "H", "T", "R", "h")})
    with h5py.File(fe, "r") as f:
        row["dofs"] = f["dofs"].shape[0]
    with h5py.File(rf, "r") as f:
        m = f["modes"]
        row["nd"] = int(m.attrs["n_fixed_interface_modes"])
        row["modes_kept"] = m["frequency_hz"].shape[0]
        row["f1_hz"] = float(m["frequency_hz"][0]) if row["modes_kept"] else float("nan")
        row["max_upper"] = float(m.attrs["max_estimate"])
    rows = list(csv.DictReader(open(est)))
    exact = [float(r["exact"]) for r in rows if r.get("exact")]
    row["max_exact"] = max(exact) if exact else ""
    total_wall, peak = 0.0, 0
    for s in STEPS:
        wall, kb = read_time(os.path.join(out, f"{name}.{s}.time"))
        row[f"{s}_s"] = wall
        total_wall += wall
        peak = max(peak, kb)
    row["wall_s"] = total_wall
    row["peak_mb"] = peak / 1024.0
    return row


def plot(rows, tol, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    sc = a.scatter([r["dofs"] for r in rows], [r["nd"] for r in rows],
                   c=[float(r["T"]) * 1e3 for r in rows], cmap="viridis")
    fig.colorbar(sc, ax=a, label="wall thickness T (mm)")
    a.set_xlabel("FE dofs")
    a.set_ylabel(f"selected Nd (upper estimate <= {tol:g})")
    a.set_title("fixed-interface modes selected per body")
    for r in rows:
        a.annotate(r["name"], (r["dofs"], r["nd"]), fontsize=6, xytext=(2, 2),
                   textcoords="offset points")
    x = range(len(rows))
    b.semilogy(x, [r["max_upper"] for r in rows], "o", label="largest upper estimate")
    ex = [(i, r["max_exact"]) for i, r in enumerate(rows) if r["max_exact"] != ""]
    if ex:
        b.semilogy([i for i, _ in ex], [e for _, e in ex], "x", ms=9, label="exact (sample)")
    b.axhline(tol, color="k", lw=0.8, ls="--", label=f"tolerance {tol:g}")
    b.set_xticks(list(x))
    b.set_xticklabels([r["name"] for r in rows], rotation=90, fontsize=6)
    b.set_ylabel("relative eigenvalue error, flexible modes 1..NM")
    b.set_title("error per body")
    b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path + ".part", format="svg")
    plt.close(fig)
    os.replace(path + ".part", path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--variants", required=True)
    ap.add_argument("--tol", type=float, required=True)
    ap.add_argument("--range", type=int, required=True)
    ap.add_argument("--jobs", default="")
    ap.add_argument("--threads", default="")
    ap.add_argument("names", nargs="+")
    a = ap.parse_args()
    params = {r["name"].strip(): r for r in csv.DictReader(open(a.variants))}
    rows = []
    for n in a.names:
        try:
            rows.append(body_row(a.out, n, params[n]))
        except (OSError, KeyError, ValueError, IndexError) as e:
            sys.exit(f"summary.py: body {n}: {e}")
    cols = list(rows[0].keys())
    path = os.path.join(a.out, "summary.csv")
    with open(path + ".part", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    plot(rows, a.tol, os.path.join(a.out, "summary.svg"))
    os.replace(path + ".part", path)
    bad = [r["name"] for r in rows if r["max_upper"] > a.tol]
    sample = [r for r in rows if r["max_exact"] != ""]
    under = [r["name"] for r in sample if r["max_exact"] > r["max_upper"]]
    dofs = [r["dofs"] for r in rows]
    nds = [r["nd"] for r in rows]
    print(f"summary: {len(rows)} bodies, {min(dofs)}..{max(dofs)} dofs, Nd {min(nds)}..{max(nds)} "
          f"for tol {a.tol:g} on flexible modes 1..{a.range}; bodies above tol: {len(bad)}; "
          f"exact error checked on {len(sample)} (upper estimate below the exact error: "
          f"{', '.join(under) if under else 'none'}); total wall of the steps "
          f"{sum(r['wall_s'] for r in rows):.1f} s, largest peak {max(r['peak_mb'] for r in rows):.0f} MB"
          + (f"; {a.jobs} jobs x {a.threads} BLAS threads" if a.jobs else ""))
    print(f"summary: {path}, {os.path.join(a.out, 'summary.svg')}")
    if bad:
        sys.exit(f"summary.py: bodies above the tolerance: {' '.join(bad)}")


if __name__ == "__main__":
    main()
