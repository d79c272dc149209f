"""`mpmfx bench surface-times` and `mpmfx bench shots`: small runs report real rows."""

import json

from mpmfx.cli import main


def test_surface_times_reports_every_case_and_setting(tmp_path):
    assert (
        main(
            [
                "bench",
                "surface-times",
                "--device",
                "cpu",
                "--quick",
                "--counts",
                "2000",
                "--peers",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    rows = json.loads((tmp_path / "surface_times.json").read_text())
    assert {(r["shape"], r["sampling"]) for r in rows} == {
        (s, m) for s in ("sphere", "torus", "box") for m in ("lattice", "random")
    }
    assert {r["method"] for r in rows} == {"mpmfx fast", "mpmfx fine", "mpmfx round"}
    for r in rows:
        assert 0 < r["ms_device"] <= r["ms_end_to_end"] * 1.01
        assert r["err_mean_h"] < 0.5 and r["vertices"] > 0


def test_surface_times_refuses_a_peer_it_does_not_run(tmp_path, capsys):
    assert main(["bench", "surface-times", "--quick", "--peers", "newton", "--out", str(tmp_path)]) == 2
    assert "newton" in capsys.readouterr().err


def test_shots_times_every_stage_of_the_hero_shots(tmp_path):
    assert main(["bench", "shots", "--quick", "--device", "cpu", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "shots.json").read_text())
    assert [s["shot"] for s in report["shots"]] == ["hero_dam", "hero_castle"]
    for s in report["shots"]:
        assert s["grid_n"] == 32 and s["particles"] > 0 and s["substeps_total"] > 0
        assert {k: v["state"] for k, v in s["stages"].items()} == {
            k: "ran" for k in ("voxelise", "simulate", "surface")
        }


def test_bench_shot_reports_each_stage_its_bytes_and_its_memory(tmp_path, capsys):
    """`mpmfx bench shot SHOT`: a real run to export, each stage's time, the cache bytes a frame,
    and the host's peak of voxelise and of the stages after it beside their estimates."""
    from tests.conftest import write_tiny_shot

    shot = write_tiny_shot(tmp_path)
    args = ["bench", "shot", str(shot), "--device", "cpu", "--cache", str(tmp_path / "c"), "--out", str(tmp_path / "o")]
    assert main([*args, "--set", "export.vdb=false"]) == 0
    row = json.loads((tmp_path / "o" / "shot.json").read_text())
    assert row["particles"] > 0 and row["frames"] == 6 and row["overlap"]
    assert all(row["bytes_per_frame"][s] > 0 for s in ("simulate", "surface", "export"))
    assert set(row["host_peak_bytes"]) == {"voxelise", "simulate + surface"}
    assert all(b > 10**6 for b in row["host_peak_bytes"].values())
    out = capsys.readouterr().out
    assert "x simulate" in out and "host peak against the estimate: voxelise" in out
