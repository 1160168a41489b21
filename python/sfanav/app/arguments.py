"""Value types of the ``sfanav`` command's arguments: each turns the text
of one argument into its value or raises ``argparse.ArgumentTypeError``
with a one-line reason."""

from __future__ import annotations

import argparse
import math

MAX_IMAGE_SIDE = 32767  # px, OpenCV's limit for remapped and resized images


def size(text: str) -> tuple[int, int]:
    try:
        if "x" in text.lower():
            w, h = (int(v) for v in text.lower().split("x"))
        else:
            w = h = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be WIDTHxHEIGHT (e.g. 600x60) or one number, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"size must be positive, got {text!r}")
    if max(w, h) > MAX_IMAGE_SIDE:
        raise argparse.ArgumentTypeError(f"size {text!r} is beyond {MAX_IMAGE_SIDE} px a side")
    return w, h


def _int_at_least(text: str, low: int) -> int:
    """An integer >= ``low``; the error states that bound, whatever the value."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}") from None
    if v < low:
        raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}")
    return v


def nonneg_int(text: str) -> int:
    """An integer >= 0."""
    return _int_at_least(text, 0)


def pos_int(text: str) -> int:
    """An integer >= 1 (``-5`` and ``0`` alike: "expected an integer >= 1")."""
    return _int_at_least(text, 1)


def pos_float(text: str) -> float:
    """A finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return v


def fraction(text: str) -> float:
    """A fraction in (0, 1] ("0.6") or a percentage with its sign ("60%")."""
    t = text.strip()
    percent = t.endswith("%")
    try:
        v = float(t[:-1] if percent else t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a fraction such as 0.6 or a percentage such as 60%, got {text!r}") from None
    if percent:
        v /= 100.0
    elif v > 1.0:
        raise argparse.ArgumentTypeError(
            f"{text!r} is more than the whole panorama: give a fraction in (0, 1] such as 0.6, "
            f"or a percentage with its sign such as {t}%")
    if not (math.isfinite(v) and 0.0 < v <= 1.0):
        raise argparse.ArgumentTypeError(f"expected a fraction in (0, 1] or a percentage in (0%, 100%], got {text!r}")
    return v


def xy(text: str) -> tuple[float, ...]:
    """A position "X,Y" (metres) or a pose "X,Y,HEADING_DEG"."""
    try:
        v = tuple(float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y (metres, comma-separated), got {text!r}") from None
    if len(v) not in (2, 3) or not all(abs(t) < float("inf") for t in v):
        raise argparse.ArgumentTypeError(f"expected X,Y or X,Y,HEADING_DEG (finite numbers), got {text!r}")
    return v


def nonneg_float(text: str) -> float:
    """A finite number >= 0 ("5", "2.5")."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return v
