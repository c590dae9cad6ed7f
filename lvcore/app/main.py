"""LV Calibration Lab: the Streamlit entry script.

Started by ``lvcore app`` (``streamlit run`` on this file) or, in a checkout,
by ``streamlit run app.py`` (a shim that calls :func:`main`). It only sets up
the process and the navigation; the pages are listed in
:data:`lvcore.app.PAGES`.
"""
from __future__ import annotations

from lvcore.app.process import setup_process

setup_process()  # once, before numpy, VTK and JAX start: threads, EGL, one XLA host device per chain

import streamlit as st  # noqa: E402

from lvcore.app import PAGES  # noqa: E402


def main() -> None:
    """Build the navigation and run the page the user is on."""
    st.set_page_config(page_title="LV Calibration Lab", page_icon="🫀", layout="wide")
    pages = [st.Page(p.path, title=p.title, icon=p.icon, url_path=p.url_path, default=(k == 0))
             for k, p in enumerate(PAGES)]
    pg = st.navigation(pages)
    from lvcore.app import warmup

    warmup.start()  # once per server process: the Calibration page's samplers and best fit, compiled in the background
    from lvcore.app.controls import render_shared_sidebar

    page = next((p for p in PAGES if p.title == pg.title), None)
    # subject, emulator, θ and EDP (each only where the page reads it): one sidebar, one state, every page
    render_shared_sidebar(theta=page is None or page.uses_theta, edp=page is None or page.uses_edp)
    pg.run()


if __name__ == "__main__":
    main()
