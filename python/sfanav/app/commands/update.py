"""``sfanav update``: a trained network with a new run added (its top
layer's slow features re-solved from the stored statistics plus the run's)."""

from __future__ import annotations

import argparse

from ..common import existing_path, log, new_file, wrap
from ..failures import UsageError
from ..registry import command


@command("update")
def _add_update(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "update",
        help="add a new run to a trained network without retraining it",
        description=wrap("Add the images of a new run to a network model file saved with its training statistics "
                         "(Network.save(..., include_statistics=True)): the run is streamed through the frozen "
                         "lower layers, its statistics are added to the stored ones as a recording of its own, and "
                         "the top layer's slow features are solved again, exactly as if that stage had been trained "
                         "on all the runs. MODEL is left as it was; NEW is written atomically. A run whose images "
                         "do not match the model (size, channels, pixel scale) is refused. See docs/updates.md."),
        epilog="example:\n  sfanav update net.sfanav --dataset week2 --out net-week2.sfanav",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", metavar="MODEL", help="network model file with training statistics")
    p.add_argument("--dataset", required=True, metavar="RUN", help="dataset folder holding the new run")
    p.add_argument("--run", dest="run_name", default=None, metavar="NAME", help="run of the dataset (default: all)")
    p.add_argument("--camera", default=None, metavar="NAME", help="camera to use if the dataset has several")
    p.add_argument("--out", required=True, metavar="NEW", help="the updated model file")
    p.add_argument("--overwrite", action="store_true", help="replace NEW if it exists")
    p.add_argument("--drop-statistics", action="store_true",
                   help="write NEW without its training statistics (smaller; it cannot be updated again)")
    p.set_defaults(run=_run_update)
    return p


def _run_update(args: argparse.Namespace) -> int:
    import numpy as np

    from ...data.dataset import Dataset
    from ...data.sources import select_run
    from ...sfa.modelfile import load
    from ...sfa.network import Network
    from ...sfa.updates import NetworkUpdater, statistics_bytes

    model = existing_path(args.model, "model file")
    out = new_file(args.out, args.overwrite, "model file")
    if out.resolve() == model.resolve():
        raise UsageError("--out must differ from MODEL: an update leaves the model it starts from as it was")
    net = load(model)
    if not isinstance(net, Network):
        raise UsageError(f"{model} holds a {type(net).__name__}; sfanav update adds runs to network model files "
                         "(a localizer's readout cannot be updated yet)")
    updater = NetworkUpdater(net)  # refuses a model without statistics before the run is read
    ds = select_run(Dataset(existing_path(args.dataset, "dataset")), args.run_name, args.camera)
    h, _, c = net.input_shape
    period = net.period_
    native = ds.images(gray=c == 1, indices=np.arange(1))
    first = np.asarray(next(iter(native)))
    if first.shape[:2] != (h, period):
        raise UsageError(f"the run's images are {first.shape[1]}x{first.shape[0]}, but the model was trained on "
                         f"{period}x{h} panoramas: the run does not match the model")
    images = updater.check_run(np.stack(list(ds.images(gray=c == 1))))
    log(f"adding {len(images)} images of {args.dataset} to {model}")
    updater.partial_fit(images)
    new = updater.network_
    new.save(out, include_statistics=not args.drop_statistics)
    stats = statistics_bytes(new)
    print(f"updated with {len(images)} images; training statistics "
          + ("dropped" if args.drop_statistics else f"kept ({stats} bytes)") + f"; wrote {out}")
    return 0
