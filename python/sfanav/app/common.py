"""Helpers the ``sfanav`` subcommands share: where messages go, how paths
given on the command line are checked, how a model file is opened, and how
tables are printed."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from .failures import UsageError

if TYPE_CHECKING:
    from pathlib import Path


def log(message: str) -> None:
    """Progress and notes go to stderr; results to stdout."""
    print(message, file=sys.stderr, flush=True)


def existing_path(text: str, what: str) -> "Path":
    """``text`` as a path that exists; else a UsageError naming ``what``."""
    from pathlib import Path

    p = Path(text)
    if not p.exists():
        raise UsageError(f"{what} {text} does not exist")
    return p


def new_file(text: str, overwrite: bool, what: str = "output") -> "Path":
    """``text`` as the path of a file to write (its folder made): a
    UsageError if it exists without ``overwrite`` or is a directory, or if
    its folder cannot be written (checked now, before the command works
    for minutes to fill it)."""
    from pathlib import Path

    from .._files import check_writable

    p = Path(text)
    if p.exists() and not overwrite:
        raise UsageError(f"{what} {p} exists; pass --overwrite to replace it")
    if p.exists() and p.is_dir():
        raise UsageError(f"{what} {p} is a directory")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        check_writable(p)
    except OSError as exc:
        raise UsageError(f"cannot write the {what} {p}: {exc.strerror or exc}") from None
    return p


def load_localizer(path: str, *, landmarks: bool = False) -> "Any":
    """The localizer in the model file ``path``: a UsageError if the file
    is missing, holds something else, or has no network to read images.
    ``landmarks``: a landmark model (:class:`sfanav.landmarks.LandmarkLocalizer`)
    is accepted too."""
    from .. import load
    from ..landmarks.model import LandmarkLocalizer
    from ..localization.localizer import Localizer

    model = load(existing_path(path, "model file"))
    if isinstance(model, LandmarkLocalizer):
        if not landmarks:
            raise UsageError(f"{path} is a landmark model (sfanav train --landmarks): it localizes with sfanav "
                             "localize and evaluate, not here")
        return model
    if not isinstance(model, Localizer):
        raise UsageError(f"{path} holds a {type(model).__name__}, not a localizer (make one with sfanav train)")
    if model.network is None:
        raise UsageError(f"{path} is a features-only localizer (no network): it cannot read images")
    return model


def mirror_of(args: argparse.Namespace, loc: "Any") -> "Any":
    """--mirror, else the mirror the model was trained with (if it unwarped)."""
    if args.mirror is not None:
        return args.mirror
    m = (loc.info or {}).get("mirror")
    if m is not None:
        log("using the mirror the model was trained with (--mirror overrides it)")
    return m


def wrap(text: str) -> str:
    """A help description wrapped to 79 columns (the raw formatter keeps
    the examples in the epilogs as written)."""
    import textwrap

    return textwrap.fill(" ".join(text.split()), 79)


def table(rows: "list[tuple[str, str]]") -> str:
    """Two columns, the first padded to its widest entry."""
    w = max(len(a) for a, _ in rows)
    return "\n".join(f"{a:<{w}}  {b}" for a, b in rows)


def fmt(v: "Any") -> str:
    """A table cell: "-" for None, four significant digits for a float."""
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)
