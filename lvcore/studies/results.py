"""Saved study results: the one locator of the bundled results, the shared JSON reader, and small background runs.

Each study module owns its results (``load(folder)``, ``tables(result)``,
``figures(result)``); this module only finds them:

* :func:`bundled_studies_dir` is the bundled results of the shipped runs
  (``studies/`` under the bundled assets), the only place that folder is located;
* :func:`find_result` looks a result file up in a given folder, then in the bundled one;
* :func:`result_sources` lists folders holding a study's result file
  (:data:`RESULT_FILES`, from the registry) for the app's Studies page;
* :func:`read_json` is the reader the study modules' ``load`` use;
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
from lvcore.studies.registry import STUDIES

#: The result file of each study that has one (study name -> file), from the registry.
RESULT_FILES = {s.name: s.result_file for s in STUDIES.values() if s.result_file}


def bundled_studies_dir() -> Path:
    """The bundled results of the shipped runs (``studies/`` under the bundled assets)."""
    from lvcore.resources import asset_path

    return asset_path("studies")


def find_result(filename: str, folder=None) -> Path | None:
    """``folder/filename`` if it exists, else the bundled ``studies/filename``, else None."""
    for d in ([Path(folder)] if folder else []) + [bundled_studies_dir()]:
        if (d / filename).is_file():
            return d / filename
    return None


def source_label(folder) -> str:
    """``bundled`` for the bundled results folder, else the folder's path (for source lines)."""
    folder = Path(folder)
    try:
        bundled = folder.resolve() == bundled_studies_dir().resolve()
    except OSError:
        bundled = False
    return "bundled" if bundled else str(folder)


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


#: Most result folders typed into the Studies page (each is searched one level deep).
MAX_TYPED_FOLDERS = 20


def parse_folders(text: str, max_folders: int = MAX_TYPED_FOLDERS) -> list[Path]:
    """Comma-separated result folders typed by a user (``~`` expanded); at most ``max_folders``.

    Raises
    ------
    LVCoreError
        More than ``max_folders`` folders; the message repeats at most 60 characters of the text.
    """
    from lvcore.safety.limits import echo

    items = [p.strip() for p in str(text).split(",") if p.strip()]
    if len(items) > max_folders:
        raise LVCoreError(f"{len(items):,} result folders typed ('{echo(text, 60)}'); give at most {max_folders}, "
                          "or their common parent folder")
    return [Path(p).expanduser() for p in items]


def read_result(folder, filename: str) -> dict:
    """A study's JSON result ``folder/filename`` (:func:`read_json`) with ``folder`` added: a study's ``load``."""
    data = read_json(Path(folder) / filename)
    data["folder"] = str(folder)
    return data


def read_json(path):
    """A study's JSON file; a clear :class:`LVCoreError` naming the file when it is missing, not a regular
    file, over :data:`lvcore.safety.limits.MAX_STUDY_RESULT_BYTES`, not UTF-8 text or not JSON."""
    from lvcore.safety import limits

    text = limits.read_text_file(path, limits.MAX_STUDY_RESULT_BYTES, "study results", LVCoreError)
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, RecursionError, ValueError) as err:
        raise LVCoreError(f"cannot read study results '{path}': not valid JSON ({str(err)[:200]})") from None
    return data


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


__all__ = ["RESULT_FILES", "bundled_studies_dir", "find_result", "source_label", "result_sources", "read_json",
           "BackgroundRun", "small_run"]
