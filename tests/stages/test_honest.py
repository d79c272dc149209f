"""Issue 18: nothing stale, nothing misleading. Bad physics is said at run time, advice names
shot keys and helps, published outputs are the current variant's."""
from __future__ import annotations

import pytest

import mpmfx
from mpmfx.cli import main
from tests.conftest import write_tiny_shot


def test_flags_cfl_above_the_cap_and_inverted_particles():
    from mpmfx.stages.qa import flags
    out = flags({1: {"mass": 1.0, "cfl_used": 0.4}, 2: {"mass": 1.0, "cfl_used": 1.6, "inverted": 12}})
    assert 1 not in out and "CFL 1.6" in "; ".join(out[2]) and "12 inverted" in "; ".join(out[2])


@pytest.fixture
def bad_physics(tmp_path, monkeypatch):
    """The tiny shot, with frame 3's QA made to show what a blown-up run shows."""
    import mpmfx.stages.simulate as sim
    real = sim._qa

    def qa(report, size):
        d = real(report, size)
        if d["substeps"] and sim_frame[0] == 3:
            d |= {"j_min": -0.06, "cfl_used": 1.6}
        sim_frame[0] += 1
        return d

    sim_frame = [2]
    monkeypatch.setattr(sim, "_qa", qa)
    return write_tiny_shot(tmp_path, frame_end=4), tmp_path / "c"


def test_bad_physics_warns_at_run_time_and_strict_fails(bad_physics, capsys):
    shot, cache = bad_physics
    assert main(["run", str(shot), "--until", "simulate", "--cache", str(cache), "-q"]) == 0
    captured = capsys.readouterr()
    assert "frame 3" in captured.err and "inverted" in captured.err and "CFL 1.6" in captured.err
    assert "1 frame flagged" in captured.out  # the closing table says it too
    # cached now: the warning stands, and --strict turns it into a failure
    assert main(["run", str(shot), "--until", "simulate", "--cache", str(cache), "-q", "--strict"]) == 1
    assert "frame 3" in capsys.readouterr().err


def _advice(err: str) -> list[str]:
    """The `--set KEY=VALUE` suggestions in an error message."""
    import re
    return re.findall(r"--set (\S+=[^\s;,)]+)", err)


@pytest.mark.parametrize("setting", ["solver.dt_min=0.005", "solver.max_substeps_per_frame=3"])
def test_advice_names_shot_keys_and_following_it_helps(tmp_path, capsys, setting):
    shot = write_tiny_shot(tmp_path, frame_end=2)
    args = ["run", str(shot), "--until", "simulate", "--cache", str(tmp_path / "c"), "-q", "--set", setting]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "SolverConfig" not in err and "lower solver.cfl" not in err.lower()
    advice = _advice(err)
    assert advice and advice[0].split("=")[0] == setting.split("=")[0], err
    assert main([*args, "--set", advice[0]]) == 0, capsys.readouterr().err
