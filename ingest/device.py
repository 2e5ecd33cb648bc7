"""Live capture from an OAK device: StereoDepth depth frames, processed like a recording."""
from __future__ import annotations

import numpy as np

from breastplan import BadInputError

from .recording import DepthFrames, depthai

SIZE = (640, 400)


def capture(device_id: str | None, frames: int) -> DepthFrames:
    """Grab `frames` depth frames (mm) from the OAK `device_id` (None: the first attached)."""
    dai = depthai()
    available = dai.Device.getAllAvailableDevices()
    if device_id not in (None, "", "auto"):
        available = [d for d in available if device_id in (d.getDeviceId(), d.name)]
    if not available:
        which = f"OAK device {device_id}" if device_id not in (None, "", "auto") else "OAK device"
        raise BadInputError(None, f"no {which} is attached (depthai found none)")
    device = dai.Device(available[0])
    with dai.Pipeline(device) as pipeline:
        stereo = pipeline.create(dai.node.StereoDepth).build(True, dai.node.StereoDepth.PresetMode.DEFAULT, SIZE)
        queue = stereo.depth.createOutputQueue(maxSize=frames, blocking=True)
        pipeline.start()
        grabbed = [queue.get() for _ in range(frames)]
        pipeline.stop()
    depth = np.stack([np.array(f.getFrame(), dtype=np.uint16) for f in grabbed])
    K = np.array(grabbed[0].getTransformation().getIntrinsicMatrix(), dtype=float)
    return DepthFrames(depth, K, f"OAK {available[0].getDeviceId()}: live, {frames} frames {SIZE[0]}x{SIZE[1]}")
