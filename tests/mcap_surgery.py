"""Damaged and forged MCAP recordings, made after the specification (https://mcap.dev/spec): the
faults `ingest` must refuse. Used by tests/test_faults.py and benchmarks/faulty_recordings.py."""
from __future__ import annotations

import struct
from pathlib import Path

from mcap.writer import CompressionType, Writer

CHUNK, STATISTICS = 0x06, 0x0B


def summary_start(data) -> int:
    return struct.unpack_from("<BQQQI", data, len(data) - 8 - 29)[2]     # the footer before the closing magic


def records(data, start, end):
    """(opcode, offset, body length) of the records between two offsets."""
    while start < end:
        op, length = struct.unpack_from("<BQ", data, start)
        yield op, start, length
        start += 9 + length


def chunk_offsets(data) -> list[int]:
    """Offsets of the chunk records of the data section."""
    return [pos for op, pos, _ in records(data, 8, summary_start(data)) if op == CHUNK]


def damage_chunk(src, dst, k, nbytes):
    """Copy `src` with `nbytes` zeroed in the middle of chunk k's compressed records."""
    data = bytearray(Path(src).read_bytes())
    at = chunk_offsets(data)[k] + 9 + 28                                   # past start, end, size, CRC
    at += 4 + struct.unpack_from("<I", data, at)[0]                        # past the compression's name
    length = struct.unpack_from("<Q", data, at)[0]
    middle = at + 8 + length // 2 - nbytes // 2
    data[middle: middle + nbytes] = bytes(nbytes)
    Path(dst).write_bytes(bytes(data))
    return Path(dst)


def forge_count(src, dst, count):
    """Copy `src` with its summary's Statistics record claiming `count` messages (summary CRC cleared:
    0 means none)."""
    data = bytearray(Path(src).read_bytes())
    footer = len(data) - 8 - 29
    pos = next(pos for op, pos, _ in records(data, summary_start(data), footer) if op == STATISTICS)
    struct.pack_into("<Q", data, pos + 9, count)
    struct.pack_into("<I", data, footer + 25, 0)
    Path(dst).write_bytes(bytes(data))
    return Path(dst)


def plain_mcap(path, payloads, compression=CompressionType.NONE, chunk_size=1 << 20):
    """An MCAP written by the `mcap` package: one channel, one message per payload."""
    with open(path, "wb") as fh:
        writer = Writer(fh, chunk_size=chunk_size, compression=compression)
        writer.start()
        schema = writer.register_schema("raw", "", b"")
        channel = writer.register_channel("depth", "raw", schema)
        for i, payload in enumerate(payloads):
            writer.add_message(channel, i, payload, i, sequence=i)
        writer.finish()
    return Path(path)


def flip_byte_of_message(path, k, size):
    """`path` with one byte flipped in the middle of its message k (a payload of `size` bytes, each k)."""
    data = bytearray(Path(path).read_bytes())
    data[data.index(bytes([k]) * size) + size // 2] ^= 0xFF
    Path(path).write_bytes(bytes(data))
    return Path(path)


def declare_chunk_size(path, size):
    """`path` with its first chunk's header declaring `size` uncompressed bytes."""
    data = bytearray(Path(path).read_bytes())
    struct.pack_into("<Q", data, chunk_offsets(data)[0] + 9 + 16, size)
    Path(path).write_bytes(bytes(data))
    return Path(path)
