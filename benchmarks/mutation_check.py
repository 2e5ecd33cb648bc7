"""Mutation check: plant plausible bugs one at a time and see whether the tests catch each one.

Copies the repository's files (`git ls-files`, untracked ones included, so new tests count) into a
temporary folder, lays the package out there as setuptools' package-dir mapping does (`breastplan` =
core/, `breastplan.deform` = deform/, … from pyproject.toml, by symbolic links) and puts that first on
PYTHONPATH: the copy, not the editable install of this working tree, is what the tests and the
`breastplan` command they run import (checked before anything runs). The unmutated copy must pass
every test file the mutants name (the baseline). Then, for each mutant, one exact source-text
replacement (a bug at two sites, such as a swap in a deformation and its inverse, is one mutant; each
original text must occur exactly once, so the script breaks loudly when the code moves) is applied,
the mutated module must still import, and the mutant's relevant test files run with
`python -m pytest -x -q -p no:cacheprovider` (serial, stopping at the first failure; the baseline runs
on two xdist workers); the file is restored afterwards. A mutant is killed when the tests fail, and
survives when they pass. Nothing in the working tree is touched.

Prints a table (mutant, where, change, verdict, the first failing test, seconds) and one JSON line:
{"figure": "mutants survived", "value": N, "target": 0, "mutants": M, ...}.

Run by hand (a few minutes; the baseline runs the slow fit and learn tests once):
    .venv/bin/python benchmarks/mutation_check.py [--only NAME ...] [--list] [--skip-baseline] [--keep] [--markdown]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from package_layout import lay_out

ROOT = Path(__file__).resolve().parents[1]
PYTEST = ["-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-p", "no:xdist", "-p", "no:dash",
          "-o", "addopts=-ra"]
"""Serial runs that stop at the first failure (the project's addopts would start two xdist workers)."""
BASELINE = ["-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:dash", "-o", "addopts=-ra -n 2"]
TIMEOUT_S = 45 * 60
"""A run that hangs this long counts as killed (by the hang), and says so."""

DEFORM = ("tests/test_reference.py", "tests/test_deformations.py", "tests/test_degree.py",
          "tests/test_inverse.py", "tests/test_databases.py", "tests/test_primitive.py")
"""The files the issue names for the deformation bugs: deformation, degree, inverse, database, primitive."""
LATTICE = ("tests/test_reference.py", "tests/test_lattice.py", "tests/test_ffd.py")
FIT = ("tests/test_reference.py", "tests/test_ffd.py", "tests/test_fit.py")
LEARN = ("tests/test_reference.py", "tests/test_learn.py", "tests/test_databases.py", "tests/test_metrics.py")
INGEST = ("tests/test_ingest.py", "tests/test_ingest_files.py")
FILTERS = ("tests/test_filters_truths.py", "tests/test_filters.py", "tests/test_meshlab.py")
BATCH = ("tests/test_batch_reuse.py", "tests/test_batch.py")


@dataclass(frozen=True)
class Mutant:
    name: str
    why: str                                   # the plausible mistake it stands for
    edits: tuple[tuple[str, str, str], ...]    # (file, original text, mutated text), one bug
    tests: tuple[str, ...]                     # relevant test files, fastest-failing first

    @property
    def module(self) -> str:
        """The importable name of the first edited file (checked to import after the mutation)."""
        path = Path(self.edits[0][0]).with_suffix("")
        top = {"core": "breastplan"}.get(path.parts[0], f"breastplan.{path.parts[0]}")
        return ".".join([top, *path.parts[1:]])


def one(name, why, file, old, new, tests) -> Mutant:
    return Mutant(name, why, ((file, old, new),), tests)


MUTANTS = [
    # --- the five the issue found surviving --------------------------------------------------------
    Mutant("top-shape-t0-t1-swapped", "β″(0) and β″(1) exchanged in top-shape and its inverse",
           (("deform/global_deformations.py", "beta(w, s0, s1, t0, t1), 1.0)", "beta(w, s0, s1, t1, t0), 1.0)"),
            ("deform/global_deformations.py", "(2 / np.pi), s0, s1, t0, t1)", "(2 / np.pi), s0, s1, t1, t0)")),
           DEFORM),
    one("ffd-stop-residual-loosened", "the FFD stopping rule 0.0015 typed as 0.005",
        "fitting/ffd.py", "STOP_RESIDUAL = 0.0015", "STOP_RESIDUAL = 0.005", FIT),
    one("generic-turn-top-0.14", "Table 4.1's generic turn-top g0 = 0.41 typed as 0.14",
        "deform/degree.py", "turn=(0.38, 0.0), turn_top=(0.41, 0.0))", "turn=(0.38, 0.0), turn_top=(0.14, 0.0))",
        ("tests/test_reference.py", "tests/test_databases.py", "tests/test_degree.py", "tests/test_inverse.py")),
    one("dataset-position-row-over-dd", "a dataset's position t = row/#dd instead of row/(#dd − 1)",
        "learn/datasets.py", "return self.row / (self.dd - 1)", "return self.row / self.dd", LEARN),
    one("learnt-position-shifted", "the learnt position off by 0.03 on the condition's line",
        "deform/by_degree.py", "model.predict(features[None, :]).reshape(-1)[0], 0.0, 1.0)",
        "model.predict(features[None, :]).reshape(-1)[0] + 0.03, 0.0, 1.0)",
        ("tests/test_reference.py", "tests/test_learn.py")),
    # --- deform ----------------------------------------------------------------------------------------
    one("bernstein-sign", "(s − 1) for (1 − s) in the Bernstein basis",
        "deform/lattice.py", "t = 1.0 - s", "t = s - 1.0", LATTICE),
    one("lattice-xy-order", "control points in meshgrid's default xy order, the basis in ij order",
        "deform/lattice.py", 'np.meshgrid(*axes, indexing="ij")', 'np.meshgrid(*axes, indexing="xy")', LATTICE),
    one("signed-extent-includes-y0", "top-shape's signed extent over y ≥ 0 instead of the upper half y > 0",
        "deform/degree.py", "upper = o[..., 1] > 0", "upper = o[..., 1] >= 0", DEFORM),
    one("turn-feature-moved-axis", "turn's moved axis copied from ptosis (y): FS5's m0 the mean y",
        "deform/descriptors.py", '"turn": (0, 2)', '"turn": (1, 2)', ("tests/test_reference.py", "tests/test_learn.py")),
    # --- core ------------------------------------------------------------------------------------------
    one("volume-a1-twice", "the closed-form volume with (a1 + a1) for (a1 + a2)",
        "core/primitive.py", "(self.a3 + self.a4) * (self.a1 + self.a2))", "(self.a3 + self.a4) * (self.a1 + self.a1))",
        ("tests/test_reference.py", "tests/test_primitive.py", "tests/test_databases.py")),
    # --- fitting ---------------------------------------------------------------------------------------
    one("ffd-residual-ratio-of-means", "the normalised residual as mean distance over mean ‖d‖",
        "fitting/ffd.py", "final = float(np.mean(dist / data_norm))", "final = float(np.mean(dist) / np.mean(data_norm))",
        FIT),
    one("ffd-smoothness-swapped", "the FFD's λ for seen and partly seen breasts exchanged",
        "fitting/breast_fit.py", "SMOOTHNESS[1] if unseen.mean() > UNSEEN_SHARE else SMOOTHNESS[0]",
        "SMOOTHNESS[0] if unseen.mean() > UNSEEN_SHARE else SMOOTHNESS[1]", ("tests/test_fit.py",)),
    one("case-source-unchecked", "a scan.npz whose source no scan comes from, or a depth camera without a camera, "
        "read as it is", "core/case.py", "        _check_source(npz, source)\n", "", ("tests/test_fit.py",)),
    one("stage-reused-from-other-code", "a case's stage reused though another breastplan's code made it",
        "core/case.py", "(found.inputs, found.options, found.code) != (wanted.inputs, wanted.options, wanted.code)",
        "(found.inputs, found.options) != (wanted.inputs, wanted.options)", ("tests/test_case.py",)),
    one("batch-reuses-other-codes-plan", "a batch reuses a finished case that another breastplan's code planned",
        "batch/task.py", "planned.options == options and planned.code == code_digest() and",
        "planned.options == options and", ("tests/test_batch_reuse.py",)),
    # --- ingest ----------------------------------------------------------------------------------------
    one("ingest-metres-factor-100", "a scan file detected in metres scaled by 100 instead of 1000",
        "ingest/files.py", 'return 1000.0, f"units m (detected', 'return 100.0, f"units m (detected', INGEST),
    one("ingest-left-right-swapped", "a mound right of the midline (patient's left) called the right breast",
        "ingest/breast.py", '"left" if centre[0] > midline_x else "right"', '"left" if centre[0] < midline_x else "right"',
        INGEST),
    one("chest-wall-front-band-40mm", "the chest wall keeps points 40 mm in front of it (the breasts) as inliers",
        "ingest/chest_wall.py", "front_mm: float = 4.0", "front_mm: float = 40.0", INGEST),
    # --- learn -----------------------------------------------------------------------------------------
    one("indirect-metric-modelled-norm", "modelled ⇒ original distances divided by ‖m‖ instead of ‖o*‖",
        "learn/metrics.py", "mo = d_mo / o_norm[nearest_o] * 100.0", "mo = d_mo / np.linalg.norm(m, axis=1) * 100.0",
        ("tests/test_metrics.py", "tests/test_reference.py")),
    one("database-volume-square-root", "the semi-axes scaled by the square root of the volume ratio",
        "learn/databases.py", "volume_cc()) ** (1 / 3)))", "volume_cc()) ** (1 / 2)))",
        ("tests/test_reference.py", "tests/test_databases.py")),
    # --- filters ---------------------------------------------------------------------------------------
    one("filter-up-ignored", "a filter's `up` not applied: the breast isolated as if the scan's up were +y",
        "filters/stages.py", "voxel_mm=recipe.voxel_mm, units=units, up=up)",
        'voxel_mm=recipe.voxel_mm, units=units, up="+y")', FILTERS),
    one("filter-units-ignored", "a filter's `units` not applied: the scan's units guessed from its extent",
        "filters/stages.py", 'None, units, name="the input")', 'None, "auto", name="the input")', FILTERS),
    one("filter-width-along-up", "the measures' left and up axes exchanged: the width taken from top to bottom",
        "filters/stages.py", "BodyLandmarks(nipple, nipple, axes[:, 0], axes[:, 1])",
        "BodyLandmarks(nipple, nipple, axes[:, 1], axes[:, 0])", FILTERS),
    one("filter-measures-input-frame", "the measures taken along the input's own axes, not the breast frame's",
        "filters/stages.py", "axes = plan.frames.breast_to_input[:3, :3]", "axes = np.eye(3)", FILTERS),
    one("filter-chain-drops-change", "a change applied to a deformed surface drops the changes it carries",
        "filters/stages.py", "[c for c in recipe.changes if c[0] != kind] + [(kind", "[(kind", FILTERS),
    one("filter-other-side-surface", "a remembered surface of one breast taken for the other side asked for",
        "filters/stages.py", 'if side not in ("auto", recipe.side):', 'if side not in ("auto", "left", "right"):',
        FILTERS),
    one("filter-isolation-memory-no-side", "an isolation remembered without its side: the right breast gets the left",
        "filters/stages.py", 'key = f"scan:{recipe.origin_key}:{_options_key(options)}"',
        'key = f"scan:{recipe.origin_key}:{_options_key(replace(options, side=SIDES[0]))}"', FILTERS),
    one("filter-remembered-fit-kept", "the cache bug: a remembered surface's own fit kept whatever lattice is asked",
        "filters/stages.py", "recipe = replace(_recipe(mesh, side), fit=fit, changes=())",
        "recipe = replace(_recipe(mesh, side), fit=_recipe(mesh, side).fit or fit, changes=())", FILTERS),
    one("filter-fit-memory-no-options", "a fit remembered by its isolation alone, not its lattice and iterations",
        "filters/stages.py", 'key = f"{scan_key}:fit:{_options_key(recipe.fit)}"', 'key = f"{scan_key}:fit"', FILTERS),
    one("filter-change-memory-no-degree", "a solved change remembered by its kind and method, not its degree",
        "filters/stages.py", "json.dumps([kind, degree, method])", "json.dumps([kind, method])", FILTERS),
    # --- batch -----------------------------------------------------------------------------------------
    one("batch-reuse-other-method", "a case planned with another --method reused",
        "batch/task.py", "planned.options == options",
        '{**planned.options, "method": None} == {**options, "method": None}', BATCH),
    one("batch-reuse-other-side", "a case planned with another --side reused",
        "batch/task.py", "planned.options == options",
        '{**planned.options, "sides": None} == {**options, "sides": None}', BATCH),
    one("batch-reuse-other-wall-from", "a case planned with another --wall-from (or none) reused",
        "batch/task.py", "planned.options == options",
        '{**planned.options, "wall_from": None} == {**options, "wall_from": None}', BATCH),
    one("batch-reuse-other-content", "a case reused though its input's content changed",
        "batch/task.py", "planned.input_sha256 == sha256", "planned.input_sha256 is not None", BATCH),
    one("batch-dead-worker-done", "a case whose worker died (every attempt) marked done",
        "batch/executors.py", '    return {"status": "failed", "seconds": 0.0,\n            "error": f"{task.input}: the worker',
        '    return {"status": "done", "seconds": 0.0,\n            "error": f"{task.input}: the worker',
        BATCH),
    one("batch-failure-succeeds", "the manifest counting a failed case as a success",
        "batch/manifest.py", 'SUCCEEDED = ("done", "reused")', 'SUCCEEDED = ("done", "reused", "failed")', BATCH),
    # --- plan ----------------------------------------------------------------------------------------
    one("plan-asymmetry-unsigned", "the measures' asymmetry kept as |left − right|, its sign lost",
        "plan/compute.py", '{k: v["left_minus_right"] for k, v in asymmetry(m).items()}',
        '{k: v["abs_difference"] for k, v in asymmetry(m).items()}',
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("plan-json-asymmetry-unsigned", "plan.json's asymmetry stored without its sign",
        "plan/record.py", '"asymmetry": m.asymmetry,',
        '"asymmetry": {w: {k: abs(v) for k, v in a.items()} for w, a in m.asymmetry.items()},',
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("plan-measures-scanned-nipple", "the as-planned measures taken at the scanned nipple, not the planned one",
        "plan/compute.py", "planned.model(nipple[None])[0]", "nipple",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("plan-symmetry-scanned-nipple", "the as-planned symmetry and ptosis taken at the scanned nipples",
        "plan/compute.py", "for when, by_side in nipples_input.items()}",
        "for when, by_side in {\"before\": nipples_input[\"before\"], \"after\": nipples_input[\"before\"]}.items()}",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("plan-volume-model-not-hers", "her volume as planned the fitted model's, not hers changed by the model's change",
        "plan/compute.py", 'measures[s]["volume_cc"] += volume - base',
        'measures[s]["volume_cc"] += 0.0',
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("surface-displacement-by-R", "a change's displacement of her surface rotated back by R instead of Rᵀ",
        "plan/surface.py", "@ first.to_primitive[:3, :3]   # back by", "@ first.to_primitive[:3, :3].T   # back by",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("record-scan-shift-by-Rt", "the scan's displacement taken to the breast frame by Rᵀ instead of R",
        "plan/record.py", "@ to_breast[:3, :3].T", "@ to_breast[:3, :3]",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("record-scan-points-breast-frame", "the scan's points (breast frame) displaced as if in the input frame",
        "plan/record.py", "planned.displacement(transform_points(sp.frames.breast_to_input, sp.scan.points))",
        "planned.displacement(sp.scan.points)",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("surface-band-doubled", "the blend's band taken as a whole footprint radius instead of half",
        "plan/surface.py", "smoothstep((self.footprint_radius(local_mm) - 1.0) / self.band)",
        "smoothstep((self.footprint_radius(local_mm) - 1.0) / (2 * self.band))",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("surface-band-constant", "BAND typed as a quarter of the footprint radius",
        "plan/surface.py", "BAND = 0.5", "BAND = 0.25",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("surface-seam-constant", "SEAM typed as half of a3",
        "plan/surface.py", "SEAM = 0.25", "SEAM = 0.5",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("smoothstep-cubic", "the cubic (C¹) smoothstep 3s² − 2s³ for the quintic C² one",
        "plan/surface.py", "1.0 - s * s * s * (s * (6.0 * s - 15.0) + 10.0)", "1.0 - s * s * (3.0 - 2.0 * s)",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("smoothstep-coefficient", "the quintic's 15 typed as 16",
        "plan/surface.py", "(6.0 * s - 15.0) + 10.0)", "(6.0 * s - 16.0) + 10.0)",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("footprint-medial-lateral-swapped", "the footprint's x semi-axes a1 (+x), a2 (−x) exchanged",
        "plan/surface.py", "ax = np.where(local_mm[:, 0] >= 0, p.a1, p.a2) * MM_PER_MU",
        "ax = np.where(local_mm[:, 0] >= 0, p.a2, p.a1) * MM_PER_MU",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("seam-fade-inverted", "top-shape faded out above y = 0 instead of in",
        "plan/surface.py", "fade = 1.0 - smoothstep(p_mu[:, 1] / (SEAM * self.primitive.a3))",
        "fade = smoothstep(p_mu[:, 1] / (SEAM * self.primitive.a3))",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("seam-split-wrong-kind", "the seam fades in every kind before turn, not top-shape alone",
        "plan/surface.py", 'self.deformation.split("flatten-side")', 'self.deformation.split("turn")',
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("combine-keeps-last-kind", "the combination keeps only the last change's kind",
        "plan/changes.py", "deformation = deformation.plus(kind, change.deformation.params(kind))",
        "deformation = Deformation.single(kind, change.deformation.params(kind))",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("combine-drops-last-change", "the combination of all but the last requested change",
        "plan/compute.py", "[combine(singles)]", "[combine(singles[:-1])]",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("slider-state-requested-degree", "a slider state solved at the requested degree instead of its own",
        "plan/compute.py", "or solve_change(sp.local_surface, kind, degree, sp.primitive, method)",
        "or solve_change(sp.local_surface, kind, requested, sp.primitive, method)",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("slider-degrees-to-7", "the slider's degrees 1..7, degree 8 left out",
        "plan/compute.py", "map(float, range(1, 9))", "map(float, range(1, 8))",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("state-first-sides-change", "each side's state planned with the first side's change",
        "plan/compute.py", "PlannedChange.of(sp, changes[s], operated.get(s))",
        "PlannedChange.of(sp, changes[next(iter(changes))], operated.get(s))",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("state-first-sides-frames", "each side's change placed in the first side's frames",
        "plan/compute.py", "PlannedChange.of(sp, changes[s], operated.get(s))",
        "PlannedChange.of(next(iter(sides.values())), changes[s], operated.get(s))",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("views-first-sides-state", "the report draws every side with the first side's planned change",
        "plan/views.py", "PlannedChange.displacements(plan.grid.planned[s], patch_in)",
        "PlannedChange.displacements(plan.grid.planned[next(iter(plan.sides))], patch_in)",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("planned-torso-one-side", "her planned torso moved by the last side's change only",
        "plan/compute.py", "moved += state.planned[side].displacement(body.torso_input)",
        "moved = body.torso_input + state.planned[side].displacement(body.torso_input)",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("frames-right-mirrored", "the right breast mirrored in x instead of the left",
        "plan/result.py", 'np.diag([-1.0, 1.0, 1.0, 1.0]) if side == "left"',
        'np.diag([-1.0, 1.0, 1.0, 1.0]) if side == "right"',
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("frames-composed-backwards", "input → primitive composed in the wrong order",
        "plan/result.py", "return self.breast_to_primitive @ self.input_to_breast",
        "return self.input_to_breast @ self.breast_to_primitive",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("left-primitive-not-swapped", "a left breast's a1, a2 not exchanged with its mirror",
        "plan/result.py", 'return replace(p, a1=p.a2, a2=p.a1) if self.side == "left" else p', "return p",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("symmetry-overlap-unmirrored", "the overlap compares each breast with itself, not the other's mirror image",
        "plan/symmetry.py", "np.minimum(h, h[::-1])", "np.minimum(h, h)",
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("symmetry-bra-unfolded", "pBRA from the nipples' x as they are, not folded onto one side",
        "plan/symmetry.py", "np.array([abs(p[0]), p[1], p[2]])", "np.array([p[0], p[1], p[2]])",
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("symmetry-bcd-unmirrored", "BCD against the other outline itself, not its mirror image",
        "plan/symmetry.py", 'regions["right"][::-1])', 'regions["right"])',
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("ptosis-grade-ii-20mm", "Regnault's grade II band ending 2 cm below the fold, not 3",
        "plan/symmetry.py", "GRADE_I_MM, GRADE_II_MM = 10.0, 30.0", "GRADE_I_MM, GRADE_II_MM = 10.0, 20.0",
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("ptosis-grade-i-15mm", "Regnault's grade I band ending 1.5 cm below the fold, not 1",
        "plan/symmetry.py", "GRADE_I_MM, GRADE_II_MM = 10.0, 30.0", "GRADE_I_MM, GRADE_II_MM = 15.0, 30.0",
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("ptosis-at-fold-0", "a nipple anywhere above the fold graded 0, no 5 mm at the fold",
        "plan/symmetry.py", "AT_FOLD_MM = 5.0", "AT_FOLD_MM = 0.0",
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("ptosis-pseudo-30mm", "pseudoptosis from a gland 3 cm below the fold, not 2",
        "plan/symmetry.py", "PSEUDO_MM = 20.0", "PSEUDO_MM = 30.0",
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("ptosis-at-lowest-5mm", "grade II with the nipple 5 mm above the lower contour, not 10",
        "plan/symmetry.py", "AT_LOWEST_MM = 10.0", "AT_LOWEST_MM = 5.0",
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("ptosis-hang-slope", "the hidden fold's slope 0.45 typed as 0.54",
        "plan/symmetry.py", "HANG_SLOPE = 0.45", "HANG_SLOPE = 0.54",
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("ptosis-grade-ii-any-nipple", "grade II without the nipple above the lower contour",
        "plan/symmetry.py", 'return "II" if to_fold >= -GRADE_II_MM and to_lowest > AT_LOWEST_MM else "III"',
        'return "II" if to_fold >= -GRADE_II_MM else "III"',
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("volume-negative-heights", "skin behind the wall subtracted from the volume",
        "plan/breast_volume.py", "float(np.clip(height[mask], 0.0, None).sum())", "float(height[mask].sum())",
        ("tests/test_breast_volume.py", "tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("volume-cell-area-linear", "a cell's area taken as CELL_MM, not CELL_MM²",
        "plan/breast_volume.py", "float(np.clip(height[mask], 0.0, None).sum()) * CELL_MM ** 2 / 1000.0",
        "float(np.clip(height[mask], 0.0, None).sum()) * CELL_MM / 1000.0",
        ("tests/test_breast_volume.py", "tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("volume-footprint-unmirrored", "each footprint not joined with the other's mirror image",
        "plan/breast_volume.py", "footprint |= own | own[::-1]", "footprint |= own",
        ("tests/test_breast_volume.py", "tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("lift-steep-skin-not-faded", "a lift's move forward or back not faded on skin seen edge-on",
        "plan/mastopexy.py", "        forward *= np.minimum(*steep)\n", "", ("tests/test_mastopexy.py",)),
    one("fold-drawn-on-her-breast", "a fold her breast hides drawn at her skin's height there, on her breast",
        "plan/symmetry.py", 'if found["fold_from"] == "seen" else 0.0)', ")", ("tests/test_plan.py",)),
    one("plan-fold-of-the-model", "nipple to fold measured to the fitted model's base, not to her fold as found",
        "plan/compute.py", "folds = {s: her_fold(volumes, sp) for s, sp in sides.items()}",
        "folds = {s: None for s in sides}",
        ("tests/test_plan.py",)),
    Mutant("plan-width-of-the-model", "her width taken from the fitted model's base outline, not measured on her skin",
           (("plan/compute.py", '"width_mm": widths[side]})', '"width_mm": fitted[side]["width_mm"]})'),
            ("plan/compute.py", '["width_mm"] += widths[s] - fitted[s]["width_mm"]', '["width_mm"] += 0.0')),
           ("tests/test_plan_repeats.py",)),
    one("lift-skin-torn-at-border", "a lift's skin risen whole up to her footprint's border, torn from her chest",
        "plan/mastopexy.py", "weight=weight * _inside(cells, mask, nipple),", "weight=weight,",
        ("tests/test_mastopexy.py",)),
    one("plan-poles-of-the-model", "as planned, her poles left as the fitted model's, not splitting her volume",
        "plan/compute.py", "        measures[s] = poles_of_her_volume(measures[s])\n", "",
        ("tests/test_plan.py",)),
    one("camera-distance-first-nipple", "the camera's distance taken to the first nipple, not to their midpoint",
        "plan/camera_distance.py", "np.mean([np.asarray(n, float) for n in nipples_from_camera.values()], axis=0)",
        "np.asarray(next(iter(nipples_from_camera.values())), float)",
        ("tests/test_camera_distance.py", "tests/test_plan.py")),
    one("camera-apart-one-way", "two visits said apart only when the later one stood further away",
        "plan/camera_distance.py", "abs(now_mm - then_mm) > APART_MM", "now_mm - then_mm > APART_MM",
        ("tests/test_camera_distance.py",)),
    one("batch-measures-left-for-both", "measures.csv giving her right breast her left's nipple distances",
        "plan/plan_file.py", 'before = _at(record, "measures", "before", side) or {}',
        'before = _at(record, "measures", "before", "left") or {}', ("tests/test_batch.py",)),
    one("batch-measures-not-of-reused", "measures.csv leaving out the cases a batch reused",
        "batch/manifest.py", 'for r in self.rows if r.status in SUCCEEDED\n', 'for r in self.rows if r.status == "done"\n',
        ("tests/test_batch.py",)),
    one("unseen-outer-side-inward", "her unseen outer side taken past the footprint's edge towards her midline",
        "plan/breast_volume.py", "outward = slice(1, None) if side == \"left\" else slice(None, -1)",
        "outward = slice(None, -1) if side == \"left\" else slice(1, None)",
        ("tests/test_breast_volume.py", "tests/test_wrapped_scans.py")),
    one("volume-unseen-mirrored-in-y", "an unseen cell filled from the cell mirrored top to bottom, not left to right",
        "plan/breast_volume.py", "np.where(np.isfinite(skin), h, h[::-1] * mirror_scale(h))",
        "np.where(np.isfinite(skin), h, h[:, ::-1] * mirror_scale(h))",
        ("tests/test_breast_volume.py", "tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("volume-area-per-1000", "the footprint's area in cm² divided by 1000 instead of 100",
        "plan/breast_volume.py", "area_cm2 = float(mask.sum() * CELL_MM ** 2 / 100.0)",
        "area_cm2 = float(mask.sum() * CELL_MM ** 2 / 1000.0)",
        ("tests/test_breast_volume.py", "tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("earlier-footprint-mirrored-in-y", "the earlier visit's grown footprint mirrored top to bottom",
        "plan/breast_volume.py", "return now, grown | grown[::-1]", "return now, grown | grown[:, ::-1]",
        ("tests/test_breast_volume.py", "tests/test_plan_truths.py", "tests/test_follow_up.py")),
    one("skin-change-on-wall-sign", "a follow-up's change on the earlier wall taken as before − after",
        "plan/compute.py", "SkinChange(before, after - before, 100.0 * (after - before) / before, alone,",
        "SkinChange(before, before - after, 100.0 * (before - after) / before, alone,",
        ("tests/test_plan_truths.py", "tests/test_follow_up.py")),
    one("skin-change-alone-sign", "a follow-up's change on each visit's own wall taken as then − now",
        "plan/compute.py", "alone = volumes.sides[side].volume_cc - then.volume_cc",
        "alone = then.volume_cc - volumes.sides[side].volume_cc",
        ("tests/test_plan_truths.py", "tests/test_follow_up.py")),
    one("measures-first-change", "the measures as planned taken at the first slider state, not the combination",
        "plan/compute.py", "grid.measures_at(grid.planned_index))", "grid.measures_at(0))",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("measures-first-torso", "the symmetry as planned measured on the first change's torso",
        "plan/compute.py", "plan_measures(sides, volumes, widths, requested[-1], torsos[-1],",
        "plan_measures(sides, volumes, widths, requested[-1], torsos[0],",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("symmetry-after-unmoved-skin", "the symmetry as planned measured on her skin as scanned",
        "plan/compute.py", '"after": cells.moved(transform_points(T, torso))', '"after": cells',
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("shown-first-change", "the plan leading with its first change instead of the combination",
        "plan/result.py", "return self.changes[-1]", "return self.changes[0]",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("record-model-blended", "the planned model written blended into the chest instead of fully changed",
        "plan/record.py", "planned.model(sp.surface_input))", "planned(sp.surface_input))",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("views-torso-last-side", "the report's torso moved by the last side's change only",
        "plan/views.py", "moved = shift if moved is None else np.add(moved, shift, out=moved)", "moved = shift",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("local-surface-input-frame", "degrees solved on the fitted surface taken from the input frame, not the breast's",
        "plan/result.py", "transform_points(self.frames.breast_to_primitive, self.fit.vertices)",
        "transform_points(self.frames.input_to_primitive, self.fit.vertices)",
        ("tests/test_plan_truths.py", "tests/test_plan.py")),
    one("symmetry-lbc-highest", "a breast's lower contour taken at its highest column, not its lowest",
        "plan/symmetry.py", "k = int(np.nanargmin(edge))", "k = int(np.nanargmax(edge))",
        ("tests/test_symmetry.py", "tests/test_plan_truths.py")),
    one("symmetry-hidden-contour-ignored", "a lower contour on a hidden cell not said to be hidden",
        "plan/symmetry.py", "return float(edge[k]), bool(cells.seen[k, np.argmax(region[k])])",
        "return float(edge[k]), True", ("tests/test_symmetry.py",)),
    # --- operations in a plan -----------------------------------------------------------------------
    one("model-not-operated", "the fitted model as planned left without her operations",
        "plan/surface.py", "start = first._before(np.asarray(vertices_mm, dtype=float).reshape(-1, 3))",
        "start = np.asarray(vertices_mm, dtype=float).reshape(-1, 3)",
        ("tests/test_plan_truths.py", "tests/test_plan_operations.py")),
    one("operated-volume-grown-skin", "her volume after an operation counting her skin its grown footprint took in",
        "plan/operated.py", "volume = now.sides[side].volume_cc + cells.volume_cc(side) - grown.volume_cc(side)",
        "volume = cells.volume_cc(side)", ("tests/test_plan_operations.py", "tests/test_symmetrising.py")),
    one("page-nipples-not-operated", "the report's marks (her nipples among them) left where they were found on an "
        "operated state", "plan/report.py",
        "const m=state&&shownD?F.map((p,r)=>p.map((v,c)=>v+shownD[markAt+3*(a+r)+c])):F;", "const m=F;",
        ("tests/test_plan_operations.py",)),
    one("lift-heights-from-below-the-arrival", "a lift's heights taken from the rise lower down, the rise read where "
        "the skin arrives, not carried by the map its points move by",
        "plan/mastopexy.py", "np.interp(y_mm, to[i], height_mm[i])", "np.interp(y_mm - (to[i] - y_mm), y_mm, height_mm[i])",
        ("tests/test_mastopexy.py",)),
    one("batch-plan-file-ignored", "a batch planning a scan with its own plan file as every other",
        "batch/run.py", "plan = {**_her_plan(options.plan, i.plan_file).as_dict(), \"wall_from\": earlier}",
        "plan = {**options.plan.as_dict(), \"wall_from\": earlier}", ("tests/test_batch_plan_files.py",)),
    # --- a clinic's own model of an operation -----------------------------------------------------------
    one("learnt-field-not-mirrored", "a clinic's model laying its field on a right breast unmirrored",
        "plan/learnt_operation.py", "np.meshgrid((cells.x - nipple[0]) * _outwards(side),",
        "np.meshgrid((cells.x - nipple[0]),",
        ("tests/test_learnt_operation.py",)),
    one("learnt-skin-not-sliding", "her skin left in place across her body where a clinic's model moves her nipple",
        "plan/learnt_operation.py", "return np.column_stack([across, forward]) @ T[:3, :3]",
        "return np.column_stack([0.0 * across, forward]) @ T[:3, :3]", ("tests/test_learnt_operation.py",)),
    one("learnt-fall-behind-wall", "a clinic's reduction sinking her skin behind her chest wall",
        "plan/learnt_operation.py", "lift = np.maximum(lift, -np.clip(cells.height_mm, 0.0, None))", "lift = lift",
        ("tests/test_learnt_operation.py",)),
    one("learnt-share-per-cell", "a clinic's reduction learning each cell's share alone, one stray height and all",
        "plan/learnt_operation.py", "SHARE_SIGMA_MM = CELL_MM", "SHARE_SIGMA_MM = 0.0", ("tests/test_learnt_operation.py",)),
    one("operation-model-unused", "a plan making an operation by the built-in model where a clinic's was given",
        "plan/operated.py", "if spec.kind in models", "if False", ("tests/test_learnt_operation_cli.py",)),
    one("skin-torn-beneath-breast", "her skin left torn in two beneath a breast that hangs",
        "plan/views.py", "keep[hidden] = beneath(points_view[faces[hidden]].mean(axis=1))", "pass",
        ("tests/test_skin_surface.py",)),
    one("marks-stay-where-found", "the nipples, footprints and folds left where found while a slider moves her skin",
        "plan/report.py", "const m=state&&shownD?", "const m=false?", ("tests/test_plan.py",)),
    one("reader-crash-not-probed", "a file that crashes MeshLab's reader read in this process",
        "ingest/files.py", "crash = crash_of(lambda: pymeshlab.MeshSet().load_new_mesh(str(path), **gltf))",
        "crash = None", ("tests/test_reader_crashes.py",)),
    one("case-link-followed", "a case folder's symbolic link followed where a plan writes",
        "plan/stages.py", "    _check_own_files(source)\n", "", ("tests/test_case_is_one_patients.py",)),
    one("copied-case-fault-names-copy", "a fault of a copied case naming the hidden copy",
        "plan/stages.py", "with clock(\"fit\"), _named_in(source, folder):", "with clock(\"fit\"):",
        ("tests/test_case_is_one_patients.py",)),
    one("follow-up-of-another-patient-id", "a follow-up measured on another patient ID's earlier plan",
        "plan/stages.py", "if then is not None and then.patient_id and then.patient_id != patient_id:",
        "if False:", ("tests/test_follow_up.py",)),
    one("worker-death-charges-all", "a batch charging every case planned beside the one whose worker died",
        "batch/executors.py", "if not solo and len(suspects) > 1:", "if False:", ("tests/test_batch_worker_death.py",)),
    one("slider-off-applies-its-kind", "a slider at off still applying its kind's change at its first degree",
        "plan/compute.py", "for k, d in zip(kinds, combo) if d != OFF] for combo in combos]",
        "for k, d in zip(kinds, [c or 1.0 for c in combo])] for combo in combos]", ("tests/test_plan_truths.py",)),
    one("volume-said-against-before", "a state's volume words counted from her breasts as scanned, not from every "
        "slider off after the operations", "plan/handout.py", "off = grid.index((OFF,) * len(grid.kinds))",
        "off = grid.index((OFF,) * len(grid.kinds)) + 1", ("tests/test_plan_truths.py",)),
    one("hole-round-nipple-accepted", "a scan with a hole where her breast is measured round the hole",
        "plan/breast_volume.py", "            if seen < AROUND_SEEN:", "            if seen < 0.0:",
        ("tests/test_breast_volume.py",)),
    one("wall-taken-for-her", "a flat wall half, seen from behind her, taken for her trunk",
        "ingest/pipeline.py", "    found = [None if body is None or _flat(body) else body for body in found]", "",
        ("tests/test_background.py",)),
]


# --- the copy -------------------------------------------------------------------------------------
def tracked_files() -> list[str]:
    out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                         check=True, capture_output=True).stdout.decode()
    return sorted({f for f in out.split("\0") if f and (ROOT / f).is_file()})


def make_copy(folder: Path) -> tuple[Path, Path]:
    """(repository copy, site folder holding the `breastplan` package laid out from the copy)."""
    repo, site = folder / "repo", folder / "site"
    for f in tracked_files():
        (repo / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / f, repo / f)
    return repo, lay_out(repo, site)


def environment(site: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
    env["PYTHONDONTWRITEBYTECODE"] = "1"     # a same-size mutation within one second must not reuse a .pyc
    return env


def check_imports_from_copy(repo: Path, site: Path, env: dict) -> str:
    """The interpreter and the `breastplan` command the tests run both import the copy; returns its path."""
    code = ("import breastplan, breastplan.deform.global_deformations as g, breastplan.cli.main as m;"
            "print(breastplan.__file__); print(g.__file__); print(m.__file__)")
    out = subprocess.run([sys.executable, "-c", code], cwd=repo, env=env, capture_output=True, text=True, check=True)
    paths = out.stdout.split()
    if not all(Path(p).is_relative_to(site) for p in paths):
        raise SystemExit(f"the package does not import from the copy: {paths}")
    script = Path(sys.executable).with_name("breastplan")        # what the tests' `cli` fixture runs
    first = script.read_text().splitlines()[0] if script.exists() else ""
    if not first.startswith("#!") or Path(first[2:].strip()).resolve() != Path(sys.executable).resolve():
        raise SystemExit(f"{script} does not run {sys.executable}, so it may not import the copy")
    return paths[0]


# --- running --------------------------------------------------------------------------------------
def first_failure(output: str) -> str:
    for line in output.splitlines():
        if line.startswith(("FAILED ", "ERROR ")):
            return line.split(" ", 1)[1].split(" - ")[0].removeprefix("tests/")
    return ""


def run_tests(args: list[str], files, repo: Path, env: dict) -> tuple[int, str, float]:
    start = time.perf_counter()
    try:
        res = subprocess.run([sys.executable, *args, *files], cwd=repo, env=env, capture_output=True,
                             text=True, timeout=TIMEOUT_S)
        code, output = res.returncode, res.stdout + res.stderr
    except subprocess.TimeoutExpired:
        code, output = -1, "timed out"
    return code, output, time.perf_counter() - start


def mutate(repo: Path, mutant: Mutant) -> dict[Path, str]:
    """Apply the mutant's edits; returns the original texts to restore. Each original text must
    occur exactly once in its file."""
    originals = {}
    for file, old, new in mutant.edits:
        path = repo / file
        text = originals.get(path) or path.read_text()
        originals.setdefault(path, text)
        current = path.read_text()
        if current.count(old) != 1:
            raise SystemExit(f"{mutant.name}: '{old}' occurs {current.count(old)} times in {file}, "
                             "not once: the code moved; update the mutant")
        path.write_text(current.replace(old, new))
    return originals


def line_of(repo: Path, file: str, old: str) -> int:
    text = (repo / file).read_text()
    return text[: text.index(old)].count("\n") + 1


def run_mutant(repo: Path, env: dict, mutant: Mutant) -> dict:
    where = ", ".join(f"{f}:{line_of(repo, f, old)}" for f, old, _ in mutant.edits)
    originals = mutate(repo, mutant)
    try:
        imp = subprocess.run([sys.executable, "-c", f"import {mutant.module}"], cwd=repo, env=env,
                             capture_output=True, text=True)
        if imp.returncode != 0:
            raise SystemExit(f"{mutant.name} breaks the import of {mutant.module}; a mutant must be a "
                             f"plausible bug, not a crash:\n{imp.stderr[-2000:]}")
        code, output, seconds = run_tests(PYTEST, mutant.tests, repo, env)
    finally:
        for path, text in originals.items():
            path.write_text(text)
    if code == 5:
        raise SystemExit(f"{mutant.name}: no tests collected from {mutant.tests}")
    verdict = "killed" if code in (1, 2) else ("killed (hang)" if code == -1 else
                                               "survived" if code == 0 else f"error {code}")
    return {"name": mutant.name, "why": mutant.why, "where": where, "change": mutant.edits[0][1:],
            "verdict": verdict, "killed_by": first_failure(output) if code else "", "seconds": round(seconds, 1),
            "tests": list(mutant.tests), "tail": output.strip().splitlines()[-3:] if code in (0, 2) else []}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run only these mutants")
    ap.add_argument("--list", action="store_true", help="list the mutants and exit")
    ap.add_argument("--skip-baseline", action="store_true", help="do not first run the tests on the unmutated copy")
    ap.add_argument("--keep", action="store_true", help="keep the temporary copy")
    ap.add_argument("--markdown", action="store_true", help="also print the table as Markdown (for the README)")
    args = ap.parse_args()
    console = Console(width=None if sys.stdout.isatty() else 200)
    mutants = MUTANTS
    if args.only:
        unknown = set(args.only) - {m.name for m in MUTANTS}
        if unknown:
            raise SystemExit(f"unknown mutants {sorted(unknown)}; --list shows them")
        mutants = [m for m in MUTANTS if m.name in args.only]
    if args.list:
        for m in MUTANTS:
            console.print(f"{m.name:32s} {m.edits[0][0]:30s} {m.why}")
        return

    start = time.perf_counter()
    folder = Path(tempfile.mkdtemp(prefix="breastplan-mutants-"))
    try:
        repo, site = make_copy(folder)
        env = environment(site)
        imported = check_imports_from_copy(repo, site, env)
        console.print(f"copy: {repo} (breastplan imports from {imported})")
        for m in mutants:                              # every original text once, before spending time
            for file, old, _ in m.edits:
                if (repo / file).read_text().count(old) != 1:
                    raise SystemExit(f"{m.name}: '{old}' does not occur exactly once in {file}")
        baseline_s = None
        if not args.skip_baseline:
            files = list(dict.fromkeys(f for m in mutants for f in m.tests))
            console.print(f"baseline: {len(files)} test files on the unmutated copy …")
            code, output, baseline_s = run_tests(BASELINE, files, repo, env)
            if code != 0:
                console.print(escape(output[-4000:]))
                raise SystemExit(f"the unmutated copy fails its tests (exit {code}): fix them first")
            console.print(f"baseline passed in {baseline_s:.0f} s: {output.strip().splitlines()[-1]}")
        results = []
        for m in mutants:
            r = run_mutant(repo, env, m)
            results.append(r)
            style = "green" if r["verdict"].startswith("killed") else "red"
            console.print(f"[{style}]{r['verdict']:>8}[/] {m.name} ({r['seconds']} s) {escape(r['killed_by'])}")
    finally:
        if args.keep:
            console.print(f"kept {folder}")
        else:
            shutil.rmtree(folder, ignore_errors=True)
    total = time.perf_counter() - start

    table = Table(title="mutation check: one planted bug at a time, its relevant tests (pytest -x)",
                  title_justify="left")
    for col in ("mutant", "the bug", "where", "change", "verdict", "first failing test", "s"):
        table.add_column(col, overflow="fold")
    for r in results:
        old, new = r["change"]
        table.add_row(escape(r["name"]), escape(r["why"]), escape(r["where"]), escape(f"{old} → {new}"),
                      f"[green]{r['verdict']}[/]" if r["verdict"].startswith("killed") else f"[red]{r['verdict']}[/]",
                      escape(r["killed_by"]), f"{r['seconds']:.1f}")
    console.print(table)
    if args.markdown:
        print("| mutant | the bug | where | verdict | first failing test | s |\n|---|---|---|---|---|---:|")
        for r in results:
            print(f"| `{r['name']}` | {r['why']} | `{r['where']}` | {r['verdict']} | `{r['killed_by']}` | {r['seconds']:.1f} |")
    survivors = [r["name"] for r in results if not r["verdict"].startswith("killed")]
    for r in results:
        if r["tail"]:
            console.print(escape(f"{r['name']}: {' | '.join(r['tail'])}"))
    print(json.dumps({"figure": "mutants survived", "value": len(survivors), "target": 0, "mutants": len(results),
                      "killed": len(results) - len(survivors), "survivors": survivors,
                      "seconds": round(total, 1), "baseline_seconds": None if baseline_s is None else round(baseline_s, 1),
                      "mutant_seconds": {r["name"]: r["seconds"] for r in results}}))


if __name__ == "__main__":
    main()
