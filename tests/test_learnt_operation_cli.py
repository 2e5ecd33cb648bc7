"""A clinic's own model of an operation, end to end through the command line on MakeHuman bodies: two women each
scanned at a small cup and again, the same body, at a larger one (`scan-synth --scan-file`, the true change of each
breast from the half-body volumes it reports) are one augmentation each on both breasts; `plan` writes a case of
every scan, `train-statistical` learns the operation from the folder of them, and `plan --operation-model` makes it
on a woman outside them (another body and cup), against the truths stated here: her volume on her skin grows by the
implant's volume exactly, her other breast is left as it was, plan.json and the report name the model, her breast
larger than the pairs' is said to lie outside them, her nipple moves as theirs did (outwards and down), and the model
moves her skin otherwise than the built-in augmentation of the same implant does. Every bad request (a file that is
no operation's model, two models of one operation, a model of an operation not planned, a pairs.csv the models do
not learn from, a deformation model's options) is refused with its exit code before anything is written."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from clitools import assert_bad_input, run
from made_once import made_once

import breastplan
from breastplan import read_ply

WOMEN = {"anna": (["--weight", "0.4"], 0.3, 0.7),
         "beth": (["--weight", "0.6", "--firmness", "0.7"], 0.25, 0.6)}
"""Each woman of the clinic's pairs: her body's scan-synth options, her cup before and after."""
HER = ["--cup", "0.45", "--muscle", "0.3"]
"""The woman the model is used on: a body and cup no pair shows."""
IMPLANT_CC = 250.0
PARAMETRIC = Path(breastplan.__file__).parent / "deform" / "models" / "ptosis-b0-gt-b1.npz"
"""A breastplan.model/1 file of another kind (a degree's parametric model)."""


def _all(cli, commands) -> list[str]:
    """Run `breastplan` commands side by side (as many at once as there are CPUs, at most 4); their stdouts."""
    def one(args):
        res = subprocess.run([cli, *map(str, args)], capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, (args, res.stderr)
        return res.stdout

    with ThreadPoolExecutor(min(4, os.cpu_count() or 1)) as pool:
        return list(pool.map(one, commands))


def _scan(name: str, body: list, cup: float, folder: Path) -> list:
    return ["scan-synth", "--body", "makehuman", *body, "--cup", cup, "--scan-file", folder / f"{name}.ply",
            "--truth", folder / f"{name}.npz", "--json"]


@pytest.fixture(scope="module")
def clinic(cli, tmp_path_factory) -> Path:
    """The pairs folder (pairs/: pairs.csv and a case of each scan), the model learnt from it (model.npz, and
    train.json what train-statistical printed), and the woman outside it planned with the model (learnt/, and
    learnt.txt what plan printed) and with the built-in augmentation (built-in/), made once per session."""
    def make(folder: Path):
        pairs = folder / "pairs"
        pairs.mkdir()
        scans = [(f"{w}-{when}", body, cup) for w, (body, *cups) in WOMEN.items()
                 for when, cup in zip(("before", "after"), cups)]
        truths = _all(cli, [_scan(name, body, cup, folder) for name, body, cup in scans] +
                      [["scan-synth", "--body", "makehuman", *HER, "--scan-file", folder / "her.ply", "--truth",
                        folder / "her.npz"]])
        half = {name: json.loads(out)["half_volumes_cc"] for (name, _, _), out in zip(scans, truths)}
        # a case of each scan, and her case planned with the built-in augmentation, side by side
        _all(cli, [["plan", folder / f"{name}.ply", "--out", pairs / name, "--deform", "ptosis:1"]
                   for name, _, _ in scans] +
             [["plan", folder / "her.ply", "--out", folder / "built-in", "--left", f"augmentation:{IMPLANT_CC:g}"]])
        rows = ["before,after,operation,side"]
        for w in WOMEN:
            change = np.mean([half[f"{w}-after"][s] - half[f"{w}-before"][s] for s in ("left", "right")])
            rows.append(f"{w}-before,{w}-after,augmentation:{change:.1f},both")
        (pairs / "pairs.csv").write_text("\n".join(rows) + "\n")
        out = _all(cli, [["train-statistical", "--pairs", pairs, "--out", folder / "model.npz", "--regressor",
                          "ridge", "--json"]])[0]
        (folder / "train.json").write_text(out)
        out = _all(cli, [["plan", folder / "built-in", "--out", folder / "learnt", "--left",
                          f"augmentation:{IMPLANT_CC:g}", "--operation-model", folder / "model.npz"]])[0]
        (folder / "learnt.txt").write_text(out)

    return made_once(tmp_path_factory, "learnt-operation-cli", make)


def _plan(case: Path) -> dict:
    return json.loads((case / "plan.json").read_text())


def test_train_statistical_learns_an_augmentation_from_a_folder_of_her_cases_before_and_after(clinic):
    trained = json.loads((clinic / "train.json").read_text())
    assert trained["operation"] == "augmentation"
    assert trained["pairs"] == 2 * len(WOMEN) and trained["women"] == len(WOMEN)      # both breasts of each
    assert trained["regressor"] == "ridge" and trained["model"] == str(clinic / "model.npz")
    assert (clinic / "model.npz").is_file()


def test_the_model_makes_her_implant_adding_its_volume_exactly_and_leaves_her_other_breast(clinic):
    plan = _plan(clinic / "learnt")
    done = plan["sides"]["left"]["operations"]
    assert done["operations"][0]["model"] == "model.npz" and done["operations"][0]["kind"] == "augmentation"
    assert done["volume_change_cc"] == pytest.approx(IMPLANT_CC, abs=0.1)
    before, after = plan["measures"]["before"], plan["measures"]["after"]
    assert after["left"]["volume_cc"] - before["left"]["volume_cc"] == pytest.approx(IMPLANT_CC, abs=0.2)
    assert after["right"]["volume_cc"] == before["right"]["volume_cc"]
    assert "operations" not in plan["sides"]["right"]
    report = (clinic / "learnt" / "report.html").read_text()
    assert "as model.npz makes it" in report


def test_her_volume_outside_the_pairs_is_said_and_her_nipple_moves_as_the_pairs_moved_theirs(clinic):
    """The pairs' breasts hold 100–125 cc before and hers about 170 cc: the plan says so, in plan.json and on the
    terminal (her change, 250 cc, lies within theirs, about 150–256 cc). Their nipples moved outwards and down under
    the larger breast, and hers does so too, on her own breast (the built-in augmentation brings it forward)."""
    plan = _plan(clinic / "learnt")
    done, volume = plan["sides"]["left"]["operations"], plan["measures"]["before"]["left"]["volume_cc"]
    assert 150.0 < volume < 200.0
    note = done["note"]
    assert done["warnings"] == []                                   # a note on how it was planned, not a warning
    assert note.startswith(f"model.npz learnt from {2 * len(WOMEN)} breasts") and "the change" not in note
    assert f"her volume {volume:.0f} cc lies outside the pairs'" in note
    printed = (clinic / "learnt.txt").read_text().splitlines()
    assert f"left: {note}" in printed
    assert any(line.startswith(f"left operated: augmentation:{IMPLANT_CC:g} (by model.npz);") for line in printed)
    landmarks = plan["measures"]["landmarks"]
    left, up = np.array(landmarks["left_axis"]), np.array(landmarks["up_axis"])
    moved = np.array(done["nipple_after_input_mm"]) - np.array(plan["sides"]["left"]["nipple_input_mm"])
    assert moved @ left > 2.0 and moved @ up < -2.0
    assert done["nipple_moved_mm"] < 60.0


def test_the_built_in_augmentation_adds_the_same_volume_but_moves_her_skin_otherwise(clinic):
    learnt, built = _plan(clinic / "learnt"), _plan(clinic / "built-in")
    made = built["sides"]["left"]["operations"]
    assert "model" not in made["operations"][0]
    assert made["volume_change_cc"] == pytest.approx(IMPLANT_CC, abs=0.1)
    assert learnt["measures"]["before"] == built["measures"]["before"]                  # one woman, one case
    torso = {name: np.asarray(read_ply(clinic / name / p["files"]["torso"]["operated"]).points, float)
             for name, p in (("learnt", learnt), ("built-in", built))}
    assert torso["learnt"].shape == torso["built-in"].shape
    assert np.linalg.norm(torso["learnt"] - torso["built-in"], axis=1).max() > 5.0
    assert learnt["sides"]["left"]["operations"]["nipple_moved_mm"] != made["nipple_moved_mm"]


def _usage_error(res, flag: str, out: Path) -> None:
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert flag in res.stderr and "Traceback" not in res.stderr
    assert not out.exists()


@pytest.mark.parametrize("name", ["parametric", "arrays", "plan.json"])
def test_a_file_that_is_no_operation_model_is_refused_naming_it(cli, clinic, tmp_path, name):
    path = {"parametric": PARAMETRIC, "arrays": tmp_path / "arrays.npz", "plan.json": clinic / "learnt" / "plan.json"}
    np.savez(tmp_path / "arrays.npz", a=np.zeros(3))
    res = run(cli, "plan", clinic / "built-in", "--out", tmp_path / "out", "--left", "augmentation:250",
              "--operation-model", path[name])
    assert_bad_input(res, path[name], tmp_path)
    assert not (tmp_path / "out").exists()


def test_two_models_of_one_operation_are_refused(cli, clinic, tmp_path):
    shutil.copy(clinic / "model.npz", tmp_path / "again.npz")
    res = run(cli, "plan", clinic / "built-in", "--out", tmp_path / "out", "--left", "augmentation:250",
              "--operation-model", clinic / "model.npz", "--operation-model", tmp_path / "again.npz")
    assert_bad_input(res, tmp_path / "again.npz", tmp_path)
    assert "one model per operation" in res.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args", [["--right", "reduction:50"], ["--deform", "ptosis:1"], []],
                         ids=["a-reduction", "a-change-by-degree", "the-default-plan"])
def test_a_model_of_an_operation_not_planned_is_a_usage_error(cli, clinic, tmp_path, args):
    res = run(cli, "plan", clinic / "built-in", "--out", tmp_path / "out", *args,
              "--operation-model", clinic / "model.npz")
    _usage_error(res, "--operation-model", tmp_path / "out")
    assert "no augmentation is planned" in " ".join(res.stderr.split())


@pytest.mark.parametrize("rows,line", [
    (["anna-before,anna-after,augmentation:250,both", "anna-after,anna-before,reduction:250,both"], 3),
    (["anna-before,anna-after,augmentation:250,middle"], 2),
    (["anna-before,anna-after,lumpectomy:30:2:30,left"], 2),
    (["../outside/anna-before,anna-after,augmentation:250,both"], 2),
    (["anna-before,anna-before,augmentation:250,both"], 2),
    (["anna-before,anna-after,augmentation:250,left"], None),                  # one breast: too few to learn from
], ids=["two-kinds", "unknown-side", "lumpectomy", "outside", "one-case", "one-breast"])
def test_a_pairs_table_the_models_do_not_learn_from_is_refused_naming_it_and_the_line(cli, clinic, tmp_path,
                                                                                       rows, line):
    bad = tmp_path / "bad"
    for name in ("anna-before", "anna-after"):                               # her cases, linked, not copied
        shutil.copytree(clinic / "pairs" / name, bad / name, copy_function=os.link)
    shutil.copytree(clinic / "pairs" / "anna-before", tmp_path / "outside" / "anna-before", copy_function=os.link)
    (bad / "pairs.csv").write_text("\n".join(["before,after,operation,side", *rows]) + "\n")
    res = run(cli, "train-statistical", "--pairs", bad, "--out", bad / "out.npz")
    assert_bad_input(res, bad / "pairs.csv", bad)
    assert line is None or f"line {line}:" in res.stderr
    assert not (bad / "out.npz").exists()


@pytest.mark.parametrize("args,flag", [(["--corresponding"], "--corresponding"), (["--lattice", "6"], "--lattice")])
def test_a_deformation_models_options_with_an_operations_pairs_are_usage_errors(cli, clinic, tmp_path, args, flag):
    res = run(cli, "train-statistical", "--pairs", clinic / "pairs", "--out", tmp_path / "out.npz", *args)
    _usage_error(res, flag, tmp_path / "out.npz")


def test_a_batch_makes_a_patients_planned_operation_by_the_clinics_model_and_the_others_by_the_built_in(cli, clinic,
                                                                                                     tmp_path):
    """Her scan with her plan file (an augmentation, which the model makes) and a scan with a reduction (which it
    does not): each volume changes by its own operation exactly; plan.json names the model beside hers alone."""
    folder, out = tmp_path / "scans", tmp_path / "cases"
    folder.mkdir()
    for name in ("her", "ida"):
        os.link(clinic / "her.ply", folder / f"{name}.ply")
    (folder / "her.plan.yaml").write_text(f"left: augmentation:{IMPLANT_CC:g}\n")
    (folder / "ida.plan.yaml").write_text("right: reduction:30\n")
    res = run(cli, "batch", folder, "--out", out, "--operation-model", clinic / "model.npz")
    assert res.returncode == 0, res.stderr
    her, ida = (_plan(out / name) for name in ("her", "ida"))
    assert her["options"]["operation_models"] == [str(clinic / "model.npz")]
    made = her["sides"]["left"]["operations"]
    assert made["operations"][0]["model"] == "model.npz"
    assert made["volume_change_cc"] == pytest.approx(IMPLANT_CC, abs=0.1)
    cut = ida["sides"]["right"]["operations"]
    assert "model" not in cut["operations"][0] and cut["volume_change_cc"] == pytest.approx(-30.0, abs=0.1)
    res = run(cli, "batch", folder, "--out", tmp_path / "none", "--operation-model", tmp_path / "missing.npz")
    assert_bad_input(res, tmp_path / "missing.npz", tmp_path)
    assert not (tmp_path / "none").exists()
