"""Ingest as a stage: a source (recording, scan file or live device) → a case folder.

Writes `scan.ply` (breast points and outward normals, mm, breast frame), `scan.npz`
(`breastplan.scan/1`) and `camera.ply` (the background-free torso, camera frame).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from breastplan import BadInputError, load_npz, save_npz, transform_points, write_ply

from .files import read_scan_file
from .pipeline import Clock, Ingested, ingest_cloud, ingest_frames
from .recording import MCAP_MAGIC, DepthFrames, read_recording

SCHEMA = "breastplan.scan/1"
SIDES = ("left", "right")
CAMERA_FRAME_COMMENT = "frame camera-opencv (x right, y down, z forward; mm)"


@dataclass(frozen=True)
class Source:
    """Where the points came from."""

    kind: str                    # "recording" | "device" | "file"
    description: str
    frames: int                  # depth frames fused (0 for files)
    K: np.ndarray                # (3, 3) intrinsics, zero for files
    image_size: np.ndarray       # (2,) width, height; 0 for files


def is_recording(path: Path) -> bool:
    """An MCAP file, by extension or by its magic bytes."""
    if path.suffix.lower() == ".mcap":
        return True
    try:
        with open(path, "rb") as fh:
            return fh.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False


def ingest(input: Path | None, side: str, voxel: float = 2.0, frames: int | None = None, roi=None, nipple=None,
           units: str = "auto", up: str = "+y", device: str | None = None) -> tuple[Ingested, Source]:
    """Run the pipeline on a recording, a scan file, or (input None) a live OAK device."""
    if side not in SIDES:
        raise ValueError(f"side must be left or right, got {side!r}")
    clock = Clock()
    if input is None or is_recording(Path(input)):
        with clock("replay (depthai)" if input is not None else "capture (depthai)"):
            if input is None:
                from .device import capture
                depth = capture(device, frames or 10)
            else:
                depth = read_recording(input, frames)
        result = ingest_frames(depth, side, voxel, roi, nipple, path=input, clock=clock)
        return result, _depth_source(depth, "recording" if input is not None else "device")
    cloud = read_scan_file(input, units)
    result = ingest_cloud(cloud, side, voxel, roi, nipple, up, path=input, clock=clock)
    return result, Source("file", cloud.description, 0, np.zeros((3, 3)), np.zeros(2, int))


def _depth_source(depth: DepthFrames, kind: str) -> Source:
    return Source(kind, depth.source, int(depth.depth.shape[0]), depth.K, np.array(depth.size))


def save_case(case_dir: str | Path, result: Ingested, source: Source, voxel: float) -> dict[str, Path]:
    """Write scan.ply, scan.npz and camera.ply into `case_dir`."""
    case = Path(case_dir)
    nipple_breast = transform_points(result.camera_to_breast, result.nipple_camera)
    header = [f"breastplan ingest: {result.side} breast, mm, breast frame", f"source {source.description}"]
    paths = {"scan_ply": write_ply(case / "scan.ply", result.points, normals=result.normals, comments=header)}
    torso_frame = CAMERA_FRAME_COMMENT if source.kind != "file" else "frame input (the scan file's own frame; mm)"
    paths["camera_ply"] = write_ply(case / "camera.ply", result.torso_camera,
                                    comments=[f"breastplan ingest: background-free torso, {torso_frame}",
                                              f"source {source.description}"])
    roi = result.crop["roi_camera_mm"]
    arrays = {
        "transform_camera_to_breast": result.camera_to_breast, "side": np.str_(result.side),
        "nipple_camera_mm": result.nipple_camera, "nipple_breast_mm": nipple_breast,
        "chest_wall": result.chest_wall.as_array(), "view_from_camera": result.view_from_camera,
        "crop_mound_centre_view_mm": result.crop["mound_centre_view_mm"],
        "crop_mound_radius_mm": np.float64(result.crop["mound_radius_mm"]),
        "crop_height_mm": np.float64(result.crop["crop_height_mm"]),
        "crop_roi_camera_mm": np.zeros(6) if roi is None else roi,  # all zero: no ROI given
        "voxel_mm": np.float64(voxel), "frames": np.int64(source.frames), "source": np.str_(source.description),
        "source_kind": np.str_(source.kind), "intrinsics": source.K, "image_size": source.image_size,
        "points": np.int64(len(result.points)),
    }
    meta = {"timings_ms": {k: round(v, 2) for k, v in result.timings_ms.items()},
            "chest_wall": "z = polynomial(x, y) in the viewing frame: [degree, x0, y0, sigma_mm, coefficients…]",
            "camera_frame": CAMERA_FRAME_COMMENT if source.kind != "file" else "the scan file's frame"}
    paths["scan_npz"] = save_npz(case / "scan.npz", SCHEMA, arrays, units="mm", frame="camera", meta=meta)
    return paths


_SPEC = {"transform_camera_to_breast": ("f", (4, 4)), "side": ("U", ()), "nipple_camera_mm": ("f", (3,)),
         "nipple_breast_mm": ("f", (3,)), "chest_wall": ("f", ("k",)), "view_from_camera": ("f", (4, 4)),
         "voxel_mm": ("f", ()), "frames": ("iu", ()), "intrinsics": ("f", (3, 3)), "image_size": ("iu", (2,))}


def load_scan(path: str | Path):
    """Load and validate scan.npz (an Artefact: arrays by name plus .meta)."""
    art = load_npz(path, SCHEMA, _SPEC)
    if str(art["side"]) not in SIDES:
        raise BadInputError(path, f"names side {art['side']!s}, not left or right")
    return art
