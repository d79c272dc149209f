"""Host copies of a solver's particles: a frame's arrays (state_to_numpy), and checkpoints that
resume a run bit-identically (checkpoint, restore). Each takes the Solver as its first argument;
the Solver's methods of the same names call these."""

from __future__ import annotations

import numpy as np
import warp as wp

from .constitutive import MODE_SAND, MODE_SNOW, MODE_WATER, MaterialParams
from .order import in_particle_order
from .state import ParticleBuffers, State, StepperClock, load_m33, m33_to_host

__all__ = ["HostStaging", "checkpoint", "host_arrays", "restore", "state_to_numpy", "volume_ratios"]

CHECKPOINT_VERSION = 3  # 3: with the slots' particles (pid); 2: with the solids' stored stress (tau); 1 and 2 are
# restored too


@wp.kernel(enable_backward=False)
def _volume_ratio(
    materials: wp.array(dtype=MaterialParams),
    material: wp.array(dtype=wp.int32),
    F: wp.array2d(dtype=wp.vec3),
    J: wp.array(dtype=float),
    solid: int,
    water: int,
    out: wp.array(dtype=float),
):
    """out[p] = det F (snow, sand), J (water) or 1 (tracers)."""
    p = wp.tid()
    mode = materials[material[p]].mode
    j = float(1.0)
    if solid != 0 and (mode == MODE_SNOW or mode == MODE_SAND):
        j = wp.determinant(load_m33(F, p))
    if water != 0 and mode == MODE_WATER:
        j = J[p]
    out[p] = j


def state_to_numpy(solver, state: State) -> dict[str, np.ndarray]:
    """Host copy: x (n,3), v (n,3), C (n,3,3), F (n,3,3) if any solid, J (n,) (det F for
    solids, J for water, 1 for tracers), Jp (n,), mass, volume (n,), material, body,
    alive (n,) int32."""
    return {**host_arrays(solver, state), "J": volume_ratios(solver, state)}


def host_arrays(solver, state: State, names=None, staging: HostStaging | None = None) -> dict[str, np.ndarray]:
    """Host copies of the particle arrays as the solver stores them (`names`: a subset):
    x, v, C, Jp, alive, mass, volume, material, body, F (if any solid) and J (water's
    volume ratio, if any water; other particles' entries unused). `volume_ratios` gives every
    particle's J. staging: copy into its reused buffers (HostStaging)."""
    cur = state.cur
    arrays = {
        "x": cur.x,
        "v": cur.v,
        "C": cur.C,
        "Jp": cur.Jp,
        "alive": cur.alive,
        "mass": state.mass,
        "volume": state.volume,
        "material": state.material,
        "body": state.body,
    }
    if solver.flags.solid:
        arrays["F"] = cur.F
    if solver.flags.water:
        arrays["J"] = cur.J
    return to_host(state, {k: a for k, a in arrays.items() if names is None or k in names}, staging)


@wp.kernel(enable_backward=False)
def _m33_in_particle_order(
    rows: wp.array2d(dtype=wp.vec3), pid: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.mat33)
):
    """out[pid[s]] = the matrix whose rows slot s holds in the (3, n) row planes: the host's
    (n, 3, 3) layout in particle order, made on the device (the host transposes nothing)."""
    s = wp.tid()
    out[pid[s]] = wp.matrix_from_rows(rows[0, s], rows[1, s], rows[2, s])


class HostStaging:
    """Host buffers that a frame's device arrays are copied into, reused frame after frame.

    A fresh host copy of every array each frame costs the host more than the copy itself: new
    pages to fault in, and from a GPU a pageable copy goes through the driver's own staging.
    Here each array lands in a buffer allocated once (page-locked on a GPU, so the copy is one
    DMA), in `sets` alternating sets: a frame's arrays may still be read (written to disk) while
    the next frame's are copied, never longer (the caller's writer holds at most one frame in
    flight: mpmfx.stages.writer.FrameWriter(1)). `take` returns numpy views of the next set."""

    def __init__(self, device, sets: int = 2):
        self.device = wp.get_device(device)
        self._sets: list[dict[str, wp.array]] = [{} for _ in range(sets)]
        self._next = 0

    def take(self, arrays: dict[str, wp.array]) -> dict[str, np.ndarray]:
        """Host copies (views of this set's buffers) of device arrays of any shape and dtype."""
        bufs = self._sets[self._next]
        self._next = (self._next + 1) % len(self._sets)
        for k, a in arrays.items():
            b = bufs.get(k)
            if b is None or b.shape != a.shape or b.dtype != a.dtype:
                b = bufs[k] = wp.empty(a.shape, dtype=a.dtype, device="cpu", pinned=self.device.is_cuda)
            wp.copy(b, a)
        if self.device.is_cuda:
            wp.synchronize_stream(wp.get_stream(self.device))
        return {k: bufs[k].numpy() for k in arrays}


def to_host(state: State, arrays: dict, staging: HostStaging | None = None) -> dict[str, np.ndarray]:
    """Host copies of device arrays, in particle order (see State: storage order); matrices
    (n, 3, 3). staging: copy into its reused buffers (views returned), else fresh arrays."""
    if staging is None:
        if state.permuted:
            arrays = {k: in_particle_order(a, state.pid) for k, a in arrays.items()}
        return {k: m33_to_host(a) if k in ParticleBuffers.MATRICES else a.numpy() for k, a in arrays.items()}
    ordered, planes = {}, set()
    for k, a in arrays.items():
        if k in ParticleBuffers.MATRICES and a.shape[-1] == state.n:
            ordered[k] = wp.empty(state.n, dtype=wp.mat33, device=a.device)
            wp.launch(_m33_in_particle_order, dim=state.n, device=a.device, inputs=[a, state.pid, ordered[k]])
        else:  # (a matrix field no material needs is a (3, 1) placeholder: transposed on the host)
            ordered[k] = in_particle_order(a, state.pid) if state.permuted else a
            if k in ParticleBuffers.MATRICES:
                planes.add(k)
    host = staging.take(ordered)
    return {k: np.ascontiguousarray(h.transpose(1, 0, 2)) if k in planes else h for k, h in host.items()}


def volume_ratios(solver, state: State) -> np.ndarray:
    """J (n,) float32 in particle order: det F for snow and sand, J for water, 1 for tracers,
    computed on the device (a frame takes 4 bytes a particle off the device instead of F's
    36, and the host neither transposes F nor takes its determinant)."""
    out = wp.empty(state.n, dtype=float, device=solver.device)
    wp.launch(
        _volume_ratio,
        dim=state.n,
        device=solver.device,
        inputs=[
            solver._materials_dev,
            state.material,
            state.cur.F,
            state.cur.J,
            int(solver.flags.solid),
            int(solver.flags.water),
            out,
        ],
    )
    return to_host(state, {"J": out})["J"]


def checkpoint(solver, state: State, t: float, staging: HostStaging | None = None) -> dict[str, np.ndarray]:
    """Full state + stepper clock, as numpy arrays in particle order, and `pid`: the particle
    each storage slot held (State), which `restore` puts back, so it resumes bit-identically.
    staging: the particle arrays copied into its reused buffers (HostStaging)."""
    data = to_host(
        state,
        {
            **dict(zip(ParticleBuffers.NAMES, state.cur.arrays())),
            "mass": state.mass,
            "volume": state.volume,
            "material": state.material,
            "body": state.body,
        },
        staging,
    )
    if state.variation is not None:  # a varied scene's multipliers (particle order): the factors and dt follow
        data["variation"] = state.variation
    data["pid"] = state.pid.numpy()
    if state.birth is not None:  # pending births (+inf: born), by particle
        data["birth"] = state.birth.numpy()
    data["clock"] = state.clock.to_array()
    data["t"] = np.array([t], np.float64)
    data["meta"] = np.array([CHECKPOINT_VERSION, solver.config.grid_n, state.n], np.int64)
    return data


def restore(solver, data: dict[str, np.ndarray]) -> tuple[State, float]:
    """State and shot time t from `checkpoint` output (ValueError if it does not fit)."""
    required = {*ParticleBuffers.NAMES, "mass", "volume", "material", "body", "clock", "t", "meta"} - {"tau"}
    missing = sorted(required - set(data))
    if missing:
        raise ValueError(
            f"checkpoint: missing arrays {', '.join(missing)}; it was not written by "
            "Solver.checkpoint (or is truncated); re-simulate from the start"
        )
    meta = np.asarray(data["meta"])
    if int(meta[0]) not in (1, 2, CHECKPOINT_VERSION) or int(meta[1]) != solver.config.grid_n:
        raise ValueError(
            f"checkpoint: version/grid_n {meta[:2].tolist()} do not match this solver "
            f"({CHECKPOINT_VERSION}, {solver.config.grid_n}); re-simulate from the start"
        )
    state = solver._build_state(data, StepperClock.from_array(data["clock"]))
    return state, float(data["t"][0])
