"""Ingest as a stage: a source (recording, scan file or live device) → the case's `Scan`.

`Case.save_scan` writes it as scan.ply (breast points and outward normals, mm, breast frame),
camera.ply (the background-free torso, input frame) and scan.npz (`breastplan.scan/1`).
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from breastplan.case import Provenance, Scan, Source
from breastplan.clock import Clock
from breastplan.errors import file_head
from breastplan.options import IngestOptions

from .files import read_scan_file
from .recording import MCAP_MAGIC, DepthFrames, read_recording

if TYPE_CHECKING:
    from .pipeline import Ingested


def is_recording(path: Path) -> bool:
    """An MCAP file, by extension or by its magic bytes."""
    if path.suffix.lower() == ".mcap":
        return True
    return file_head(path, len(MCAP_MAGIC)) == MCAP_MAGIC


def ingest(input: Path | None, options: IngestOptions) -> Scan:
    """Run the pipeline on a recording, a scan file, or (input None) a live OAK device.

    The file readers name `input` in their errors; the pipeline's errors name no file. The pipeline
    (scipy) is imported after the source is read, so that bad input is refused quickly.
    """
    return ingest_sides(input, [options])[0]


def ingest_sides(input: Path | None, options: list[IngestOptions]) -> list[Scan]:
    """`ingest` once per options (one per side), the source read once and its body found once (once
    per up axis of a scan file); each side's timings hold the read's and the body's."""
    clock = Clock()
    first = options[0]
    if input is None or is_recording(Path(input)):
        with clock("replay (depthai)" if input is not None else "capture (depthai)"):
            if input is None:
                from .device import capture
                depth = capture(first.device_id, first.frames or 10)
            else:
                depth = read_recording(input, first.frames)
        from .pipeline import frames_body

        cloud, body_of = None, lambda up, c: frames_body(depth, c)  # noqa: E731
        source = depth_source(depth, "recording" if input is not None else "device")
    else:
        cloud = read_scan_file(input, first.units)
        from .pipeline import cloud_body

        body_of = lambda up, c: cloud_body(cloud, up, c)  # noqa: E731
    from .pipeline import isolate_side

    inputs = {} if input is None else {Path(input).name: input}
    bodies, scans = {}, []
    for opts in options:
        up = None if cloud is None else opts.up            # a recording's body does not depend on it
        if up not in bodies:
            bodies[up] = body_of(up, _clock(clock.ms))
        if cloud is not None:
            source = Source("file", cloud.description + _up_note(bodies[up]))
        result = isolate_side(bodies[up], opts, _clock(bodies[up].timings_ms))
        scans.append(scan_record(result, source, opts, Provenance.of(inputs, opts.as_dict())))
    return scans


def _up_note(body) -> str:
    """How a scan file's up axis was known, for its description."""
    if body.up is None:
        return ""
    how = {"given": "given", "her head": "found: her head stands above her chest along it",
           "taken": "taken: her head is not in view, give --up if it is another"}[body.up_found]
    return f", up {body.up} ({how})"


def _clock(ms: dict) -> Clock:
    """A clock holding a copy of the steps `ms` timed already."""
    clock = Clock()
    clock.ms.update(ms)
    return clock


def depth_source(depth: DepthFrames, kind: str = "recording") -> Source:
    """The `Source` of depth frames: their kind ("recording" or "device"), description, count, intrinsics and size."""
    return Source(kind, depth.source, int(depth.depth.shape[0]), depth.K, np.array(depth.size))


def scan_record(result: Ingested, source: Source, options: IngestOptions, provenance: Provenance) -> Scan:
    """The case's record of an ingested breast."""
    crop = result.crop
    return Scan(points=result.points, normals=result.normals, torso_camera=result.torso_camera,
                input_to_breast=result.input_to_breast, input_to_view=result.input_to_view,
                side=result.side, nipple_camera_mm=result.nipple_camera, nipple_found=result.nipple_found,
                chest_wall=result.chest_wall,
                mound_centre_view_mm=np.asarray(crop["mound_centre_view_mm"], float),
                mound_radius_mm=float(crop["mound_radius_mm"]), crop_height_mm=float(crop["crop_height_mm"]),
                roi_camera_mm=crop["roi_camera_mm"], voxel_mm=options.voxel_mm, source=source,
                plumb_camera=result.plumb_camera, timings_ms=dict(result.timings_ms), provenance=provenance,
                torso_rgb=result.torso_rgb)
