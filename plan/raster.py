"""Her skin drawn off-screen: an orthographic, z-buffered, smoothly shaded picture of a triangle surface
(numpy only: no display, no GPU, the same pixels on every machine).

Frames: the display frame (x to her left — the image's right seen from the front —, y away from a
viewer in front of her, z up; mm). A `Camera` looks at her from `azimuth_deg` about her vertical
axis: 0 from the front, +45 her left oblique, +90 her left lateral, negative her right. Pictures are
(H, W, 3) uint8, row 0 at the top.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from breastplan.meshes import vertex_normals

SUPERSAMPLE = 2
"""Each pixel is the mean of SUPERSAMPLE² samples, so that her outline is smooth, not stepped."""
CHUNK = 4_000_000
"""At most this many candidate samples are held at once (memory bound, not a result)."""
BACKGROUND = (255, 255, 255)


@dataclass(frozen=True)
class Camera:
    """An orthographic view: from `azimuth_deg` about the display frame's z axis, `mm_per_px` mm per
    pixel, the picture (`width`, `height` px) centred on `centre` (display frame, mm)."""

    azimuth_deg: float
    centre: np.ndarray
    mm_per_px: float
    width: int
    height: int

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) display frame → camera frame (x to the picture's right, y away from the camera, z up)."""
        a = np.radians(self.azimuth_deg)
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((N, 2) pixel coordinates (column, row; pixel centres at .5), (N,) depth mm away from the camera)."""
        p = (np.asarray(points, float) - self.centre) @ self.rotation.T
        col = self.width / 2 + p[:, 0] / self.mm_per_px
        row = self.height / 2 - p[:, 2] / self.mm_per_px
        return np.stack([col, row], axis=1), p[:, 1]

    def light(self, light_camera: np.ndarray) -> np.ndarray:
        """A light given in the camera frame, in the display frame: the light turns with the camera."""
        return self.rotation.T @ np.asarray(light_camera, float)


def framing(points: list[np.ndarray], azimuth_deg: float, width: int, height: int, margin: float = 0.04,
            stray: float = 0.0) -> Camera:
    """The camera from `azimuth_deg` that holds `points` (display frame, mm) in a `width` × `height` picture with
    `margin` of it left free on every side, at equal scales: all of them, or all but a share `stray` at each end
    of each axis (a few points far from the rest need not shrink the picture)."""
    probe = Camera(azimuth_deg, np.zeros(3), 1.0, 0, 0)
    p = np.concatenate(points) @ probe.rotation.T
    lo, hi = np.quantile(p, stray, axis=0), np.quantile(p, 1.0 - stray, axis=0)
    scale = max((hi[0] - lo[0]) / (width * (1 - 2 * margin)), (hi[2] - lo[2]) / (height * (1 - 2 * margin)), 1e-9)
    return Camera(azimuth_deg, probe.rotation.T @ ((lo + hi) / 2), float(scale), width, height)


def lit(vertices: np.ndarray, faces: np.ndarray, rgb: np.ndarray, light: np.ndarray,
        shade: tuple[float, float]) -> np.ndarray:
    """(V, 3) vertex colours 0..1: `rgb` (3,) or (V, 3), 0..255, × (ambient + diffuse · |normal · light|)
    (`shade` = (ambient, diffuse); either side of the surface is lit)."""
    facing = np.abs(vertex_normals(vertices, faces) @ (light / np.linalg.norm(light)))
    return np.clip(np.asarray(rgb, float) / 255 * (shade[0] + shade[1] * facing)[:, None], 0, 1)


@dataclass(frozen=True)
class Picture:
    """A drawn surface: `rgb` (H, W, 3) uint8 and `depth` (H, W) mm from the camera (inf where nothing is)."""

    rgb: np.ndarray
    depth: np.ndarray
    camera: Camera

    def visible(self, points: np.ndarray, tolerance_mm: float = 3.0) -> np.ndarray:
        """(N,) whether each point (display frame) lies over the surface drawn (in the picture, on a pixel
        the surface covers) and no further than `tolerance_mm` behind it."""
        px, depth = self.camera.project(points)
        col, row = np.floor(px[:, 0]).astype(int), np.floor(px[:, 1]).astype(int)
        inside = (col >= 0) & (col < self.camera.width) & (row >= 0) & (row < self.camera.height)
        out = np.zeros(len(points), bool)
        surface = self.depth[row[inside], col[inside]]
        out[inside] = np.isfinite(surface) & (depth[inside] <= surface + tolerance_mm)
        return out


def draw(vertices: np.ndarray, faces: np.ndarray, colours: np.ndarray, camera: Camera) -> Picture:
    """The surface (display frame, mm; `colours` (V, 3) 0..1 per vertex, interpolated across each triangle)
    seen by `camera`: the nearest triangle at each sample, SUPERSAMPLE² samples per pixel averaged."""
    fine = Camera(camera.azimuth_deg, camera.centre, camera.mm_per_px / SUPERSAMPLE,
                  camera.width * SUPERSAMPLE, camera.height * SUPERSAMPLE)
    xy, depth = fine.project(vertices)
    tri = xy[faces]
    attributes = np.concatenate([depth[faces][:, :, None], colours[faces]], axis=2)     # (F, 3 corners, 4)
    zbuf = np.full(fine.height * fine.width, np.inf)
    rgb = np.empty((fine.height * fine.width, 3))
    rgb[:] = np.array(BACKGROUND, float) / 255
    spans = _row_spans(tri, _planes(tri, attributes), fine.width, fine.height)
    start = np.cumsum(spans.count) - spans.count
    for part in np.split(np.arange(len(spans.count)), np.flatnonzero(np.diff(start // CHUNK)) + 1):
        _draw_spans(spans.take(part), fine.width, zbuf, rgb)
    rgb = rgb.reshape(camera.height, SUPERSAMPLE, camera.width, SUPERSAMPLE, 3)
    zbuf = zbuf.reshape(camera.height, SUPERSAMPLE, camera.width, SUPERSAMPLE)
    coarse, near = rgb[:, 0, :, 0], zbuf[:, 0, :, 0]
    for i, j in np.ndindex(SUPERSAMPLE, SUPERSAMPLE):         # the samples of each pixel, summed (faster than sum())
        if i or j:
            coarse, near = coarse + rgb[:, i, :, j], np.minimum(near, zbuf[:, i, :, j])
    coarse = coarse / SUPERSAMPLE**2
    return Picture(np.round(coarse * 255).astype(np.uint8), near, camera)


def _planes(tri: np.ndarray, attributes: np.ndarray) -> np.ndarray:
    """(F, A, 3): each triangle's attributes (F, 3 corners, A) as planes over the picture, value = a · x + b · y
    + c at a point (x, y) (pixels; corners `tri` (F, 3, 2)); a degenerate triangle's are NaN."""
    (x0, y0), (x1, y1), (x2, y2) = (tri[:, k].T for k in range(3))
    area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(area != 0, 1.0 / area, np.nan)
    w0 = np.stack([(y1 - y2) * inv, (x2 - x1) * inv, (x1 * y2 - x2 * y1) * inv], axis=1)
    w1 = np.stack([(y2 - y0) * inv, (x0 - x2) * inv, (x2 * y0 - x0 * y2) * inv], axis=1)
    w2 = -w0 - w1
    w2[:, 2] += 1.0
    return np.einsum("fkj,fka->faj", np.stack([w0, w1, w2], axis=1), attributes)


@dataclass(frozen=True)
class _Spans:
    """Row spans of sample centres inside triangles: each span's row, first column and number of columns,
    and along it the attributes (depth, r, g, b), each slope · column centre + offset."""

    row: np.ndarray       # (S,)
    first: np.ndarray     # (S,)
    count: np.ndarray     # (S,)
    slope: np.ndarray     # (S, 4)
    offset: np.ndarray    # (S, 4)

    def take(self, i: np.ndarray) -> _Spans:
        return _Spans(self.row[i], self.first[i], self.count[i], self.slope[i], self.offset[i])


def _row_spans(tri: np.ndarray, planes: np.ndarray, width: int, height: int) -> _Spans:
    """Each triangle's sample centres (column + .5, row + .5) inside it, row by row: between its long edge (top
    corner to bottom corner) and its upper or lower short edge. An edge's crossing of a row is computed from
    its corners in one order whichever triangle it bounds, so neighbours neither gap nor overlap."""
    order = np.argsort(tri[:, :, 1], axis=1, kind="stable")
    (x0, y0), (x1, y1), (x2, y2) = (np.take_along_axis(tri, order[:, k, None, None], axis=1)[:, 0].T for k in range(3))
    first = np.ceil(y0 - 0.5).clip(0, height).astype(np.int64)
    last = np.floor(y2 - 0.5).clip(-1, height - 1).astype(np.int64)
    rows = np.where(np.isfinite(planes[:, 0, 0]), np.maximum(last - first + 1, 0), 0)
    f = np.repeat(np.arange(len(tri)), rows)
    row = first[f] + np.arange(rows.sum()) - np.repeat(np.cumsum(rows) - rows, rows)
    y = row + 0.5
    with np.errstate(divide="ignore", invalid="ignore"):
        x_long = x0[f] + (y - y0[f]) * ((x2 - x0) / (y2 - y0))[f]
        upper = y < y1[f]
        x_short = np.where(upper, x0[f] + (y - y0[f]) * ((x1 - x0) / (y1 - y0))[f],
                           x1[f] + (y - y1[f]) * ((x2 - x1) / (y2 - y1))[f])
    c0 = np.ceil(np.maximum(np.minimum(x_long, x_short), 0.0) - 0.5)
    c1 = np.floor(np.minimum(np.maximum(x_long, x_short), width) - 0.5)
    count = np.where(np.isfinite(c0) & np.isfinite(c1), np.maximum(c1 - c0 + 1, 0), 0).astype(np.int64)
    keep = count > 0
    f, y = f[keep], y[keep]
    p = planes[f]                                                          # (S, 4, abc)
    return _Spans(row[keep], c0[keep].astype(np.int64), count[keep], p[:, :, 0], p[:, :, 1] * y[:, None] + p[:, :, 2])


def _draw_spans(spans: _Spans, width, zbuf, rgb) -> None:
    """Write the spans' samples into the z-buffer `zbuf` and `rgb` (flat, fine samples) where nearer."""
    n = spans.count
    seg = np.repeat(np.arange(len(n)), n)
    col = spans.first[seg] + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    x = col + 0.5
    depth = spans.slope[seg, 0] * x + spans.offset[seg, 0]
    pix = spans.row[seg] * width + col
    np.minimum.at(zbuf, pix, depth)
    win = depth <= zbuf[pix]
    seg, x = seg[win], x[win]
    rgb[pix[win]] = spans.slope[seg, 1:] * x[:, None] + spans.offset[seg, 1:]   # the colours of the nearest only
