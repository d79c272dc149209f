"""`mpmfx status SHOT --qa`: the simulation's per-frame observables, with suspicious frames flagged."""

from __future__ import annotations

import math
import sys

MASS_TOL = 1e-4  # relative change of total mass that counts as "mass changed"
ENERGY_JUMP = 1.5  # kinetic + elastic energy growing by more than this factor in one frame ...
SPEED_SLACK = 2.0  # ... while the top speed grew faster than SPEED_SLACK x gravity alone allows
CFL_CAP = 1.0  # SolverConfig's upper bound on cfl: past it a particle outran a cell in a substep


def flags(
    qa: dict[int, dict], *, gravity: float = 9.81, frame_dt: float = 1 / 24, entering_speed: float = 0.0
) -> dict[int, list[str]]:
    """Frame -> reasons it looks wrong (mass changed, energy jumped, particles lost, rejected substeps).

    Energy released by gravity is not a jump: a frame is flagged only when kinetic + elastic
    energy grew ENERGY_JUMP-fold and the top speed (m/s) grew faster than gravity (m/s^2) can
    explain over frame_dt (s), from the faster of the last frame's top speed and entering_speed
    (m/s: what emitters and late objects bring in, which gravity then speeds up)."""
    out: dict[int, list[str]] = {}
    frames = sorted(qa)
    m0 = qa[frames[0]].get("mass") if frames else None
    prev = None
    for f in frames:
        q, why = qa[f], []
        m_ref = q.get("mass_entered", m0)  # (a shot with emitters or late objects gains mass as they enter)
        if m_ref and q.get("mass") is not None and abs(q["mass"] - m_ref) > MASS_TOL * abs(m_ref):
            why.append(f"mass changed {100 * (q['mass'] - m_ref) / m_ref:+.3f} %")
        ke = (q.get("kinetic_energy") or 0.0) + (q.get("elastic_energy") or 0.0)
        speed = q.get("max_speed") or 0.0
        if (
            prev is not None
            and prev[0] > 1e-12
            and ke > ENERGY_JUMP * prev[0]
            and speed > max(prev[1], entering_speed) + SPEED_SLACK * gravity * frame_dt
        ):
            why.append(f"energy x{ke / prev[0]:.1f} beyond what gravity explains")
        if q.get("j_min") is not None and q["j_min"] <= 0:
            why.append(f"inverted particles (J min {q['j_min']:.3g})")
        if q.get("cfl_used") is not None and q["cfl_used"] > CFL_CAP:
            why.append(f"CFL {q['cfl_used']:.2g} above the cap {CFL_CAP:g} (material outran the grid)")
        if q.get("inverted"):
            why.append(f"{q['inverted']} inverted particle-substeps mirrored back")
        if q.get("particles_lost"):
            why.append(f"{q['particles_lost']} particles lost")
        if q.get("rejected_substeps"):
            why.append(f"{q['rejected_substeps']} substeps rejected")
        if why:
            out[f] = why
        prev = (ke, speed)
    return out


def shot_flags(shot, qa: dict) -> dict[int, list[str]]:
    """`flags` of a simulate manifest's QA (frame keys may be strings), with the shot's gravity."""
    qa = {int(k): v for k, v in qa.items()}
    return flags(
        qa,
        gravity=float(sum(g * g for g in shot.solver.gravity) ** 0.5),
        frame_dt=shot.solver.time_scale / shot.shot.fps,
        entering_speed=max(
            [_speed(e.velocity) for e in shot.emitters]
            + [_speed(o.velocity) for o in shot.objects if o.start_time > 0]
            + [0.0]
        ),
    )


def _speed(v) -> float:
    return float(sum(c * c for c in v) ** 0.5)


def warn_flags(bad: dict[int, list[str]], shot_path: str = "SHOT") -> None:
    """Say flagged frames on stderr at run time (they are easy to miss in `status --qa`)."""
    if not bad:
        return
    print(
        f"[simulate] warning: QA flags {len(bad)} frame(s); the result may not be physical "
        f"(`mpmfx status {shot_path} --qa` has the table):",
        file=sys.stderr,
    )
    for f, why in sorted(bad.items())[:10]:
        print(f"  frame {f}: {'; '.join(why)}", file=sys.stderr)
    if len(bad) > 10:
        print(f"  ... and {len(bad) - 10} more", file=sys.stderr)


def print_qa(run) -> int:
    entry = run.entries()["simulate"]
    man = entry.manifest()
    if not man or not man.get("qa"):
        print("no simulation QA yet: run the shot first")
        return 1
    qa = {int(k): v for k, v in man["qa"].items()}
    bad = shot_flags(run.shot, qa)
    widths = [max(len(c), len(u), 10) for c, u in QA_COLUMNS.items()]
    print("frame  " + "  ".join(f"{c:>{w}}" for c, w in zip(QA_COLUMNS, widths)) + "  flags")
    print("       " + "  ".join(f"{u:>{w}}" for u, w in zip(QA_COLUMNS.values(), widths)))
    for f in sorted(qa):
        vals = [qa[f].get(c) for c in QA_COLUMNS]
        cells = [
            f"{v:{w}.4g}"
            if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            else f"{'-' if v is None else str(v):>{w}}"
            for v, w in zip(vals, widths)
        ]
        print(f"{f:5d}  " + "  ".join(cells) + "  " + "; ".join(bad.get(f, [])))
    print(
        f"frame {min(qa)} is the initial state (no step). Mass and energies are in the solver's domain units "
        f"(the presets' units: density x domain^3, x domain^2/s^2), comparable frame to frame."
    )
    return 0


# what `status --qa` prints, with units: "domain" = the solver's normalised domain (docs/physics.md)
QA_COLUMNS = {
    "mass": "domain",
    "kinetic_energy": "domain",
    "elastic_energy": "domain",
    "j_min": "1",
    "j_max": "1",
    "max_speed": "m/s",
    "substeps": "count",
    "rejected_substeps": "count",
    "cfl_used": "1 (cap 1)",
}
