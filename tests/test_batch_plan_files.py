"""`batch` with a plan file beside a scan (`anna.plan.yaml` beside `anna.mcap`): her case is planned as the file
writes it — the operations each side its own, and her volume on her skin changed by exactly each operation's — the
scans without one as the batch's options say; a plan file that cannot be planned fails her case alone, naming the
file; a plan file with no scan of its name, or a second one of a scan, is skipped, saying so; a changed plan file
plans her case again."""
import json
import shutil

import pytest
from clitools import run

from breastplan.batch.inputs import find_inputs
from breastplan.plan.job import sample_recording


def test_find_inputs_gives_a_scan_its_plan_file_and_skips_the_others(tmp_path):
    for name in ("anna.ply", "anna.plan.yaml", "anna.plan.json", "bea.ply", "cara.plan.yml", "ward/dora.mcap",
                 "ward/dora.plan.JSON"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("x")
    found = {i.name: i for i in find_inputs(tmp_path)}
    assert set(found) == {"anna.ply", "anna.plan.yaml", "bea.ply", "cara.plan.yml", "ward/dora.mcap"}
    assert found["anna.ply"].plan_file == tmp_path / "anna.plan.json" and found["anna.ply"].skipped is None
    assert found["anna.plan.yaml"].skipped == "a second plan file of anna.ply (its plan is anna.plan.json)"
    assert found["bea.ply"].plan_file is None
    assert found["cara.plan.yml"].skipped == "a plan file with no scan or recording of its name beside it"
    assert found["ward/dora.mcap"].plan_file == tmp_path / "ward" / "dora.plan.JSON"


def _manifest(out):
    return {c["input"]: c for c in json.loads((out / "manifest.json").read_text())["cases"]}


def test_a_scans_plan_file_plans_her_operations_and_a_bad_one_fails_her_case_alone(cli, tmp_path):
    folder, out = tmp_path / "scans", tmp_path / "cases"
    folder.mkdir()
    for name in ("anna", "bea", "dora"):
        shutil.copy(sample_recording(), folder / f"{name}.mcap")
    (folder / "anna.plan.yaml").write_text("left: [augmentation:250:moderate]\nright: reduction:30\n")
    (folder / "dora.plan.json").write_text(json.dumps({"left": "augmentation:250", "breast": "right"}))
    (folder / "cara.plan.json").write_text("{}")
    res = run(cli, "batch", folder, "--out", out, "--jobs", "2", "--deform", "ptosis:2")
    assert res.returncode == 0, res.stderr
    rows = _manifest(out)
    assert {k: r["status"] for k, r in rows.items()} == {"anna.mcap": "done", "bea.mcap": "done",
                                                          "dora.mcap": "failed", "cara.plan.json": "skipped"}
    assert "dora.plan.json" in rows["dora.mcap"]["error"] and not (out / "dora").exists()
    anna = json.loads((out / "anna" / "plan.json").read_text())
    assert anna["options"]["operations"] == [["left", "augmentation:250:moderate"], ["right", "reduction:30"]]
    assert anna["options"]["changes"] == []
    m = anna["measures"]
    assert m["after"]["left"]["volume_cc"] == pytest.approx(m["before"]["left"]["volume_cc"] + 250.0, abs=0.2)
    assert m["after"]["right"]["volume_cc"] == pytest.approx(m["before"]["right"]["volume_cc"] - 30.0, abs=0.2)
    bea = json.loads((out / "bea" / "plan.json").read_text())
    assert bea["options"]["operations"] == [] and bea["options"]["changes"] == [["ptosis", 2.0]]
    (folder / "anna.plan.yaml").write_text("left: [augmentation:250:moderate]\nright: reduction:40\n")
    res = run(cli, "batch", folder, "--out", out, "--deform", "ptosis:2")
    rows = _manifest(out)
    assert rows["anna.mcap"]["status"] == "done" and rows["bea.mcap"]["status"] == "reused"
    anna = json.loads((out / "anna" / "plan.json").read_text())
    assert anna["options"]["operations"][1] == ["right", "reduction:40"]
