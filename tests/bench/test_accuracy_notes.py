"""An order far from 2 in `bench accuracy` comes with the reason."""

from types import SimpleNamespace as NS

from mpmfx.bench.accuracy import _order_rows


def test_orders_that_are_not_convergence_say_why():
    res = [NS(case="hydrostatic", grid_n=n, error=e) for n, e in ((32, 0.030), (64, 0.0285))]
    res += [NS(case="standing_wave", grid_n=n, error=e) for n, e in ((32, 4e-3), (64, 1e-3))]
    t_runs = [NS(cfl=c, extra={"dt": d}) for c, d in ((0.2, 1e-3), (0.4, 2e-3))]
    rows = _order_rows(res, t_runs, [1.0e-3, 1.01e-3])
    why = {(r["case"], r["in"]): r.get("why", "") for r in rows}
    assert "quadrature" in why[("hydrostatic", "space")]
    assert "spatial" in why[("standing_wave", "time")]
    assert why[("standing_wave", "space")] == ""  # a clean second order needs no note
