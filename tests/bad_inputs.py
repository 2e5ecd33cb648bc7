"""Inputs no patient scan is — malformed, mis-scaled, forged or oversized files — that the commands
must refuse. Used by tests/test_bad_input.py and benchmarks/bench_refusal.py; large files are sparse
(they cost no disk)."""
from __future__ import annotations

import io
import os
import zipfile

import numpy as np

PLY_XYZ = "property float x\nproperty float y\nproperty float z\n"


def ply_header(count: int, fmt: str = "binary_little_endian") -> bytes:
    """The header of a PLY of `count` x, y, z float vertices."""
    return f"ply\nformat {fmt} 1.0\nelement vertex {count}\n{PLY_XYZ}end_header\n".encode()


def breast_mm(n=2000, seed=0):
    """A hemisphere of radius 60 mm: a breast-sized point cloud in millimetres."""
    v = np.random.default_rng(seed).normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return 60.0 * v / np.linalg.norm(v, axis=1, keepdims=True)


def sparse(path, header: bytes, size: int):
    """`header` then zeros up to `size` bytes, without writing the zeros."""
    path.write_bytes(header)
    os.truncate(path, size)
    return path


def four_numbers_ply(path):
    """An ASCII PLY of 60 vertices whose first line holds 4 numbers."""
    rows = np.random.default_rng(0).uniform(0, 100, (60, 3))
    text = "\n".join(" ".join(f"{v:.3f}" for v in row) for row in rows).replace("\n", " 5.0\n", 1)
    path.write_bytes(ply_header(60, "ascii") + f"{text}\n".encode())
    return path


def forged_npz(path):
    """An NPZ whose member's header declares 10¹² × 3 float64 values (24 TB) while it holds 24 bytes."""
    np.savez(path, grid=np.zeros(2))
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**12, 3)})
    with zipfile.ZipFile(path, "a") as archive:
        archive.writestr("points.npy", header.getvalue() + b"\0" * 24)
    return path


def inflating_npz(path, mib=300):
    """A small NPZ (deflated) one of whose members unpacks to `mib` MiB of zeros, its header true to them."""
    np.savez(path, grid=np.zeros(2))
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False,
                                                  "shape": (mib << 17,)})
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as archive:
        with archive.open("points.npy", "w", force_zip64=True) as member:
            member.write(header.getvalue())
            for _ in range(mib):
                member.write(bytes(1 << 20))
    return path
