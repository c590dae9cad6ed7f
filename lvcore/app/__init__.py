"""The Streamlit app, shipped inside the package so an installed wheel can start it.

``lvcore app`` (or ``streamlit run app.py`` in a checkout) runs :data:`ENTRY`,
which builds the navigation from :data:`PAGES`. The home page (``simulator.py``)
is in this folder; the other pages are thin scripts in the repository's
``pages/`` (installed as ``pages/``, see :func:`lvcore.resources.pages_dir`):
they gather inputs and show results, the science is in lvcore.
Importing this package does not import Streamlit.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from lvcore.resources import pages_dir

#: This folder: the entry script and the home page (installed with the package).
APP_DIR = Path(__file__).resolve().parent
#: The page scripts: the checkout's ``pages/``, or ``pages/`` in an installed wheel.
PAGES_DIR = pages_dir()
#: The script ``streamlit run`` starts.
ENTRY = APP_DIR / "main.py"


@dataclass(frozen=True)
class AppPage:
    """One page of the app: its script (``pages/<name>`` or, for the home page, relative to :data:`APP_DIR`),
    title in the navigation, icon and URL; ``uses_theta``/``uses_edp``: the page reads θ / the EDP from the shared
    sidebar (elsewhere the sidebar hides those controls, which would do nothing there)."""

    script: str
    title: str
    icon: str
    url_path: str
    uses_theta: bool = False
    uses_edp: bool = False

    @property
    def path(self) -> Path:
        if self.script.startswith("pages/"):
            return PAGES_DIR / self.script[len("pages/"):]
        return APP_DIR / self.script


#: The app's pages in navigation order; the first is the home page. The navigation is explicit
#: (``st.navigation``), so Streamlit does not list the ``pages/`` folder beside ``app.py`` by itself.
PAGES = (
    AppPage("simulator.py", "Simulator", ":material/monitor_heart:", "simulator"),
    AppPage("pages/1_Geometry_and_operators.py", "Geometry & operators", ":material/view_in_ar:", "geometry"),
    AppPage("pages/2_Shape_model.py", "Shape model", ":material/scatter_plot:", "shape-model"),
    AppPage("pages/3_Fibre_angles.py", "Fibre angles", ":material/tune:", "fibre-angles", uses_theta=True,
            uses_edp=True),
    AppPage("pages/4_Emulator.py", "Emulator", ":material/speed:", "emulator", uses_theta=True, uses_edp=True),
    AppPage("pages/5_Calibration.py", "Calibration", ":material/query_stats:", "calibration"),
    AppPage("pages/6_Studies.py", "Studies", ":material/science:", "studies"),
    AppPage("pages/8_My_subject.py", "My subject", ":material/person:", "my-subject"),
    AppPage("pages/7_Report.py", "Report", ":material/summarize:", "report"),
)

__all__ = ["APP_DIR", "PAGES_DIR", "ENTRY", "AppPage", "PAGES"]
