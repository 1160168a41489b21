"""A Dask LocalCluster for the distributed-training tests: worker processes
that import the sfanav under test (and these test helpers)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from clitools import SFANAV_ROOT


@contextlib.contextmanager
def local_cluster(n_workers: int = 2, *, dask_malloc_default: bool = False) -> Iterator[Any]:
    """A LocalCluster of ``n_workers`` processes (1 thread each), started
    as docs/distributed.md recommends. The workers import sfanav (and the
    tests' loaders) from the same places; PYTHONPATH is restored afterwards
    so that later tests' subprocesses do not inherit it.
    ``dask_malloc_default``: keep Dask's MALLOC_TRIM_THRESHOLD_ (which the
    nanny also leaves in this process's environment: removed afterwards)."""
    import dask
    import distributed

    here = Path(__file__).resolve().parent
    saved = os.environ.get("PYTHONPATH")
    saved_malloc = os.environ.get("MALLOC_TRIM_THRESHOLD_")
    os.environ["PYTHONPATH"] = os.pathsep.join([SFANAV_ROOT, str(here)] + [
        p for p in (saved or "").split(os.pathsep) if p])
    try:
        # without Dask's MALLOC_TRIM_THRESHOLD_ in the workers (it halves the core's speed; docs/distributed.md)
        malloc = {} if dask_malloc_default else {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
        with dask.config.set(malloc):
            cluster = distributed.LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                               dashboard_address=None, silence_logs=50)
        try:
            yield cluster
        finally:
            cluster.close()
    finally:
        if saved_malloc is None:
            os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)
        if saved is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = saved
