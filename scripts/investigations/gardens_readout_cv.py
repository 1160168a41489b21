"""How the readout choice rules would have chosen on the gardens runs
(issue 7): reads the ``cv diagnostics`` the ``sfanav default`` rows record
(per seed and scene: for blocked CV on the training run with 5 or 10
contiguous folds, or 10 folds of interleaved 10-image blocks (the default),
the best kernel-ridge and kNN candidates' CV errors and their test-walk
errors)
and prints, per rule, how often it picked the readout that was better on the
test walk and the mean test MAE of its picks.

    PYTHONPATH=python python3 scripts/investigations/gardens_readout_cv.py RUN_DIR/gardens-subset.json [more.json ...]
"""

from __future__ import annotations

import json
import sys

import numpy as np


def main() -> None:
    cases = []
    for path in sys.argv[1:]:
        avg = json.load(open(path))
        for cfg, m in avg.items():
            if not cfg.endswith("sfanav default") or "cv diagnostics" not in m:
                continue
            diags = m["cv diagnostics"]
            diags = diags if isinstance(diags, list) else [diags]
            for i, d in enumerate(diags):
                cases.append((f"{cfg} #{i}", d))
    rules = {"5 contiguous folds, argmin": ("5 contiguous", 0.0),
             "5 contiguous folds, kernel unless kNN > 10 % lower": ("5 contiguous", 0.1),
             "10 contiguous folds, argmin": ("10 contiguous", 0.0),
             "10 contiguous folds, kernel unless kNN > 10 % lower": ("10 contiguous", 0.1),
             "10 folds of 10-image blocks, argmin": ("10 blocks of 10", 0.0),
             "10 folds of 10-image blocks, kernel unless kNN > 10 % lower (the default)": ("10 blocks of 10", 0.1),
             "always kNN (10-image blocks)": ("10 blocks of 10", -1.0)}
    print(f"{len(cases)} cases (scene x seed)\n")
    print("| rule | picks the better readout on the test walk | kNN picked | mean test MAE x / y (%) | mean test MED (m) |")
    print("|---|---|---|---|---|")
    oracle = []
    for name, (folds, tol) in rules.items():
        good, knn, mx, my, med = 0, 0, [], [], []
        for _, d in cases:
            k, n = d[f"cv {folds} kernel"], d[f"cv {folds} knn"]
            pick = n if (tol < 0 or n["cv (m)"] < (1 - tol) * k["cv (m)"]) else k
            better = n if n["test MED (m)"] < k["test MED (m)"] else k
            good += pick is better
            knn += pick is n
            mx.append(pick["test MAE x (%)"])
            my.append(pick["test MAE y (%)"])
            med.append(pick["test MED (m)"])
        print(f"| {name} | {good} / {len(cases)} | {knn} | {np.mean(mx):.2f} / {np.mean(my):.2f} | {np.mean(med):.3f} |")
    for _, d in cases:  # the better on the test walk of all the kinds' and schemes' picks
        oracle.append(min((v for k, v in d.items() if k.startswith("cv ")), key=lambda z: z["test MED (m)"]))
    print(f"| oracle (the best of these picks on the test walk) | - | - | {np.mean([o['test MAE x (%)'] for o in oracle]):.2f} / "
          f"{np.mean([o['test MAE y (%)'] for o in oracle]):.2f} | {np.mean([o['test MED (m)'] for o in oracle]):.3f} |")
    print("\nper case and scheme: best kernel / kNN candidate, CV error (m), test MED (m)")
    for name, d in cases:
        print(f"  {name}:")
        for sch in ("5 contiguous", "10 contiguous", "10 blocks of 10"):
            k, n = d[f"cv {sch} kernel"], d[f"cv {sch} knn"]
            print(f"    {sch}: {k['spec']} cv {k['cv (m)']:.3f} test {k['test MED (m)']:.3f} | "
                  f"{n['spec']} cv {n['cv (m)']:.3f} test {n['test MED (m)']:.3f}")


if __name__ == "__main__":
    main()
