"""JAX's persistent compilation cache for everything lvcore compiles.

The simulator's Newton kernels, the emulators and the NUTS / HMC-within-Gibbs
samplers are all jit-compiled; with the cache on, a second process that
compiles the same program (same shapes, same constants) loads it from disk
instead of compiling it again. It is switched on when :mod:`lvcore` is
imported.

That cache keys compiled code by the lowered program, so a new process still
traces and lowers every kernel first. The simulator's kernels are therefore
:class:`ExportedKernel` objects: their lowered programs are kept beside the
cache (:mod:`jax.export`, folder ``exported/``), and a new process reads them
instead of tracing (≈ 0.7 CPU-s less per process for a ``default`` solve).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

#: Where compiled programs go unless ``LVCORE_JAX_CACHE`` says otherwise.
DEFAULT_JAX_CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "lvcore" / "jax"
#: Smallest compile time (s) of a program that is written to the cache. Zero: every program, also the many
#: small kernels of a solve that compile in well under a second each but add up to seconds per process
#: (a second ``lvcore campaign run`` and every campaign worker load them instead).
MIN_COMPILE_TIME_S = 0.0


def _set(option: str, value) -> None:
    """Set JAX's config ``option`` now if JAX is imported, else through the environment variable JAX reads."""
    if "jax" in sys.modules:
        sys.modules["jax"].config.update(option, value)
    else:
        os.environ[option.upper()] = str(value).lower() if isinstance(value, bool) else str(value)


def enable_x64() -> None:
    """Switch JAX to float64 (the simulator needs it), without importing JAX where it is not imported yet."""
    _set("jax_enable_x64", True)


def enable_compilation_cache(path: str | os.PathLike | None = None) -> str | None:
    """Turn on JAX's persistent compilation cache.

    Does not import JAX: where it is not imported yet the settings go into the environment
    variables it reads on import (and that child processes inherit).

    Parameters
    ----------
    path : path, optional
        Cache directory; default ``LVCORE_JAX_CACHE`` or
        ``$XDG_CACHE_HOME/lvcore/jax`` (``~/.cache/lvcore/jax``). The value
        ``off`` (in ``path`` or ``LVCORE_JAX_CACHE``) disables the cache.

    Returns
    -------
    str or None
        The directory used, or None when disabled or not writable.
    """
    path = str(path or os.environ.get("LVCORE_JAX_CACHE") or DEFAULT_JAX_CACHE)
    if path.lower() == "off":
        if "jax" not in sys.modules:  # nor the cache a parent process that imported lvcore passed on
            os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
        return None
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
        _set("jax_compilation_cache_dir", path)
        _set("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)
        _set("jax_persistent_cache_min_entry_size_bytes", 0)
    except Exception:  # noqa: BLE001 - read-only home etc.: the cache is an optimisation only
        return None
    return path


# ----- exported kernels: the traced and lowered program kept on disk ---------------------------------------------
#: Sub-folder of the compilation cache that holds the exported kernels (:class:`ExportedKernel`).
EXPORT_SUBDIR = "exported"
#: Environment variable that turns the exported kernels off (``0``/``off``): every kernel is then a plain
#: ``jax.jit``. They are off too whenever the compilation cache is.
EXPORT_ENV = "LVCORE_JAX_EXPORT"
#: Exported programs kept in the folder, the most recently written (:func:`prune_exported`): about 40 kB to
#: 300 kB each; a ``default`` solve has 5.
MAX_EXPORTED_FILES = 200
_MAGIC = b"LVCORE-JAX-EXPORT 1\n"
_JIT = "jit"  # a key whose exported program could not be made or loaded: the plain jit path
_CODE_VERSION: list[str] = []


def _exports_off() -> bool:
    """Whether the exported kernels are off (cheap: checked on every call)."""
    return (os.environ.get(EXPORT_ENV, "").lower() in ("0", "off", "false", "no")
            or not sys.modules["jax"].config.jax_compilation_cache_dir)


def export_dir() -> Path | None:
    """The folder of the exported kernels, or None when they are off (the compilation cache off or
    ``LVCORE_JAX_EXPORT=0``). JAX must be imported."""
    if os.environ.get(EXPORT_ENV, "").lower() in ("0", "off", "false", "no"):
        return None
    cache = sys.modules["jax"].config.jax_compilation_cache_dir
    return Path(cache) / EXPORT_SUBDIR if cache else None


def code_version() -> str:
    """What an exported program depends on besides its inputs' shapes: lvcore's version and a hash of its
    source files (every ``lvcore/**/*.py``), the versions of jax and jaxlib, the backend and the x64 flag."""
    if not _CODE_VERSION:
        import hashlib

        import jax
        import jaxlib

        root = Path(__file__).resolve().parents[1]  # the lvcore package
        h = hashlib.sha256()
        for f in sorted(root.rglob("*.py")):
            h.update(str(f.relative_to(root)).encode())
            h.update(f.read_bytes())
        version = getattr(sys.modules.get("lvcore"), "__version__", "?")
        _CODE_VERSION.append(f"lvcore {version}+src.{h.hexdigest()[:16]}; jax {jax.__version__}; "
                             f"jaxlib {jaxlib.__version__}; {jax.default_backend()}; "
                             f"x64 {bool(jax.config.jax_enable_x64)}")
    return _CODE_VERSION[0]


def _signature(x) -> tuple:
    """Shape, dtype and weak type of one argument leaf (a Python scalar by its type: jit treats it so)."""
    if isinstance(x, (bool, int, float, complex)):
        return (type(x).__name__,)
    return (tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False)))


def _checksum(identity: str, payload: bytes) -> bytes:
    """SHA-256 of a program's identity and its payload: a file of another program, copied or renamed, is refused."""
    import hashlib

    return hashlib.sha256(identity.encode() + b"\0" + bytes(payload)).hexdigest().encode()


def write_exported(path: Path, payload: bytes, identity: str) -> None:
    """Write a serialized program atomically, with a checksum of ``identity`` (what the program is: kernel,
    signature, :func:`code_version`) and ``payload`` that :func:`read_exported` checks."""
    import tempfile

    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(_MAGIC + _checksum(identity, payload) + b"\n" + bytes(payload))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    prune_exported(path.parent)


def prune_exported(folder: Path, keep: int | None = None) -> int:
    """Delete all but the ``keep`` (default :data:`MAX_EXPORTED_FILES`) most recently written programs in
    ``folder``; returns how many were deleted. Every change of lvcore's source makes new files (the name hashes
    :func:`code_version`), so without this the folder would only grow."""
    keep = MAX_EXPORTED_FILES if keep is None else keep
    files = []
    for f in folder.glob("*.jaxexp"):
        try:
            files.append((f.stat().st_mtime_ns, f))
        except OSError:  # deleted meanwhile by another process
            continue
    old = sorted(files, reverse=True)[keep:]
    for _, f in old:
        f.unlink(missing_ok=True)
    return len(old)


def read_exported(path: Path, identity: str) -> bytes | None:
    """The payload :func:`write_exported` wrote for ``identity``, or None if the file is missing, truncated,
    altered, or holds another program."""
    try:
        blob = path.read_bytes()
    except OSError:
        return None
    head, _, payload = blob[len(_MAGIC):].partition(b"\n")
    if not blob.startswith(_MAGIC) or head != _checksum(identity, payload):
        return None
    return payload


class ExportedKernel:
    """``jax.jit(fn)`` whose traced and lowered program is kept on disk, so a new process skips tracing.

    JAX's persistent compilation cache keys compiled code by the lowered program, so every process still
    traces and lowers each kernel before it can load the compiled code (about a second of CPU per process
    for the simulator's kernels). This wrapper serializes the lowered program with :mod:`jax.export`, once
    per argument signature (pytree structure, static arguments, shapes, dtypes and weak types of the
    leaves), into :func:`export_dir` under a name that also hashes :func:`code_version`; a later process
    deserializes it and runs it (its compiled code then comes from the persistent cache). Every call, first
    process or not, runs the exported program, so results do not depend on whether the file existed.

    Falls back to the plain ``jax.jit`` path, quietly, where the exports are off (:func:`export_dir`), for
    traced arguments (the kernel called inside another transformation), and on any error in making,
    writing, reading or running an exported program; a missing, truncated or altered file is made again.

    Parameters
    ----------
    fn : callable
        The kernel; positional arguments are arrays or pytrees of arrays, keyword arguments static.
    static_argnames : tuple of str
        As for :func:`jax.jit`.
    """

    def __init__(self, fn, static_argnames: tuple[str, ...] = ()):
        import functools

        import jax

        functools.update_wrapper(self, fn)
        self.jitted = jax.jit(fn, static_argnames=static_argnames)
        self._programs: dict = {}
        #: The files of the exported programs this process read or wrote: path -> identity (:meth:`identity`).
        self.files: dict[Path, str] = {}

    def __call__(self, *args, **static):
        if _exports_off():
            return self.jitted(*args, **static)
        import jax

        leaves, tree = jax.tree.flatten(args)
        tracer = jax.core.Tracer
        if any(isinstance(x, tracer) for x in leaves):
            return self.jitted(*args, **static)
        # the in-memory key, cheap (~10 µs); the file's is :meth:`signature`, made once per new key
        key = (tree, tuple(sorted(static.items())), tuple([(x.shape, x.dtype, getattr(x, "weak_type", False))
                                                           if hasattr(x, "shape") else type(x) for x in leaves]))
        program = self._programs.get(key)
        if program is None:
            program = self._programs[key] = self._program(export_dir(), args, static)
        if program == _JIT:
            return self.jitted(*args, **static)
        if callable(program):
            return program(*leaves)
        try:  # the first call of a freshly loaded program: an error here means the plain jit path
            out = program[0](*leaves)
        except Exception:  # noqa: BLE001 - the exported program is an optimisation only
            self._programs[key] = _JIT
            return self.jitted(*args, **static)
        self._programs[key] = program[0]
        return out

    @staticmethod
    def signature(args: tuple, static: dict) -> tuple:
        """What selects an exported program: the pytree structure of ``args``, the static arguments and each leaf's
        shape, dtype and weak type (a Python scalar by its type)."""
        import jax

        leaves, tree = jax.tree.flatten(args)
        return (tree, tuple(sorted(static.items())), tuple(map(_signature, leaves)))

    def identity(self, key) -> str:
        """What the exported program of signature ``key`` is: this kernel, ``key`` and :func:`code_version`."""
        return repr((f"{self.__module__}.{self.__qualname__}", key, code_version()))

    def file_for(self, folder: Path, key) -> Path:
        """The file of the exported program of signature ``key`` in ``folder``."""
        import hashlib

        return folder / f"{self.__name__}-{hashlib.sha256(self.identity(key).encode()).hexdigest()[:32]}.jaxexp"

    def _program(self, folder: Path | None, args, static):
        """``(callable,)`` running the exported program of ``args`` (loaded, or made and written), or _JIT."""
        import jax

        if folder is None:
            return _JIT
        try:
            from jax import export

            key = self.signature(args, static)
            path, identity = self.file_for(folder, key), self.identity(key)
            self.files[path] = identity
            payload = read_exported(path, identity)
            exp = None
            if payload is not None:
                try:
                    exp = export.deserialize(bytearray(payload))
                except Exception:  # noqa: BLE001 - unreadable: made again below
                    exp = None
            leaves, tree = jax.tree.flatten(args)
            if exp is None or exp.fun_name != self.__name__ or [(a.shape, a.dtype) for a in exp.in_avals] != \
                    [(jax.numpy.shape(x), jax.numpy.result_type(x)) for x in leaves]:
                def flat(*xs):
                    return self.__wrapped__(*jax.tree.unflatten(tree, xs), **static)

                flat.__name__ = flat.__qualname__ = self.__name__  # exp.fun_name: checked when read back

                exp = export.export(jax.jit(flat))(*leaves)
                try:
                    write_exported(path, exp.serialize(), identity)
                except Exception:  # noqa: BLE001 - read-only cache etc.: the program is still used here
                    pass
            return (jax.jit(exp.call),)
        except Exception:  # noqa: BLE001 - e.g. no flatbuffers, an export JAX cannot do: the jit path
            return _JIT


def exported_kernel(fn=None, *, static_argnames: tuple[str, ...] = ()):
    """Decorator: ``@exported_kernel`` or ``@exported_kernel(static_argnames=(...))``, an :class:`ExportedKernel`."""
    if fn is None:
        return lambda f: ExportedKernel(f, static_argnames)
    return ExportedKernel(fn, static_argnames)
