"""The Warp modules a Solver launches kernels of, listed before it exists, so that a run can
compile them ahead, side by side, while it prepares the scene (mpmfx.stages.kernels).

Warp compiles a module, every kernel in it, the first time one of its kernels launches: the
solver's would otherwise compile one after another before its first frame. The specialised
kernels are made here by the same cached factories the Solver calls (so the Solver later finds
them made and their modules loaded); only the variants the scene uses are listed.
"""

from __future__ import annotations

from typing import Sequence

import warp as wp

from . import animated as animated_mod
from .bricks import fits_brick_keys
from .config import SolverConfig
from .emission import activate
from .energy import make_report
from .g2p import g2p_launch_shape, make_g2p
from .grid_update import make_grid_update
from .materials import Material
from .p2g import make_p2g
from .p2g_brick import BLOCK_CUDA, make_brick_scatter
from .state import SceneFlags
from .stepper import make_clock_kernels

__all__ = ["solver_modules"]

# modules of plain (unspecialised) kernels every run launches: the frame's read-back, the solid stress
STATIC = ("mpmfx.mpm.readback", "mpmfx.mpm.g2p")
# and those of the brick P2G's runs: its sort, the sparse grid clear (not mpmfx.mpm.order, which
# puts frames back in particle order: its kernel is generic, made for its types at the launch)
BRICK = ("mpmfx.mpm.bricks", "mpmfx.mpm.clear_grid")


def solver_modules(
    materials: Sequence[Material],
    config: SolverConfig,
    *,
    device=None,
    colliders: bool = False,
    animated: bool = False,
    emission: bool = False,
    variation: bool = False,
    stepper: str = "device",
) -> list:
    """(`warp.Module`, block_dim) of each Warp module a `Solver(materials, config, ...,
    device=device, stepper=stepper)` launches kernels of; block_dim: the threads a block its
    kernels launch with on a GPU (a module compiles for one), None for Warp's default.
    colliders: the scene has rigid colliders (posed on the device); animated: animated mesh
    colliders; emission: particles born late (emitters, late objects); variation: as Solver's."""
    # (by the device's name: the list is also made where no GPU is, to measure what one compiles)
    cuda = str(device if device is not None else wp.get_device()).startswith("cuda")
    flags = SceneFlags.of(materials, multi_field=config.multi_field, varied=variation, flip=config.flip)
    meshes = animated_mod.INSIDE_TEST if animated else ""
    dc = stepper == "device"
    # the brick P2G: chunked.DeviceAdvance's choice, on a GPU
    brick = dc and cuda and not flags.multi_field and flags.flip == 0.0 and fits_brick_keys(config.grid_n + 1)
    g2p = make_g2p(flags, device_clock=dc)
    # the frame's sums (make_report) share the module of the host clock's P2G
    kernels = [make_p2g(flags), make_report(flags), g2p]
    blocks = {g2p.module.name: g2p_launch_shape()[1]}  # module name -> block_dim, where not Warp's default
    names = list(STATIC)
    if dc:
        kernels += make_clock_kernels(flags.snow, flags.water)
    if not brick:  # the reference P2G and the grid update over every node
        kernels.append(make_grid_update(device_clock=dc, meshes=meshes))
    if dc and not brick:
        kernels.append(make_p2g(flags, device_clock=True))
    if brick:  # its scatter, the G2P of a substep that sorted, the sparse grid update
        scatter, g2p_sort = (
            make_brick_scatter(flags, bool(config.deterministic)),
            make_g2p(flags, device_clock=True, sorting=True),
        )
        sparse = make_grid_update(device_clock=True, sparse=True, clears=not flags.volume_recovery, meshes=meshes)
        kernels += [scatter, g2p_sort, sparse]
        blocks |= {scatter.module.name: BLOCK_CUDA, g2p_sort.module.name: g2p_launch_shape()[1]}
        names += BRICK
    if colliders and dc:
        names.append("mpmfx.mpm.stepper")
    if animated:
        names.append("mpmfx.mpm.animated")
    if emission:
        kernels.append(activate)
    modules = {k.module.name: k.module for k in kernels}
    for name in names:
        modules.setdefault(name, wp.get_module(name))
    return [(m, blocks.get(name)) for name, m in modules.items()]
