"""Solver knobs: what the solver owns, as opposed to the material table (docs/physics.md)."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from mpmfx.mpm.slots import WallCode

__all__ = ["WallType", "OutOfDomain", "SolverConfig", "SolverConfigError", "STANDARD_GRAVITY"]

STANDARD_GRAVITY = 9.81  # m/s^2; in domain units it is this over the domain's edge in metres


class SolverConfigError(ValueError):
    """A SolverConfig field out of range; `field` names it so a shot file can name its key."""

    def __init__(self, field: str, what: str):
        super().__init__(f"SolverConfig.{field}: {what}")
        self.field, self.what = field, what


class WallType(enum.Enum):
    """Boundary condition on one face of the domain box."""

    STICKY = "sticky"  # grid velocity set to zero: material glues to the wall
    SLIP = "slip"  # normal velocity zeroed both ways; tangential kept (minus friction)
    SEPARATE = "separate"  # normal velocity zeroed only when moving into the wall

    @property
    def code(self) -> int:
        """The grid update's integer code for this wall (slots.WallCode, same name)."""
        return int(WallCode[self.name])


class OutOfDomain(enum.Enum):
    """What happens to a particle that reaches the last grid cell of the domain."""

    CLAMP = "clamp"  # position clamped into the domain; the particle stays
    REMOVE = "remove"  # particle deactivated (alive = 0), counted in particles_lost


@dataclass(frozen=True)
class SolverConfig:
    """Solver parameters. Everything is in domain units (box [0,1]^3) and seconds.

    These defaults are the product's only solver defaults: the shot schema
    (`mpmfx.config.Solver`) takes its defaults from here, so the Python API and a shot file
    that leaves a field unset run the same physics (gravity: a 1 m domain's, see below).

    Attributes:
        grid_n: cells per axis; dx = 1 / grid_n. Sets feature size, interaction range and
            the time-step ceiling: changing it changes the material.
        cfl: CFL number; dt = cfl * dx / (c_max + |v|_max), usually 0.3-0.5 (docs/physics.md,
            "The method").
        gravity: (3,) domain/s^2; the default is standard gravity for a 1 m domain (a shot
            gives m/s^2 and the stage divides by the domain's size). A balance knob (mound vs
            pancake), not a speed knob: time_scale is the speed knob.
        damping: 1/s velocity decay rate, applied per substep as v *= 1 - damping * dt
            so its effect per second does not depend on dt. Without it an elastic body rings on.
        drag: 1/s rate at which the affine velocity C is blended toward PIC,
            C *= 1 - drag * dt. A rate, never a per-substep fraction (one would depend on dt):
            it damps sub-cell rotation and noise, not bulk motion.
        flip: FLIP share of the particle velocity update, in [0, 1]: the particle keeps
            flip * (v_p + grid velocity change) + (1 - flip) * grid velocity, with the APIC
            affine velocity C kept (Fei et al. 2021; docs/physics.md, "The method"). 0 is APIC
            alone; higher keeps more of the particle's own motion (less numerical damping,
            more noise). Compiled only into scenes that set it.
        time_scale: simulated seconds per shot second (playback speed).
            `Solver.advance(t0, t1)` simulates (t1 - t0) * time_scale seconds.
            Collider keyframes stay on the shot clock.
        walls: 6 WallTypes for the faces -x, +x, -y, +y, -z, +z.
        wall_friction: Coulomb coefficient mu at the walls: tangential speed drops by
            mu * |removed normal speed|, an impulse ratio independent of dt (a fraction
            kept per substep would make creep on a slope depend on dt).
        wall_layer: domain units (>= 0): the boundary layer over which a wall's friction acts, a
            modelling choice (default 0.02: 2 cm in a 1 m domain). The Coulomb impulse, mu times
            the normal impulse the wall takes at a column of nodes, is shared over the column's
            nodes within this distance of the plane (more to those nearer), so the friction a
            wall applies is the same on any grid, for water too (docs/physics.md, "Boundaries").
            0: it acts at the nodes on the plane and beyond only, whose layer of water thins as
            the grid refines.
        boundary_cells: how far inside each face of the domain its wall's plane lies, in cells
            (`wall_planes`). The nodes between the face and the plane are a guard that keeps the
            3-node stencil on the grid (>= 2).
        dt_max, dt_min: bounds on the substep, seconds. A substep that has to go below
            dt_min raises SimulationError.
        max_substeps_per_frame: SimulationError past this many substeps in one advance().
        deterministic: P2G in fixed-point integer atomics so a replay (or a resume from a
            checkpoint) is bit-identical on the same device; see `mpmfx.mpm.p2g`
            for range and resolution. A GPU's brick P2G rounds each run of particles' sums,
            the CPU's reference P2G each particle's, so CPU and GPU runs differ in the last bits.
        multi_field: one velocity field per body (Particles.body), so separate bodies collide
            and part instead of fusing (docs/physics.md, "Boundaries"); costs one grid per body (at most 8).
        contact_friction: Coulomb mu between bodies in multi-field mode.
        out_of_domain: OutOfDomain (or its string value).
    """

    grid_n: int = 64
    cfl: float = 0.4
    gravity: tuple[float, float, float] = (0.0, -STANDARD_GRAVITY, 0.0)
    damping: float = 0.0
    drag: float = 0.0
    flip: float = 0.0
    time_scale: float = 1.0
    walls: tuple[WallType, ...] = (WallType.SEPARATE,) * 6
    wall_friction: float = 0.3
    wall_layer: float = 0.02
    boundary_cells: int = 3
    dt_max: float = 1e-2
    dt_min: float = 1e-7
    max_substeps_per_frame: int = 20000
    deterministic: bool = True
    multi_field: bool = False
    contact_friction: float = 0.2
    out_of_domain: OutOfDomain | str = OutOfDomain.CLAMP

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        try:
            set_("out_of_domain", OutOfDomain(self.out_of_domain))
        except ValueError:
            raise SolverConfigError(
                "out_of_domain", f"{self.out_of_domain!r}: use {' or '.join(repr(o.value) for o in OutOfDomain)}"
            ) from None
        walls = tuple(self.walls)
        if len(walls) != 6:
            raise SolverConfigError("walls", f"{len(walls)} entries; give 6 (-x, +x, -y, +y, -z, +z)")
        try:
            set_("walls", tuple(WallType(w) for w in walls))
        except ValueError as err:
            raise SolverConfigError("walls", f"{err}; use {', '.join(w.value for w in WallType)}") from None
        gravity = tuple(float(g) for g in self.gravity)
        if len(gravity) != 3 or not all(math.isfinite(g) for g in gravity):
            raise SolverConfigError("gravity", f"{self.gravity!r}: give 3 finite numbers")
        set_("gravity", gravity)
        for name in (
            "cfl",
            "damping",
            "drag",
            "flip",
            "time_scale",
            "wall_friction",
            "wall_layer",
            "contact_friction",
            "dt_max",
            "dt_min",
        ):
            if not math.isfinite(getattr(self, name)):
                raise SolverConfigError(name, f"{getattr(self, name)!r}: give a finite number")
        checks = [
            ("grid_n", 8 <= self.grid_n <= 4096, "must be in [8, 4096]"),
            (
                "cfl",
                0 < self.cfl <= 1.0,
                "must be in (0, 1]: above 1 a particle outruns the grid "
                "and elastic energy grows without any non-finite value to catch; 0.3-0.5 is usual",
            ),
            ("damping", self.damping >= 0, "must be >= 0 (a rate, 1/s)"),
            ("drag", self.drag >= 0, "must be >= 0 (a rate, 1/s)"),
            ("flip", 0 <= self.flip <= 1, "must be in [0, 1] (0: APIC; 0.9-0.99: FLIP blends)"),
            ("time_scale", self.time_scale > 0, "must be > 0"),
            ("wall_friction", self.wall_friction >= 0, "must be >= 0"),
            ("wall_layer", self.wall_layer >= 0, "must be >= 0 (a length; 0: friction at the wall's nodes only)"),
            ("contact_friction", self.contact_friction >= 0, "must be >= 0"),
            ("boundary_cells", 2 <= self.boundary_cells < self.grid_n // 2, "must be >= 2 and < grid_n / 2"),
            ("dt_min", 0 < self.dt_min <= self.dt_max, f"must be > 0 and not above dt_max ({self.dt_max})"),
            ("max_substeps_per_frame", self.max_substeps_per_frame >= 1, "must be >= 1"),
        ]
        for name, ok, what in checks:
            if not ok:
                raise SolverConfigError(name, f"{getattr(self, name)!r} {what}")

    @property
    def dx(self) -> float:
        """Cell width, domain units."""
        return 1.0 / self.grid_n

    @property
    def wall_planes(self) -> tuple[float, float]:
        """(lo, hi), domain units: the walls are the planes x = lo and x = hi on every axis
        (the floor is y = lo). Material rests on them; shots place material and renders draw
        the ground and the tank here."""
        inset = self.boundary_cells / self.grid_n
        return inset, 1.0 - inset
