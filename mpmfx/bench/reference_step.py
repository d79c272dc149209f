"""The MLS-MPM substep written plainly in numpy (float64), for tests and benchmarks.

Read it line by line against docs/physics.md ("The method", "Materials", "Boundaries") or
the tutorial "Material Point Method: Step by Step": the four phases, the stencil and B-spline
weights, the fused MLS stress, fixed-corotated elasticity, the snow clamp and the sand cone, the Tait fluid, and the
walls of `mpmfx.mpm.config.SolverConfig` (planes `wall_planes`, holding the nodes on and beyond
them, sticky / slip / separate, Coulomb `wall_friction` over the `wall_layer`). It is the reference the production
Warp solver (`mpmfx.mpm.Solver`) must match on the same particles, grid and dt; it is
slow (vectorised numpy, thousands of particles) and has the FLIP blend (`SolverConfig.flip`)
but no colliders, multi-field contact,
tracers, water volume recovery or adaptive stepping.

    ref = ReferenceSolver([preset("Water")], SolverConfig(grid_n=24))
    state = ref.init_state(particles)          # the same Particles the Solver takes
    for _ in range(steps):
        ref.step(state, dt)
    x = ref.state_to_numpy(state)["x"]

Units as the solver's: domain units ([0, 1]^3), seconds, mass = rest volume * density.
"""

from __future__ import annotations

import itertools

import numpy as np

from mpmfx.mpm.config import OutOfDomain, SolverConfig
from mpmfx.mpm.materials import Material, Mode

__all__ = ["ReferenceSolver"]

_OFFSETS = np.array(list(itertools.product(range(3), repeat=3)))  # the 27 nodes of a particle's stencil
_I3 = np.eye(3)


def bspline(fx: np.ndarray) -> np.ndarray:
    """Quadratic B-spline weights. fx: (n, 3) offsets from the base node, cells,
    in [0.5, 1.5). Returns (n, 3 nodes, 3 axes); each axis sums to 1."""
    return np.stack([0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2], axis=1)


def svd(F: np.ndarray):
    """F = U diag(s) V^T with U, V rotations (det +1); the sign of det F goes on s[:, 2]
    (as Warp's svd3, so R = U V^T is a rotation even for an inverted F)."""
    U, s, Vt = np.linalg.svd(F)
    flip = np.linalg.det(U) * np.linalg.det(Vt) < 0
    s[flip, 2] *= -1.0
    U[flip, :, 2] *= -1.0
    V = np.transpose(Vt, (0, 2, 1)).copy()
    neg = np.linalg.det(U) < 0  # both -1: flip one column of each, s unchanged
    U[neg, :, 2] *= -1.0
    V[neg, :, 2] *= -1.0
    return U, s, V


def rebuild(U, s, V):
    """U diag(s) V^T for (n, 3, 3), (n, 3), (n, 3, 3)."""
    return np.einsum("nij,nj,nkj->nik", U, s, V)


def log_strain(s: np.ndarray) -> np.ndarray:
    """Hencky strain of the singular values, ln max(|s|, 1e-4) (Klar et al. 2016)."""
    return np.log(np.maximum(np.abs(s), 1e-4))


# ------------------------------------------------------------------ stress
def fixed_corotated_tau(F, mu, lam):
    """Fixed-corotated: tau = P F^T = 2 mu (F - R) F^T + lambda (J - 1) J I; mu, lam per particle."""
    U, s, V = svd(F)
    R = U @ np.transpose(V, (0, 2, 1))
    J = np.prod(s, axis=1)
    return 2.0 * mu[:, None, None] * (F - R) @ np.transpose(F, (0, 2, 1)) + (lam * (J - 1.0) * J)[:, None, None] * _I3


def hencky_tau(F, mu, lam):
    """Klar et al. 2016: tau = U (2 mu ln S + lambda tr(ln S) I) U^T."""
    U, s, V = svd(F)
    eps = log_strain(s)
    d = 2.0 * mu[:, None] * eps + lam[:, None] * eps.sum(1, keepdims=True)
    return np.einsum("nij,nj,nkj->nik", U, d, U)


def tait_pressure(m: Material, J):
    """Tait: p = K (J^-gamma - 1), clamped to p >= 0 when clamp_pressure."""
    p = m.bulk_modulus * (np.maximum(J, 1e-4) ** (-m.eos_gamma) - 1.0)
    return np.maximum(p, 0.0) if m.clamp_pressure else p


# ------------------------------------------------------------------ plasticity
def snow_clamp(m: Material, F, Jp):
    """Singular values into [1 - theta_c, 1 + theta_s]; the clamped-away volume into Jp,
    clamped to [jp_min, jp_max] (Stomakhin et al. 2013)."""
    U, s, V = svd(F)
    sc = np.clip(s, 1.0 - m.theta_c, 1.0 + m.theta_s)
    Jp = np.clip(Jp * np.prod(s, 1) / np.prod(sc, 1), m.jp_min, m.jp_max)
    return rebuild(U, sc, V), Jp


def sand_project(m: Material, F, vc):
    """Drucker-Prager return map in Hencky strain (Klar et al. 2016: a cone), with
    cohesion (apex at tr = cohesion) and volume correction (vc: log-volume discarded at the
    apex, Tampubolon et al. 2017). Returns (elastic F, new vc)."""
    U, s, V = svd(F)
    eps = log_strain(s)
    tr = eps.sum(1) + vc
    eps_hat = eps - tr[:, None] / 3.0
    norm = np.linalg.norm(eps_hat, axis=1) + 1e-20
    trc = tr - m.cohesion
    apex = trc >= 0.0  # tension beyond the apex: no strength, keep the cohesive part only
    dgamma = norm + (3.0 * m.lambda0 + 2.0 * m.mu0) / (2.0 * m.mu0) * trc * m.dp_alpha
    yielded = ~apex & (dgamma > 0.0)  # outside the cone: back onto it along eps_hat
    eps_new = np.where(yielded[:, None], eps - (dgamma / norm)[:, None] * eps_hat, eps)
    eps_new[apex] = m.cohesion / 3.0
    vc_new = np.where(apex & m.volume_correction, trc, 0.0)
    return rebuild(U, np.exp(eps_new), V), vc_new


def uninvert(F):
    """An inverted trial F (det <= 0) keeps the magnitude of its stretches (constitutive.uninvert)."""
    U, s, V = svd(F)
    return rebuild(U, np.abs(s), V)


# ------------------------------------------------------------------ walls (SolverConfig)
def apply_wall(v, n_out: np.ndarray, kind: str, mu: float):
    """One face on the nodes v (k, 3): sticky stops; slip removes the normal speed both ways;
    separate only into the wall. Coulomb friction takes mu |vn| off the tangential speed."""
    if kind == "sticky":
        return np.zeros_like(v)
    vn = v @ n_out
    vt = v - vn[:, None] * n_out
    lt = np.linalg.norm(vt, axis=1)
    into = vn > 0.0
    scale = np.where(into & (lt > 0), np.maximum(0.0, 1.0 - mu * np.maximum(vn, 0) / np.maximum(lt, 1e-300)), 1.0)
    out = vt * scale[:, None]
    if kind == "separate":
        out = np.where(into[:, None], out, v)
    return out


def layer_friction(v, grid_m, cfg: SolverConfig) -> np.ndarray:
    """The walls' Coulomb friction over their boundary layer (grid_update.layer_friction): per wall
    and column of nodes across it, mu times the normal impulse J = sum m vn (into the wall) of
    the column's nodes on the plane or beyond, taken off the tangential speed of its nodes within
    `wall_layer` of the plane, each scaled by max(0, 1 - w mu J / sum w m |vt|), w = 1 - d /
    wall_layer. v, grid_m: the nodes' velocities (N^3, 3) before the walls and masses (N^3,)."""
    n = cfg.grid_n + 1
    lo, hi = cfg.wall_planes
    v0 = v.reshape(n, n, n, 3)
    m = grid_m.reshape(n, n, n)
    out = v0.copy()
    c = np.arange(n) * cfg.dx
    for a in range(3):
        for side, kind in ((-1.0, cfg.walls[2 * a]), (1.0, cfg.walls[2 * a + 1])):
            if kind.value == "sticky":
                continue
            d = c - lo if side < 0 else hi - c  # distance from the plane into the domain
            w = np.where(d < cfg.wall_layer, 1.0 - np.maximum(d, 0.0) / cfg.wall_layer, 0.0)
            shape = [1, 1, 1]
            shape[a] = n
            w, wall = w.reshape(shape), (d < 0.5 * cfg.dx).reshape(shape)
            vn = v0[..., a] * side
            vt = v0.copy()
            vt[..., a] = 0.0
            jn = (m * np.maximum(vn, 0.0) * wall).sum(axis=a, keepdims=True)
            share = (w * m * np.linalg.norm(vt, axis=-1)).sum(axis=a, keepdims=True)
            ratio = np.where((jn > 0) & (share > 0), cfg.wall_friction * jn / np.maximum(share, 1e-300), 0.0)
            scale = np.maximum(0.0, 1.0 - w * ratio)
            keep = out[..., a].copy()
            out *= scale[..., None]
            out[..., a] = keep
    return out.reshape(-1, 3)


class ReferenceSolver:
    """Plain MLS-MPM with the Solver's interface subset: init_state, step, state_to_numpy."""

    def __init__(self, materials, config: SolverConfig):
        self.materials = tuple(materials)
        self.config = config
        for i, m in enumerate(self.materials):
            if m.mode == Mode.TRACER or (m.mode == Mode.WATER and m.volume_recovery):
                raise ValueError(
                    f"ReferenceSolver: materials[{i}] uses {m.mode.name} "
                    "(tracers / volume recovery are not in the reference)"
                )
        if config.multi_field:
            raise ValueError("ReferenceSolver: multi_field is not in the reference")

    def init_state(self, p) -> dict:
        """Particles -> state dict of float64 arrays (F = I, J = 1, Jp = 1 snow / 0 sand)."""
        n = len(p.x)
        mat = np.asarray(p.material, int)
        dens = np.array([m.density for m in self.materials])[mat]
        sand = np.array([m.mode == Mode.SAND for m in self.materials])[mat]
        return {
            "x": np.asarray(p.x, float).copy(),
            "v": np.asarray(p.v, float).copy(),
            "C": np.zeros((n, 3, 3)),
            "F": np.tile(_I3, (n, 1, 1)),
            "J": np.ones(n),
            "Jp": np.where(sand, 0.0, 1.0),
            "volume": np.asarray(p.volume, float),
            "mass": np.asarray(p.volume, float) * dens,
            "material": mat,
            "alive": np.ones(n, bool),
        }

    def state_to_numpy(self, state: dict) -> dict:
        return dict(state)

    def wave_speed(self) -> float:
        return max(m.wave_speed() for m in self.materials)

    # -------------------------------------------------------------- one substep: the four phases
    def step(self, s: dict, dt: float) -> None:
        cfg = self.config
        n_nodes = cfg.grid_n + 1
        inv_dx, dx = float(cfg.grid_n), cfg.dx
        live = np.flatnonzero(s["alive"])
        # 1 · clear: the grid is scratch, made fresh every substep (np.bincount below)
        # the 3x3x3 block and where the particle sits in it
        x = s["x"][live]
        base = np.floor(x * inv_dx - 0.5).astype(int)
        fx = x * inv_dx - base
        w = bspline(fx)
        # 2 · P2G with the stress fused into the affine term
        tau = self._stress(s, live)
        m = s["mass"][live]
        affine = (-dt * s["volume"][live] * 4.0 * inv_dx**2)[:, None, None] * tau + m[:, None, None] * s["C"][live]
        node = base[None] + _OFFSETS[:, None, :]  # (27, n, 3)
        nid = (node[..., 0] * n_nodes + node[..., 1]) * n_nodes + node[..., 2]
        wk = w[:, _OFFSETS[:, 0], 0].T * w[:, _OFFSETS[:, 1], 1].T * w[:, _OFFSETS[:, 2], 2].T  # (27, n)
        dpos = (_OFFSETS[:, None, :] - fx[None]) * dx  # node minus particle, (27, n, 3)
        mom = wk[..., None] * (m[:, None] * s["v"][live] + np.matmul(affine[None], dpos[..., None])[..., 0])
        flat = nid.ravel()
        grid_m = np.bincount(flat, (wk * m).ravel(), minlength=n_nodes**3)
        grid_mv = np.stack([np.bincount(flat, mom[..., a].ravel(), minlength=n_nodes**3) for a in range(3)], -1)
        # 3 · grid update: v = mv / m, gravity, damping, walls
        grid_v = self._grid_update(grid_m, grid_mv, dt)
        if cfg.flip > 0:  # the grid's velocity before the update: the momentum without the stress
            mom0 = wk[..., None] * (
                m[:, None] * s["v"][live] + np.matmul(s["C"][live][None], dpos[..., None])[..., 0] * m[:, None]
            )
            mv0 = np.stack([np.bincount(flat, mom0[..., a].ravel(), minlength=n_nodes**3) for a in range(3)], -1)
            v_old = (wk[..., None] * (mv0 / np.where(grid_m > 0, grid_m, 1.0)[:, None])[nid]).sum(0)
        # 4 · G2P: gather v and C = B D^-1 (D^-1 = 4 / dx^2), update F / J, advect
        wg = wk[..., None] * grid_v[nid]  # (27, n, 3)
        v = wg.sum(0)
        B = np.matmul(wg.transpose(1, 2, 0), dpos.transpose(1, 0, 2))  # sum_k wg dpos^T
        C = (4.0 * inv_dx**2) * B * max(0.0, 1.0 - cfg.drag * dt)
        self._update_deformation(s, live, C, dt)
        v_move = v  # the grid's velocity advects; FLIP: v = flip (v_p + v - v_old) + (1 - flip) v
        if cfg.flip > 0:
            v = v + cfg.flip * (s["v"][live] - v_old)
        s["v"][live], s["C"][live] = v, C
        x_new = x + dt * v_move
        lo, hi = dx, 1.0 - dx
        if cfg.out_of_domain == OutOfDomain.REMOVE:
            out = np.any((x_new < lo) | (x_new > hi), axis=1)
            s["alive"][live[out]] = False
        else:
            x_new = np.clip(x_new, lo, hi)
        s["x"][live] = x_new

    def _stress(self, s, live) -> np.ndarray:
        """Kirchhoff stress tau (n_live, 3, 3) of each particle's mode."""
        tau = np.zeros((len(live), 3, 3))
        mat = s["material"][live]
        for i, m in enumerate(self.materials):
            sel = mat == i
            if not sel.any():
                continue
            idx = live[sel]
            if m.mode == Mode.WATER:
                J = s["J"][idx]
                tau[sel] = (-tait_pressure(m, J) * J)[:, None, None] * _I3
            elif m.mode == Mode.SAND:
                k = np.ones(len(idx))
                tau[sel] = hencky_tau(s["F"][idx], m.mu0 * k, m.lambda0 * k)
            else:  # snow: moduli hardened by exp(xi (1 - Jp))
                h = np.exp(m.hardening * (1.0 - s["Jp"][idx]))
                tau[sel] = fixed_corotated_tau(s["F"][idx], m.mu0 * h, m.lambda0 * h)
        return tau

    def _grid_update(self, grid_m, grid_mv, dt) -> np.ndarray:
        cfg = self.config
        n_nodes, (lo, hi) = cfg.grid_n + 1, cfg.wall_planes
        has = grid_m > 0
        v = np.zeros_like(grid_mv)
        v[has] = grid_mv[has] / grid_m[has, None]
        v[has] = (v[has] + dt * np.asarray(cfg.gravity)) * max(0.0, 1.0 - cfg.damping * dt)
        xn = np.stack(np.unravel_index(np.flatnonzero(has), (n_nodes,) * 3), -1) * cfg.dx
        reach = 0.5 * cfg.dx  # the planes lie on nodes: the half cell only absorbs rounding
        mu = cfg.wall_friction
        if cfg.wall_layer > 0 and mu > 0:
            v = layer_friction(v, grid_m, cfg)
            mu = 0.0  # the walls below only hold the normal speed: their friction was the layer's
        for a in range(3):  # same face order as grid_update.apply_walls: -a then +a
            for side, band in ((-1.0, xn[:, a] < lo + reach), (1.0, xn[:, a] > hi - reach)):
                sel = np.flatnonzero(has)[band]
                n_out = np.zeros(3)
                n_out[a] = side
                kind = cfg.walls[2 * a + (side > 0)].value
                v[sel] = apply_wall(v[sel], n_out, kind, mu)
        return v

    def _update_deformation(self, s, live, C, dt) -> None:
        """F <- return_map((I + dt C) F) for solids; J <- det(I + dt C) J for water."""
        mat = s["material"][live]
        for i, m in enumerate(self.materials):
            sel = mat == i
            if not sel.any():
                continue
            idx = live[sel]
            step = _I3 + dt * C[sel]
            if m.mode == Mode.WATER:
                J = s["J"][idx] * np.linalg.det(step)
                s["J"][idx] = np.minimum(J, 1.0) if m.clamp_pressure else J
                continue
            Ft = step @ s["F"][idx]
            bad = np.linalg.det(Ft) <= 0.0
            if bad.any():
                Ft[bad] = uninvert(Ft[bad])
            if m.mode == Mode.SAND:
                s["F"][idx], s["Jp"][idx] = sand_project(m, Ft, s["Jp"][idx])
            elif m.plastic:
                s["F"][idx], s["Jp"][idx] = snow_clamp(m, Ft, s["Jp"][idx])
            else:
                s["F"][idx] = Ft


def cfl_dt(config: SolverConfig, wave_speed: float, vmax: float) -> float:
    """The solver's step rule, dt = cfl dx / (c + |v|max), for fixed-dt comparisons."""
    return config.cfl * config.dx / max(wave_speed + vmax, 1e-12)
