"""Statistics bytes and update-vs-retrain time of the tiny test network
(docs/updates.md). Run from the repository root:
PYTHONPATH=python python scripts/update_cost_tiny.py"""

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_updates import ROT, TINY, _images  # noqa: E402

from sfanav import Network  # noqa: E402
from sfanav.sfa.updates import NetworkUpdater, statistics_bytes  # noqa: E402

A, B = _images(200, 1), _images(20, 2)
net = Network(TINY).fit(A, ROT, cache=False, progress=False)
print("model bytes with / without statistics:", len(net.to_bytes(include_statistics=True)), len(net.to_bytes()),
      "statistics:", statistics_bytes(net))
AB = np.concatenate([A, B])
t = time.perf_counter()
Network(TINY).fit(AB, ROT, cache=False, progress=False)
tf = time.perf_counter() - t
t = time.perf_counter()
NetworkUpdater(net).partial_fit(B)
tu = time.perf_counter() - t
print(f"retrain on {len(AB)} images {tf:.3f} s, update with {len(B)} images {tu:.3f} s, ratio {tu / tf:.3f}")
