"""How the readout choice rules would have chosen on the gardens runs
(issue 7): reads the ``cv diagnostics`` the ``sfanav default`` rows record
(per seed and scene: for 5- and 10-fold blocked CV on the training run, the
best kernel-ridge and kNN candidates' CV errors and their test-walk errors)
and prints, per rule, how often it picked the readout that was better on the
test walk and the mean test MAE of its picks.

    PYTHONPATH=python python3 scripts/gardens_readout_cv.py RUN_DIR/gardens-subset.json [more.json ...]
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
    rules = {"5-fold argmin": (5, 0.0), "5-fold, kernel within 10 %": (5, 0.1),
             "10-fold argmin": (10, 0.0), "10-fold, kernel within 10 % (the default)": (10, 0.1),
             "always kernel ridge (10-fold grid)": (10, 1.0), "always kNN (10-fold grid)": (10, -1.0)}
    print(f"{len(cases)} cases (scene x seed)\n")
    print("| rule | picks the better readout on the test walk | kNN picked | mean test MAE x / y (%) | mean test MED (m) |")
    print("|---|---|---|---|---|")
    oracle = []
    for name, (folds, tol) in rules.items():
        good, knn, mx, my, med = 0, 0, [], [], []
        for _, d in cases:
            k, n = d[f"cv{folds} kernel"], d[f"cv{folds} knn"]
            pick = n if (tol < 0 or n["cv (m)"] < (1 - tol) * k["cv (m)"]) else k
            better = n if n["test MED (m)"] < k["test MED (m)"] else k
            good += pick is better
            knn += pick is n
            mx.append(pick["test MAE x (%)"])
            my.append(pick["test MAE y (%)"])
            med.append(pick["test MED (m)"])
        print(f"| {name} | {good} / {len(cases)} | {knn} | {np.mean(mx):.2f} / {np.mean(my):.2f} | {np.mean(med):.3f} |")
    for _, d in cases:
        k, n = d["cv10 kernel"], d["cv10 knn"]
        oracle.append(min((k, n), key=lambda z: z["test MED (m)"]))
    print(f"| oracle (the better on the test walk) | - | - | {np.mean([o['test MAE x (%)'] for o in oracle]):.2f} / "
          f"{np.mean([o['test MAE y (%)'] for o in oracle]):.2f} | {np.mean([o['test MED (m)'] for o in oracle]):.3f} |")
    print("\nper case: CV error (m) kernel / kNN at 5 and 10 folds; test MED (m) kernel / kNN")
    for name, d in cases:
        print(f"  {name}: cv5 {d['cv5 kernel']['cv (m)']:.3f} / {d['cv5 knn']['cv (m)']:.3f}, "
              f"cv10 {d['cv10 kernel']['cv (m)']:.3f} / {d['cv10 knn']['cv (m)']:.3f}; test "
              f"{d['cv10 kernel']['test MED (m)']:.3f} / {d['cv10 knn']['test MED (m)']:.3f} "
              f"({d['cv10 kernel']['spec']}, {d['cv10 knn']['spec']})")


if __name__ == "__main__":
    main()
