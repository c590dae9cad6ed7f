"""Run a file parser in a child process with a memory limit and a timeout.

VTK and meshio are C/C++ (or numpy-heavy) parsers that trust what a file
says: a crafted PLY makes VTK throw ``std::bad_alloc`` (SIGABRT), an OBJ
face index of 10⁹ makes it read out of bounds (SIGSEGV). In the caller's
process that kills the CLI with exit 134/139 and, in the app, the Streamlit
server with every user's session. :func:`run_isolated` runs the parser in a
forked child instead:

* the child's address space is capped at what it inherited plus
  :data:`~lvcore.safety.limits.MAX_READER_MEMORY_BYTES` (``RLIMIT_AS``), so a
  declared 10⁹ vertices fails there as an allocation error instead of
  exhausting the machine's memory;
* it is killed after :data:`~lvcore.safety.limits.MAX_READER_SECONDS`;
* its result (plain Python and numpy objects) comes back pickled through a
  pipe; an :class:`~lvcore.exceptions.LVCoreError` raised in the child is
  raised again in the caller, and any other exception, a crash by a signal,
  running out of memory or time becomes ``error(message)`` naming the file.

The child is forked (not spawned): importing VTK anew would take seconds. It
leaves with ``os._exit`` so no ``atexit`` handler or temporary-folder
cleanup of the parent runs twice. Where ``os.fork`` does not exist
(Windows), the function runs in the caller's process.
"""
from __future__ import annotations

import os
import pickle
import select
import signal
import time
import warnings
from typing import Any, Callable

from lvcore.safety import limits
from lvcore.exceptions import LimitError, LVCoreError

#: Exit status of a child that could not send its result (e.g. it ran out of memory while pickling).
_CHILD_FAILED = 70


def _address_space_bytes() -> int:
    """Current virtual memory size of this process (bytes), from /proc (0 if unknown)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):  # pragma: no cover - non-Linux
        return 0


def _limit_memory(extra_bytes: int) -> None:
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    want = _address_space_bytes() + int(extra_bytes)
    if hard != resource.RLIM_INFINITY:
        want = min(want, hard)
    if soft == resource.RLIM_INFINITY or want < soft:
        resource.setrlimit(resource.RLIMIT_AS, (want, hard))


def _child(write_fd: int, func, args, kwargs, memory_bytes: int) -> None:  # pragma: no cover - runs in the child
    status = 0
    try:
        try:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            import faulthandler

            faulthandler.disable()  # a crash here is reported by the parent, not as a traceback dump
            _limit_memory(memory_bytes)
            result = ("ok", func(*args, **kwargs))
        except LVCoreError as err:
            result = ("lvcore", type(err).__module__, type(err).__qualname__, str(err))
        except MemoryError:
            result = ("memory", "", "", "")
        except BaseException as err:  # noqa: BLE001 - reported to the parent, never raised here
            result = ("other", type(err).__module__, type(err).__name__, str(err)[:500])
        try:
            payload = pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)
        except MemoryError:
            payload = pickle.dumps(("memory", "", "", ""))
        view = memoryview(payload)
        while view:
            n = os.write(write_fd, view[: 1 << 20])
            view = view[n:]
    except BaseException:  # noqa: BLE001
        status = _CHILD_FAILED
    finally:
        os._exit(status)


def _describe_signal(sig: int) -> str:
    try:
        name = signal.Signals(sig).name
    except ValueError:
        name = f"signal {sig}"
    meaning = {"SIGSEGV": "a memory access error", "SIGABRT": "an abort, typically a failed allocation",
               "SIGBUS": "a bus error", "SIGFPE": "an arithmetic error", "SIGKILL": "killed"}.get(name, "")
    return f"{name}{', ' + meaning if meaning else ''}"


def run_isolated(func: Callable[..., Any], *args, what: str, path, error: Callable[[str], Exception] = LimitError,
                 memory_bytes: int | None = None, timeout_s: float | None = None, **kwargs) -> Any:
    """``func(*args, **kwargs)`` in a forked child with a memory limit and a timeout.

    Parameters
    ----------
    func : callable
        The parser; its result must be picklable (numpy arrays, dataclasses of them, meshio meshes).
    what : str
        What is read, for messages (e.g. ``"endo surface file"``).
    path : str or Path
        The file being parsed, named in messages.
    error : callable
        ``error(message) -> exception`` for crashes, memory and time (default :class:`LimitError`).
    memory_bytes : int, optional
        Address space the child may add (default :data:`~lvcore.safety.limits.MAX_READER_MEMORY_BYTES`).
    timeout_s : float, optional
        Seconds before the child is killed (default :data:`~lvcore.safety.limits.MAX_READER_SECONDS`).

    Returns
    -------
    Whatever ``func`` returned.

    Raises
    ------
    LVCoreError
        The error ``func`` raised in the child (same class when it can be rebuilt from its message,
        else ``error``), or ``error(message)`` when the child crashed, ran out of memory or time.
    """
    memory_bytes = limits.MAX_READER_MEMORY_BYTES if memory_bytes is None else int(memory_bytes)
    timeout_s = limits.MAX_READER_SECONDS if timeout_s is None else float(timeout_s)
    if not hasattr(os, "fork"):  # pragma: no cover - Windows
        return func(*args, **kwargs)
    read_fd, write_fd = os.pipe()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # JAX warns that fork() and threads mix badly; the child runs no JAX
        pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        os.close(read_fd)
        _child(write_fd, func, args, kwargs, memory_bytes)
    os.close(write_fd)
    chunks, deadline, timed_out = [], time.monotonic() + timeout_s, False
    try:
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                timed_out = True
                break
            ready, _, _ = select.select([read_fd], [], [], min(left, 1.0))
            if ready:
                chunk = os.read(read_fd, 1 << 20)
                if not chunk:
                    break
                chunks.append(chunk)
    finally:
        os.close(read_fd)
        if timed_out:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        _, status = os.waitpid(pid, 0)
    if timed_out:
        raise error(f"reading {what} '{path}' took longer than {timeout_s:g} s "
                    "(lvcore.safety.limits.MAX_READER_SECONDS) and was stopped; the file is damaged or far too large")
    if os.WIFSIGNALED(status):
        raise error(f"{what} '{path}' crashed the mesh reader ({_describe_signal(os.WTERMSIG(status))}); "
                    "the file is malformed or declares more data than it holds. Export it again or give "
                    "another format")
    if not chunks:
        raise error(f"{what} '{path}' could not be read: the reader process ended without a result "
                    f"(exit status {os.WEXITSTATUS(status)}); it probably ran out of memory "
                    f"(limit {memory_bytes / 1024 ** 3:.1f} GB, lvcore.safety.limits.MAX_READER_MEMORY_BYTES)")
    kind, *rest = pickle.loads(b"".join(chunks))  # our own child's output, never the file's bytes
    if kind == "ok":
        return rest[0]
    if kind == "memory":
        raise error(f"{what} '{path}' needs more memory than a reader may use "
                    f"({memory_bytes / 1024 ** 3:.1f} GB, lvcore.safety.limits.MAX_READER_MEMORY_BYTES); the file declares "
                    "more data than it holds or is far too large for an LV mesh")
    module, name, message = rest
    if kind == "lvcore":
        import importlib

        try:
            cls = getattr(importlib.import_module(module), name.split(".")[-1])
            exc = cls(message)
        except Exception:  # noqa: BLE001 - e.g. CaseError needs two arguments
            exc = error(message)
        raise exc
    raise error(f"cannot read {what} '{path}' ({name}: {message})")


__all__ = ["run_isolated"]
