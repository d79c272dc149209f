"""Per-frame stages on a two-worker Dask LocalCluster, killed workers, and wedges."""

from __future__ import annotations

import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest
from distributed import WorkerPlugin

from mpmfx.cache import TEMP_GLOB
from mpmfx.config import ShotError
from mpmfx.shotfile import load_shot_config
from mpmfx.stages.parallel import Frames, worth_a_cluster
from mpmfx.stages.runner import ShotRun
from mpmfx.wedge import parse_vary, pick, run_wedge, variant_shots, write_sheets
from tests.conftest import write_tiny_shot


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The tiny shot run serially (workers=1) to render: the byte-for-byte reference."""
    folder = tmp_path_factory.mktemp("parallel")
    shot = write_tiny_shot(folder)
    cwd = os.getcwd()
    os.chdir(folder)  # render publishes to renders/<shot>/ in the working directory
    try:
        results = ShotRun(load_shot_config(shot), cache_root=folder / "serial", quiet=True, workers=1).run()
    finally:
        os.chdir(cwd)
    return shot, {r.stage: r.entry for r in results}


@pytest.fixture(scope="module")
def cluster():
    """One two-worker LocalCluster for the module (starting one costs seconds)."""
    with Frames(workers=2) as ex:
        yield ex


def test_workers_share_the_cores_for_the_surfacers_threads(cluster):
    import os

    from mpmfx.threads import cpu_threads

    cores = len(os.sched_getaffinity(0))
    threads = cluster.client().run(cpu_threads)  # worker address -> its split
    assert sorted(threads.values()) == [max(1, cores // 2)] * 2


def _cache_with_simulation(reference, cache: Path) -> Path:
    """A fresh cache holding only the reference's voxelise and simulate entries."""
    shot, entries = reference
    for stage in ("voxelise", "simulate"):
        src = entries[stage]
        shutil.copytree(src, cache / "tiny" / stage / src.name)
    return cache


def _files(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != "manifest.json"
    }


def test_two_worker_cluster_writes_the_serial_cache_byte_for_byte(reference, cluster, tmp_path, monkeypatch):
    shot, ref = reference
    cache = _cache_with_simulation(reference, tmp_path / "cache")
    monkeypatch.chdir(tmp_path)
    results = ShotRun(load_shot_config(shot), cache_root=cache, quiet=True, executor=cluster).run()
    got = {r.stage: r for r in results}
    assert [got[s].state for s in ("voxelise", "simulate", "surface", "export", "render")] == [
        "cached",
        "cached",
        "ran",
        "ran",
        "ran",
    ]
    for stage in ("surface", "export", "render"):
        a, b = _files(ref[stage]), _files(got[stage].entry)
        assert a.keys() == b.keys(), stage
        vdb = {k for k in a if k.endswith(".vdb")}  # OpenVDB writes a random file UUID: compare grids
        sums = {k for k in a if k.endswith(".vdb.b2")}  # (so their checksums differ too)
        assert {k for k in a if a[k] != b[k]} <= vdb | sums, f"{stage}: files differ from the serial run's"
        for k in vdb:
            assert _vdb_values(ref[stage] / k) == _vdb_values(got[stage].entry / k)
    assert not list(cache.rglob(TEMP_GLOB))
    assert len(list((tmp_path / "renders" / "tiny").glob("[0-9]*.png"))) == 6


def _vdb_values(path: Path) -> dict[str, bytes]:
    from mpmfx.io.vdb import read_vdb

    return {name: np.asarray(g["values"]).tobytes() for name, g in read_vdb(path, with_values=True)["grids"].items()}


class KillOnce(WorkerPlugin):
    """A Dask worker plugin: SIGKILL the worker the first time a task for `frame` starts on it."""

    def __init__(self, frame: int, marker: str):
        self.frame, self.marker = frame, marker

    def transition(self, key, start, finish, **kwargs):
        if finish == "executing" and str(key).endswith(f"-{self.frame:04d}") and not os.path.exists(self.marker):
            Path(self.marker).write_text(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)


def test_killed_worker_is_retried_and_the_cache_holds_nothing_partial(reference, cluster, tmp_path):
    shot, ref = reference
    cache = _cache_with_simulation(reference, tmp_path / "cache")
    run = ShotRun(load_shot_config(shot), cache_root=cache, quiet=True, executor=cluster)
    surface = run.entries()["surface"]
    # what a writer killed mid-write leaves: a temp file beside the frames
    surface.frames_dir.mkdir(parents=True)
    (surface.frames_dir / ".0002.999-dead.tmp.npz").write_bytes(b"PK\x03\x04 half a zip")
    marker = tmp_path / "killed"
    cluster.client().register_plugin(KillOnce(3, str(marker)), name="kill-once")
    results = run.run(until="surface")
    assert marker.is_file(), "the worker running frame 3 must have been killed"
    assert results[-1].state == "resumed"
    assert not list(cache.rglob(TEMP_GLOB))
    assert _files(ref["surface"]) == _files(surface.root)
    assert surface.complete(list(range(1, 7)))
    assert run.run(until="surface")[-1].state == "cached"


def test_a_changed_frame_met_on_a_worker_is_redone_by_its_stage(reference, cluster, tmp_path):
    """A simulate frame flipped at equal size: the worker surfacing it finds it by its checksum,
    the client has simulate redo it, and the surfaces equal the serial run's."""
    shot, ref = reference
    cache = _cache_with_simulation(reference, tmp_path / "cache")
    run = ShotRun(load_shot_config(shot), cache_root=cache, quiet=True, executor=cluster)
    frame = run.entries()["simulate"].frame_path(4, "npz")
    written = bytearray(frame.read_bytes())
    written[len(written) // 2] ^= 0xFF
    frame.write_bytes(bytes(written))
    results = {r.stage: r.state for r in run.run(until="surface")}
    assert results["simulate"] == "resumed" and results["surface"] in ("ran", "resumed")
    assert frame.read_bytes() == (ref["simulate"] / "frames" / "0004.npz").read_bytes()
    assert _files(ref["surface"]) == _files(run.entries()["surface"].root)


def test_wedge_of_a_surfacing_field_shares_one_simulation(reference, cluster, tmp_path):
    shot, _ = reference
    cache = _cache_with_simulation(reference, tmp_path / "cache")
    key, values = parse_vary("surface.smooth_iters=0,3")
    shots = variant_shots(shot, key, values)
    roots = run_wedge(shots, cache_root=cache, executor=cluster, frames=[1, 2, 3], quiet=True)
    assert len({r["simulate"] for r in roots}) == 1 and len(list((cache / "tiny" / "simulate").iterdir())) == 1
    assert len({r["surface"] for r in roots}) == 2
    assert all(shot.solver.deterministic and shot.voxelise.seed == 0 for shot in shots)
    a, b = (sorted((r["render"] / "frames").glob("*.png")) for r in roots)
    assert len(a) == len(b) == 3 and a[0].read_bytes() != b[0].read_bytes()
    tiles = [
        (f"smooth_iters={v}", {f: r["render"] / "frames" / f"{f:04d}.png" for f in (1, 2, 3)})
        for v, r in zip(values, roots)
    ]
    made = write_sheets(tmp_path / "wedge", tiles, [1, 2, 3], fps=24, movie=False)
    import imageio.v2 as imageio

    sheet = imageio.imread(made["sheets"] / "0002.png")
    assert sheet.shape[1] == 2 * 160 and sheet.shape[0] == 120  # two tiles side by side


def test_vary_ranges_and_pick_writes_a_loadable_copy(tmp_path):
    assert parse_vary("surface.smooth_iters=0:6:4") == ("surface.smooth_iters", [0, 2, 4, 6])
    assert parse_vary("objects.cube.overrides.youngs_modulus=100:10000:3", log=True)[1] == [100.0, 1000.0, 10000.0]
    with pytest.raises(ShotError, match="two or more"):
        parse_vary("surface.smooth_iters=2")
    shot = write_tiny_shot(tmp_path)
    out = pick(shot, "objects.0.overrides.youngs_modulus", 3000, out=tmp_path / "picked" / "tiny.toml")
    picked = load_shot_config(out)
    assert picked.objects[0].overrides == {"youngs_modulus": 3000}
    assert picked.objects[0].mesh != load_shot_config(shot).objects[0].mesh  # rewritten for the new folder
    assert picked.model_dump(exclude={"objects", "base_dir"}) == load_shot_config(shot).model_dump(
        exclude={"objects", "base_dir"}
    )


def test_status_names_the_host_that_wrote_an_entry(reference, tmp_path):
    import json

    shot, ref = reference
    cache = _cache_with_simulation(reference, tmp_path / "cache")
    man = next((cache / "tiny" / "simulate").iterdir()) / "manifest.json"
    man.write_text(json.dumps({**json.loads(man.read_text()), "host": "farm-node-7"}))
    status = {s.stage: s for s in ShotRun(load_shot_config(shot), cache_root=cache).status()}
    assert status["simulate"].state == "cached" and "farm-node-7" in status["simulate"].why
    assert "written on" not in status["voxelise"].why  # written here (or by an older mpmfx)


def test_a_bad_worker_count_is_bad_input_not_a_traceback(tiny_shot, tmp_path, monkeypatch, capsys):
    from mpmfx.cli import main

    monkeypatch.setenv("MPMFX_WORKERS", "two")
    assert main(["run", str(tiny_shot), "--cache", str(tmp_path / "cache"), "--until", "voxelise"]) == 2
    assert "$MPMFX_WORKERS = 'two'" in capsys.readouterr().err


@pytest.mark.parametrize("value, fix", [("two", "whole number"), ("0", "at least 1")])
def test_a_bad_surfacer_thread_count_is_bad_input_not_a_traceback(tiny_shot, tmp_path, monkeypatch, capsys, value, fix):
    from mpmfx.cli import main

    monkeypatch.setenv("MPMFX_SURFACE_THREADS", value)
    assert main(["run", str(tiny_shot), "--cache", str(tmp_path / "cache"), "--until", "voxelise"]) == 2
    err = capsys.readouterr().err
    assert f"$MPMFX_SURFACE_THREADS='{value}'" in err and fix in err and "Traceback" not in err


def test_auto_starts_workers_only_where_they_would_finish_sooner():
    # on a 2-core CPU (lab/bench_frames.py) the default shot's light surface frames (0.16 s a frame on 1.7 cores) are
    # slower on two workers than serial; heavy single-core frames (5 s each) are faster there;
    # a Cycles frame already uses both cores
    assert not worth_a_cluster(22, wall=0.16, cpu=0.27, cores=2)
    assert worth_a_cluster(10, wall=5.0, cpu=5.0, cores=2)
    assert not worth_a_cluster(6, wall=5.0, cpu=10.0, cores=2)
    assert not worth_a_cluster(100, wall=5.0, cpu=5.0, cores=1)


def test_auto_keeps_light_frames_serial(monkeypatch):
    # 12 frames (over the auto threshold) that take no time: the probe keeps them here, in
    # order, and no cluster starts
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    monkeypatch.delenv("MPMFX_WORKERS", raising=False)
    monkeypatch.delenv("MPMFX_SCHEDULER", raising=False)
    seen = []
    with Frames() as ex:
        out = ex.map(lambda job, f: seen.append(f) or f * 2, [(None, f) for f in range(12)], quiet=True)
        assert ex._cluster is None and ex._client is None
    assert out == [f * 2 for f in range(12)] and seen == list(range(12))


def test_a_scheduler_address_that_is_no_address_is_refused_before_any_stage(tmp_path, capsys):
    from mpmfx.cli import main

    shot = write_tiny_shot(tmp_path)
    cache = tmp_path / "cache"
    code = main(["run", str(shot), "--until", "surface", "--cache", str(cache), "--scheduler", "bogus-address"])
    assert code == 2
    assert "--scheduler" in capsys.readouterr().err
    assert not cache.exists()
