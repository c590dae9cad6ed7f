#!/usr/bin/env python
"""Run the fibre-discrepancy study on the shipped real LV for one strain layer and ship the result file.

The geometry is the REAL patient-derived LV in ``assets/real_lv/`` (``scripts/ship_real_lv.py``); the data are
FE-simulated on it (SYNTHETIC data on a real shape). One run of this script does one strain layer:

1. the subject emulator of the layer (``--emulator``, default ``build/real_lv/emulator_<layer>``) is built
   beforehand with the documented command (the inner half is lvcore's default layer)::

       nice -n 5 lvcore emulator build --geometry assets/real_lv/real_lv_dalton2022_template.vtu \\
           --out build/real_lv/emulator_inner_half --name real-lv-inner-half

2. ``study``: ``lvcore study fibre-discrepancy --geometry real-lv --emulator DIR`` as a function call (12 test sets
   FE-simulated on the real LV, three likelihoods fitted by MCMC; the full output in ``--work``/study_<layer>);
3. ``regional``: the Fig 9.5 pattern, the FE change (−60°, 60°) → (0°, 90°) at the study's 4 θ on the real LV
   (the (0°, 90°) outputs are the study's noise-free data) and on the SYNTHETIC geometries: the study's PCA
   geometry ``h`` and the bundled volunteers (``--volunteers``);
4. ``assemble``: every layer whose pieces are in ``--work`` goes into ``assets/studies/`` (the registry's result
   file of ``fibre-discrepancy-real-lv``), floats rounded to 6 digits;
5. ``docs``: the generated block of docs/studies.md is rewritten from the shipped file.

Run from the repository root (each layer about 20-25 min on 2 shared cores at the default budget)::

    OMP_NUM_THREADS=1 nice -n 5 python scripts/ship_fibre_discrepancy_real_lv.py --layer inner_half
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


def run_layer_study(layer: str, emulator: Path, work: Path, warmup: int, samples: int, chains: int, seed: int,
                    resolution: str) -> dict:
    from lvcore.inference import samplers
    from lvcore.studies import fibre_discrepancy as fd

    samplers.use_host_devices(chains)
    cfg = samplers.SamplerConfig(num_warmup=warmup, num_samples=samples, num_chains=chains, seed=seed)
    return fd.run_study(config=cfg, seed=seed, resolution=resolution, emulator=str(emulator), geometry=fd.REAL_LV,
                        out=work / f"study_{layer}", progress=lambda msg, frac: _say(msg))


def _warm(simulator):
    """The simulator with warm starts (each solve starts Newton from the nearest converged state; same tolerances)."""
    return dataclasses.replace(simulator, warm_start=True)


def regional(study: dict, volunteers: list[str], resolution: str, base: str) -> tuple[list, dict]:
    """The real LV's and the SYNTHETIC geometries' regional changes at the study's 4 θ."""
    from lvcore.resources import volunteer_files
    from lvcore.studies import fibre_discrepancy as fd
    from lvcore.studies import fibre_discrepancy_real_lv as rl

    thetas = fd.THETA_SETS
    to = {tuple(s["theta"][n] for n in fd.THETA_NAMES): s["z"] for s in study["sets"]
          if (s["alpha_endo"], s["alpha_epi"]) == rl.TO_ANGLES}
    sim = fd.data_simulator(resolution=resolution, base=base, geometry=fd.geometry_section(fd.REAL_LV))
    _say("regional change on the REAL LV")
    real = rl.regional_changes(_warm(sim), thetas, to_outputs=[to.get(tuple(th)) for th in thetas]
                               if all(tuple(th) in to for th in thetas) else None, progress=_say)
    synthetic = {}
    _say("regional change on the SYNTHETIC PCA geometry h")
    synthetic["SYNTHETIC h"] = rl.regional_changes(_warm(fd.data_simulator(fd.DEFAULT_H, resolution, base)), thetas,
                                                   progress=_say)
    for name in volunteers:
        _say(f"regional change on {name}")
        geo = {"kind": "mesh", "path": str(volunteer_files(name).geometry)}
        synthetic[name] = rl.regional_changes(_warm(fd.data_simulator(resolution=resolution, base=base, geometry=geo)),
                                              thetas, progress=_say)
    return real, synthetic


def assemble(work: Path, out: Path) -> Path:
    from lvcore.studies import fibre_discrepancy_real_lv as rl
    from lvcore.studies._common import clean, round_floats

    layers, synthetic = {}, {}
    for layer in rl.LAYERS:
        f = work / f"pieces_{layer}.json"
        if f.is_file():
            p = json.loads(f.read_text())
            layers[layer] = {"study": p["study"], "regional": p["regional"], "emulator": p["emulator"]}
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
    p.add_argument("--warmup", type=int, default=250, help="warm-up per chain (default 250)")
    p.add_argument("--samples", type=int, default=250, help="draws kept per chain (default 250)")
    p.add_argument("--chains", type=int, default=2, help="chains per fit (default 2)")
    p.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    p.add_argument("--resolution", default="default", help="FE mesh preset (default 'default')")
    p.add_argument("--volunteers", default=",".join(f"SYNTHETIC_HV{i}" for i in range(1, 9)),
                   help="SYNTHETIC volunteers of the regional comparison (default SYNTHETIC_HV1..8)")
    p.add_argument("--steps", default="study,regional,assemble,docs",
                   help="steps to run, of study,regional,assemble,docs (default all four)")
    p.add_argument("--docs", type=Path, default=ROOT / "docs" / "studies.md",
                   help="docs file whose generated block the docs step rewrites (default docs/studies.md)")
    p.add_argument("--work", type=Path, default=ROOT / "build" / "real_lv", help="work folder (default build/real_lv)")
    p.add_argument("--out", type=Path, default=ROOT / "assets" / "studies", help="output folder (default assets/studies)")
    args = p.parse_args(argv)
    steps = {s.strip() for s in args.steps.split(",")}
    emulator = args.emulator or args.work / f"emulator_{args.layer}"
    pieces = args.work / f"pieces_{args.layer}.json"
    t0 = time.perf_counter()
    if "study" in steps:
        from lvcore.emulator.io import load_emulator

        study = run_layer_study(args.layer, emulator, args.work, args.warmup, args.samples, args.chains, args.seed,
                                args.resolution)
        emu = load_emulator(emulator)
        record = {"name": emu.name, **{k: emu.metadata["test"][k] for k in ("n", "lvv_rmse_ml", "strain_rmse")},
                  "runs": emu.metadata["subject"]["runs"], "seconds": emu.metadata["subject"]["seconds"],
                  "prior": {k: emu.metadata["subject"]["prior"].get(k) for k in ("used", "name", "scale", "clipped")},
                  "base": emu.base, "resolution": emu.resolution, "strain_layer": args.layer}
        pieces.write_text(json.dumps({"study": study, "emulator": record, "regional": [], "synthetic": {}}))
        _say(f"study done in {time.perf_counter() - t0:.0f} s: {json.dumps(study['findings'])}")
    if "regional" in steps:
        p_ = json.loads(pieces.read_text())
        vols = [v.strip() for v in args.volunteers.split(",") if v.strip()]
        p_["regional"], p_["synthetic"] = regional(p_["study"], vols, args.resolution, p_["emulator"]["base"])
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
