"""Metrics and the six-plot (docs/model.md §7): hand-computed truths, not numbers from the code."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from matplotlib import image

from breastplan.learn.figures import six_plot
from breastplan.learn.metrics import (INDIRECT_KEYS, indirect_distances, indirect_metrics, mpe_pct,
                                      rmse_pct, summary, ttest)

ORIGINAL = np.array([[1.0, 0, 0], [0, 2.0, 0], [0, 0, 3.0]])   # ‖o‖ = 1, 2, 3


# --- direct metrics ---------------------------------------------------------------------------

def test_rmse_hand_computed():
    # errors (1, 0, 0, −2): mean square 5/4, RMSE √5/2; mean(y) = 2.5 → √5/2 / 2.5 · 100 = 20√5 %
    y, f = [1.0, 2, 3, 4], [2.0, 2, 3, 2]
    assert rmse_pct(f, y) == pytest.approx(20 * math.sqrt(5))
    assert isinstance(rmse_pct(f, y), float)


def test_rmse_negative_targets_use_abs_mean():
    # the same errors around mean(y) = −2.5 stay a positive 20√5 %
    assert rmse_pct([-2.0, -2, -3, -2], [-1.0, -2, -3, -4]) == pytest.approx(20 * math.sqrt(5))


def test_rmse_zero_mean_target_is_nan():
    assert math.isnan(rmse_pct([0.0, 0.0], [-1.0, 1.0]))


def test_mpe_hand_computed_excludes_zero_targets():
    # |f − y|/|y| = 1, 0.5, 0.25 over y ≠ 0; the y = 0 entry has no relative error → mean 7/12
    assert mpe_pct([2.0, 1, 5, 3], [1.0, 2, 4, 0]) == pytest.approx(700 / 12)
    assert math.isnan(mpe_pct([1.0, 2.0], [0.0, 0.0]))


def test_mpe_negative_targets():
    # |−3 − (−2)| / |−2| = 0.5, |−4 − (−4)| / 4 = 0 → 25 %
    assert mpe_pct([-3.0, -4.0], [-2.0, -4.0]) == pytest.approx(25.0)


def test_direct_metrics_per_column():
    y = np.array([[1.0, 10], [2, 10], [3, 10], [4, 10]])
    f = np.array([[2.0, 11], [2, 9], [3, 10], [2, 10]])
    # column 1: errors (1, −1, 0, 0): RMSE √0.5, / 10 → 5√2 %; MPE (0.1 + 0.1) / 4 → 5 %
    # column 0: as test_rmse_hand_computed; MPE (1 + 0 + 0 + 0.5) / 4 → 37.5 %
    assert rmse_pct(f, y) == pytest.approx([20 * math.sqrt(5), 5 * math.sqrt(2)])
    assert mpe_pct(f, y) == pytest.approx([37.5, 5.0])
    assert rmse_pct(f, y).shape == (2,)


def test_direct_metrics_reject_mismatched_shapes():
    with pytest.raises(ValueError):
        rmse_pct([1.0, 2.0], [1.0, 2.0, 3.0])


# --- indirect metrics -------------------------------------------------------------------------

def test_three_point_distances_by_hand():
    modelled = np.array([[1.5, 0, 0], [0, 2.0, 0], [0, 0, 3.6]])
    # modelled → original: (1.5,0,0) is 0.5 from (1,0,0) (next: (0,2,0) at 2.5) → 0.5/‖(1,0,0)‖ = 50 %
    #   (normalising by the original point, not by ‖m‖ = 1.5 which would give 33 %);
    #   (0,2,0) → 0; (0,0,3.6) is 0.6 from (0,0,3) → 0.6/3 = 20 %. Mean 70/3 %, max 50 %.
    # original → modelled: the same nearest pairs, 0.5/1, 0, 0.6/3 → the same numbers.
    d = indirect_distances(ORIGINAL, modelled)
    assert d["modelled_to_original_euclidean"] == pytest.approx(70 / 3)
    assert d["modelled_to_original_hausdorff"] == pytest.approx(50.0)
    assert d["original_to_modelled_euclidean"] == pytest.approx(70 / 3)
    assert d["original_to_modelled_hausdorff"] == pytest.approx(50.0)


def test_subset_is_asymmetric():
    modelled = ORIGINAL[:2]
    # modelled → original: every modelled point is an original point → 0.
    # original → modelled: (0,0,3) is √10 from (1,0,0) and √13 from (0,2,0) → √10/3;
    #   the other two are 0 → mean √10/9, max √10/3 (× 100 %).
    d = indirect_distances(ORIGINAL, modelled)
    assert d["modelled_to_original_euclidean"] == 0 and d["modelled_to_original_hausdorff"] == 0
    assert d["original_to_modelled_euclidean"] == pytest.approx(100 * math.sqrt(10) / 9)
    assert d["original_to_modelled_hausdorff"] == pytest.approx(100 * math.sqrt(10) / 3)


def test_identical_clouds_are_zero():
    p = np.random.default_rng(1).normal(size=(500, 3)) + [0, 0, 5]
    assert indirect_distances(p, p) == dict.fromkeys(INDIRECT_KEYS, 0.0)


def _lat_long_sphere(n: int) -> np.ndarray:
    """Unit sphere on n + 1 colatitudes (poles included) × 2n longitudes, both spaced π/n."""
    theta = np.linspace(0, np.pi, n + 1)[:, None]
    phi = np.arange(2 * n)[None, :] * np.pi / n
    return np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                        np.cos(theta)), axis=-1).reshape(-1, 3)


N_GRID = 300
DENSE = _lat_long_sphere(N_GRID)
SPARSE = np.random.default_rng(2).normal(size=(2000, 3))
SPARSE /= np.linalg.norm(SPARSE, axis=1, keepdims=True)


@settings(max_examples=15, deadline=None)
@given(s=st.floats(0.02, 0.2))
def test_scaled_sphere_original_to_modelled_is_s(s):
    radius = 7.0
    original, modelled = radius * SPARSE, radius * (1 + s) * DENSE
    # Every modelled point lies at radius R(1+s), so each normalised distance is ≥ s. Any unit
    # direction is within angle δ ≤ π/(2n) + π/(2n) of a grid direction (half a ring gap along
    # the meridian, then at most half a longitude gap along the parallel), and a point at angle
    # δ on the scaled sphere lies at R·√(s² + 2(1+s)(1 − cos δ)) ≤ R·√(s² + (1+s)δ²).
    delta = np.pi / N_GRID
    upper = 100 * math.sqrt(s * s + (1 + s) * delta * delta)   # ≤ 1.14 · 100 s at s = 0.02
    d = indirect_distances(original, modelled)
    for key in ("original_to_modelled_euclidean", "original_to_modelled_hausdorff"):
        assert 100 * s - 1e-9 <= d[key] <= upper


def test_indirect_metrics_per_example():
    shifted = np.array([[1.5, 0, 0], [0, 2.0, 0], [0, 0, 3.6]])
    out = indirect_metrics(np.stack([ORIGINAL, ORIGINAL]), np.stack([ORIGINAL, shifted]), threads=2)
    # example 0 identical → 0; example 1 as test_three_point_distances_by_hand
    assert out["modelled_to_original_euclidean"] == pytest.approx([0, 70 / 3])
    assert out["original_to_modelled_hausdorff"] == pytest.approx([0, 50])
    assert all(out[k].shape == (2,) for k in INDIRECT_KEYS)


# --- summaries and tests ----------------------------------------------------------------------

def test_summary():
    # sample variance of 1..4: ((1.5² + 0.5²) · 2) / 3 = 5/3
    assert summary([1, 2, 3, 4]) == pytest.approx({"mean": 2.5, "sd": math.sqrt(5 / 3), "min": 1, "max": 4})
    one = summary([7.0])
    assert math.isnan(one["sd"]) and one["mean"] == one["min"] == one["max"] == 7.0


def test_ttest_identical_samples():
    r = ttest([1.0, 2, 3, 5], [1.0, 2, 3, 5])
    assert r["t"] == 0 and r["p"] == pytest.approx(1.0) and r["significant"] is False


def test_ttest_clearly_different():
    rng = np.random.default_rng(3)
    assert ttest(rng.normal(0, 1, 50), rng.normal(3, 1, 50))["significant"] is True


def test_ttest_hand_computed_pooled():
    # (1,2,3) vs (4,5,6): variances 1, pooled 1, SE √(2/3) → t = −3/√(2/3) = −√13.5, df = 4.
    # Student t CDF at df 4: F(t) = ½ + ¾·u·(1 − u²/3), u = t/√(4 + t²) → p = 1 − 3u/2 + u³/2.
    u = math.sqrt(13.5 / 17.5)
    r = ttest([1.0, 2, 3], [4.0, 5, 6])
    assert r["t"] == pytest.approx(-math.sqrt(13.5))
    assert r["p"] == pytest.approx(1 - 1.5 * u + 0.5 * u**3)    # ≈ 0.0213
    assert r["significant"] is True
    # unequal sizes tell pooled from Welch: (0,2,4) vs (5,7): variances 4, 2; pooled (2·4 + 2)/3,
    # SE √(10/3 · (1/3 + 1/2)) = 5/3 → t = −4/(5/3) = −2.4 (Welch would give −4/√(7/3) ≈ −2.62)
    assert ttest([0.0, 2, 4], [5.0, 7])["t"] == pytest.approx(-2.4)


# --- figures ----------------------------------------------------------------------------------

def test_six_plot_writes_png_atomically(tmp_path):
    rng = np.random.default_rng(4)
    y = rng.uniform(-2, 3, 200)
    path = tmp_path / "six.png"
    assert six_plot(y, y + rng.normal(0, 0.1, 200), path, "s0") == path
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert image.imread(path).shape[:2] == (550, 900)           # 9 × 5.5 in at 100 dpi
    assert [p.name for p in tmp_path.iterdir()] == ["six.png"]  # no temporary file left


def test_vertex_spike_ratio_is_one_for_a_uniform_error_and_large_for_one_stray_point():
    from breastplan.learn.metrics import vertex_spike_ratios

    truth = np.random.default_rng(0).normal(size=(2, 200, 3)) * 50
    shifted = truth + [1.0, -2.0, 0.5]                  # every vertex off by the same vector
    stray = shifted.copy()
    stray[1, 7] += [0.0, 0.0, 40.0]                     # one vertex of the second breast astray
    assert np.allclose(vertex_spike_ratios(truth, shifted), 1.0)
    ratios = vertex_spike_ratios(truth, stray)
    assert ratios[0] == pytest.approx(1.0) and ratios[1] > 10


@settings(max_examples=20, deadline=None)
@given(st.floats(0.01, 2.0))
def test_spike_ratio_is_one_for_a_sphere_grown_evenly_and_large_for_one_stray_point(grow_mm):
    """Truth: every point of a sphere of radius R moved out by the same δ (smaller than the sample
    spacing) lies δ from its own original point and farther from any other, so every modelled→original
    distance is δ / R: largest = median. One point pushed 40 mm out is a spike of 40 / δ."""
    from breastplan.learn.metrics import spike_ratios

    n = np.random.default_rng(1).normal(size=(2000, 3))
    sphere = 80.0 * n / np.linalg.norm(n, axis=1, keepdims=True)
    grown = sphere * (80.0 + grow_mm) / 80.0
    stray = grown.copy()
    stray[5] *= (80.0 + grow_mm + 40.0) / (80.0 + grow_mm)
    ratios = spike_ratios(indirect_metrics(np.stack([sphere, sphere]), np.stack([grown, stray])))
    assert ratios[0] == pytest.approx(1.0, rel=1e-9) and ratios[1] > 40.0 / grow_mm * 0.99
