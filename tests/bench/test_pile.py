"""The poured pile of `mpmfx bench accuracy` (mpmfx/bench/pile.py): its slope measurement on a
known cone, and a tiny pour that heaps into a pile."""

import math

import numpy as np
import pytest

from mpmfx.bench import pile
from mpmfx.bench.cases import lattice


def _cone(phi: float, *, quarter: bool, dx=1 / 32, radius=0.4):
    """Particles filling a cone of slope `phi` degrees on the floor y = 3 dx: a quarter one in the
    corner, or a whole one in the middle. Returns (x, volume, origin, sector)."""
    sp, lo = dx / 2, 3 * dx
    c = (lo, lo, lo) if quarter else (0.5, lo, 0.5)
    a = lo if quarter else 0.5 - radius
    h = radius * math.tan(math.radians(phi))
    x = lattice(
        [a, lo, a],
        [c[0] + radius, lo + h, c[2] + radius],
        sp,
        inside=lambda p: p[:, 1] - lo <= h * (1 - np.hypot(p[:, 0] - c[0], p[:, 2] - c[2]) / radius),
    )
    return x, np.full(len(x), sp**3), c, 0.25 if quarter else 1.0


@pytest.mark.parametrize("quarter", [True, False])
@pytest.mark.parametrize("phi", [20.0, 30.0, 38.0])
def test_the_slope_of_a_known_cone_is_recovered(phi, quarter):
    x, vol, origin, sector = _cone(phi, quarter=quarter)
    angle, radius, height = pile.repose_angle(x, vol, 1 / 32, origin=origin, sector=sector)
    assert angle == pytest.approx(phi, abs=2.0)  # measured within 1.6 deg on this lattice
    assert radius == pytest.approx(0.4, abs=2 / 32)
    assert height == pytest.approx(0.4 * math.tan(math.radians(phi)), abs=1 / 32)


def test_a_flat_layer_has_no_flank_and_a_scatter_no_pile():
    x = lattice([0.1, 0.1, 0.1], [0.9, 0.1 + 1 / 64, 0.9], 1 / 64)
    angle, _, _ = pile.repose_angle(x, np.full(len(x), 1 / 64**3), 1 / 32, origin=(0.5, 0.1, 0.5))
    assert abs(angle) < 1.0
    angle, radius, _ = pile.repose_angle(x[:3], np.full(3, 1e-9), 1 / 32, origin=(0.5, 0.1, 0.5))
    assert math.isnan(angle) and radius == 0.0


def test_the_hopper_emits_its_volume_at_a_steady_rate():
    parts = pile.hopper(1 / 32, volume=0.01, pour_time=2.0, outlet=0.1, drop=0.3)
    assert parts.volume.sum() == pytest.approx(0.01, rel=0.01)
    assert np.all(np.diff(parts.birth) > 0) and parts.birth[-1] < 2.0
    assert np.all(parts.x[:, [0, 2]] >= 3 / 32)  # inside the symmetry planes


def test_a_tiny_pour_heaps_into_a_pile():
    p = pile.pour(grid_n=16, pour_time=1.0, settle_time=0.3, device="cpu")
    assert len(p.x) == p.particles  # every particle born and in the shot
    assert 0.0 < p.angle < 45.0, (p.angle, p.radius, p.height)
    assert p.height > 0.1 and p.radius < 0.7
