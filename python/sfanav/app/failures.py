"""Which failures of an ``sfanav`` command are bad input (reported as one
line with exit status 2) and how they read; SIGTERM as an exception, so
that writers clean up as after Ctrl-C."""

from __future__ import annotations

from typing import Any


class UsageError(Exception):
    """A bad command line the argument parser cannot see (a missing file,
    an output that exists, ...)."""


# Failures that bad input causes (a file, a size, a config, a model): one line
# and EXIT_USAGE. RuntimeError covers the core's internal-error report and
# RecursionError; MemoryError a request the allocator refused.
INPUT_ERRORS = (UsageError, ValueError, TypeError, OSError, ImportError, KeyError, NotImplementedError,
                ArithmeticError, AttributeError, IndexError, RuntimeError, MemoryError, EOFError)


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that writers clean up."""


def on_sigterm(signum: int, frame: Any) -> None:
    raise Terminated()


def one_line(exc: BaseException) -> str:
    msg = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    if isinstance(exc, MemoryError):
        msg = f"out of memory{': ' + msg if msg else ''}"
    return " ".join(msg.split()) or type(exc).__name__


def _is_cv2_error(exc: BaseException) -> bool:
    return type(exc).__module__.startswith("cv2") and type(exc).__name__ == "error"


def is_input_error(exc: BaseException) -> bool:
    """Whether ``exc`` is a failure of bad input (one line, EXIT_USAGE),
    not a bug."""
    return isinstance(exc, INPUT_ERRORS) or _is_cv2_error(exc)
