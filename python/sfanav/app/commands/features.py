"""``sfanav features``: long-term robust local features (thesis 6.1.2).

``sfanav features train`` learns a robustness predictor from a seasonal
dataset (the same route recorded in several conditions, the k-th frame of
each condition at the same pose, as preset ``thesis-6.1-seasons`` makes);
``sfanav features select`` keeps k keypoints of every image of a dataset,
chosen by detector response and predicted robustness (``--method``,
``--candidates``), and writes them as JSON. Select the map's keypoints and
those of the images to match against it alike.
"""

from __future__ import annotations

import argparse
import json

from .. import arguments as arg
from ..common import existing_path, log, new_file, wrap
from ..failures import UsageError
from ..registry import command

EXAMPLES = """examples:
  sfanav simulate --preset thesis-6.1-seasons --out seasons
  sfanav features train --dataset seasons --run route --seasons spring,summer,autumn --out robust.json
  sfanav features select --predictor robust.json --dataset seasons --run route --condition spring \\
      --top-k 200 --out map-keypoints.json
  sfanav features select --predictor robust.json --dataset seasons --run route --condition winter \\
      --top-k 200 --out live-keypoints.json
"""


@command("features")
def _add_features(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from ...features import CANDIDATES, DETECTORS, METHODS

    p = sub.add_parser("features", help="train a robustness predictor for local features; keep robust keypoints",
                       description=wrap("Local visual features over the seasons (thesis 6.1.2): train an SVM that "
                                        "predicts which keypoints stay matchable across seasons, and keep the "
                                        "top-k most robust keypoints of images."),
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    fs = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    t = fs.add_parser("train", help="learn a predictor from a seasonal dataset",
                      description=wrap("Stable features (matched in all given conditions) and unstable ones (in "
                                       "none) of every place train an RBF SVM (grid search, cross-validation); "
                                       "the k-th frame of every condition is taken as the same place."))
    t.add_argument("--dataset", required=True, metavar="DIR", help="sfanav dataset with several conditions")
    t.add_argument("--out", required=True, metavar="FILE", help="predictor file to write (JSON)")
    t.add_argument("--run", dest="run_name", default=None, metavar="RUN", help="use this run only")
    t.add_argument("--seasons", default=None, metavar="A,B,...",
                   help="conditions to use (default: every condition of the run)")
    t.add_argument("--detector", choices=DETECTORS, default="fast-brief", help="detector (default fast-brief)")
    t.add_argument("--features", type=arg.pos_int, default=1000, metavar="N", help="features per image (1000)")
    t.add_argument("--threshold", type=float, default=10.0, metavar="PX",
                   help="largest pixel distance of a true match (10)")
    t.add_argument("--max-samples", type=arg.pos_int, default=4000, metavar="N",
                   help="most balanced training samples (4000)")
    t.add_argument("--cv", type=arg.pos_int, default=5, metavar="K", help="cross-validation folds (5)")
    t.add_argument("--seed", type=arg.nonneg_int, default=0, help="seed of the class balancing (0)")
    t.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    t.set_defaults(run=_run_train)
    s = fs.add_parser("select", help="keep k robust keypoints of every image",
                      description=wrap("Detects the C k keypoints of largest response in every image (--candidates "
                                       "C, default 4), scores them with the predictor and keeps k: by default the "
                                       "k most robust (--method robust), or those of the smallest sum of their "
                                       "rank by response and their rank by robustness (--method rank-sum); "
                                       "writes JSON (per image: x, y, detector response, robustness score). "
                                       "Select the map's images and the images matched against the map alike; "
                                       "to filter the map only, --method rank-sum --candidates 1.5 does better "
                                       "(the thesis: --method robust --candidates 1.5, map only)."))
    s.add_argument("--predictor", required=True, metavar="FILE", help="file of sfanav features train")
    s.add_argument("--dataset", required=True, metavar="DIR", help="sfanav dataset (RGB images)")
    s.add_argument("--out", required=True, metavar="FILE", help="keypoint file to write (JSON)")
    s.add_argument("--top-k", type=arg.pos_int, default=200, metavar="K", help="keypoints per image (200)")
    s.add_argument("--method", choices=METHODS, default=METHODS[0],
                   help="robust (default): the most robust; rank-sum: response rank + robustness rank")
    s.add_argument("--candidates", type=arg.pos_float, default=CANDIDATES, metavar="C",
                   help=f"candidate pool in multiples of --top-k ({CANDIDATES:g})")
    s.add_argument("--run", dest="run_name", default=None, metavar="RUN", help="only this run")
    s.add_argument("--condition", default=None, help="only this condition")
    s.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    s.set_defaults(run=_run_select)
    return p


def _dataset(path: str, run: str | None, condition: str | None = None):
    from ...data.dataset import Dataset

    ds = Dataset(existing_path(path, "dataset"))
    filters = {k: v for k, v in (("run", run), ("condition", condition)) if v is not None}
    if filters:
        sub = ds.select(**filters)
        if len(sub) == 0:
            raise UsageError(f"dataset {path} has no frames with {filters}")
        ds = sub
    return ds


def _run_train(args: argparse.Namespace) -> int:
    import numpy as np

    from ...features import RobustnessPredictor, balanced, training_samples

    out = new_file(args.out, args.overwrite, "predictor file")
    ds = _dataset(args.dataset, args.run_name)
    conds = sorted(set(ds.conditions.tolist())) if args.seasons is None else [
        c.strip() for c in args.seasons.split(",") if c.strip()]
    missing = [c for c in conds if c not in set(ds.conditions.tolist())]
    if missing:
        raise UsageError(f"dataset has no condition {missing[0]!r}; it has {sorted(set(ds.conditions.tolist()))}")
    if len(conds) < 2:
        raise UsageError(f"training needs at least two conditions (seasons), got {conds}")
    order = {c: np.flatnonzero(ds.conditions == c)[np.argsort(ds.frames[ds.conditions == c], kind="stable")]
             for c in conds}
    n = min(len(v) for v in order.values())
    log(f"{n} places in {len(conds)} conditions ({', '.join(conds)}), detector {args.detector}")
    places = ([ds.image(int(order[c][k])) for c in conds] for k in range(n))
    X, y = training_samples(places, args.detector, n=args.features, threshold=args.threshold)
    if min((y == 1).sum(), (y == 0).sum()) < args.cv:
        raise UsageError(f"too few stable ({(y == 1).sum()}) or unstable ({(y == 0).sum()}) features to train "
                         f"with {args.cv}-fold cross-validation")
    rng = np.random.default_rng(args.seed)
    sel = balanced(y, rng)
    if len(sel) > args.max_samples:
        sel = np.sort(rng.choice(sel, args.max_samples, replace=False))
    log(f"{len(sel)} balanced samples of {len(y)} labelled; grid search")
    pred = RobustnessPredictor.fit(X[sel], y[sel], detector=args.detector, cv=args.cv, seed=args.seed)
    pred.save(out, overwrite=True)
    print(f"wrote {out}: {len(pred.support_vectors)} support vectors, C {pred.info['C']:g}, gamma {pred.gamma:g}, "
          f"cross-validated accuracy {pred.info['cv_accuracy']:.3f}")
    return 0


def _run_select(args: argparse.Namespace) -> int:
    from ...features import RobustnessPredictor
    from ..._files import write_text_atomic

    pred = RobustnessPredictor.load(existing_path(args.predictor, "predictor file"))
    out = new_file(args.out, args.overwrite, "keypoint file")
    ds = _dataset(args.dataset, args.run_name, args.condition)
    images = []
    for i, path in enumerate(ds.image_paths):
        img = ds.image(i)
        if img.ndim != 3:
            raise UsageError(f"{path} is a gray image; robustness prediction needs RGB (the hue histogram)")
        kept = pred.select(img, args.top_k, method=args.method, candidates=args.candidates)
        scores = pred.score_keypoints(img, kept)
        images.append({"image": str(path.name), "frame": int(ds.frames[i]),
                       "keypoints": [[round(float(x), 2), round(float(y), 2), float(r), round(float(s), 4)]
                                     for (x, y), r, s in zip(kept.xy, kept.response, scores)]})
    doc = {"format": "sfanav-robust-keypoints", "version": 1, "detector": pred.detector, "top_k": args.top_k,
           "method": args.method, "candidates": args.candidates,
           "columns": ["x", "y", "response", "robustness"], "images": images}
    write_text_atomic(out, json.dumps(doc), overwrite=True)
    print(f"wrote {out}: {sum(len(im['keypoints']) for im in images)} keypoints of {len(images)} images")
    return 0
