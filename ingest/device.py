"""Live capture from an OAK device: StereoDepth depth frames, aligned to its colour camera (CAM_A) with that
camera's frames beside them when it has one, processed like a recording."""
from __future__ import annotations

import numpy as np

from breastplan import BadInputError

from .mcap_check import MAX_MESSAGES
from .recording import MAX_COLOUR_FRAMES, DepthFrames, aligned_colour, colour_of, depthai

SIZE = (640, 400)


def capture(device_id: str | None, frames: int) -> DepthFrames:
    """Grab `frames` depth frames (mm) from the OAK `device_id` (None: the first attached), and her colour (the
    median of the colour frames that arrived meanwhile, RGB888i at the depth's size and aligned to it; none from
    a device without a colour camera)."""
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
    i, colours = 0, []
    with dai.Pipeline(device) as pipeline:
        stereo = pipeline.create(dai.node.StereoDepth).build(True, dai.node.StereoDepth.PresetMode.DEFAULT, SIZE)
        colour = _colour_output(dai, pipeline, device, stereo)
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
                while colour is not None and len(colours) < MAX_COLOUR_FRAMES and colour.has():
                    colours.append(colour_of(colour.get(), bgr=False))
        except dai.MessageQueue.QueueException:
            raise BadInputError(None, f"the OAK device {available[0].getDeviceId()} stopped sending depth "
                                      f"frames after {i} of {frames}") from None
        finally:
            pipeline.stop()
    rgb, said = aligned_colour(colours, depth.shape[1:])
    return DepthFrames(depth, K, f"OAK {available[0].getDeviceId()}: live, {frames} frames {SIZE[0]}x{SIZE[1]}{said}",
                       rgb)


def _colour_output(dai, pipeline, device, stereo):
    """The queue of the device's colour camera (CAM_A) at SIZE, RGB888i, with the depth aligned to it; None when
    the device has no colour camera (the depth stays as the stereo pair sees it)."""
    if dai.CameraBoardSocket.CAM_A not in device.getConnectedCameras():
        return None
    stereo.setDepthAlign(dai.CameraBoardSocket.CAM_A)
    stereo.setOutputSize(*SIZE)
    camera = pipeline.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_A)
    return camera.requestOutput(SIZE, dai.ImgFrame.Type.RGB888i).createOutputQueue(maxSize=4, blocking=False)
