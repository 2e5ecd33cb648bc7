"""`plan.modes`: many states' displacements stored as shared int16 modes, against truths built here: states of
a known rank come back in that many modes, every state within TOLERANCE_MM of its own displacement."""
from __future__ import annotations

import numpy as np
import pytest

from breastplan.plan.modes import TOLERANCE_MM, modes_of


def _worst(stored, displacements) -> float:
    return float(np.linalg.norm(stored.decode() - displacements, axis=-1).max())


def test_states_of_a_known_rank_come_back_in_that_many_modes_within_the_tolerance():
    """300 states, each a combination of 4 fixed smooth fields over 2,000 points (tens of mm): 4 modes, every
    point of every state within TOLERANCE_MM, and each state decoded alone as in the batch."""
    rng = np.random.default_rng(7)
    x = np.linspace(0.0, 1.0, 2000)
    fields = np.stack([np.stack([np.sin((k + 1) * np.pi * x), np.cos(k * x), x ** k], axis=1) for k in range(4)])
    weights = rng.uniform(-20.0, 20.0, (300, 4))
    displacements = np.einsum("sk,knc->snc", weights, fields)
    stored = modes_of(displacements)
    assert stored.coefficients.shape == (300, 4) and stored.modes.shape == (4, 2000, 3)
    assert stored.modes.dtype == np.int16 and stored.worst_mm <= TOLERANCE_MM
    assert _worst(stored, displacements) == pytest.approx(stored.worst_mm, abs=1e-4)   # checked in float32
    assert np.allclose(stored.decode(123), stored.decode()[123])


def test_rigid_shifts_are_three_modes_and_no_displacement_none():
    """Each state a translation of every point (a closed form of rank 3): at most 3 modes; all zero: none, and
    zeros decoded."""
    shifts = np.random.default_rng(3).normal(0.0, 10.0, (50, 3))
    displacements = np.repeat(shifts[:, None], 700, axis=1)
    stored = modes_of(displacements)
    assert len(stored.scales) <= 3 and _worst(stored, displacements) <= TOLERANCE_MM
    none = modes_of(np.zeros((20, 100, 3)))
    assert len(none.scales) == 0 and np.array_equal(none.decode(), np.zeros((20, 100, 3)))


def test_noise_is_kept_within_the_tolerance_by_more_modes():
    """Small full-rank noise over a rank-2 field: more modes, as many as the tolerance needs, and never a point
    farther than it."""
    rng = np.random.default_rng(11)
    base = np.einsum("sk,knc->snc", rng.uniform(-15, 15, (80, 2)), rng.normal(0, 1, (2, 400, 3)))
    displacements = base + rng.normal(0.0, 0.02, base.shape)
    stored = modes_of(displacements)
    assert 2 < len(stored.scales) <= 80 and _worst(stored, displacements) <= TOLERANCE_MM
