"""Emitters and late entries through the stages: the emitted mass per second is the rate, a late
object is absent before its start, ids stay with their particles from frame to frame (and reach
the USD points), a run killed mid-emission resumes byte-identically, and bad emitter input stops
the run with exit 2, naming the file and the key."""

from __future__ import annotations

import numpy as np
import pytest

import mpmfx
from mpmfx.cli import main
from mpmfx.io.frames import ParticleFrame, SeedParticles, SurfaceFrame
from tests.conftest import write_tiny_shot

FPS = 24.0
RATE = 0.02  # m^3/s
EXTRA = """
[[objects]]
name = "late"
mesh = "cube.obj"
material = "Elastic"
translate = [0.7, 0.75, 0.7]
start_time = 0.1                 # s: enters between frames 3 and 4 (t = 0.083 and 0.125)

[[emitters]]
name = "spout"
shape = "box"
size = [0.1, 0.05, 0.1]
translate = [0.3, 0.8, 0.3]
material = "Water"
rate = {rate}
velocity = [0.0, -1.0, 0.0]
start_time = 0.0
end_time = 0.2
"""


def _shot(folder, *, frame_end=6, rate=RATE, extra=""):
    return write_tiny_shot(folder, frame_end=frame_end, extra=EXTRA.format(rate=rate) + extra)


@pytest.fixture(scope="module")
def ran(tmp_path_factory):
    folder = tmp_path_factory.mktemp("emit")
    run = mpmfx.load_shot(_shot(folder), cache_root=folder / "cache", quiet=True)
    results = {r.stage: r for r in run.run(until="export")}
    return run, results


def _frames(entry) -> dict[int, ParticleFrame]:
    return {int(p.stem): ParticleFrame.read(p) for p in sorted((entry / "frames").glob("*.npz"))}


def test_the_emitted_mass_per_second_is_the_rate(ran):
    run, results = ran
    seed = SeedParticles.read(results["voxelise"].entry)
    shot = run.shot
    spout = seed.body == 2  # objects cube, late; then the emitter
    vp = (shot.domain.size / shot.domain.grid_n) ** 3 / shot.voxelise.ppc
    assert seed.volume[spout].sum() == pytest.approx(RATE * 0.2, abs=vp)
    assert results["simulate"].flagged == 0  # the QA expects the mass that has entered (stages/qa.py)
    frames = _frames(results["simulate"].entry)
    density = 1000.0  # kg/m^3 (Water's, in the shot's world): any constant checks the same ratio
    for f, p in frames.items():
        t = (f - shot.shot.frame_start) / FPS
        emitted = np.count_nonzero(p.body == 2) * vp * density  # kg in the shot at t
        # a particle enters at the first substep starting at or after its birth: within a frame
        assert emitted == pytest.approx(RATE * density * min(t, 0.2), abs=RATE * density / FPS + vp * density)


def test_a_late_object_is_absent_before_its_start_and_present_after(ran):
    _, results = ran
    frames = _frames(results["simulate"].entry)
    seed = SeedParticles.read(results["voxelise"].entry)
    n_late = np.count_nonzero(seed.body == 1)
    for f, p in frames.items():
        here = np.count_nonzero(p.body == 1)
        assert here == (0 if (f - 1) / FPS < 0.1 else n_late), f


def test_ids_stay_with_their_particles_and_reach_the_usd_points(ran):
    from pxr import Usd, UsdGeom  # optional: pxr

    run, results = ran
    frames = _frames(results["simulate"].entry)
    seed = SeedParticles.read(results["voxelise"].entry)
    for f in sorted(frames)[1:]:
        a, b = frames[f - 1], frames[f]
        assert np.all(np.diff(b.id) > 0) and set(a.id) <= set(b.id)  # none lost, the new ones added
        np.testing.assert_array_equal(b.body, seed.body[b.id])
        same = np.isin(b.id, a.id) & (b.body > 0)  # the late ones (the first cube bounces off the floor)
        prev = np.isin(a.id, b.id) & (a.body > 0)
        # each id is where its own velocity (and gravity) took it: the same particle, not another's,
        # which would be a body's size away (a few contacts bend a path by about a spacing, 1/48 m)
        pred = a.x[prev] + a.v[prev] / FPS + np.array([0.0, -0.5 * 9.81 / FPS**2, 0.0])
        miss = np.linalg.norm(b.x[same] - pred, axis=1)
        assert not len(miss) or (np.percentile(miss, 99) < 0.02 and miss.max() < 0.05)  # m
    surfaces = [SurfaceFrame.read(p) for p in sorted((results["surface"].entry / "frames").glob("*.npz"))]
    assert all(list(s.groups) == ["Elastic", "Water"] for s in surfaces)  # one mesh a material, as it grows
    water = [len(s.groups["Water"].vertices) for s in surfaces]
    assert water[0] == 0 and 0 < water[2] < water[-1]  # (none emitted yet at t = 0)
    stage = Usd.Stage.Open(str(results["export"].entry / "shot.usda"))
    last = run.shot.shot.frame_end
    points = UsdGeom.Points(stage.GetPrimAtPath("/World/particles/spout_particles"))
    ids = np.asarray(points.GetIdsAttr().Get(last))
    np.testing.assert_array_equal(ids, frames[last].id[frames[last].body == 2])
    assert len(points.GetVelocitiesAttr().Get(last)) == len(ids) > 0


def test_a_run_killed_mid_emission_resumes_byte_identically(tmp_path):
    """As tests/stages/test_safety.py kills a run: after frame 3 of 8, while the spout emits."""
    from tests.stages.test_safety import kill_mid_simulate

    shot = _shot(tmp_path, frame_end=8)
    ref = mpmfx.load_shot(shot, cache_root=tmp_path / "ref", quiet=True).run(until="simulate")[1].entry
    run, frames = kill_mid_simulate(shot, tmp_path / "killed")
    assert 3 <= len(list(frames.glob("[0-9]*.npz"))) < 8
    assert {r.stage: r.state for r in run.run(until="simulate")}["simulate"] == "resumed"
    assert [p.read_bytes() for p in sorted(frames.glob("*.npz"))] == [
        p.read_bytes() for p in sorted((ref / "frames").glob("*.npz"))
    ]


@pytest.mark.parametrize(
    "overrides, key",
    [
        (["emitters.0.rate=0"], "emitters[0].rate"),
        (["emitters.0.rate=-0.1"], "emitters[0].rate"),
        (["emitters.0.end_time=0.0"], "emitters[0].end_time"),
        (["solver.max_particles=400"], "solver.max_particles"),  # the spout alone: 442, at load
        (["solver.max_particles=2000"], "solver.max_particles"),  # with the objects' 3456: before simulating
        (["objects.1.start_time=-1.0"], "objects[1].start_time"),
    ],
)
def test_bad_emitter_input_exits_2_naming_the_file_and_the_key(tmp_path, capsys, overrides, key):
    shot = _shot(tmp_path)
    sets = [a for o in overrides for a in ("--set", o)]
    assert main(["run", str(shot), "--until", "simulate", "--cache", str(tmp_path / "c"), *sets]) == 2
    err = capsys.readouterr().err
    assert str(shot) in err and key in err


def test_an_open_mesh_as_an_emitter_exits_2(tmp_path, capsys):
    import trimesh

    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    box.update_faces(np.arange(len(box.faces)) != 0)
    box.export(tmp_path / "open.obj")
    shot = _shot(
        tmp_path,
        extra='\n[[emitters]]\nname = "hose"\nshape = "mesh"\nmesh = "open.obj"\n'
        "translate = [0.7, 0.3, 0.3]\nrate = 0.001\nend_time = 0.1\n",
    )
    assert main(["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert str(shot) in err and "emitters[1].mesh" in err and "not closed" in err


def test_cache_keys_cover_emitters_and_start_times(tmp_path):
    """Where a particle is emitted, and when it enters, are voxelise's parameters (and so every key
    after it); an emitter's material is simulate's, as an object's is."""
    shot = _shot(tmp_path)

    def keys(*sets):
        entries = mpmfx.load_shot(shot, overrides=list(sets), cache_root=tmp_path / "c", quiet=True).entries()
        return {stage: e.root.name for stage, e in entries.items()}

    base = keys()
    for change in ("emitters.0.rate=0.01", "emitters.0.seed=1", "emitters.0.end_time=0.3", "objects.1.start_time=0.2"):
        changed = keys(change)
        assert changed["voxelise"] != base["voxelise"] and changed["simulate"] != base["simulate"], change
    changed = keys("emitters.0.material=Mushy")
    assert changed["voxelise"] == base["voxelise"] and changed["simulate"] != base["simulate"]
