"""The ``sfanav`` command.

Subcommands (more follow: ``train``, ``localize``, ``evaluate``, ``demo``,
``experiment``):

* ``sfanav simulate --preset NAME --out DIR [--seed N]``: a dataset from the
  built-in garden simulator.

Errors in the input (unknown preset, bad size, an existing output directory,
...) end with a one-line message on stderr and exit status 2, never a
traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

EXIT_USAGE = 2

# subcommand name -> function that adds its parser (with a ``run`` default)
_COMMANDS: dict[str, Callable[[argparse._SubParsersAction], argparse.ArgumentParser]] = {}


def command(name: str) -> Callable:
    """Registers a subcommand: the decorated function adds its parser to the
    subparsers and sets the parser's ``run`` default to the function that
    executes it (returning the exit status)."""

    def deco(add_parser: Callable[[argparse._SubParsersAction], argparse.ArgumentParser]) -> Callable:
        _COMMANDS[name] = add_parser
        return add_parser

    return deco


class _UsageError(Exception):
    pass


def _size(text: str) -> tuple[int, int]:
    try:
        if "x" in text.lower():
            w, h = (int(v) for v in text.lower().split("x"))
        else:
            w = h = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be WIDTHxHEIGHT (e.g. 600x60) or one number, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"size must be positive, got {text!r}")
    return w, h


def _nonneg_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}")
    return v


def _pos_int(text: str) -> int:
    v = _nonneg_int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return v


# ---------------------------------------------------------------- simulate


@command("simulate")
def _add_simulate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from .sim import presets

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
    p.add_argument("--seed", type=_nonneg_int, default=0, help="seed of world, trajectories and noise (default 0)")
    p.add_argument("--max-frames", type=_pos_int, default=None, metavar="N",
                   help="keep only the first N frames of every run (quick looks)")
    p.add_argument("--camera", choices=("panorama", "omni"), default=None,
                   help="replace the preset's camera by a panoramic or an omnidirectional one")
    p.add_argument("--size", type=_size, default=None, metavar="WxH",
                   help="image size (panorama WIDTHxHEIGHT, omni SIZE); default the preset's")
    p.add_argument("--gray", action="store_true", help="gray images instead of RGB")
    p.add_argument("--overwrite", action="store_true", help="replace an existing dataset in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_simulate)
    return p


def _run_simulate(args: argparse.Namespace) -> int:
    from .sim import OmniCamera, PanoramicCamera, presets

    if args.preset not in presets.PRESETS:
        raise _UsageError(f"unknown preset {args.preset!r}; available: {', '.join(presets.PRESETS)}")
    p = presets.get(args.preset)
    camera = None
    if args.camera or args.size or args.gray:
        base = p.camera()
        kind = args.camera or base.kind
        if kind == "omni":
            size = args.size[0] if args.size else (base.size if isinstance(base, OmniCamera) else 500)
            if args.size and args.size[0] != args.size[1]:
                raise _UsageError(f"an omni image is square: give --size N or NxN, got {args.size[0]}x{args.size[1]}")
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
    ds = presets.simulate(args.preset, args.out, args.seed, max_frames=args.max_frames, camera=camera,
                          overwrite=args.overwrite, progress=not args.no_progress)
    print(f"wrote {len(ds)} images to {args.out}")
    return 0


# ---------------------------------------------------------------- main


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (no usage dump)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="sfanav",
        description="Localization and navigation from a panoramic camera with hierarchical Slow Feature Analysis.",
    )
    from . import __version__

    parser.add_argument("--version", action="version", version=f"sfanav {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for add in _COMMANDS.values():
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``sfanav`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except _UsageError as exc:
        parser.exit(EXIT_USAGE, f"sfanav {args.command}: error: {exc}\n")
    except (ValueError, TypeError, FileNotFoundError, FileExistsError, NotADirectoryError,
            PermissionError, ImportError) as exc:
        parser.exit(EXIT_USAGE, f"sfanav {args.command}: error: {exc}\n")
    except KeyboardInterrupt:
        parser.exit(130, "interrupted\n")
    return 0  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
