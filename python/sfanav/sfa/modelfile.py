"""The sfanav model file: versioned, checksummed, pickle-free.

A model file is a ZIP archive (stored, uncompressed) with

* ``manifest.json``: ``{"format": "sfanav-model", "version": 1, "kind": ...,
  "sfanav_version": ..., "state": <JSON tree>, "arrays": {name: {"dtype",
  "shape", "sha256"}}, "digest": <sha256>}``. Arrays inside ``state`` are
  written as ``{"__array__": name}``.
* ``arrays/<name>.npy``: one NumPy ``.npy`` file per array, read back with
  ``allow_pickle=False``.

``digest`` is the SHA-256 of the canonical JSON of the manifest without the
digest itself; with the per-array SHA-256 it makes any truncation or
alteration an error on load (ValueError naming the problem). A file written
by a newer format version is refused with a message saying so. See
``docs/model-format.md``.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

FORMAT = "sfanav-model"


VERSION = 4  # the newest version this sfanav reads and writes (see docs/model-format.md)


_LOADERS: dict[str, Callable[[dict[str, Any]], Any]] = {}


def register_loader(kind: str, loader: Callable[[dict[str, Any]], Any]) -> None:
    """Registers the function that rebuilds an object of ``kind`` from its state."""
    _LOADERS[kind] = loader


def _split(obj: Any, arrays: dict[str, np.ndarray], path: str) -> Any:
    if isinstance(obj, np.ndarray):
        name = path or "root"
        arrays[name] = obj
        return {"__array__": name}
    if isinstance(obj, dict):
        for k in obj:
            if not isinstance(k, str) or "/" in k or k.startswith("__"):
                raise ValueError(f"cannot store state key {k!r}")
        return {k: _split(v, arrays, f"{path}/{k}" if path else k) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_split(v, arrays, f"{path}/{i}") for i, v in enumerate(obj)]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if obj is None or isinstance(obj, (bool, int, float, str)):
        if isinstance(obj, float) and not np.isfinite(obj):
            raise ValueError(f"cannot store non-finite value at {path}")
        return obj
    raise TypeError(f"cannot store {type(obj).__name__} at {path or 'root'}")


def _join(tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    if isinstance(tree, dict):
        if set(tree) == {"__array__"}:
            name = tree["__array__"]
            if name not in arrays:
                raise ValueError(f"model file is corrupted: array {name!r} is missing")
            return arrays[name]
        return {k: _join(v, arrays) for k, v in tree.items()}
    if isinstance(tree, list):
        return [_join(v, arrays) for v in tree]
    return tree


def _canonical(obj: Any) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def save_model(path: str | os.PathLike, kind: str, state: dict[str, Any], *, version: int = 1) -> Path:
    """Writes ``state`` (a tree of dicts, lists, scalars and arrays) as a
    model file of ``kind``. The write is atomic (temporary file + rename).
    ``version``: the format version the state needs (1 unless it uses
    something older readers cannot rebuild; at most :data:`VERSION`)."""
    if not 1 <= int(version) <= VERSION:
        raise ValueError(f"version must be 1 .. {VERSION}, got {version}")
    from .._core import __version__

    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a directory, not a model file path")
    arrays: dict[str, np.ndarray] = {}
    tree = _split(state, arrays, "")
    blobs: dict[str, bytes] = {}
    meta: dict[str, Any] = {}
    for name, arr in arrays.items():
        arr = np.ascontiguousarray(arr)
        if arr.dtype.kind not in "biuf":
            raise TypeError(f"array {name} has unsupported dtype {arr.dtype}")
        buf = io.BytesIO()
        np.save(buf, arr, allow_pickle=False)
        blob = buf.getvalue()
        blobs[name] = blob
        meta[name] = {
            "dtype": arr.dtype.str,
            "shape": list(arr.shape),
            "sha256": hashlib.sha256(blob).hexdigest(),
        }
    manifest = {
        "format": FORMAT,
        "version": int(version),
        "kind": kind,
        "sfanav_version": __version__,
        "state": tree,
        "arrays": meta,
    }
    manifest["digest"] = hashlib.sha256(_canonical(manifest)).hexdigest()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".sfanav-", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh, zipfile.ZipFile(fh, "w", zipfile.ZIP_STORED) as zf:
            zf.writestr("manifest.json", json.dumps(manifest, indent=1, sort_keys=True))
            for name, blob in blobs.items():
                zf.writestr(f"arrays/{name}.npy", blob)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def read_model(path: str | os.PathLike) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """Reads and verifies a model file; returns ``(kind, state, manifest)``."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no model file at {path}")
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a directory, not a model file")
    bad = f"{path} is not a valid sfanav model file"
    try:
        with zipfile.ZipFile(path, "r") as zf:
            try:
                manifest = json.loads(zf.read("manifest.json"))
            except KeyError:
                raise ValueError(f"{bad}: it has no manifest.json") from None
            if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
                raise ValueError(f"{bad}: unknown format {manifest.get('format')!r}")
            version = manifest.get("version")
            if isinstance(version, bool) or not isinstance(version, int):
                raise ValueError(f"{bad}: missing format version (an integer), got {version!r}")
            if version < 1:
                raise ValueError(f"{bad}: format version {version} does not exist (versions start at 1)")
            if version > VERSION:
                raise ValueError(
                    f"{path} uses model format version {version}, but this sfanav reads "
                    f"versions up to {VERSION}: upgrade sfanav"
                )
            digest = manifest.pop("digest", None)
            if digest != hashlib.sha256(_canonical(manifest)).hexdigest():
                raise ValueError(f"{bad}: the manifest was altered (checksum mismatch)")
            arrays: dict[str, np.ndarray] = {}
            for name, info in manifest["arrays"].items():
                try:
                    blob = zf.read(f"arrays/{name}.npy")
                except KeyError:
                    raise ValueError(f"{bad}: array {name!r} is missing") from None
                if hashlib.sha256(blob).hexdigest() != info["sha256"]:
                    raise ValueError(f"{bad}: array {name!r} was altered (checksum mismatch)")
                arr = np.load(io.BytesIO(blob), allow_pickle=False)
                if arr.dtype.str != info["dtype"] or list(arr.shape) != info["shape"]:
                    raise ValueError(f"{bad}: array {name!r} has the wrong dtype or shape")
                arrays[name] = arr
    except zipfile.BadZipFile as exc:
        raise ValueError(f"{bad} (truncated or corrupted: {exc})") from None
    except (KeyError, TypeError, AttributeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{bad}: malformed manifest ({exc})") from None
    except (zipfile.LargeZipFile, EOFError, OSError) as exc:
        if isinstance(exc, (FileNotFoundError, IsADirectoryError, PermissionError)):
            raise
        raise ValueError(f"{bad} (truncated or corrupted: {exc})") from None
    state = _join(manifest["state"], arrays)
    return manifest["kind"], state, manifest


def load(path: str | os.PathLike) -> Any:
    """Loads any sfanav model file (``SFA``, and later networks and localizers).

    Raises FileNotFoundError if the file does not exist and ValueError if it
    is not a valid, unaltered sfanav model file of a supported version.
    """
    kind, state, _ = read_model(path)
    loader = _LOADERS.get(kind)
    if loader is None:
        raise ValueError(f"{path} holds a model of unknown kind {kind!r}")
    return loader(state)
