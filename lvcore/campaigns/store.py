"""The campaign store: one HDF5 file (h5py) per campaign.

The file's layout (one fixed-size entry per design row in every dataset), its
format versions and the migration of a version-1 store are defined in
:mod:`lvcore.campaigns.store_format`; this module reads and writes stores
(:class:`CampaignStore`, :func:`read_store`) and summarises them.

Crash safety
------------
A row is committed by its ``state`` entry, which is written and flushed
*after* every other field of the row has been written and flushed. A process
killed with SIGKILL at any moment therefore leaves each row either committed
with all its fields or still pending (its partial fields are overwritten
when it is run again). Because no write after creation touches HDF5
metadata, the file stays readable. Only one process may write a store at a
time: a ``<store>.lock`` file is held with ``fcntl.flock`` (the kernel
releases it when the process dies).
"""
from __future__ import annotations

import fcntl
import json
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

import lvcore
from lvcore.safety import limits
from lvcore.campaigns.designs import Design
from lvcore.campaigns.store_format import (CONVERGED, FAILED, FORMAT, FORMAT_VERSION, PENDING, PROVENANCE,
                                          REASON_LEN, START_COLD, START_NAMES, START_RESOLVED, START_WARM,
                                          STATE_NAMES, VERSION_LEN, WORKER_LEN, add_provenance, layout_problem,
                                          migrate)
from lvcore.core.space import ParameterSpace
from lvcore.exceptions import CampaignError
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, N_OUTPUTS, OUTPUT_COLUMNS, STRAIN_LAYER_LABELS, strain_layer


def worker_tag() -> str:
    """``host:pid`` of the calling process."""
    return f"{socket.gethostname()}:{os.getpid()}"


@dataclass(frozen=True)
class RowResult:
    """The outcome of one design row, as produced by a worker.

    Parameters
    ----------
    index : int
        Row number in the design.
    outputs : np.ndarray
        ``(25,)`` [LVV mL, 24 strains]; ignored (stored as NaN) unless converged.
    converged : bool
        Whether the simulator converged.
    reason : str
        Why it failed (empty when converged).
    seconds : float
        Wall time of the solve (s).
    version : str
        ``lvcore.__version__`` in the worker.
    worker : str
        ``host:pid`` of the worker.
    chain, chain_position : int
        The continuation chain of the row and its place in it (-1: solved on its own).
    seed_row : int
        The store row whose converged state warm-started this one (-1: none).
    start : int
        :data:`START_COLD`, :data:`START_WARM` or :data:`START_RESOLVED` (a warm result discarded
        for a cold solve).
    resolve_reason : str
        Why a warm-started row was solved again cold (not stored; the driver passes it on to the chains).
    """

    index: int
    outputs: np.ndarray
    converged: bool
    reason: str = ""
    seconds: float = float("nan")
    version: str = lvcore.__version__
    worker: str = ""
    chain: int = -1
    chain_position: int = -1
    seed_row: int = -1
    start: int = START_COLD
    resolve_reason: str = ""


def _value(v) -> str:
    """A stored number as a message shows it: ``7``, ``1.5``, ``nan`` (integral floats without ``.0``)."""
    v = v.item() if isinstance(v, np.generic) else v
    if isinstance(v, float) and np.isfinite(v) and v == int(v):
        return str(int(v))
    return str(v)[:40]


def recorded_strain_layer(attrs: dict) -> str:
    """The wall layer of a store's strains: its ``strain_layer`` attribute (a name of
    :data:`lvcore.domain.outputs.STRAIN_LAYERS`); stores written before the layer was recorded hold the simulator's
    default, the inner half.

    Raises
    ------
    CampaignError
        An attribute that names no layer.
    """
    try:
        return strain_layer(str(attrs.get("strain_layer", DEFAULT_STRAIN_LAYER)), "store attribute strain_layer")
    except ValueError as err:
        raise CampaignError(str(err)) from None


@dataclass(frozen=True)
class StoreContents:
    """Everything in a store, read into memory (see the layout table of :mod:`lvcore.campaigns.store_format`)."""

    space: ParameterSpace
    inputs: np.ndarray
    outputs: np.ndarray
    state: np.ndarray
    seconds: np.ndarray
    reasons: tuple[str, ...]
    versions: tuple[str, ...]
    workers: tuple[str, ...]
    finished_at: np.ndarray
    record_count: np.ndarray
    attrs: dict
    #: Provenance (format version 2; -1 / 0 where not recorded): see :mod:`lvcore.campaigns.store_format`.
    run: np.ndarray | None = None
    chain: np.ndarray | None = None
    chain_position: np.ndarray | None = None
    seed_row: np.ndarray | None = None
    start: np.ndarray | None = None

    def solve_order(self) -> np.ndarray:
        """Committed rows in the order they were solved: by run, chain and place in the chain (rows without
        provenance last, by index)."""
        done = np.flatnonzero(self.state != PENDING)
        if self.run is None:
            return done
        known = done[self.run[done] >= 0]
        key = np.lexsort((self.chain_position[known], self.chain[known], self.run[known]))
        return np.concatenate([known[key], done[self.run[done] < 0]])

    @property
    def strain_layer(self) -> str:
        """The wall layer of the stored strains (:func:`recorded_strain_layer`)."""
        return recorded_strain_layer(self.attrs)

    @property
    def converged(self) -> np.ndarray:
        """Rows committed as converged that pass :meth:`check` (inconsistent rows are never counted)."""
        return (self.state == CONVERGED) & ~self.inconsistent

    @property
    def failed(self) -> np.ndarray:
        return (self.state == FAILED) & ~self.inconsistent

    @property
    def pending(self) -> np.ndarray:
        return (self.state == PENDING) & ~self.inconsistent

    @property
    def inconsistent(self) -> np.ndarray:
        """Rows whose fields contradict each other (see :meth:`check`)."""
        return self._problem_masks()[0]

    def check(self, limit: int | None = None) -> tuple[str, ...]:
        """One message per inconsistent row (the first ``limit`` rows), e.g. ``"row 3: state value 7 ..."``.

        A row is inconsistent when its ``state`` is not exactly 0, 1 or 2 (7,
        1.5 and NaN all are, whatever the dataset's type); when it is
        committed (converged or failed) but ``record_count`` is not 1; when it
        is converged with a NaN/inf output; or when its inputs are not finite or
        lie outside the store's parameter space. Such rows are excluded from
        :attr:`converged`, :attr:`failed` and :attr:`pending` (so from every
        count and from emulator training), and are not run by a resume.
        """
        bad, reasons = self._problem_masks()
        rows = np.flatnonzero(bad)
        if limit is not None:
            rows = rows[:limit]
        out = []
        for i in rows:
            why = "; ".join(text(int(i)) for mask, text in reasons if mask[i])
            out.append(f"row {int(i)}: {why}")
        return tuple(out)

    def _problem_masks(self):
        # compared as stored, never cast to int first: a float state 1.5 (or a record_count 1.5) would become 1
        state = np.asarray(self.state)
        count = np.asarray(self.record_count)
        bad_state = ~np.isin(state, (PENDING, CONVERGED, FAILED))
        done = (state == CONVERGED) | (state == FAILED)
        bad_count = done & (count != 1)
        nonfinite = (state == CONVERGED) & ~np.all(np.isfinite(self.outputs), axis=1)
        inputs = np.asarray(self.inputs, dtype=float)
        finite_in = np.all(np.isfinite(inputs), axis=1)
        outside = ~finite_in.copy()
        if finite_in.any():
            outside[finite_in] = ~self.space.contains(inputs[finite_in])
        reasons = (
            (bad_state, lambda i: f"state value {_value(state[i])} is none of 0 pending, 1 converged, 2 failed"),
            (bad_count, lambda i: f"{STATE_NAMES.get(int(state[i]), '?')} but recorded {_value(count[i])} times "
                                  "(a committed row is recorded once)"),
            (nonfinite, lambda i: "converged but its outputs contain NaN or inf"),
            (outside, lambda i: "its inputs are not finite or lie outside the store's parameter space"),
        )
        return bad_state | bad_count | nonfinite | outside, reasons


@dataclass(frozen=True)
class StoreSummary:
    """Counts per state and the failure reasons with their counts."""

    path: str
    n: int
    converged: int
    failed: int
    pending: int
    reasons: tuple[tuple[str, int], ...]
    mean_seconds: float
    versions: tuple[str, ...]
    space: str
    resolution: str
    forward: str
    inconsistent: int = 0
    problems: tuple[str, ...] = ()
    #: Committed rows started warm / re-solved cold after a discarded warm start (format version 2 stores).
    warm: int = 0
    resolved: int = 0
    #: The wall layer of the stored strains (:func:`recorded_strain_layer`).
    strain_layer: str = DEFAULT_STRAIN_LAYER

    def format(self, all_problems: bool = False) -> str:
        """Human-readable summary; the inconsistent rows are listed (the first 10 unless ``all_problems``)."""
        rows = f"  rows {self.n}: converged {self.converged}, failed {self.failed}, pending {self.pending}"
        if self.inconsistent:
            rows += f", inconsistent {self.inconsistent} (excluded from every count and from emulator training)"
        lines = [
            f"campaign store {self.path}",
            f"  space {self.space}, resolution {self.resolution}, forward {self.forward}, strains over the "
            f"{STRAIN_LAYER_LABELS.get(self.strain_layer, self.strain_layer)}",
            rows,
        ]
        if self.inconsistent:
            shown = self.problems if all_problems else self.problems[:10]
            lines.append("  inconsistent rows (the store was edited or damaged; rerun them in a new campaign):")
            lines += [f"    {p}" for p in shown]
            if len(shown) < self.inconsistent:
                lines.append(f"    ... and {self.inconsistent - len(shown)} more (lvcore campaign status --check)")
        if self.warm or self.resolved:
            lines.append(f"  warm-started {self.warm}, re-solved cold {self.resolved} (a warm start that reached an "
                         "unstable equilibrium)")
        if np.isfinite(self.mean_seconds):
            lines.append(f"  mean solve time {self.mean_seconds:.3f} s")
        if self.versions:
            lines.append(f"  simulator versions: {', '.join(self.versions)}")
        if self.reasons:
            lines.append("  failure reasons:")
            lines += [f"    {count:6d}  {reason}" for reason, count in self.reasons]
        return "\n".join(lines)


def _fixed_bytes(text: str, length: int) -> bytes:
    raw = str(text).encode("utf-8", "replace")[:length]
    return raw.decode("utf-8", "ignore").encode("utf-8")


def _decode(arr) -> tuple[str, ...]:
    return tuple(b.decode("utf-8", "replace") for b in np.asarray(arr))


class CampaignStore:
    """A campaign's HDF5 store. Use :meth:`create` or :meth:`open`.

    In write mode, the store holds the ``<path>.lock`` file lock until
    :meth:`close`. Use as a context manager.
    """

    def __init__(self, path: Path, h5: h5py.File, lock_fd: int | None):
        self.path = Path(path)
        self._h5 = h5
        self._lock_fd = lock_fd
        self._run: int | None = None  # the number of this writing session's run (set on the first record)

    # ----- life cycle -------------------------------------------------------
    @classmethod
    def create(cls, path: str | Path, design: Design, *, forward: str, resolution: str, overwrite: bool = False,
               strain_layer: str = DEFAULT_STRAIN_LAYER) -> "CampaignStore":
        """Create a store for ``design`` and open it for writing; ``strain_layer`` (the wall layer of the strains
        the forward model writes) is recorded as the store attribute ``strain_layer``.

        Raises
        ------
        CampaignError
            If ``path`` exists and ``overwrite`` is false (use ``resume``).
        """
        path = Path(path)
        if path.exists() and not overwrite:
            raise CampaignError(f"store '{path}' already exists; use `lvcore campaign resume {path}` or choose another --out")
        path.parent.mkdir(parents=True, exist_ok=True)
        lock_fd = cls._lock(path)
        tmp = path.with_name(path.name + ".creating")
        n, d = design.points.shape
        try:
            with h5py.File(tmp, "w") as f:
                f.attrs.update({
                    "format": FORMAT,
                    "format_version": FORMAT_VERSION,
                    "space": design.space.to_json(),
                    "input_names": json.dumps(list(design.space.names)),
                    "output_names": json.dumps(list(OUTPUT_COLUMNS)),
                    "design_method": design.method,
                    "design_seed": -1 if design.seed is None else int(design.seed),
                    "resolution": resolution,
                    "forward": forward,
                    "strain_layer": recorded_strain_layer({"strain_layer": strain_layer}),
                    "lvcore_version": lvcore.__version__,
                    "created_at": time.time(),
                })
                # Writing full arrays now allocates contiguous storage at creation,
                # so later row writes only touch raw data.
                f.create_dataset("inputs", data=np.asarray(design.points, dtype="f8"))
                f.create_dataset("outputs", data=np.full((n, N_OUTPUTS), np.nan))
                f.create_dataset("state", data=np.zeros(n, dtype="i1"))
                f.create_dataset("seconds", data=np.full(n, np.nan))
                f.create_dataset("reason", data=np.zeros(n, dtype=f"S{REASON_LEN}"))
                f.create_dataset("version", data=np.zeros(n, dtype=f"S{VERSION_LEN}"))
                f.create_dataset("worker", data=np.zeros(n, dtype=f"S{WORKER_LEN}"))
                f.create_dataset("finished_at", data=np.full(n, np.nan))
                f.create_dataset("record_count", data=np.zeros(n, dtype="i4"))
                add_provenance(f, n)
            os.replace(tmp, path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            cls._unlock(lock_fd)
            raise
        return cls(path, h5py.File(path, "r+"), lock_fd)

    @classmethod
    def open(cls, path: str | Path, mode: str = "r") -> "CampaignStore":
        """Open an existing store, ``mode`` ``"r"`` (read) or ``"r+"`` (write, locked)."""
        path = limits.check_regular_file(path, float("inf"), "store", CampaignError)
        lock_fd = cls._lock(path) if mode == "r+" else None
        if mode == "r+":
            try:
                migrate(path)
            except BaseException:
                cls._unlock(lock_fd)
                raise
        try:
            h5 = h5py.File(path, mode, locking=False) if mode == "r" else h5py.File(path, mode)
        except (OSError, RuntimeError, ValueError) as err:
            cls._unlock(lock_fd)
            if _is_lock_error(err):
                # another process writes this file under another name (a hard link or a copy of the path):
                # its <name>.lock differs, but HDF5's own lock on the file is held
                raise CampaignError(f"store '{path}' is locked: it is being written by another process "
                                    "(possibly opened under another name or hard link); wait for it to finish") from None
            raise CampaignError(f"store '{path}' is not a readable HDF5 file: {err}") from None
        try:
            problem = layout_problem(h5)
        except Exception as err:  # noqa: BLE001 - any failure to read the layout means "not a store"
            problem = f"cannot read its layout ({type(err).__name__}: {err})"
        if problem:
            h5.close()
            cls._unlock(lock_fd)
            raise CampaignError(f"'{path}' is not an lvcore campaign store: {problem}")
        return cls(path, h5, lock_fd)

    @staticmethod
    def _lock(path: Path) -> int:
        fd = os.open(str(path) + ".lock", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as err:
            os.close(fd)
            raise CampaignError(f"store '{path}' is being written by another process (lock {path}.lock held)") from err
        return fd

    @staticmethod
    def _unlock(fd: int | None) -> None:
        if fd is not None:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)

    def close(self) -> None:
        if self._h5 is not None:
            self._h5.close()
            self._h5 = None
        self._unlock(self._lock_fd)
        self._lock_fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ----- metadata ---------------------------------------------------------
    @property
    def attrs(self) -> dict:
        return {k: (v.item() if isinstance(v, np.generic) else v) for k, v in self._h5.attrs.items()}

    @property
    def space(self) -> ParameterSpace:
        return ParameterSpace.from_json(self._h5.attrs["space"])

    @property
    def n(self) -> int:
        return int(self._h5["state"].shape[0])

    def design(self) -> Design:
        seed = int(self._h5.attrs["design_seed"])
        return Design(self.space, self._h5["inputs"][...], str(self._h5.attrs["design_method"]), None if seed < 0 else seed)

    # ----- rows -------------------------------------------------------------
    def state(self) -> np.ndarray:
        return self._h5["state"][...]

    def pending_rows(self, retry_failed: bool = False) -> np.ndarray:
        """Indices of rows still to run (and failed ones if ``retry_failed``)."""
        s = self.state()
        todo = s == PENDING
        if retry_failed:
            todo |= s == FAILED
        return np.flatnonzero(todo & ~self.read().inconsistent)

    def record(self, result: RowResult, *, allow_rerecord: bool = False) -> None:
        """Write one row and commit it (see *Crash safety*).

        Raises
        ------
        CampaignError
            If the row is already committed (a duplicate run) and
            ``allow_rerecord`` is false.
        """
        self.record_many([result], allow_rerecord=allow_rerecord)

    def record_many(self, results, *, allow_rerecord: bool = False) -> None:
        """Write several rows and commit them together (see *Crash safety*).

        Every row is checked before anything is written; the data of all rows
        is written and flushed before their states commit them, so a run
        killed in between leaves them pending (run again on resume), never
        half-recorded. One write per column for the whole batch: a chunk of
        a continuation chain (12 rows) costs about one row's I/O, which the
        driver process of a campaign otherwise spends beside its workers.

        Raises
        ------
        CampaignError
            If a row is outside the store, is given twice, is already committed
            (a duplicate run) and ``allow_rerecord`` is false, or has the wrong
            number of outputs; nothing is written then.
        """
        if self._lock_fd is None:
            raise CampaignError(f"store '{self.path}' is open read-only")
        results = list(results)
        if not results:
            return
        f = self._h5
        idx = np.array([int(r.index) for r in results], dtype=np.int64)
        bad = idx[(idx < 0) | (idx >= self.n)]
        if bad.size:
            raise CampaignError(f"row {int(bad[0])} is outside the store's {self.n} rows")
        uniq, counts = np.unique(idx, return_counts=True)
        if np.any(counts > 1):
            raise CampaignError(f"row {int(uniq[counts > 1][0])} is given twice in one batch; refusing to record it twice")
        state = f["state"][...]
        rows = []
        for i, result in zip(idx.tolist(), results):
            current = int(state[i])
            if current == CONVERGED or (current == FAILED and not allow_rerecord):
                raise CampaignError(f"row {i} of '{self.path}' is already recorded as {STATE_NAMES[current]}; "
                                    "refusing to record it twice")
            out = np.asarray(result.outputs, dtype=float).reshape(-1) if result.converged else np.full(N_OUTPUTS, np.nan)
            if out.shape != (N_OUTPUTS,):
                raise CampaignError(f"row {i}: the forward model returned {out.shape[0]} outputs, expected {N_OUTPUTS}")
            converged = bool(result.converged) and bool(np.all(np.isfinite(out)))
            reason = result.reason if not result.converged else ("" if converged else "non-finite outputs")
            if not converged:
                out = np.full(N_OUTPUTS, np.nan)
                reason = reason or "did not converge (no reason given)"
            rows.append((i, out, converged, reason, result))
        rows.sort(key=lambda r: r[0])  # h5py writes a list selection in increasing order
        sel = [r[0] for r in rows]
        now = time.time()
        f["outputs"][sel] = np.stack([r[1] for r in rows])
        f["seconds"][sel] = np.array([float(r[4].seconds) for r in rows])
        f["reason"][sel] = np.array([_fixed_bytes(r[3], REASON_LEN) for r in rows], dtype=f["reason"].dtype)
        f["version"][sel] = np.array([_fixed_bytes(r[4].version, VERSION_LEN) for r in rows], dtype=f["version"].dtype)
        f["worker"][sel] = np.array([_fixed_bytes(r[4].worker, WORKER_LEN) for r in rows], dtype=f["worker"].dtype)
        f["finished_at"][sel] = np.full(len(rows), now)
        # a committed row is recorded exactly once: a row left half-written by a killed run, or a failed
        # row run again, is committed anew (record_count 1); any other value means the store was edited
        f["record_count"][sel] = np.ones(len(rows), dtype="i4")
        if "start" in f:  # provenance (format version 2)
            if self._run is None:
                runs = f["run"][...][state != PENDING]
                self._run = int(runs.max()) + 1 if runs.size and runs.max() >= 0 else int(bool(runs.size))
            f["run"][sel] = np.full(len(rows), self._run, dtype="i2")
            for key in ("chain", "chain_position", "seed_row", "start"):
                f[key][sel] = np.array([int(getattr(r[4], key)) for r in rows], dtype=f[key].dtype)
        f.flush()
        f["state"][sel] = np.array([CONVERGED if r[2] else FAILED for r in rows], dtype=f["state"].dtype)  # the commit
        f.flush()

    # ----- reading ----------------------------------------------------------
    def read(self) -> StoreContents:
        try:
            return self._read()
        except (OSError, RuntimeError, ValueError, TypeError, KeyError) as err:  # damaged blocks of a valid layout
            raise CampaignError(f"store '{self.path}' cannot be read ({type(err).__name__}: {err}); "
                                "the file is damaged") from None

    def _read(self) -> StoreContents:
        f = self._h5
        return StoreContents(
            space=self.space,
            inputs=f["inputs"][...],
            outputs=f["outputs"][...],
            state=f["state"][...],
            seconds=f["seconds"][...],
            reasons=_decode(f["reason"][...]),
            versions=_decode(f["version"][...]),
            workers=_decode(f["worker"][...]),
            finished_at=f["finished_at"][...],
            record_count=f["record_count"][...],
            attrs=self.attrs,
            **{k: (f[k][...] if k in f else np.full(f["state"].shape[0], fill, dtype=dt))
               for k, (dt, fill) in PROVENANCE.items()},
        )

    def summary(self) -> StoreSummary:
        c = self.read()
        reasons: dict[str, int] = {}
        for r, failed in zip(c.reasons, c.failed):
            if failed:
                reasons[r] = reasons.get(r, 0) + 1
        done = ~c.pending
        secs = c.seconds[done & np.isfinite(c.seconds)]
        return StoreSummary(
            path=str(self.path),
            n=int(c.state.size),
            converged=int(c.converged.sum()),
            failed=int(c.failed.sum()),
            pending=int(c.pending.sum()),
            reasons=tuple(sorted(reasons.items(), key=lambda kv: -kv[1])),
            mean_seconds=float(secs.mean()) if secs.size else float("nan"),
            versions=tuple(sorted({v for v, d in zip(c.versions, done) if d and v})),
            space=c.space.name,
            resolution=str(c.attrs.get("resolution", "")),
            forward=str(c.attrs.get("forward", "")),
            inconsistent=int(c.inconsistent.sum()),
            problems=c.check(limit=1000),
            warm=int(np.sum(done & (c.start == START_WARM))),
            resolved=int(np.sum(done & (c.start == START_RESOLVED))),
            strain_layer=c.strain_layer,
        )


def _is_lock_error(err: OSError) -> bool:
    text = str(err).lower()
    return "lock" in text and ("errno = 11" in text or "temporarily unavailable" in text or "errno = 35" in text)


def read_store(path: str | Path) -> StoreContents:
    """Read a whole store into memory (read-only, no lock)."""
    with CampaignStore.open(path, "r") as store:
        return store.read()


__all__ = ["CampaignStore", "RowResult", "StoreContents", "StoreSummary", "read_store", "worker_tag",
           # the file format's names, defined in lvcore.campaigns.store_format
           "FORMAT", "FORMAT_VERSION", "PENDING", "CONVERGED", "FAILED", "START_COLD", "START_WARM", "START_RESOLVED",
           "START_NAMES", "PROVENANCE", "STATE_NAMES"]
