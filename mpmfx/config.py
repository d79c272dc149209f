"""The shot schema: one typed, validated model for a shot's TOML file.

World units everywhere in this file: metres, seconds, degrees. The solver's normalised domain
[0, 1]^3 (docs/physics.md, "The method") begins only when particles enter the solver;
`mpmfx.stages.simulate` maps. Material moduli are the exception: they are the presets' units
(docs/physics.md, "Materials"), defined in the normalised domain, so a preset looks the same in a
1 m box and a 10 m box. The field descriptions are the shot reference: `mpmfx docs --write`
renders them into docs/shots.md.

Errors name the file, the key and the fix: `ShotError("shot.toml: [solver].cfl: ...")`.
"""

from __future__ import annotations

import dataclasses
import enum
from pathlib import Path
from typing import Annotated, Literal

from pydantic import AllowInfNan, BaseModel, ConfigDict, Field, Strict, field_validator

from mpmfx.mpm.config import STANDARD_GRAVITY, SolverConfig, WallType
from mpmfx.mpm.materials import PRESETS, Mode
from mpmfx.render.looks import LOOKS

# Every number of the schema is one of these: finite (NaN or inf in a TOML file or a --set is a
# typo, never a setting) and strict (a quoted "0.3" is an error, not silently a number).
Real = Annotated[float, Strict(), AllowInfNan(False)]
Int = Annotated[int, Strict()]
Bool = Annotated[bool, Strict()]
Vec3 = tuple[Real, Real, Real]
_SOLVER = SolverConfig()  # the solver's defaults: the only ones (its docstring has the ranges)


class ShotError(ValueError):
    """A shot file that cannot run; the message names file, key and fix."""


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ShotInfo(_Section):
    name: str = Field(
        pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$",
        max_length=100,  # it names folders and files (with suffixes): far below a file system's 255
        description="Shot name; names the cache and renders/<name>/ (letters, digits, _ - ., not starting "
        "with '.'; at most 100 characters).",
    )
    frame_start: Int = Field(1, ge=0, description="First frame number (frame_start is the initial state, t = 0).")
    frame_end: Int = Field(48, ge=0, description="Last frame number, inclusive.")
    fps: Real = Field(24.0, gt=0, le=1000, description="Frames per second; one frame is 1/fps seconds.")


class Domain(_Section):
    origin: Vec3 = Field((-1.0, 0.0, -1.0), description="World position (m) of the domain's min corner.")
    size: Real = Field(2.0, gt=0, le=1.0e4, description="Edge of the cubic domain (m), at most 10 km.")
    grid_n: Int = Field(64, description="Grid cells per axis (8-4096, checked by the solver); dx = size / grid_n (m).")


class Variation(_Section):
    """Seeded noise on an object's material fields (docs/physics.md, "Variation"): a field's
    value at a particle is its material's value times exp(amplitude * n), n a smooth noise of
    unit standard deviation (clipped to +-3) at the particle's rest position."""

    youngs_modulus: Real = Field(
        0.0, ge=0, le=1, description="Amplitude on the stiffness (so mu and lambda); 0 = none."
    )
    hardening: Real = Field(0.0, ge=0, le=1, description="Amplitude on the snow's hardening; 0 = none.")
    friction_angle: Real = Field(
        0.0, ge=0, le=1, description="Amplitude on the sand's friction coefficient tan(friction_angle); 0 = none."
    )
    cohesion: Real = Field(0.0, ge=0, le=1, description="Amplitude on the sand's cohesion; 0 = none.")
    density: Real = Field(0.0, ge=0, le=1, description="Amplitude on the density (the particles' mass); 0 = none.")
    feature_size: Real = Field(
        gt=0,
        description="Size of the noise's features (m): its correlation length (correlation 0.61 at this distance).",
    )
    seed: Int = Field(0, ge=0, description="Noise seed; each field draws its own noise from it.")


class SceneObject(_Section):
    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", description="Object name (a USD prim name).")
    mesh: Path = Field(
        description="Mesh file (obj, ply, stl, glb, gltf, usd, usda, usdc, usdz, blend, fbx), "
        "relative to the shot file."
    )
    prim_path: str | None = Field(
        None,
        description="The part of the file taken: a USD prim whose meshes are taken, "
        "or a .blend / .fbx object or collection name; default: the whole file.",
    )
    material: str = Field(
        "Elastic",
        description="Material preset (Soft, Mushy, Goopy, Wet, Slush, Elastic, "
        'Granular, CohesiveGranular, Water, Tracer; docs/physics.md, "Materials").',
    )
    overrides: dict[str, Real | Bool | str] = Field(
        default_factory=dict,
        description='Material fields to change, e.g. {youngs_modulus = 3000} or {friction_fit = "compression"}.',
    )
    translate: Vec3 = Field((0.0, 0.0, 0.0), description="Translation (m), applied after rotate and scale.")
    rotate: Vec3 = Field((0.0, 0.0, 0.0), description="XYZ Euler rotation (degrees).")
    scale: Real = Field(1.0, gt=0, description="Uniform scale of the mesh file's units to metres.")
    velocity: Vec3 = Field((0.0, 0.0, 0.0), description="Initial linear velocity (m/s).")
    angular_velocity: Vec3 = Field((0.0, 0.0, 0.0), description="Initial angular velocity about the centroid (rad/s).")
    start_time: Real = Field(0.0, ge=0, description="Seconds from frame_start at which the object enters the shot.")
    variation: Variation | None = Field(
        None,
        description="Per-particle noise on the material, e.g. {youngs_modulus = 0.3, friction_angle = 0.1, "
        "feature_size = 0.05, seed = 7}; default: none (uniform material).",
    )


class Emitter(_Section):
    """A continuous source (a pour, a hose, a hopper): docs/physics.md, "Emitters and late entries"."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", description="Emitter name (a USD prim name).")
    shape: Literal["box", "sphere", "mesh"] = Field("box", description="Source volume: box, sphere or a mesh file.")
    size: Vec3 = Field((0.1, 0.1, 0.1), description="box: edge lengths (m).")
    radius: Real = Field(0.05, gt=0, description="sphere: radius (m).")
    mesh: Path | None = Field(None, description="mesh: a closed mesh file, relative to the shot file.")
    prim_path: str | None = Field(None, description="mesh: the part of the file taken (as for objects).")
    translate: Vec3 = Field((0.0, 0.0, 0.0), description="Translation (m) of the source, after rotate and scale.")
    rotate: Vec3 = Field((0.0, 0.0, 0.0), description="XYZ Euler rotation (degrees).")
    scale: Real = Field(1.0, gt=0, description="mesh: uniform scale of the file's units to metres.")
    material: str = Field("Water", description="Material preset (as for objects).")
    overrides: dict[str, Real | Bool | str] = Field(default_factory=dict, description="Material fields to change.")
    rate: Real = Field(gt=0, description="Volume emitted per second (m^3/s); mass per second = rate x density.")
    velocity: Vec3 = Field((0.0, 0.0, 0.0), description="Velocity of the emitted material (m/s).")
    start_time: Real = Field(0.0, ge=0, description="Seconds from frame_start at which emission starts.")
    end_time: Real = Field(gt=0, description="Seconds from frame_start at which emission stops.")
    seed: Int = Field(0, ge=0, description="Jitter seed of the emitted particles.")
    variation: Variation | None = Field(
        None,
        description="Per-particle noise on the emitted material, as for objects; sampled where a particle "
        "would be had the source moved back along the stream (its position less velocity x birth time, "
        "1 m/s down with no velocity), so a pour is not the same puff repeated; default: none.",
    )


class Thickness(str, enum.Enum):
    ERROR = "error"
    WARN = "warn"
    IGNORE = "ignore"


class Voxelise(_Section):
    ppc: Literal[1, 8, 27, 64] = Field(8, description="Particles per grid cell: a k*k*k jittered lattice.")
    seed: Int = Field(0, ge=0, description="Jitter seed; the same seed re-voxelises identically.")
    thickness: Thickness = Field(Thickness.WARN, description="What a failed five-cell thickness check does.")


WallName = Literal[tuple(w.value for w in WallType)]  # the names mpm.config.WallType declares


class ColliderShape(str, enum.Enum):
    PLANE = "plane"
    BOX = "box"
    SPHERE = "sphere"
    MESH = "mesh"


class Keyframe(_Section):
    time: Real = Field(ge=0, description="Seconds from frame_start.")
    translate: Vec3 = Field((0.0, 0.0, 0.0), description="Position (m) of the collider's origin.")
    rotate: Vec3 = Field((0.0, 0.0, 0.0), description="XYZ Euler rotation (degrees).")


class ColliderCfg(_Section):
    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", description="Collider name (a USD prim name).")
    shape: ColliderShape = Field(
        description="plane, box or sphere (analytic), or mesh (a file, as a signed distance grid)."
    )
    friction: Real = Field(0.3, ge=0, description="Coulomb friction coefficient.")
    normal: Vec3 = Field((0.0, 1.0, 0.0), description="plane: outward normal.")
    half_extents: Vec3 = Field((0.1, 0.1, 0.1), description="box: half extents (m).")
    radius: Real = Field(0.1, gt=0, description="sphere: radius (m).")
    mesh: Path | None = Field(None, description="mesh: file, relative to the shot file.")
    scale: Real = Field(1.0, gt=0, description="mesh: uniform scale.")
    animated: Bool = Field(
        False,
        description="mesh: the file's own animation moves and deforms it (USD time samples; .blend / .fbx "
        "as Blender evaluates them), sampled at every shot frame, met on the grid each substep; "
        "the keyframes move it further. The animation must cover the shot's frames.",
    )
    keyframes: list[Keyframe] = Field(
        default_factory=lambda: [Keyframe(time=0.0)], description="Rigid transform keys, interpolated per substep."
    )


class Solver(_Section):
    """The solver's knobs in world units. Defaults and ranges are `mpmfx.mpm.SolverConfig`'s
    (checked when the shot loads: `Shot.solver_config()`), so the CLI and the Python API agree."""

    cfl: Real = Field(_SOLVER.cfl, description="CFL number: dt = cfl * dx / (c_max + |v|_max), in (0, 1].")
    gravity: Vec3 = Field(
        (0.0, -STANDARD_GRAVITY, 0.0),
        description="Gravity (m/s^2, world), at most 1000 m/s^2 (100 g) in size; the solver sees it / domain.size.",
    )
    damping: Real = Field(
        _SOLVER.damping,
        description="Velocity decay rate (1/s): v *= 1 - damping*dt, so "
        "its effect per second does not depend on dt; without it elastic bodies ring on.",
    )
    drag: Real = Field(_SOLVER.drag, description="PIC blend as a rate (1/s), never a per-substep fraction.")
    flip: Real = Field(
        _SOLVER.flip,
        description="FLIP share of the particle velocity update, 0..1 (0: APIC; 0.9-0.99 keeps more motion, "
        "less numerical damping, more noise).",
    )
    time_scale: Real = Field(
        _SOLVER.time_scale,
        description="Playback speed: simulated seconds per shot "
        "second (the knob for faster action; gravity changes how material settles).",
    )
    walls: WallName | list[WallName] = Field(
        _SOLVER.walls[0].value, description="Domain walls: one type, or six for -x,+x,-y,+y,-z,+z."
    )
    wall_friction: Real = Field(_SOLVER.wall_friction, description="Coulomb friction at the walls.")
    wall_layer: Real = Field(
        _SOLVER.wall_layer,
        description="The layer over which a wall's friction acts (m, >= 0; a modelling choice): mu times "
        "the wall's normal impulse is shared by the material within it, so friction slows water alike on "
        "any grid. 0: only the nodes at the wall, whose layer thins as the grid refines.",
    )
    dt_max: Real = Field(_SOLVER.dt_max, description="Largest substep (s).")
    dt_min: Real = Field(_SOLVER.dt_min, description="Substep floor (s): below it the run stops with advice.")
    deterministic: Bool = Field(
        _SOLVER.deterministic, description="Fixed-point P2G: bit-identical replays and resumes on the same device."
    )
    multi_field: Bool = Field(_SOLVER.multi_field, description="One velocity field per object so bodies don't fuse.")
    contact_friction: Real = Field(
        _SOLVER.contact_friction, description="Coulomb friction between objects (multi_field)."
    )
    out_of_domain: Literal["clamp", "remove"] = Field(
        _SOLVER.out_of_domain.value,
        description="Particles reaching the domain edge: clamped in, or removed and counted in the QA.",
    )
    max_substeps_per_frame: Int = Field(
        _SOLVER.max_substeps_per_frame,
        description="A frame needing more substeps stops the run with advice (a runaway guard).",
    )
    max_particles: Int = Field(
        50_000_000, ge=1, description="Particle budget: objects and all emitted; over it, no simulation."
    )
    checkpoint_every: Int = Field(
        1,
        ge=1,
        description="Frames between full-state checkpoints (resume points; "
        "cheap enough for every frame; the last two are kept on disk).",
    )

    @field_validator("walls")
    @classmethod
    def _six_walls(cls, v):
        if isinstance(v, list) and len(v) != 6:
            raise ValueError("give one wall type or exactly six (-x,+x,-y,+y,-z,+z)")
        return v


class SurfaceGroup(str, enum.Enum):
    ALL = "all"
    MATERIAL = "material"
    OBJECT = "object"


class Surface(_Section):
    radius_scale: Real = Field(
        1.0,
        gt=0,
        description="Multiplier on the particle radius (0.6 x the spacing: mpmfx.surface.PARTICLE_RADIUS_PER_SPACING).",
    )
    voxel_size: Real | None = Field(None, gt=0, description="Level-set voxel (m); default half the particle spacing.")
    smooth_iters: Int = Field(
        8,
        ge=0,
        le=50,
        description="Level-set smoothing steps (mean-curvature flow along the surface; together they move the surface inward at most 0.3 x the particle spacing).",
    )
    dilate: Real = Field(0.0, description="Offset (m): + dilates, - erodes.")
    min_feature_particles: Int = Field(8, ge=0, description="Blobs of fewer particles are removed (specks).")
    group: SurfaceGroup = Field(SurfaceGroup.MATERIAL, description="One surface per material, per object, or one.")
    close_voids: Real = Field(
        0.0,
        ge=0,
        description="Radius (m) of a ball rolled over the surface before smoothing: "
        "fills the dents of sparse particles without rounding edges (~ the "
        "particle spacing; 0 = off; slower, random sheets get thicker).",
    )
    anisotropic: Bool = Field(
        False,
        description="Yu & Turk anisotropic kernels: thin sheets of water stay sheets "
        "(no holes); slower, and sharp box edges round off more.",
    )
    sharp_edges: Literal["auto"] | Bool = Field(
        "auto",
        description="Give convex edges and corners back the sharpness the particles lost there (the "
        "faces' planes meet again; outward only; round bodies come out as they were); false "
        "leaves them rounded as the particles' kernels make them; auto: on for every surface "
        "group without a fluid (water, tracers) in it, as a liquid holds no edge of its own. "
        "Works while smoothing: smooth_iters = 0 turns it off.",
    )
    density: Bool = Field(
        False,
        description="Also write a fog density grid (0..1, dimensionless: 1 in the bulk of "
        "the material) for granular / volume looks.",
    )


class Export(_Section):
    """The USD stage is always written (it is the stage's product); these add to it."""

    vdb: Bool = Field(True, description="Write per-frame .vdb level sets.")
    points: Bool = Field(True, description="Include particles as UsdGeomPoints.")


class RenderEngine(str, enum.Enum):
    CYCLES = "cycles"
    PREVIEW = "preview"


class Render(_Section):
    """How frames are drawn. `cycles`: Blender's path tracer on the exported USD stage (lit,
    shaded, per-material looks; Blender runs in its own process); `preview`: a fast PyVista
    viewport capture of the surfaces."""

    engine: RenderEngine = Field(
        RenderEngine.CYCLES, description="cycles (Blender, the look) or preview (PyVista, seconds a frame)."
    )
    device: Literal["cpu", "gpu"] = Field(
        "cpu",
        description="cycles: where Cycles renders; gpu: the first of OptiX, CUDA, HIP, oneAPI, Metal that "
        "Blender finds here, else the CPU, said in the run's output.",
    )
    width: Int = Field(960, ge=16, le=8192, description="Picture width (pixels).")
    height: Int = Field(540, ge=16, le=8192, description="Picture height (pixels).")
    samples: Int = Field(16, ge=1, le=65536, description="cycles: path-tracing samples per pixel.")
    denoise: Bool = Field(True, description="cycles: OpenImageDenoise on the finished frame.")
    shutter: Real = Field(
        0.5,
        ge=0,
        le=1,
        description="cycles: motion blur along the exported velocities, "
        "shutter open this fraction of a frame (0.5: a 180-degree shutter; 0: no blur).",
    )
    frame_step: Int = Field(
        1,
        ge=1,
        description="cycles: render every n-th frame; the frames between hold the last "
        "rendered one, so the movie keeps the shot's timing (preview draws every frame).",
    )
    looks: dict[str, str] = Field(
        default_factory=dict,
        description="cycles: look per preset, object or surface "
        'group, e.g. {Goopy = "mud"}, of a collider by its name, e.g. {glass = "glass"}, or of the '
        'basin, {basin = "glass"} (looks: mpmfx/render/looks.py).',
    )
    basin: Real | None = Field(
        None,
        gt=0,
        description="cycles: height (m) of a basin drawn along the solver's "
        "side walls (stone, or render.looks.basin), for a pool that the walls hold; default none.",
    )
    sun_elevation: Real = Field(35.0, ge=0, le=90, description="cycles: sun height above the horizon (degrees).")
    sun_rotation: Real = Field(150.0, description="cycles: sun direction about the up axis (degrees).")
    mode: Literal["surface", "particles"] = Field(
        "surface",
        description="surface: the surfaces; particles: every "
        "particle as a soft blob, the debug look for tuning motion.",
    )
    camera_position: Vec3 | None = Field(
        None,
        description="Camera position (m); default: cycles frames what was simulated, preview a 3/4 view of the domain.",
    )
    camera_look_at: Vec3 | None = Field(None, description="Camera target (m); default the domain centre.")
    movie: Bool = Field(True, description="Also write an mp4 of the frames.")

    @field_validator("looks")
    @classmethod
    def _known_looks(cls, v):
        bad = {k: look for k, look in v.items() if look not in LOOKS}
        if bad:
            raise ValueError(f"unknown look(s) {bad}: use one of {', '.join(LOOKS)}")
        return v


class Shot(_Section):
    shot: ShotInfo = Field(description="The shot's name and clock.")
    domain: Domain = Field(
        Domain(),
        description="The simulated box: a cube of `size` metres from `origin`, cut "
        "into grid_n cells per axis; the solver's walls (and floor) are planes 3 cells inside its faces.",
    )
    objects: list[SceneObject] = Field(default_factory=list, description="Meshes that become material, one table each.")
    emitters: list[Emitter] = Field(default_factory=list, description="Sources that emit material during the shot.")
    colliders: list[ColliderCfg] = Field(
        default_factory=list,
        description="Kinematic bodies the material hits: they push it and are not pushed back, and move by keyframes.",
    )
    voxelise: Voxelise = Field(Voxelise(), description="How meshes become particles.")
    solver: Solver = Field(Solver(), description="Time stepping, gravity, walls and contact.")
    surface: Surface = Field(Surface(), description="How particles become surfaces (level sets and meshes).")
    export: Export = Field(Export(), description="What the USD stage and the VDB files hold.")
    render: Render = Field(Render(), description="How frames are drawn.")
    # Not part of the schema's TOML (excluded from dumps and from docs/shots.md):
    base_dir: Path = Field(
        Path("."), exclude=True, description="Where the shot file lives; relative paths resolve from here."
    )
    source: Path | None = Field(None, exclude=True, description="The shot file, for messages.")
    overrides: tuple[str, ...] = Field((), exclude=True, description="The --set values it was loaded with.")

    @property
    def frames(self) -> range:
        return range(self.shot.frame_start, self.shot.frame_end + 1)

    def resolve(self, p: Path) -> Path:
        return p if p.is_absolute() else (self.base_dir / p).resolve()

    def solver_config(self) -> SolverConfig:
        """The solver's config in domain units: every `[solver]` knob that SolverConfig has, by
        name, plus grid_n, and gravity and wall_layer / domain.size (the solver's domain is [0, 1]^3). Raises SolverConfigError."""
        s = self.solver
        knobs = {f.name: getattr(s, f.name) for f in dataclasses.fields(SolverConfig) if f.name in Solver.model_fields}
        knobs |= {
            "grid_n": self.domain.grid_n,
            "gravity": tuple(g / self.domain.size for g in s.gravity),
            "wall_layer": s.wall_layer / self.domain.size,
            "walls": (s.walls,) * 6 if isinstance(s.walls, str) else tuple(s.walls),
        }
        return SolverConfig(**knobs)

    def wall_box(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(lo, hi) world corners (m) of the box the solver's walls hold material in: its walls
        are these planes (`SolverConfig.wall_planes`), the floor is y = lo[1]. Material rests on
        them; voxelise checks placements and renders draw the ground and the tank here."""
        lo, hi = self.solver_config().wall_planes
        o, size = self.domain.origin, self.domain.size
        return tuple(float(c + lo * size) for c in o), tuple(float(c + hi * size) for c in o)

    @property
    def bodies(self) -> list[SceneObject | Emitter]:
        """What becomes material, in the order a particle's `body` indexes: objects, then emitters."""
        return [*self.objects, *self.emitters]

    @property
    def particle_spacing(self) -> float:
        """Mean particle spacing h (m): dx / ppc^(1/3)."""
        return self.domain.size / self.domain.grid_n / self.voxelise.ppc ** (1 / 3)

    def fluid_objects(self) -> list[bool]:
        """Per object: is its material a fluid (a water or tracer preset)? A fluid holds no shape:
        no thickness rule (voxelise), no sharp edges by default (sharp_edges_for)."""
        by_name = {k.lower(): m for k, m in PRESETS.items()}
        return [
            o.material.lower() in by_name and by_name[o.material.lower()].mode in (Mode.WATER, Mode.TRACER)
            for o in self.bodies
        ]

    def sharp_edges_for(self, group: str) -> bool:
        """surface.sharp_edges for surface group `group` (one of surface_groups()): "auto" is on
        where none of the group's objects is a fluid; off without smoothing."""
        s = self.surface
        if s.smooth_iters == 0:
            return False
        if s.sharp_edges != "auto":
            return s.sharp_edges
        return not any(f for f, g in zip(self.fluid_objects(), self.surface_groups()) if g == group)

    def surface_groups(self) -> list[str]:
        """Per object, the surface group it belongs to: its material preset name, its own
        name, or 'all' (`surface.group`)."""
        g = self.surface.group
        if g is SurfaceGroup.OBJECT:
            return [o.name for o in self.bodies]
        if g is SurfaceGroup.MATERIAL:
            return [o.material for o in self.bodies]
        return ["all" for _ in self.bodies]
