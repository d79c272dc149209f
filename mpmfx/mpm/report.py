"""What one `Solver.advance` reports (StepReport), and the sums over the particles it reports,
summed on the device."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from .energy import ENERGY_CHUNK, SUMS
from .state import State
from .stepper import sum_partials

__all__ = ["StepReport"]


@dataclass
class StepReport:
    """What one `advance` did. Times in s, speeds domain/s, mass in density*domain^3.

    cfl_used: largest dt * (c_max + |v|max) / dx, with c and |v| measured at the end of
    each accepted substep (the CFL actually experienced); momentum: (3,);
    kinetic_energy, elastic_energy: at the end of the advance, mass*domain^2/s^2 (see
    `Solver.elastic_energy`); their sum is conserved by an undamped scene without walls;
    j_min, j_max: range of J (det F for solids, J for water) over the accepted substeps;
    j_min <= 0 when a particle inverted, even though it was mirrored back out;
    inverted: particle-substeps whose F inverted (det F <= 0) and was mirrored back out
    (see `constitutive.uninvert`); 0 in a healthy run.
    """

    substeps: int
    rejected_substeps: int
    dt_min: float
    dt_max: float
    max_speed: float
    cfl_used: float
    particles_lost: int
    mass: float
    momentum: np.ndarray
    kinetic_energy: float
    elastic_energy: float | None
    j_min: float
    j_max: float
    wall_time_s: float
    inverted: int = 0


def step_report(solver, state, substeps, rejected, dts, vmax, cfl_used, lost, jmin, jmax, wall0) -> StepReport:
    """The StepReport of an advance from its substeps' statistics (dts: the accepted dts, s; wall0:
    time.perf_counter() at its start) and the particle sums at its end."""
    sums = particle_sums(solver, state)
    return StepReport(
        substeps=substeps,
        rejected_substeps=rejected,
        dt_min=min(dts) if dts else 0.0,
        dt_max=max(dts) if dts else 0.0,
        max_speed=vmax,
        cfl_used=cfl_used,
        particles_lost=lost,
        mass=float(sums[0]),
        momentum=sums[1:4].copy(),
        kinetic_energy=float(0.5 * sums[4]),
        elastic_energy=float(sums[5]),
        j_min=jmin if dts else 1.0,
        j_max=jmax if dts else 1.0,
        wall_time_s=time.perf_counter() - wall0,
    )


def particle_sums(solver, state: State) -> np.ndarray:
    """(6,) float64 over the live particles, summed on the device in a fixed order (replays
    give the same bits; only a few partial sums come to the host): mass, momentum (3),
    mass * |v|^2 (twice the kinetic energy) and the elastic energy (`elastic_energy`)."""
    cur = state.cur
    part = wp.empty(((state.n + ENERGY_CHUNK - 1) // ENERGY_CHUNK, SUMS), dtype=wp.float64, device=solver.device)
    wp.launch(
        solver._report_partials,
        dim=part.shape[0],
        device=solver.device,
        inputs=[
            solver._materials_dev,
            state.material,
            state.mass,
            state.volume,
            cur.v,
            cur.F,
            cur.J,
            cur.Jp,
            cur.alive,
            state.n,
            int(solver.device.is_cuda),
            part,
            state.vary,
            state.pid,
        ],
    )
    return sum_partials(part, solver.device)
