"""``lvcore report --out DIR [--from RESULTS]``."""
from __future__ import annotations

from lvcore import cli_args
from lvcore.studies.registry import STUDIES


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "report", help="regenerate the chapter's figures and tables (PNG, SVG, HTML, data, index.html, manifest.json)",
        description="Regenerate every figure and table of the chapter that the project reproduces. Study results "
                    "come from --from RESULTS (the --out folders of `lvcore study ...`) or else the package's "
                    "bundled lvcore/assets/studies; figures without results are listed as missing in manifest.json.")
    p.add_argument("--out", type=cli_args.output_dir, required=True, help="output folder, created if missing")
    files = ", ".join(s.result_file for s in STUDIES.values() if s.result_file)
    p.add_argument("--from", dest="results", default=None,
                   help=f"folder with study results, the --out folder of `lvcore study ...` ({files}; "
                        "default: the bundled results in assets/studies)")
    p.add_argument("--sweep", choices=("emulator", "simulator"), default="emulator",
                   help="Fig 9.5 by the bundled `angles` emulator (default, seconds) or the FE simulator (fast mesh)")
    p.add_argument("--no-calibration", action="store_true", help="skip the live calibration posterior")
    p.add_argument("--formats", default="png,svg", type=_formats,
                   help="static formats, comma-separated (default png,svg; they need kaleido, pip install "
                        "'lvcore[report]', and a Chromium; without them the HTML report is written and the skipped "
                        "formats are named); '' for HTML only")
    p.add_argument("--json", action="store_true", help="print the manifest as JSON")
    p.set_defaults(func=_run)


#: Static figure formats ``--formats`` accepts (those plotly's kaleido writes).
STATIC_FORMATS = ("png", "svg", "pdf", "jpeg", "webp")


def _formats(text: str) -> str:
    """``type=`` of ``--formats``: a comma-separated subset of :data:`STATIC_FORMATS` (or '')."""
    import argparse

    bad = [f.strip() for f in str(text).split(",") if f.strip() and f.strip().lower() not in STATIC_FORMATS]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown format {cli_args.echo(bad[0])!r}; choose from "
                                         f"{', '.join(STATIC_FORMATS)}, comma-separated, or '' for HTML only")
    return ",".join(f.strip().lower() for f in str(text).split(",") if f.strip())


def _run(args) -> int:
    import json
    import sys

    from lvcore.inference.samplers import use_host_devices

    use_host_devices(4)  # before JAX starts: one host device per calibration chain
    from lvcore.report.build import build_report

    formats = tuple(f.strip() for f in args.formats.split(",") if f.strip())
    manifest = build_report(args.out, args.results, sweep=args.sweep, calibration=not args.no_calibration,
                            formats=formats, progress=None if args.json else (lambda m: print(m, flush=True)))
    if args.json:
        print(json.dumps(manifest, indent=1))
    else:
        ok = [f for f in manifest["figures"] if f["status"] == "ok"]
        missing = [f for f in manifest["figures"] if f["status"] != "ok"]
        print(f"wrote {len(ok)} figures/tables to {args.out} in {manifest['wall_s']:.0f} s "
              f"(index.html, manifest.json)")
        for f in missing:
            print(f"  missing {f['name']}: {f['missing']}")
    if manifest.get("skipped_formats"):  # the HTML report is complete; say what was not written, on stderr
        print(f"static formats skipped: {', '.join(manifest['skipped_formats'])} "
              f"({manifest['static_export_error']})", file=sys.stderr)
    return 0
