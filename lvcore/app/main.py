"""LV Calibration Lab: the Streamlit entry script.

Started by ``lvcore app`` (``streamlit run`` on this file) or, in a checkout,
by ``streamlit run app.py`` (a shim whose ASGI app serves this script). It only sets up
the process and the navigation; the pages are listed in
:data:`lvcore.app.PAGES`.
"""
from __future__ import annotations

from lvcore.app.process import setup_process

setup_process()  # once, before numpy, VTK and JAX start: threads, EGL, one XLA host device per chain

import streamlit as st  # noqa: E402

from lvcore.app import PAGES  # noqa: E402


#: Internal name (never a URL) of the home page's entry at the root URL; its own URL path is served by a hidden alias.
HOME_AT_ROOT = "home-at-root"


def navigation_pages(st) -> list:
    """The ``st.Page`` list of :data:`lvcore.app.PAGES`: every page at ``/<url_path>``, the home page also at ``/``.

    Streamlit serves the default page only at the root URL (it ignores the default page's ``url_path``), so typing
    ``/simulator`` would say "Page not found". The home page is therefore listed twice: once as the visible default
    (at ``/``, highlighted in the sidebar) and once, hidden from the sidebar, at its own URL path.
    """
    home, *others = PAGES
    pages = [st.Page(home.path, title=home.title, icon=home.icon, url_path=HOME_AT_ROOT, default=True)]
    pages += [st.Page(p.path, title=p.title, icon=p.icon, url_path=p.url_path) for p in others]
    pages.append(st.Page(home.path, title=home.title, icon=home.icon, url_path=home.url_path, visibility="hidden"))
    return pages


def main() -> None:
    """Build the navigation and run the page the user is on."""
    st.set_page_config(page_title="LV Calibration Lab", page_icon="🫀", layout="wide")
    pg = st.navigation(navigation_pages(st))
    from lvcore.app import warmup

    warmup.start()  # once per server process: the Calibration page's samplers and best fit, compiled in the background
    if warmup.note():  # it did less than asked: memory is short on this server
        st.sidebar.caption(warmup.note())
    from lvcore.app.controls import render_shared_sidebar

    page = next((p for p in PAGES if p.title == pg.title), None)
    # subject, emulator, θ and EDP (each only where the page reads it): one sidebar, one state, every page
    render_shared_sidebar(theta=page is None or page.uses_theta, edp=page is None or page.uses_edp)
    pg.run()


if __name__ == "__main__":
    main()
