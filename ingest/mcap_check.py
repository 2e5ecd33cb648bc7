"""Checking an MCAP recording before depthai replays it (https://mcap.dev/spec).

depthai's ReplayMessage skips a chunk it cannot read, and the summary's message count can say
anything. So before a frame is replayed the file is checked whole: its summary's message count
(read with the `mcap` package) must be one a body scan can hold, and a walk of its data section
— each chunk decompressed within its declared size and checked against its CRC-32, one chunk in
memory at a time — must find that many messages and no damage. Anything else is refused with one
sentence naming the file (BadInputError); no exception of the `mcap` package escapes.
"""
from __future__ import annotations

import io
import struct
import zlib
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.stream_reader import MAGIC_SIZE, read_magic

from breastplan import BadInputError, require_file

MAX_MESSAGES = 3_000
"""Messages a recording may hold: 100 s of a 30 fps depth stream; a body scan takes seconds."""
MAX_DATA_BYTES = 1 << 30
"""Uncompressed message bytes a recording may hold: 2 000 frames of 640×400, 500 of 1280×800."""
MAX_CHUNK_BYTES = 64 << 20
"""Bytes of one chunk, compressed or not (depthai writes chunks of about 1 MB)."""
MAX_RECORDS = 100_000
"""Records of any kind a recording may hold (bounds the time a forged file can cost)."""
FOOTER, MESSAGE, CHUNK, MESSAGE_INDEX, DATA_END = 0x02, 0x05, 0x06, 0x07, 0x0F
_RECORD = struct.Struct("<BQ")
_CHUNK = struct.Struct("<QQQI")


def check_recording(path: Path) -> int:
    """The number of messages of a whole, undamaged MCAP recording; BadInputError otherwise."""
    require_file(path, "recording")
    with open(path, "rb") as fh:
        claimed = _summary_count(path, fh)
        found = _Walk(path, fh).run()
    if found != claimed:
        raise BadInputError(path, f"is a corrupt MCAP recording: its summary claims {claimed:,} messages but its "
                                  f"data section holds {found:,}")
    return found


def _summary_count(path: Path, fh) -> int:
    """The message count of the summary's statistics, refused if no body scan holds that many."""
    try:
        reader = make_reader(fh)                           # checks the leading magic bytes
    except Exception:
        raise BadInputError(path, "is not an MCAP recording (it lacks the MCAP magic bytes)") from None
    try:
        fh.seek(-MAGIC_SIZE, io.SEEK_END)                 # a whole recording ends with them again
        read_magic(ReadDataStream(fh))
    except Exception:
        raise BadInputError(path, "is a truncated MCAP recording (its end is missing)") from None
    try:
        summary = reader.get_summary()
        stats = None if summary is None else summary.statistics
        count = None if stats is None else stats.message_count
    except Exception:
        raise BadInputError(path, "is a corrupt MCAP recording (its summary section cannot be read)") from None
    if not isinstance(count, int) or count < 0:
        raise BadInputError(path, "is a corrupt MCAP recording (its summary holds no message count)")
    if count > MAX_MESSAGES:
        raise BadInputError(path, f"is an MCAP recording whose summary claims {count:,} messages, more than any "
                                  f"body scan holds ({MAX_MESSAGES:,} frames, 100 s at 30 fps)")
    return count


class _Walk:
    """One pass over the records of the data section: messages counted, chunks checked."""

    def __init__(self, path: Path, fh):
        self.path, self.fh = path, fh
        self.end = fh.seek(0, io.SEEK_END) - MAGIC_SIZE
        self.messages = self.records = self.chunks = self.data_bytes = 0
        self.damaged: list[list] = []     # [chunk number, first message, messages or None, why]

    def run(self) -> int:
        pos = MAGIC_SIZE
        while pos < self.end:
            self.fh.seek(pos)
            head = self.fh.read(_RECORD.size)
            op, length = _RECORD.unpack(head) if len(head) == _RECORD.size else (None, 0)
            if op is None or length > self.end - pos - _RECORD.size:
                raise BadInputError(self.path, f"is a corrupt MCAP recording (its record at byte {pos:,} runs past "
                                               f"the end of the file)")
            self._count_record()
            if op in (DATA_END, FOOTER):                   # the summary section follows
                break
            if op == CHUNK:
                self._chunk(length)
            elif op == MESSAGE:                            # a message outside any chunk
                self._message()
                self._count_bytes(length)
            elif op == MESSAGE_INDEX and self.damaged and self.damaged[-1][0] == self.chunks:
                self._index_of_damaged(length)
            pos += _RECORD.size + length
        if self.damaged:
            raise BadInputError(self.path, self._damage())
        return self.messages

    def _count_record(self) -> None:
        self.records += 1
        if self.records > MAX_RECORDS:
            raise BadInputError(self.path, f"is an MCAP recording of more than {MAX_RECORDS:,} records, more than "
                                           f"any body scan holds")

    def _message(self) -> None:
        self.messages += 1
        if self.messages > MAX_MESSAGES:
            raise BadInputError(self.path, f"is an MCAP recording of more than {MAX_MESSAGES:,} messages, more "
                                           f"than any body scan holds")

    def _count_bytes(self, n: int) -> None:
        self.data_bytes += n
        if self.data_bytes > MAX_DATA_BYTES:
            raise BadInputError(self.path, f"is an MCAP recording of more than {MAX_DATA_BYTES >> 20:,} MB of "
                                           f"depth data, more than any body scan holds")

    def _chunk(self, length: int) -> None:
        self.chunks += 1
        if length > MAX_CHUNK_BYTES:
            raise BadInputError(self.path, f"is an MCAP recording whose chunk {self.chunks} takes {length:,} bytes, "
                                           f"more than a recording's chunks do ({MAX_CHUNK_BYTES >> 20} MB)")
        body = self.fh.read(length)
        first = self.messages
        try:
            data = self._chunk_data(body)
        except ValueError as exc:
            self.damaged.append([self.chunks, first, None, str(exc)])
            return
        try:
            for op in _opcodes(data):
                self._count_record()
                if op == MESSAGE:
                    self._message()
        except ValueError as exc:
            self.messages = first
            self.damaged.append([self.chunks, first, None, str(exc)])

    def _chunk_data(self, body: bytes) -> bytes:
        """The uncompressed records of a chunk; ValueError saying why they cannot be trusted."""
        if len(body) < _CHUNK.size + 4:
            raise ValueError("its chunk header is cut short")
        _, _, size, crc = _CHUNK.unpack_from(body)
        name_len = struct.unpack_from("<I", body, _CHUNK.size)[0]
        at = _CHUNK.size + 4 + name_len
        if at + 8 > len(body) or struct.unpack_from("<Q", body, at)[0] != len(body) - at - 8:
            raise ValueError("its chunk header is malformed")
        compression = body[_CHUNK.size + 4: at].decode(errors="replace")
        if size > MAX_CHUNK_BYTES:
            raise BadInputError(self.path, f"is an MCAP recording whose chunk {self.chunks} declares {size:,} bytes, "
                                           f"more than a recording's chunks hold ({MAX_CHUNK_BYTES >> 20} MB)")
        self._count_bytes(size)
        data = _decompress(compression, memoryview(body)[at + 8:], size, self.path)
        if len(data) != size:
            raise ValueError(f"it decompresses to {len(data):,} bytes, not the {size:,} its header declares")
        if crc and zlib.crc32(data) != crc:
            raise ValueError("its data fails the CRC-32 check")
        return data

    def _index_of_damaged(self, length: int) -> None:
        """Count a damaged chunk's messages from the message index that follows it."""
        entry = self.fh.read(min(length, 6))
        count = struct.unpack_from("<I", entry, 2)[0] // 16 if len(entry) == 6 else MAX_MESSAGES + 1
        if count <= MAX_MESSAGES:                          # else the index is damaged too: count unknown
            damaged = self.damaged[-1]
            damaged[2] = (damaged[2] or 0) + count
            self.messages += count

    def _damage(self) -> str:
        chunk, first, count, why = self.damaged[0]
        frames = (f"frame {first}" if count == 1 else f"frames {first}–{first + count - 1}" if count
                  else f"the frames from frame {first} on")
        more = len(self.damaged) - 1
        others = f", and {more} more of its chunks are damaged too" if more else ""
        return (f"is a damaged MCAP recording: chunk {chunk} of {self.chunks}, holding {frames} (counting from 0), "
                f"cannot be read because {why}{others}; copy the recording again from the machine that made it")


def _opcodes(data: bytes):
    """The opcode of each record in a chunk's uncompressed data; ValueError if they do not add up."""
    pos = 0
    while pos < len(data):
        if pos + _RECORD.size > len(data):
            raise ValueError("its records are cut short")
        op, length = _RECORD.unpack_from(data, pos)
        pos += _RECORD.size
        if length > len(data) - pos:
            raise ValueError("a record in it runs past its end")
        yield op
        pos += length


def _decompress(compression: str, data, size: int, path: Path) -> bytes:
    """At most `size` + 1 bytes of a chunk's data; ValueError if it cannot be decompressed."""
    if compression == "zstd":
        raise BadInputError(path, "is an MCAP recording compressed with 'zstd', which depthai's replay cannot read; "
                                  "record it (or write it again) with lz4 or no compression")
    if compression not in ("", "lz4"):
        raise BadInputError(path, f"is an MCAP recording compressed with '{compression}', which breastplan "
                                  f"cannot read")
    try:
        if compression == "lz4":
            import lz4.frame
            return lz4.frame.LZ4FrameDecompressor().decompress(bytes(data), max_length=size + 1)
        return bytes(data)
    except Exception as exc:                               # lz4 raises RuntimeError
        raise ValueError("its data cannot be decompressed") from exc
