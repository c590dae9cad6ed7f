"""A subject-specific emulator built from the app (``lvcore emulator build --geometry FILE``) in a background
thread, with progress, a stop request and a cache folder per request (:mod:`lvcore.app.subject_flow`)."""
from __future__ import annotations

import hashlib
import json
import tempfile
import threading
import time
from pathlib import Path
from typing import Mapping

from lvcore.exceptions import LVCoreError

#: Where the app keeps the subject emulators it builds (one folder per geometry, design and seed; a rebuild of
#: the same is found there, and a stopped or failed build resumes from the FE runs it kept).
BUILD_CACHE = Path(tempfile.gettempdir()) / "lvcore_subject_emulators"
#: Held-out accuracy targets of a subject emulator (issue 25): LVV RMSE (mL) and strain RMSE.
HELD_OUT_TARGETS = {"lvv_rmse_ml": 1.0, "strain_rmse": 0.003}
#: How the build log's line of the EDPVR stage begins (:func:`lvcore.emulator.subject._build_edpvr`).
EDPVR_STAGE = "EDPVR emulator:"


def build_dir(geometry_bytes: bytes, stem: str, *, units: str = "mm", design=None, seed: int = 0,
              resolution: str = "default", root: Path | None = None, edpvr: bool = False) -> Path:
    """The cache folder of a subject emulator: named by the geometry file's stem and a digest of its contents,
    units, design, seed, mesh and whether its own EDPVR emulator is built too (``edpvr``), so the same request
    finds the same folder (and a build without the EDPVR emulator is not taken for one with it)."""
    from lvcore.emulator.subject import SubjectDesign
    from lvcore.app.uploads import safe_name

    design = design or SubjectDesign()
    request = {"units": units, "design": [design.n_train, design.n_valid, design.n_test, design.method],
               "seed": int(seed), "resolution": resolution}
    if edpvr:  # only then: the folders of the builds without it keep their names
        request["edpvr"] = True
    key = json.dumps(request, sort_keys=True).encode()
    digest = hashlib.sha256(bytes(geometry_bytes) + b"\0" + key).hexdigest()[:16]
    return Path(root or BUILD_CACHE) / f"{safe_name(Path(stem).stem, 'geometry')}-{digest}"


def held_out_summary(metadata: Mapping) -> dict:
    """The held-out test accuracy of a subject emulator (``metadata["test"]``: FE runs the training never saw),
    the run counts and wall time, whether the accuracy meets :data:`HELD_OUT_TARGETS`, and its own EDPVR
    emulator's summary (``edpvr``; None when it was built without one)."""
    from lvcore.emulator.subject import describe_prior

    test = dict(metadata.get("test") or {})
    sub = dict(metadata.get("subject") or {})
    runs, secs = dict(sub.get("runs") or {}), dict(sub.get("seconds") or {})
    return {"n_test": test.get("n"), "lvv_rmse_ml": test.get("lvv_rmse_ml"), "strain_rmse": test.get("strain_rmse"),
            "runs_converged": runs.get("converged"), "runs_total": runs.get("total"), "wall_s": secs.get("total"),
            "geometry_source": sub.get("geometry_source"), "prior": describe_prior(sub.get("prior")),
            "within_targets": bool(test) and all(float(test[k]) <= v for k, v in HELD_OUT_TARGETS.items()),
            "edpvr": dict(sub["edpvr"]) if sub.get("edpvr") else None}


class SubjectBuild:
    """One subject-emulator build, ``lvcore emulator build --geometry FILE --out DIR``, for the app.

    :meth:`start` runs :func:`lvcore.emulator.subject.build_subject_emulator` in a background thread (or finds a
    finished build in ``out``); the page polls :attr:`fraction`, :attr:`lines` and :attr:`finished`. A failed or
    stopped build sets :attr:`error`, a message saying what to do; the FE runs done are kept in ``out`` and the
    next build of the same design resumes from them.

    Parameters
    ----------
    geometry_file : path
        The geometry as the CLI's ``--geometry`` takes it (a volume or template mesh, contours, PC scores).
    out : path
        The emulator folder (:func:`build_dir`).
    design : lvcore.emulator.subject.SubjectDesign, optional
        Run counts; default the CLI's (``SubjectDesign()``: 512 + 50 + 100).
    units : str
        Units of a volume mesh.
    workers, seed, resolution
        As the CLI's ``--workers`` (2), ``--seed`` (0) and ``--resolution`` (``default``).
    label : str, optional
        The user's name of the geometry (messages).
    edpvr : bool
        Also build the subject's own EDPVR emulator (``--edpvr``; default
        :data:`lvcore.emulator.subject.DEFAULT_EDPVR`, on: the geometry is a mesh file): the derived EDPVR and
        stress of a calibration through it then take a fraction of a second instead of FE load paths.
    """

    def __init__(self, geometry_file, out, *, design=None, units: str = "mm", workers: int = 2, seed: int = 0,
                 resolution: str = "default", label: str | None = None, edpvr: bool | None = None):
        from lvcore.emulator.subject import DEFAULT_EDPVR, SubjectDesign

        self.geometry_file = Path(geometry_file)
        self.out = Path(out)
        self.design = design or SubjectDesign()
        self.units, self.workers, self.seed, self.resolution = units, int(workers), int(seed), resolution
        self.label = label or self.geometry_file.name
        self.edpvr = DEFAULT_EDPVR if edpvr is None else bool(edpvr)
        self.lines: list[str] = []
        self.done_runs = 0
        self.error: str | None = None
        self.metadata: dict | None = None
        self.finished = False
        self.cached = False
        self.t0 = time.perf_counter()
        self.elapsed: float | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # --- state the page reads ------------------------------------------------
    @property
    def total_runs(self) -> int:
        return int(self.design.total)

    @property
    def running(self) -> bool:
        return not self.finished

    @property
    def ok(self) -> bool:
        return self.finished and self.error is None and self.metadata is not None

    @property
    def fraction(self) -> float:
        """Progress in [0, 1]: the FE runs are 90 %, the training (and the EDPVR emulator's load paths) the rest."""
        if self.finished:
            return 1.0
        if self.edpvr and any(line.startswith(EDPVR_STAGE) for line in self.lines):
            return 0.95
        return 0.9 * min(1.0, self.done_runs / max(1, self.total_runs))

    def status(self) -> str:
        """One line: what the build is doing now."""
        t = (self.elapsed if self.elapsed is not None else time.perf_counter() - self.t0)
        if self.finished:
            return f"{'found in the cache' if self.cached else 'built'} in {t:.0f} s" if self.ok else "failed"
        if self.done_runs < self.total_runs:
            return f"FE runs {self.done_runs} of {self.total_runs} ({t:.0f} s)"
        if self.edpvr and any(line.startswith(EDPVR_STAGE) for line in self.lines):
            return f"building the EDPVR emulator: FE load paths of 0-30 mmHg ({t:.0f} s)"
        return f"training the network on the converged runs ({t:.0f} s)"

    # --- running -------------------------------------------------------------
    def start(self, background: bool = True) -> "SubjectBuild":
        """Start the build (in a daemon thread unless ``background`` is False); a finished build in ``out`` is
        loaded instead."""
        if (self.out / "metadata.json").is_file() and (self.out / "network.npz").is_file():
            try:
                from lvcore.emulator.io import load_emulator

                metadata = dict(load_emulator(self.out).metadata)
                if not self.edpvr or "edpvr" in dict(metadata.get("subject") or {}):  # else: build it with one
                    self.metadata, self.cached = metadata, True
                    self._finish()
                    return self
            except LVCoreError:
                pass  # damaged: build again
        if background:
            self._thread = threading.Thread(target=self.run, name=f"subject-emulator {self.label}", daemon=True)
            self._thread.start()
        else:
            self.run()
        return self

    def stop(self) -> None:
        """Ask the build to stop before its next batch of FE runs (the runs done are kept)."""
        self._stop.set()

    def join(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def run(self) -> None:
        """The build itself (what the thread runs)."""
        from lvcore.emulator.subject import build_subject_emulator

        try:
            emu = build_subject_emulator(self.geometry_file, self.out, design=self.design, units=self.units,
                                         workers=self.workers, seed=self.seed, resolution=self.resolution,
                                         log=self.lines.append, progress=self._progress, stop=self._stop.is_set,
                                         edpvr=self.edpvr)
            self.metadata = dict(emu.metadata)
        except (LVCoreError, ValueError) as err:
            self.error = self._failure(str(err))
        except Exception as err:  # noqa: BLE001 - a dead worker or the like: shown to the user, never a traceback
            self.error = self._failure(f"{type(err).__name__}: {err}")
        finally:
            self._finish()

    def _progress(self, done: int, total: int) -> None:
        self.done_runs = int(done)

    def _finish(self) -> None:
        self.elapsed = time.perf_counter() - self.t0
        self.finished = True

    def _failure(self, reason: str) -> str:
        from lvcore.emulator.subject import RUNS_FILE

        kept = (f"The {self.done_runs} FE runs done are kept ({self.out / RUNS_FILE}); build again with the same "
                "geometry, design size and seed to resume from them") if self.done_runs else "No FE run was finished"
        d = self.design
        return (f"The subject emulator for {self.label} was not built: {reason}. {kept}. If it fails again, run it "
                f"in a terminal, where it reports every stage: lvcore emulator build --geometry {self.label} "
                f"--units {self.units} --n-train {d.n_train} --n-valid {d.n_valid} --n-test {d.n_test}"
                f" {'--edpvr' if self.edpvr else '--no-edpvr'} --out {self.out}")

