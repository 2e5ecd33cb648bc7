"""Realistic ptosis pairs (scenes/realistic_pairs.py): MakeHuman bodies firm (before) and sagging (after),
seen by the simulated depth camera, written as a pairs folder in one breast frame.

Truths the module does not compute: the MakeHuman meshes rebuilt here (both scans must lie on their
own body's surface laid in the before's frame), the geometry of the written clouds (the base stays,
the lower breast drops), and a model learnt by `train-statistical` from other bodies, judged on a
held-out body's true after.
"""
import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

from breastplan import read_ply, transform_points
from breastplan.scenes.makehuman import BodyOptions, make_body
from breastplan.scenes.realistic_pairs import PairsOptions, frame_from_comments, scan_pairs, write_realistic_pairs
from breastplan.learn.pair_folder import breast_cloud, read_pairs
from breastplan.options import OptionError

from clitools import run

BODIES = (
    BodyOptions(cup=0.3, weight=0.6),
    BodyOptions(cup=0.6, weight=0.5),
    BodyOptions(cup=0.5, weight=0.4, muscle=0.6),
    BodyOptions(cup=0.8, weight=0.5),
    BodyOptions(cup=0.4, weight=0.8, muscle=0.3),
    BodyOptions(cup=0.7, weight=0.3, muscle=0.6),
    BodyOptions(cup=0.9, weight=0.6, muscle=0.4),
)
HELD_OUT = 5
"""The test split: a body inside the training bodies' range (cup 0.7), sagging well beyond the scans' noise."""
LEVELS = (0.5, 0.0)
SIDE = "right"
OPTIONS = PairsOptions(test=(HELD_OUT,))      # 640×400, 3 frames, seed 0
BASE_MM = 3.0
"""Points this close to the base plane (z = 0) are the breast's base on the chest wall."""
STILL_MM = 1.0
"""Skin that MakeHuman's firmness change moves less than this stays in place."""
DROP_MM = 1.0
"""The lower breast drops by more than this (half the clouds' voxel) from firmness 0.5 to 0: its
nipple drops by 9–55 mm more; the smallest breast's lower tenth is mostly base skin and drops least."""


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("realistic-pairs")
    csv = write_realistic_pairs(out / "pairs", BODIES, LEVELS, SIDE, OPTIONS)
    assert csv == out / "pairs" / "pairs.csv"
    return out


@pytest.fixture(scope="module")
def pairs(folder):
    """(body index, firmness, row, before points, after points) of every pair."""
    out = []
    for row in read_pairs(folder / "pairs"):
        body = int(row.before.stem.removeprefix("body"))
        firmness = float(row.after.stem.split("-f")[1])
        out.append((body, firmness, row, breast_cloud(row.before), breast_cloud(row.after)))
    return out


def test_the_folder_holds_ptosis_pairs_with_degrees_that_grow_as_firmness_falls(pairs):
    assert len(pairs) == len(BODIES) * len(LEVELS)
    degrees = {}
    for body, firmness, row, before, after in pairs:
        assert row.kind == "ptosis" and 1.0 <= row.degree <= 8.0
        assert row.split == ("test" if body == HELD_OUT else "train")
        assert before[:, 2].min() > 0.0 and after[:, 2].min() > 0.0         # in front of the base plane
        degrees[body, firmness] = row.degree
    for body in range(len(BODIES)):
        assert degrees[body, 0.0] == 8.0                                       # the full sagging
        # MakeHuman sags little from firmness 1 to 0.5 and most below: the extent map is below the linear one
        assert 1.5 < degrees[body, 0.5] < 1.0 + 7.0 * 0.5


def _laid(body, frame):
    """A MakeHuman body's vertices laid in a pair's breast frame."""
    return transform_points(frame, body.vertices)


def _on_body(points, frame, body):
    """Median distance (mm) of breast-frame points to a MakeHuman body's surface laid in that frame."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(_laid(body, frame).astype(np.float32)),
                        o3d.core.Tensor(body.faces.astype(np.uint32)))
    return float(np.median(scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()))


@pytest.fixture(scope="module")
def truth(pairs):
    """Per pair: the frame its PLYs record, and the firm and sagging MakeHuman bodies rebuilt here."""
    out = []
    for body, firmness, row, _, _ in pairs:
        frame = frame_from_comments(read_ply(row.before).comments)
        assert np.array_equal(frame, frame_from_comments(read_ply(row.after).comments))
        out.append((frame, make_body(replace(BODIES[body], firmness=1.0)),
                    make_body(replace(BODIES[body], firmness=firmness))))
    return out


def test_both_scans_lie_on_their_own_body_in_the_before_frame(pairs, truth):
    """The truth laid in the frame the PLYs record: the firm mesh under the before, the sagging mesh
    under the after (an after in a frame of its own, 5–60 mm off, would miss its body)."""
    for (body, firmness, _, before, after), (frame, firm, sagging) in zip(pairs, truth):
        assert _on_body(before, frame, firm) < 1.0
        assert _on_body(after, frame, sagging) < 1.0
        if firmness == 0.0:                            # and it did change: the firm body is not under the after
            assert _on_body(after, frame, firm) > 2.0 * _on_body(after, frame, sagging), body


def test_the_base_stays_on_the_chest_wall_while_the_lower_breast_drops(pairs, truth):
    """Up is +y in the breast frame (docs/model.md §1). The after's base points (z small) on skin that
    MakeHuman's firmness leaves in place coincide with the before's cloud (the frame is shared; a large
    breast's firmness target drags its whole base, so some pairs have no such skin), and the lower part
    of the breast drops, more as the firmness falls. Coincide: the median gap under the clouds'
    voxel size (two noisy samplings of one skin, 2 mm apart; an after ingested in a frame of its own
    lay 5–61 mm off)."""
    checked, drops = 0, {}
    for (body, firmness, _, before, after), (frame, firm, sagging) in zip(pairs, truth):
        base = after[after[:, 2] < BASE_MM]
        laid_firm, laid_sagging = _laid(firm, frame), _laid(sagging, frame)
        _, vertex = cKDTree(laid_sagging).query(base)
        still = np.linalg.norm(laid_sagging[vertex] - laid_firm[vertex], axis=1) < STILL_MM
        if still.sum() >= 15:
            gap = float(np.median(cKDTree(before).query(base[still])[0]))
            assert gap < OPTIONS.voxel_mm, f"body {body}, firmness {firmness}: the after's still base lies {gap:.1f} mm from the before"
            checked += 1
        drops[body, firmness] = _lower(before) - _lower(after)
    assert checked >= 5
    for body in range(len(BODIES)):
        assert drops[body, 0.5] > -0.5, f"body {body}: the lower breast rose at firmness 0.5 ({drops[body, 0.5]:.1f} mm)"
        assert drops[body, 0.0] > drops[body, 0.5] + DROP_MM, f"body {body}: drops {drops[body, 0.5]:.1f}, {drops[body, 0.0]:.1f} mm"


def _lower(points):
    """The height (y, up) below which a tenth of the breast's raised points lie: its lower part."""
    return float(np.percentile(points[points[:, 2] > 5.0, 1], 10))


def test_a_scan_is_reproducible_and_the_firmness_map_is_linear(pairs):
    body, _, _, before, after = next(p for p in pairs if p[1] == 0.0)
    options = replace(OPTIONS, degree="firmness")
    scanned = scan_pairs(BODIES[body], (0.75, 0.0), SIDE, options, seed=OPTIONS.seed + 1000 * body)
    assert np.array_equal(scanned.before, before) and np.array_equal(scanned.afters[0.0], after)   # seeded
    assert scanned.degrees == {0.75: 2.75, 0.0: 8.0}                                              # 1 + 7 (1 − f)


@pytest.mark.parametrize("levels, side, test", [((1.0,), "right", ()), ((0.5, 0.5), "right", ()), ((-0.1,), "right", ()),
                                                ((), "right", ()), ((0.5,), "middle", ()), ((0.5,), "right", (0, 1)),
                                                ((0.5,), "right", (7,))])
def test_bad_arguments_are_refused_before_any_scan(tmp_path, levels, side, test):
    with pytest.raises(OptionError):
        write_realistic_pairs(tmp_path / "pairs", BODIES[:2], levels, side, PairsOptions(test=test))
    assert not (tmp_path / "pairs").exists()


@pytest.fixture(scope="module")
def trained(cli, folder):
    res = run(cli, "train-statistical", "--pairs", folder / "pairs", "--out", folder / "model.npz",
              "--cache", folder / "cache", "--json")
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_a_model_learnt_from_other_bodies_brings_the_held_out_breast_towards_its_true_sagging(cli, folder, pairs, trained):
    """Held-out body, full sagging (degree 8): the model's breast lies nearer the true after than the
    before does, and nearer than the trivial change (the mean training field, whatever the degree)."""
    from breastplan.learn.displacements import FitCache, PairOptions, apply_field, fit_before, fit_pair

    assert trained["pairs"] == (len(BODIES) - 1) * len(LEVELS) and trained["befores"] == len(BODIES) - 1
    body, firmness, row, before, after = next(p for p in pairs if p[0] == HELD_OUT and p[1] == 0.0)
    out = folder / "deformed.ply"
    res = run(cli, "deform", row.before, "--kind", "ptosis", "--degree", row.degree, "--model", folder / "model.npz",
              "--out", out, "--json")
    assert res.returncode == 0, res.stderr
    modelled = read_ply(out).points
    truth = cKDTree(after)

    def gap(points):
        return float(np.median(truth.query(points)[0]))

    cache = FitCache(folder / "cache")                 # the fits train-statistical made
    fields = [fit_pair(fit_before(b, 5, cache), b, a, PairOptions(), cache) for i, _, _, b, a in pairs if i != HELD_OUT]
    trivial = apply_field(before, np.mean(fields, axis=0), fit_before(before, 5, cache).box(5))
    assert gap(before) > 5.0                           # the held-out breast sags well beyond the scans' noise
    assert gap(modelled) < 0.5 * gap(before), (gap(modelled), gap(before))
    assert gap(modelled) < gap(trivial), (gap(modelled), gap(trivial))
