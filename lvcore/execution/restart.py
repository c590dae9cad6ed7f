"""A long, resumable command restarts itself before the kernel's limit on memory mappings stops it.

Every compiled XLA CPU program keeps a few executable memory mappings, and Linux allows a process
``vm.max_map_count`` of them (65,530 by default). A study that runs hundreds of calibrations in one process
(``lvcore study sbc``, ``lvcore study information``) compiles thousands of programs; clearing JAX's caches
between subjects does not give all of them back (measured 2026-12-02: about 2,900 executable mappings after 66
calibrations with the caches cleared after every subject), and LLVM then aborts the process with "Unable to
allocate section memory". These commands record every finished run and resume from the records, so the cure
is to start afresh: :func:`restart_when_mappings_high` replaces the process by a new run of the same command
line (``os.execv``) once the mappings pass a share of the limit.

Examples
--------
>>> share = mapping_share()
>>> share is None or 0.0 < share < 1.0
True
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Callable

#: Share of ``vm.max_map_count`` at which a resumable command restarts itself.
RESTART_SHARE = 0.5
#: Set in the restarted process (how many restarts so far), so a command can tell the user it resumed.
RESTARTS_ENV = "LVCORE_RESTARTS"


def mapping_share() -> float | None:
    """This process's memory mappings as a share of the kernel's limit (None where ``/proc`` cannot tell)."""
    try:
        with open("/proc/self/maps", "rb") as f:
            maps = sum(1 for _ in f)
        limit = int(Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):
        return None
    return maps / limit if limit > 0 else None


def restart_when_mappings_high(say: Callable[[str], None] = print, share: float = RESTART_SHARE) -> None:
    """Replace this process by a fresh run of its own command line when its mappings pass ``share`` of the limit.

    Call it only between two recorded runs of a resumable command: the new process starts where the records
    stop. Nothing happens below the share, or where the share cannot be read.
    """
    now = mapping_share()
    if now is None or now < share:
        return
    n = int(os.environ.get(RESTARTS_ENV, "0")) + 1
    say(f"this process holds {now:.0%} of the kernel's memory-mapping limit (compiled programs); restarting it "
        f"(restart {n}) to resume from the recorded runs")
    sys.stdout.flush()
    sys.stderr.flush()
    os.environ[RESTARTS_ENV] = str(n)
    argv = list(getattr(sys, "orig_argv", None) or [sys.executable, *sys.argv])
    os.execv(sys.executable, [sys.executable, *argv[1:]])


__all__ = ["RESTART_SHARE", "RESTARTS_ENV", "mapping_share", "restart_when_mappings_high"]
