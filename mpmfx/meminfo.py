"""The host memory a new allocation may take (standard library only)."""

from __future__ import annotations

import resource
import sys


def host_available() -> int | None:
    """MemAvailable of /proc/meminfo in bytes: what the kernel can give without swapping
    (None where there is no /proc/meminfo, e.g. macOS)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def peak_rss() -> int:
    """This process's peak resident memory in bytes since it started or since the last
    `reset_peak_rss` (VmHWM of /proc/self/status; elsewhere getrusage's ru_maxrss, never reset)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    scale = 1 if sys.platform == "darwin" else 1024  # bytes on macOS, KiB on Linux
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale


def reset_peak_rss() -> bool:
    """Start `peak_rss` again from the current resident memory (Linux 4.0+: "5" to
    /proc/self/clear_refs); False where it cannot be reset."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False
