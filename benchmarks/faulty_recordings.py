"""MCAP recordings `ingest` must refuse, for bench_refusal.py (tests/test_faults.py checks them).

Each is made from one intact 10-frame recording of the synthetic scanner (written once per run),
damaged or forged after the MCAP specification (https://mcap.dev/spec), or written whole by the
`mcap` package. `RECORDINGS` lists (name, build(folder) → path).
"""
from __future__ import annotations

import atexit
import functools
import shutil
import struct
import tempfile
from pathlib import Path


@functools.cache
def _intact() -> Path:
    from breastplan.ingest import synthetic
    from breastplan.ingest.recording import write_recording

    folder = Path(tempfile.mkdtemp(prefix="bench_recording_"))
    atexit.register(shutil.rmtree, folder, True)
    scene = synthetic.make_scene(1, tilt_deg=10.0)
    return write_recording(folder / "rec.mcap", synthetic.depth_frames(scene, 10, 1), scene.K)


def _records(data, start: int, end: int):
    while start < end:
        op, length = struct.unpack_from("<BQ", data, start)
        yield op, start, length
        start += 9 + length


def _summary_start(data) -> int:
    return struct.unpack_from("<BQQQI", data, len(data) - 37)[2]


def _chunks(data) -> list[int]:
    return [pos for op, pos, _ in _records(data, 8, _summary_start(data)) if op == 0x06]


def zeroed(k: int, nbytes: int):
    """The intact recording with `nbytes` zeroed in the middle of chunk k's compressed records."""
    def build(folder: Path) -> Path:
        data = bytearray(_intact().read_bytes())
        at = _chunks(data)[k] + 9 + 28
        at += 4 + struct.unpack_from("<I", data, at)[0]
        middle = at + 8 + struct.unpack_from("<Q", data, at)[0] // 2 - nbytes // 2
        data[middle: middle + nbytes] = bytes(nbytes)
        return _write(folder / f"zeroed{nbytes}.mcap", data)
    return build


def claiming(count: int, base=None):
    """A recording whose summary's Statistics claim `count` messages (summary CRC cleared)."""
    def build(folder: Path) -> Path:
        data = bytearray((base(folder) if base else _intact()).read_bytes())
        footer = len(data) - 37
        pos = next(pos for op, pos, _ in _records(data, _summary_start(data), footer) if op == 0x0B)
        struct.pack_into("<Q", data, pos + 9, count)
        struct.pack_into("<I", data, footer + 25, 0)
        return _write(folder / f"claims{count}.mcap", data)
    return build


def plain(name: str, payloads, compression: str = "none", chunk_size: int = 1 << 20):
    """An MCAP the `mcap` package writes: one channel, one message per payload."""
    def build(folder: Path) -> Path:
        from mcap.writer import CompressionType, Writer

        with open(folder / name, "wb") as fh:
            writer = Writer(fh, chunk_size=chunk_size, compression=CompressionType[compression.upper()])
            writer.start()
            channel = writer.register_channel("depth", "raw", writer.register_schema("raw", "", b""))
            for i, payload in enumerate(payloads):
                writer.add_message(channel, i, payload, i, sequence=i)
            writer.finish()
        return folder / name
    return build


def flipped_byte(folder: Path) -> Path:
    """An uncompressed chunk with one byte of a message flipped: only its CRC-32 tells."""
    path = plain("flipped.mcap", [bytes([i]) * 1000 for i in range(6)], chunk_size=2000)(folder)
    data = bytearray(path.read_bytes())
    data[data.index(bytes([3]) * 1000) + 500] ^= 0xFF
    return _write(path, data)


def bomb(folder: Path) -> Path:
    """An LZ4 chunk whose header declares 1 TB uncompressed."""
    path = plain("bomb.mcap", [b"\0" * 1000] * 3, "lz4")(folder)
    data = bytearray(path.read_bytes())
    struct.pack_into("<Q", data, _chunks(data)[0] + 9 + 16, 1 << 40)
    return _write(path, data)


def _write(path: Path, data) -> Path:
    path.write_bytes(bytes(data))
    return path


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
