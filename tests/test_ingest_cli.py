"""`breastplan scan-synth` and `breastplan ingest` end to end, and every bad input of ingest."""
import json

import numpy as np
import pytest

from breastplan import read_ply, write_ply
from breastplan.scenes import synthetic
from breastplan.ingest.recording import END_OF_RECORDING, depthai, record_messages, write_recording

from clitools import assert_bad_input, run

K = np.array([[450.0, 0, 320], [0, 450.0, 200], [0, 0, 1]])


@pytest.fixture(scope="module")
def recording(cli, tmp_path_factory):
    folder = tmp_path_factory.mktemp("rec")
    res = run(cli, "scan-synth", "--out", folder / "rec.mcap", "--truth", folder / "truth.npz", "--frames", 6,
              "--seed", 2, "--tilt", 10, "--side-params", "right:a5=0.6,b0=0,b1=0", "--json")
    assert res.returncode == 0, res.stderr
    return folder, json.loads(res.stdout)


def test_scan_synth_records_frames_and_truth(recording):
    folder, out = recording
    assert out["frames"] == 6 and out["size"] == [640, 400] and 0.9 < out["valid_pixels"] < 1.0
    truth = synthetic.load_truth(folder / "truth.npz")
    assert truth["right_primitive"][4] == pytest.approx(0.6)   # the override reached the truth
    assert truth.meta["tilt_deg"] == 10.0


def test_ingest_writes_the_case_folder(cli, recording, tmp_path):
    folder, _ = recording
    res = run(cli, "ingest", folder / "rec.mcap", "--side", "left", "--out", tmp_path / "case", "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert {"points", "nipple_camera_mm", "frames", "seconds"} <= set(out) and out["frames"] == 6
    truth = synthetic.load_truth(folder / "truth.npz")
    assert np.linalg.norm(np.array(out["nipple_camera_mm"]) - truth["left_nipple_camera_mm"]) <= 2.0
    assert sorted(p.name for p in (tmp_path / "case").iterdir()) == ["camera.ply", "scan.npz", "scan.ply"]
    assert len(read_ply(tmp_path / "case" / "scan.ply").points) == out["points"]


def write_gray8_recording(path):
    """An MCAP of 8-bit images: a recording, but without depth frames."""
    dai = depthai()
    frames = []
    for seq in (0, END_OF_RECORDING):
        frame = dai.ImgFrame()
        frame.setType(dai.ImgFrame.Type.GRAY8)
        frame.setWidth(64)
        frame.setHeight(40)
        frame.setFrame(np.full((40, 64), 128, np.uint8))
        frame.setSequenceNum(seq)
        frames.append(frame)
    record_messages(path, frames)


@pytest.fixture(scope="module")
def bad_inputs(recording, tmp_path_factory):
    """A folder of bad inputs: name → (input path, extra arguments); each must exit 3 naming the input."""
    folder, recording_folder = tmp_path_factory.mktemp("bad"), recording[0]
    cases = {}
    cases["missing file"] = (folder / "nope.mcap", [])
    (folder / "empty.ply").write_bytes(b"")
    cases["empty file"] = (folder / "empty.ply", [])
    write_ply(folder / "torso.ply", np.random.default_rng(0).normal(0, 100, (2000, 3)))
    data = (folder / "torso.ply").read_bytes()
    (folder / "truncated.ply").write_bytes(data[: len(data) // 2])
    cases["truncated PLY"] = (folder / "truncated.ply", [])
    nan = np.random.default_rng(1).normal(0, 100, (2000, 3))
    nan[5, 1] = np.nan
    write_ply(folder / "nan.ply", nan)
    cases["NaN coordinates"] = (folder / "nan.ply", [])
    (folder / "text.mcap").write_text("this is not a recording\n")
    cases["not an MCAP"] = (folder / "text.mcap", [])
    write_gray8_recording(folder / "gray.mcap")
    cases["MCAP without depth frames"] = (folder / "gray.mcap", [])
    write_recording(folder / "zeros.mcap", np.zeros((3, 40, 64), np.uint16), [[45, 0, 32], [0, 45, 20], [0, 0, 1]])
    cases["all-zero depth"] = (folder / "zeros.mcap", [])
    write_recording(folder / "sizes.mcap", [np.full((40, 64), 700, np.uint16), np.full((20, 32), 700, np.uint16)],
                    [[45, 0, 32], [0, 45, 20], [0, 0, 1]])
    cases["frames change size"] = (folder / "sizes.mcap", [])
    rec = recording_folder / "rec.mcap"
    truth = synthetic.load_truth(recording_folder / "truth.npz")
    nipple = truth["left_nipple_camera_mm"]
    box = ",".join(f"{v:.1f}" for v in np.concatenate([nipple - [6, 6, 30], nipple + [6, 6, 5]]))
    cases["fewer than 500 points after cropping"] = (rec, ["--roi", box])
    cases["no mound on the requested side"] = (rec, ["--side", "right"])
    far = np.random.default_rng(2).normal(0, 100, (2000, 3))
    far[9] = [1e30, 0.0, 0.0]
    write_ply(folder / "far.ply", far)
    cases["one coordinate 1e30 in mm"] = (folder / "far.ply", ["--units", "mm"])
    cases["no mound under the given nipple"] = (rec, ["--nipple", "-900.25,12.5,640"])
    in_front = nipple - [0.0, 0.0, 150.0]                   # over her breast in the image, 150 mm before her skin
    cases["a given nipple off her skin"] = (rec, ["--nipple", ",".join(f"{v:.1f}" for v in in_front)])
    return folder, cases


SENTENCES = {
    "missing file": "no such file", "empty file": "is empty", "truncated PLY": "truncated",
    "NaN coordinates": "NaN", "not an MCAP": "is not an MCAP recording",
    "MCAP without depth frames": "without RAW16 depth frames", "all-zero depth": "are all zero",
    "frames change size": "change size", "fewer than 500 points after cropping": "fewer than 500",
    "no mound on the requested side": "no breast mound found on the right side",
    "one coordinate 1e30 in mm": "more than any body scan spans",
    "no mound under the given nipple":              # echoed as typed, not in the pipeline's viewing frame
        "no breast mound lies under the given nipple -900.25,12.5,640 (camera mm)",
    "a given nipple off her skin": "mm off the skin of the breast mound under it (at most 25 mm)"}


@pytest.mark.parametrize("case", list(SENTENCES))
def test_bad_input_exits_3_and_writes_nothing(cli, bad_inputs, case):
    folder, cases = bad_inputs
    path, extra = cases[case]
    args = ["ingest", path, "--out", folder / "out"] + (extra if "--side" in extra else ["--side", "left"] + extra)
    res = run(cli, *args)
    assert_bad_input(res, path, folder)
    assert SENTENCES[case] in res.stderr


def test_scan_declared_mm_whose_extent_says_metres(cli, recording, tmp_path):
    folder, _ = recording
    res = run(cli, "ingest", folder / "rec.mcap", "--side", "left", "--out", tmp_path / "case")
    assert res.returncode == 0, res.stderr
    torso = read_ply(tmp_path / "case" / "camera.ply").points / 1000.0
    write_ply(tmp_path / "metres.ply", torso)
    res = run(cli, "ingest", tmp_path / "metres.ply", "--side", "left", "--units", "mm", "--out", tmp_path / "out")
    assert_bad_input(res, tmp_path / "metres.ply", tmp_path)
    assert "metres" in res.stderr


def test_live_device_absent_exits_3(cli, tmp_path):
    res = run(cli, "ingest", "--device", "--side", "left", "--out", tmp_path / "out")
    assert res.returncode == 3 and "no OAK device" in res.stderr and not (tmp_path / "out").exists()


@pytest.mark.parametrize("args", [
    ["ingest", "x.mcap", "--side", "middle", "--out", "o"],
    ["ingest", "--side", "left", "--out", "o"],
    ["ingest", "x.mcap", "--side", "left", "--out", "o", "--roi", "1,2,3"],
    ["scan-synth", "--out", "r.mcap", "--truth", "t.npz", "--side-params", "left:a9=3"],
    ["scan-synth", "--out", "r.mcap", "--truth", "t.npz", "--side-params", "left:a1=1e9"],
    ["scan-synth", "--out", "r.mcap", "--truth", "t.npz", "--side-params", "left:b0=1e6"],
    ["scan-synth", "--out", "r.mcap", "--truth", "t.npz", "--side-params", "right:s0=nan"],
    ["scan-synth", "--out", "r.mcap", "--truth", "t.npz", "--frames", "0"],
])
def test_ingest_usage_errors_exit_2(cli, tmp_path, args):
    res = run(cli, *args)
    assert res.returncode == 2, (res.returncode, res.stderr)


def test_a_summary_claiming_ten_million_messages_is_refused(cli, recording, tmp_path):
    """The MCAP summary's Statistics record (opcode 0x0B) forged to 10⁷ messages, its CRC cleared
    (0 means none, in the MCAP specification); the frames themselves are intact."""
    import struct
    data = bytearray((recording[0] / "rec.mcap").read_bytes())
    footer = len(data) - 8 - 29                          # footer record before the closing magic
    _, _, summary_start, offsets_start, _ = struct.unpack_from("<BQQQI", data, footer)
    pos = summary_start
    while data[pos] != 0x0B:                              # walk the summary's records to Statistics
        pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
    struct.pack_into("<Q", data, pos + 9, 10**7)
    struct.pack_into("<I", data, footer + 25, 0)
    forged = tmp_path / "forged.mcap"
    forged.write_bytes(bytes(data))
    res = run(cli, "ingest", forged, "--side", "left", "--out", tmp_path / "out")
    assert_bad_input(res, forged, tmp_path)
    assert "claims 10,000,000 messages" in res.stderr
