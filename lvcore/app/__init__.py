"""The Streamlit app, shipped inside the package so an installed wheel can start it.

``lvcore app`` (or ``streamlit run app.py`` in a checkout) runs :data:`ENTRY`,
which builds the navigation from :data:`PAGES`. Each page is a thin script in
this folder: it gathers inputs and shows results, the science is in lvcore.
Importing this package does not import Streamlit.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

#: This folder: the entry script and the page scripts (installed with the package).
APP_DIR = Path(__file__).resolve().parent
#: The script ``streamlit run`` starts.
ENTRY = APP_DIR / "main.py"


@dataclass(frozen=True)
class AppPage:
    """One page of the app: its script (relative to :data:`APP_DIR`), title in the navigation, icon and URL."""

    script: str
    title: str
    icon: str
    url_path: str

    @property
    def path(self) -> Path:
        return APP_DIR / self.script


#: The app's pages in navigation order; the first is the home page. The page scripts sit in ``views/``, not
#: ``pages/``: Streamlit lists a ``pages/`` folder beside the entry script by itself, with the entry as "main".
PAGES = (
    AppPage("simulator.py", "Simulator", ":material/monitor_heart:", "simulator"),
    AppPage("views/1_Geometry_and_operators.py", "Geometry & operators", ":material/view_in_ar:", "geometry"),
    AppPage("views/2_Shape_model.py", "Shape model", ":material/scatter_plot:", "shape-model"),
    AppPage("views/3_Fibre_angles.py", "Fibre angles", ":material/tune:", "fibre-angles"),
    AppPage("views/4_Emulator.py", "Emulator", ":material/speed:", "emulator"),
    AppPage("views/5_Calibration.py", "Calibration", ":material/query_stats:", "calibration"),
    AppPage("views/6_Studies.py", "Studies", ":material/science:", "studies"),
    AppPage("views/7_Report.py", "Report", ":material/summarize:", "report"),
)

__all__ = ["APP_DIR", "ENTRY", "AppPage", "PAGES"]
