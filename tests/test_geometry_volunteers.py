"""The bundled SYNTHETIC volunteers: public files hold no truth; data = simulation(truth) + noise."""
import json

import numpy as np

from lvcore.geometry.io import read_template_mesh
from lvcore.geometry.measures import cavity_volume
from lvcore.geometry.template import DEFAULT_TEMPLATE
from lvcore.inference.data import read_measured_csv
from lvcore.resources import volunteers_dir

VOL = volunteers_dir()


def test_volunteer_files_and_separate_truth():
    meta = json.loads((VOL / "SYNTHETIC_volunteers.json").read_text())
    truth = json.loads((VOL / "truth" / "SYNTHETIC_volunteers_truth.json").read_text())
    assert meta["synthetic"] and len(meta["volunteers"]) == 8
    public_text = (VOL / "SYNTHETIC_volunteers.json").read_text()
    assert "theta" not in public_text and "alpha_endo" not in public_text
    by_subject = {t["subject"]: t for t in truth["volunteers"]}
    for v in meta["volunteers"]:
        assert v["subject"].startswith("SYNTHETIC-HV")
        rows = read_measured_csv(VOL / v["measured"])
        assert len(rows) == 1 and rows[0].subject == v["subject"]
        t = by_subject[v["subject"]]
        assert np.allclose(rows[0].y, np.add(t["outputs_noise_free"], t["noise"]), atol=1e-5)
        nodes = read_template_mesh(VOL / v["geometry"])
        assert np.isclose(float(cavity_volume(nodes, DEFAULT_TEMPLATE)) / 1000.0, v["early_diastolic_volume_ml"],
                          rtol=1e-4)
    noise = np.array([t["noise"] for t in truth["volunteers"]])
    assert np.all(np.abs(noise[:, 0]) < 4 * 5.0) and 0.015 < noise[:, 1:].std() < 0.045
