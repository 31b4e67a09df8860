"""Memory estimates checked before big allocations: refuse with the numbers, never swap or hang.

A run whose arrays would not fit raises :class:`MemoryLimitError` naming the estimate, the
limit and the option to change, before anything is allocated. The limit is the environment
variable ``SKYSIM_MEMORY_LIMIT_MB`` if set, else 80 % of the memory the operating system
reports as available (``MemAvailable`` in ``/proc/meminfo``; the physical memory elsewhere).
"""

from __future__ import annotations

import os

from .exceptions import InvalidParameterError

__all__ = ["MemoryLimitError", "check_memory", "format_count", "memory_limit_bytes"]

AVAILABLE_FRACTION = 0.8
"""Share of the available memory one run may plan to use (the rest: the interpreter,
libraries, other processes, temporaries the estimates leave out)."""


class MemoryLimitError(InvalidParameterError):
    """A run would need more memory than the limit; the message gives both and the fix."""


def _available_bytes() -> int:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def memory_limit_bytes() -> int:
    """The memory one run may plan to use [bytes] (see the module docstring).

    Raises
    ------
    InvalidParameterError
        If ``SKYSIM_MEMORY_LIMIT_MB`` is set but not a positive number.
    """
    env = os.environ.get("SKYSIM_MEMORY_LIMIT_MB")
    if env is not None:
        try:
            mb = float(env)
        except ValueError:
            mb = float("nan")
        if not mb > 0:
            raise InvalidParameterError(f"SKYSIM_MEMORY_LIMIT_MB must be a positive number of "
                                        f"MB; got {env!r}")
        return int(mb * 1e6)
    return int(AVAILABLE_FRACTION * _available_bytes())


def format_count(n) -> str:
    """A count for a message: exact up to 10^12, else three digits (``3.24e+305``)."""
    return str(int(n)) if n < 10**12 else f"{float(min(n, 10**300)):.3g}"


def _gib(n: float) -> str:
    return f"{n / 2**30:.3g} GiB" if n >= 2**30 else f"{n / 2**20:.3g} MiB"


def check_memory(nbytes: float, what: str, fix: str) -> None:
    """Raise :class:`MemoryLimitError` if ``nbytes`` exceeds :func:`memory_limit_bytes`.

    Parameters
    ----------
    nbytes : float
        Estimated peak memory of the planned step [bytes].
    what : str
        What would be allocated, e.g. ``"324000000 sky directions"``.
    fix : str
        How to make it fit, e.g. ``"use a coarser --grid-step"``.
    """
    limit = memory_limit_bytes()
    nbytes = float(min(nbytes, 10**300))   # sizes beyond a float (a step of 1e-300 deg)
    if nbytes > limit:
        raise MemoryLimitError(
            f"{what} would need about {_gib(nbytes)} of memory, more than the {_gib(limit)} "
            f"this run may use (80% of the available memory, or SKYSIM_MEMORY_LIMIT_MB); {fix}")
