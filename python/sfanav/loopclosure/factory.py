"""The loop-closure detectors by name, for configuration files and the
command line (``sfanav train --loop-closures gt|bow|fourier``)."""

from __future__ import annotations

from typing import Any

from .bow import BagOfWordsDetector
from .detectors import FourierDetector, GroundTruthDetector, LoopClosureDetector

#: detector name -> class
DETECTORS: dict[str, type[LoopClosureDetector]] = {
    "gt": GroundTruthDetector,
    "bow": BagOfWordsDetector,
    "fourier": FourierDetector,
}


def make_detector(kind: str, **params: Any) -> LoopClosureDetector:
    """The detector named ``kind``: ``"gt"`` (:class:`GroundTruthDetector`),
    ``"bow"`` (:class:`~sfanav.loopclosure.bow.BagOfWordsDetector`) or
    ``"fourier"`` (:class:`FourierDetector`), built with ``params``.

    Raises
    ------
    ValueError
        For another name.

    Examples
    --------
    >>> make_detector("gt", max_distance=0.1).max_distance
    0.1
    """
    if kind not in DETECTORS:
        raise ValueError(f"unknown loop-closure detector {kind!r}; choose one of {sorted(DETECTORS)}")
    return DETECTORS[kind](**params)
