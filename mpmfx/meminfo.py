"""The host memory a new allocation may take (standard library only)."""

from __future__ import annotations


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
