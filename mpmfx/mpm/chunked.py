"""`Solver.advance` in chunks of substeps decided on the device (see stepper.py for the rules).

The host uploads the clock once per advance, launches a chunk of substeps (one CUDA graph
on a GPU), reads the clock back once per chunk, and acts on its status: continue, retry
after a rejection (the chunk stopped at the rejected substep), finish, or raise the same
SimulationError as the reference loop (`Solver._advance_host`).
"""

from __future__ import annotations

import math
import time

import numpy as np
import warp as wp

from .bricks import fits_brick_keys, sort_cadence, travel_cadence
from .colliders import ColliderKeys, pack_colliders
from .emission import pending_between
from .errors import raise_too_small, too_many
from .p2g_brick import BrickP2G
from .report import step_report
from .slots import Clock, Count, Status
from .stepper import CHUNKS, StepperParams, WaveParams, make_clock_kernels, pose_colliders, wave_table

__all__ = ["DeviceAdvance"]


class DeviceAdvance:
    """The device stepper of one Solver (its grid, statistics and kernels)."""

    def __init__(self, solver):
        self.s = solver
        cfg = solver.config
        with wp.ScopedDevice(solver.device):
            self.clk = wp.zeros(len(Clock), dtype=wp.float64)
            self.last_bad = wp.zeros(Count.size(len(solver.materials)), dtype=wp.int32)
            self.waves = wp.array(wave_table(solver.materials), dtype=WaveParams)
        # where each chunk's clock (and the brick P2G's wear counts) land on the host: page-locked
        # on a GPU, so both copies queue behind the chunk and one wait reads them
        self._clk_host = wp.empty(len(Clock), dtype=wp.float64, device="cpu", pinned=solver.device.is_cuda)
        self._frag_host = None
        sp = StepperParams()
        sp.cfl, sp.dx, sp.dt_max, sp.dt_min = cfg.cfl, cfg.dx, cfg.dt_max, cfg.dt_min
        sp.damping, sp.drag = cfg.damping, cfg.drag
        sp.max_substeps = float(cfg.max_substeps_per_frame)
        sp.time_scale = cfg.time_scale
        sp.n_materials, sp.n_counts = len(solver.materials), Count.size(len(solver.materials))
        self.sp = sp
        self.begin, self.end = make_clock_kernels(solver.flags.snow, solver.flags.water)
        # keyframes on the device: the chunk poses the colliders itself (no host round trip)
        self.keys = ColliderKeys(solver.colliders, solver.device) if solver.colliders else None
        # capture chunks in CUDA graphs (off: launch each kernel; for measuring); an animated
        # collider's refit allocates scratch, which a capture allows only from a memory pool
        self.graphs = solver._meshes is None or not solver.device.is_cuda or wp.is_mempool_enabled(solver.device)
        # P2G: "brick" (p2g_brick.py) on a GPU, several times faster there than the reference;
        # "reference" (p2g.py) everywhere else: on the CPU a sorted P2G's extra passes cost
        # more than the atomics it saves, and multi-field
        # scenes scatter mass gradients the brick P2G does not, FLIP scenes (SolverConfig.flip)
        # the momentum without the stress; grids past ~1286 cells an axis
        # would overflow its int32 sort keys
        brick = not solver.flags.multi_field and solver.flags.flip == 0.0
        brick = brick and solver.device.is_cuda and fits_brick_keys(cfg.grid_n + 1)
        self.p2g = "brick" if brick else "reference"
        self._brick = None
        self.sort_every = 0  # 0: re-sort as the order wears (sort_cadence); k > 0: every k substeps (measuring)
        self.last_sort_every = CHUNKS[-1]  # what the last chunk did
        self._graphs: dict = {}
        self._graph_state = None  # the State the cached graphs point into (kept alive with them)
        self.frag_total = None  # the last advance's wear counts summed over its chunks (measuring)

    # ------------------------------------------------------------------ one chunk
    def _launch_chunk(self, state, k: int, every: int) -> None:
        s, dev = self.s, self.s.device
        bufs = (state.cur, state.nxt)
        for i in range(k):
            wp.launch(
                self.begin,
                dim=1,
                device=dev,
                inputs=[self.sp, self.waves, self.clk, s._sub, s._stats, s._stats_init, s._counts],
            )
            if self.keys is not None:
                k_ = self.keys
                wp.launch(
                    pose_colliders,
                    dim=k_.n,
                    device=dev,
                    inputs=[
                        self.sp,
                        self.clk,
                        k_.times,
                        k_.translations,
                        k_.rotations,
                        k_.offsets,
                        k_.counts,
                        s._colliders_dev,
                    ],
                )
            if s._meshes is not None:  # the interpolation weight from the device clock; refit
                s._meshes.pose_device(self.sp, self.clk)
            s._phases(
                state,
                bufs[i % 2],
                bufs[1 - i % 2],
                0.0,
                device_clock=True,
                brick=self._brick if self.p2g == "brick" else None,
                chunk_start=i == 0,
                resort=i % every == 0,
            )
            wp.launch(
                self.end,
                dim=1,
                device=dev,
                inputs=[self.sp, self.waves, self.clk, s._sub, s._stats, s._counts, self.last_bad],
            )

    def _chunk(self, state, k: int, every: int) -> None:
        """k substeps starting from state.cur, the brick P2G re-sorting every `every` (and at
        the first); on CUDA replayed from a captured graph."""
        if not (self.s.device.is_cuda and self.graphs):
            self._launch_chunk(state, k, every)
            return
        if self._graph_state is not state:
            self._graphs.clear()
            self._graph_state = state
        key = (
            k,
            id(state.cur),
            id(state.mass),
            self.s._grid_v.ptr,
            state.n_fields,
            self.s._q_mass,
            self.p2g,
            id(self._brick),
            every,
        )
        graph = self._graphs.get(key)
        if graph is None:
            with wp.ScopedCapture(device=self.s.device) as cap:
                self._launch_chunk(state, k, every)
            graph = self._graphs[key] = cap.graph
        wp.capture_launch(graph)

    # ------------------------------------------------------------------ advance
    def _upload(self, state, t0: float, t1: float) -> np.ndarray:
        ck = state.clock
        total = (t1 - t0) * self.s.config.time_scale
        c = np.zeros(len(Clock), np.float64)
        c[Clock.TOTAL] = total
        c[Clock.T0], c[Clock.T1] = t0, t1
        c[Clock.DT_SCALE], c[Clock.MAX_SPEED] = ck.dt_scale, ck.max_speed
        c[Clock.MAX_HARDENING], c[Clock.WATER_J_MIN] = ck.max_hardening, ck.water_j_min
        c[Clock.LAST_DT], c[Clock.SUBSTEPS] = ck.last_dt, ck.substeps
        c[Clock.DT_MIN], c[Clock.DT_MAX] = math.inf, -math.inf
        c[Clock.J_MIN], c[Clock.J_MAX] = math.inf, -math.inf
        c[Clock.STATUS] = Status.RUNNING if 0.0 < total else Status.FINISHED
        self.clk.assign(c)
        return c

    def _read_back(self):
        """After a chunk: (the clock, the brick P2G's wear counts or None), in one wait for the
        device (two read-backs would be two waits); the wear counters are zeroed for the next
        chunk."""
        wp.copy(self._clk_host, self.clk)
        if self._brick is not None:
            if self._frag_host is None:
                self._frag_host = wp.empty_like(self._brick.frag, device="cpu", pinned=self.s.device.is_cuda)
            wp.copy(self._frag_host, self._brick.frag)
            self._brick.frag.zero_()
        wp.synchronize_device(self.s.device)
        frag = self._frag_host.numpy().copy() if self._brick is not None else None
        return self._clk_host.numpy().copy(), frag

    @staticmethod
    def _to_clock(state, c: np.ndarray) -> None:
        ck = state.clock
        ck.dt_scale, ck.max_speed = float(c[Clock.DT_SCALE]), float(c[Clock.MAX_SPEED])
        ck.max_hardening, ck.water_j_min = float(c[Clock.MAX_HARDENING]), float(c[Clock.WATER_J_MIN])
        ck.last_dt, ck.substeps = float(c[Clock.LAST_DT]), int(c[Clock.SUBSTEPS])

    def _chunk_length(self, c: np.ndarray, dt_guess: float) -> int:
        """Substeps to launch next: the largest chunk length that the rest of the advance
        fills at the last dt (so no substep is launched only to do nothing, and the few
        lengths each have one graph captured once), at least 1."""
        remaining = c[Clock.TOTAL] - c[Clock.DONE]
        dt = c[Clock.DT_CFL] if c[Clock.DT_CFL] > 0 else dt_guess
        want = math.ceil(remaining / dt) if dt > 0 else CHUNKS[-1]
        return max((k for k in CHUNKS if k <= want), default=CHUNKS[0])

    def _sort_every(self, state, c: np.ndarray, dt_guess: float, frag) -> int:
        """The next chunk's substeps between the brick P2G's sorts: from the wear the last
        chunk's scatters counted (`frag`; bricks.sort_cadence), or at an advance's first
        chunk the cadence the last advance ended with (state.clock, checkpointed: a resumed run
        picks what the uninterrupted one did), never longer than the fastest particle's travel
        allows (travel_cadence)."""
        if self.sort_every or self.p2g != "brick":
            return self.sort_every or CHUNKS[-1]
        dt = c[Clock.DT_CFL] if c[Clock.DT_CFL] > 0 else dt_guess
        cap = travel_cadence(float(c[Clock.MAX_SPEED]), float(dt), self.s.config.dx, CHUNKS[-1])
        if frag is None:
            return max(1, min(state.clock.sort_every or cap, cap))
        return sort_cadence(frag, self.last_sort_every, state.n, cap)

    def run(self, state, t0: float, t1: float):
        s, cfg = self.s, self.s.config
        wall0 = time.perf_counter()
        s._last_bad = None
        if self.p2g == "brick" and s.flags.flip > 0.0:
            raise ValueError("DeviceAdvance.p2g: the brick P2G has no FLIP blend (SolverConfig.flip); use 'reference'")
        if self.p2g == "brick" and (self._brick is None or self._brick.n != state.n):
            self._brick = BrickP2G(s.flags, state.n, s.device, nodes=cfg.grid_n + 1)  # before any capture: it allocates
        if self.p2g == "brick":
            state.spare_consts()  # where sorting substeps store the constants: allocated before any capture
        c = self._upload(state, t0, t1)
        if self.keys is not None:  # the fields no substep changes (kind, shape, friction, ...)
            s._colliders_dev.assign(pack_colliders(s.colliders, t0, t0, 1.0))
        frag, cadence = None, 0  # the brick P2G's wear counts of the last chunk (none yet in this advance)
        if self._brick is not None:
            self._brick.frag.zero_()
            self.frag_total = 0
        while int(c[Clock.STATUS]) in (Status.RUNNING, Status.REJECTED):
            if int(c[Clock.STATUS]) == Status.REJECTED:
                c[Clock.STATUS] = Status.RUNNING
                self.clk.assign(c)
            before = c[Clock.N_SUB]
            dt_guess = s._cfl_dt(state.clock)  # the first chunk's: the host's CFL dt
            k = self._chunk_length(c, dt_guess)
            cadence = self._sort_every(state, c, dt_guess, frag)
            if self.p2g == "brick" and pending_between(state.birth_host, t0, t1):
                cadence = 1  # a particle woken since the last sort has no segment: sort every substep
            self.last_sort_every = min(k, cadence)  # (a chunk no longer than it sorts at its start only: one graph)
            consts = (state.consts(), state.spare)  # (spare: allocated above where the brick P2G runs)
            self._chunk(state, k, self.last_sort_every)
            c, frag = self._read_back()
            if self._brick is not None:
                # each accepted sorting substep moved the constants into their other copy
                # (launching or capturing the chunk swapped them once per sorting substep)
                sorts = -(-int(c[Clock.N_SUB] - before) // self.last_sort_every)
                if state.mass is not consts[sorts % 2][0]:
                    state.swap_consts()
                self.frag_total = self.frag_total + frag
            if int(c[Clock.N_SUB] - before) % 2:
                state.swap()
        self._to_clock(state, c)
        if self.p2g == "brick" and not self.sort_every and cadence:
            state.clock.sort_every = cadence
        t = t0 + c[Clock.DONE] / cfg.time_scale
        if int(c[Clock.STATUS]) == Status.DT_TOO_SMALL:
            s._last_bad = self.last_bad.numpy() if c[Clock.HAS_BAD] else None
            raise_too_small(s, state, t, float(c[Clock.DT_CFL]))
        if int(c[Clock.STATUS]) == Status.TOO_MANY:
            raise too_many(
                s, state, t, t1, int(c[Clock.N_SUB]), float(c[Clock.DT_CFL]), float(c[Clock.TOTAL] - c[Clock.DONE])
            )
        n = int(c[Clock.N_SUB])
        dts = [float(c[Clock.DT_MIN]), float(c[Clock.DT_MAX])] if n else []
        report = step_report(
            s,
            state,
            n,
            int(c[Clock.N_REJ]),
            dts,
            float(c[Clock.VMAX]),
            float(c[Clock.CFL_USED]),
            int(c[Clock.LOST]),
            float(c[Clock.J_MIN]),
            float(c[Clock.J_MAX]),
            wall0,
        )
        report.inverted = int(c[Clock.INVERTED])
        return report
