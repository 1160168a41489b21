"""Structure-aware editing of model files for the bad-input tests and the
fuzz harness: change a manifest's state or an array and recompute every
checksum, so that the edited file passes the integrity checks and reaches
the state validation behind them."""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def _canonical(obj: Any) -> bytes:
    # The digest's canonical JSON, as docs/model-format.md defines it.
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def read_parts(path: str | Path) -> tuple[dict[str, Any], dict[str, bytes]]:
    """The manifest (without its digest) and the array blobs by name."""
    with zipfile.ZipFile(path) as zf:
        manifest = json.loads(zf.read("manifest.json"))
        blobs = {n[len("arrays/"):-len(".npy")]: zf.read(n) for n in zf.namelist() if n.startswith("arrays/")}
    manifest.pop("digest", None)
    return manifest, blobs


def npy(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    return buf.getvalue()


def set_array(manifest: dict[str, Any], blobs: dict[str, bytes], name: str, arr: np.ndarray) -> None:
    """Replaces (or adds) array ``name``, with matching manifest metadata."""
    blob = npy(np.asarray(arr))
    blobs[name] = blob
    manifest["arrays"][name] = {"dtype": np.asarray(arr).dtype.str, "shape": list(np.shape(arr)),
                                "sha256": hashlib.sha256(blob).hexdigest()}


def write_parts(path: str | Path, manifest: dict[str, Any], blobs: dict[str, bytes], *,
                compression: int = zipfile.ZIP_STORED, manifest_text: bytes | None = None) -> Path:
    """Writes a model file with the digest recomputed (``manifest_text``
    replaces the serialised manifest, e.g. padded with whitespace)."""
    m = dict(manifest)
    m["digest"] = hashlib.sha256(_canonical(m)).hexdigest()
    with zipfile.ZipFile(path, "w", compression) as zf:
        zf.writestr("manifest.json", manifest_text if manifest_text is not None else json.dumps(m))
        for name, blob in blobs.items():
            zf.writestr(f"arrays/{name}.npy", blob)
    return Path(path)


def edit_model(src: str | Path, dst: str | Path,
               fn: Callable[[dict[str, Any], dict[str, bytes]], None]) -> Path:
    """Copies ``src`` to ``dst`` with ``fn(manifest, blobs)`` applied and the
    checksums recomputed."""
    manifest, blobs = read_parts(src)
    fn(manifest, blobs)
    return write_parts(dst, manifest, blobs)


def strip_statistics(manifest: dict[str, Any], blobs: dict[str, bytes]) -> None:
    """Drops every node's training statistics (as ``include_statistics=False``)."""
    def walk(node: Any) -> None:
        if isinstance(node, dict):
            if "stats" in node and isinstance(node["stats"], dict):
                node["stats"] = None
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)
    walk(manifest["state"])
    for name in [n for n in manifest["arrays"] if "/stats/" in n]:
        del manifest["arrays"][name]
        blobs.pop(name, None)
