"""`mpmfx wedge` input: the values of a --vary."""

import pytest


def test_a_wedge_of_one_value_written_twice_is_refused():
    from mpmfx.wedge import parse_vary

    with pytest.raises(Exception, match="two or more different values"):
        parse_vary("surface.radius_scale=1,1.0")
    assert parse_vary("surface.radius_scale=1,1.5") == ("surface.radius_scale", [1, 1.5])
