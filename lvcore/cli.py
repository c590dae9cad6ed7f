"""The ``lvcore`` command. Each stage owns its sub-commands in a ``cli`` module
exposing ``register(subparsers)``; this file only wires them together."""
from __future__ import annotations

import argparse
import importlib
import sys
import traceback
import warnings

#: Modules that contribute sub-commands, in the order of the data flow.
COMMAND_MODULES = (
    "lvcore.mechanics.cli",     # lvcore simulate
    "lvcore.geometry.cli",      # lvcore geometry ...
    "lvcore.campaigns.cli",     # lvcore campaign run|status|resume, lvcore design
    "lvcore.emulator.cli",      # lvcore emulator train|info
    "lvcore.inference.cli",     # lvcore calibrate
    "lvcore.studies.cli",       # lvcore study ...
    "lvcore.report.cli",        # lvcore report
    "lvcore.app.cli",           # lvcore app
)

#: The top-level command(s) each module of :data:`COMMAND_MODULES` adds (``tests/test_cli.py`` checks the
#: two agree), so that a command imports only its own module: ``lvcore campaign status`` reads an HDF5 store
#: without importing the studies (and with them ArviZ, numpyro and the report).
COMMANDS = {
    "simulate": "lvcore.mechanics.cli",
    "geometry": "lvcore.geometry.cli",
    "campaign": "lvcore.campaigns.cli",
    "design": "lvcore.campaigns.cli",
    "emulator": "lvcore.emulator.cli",
    "calibrate": "lvcore.inference.cli",
    "study": "lvcore.studies.cli",
    "report": "lvcore.report.cli",
    "app": "lvcore.app.cli",
}

#: ``lvcore --help``'s line for each command, in the order the modules register them: the top-level help
#: (and the error for a missing or unknown command) is built from these without importing any command module,
#: so it takes a fraction of a second (``tests/test_cli_startup.py`` checks them against each module's own).
COMMAND_HELP = {
    "simulate": "run one forward simulation of a case file",
    "geometry": "fit segmentations to the LV template, inspect meshes, PCA",
    "design": "write a space-filling design (CSV) over a named parameter space",
    "campaign": "run, resume or inspect a simulation campaign",
    "emulator": "train or inspect neural-network emulators",
    "calibrate": "infer theta = (a, b, af, bf) from measured LVV + 24 strains",
    "study": "run one of the chapter's studies",
    "report": "regenerate the chapter's figures and tables (PNG, SVG, HTML, data, index.html, manifest.json)",
    "app": "start the Streamlit app (streamlit run on the packaged entry script)",
}

#: Warnings from modules matching this (every module outside lvcore, e.g. ArviZ's "ArviZ is undergoing a major
#: refactor" FutureWarning) are not shown by ``lvcore`` when their category is one of
#: :data:`QUIET_CATEGORIES`: they speak to the developers of lvcore, not to its users.
THIRD_PARTY_MODULES = r"(?!lvcore(\.|$)|__main__$)"
#: Categories of third-party warnings that ``lvcore`` does not show (library deprecation chatter).
QUIET_CATEGORIES = (FutureWarning, DeprecationWarning, PendingDeprecationWarning)


def build_parser(command: str | None = None, *, commands_only: bool = False) -> argparse.ArgumentParser:
    """The ``lvcore`` parser.

    Parameters
    ----------
    command : str, optional
        A top-level command of :data:`COMMANDS`: register only the module that
        adds it (what ``main`` does once the command line names one). Default:
        every module.
    commands_only : bool
        Without ``command``: the top level only, each command with its line of
        :data:`COMMAND_HELP` and no options of its own, importing no command
        module (what ``main`` uses for ``lvcore --help`` and a missing or
        unknown command; the same help text as the full parser's).
    """
    parser = argparse.ArgumentParser(
        prog="lvcore", description="LV Calibration Lab command line",
        epilog="exit codes: " + "; ".join(f"{code} {text}" for code, text in EXIT_CODES.items()))
    parser.add_argument("--debug", action="store_true",
                        help="on an internal error print the full traceback (otherwise one line)")
    sub = parser.add_subparsers(dest="command", required=True)
    if commands_only and command not in COMMANDS:
        for name, text in COMMAND_HELP.items():
            sub.add_parser(name, help=text)
    else:
        for name in ((COMMANDS[command],) if command in COMMANDS else COMMAND_MODULES):
            importlib.import_module(name).register(sub)
    for p in _all_parsers(parser):
        p.formatter_class = HelpFormatter
    return parser


class HelpFormatter(argparse.HelpFormatter):
    """Help that states every option's default: ``(default: X)`` is appended where the text does not say it."""

    def _get_help_string(self, action):
        text = action.help or ""
        if (action.option_strings and "default" not in text.lower() and action.default not in (None, False)
                and action.default is not argparse.SUPPRESS and not isinstance(action, argparse._HelpAction)):
            text += " (default: %(default)s)"
        return text


def _all_parsers(parser):
    """``parser`` and every sub-command parser under it."""
    out = [parser]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):
                out += _all_parsers(child)
    return out


#: Exit codes of ``lvcore`` (docs/reliability.md). ``EXIT_FLAGGED`` is ``lvcore.inference.cli.EXIT_FLAGGED``.
EXIT_OK, EXIT_NOT_CONVERGED, EXIT_BAD_INPUT, EXIT_INTERNAL, EXIT_FLAGGED, EXIT_INTERRUPTED = 0, 1, 2, 3, 4, 130
#: What each exit code means, as ``lvcore --help`` lists them; README.md and docs/reliability.md list the same.
EXIT_CODES = {
    EXIT_OK: "success",
    EXIT_NOT_CONVERGED: "did not converge (the solver, or a posterior that fails its R-hat/ESS checks)",
    EXIT_BAD_INPUT: "bad input (the message names the file and the field)",
    EXIT_INTERNAL: "internal error (a bug; rerun with --debug for the traceback)",
    EXIT_FLAGGED: "ran, results flagged (`lvcore calibrate`: every posterior converged and was written, but the "
                  "verdict flagged at least one run)",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C)",
}


def main(argv=None) -> int:
    """Run ``lvcore`` with ``argv`` (default ``sys.argv[1:]``) and return its exit code (docs/reliability.md)."""
    with warnings.catch_warnings():
        for category in QUIET_CATEGORIES:
            warnings.filterwarnings("ignore", category=category, module=THIRD_PARTY_MODULES)
        return _main(argv)


def _main(argv) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # --debug is global but accepted anywhere before a "--"
    cut = argv.index("--") if "--" in argv else len(argv)
    debug = "--debug" in argv[:cut]
    argv = [a for a in argv[:cut] if a != "--debug"] + argv[cut:]
    # the only global options are --debug (removed above) and -h, so a command is the first word
    # no command (lvcore --help) or an unknown one: the top level alone, no command module imported
    parser = build_parser(argv[0] if argv and argv[0] in COMMANDS else None, commands_only=True)
    args, extra = parser.parse_known_args(argv)
    if extra and not getattr(args, "passthrough", False):  # only `lvcore app` passes options on (to streamlit)
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    args.extra = extra
    from lvcore.exceptions import LVCoreError, SolverError

    try:
        return int(args.func(args) or 0)
    except SolverError as err:
        print(f"lvcore: did not converge: {err}", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    except LVCoreError as err:
        text = str(err)
        print(f"lvcore: error: {text if len(text) <= 4000 else text[:4000] + '...'}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as err:
        if err.filename is None:
            return _internal(err, debug)
        # a path the user named cannot be read or written (read-only folder, a file where a folder is needed,
        # a full disk): bad input, exit 2, naming the path
        from lvcore.cli_args import echo

        where = f"'{echo(err.filename)}'" + (f" -> '{echo(err.filename2)}'" if err.filename2 else "")
        print(f"lvcore: error: cannot use {where}: {err.strerror or type(err).__name__}; check the path given "
              "on the command line (--out, --from, ...) and its permissions", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("lvcore: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as err:  # noqa: BLE001 - the last line of defence: one line, exit 3
        return _internal(err, debug)


def _internal(err: BaseException, debug: bool) -> int:
    if debug:
        traceback.print_exception(err)
    print(f"lvcore: internal error: {type(err).__name__}: {_one_line(err)}"
          + ("" if debug else " (rerun with --debug for the traceback)"), file=sys.stderr)
    return EXIT_INTERNAL


def _one_line(err: BaseException, limit: int = 2000) -> str:
    text = " ".join(str(err).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
