"""depthai recordings of depth frames (docs/design.md "Known facts").

A recording is an MCAP file written by `dai.node.RecordMessage` in a host-only pipeline
(`dai.Pipeline(False)`): RAW16 `ImgFrame`s holding depth in millimetres (0 = no
measurement), each carrying its pinhole intrinsics in its `ImgTransformation`, and optionally the
colour camera's RGB888i/BGR888i `ImgFrame`s aligned to depth (the same pixels). Replay goes
through `dai.node.ReplayMessage`, unpaced (as fast as the host can take the frames).
"""
from __future__ import annotations

import datetime
import errno
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from breastplan import BadInputError
from breastplan.atomic import atomic_set

from .mcap_check import check_recording

MCAP_MAGIC = b"\x89MCAP0\r\n"
END_OF_RECORDING = 2**31 - 1
"""Sequence number of the end marker (a copy of the last frame) that readers skip: once the
recorder has taken it from its input, every real frame before it is written."""
DRAIN_POLL_S = 0.002
UNPACED_FPS = 1e6
"""Replay rate asked of ReplayMessage: far above any camera's, so replay is not paced."""
MAX_SIDE_PX = 4096
"""The largest depth image side replayed: depth cameras give at most 1280×800."""
MAX_COLOUR_FRAMES = 30
"""Her colour is the median of at most this many colour frames (the first)."""


def depthai():
    """Import depthai quietly (it prints a USB warning on stdout otherwise), leaving signals to Python
    (depthai's crash handler would turn SIGXFSZ, which Python ignores so that a write past a file-size
    limit fails with an OSError naming the file, into a crash)."""
    os.environ.setdefault("DEPTHAI_LEVEL", "off")  # problems surface as our own errors
    os.environ.setdefault("DEPTHAI_INSTALL_SIGNAL_HANDLER", "0")
    import depthai as dai
    return dai


@dataclass(frozen=True)
class DepthFrames:
    """A stack of depth frames from one camera: depth (N, H, W) uint16 mm, K (3, 3) px, and the colour
    seen at each depth pixel ((H, W, 3) uint8 RGB, the median of the colour frames aligned to depth;
    None: no colour recorded)."""

    depth: np.ndarray
    K: np.ndarray
    source: str
    colour: np.ndarray | None = None

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return int(self.depth.shape[2]), int(self.depth.shape[1])


def write_recording(path: str | Path, depth, K: np.ndarray, fps: float = 30.0, colour=None) -> Path:
    """Record depth frames ((N, H, W) or a sequence of (H, W); uint16 mm) with intrinsics K, atomically;
    with `colour` ((H, W, 3) uint8 RGB aligned to depth, or one such per depth frame), a colour frame after
    the first depth frame (or after each)."""
    dai = depthai()
    frames = [np.ascontiguousarray(frame, dtype=np.uint16) for frame in depth]
    if not frames:
        raise ValueError("a recording needs at least one depth frame")
    colour = None if colour is None else np.ascontiguousarray(colour, dtype=np.uint8)
    colours = [] if colour is None else [colour] if colour.ndim == 3 else list(colour)
    messages = []
    for i, frame in enumerate(frames):
        messages.append(_img_frame(dai, frame, K, i, i / fps))
        if i < len(colours):
            messages.append(_img_frame(dai, colours[i], K, i, i / fps))
    marker = _img_frame(dai, frames[-1], K, END_OF_RECORDING, len(frames) / fps)  # the last frame again
    return record_messages(path, messages + [marker])


def record_messages(path: str | Path, messages) -> Path:
    """Record depthai messages through RecordMessage into an MCAP file, atomically; OSError naming
    `path` unless the file holds every message.

    Messages go straight into the recorder's blocking input, which writes each before taking the
    next: once it has taken the last, all before it are written. The caller ends with a marker
    message (readers skip it) so that the last real message is written before the pipeline stops.
    """
    path, messages = Path(path), list(messages)
    with atomic_set() as stage:
        part = stage(path)
        open(part, "wb").close()  # an unwritable path fails here, naming itself, not in depthai's thread
        _record(part, messages)
        _verify(part, len(messages))
    return path


def _record(part: Path, messages: list) -> None:
    """Send `messages` to a RecordMessage node writing `part`; stop it once it has taken the last."""
    dai = depthai()
    pipeline = dai.Pipeline(False)
    rec = pipeline.create(dai.node.RecordMessage)
    rec.setRecordFile(str(part))
    rec.input.setBlocking(True)  # a non-blocking input drops messages sent faster than they are written
    rec.input.setMaxSize(4)
    pipeline.start()
    try:
        for message in messages:
            rec.input.send(message)  # not via createInputQueue: its forwarding node hides messages in flight
        while rec.input.has():
            time.sleep(DRAIN_POLL_S)
    except dai.MessageQueue.QueueException:  # the recorder failed and its input was closed
        raise OSError(errno.EIO, "depthai's recorder stopped before it had written every message", str(part)) from None
    finally:
        pipeline.stop()
        pipeline.wait()


def _verify(part: Path, expected: int) -> None:
    """OSError naming `part` unless it is a whole MCAP recording of `expected` messages."""
    try:
        written = check_recording(part)
    except BadInputError as exc:
        raise OSError(errno.EIO, f"depthai's recorder wrote a file that {exc.problem}", str(part)) from None
    if written != expected:
        raise OSError(errno.EIO, f"depthai's recorder wrote {written} of the {expected} messages sent to it",
                      str(part))


def _img_frame(dai, image: np.ndarray, K: np.ndarray, seq: int, seconds: float):
    """A RAW16 depth frame ((H, W) uint16) or an RGB888i colour frame ((H, W, 3) uint8)."""
    h, w = image.shape[:2]
    frame = dai.ImgFrame()
    frame.setType(dai.ImgFrame.Type.RAW16 if image.ndim == 2 else dai.ImgFrame.Type.RGB888i)
    frame.setWidth(w)
    frame.setHeight(h)
    frame.setFrame(image)
    frame.setTransformation(dai.ImgTransformation(w, h, np.asarray(K, float).tolist()))
    frame.setSequenceNum(seq)
    stamp = datetime.timedelta(seconds=seconds)
    frame.setTimestamp(stamp)
    frame.setTimestampDevice(stamp)
    return frame


def read_recording(path: str | Path, max_frames: int | None = None) -> DepthFrames:
    """Replay the RAW16 depth frames of an MCAP recording (at most `max_frames`), once each.

    The file is checked whole first (`check_recording`); frames are then taken in the order of
    their sequence numbers until the end marker or the file's last message, never from a second pass.
    """
    path = Path(path)
    count = check_recording(path)
    if count == 0:
        raise BadInputError(path, "is an MCAP recording without messages (no depth frames)")
    types = depthai().ImgFrame.Type
    stack, K, frames, last, messages, ended, colours = None, None, 0, -1, 0, False, []
    for messages, msg in enumerate(_replay(path, count), 1):
        if type(msg).__name__ != "ImgFrame":
            continue
        if msg.getType() in (types.RGB888i, types.BGR888i):
            if len(colours) < MAX_COLOUR_FRAMES:
                colours.append(colour_of(msg, msg.getType() == types.BGR888i))
            continue
        if msg.getType() != types.RAW16:
            continue
        seq = msg.getSequenceNum()
        if seq == END_OF_RECORDING:
            ended = True
            break
        if seq <= last:
            raise BadInputError(path, f"is a recording whose frame {frames} has sequence number {seq}, not after "
                                      f"{last}: its frames repeat or run backwards")
        depth = _depth_of(path, msg, frames)
        if stack is None:
            stack = np.empty((min(count, max_frames or count), *depth.shape), np.uint16)
            K = np.array(msg.getTransformation().getIntrinsicMatrix(), dtype=float)
        elif depth.shape != stack.shape[1:]:
            raise BadInputError(path, f"its depth frames change size from {stack.shape[2]}×{stack.shape[1]} "
                                      f"to {depth.shape[1]}×{depth.shape[0]} at frame {frames + 1}")
        stack[frames], frames, last = depth, frames + 1, seq
        if frames == len(stack):
            ended = True
            break
    if not messages:
        raise BadInputError(path, "is a corrupt MCAP recording (depthai could not replay any message)")
    if not ended and messages < count:
        raise BadInputError(path, f"is an MCAP recording of which depthai replayed only {messages} of its "
                                  f"{count} messages")
    if stack is None:
        raise BadInputError(path, "is an MCAP recording without RAW16 depth frames")
    depth = stack[:frames]                          # the marker's slot, if any, stays unused
    if not depth.any():
        raise BadInputError(path, f"its {frames} depth frames are all zero (no depth measured)")
    _check_intrinsics(path, K, depth.shape[2], depth.shape[1])
    colour, said = aligned_colour(colours, depth.shape[1:])
    return DepthFrames(depth, K, f"{path.name}: depthai recording, {frames} frames "
                                 f"{depth.shape[2]}x{depth.shape[1]}{said}", colour)


def aligned_colour(colours: list, shape: tuple[int, int]) -> tuple[np.ndarray | None, str]:
    """Her colour from colour frames ((H, W, 3) uint8 RGB, or None for a damaged one) beside depth frames of
    `shape` (H, W): the median of those aligned to depth (of its size), or None; and what was used, for the
    source's description (", 3 colour frames")."""
    aligned = [c for c in colours if c is not None and c.shape[:2] == tuple(shape)]
    colour = np.median(np.stack(aligned), axis=0).round().astype(np.uint8) if aligned else None
    said = (f", {len(aligned)} colour frame{'s' if len(aligned) > 1 else ''}" if aligned
            else ", colour frames not aligned to depth or damaged (not used)" if colours else "")
    return colour, said


def colour_of(msg, bgr: bool) -> np.ndarray | None:
    """The (H, W, 3) uint8 RGB image of an interleaved colour frame; None if its header and data disagree."""
    w, h, stride, size = msg.getWidth(), msg.getHeight(), msg.getStride(), len(msg.getData())
    if not (0 < w <= MAX_SIDE_PX and 0 < h <= MAX_SIDE_PX) or stride != 3 * w or size < 3 * w * h:
        return None
    image = np.frombuffer(msg.getData(), np.uint8, 3 * w * h).reshape(h, w, 3)
    return image[:, :, ::-1].copy() if bgr else image.copy()


def _depth_of(path: Path, msg, index: int) -> np.ndarray:
    """The (H, W) uint16 depth image of RAW16 frame `index`; BadInputError if its header's size, row
    stride and data disagree (depthai would refuse it, or read past the data)."""
    w, h, stride, size = msg.getWidth(), msg.getHeight(), msg.getStride(), len(msg.getData())
    if not (0 < w <= MAX_SIDE_PX and 0 < h <= MAX_SIDE_PX):
        raise BadInputError(path, f"its depth frame {index + 1} is {w}×{h} pixels; a depth camera's are "
                                  f"1 to {MAX_SIDE_PX} a side")
    if stride != 2 * w or size < 2 * w * h:
        raise BadInputError(path, f"its depth frame {index + 1} ({w}×{h}) holds {size:,} bytes in rows of "
                                  f"{stride} where RAW16 needs {2 * w * h:,} in rows of {2 * w} (a damaged frame)")
    return np.asarray(msg.getFrame(), dtype=np.uint16)


def _replay(path: Path, count: int):
    """Yield the first `count` messages of a recording (all it holds) through ReplayMessage, unpaced.

    The node loops only because at end of file it closes its queue at once, dropping messages not
    yet taken; no message past the `count`th, which would come from the second pass, is taken.
    """
    dai = depthai()
    pipeline = dai.Pipeline(False)
    replay = pipeline.create(dai.node.ReplayMessage)
    replay.setReplayFile(str(path))
    replay.setLoop(True)
    replay.setFps(UNPACED_FPS)
    queue = replay.out.createOutputQueue(maxSize=8, blocking=True)
    pipeline.start()
    try:
        for _ in range(count):
            try:
                yield queue.get()
            except dai.MessageQueue.QueueException:  # the replay node failed (unreadable file)
                return
    finally:
        pipeline.stop()
        pipeline.wait()


def _check_intrinsics(path: Path, K, width: int, height: int) -> None:
    K = np.asarray(K, float)
    ok = (K.shape == (3, 3) and np.isfinite(K).all() and K[0, 0] > 0 and K[1, 1] > 0
          and 0 < K[0, 2] < width and 0 < K[1, 2] < height)
    if not ok:
        raise BadInputError(path, f"its depth frames carry no usable intrinsics (K = {K.round(2).tolist()})")
