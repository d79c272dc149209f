"""Which Warp modules hold the surfacer's kernels, and which of them a device loads.

Warp compiles a module whole, every kernel in it, the first time any one of them launches on a
device. The CPU-only kernels (the `*_by_block` passes, mpmfx.surface.variants) are therefore kept
in Warp modules of their own, named `<python module>_cpu` (`cpu_kernel`), so a GPU never compiles
them, and `device_modules` lists what a device loads: on a GPU every surfacer module but those.
"""

from __future__ import annotations

import warp as wp
from warp._src.context import user_modules  # (Warp's registry of modules, as its load_module reads it)

CPU_SUFFIX = "_cpu"  # the Warp modules of CPU-only kernels: "<python module>_cpu"
PACKAGE = "mpmfx.surface"


def cpu_kernel(fn):
    """`@wp.kernel` for a kernel only the CPU launches: forward only (nothing differentiates the
    surfacer), in the Warp module `<its python module>_cpu`."""
    return wp.kernel(fn, enable_backward=False, module=fn.__module__ + CPU_SUFFIX)


def device_modules(device) -> list:
    """The surfacer's Warp modules (`warp.Module`; those holding kernels, as functions compile
    into the modules that call them) that `device` launches kernels of: all on the CPU, all but
    the CPU-only ones on a GPU. Import mpmfx.surface first (it registers them)."""
    # (by the device's name: the list is also made where no GPU is, to measure what one compiles)
    cpu = not str(device if device is not None else wp.get_device()).startswith("cuda")
    return [
        m
        for name, m in list(user_modules.items())
        if name.startswith(PACKAGE + ".") and m.kernels and (cpu or not name.endswith(CPU_SUFFIX))
    ]
