"""Real faults, end to end: damaged and forged MCAP recordings, a full disk, a file-size limit and
processes killed between the writes of a case's artefacts. Each refused input exits 3 with one
sentence naming the file and leaves nothing behind; each interrupted write leaves the old set or
the new one, never a mix. No mocks: the files are damaged on disk, the disk is a small tmpfs
(skipped without root), the size limit is RLIMIT_FSIZE and the kills are SIGKILL.
"""
import hashlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType

from breastplan import BadInputError, read_ply, write_ply
from breastplan.case import Case
from breastplan.ingest.recording import END_OF_RECORDING, depthai, read_recording, record_messages

from clitools import assert_bad_input, run
from mcap_surgery import damage_chunk, declare_chunk_size, flip_byte_of_message, forge_count, plain_mcap

GB = 1 << 30
FIT = ("--lattice", 3, "--max-iterations", 20)


# --- MCAP surgery (the damaged and forged files: mcap_surgery.py) -------------------------
def messages_per_chunk(path) -> list[int]:
    """Messages of each chunk, from the message indexes the `mcap` package reads."""
    counts = []
    with open(path, "rb") as fh:
        for record in StreamReader(fh, emit_chunks=True).records:
            kind = type(record).__name__
            if kind == "Chunk":
                counts.append(0)
            elif kind == "MessageIndex":
                counts[-1] += len(record.records)
    return counts


# --- running the command with real faults ---------------------------------------------
def run_measured(cli, *args, fsize=None):
    """Run `breastplan ARGS` (under RLIMIT_FSIZE = `fsize` bytes if given): its returncode, stdout,
    stderr and peak RSS in bytes (`rss`, the child's own rusage, from wait4)."""
    def limits():
        if fsize is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)                # a write past it fails with EFBIG
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
    with open(os.devnull, "rb") as null, tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen([cli, *map(str, args)], stdin=null, stdout=out, stderr=err, preexec_fn=limits)
        _, status, usage = os.wait4(proc.pid, 0)
        out.seek(0), err.seek(0)
        return SimpleNamespace(returncode=os.waitstatus_to_exitcode(status), stdout=out.read().decode(),
                               stderr=err.read().decode(), rss=usage.ru_maxrss * 1024)


def refused(cli, path, folder, *args, **kwargs):
    """Run a command that must refuse `path`: exit 3, one line naming it, nothing left in `folder`."""
    res = run_measured(cli, *args, **kwargs)
    assert_bad_input(res, path, folder)
    return res


@pytest.fixture
def small_disk(tmp_path):
    """mount() a fresh tmpfs; mount.fill(point, free) leaves about `free` bytes of it free."""
    mounted = []

    def mount() -> Path:
        point = tmp_path / f"disk{len(mounted)}"
        point.mkdir()
        res = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=16m", "tmpfs", str(point)], capture_output=True)
        if res.returncode != 0:
            pytest.skip(f"a tmpfs cannot be mounted here ({res.stderr.decode().strip() or 'not root'})")
        mounted.append(point)
        return point

    def fill(point: Path, free: int) -> None:
        st = os.statvfs(point)
        with open(point / "filler", "wb") as fh:
            fh.write(bytes(st.f_bavail * st.f_frsize - free))

    mount.fill = fill
    yield mount
    for point in mounted:
        subprocess.run(["umount", "-l", str(point)], capture_output=True)


def digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


# --- a recording, its case and fit ----------------------------------------------------
@pytest.fixture(scope="module")
def made(cli, tmp_path_factory):
    """A 10-frame recording from scan-synth, the case ingest makes of it, and a fit (FIT options)."""
    folder = tmp_path_factory.mktemp("faults")
    res = run(cli, "scan-synth", "--out", folder / "rec.mcap", "--truth", folder / "truth.npz", "--frames", 10,
              "--seed", 2, "--tilt", 10, "--side-params", "right:a5=0.6,b0=0,b1=0")
    assert res.returncode == 0, res.stderr
    res = run(cli, "ingest", folder / "rec.mcap", "--side", "left", "--out", folder / "case", "--json")
    assert res.returncode == 0 and '"frames": 10' in res.stdout, res.stderr
    res = run(cli, "fit", folder / "case", *FIT)
    assert res.returncode == 0, res.stderr
    return folder


# --- damaged and forged recordings --------------------------------------------------
def test_a_chunk_with_64_kb_zeroed_is_refused_naming_its_frames(cli, made, tmp_path):
    counts = messages_per_chunk(made / "rec.mcap")
    bad = damage_chunk(made / "rec.mcap", tmp_path / "zeroed.mcap", 1, 65536)
    first = counts[0]
    res = refused(cli, bad, tmp_path, "ingest", bad, "--side", "left", "--out", tmp_path / "out")
    assert f"is a damaged MCAP recording: chunk 2 of {len(counts)}, holding frames {first}–{first + counts[1] - 1}" \
        in res.stderr


def test_one_damaged_chunk_is_refused_not_filled_from_a_second_pass(cli, made, tmp_path):
    """depthai skips a chunk it cannot read and, looping, would replay frames 0–1 as 9–10."""
    counts = messages_per_chunk(made / "rec.mcap")
    k = int(np.searchsorted(np.cumsum(counts), 4, side="right"))            # the chunk holding frame 4
    bad = damage_chunk(made / "rec.mcap", tmp_path / "damaged.mcap", k, 4096)
    first = sum(counts[:k])
    res = refused(cli, bad, tmp_path, "ingest", bad, "--side", "left", "--out", tmp_path / "out")
    assert f"holding frames {first}–{first + counts[k] - 1} (counting from 0)" in res.stderr
    assert "copy the recording again" in res.stderr
    with pytest.raises(BadInputError, match="damaged"):
        read_recording(bad)


@pytest.mark.parametrize("claim,sentence", [
    (10**7, "summary claims 10,000,000 messages, more than any body scan holds"),
    (2_000, "its summary claims 2,000 messages but its data section holds 11"),
    (5, "its summary claims 5 messages but its data section holds 11"),
])
def test_a_summary_that_lies_is_refused_up_front_in_little_memory(cli, made, tmp_path, claim, sentence):
    forged = forge_count(made / "rec.mcap", tmp_path / "forged.mcap", claim)
    res = refused(cli, forged, tmp_path, "ingest", forged, "--side", "left", "--out", tmp_path / "out")
    assert sentence in res.stderr
    assert res.rss <= GB, f"peak RSS {res.rss / 2**20:.0f} MB"


def test_a_flipped_byte_in_an_uncompressed_chunk_fails_its_crc(tmp_path):
    path = plain_mcap(tmp_path / "plain.mcap", [bytes([i]) * 1000 for i in range(6)], chunk_size=2000)
    assert messages_per_chunk(path) == [2, 2, 2]
    flip_byte_of_message(path, 3, 1000)
    with pytest.raises(BadInputError, match=r"plain\.mcap: is a damaged MCAP recording: chunk 2 of 3, holding "
                                            r"frames 2–3 \(counting from 0\), cannot be read because its data "
                                            r"fails the CRC-32 check"):
        read_recording(path)


def test_a_chunk_declaring_a_huge_size_is_refused_before_it_is_decompressed(tmp_path):
    path = plain_mcap(tmp_path / "bomb.mcap", [b"\0" * 1000] * 3, compression=CompressionType.LZ4)
    declare_chunk_size(path, 1 << 40)                                      # uncompressed size: 1 TB
    with pytest.raises(BadInputError, match="chunk 1 declares 1,099,511,627,776 bytes, more than"):
        read_recording(path)


def test_a_recording_compressed_with_zstd_is_refused_saying_depthai_cannot_replay_it(tmp_path):
    """A valid MCAP whose chunks are zstd-compressed: depthai's replay reads none of its messages."""
    path = plain_mcap(tmp_path / "zstd.mcap", [b"\0" * 1000] * 3, compression=CompressionType.ZSTD)
    with pytest.raises(BadInputError, match=r"zstd\.mcap: is an MCAP recording compressed with 'zstd', which "
                                            r"depthai's replay cannot read; record it .* with lz4"):
        read_recording(path)


def test_more_messages_than_a_body_scan_holds_are_refused_whatever_the_summary_says(tmp_path):
    path = forge_count(plain_mcap(tmp_path / "many.mcap", [b"x"] * 3_500), tmp_path / "lying.mcap", 11)
    with pytest.raises(BadInputError, match=r"lying\.mcap: is an MCAP recording of more than 3,000 messages"):
        read_recording(path)


def frame(dai, value, seq):
    f = dai.ImgFrame()
    f.setType(dai.ImgFrame.Type.RAW16)
    f.setWidth(8)
    f.setHeight(4)
    f.setFrame(np.full((4, 8), value, np.uint16))
    f.setTransformation(dai.ImgTransformation(8, 4, [[5.0, 0, 4], [0, 5.0, 2], [0, 0, 1]]))
    f.setSequenceNum(seq)
    return f


def test_frames_are_replayed_once_each_in_sequence_and_repeats_are_refused(tmp_path):
    dai = depthai()
    record_messages(tmp_path / "once.mcap", [frame(dai, 600 + i, i) for i in range(6)]
                    + [frame(dai, 605, END_OF_RECORDING)])
    back = read_recording(tmp_path / "once.mcap").depth[:, 0, 0]
    assert back.tolist() == list(range(600, 606))                           # each frame once, none from a loop
    seqs = [0, 1, 2, 0, 1]                                                  # two takes run together
    record_messages(tmp_path / "twice.mcap", [frame(dai, 600 + i, s) for i, s in enumerate(seqs)]
                    + [frame(dai, 600, END_OF_RECORDING)])
    with pytest.raises(BadInputError, match=r"twice\.mcap: is a recording whose frame 3 has sequence number 0, "
                                            r"not after 2: its frames repeat"):
        read_recording(tmp_path / "twice.mcap")


def damaged_frame(dai, width, height, data, stride):
    f = frame(dai, 600, 0)
    f.setWidth(width)
    f.setHeight(height)
    f.setData(data)
    f.setStride(stride)
    return f


@pytest.mark.parametrize("width, height, data, stride, problem", [
    (8, 4, bytes(10), 16, r"its depth frame 1 \(8×4\) holds 10 bytes in rows of 16 where RAW16 needs 64 in rows"),
    (8, 4, bytes(64), 4, r"its depth frame 1 \(8×4\) holds 64 bytes in rows of 4 where RAW16 needs 64 in rows of 16"),
    (0, 4, bytes(64), 0, r"its depth frame 1 is 0×4 pixels; a depth camera's are 1 to 4096 a side"),
    (2**31, 4, bytes(64), 16, r"its depth frame 1 is 2147483648×4 pixels"),
])
def test_a_frame_whose_size_stride_and_data_disagree_is_refused_not_decoded(tmp_path, width, height, data, stride,
                                                                             problem):
    """Truth: a RAW16 image of W×H pixels is W·H·2 bytes in rows of 2·W; a frame saying otherwise is damaged
    (depthai itself would refuse it, or read past its data)."""
    record_messages(tmp_path / "damaged.mcap", [damaged_frame(depthai(), width, height, data, stride)])
    with pytest.raises(BadInputError, match=r"damaged\.mcap: " + problem):
        read_recording(tmp_path / "damaged.mcap")


# --- a full disk, a file-size limit ------------------------------------------------
def test_ingest_on_a_full_disk_names_the_file_and_writes_nothing(cli, made, small_disk):
    disk = small_disk()
    small_disk.fill(disk, (made / "case" / "scan.ply").stat().st_size + 40 * 1024)   # scan.ply fits, camera.ply not
    res = refused(cli, disk / "case" / "camera.ply", disk, "ingest", made / "rec.mcap", "--side", "left",
                  "--out", disk / "case")
    assert "No space left on device" in res.stderr
    assert sorted(p.name for p in disk.iterdir()) == ["filler"]             # not even the case folder


def test_ingest_past_a_file_size_limit_keeps_the_previous_set(cli, made, tmp_path):
    case = tmp_path / "case"
    shutil.copytree(made / "case", case)
    before = digest(case)
    limit = (case / "scan.ply").stat().st_size + 1024                      # scan.ply fits, camera.ply not
    res = refused(cli, case / "camera.ply", case, "ingest", made / "rec.mcap", "--side", "left", "--out", case,
                  "--voxel", 2.5, fsize=limit)
    assert "File too large" in res.stderr
    assert digest(case) == before


def test_a_refit_on_a_full_disk_fails_at_its_second_file_and_keeps_the_old_set(cli, made, small_disk):
    disk = small_disk()
    case = disk / "case"
    shutil.copytree(made / "case", case)
    before = digest(case)
    small_disk.fill(disk, (case / "fit.ply").stat().st_size + 8 * 1024)   # fit.ply fits, fit.npz not
    res = refused(cli, case / "fit.npz", disk, "fit", case, "--lattice", 4, "--max-iterations", 20)
    assert "No space left on device" in res.stderr
    assert digest(case) == before
    assert Case(case).load_fit().lattice_shape.tolist() == [3, 3, 3]


@pytest.mark.parametrize("limit,failing", [(1000, "S-shape1-00.ply"), (50_000, "database.npz")])
def test_synth_ply_past_a_file_size_limit_writes_nothing(cli, tmp_path, limit, failing):
    res = refused(cli, tmp_path / "db" / failing, tmp_path, "synth", "--db", "S", "--points", 100, "--ply",
                  "--out", tmp_path / "db", fsize=limit)
    assert "File too large" in res.stderr and not (tmp_path / "db").exists()
    assert run(cli, "synth", "--db", "S", "--points", 100, "--ply", "--out", tmp_path / "db").returncode == 0
    before = digest(tmp_path / "db")
    refused(cli, tmp_path / "db" / failing, tmp_path / "db", "synth", "--db", "S", "--points", 100, "--ply",
            "--seed", 1, "--out", tmp_path / "db", fsize=limit)
    assert digest(tmp_path / "db") == before                                # the old database and its PLYs


# --- killed between writes -------------------------------------------------------
HOOKS = """
import os, sys

def paused(name, real):
    def call(*args, **kwargs):
        print("step", name, *args, flush=True)        # report the step, then wait for the go-ahead
        sys.stdin.readline()
        return real(*args, **kwargs)
    return call

for name in ("replace", "fsync", "unlink"):
    setattr(os, name, paused(name, getattr(os, name)))
"""

REFIT = HOOKS + """
import dataclasses
from breastplan.case import Case
case = Case(sys.argv[1])
old = case.load_fit()
case.save_fit(dataclasses.replace(old, vertices=old.vertices + 1.0, normalised_residual=0.5))
"""


def run_until(script: Path, args, kill_at=None, when=None):
    """Run `script`, letting it take one step at a time; SIGKILL it before step `kill_at` (1-based) or
    before the step after one for which `when(step)` holds. The steps it reported."""
    proc = subprocess.Popen([sys.executable, str(script), *map(str, args)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    steps, kill_next = [], False
    for line in proc.stdout:
        if not line.startswith("step "):
            continue
        steps.append(line.split()[1:])
        if len(steps) == kill_at or kill_next:
            proc.kill()
            break
        kill_next = bool(when and when(steps[-1]))
        proc.stdin.write("\n")
        proc.stdin.flush()
    assert proc.wait() == (-signal.SIGKILL if kill_at or when else 0)
    return steps


def test_a_refit_killed_at_any_step_leaves_the_old_fit_or_the_new_one(made, tmp_path):
    script = tmp_path / "refit.py"
    script.write_text(REFIT)
    old = Case(made / "case").load_fit()
    steps = run_until(script, [shutil.copytree(made / "case", tmp_path / "whole")])
    assert Case(tmp_path / "whole").load_fit().normalised_residual == 0.5
    assert sorted(p.name for p in (tmp_path / "whole").iterdir()) == sorted(p.name for p in (made / "case").iterdir())
    seen = []
    for k in range(1, len(steps) + 1):
        case = shutil.copytree(made / "case", tmp_path / f"killed{k}")
        run_until(script, [case], kill_at=k)
        fit = Case(case).load_fit()                                         # completes a committed set
        new = fit.normalised_residual == 0.5
        assert np.array_equal(fit.vertices, old.vertices + 1.0 if new else old.vertices), k
        if not new:
            assert fit.normalised_residual == old.normalised_residual, k
        seen.append(new)
        Case(case).save_fit(old)                                            # the next write sweeps what a kill left
        assert not [p.name for p in case.iterdir() if p.name.startswith(".")], k
    assert seen[0] is False and seen[-1] is True and seen == sorted(seen)   # old until the commit point, then new


def test_a_journal_that_names_other_files_than_staged_ones_is_ignored(made, tmp_path):
    case = shutil.copytree(made / "case", tmp_path / "case")
    (tmp_path / "victim").write_text("keep me")
    forged = case / ".fit.npz.commit"
    forged.write_text(json.dumps({"schema": "breastplan.commit/1", "renames": [["../victim", "fit.ply"]]}))
    before = digest(case)
    assert Case(case).load_fit().lattice_shape.tolist() == [3, 3, 3]
    assert digest(case) == before and (tmp_path / "victim").read_text() == "keep me"


def test_a_refit_command_killed_between_its_two_renames_leaves_the_new_fit(cli, made, tmp_path):
    script = tmp_path / "fit_command.py"
    script.write_text(HOOKS + "from breastplan.cli.main import main\nsys.argv[0] = 'breastplan'\nmain()\n")
    case = shutil.copytree(made / "case", tmp_path / "case")
    steps = run_until(script, ["fit", case, "--lattice", 4, "--max-iterations", 20],
                      when=lambda step: step[0] == "replace" and step[-1] == str(case / "fit.ply"))
    assert steps[-2][-1] == str(case / "fit.ply")                           # killed right after fit.ply's rename
    assert any(p.name.endswith(".commit") for p in case.iterdir())          # fit.npz is still the old one
    assert Case(case).load_fit().lattice_shape.tolist() == [4, 4, 4]        # the new set, completed on load
    assert not any(p.name.startswith(".") for p in case.iterdir())
    res = run(cli, "deform", case, "--kind", "ptosis", "--param", "b0=0.1", "--out", tmp_path / "moved.ply")
    assert res.returncode == 0, res.stderr


# --- a mixed set is refused ------------------------------------------------------
@pytest.mark.parametrize("command,replaced", [("deform", "fit.ply"), ("fit", "camera.ply"), ("fit", "scan.ply")])
def test_a_case_holding_a_mixed_set_is_refused(cli, made, tmp_path, command, replaced):
    case = shutil.copytree(made / "case", tmp_path / "case")
    geometry = read_ply(case / replaced)
    write_ply(case / replaced, geometry.points + 1.0, normals=geometry.normals, faces=geometry.faces,
              comments=geometry.comments)                                   # a file of another write
    before = digest(case)
    args = ["--kind", "ptosis", "--param", "b0=0.1", "--out", tmp_path / "out.ply"] if command == "deform" else []
    res = refused(cli, case / replaced, tmp_path, command, case, *args)
    assert "is not the file" in res.stderr and "was written with" in res.stderr
    assert digest(case) == before
