"""mpmfx: meshes to simulated, surfaced and rendered MPM snow, sand, mud, water and jelly.

    import mpmfx
    mpmfx.load_shot("pipeline/shots/jelly_splash.toml").run(until="surface")

Importing mpmfx is cheap: warp, pxr, pyopenvdb and pyvista load only when a stage needs them.
"""

__version__ = "0.1.0"


def load_shot(path, **kwargs):
    """Load and validate a shot file -> `mpmfx.stages.runner.ShotRun` (see its docstring).

    The same schema and defaults as `mpmfx run`: a field the file leaves unset takes the
    schema's default, and the solver's defaults are `mpmfx.mpm.SolverConfig`'s own."""
    from mpmfx.stages.runner import load_shot as _load  # backend: warp (keeps import mpmfx light)

    return _load(path, **kwargs)
