"""Thread policy for small-matrix optimisation loops: one BLAS thread (see
:func:`one_blas_thread`)."""

from __future__ import annotations


def one_blas_thread():
    """One BLAS thread for the optimisation loops: their matrices are tiny, and
    scipy's L-BFGS-B calls BLAS on vectors of a few hundred entries thousands
    of times, where thread start-up dominates (measured in docs/odometry.md).
    A context manager; a no-op without threadpoolctl."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")
