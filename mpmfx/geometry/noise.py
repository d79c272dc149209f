"""Seeded smooth noise at points: the per-particle variation of an object's material.

A sum of random Fourier modes (a spectral Gaussian random field):

    n(x) = sqrt(2 / M) sum_m cos(k_m . x + phi_m),   k_m ~ N(0, I / l^2),  phi_m ~ U[0, 2 pi)

has zero mean, unit variance and the Gaussian correlation E[n(x) n(x + r)] = exp(-|r|^2 / (2 l^2))
(the average of cos(k . r) over k ~ N(0, I / l^2)), so l, the feature size in metres, is the
distance at which two points' values are correlated by exp(-1/2) ~ 0.61. It is smooth (no
lattice: the modes point in random directions), defined everywhere (a point's value does not
depend on which other points are asked), and deterministic: the same seed gives the same
field, in numpy alone.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from mpmfx.threads import cpu_threads

__all__ = ["MODES", "CLIP", "fourier_noise"]

MODES = 128  # cosines summed: enough that the field looks random, not like a few plane waves
CLIP = 3.0  # values are clipped to [-CLIP, CLIP] standard deviations (bounds the multipliers)
_CHUNK = 65536  # points per block (a block's phase matrix is CHUNK x MODES float64)


def fourier_noise(
    points: np.ndarray, feature_size: float, seed: int | tuple[int, ...], modes: int = MODES
) -> np.ndarray:
    """Noise of unit standard deviation at `points`.

    points: (n, 3) world positions, m; feature_size: correlation length l, m (> 0); seed: an int
    or a tuple of ints (e.g. (object seed, field index): one independent field per field).
    Returns (n,) float64, clipped to [-CLIP, CLIP]. About 3 s a million points on one core
    (128 cosines each); blocks of points run on mpmfx.threads.cpu_threads() threads."""
    if not feature_size > 0:
        raise ValueError(f"fourier_noise: feature_size = {feature_size!r} must be > 0 (metres)")
    rng = np.random.default_rng(seed)
    k = rng.standard_normal((modes, 3)) / float(feature_size)  # 1/m
    phase = rng.uniform(0.0, 2.0 * np.pi, modes)
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    out = np.empty(len(pts), np.float64)

    def block(s: int) -> None:  # (numpy releases the GIL: blocks run on every core; each row's sum is its own)
        out[s : s + _CHUNK] = np.cos(pts[s : s + _CHUNK] @ k.T + phase).sum(axis=1)

    starts = range(0, len(pts), _CHUNK)
    if len(starts) > 1 and cpu_threads() > 1:
        with ThreadPoolExecutor(cpu_threads()) as pool:
            list(pool.map(block, starts))
    else:
        for s in starts:
            block(s)
    out *= np.sqrt(2.0 / modes)
    return np.clip(out, -CLIP, CLIP)
