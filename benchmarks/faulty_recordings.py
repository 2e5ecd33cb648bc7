"""MCAP recordings `ingest` must refuse, for bench_refusal.py (tests/test_faults.py checks them).

Each is made from one intact 10-frame recording of the synthetic scanner (written once per run),
damaged or forged by tests/mcap_surgery.py (after the MCAP specification), or written whole by
the `mcap` package. `RECORDINGS` lists (name, build(folder) → path).
"""
from __future__ import annotations

import atexit
import functools
import shutil
import sys
import tempfile
from pathlib import Path

from mcap.writer import CompressionType

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from mcap_surgery import damage_chunk, declare_chunk_size, flip_byte_of_message, forge_count, plain_mcap  # noqa: E402


@functools.cache
def _intact() -> Path:
    from breastplan.scenes import synthetic
    from breastplan.ingest.recording import write_recording

    folder = Path(tempfile.mkdtemp(prefix="bench_recording_"))
    atexit.register(shutil.rmtree, folder, True)
    scene = synthetic.make_scene(1, tilt_deg=10.0)
    return write_recording(folder / "rec.mcap", synthetic.depth_frames(scene, 10, 1), scene.K)


def zeroed(k: int, nbytes: int):
    """The intact recording with `nbytes` zeroed in the middle of chunk k's compressed records."""
    return lambda folder: damage_chunk(_intact(), folder / f"zeroed{nbytes}.mcap", k, nbytes)


def claiming(count: int, base=None):
    """A recording (the intact one, or `base`'s) whose summary claims `count` messages."""
    return lambda folder: forge_count(base(folder) if base else _intact(), folder / f"claims{count}.mcap", count)


def plain(name: str, payloads, compression: str = "none", chunk_size: int = 1 << 20):
    """An MCAP the `mcap` package writes: one channel, one message per payload."""
    return lambda folder: plain_mcap(folder / name, payloads, CompressionType[compression.upper()], chunk_size)


def flipped_byte(folder: Path) -> Path:
    """An uncompressed chunk with one byte of a message flipped: only its CRC-32 tells."""
    return flip_byte_of_message(plain("flipped.mcap", [bytes([i]) * 1000 for i in range(6)], chunk_size=2000)(folder),
                                3, 1000)


def bomb(folder: Path) -> Path:
    """An LZ4 chunk whose header declares 1 TB uncompressed."""
    return declare_chunk_size(plain("bomb.mcap", [b"\0" * 1000] * 3, "lz4")(folder), 1 << 40)


RECORDINGS = [
    ("MCAP, 64 kB of a chunk zeroed", zeroed(1, 65536)),
    ("MCAP, one chunk damaged (frames 4-5)", zeroed(2, 4096)),
    ("MCAP, a byte flipped in an uncompressed chunk (CRC)", flipped_byte),
    ("MCAP, summary claiming 10^7 messages", claiming(10**7)),
    ("MCAP, summary claiming 2 000 of its 11 messages", claiming(2_000)),
    ("MCAP, summary claiming 5 of its 11 messages", claiming(5)),
    ("MCAP, a chunk declaring 1 TB uncompressed", bomb),
    ("MCAP, 3 500 messages, summary claiming 11", claiming(11, plain("many.mcap", [b"x"] * 3_500))),
]
