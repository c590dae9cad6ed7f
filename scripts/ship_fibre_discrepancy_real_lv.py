#!/usr/bin/env python
"""Run the fibre-discrepancy study on the shipped real LV for one strain layer and ship the result file.

The geometry is the REAL patient-derived LV in ``assets/real_lv/`` (``scripts/ship_real_lv.py``); the data are
FE-simulated on it (SYNTHETIC data on a real shape). One run of this script does one strain layer:

1. ``emulator``: the subject emulator of the layer (``--emulator``, default ``build/real_lv/emulator_<layer>``),
   unless one is there: :data:`LAYER_SETUP`'s mesh, design and prior mean. For the inner half (lvcore's default
   layer) that is exactly::

       nice -n 5 lvcore emulator build --geometry assets/real_lv/real_lv_dalton2022_template.vtu \\
           --out build/real_lv/emulator_inner_half --name real-lv-inner-half --no-edpvr

   and for the whole wall the same with ``--strain-layer whole_wall --prior none``, 640 + 50 + 60 runs, on the
   default mesh with two elements through the wall (a mesh the command's ``--resolution`` does not name);

2. ``study``: ``lvcore study fibre-discrepancy --geometry real-lv --emulator DIR`` as a function call (12 test sets
   FE-simulated on the real LV, three likelihoods fitted by MCMC; the full output in ``--work``/study_<layer>);
3. ``regional``: the Fig 9.5 pattern, the FE change (−60°, 60°) → (0°, 90°) at the study's 4 θ on the real LV
   (the (0°, 90°) outputs are the study's noise-free data) and on the SYNTHETIC geometries: the study's PCA
   geometry ``h`` and the bundled volunteers (``--volunteers``);
4. ``assemble``: every layer whose pieces are in ``--work`` goes into ``assets/studies/`` (the registry's result
   file of ``fibre-discrepancy-real-lv``), floats rounded to 6 digits;
5. ``docs``: the generated block of docs/studies.md is rewritten from the shipped file.

The default sampler budget, 2 chains x (500 warm-up + 500 draws) per fit, is the one at which every fit of both
layers has R-hat <= 1.05 (at 2 x (250 + 250) one volume-only fit per layer did not converge: R-hat 1.19 and 1.06).
Run from the repository root (each layer about 12.5 min wall on 2 shared cores at the default budget, with the two
layers run side by side at load 3.5-8.7, its subject emulator build included)::

    OMP_NUM_THREADS=1 nice -n 5 python scripts/ship_fibre_discrepancy_real_lv.py --layer inner_half
    OMP_NUM_THREADS=1 nice -n 5 python scripts/ship_fibre_discrepancy_real_lv.py --layer whole_wall
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads

pin_threads()  # before numpy is imported

ROOT = Path(__file__).resolve().parent.parent


def _say(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


#: Per layer: the FE mesh, the subject emulator's design (train, validation, held-out test) and its prior mean. The
#: whole wall needs two elements through the wall (docs/simulator.md "Strain layers"); no bundled emulator has
#: whole-wall strains, so its subject emulator has no prior mean and more training runs.
LAYER_SETUP = {"inner_half": {"resolution": "default", "design": (512, 50, 100), "prior": "auto"},
               "whole_wall": {"resolution": "6,2+1+1+2,2,5", "design": (640, 50, 60), "prior": "none"}}


def build_emulator(layer: str, out: Path, workers: int = 2) -> None:
    """The subject emulator of ``layer`` on the shipped real LV (:data:`LAYER_SETUP`), as ``lvcore emulator build``
    builds it with ``--no-edpvr`` (the inner half's is exactly that command's default otherwise): the study reads
    no derived EDPVR."""
    from lvcore.emulator.subject import SubjectDesign, build_subject_emulator
    from lvcore.resources import real_lv_files

    setup = LAYER_SETUP[layer]
    build_subject_emulator(real_lv_files().template, out, design=SubjectDesign(*setup["design"]),
                           resolution=mesh(setup["resolution"]), strain_layer=layer, prior=setup["prior"],
                           name=f"real-lv-{layer.replace('_', '-')}", workers=workers, log=_say, edpvr=False)


def run_layer_study(layer: str, emulator: Path, work: Path, warmup: int, samples: int, chains: int, seed: int,
                    resolution) -> dict:
    from lvcore.inference import samplers
    from lvcore.studies import fibre_discrepancy as fd

    samplers.use_host_devices(chains)
    cfg = samplers.SamplerConfig(num_warmup=warmup, num_samples=samples, num_chains=chains, seed=seed)
    return fd.run_study(config=cfg, seed=seed, resolution=resolution, emulator=str(emulator), geometry=fd.REAL_LV,
                        out=work / f"study_{layer}", progress=lambda msg, frac: _say(msg))


def regional(study: dict | None, volunteers: list[str], resolution, base: str, layer: str) -> tuple[list, dict]:
    """The real LV's and the SYNTHETIC geometries' regional changes at the study's 4 θ (strains of ``layer``)."""
    from lvcore.resources import volunteer_files
    from lvcore.studies import fibre_discrepancy as fd
    from lvcore.studies import fibre_discrepancy_real_lv as rl

    def sim(h=fd.DEFAULT_H, geometry=None):  # warm starts: each solve starts from the nearest converged state
        return dataclasses.replace(fd.data_simulator(h, resolution, base, geometry, strain_layer=layer), warm_start=True)

    thetas = fd.THETA_SETS
    to = {tuple(s["theta"][n] for n in fd.THETA_NAMES): s["z"] for s in (study or {}).get("sets", [])
          if (s["alpha_endo"], s["alpha_epi"]) == rl.TO_ANGLES}
    known = [to[tuple(th)] for th in thetas] if all(tuple(th) in to for th in thetas) else None
    _say(f"regional change on the REAL LV ({layer})")
    real = rl.regional_changes(sim(geometry=fd.geometry_section(fd.REAL_LV)), thetas, to_outputs=known, progress=_say)
    _say("regional change on the SYNTHETIC PCA geometry h")
    synthetic = {"SYNTHETIC h": rl.regional_changes(sim(), thetas, progress=_say)}
    for name in volunteers:
        _say(f"regional change on {name}")
        geo = {"kind": "mesh", "path": str(volunteer_files(name).geometry)}
        synthetic[name] = rl.regional_changes(sim(geometry=geo), thetas, progress=_say)
    return real, synthetic


def mesh(spec: str):
    """A preset name as it is, else ``NC,NL,NT[,GP]`` (e.g. ``6,2+1+1+2,2,5``) as the case's resolution dict."""
    from lvcore.mechanics.resolution import RESOLUTION_PRESETS, LVResolution

    return spec if spec in RESOLUTION_PRESETS else LVResolution.from_spec(spec).case_dict()


def assemble(work: Path, out: Path) -> Path:
    from lvcore.studies import fibre_discrepancy_real_lv as rl
    from lvcore.studies._common import clean, round_floats

    layers, synthetic = {}, {}
    for layer in rl.LAYERS:
        f = work / f"pieces_{layer}.json"
        if f.is_file():
            p = json.loads(f.read_text())
            layers[layer] = {"study": p["study"], "regional": p["regional"], "emulator": p["emulator"],
                             "resolution": p.get("resolution", "default")}
            synthetic[layer] = p["synthetic"]
    result = round_floats(clean(rl.assemble(layers, synthetic)))
    out.mkdir(parents=True, exist_ok=True)
    path = out / rl.RESULT_FILE
    path.write_text(json.dumps(result, indent=1) + "\n")
    return path


def rewrite_docs(docs: Path, shipped: Path) -> None:
    """The generated block of ``docs`` (between ``DOCS_BEGIN`` and ``DOCS_END``) from the shipped result."""
    import re

    from lvcore.studies import fibre_discrepancy_real_lv as rl

    text, block = docs.read_text(), rl.docs_markdown(json.loads(shipped.read_text()))
    pattern = re.compile(re.escape(rl.DOCS_BEGIN) + ".*?" + re.escape(rl.DOCS_END), re.S)
    if len(pattern.findall(text)) != 1:
        raise SystemExit(f"{docs}: expected one generated block")
    docs.write_text(pattern.sub(lambda m: f"{rl.DOCS_BEGIN}\n{block}\n{rl.DOCS_END}", text))


def main(argv=None) -> int:
    from lvcore.studies import fibre_discrepancy_real_lv as rl

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--layer", choices=rl.LAYERS, default="inner_half", help="strain layer (default inner_half)")
    p.add_argument("--emulator", type=Path, default=None,
                   help="subject emulator of the layer (default build/real_lv/emulator_<layer>)")
    p.add_argument("--warmup", type=int, default=500, help="warm-up per chain (default 500)")
    p.add_argument("--samples", type=int, default=500, help="draws kept per chain (default 500)")
    p.add_argument("--chains", type=int, default=2, help="chains per fit (default 2)")
    p.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    p.add_argument("--resolution", default=None,
                   help="FE mesh: a preset or NC,NL,NT[,GP] (default: the layer's, LAYER_SETUP: 'default' for the "
                        "inner half, 6,2+1+1+2,2,5 (the default mesh with two elements through the wall) for the whole "
                        "wall)")
    p.add_argument("--volunteers", default=",".join(f"SYNTHETIC_HV{i}" for i in range(1, 9)),
                   help="SYNTHETIC volunteers of the regional comparison (default SYNTHETIC_HV1..8)")
    p.add_argument("--steps", default="emulator,study,regional,assemble,docs",
                   help="steps to run, of emulator,study,regional,assemble,docs (default all five; the emulator step "
                        "is skipped when --emulator already holds one)")
    p.add_argument("--docs", type=Path, default=ROOT / "docs" / "studies.md",
                   help="docs file whose generated block the docs step rewrites (default docs/studies.md)")
    p.add_argument("--work", type=Path, default=ROOT / "build" / "real_lv", help="work folder (default build/real_lv)")
    p.add_argument("--out", type=Path, default=ROOT / "assets" / "studies", help="output folder (default assets/studies)")
    args = p.parse_args(argv)
    steps = {s.strip() for s in args.steps.split(",")}
    emulator = args.emulator or args.work / f"emulator_{args.layer}"
    pieces = args.work / f"pieces_{args.layer}.json"
    args.resolution = args.resolution or LAYER_SETUP[args.layer]["resolution"]
    t0 = time.perf_counter()
    if steps & {"emulator", "study", "regional"}:
        from lvcore.mechanics.linear import default_backend

        _say(f"FE linear solver: {default_backend()}")
    if "emulator" in steps and not (emulator / "metadata.json").is_file():
        build_emulator(args.layer, emulator)
    if "study" in steps:
        from lvcore.emulator.io import load_emulator

        study = run_layer_study(args.layer, emulator, args.work, args.warmup, args.samples, args.chains, args.seed,
                                mesh(args.resolution))
        emu = load_emulator(emulator)
        record = {"name": emu.name, **{k: emu.metadata["test"][k] for k in ("n", "lvv_rmse_ml", "strain_rmse")},
                  "runs": emu.metadata["subject"]["runs"], "seconds": emu.metadata["subject"]["seconds"],
                  "prior": {k: emu.metadata["subject"]["prior"].get(k) for k in ("used", "name", "scale", "clipped")},
                  "base": emu.base, "resolution": args.resolution, "strain_layer": emu.strain_layer}
        old = json.loads(pieces.read_text()) if pieces.is_file() else {}  # FE sweeps already run are kept
        pieces.write_text(json.dumps({"regional": [], "synthetic": {}, **old, "study": study, "emulator": record}))
        _say(f"study done in {time.perf_counter() - t0:.0f} s: {json.dumps(study['findings'])}")
    if "regional" in steps:
        p_ = json.loads(pieces.read_text()) if pieces.is_file() else {"study": None, "emulator": {"base": "sliding"}}
        vols = [v.strip() for v in args.volunteers.split(",") if v.strip()]
        p_["regional"], p_["synthetic"] = regional(p_["study"], vols, mesh(args.resolution), p_["emulator"]["base"],
                                                   args.layer)
        p_["resolution"] = args.resolution
        pieces.write_text(json.dumps(p_))
        _say(f"regional done at {time.perf_counter() - t0:.0f} s")
    if "assemble" in steps:
        _say(f"wrote {assemble(args.work, args.out)}")
    if "docs" in steps:
        rewrite_docs(args.docs, args.out / rl.RESULT_FILE)
        _say(f"rewrote the generated block of {args.docs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
