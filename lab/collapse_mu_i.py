"""What a rate-dependent friction, mu(I), would do to a column collapse's runout: a bound.

mu(I) (Jop, Forterre & Pouliquen 2006; in MPM, Dunatunga & Kamrin 2015) raises the friction
with the inertial number I = shear rate x grain diameter / sqrt(pressure / grain density):
mu(I) = mu_s + (mu_2 - mu_s) I / (I0 + I) >= mu_s everywhere. The solver's friction is rate
independent (the `repose` fit, mu = tan(friction_angle)), so this probe brackets mu(I) with
constant frictions: for each I, the friction angle atan(mu(I)) with mu_s = tan(--phi), and the
runout of a quasi-2D collapse (mpmfx.bench.experiments.column_collapse, Lube et al. 2005's law)
run at that angle. Every point of a mu(I) flow is at least as strong as the I = 0 row and
at most as strong as the largest I's, so its runout lies between those rows. I estimates for
a laboratory column (grain d = 0.5 mm, H0 = 0.2 m): about 0.005 in the bulk (shear rate
sqrt(g / H0) under half the column's weight), up to about 1 in the thin fast front.

    python lab/collapse_mu_i.py [--device cpu] [--grid 40] [--a 0.5] [--phi 30] [--I 0 0.1 0.3 1]

One table; mu_2 - mu_s = 0.26 and I0 = 0.279 are Jop et al.'s glass-bead constants.
"""

import argparse
import math

from mpmfx.bench import experiments as ex
from mpmfx.bench.report import print_table
from mpmfx.mpm import preset

DMU, I0 = 0.26, 0.279  # mu_2 - mu_s, I0: Jop, Forterre & Pouliquen 2006 (glass beads)


def friction_angle(phi_s: float, inertial: float) -> float:
    """atan(mu(I)) in degrees for mu_s = tan(phi_s)."""
    mu = math.tan(math.radians(phi_s)) + DMU * inertial / (I0 + inertial)
    return math.degrees(math.atan(mu))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--grid", type=int, default=40)
    p.add_argument("--a", type=float, default=0.5, help="aspect ratio H0 / L0")
    p.add_argument("--phi", type=float, default=30.0, help="static friction angle, degrees")
    p.add_argument("--I", type=float, nargs="+", default=[0.0, 0.1, 0.3, 1.0], help="inertial numbers")
    args = p.parse_args()
    rows = []
    for inertial in args.I:
        phi = friction_angle(args.phi, inertial)
        mat = preset("Granular", friction_angle=phi)
        r = ex.column_collapse(a=args.a, grid_n=args.grid, material=mat, ppz=1, device=args.device)
        e = r.extra
        rows.append(
            {
                "I": inertial,
                "friction_angle": round(phi, 2),
                "cells_across": round(e["cells_across"], 1),
                "runout": e["runout"],
                "law_runout": e["law_runout"],
                "runout_error": e["runout"] / e["law_runout"] - 1.0,
                "runout_q": e["runout_q"],  # not quantised to cells: compares the rows
                "height": e["height"],
                "wall_s": round(r.wall_s, 1),
                "device": r.device,
            }
        )
    print_table(rows)


if __name__ == "__main__":
    main()
