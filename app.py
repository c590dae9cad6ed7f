"""LV Calibration Lab, started from a checkout: ``streamlit run app.py``.

A shim: the app ships inside the package (:mod:`lvcore.app`), so an installed
wheel starts the same app with ``lvcore app``.
"""
from lvcore.app.main import main

main()
