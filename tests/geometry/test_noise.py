"""The seeded noise of material variation (mpmfx.geometry.noise)."""

import numpy as np
import pytest

from mpmfx.geometry.noise import CLIP, fourier_noise


def _points(n, size, seed=0):
    return np.random.default_rng(seed).uniform(0.0, size, (n, 3))


def test_the_same_seed_gives_the_same_values_another_seed_others():
    x = _points(2000, 1.0)
    a = fourier_noise(x, 0.05, 7)
    assert np.array_equal(a, fourier_noise(x, 0.05, 7))
    assert np.array_equal(a[:10], fourier_noise(x[:10], 0.05, 7))  # a point's value is its own
    b = fourier_noise(x, 0.05, 8)
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.1
    assert abs(np.corrcoef(a, fourier_noise(x, 0.05, (7, 1)))[0, 1]) < 0.1


@pytest.mark.parametrize("feature", [0.02, 0.1])
def test_unit_deviation_and_the_feature_size_is_its_correlation_length(feature):
    """std 1 over a region many features wide; correlation exp(-r^2 / (2 l^2)) at lag r, for a
    random direction: 0.61 at r = l, 0.14 at 2 l."""
    x = _points(20000, 40 * feature, seed=1)
    n = fourier_noise(x, feature, 3)
    assert abs(n.mean()) < 0.1 and abs(n.std() - 1.0) < 0.1
    assert np.abs(n).max() <= CLIP
    d = np.random.default_rng(2).standard_normal((len(x), 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for lag, expected in ((0.5, np.exp(-0.125)), (1.0, np.exp(-0.5)), (2.0, np.exp(-2.0))):
        m = fourier_noise(x + lag * feature * d, feature, 3)
        assert np.corrcoef(n, m)[0, 1] == pytest.approx(expected, abs=0.08), lag


def test_a_feature_size_must_be_positive():
    with pytest.raises(ValueError, match="feature_size"):
        fourier_noise(np.zeros((1, 3)), 0.0, 0)


def test_the_values_do_not_depend_on_the_thread_count(monkeypatch):
    x = _points(150_000, 1.0)  # three blocks
    monkeypatch.setenv("MPMFX_SURFACE_THREADS", "1")
    one = fourier_noise(x, 0.05, 4)
    monkeypatch.setenv("MPMFX_SURFACE_THREADS", "3")
    assert np.array_equal(one, fourier_noise(x, 0.05, 4))
