"""The case folder: one owner of a patient's artefacts, their names, typed round trips and provenance.

    case/scan.ply  scan.npz  camera.ply     ingest (breast frame; camera.ply in the camera frame)
    case/fit.ply   fit.npz                  fit
    case/plan/  report.html  plan.json      plan

Each artefact set is written all or nothing (`atomic_set`): its PLYs are staged first and its
NPZ last, and a process killed at any point leaves the previous set or (completed by `recover`,
which every load runs first) the new one. The NPZ records the SHA-256 of each sibling, so a set
whose files do not belong together (a file copied in, a write by another tool) is refused on load.
Every NPZ records its provenance: the content hashes of its inputs, the options and the code that made it
(docs/artefacts.md).
"""
from __future__ import annotations

import contextlib
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import __version__
from .artefacts import load_npz, save_npz
from .code_digest import code_digest
from .atomic import Stage, atomic_set, recover
from .body import Body
from .chest_wall import ChestWall
from .errors import ArtefactError, BadInputError, NewerArtefactError
from .frames import is_rigid, transform_points
from .meshes import mesh_volume
from .options import SIDES
from .ply import read_ply, write_ply
from .primitive import Primitive
from .units import BREAST_EXTENT_MM

SCAN_SCHEMA, FIT_SCHEMA, CHANGE_SCHEMA = "breastplan.scan/1", "breastplan.fit/2", "breastplan.deformation/1"
CAMERA_FRAME = "frame camera-opencv"
"""Tag, in a PLY comment, of points in an OpenCV camera frame (x right, y down, z forward; mm)."""
RESIDUAL_STATS = ("mean", "rms", "p95", "max")
POSE = "pose (primitive frame to breast frame, mm)"
"""Start of the PLY header comment that carries a fitted model's pose (16 numbers, row-major)."""
NIPPLE_FOUND = ("areola", "apex", "given")
"""How a scan's nipple was found: the centre of the raised nipple-areola disc, the mound's apex, or given."""


def sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's content."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@dataclass(frozen=True)
class Provenance:
    """What made an artefact: content hashes of its inputs (name → SHA-256), options, version, and the
    digest of the code that made it (`code_digest`)."""

    inputs: dict[str, str] = field(default_factory=dict)
    options: dict = field(default_factory=dict)
    version: str = __version__
    code: str = field(default_factory=code_digest)

    @classmethod
    def of(cls, inputs: dict[str, str | Path], options: dict) -> "Provenance":
        """Provenance of files `inputs` (name → path) made with `options`."""
        return cls({name: sha256(path) for name, path in inputs.items()}, dict(options))

    def as_dict(self) -> dict:
        return {"inputs": self.inputs, "options": self.options, "version": self.version, "code": self.code}

    @classmethod
    def from_meta(cls, meta: dict) -> "Provenance":
        p = meta.get("provenance") or {}
        return cls(dict(p.get("inputs", {})), dict(p.get("options", {})), str(p.get("version", "")),
                   str(p.get("code", "")))


SOURCE_KINDS = ("recording", "device", "file")
"""Where a scan's points can come from: a depth recording, a live depth camera, or a scan file."""


@dataclass(frozen=True)
class Source:
    """Where a scan's points came from."""

    kind: str                    # "recording" | "device" | "file"
    description: str
    frames: int = 0              # depth frames fused (0 for files)
    K: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))   # intrinsics, px; zero for files
    image_size: np.ndarray = field(default_factory=lambda: np.zeros(2, np.int64))  # width, height


@dataclass(frozen=True, eq=False)
class Scan:
    """An ingested breast: scan.ply (points, normals; mm, breast frame), camera.ply (the
    background-free torso, mm, input frame, with the colour seen at each point when one was recorded) and
    scan.npz (how they were found)."""

    points: np.ndarray               # (N, 3)
    normals: np.ndarray              # (N, 3) outward unit normals
    torso_camera: np.ndarray         # (M, 3)
    input_to_breast: np.ndarray      # (4, 4) input frame → breast frame
    input_to_view: np.ndarray        # (4, 4) input frame → viewing frame
    side: str
    nipple_camera_mm: np.ndarray     # (3,)
    chest_wall: ChestWall            # viewing frame
    mound_centre_view_mm: np.ndarray  # (2,)
    mound_radius_mm: float
    crop_height_mm: float
    roi_camera_mm: np.ndarray | None  # (6,) or None
    voxel_mm: float
    source: Source
    nipple_found: str = "apex"       # "areola" (centre of the raised disc), "apex" or "given"
    plumb_camera: np.ndarray | None = None  # (3,) unit normal of a wall behind her, input frame; None: no wall
    timings_ms: dict = field(default_factory=dict)
    provenance: Provenance = field(default_factory=Provenance)
    torso_rgb: np.ndarray | None = None   # (M, 3) uint8 her skin's colour at each torso point; None: not recorded

    @property
    def body(self) -> Body:
        """Her body as this scan saw it (shared by both sides of one recording)."""
        return Body(self.torso_camera, self.input_to_view, self.plumb_camera, self.torso_rgb)

    @property
    def nipple_breast_mm(self) -> np.ndarray:
        T = np.asarray(self.input_to_breast, float)
        return T[:3, :3] @ self.nipple_camera_mm + T[:3, 3]

    @property
    def nipple_from_camera_mm(self) -> np.ndarray | None:
        """(3,) the nipple from the depth camera that saw it (a recording's input frame is the camera's, mm); None
        for a scan file, whose frame holds no camera."""
        return np.asarray(self.nipple_camera_mm, float) if self.source.kind in ("recording", "device") else None


@dataclass(frozen=True, eq=False)
class Fit:
    """A fitted breast model: fit.ply (closed surface, mm, breast frame) and fit.npz."""

    vertices: np.ndarray             # (V, 3)
    faces: np.ndarray                # (F, 3)
    primitive: Primitive             # model units
    pose: np.ndarray                 # (4, 4) primitive frame → breast frame, mm
    deformation: np.ndarray          # (12,) s0 s1 t0 t1 h0 h1 g0 g1 b0 b1 c0 c1, model units
    lattice_shape: np.ndarray        # (3,) control points per axis
    lattice_box_mm: np.ndarray       # (2, 3) lo, hi
    control_rest_mm: np.ndarray      # (K, 3)
    control_fitted_mm: np.ndarray    # (K, 3)
    residuals_mm: dict               # data ↔ surface distance: mean, rms, p95, max
    normalised_residual: float       # mean ‖d − m‖ / ‖d‖ (docs/model.md §6)
    volume_cc_primitive: float
    volume_cc_mesh: float            # the closed surface (base cap near z = 0)
    volume_cc_below_base: float      # between its base and the curved chest wall beneath
    iterations: tuple[int, int]      # superquadric evaluations, FFD iterations
    seconds: tuple[float, float]
    points: int                      # data points fitted
    residual_map_mm: np.ndarray      # (points,) each data point's distance to the fitted surface, in input order
    converged: bool                  # met the stopping rule or stopped improving (not cut by the budget)
    stopping_rule_met: bool          # normalised residual < the thesis's stopping rule
    provenance: Provenance = field(default_factory=Provenance)

    @property
    def volume_cc(self) -> float:
        """The breast's volume on the chest wall: the closed surface's and the gap below its base."""
        return self.volume_cc_mesh + self.volume_cc_below_base


_SCAN_SPEC = {"transform_camera_to_breast": ("f", (4, 4)), "side": ("U", ()), "nipple_camera_mm": ("f", (3,)),
              "nipple_breast_mm": ("f", (3,)), "chest_wall": ("f", ("k",)), "view_from_camera": ("f", (4, 4)),
              "crop_mound_centre_view_mm": ("f", (2,)), "crop_mound_radius_mm": ("f", ()),
              "crop_height_mm": ("f", ()), "crop_roi_camera_mm": ("f", (6,)),
              "voxel_mm": ("f", ()), "frames": ("iu", ()), "source": ("U", ()), "source_kind": ("U", ()),
              "intrinsics": ("f", (3, 3)), "image_size": ("iu", (2,)), "points": ("iu", ())}
_FIT_SPEC = {"primitive": ("f", (7,)), "pose": ("f", (4, 4)), "deformation": ("f", (12,)),
             "lattice_shape": ("iu", (3,)), "lattice_box_mm": ("f", (2, 3)),
             "control_rest_mm": ("f", ("cp", 3)), "control_fitted_mm": ("f", ("cp", 3)),
             "residuals_mm": ("f", (4,)), "normalised_residual": ("f", ()),
             "volume_cc_primitive": ("f", ()), "volume_cc_mesh": ("f", ()),
             "volume_cc_below_base": ("f", ()),
             "iterations": ("iu", (2,)), "seconds": ("f", (2,)), "residual_map_mm": ("f", ("n",))}


_PROVENANCE_META = {"inputs": {"*": str}, "options": dict, "version": str, "code": str}
_SET_META = {"set": {"*": str}, "provenance": _PROVENANCE_META}
_SCAN_META = {**_SET_META, "timings_ms": {"*": float}, "nipple_found": str, "plumb_camera": [float]}
_FIT_META = {**_SET_META, "points": int, "converged": bool, "stopping_rule_met": bool}
_META = {SCAN_SCHEMA: _SCAN_META, FIT_SCHEMA: _FIT_META, CHANGE_SCHEMA: _SET_META}


class Case:
    """A case folder (created on the first write)."""

    SCAN_PLY, SCAN_NPZ, CAMERA_PLY = "scan.ply", "scan.npz", "camera.ply"
    FIT_PLY, FIT_NPZ = "fit.ply", "fit.npz"
    PLAN, REPORT, PLAN_JSON = "plan", "report.html", "plan.json"
    FILES = (SCAN_PLY, SCAN_NPZ, CAMERA_PLY, FIT_PLY, FIT_NPZ, REPORT, PLAN_JSON)

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)

    def __repr__(self) -> str:
        return f"Case({str(self.folder)!r})"

    def path(self, name: str) -> Path:
        return self.folder / name

    @classmethod
    def owns(cls, path: str | Path) -> bool:
        """Whether `path` (by whatever path or link) is one of the files a case folder writes."""
        path = Path(path).resolve()
        return path.name in cls.FILES and any((path.parent / f).is_file() for f in (cls.SCAN_NPZ, cls.PLAN_JSON))

    @classmethod
    def holds(cls, folder: str | Path) -> bool:
        """Whether `folder` is a case folder (it holds an ingested scan)."""
        cls(folder)._recover()
        return (Path(folder) / cls.SCAN_NPZ).is_file()

    @classmethod
    def of_sides(cls, folder: str | Path) -> dict[str, "Case"]:
        """The cases a folder holds, by side: itself when it is one side's case (from `ingest`), else its
        `left/` and `right/` (a plan's); BadInputError naming the folder when it holds none."""
        if cls.holds(folder):
            return {cls(folder).load_scan().side: cls(folder)}
        cases = {side: cls(Path(folder) / side) for side in SIDES if cls.holds(Path(folder) / side)}
        if not cases:
            raise BadInputError(folder, "is not a case folder: it holds no scan.npz, nor left/ or right/ cases")
        return cases

    # --- scan -------------------------------------------------------------------------
    def save_scan(self, scan: Scan) -> dict[str, Path]:
        """Write scan.ply, camera.ply and scan.npz, all or nothing."""
        src = scan.source
        header = [f"breastplan ingest: {scan.side} breast, mm, breast frame", f"source {src.description}"]
        torso_frame = (f"{CAMERA_FRAME} (x right, y down, z forward; mm)" if src.kind != "file"
                       else "frame input (the scan file's own frame; mm)")
        roi = scan.roi_camera_mm
        arrays = {
            "transform_camera_to_breast": scan.input_to_breast, "side": np.str_(scan.side),
            "nipple_camera_mm": scan.nipple_camera_mm, "nipple_breast_mm": scan.nipple_breast_mm,
            "chest_wall": scan.chest_wall.as_array(), "view_from_camera": scan.input_to_view,
            "crop_mound_centre_view_mm": scan.mound_centre_view_mm,
            "crop_mound_radius_mm": np.float64(scan.mound_radius_mm),
            "crop_height_mm": np.float64(scan.crop_height_mm),
            "crop_roi_camera_mm": np.zeros(6) if roi is None else np.asarray(roi, float),  # all zero: no ROI
            "voxel_mm": np.float64(scan.voxel_mm), "frames": np.int64(src.frames), "source": np.str_(src.description),
            "source_kind": np.str_(src.kind), "intrinsics": np.asarray(src.K, float),
            "image_size": np.asarray(src.image_size, np.int64), "points": np.int64(len(scan.points)),
        }
        meta = {"timings_ms": {k: round(v, 2) for k, v in scan.timings_ms.items()}, "nipple_found": scan.nipple_found,
                "chest_wall": "z = polynomial(x, y) in the viewing frame: [degree, x0, y0, sigma_mm, coefficients…]",
                "camera_frame": torso_frame}
        if scan.plumb_camera is not None:
            meta["plumb_camera"] = [float(v) for v in scan.plumb_camera]
        plys = {self.SCAN_PLY: dict(points=scan.points, normals=scan.normals, comments=header),
                self.CAMERA_PLY: dict(points=scan.torso_camera, colours=scan.torso_rgb, comments=[
                    f"breastplan ingest: background-free torso, {torso_frame}", f"source {src.description}"])}
        return self._write_set(plys, self.SCAN_NPZ, SCAN_SCHEMA, arrays, meta, scan.provenance, frame="camera")

    def load_scan(self) -> Scan:
        """The scan of this case; ArtefactError naming the file for anything missing or inconsistent."""
        art = self._load_set(self.SCAN_NPZ, SCAN_SCHEMA, _SCAN_SPEC, (self.SCAN_PLY, self.CAMERA_PLY))
        npz = self.path(self.SCAN_NPZ)
        side = str(art["side"])
        if side not in SIDES:
            raise ArtefactError(npz, f"names side {side}, not left or right")
        for key in ("transform_camera_to_breast", "view_from_camera"):
            if not is_rigid(art[key]):
                raise ArtefactError(npz, f"has a '{key}' that is not a rigid transform")
        try:
            wall = ChestWall.from_array(art["chest_wall"])
        except ValueError as e:
            raise ArtefactError(npz, f"has a 'chest_wall' {e}") from None
        for key in ("crop_mound_radius_mm", "voxel_mm"):
            if not art[key] > 0:
                raise ArtefactError(npz, f"has a '{key}' of {float(art[key]):g}, not a positive length")
        if wall.scale_mm < 0 or art["crop_height_mm"] < 0:
            raise ArtefactError(npz, "has a negative spread of its chest wall or crop height")
        nipple_view = transform_points(art["view_from_camera"], art["nipple_camera_mm"])
        with np.errstate(all="ignore"):
            depth = float(wall.height(nipple_view))
        if not 0 <= depth <= BREAST_EXTENT_MM[1]:
            raise ArtefactError(npz, f"has a 'chest_wall' that does not lie behind its nipple (the nipple stands "
                                     f"{depth:.4g} mm in front of it; a breast projects 0–{BREAST_EXTENT_MM[1]:g})")
        found = art.meta.get("nipple_found", "apex")
        if found not in NIPPLE_FOUND:
            raise ArtefactError(npz, f"says its nipple was found by '{found}', not one of {', '.join(NIPPLE_FOUND)}")
        plumb = art.meta.get("plumb_camera")
        if plumb is not None and not _is_unit_vector(plumb):
            raise ArtefactError(npz, "has a 'plumb_camera' that is not a unit vector")
        breast, torso = read_ply(self.path(self.SCAN_PLY)), read_ply(self.path(self.CAMERA_PLY))
        if breast.normals is None or len(breast.points) != int(art["points"]):
            raise ArtefactError(self.path(self.SCAN_PLY), "does not hold the points and normals scan.npz records")
        nipple = transform_points(art["transform_camera_to_breast"], art["nipple_camera_mm"])
        if not np.allclose(nipple, art["nipple_breast_mm"], atol=0.01) or \
                np.abs(nipple - breast.points.mean(axis=0)).max() > BREAST_EXTENT_MM[1]:
            raise ArtefactError(npz, "has a nipple that is not on its breast (its two frames disagree, or it lies "
                                     "far from the breast's points)")
        roi = art["crop_roi_camera_mm"]
        source = Source(str(art["source_kind"]), str(art["source"]), int(art["frames"]), art["intrinsics"],
                        art["image_size"])
        _check_source(npz, source)
        return Scan(points=breast.points, normals=breast.normals, torso_camera=torso.points,
                    input_to_breast=art["transform_camera_to_breast"], input_to_view=art["view_from_camera"],
                    side=side, nipple_camera_mm=art["nipple_camera_mm"], chest_wall=wall,
                    mound_centre_view_mm=art["crop_mound_centre_view_mm"],
                    mound_radius_mm=float(art["crop_mound_radius_mm"]), crop_height_mm=float(art["crop_height_mm"]),
                    roi_camera_mm=None if not roi.any() else roi, voxel_mm=float(art["voxel_mm"]), source=source,
                    nipple_found=found,
                    plumb_camera=None if plumb is None else np.asarray(plumb, float),
                    timings_ms=dict(art.meta.get("timings_ms", {})), provenance=Provenance.from_meta(art.meta),
                    torso_rgb=torso.colours)

    # --- fit --------------------------------------------------------------------------
    def save_fit(self, fit: Fit) -> dict[str, Path]:
        """Write fit.ply and fit.npz, all or nothing."""
        stats = [fit.residuals_mm[k] for k in RESIDUAL_STATS]
        arrays = {
            "primitive": fit.primitive.as_array(), "pose": fit.pose, "deformation": fit.deformation,
            "lattice_shape": np.asarray(fit.lattice_shape, np.int64), "lattice_box_mm": fit.lattice_box_mm,
            "control_rest_mm": fit.control_rest_mm, "control_fitted_mm": fit.control_fitted_mm,
            "residuals_mm": np.array(stats), "normalised_residual": np.float64(fit.normalised_residual),
            "volume_cc_primitive": np.float64(fit.volume_cc_primitive),
            "volume_cc_mesh": np.float64(fit.volume_cc_mesh),
            "volume_cc_below_base": np.float64(fit.volume_cc_below_base),
            "iterations": np.array(fit.iterations, dtype=np.int64), "seconds": np.array(fit.seconds, dtype=float),
            "residual_map_mm": np.asarray(fit.residual_map_mm, np.float32),
        }
        meta = {"primitive": list(fit.primitive.as_dict()), "residuals_mm": list(RESIDUAL_STATS),
                "iterations": ["superquadric", "ffd"], "pose": "primitive frame → breast frame, mm",
                "points": fit.points, "converged": fit.converged, "stopping_rule_met": fit.stopping_rule_met}
        comments = ["breastplan fit: fitted breast surface, mm, breast frame", fit.primitive.comment(),
                    pose_comment(fit.pose),
                    f"volume_cc {fit.volume_cc:.2f} rms_mm {fit.residuals_mm['rms']:.3f}"]
        plys = {self.FIT_PLY: dict(points=fit.vertices, faces=fit.faces, comments=comments)}
        return self._write_set(plys, self.FIT_NPZ, FIT_SCHEMA, arrays, meta, fit.provenance)

    def load_fit(self) -> Fit:
        """The fit of this case; ArtefactError naming the file for anything missing or inconsistent."""
        art = self._load_set(self.FIT_NPZ, FIT_SCHEMA, _FIT_SPEC, (self.FIT_PLY,))
        npz = self.path(self.FIT_NPZ)
        shape = art["lattice_shape"]
        if (shape < 2).any() or art["control_rest_mm"].shape[0] != int(np.prod(shape)):
            raise ArtefactError(npz, "has a lattice whose control points do not match its shape")
        try:
            primitive = Primitive.from_array(art["primitive"])
        except ValueError as exc:
            raise ArtefactError(npz, f"has an invalid primitive ({exc})") from None
        mesh = read_ply(self.path(self.FIT_PLY))
        if mesh.faces is None:
            raise ArtefactError(self.path(self.FIT_PLY), "holds no faces; a fitted surface is a closed mesh")
        problem = _fit_problem(art, primitive, mesh)
        if problem:
            raise ArtefactError(npz, problem)
        meta = art.meta
        return Fit(vertices=mesh.points, faces=mesh.faces, primitive=primitive, pose=art["pose"],
                   deformation=art["deformation"], lattice_shape=shape, lattice_box_mm=art["lattice_box_mm"],
                   control_rest_mm=art["control_rest_mm"], control_fitted_mm=art["control_fitted_mm"],
                   residuals_mm=dict(zip(RESIDUAL_STATS, map(float, art["residuals_mm"]))),
                   normalised_residual=float(art["normalised_residual"]),
                   volume_cc_primitive=float(art["volume_cc_primitive"]), volume_cc_mesh=float(art["volume_cc_mesh"]),
                   volume_cc_below_base=float(art["volume_cc_below_base"]),
                   iterations=tuple(int(i) for i in art["iterations"]), seconds=tuple(map(float, art["seconds"])),
                   points=int(meta.get("points", 0)), residual_map_mm=art["residual_map_mm"],
                   converged=bool(meta.get("converged", True)),
                   stopping_rule_met=bool(meta.get("stopping_rule_met", True)),
                   provenance=Provenance.from_meta(meta))

    # --- planned changes --------------------------------------------------------------
    def save_change(self, name: str, model: tuple[np.ndarray, np.ndarray], scan_points: np.ndarray,
                    record: dict, provenance: Provenance, stage: Stage | None = None) -> dict[str, Path]:
        """Write plan/NAME.ply (the planned breast model: vertices, faces; mm, breast frame),
        plan/NAME-scan.ply (the scan's points with the change applied, breast frame) and
        plan/NAME.npz (the change's kinds, degrees and parameters in its metadata; the scan
        points' displacements, mm, breast frame), all or nothing, or staged in a larger set's `stage`."""
        stem = f"{self.PLAN}/{name}"
        plys = {f"{stem}.ply": dict(points=model[0], faces=model[1], comments=[
                    f"breastplan plan: {name}, planned breast model, mm, breast frame"]),
                f"{stem}-scan.ply": dict(points=scan_points, comments=[
                    f"breastplan plan: {name}, the scan's points changed, mm, breast frame"])}
        record = dict(record)
        arrays = {"displacement_mm": np.asarray(record.pop("displacement_mm"), float)}
        return self._write_set(plys, f"{stem}.npz", CHANGE_SCHEMA, arrays, record, provenance, stage=stage)

    # --- provenance -------------------------------------------------------------------
    def provenance(self, npz_name: str) -> Provenance:
        """What made the NPZ; empty when it is missing or cannot be read."""
        try:
            return Provenance.from_meta(self._meta(npz_name))
        except ArtefactError:
            return Provenance()

    def is_fresh(self, npz_name: str, wanted: Provenance) -> bool:
        """Whether the NPZ exists, was made from inputs of the same content with the same options by the
        same code, and its set is whole (a stage that can be reused)."""
        self._recover()
        if not self.path(npz_name).is_file():
            return False
        try:
            meta = self._meta(npz_name)
            found = Provenance.from_meta(meta)
            if (found.inputs, found.options, found.code) != (wanted.inputs, wanted.options, wanted.code):
                return False
            self._check_set(npz_name, meta)
        except NewerArtefactError:
            raise
        except ArtefactError:
            return False
        return True

    def _meta(self, npz_name: str) -> dict:
        """The NPZ's meta, its set recovered first; ArtefactError when it cannot be read."""
        self._recover()
        schema = _schema_of(npz_name)
        return load_npz(self.path(npz_name), schema, meta_spec=_META[schema]).meta

    # --- sets -------------------------------------------------------------------------
    def _write_set(self, plys: dict[str, dict], npz: str, schema: str, arrays: dict, meta: dict,
                   provenance: Provenance, frame: str = "breast", stage: Stage | None = None) -> dict[str, Path]:
        with contextlib.nullcontext(stage) if stage else atomic_set() as stage:
            hashes = {}
            for name, ply in plys.items():
                hashes[name] = sha256(write_ply(stage(self.path(name)), **ply))
            meta = {**meta, "set": hashes, "provenance": provenance.as_dict()}
            save_npz(stage(self.path(npz)), schema, arrays, units="mm", frame=frame, meta=meta)
        return {name: self.path(name) for name in (*plys, npz)}

    def _recover(self) -> None:
        """Complete a set write a killed process committed (`atomic.recover`)."""
        try:
            recover(self.folder)
        except OSError as exc:
            raise ArtefactError(self.folder, f"holds an interrupted write that cannot be completed here "
                                             f"({exc.strerror or exc}); run the stage again") from None

    def _load_set(self, npz: str, schema: str, spec: dict, siblings: tuple[str, ...]):
        self._recover()
        art = load_npz(self.path(npz), schema, spec, _META[schema])
        if art.schema != schema:             # a case's sets have one layout each: an older one is not read
            raise ArtefactError(self.path(npz), f"has schema {art.schema}, an older schema than this breastplan "
                                                f"reads ({schema}); run the stage again")
        self._check_set(npz, art.meta, siblings)
        return art

    def _check_set(self, npz: str, meta: dict, siblings: tuple[str, ...] | None = None) -> None:
        """ArtefactError unless every sibling file is the one the NPZ was written with."""
        recorded = meta.get("set", {})
        for name in siblings if siblings is not None else tuple(recorded):
            path = self.path(name)
            if not path.is_file():
                raise ArtefactError(path, f"is missing; {npz} was written with it")
            if name in recorded and sha256(path) != recorded[name]:
                raise ArtefactError(path, f"is not the file {npz} was written with (an interrupted or "
                                          f"foreign write); run the stage again")


def _fit_problem(art, primitive: Primitive, mesh) -> str | None:
    """Why a fit.npz's numbers cannot describe the closed surface of fit.ply beside it, or None."""
    problem = primitive.breast_problem()
    if problem:
        return f"has a primitive that {problem}"
    if not is_rigid(art["pose"]) or np.abs(art["pose"][:3, 3]).max() > BREAST_EXTENT_MM[1]:
        return "has a 'pose' that is not a rigid transform near the breast"
    if (art["residuals_mm"] < 0).any() or art["normalised_residual"] < 0 or (art["residual_map_mm"] < 0).any():
        return "has negative residuals"
    enclosed = mesh_volume(mesh.points, mesh.faces) / 1000.0
    if not abs(float(art["volume_cc_mesh"]) - enclosed) <= 1e-3 * abs(enclosed) + 0.01:
        return f"records a volume of {float(art['volume_cc_mesh']):.6g} cc where fit.ply encloses {enclosed:.6g} cc"
    if not 0.0 < float(art["volume_cc_mesh"]) + float(art["volume_cc_below_base"]) < np.inf:
        return "records a volume down to the chest wall that is not positive"
    return None


def _check_source(npz: Path, source: Source) -> None:
    """ArtefactError unless `source` is one SOURCE_KINDS names and, from a depth camera, holds the camera: at
    least one frame, positive focal lengths and a positive image size (their shapes and finiteness are
    _SCAN_SPEC's)."""
    if source.kind not in SOURCE_KINDS:
        raise ArtefactError(npz, f"names its source '{source.kind}', not one of {', '.join(SOURCE_KINDS)}")
    if source.kind == "file":
        return
    K, size = source.K, source.image_size
    if not (source.frames >= 1 and K[0, 0] > 0 and K[1, 1] > 0 and (size > 0).all()):
        raise ArtefactError(npz, f"says its points came from a depth camera ({source.kind}) but holds no usable "
                                 f"camera: {source.frames} frames, focal lengths {K[0, 0]:g} and {K[1, 1]:g} px, "
                                 f"image {size.tolist()} px")


def _is_unit_vector(value) -> bool:
    try:
        v = np.asarray(value, float)
    except (TypeError, ValueError):
        return False
    return v.shape == (3,) and bool(np.isfinite(v).all()) and abs(float(np.linalg.norm(v)) - 1.0) < 1e-6


def pose_comment(pose) -> str:
    """The PLY header comment that carries a pose (read back by `pose_from_comments`)."""
    return f"{POSE} " + " ".join(f"{v:.17g}" for v in np.ravel(pose))


def pose_from_comments(comments) -> np.ndarray | None:
    """The (4, 4) pose a PLY header comment carries, or None; ValueError if it is malformed."""
    for line in comments:
        if line.startswith(POSE):
            try:
                pose = np.array([float(v) for v in line[len(POSE):].split()]).reshape(4, 4)
            except ValueError:
                raise ValueError(f"its pose comment '{line}' is malformed") from None
            if not np.isfinite(pose).all():
                raise ValueError(f"its pose comment '{line}' is malformed")
            return pose
    return None


def _schema_of(npz_name: str) -> str:
    return {Case.SCAN_NPZ: SCAN_SCHEMA, Case.FIT_NPZ: FIT_SCHEMA}[npz_name]
