"""A clinic's own model of an operation (`plan.learnt_operation`), learnt from before/after pairs and checked on a
woman it has not seen, against the built-in model of the same operation in the same run.

The MakeHuman world stands in for a clinic's records: each body of `bench_operations.PAIRS` (build, firmness,
weight, muscle, pose varied) scanned at cup c1 and again at cup c2, as a clinic scans her (650 mm, pitch 5°, a wall
400 mm behind, 800×600, 8 frames), both breasts, is one woman's augmentation (c1 → c2, the implant of the true
half-body change) and, read backwards, one woman's reduction (c2 → c1). Leave one woman out: the model is learnt
from the other five women's pairs (10 breasts), then makes her operation on her scan, which is compared with the
true body she would have (the c2 or c1 mesh in the same camera frame), as `bench_operations` compares the built-in
operations (targets there: augmentation 2.5 mm mean, 7 mm 95th percentile, nipple 6 mm; reduction 3 mm mean).

These bodies are MakeHuman's larger or smaller cup, not an implant or a resection: what is measured is how well a
model learnt from a clinic's pairs predicts a woman outside them, when the pairs show the change she will have.

Run:  .venv/bin/python benchmarks/bench_learnt_operation.py     (about 2 minutes)
"""
from __future__ import annotations

import json
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table
from threadpoolctl import threadpool_limits

from bench_operations import PAIRS, against, over_breast, scanned
from timing import median_time, median_times

from breastplan.body import Body
from breastplan.plan.augmentation import augmentation
from breastplan.plan.breast_volume import measure_breasts
from breastplan.plan.implants import Implant
from breastplan.plan.learnt_operation import Pair, load_operation_model, save, train
from breastplan.plan.operation_spec import OperationSpec
from breastplan.plan.reduction import reduction
from breastplan.plan.symmetry import ptosis_from_cells
from breastplan.scenes.makehuman import make_body

SIDES = ("left", "right")


def woman(name: str, before, cup: float) -> dict:
    """One body scanned at both cups: bodies, scans, her breasts measured on her skin, and the true half-body
    change of each breast (c2 less c1, cc)."""
    small, large = make_body(before), make_body(replace(before, cup=cup))
    out = {"name": name, "bodies": (small, large), "scans": (scanned(small), scanned(large))}
    out["volumes"] = tuple(measure_breasts(Body(s[0], s[2], s[3]), s[1]) for s in out["scans"])
    out["change"] = {s: large.half_volumes_cc()[s] - small.half_volumes_cc()[s] for s in SIDES}
    return out


def pairs_of(w: dict, kind: str) -> list[Pair]:
    """Her two breasts' pairs of `kind`: augmentation c1 → c2, or reduction c2 → c1."""
    first, then = (0, 1) if kind == "augmentation" else (1, 0)
    return [Pair(w["volumes"][first], w["volumes"][then], w["scans"][first][1][s], w["scans"][then][1][s], s,
                 _spec(kind, w["change"][s]), w["name"]) for s in SIDES]


def _spec(kind: str, change_cc: float) -> OperationSpec:
    return OperationSpec.parse(f"augmentation:{change_cc:.1f}" if kind == "augmentation" else
                               f"reduction:{change_cc:.1f}:none")


def _built_in(w: dict, kind: str, side: str):
    """The built-in model's operation on her breast: the catalogue's moderate round implant of the true change, or
    the resection of it (no lift)."""
    first = 0 if kind == "augmentation" else 1
    volumes, nipple = w["volumes"][first], w["scans"][first][1][side]
    if kind == "reduction":
        return reduction(volumes, side, nipple, volume_cc=w["change"][side])
    fold = ptosis_from_cells(volumes.in_body(nipple), volumes.cells, side)["nipple_to_fold_mm"]
    return augmentation(volumes, side, nipple, fold, Implant.of(w["change"][side], "moderate"))


def held_out(women: list[dict], k: int, kind: str, folder: Path) -> list[dict]:
    """Woman k's operation made by the model learnt from the others', and by the built-in model, against the body
    she would have."""
    path = save(folder / f"{kind}-{k}.npz", train([p for j, w in enumerate(women) if j != k
                                                   for p in pairs_of(w, kind)]))
    model, w = load_operation_model(path), women[k]
    first = 0 if kind == "augmentation" else 1
    body, truth = w["bodies"][first], w["bodies"][1 - first]
    torso, nipples, _, _, camera_from_body = w["scans"][first]
    rows = []
    for side in SIDES:
        over = over_breast(body, camera_from_body, torso, side)
        learnt = model.operate(w["volumes"][first], nipples[side], side, _spec(kind, w["change"][side]))
        built = _built_in(w, kind, side)
        found = {name: against(truth, camera_from_body, op(torso), torso, over, nipples[side],
                               op(nipples[side][None])[0], side) for name, op in (("learnt", learnt),
                                                                                  ("built-in", built))}
        rows.append({"operation": kind, "woman": w["name"], "side": side, "true_change_cc": w["change"][side],
                     **{f"{name} {k}": v for name, f in found.items() for k, v in f.items()
                        if not k.startswith(("baseline", "nipple_baseline"))},
                     "as scanned surface_mean_mm": found["learnt"]["baseline_mean_mm"],
                     "as scanned nipple_mm": found["learnt"]["nipple_baseline_mm"]})
    return rows


def timed(women: list[dict], folder: Path) -> dict[str, float]:
    """Seconds: learning a model from five women's pairs; one breast's augmentation by it and by the built-in
    model, her skin moved (medians)."""
    train_set = [p for w in women[1:] for p in pairs_of(w, "augmentation")]
    model = load_operation_model(save(folder / "timed.npz", train(train_set)))
    w = women[0]
    torso, nipples = w["scans"][0][0], w["scans"][0][1]
    spec = _spec("augmentation", w["change"]["left"])
    learnt, built = median_times(lambda: model.operate(w["volumes"][0], nipples["left"], "left", spec)(torso),
                                 lambda: _built_in(w, "augmentation", "left")(torso), 7)
    return {"learning from 10 pairs": median_time(lambda: train(train_set), 3),
            "one augmentation, the clinic's model": learnt, "one augmentation, built-in (baseline)": built}


def main() -> None:
    with threadpool_limits(1, "blas"), tempfile.TemporaryDirectory() as tmp:
        women = [woman(*case) for case in PAIRS]
        rows = [r for kind in ("augmentation", "reduction") for k in range(len(women))
                for r in held_out(women, k, kind, Path(tmp))]
        seconds = timed(women, Path(tmp))
    figures = ("surface_mean_mm", "surface_p95_mm", "nipple_mm")
    summary = {}
    for kind in ("augmentation", "reduction"):
        mine = [r for r in rows if r["operation"] == kind]
        table = Table(title=f"bench_learnt_operation — {kind}, a woman left out, against the body she would have "
                            "(mm: surface mean / 95th percentile, nipple)")
        for col in ("woman", "side", "true change cc", "the clinic's model", "built-in", "as scanned"):
            table.add_column(col)
        for r in mine:
            table.add_row(r["woman"], r["side"], f"{r['true_change_cc']:.0f}",
                          *(" / ".join(f"{r[f'{m} {f}']:.1f}" for f in figures) for m in ("learnt", "built-in")),
                          f"{r['as scanned surface_mean_mm']:.1f} / — / {r['as scanned nipple_mm']:.1f}")
        Console().print(table)
        summary[kind] = {m: {f: {"median": float(np.median([r[f"{m} {f}"] for r in mine])),
                                 "worst": float(max(r[f"{m} {f}"] for r in mine))} for f in figures}
                         for m in ("learnt", "built-in")}
    for kind, by in summary.items():
        for m, figs in by.items():
            print(f"{kind:12s} {m:8s} " + "  ".join(f"{f} {v['median']:.1f} (worst {v['worst']:.1f})"
                                                     for f, v in figs.items()))
    for name, value in seconds.items():
        print(f"{name}: {value:.3f} s")
    print(json.dumps({"benchmark": "learnt_operation", "summary": summary, "seconds": seconds, "rows": rows},
                     default=float))


if __name__ == "__main__":
    main()
