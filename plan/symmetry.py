"""How alike her two breasts are, and how far each hangs: BCCT.core's asymmetry measures and Regnault's
ptosis grade, taken in 3-D from her skin's cells (docs/symmetry.md).

BCCT.core (Cardoso & Cardoso) measures a frontal photograph: the sternal notch, the nipples and each
breast's contour, marked on the picture. Here the same points come from her surface, in her body frame
(x to her left, y up, z anterior, origin the sternal notch, mm; `plan.breast_volume.body_frame`):

* the nipples: given, moved into that frame;
* the lower contour of each breast: the lowest edge of its *own region* — the cells of its side of the
  footprint where her skin stands more than FOOT_MM in front of the chest wall (the footprint itself is
  both sides' joined and mirrored, so it cannot tell them apart; the heights can);
* the chest wall: height 0 of `SkinCells.height_mm`.

A length the photograph measures in its plane (the notch-to-nipple distance) is taken as the 3-D chord;
a height is taken along her up axis. The measures work on (nipples, cells) alone (`bcct_measures`,
`ptosis_from_cells`), so a planned state — moved nipples, planned heights on the same cells — is
measured the same way as the scan.

The inframammary fold is not in a frontal view under a breast that hangs over it. Under the nipple,
where the skin is seen coming down to the skin below the breast, the fold is where it gets there
(`fold_from` "seen"); where the lower pole ends in a cliff instead (its lowest cell over TAPER_MM in
front of the wall), the fold is hidden behind it and is estimated from how far that lowest point stands
in front of the wall (HANG_SLOPE; "estimated"). The nipple's height above the breast's lowest point is
measured either way.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from breastplan import transform_points
from breastplan.options import SIDES

from .breast_volume import CELL_MM, FOOT_MM, BreastVolumes, SkinCells

TAPER_MM = 25.0
"""A column of the footprint whose lowest cell stands more than this above the wall ends in a cliff: the
lower pole overhangs there and hides where the skin meets the wall."""
UNDER_NIPPLE_MM = 7.5
"""The columns within this of the nipple's x are the ones under the nipple (three 5 mm columns)."""
FLOOR_BAND, FLOOR_MM = (15.0, 40.0), 2.0
"""The skin below the breast: the seen cells 15–40 mm below its lowest cell; the skin coming down from
the breast has reached it (the fold) within FLOOR_MM of their median height."""
HANG_SLOPE = 0.45
"""A hidden fold is put this many mm above the breast's lowest point per mm that point stands in front of
the wall: its underside taken to rise back to the wall at about 24°. A prior, about the least-squares
slope (0.47) over 26 hidden folds of MakeHuman scans whose folds are known (benchmarks/bench_folds.py
measures the error)."""
AT_FOLD_MM = 5.0
"""A nipple less than this above the fold is at the fold (half a cell: the fold's precision)."""
GRADE_I_MM, GRADE_II_MM = 10.0, 30.0
"""Regnault's bands: a nipple down to 1 cm below the fold is grade I, down to 3 cm grade II, lower III."""
AT_LOWEST_MM = 10.0
"""A nipple less than this above the breast's lowest point is at the lower contour (grade III)."""
PSEUDO_MM = 20.0
"""A breast whose lowest point hangs more than this below the fold, the nipple above it, is pseudoptosis
(with a hidden fold: a lowest point standing over PSEUDO_MM / HANG_SLOPE in front of the wall)."""
GRADES = ("0", "I", "II", "III", "pseudoptosis")


def symmetry_measures(volumes: BreastVolumes, nipples_input: dict) -> dict[str, float]:
    """BCCT.core's asymmetry measures of her two breasts (`bcct_measures`), from a measured scan:
    nipples_input side → (3,) input frame, mm. {} unless both sides were measured and both nipples given."""
    if not set(SIDES) <= set(volumes.sides) or not set(SIDES) <= set(nipples_input):
        return {}
    T = volumes.body_from_input
    nipples = {s: transform_points(T, np.asarray(nipples_input[s], float).reshape(1, 3))[0] for s in SIDES}
    return bcct_measures(nipples, volumes.cells)


def bcct_measures(nipples_body: dict, cells: SkinCells) -> dict[str, float]:
    """The asymmetry measures of the two breasts, from both nipples (side → (3,), her body frame, mm:
    the notch is the origin) and her skin's cells (the scan's, or planned heights on the same cells).

    * BRA_mm: the distance between one nipple and the other's mirror image, both from the notch;
      pBRA_pct: over the mean notch-to-nipple chord.
    * UNR_mm: the difference of the nipples' heights below the notch; pUNR_pct: over their mean.
    * LBC_mm: the difference of the heights of the breasts' lowest points (lower contours); pLBC_pct:
      over the mean height of notch to nipple to lowest point.
    * BCE_mm: the difference of the nipples' heights above their breast's lowest point; pBCE_pct: over
      their mean.
    * BCD_mm: the mean distance between one breast's outline and the other's mirror image (cells' centres).
    * overlap_pct: the tissue the two breasts share, one mirrored onto the other — Σ min(h_left, h_right
      mirrored) over the footprint — over their mean volume (a Dice overlap: 100 for mirror twins).
    * lower_contours_hidden: how many of the two lowest points (0, 1 or 2) lie on a cell the camera did not
      see, whose height is her other side's mirrored (`plan.breast_volume`): LBC and BCE then rest on that
      estimate, and read a lowered breast's difference short.

    Heights are along her up axis. The measures that need a breast's own region are left out when a side
    has none (its skin nowhere FOOT_MM above the wall)."""
    n = {s: np.asarray(nipples_body[s], float) for s in SIDES}
    folded = {s: np.array([abs(p[0]), p[1], p[2]]) for s, p in n.items()}
    chord = np.mean([np.linalg.norm(p) for p in n.values()])
    drop = {s: abs(p[1]) for s, p in n.items()}
    out = {"BRA_mm": float(np.linalg.norm(folded["left"] - folded["right"])),
           "UNR_mm": float(abs(drop["left"] - drop["right"]))}
    out["pBRA_pct"] = _pct(out["BRA_mm"], chord)
    out["pUNR_pct"] = _pct(out["UNR_mm"], np.mean(list(drop.values())))
    regions = {s: own_region(cells, s, n[s]) for s in SIDES}
    if not all(r.any() for r in regions.values()):
        return out
    lowest_point = {s: _lowest_point(cells, regions[s]) for s in SIDES}
    lowest = {s: y for s, (y, _) in lowest_point.items()}
    above = {s: abs(n[s][1] - lowest[s]) for s in SIDES}
    out["LBC_mm"] = float(abs(lowest["left"] - lowest["right"]))
    out["pLBC_pct"] = _pct(out["LBC_mm"], np.mean([drop[s] + above[s] for s in SIDES]))
    out["BCE_mm"] = float(abs(above["left"] - above["right"]))
    out["pBCE_pct"] = _pct(out["BCE_mm"], np.mean(list(above.values())))
    out["BCD_mm"] = _outline_distance(regions["left"], regions["right"][::-1])
    h = np.clip(cells.height_mm, 0.0, None)
    left = cells.side("left")
    shared = float(np.minimum(h, h[::-1])[left].sum())
    mean = 0.5 * float(h[left].sum() + h[cells.side("right")].sum())
    out["overlap_pct"] = 100.0 * shared / mean if mean > 0 else 0.0
    out["lower_contours_hidden"] = float(sum(not seen for _, seen in lowest_point.values()))
    return out


def _lowest_point(cells: SkinCells, region: np.ndarray) -> tuple[float, bool]:
    """(the height (y, mm) of the region's lowest point, its `lower_edge`; whether the camera saw the region's
    lowest cell in that column, the one the point lies below)."""
    edge = lower_edge(cells, region)
    k = int(np.nanargmin(edge))
    return float(edge[k]), bool(cells.seen[k, np.argmax(region[k])])


def ptosis_grade(volumes: BreastVolumes, nipples_input: dict, side: str) -> dict:
    """Regnault's ptosis grade of one breast (`ptosis_from_cells`), from a measured scan: nipples_input
    side → (3,) input frame, mm."""
    nipple = transform_points(volumes.body_from_input, np.asarray(nipples_input[side], float).reshape(1, 3))[0]
    return ptosis_from_cells(nipple, volumes.cells, side)


def fold_line(volumes: BreastVolumes, nipple_input, found: dict, across_mm=(0.0,)) -> np.ndarray | None:
    """(K, 3) points of a breast's inframammary fold under its nipple ((3,) input frame), `across_mm` to her left of
    the nipple's x (body frame), at the height its ptosis (`found`, `ptosis_from_cells`) puts the fold: on her skin
    where the fold was seen, on the chest wall behind her breast where it hides the fold; input frame, mm. None where
    no fold was found."""
    cells = volumes.cells
    nipple = volumes.in_body(nipple_input)
    if found["nipple_to_fold_mm"] is None or not np.isfinite(found["nipple_to_fold_mm"]):
        return None
    x, y = nipple[0] + np.asarray(across_mm, float), nipple[1] - found["nipple_to_fold_mm"]
    i = np.clip(np.searchsorted(cells.x, x), 0, len(cells.x) - 1)
    j = np.clip(np.searchsorted(cells.y, y), 0, len(cells.y) - 1)
    front = cells.wall_mm[i, j] + (np.clip(cells.height_mm[i, j], 0.0, None) if found["fold_from"] == "seen" else 0.0)
    return transform_points(np.linalg.inv(volumes.body_from_input), np.column_stack([x, np.full_like(x, y), front]))


def ptosis_from_cells(nipple_body, cells: SkinCells, side: str) -> dict:
    """Regnault's ptosis grade of the `side` breast from its nipple ((3,) her body frame, mm) and her
    skin's cells, with what it rests on, heights along her up axis (mm):

    * nipple_to_lowest_mm: the nipple's height above the breast's lowest point under it (its lower
      contour, or the fold where the skin is seen to meet the wall): measured in every case;
    * nipple_to_fold_mm: the nipple's height above the inframammary fold under it (< 0: below);
    * lowest_to_fold_mm: the height of that lowest point above the fold (< 0: the gland hangs below it);
    * fold_from: "seen" — the skin under the nipple is seen to come down to the skin below the breast,
      and the fold is where it does; "estimated" — the lower pole ends in a cliff that hides the fold,
      which is put HANG_SLOPE × the gland's depth at its lowest point above that point (the underside
      taken to rise back to the wall at that slope); "none" — no breast under the nipple (grade "0",
      the heights None);
    * grade: above the fold by over AT_FOLD_MM, "pseudoptosis" when the gland hangs over PSEUDO_MM below
      the fold, else "0"; "I" from there down to GRADE_I_MM below the fold; "II" down to GRADE_II_MM
      below, the nipple above the lower contour by over AT_LOWEST_MM; "III" lower, or below the fold at
      the lower contour."""
    nipple = np.asarray(nipple_body, float)
    region = own_region(cells, side, nipple)
    edge = lower_edge(cells, region)
    under = np.flatnonzero(np.isfinite(edge) & (np.abs(cells.x - nipple[0]) <= UNDER_NIPPLE_MM))
    if not len(under):
        return {"grade": "0", "nipple_to_lowest_mm": None, "nipple_to_fold_mm": None, "lowest_to_fold_mm": None,
                "fold_from": "none"}
    j = np.argmax(region[under], axis=1)                         # each column's lowest cell of the breast
    depth = cells.height_mm[under, j]
    cliff = depth > TAPER_MM
    if cliff.mean() < 0.5:
        fold = float(np.median([_fold_in_column(cells, i, jj, edge[i]) for i, jj in zip(under[~cliff], j[~cliff])]))
        lowest, fold_from = min(float(np.median(edge[under])), fold), "seen"
    else:
        lowest = float(np.median(edge[under[cliff]]))
        fold, fold_from = lowest + HANG_SLOPE * float(np.median(depth[cliff])), "estimated"
    to_fold, to_lowest = float(nipple[1] - fold), float(nipple[1] - lowest)
    return {"grade": regnault_grade(to_fold, to_lowest), "nipple_to_lowest_mm": to_lowest,
            "nipple_to_fold_mm": to_fold, "lowest_to_fold_mm": lowest - fold, "fold_from": fold_from}


def regnault_grade(to_fold: float, to_lowest: float) -> str:
    """Regnault's grade from the nipple's height above the fold and above the breast's lowest point (mm, along
    her up axis): `ptosis_from_cells`'s bands."""
    if to_fold > AT_FOLD_MM:
        return "pseudoptosis" if to_fold - to_lowest < -PSEUDO_MM else "0"
    if to_fold >= -GRADE_I_MM:
        return "I"
    return "II" if to_fold >= -GRADE_II_MM and to_lowest > AT_LOWEST_MM else "III"


def _fold_in_column(cells: SkinCells, i: int, j: int, edge: float) -> float:
    """Where the skin of column i, coming down from the breast's lowest cell j, reaches the skin below the
    breast (within FLOOR_MM of the median height of the seen cells FLOOR_BAND below): the fold (y, mm),
    interpolated between cell centres; the breast's lower edge `edge` when no cell there was seen."""
    h, seen, y = cells.height_mm[i], cells.seen[i], cells.y
    lo, hi = FLOOR_BAND
    band = np.arange(max(j - int(hi / CELL_MM), 0), max(j - int(lo / CELL_MM) + 1, 0))
    band = band[seen[band]]
    if not len(band):
        return float(edge)
    floor = float(np.median(h[band])) + FLOOR_MM
    prev = j
    for k in range(j - 1, band.min() - 1, -1):                  # down from the breast, over the seen cells
        if not seen[k]:
            continue
        if h[k] <= floor:
            frac = (h[prev] - floor) / (h[prev] - h[k]) if h[prev] > h[k] else 1.0
            return float(y[prev] - (y[prev] - y[k]) * np.clip(frac, 0.0, 1.0))
        prev = k
    return float(y[band.min()])


def own_region(cells: SkinCells, side: str, nipple_body) -> np.ndarray:
    """(nx, ny) the `side` breast's own cells: its side of the footprint where her skin stands more than
    FOOT_MM in front of the wall (the joined footprint also holds the other breast's mirror image), the
    piece that holds the nipple (the largest piece when none does)."""
    labels, count = ndimage.label(cells.side(side) & (cells.height_mm > FOOT_MM))
    if count == 0:
        return labels > 0
    i, j = _cell(cells, nipple_body)
    keep = labels[i, j] if i is not None and labels[i, j] else np.argmax(np.bincount(labels.ravel())[1:]) + 1
    return labels == keep


def _cell(cells: SkinCells, point) -> tuple:
    """(i, j) the cell holding `point` ((2+,) her body frame, mm), (None, None) off the grid."""
    i = int(np.floor((point[0] - cells.x[0]) / CELL_MM + 0.5))
    j = int(np.floor((point[1] - cells.y[0]) / CELL_MM + 0.5))
    inside = 0 <= i < len(cells.x) and 0 <= j < len(cells.y)
    return (i, j) if inside else (None, None)


def lower_edge(cells: SkinCells, region: np.ndarray) -> np.ndarray:
    """(nx,) the height (y, mm) of the region's lower edge in each column of cells, NaN where the column
    has none: where her skin falls through FOOT_MM below the column's lowest cell of the region,
    interpolated between that cell's centre and the next one down."""
    nx, ny = region.shape
    has = region.any(1)
    j = np.where(has, np.argmax(region, axis=1), 0)              # the lowest cell of each column
    i = np.arange(nx)
    h = cells.height_mm[i, j]
    below = np.where(j > 0, cells.height_mm[i, np.maximum(j - 1, 0)], -np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(h > below, (h - FOOT_MM) / (h - below), 0.5)
    edge = cells.y[j] - CELL_MM * np.clip(frac, 0.0, 1.0)
    return np.where(has, edge, np.nan)


def _outline_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Mean distance (mm) between the outlines of two cell regions, each outline cell to the nearest of
    the other's, averaged both ways."""
    ea, eb = a & ~ndimage.binary_erosion(a), b & ~ndimage.binary_erosion(b)
    da, db = ndimage.distance_transform_edt(~eb), ndimage.distance_transform_edt(~ea)
    return float(0.5 * (da[ea].mean() + db[eb].mean()) * CELL_MM)


def _pct(value: float, length: float) -> float:
    return float(100.0 * value / length) if length > 0 else 0.0
