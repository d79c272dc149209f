"""A shot's memory is estimated before voxelise starts and stated in one line; a shot over what
the machine has is refused (exit 2) naming the keys that shrink it, with nothing written."""

from __future__ import annotations

import pytest

import mpmfx.stages.memory as memory
from mpmfx.cli import main
from tests.conftest import write_tiny_shot


def test_a_grid_that_exhausts_memory_is_refused_naming_the_keys(tmp_path, monkeypatch, capsys):
    shot = write_tiny_shot(tmp_path, frame_end=2)
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(shot), "--set", "domain.grid_n=4096", "--cache", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "domain.grid_n = 4096" in err and "voxelise.ppc" in err and "surface.voxel_size" in err
    assert "Traceback" not in err and "GB available" in err
    assert not (tmp_path / "c").exists() and not (tmp_path / "renders").exists()  # nothing written


def test_a_normal_shot_states_its_estimate_and_runs(tmp_path, monkeypatch, capsys):
    shot = write_tiny_shot(tmp_path, frame_end=2)
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "c")]) == 0
    line = [x for x in capsys.readouterr().err.splitlines() if "memory:" in x]
    assert len(line) == 1 and "host available" in line[0] and "particles" in line[0]


def test_the_estimate_is_held_against_the_memory_available(tmp_path, monkeypatch, capsys):
    shot = write_tiny_shot(tmp_path, frame_end=2)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(memory, "host_available", lambda: 10**5)  # 100 kB free
    assert main(["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "c"), "-q"]) == 2
    assert "host memory" in capsys.readouterr().err
    monkeypatch.setattr(memory, "host_available", lambda: 10**12)
    monkeypatch.setattr(memory, "device_free", lambda device: 10**5)  # a GPU with 100 kB free
    assert main(["run", str(shot), "--until", "voxelise", "--cache", str(tmp_path / "c"), "-q"]) == 2
    assert "device memory" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()


def test_the_estimate_bounds_the_particles_voxelise_makes(tmp_path):
    """The count before voxelising is an upper bound of the particles made (the objects' boxes)."""
    import mpmfx

    shot = write_tiny_shot(tmp_path, frame_end=2)
    run = mpmfx.load_shot(shot, cache_root=tmp_path / "c", quiet=True)
    bound = memory.counts(run.shot).particles
    run.run(until="voxelise")
    made = run.entries()["voxelise"].manifest()["particles"]
    assert made <= bound <= 2 * made


@pytest.mark.parametrize("grid_n, words", [(100000, "8 to 4096"), (4096, "GB of memory available"), (4, "8 to 4096")])
def test_check_bounds_its_grid(tmp_path, capsys, grid_n, words):
    import trimesh

    trimesh.creation.box(extents=[0.4, 0.4, 0.4]).export(tmp_path / "box.obj")
    assert main(["check", str(tmp_path / "box.obj"), "--grid-n", str(grid_n)]) == 2
    err = capsys.readouterr().err
    assert "--grid-n" in err and words in err


def test_followed_stages_need_the_solver_and_the_surfacer_at_once(tmp_path):
    """Surface follows simulate: on a GPU both hold their buffers together; the largest shot the
    estimate admits fits what it was given, and one more million particles does not."""
    import mpmfx

    shot = mpmfx.load_shot(write_tiny_shot(tmp_path), cache_root=tmp_path / "c").shot
    n = memory.Counts(2_000_000)
    apart = memory.need(shot, n, cuda=True)
    both = memory.need(shot, n, cuda=True, overlap=True)
    assert both.device["simulate + surface"] == apart.device["simulate"] + apart.device["surface"]
    assert max(both.host.values()) > max(apart.host.values())
    most, per = memory.largest(shot, cuda=True, overlap=True, host_free=64 * 10**9, device_free=80 * 10**9)
    fits = memory.need(shot, memory.Counts(most), cuda=True, overlap=True)
    over = memory.need(shot, memory.Counts(most + 10**6), cuda=True, overlap=True)
    assert max(fits.host.values()) <= 64e9 and max(fits.device.values()) <= 80e9
    assert max(over.host.values()) > 64e9 or max(over.device.values()) > 80e9
    assert 100 < per["device"]["simulate + surface"] < 2000  # bytes a particle
