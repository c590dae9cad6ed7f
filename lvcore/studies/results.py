"""Saved study results: find and load them (``--out`` folders and the bundled ``studies/`` folder), and start small runs.

The app's Studies page reads everything through this module:

* :func:`result_sources` lists folders holding ``bo_fibres.json``,
  ``operators.json`` or ``fibre_discrepancy.json``: the bundled results of a
  shipped run (``studies/`` under the bundled assets) and any folder given;
* :func:`load_bo`, :func:`load_operators`, :func:`load_fibre_discrepancy`
  read one folder;
* :class:`BackgroundRun` starts ``lvcore study ...`` in a subprocess and
  reports its progress from the files it writes, so a page is never blocked.
"""
from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from lvcore.exceptions import LVCoreError
from lvcore.studies._common import bundled_path

#: The result file of each study.
RESULT_FILES = {"bo-fibres": "bo_fibres.json", "operators": "operators.json",
                "fibre-discrepancy": "fibre_discrepancy.json"}


def bundled_studies_dir() -> Path:
    """The bundled results of the shipped runs (``studies/`` under the bundled assets)."""
    return bundled_path("studies")


def result_sources(extra: Sequence = ()) -> dict[str, list[tuple[str, Path]]]:
    """Study -> ``[(label, folder)]`` of every folder holding its result file.

    Looks in the bundled ``studies/<study>/`` folders and in each folder of
    ``extra`` (an ``--out`` folder, or a parent of several).
    """
    found: dict[str, list[tuple[str, Path]]] = {k: [] for k in RESULT_FILES}
    roots = [("bundled", bundled_studies_dir())] + [(str(p), Path(p)) for p in extra]
    for label, root in roots:
        if not root.is_dir():
            continue
        for study, fname in RESULT_FILES.items():
            for f in sorted(root.glob(fname)) + sorted(root.glob(f"*/{fname}")):
                name = label if f.parent == root else f"{label}: {f.parent.name}"
                if (name, f.parent) not in found[study]:
                    found[study].append((name, f.parent))
    return found


def _read(path: Path):
    try:
        return json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise LVCoreError(f"cannot read study results '{path}': {err}") from None


def load_bo(folder) -> tuple[list[dict], dict]:
    """``(entries, meta)`` of a bo-fibres result folder (meta empty if ``bo_fibres_meta.json`` is missing)."""
    folder = Path(folder)
    entries = _read(folder / "bo_fibres.json")
    meta_path = folder / "bo_fibres_meta.json"
    meta = _read(meta_path) if meta_path.is_file() else {}
    if not meta:
        from lvcore.studies.bo_fibres import findings

        meta = {"findings": findings(entries)}
    return entries, meta


def load_operators(folder) -> dict:
    """``operators.json`` of a result folder, with ``surfaces`` from ``rss_surfaces.json`` when present."""
    folder = Path(folder)
    data = _read(folder / "operators.json")
    data["surfaces"] = []
    for name in ("rss_surfaces_simulator.json", "rss_surfaces.json"):  # simulator surfaces first
        if (folder / name).is_file():
            data["surfaces"] += _read(folder / name)
    data.pop("rss_surfaces", None)  # the flat copy for reports; the page uses the grouped files
    return data


def load_fibre_discrepancy(folder) -> dict:
    """``fibre_discrepancy.json`` of a result folder."""
    return _read(Path(folder) / "fibre_discrepancy.json")


# ----------------------------------------------------------------------------- background runs
@dataclass
class BackgroundRun:
    """A study command running in a subprocess; progress is read from the files it writes.

    Parameters
    ----------
    study : {"bo-fibres", "operators"}
    out : Path
        The run's ``--out`` folder.
    args : list of str
        Further command-line arguments.
    total : int
        Evaluations (bo-fibres) or fits (operators) the run will make, for the progress fraction.
    """

    study: str
    out: Path
    args: list
    total: int
    process: subprocess.Popen | None = None
    started: float = field(default_factory=time.time)

    def start(self) -> "BackgroundRun":
        if self.study not in ("bo-fibres", "operators"):
            raise LVCoreError(f"background runs exist for bo-fibres and operators, not {self.study!r}")
        self.out = Path(self.out)
        self.out.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "lvcore.cli", "study", self.study, *self.args, "--json", "--out", str(self.out)]
        log = open(self.out / "run.log", "w")  # noqa: SIM115 - owned by the child process
        self.process = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        return self

    def done_count(self) -> int:
        """Evaluations (bo-fibres: from the state files) or fits (operators: ``fits/``) finished so far."""
        if self.study == "operators":
            return len(list((self.out / "fits").glob("*.json")))
        n = 0
        for f in (self.out / "state").glob("*.json"):
            try:
                n += len(json.loads(f.read_text())["X"])
            except (OSError, json.JSONDecodeError, KeyError):
                pass  # being replaced right now; counted on the next poll
        return n

    @property
    def fraction(self) -> float:
        return min(1.0, self.done_count() / max(1, self.total))

    @property
    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    @property
    def returncode(self) -> int | None:
        return None if self.process is None else self.process.poll()

    def log_tail(self, n: int = 15) -> str:
        p = self.out / "run.log"
        return "\n".join(p.read_text(errors="replace").splitlines()[-n:]) if p.is_file() else ""

    def stop(self) -> None:
        if self.running:
            self.process.terminate()


def small_run(study: str, out, *, subject: str = "SYNTHETIC-HV1", patient: str = "SYNTHETIC-P01",
              n_initial: int = 6, n_iterations: int = 4, resolution: str = "fast", workers: int = 1) -> BackgroundRun:
    """A small background run for the app (fast mesh, one subject or patient)."""
    if study == "bo-fibres":
        args = ["--subjects", subject, "--initial", str(n_initial), "--iterations", str(n_iterations),
                "--resolution", resolution, "--workers", str(workers)]
        total = 2 * (n_initial + n_iterations)
    else:
        args = ["--patients", patient, "--resolution", resolution, "--workers", str(workers)]
        total = 12
    return BackgroundRun(study, Path(out), args, total).start()


__all__ = ["RESULT_FILES", "bundled_studies_dir", "result_sources", "load_bo", "load_operators",
           "load_fibre_discrepancy", "BackgroundRun", "small_run"]
