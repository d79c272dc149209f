"""Material table: the constitutive constants of each material row (docs/physics.md, "Materials").

A material is a row of constants plus a mode that picks the stress function and the
yield surface. Units follow the solver's normalised domain: lengths in domain
units (the simulation box is [0,1]^3), time in seconds, density in mass per domain
unit^3, so moduli are in mass / (domain unit * s^2). With density 1 the numbers of
the material table of the tutorial "Material Point Method: Step by Step" (E = 1500 for Soft) are used as is.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass

__all__ = ["Mode", "Material", "PRESETS", "VARIED_FIELDS", "VARIED_BY_MODE", "preset"]


class Mode(enum.IntEnum):
    """Constitutive branch of a material (the `mode` column of the presets' table)."""

    SNOW = 0  # fixed-corotated elasticity + Stomakhin singular-value clamp (+ hardening)
    SAND = 1  # Drucker-Prager on Hencky strain (Klar et al. 2016)
    WATER = 2  # weakly compressible Tait fluid: pressure only, tracks J not F
    TRACER = 3  # massless marker: takes the grid velocity of the material around it and
    # exerts nothing; in empty space (no material nodes) it stands still


@dataclass(frozen=True)
class Material:
    """One row of the material table.

    Attributes:
        mode: constitutive branch, see :class:`Mode`.
        youngs_modulus: E, mass/(domain*s^2) (snow, sand). Stiffness of elastic rebound;
            raising it costs time step (dt ~ 1/sqrt(E)) and buys ringing, not hardness
            (hardness comes from cohesion).
        poisson_ratio: nu, dimensionless, in [0, 0.5).
        density: rest density rho0, mass/domain^3. Particle mass = rest volume * density.
        hardening: xi, dimensionless; moduli scale by exp(xi * (1 - Jp)) (snow). 0 = off.
        theta_c: critical compression, dimensionless; singular values are clamped to
            >= 1 - theta_c (snow). The Elastic preset uses 1e9 so the clamp never fires.
        theta_s: critical stretch, dimensionless; singular values <= 1 + theta_s (snow).
        jp_min: lower clamp of the plastic volume ratio Jp (snow), dimensionless.
        jp_max: upper clamp of Jp (snow), dimensionless.
        friction_angle: the sand's friction angle, degrees: the angle of repose under
            the default fit; see friction_fit.
        friction_fit: how friction_angle sets the Drucker-Prager cone (sand). Default
            "repose" (below): the tutorial's promise "friction angle = angle of repose",
            measured against column-collapse experiments (docs/physics.md, "Validation").
            "compression" (Klar et al. 2016's alpha formula): the outer cone, exact in triaxial
            compression; in plane-strain flow (a slab, a dam, a chute: anything that flows
            in a plane) it is as strong as Mohr-Coulomb at a much larger angle (asin of
            2 sqrt(3) sin(phi) / (3 - sin(phi)): 63.5 deg for phi = 38, 43.9 deg for 30), so
            such flows stop short. "plane_strain": exact for plane-strain flow at zero
            dilatancy (sqrt(J2) = p sin(phi)): Mohr-Coulomb's static strength; a flowing
            layer stops on slopes below atan(sin(phi)) (31.6 deg for phi = 38).
            "repose": friction_angle is read as the material's angle of repose, as
            experiments quote it: friction coefficient mu = tan(phi) = sqrt(J2) / p in
            simple shear, the convention of granular rheology (Jop, Forterre & Pouliquen
            2006; Dunatunga & Kamrin 2015 use it in MPM). Same cone as "plane_strain" at
            asin(tan(phi)); needs phi < 45 deg. Runouts of column collapses match Lube et
            al. 2005 (sands) at 32 deg and Lajeunesse et al. 2005 (glass beads) at 24-28.
        cohesion: tensile strength of the sand cone, as a volumetric Hencky (log) strain
            the grains sustain before they separate (dimensionless; 0 = dry sand). The
            cone apex moves from tr(log strain) = 0 to tr = cohesion.
        volume_correction: sand only; remember the volume expansion discarded at the
            cone apex (stored in Jp as a log strain) so a re-compacted pile does not stay
            fluffed (Tampubolon et al. 2017).
        bulk_modulus: Tait bulk modulus K, mass/(domain*s^2) (water):
            p = K * (J^-gamma - 1).
        eos_gamma: Tait exponent gamma, dimensionless (water).
        volume_recovery: water only; grid volume recovery, for a fluid level that slowly
            drops. J integrated through det(I + dt C) does not see particles packing
            closer under shear, so the level sinks while J stays ~1. With this on, every
            substep also measures J from the grid, J_grid = density / (grid density at the
            particle), and relaxes J toward min(J_grid, 1) at `volume_recovery_rate`, where
            every node of the particle's stencil is at least half full. A free surface looks
            like expansion to the grid, so the top ~1.5 cells are left alone (and the target
            is capped at 1). It restores volume lost by packing; it does not remove volume
            gained by aeration (stirred water trapping one-cell voids: the grid cannot tell
            those from a surface). The grid density counts every material sharing the
            velocity field: next to a solid of another density use multi_field.
        volume_recovery_rate: 1/s, how fast J relaxes toward the grid's J (a rate, so the
            result does not depend on dt): J += (J_grid - J) * (1 - exp(-rate * dt)).
        clamp_pressure: water only; clamp the pressure to p >= 0 so water in tension
            does not clump into strings.
    """

    mode: Mode
    youngs_modulus: float = 1500.0
    poisson_ratio: float = 0.2
    density: float = 1.0
    hardening: float = 0.0
    theta_c: float = 2.5e-2
    theta_s: float = 7.5e-3
    jp_min: float = 0.6
    jp_max: float = 20.0
    friction_angle: float = 38.0
    friction_fit: str = "repose"
    cohesion: float = 0.0
    volume_correction: bool = True
    bulk_modulus: float = 100.0
    eos_gamma: float = 7.0
    volume_recovery: bool = False
    volume_recovery_rate: float = 10.0
    clamp_pressure: bool = True

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "mode", Mode(self.mode))
        except ValueError:
            raise ValueError(
                f"Material.mode: {self.mode!r} is not a mode; use one of {', '.join(m.name for m in Mode)}"
            ) from None
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.type in ("float", "bool") and not isinstance(value, (int, float)):
                raise ValueError(f"Material.{f.name} = {value!r}: give a {f.type}")
        checks = [
            ("youngs_modulus", self.youngs_modulus > 0, "must be > 0"),
            ("poisson_ratio", 0.0 <= self.poisson_ratio < 0.5, "must be in [0, 0.5)"),
            ("density", self.density > 0, "must be > 0"),
            ("hardening", self.hardening >= 0, "must be >= 0"),
            ("theta_c", 0 < self.theta_c, "must be > 0"),
            ("theta_s", 0 < self.theta_s, "must be > 0"),
            ("jp_min", 0 < self.jp_min <= 1.0 <= self.jp_max, "needs 0 < jp_min <= 1 <= jp_max"),
            ("friction_angle", 0 <= self.friction_angle < 90, "must be in [0, 90) degrees"),
            ("cohesion", self.cohesion >= 0, "must be >= 0"),
            ("bulk_modulus", self.bulk_modulus > 0, "must be > 0"),
            ("eos_gamma", self.eos_gamma >= 1, "must be >= 1"),
            ("volume_recovery_rate", self.volume_recovery_rate >= 0, "must be >= 0 (a rate, 1/s)"),
        ]
        if self.friction_fit not in FRICTION_FITS:
            raise ValueError(f"Material.friction_fit = {self.friction_fit!r}: use one of {', '.join(FRICTION_FITS)}")
        if self.friction_fit == "repose" and not self.friction_angle < 45.0:
            raise ValueError(
                f'Material.friction_angle = {self.friction_angle!r} with friction_fit = "repose": '
                "an angle of repose must be < 45 degrees (tan(phi) is the friction coefficient)"
            )
        for name, ok, what in checks:
            value = getattr(self, name)
            if not (ok and math.isfinite(float(value))):
                raise ValueError(f"Material.{name} = {value!r} {what}")

    @property
    def mu0(self) -> float:
        """Lame shear modulus mu = E / (2 (1 + nu)), unhardened."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def lambda0(self) -> float:
        """Lame first parameter lambda = E nu / ((1 + nu)(1 - 2 nu)), unhardened."""
        nu = self.poisson_ratio
        return self.youngs_modulus * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))

    @property
    def dp_alpha(self) -> float:
        """Drucker-Prager cone parameter alpha: the yield surface is |dev tau| = -alpha tr tau
        (Klar et al. 2016), i.e. sqrt(J2) = (3 / sqrt(2)) alpha p. friction_fit "compression":
        alpha = sqrt(2/3) 2 sin(phi) / (3 - sin(phi)) (Mohr-Coulomb in triaxial compression);
        "plane_strain": alpha = sqrt(2) sin(phi) / 3 (Mohr-Coulomb in plane-strain flow at
        zero dilatancy, where the cone's non-dilatant return map puts the stress);
        "repose": alpha = sqrt(2) tan(phi) / 3 (sqrt(J2) / p = tan(phi) in simple shear)."""
        phi = math.radians(self.friction_angle)
        s = math.sin(phi)
        if self.friction_fit == "plane_strain":
            return math.sqrt(2.0) * s / 3.0
        if self.friction_fit == "repose":
            return math.sqrt(2.0) * math.tan(phi) / 3.0
        return math.sqrt(2.0 / 3.0) * 2.0 * s / (3.0 - s)

    @property
    def plastic(self) -> bool:
        """False when the snow clamp can never fire (Elastic preset: thetas >= 1e8)."""
        return not (self.theta_c >= 1e8 and self.theta_s >= 1e8)

    def wave_speed(self, *, hardening_factor: float = 1.0, j_min: float = 1.0) -> float:
        """Dilatational wave speed c, domain/s, for the CFL time step
        (docs/physics.md, "The method").

        hardening_factor: current exp(xi (1 - Jp)) of the stiffest particle (snow).
        j_min: smallest current volume ratio J (water; Tait stiffens under compression).
        """
        if self.mode == Mode.TRACER:
            return 0.0
        if self.mode == Mode.WATER:
            k_eff = self.bulk_modulus * self.eos_gamma * max(j_min, 1e-4) ** (-self.eos_gamma)
            return math.sqrt(k_eff / self.density)
        stiff = (self.lambda0 + 2.0 * self.mu0) * hardening_factor
        return math.sqrt(stiff / self.density)


FRICTION_FITS = ("compression", "plane_strain", "repose")  # see Material.friction_fit

_ELASTIC_YIELD = 1e9  # thetas this large mean "the clamp never fires"

PRESETS: dict[str, Material] = {
    # The material table of the tutorial "Material Point Method: Step by Step", verbatim:
    # name -> (mode, E, hardening, extras)
    "Soft": Material(Mode.SNOW, youngs_modulus=1500.0, hardening=4.0),
    "Mushy": Material(Mode.SNOW, youngs_modulus=600.0, hardening=2.0),
    "Goopy": Material(Mode.SNOW, youngs_modulus=250.0, hardening=1.0),
    "Wet": Material(Mode.SNOW, youngs_modulus=150.0, hardening=0.7),
    "Slush": Material(Mode.SNOW, youngs_modulus=90.0, hardening=0.5),
    "Elastic": Material(
        Mode.SNOW, youngs_modulus=1200.0, hardening=0.0, theta_c=_ELASTIC_YIELD, theta_s=_ELASTIC_YIELD
    ),
    "Granular": Material(Mode.SAND, youngs_modulus=400.0, hardening=0.0, friction_angle=38.0),
    "CohesiveGranular": Material(Mode.SAND, youngs_modulus=400.0, hardening=0.0, friction_angle=38.0, cohesion=0.0006),
    "Water": Material(Mode.WATER, bulk_modulus=100.0),
    "Tracer": Material(Mode.TRACER),
}


VARIED_FIELDS = ("youngs_modulus", "hardening", "friction_angle", "cohesion", "density")
"""The columns of a particle's variation multipliers, in order. Each multiplies the material's
field, except friction_angle's, which multiplies the friction coefficient tan(friction_angle):
any factor > 0 keeps the angle in [0, 90) degrees."""

VARIED_BY_MODE = {
    Mode.SNOW: ("youngs_modulus", "hardening", "density"),
    Mode.SAND: ("youngs_modulus", "friction_angle", "cohesion", "density"),
}
"""The fields a mode has a use for (water and tracers: none)."""


def preset(name: str, **overrides) -> Material:
    """Return the preset `name` (case-insensitive) with `overrides` applied.

    Raises ValueError naming the unknown preset or field and listing the valid ones.
    """
    lookup = {k.lower(): k for k in PRESETS}
    key = lookup.get(str(name).lower())
    if key is None:
        raise ValueError(f"unknown material preset {name!r}; valid presets: {', '.join(PRESETS)}")
    fields = [f.name for f in dataclasses.fields(Material)]
    unknown = sorted(set(overrides) - set(fields))
    if unknown:
        raise ValueError(
            f"unknown Material field(s) {', '.join(unknown)} in overrides for preset {key!r}; "
            f"valid fields: {', '.join(fields)}"
        )
    return dataclasses.replace(PRESETS[key], **overrides)
