"""Files uploaded to the app: per-session temporary folders and messages in the user's terms.

The Streamlit pages keep no upload logic of their own; they call this module:

* :class:`UploadSession` is one temporary folder per browser session
  (:func:`session_uploads` keeps it in ``st.session_state``), so two users
  never see or overwrite each other's files. The folder is removed when the
  session ends (the object is garbage-collected) and at interpreter exit.
* :meth:`UploadSession.read` saves an upload under a safe name, runs an
  lvcore reader on it and turns *any* failure into an :class:`UploadError`
  whose message names the user's file, never a server path.
* :func:`fit_segmentation` fits uploaded contours or surfaces (the Geometry page).

Uploads are limited to :data:`MAX_UPLOAD_MB` (Streamlit enforces it in the
browser: ``lvcore app`` passes ``--server.maxUploadSize``, and
``.streamlit/config.toml`` sets it for ``streamlit run app.py`` in a
checkout; this module enforces it again on the server).
"""
from __future__ import annotations

import re
import tempfile
from pathlib import Path
from typing import Any, Callable

from lvcore.exceptions import LVCoreError

#: Largest upload accepted (MB); keep equal to ``server.maxUploadSize`` in ``.streamlit/config.toml``.
#: The largest legitimate uploads are surface meshes (a 50,000-triangle binary STL is 2.5 MB)
#: and template meshes (the volunteers' VTU files are 50 kB).
MAX_UPLOAD_MB = 10
#: Prefix of the per-session folders under the system temporary directory.
TMP_PREFIX = "lvcore_upload_"


class UploadError(LVCoreError, ValueError):
    """An uploaded file cannot be used; the message names the user's file name only."""


def safe_name(name: str, default: str = "upload") -> str:
    """A file name without folders or odd characters (letters, digits, ``.``, ``_``, ``-``), at most 80 characters."""
    base = re.split(r"[\\/]", str(name))[-1]
    base = re.sub(r"[^A-Za-z0-9._-]", "_", base)
    base = re.sub(r"\.{2,}", "_", base).lstrip(".-_")[-80:]
    return base or default


class UploadSession:
    """A temporary folder for one browser session's uploads.

    Parameters
    ----------
    root : path, optional
        Parent folder (default: the system temporary directory).
    """

    def __init__(self, root=None):
        self._tmp = tempfile.TemporaryDirectory(prefix=TMP_PREFIX, dir=root)
        self.path = Path(self._tmp.name)
        self._names: dict[str, str] = {}  # saved path -> the user's file name

    def save(self, name: str, data: bytes, slot: str | None = None) -> Path:
        """Write an upload into this session's folder and return its path.

        ``slot`` (e.g. ``"measured"``) gives a fixed stem, so a new upload to
        the same widget replaces the previous one; the suffix of ``name`` is kept.
        """
        if len(data) > MAX_UPLOAD_MB * 1024 * 1024:
            raise UploadError(f"'{_display(name)}' is {len(data) / 1024 ** 2:.1f} MB, more than the "
                              f"{MAX_UPLOAD_MB} MB allowed for uploads")
        if not self.path.is_dir():
            raise UploadError("this session's upload folder was removed; reload the page")
        clean = safe_name(name)
        if slot is not None:
            clean = safe_name(slot) + "".join(Path(clean).suffixes[-1:]).lower()
        path = self.path / clean
        path.write_bytes(data)
        self._names[str(path)] = _display(name)
        return path

    def message(self, text: str) -> str:
        """``text`` with this session's server paths replaced by the user's file names."""
        for saved, shown in sorted(self._names.items(), key=lambda kv: -len(kv[0])):
            text = text.replace(saved, shown).replace(Path(saved).name, shown)
        return text.replace(str(self.path) + "/", "").replace(str(self.path), "<upload>")

    def read(self, name: str, data: bytes, reader: Callable[[Path], Any], slot: str | None = None) -> Any:
        """Save an upload and read it with ``reader(path)``.

        Raises
        ------
        UploadError
            For any failure (a bad file, or an unexpected error of the reader),
            with a message that names ``name`` and no server path.
        """
        path = self.save(name, data, slot)
        try:
            return reader(path)
        except LVCoreError as err:
            raise UploadError(self.message(str(err))) from None
        except UnicodeDecodeError as err:
            raise UploadError(f"'{_display(name)}' is not a text file (byte {err.start} cannot be read as UTF-8 text); "
                              "save it as UTF-8 text (CSV or JSON), or check that it is the right file") from None
        except (Exception, SystemExit) as err:  # noqa: BLE001 - shown as a message, never as a traceback or an exit
            detail = "the reader gave up on its contents" if isinstance(err, SystemExit) else \
                f"{type(err).__name__}: {self.message(str(err))[:300]}"
            raise UploadError(f"cannot read '{_display(name)}' ({detail}); check that it is the right file in a "
                              "format this upload takes") from None

    def cleanup(self) -> None:
        """Remove the folder now (it is also removed when this object is garbage-collected)."""
        self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.cleanup()


def display_name(name: str) -> str:
    """The user's file name as shown in messages (no folders, printable, at most 80 characters)."""
    base = re.split(r"[\\/]", str(name))[-1]
    return "".join(c if c.isprintable() else "?" for c in base)[:80] or "upload"


_display = display_name


def session_uploads(state=None, key: str = "_lvcore_uploads") -> UploadSession:
    """The :class:`UploadSession` of the current Streamlit session (created on first use).

    ``state`` is ``st.session_state`` (default) or any mutable mapping. The
    session state is dropped when the browser session ends, and with it the
    folder.
    """
    if state is None:
        import streamlit as st

        state = st.session_state
    session = state.get(key)
    if not isinstance(session, UploadSession) or not session.path.is_dir():
        session = UploadSession()
        state[key] = session
    return session


def fit_segmentation(kind: str, files) -> dict:
    """Fit uploaded contours (``kind="contours"``, one file), endo + epi surfaces (two files) or a
    volumetric mesh (``kind="mesh"``, one file, :func:`lvcore.geometry.volume_mesh.fit_volume_mesh`).

    ``files`` are ``(name, bytes)`` pairs. Returns ``{"nodes", "summary"}``,
    or ``{"error": message}`` with a message in terms of the user's file names.
    """
    from lvcore.geometry.fitting import fit_contours, fit_surfaces, units_warnings
    from lvcore.geometry.volume_mesh import fit_volume_mesh

    with UploadSession() as session:
        try:
            paths = [session.save(name, data, slot=f"{kind}{i}") for i, (name, data) in enumerate(files)]

            def fit(_):
                if kind == "mesh":
                    return fit_volume_mesh(paths[0])
                return fit_contours(paths[0]) if kind == "contours" else fit_surfaces(paths[0], paths[1])

            res = session.read(files[0][0], files[0][1], fit, slot=f"{kind}0")
        except UploadError as err:
            return {"error": str(err)}
    fitted = res.fit if kind == "mesh" else res
    summary = res.summary()
    summary["warnings"] = list(summary.get("warnings", [])) + units_warnings(fitted, "mm", UPLOAD_UNITS)
    return {"nodes": fitted.nodes, "summary": summary}


#: How the wrong-units warning of :func:`fit_segmentation` names the units: uploads are read as mm.
UPLOAD_UNITS = "the file's units (uploads here are read as mm: convert the file to mm)"


__all__ = ["MAX_UPLOAD_MB", "UploadError", "UploadSession", "session_uploads", "safe_name", "display_name",
           "fit_segmentation"]
