"""A plan file (`plan.written_plan`) read back as the options it writes, and every file that is not one refused in
one sentence naming it — never building a Python object from it."""
import json
import os

import pytest

from breastplan.plan.written_plan import MAX_BYTES, WrittenPlan, read_written_plan


@pytest.mark.parametrize("name,text", [
    ("p.yaml", "left: [augmentation:300:moderate, lift:fold=40]\nright: reduction:60\ndeform: ptosis:2\n"
               "symmetrise: right\n"),
    ("p.json", json.dumps({"left": ["augmentation:300:moderate", "lift:fold=40"], "right": "reduction:60",
                           "deform": ["ptosis:2"], "symmetrise": "right"}))])
def test_yaml_and_json_say_the_same_plan(tmp_path, name, text):
    (tmp_path / name).write_text(text)
    assert read_written_plan(tmp_path / name) == WrittenPlan(("augmentation:300:moderate", "lift:fold=40"),
                                                             ("reduction:60",), ("ptosis:2",), "right")


def test_an_empty_file_plans_nothing_of_its_own(tmp_path):
    (tmp_path / "p.yaml").write_text("# nothing yet\n")
    assert read_written_plan(tmp_path / "p.yaml") == WrittenPlan()


@pytest.mark.parametrize("text,words", [
    ("!!python/object/apply:os.system ['touch pwned']\n", "cannot be read as YAML or JSON"),
    ("left: [augmentation:300\n", "cannot be read as YAML or JSON"),
    ("- augmentation:300\n", "only the keys"),
    ("left: augmentation:300\nbreast: right\n", "only the keys"),
    ("left: {volume: 300}\n", "a word or a list of words"),
    ("symmetrise: [left, right]\n", "one side"),
    ("left: true\n", "a word or a list of words"),
    ("left: " + "[" * 200_000 + "]" * 200_000 + "\n", "cannot be read as YAML or JSON"),   # deeper than its parser
    ("left: " + "{a: " * 50_000 + "b" + "}" * 50_000 + "\n", "cannot be read as YAML or JSON")])
def test_a_file_that_is_no_plan_is_refused_naming_it(tmp_path, text, words):
    (tmp_path / "p.yaml").write_text(text)
    with pytest.raises(ValueError, match=words) as caught:
        read_written_plan(tmp_path / "p.yaml")
    assert str(tmp_path / "p.yaml") in str(caught.value)
    assert not (tmp_path / "pwned").exists() and not (tmp_path.parent / "pwned").exists()


def test_a_file_over_its_size_missing_or_a_pipe_is_refused_naming_it(tmp_path):
    (tmp_path / "big.yaml").write_bytes(b"#" * (MAX_BYTES + 1))
    with pytest.raises(ValueError, match="over 1 MB"):
        read_written_plan(tmp_path / "big.yaml")
    with pytest.raises(ValueError, match="cannot be read"):
        read_written_plan(tmp_path / "missing.yaml")
    os.mkfifo(tmp_path / "pipe.yaml")                           # reading it would wait for a writer forever
    with pytest.raises(ValueError, match="not a regular file"):
        read_written_plan(tmp_path / "pipe.yaml")
