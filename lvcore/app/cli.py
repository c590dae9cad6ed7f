"""``lvcore app``: start the Streamlit app shipped with the package."""
from __future__ import annotations

import os
import subprocess
import sys

from lvcore.app import ENTRY


def register(subparsers) -> None:
    """Add the ``app`` sub-command."""
    p = subparsers.add_parser(
        "app",
        help="start the Streamlit app (streamlit run on the packaged entry script)",
        description="Start the LV Calibration Lab app. Options this command does not know are passed to "
                    "`streamlit run`, e.g. `lvcore app --port 8502 --server.headless true "
                    "--server.address 127.0.0.1`.",
    )
    p.add_argument("--port", type=int, default=None, help="port to serve on (default: Streamlit's, 8501)")
    p.set_defaults(func=run_app, passthrough=True)


def streamlit_command(port: int | None = None, extra=()) -> list[str]:
    """The ``python -m streamlit run`` command line for the packaged app."""
    from lvcore.app.uploads import MAX_UPLOAD_MB

    # the upload limit travels with the command (a .streamlit/config.toml is read only from the working directory)
    # no usage statistics: nothing leaves localhost (also in .streamlit/config.toml for `streamlit run app.py`)
    cmd = [sys.executable, "-m", "streamlit", "run", str(ENTRY), "--server.maxUploadSize", str(MAX_UPLOAD_MB),
           "--browser.gatherUsageStats", "false"]
    if port is not None:
        cmd += ["--server.port", str(int(port))]
    return cmd + list(extra)


def run_app(args) -> int:
    from lvcore.app.memory import launch_environment

    cmd = streamlit_command(args.port, getattr(args, "extra", ()))
    os.environ.update(launch_environment())  # under ulimit -v: fewer malloc arenas, Arrow's system allocator
    sys.stdout.flush()
    if os.name != "posix":  # pragma: no cover (Windows)
        return subprocess.call(cmd)
    os.execv(cmd[0], cmd)  # become the server, so signals (Ctrl-C, kill) reach it directly; does not return
    return 0
