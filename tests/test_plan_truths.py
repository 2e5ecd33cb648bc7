"""A plan of the bundled sample (`plan.result.Plan`, planned once) against truths computed here, not by
plan/: every state's planned breast is tests/reference_model.py's deformation of her fitted breast at
that state's parameters, and those parameters give the state's degree by the reference model; the
report's drawing, the written displacements of her scan and torso and the as-planned measures are
that same deformation (blended into her chest as docs/cli.md states it: a C² quintic step over half
a footprint radius, top-shape faded in over the first quarter of a3); plan.json's asymmetry is
left − right of its own per-side measures, signed; a follow-up's change on her skin has the sign and
size of tissue added in closed form.

Frames are taken from the case's data (the scan's input → breast transform, the fit's pose, a left
breast mirrored in x as docs/model.md §1 plans it), not from `plan.result.BreastFrames`.
"""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

import reference_model as ref

from breastplan import read_ply, transform_points
from breastplan.body import Body

CHANGES = ("ptosis:3", "turn:2.5", "top-shape:4")
KINDS = ("ptosis", "turn", "top-shape")
REQUESTED = {"ptosis": 3.0, "turn": 2.5, "top-shape": 4.0}
CONDITION = {"ptosis": "ptosis b0>b1", "turn": "turn c0>c1", "top-shape": "top-shape s1->s0+"}
"""Each kind's default condition (docs/model.md §4)."""
DD = 8
BAND = 0.5
"""docs/cli.md: a change fades out over a band of half the breast's footprint radius around its base."""
SEAM = 0.25
"""docs/cli.md: top-shape is faded in over the first quarter of the upper semi-axis on her surface."""
MIRROR_X = np.diag([-1.0, 1.0, 1.0, 1.0])
VIEW_TO_DISPLAY = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])
"""The report's display frame (x right, y away from the viewer, z up) from the viewing frame (x right,
y down, z away): (x, y, z) → (x, z, −y)."""
TOL_MM = 1e-6


@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    """(the sample planned as a value, its case folder, its plan.json), planned once."""
    from breastplan.options import PlanOptions
    from breastplan.plan.job import run_plan

    case = tmp_path_factory.mktemp("truths") / "case"
    plan = run_plan(None, case, PlanOptions.parse(list(CHANGES)))
    return plan, case, json.loads((case / "plan.json").read_text())


# --- the truths, written here --------------------------------------------------------------------
def quintic_step(s) -> np.ndarray:
    """C² step from 1 (s ≤ 0) to 0 (s ≥ 1): 1 − (6s⁵ − 15s⁴ + 10s³) (docs/cli.md's C² step)."""
    s = np.clip(np.asarray(s, float), 0.0, 1.0)
    return 1.0 - (6 * s**5 - 15 * s**4 + 10 * s**3)


class Breast:
    """One side's fitted breast with its frames from the case's data: input → breast (the scan's),
    breast → anatomical primitive frame (the fit's pose inverted; a left breast mirrored in x, its a1 and
    a2 exchanged)."""

    def __init__(self, sp):
        self.side = sp.side
        self.input_to_breast = np.asarray(sp.scan.input_to_breast, float)
        self.breast_to_local = (MIRROR_X if sp.side == "left" else np.eye(4)) @ np.linalg.inv(sp.fit.pose)
        self.input_to_local = self.breast_to_local @ self.input_to_breast
        p = sp.fit.primitive
        a1, a2 = (p.a2, p.a1) if sp.side == "left" else (p.a1, p.a2)
        self.prim = (a1, a2, p.a3, p.a4, p.a5, p.eps1, p.eps2)
        self.fitted_input = transform_points(np.linalg.inv(self.input_to_breast), sp.fit.vertices)
        self.faces = sp.fit.faces

    def local(self, points_input):
        return transform_points(self.input_to_local, points_input)

    def to_input(self, points_local):
        return transform_points(np.linalg.inv(self.input_to_local), points_local)

    def model(self, points_input, vector) -> np.ndarray:
        """Input-frame points moved by the reference model's deformation (the full change), input frame."""
        return self.to_input(ref.mm(ref.deform(ref.mu(self.local(points_input)), self.prim, vector)))

    def radius(self, local_mm) -> np.ndarray:
        """Normalised radius over the base superellipse's semi-axes a1..a4 (1 on the footprint's rim)."""
        a1, a2, a3, a4 = (ref.MM_PER_MU * a for a in self.prim[:4])
        return np.hypot(local_mm[:, 0] / np.where(local_mm[:, 0] >= 0, a1, a2),
                        local_mm[:, 1] / np.where(local_mm[:, 1] >= 0, a3, a4))

    def blended_local(self, local_mm, vector) -> np.ndarray:
        """The displacement of primitive-frame points on her surface (mm, primitive frame): the full change
        on the footprint, top-shape faded in over 0 < y < SEAM·a3, the whole faded out over the band."""
        p = ref.mu(local_mm)
        top = ref.with_kind(np.zeros(12), "top-shape", np.asarray(vector)[ref.SLICES["top-shape"]])
        rest = np.array(vector, float)
        rest[ref.SLICES["top-shape"]] = 0.0
        fade = 1.0 - quintic_step(p[:, 1] / (SEAM * self.prim[2]))
        seamed = p + (ref.deform(p, self.prim, top) - p) * fade[:, None]
        moved = ref.mm(ref.deform(seamed, self.prim, rest))
        w = quintic_step((self.radius(local_mm) - 1.0) / BAND)
        return (moved - local_mm) * w[:, None]


def vector_of(change) -> np.ndarray:
    """The 12-vector of a change: each of its kinds' parameters as solved (docs/model.md §3)."""
    v = np.zeros(12)
    for d in change.details:
        v = ref.with_kind(v, d["kind"], d["params"])
    return v


_extents: dict = {}


def ref_degree(kind, fitted_input, moved_input, breast: Breast) -> float:
    """The reference model's continuous degree of a planned breast against the fitted one (docs §5)."""
    name = CONDITION[kind]
    if name not in _extents:
        _extents[name] = ref.reference_extents(name, DD)
    fitted, moved = (ref.mu(breast.local(p)) for p in (fitted_input, moved_input))
    return float(ref.continuous_degree(ref.condition_extent(name, fitted, moved, breast.prim[4]), _extents[name]))


def divergence_volume_cc(vertices, faces) -> float:
    tri = np.asarray(vertices)[faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6000.0)


# --- every state --------------------------------------------------------------------------------
def test_the_states_are_each_kinds_slider_degrees_and_the_combination(sample):
    """The report's states: for each requested kind, in order, the degrees 1..8 and the requested one,
    then the combination of the requested changes (kind and degree None)."""
    plan, _, _ = sample
    want = [(k, d) for k in KINDS for d in sorted({*range(1, 9), REQUESTED[k]})]
    assert [(st.kind, st.degree) for st in plan.states[:-1]] == want
    assert [st.key for st in plan.states[:-1]] == [f"{k}-{d:g}" for k, d in want]
    last = plan.states[-1]
    assert (last.key, last.kind, last.degree) == ("combined", None, None)
    assert [st.key for st in plan.changes] == ["ptosis-3", "turn-2.5", "top-shape-4", "combined"]


def test_every_states_planned_breast_is_the_reference_models_deformation_of_her_fitted_breast(sample):
    """Each state of the report (`Plan.states`), each side: the planned breast (`PlanState.planned[side]
    .model` of the fitted surface) is tests/reference_model.py's deformation of the fitted surface at the
    state's parameters — its own kind's for a slider state, every requested kind's, in docs §3 order, for
    the combination — within 1e-6 mm; and the change is the side's own (its details the state's kind and
    degree)."""
    plan, _, _ = sample
    breasts = {s: Breast(sp) for s, sp in plan.sides.items()}
    for st in plan.states:
        for side, b in breasts.items():
            change = st.changes[side]
            if st.kind is None:
                assert [(d["kind"], d["degree"]) for d in change.details] == [(k, REQUESTED[k]) for k in KINDS]
            else:
                assert [(d["kind"], d["degree"]) for d in change.details] == [(st.kind, st.degree)]
            got = st.planned[side].model(plan.sides[side].surface_input)
            want = b.model(b.fitted_input, vector_of(change))
            assert np.abs(got - want).max() < TOL_MM, (st.key, side)


def test_every_slider_state_reaches_its_degree_by_the_reference_model(sample):
    """A slider state's parameters lie on its kind's condition line (docs §4) and give the breast its
    degree by the reference model's extents (docs §5) within 1e-6 — or, for a degree beyond this breast's
    line, lie at the line's end nearer to it; the change's `degree_reached` is the reference degree."""
    plan, _, _ = sample
    breasts = {s: Breast(sp) for s, sp in plan.sides.items()}
    beyond = 0
    for st in plan.states[:-1]:
        for side, b in breasts.items():
            d = st.changes[side].details[0]
            assert d["condition"] == CONDITION[st.kind]
            assert np.allclose(d["params"], ref.condition_at(CONDITION[st.kind], d["t"]), atol=1e-12)
            moved = b.model(b.fitted_input, ref.with_kind(np.zeros(12), st.kind, d["params"]))
            reached = ref_degree(st.kind, b.fitted_input, moved, b)
            assert reached == pytest.approx(d["degree_reached"], abs=1e-6), (st.key, side)
            ends = [ref_degree(st.kind, b.fitted_input, b.model(b.fitted_input, ref.with_kind(
                np.zeros(12), st.kind, ref.condition_at(CONDITION[st.kind], t))), b) for t in (0.0, 1.0)]
            if min(ends) - 1e-6 <= st.degree <= max(ends) + 1e-6:
                assert reached == pytest.approx(st.degree, abs=1e-6), (st.key, side)
            else:
                beyond += 1
                nearer = float(np.argmin(np.abs(np.array(ends) - st.degree)))
                assert d["t"] == nearer and reached == pytest.approx(ends[int(nearer)], abs=1e-6), (st.key, side)
    assert beyond < len(plan.states)                        # most degrees lie on the line


def _some_states(grid) -> list[int]:
    """A deterministic sample of the grid's states: its corners, the state planned and every 23rd."""
    return sorted({0, len(grid) - 1, grid.planned_index, *range(0, len(grid), 23)})


def test_the_reports_drawing_of_every_state_is_the_reference_deformation(sample):
    """`plan.views.build_views`: each drawn state (a sample of every slider state), each side, is the reference
    deformation of her fitted breast at that state's parameters, in the display frame (the viewing frame's (x, y,
    z) → (x, z, −y)); the torso drawn near the breasts is moved by both sides' blended displacements. Drawn in
    float32: within 1e-3 mm."""
    from breastplan.plan.views import build_views

    plan, _, _ = sample
    views = build_views(plan)
    grid = plan.grid
    assert views.keys == grid.keys and views.moved.shape[0] == len(grid)
    breasts = {s: Breast(sp) for s, sp in plan.sides.items()}
    to_display = VIEW_TO_DISPLAY @ np.asarray(plan.first.scan.input_to_view, float)
    patch = transform_points(np.linalg.inv(to_display), views.patch)         # her torso near the breasts, input frame
    assert len(patch) > 1000
    for i in _some_states(grid):
        drawn = views.state(grid.keys[i])
        torso = patch.copy()
        for side, b in breasts.items():
            vector = vector_of(grid.changes[side][i])
            want = transform_points(to_display, b.model(b.fitted_input, vector))
            assert np.abs(drawn.mesh[side] - want).max() < 1e-3, (grid.keys[i], side)
            torso += b.blended_local(b.local(patch), vector) @ b.input_to_local[:3, :3]
        assert np.abs(drawn.torso - transform_points(to_display, torso)).max() < 1e-3, grid.keys[i]


def test_the_sliders_reach_every_combination_of_the_kinds_degrees_each_as_solved_alone(sample):
    """`Plan.grid`: every combination of each kind's slider positions (off, 1..8 and the requested degree), state i
    at the mixed-radix digits of i; each state's change is every kind not off at its degree with the parameters it
    was solved with alone, its planned breast the reference deformation (every kind off: her fitted breast as it
    is); its measures are the reference breast's (her volume on her skin changed by as much as the reference
    model's, computed here by the divergence theorem; the nipple's chord to the notch); and the state planned is
    named "combined" and measures as the plan does."""
    plan, _, _ = sample
    grid = plan.grid
    degrees = [sorted({0.0, *map(float, range(1, 9)), REQUESTED[k]}) for k in KINDS]
    assert grid.kinds == KINDS and [list(d) for d in grid.degrees] == degrees
    assert len(grid) == len(set(grid.keys)) == np.prod([len(d) for d in degrees])
    assert grid.keys[grid.planned_index] == "combined"
    assert grid.combination(grid.planned_index) == tuple(REQUESTED[k] for k in KINDS)
    singles = {(st.kind, st.degree): st for st in plan.states if st.kind is not None}
    breasts = {s: Breast(sp) for s, sp in plan.sides.items()}
    notch = plan.volumes.landmarks.sternal_notch
    assert grid.combination(0) == (0.0,) * len(KINDS) and grid.keys[0] == "operated"     # every slider off
    half_off = grid.index((0.0, *(REQUESTED[k] for k in KINDS[1:])))
    for i in _some_states(grid) + [half_off]:
        combo = grid.combination(i)
        on = [(k, d) for k, d in zip(KINDS, combo) if d != 0.0]
        assert grid.index(combo) == i
        assert grid.keys[i] == ("combined" if combo == tuple(REQUESTED[k] for k in KINDS)
                                else "+".join(f"{k}-{d:g}" for k, d in on) or "operated")
        measures = grid.measures_at(i)
        for side, b in breasts.items():
            change = grid.changes[side][i]
            assert [(d["kind"], d["degree"]) for d in change.details] == on
            assert [d["params"] for d in change.details] == [singles[k, d].changes[side].details[0]["params"]
                                                             for k, d in on]
            vector = vector_of(change)
            moved = b.model(b.fitted_input, vector)
            assert np.abs(grid.models[side][i] - moved).max() < 1e-3, (grid.keys[i], side)
            grown = divergence_volume_cc(moved, b.faces) - divergence_volume_cc(b.fitted_input, b.faces)
            assert measures[side]["volume_cc"] == pytest.approx(plan.volumes.sides[side].volume_cc + grown, abs=1e-6)
            nipple = b.model(plan.sides[side].scan.nipple_camera_mm[None], vector)[0]
            assert measures[side]["notch_to_nipple_mm"] == pytest.approx(np.linalg.norm(nipple - notch), abs=1e-6)
    for side in plan.sides:
        assert grid.measures_at(grid.planned_index)[side] == pytest.approx(plan.measures.after[side], abs=1e-9)


def test_each_state_says_the_volume_its_changes_add_and_shears_add_none(sample):
    """The words of a slider state (the page's "Showing: …") say how much its changes make each breast larger or
    smaller, against every slider off: ptosis and turn are shears (their Jacobian's determinant is 1), so a state
    with top-shape off says nothing of volume; with top-shape on, the figures said are the reference model's
    change of each breast's volume (divergence theorem), where one reaches 5 cc."""
    from breastplan.plan.handout import measure_notes
    from breastplan.plan.report import _state_said

    plan, _, _ = sample
    grid = plan.grid
    breasts = {s: Breast(sp) for s, sp in plan.sides.items()}
    at = KINDS.index("top-shape")
    for i in _some_states(grid):
        words = _state_said(plan, i)
        grown = {s: divergence_volume_cc(b.model(b.fitted_input, vector_of(grid.changes[s][i])), b.faces)
                 - divergence_volume_cc(b.fitted_input, b.faces) for s, b in breasts.items()}
        if grid.combination(i)[at] == 0.0:
            assert all(abs(v) < 0.5 for v in grown.values()) and "cc larger" not in words and "cc smaller" not in words
        elif max(map(abs, grown.values())) >= 5.5:
            said = " and ".join(f"her {s} breast {abs(grown[s]):.0f} cc {'larger' if grown[s] > 0 else 'smaller'}"
                                for s in ("right", "left"))
            assert "; these changes make " + said + " (a change of shape alone " in words, (grid.keys[i], words)
            if min(grown.values()) >= 5.5:                            # both larger: the volume must come from somewhere
                assert words.endswith("adds no volume: that takes an implant or a fat graft)"), (grid.keys[i], words)
                if i == grid.planned_index:                             # and her handout says so
                    assert f"As planned, {words.split('; ')[-1]}." in measure_notes(plan)


# --- what is written ---------------------------------------------------------------------------
def test_the_written_planned_breasts_and_scan_displacements_are_the_reference_deformation(sample):
    """Each side's plan/<change>.ply is the reference deformation of fit.ply (breast frame); plan/<change>
    .npz's displacement_mm of the scan's points (breast frame) is the reference model's displacement
    inside the footprint (away from top-shape's seam), the same faded by the quintic step over the band,
    nothing past it; and <change>-scan.ply is the scan moved by it."""
    plan, case, _ = sample
    for side, sp in plan.sides.items():
        b = Breast(sp)
        scan = sp.scan.points                                              # breast frame
        local = transform_points(b.breast_to_local, scan)
        r = b.radius(local)
        for st in plan.changes:
            vector = vector_of(st.changes[side])
            model = read_ply(case / side / "plan" / f"{st.key}.ply").points
            want = transform_points(b.input_to_breast, b.model(b.fitted_input, vector))
            assert np.abs(model - want).max() < TOL_MM, (st.key, side)
            written = np.load(case / side / "plan" / f"{st.key}.npz")["displacement_mm"]
            full = ref.mm(ref.deform(ref.mu(local), b.prim, vector)) - local
            R = np.linalg.inv(b.breast_to_local)[:3, :3]                 # primitive → breast, for vectors
            inside = (r <= 1.0) & ((local[:, 1] <= 0) | (local[:, 1] >= SEAM * ref.MM_PER_MU * b.prim[2]))
            assert inside.mean() > 0.3 and (r > 1.0).any()
            assert np.abs(written[inside] - full[inside] @ R.T).max() < TOL_MM, (st.key, side)
            assert np.abs(written - b.blended_local(local, vector) @ R.T).max() < TOL_MM, (st.key, side)
            assert np.all(written[r >= 1.0 + BAND + 1e-9] == 0.0)
            moved = read_ply(case / side / "plan" / f"{st.key}-scan.ply").points
            assert np.abs(moved - (scan + written)).max() < TOL_MM


def test_her_planned_torso_is_moved_by_both_breasts_blended_changes(sample):
    """`Plan.planned_torsos` and plan/<change>-torso.ply: her torso (input frame) plus each side's
    displacement — the reference deformation on the footprint, faded out over the band, top-shape faded in
    above its seam — rotated back from the primitive frame into the input frame."""
    plan, case, _ = sample
    torso = plan.first.scan.torso_camera
    breasts = {s: Breast(sp) for s, sp in plan.sides.items()}
    for st, moved in zip(plan.changes, plan.planned_torsos):
        want = torso.copy()
        for side, b in breasts.items():
            want += b.blended_local(b.local(torso), vector_of(st.changes[side])) @ b.input_to_local[:3, :3]
        assert np.abs(moved - want).max() < TOL_MM, st.key
        assert np.abs(moved - torso).max() > 1.0
        assert np.abs(read_ply(case / "plan" / f"{st.key}-torso.ply").points - want).max() < TOL_MM


# --- the measures --------------------------------------------------------------------------------
def _nipple_measures(landmarks, nipple) -> dict[str, float]:
    """The measures of a nipple alone, from their definitions (plan/measures.py's docstring)."""
    return {"notch_to_nipple_mm": float(np.linalg.norm(nipple - landmarks.sternal_notch)),
            "nipple_below_notch_mm": float((landmarks.sternal_notch - nipple) @ landmarks.up_axis),
            "nipple_to_midline_mm": float(abs((nipple - landmarks.midline_point) @ landmarks.left_axis))}


def test_the_as_planned_measures_are_taken_at_the_planned_nipple_and_breast(sample):
    """As planned (the combination), each side's nipple is the reference deformation of the scanned
    nipple: its chord from the notch, its height below it and its distance from the midline are those of
    that point; her volume as planned is hers on her skin plus the change of the model's volume (the
    enclosed volumes of the reference-deformed and the fitted mesh, divergence theorem here). Before, the
    same of the scanned nipple. plan.json says the same numbers."""
    plan, _, record = sample
    landmarks = plan.volumes.landmarks
    shown = plan.shown
    assert shown.key == "combined"
    for side, sp in plan.sides.items():
        b = Breast(sp)
        vector = vector_of(shown.changes[side])
        scanned = np.asarray(sp.scan.nipple_camera_mm, float)
        planned = b.model(scanned[None], vector)[0]
        assert np.linalg.norm(planned - scanned) > 2.0                 # the plan moves her nipple
        for when, nipple in (("before", scanned), ("after", planned)):
            for name, value in _nipple_measures(landmarks, nipple).items():
                assert getattr(plan.measures, when)[side][name] == pytest.approx(value, abs=1e-9), (when, side, name)
                assert record["measures"][when][side][name] == pytest.approx(value, abs=0.006), (when, side, name)
        model_change = (divergence_volume_cc(b.model(b.fitted_input, vector), b.faces)
                        - divergence_volume_cc(b.fitted_input, b.faces))
        skin = plan.volumes.sides[side].volume_cc
        assert plan.measures.before[side]["volume_cc"] == skin
        assert plan.measures.after[side]["volume_cc"] == pytest.approx(skin + model_change, abs=1e-6)


def test_her_symmetry_as_planned_is_measured_at_the_planned_nipples_and_skin(sample):
    """BCCT.core's nipple measures as planned, from the reference-deformed nipples in her body frame (x her
    left, y up, origin the notch): UNR the difference of their heights below the notch; BRA the distance
    between the left nipple and the right one's mirror image. Every symmetry measure and each side's
    ptosis grade as planned are those `plan.symmetry` takes (tested on its own in tests/test_symmetry.py)
    from those nipples and her skin's cells with her torso moved by the reference deformation, blended."""
    from breastplan.plan.symmetry import bcct_measures, ptosis_from_cells

    plan, _, _ = sample
    T = plan.volumes.body_from_input
    torso = plan.first.scan.torso_camera
    for when, state in (("before", None), ("after", plan.shown)):
        n, moved = {}, torso.copy()
        for side, sp in plan.sides.items():
            nipple = np.asarray(sp.scan.nipple_camera_mm, float)[None]
            if state is not None:
                b = Breast(sp)
                nipple = b.model(nipple, vector_of(state.changes[side]))
                moved += b.blended_local(b.local(torso), vector_of(state.changes[side])) @ b.input_to_local[:3, :3]
            n[side] = transform_points(T, nipple)[0]
        symmetry = plan.measures.symmetry[when]
        assert symmetry["UNR_mm"] == pytest.approx(abs(abs(n["left"][1]) - abs(n["right"][1])), abs=1e-9)
        assert symmetry["BRA_mm"] == pytest.approx(np.linalg.norm(n["left"] - n["right"] * [-1.0, 1.0, 1.0]), abs=1e-9)
        cells = plan.volumes.cells if state is None else plan.volumes.cells.moved(transform_points(T, moved))
        assert symmetry == pytest.approx(bcct_measures(n, cells), abs=1e-9)
        for side in plan.sides:
            assert plan.measures.ptosis[when][side] == pytest.approx(ptosis_from_cells(n[side], cells, side), abs=1e-9)
    assert plan.measures.symmetry["after"]["overlap_pct"] != plan.measures.symmetry["before"]["overlap_pct"]


def test_plan_json_asymmetry_is_left_minus_right_of_its_own_measures_with_the_sign(sample):
    """plan.json's `measures.asymmetry`, before and as planned: left − right of the per-side measures it
    records beside it (to their rounding), signed — the sample has measures larger on either side — and the
    plan's value the exact difference."""
    plan, _, record = sample
    signs = set()
    for when in ("before", "after"):
        m = record["measures"][when]
        asym = record["measures"]["asymmetry"][when]
        assert set(asym) == set(m["left"]) & set(m["right"])
        for name, value in asym.items():
            diff = m["left"][name] - m["right"][name]
            assert value == pytest.approx(diff, abs=0.0151), (when, name)
            exact = getattr(plan.measures, when)["left"][name] - getattr(plan.measures, when)["right"][name]
            assert plan.measures.asymmetry[when][name] == exact
            if abs(diff) > 0.1:
                signs.add(np.sign(diff))
    assert signs == {-1.0, 1.0}


# --- a follow-up ---------------------------------------------------------------------------------
def test_a_follow_ups_change_on_her_skin_is_the_tissue_added_with_its_sign(sample):
    """The sample as the earlier visit and, as the later one, the same torso with a raised-cosine bump of
    closed-form volume π r² h (1/2 − 2/π²) pushed onto her left breast (her anterior axis), registered by
    the identity: the left breast's change on the earlier wall is that volume (within 15 %), positive, and
    from each visit's own wall (which the bump moves too) within half of it; the right one's nothing; the
    percentages are of the earlier volume."""
    from breastplan.plan.breast_volume import measure_breasts
    from breastplan.plan.compute import skin_changes

    plan, _, _ = sample
    scan = plan.first.scan
    earlier = plan.volumes
    T = earlier.body_from_input
    torso = scan.torso_camera
    body = transform_points(T, torso)
    centre = transform_points(T, plan.sides["left"].scan.nipple_camera_mm[None])[0]
    r, h = 45.0, 10.0
    d = np.linalg.norm(body[:, :2] - centre[:2], axis=1)
    body[:, 2] += np.where(d < r, 0.5 * h * (1.0 + np.cos(np.pi * d / r)), 0.0)
    later_torso = transform_points(np.linalg.inv(T), body)
    nipples = {s: sp.scan.nipple_camera_mm for s, sp in plan.sides.items()}
    later_body = Body(later_torso, scan.input_to_view, scan.plumb_camera)
    later = measure_breasts(later_body, nipples)
    sides = {s: SimpleNamespace(follow_up=SimpleNamespace(registration=SimpleNamespace(earlier_from_later=np.eye(4))))
             for s in plan.sides}
    out = skin_changes(later_body, sides, later, earlier)
    added_cc = np.pi * r * r * h * (0.5 - 2.0 / np.pi ** 2) / 1000.0
    left, right = out["left"], out["right"]
    assert left.on_wall_cc == pytest.approx(added_cc, rel=0.15)
    assert 0.5 * added_cc < left.alone_cc < 1.5 * added_cc         # each visit's own wall: moved by the bump too
    assert abs(right.on_wall_cc) < 0.02 * right.earlier_cc and abs(right.alone_cc) < 0.03 * right.earlier_cc
    for side, change in out.items():
        assert change.earlier_cc == pytest.approx(earlier.sides[side].volume_cc, rel=0.05)
        assert change.on_wall_pct == pytest.approx(100.0 * change.on_wall_cc / change.earlier_cc, rel=1e-12)
        assert change.alone_pct == pytest.approx(100.0 * change.alone_cc / earlier.sides[side].volume_cc, rel=1e-12)
        assert change.alone_cc == pytest.approx(later.sides[side].volume_cc - earlier.sides[side].volume_cc, abs=1e-9)


def test_each_footprints_area_is_the_area_its_outline_encloses(sample):
    """A footprint's area (cm², seen from the front) is the area its closed outline encloses in her body
    frame's (x, y) plane (shoelace formula), to the cells the outline cuts at its corners (under 4 %);
    plan.json records it."""
    plan, _, record = sample
    T = plan.volumes.body_from_input
    for side, v in plan.volumes.sides.items():
        xy = transform_points(T, v.footprint_input_mm)[:, :2]
        enclosed_cm2 = 0.5 * abs(np.dot(xy[:-1, 0], xy[1:, 1]) - np.dot(xy[1:, 0], xy[:-1, 1])) / 100.0
        assert v.area_cm2 == pytest.approx(enclosed_cm2, rel=0.04), side
        assert record["sides"][side]["volume"]["footprint_area_cm2"] == pytest.approx(v.area_cm2, abs=0.051)


def test_a_change_by_degree_after_an_operation_deforms_her_operated_breast(tmp_path):
    """`plan --left augmentation:250:moderate --deform ptosis:3` on the sample: on the left, each slider state's
    planned breast is the reference deformation (at the parameters solved on her breast as scanned) of her fitted
    breast as the operation left it, and its volume her volume plus the implant's 250 cc plus the reference model's
    change from there (the divergence theorem); the right, not operated, is the reference deformation of her
    fitted breast, as in a plan without operations."""
    from breastplan.options import PlanOptions
    from breastplan.plan.job import run_plan

    plan = run_plan(None, tmp_path / "case", PlanOptions(changes=(("ptosis", 3.0),),
                                                         operations=(("left", "augmentation:250:moderate"),)))
    grid, implant = plan.grid, plan.operated["left"]
    assert set(plan.operated) == {"left"} and grid.kinds == ("ptosis",)
    breasts = {s: Breast(sp) for s, sp in plan.sides.items()}
    for i in range(len(grid)):
        measures = grid.measures_at(i)
        for side, b in breasts.items():
            start = implant(b.fitted_input) if side == "left" else b.fitted_input
            moved = b.model(start, vector_of(grid.changes[side][i]))
            assert np.abs(grid.models[side][i] - moved).max() < 1e-3, (grid.keys[i], side)
            grown = divergence_volume_cc(moved, b.faces) - divergence_volume_cc(start, b.faces)
            added = 250.0 if side == "left" else 0.0
            assert measures[side]["volume_cc"] == pytest.approx(
                plan.volumes.sides[side].volume_cc + added + grown, abs=1e-3), (grid.keys[i], side)
