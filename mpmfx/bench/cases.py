"""Validation cases for `mpmfx bench accuracy` (docs/physics.md, "Validation"), scaled into the domain.

Each case runs the solver at fixed substeps dt = cfl * dx / (c + |v|max) (so halving the
CFL number halves dt exactly, which the time-order measurement needs) and returns a
`CaseResult` whose `error` is its observable's error against the reference. Physical cases
are scaled into the domain [0, 1]^3 by a length factor s: lengths and speeds by s, E/rho by
s^2, gravity by s, times unchanged.

3D runs use thin slabs (2 cells) with nu = 0 where the reference is 1D, so no lateral walls
are needed: under uniaxial strain with lambda = 0 the lateral stress is exactly zero.
Imports numpy, warp and mpmfx.mpm only (the GPU machine has nothing else).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from mpmfx.mpm import Particles, Solver, SolverConfig, preset

from ..mpm.state import m33_assign

__all__ = [
    "CaseResult",
    "lattice",
    "fc_energy",
    "free_fall",
    "rigid_rotation",
    "vibrating_bar",
    "standing_wave",
    "hydrostatic_column",
    "colliding_disks",
]


@dataclass
class CaseResult:
    """One run of one case. error: dimensionless (what `metric` says); wall_s: seconds of
    stepping (after compilation); particle_substeps: particles x substeps."""

    case: str
    grid_n: int
    cfl: float
    ppc: int
    particles: int
    substeps: int
    wall_s: float
    error: float
    metric: str
    device: str
    extra: dict = field(default_factory=dict)
    x_final: np.ndarray | None = None  # (n, 3) positions at the end, for self-convergence

    def row(self) -> dict:
        r = {
            "case": self.case,
            "grid_n": self.grid_n,
            "cfl": self.cfl,
            "ppc": self.ppc,
            "particles": self.particles,
            "substeps": self.substeps,
            "error": self.error,
            "metric": self.metric,
            "wall_s": self.wall_s,
            "Mparticle_substeps_per_s": self.particles * self.substeps / max(self.wall_s, 1e-9) / 1e6,
            "device": self.device,
        }
        r.update(self.extra)
        return r


# ---------------------------------------------------------------------------- helpers
def lattice(lo, hi, spacing: float, inside=None) -> np.ndarray:
    """Regular lattice of points at sub-cell centres in the box [lo, hi] (domain units),
    `spacing` apart; `inside(x) -> bool mask` keeps a subset. Returns (n, 3) float32."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    counts = np.maximum(1, np.round((hi - lo) / spacing).astype(int))
    axes = [lo[a] + (np.arange(counts[a]) + 0.5) * spacing for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    if inside is not None:
        x = x[inside(x)]
    return x.astype(np.float32)


def _polar(F: np.ndarray):
    """Signed SVD (det U = det V = +1, smallest singular value may be negative): U, S, Vt."""
    U, S, Vt = np.linalg.svd(F.astype(np.float64))
    flip = np.linalg.det(U) * np.linalg.det(Vt) < 0
    S[flip, 2] *= -1.0
    U[flip, :, 2] *= -1.0
    return U, S, Vt


def fc_energy(F: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """Fixed-corotated energy density psi = mu |F - R|^2 + lambda/2 (J - 1)^2 per rest volume.
    F: (n, 3, 3). Returns (n,) float64."""
    U, S, Vt = _polar(F)
    R = U @ Vt
    J = np.prod(S, axis=1)
    return mu * ((F - R) ** 2).sum(axis=(1, 2)) + 0.5 * lam * (J - 1.0) ** 2


def fc_cauchy(F: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """Cauchy stress sigma = tau / J of fixed-corotated, (n, 3, 3)."""
    U, S, Vt = _polar(F)
    R = U @ Vt
    J = np.prod(S, axis=1)
    tau = 2.0 * mu * (F - R) @ np.transpose(F, (0, 2, 1)) + (lam * (J - 1.0) * J)[:, None, None] * np.eye(3)
    return tau / J[:, None, None]


def device_name(solver) -> str:
    d = solver.device
    return d.name if d.is_cuda else "cpu"


def _elastic(E: float, nu: float, rho: float = 1.0):
    return preset("Elastic", youngs_modulus=float(E), poisson_ratio=float(nu), density=float(rho))


def _setup(mat, x, v, spacing, *, grid_n, gravity=(0.0, 0.0, 0.0), device=None, damping=0.0, **cfg):
    """Solver + state for one material; warms the kernels up so timing excludes compiling."""
    config = SolverConfig(grid_n=grid_n, gravity=gravity, damping=damping, **cfg)
    solver = Solver([mat], config, device=device)
    n = len(x)
    one = Particles(
        x=np.full((1, 3), 0.5, np.float32),
        v=np.zeros((1, 3), np.float32),
        volume=np.ones(1, np.float32) * spacing**3,
        material=np.zeros(1, np.int32),
        body=np.zeros(1, np.int32),
    )
    solver.step(solver.init_state(one), 1e-6)  # compile + load modules now
    parts = Particles(
        x=np.asarray(x, np.float32),
        v=np.asarray(v, np.float32),
        volume=np.full(n, spacing**3, np.float32),
        material=np.zeros(n, np.int32),
        body=np.zeros(n, np.int32),
    )
    return solver, solver.init_state(parts)


def _dt(solver, state, cfl: float, vmax: float) -> float:
    return cfl * solver.config.dx / (solver.wave_speed(state.clock) + vmax)


def _march(solver, state, dt: float, steps: int, observe=None, every: int = 1) -> float:
    """`steps` substeps of dt; observe(k) after substep k when k % every == 0. Returns
    (wall seconds, device synchronised and including the observations' copies; simulated seconds)."""
    wp.synchronize_device(solver.device)
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        solver.step(state, dt)
        if observe is not None and k % every == 0:
            observe(k)
    wp.synchronize_device(solver.device)
    return time.perf_counter() - t0, dt * steps


def _result(case, solver, state, cfl, ppa, steps, wall, error, metric, **extra) -> CaseResult:
    return CaseResult(
        case=case,
        grid_n=solver.config.grid_n,
        cfl=cfl,
        ppc=ppa**3,
        particles=state.n,
        substeps=steps,
        wall_s=wall,
        error=float(error),
        metric=metric,
        device=device_name(solver),
        extra=extra,
        x_final=solver.state_to_numpy(state)["x"].astype(np.float64),
    )


# ---------------------------------------------------------------------------- exact kinematics
def free_fall(*, grid_n: int = 32, cfl: float = 0.4, ppa: int = 2, device=None) -> CaseResult:
    """Unstressed block in gravity vs the exact symplectic-Euler discrete trajectory
    x_n = x0 + v0 t + g t^2/2 + g t dt/2. error: max |x - x_n| / |g t^2 / 2| (relative)."""
    g = np.array([0.0, -4.9, 0.0])
    v0 = np.array([0.3, 0.0, 0.0])
    dx = 1.0 / grid_n
    x0 = lattice([0.3, 0.55, 0.4], [0.5, 0.75, 0.6], dx / ppa)
    solver, state = _setup(
        _elastic(1.0, 0.2), x0, np.tile(v0, (len(x0), 1)), dx / ppa, grid_n=grid_n, gravity=tuple(g), device=device
    )
    t_end = 0.25
    dt0 = _dt(solver, state, cfl, float(np.linalg.norm(v0 + g * t_end)))
    steps = math.ceil(t_end / dt0)
    dt = t_end / steps
    wall, sim_s = _march(solver, state, dt, steps)
    s = solver.state_to_numpy(state)
    exact = x0 + v0 * t_end + 0.5 * g * t_end**2 + 0.5 * g * t_end * dt
    err = np.abs(s["x"] - exact).max() / (0.5 * np.linalg.norm(g) * t_end**2)
    f_dev = float(np.abs(s["F"] - np.eye(3)).max())
    return _result(
        "free_fall", solver, state, cfl, ppa, steps, wall, err, "max|x-x_exact|/drop", F_minus_I=f_dev, sim_s=sim_s
    )


def _angular_momentum(s, c, dx) -> np.ndarray:
    """Total angular momentum about c, with APIC's affine part m dx^2/4 eps:C (D = dx^2/4 I)."""
    m = s["mass"].astype(np.float64)[:, None]
    r = s["x"] - c
    L = (m * np.cross(r, s["v"])).sum(0)
    C = s["C"].astype(np.float64)
    axial = np.stack([C[:, 2, 1] - C[:, 1, 2], C[:, 0, 2] - C[:, 2, 0], C[:, 1, 0] - C[:, 0, 1]], -1)
    return L + (m * axial).sum(0) * dx**2 / 4.0


def rigid_rotation(
    *, grid_n: int = 16, cfl: float = 0.4, ppa: int = 2, revolutions: float = 1.0, pic: bool = False, device=None
) -> CaseResult:
    """Spinning elastic ball, no gravity, no walls reached (Jiang et al. 2015). v = w x r,
    C = skew(w); rho w^2 R^2 / E = 1e-3. error: |L(T) - L0| / |L0| after `revolutions`.
    pic=True drops the affine velocity every substep (drag -> inf): the PIC baseline."""
    dx = 1.0 / grid_n
    R, w = 0.15, np.array([0.0, 0.0, 2.0])
    c = np.array([0.5, 0.5, 0.5])
    x = lattice(c - R, c + R, dx / ppa, inside=lambda p: np.linalg.norm(p - c, axis=1) <= R)
    v = np.cross(w, x - c)
    E = float(np.dot(w, w) * R**2 / 1e-3)
    extra = {"drag": 1e9} if pic else {}
    solver, state = _setup(_elastic(E, 0.2), x, v, dx / ppa, grid_n=grid_n, device=device, **extra)
    skew = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]], np.float32)
    m33_assign(state.cur.C, np.tile(skew, (state.n, 1, 1)))
    L0 = _angular_momentum(solver.state_to_numpy(state), c, dx)
    t_end = revolutions * 2 * math.pi / np.linalg.norm(w)
    steps = math.ceil(t_end / _dt(solver, state, cfl, R * np.linalg.norm(w)))
    wall, sim_s = _march(solver, state, t_end / steps, steps)
    L = _angular_momentum(solver.state_to_numpy(state), c, dx)
    err = np.linalg.norm(L - L0) / np.linalg.norm(L0)
    return _result(
        "rotation_pic" if pic else "rotation_apic",
        solver,
        state,
        cfl,
        ppa,
        steps,
        wall,
        err,
        "|L-L0|/L0",
        revolutions=revolutions,
        sim_s=sim_s,
    )


# ---------------------------------------------------------------------------- elastic
def vibrating_bar(*, grid_n: int = 40, cfl: float = 0.4, ppa: int = 2, device=None) -> CaseResult:
    """Buzzi et al. 2008 bar (E=100, L=25, rho=1, v0=0.1, nu=0, period 10 s) as the right half of
    a free-free bar of length 2L (its midpoint is a node of the first mode). error: relative
    period error from v_cm zero crossings; extra: v_cm amplitude error vs 2 v0 / pi."""
    L = 0.3  # with the walls' planes 2 cells in, the ends stay out of their reach down to grid_n = 20
    s = L / 25.0  # length scale into the domain
    E, v0 = 100.0 * s**2, 0.1 * s
    dx = 1.0 / grid_n
    xc = 0.5
    half = dx  # cross-section 2 x 2 cells
    x = lattice([xc - L, 0.5 - half, 0.5 - half], [xc + L, 0.5 + half, 0.5 + half], dx / ppa)
    beta = math.pi / (2 * L)
    v = np.zeros_like(x)
    v[:, 0] = v0 * np.sin(beta * (x[:, 0] - xc))
    solver, state = _setup(_elastic(E, 0.0), x, v, dx / ppa, grid_n=grid_n, device=device, boundary_cells=2)
    T = 10.0
    steps = math.ceil(T / _dt(solver, state, cfl, v0))
    dt = T / steps
    right = x[:, 0] > xc
    vcm = [float(v[right, 0].mean())]
    wall, sim_s = _march(
        solver, state, dt, int(steps * 1.05), observe=lambda k: vcm.append(float(state.cur.v.numpy()[right, 0].mean()))
    )
    t = np.arange(len(vcm)) * dt
    vc = np.array(vcm)
    cross = [t[i] - vc[i] * dt / (vc[i + 1] - vc[i]) for i in range(len(vc) - 1) if vc[i] * vc[i + 1] < 0]
    period = 2.0 * (cross[1] - cross[0]) if len(cross) >= 2 else float("nan")
    amp = 2 * v0 / math.pi
    amp_err = np.abs(vc[t <= T] - amp * np.cos(2 * math.pi * t[t <= T] / T)).max() / amp
    return _result(
        "vibrating_bar",
        solver,
        state,
        cfl,
        ppa,
        len(vcm) - 1,
        wall,
        abs(period - T) / T,
        "|T-10|/10",
        period_s=period,
        vcm_error=float(amp_err),
        sim_s=sim_s,
    )


def standing_wave(
    *, grid_n: int = 32, cfl: float = 0.4, ppa: int = 2, strain: float = 0.2, periods: float = 1.0, device=None
) -> CaseResult:
    """Exact large-amplitude fixed-corotated standing wave (free-free, nu = 0, E = rho = 1):
    u(X, t) = A cos(k X) sin(w t), k = pi / L, w = k c, A k = strain. error: RMS over particles
    and the quarter-period samples of |u - u_exact| / A."""
    L, c = 0.5, 1.0
    k = math.pi / L
    A, w = strain / k, k * c
    dx = 1.0 / grid_n
    x0 = lattice([0.25, 0.5 - dx, 0.5 - dx], [0.75, 0.5 + dx, 0.5 + dx], dx / ppa)
    X = x0[:, 0].astype(np.float64) - 0.25
    v = np.zeros_like(x0)
    v[:, 0] = A * w * np.cos(k * X)
    # free-free: the walls' planes 2 cells in keep the ends (at 0.25 - A) out of their reach at grid 16
    solver, state = _setup(_elastic(1.0, 0.0), x0, v, dx / ppa, grid_n=grid_n, device=device, boundary_cells=2)
    T = 2 * math.pi / w
    per_q = math.ceil(T / 4 / _dt(solver, state, cfl, A * w))
    dt = T / 4 / per_q
    quarters = max(1, round(4 * periods))
    sq = []

    def observe(step):
        u = solver.state_to_numpy(state)["x"][:, 0] - x0[:, 0]
        sq.append(np.mean((u - A * np.cos(k * X) * np.sin(w * step * dt)) ** 2))

    wall, sim_s = _march(solver, state, dt, per_q * quarters, observe=observe, every=per_q)
    err = math.sqrt(np.mean(sq)) / A
    return _result(
        "standing_wave", solver, state, cfl, ppa, per_q * quarters, wall, err, "rms|u-u_exact|/A", dt=dt, sim_s=sim_s
    )


def hydrostatic_column(*, grid_n: int = 32, cfl: float = 0.4, ppa: int = 2, device=None) -> CaseResult:
    """Elastic column (nu = 0, 2 x 2 cells) settling under gravity on the floor, damped.
    Reference sigma_yy = -rho g (H - Y) at the rest height Y. error: relative L2 over
    particles more than 2 cells above the foot; extra bias = sum(sigma) / sum(sigma_exact) - 1 (CB-Geo: -2.6..-2.9 %)."""
    dx = 1.0 / grid_n
    g, H, rho = 4.9, 0.4, 1.0
    E = rho * g * H / 0.02  # 2 % strain at the foot
    y0 = 3 * dx  # the floor plane (SolverConfig.wall_planes)
    x0 = lattice([0.5 - dx, y0, 0.5 - dx], [0.5 + dx, y0 + H, 0.5 + dx], dx / ppa)
    solver, state = _setup(
        _elastic(E, 0.0, rho),
        x0,
        np.zeros_like(x0),
        dx / ppa,
        grid_n=grid_n,
        gravity=(0.0, -g, 0.0),
        damping=40.0,
        device=device,
    )
    t_end = 0.4
    steps = math.ceil(t_end / _dt(solver, state, cfl, 0.0))
    wall, sim_s = _march(solver, state, t_end / steps, steps)
    s = solver.state_to_numpy(state)
    sig = fc_cauchy(s["F"].astype(np.float64), solver.materials[0].mu0, solver.materials[0].lambda0)[:, 1, 1]
    exact = -rho * g * (y0 + H - x0[:, 1].astype(np.float64))
    # the bottom 2 cells share nodes with the floor and its guard: a boundary artefact, not
    # the bulk stress the reference describes (CB-Geo also reads the bulk)
    bulk = x0[:, 1] > y0 + 2 * dx
    sig, exact = sig[bulk], exact[bulk]
    err = np.linalg.norm(sig - exact) / np.linalg.norm(exact)
    return _result(
        "hydrostatic",
        solver,
        state,
        cfl,
        ppa,
        steps,
        wall,
        err,
        "L2|s_yy-exact|/|exact|",
        bias=float(sig.sum() / exact.sum() - 1.0),
        sim_s=sim_s,
    )


def colliding_disks(*, grid_n: int = 32, cfl: float = 0.4, ppa: int = 2, t_end: float = 4.0, device=None) -> CaseResult:
    """Sulsky, Chen & Schreyer 1994 disks (E = 1000, nu = 0.3, rho = 1000, r = 0.2, v = +-(0.1, 0.1)),
    scaled by s = 0.6 into the domain, as 2-cell-thick slabs (plane stress). error: total energy
    change |E(t) - E0| / E0 at t_end; extra: |momentum| / sum(m |v0|), first-touch time."""
    s, off = 0.6, 0.2  # 0.2: clear of the wall layer (3 cells) down to grid_n = 20
    dx = 1.0 / grid_n
    r = 0.2 * s
    cs = [np.array([off + 0.2 * s, off + 0.2 * s, 0.5]), np.array([off + 0.8 * s, off + 0.8 * s, 0.5])]
    blobs, vel = [], []
    for c, sign in zip(cs, (1.0, -1.0)):
        xb = lattice(
            c - [r, r, dx],
            c + [r, r, dx],
            dx / ppa,
            inside=lambda p, c=c: np.linalg.norm(p[:, :2] - c[:2], axis=1) <= r,
        )
        blobs.append(xb)
        vel.append(np.tile([sign * 0.1 * s, sign * 0.1 * s, 0.0], (len(xb), 1)))
    x, v = np.concatenate(blobs), np.concatenate(vel).astype(np.float32)
    mat = _elastic(1000.0 / 1000.0 * s**2, 0.3)
    solver, state = _setup(mat, x, v, dx / ppa, grid_n=grid_n, device=device)
    m = solver.state_to_numpy(state)["mass"].astype(np.float64)

    def energy():
        st = solver.state_to_numpy(state)
        ke = 0.5 * (m * (st["v"].astype(np.float64) ** 2).sum(1)).sum()
        return ke + (fc_energy(st["F"].astype(np.float64), mat.mu0, mat.lambda0) * st["volume"]).sum(), st

    e0, _ = energy()
    steps = math.ceil(t_end / _dt(solver, state, cfl, 0.1 * s * math.sqrt(2)))
    wall, sim_s = _march(solver, state, t_end / steps, steps)
    e1, st = energy()
    p = np.abs((m[:, None] * st["v"]).sum(0)).max() / (m * np.linalg.norm(v, axis=1)).sum()
    return _result(
        "colliding_disks",
        solver,
        state,
        cfl,
        ppa,
        steps,
        wall,
        abs(e1 - e0) / e0,
        "|E-E0|/E0",
        momentum_error=float(p),
        sim_s=sim_s,
    )
