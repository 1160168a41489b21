"""Atomic file writes: a temporary file in the same directory, then
:func:`os.replace`, so an interrupted run never leaves a file that looks
complete."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any


def write_text_atomic(path: str | os.PathLike, text: str, *, overwrite: bool = True) -> Path:
    """Writes ``text`` (UTF-8) to ``path`` atomically and returns the path
    (see :func:`write_bytes_atomic` for the errors)."""
    return write_bytes_atomic(path, text.encode("utf-8"), overwrite=overwrite)


def write_bytes_atomic(path: str | os.PathLike, data: bytes, *, overwrite: bool = True) -> Path:
    """Writes ``data`` to ``path`` atomically (a temporary file in the same
    folder, flushed to disk, then renamed) and returns the path.

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``overwrite`` is false.
    FileNotFoundError
        If the parent directory does not exist.
    OSError
        If the folder cannot be written (it names ``path``, not the
        temporary file).
    """
    p = Path(path)
    if not p.parent.is_dir():
        raise FileNotFoundError(f"the folder {p.parent} for {p.name} does not exist")
    if p.exists() and not overwrite:
        raise FileExistsError(f"{p} exists; pass overwrite=True to replace it")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".part", dir=p.parent)
    except OSError as exc:  # name the file asked for, not the temporary one
        raise type(exc)(exc.errno, exc.strerror, str(p)) from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return p


def check_writable(path: str | os.PathLike) -> None:
    """Checks, before any work, that a file can be created beside ``path``
    (the folder exists and is writable: a probe file is made and removed),
    so that a command fails at once, not after computing what it would
    write. Raises the OSError, naming ``path``."""
    p = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".probe", dir=p.parent)
    except OSError as exc:
        raise type(exc)(exc.errno, exc.strerror, str(p)) from None
    os.close(fd)
    os.unlink(tmp)


def write_csv_atomic(path: str | os.PathLike, header: Sequence[str], rows: Iterable[Sequence[Any]], *,
                     overwrite: bool = True) -> Path:
    """Writes a CSV (``header``, then ``rows``, each a sequence of cells)
    atomically and returns the path (see :func:`write_bytes_atomic`)."""
    import csv
    import io

    buf = io.StringIO(newline="")
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    return write_text_atomic(path, buf.getvalue(), overwrite=overwrite)
