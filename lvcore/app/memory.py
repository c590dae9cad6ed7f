"""The app server's memory: an address-space limit, the room left under it, and how the process economises.

Under ``ulimit -v`` (``RLIMIT_AS``) the kernel counts every mapping of the
process, reserved or touched, and a native library that cannot map more
(LLVM, compiling a JAX program: ``LLVM ERROR: Unable to allocate section
memory!``; ``std::bad_alloc``) aborts the whole server, every user's session
with it. Python cannot catch that, so the app keeps its *address space*, not
only its resident memory, well below the limit:

* :func:`launch_environment` (``lvcore app``) and :func:`economise` (called by
  :func:`lvcore.app.process.setup_process` when a limit is set) drop the two largest reservations that hold no data: glibc's
  per-thread malloc arenas (64 MB each, up to 8 per core; capped at
  :data:`LEAN_MALLOC_ARENAS`) and the 1 GB that Arrow's mimalloc pool reserves
  on the first table Streamlit sends (Arrow's ``system`` pool instead).
  Measured 2026-12-02 on the 2-core machine: the warm-up plus a ``fast``
  simulation took the process from 3.8 GB to 2.2 GB of address space with the
  same resident memory (1.1 GB).
* :func:`headroom_bytes` is the room left: the least of the room under the
  limit (limit minus the address space mapped now, ``VmSize``) and the
  kernel's available memory (``MemAvailable``, and a cgroup's ``memory.max``
  minus its ``memory.current`` where one is set).

Linux only; elsewhere nothing is limited and :func:`economise` does nothing.
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass

#: glibc malloc arenas kept under an address-space limit (glibc's default is 8 per core, each reserving 64 MB).
LEAN_MALLOC_ARENAS = 2
#: ``mallopt`` parameter number of ``M_ARENA_MAX`` (glibc ``malloc.h``).
_M_ARENA_MAX = -8
GiB = 1024.0 ** 3


@dataclass(frozen=True)
class MemoryState:
    """The process's memory now (bytes; ``inf`` where unknown or unlimited).

    Attributes
    ----------
    address_space_limit : float
        Soft ``RLIMIT_AS`` (``ulimit -v``), ``inf`` when none.
    address_space_used : float
        Address space mapped now (``VmSize``).
    resident : float
        Resident memory now (``VmRSS``).
    peak_resident : float
        Peak resident memory so far (``VmHWM``).
    available : float
        Memory the kernel can still give (``MemAvailable``, and a cgroup ``memory.max`` if set).
    """

    address_space_limit: float
    address_space_used: float
    resident: float
    peak_resident: float
    available: float

    @property
    def capped(self) -> bool:
        """True when an address-space limit is set."""
        return self.address_space_limit != float("inf")

    @property
    def headroom(self) -> float:
        """Bytes the process can still map: the room under the limit and the memory available, the lesser."""
        return min(self.address_space_limit - self.address_space_used, self.available)

    def text(self) -> str:
        """One line for a log or a page, in GB."""
        cap = f"{self.address_space_limit / GiB:.1f} GB address-space limit" if self.capped else "no address-space limit"
        return (f"{cap}, {self.address_space_used / GiB:.1f} GB mapped, {self.resident / GiB:.2f} GB resident, "
                f"{self.headroom / GiB:.1f} GB left")


def address_space_limit() -> float:
    """The soft ``RLIMIT_AS`` of this process (bytes), ``inf`` when unlimited or unknown."""
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, OSError, ValueError):  # pragma: no cover - non-POSIX
        return float("inf")
    return float("inf") if soft == resource.RLIM_INFINITY or soft < 0 else float(soft)


def _status_kib(fields=("VmSize", "VmRSS", "VmHWM"), path="/proc/self/status") -> dict:
    out = {}
    try:
        with open(path) as f:
            for line in f:
                key, _, rest = line.partition(":")
                if key in fields:
                    out[key] = float(rest.split()[0]) * 1024.0
    except (OSError, ValueError, IndexError):  # pragma: no cover - non-Linux
        pass
    return out


def _read_number(path) -> float:
    try:
        with open(path) as f:
            text = f.read().strip()
        return float("inf") if text == "max" else float(text)
    except (OSError, ValueError):
        return float("inf")


def available_bytes() -> float:
    """Memory the kernel can still give this process (bytes): ``MemAvailable``, and the room under a cgroup v2
    ``memory.max`` when the process runs in a memory-limited cgroup; ``inf`` where neither is known."""
    from lvcore.safety.limits import mem_available_bytes

    room = mem_available_bytes()
    try:
        with open("/proc/self/cgroup") as f:
            rel = next((ln.split(":", 2)[2].strip() for ln in f if ln.startswith("0::")), None)
    except OSError:  # pragma: no cover - non-Linux
        rel = None
    if rel is not None:
        base = "/sys/fs/cgroup" + ("" if rel == "/" else rel)
        cap = _read_number(base + "/memory.max")
        if cap != float("inf"):
            room = min(room, max(cap - _read_number(base + "/memory.current"), 0.0))
    return room


def state() -> MemoryState:
    """The process's :class:`MemoryState` now."""
    kib = _status_kib()
    inf = float("inf")
    return MemoryState(address_space_limit=address_space_limit(), address_space_used=kib.get("VmSize", 0.0),
                       resident=kib.get("VmRSS", inf), peak_resident=kib.get("VmHWM", inf),
                       available=available_bytes())


def headroom_bytes() -> float:
    """Bytes this process can still map (:attr:`MemoryState.headroom`)."""
    return state().headroom


def launch_environment(env=None, arenas: int = LEAN_MALLOC_ARENAS) -> dict:
    """The environment to start the app server in: under an address-space limit, ``MALLOC_ARENA_MAX`` and Arrow's
    ``system`` pool are set (values already there are kept). ``lvcore app`` uses it.

    glibc reads ``MALLOC_ARENA_MAX`` when the process starts, so it also caps the arenas of the threads Streamlit
    starts before the entry script runs, which :func:`economise` (``mallopt``, later) cannot take back.
    """
    env = dict(os.environ if env is None else env)
    if address_space_limit() != float("inf"):
        env.setdefault("MALLOC_ARENA_MAX", str(int(arenas)))
        env.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    return env


def economise(arenas: int = LEAN_MALLOC_ARENAS) -> list[str]:
    """Drop the address-space reservations that hold no data; returns what was changed (for the log).

    Caps glibc's malloc arenas at ``arenas`` (``mallopt(M_ARENA_MAX)``; new threads share them) and makes
    Arrow use the system allocator (``ARROW_DEFAULT_MEMORY_POOL=system``; mimalloc reserves 1 GB on the first
    table). Values the user set in the environment are kept. Call it before threads start and before Arrow
    allocates (:func:`lvcore.app.process.setup_process` does).
    """
    done = []
    if "MALLOC_ARENA_MAX" not in os.environ:
        try:
            import ctypes

            libc = ctypes.CDLL(None)
            if getattr(libc, "mallopt", None) is not None and libc.mallopt(_M_ARENA_MAX, int(arenas)) == 1:
                done.append(f"malloc arenas <= {int(arenas)}")
        except (OSError, AttributeError):  # pragma: no cover - not glibc
            pass
    if os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system") == "system":
        pa = sys.modules.get("pyarrow")
        if pa is not None:  # already imported: switch the default pool too (tables made so far keep theirs)
            try:
                pa.set_memory_pool(pa.system_memory_pool())
            except Exception:  # noqa: BLE001 - an economy only  # pragma: no cover
                pass
        done.append("Arrow's system allocator")
    return done


__all__ = ["LEAN_MALLOC_ARENAS", "MemoryState", "address_space_limit", "available_bytes", "state",
           "headroom_bytes", "launch_environment", "economise"]
