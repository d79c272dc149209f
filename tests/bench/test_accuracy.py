"""Quick accuracy checks against the references of docs/physics.md, "Validation" (tiny sizes, CPU)."""

from __future__ import annotations

import dataclasses

import numpy as np

from mpmfx.bench import accuracy, cases
from mpmfx.bench.snow_table import snow_compression


def test_free_fall_follows_exact_discrete_trajectory():
    # the discrete trajectory is exact: float32 round-off (~1e-6 relative)
    r = cases.free_fall(grid_n=16)
    assert r.error < 1e-5, r.row()
    assert r.extra["F_minus_I"] < 1e-5  # an unstressed body stays unstrained


def test_standing_wave_converges_at_second_order_in_space():
    rs = [cases.standing_wave(grid_n=n) for n in (16, 32)]
    errs = [r.error for r in rs]
    # measured 0.045 and 0.0115 on a 2-core CPU; order 1.95
    assert errs[0] < 0.06 and errs[1] < 0.02, errs
    order = accuracy.observed_order([1 / 16, 1 / 32], errs)[0]
    assert order > 1.5, order


def test_apic_keeps_angular_momentum_pic_loses_it():
    apic = cases.rigid_rotation(grid_n=16, revolutions=0.25)
    pic = cases.rigid_rotation(grid_n=16, revolutions=0.25, pic=True)
    assert apic.error < 1e-3 < pic.error, (apic.error, pic.error)


def test_snow_return_map_matches_table():
    row = snow_compression()
    assert row["error"] < 0.01, row["table"]  # the derived table, within 1 %


def test_plot_and_tables_are_written(tmp_path):
    rows = [cases.free_fall(grid_n=16).row(), cases.standing_wave(grid_n=16).row()]
    import imageio.v3 as iio

    from mpmfx.bench.plot import speed_error_plot

    png = speed_error_plot(rows, tmp_path)
    img = iio.imread(png)
    assert img.shape[:2] == (700, 1000) and np.ptp(img) > 0  # not a blank image


def test_experiments_section_runs_and_reads_its_sources(tmp_path, monkeypatch):
    """The quick experiments section: every row finite, the data files' laws match the code's."""
    from mpmfx.bench import experiments as ex
    from mpmfx.bench import lab

    laws = {r["source"]: r for r in lab.read_csv("granular_collapse_laws.csv")}
    for name, law in ex.GRANULAR_LAWS.items():
        for k in ("l1", "l2", "a0", "h_a0", "h2"):
            assert laws[name][k] == law[k], (name, k)
    refs = lab.water_references()
    assert set(refs) == {"martin_moyce_1952_a1.125in", "martin_moyce_1952_a2.25in", "koshizuka_oka_1996"}
    monkeypatch.setattr(lab, "QUICK", dataclasses.replace(lab.QUICK, pile_grids=(16,)))  # grid 32 takes ~40 s here
    rows = accuracy.experiments(quick=True, device=None, out=tmp_path)
    assert rows and all(np.isfinite(r["error"]) for r in rows), rows
    assert (tmp_path / "experiments.csv").exists() and (tmp_path / "experiments_trend.csv").exists()
    # inviscid water on a frictionless floor runs ahead of every experiment, never behind
    dam = [r for r in rows if r["case"] == "dam_break frictionless"]
    assert all(r["error"] > -0.1 for r in dam), dam
