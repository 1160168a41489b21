#!/usr/bin/env python3
"""Double vs mixed precision on the Table 5.2 network: the same N synthetic
panoramas (the seeded generator of ``bench_network.py``) trained both ways;
prints fit times, the top node's Delta values, their largest relative
difference and how well each slow output agrees on 50 held-out images.

    python3 benches/bench_precision.py [N]      # default 200
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_network import make_images  # noqa: E402

import sfanav  # noqa: E402


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    imgs = make_images(0, n, 60, 600, 3, 20261124)
    test = make_images(n, n + 50, 60, 600, 3, 20261124)
    res = {}
    for prec in ("double", "mixed"):
        net = sfanav.Network.from_preset("thesis-5.2", precision=prec)
        t = time.perf_counter()
        net.fit(imgs, sfanav.Rotation(step=5), progress=False)
        dt = time.perf_counter() - t
        res[prec] = (net.delta_values_, net.transform(test))
        print(f"{prec}: fit {dt:.1f} s; Delta {np.array2string(net.delta_values_, precision=4)}")
    (dd, yd), (dm, ym) = res["double"], res["mixed"]
    print(f"largest relative Delta difference: {np.max(np.abs(dd - dm) / np.abs(dd)):.3g}")
    corr = [abs(np.corrcoef(yd[:, i], ym[:, i])[0, 1]) for i in range(yd.shape[1])]
    print("|correlation| of each output on 50 held-out images:", np.round(corr, 3))


if __name__ == "__main__":
    main()
