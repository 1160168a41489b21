"""The navigation peer on 7.1's own trials: homing by perfect memory (the
robust descent of the rotational image difference to the target's panorama,
sfanav.navigation.homing) in the 7.1 open-field and v-obstacle scenes, on
the trials the experiments draw (``trials_71``, same seed, same first N), so
that its success and efficiency stand beside the slow-feature arms of the
committed 7.1 results without retraining their networks (the peer needs
none). Writes the rows and the per-trial outcomes as JSON.

    PYTHONPATH=python python3 scripts/investigations/homing_peer_71.py OUT.json [--trials N] [--kinds open obstacle]

About 10-30 s of rendering per trial on 2 cores (up to 400 stops, two
cameras, 600x60 panoramas).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from sfanav import navigation as nav
from sfanav.experiments.navigation import trials_71
from sfanav.experiments.navigation_scenes import homing_navigator, scene

LABEL = "robust descent, perfect memory homing (rotational image difference)"


def run(kind: str, n: int, seed: int = 0) -> dict:
    sc = scene(kind, seed)
    starts, targets, optimal, _, _ = trials_71(sc, kind, seed, 50)  # the experiment's 50, then the first n
    t0 = time.perf_counter()
    s = nav.evaluate_trials(homing_navigator(sc), starts[:n], targets[:n],
                            optimal_lengths=None if optimal is None else optimal[:n], progress=True, desc=kind)
    return {"trials": n, "seconds": time.perf_counter() - t0,
            "rows": {f"success ({LABEL})": s.success_rate, f"efficiency ({LABEL})": s.efficiency,
                     f"mean stops ({LABEL})": s.mean_iterations},
            "reasons": dict(s.reasons),
            "per_trial": [{"start": st.tolist(), "target": tg.tolist(), "success": bool(r.success),
                           "reason": r.reason, "travelled": float(r.travelled), "stops": int(r.iterations)}
                          for st, tg, r in zip(starts[:n], targets[:n], s.results)]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--kinds", nargs="+", default=["open", "obstacle"], choices=["open", "obstacle"])
    a = ap.parse_args(argv)
    res = {"command": "scripts/investigations/homing_peer_71.py " + " ".join(argv or []), "scenes": {}}
    for kind in a.kinds:
        res["scenes"][kind] = run(kind, a.trials)
        print(kind, res["scenes"][kind]["rows"], res["scenes"][kind]["reasons"], flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = a.out.with_name(a.out.name + ".tmp")
    tmp.write_text(json.dumps(res, indent=1) + "\n")
    os.replace(tmp, a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
