"""Worker threads and the memory limit of the Rust core.

The core checks every request whose size follows from a caller's
dimensions (statistics matrices, expansions, networks, training) against a
memory limit before allocating, and refuses it with a ValueError naming
the size; by default the limit is the machine's physical memory, lowered
to what the process's address-space limit (``ulimit -v``) leaves.
"""

from __future__ import annotations

from typing import Any

from . import _core
from ._checks import check_int


def set_num_threads(n: int) -> None:
    """Sets the number of worker threads of the Rust core (0: one per core,
    the default). Raises TypeError for a non-integer, ValueError below 0.

    >>> import sfanav
    >>> sfanav.set_num_threads(1)
    >>> sfanav.get_num_threads()
    1
    >>> sfanav.set_num_threads(0)
    """
    _core.set_num_threads(check_int(n, "n", minimum=0))


def get_num_threads() -> int:
    """The number of worker threads the Rust core uses."""
    return _core.get_num_threads()


def set_memory_limit(limit: Any) -> None:
    """Sets the memory limit (bytes) that the Rust core checks its large
    requests against; ``None`` or 0 restores the automatic limit (physical
    memory, or what the address-space limit leaves). Raises TypeError for a
    non-integer, ValueError below 0.

    >>> import sfanav
    >>> sfanav.set_memory_limit(2 * 10**9)
    >>> sfanav.get_memory_limit()
    2000000000
    >>> sfanav.set_memory_limit(None)
    """
    _core.set_memory_limit(0 if limit is None else check_int(limit, "limit", minimum=0))


def get_memory_limit() -> int:
    """The memory limit (bytes) the Rust core checks its requests against now."""
    return _core.get_memory_limit()
