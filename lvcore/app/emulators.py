"""The app's emulators: loaded once per server process and shared by the pages and sessions, and loaded again when
the files behind a name change (another ``LVCORE_EMULATORS``, a rebuilt emulator)."""
from __future__ import annotations

import streamlit as st

from lvcore.emulator.io import emulator_identity, load_emulator


@st.cache_resource(show_spinner=False)
def _cached(name_or_path: str, identity: tuple):   # identity is the cache key's part that follows the files
    return load_emulator(name_or_path)


def cached_emulator(name_or_path: str):
    """:func:`lvcore.emulator.io.load_emulator` of ``name_or_path``, cached per server process by the name and
    :func:`lvcore.emulator.io.emulator_identity` (its folder and files' modification time)."""
    return _cached(str(name_or_path), emulator_identity(name_or_path))


__all__ = ["cached_emulator"]
