"""``sfanav simulate``: a dataset from the built-in garden simulator."""

from __future__ import annotations

import argparse

from .. import arguments as arg
from ..failures import UsageError
from ..registry import command


@command("simulate")
def _add_simulate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from ...sim import presets

    p = sub.add_parser(
        "simulate",
        help="generate a dataset with the built-in garden simulator",
        description="Generate a dataset (PNG images, frames.csv, metadata.json, world.json) from one of the "
                    "simulator presets of the thesis's scenes.",
        epilog="presets:\n" + "\n".join("  " + ln for ln in presets.describe().splitlines()),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--preset", required=True, metavar="NAME", help="scene preset (listed below)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (new or empty)")
    p.add_argument("--seed", type=arg.nonneg_int, default=0, help="seed of world, trajectories and noise (default 0)")
    p.add_argument("--max-frames", type=arg.pos_int, default=None, metavar="N",
                   help="keep only the first N frames of every run (quick looks)")
    p.add_argument("--camera", choices=("panorama", "omni"), default=None,
                   help="replace the preset's camera by a panoramic or an omnidirectional one")
    p.add_argument("--size", type=arg.size, default=None, metavar="WxH",
                   help="image size (panorama WIDTHxHEIGHT, omni SIZE); default the preset's")
    p.add_argument("--gray", action="store_true", help="gray images instead of RGB")
    p.add_argument("--overwrite", action="store_true", help="replace an existing dataset in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_simulate)
    return p


def _run_simulate(args: argparse.Namespace) -> int:
    from ...sim import OmniCamera, PanoramicCamera, presets, recording

    if args.preset not in presets.PRESETS:
        raise UsageError(f"unknown preset {args.preset!r}; available: {', '.join(presets.PRESETS)}")
    p = presets.get(args.preset)
    camera = None
    if args.camera or args.size or args.gray:
        base = p.camera()
        kind = args.camera or base.kind
        if kind == "omni":
            size = args.size[0] if args.size else (base.size if isinstance(base, OmniCamera) else 500)
            if args.size and args.size[0] != args.size[1]:
                raise UsageError(f"an omni image is square: give --size N or NxN, got {args.size[0]}x{args.size[1]}")
            camera = OmniCamera(size, rgb=not args.gray)
        else:
            if args.size:
                w, h = args.size
            elif isinstance(base, PanoramicCamera):
                w, h = base.width, base.height
            else:
                w, h = 600, 60
            el = base.elevation_deg if isinstance(base, PanoramicCamera) else (-30.0, 20.0)
            camera = PanoramicCamera(w, h, el, rgb=not args.gray)
    ds = recording.simulate(args.preset, args.out, args.seed, max_frames=args.max_frames, camera=camera,
                            overwrite=args.overwrite, progress=not args.no_progress)
    print(f"wrote {len(ds)} images to {args.out}")
    return 0
