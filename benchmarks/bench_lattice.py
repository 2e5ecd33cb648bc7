"""Speed of applying an FFD lattice (docs/model.md §6): `Lattice.__call__` against mathLab PyGeM's `FFD`.

A 5³ lattice on the padded bounding box of P00 sampled on a 1000×1000 grid (1 000 000 points,
mm), every control point displaced by N(0, 3 mm) (seeded), is applied to those points by

1. `Lattice.__call__` (chunked tensor product);
2. PyGeM's `FFD.__call__` on the same box and displaced control points (PyGeM stores the
   displacements as `array_mu_x/y/z`, divided by the box lengths); skipped, saying so, when
   `import pygem` fails (it is not on PyPI under that name: install it from github.com/mathLab/PyGeM);
3. the dense basis product `Lattice.basis(points) @ P` on the first 100 000 points only (the
   (N, 125) basis of 1 M points would take 1 GB), its time scaled ×10 (marked "est.");
4. baseline, minimal numpy work: `np.linalg.norm(points, axis=1)` over the same 1 M points.

The cases alternate within each repeat (the machine is shared and noisy) and each row gives the
median after one warm-up round. Checks: PyGeM's control points equal ours, and the largest
difference between PyGeM's, the dense product's and our deformed points (mm) is printed.
Target: ours ≤ PyGeM's time / 3, against PyGeM measured in the same run (PyGeM was once measured
at 2.00 s on this machine; without PyGeM that figure is quoted, not compared).

Run:  .venv/bin/python benchmarks/bench_lattice.py [--repeats N] [--quick]   (default 5; --quick 2)
"""
from __future__ import annotations

import json
import statistics

import numpy as np
from rich.console import Console
from rich.table import Table
from threadpoolctl import threadpool_limits

from breastplan import Primitive, to_mm
from breastplan.deform.lattice import Lattice

from timing import fmt, repeats_argument, timed

GRID = (1000, 1000)
SHAPE = 5
DENSE_POINTS = 100_000
TARGET_FACTOR = 3.0
PYGEM_RECORDED_S = 2.00
"""PyGeM's time on 1 M points once measured on this machine (the lattice code before its chunked apply: 2.13 s)."""


def setup(seed: int = 0) -> tuple[np.ndarray, Lattice]:
    points = to_mm(Primitive().sample(*GRID))
    lattice = Lattice.around(points, SHAPE)
    lattice.displacements = np.random.default_rng(seed).normal(0.0, 3.0, (lattice.size, 3))
    return points, lattice


def pygem_ffd(lattice: Lattice):
    """PyGeM's FFD with our box and displaced control points, or None without PyGeM."""
    try:
        from pygem import FFD
    except ImportError:
        return None
    ffd = FFD(list(lattice.shape))
    ffd.box_origin = lattice.lo.copy()
    ffd.box_length = lattice.hi - lattice.lo
    ffd.rot_angle = np.zeros(3)
    mu = lattice.displacements.reshape(*lattice.shape, 3) / ffd.box_length     # PyGeM: displacement / box length
    ffd.array_mu_x, ffd.array_mu_y, ffd.array_mu_z = (np.ascontiguousarray(mu[..., c]) for c in range(3))
    if not np.allclose(ffd.control_points(deformed=True), lattice.points, rtol=0, atol=1e-9):
        raise SystemExit("PyGeM's control points differ from the lattice's: the conversion is wrong")
    return ffd


def measure(repeats: int) -> dict:
    points, lattice = setup()
    dense_points = points[:DENSE_POINTS]
    ffd = pygem_ffd(lattice)
    cases = {"ours": lambda: lattice(points),
             "pygem": (lambda: ffd(points)) if ffd is not None else None,
             "dense": lambda: lattice.basis(dense_points) @ lattice.points,
             "baseline": lambda: np.linalg.norm(points, axis=1)}
    cases = {k: f for k, f in cases.items() if f is not None}
    times = {k: [] for k in cases}
    for _ in range(repeats + 1):                  # alternate the cases; the first round is a warm-up
        for k, f in cases.items():
            times[k].append(timed(f))
    med = {k: statistics.median(t[1:]) for k, t in times.items()}
    ours = lattice(points)
    diff = {"dense": float(np.abs(lattice.basis(dense_points) @ lattice.points - ours[:DENSE_POINTS]).max())}
    if ffd is not None:
        diff["pygem"] = float(np.abs(ffd(points) - ours).max())
    return {"n_points": len(points), "moved_mm": float(np.linalg.norm(ours - points, axis=1).max()),
            "median_s": med, "max_diff_mm": diff, "pygem": ffd is not None}


def rows_of(m: dict) -> list[dict]:
    med, base, n = m["median_s"], m["median_s"]["baseline"], m["n_points"]
    pygem = med.get("pygem")

    def row(case, points, seconds, diff=None, note=""):
        return {"case": case, "points": points, "median_s": seconds, "baseline_s": base, "ratio": seconds / base,
                "vs_pygem": None if pygem is None else seconds / pygem, "max_diff_mm": diff, "note": note}
    rows = [row("Lattice.__call__ (chunked tensor product)", n, med["ours"])]
    if pygem is not None:
        rows.append(row("PyGeM FFD.__call__", n, pygem, m["max_diff_mm"]["pygem"]))
    rows.append(row(f"basis(points) @ P (dense, {DENSE_POINTS:,} points ×{n // DENSE_POINTS})", n,
                    med["dense"] * n / DENSE_POINTS, m["max_diff_mm"]["dense"], "est."))
    rows.append(row("baseline: np.linalg.norm(points, axis=1)", n, base))
    return rows


def print_table(rows: list[dict], m: dict, repeats: int) -> None:
    caption = (f"5³ lattice, control points displaced by N(0, 3 mm) (points move up to {m['moved_mm']:.1f} mm); "
               "medians of alternating runs after a warm-up round. ratio = median / baseline median; "
               "max |Δ| = largest coordinate difference from Lattice.__call__, mm. The dense row is timed on "
               f"{DENSE_POINTS:,} points and scaled.")
    if not m["pygem"]:
        caption += (" PyGeM row skipped: `import pygem` failed (install mathLab PyGeM from GitHub; "
                    f"it was once measured at {PYGEM_RECORDED_S:.2f} s on 1 M points on this machine).")
    table = Table(title=f"bench_lattice — {m['n_points']:,} points, {repeats} repeats", caption=caption,
                  caption_justify="left")
    for col in ("case", "median", "baseline median", "ratio", "÷ PyGeM", "max |Δ| mm"):
        table.add_column(col, justify="left" if col == "case" else "right")
    for r in rows:
        table.add_row(r["case"], fmt(r["median_s"], 1) + (" est." if r["note"] else ""), fmt(r["baseline_s"], 1),
                      f"{r['ratio']:.1f}", "" if r["vs_pygem"] is None else f"{r['vs_pygem']:.3f}",
                      "" if r["max_diff_mm"] is None else f"{r['max_diff_mm']:.1e}")
    Console(width=150).print(table)


def main() -> None:
    repeats = repeats_argument(__doc__.splitlines()[0], 5, 2)
    with threadpool_limits(1, "blas"):           # as the commands run the library's work
        m = measure(repeats)
    rows = rows_of(m)
    print_table(rows, m, repeats)
    ours, pygem = m["median_s"]["ours"], m["median_s"].get("pygem")
    figure = {"name": "lattice_apply_1M_s", "median_s": ours, "baseline_s": m["median_s"]["baseline"],
              "target": f"≤ PyGeM FFD / {TARGET_FACTOR:g}"}
    if pygem is not None:
        figure.update(pygem_s=pygem, target_s=pygem / TARGET_FACTOR, met=bool(ours <= pygem / TARGET_FACTOR),
                      pygem_max_diff_mm=m["max_diff_mm"]["pygem"])
    else:
        figure.update(pygem_s=None, target_s=None, met=None,
                      target_note=f"PyGeM not installed, not measured; it once took {PYGEM_RECORDED_S:.2f} s "
                                  f"on this machine (÷3: {PYGEM_RECORDED_S / TARGET_FACTOR:.2f} s), "
                                  "not a baseline of this run")
    print(json.dumps({"benchmark": "bench_lattice", "repeats": repeats, "figure": figure, "rows": rows}))


if __name__ == "__main__":
    main()
