"""Progress bars and log lines for long work, in one place.

Every long-running call of sfanav takes ``progress: bool`` and shows a tqdm
bar while it runs; library code that reports a decision (an assumed camera
elevation, an unwarping mirror) takes a ``log`` callable, by default
:func:`stderr_log`.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

Log = Callable[[str], None]


def progress_bar(enabled: bool, total: int | None, desc: str, *, unit: str = "img") -> Any:
    """A tqdm bar (``leave=False``) of ``total`` steps, or None when
    ``enabled`` is false; callers ``update`` and ``close`` it."""
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, leave=False)


def stderr_log(message: str) -> None:
    """The default ``log``: one line on stderr."""
    print(message, file=sys.stderr, flush=True)


def quiet_log(message: str) -> None:
    """A ``log`` that drops every message."""
