"""The table of ``sfanav`` subcommands: each module of
``sfanav.app.commands`` registers its subcommands here with
:func:`command`, and :func:`sfanav.app.cli.build_parser` adds them in
registration order."""

from __future__ import annotations

import argparse
from collections.abc import Callable

#: subcommand name -> function that adds its parser (with a ``run`` default)
COMMANDS: dict[str, Callable[[argparse._SubParsersAction], argparse.ArgumentParser]] = {}


def command(name: str) -> Callable:
    """Registers a subcommand: the decorated function adds its parser to the
    subparsers and sets the parser's ``run`` default to the function that
    executes it (returning the exit status)."""

    def deco(add_parser: Callable[[argparse._SubParsersAction], argparse.ArgumentParser]) -> Callable:
        COMMANDS[name] = add_parser
        return add_parser

    return deco
