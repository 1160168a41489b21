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
by a newer format version is refused with a message saying so.

Reading is bounded: every entry must be stored uncompressed (so no entry can
expand beyond the file's own size), arrays must hold exactly the bytes their
header declares and only finite numbers, and the JSON tree may nest at most
:data:`MAX_DEPTH` levels. Any malformed file, including one whose checksums
were recomputed after an edit, ends in a ValueError naming the file and the
problem. See ``docs/model-format.md`` and ``docs/security.md``.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .._files import write_bytes_atomic

FORMAT = "sfanav-model"


VERSION = 8  # the newest version this sfanav reads and writes (see docs/model-format.md)

MAX_DEPTH = 64  # deepest nesting of the manifest's JSON tree


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


def dumps(kind: str, state: dict[str, Any], *, version: int = 1) -> bytes:
    """``state`` (a tree of dicts, lists, scalars and arrays) as the bytes
    of a model file of ``kind``: what :func:`save_model` writes and
    :func:`loads` reads (and what ``to_bytes`` of the models returns, for
    shipping them between processes without pickle).

    Raises
    ------
    ValueError
        For a ``version`` outside 1 .. :data:`VERSION` or an array with NaN
        or infinity.
    TypeError
        For an array of another dtype than bool, integer or float.
    """
    if not 1 <= int(version) <= VERSION:
        raise ValueError(f"version must be 1 .. {VERSION}, got {version}")
    from .._core import __version__

    arrays: dict[str, np.ndarray] = {}
    tree = _split(state, arrays, "")
    blobs: dict[str, bytes] = {}
    meta: dict[str, Any] = {}
    for name, arr in arrays.items():
        arr = np.ascontiguousarray(arr)
        if arr.dtype.kind not in "biuf":
            raise TypeError(f"array {name} has unsupported dtype {arr.dtype}")
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise ValueError(f"cannot store array {name}: it holds NaN or infinity")
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
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as zf:
        zf.writestr("manifest.json", json.dumps(manifest, indent=1, sort_keys=True))
        for name, blob in blobs.items():
            zf.writestr(f"arrays/{name}.npy", blob)
    return out.getvalue()


def save_model(path: str | os.PathLike, kind: str, state: dict[str, Any], *, version: int = 1) -> Path:
    """Writes ``state`` (a tree of dicts, lists, scalars and arrays) as a
    model file of ``kind`` (:func:`dumps`). The write is atomic (temporary
    file + rename). ``version``: the format version the state needs (1
    unless it uses something older readers cannot rebuild; at most
    :data:`VERSION`)."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a directory, not a model file path")
    data = dumps(kind, state, version=version)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_bytes_atomic(path, data)


def _depth_ok(tree: Any, limit: int) -> bool:
    """Whether ``tree`` nests at most ``limit`` levels (iteratively)."""
    stack = [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        if depth > limit:
            return False
        if isinstance(node, dict):
            stack.extend((v, depth + 1) for v in node.values())
        elif isinstance(node, list):
            stack.extend((v, depth + 1) for v in node)
    return True


def _check_entries(zf: zipfile.ZipFile, size: int, bad: str) -> None:
    """Refuses compressed, oversized or encrypted entries before any is read."""
    for info in zf.infolist():
        if info.compress_type != zipfile.ZIP_STORED:
            raise ValueError(f"{bad}: entry {info.filename!r} is compressed (method {info.compress_type}); "
                             "sfanav writes model files uncompressed")
        if info.flag_bits & 0x1:
            raise ValueError(f"{bad}: entry {info.filename!r} is encrypted")
        if info.file_size > size or info.compress_size > size:
            raise ValueError(f"{bad}: entry {info.filename!r} claims {info.file_size} bytes, "
                             f"more than the file's {size}")


def _load_array(blob: bytes, name: str, info: Any, bad: str) -> np.ndarray:
    """One ``.npy`` blob, its header checked against the manifest and its
    length before anything is allocated."""
    from numpy.lib import format as npy

    if not isinstance(info, dict):
        raise ValueError(f"{bad}: the manifest entry of array {name!r} is not an object")
    fh = io.BytesIO(blob)
    try:
        major, _ = npy.read_magic(fh)
        read_header = npy.read_array_header_1_0 if major == 1 else npy.read_array_header_2_0
        shape, fortran, dtype = read_header(fh, max_header_size=10_000)
    except (ValueError, SyntaxError, TypeError, RecursionError, MemoryError) as exc:
        raise ValueError(f"{bad}: array {name!r} has a malformed header ({exc})") from None
    if dtype.kind not in "biuf" or dtype.hasobject:
        raise ValueError(f"{bad}: array {name!r} has unsupported dtype {dtype}")
    if dtype.str != info.get("dtype") or list(shape) != info.get("shape"):
        raise ValueError(f"{bad}: array {name!r} has the wrong dtype or shape")
    count = 1
    for n in shape:
        count *= int(n)
    if count * dtype.itemsize != len(blob) - fh.tell():
        raise ValueError(f"{bad}: array {name!r} holds {len(blob) - fh.tell()} bytes of data, "
                         f"its header declares {count * dtype.itemsize}")
    arr = np.frombuffer(blob, dtype=dtype, count=count, offset=fh.tell())
    arr = arr.reshape(shape, order="F" if fortran else "C").copy()
    if dtype.kind == "f" and not np.isfinite(arr).all():
        raise ValueError(f"{bad}: array {name!r} holds NaN or infinity")
    return arr


def read_model(path: str | os.PathLike) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """Reads and verifies a model file; returns ``(kind, state, manifest)``."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no model file at {path}")
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a directory, not a model file")
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise ValueError(f"{path} is not a valid sfanav model file ({exc})") from None
    return _read(path, size, str(path))


def loads(data: bytes) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """Reads and verifies the bytes of a model file (:func:`dumps`), with the
    same checks as :func:`read_model`; returns ``(kind, state, manifest)``.

    Raises
    ------
    TypeError
        If ``data`` is not bytes.
    ValueError
        If the bytes are not a valid, unaltered sfanav model of a supported
        version.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise TypeError(f"expected the bytes of an sfanav model, got {type(data).__name__}")
    data = bytes(data)
    return _read(io.BytesIO(data), len(data), "the bytes")


def _read(source: Any, size: int, label: str) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """The checks and the reading of a model file or its bytes."""
    path = label
    bad = f"{label} {'are' if label == 'the bytes' else 'is'} not a valid sfanav model file"
    try:
        with zipfile.ZipFile(source, "r") as zf:
            _check_entries(zf, size, bad)
            try:
                text = zf.read("manifest.json")
            except KeyError:
                raise ValueError(f"{bad}: it has no manifest.json") from None
            try:
                manifest = json.loads(text)
            except RecursionError:
                raise ValueError(f"{bad}: the manifest nests too deeply") from None
            except UnicodeDecodeError as exc:
                raise ValueError(f"{bad}: the manifest is not UTF-8 text ({exc})") from None
            if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
                got = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
                raise ValueError(f"{bad}: unknown format {got!r}")
            if not _depth_ok(manifest, MAX_DEPTH):
                raise ValueError(f"{bad}: the manifest nests more than {MAX_DEPTH} levels deep")
            version = manifest.get("version")
            if isinstance(version, bool) or not isinstance(version, int):
                raise ValueError(f"{bad}: missing format version (an integer), got {version!r}")
            if version < 1:
                raise ValueError(f"{bad}: format version {version} does not exist (versions start at 1)")
            if version > VERSION:
                raise ValueError(
                    f"{path} {'use' if path == 'the bytes' else 'uses'} model format version {version}, but this sfanav reads "
                    f"versions up to {VERSION}: upgrade sfanav"
                )
            digest = manifest.pop("digest", None)
            if digest != hashlib.sha256(_canonical(manifest)).hexdigest():
                raise ValueError(f"{bad}: the manifest was altered (checksum mismatch)")
            if (not isinstance(manifest.get("arrays"), dict) or not isinstance(manifest.get("kind"), str)
                    or "state" not in manifest):
                raise ValueError(f"{bad}: malformed manifest (no 'arrays' table, 'kind' or 'state')")
            arrays: dict[str, np.ndarray] = {}
            for name, info in manifest["arrays"].items():
                try:
                    blob = zf.read(f"arrays/{name}.npy")
                except KeyError:
                    raise ValueError(f"{bad}: array {name!r} is missing") from None
                if not isinstance(info, dict) or hashlib.sha256(blob).hexdigest() != info.get("sha256"):
                    raise ValueError(f"{bad}: array {name!r} was altered (checksum mismatch)")
                arrays[name] = _load_array(blob, name, info, bad)
            state = _join(manifest["state"], arrays)
    except zipfile.BadZipFile as exc:
        raise ValueError(f"{bad} (truncated or corrupted: {exc})") from None
    except (KeyError, TypeError, AttributeError, json.JSONDecodeError, NotImplementedError, OverflowError,
            RecursionError) as exc:
        raise ValueError(f"{bad}: malformed manifest ({type(exc).__name__}: {exc})") from None
    except (zipfile.LargeZipFile, EOFError, OSError) as exc:
        if isinstance(exc, (FileNotFoundError, IsADirectoryError, PermissionError)):
            raise
        raise ValueError(f"{bad} (truncated or corrupted: {exc})") from None
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
    try:
        return loader(state)
    except (ValueError, TypeError, KeyError, IndexError, AttributeError, OverflowError, RecursionError,
            RuntimeError, MemoryError) as exc:
        msg = str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}"
        raise ValueError(f"{path} is not a valid sfanav {kind} model: {msg}") from None


def state_from_bytes(data: bytes, kind: str) -> dict[str, Any]:
    """The state in the bytes of a model of ``kind`` (:func:`loads`).

    Raises
    ------
    TypeError
        If ``data`` is not bytes.
    ValueError
        If the bytes are not a valid sfanav model, or hold another kind.
    """
    got, state, _ = loads(data)
    if got != kind:
        raise ValueError(f"the bytes hold a {got} model, not a {kind}")
    return state
