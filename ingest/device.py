"""Live capture from an OAK device: StereoDepth depth frames, processed like a recording."""
from __future__ import annotations

import numpy as np

from breastplan import BadInputError

from .mcap_check import MAX_MESSAGES
from .recording import DepthFrames, depthai

SIZE = (640, 400)


def capture(device_id: str | None, frames: int) -> DepthFrames:
    """Grab `frames` depth frames (mm) from the OAK `device_id` (None: the first attached)."""
    if frames > MAX_MESSAGES:
        raise BadInputError(None, f"a live capture of {frames:,} frames is more than any body scan takes "
                                  f"(at most {MAX_MESSAGES:,})")
    dai = depthai()
    available = dai.Device.getAllAvailableDevices()
    if device_id not in (None, "", "auto"):
        available = [d for d in available if device_id in (d.getDeviceId(), d.name)]
    if not available:
        which = f"OAK device {device_id}" if device_id not in (None, "", "auto") else "OAK device"
        raise BadInputError(None, f"no {which} is attached (depthai found none)")
    device = dai.Device(available[0])
    depth = K = None
    i = 0
    with dai.Pipeline(device) as pipeline:
        stereo = pipeline.create(dai.node.StereoDepth).build(True, dai.node.StereoDepth.PresetMode.DEFAULT, SIZE)
        queue = stereo.depth.createOutputQueue(maxSize=min(frames, 30), blocking=True)
        pipeline.start()
        try:
            for i in range(frames):
                frame = queue.get()
                image = np.asarray(frame.getFrame(), dtype=np.uint16)
                if depth is None:                   # one stack, filled frame by frame
                    depth = np.empty((frames, *image.shape), np.uint16)
                    K = np.array(frame.getTransformation().getIntrinsicMatrix(), dtype=float)
                depth[i] = image
        except dai.MessageQueue.QueueException:
            raise BadInputError(None, f"the OAK device {available[0].getDeviceId()} stopped sending depth "
                                      f"frames after {i} of {frames}") from None
        finally:
            pipeline.stop()
    return DepthFrames(depth, K, f"OAK {available[0].getDeviceId()}: live, {frames} frames {SIZE[0]}x{SIZE[1]}")
