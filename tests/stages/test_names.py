"""What the hand-off USD calls things: readable, valid prim names, each its own (a DCC makes one
object per prim, and Blender renames a repeated name to name.001)."""

from __future__ import annotations

from types import SimpleNamespace

from mpmfx.stages.names import STAGE_NAMES, usd_names


def _shot(bodies: list[tuple[str, str]], colliders=(), group="material"):
    objs = [SimpleNamespace(name=n, material=m) for n, m in bodies]
    groups = {"material": [m for _, m in bodies], "object": [n for n, _ in bodies], "all": ["all"] * len(bodies)}
    return SimpleNamespace(
        bodies=objs,
        colliders=[SimpleNamespace(name=c) for c in colliders],
        surface_groups=lambda: groups[group],
    )


def test_surfaces_take_their_objects_names_not_the_presets():
    names = usd_names(_shot([("bear", "Elastic"), ("pool", "Water"), ("splash", "Water")]))
    assert names.surfaces == {"Elastic": "bear", "Water": "pool_splash"}
    assert names.volumes == {"Elastic": "bear_vdb", "Water": "pool_splash_vdb"}
    assert names.particles == {"bear": "bear_particles", "pool": "pool_particles", "splash": "splash_particles"}


def test_names_are_valid_and_distinct_from_each_other_the_colliders_and_the_stage():
    shot = _shot([("my-bear", "Elastic"), ("1st", "Water"), ("camera", "Granular")], colliders=["my_bear"])
    names = usd_names(shot)
    every = [*names.surfaces.values(), *names.volumes.values(), *names.particles.values()]
    assert len(set(every)) == len(every)
    assert not set(every) & ({"my_bear", *STAGE_NAMES})
    assert all(n.replace("_", "a").isalnum() and not n[0].isdigit() for n in every)
    assert names.surfaces["Elastic"] == "my_bear_2" and names.surfaces["Water"] == "_1st"
