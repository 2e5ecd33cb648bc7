"""The `ingest` command: a depth recording or scan → the clean breast of one side, in the breast frame."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from breastplan.clock import Clock
from breastplan.errors import about
from breastplan.options import IngestOptions, OptionError

from .app import JSON, UNITS_HELP, UP_HELP, command, parse_numbers, scan_file_options
from .output import not_one_side_of_a_plan, report, usage_error, writable

FLAGS = {"side": "--side", "voxel_mm": "--voxel", "frames": "--frames", "roi_camera_mm": "--roi",
         "nipple_camera_mm": "--nipple", "units": "--units", "up": "--up"}


@command()
def ingest(
    input: Optional[Path] = typer.Argument(None, help="depthai recording (.mcap) or scan file (PLY, OBJ, STL, PCD, "
                                           "XYZ, glTF/GLB); omit with --device."),
    side: str = typer.Option(..., "--side", help="The patient's breast to isolate: left or right."),
    out: Path = typer.Option(..., "--out", help="Case folder for scan.ply, scan.npz and camera.ply."),
    voxel: float = typer.Option(2.0, "--voxel", help="Voxel size of the downsampling, mm."),
    frames: Optional[int] = typer.Option(None, "--frames", help="Fuse at most N depth frames (default: all; 10 live)."),
    roi: Optional[str] = typer.Option(None, "--roi", help="X0,Y0,Z0,X1,Y1,Z1: box (camera mm) holding the breast."),
    nipple: Optional[str] = typer.Option(None, "--nipple", help="X,Y,Z: the nipple (camera mm), overriding the apex."),
    units: str = typer.Option("auto", "--units", help=UNITS_HELP),
    up: str = typer.Option("auto", "--up", help=UP_HELP),
    device: bool = typer.Option(False, "--device", help="Capture from a live OAK device instead of INPUT."),
    device_id: Optional[str] = typer.Option(None, "--device-id", help="With --device: the OAK's ID (default: the first)."),
    as_json: bool = JSON,
):
    """Turn a depth recording or scan into the clean breast of one side, in the breast frame."""
    clock = Clock()
    if (input is None) != device:
        raise usage_error("give either INPUT or --device", "INPUT/--device")
    try:
        options = IngestOptions(side, voxel, frames, parse_numbers(roi, 6, "--roi"), parse_numbers(nipple, 3, "--nipple"),
                                units, up, device_id)
    except OptionError as exc:
        raise usage_error(str(exc), FLAGS[exc.option]) from None
    scan_file_options(input, units, up)
    not_one_side_of_a_plan(out, "ingested")
    writable(out, folder=True)
    from threadpoolctl import threadpool_limits

    from breastplan.case import Case
    from breastplan.ingest.scan import ingest as run_ingest

    with about(input), threadpool_limits(1, "blas"):     # small least squares: threads only add contention
        scan = run_ingest(input, options)
    paths = Case(out).save_scan(scan)
    report({"scan": str(paths[Case.SCAN_PLY]), "points": len(scan.points), "side": scan.side,
            "nipple_camera_mm": scan.nipple_camera_mm.round(2), "nipple_found": scan.nipple_found,
            "frames": scan.source.frames,
            "source": scan.source.description,
            "timings_ms": {k: round(v, 1) for k, v in scan.timings_ms.items()}, "seconds": clock.seconds},
           as_json, f"ingest {scan.side} breast → {out}")
