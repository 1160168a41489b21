"""The ``sfanav`` command.

Subcommands:

* ``sfanav simulate --preset NAME --out DIR [--seed N]``: a dataset from the
  built-in garden simulator.
* ``sfanav import BAG [BAG ...] --odom-topic T --out DIR``: a robot's ROS
  bags (images, odometry, ground truth) as a dataset, one run per bag.
* ``sfanav train --dataset DIR --preset NAME|--config FILE --out MODEL``:
  train a network under simulated rotation and the regression to metres.
* ``sfanav localize MODEL INPUT --out CSV|BAG``: positions of a dataset, an
  image folder or a video, one CSV row ``frame,x,y`` per image, or a ROS bag.
* ``sfanav evaluate MODEL DATASET --out DIR``: metrics, baselines, plots and a
  Markdown report.
* ``sfanav navigate MODEL DATASET --start X,Y --target X,Y --out DIR``: drive
  the simulated robot of a dataset's world to a target with a trained model.
* ``sfanav demo``: simulate, train, localize and evaluate the demo garden.
* ``sfanav experiment NAME`` / ``--list``: rerun a thesis experiment.

Errors in the input (unknown preset, bad size, an existing output directory,
a missing dataset, a bad network config or model file, a request beyond the
machine's memory, ...) end with a one-line message on stderr and exit status
2, never a traceback (set ``SFANAV_DEBUG=1`` to see the traceback); an exception
of another kind is a bug and shows its traceback. SIGINT and SIGTERM stop a command with
status 130 and 143, leaving no output that a later command takes for complete.
Results go to stdout, progress and notes to stderr.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from . import commands  # noqa: F401  (registers the subcommands)
from .failures import Terminated, UsageError, is_input_error, on_sigterm, one_line
from .registry import COMMANDS, command

__all__ = ["EXIT_USAGE", "build_parser", "command", "main"]

EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (no usage dump)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="sfanav",
        description="Localization and navigation from a panoramic camera with hierarchical Slow Feature Analysis.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"sfanav {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for add in COMMANDS.values():
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``sfanav`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, on_sigterm)
    else:  # pragma: no cover - main() called from a worker thread
        previous = None
    try:
        return int(args.run(args) or 0)
    except Exception as exc:
        # anything else is a bug: its traceback is the report
        if not is_input_error(exc):
            raise
        if os.environ.get("SFANAV_DEBUG") and not isinstance(exc, UsageError):
            raise  # the traceback, for bug reports
        parser.exit(EXIT_USAGE, f"sfanav {args.command}: error: {one_line(exc)}\n")
    except KeyboardInterrupt:
        parser.exit(130, "interrupted\n")
    except Terminated:
        parser.exit(143, "terminated\n")
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
