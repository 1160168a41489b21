"""Structure-aware mutations for the fuzz targets: edit a model file's
manifest or arrays (or a config) the way a hostile or careless editor
would, then recompute every checksum, so that the result passes the
integrity checks and exercises the validation behind them. Fields are
often changed in pairs (a node's ``n_features`` with its first stage's
``input_dim``, say): the crashes the checksums hid needed two.

Bags are damaged the way disks, networks and killed recorders damage
them: cut short, bits flipped, and, in a ROS 1 bag's compressed chunks,
the compressed stream damaged or the records inside it damaged and
compressed again (``bagrecords``)."""

from __future__ import annotations

import hashlib
import io
import json
import random
import zipfile
from typing import Any

import numpy as np
from bagrecords import chunks, damage_chunk

INTERESTING_INTS = [0, 1, 2, 3, -1, -3, 7, 255, 1000, 2**16, 2**20, 2**31 - 1, 2**32 + 1, 2**40, 2**63 - 1,
                    2**63, 2**64 - 1, 2**64, 10**30]
INTERESTING_OTHER: list[Any] = [None, True, False, 0.5, 1.5, -0.0, 1e308, -1e308, 1e-320, "", "x", "false",
                                [], {}, [1, 2], {"a": 1}, [[[[]]]]]


def canonical(obj: Any) -> bytes:
    # The digest's canonical JSON (docs/model-format.md).
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def read_model_bytes(data: bytes) -> tuple[dict[str, Any], dict[str, bytes]] | None:
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            manifest = json.loads(zf.read("manifest.json"))
            blobs = {n[7:-4]: zf.read(n) for n in zf.namelist() if n.startswith("arrays/") and n.endswith(".npy")}
    except Exception:  # noqa: BLE001 - any failure to parse: not a model or a config
        return None
    if not isinstance(manifest, dict) or not isinstance(manifest.get("arrays"), dict):
        return None
    manifest.pop("digest", None)
    return manifest, blobs


def write_model_bytes(manifest: dict[str, Any], blobs: dict[str, bytes]) -> bytes:
    m = dict(manifest)
    try:
        m["digest"] = hashlib.sha256(canonical(m)).hexdigest()
        text = json.dumps(m)
    except (ValueError, TypeError, RecursionError):
        text = "{}"
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        zf.writestr("manifest.json", text)
        for name, blob in blobs.items():
            zf.writestr(f"arrays/{name}.npy", blob)
    return buf.getvalue()


def _paths(tree: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path to a scalar or container inside ``tree``."""
    out = [prefix] if prefix else []
    if isinstance(tree, dict):
        for k, v in tree.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            out += _paths(v, prefix + (i,))
    return out


def _get(tree: Any, path: tuple) -> Any:
    for k in path:
        tree = tree[k]
    return tree


def _set(tree: Any, path: tuple, value: Any) -> None:
    _get(tree, path[:-1])[path[-1]] = value


def _value(rng: random.Random, old: Any) -> Any:
    r = rng.random()
    if isinstance(old, bool) or r < 0.1:
        return rng.choice(INTERESTING_OTHER)
    if isinstance(old, int) and r < 0.8:
        return rng.choice([old + 1, old - 1, old * 2, -old, rng.choice(INTERESTING_INTS)])
    if isinstance(old, float) and r < 0.8:
        return rng.choice([old * 10, -old, 0.0, 1e300, rng.choice(INTERESTING_INTS)])
    if isinstance(old, str) and r < 0.6:
        return rng.choice(["", old + "x", "quadratic", "gp", "knn", "kernel", "mixed", "double", "SFA", "Network"])
    if isinstance(old, list) and r < 0.7 and old:
        return rng.choice([old[:-1], old + old[-1:], old[::-1], []])
    return rng.choice(INTERESTING_INTS + INTERESTING_OTHER)


def _array(rng: random.Random, old: bytes) -> np.ndarray:
    try:
        a = np.load(io.BytesIO(old), allow_pickle=False)
    except Exception:  # noqa: BLE001 - any failure to parse: not a model or a config
        a = np.zeros(3)
    r = rng.random()
    if r < 0.25 and a.size:
        a = a.astype(float).copy()
        a.flat[rng.randrange(a.size)] = rng.choice([np.nan, np.inf, -np.inf, 1e308, 0.0, -1.0])
        return a
    if r < 0.5:
        return np.zeros(tuple(rng.choice([0, 1, 2, 3, 7]) for _ in range(rng.choice([1, 2, 3]))))
    if r < 0.65:
        return a.reshape(-1)
    if r < 0.8:
        return a.astype(rng.choice([np.float32, np.int64, np.uint8, np.bool_]))
    return np.concatenate([a.reshape(-1), a.reshape(-1)]) if a.size else np.ones(5)


def mutate_model(data: bytes, seed: int) -> bytes | None:
    """A structure-aware mutation of a model file (None if ``data`` is not
    one): one to three manifest fields, or an array, or a pair of fields
    set to the same value; checksums recomputed."""
    parts = read_model_bytes(data)
    if parts is None:
        return None
    manifest, blobs = parts
    rng = random.Random(seed)
    state_paths = [p for p in _paths(manifest) if p[0] not in ("arrays", "digest")]
    kind = rng.random()
    if kind < 0.25 and blobs:
        name = rng.choice(sorted(blobs))
        arr = _array(rng, blobs[name])
        buf = io.BytesIO()
        np.save(buf, arr, allow_pickle=False)
        blobs[name] = buf.getvalue()
        meta = {"dtype": arr.dtype.str, "shape": list(arr.shape), "sha256": hashlib.sha256(blobs[name]).hexdigest()}
        manifest["arrays"][name] = meta
    elif kind < 0.45 and state_paths:
        # two fields named alike (n_features / input_dim, n_out / n_components, ...) set to one value
        ints = [p for p in state_paths if isinstance(_get(manifest, p), int) and not isinstance(_get(manifest, p), bool)]
        if len(ints) >= 2:
            a, b = rng.sample(ints, 2)
            v = rng.choice(INTERESTING_INTS)
            _set(manifest, a, v)
            _set(manifest, b, v)
    elif state_paths:
        for _ in range(rng.choice([1, 1, 2, 3])):
            paths = [p for p in _paths(manifest) if p[0] not in ("arrays", "digest")]
            if not paths:
                break
            p = rng.choice(paths)
            if rng.random() < 0.1 and isinstance(_get(manifest, p[:-1]), dict):
                del _get(manifest, p[:-1])[p[-1]]
            else:
                _set(manifest, p, _value(rng, _get(manifest, p)))
    return write_model_bytes(manifest, blobs)


def mutate_config(data: bytes, seed: int) -> bytes | None:
    """A structure-aware mutation of a JSON network config."""
    try:
        cfg = json.loads(data)
    except Exception:  # noqa: BLE001 - any failure to parse: not a model or a config
        return None
    if not isinstance(cfg, dict):
        return None
    rng = random.Random(seed)
    for _ in range(rng.choice([1, 1, 2, 3])):
        paths = _paths(cfg)
        if not paths:
            break
        p = rng.choice(paths)
        r = rng.random()
        if r < 0.1 and isinstance(_get(cfg, p[:-1]), dict):
            del _get(cfg, p[:-1])[p[-1]]
        elif r < 0.2 and isinstance(_get(cfg, p), dict):
            _get(cfg, p)[rng.choice(["rf", "stride", "out", "degree", "reduce_to", "weight_sharing", "max_expanded",
                                     "precision", "tol", "width", "height", "channels", "netwrok"])] = _value(rng, 1)
        else:
            _set(cfg, p, _value(rng, _get(cfg, p)))
    try:
        return json.dumps(cfg).encode()
    except (ValueError, TypeError):
        return None


def mutate_bag(data: bytes, seed: int) -> bytes | None:
    """A damaged bag: cut at a random place (often near the end, as a
    killed recorder leaves it), 1 to 16 bits flipped, or a compressed
    chunk's stream or its records damaged (ROS 1). None for empty data."""
    if not data:
        return None
    rng = random.Random(seed)
    kind = rng.random()
    found = chunks(data) if kind < 0.4 else []
    if found:
        chunk = rng.choice(found)
        offsets = [rng.randrange(2**31) for _ in range(rng.choice([1, 1, 2, 4, 16]))]
        damaged = _damaged_chunk(data, chunk, offsets, rng.random() < 0.5)
        if damaged is not None:
            return damaged
    if kind < 0.7:
        out = bytearray(data)
        for _ in range(rng.choice([1, 1, 2, 4, 16])):
            out[rng.randrange(len(out))] ^= 1 << rng.randrange(8)
        return bytes(out)
    cut = len(data) - rng.randrange(1, 64) if rng.random() < 0.5 else rng.randrange(len(data))
    return data[: max(cut, 0)]


def _damaged_chunk(data: bytes, chunk: Any, offsets: list[int], before_compression: bool) -> bytes | None:
    """``damage_chunk``, or None for a chunk already too damaged to decompress."""
    try:
        return damage_chunk(data, chunk, offsets, before_compression=before_compression)
    except Exception:  # noqa: BLE001 - bz2, lz4 and struct fail each in their own way
        return None
