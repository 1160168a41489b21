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
def local_cluster(n_workers: int = 2) -> Iterator[Any]:
    """A LocalCluster of ``n_workers`` processes (1 thread each). The
    workers import sfanav (and the tests' loaders) from the same places;
    PYTHONPATH is restored afterwards so that later tests' subprocesses do
    not inherit it."""
    import distributed

    here = Path(__file__).resolve().parent
    saved = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join([SFANAV_ROOT, str(here)] + [
        p for p in (saved or "").split(os.pathsep) if p])
    try:
        cluster = distributed.LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                           dashboard_address=None, silence_logs=50)
        try:
            yield cluster
        finally:
            cluster.close()
    finally:
        if saved is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = saved
