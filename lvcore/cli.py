"""The ``lvcore`` command. Each stage owns its sub-commands in a ``cli`` module
exposing ``register(subparsers)``; this file only wires them together."""
from __future__ import annotations

import argparse
import importlib
import sys

#: Modules that contribute sub-commands, in the order of the data flow.
COMMAND_MODULES = (
    "lvcore.mechanics.cli",     # lvcore simulate
    "lvcore.geometry.cli",      # lvcore geometry ...
    "lvcore.campaigns.cli",     # lvcore campaign run|status|resume, lvcore design
    "lvcore.emulator.cli",      # lvcore emulator train|info
    "lvcore.inference.cli",     # lvcore calibrate
    "lvcore.studies.cli",       # lvcore study ...
    "lvcore.app.cli",           # lvcore app
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lvcore", description="LV Calibration Lab command line")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra and not getattr(args, "passthrough", False):  # only `lvcore app` passes options on (to streamlit)
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    args.extra = extra
    from lvcore.exceptions import LVCoreError

    try:
        return int(args.func(args) or 0)
    except LVCoreError as err:
        print(f"lvcore: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
