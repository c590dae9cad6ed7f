"""The campaign store's file format: its layout, its version, the check of a file's layout and the migration.

Layout (all datasets have one entry per design row, fixed size, allocated and
filled when the store is created, so recording a row never changes the file's
structure, only raw data at fixed offsets):

========================  =============  =======================================
dataset                   dtype          meaning
========================  =============  =======================================
``inputs``                (n, d) f8      design points, physical units
``outputs``               (n, 25) f8     [LVV mL, 24 strains]; NaN unless converged
``state``                 (n,) i1        0 pending, 1 converged, 2 failed
``seconds``               (n,) f8        wall time of the solve (s)
``reason``                (n,) S256      failure reason (empty if converged)
``version``               (n,) S32       simulator version of the worker: ``lvcore.__version__``
                                         plus a hash of the simulator sources
``worker``                (n,) S64       ``host:pid`` of the worker
``finished_at``           (n,) f8        UNIX time the row was recorded
``record_count``          (n,) i4        1 once the row is committed (also when a failed row
                                         is run again); anything else is reported by
                                         ``StoreContents.check``
``run``                   (n,) i2        the run that recorded the row: 0 ``campaign run``,
                                         k the k-th ``campaign resume``; -1 pending
``chain``                 (n,) i4        the continuation chain of the row in its run
                                         (:mod:`lvcore.execution.chains`); -1 solved on its own (cold)
``chain_position``        (n,) i4        its place in that chain (0 first): with ``run`` and
                                         ``chain``, the order the rows were solved in
``seed_row``              (n,) i8        the row whose converged state warm-started this one
                                         (the nearest of the predictor's neighbours); -1 none
``start``                 (n,) i1        0 cold (no start, or the simulator's soft
                                         corner), 1 warm from ``seed_row``, 2 warm
                                         result discarded and re-solved cold (it was
                                         suspect: see
                                         :func:`lvcore.mechanics.forward.solve_warm`)
========================  =============  =======================================

The last five datasets came with format version 2. A version-1 store is read as
it is (those fields read -1, ``start`` 0: not recorded); opening one for writing
(``campaign resume``) first migrates it to version 2 in a copy that replaces the
file only once complete (the rows already recorded keep "not recorded"). A
store of a newer version than this lvcore knows is refused with a message.

File attributes: ``format`` (``"lvcore-campaign"``), ``format_version``,
``space`` (JSON), ``input_names``, ``output_names``, ``design_method``,
``design_seed``, ``resolution``, ``forward``, ``lvcore_version``,
``created_at``.

:class:`lvcore.campaigns.store.CampaignStore` reads and writes stores through these definitions.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import h5py
import numpy as np

import lvcore
from lvcore.safety import limits
from lvcore.core.space import ParameterSpace
from lvcore.exceptions import CampaignError
from lvcore.domain.outputs import N_OUTPUTS

FORMAT = "lvcore-campaign"
FORMAT_VERSION = 2
PENDING, CONVERGED, FAILED = 0, 1, 2
#: ``start`` codes: how a row's recorded solve began.
START_COLD, START_WARM, START_RESOLVED = 0, 1, 2
START_NAMES = {START_COLD: "cold", START_WARM: "warm", START_RESOLVED: "re-solved cold"}
#: Datasets added by format version 2, with their dtype and the value of a row without them.
PROVENANCE = {"run": ("i2", -1), "chain": ("i4", -1), "chain_position": ("i4", -1), "seed_row": ("i8", -1),
              "start": ("i1", START_COLD)}
STATE_NAMES = {PENDING: "pending", CONVERGED: "converged", FAILED: "failed"}
REASON_LEN, VERSION_LEN, WORKER_LEN = 256, 32, 64

#: Datasets of a store and their trailing shape (after the row dimension).
DATASETS = {"inputs": None, "outputs": (N_OUTPUTS,), "state": (), "seconds": (), "reason": (), "version": (),
             "worker": (), "finished_at": (), "record_count": ()}


def format_version(h5: h5py.File):
    """The store's ``format_version`` as an int (1 where missing), or its raw value when it is not an integer."""
    v = h5.attrs.get("format_version", 1)
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        return v
    return int(v)


def add_provenance(f: h5py.File, n: int) -> None:
    """Create the version-2 datasets (every row "not recorded") and set ``format_version`` to 2."""
    for key, (dtype, fill) in PROVENANCE.items():
        f.create_dataset(key, data=np.full(n, fill, dtype=dtype))
    f.attrs["format_version"] = FORMAT_VERSION


def migrate(path: Path) -> None:
    """Bring a version-1 store up to version 2 before it is written (the caller holds its lock).

    The new datasets are added to a copy, which replaces the store only once it is complete and
    flushed: a process killed meanwhile leaves the version-1 store as it was (and a stale copy,
    replaced next time). Anything that is not a readable version-1 store is left to :meth:`open`.
    """
    try:
        with h5py.File(path, "r") as h5:
            if layout_problem(h5) is not None or format_version(h5) != 1 or "start" in h5:
                return
            n = int(h5["state"].shape[0])
    except (OSError, RuntimeError, ValueError, KeyError):
        return
    tmp = path.with_name(path.name + ".migrating")
    try:
        import shutil

        shutil.copyfile(path, tmp)
        with h5py.File(tmp, "r+") as f:
            add_provenance(f, n)
            f.attrs["migrated_from_version"] = 1
            f.attrs["migrated_at"] = time.time()
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise CampaignError(f"store '{path}' has format version 1 and could not be migrated to version "
                            f"{FORMAT_VERSION} for writing ({err}); it is unchanged and can still be read") from None


def layout_problem(h5: h5py.File) -> str | None:
    """What is wrong with the layout of an opened store, or None if it is a store (format, attributes, datasets)."""
    fmt = h5.attrs.get("format")
    if isinstance(fmt, bytes):
        fmt = fmt.decode("utf-8", "replace")
    if fmt != FORMAT:
        return f"format attribute {str(fmt)[:60]!r}, expected {FORMAT!r}"
    version = format_version(h5)
    if not isinstance(version, int) or version < 1:
        return f"attribute 'format_version' is {str(version)[:60]!r}, not a version number (1 or {FORMAT_VERSION})"
    if version > FORMAT_VERSION:
        return (f"its format version {version} is newer than this lvcore ({lvcore.__version__}) reads "
                f"(up to {FORMAT_VERSION}); upgrade lvcore to read it")
    for key in ("space", "design_seed", "design_method"):
        if key not in h5.attrs:
            return f"attribute '{key}' is missing"
    seed = h5.attrs["design_seed"]
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        return f"attribute 'design_seed' is {str(seed)[:60]!r}, not an integer"
    try:
        space = ParameterSpace.from_json(h5.attrs["space"])
    except Exception as err:  # noqa: BLE001
        return f"attribute 'space' is not a parameter space ({type(err).__name__}: {str(err)[:200]})"
    if len(space.names) > limits.MAX_DESIGN_DIMENSIONS:
        return (f"its space has {len(space.names)} parameters, more than the limit of "
                f"{limits.MAX_DESIGN_DIMENSIONS} (lvcore.safety.limits.MAX_DESIGN_DIMENSIONS)")
    n = None
    for name, tail in DATASETS.items():
        if name not in h5 or not isinstance(h5[name], h5py.Dataset):
            return f"dataset '{name}' is missing"
        shape = h5[name].shape
        if not shape:
            return f"dataset '{name}' is a scalar"
        n = shape[0] if n is None else n
        if n > limits.MAX_DESIGN_POINTS:  # checked before any dataset is read into memory
            return (f"dataset '{name}' declares {n:,} rows, more than the limit of {limits.MAX_DESIGN_POINTS:,} "
                    "(lvcore.safety.limits.MAX_DESIGN_POINTS)")
        expect = (n, len(space.names)) if name == "inputs" else (n,) + tail
        if shape != expect:
            return f"dataset '{name}' has shape {shape}, expected {expect}"
    if version >= 2:
        for name in PROVENANCE:
            if name not in h5 or not isinstance(h5[name], h5py.Dataset):
                return f"dataset '{name}' is missing (format version {version})"
            if h5[name].shape != (n,):
                return f"dataset '{name}' has shape {h5[name].shape}, expected {(n,)}"
            if not np.issubdtype(h5[name].dtype, np.integer):
                return f"dataset '{name}' holds {h5[name].dtype}, expected integers"
    return None


__all__ = ["FORMAT", "FORMAT_VERSION", "PENDING", "CONVERGED", "FAILED", "START_COLD", "START_WARM", "START_RESOLVED",
           "START_NAMES", "PROVENANCE", "STATE_NAMES", "DATASETS", "format_version", "add_provenance", "migrate",
           "layout_problem"]
