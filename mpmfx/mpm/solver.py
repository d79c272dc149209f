"""The MLS-MPM solver: model (materials, colliders, grid), state, and the adaptive stepper.

`Solver.step` is the four-phase loop of docs/physics.md ("The method"), one phase per file:

    clear grid -> P2G -> grid update -> G2P

`Solver.advance` owns the clock, the wall-clock-to-substep accounting:
dt = cfl * dx / (c_max + |v|max) from the current hardened moduli, a substep
that produces non-finite values or moves a particle more than a cell is rejected and redone
at half dt, and the substeps land exactly on the requested time.
"""

from __future__ import annotations

import math
import time
from typing import Sequence

import numpy as np
import warp as wp

from . import animated as animated_mod
from . import readback
from .animated import AnimatedMesh, AnimatedMeshes
from .bricks import BRICK
from .chunked import DeviceAdvance
from .clear_grid import clear_grid
from .colliders import Collider, ColliderParams, concat_sdfs, pack_colliders
from .config import OutOfDomain, SolverConfig
from .constitutive import MaterialParams, pack_material, vec5
from .emission import activate
from .energy import make_report
from .errors import SimulationError, raise_too_small, too_many
from .g2p import G2PParams, g2p_launch_shape, make_g2p, solid_stress
from .grid_update import GridParams, make_grid_update
from .materials import Material, Mode
from .order import to_slots
from .p2g import FIXED_POINT_BITS, P2GParams, make_p2g
from .particles import Particles, check_particles
from .report import StepReport, particle_sums, step_report
from .slots import REJECTING, Count, Stat
from .state import ParticleBuffers, SceneFlags, State, StepperClock, m33_assign
from .stepper import SubstepDev
from .variation import DENSITY, state_factors

__all__ = ["Particles", "Solver", "StepReport", "SimulationError"]

MAX_FIELDS = 8  # multi-field contact: grid memory grows with the number of fields


def _pow2_at_least(x: float) -> float:
    return 2.0 ** math.ceil(math.log2(max(x, 1e-30)))


class Solver:
    """Explicit MLS-MPM on a dense grid in the domain [0, 1]^3.

    materials: the material table; particles index into it. config: solver knobs.
    colliders: kinematic Colliders; animated: AnimatedMeshes. device: Warp device ("cpu", "cuda:0"; None = default).
    stepper: "device" runs `advance` in chunks of substeps decided and colliders posed on the
    device (stepper.py), "host" the reference loop that reads the
    statistics back after every substep; both give the same substeps and results.
    variation: particles carry multipliers of their material's fields (Particles.variation);
    the kernels read them only then (SceneFlags.varied).
    """

    def __init__(
        self,
        materials: Sequence[Material],
        config: SolverConfig,
        *,
        colliders: Sequence[Collider] = (),
        animated: Sequence[AnimatedMesh] = (),
        device: str | None = None,
        stepper: str = "device",
        variation: bool = False,
    ):
        self.materials = tuple(materials)
        if not self.materials:
            raise ValueError("Solver: materials is empty; give at least one Material")
        for i, m in enumerate(self.materials):
            if not isinstance(m, Material):
                raise ValueError(f"Solver: materials[{i}] is {type(m).__name__}, not a Material")
        self.config = config
        self.colliders = tuple(colliders)
        self.device = wp.get_device(device)
        self.flags = SceneFlags.of(self.materials, multi_field=config.multi_field, varied=variation, flip=config.flip)
        self._wave_materials = self.materials  # the CFL's materials: the stiffest particle's moduli (variation.py)
        # specialised kernels for this scene: all three land in one Warp module per flags,
        # built before the first launch so the module compiles once
        # [device_clock]: the reference kernels, and the device stepper's (stepper.py)
        self._kernels = {
            dc: (
                make_p2g(self.flags, device_clock=dc),
                make_g2p(self.flags, device_clock=dc),
                make_grid_update(device_clock=dc, meshes=animated_mod.INSIDE_TEST if animated else ""),
            )
            for dc in (False, True)
        }
        if stepper not in ("device", "host"):
            raise ValueError(f"Solver: stepper={stepper!r}; use 'device' (default) or 'host' (the reference loop)")
        self.stepper = stepper
        self._report_partials = make_report(self.flags)
        self._n_fields = 0
        self._grid_writer = None  # the brick P2G that wrote the grid last (its marks are valid), if one did
        self._grid_cleared = False  # whether the last grid update zeroed the nodes it read (_phases)
        self._allocate_grid(1)
        with wp.ScopedDevice(self.device):
            self._materials_dev = wp.array([pack_material(m) for m in self.materials], dtype=MaterialParams)
            self._sdf = wp.array(concat_sdfs(self.colliders), dtype=float)
            self._colliders_dev = wp.empty(max(1, len(self.colliders)), dtype=ColliderParams)
            self._stats = wp.zeros(len(Stat), dtype=float)
            self._counts = wp.zeros(Count.size(len(self.materials)), dtype=wp.int32)
            self._stats_init = wp.array(np.array(Stat.initial(), np.float32), dtype=float)
            self._sub = wp.zeros(1, dtype=SubstepDev)
        self._meshes = AnimatedMeshes(animated, self.device, config.dx) if animated else None  # posed every substep
        self._q_mass = 1.0
        self._q_mom = 1.0
        self._last_bad = None  # counts of the last rejected substep, for error messages
        self._device_advance = DeviceAdvance(self)

    # ------------------------------------------------------------------ setup
    def _allocate_grid(self, n_fields: int) -> None:
        """Dense grid, one block of nodes per velocity field along the first axis
        (allocated when a state with a new field count is built, never per step)."""
        if n_fields == self._n_fields:
            return
        self._n_fields = n_fields
        self._grid_writer = None
        nn = self.config.grid_n + 1  # nodes at i * dx, i = 0..grid_n
        det, multi = self.config.deterministic, self.flags.multi_field
        full = (n_fields * nn, nn, nn)
        with wp.ScopedDevice(self.device):
            self._grid_m = wp.zeros(full if not det else (1, 1, 1), dtype=float)
            self._grid_mv = wp.zeros(full if not det else (1, 1, 1), dtype=wp.vec3)
            self._grid_normal = wp.zeros(full if multi and not det else (1, 1, 1), dtype=wp.vec3)
            channels = self.flags.fixed_channels
            self._grid_fixed = wp.zeros(full + (channels,) if det else (1, 1, 1, channels), dtype=wp.int64)
            # FLIP: the momentum without the stress (p2g.py), in fixed point in grid_fixed
            self._grid_mv0 = wp.zeros(full if self.flags.flip > 0.0 and not det else (1, 1, 1), dtype=wp.vec3)
            self._grid_v = wp.zeros(full, dtype=wp.vec3)

    def _field_ids(self, body: np.ndarray) -> tuple[np.ndarray, int]:
        """Velocity field of each particle: its body's rank in multi-field mode, else 0."""
        if not self.config.multi_field:
            return np.zeros(len(body), np.int32), 1
        bodies, ids = np.unique(body, return_inverse=True)
        if len(bodies) > MAX_FIELDS:
            raise ValueError(
                f"Particles.body: {len(bodies)} distinct bodies, but multi-field contact keeps at most "
                f"{MAX_FIELDS} velocity fields; give bodies that never touch the same id, or set "
                "SolverConfig.multi_field=False"
            )
        return ids.astype(np.int32), len(bodies)

    def init_state(self, particles: Particles) -> State:
        """Upload particles; F = I, C = 0, J = Jp = 1, alive = 1 (0: dormant until its birth)."""
        n = check_particles(particles, len(self.materials), varied=self.flags.varied)
        mat_idx = np.asarray(particles.material, dtype=np.int32)
        density = np.array([m.density for m in self.materials], dtype=np.float64)
        tracer = np.array([m.mode == Mode.TRACER for m in self.materials])
        volume = np.asarray(particles.volume, dtype=np.float32)
        rho = density[mat_idx]
        if self.flags.varied:  # the density multiplier acts on the mass alone
            rho = rho * np.asarray(particles.variation, np.float64)[:, DENSITY]
        mass = np.where(tracer[mat_idx], 0.0, volume * rho).astype(np.float32)
        data = {
            "x": np.asarray(particles.x, np.float32),
            "v": np.asarray(particles.v, np.float32),
            "C": np.zeros((n, 3, 3), np.float32),
            "F": np.tile(np.eye(3, dtype=np.float32), (n if self.flags.solid else 1, 1, 1)),
            "J": np.ones(n if self.flags.water else 1, np.float32),
            "Jp": np.where(np.array([m.mode == Mode.SAND for m in self.materials])[mat_idx], 0.0, 1.0),
            "alive": np.ones(n, np.int32),
            "mass": mass,
            "volume": volume,
            "material": mat_idx,
            "body": np.asarray(particles.body, np.int32),
        }
        speed = np.linalg.norm(data["v"], axis=1)
        if particles.birth is not None:  # dormant until their birth; born ones: birth +inf
            dormant = np.asarray(particles.birth, np.float32) > 0
            data["alive"] = (~dormant).astype(np.int32)
            data["birth"] = np.where(dormant, np.asarray(particles.birth, np.float32), np.float32(np.inf))
            speed = speed[~dormant] if (~dormant).any() else np.zeros(1)
        if self.flags.varied:
            data["variation"] = np.asarray(particles.variation, np.float32)
        clock = StepperClock(max_speed=float(speed.max()))
        state = self._build_state(data, clock)
        if self.flags.varied:  # the stiffest snow particle's waves, before G2P reports them
            state.clock.max_hardening = self._first_hardening
        return state

    def _build_state(self, data: dict, clock: StepperClock) -> State:
        """data: arrays in particle order, and `pid` (a checkpoint's: the slot order to restore)."""
        n = int(data["x"].shape[0])
        pid = np.asarray(data["pid"], np.int32) if "pid" in data else np.arange(n, dtype=np.int32)
        permuted = bool(np.any(pid != np.arange(n)))
        vary = state_factors(self, data)  # from the particle-order materials, before they move into slots
        if permuted:  # back into the slots they were in, so a resumed run sums as the first did
            per_particle = (*ParticleBuffers.NAMES, "mass", "volume", "material", "body")
            data = {k: to_slots(np.asarray(v), pid, n) if k in per_particle else v for k, v in data.items()}
        field_id, n_fields = self._field_ids(np.asarray(data["body"]))
        self._allocate_grid(n_fields)
        with wp.ScopedDevice(self.device):
            cur = ParticleBuffers.allocate(n, self.flags, self.device)
            nxt = ParticleBuffers.allocate(n, self.flags, self.device)
            for name, arr in zip(ParticleBuffers.NAMES, cur.arrays()):
                if name in ParticleBuffers.MATRICES:
                    m33_assign(arr, data[name])
                elif name in data:
                    scalar = np.int32 if name == "alive" else np.float32
                    arr.assign(np.ascontiguousarray(data[name], dtype=scalar))
            state = State(
                n=n,
                cur=cur,
                nxt=nxt,
                mass=wp.array(np.asarray(data["mass"], np.float32), dtype=float),
                volume=wp.array(np.asarray(data["volume"], np.float32), dtype=float),
                material=wp.array(np.asarray(data["material"], np.int32), dtype=wp.int32),
                body=wp.array(np.asarray(data["body"], np.int32), dtype=wp.int32),
                field_id=wp.array(field_id, dtype=wp.int32),
                pid=wp.array(pid, dtype=wp.int32),
                n_fields=n_fields,
                clock=clock,
                permuted=permuted,
                vary=wp.array(vary, dtype=vec5),
                variation=np.asarray(data["variation"], np.float32) if self.flags.varied else None,
            )
            if "birth" in data:  # in particle order (State.birth)
                state.birth = wp.array(np.asarray(data["birth"], np.float32), dtype=wp.float32)
                state.birth_host = np.sort(np.asarray(data["birth"], np.float64))
        if "tau" not in data:  # a new state, or a version 1 checkpoint
            self.update_stress(state)
        m = np.asarray(data["mass"], np.float64)
        m_ref = float(m[m > 0].mean()) if np.any(m > 0) else 1.0
        # fixed-point quanta: powers of two (see p2g module docstring)
        self._q_mass = _pow2_at_least(m_ref) * 2.0**-FIXED_POINT_BITS
        self._q_mom = self._q_mass
        return state

    def update_stress(self, state: State) -> None:
        """Recompute the stored stress (state.cur.tau) of every solid from its F and Jp. G2P
        keeps it current; call this after writing F or Jp of `state.cur` directly."""
        if self.flags.solid:
            cur, varied = state.cur, int(self.flags.varied)
            inputs = [self._materials_dev, state.material, cur.F, cur.Jp, cur.tau, state.vary, state.pid, varied]
            wp.launch(solid_stress, dim=state.n, device=self.device, inputs=inputs)

    # ------------------------------------------------------------------ one substep
    def step(self, state: State, dt: float, *, t: float = 0.0) -> None:
        """ONE substep of dt seconds, committed unconditionally (no adaptivity; see
        `advance`). t: shot time of the substep start, s (poses the colliders)."""
        self._substep(state, dt, t, t + dt / self.config.time_scale)
        state.swap()
        state.clock.substeps += 1
        state.clock.last_dt = dt

    def _substep(self, state: State, dt: float, t0: float, t1: float) -> None:
        """clear grid -> P2G -> grid update -> G2P, writing state.nxt (state.cur intact)."""
        wp.copy(self._stats, self._stats_init)
        self._counts.zero_()
        if self.colliders:
            self._colliders_dev.assign(pack_colliders(self.colliders, t0, t1, dt))
        if self._meshes is not None:
            self._meshes.pose_host(t0, t1, dt)
        self._phases(state, state.cur, state.nxt, dt, device_clock=False, t=t0)

    def _phases(
        self,
        state: State,
        cur: ParticleBuffers,
        nxt: ParticleBuffers,
        dt: float,
        *,
        device_clock: bool,
        brick=None,
        resort: bool = False,
        chunk_start: bool = True,
        keep_grid: bool = False,
        t: float = 0.0,
    ) -> None:
        """Launch the four phases reading `cur`, writing `nxt`. device_clock: the kernels take
        dt (and the dt-dependent factors) from self._sub instead of `dt` (stepper.py);
        brick: a p2g_brick.BrickP2G to scatter with (device clock only), else the reference P2G;
        resort: the brick P2G re-sorts its particle order first; chunk_start: clear the whole
        grid even where the brick P2G's marks would allow a sparse clear; keep_grid: leave the
        scattered node masses and momenta in place for inspection (tests), where the brick
        path's grid update would zero them as it reads them; t: the substep's start, s on the
        shot clock (the host loop's; the device clock has its own), when dormant particles wake."""
        cfg = self.config
        inv_dx = float(cfg.grid_n)
        nn = cfg.grid_n + 1
        p2g, g2p, grid = self._kernels[device_clock]
        # 1 · clear: with the brick P2G, only the node bricks its last scatter marked, unless a
        # chunk starts (or another P2G wrote last): then all of it, once every ~32 substeps
        sparse = brick is not None and not chunk_start and self._grid_writer is brick
        if not (sparse and self._grid_cleared):  # else the last grid update zeroed what it read
            clear_grid(
                self._grid_m,
                self._grid_mv,
                self._grid_normal,
                self._grid_fixed,
                deterministic=cfg.deterministic,
                multi_field=self.flags.multi_field,
                marks=brick.marks if sparse else None,
            )
            if self.flags.flip > 0.0 and not cfg.deterministic:  # (the brick P2G has no FLIP: chunked.py)
                self._grid_mv0.zero_()
        if brick is not None:
            brick.marks.zero_()  # the scatter below marks what it writes
        self._grid_writer = brick
        if state.birth is not None:  # particles entering now (emission.py), before they scatter
            wp.launch(
                activate,
                dim=state.n,
                device=self.device,
                inputs=[
                    t,
                    int(device_clock),
                    cfg.time_scale,
                    self._device_advance.clk,
                    state.pid,
                    state.birth,
                    cur.alive,
                ],
            )
        # 2 · P2G
        pp = P2GParams()
        pp.inv_dx, pp.dt, pp.nodes = inv_dx, float(dt), nn
        pp.deterministic = int(cfg.deterministic)
        pp.q_mass_inv, pp.q_mom_inv = 1.0 / self._q_mass, 1.0 / self._q_mom
        permute = False
        if brick is not None:
            permute = brick.launch(
                pp,
                state,
                cur,
                self._materials_dev,
                self._grid_m,
                self._grid_mv,
                self._grid_fixed,
                self._sub,
                sort=resort,
            )
        else:
            wp.launch(
                p2g,
                dim=state.n,
                device=self.device,
                inputs=[
                    pp,
                    cur.x,
                    cur.v,
                    cur.C,
                    cur.tau,
                    cur.J,
                    cur.alive,
                    state.mass,
                    state.volume,
                    state.material,
                    state.field_id,
                    self._materials_dev,
                    self._grid_m,
                    self._grid_mv,
                    self._grid_normal,
                    self._grid_fixed,
                    self._sub,
                    self._grid_mv0,
                ],
            )
        # 3 · grid update (with the brick P2G: only the node bricks it marked)
        dim = (nn, nn, nn)
        # with the brick P2G the update zeroes what it read, the next substep's sparse clear,
        # unless G2P reads node masses (water volume recovery) or the walls' friction layer reads
        # other nodes' (a node zeroed while its column is read would race): the clear then costs
        # almost nothing
        layer = cfg.wall_layer > 0 and cfg.wall_friction > 0
        self._grid_cleared = brick is not None and not self.flags.volume_recovery and not keep_grid and not layer
        max_blocks = 0
        if brick is not None:
            grid = make_grid_update(
                device_clock=device_clock,
                sparse=True,
                clears=self._grid_cleared,
                meshes=animated_mod.INSIDE_TEST if self._meshes else "",
            )
            dim = brick.marks.shape[0] * BRICK**3
            # a grid-stride loop over a few blocks a multiprocessor: one thread per node brick slot
            # is ~69k short-lived blocks at grid 256, most of whose bricks are unmarked; 8 blocks a
            # multiprocessor is as fast as more, and faster than fewer
            max_blocks = 8 * self.device.sm_count if self.device.is_cuda else 0
        wp.launch(
            grid,
            dim=dim,
            device=self.device,
            max_blocks=max_blocks,
            inputs=[
                self._grid_params(dt, state.n_fields),
                self._grid_m,
                self._grid_mv,
                self._grid_normal,
                self._grid_fixed,
                self._colliders_dev,
                self._sdf,
                self._grid_v,
                self._counts,
                brick.marks if brick is not None else self._counts,
                self._sub,
                AnimatedMeshes.grid_argument(self._meshes),
            ],
        )
        # 4 · G2P
        gp = G2PParams()
        gp.dt, gp.inv_dx = float(dt), inv_dx
        gp.affine_keep = max(0.0, 1.0 - cfg.drag * dt)  # a rate, not a per-substep fraction
        gp.lo, gp.hi = 1.0 / cfg.grid_n, 1.0 - 1.0 / cfg.grid_n  # stencil stays on the grid
        gp.remove = int(cfg.out_of_domain == OutOfDomain.REMOVE)
        gp.nodes = nn
        gp.deterministic, gp.q_mass = int(cfg.deterministic), self._q_mass
        # a sorting substep stores the particles in the sort's order (State: storage order); the
        # other G2P takes the same arguments and leaves the order and the constants' outputs unread
        order, outs = state.pid, state.consts()
        if permute:
            g2p = make_g2p(self.flags, device_clock=device_clock, sorting=True)
            order, outs = brick.idx, state.spare_consts()
        wp.launch(
            g2p,
            dim=state.n,
            block_dim=g2p_launch_shape()[1],
            device=self.device,
            inputs=[
                gp,
                self._grid_v,
                self._grid_m,
                self._grid_fixed,
                self._materials_dev,
                state.material,
                state.field_id,
                *cur.arrays(),
                *nxt.arrays(),
                self._stats,
                self._counts,
                self._sub,
                order,
                state.mass,
                state.volume,
                state.body,
                state.pid,
                *outs,
                state.vary,
                self._grid_mv0,
            ],
        )
        if permute:
            state.swap_consts()
            state.permuted = True

    def _grid_params(self, dt: float, n_fields: int) -> GridParams:
        cfg = self.config
        gp = GridParams()
        gp.dt, gp.dx = float(dt), cfg.dx
        gp.gravity = wp.vec3(*cfg.gravity)
        gp.damping_factor = max(0.0, 1.0 - cfg.damping * dt)  # v *= 1 - damping*dt: a rate, so dt does not change it
        codes = [w.code for w in cfg.walls]
        gp.walls_lo = wp.vec3i(codes[0], codes[2], codes[4])
        gp.walls_hi = wp.vec3i(codes[1], codes[3], codes[5])
        gp.wall_friction = cfg.wall_friction
        gp.wall_layer = cfg.wall_layer
        gp.plane_lo, gp.plane_hi = cfg.wall_planes
        gp.deterministic = int(cfg.deterministic)
        gp.q_mass, gp.q_mom = self._q_mass, self._q_mom
        gp.num_colliders = len(self.colliders)
        gp.nodes, gp.n_fields = cfg.grid_n + 1, n_fields
        gp.contact_friction = cfg.contact_friction
        return gp

    # ------------------------------------------------------------------ stepper
    def wave_speed(self, clock: StepperClock) -> float:
        """c_max, domain/s, over the scene's materials at the current hardening / J."""
        return max(
            m.wave_speed(
                hardening_factor=max(1.0, clock.max_hardening) if m.mode == Mode.SNOW else 1.0, j_min=clock.water_j_min
            )
            for m in self._wave_materials
        )

    def _cfl_dt(self, clock: StepperClock) -> float:
        cfg = self.config
        c = self.wave_speed(clock) + clock.max_speed
        dt = cfg.dt_max if c <= 0 else min(cfg.dt_max, cfg.cfl * cfg.dx / c)
        return dt * clock.dt_scale

    def advance(self, state: State, t0: float, t1: float) -> StepReport:
        """Advance from shot time t0 to t1 (s), i.e. (t1 - t0) * time_scale simulated
        seconds, in adaptive substeps landing exactly on t1. Raises SimulationError when
        a substep would need dt < dt_min or the frame needs > max_substeps_per_frame."""
        if not t1 >= t0:
            raise ValueError(f"Solver.advance: t1 = {t1} must be >= t0 = {t0}")
        if self.stepper == "device":
            return self._device_advance.run(state, t0, t1)
        return self._advance_host(state, t0, t1)

    def _advance_host(self, state: State, t0: float, t1: float) -> StepReport:
        """The reference stepper: statistics read back after every substep."""
        cfg = self.config
        wall0 = time.perf_counter()
        self._last_bad = None
        total = (t1 - t0) * cfg.time_scale
        done, substeps, rejected = 0.0, 0, 0
        dts, cfl_used, vmax, jmin, jmax, lost, inverted = [], 0.0, 0.0, math.inf, -math.inf, 0, 0
        while done < total:
            remaining = total - done
            dt_cfl = self._cfl_dt(state.clock)
            if dt_cfl < cfg.dt_min:
                raise_too_small(self, state, t0 + done / cfg.time_scale, dt_cfl)
            if substeps >= cfg.max_substeps_per_frame:
                raise too_many(self, state, t0 + done / cfg.time_scale, t1, substeps, dt_cfl, total - done)
            last = remaining <= dt_cfl * (1.0 + 1e-6)
            dt = remaining if last else (0.5 * remaining if remaining < 2.0 * dt_cfl else dt_cfl)
            ts0 = t0 + done / cfg.time_scale
            ts1 = t1 if last else t0 + (done + dt) / cfg.time_scale
            self._substep(state, dt, ts0, ts1)
            stats = self._stats.numpy()
            counts = self._counts.numpy()
            if counts[list(REJECTING)].sum() > 0:
                rejected += 1
                state.clock.dt_scale *= 0.5  # redo at half dt (Ziran)
                self._last_bad = counts  # for the error message if dt runs out
                continue
            state.swap()
            done = total if last else done + dt
            substeps += 1
            clock = state.clock
            clock.substeps += 1
            clock.last_dt = dt
            clock.dt_scale = min(1.0, clock.dt_scale * 1.25)
            clock.max_speed = float(stats[Stat.MAX_SPEED])
            if self.flags.snow:
                clock.max_hardening = max(1.0, float(stats[Stat.MAX_HARDENING]))
            if self.flags.water:
                clock.water_j_min = min(1.0, float(stats[Stat.WATER_J_MIN]))
            dts.append(dt)
            c = self.wave_speed(clock) + clock.max_speed
            cfl_used = max(cfl_used, dt * c / cfg.dx)
            vmax = max(vmax, clock.max_speed)
            if stats[Stat.J_MIN] <= stats[Stat.J_MAX]:
                jmin = min(jmin, float(stats[Stat.J_MIN]))
                jmax = max(jmax, float(stats[Stat.J_MAX]))
            lost += int(counts[Count.LOST])
            inverted += int(counts[Count.INVERTED])
        report = step_report(self, state, substeps, rejected, dts, vmax, cfl_used, lost, jmin, jmax, wall0)
        report.inverted = inverted
        return report

    def report_sums(self, state: State) -> np.ndarray:
        """(6,) float64: mass, momentum (3), twice the kinetic energy, elastic energy (report.particle_sums)."""
        return particle_sums(self, state)

    def elastic_energy(self, state: State) -> float:
        """Energy stored in the particles' elastic state, mass*domain^2/s^2 (same units as
        kinetic energy): sum of rest volume * energy density, with the hardened moduli of
        snow, Hencky StVK for sand, the Tait potential for water, 0 for tracers. `advance`
        reports it once per frame, with the other sums of `report_sums`."""
        return float(self.report_sums(state)[5])

    # ------------------------------------------------------------------ I/O
    def state_to_numpy(self, state: State) -> dict[str, np.ndarray]:
        """Host copy of the particles, in particle order (readback.state_to_numpy)."""
        return readback.state_to_numpy(self, state)

    def host_arrays(self, state: State, names=None, staging=None) -> dict[str, np.ndarray]:
        """Host copies of the particle arrays as stored (readback.host_arrays; staging: a
        readback.HostStaging whose buffers they land in)."""
        return readback.host_arrays(self, state, names, staging)

    def volume_ratios(self, state: State) -> np.ndarray:
        """J (n,) float32 in particle order, computed on the device (readback.volume_ratios)."""
        return readback.volume_ratios(self, state)

    def checkpoint(self, state: State, t: float, staging=None) -> dict[str, np.ndarray]:
        """Full state and stepper clock at shot time t, s, as numpy arrays (readback.checkpoint;
        staging: a readback.HostStaging whose buffers they land in)."""
        return readback.checkpoint(self, state, t, staging)

    def restore(self, data: dict[str, np.ndarray]) -> tuple[State, float]:
        """State and shot time t from `checkpoint` output (readback.restore)."""
        return readback.restore(self, data)
