"""Per-step solver state (particles, double-buffered) and the per-scene kernel flags."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from .constitutive import vec6
from .materials import Mode

__all__ = [
    "SceneFlags",
    "ParticleBuffers",
    "StepperClock",
    "State",
    "load_m33",
    "store_m33",
    "m33_to_host",
    "m33_assign",
]


@dataclass(frozen=True)
class SceneFlags:
    """Which constitutive branches a scene compiles (model only what the scene needs).

    A water-only scene compiles no SVD and keeps no F; a snow-only scene keeps no J;
    only a scene with water volume recovery compiles the grid-density gather; a scene of one
    material reads no particle's material index (it is 0), and one of one field no field index.
    varied: particles carry their own factors on their material's row (State.vary).
    flip: the FLIP share of the velocity update (SolverConfig.flip), a constant of the kernels;
    above 0, P2G also scatters the momentum without the stress and G2P gathers it back as the
    grid's velocity before the update (Solver: `_grid_mv0`).
    """

    snow: bool
    sand: bool
    water: bool
    multi_field: bool = False
    volume_recovery: bool = False
    one_material: bool = False
    varied: bool = False
    flip: float = 0.0

    @classmethod
    def of(cls, materials, *, multi_field: bool = False, varied: bool = False, flip: float = 0.0) -> "SceneFlags":
        modes = {m.mode for m in materials}
        recovery = any(m.mode == Mode.WATER and m.volume_recovery for m in materials)
        return cls(
            Mode.SNOW in modes,
            Mode.SAND in modes,
            Mode.WATER in modes,
            bool(multi_field),
            recovery,
            len(materials) == 1,
            bool(varied),
            float(flip),
        )

    @property
    def solid(self) -> bool:
        """Any material that carries a deformation gradient F."""
        return self.snow or self.sand

    @property
    def fixed_channels(self) -> int:
        """Fixed-point channels a grid node keeps in deterministic mode: mass, momentum (3),
        the mass gradient (3, multi-field), the momentum without the stress (3, FLIP)."""
        return 4 + 3 * self.multi_field + 3 * (self.flip > 0.0)

    @property
    def flip_channel(self) -> int:
        """First fixed-point channel of the momentum without the stress (FLIP scenes)."""
        return 4 + 3 * self.multi_field

    @property
    def key(self) -> str:
        """Prefix of the Warp modules holding this scene's specialised P2G and G2P kernels."""
        flags = (
            ("s", self.snow),
            ("g", self.sand),
            ("w", self.water),
            ("m", self.multi_field),
            ("r", self.volume_recovery),
            ("1", self.one_material),
            ("v", self.varied),
        )
        tag = "".join(c for c, on in flags if on)
        if self.flip > 0.0:
            tag += f"f{round(self.flip * 1e6)}"
        return f"mpmfx_mpm_scene_{tag or 'tracer'}"


# A matrix field (C, F) is stored as three planes of rows, a (3, n) vec3 array: row r of
# particle p at [r, p]. Why: three planes of 12-byte rows copy about three times faster on a
# GPU than an array of mat33 (36 bytes a particle), and G2P reads F and writes C and F every
# substep.


@wp.func
def load_m33(a: wp.array2d(dtype=wp.vec3), p: int) -> wp.mat33:
    """Particle p's matrix of a (3, n) row-plane array."""
    return wp.matrix_from_rows(a[0, p], a[1, p], a[2, p])


@wp.func
def store_m33(a: wp.array2d(dtype=wp.vec3), p: int, m: wp.mat33):
    """Write particle p's matrix into a (3, n) row-plane array."""
    a[0, p] = m[0]
    a[1, p] = m[1]
    a[2, p] = m[2]


def m33_to_host(a: wp.array) -> np.ndarray:
    """(n, 3, 3) float32 host copy of a (3, n) row-plane array."""
    return np.ascontiguousarray(a.numpy().transpose(1, 0, 2))


def m33_assign(a: wp.array, values) -> None:
    """Upload (n, 3, 3) matrices into a (3, n) row-plane array."""
    a.assign(np.ascontiguousarray(np.asarray(values, np.float32).transpose(1, 0, 2)))


@dataclass
class ParticleBuffers:
    """The particle fields that change every substep, on the device.

    x: (n,) vec3 domain units; v: (n,) vec3 domain/s; C: (3, n) row planes (load_m33) of
    the 1/s APIC affine velocity; F: (3, n) row planes of the elastic deformation gradient,
    or (3, 1) when no material needs it; J: (n,) float32 volume ratio of water particles, or (1,) without water;
    Jp: (n,) float32 plastic volume ratio (snow) or log-volume correction (sand);
    alive: (n,) int32, 0 once a particle left the domain in REMOVE mode;
    tau: (n,) vec6 Kirchhoff stress of a solid's F and Jp, mass/(domain s^2) (symmetric:
    xx, yy, zz, xy, xz, yz; written by G2P, read by P2G), or (1,) without solids.
    """

    x: wp.array
    v: wp.array
    C: wp.array
    F: wp.array
    J: wp.array
    Jp: wp.array
    alive: wp.array
    tau: wp.array

    NAMES = ("x", "v", "C", "F", "J", "Jp", "alive", "tau")
    MATRICES = ("C", "F")  # row planes: m33_to_host / m33_assign on the host

    @classmethod
    def allocate(cls, n: int, flags: SceneFlags, device) -> "ParticleBuffers":
        def arr(dtype, count=n):
            return wp.zeros(count, dtype=dtype, device=device)

        return cls(
            x=arr(wp.vec3),
            v=arr(wp.vec3),
            C=arr(wp.vec3, (3, n)),
            F=arr(wp.vec3, (3, n if flags.solid else 1)),
            J=arr(wp.float32, n if flags.water else 1),
            Jp=arr(wp.float32),
            alive=arr(wp.int32),
            tau=arr(vec6, n if flags.solid else 1),
        )

    def arrays(self):
        return [getattr(self, k) for k in self.NAMES]


@dataclass
class StepperClock:
    """What the adaptive stepper carries from one substep to the next.

    Checkpointed with the state so a resumed run picks exactly the same dt sequence.
    dt_scale: factor in (0, 1] on the CFL step, halved per rejected substep and regrown by
    1.25x per accepted one; max_speed: |v|max of the last accepted substep, domain/s;
    max_hardening: largest exp(xi (1 - Jp)) among snow particles (with variation, each times the
    particle's stiffness / density factor: variation.py); water_j_min: smallest
    J among water particles; substeps: accepted substeps since init_state; sort_every: the
    brick P2G's re-sort cadence the last advance ended with (0: none yet; chunked.py).
    """

    dt_scale: float = 1.0
    max_speed: float = 0.0
    max_hardening: float = 1.0
    water_j_min: float = 1.0
    last_dt: float = 0.0
    substeps: int = 0
    sort_every: int = 0

    FIELDS = ("dt_scale", "max_speed", "max_hardening", "water_j_min", "last_dt", "substeps", "sort_every")

    def to_array(self) -> np.ndarray:
        return np.array([float(getattr(self, k)) for k in self.FIELDS], dtype=np.float64)

    @classmethod
    def from_array(cls, a: np.ndarray) -> "StepperClock":
        vals = dict(zip(cls.FIELDS, (float(x) for x in a)))
        vals["substeps"] = int(vals["substeps"])
        vals["sort_every"] = int(vals.get("sort_every", 0))  # (absent in older checkpoints)
        return cls(**vals)


@dataclass
class State:
    """Everything that evolves: particle buffers (current + scratch for the next
    substep, swapped on acceptance so a rejected substep leaves `cur` untouched), the
    constant per-particle arrays and the stepper clock.

    mass: (n,) float32 (0 for tracers); volume: (n,) float32 rest volume, domain^3;
    material: (n,) int32 row in the solver's material table; body: (n,) int32 object id;
    field_id: (n,) int32 velocity field of the particle (0, or the body's field in multi-field
    mode); pid: (n,) int32 the particle (its index in init_state's Particles) each storage slot
    holds; n_fields: number of fields.

    Storage order: on a GPU the brick P2G keeps the particles themselves in its sort order (a
    sorting substep's G2P writes them there, p2g_brick.py), so every array above is in slot
    order, not particle order: `Solver.host_arrays` and `checkpoint` give them back in particle
    order (`birth`, where there is one, is indexed by particle). vary: (n,) vec5 material factors
    of a varied scene (SceneFlags.varied; variation.variation_factors), in particle order (read
    through pid), else (1,) unused; variation: its (n, 5) host multipliers (Particles.variation),
    which a checkpoint carries. The constants' other copy (`spare`, CONSTS order) is where a
    sorting G2P writes the
    permuted ones; `swap_consts` makes it current.
    """

    n: int
    cur: ParticleBuffers
    nxt: ParticleBuffers
    mass: wp.array
    volume: wp.array
    material: wp.array
    body: wp.array
    field_id: wp.array
    pid: wp.array
    n_fields: int = 1
    clock: StepperClock = field(default_factory=StepperClock)
    spare: tuple | None = None  # the constants' second copy (spare_consts)
    permuted: bool = False  # whether slots may differ from particles (pid not the identity)
    birth: wp.array | None = None  # (n,) float32 by particle: pending birth, s (emission.py), or None
    birth_host: np.ndarray | None = None  # the births sorted, float64 (which advances wake particles)
    vary: wp.array | None = None
    variation: np.ndarray | None = None

    CONSTS = ("mass", "volume", "material", "body", "field_id", "pid")

    def swap(self) -> None:
        self.cur, self.nxt = self.nxt, self.cur

    def consts(self) -> tuple:
        return tuple(getattr(self, k) for k in self.CONSTS)

    def spare_consts(self) -> tuple:
        """The constants' second copy, allocated at the first call (before a CUDA graph capture)."""
        if self.spare is None:
            self.spare = tuple(wp.empty_like(a) for a in self.consts())
        return self.spare

    def swap_consts(self) -> None:
        """Make the spare constants (a sorting G2P's output) current, and the current spare."""
        now = self.consts()
        for k, a in zip(self.CONSTS, self.spare):
            setattr(self, k, a)
        self.spare = now
