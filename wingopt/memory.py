"""What memory this process may use now (the limit of :func:`wingopt.resources.check`)."""

from __future__ import annotations

import os

__all__ = ["available_memory", "BASE_BYTES"]

BASE_BYTES = 150e6
"""Interpreter, numpy/scipy/cvxpy imports and small arrays (measured ~150 MB)."""


def available_memory() -> float:
    """Bytes this process may use now: the least of ``MemAvailable`` (total physical memory where
    unknown), the address-space limit (``ulimit -v``, less what is mapped already) and the cgroup's
    memory limit (less its current use)."""
    avail = float("inf")
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = float(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if avail == float("inf"):
        try:
            avail = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
        except (ValueError, OSError, AttributeError):
            pass
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY and soft > 0:
            avail = min(avail, max(soft - _mapped_bytes(), 0.0) + BASE_BYTES)
    except (ImportError, OSError, ValueError):
        pass
    for limit_file, usage_file in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
    ):
        try:
            text = open(limit_file).read().strip()
            if text.isdigit() and int(text) < 1 << 60:
                used = float(open(usage_file).read().strip())
                avail = min(avail, max(float(text) - used, 0.0) + BASE_BYTES)
            break
        except (OSError, ValueError):
            continue
    return avail


def _mapped_bytes() -> float:
    """Virtual memory this process maps now (what counts against ``ulimit -v``)."""
    try:
        with open("/proc/self/statm") as fh:
            return float(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError, AttributeError):
        return 0.0
