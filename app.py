"""LV Calibration Lab, started from a checkout: ``streamlit run app.py``.

``streamlit run`` finds :data:`app` below and serves the packaged entry
(``lvcore/app/main.py``, :data:`lvcore.app.ENTRY`), the script ``lvcore app``
runs too. This file is not the app's script itself: a script here would sit
beside the checkout's ``pages/`` folder, and Streamlit runs the first session
of a fresh server inside that folder's own page list, which knows none of the
app's URL paths, so a first visit to ``/simulator`` or ``/my-subject`` said
"Page not found" before the app's navigation took over.
"""
from pathlib import Path

from streamlit.starlette import App

#: The packaged entry, found without importing lvcore (the entry sets up threads and devices before anything starts).
ENTRY = Path(__file__).resolve().parent / "lvcore" / "app" / "main.py"

#: What ``streamlit run app.py`` serves (Streamlit's ASGI entry point).
app = App(ENTRY)
