"""Network configs: reading TOML / JSON files and presets, and resolving a
config into the full layer specification the Rust core builds
(``sfanav._core.Network``): receptive fields, strides, reductions and
expansions per layer, checked with errors that name the layer and key."""

from __future__ import annotations

import copy
import json
import os
import sys
from importlib import resources
from math import comb
from pathlib import Path
from typing import Any

import numpy as np

from .. import _core

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["PRESETS", "preset_config", "read_config_file", "resolve_config", "spec_to_json"]

PRESETS = ("thesis-5.1", "thesis-5.2", "thesis-5.3", "sfanav-default", "landmark-120")

MAX_CONFIG_BYTES = 1_000_000  # a network config file is small text


def read_config_file(path: str | os.PathLike) -> dict[str, Any]:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no network config at {path}")
    if path.is_dir():
        raise IsADirectoryError(f"network config {path} is a directory")
    if path.stat().st_size > MAX_CONFIG_BYTES:
        raise ValueError(f"network config {path} is {path.stat().st_size} bytes; a config is at most "
                         f"{MAX_CONFIG_BYTES} bytes of TOML or JSON")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"network config {path} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    try:
        cfg = json.loads(text) if path.suffix.lower() == ".json" else tomllib.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"cannot parse network config {path}: {exc}") from None
    except RecursionError:
        raise ValueError(f"cannot parse network config {path}: it nests too deeply") from None
    if not isinstance(cfg, dict):
        raise ValueError(f"network config {path} must be a table (a JSON object), got {type(cfg).__name__}")
    return cfg


def preset_config(name: str) -> dict[str, Any]:
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; available: {', '.join(PRESETS)}")
    text = resources.files("sfanav.sfa").joinpath("presets", f"{name}.toml").read_text()
    return tomllib.loads(text)


def _pair(v: Any, what: str) -> tuple[int, int]:
    if (
        isinstance(v, (list, tuple))
        and len(v) == 2
        and all(isinstance(x, int) and not isinstance(x, bool) for x in v)
    ):
        return int(v[0]), int(v[1])
    raise ValueError(f"{what} must be [width, height] (two integers), got {v!r}")


MAX_LAYER_DEGREE = 3  # the network's nodes expand to degree 1, 2 or 3


def _default_reduce(in_dim: int, degree: int, max_expanded: int) -> int:
    """The largest k <= in_dim whose polynomial expansion of degree
    ``degree`` has at most ``max_expanded`` dimensions (at least 1), by
    bisection (the expansion's size grows with k)."""
    lo, hi = 1, max(1, in_dim)
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if comb(mid + degree, degree) - 1 <= max_expanded:
            lo = mid
        else:
            hi = mid - 1
    return lo


def _config_int(value: Any, what: str, minimum: int = 1) -> int:
    """A config value that must be an integer (not a bool, not a fraction)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"network config: {what} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"network config: {what} must be at least {minimum}, got {value}")
    return int(value)


CONFIG_SECTIONS = ("name", "description", "input", "network", "layers")
"""The top-level keys a network config may have."""


def resolve_config(config: dict[str, Any]) -> dict[str, Any]:
    """Checks a network config (as in the preset TOML files) and resolves it
    into the spec the Rust core takes: ``"full"`` RFs become the size of the
    map below, and a missing ``reduce_to`` becomes the largest k whose
    expansion stays within ``max_expanded``. Raises ValueError naming the
    layer and the problem."""
    if not isinstance(config, dict):
        raise TypeError(f"a network config must be a dict, got {type(config).__name__}")
    unknown = set(config) - set(CONFIG_SECTIONS)
    if unknown:
        raise ValueError(f"network config: unknown sections or keys {sorted(map(str, unknown))}; "
                         f"a config has {', '.join(CONFIG_SECTIONS)}")
    for key in ("name", "description"):
        if key in config and not isinstance(config[key], str):
            raise ValueError(f"network config: {key} must be a string, got {config[key]!r}")
    inp = config.get("input")
    if not isinstance(inp, dict) or "width" not in inp or "height" not in inp:
        raise ValueError("network config: [input] needs width, height (and channels)")
    unknown = set(inp) - {"width", "height", "channels"}
    if unknown:
        raise ValueError(f"network config: unknown [input] keys {sorted(map(str, unknown))}")
    w, h = _config_int(inp["width"], "[input] width"), _config_int(inp["height"], "[input] height")
    c = _config_int(inp.get("channels", 1), "[input] channels")
    net = config.get("network", {})
    if not isinstance(net, dict):
        raise ValueError(f"network config: [network] must be a table, got {type(net).__name__}")
    unknown = set(net) - {"weight_sharing", "max_expanded", "tol", "precision"}
    if unknown:
        raise ValueError(f"network config: unknown [network] keys {sorted(map(str, unknown))}")
    sharing = net.get("weight_sharing", True)
    if not isinstance(sharing, (bool, np.bool_)):
        raise ValueError(f"network config: weight_sharing must be true or false, got {sharing!r}")
    max_expanded = _config_int(net.get("max_expanded", 300), "[network] max_expanded")
    tol = net.get("tol", _core.DEFAULT_TOL)
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 <= tol < 1:
        raise ValueError(f"network config: tol must be a number in [0, 1), got {tol!r}")
    tol = float(tol)
    precision = net.get("precision", "double")
    if precision not in ("double", "mixed"):
        raise ValueError(f"network config: precision must be 'double' or 'mixed', got {precision!r}")
    layers = config.get("layers")
    if not isinstance(layers, list) or not layers:
        raise ValueError("network config: needs at least one [[layers]] entry")
    spec_layers = []
    mw, mh, mc = w, h, c
    for i, layer in enumerate(layers, 1):
        name = f"layer {i}"
        if not isinstance(layer, dict):
            raise ValueError(f"{name}: must be a table")
        unknown = set(layer) - {"rf", "stride", "out", "degree", "reduce_to"}
        if unknown:
            raise ValueError(f"{name}: unknown keys {sorted(unknown)}")
        rf = (mw, mh) if layer.get("rf") == "full" else _pair(layer.get("rf"), f"{name}: rf")
        stride = _pair(layer.get("stride", [1, 1]), f"{name}: stride")
        degree = _config_int(layer.get("degree", 2), f"{name}: degree")
        if degree > MAX_LAYER_DEGREE:
            raise ValueError(f"{name}: degree must be 1, 2 or 3, got {degree}")
        if "out" not in layer:
            raise ValueError(f"{name}: missing 'out' (the node's output dim)")
        out = _config_int(layer["out"], f"{name}: out")
        in_dim = rf[0] * rf[1] * mc
        reduce_to = layer.get("reduce_to")
        if reduce_to is None:
            reduce_to = _default_reduce(in_dim, degree, max_expanded)
        else:
            reduce_to = _config_int(reduce_to, f"{name}: reduce_to")
        spec_layers.append(
            {"rf": rf, "stride": stride, "n_out": out, "reduce_to": int(reduce_to), "degree": degree}
        )
        if rf[0] > mw or rf[1] > mh or min(stride) < 1:
            break  # the core names the problem
        mw, mh, mc = (mw - rf[0]) // stride[0] + 1, (mh - rf[1]) // stride[1] + 1, out
    return {
        "height": h,
        "width": w,
        "channels": c,
        "layers": spec_layers,
        "weight_sharing": bool(sharing),
        "tol": tol,
        "mixed_precision": precision == "mixed",
    }


def spec_to_json(spec: dict[str, Any]) -> dict[str, Any]:
    """The resolved spec as stored in model files (pairs as JSON lists); on
    load the spec is recomputed from the config and compared with it."""
    s = copy.deepcopy(spec)
    for layer in s["layers"]:
        layer["rf"] = list(layer["rf"])
        layer["stride"] = list(layer["stride"])
    return s
