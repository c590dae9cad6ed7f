"""Option types shared by the ``lvcore`` sub-commands: bounded numbers, seeds, output paths; and the two
helpers that add a sub-command (:func:`command`) or a group of them (:func:`command_group`) to a parser.

Each option type is an ``argparse`` ``type=`` callable. A value outside its
range is refused by argparse itself, so the command exits with 2 and a message
that names the option (``argument --n: must be an integer from 1 to
100,000, got 1e9``) before anything runs. User input is echoed at most
:data:`ECHO_CHARS` characters long.
"""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from lvcore.safety.limits import MAX_ECHO_CHARS as ECHO_CHARS
from lvcore.safety.limits import echo
#: Largest seed accepted (numpy, scipy.stats.qmc and JAX all take a non-negative 32-bit integer).
MAX_SEED = 2 ** 32 - 1


def int_in(lo: int, hi: int | None = None):
    """An ``argparse`` type: an integer from ``lo`` to ``hi`` (inclusive; ``hi=None`` for no upper bound)."""
    span = f"from {lo:,} to {hi:,}" if hi is not None else f">= {lo:,}"

    def parse(text: str) -> int:
        try:
            value = int(str(text).strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer {span}, got '{echo(text)}'") from None
        if value < lo or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"must be an integer {span}, got {echo(value)}")
        return value

    parse.__name__ = "integer"
    return parse


def float_in(lo: float, hi: float, *, unit: str = "", open_lo: bool = False):
    """An ``argparse`` type: a finite number in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``)."""
    span = f"{'(' if open_lo else '['}{lo:g}, {hi:g}]{' ' + unit if unit else ''}"

    def parse(text: str) -> float:
        try:
            value = float(str(text).strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number in {span}, got '{echo(text)}'") from None
        if not math.isfinite(value) or value > hi or value < lo or (open_lo and value == lo):
            raise argparse.ArgumentTypeError(f"must be a number in {span}, got {echo(text)}")
        return value

    parse.__name__ = "number"
    return parse


#: ``type=`` of every ``--seed``: an integer from 0 to 2³² - 1.
seed = int_in(0, MAX_SEED)


def max_local_workers() -> int:
    """Most local worker processes: 4 per core (more only with a scheduler)."""
    return 4 * (os.cpu_count() or 1)


def workers(text: str) -> int:
    """``type=`` of ``--workers``: 1 to :func:`max_local_workers` (give a Dask scheduler for more)."""
    value = int_in(1, max_local_workers())
    try:
        return value(text)
    except argparse.ArgumentTypeError as err:
        raise argparse.ArgumentTypeError(f"{err} (4 per core on this machine; for more, give --scheduler)") from None


def _nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _check_parent(path: Path, kind: str) -> None:
    for parent in list(reversed(path.parents)):
        if parent.exists() and not parent.is_dir():
            raise argparse.ArgumentTypeError(f"'{echo(parent)}' is a file, not a folder, so {kind} "
                                             f"'{echo(path)}' cannot be created there")
    base = _nearest_existing(path.parent)
    if not os.access(base, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"folder '{echo(base)}' is not writable; choose another place for "
                                         f"{kind} '{echo(path)}'")


def output_file(text: str) -> Path:
    """``type=`` of an ``--out`` naming a file: not a folder, under folders that are folders and writable."""
    if not str(text).strip():
        raise argparse.ArgumentTypeError("is empty; give a file path")
    path = Path(text)
    if path.is_dir() or str(text).endswith(("/", os.sep)) or path.name in ("", ".", ".."):
        raise argparse.ArgumentTypeError(f"'{echo(text)}' is a folder; give a file path (e.g. {echo(text)}"
                                         f"{'' if str(text).endswith('/') else '/'}design.csv)")
    if path.exists() and not path.is_file():
        raise argparse.ArgumentTypeError(f"'{echo(text)}' exists and is not a regular file")
    if path.exists() and not os.access(path, os.W_OK):
        raise argparse.ArgumentTypeError(f"file '{echo(text)}' is not writable")
    _check_parent(path, "file")
    return path


def output_dir(text: str) -> Path:
    """``type=`` of an ``--out`` naming a folder: not an existing file, creatable and writable."""
    if not str(text).strip():
        raise argparse.ArgumentTypeError("is empty; give a folder path")
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"'{echo(text)}' is a file; give a folder (it is created if missing)")
    if path.is_dir() and not os.access(path, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"folder '{echo(text)}' is not writable")
    _check_parent(path, "folder")
    return path


def command(subparsers, name: str, func, *, help: str, description: str, **defaults) -> argparse.ArgumentParser:
    """Add the sub-command ``name``, run as ``func(args)`` (which returns the exit code); returns its parser.

    ``defaults`` are further ``set_defaults`` of the sub-command (values its options do not set).
    """
    parser = subparsers.add_parser(name, help=help, description=description)
    parser.set_defaults(func=func, **defaults)
    return parser


def command_group(subparsers, name: str, *, help: str, description: str):
    """Add ``name`` with sub-commands of its own, one of which must be given (``args.<name>_command`` names it);
    returns the action to add them to (with :func:`command`)."""
    parser = subparsers.add_parser(name, help=help, description=description)
    return parser.add_subparsers(dest=f"{name}_command", required=True)


__all__ = ["ECHO_CHARS", "MAX_SEED", "echo", "int_in", "float_in", "seed", "workers", "max_local_workers",
           "output_file", "output_dir", "command", "command_group"]
