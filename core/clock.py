"""The one wall clock of breastplan: milliseconds per named step, and seconds since construction.

Used by the commands (the `seconds` they report), the ingest pipeline (`Ingested.timings_ms`)
and the benchmarks (`benchmarks/timing.py`). Standard library only: importing it costs nothing.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Iterator


class Clock:
    """Wall-clock time since construction; `with clock("step"):` adds the block's milliseconds to
    `ms["step"]` (a step timed twice accumulates)."""

    def __init__(self):
        self.start = time.perf_counter()
        self.ms: dict[str, float] = {}

    @contextmanager
    def __call__(self, step: str) -> Iterator[None]:
        start = time.perf_counter()
        yield
        self.ms[step] = self.ms.get(step, 0.0) + 1e3 * (time.perf_counter() - start)

    @property
    def seconds(self) -> float:
        """Seconds since construction, rounded to the millisecond (as the commands report them)."""
        return round(time.perf_counter() - self.start, 3)
