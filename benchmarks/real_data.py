"""Real subjects without a mesh: coverage of ``lvcore calibrate --geometry infer`` on SYNTHETIC ellipsoids.

    python benchmarks/real_data.py --workdir build/real_data              # simulate, calibrate, print the table
    python benchmarks/real_data.py --workdir build/real_data --steps simulate
    python benchmarks/real_data.py --workdir build/real_data --steps calibrate --chains 2 --warmup 500 --samples 500
    python benchmarks/real_data.py --workdir build/real_data --steps table     # from results*.json
    python benchmarks/real_data.py --workdir build/real_data --steps compare --tag floor=floor_nf+floor_noisy,known_fe
    python benchmarks/real_data.py --workdir build/real_data --steps fisher    # Laplace: a's best-case precision

Subjects (all SYNTHETIC, made by lvcore's FE simulator): one truncated
ellipsoid (endo rs 25 / ry 22.5 / rl 60 mm, wall 9.5 mm, 10 mm thicker at
the apex, base plane 8 mm above the centre; PC scores inside the emulator's
box once size-normalised) scaled to reference cavities of 40, 60, 120 and
180 mL, i.e. outside the shape model's 62-110 mL; three theta from the prior
box each; sliding base, fibres -60/60 deg, 8 mmHg (the ``chapter``
emulator's conditions); the default mesh resolution.

Each subject is calibrated twice with the CLI (``--geometry infer
--reference-volume``, iid model, ``chapter`` emulator), noise-free and with
sigma_V = 5 mL on the LVV and the reference volume and sigma_S = 0.03 on the
strains (seeded). A case is *right* when all four true theta and the
subject's own V20 (the FE simulator on the ellipsoid at 20 mmHg) lie in their
90 % intervals (q05-q95; V20 from ``summary.json``'s derived EDPVR).
Criterion (the verdict that flags defects only): every case that is not
right exits 4 (flagged), every MISFIT case is flagged, and no case exits 4
for weak identification alone.

Variants (``--tag`` names the results file, ``results_<tag>.json``):

* ``--representation-error off``: infer mode without the shape model's
  representation-error floor (:mod:`lvcore.inference.representation_error`);
* ``--geometry known``: the identifiability floor. The geometry is given
  (``--geometry`` the ellipsoid's template nodes, .npy: the CLI splits them
  into the scale and the 5 PC scores, so the emulator runs at the
  ellipsoid's projection and exact size) instead of inferred;
* ``--data-source emulator`` (with ``--geometry known``): the data are the
  ``chapter`` emulator's own outputs at that projection and scale (LVV x s^3),
  with the same noise: no model error at all, so what is left of a's
  spread is the data's (one pressure, 24 strains, sigma_S, the priors).

``--steps projection`` simulates each ellipsoid's 5-mode reconstruction
(``s * reconstruct(h)``) at the true theta: the benchmark subjects' own
representation error, to set against the cohort's floor.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

#: Reference cavity volumes of the subjects (mL).
VOLUMES_ML = (40.0, 60.0, 120.0, 180.0)
#: The true theta (a kPa, b, af kPa, bf), inside the prior box.
THETAS = ((0.5, 3.0, 1.5, 5.0), (0.25, 6.0, 0.8, 10.0), (1.2, 2.0, 3.0, 3.0))
#: The ellipsoid before scaling (mm).
SHAPE = {"endo": {"rs": 25.0, "ry": 22.5, "rl": 60.0}, "epi": {"rs": 34.5, "ry": 32.0, "rl": 70.0}, "base_z": 8.0}
SIGMA_V, SIGMA_S = 5.0, 0.03
NOISE_SEED = 2024


def ellipsoid(scale: float) -> dict:
    """The case geometry section of the benchmark ellipsoid scaled by ``scale``."""
    return {"kind": "ellipsoid", "endo": {k: v * scale for k, v in SHAPE["endo"].items()},
            "epi": {k: v * scale for k, v in SHAPE["epi"].items()}, "base_z": SHAPE["base_z"] * scale}


def unit_volume_ml() -> float:
    from lvcore.geometry.analytic import EllipsoidSurface, TruncatedEllipsoidLV

    lv = TruncatedEllipsoidLV(EllipsoidSurface(**SHAPE["endo"]), EllipsoidSurface(**SHAPE["epi"]), SHAPE["base_z"])
    return lv.cavity_volume_mm3() / 1000.0


def simulate_all(workdir: Path) -> list[dict]:
    """Run (or reuse) the 12 FE simulations; returns one record per subject."""
    from lvcore.mechanics.simulate import simulate

    path = workdir / "simulations.json"
    done = json.loads(path.read_text()) if path.is_file() else []
    have = {(r["volume_ml"], tuple(r["theta"])) for r in done}
    v1 = unit_volume_ml()
    for vol in VOLUMES_ML:
        s = (vol / v1) ** (1.0 / 3.0)
        for th in THETAS:
            if (vol, tuple(th)) in have:
                continue
            case = {"geometry": ellipsoid(s), "material": {"law": "holzapfel-ogden", **dict(zip(("a", "b", "af", "bf"), th))},
                    "fibres": {"alpha_endo": -60.0, "alpha_epi": 60.0}, "load": {"pressure": 8.0, "units": "mmHg"},
                    "boundary": {"base": "sliding"}}
            t0 = time.perf_counter()
            r = simulate(case)
            rec = {"volume_ml": vol, "scale": s, "theta": list(th), "converged": bool(r.converged),
                   "message": str(r.message), "seconds": time.perf_counter() - t0,
                   "reference_volume_ml": float(r.cavity_volume_mm3[0]) / 1000.0,
                   "outputs": [float(v) for v in r.outputs()] if r.converged else None}
            rec.update(true_edpvr(case, r))
            done.append(rec)
            workdir.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(done, indent=1))
            print(f"simulated V0 {vol:g} mL theta {th}: {'ok' if r.converged else r.message} "
                  f"({rec['seconds']:.1f} s)", flush=True)
    return done


def true_edpvr(case: dict, at_edp) -> dict:
    """The subject's own V20 and V30 (mL): the FE simulator on the ellipsoid at 20 and 30 mmHg, warm-started."""
    from lvcore.mechanics.simulate import simulate

    out, warm = {}, at_edp.warm_state if at_edp.converged else None
    for p in (20.0, 30.0):
        r = simulate({**case, "load": {"pressure": p, "units": "mmHg"}}, initial=warm)
        out[f"v{p:g}_ml"] = float(r.cavity_volume_mm3[1]) / 1000.0 if r.converged else None
        warm = r.warm_state if r.converged else warm
    return out


def add_true_edpvr(workdir: Path, sims: list[dict]) -> list[dict]:
    """V20 and V30 of simulations recorded before they were (simulations.json is updated in place)."""
    from lvcore.mechanics.simulate import simulate

    for sim in sims:
        if sim["converged"] and "v20_ml" not in sim:
            case = {"geometry": ellipsoid(sim["scale"]),
                    "material": {"law": "holzapfel-ogden", **dict(zip(("a", "b", "af", "bf"), sim["theta"]))},
                    "fibres": {"alpha_endo": -60.0, "alpha_epi": 60.0}, "load": {"pressure": 8.0, "units": "mmHg"},
                    "boundary": {"base": "sliding"}}
            sim.update(true_edpvr(case, simulate(case)))
    (workdir / "simulations.json").write_text(json.dumps(sims, indent=1))
    return sims


def template_nodes(scale: float):
    """Template nodes (mm) of the benchmark ellipsoid scaled by ``scale`` (the simulator's parametric map)."""
    from lvcore.geometry.analytic import EllipsoidSurface, TruncatedEllipsoidLV
    from lvcore.geometry.template import DEFAULT_TEMPLATE

    g = ellipsoid(scale)
    lv = TruncatedEllipsoidLV(EllipsoidSurface(**g["endo"]), EllipsoidSurface(**g["epi"]), g["base_z"])
    return DEFAULT_TEMPLATE.nodes_from_map(lv.position)


def projection(scale: float, n_pc: int = 5):
    """:class:`lvcore.geometry.scaling.ScaledScores` of the ellipsoid scaled by ``scale`` (what the CLI computes)."""
    from lvcore.geometry.scaling import size_normalised_scores

    return size_normalised_scores(template_nodes(scale), n_pc)


def emulator_outputs(sim: dict, emulator: str = "chapter"):
    """The emulator's [LVV, 24 strains] at the true theta and the ellipsoid's projection and scale."""
    import numpy as np

    from lvcore.emulator.forward import emulator_forward
    from lvcore.emulator import load_emulator
    from lvcore.geometry.scaling import ScaledForward

    sc = projection(sim["scale"])
    fw = ScaledForward(emulator_forward(load_emulator(emulator), sc.h, name=emulator), sc.scale)
    return np.asarray(fw(dict(zip(("a", "b", "af", "bf"), sim["theta"]))), float)


def project_all(workdir: Path, sims: list[dict]) -> list[dict]:
    """FE solves of each ellipsoid's 5-mode reconstruction at its true theta: its own representation error."""
    import numpy as np

    from lvcore.geometry.io import write_template_mesh
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.mechanics.simulate import simulate

    path = workdir / "projections.json"
    done = json.loads(path.read_text()) if path.is_file() else []
    have = {(r["volume_ml"], tuple(r["theta"])) for r in done}
    model = load_shape_model()
    for sim in sims:
        if not sim["converged"] or (sim["volume_ml"], tuple(sim["theta"])) in have:
            continue
        sc = projection(sim["scale"])
        mesh = workdir / "projection.vtu"
        write_template_mesh(mesh, sc.scale * model.reconstruct(sc.h))
        case = {"geometry": {"kind": "mesh", "path": str(mesh)},
                "material": {"law": "holzapfel-ogden", **dict(zip(("a", "b", "af", "bf"), sim["theta"]))},
                "fibres": {"alpha_endo": -60.0, "alpha_epi": 60.0}, "load": {"pressure": 8.0, "units": "mmHg"},
                "boundary": {"base": "sliding"}}
        r = simulate(case)
        y, yr = np.asarray(sim["outputs"], float), np.asarray(r.outputs(), float)
        v0r = float(r.cavity_volume_mm3[0]) / 1000.0
        d = y[1:] - yr[1:]
        rec = {"volume_ml": sim["volume_ml"], "theta": sim["theta"], "h": sc.h.tolist(), "scale": sc.scale,
               "projection_mse_cm2": sc.projection_mse_cm2, "v0_recon_ml": v0r, "strain_delta": d.tolist(),
               "strain_rms": float(np.sqrt(np.mean(d ** 2))),
               "lvv_rel_delta": float((y[0] / sim["reference_volume_ml"]) / (yr[0] / v0r) - 1.0),
               "emulator_strain_rms": float(np.sqrt(np.mean((y[1:] - emulator_outputs(sim)[1:]) ** 2)))}
        done.append(rec)
        path.write_text(json.dumps(done, indent=1))
        print(f"projection V0 {sim['volume_ml']:g} mL theta {sim['theta']}: strain RMS difference "
              f"{rec['strain_rms']:.4f} (ellipsoid vs its 5-mode reconstruction, FE), EDV/V0 "
              f"{100 * rec['lvv_rel_delta']:+.2f} %; emulator at the projection vs the ellipsoid FE: strain RMS "
              f"{rec['emulator_strain_rms']:.4f}", flush=True)
    return done


def fisher_all(sims: list[dict], emulator: str = "chapter", sigma_s: float = SIGMA_S, sigma_v: float = SIGMA_V) -> list[dict]:
    """The best case for a's precision, without sampling: the Laplace (Fisher-information) approximation of
    the posterior of log theta with the geometry known and no model error at all.

    For each subject, the ``chapter`` emulator at the ellipsoid's 5-mode projection and exact scale
    (:func:`emulator_outputs`' forward model) is differentiated at the true theta with respect to
    ``log a, log b, log af, log bf``; with the benchmark's noise (LVV sd ``sigma_v``, 24 strains sd
    ``sigma_s``) the information is ``I = J^T diag(sigma^-2) J`` and the approximate posterior sd of
    ``log a`` is ``sqrt((I^-1)_aa)``, so a's q95/q05 is about ``exp(2 * 1.645 * sd)``. The prior box is
    ignored (it can only narrow an interval that reaches it); everything else can only widen it (the
    geometry inferred, a model error, a non-Gaussian posterior along the a-b trade-off).
    """
    import jax
    import jax.numpy as jnp
    import numpy as np

    from lvcore.emulator import load_emulator
    from lvcore.emulator.forward import emulator_forward
    from lvcore.geometry.scaling import ScaledForward

    emu = load_emulator(emulator)
    out = []
    w = np.r_[1.0 / sigma_v ** 2, np.full(24, 1.0 / sigma_s ** 2)]
    for sim in sims:
        sc = projection(sim["scale"])
        fw = ScaledForward(emulator_forward(emu, sc.h, name=emulator), sc.scale)

        def f(lt):
            return jnp.asarray(fw(dict(zip(("a", "b", "af", "bf"), jnp.exp(lt)))))

        lt0 = jnp.log(jnp.asarray(sim["theta"], dtype=jnp.float64))
        jac = np.asarray(jax.jacfwd(f)(lt0), float)             # (25, 4)
        info = jac.T @ (w[:, None] * jac)
        cov = np.linalg.inv(info)
        sd = np.sqrt(np.diag(cov))
        strains_only = np.linalg.inv(jac[1:].T @ jac[1:] / sigma_s ** 2 + 1e-12 * np.eye(4))
        lam, vec = np.linalg.eigh(info)                          # ascending: the least-informed direction first
        v0 = vec[:, 0] * np.sign(vec[0, 0] or 1.0)
        out.append({"volume_ml": sim["volume_ml"], "theta": sim["theta"], "sd_log": sd.tolist(),
                    "weakest_direction": v0.tolist(), "weakest_sd": float(1.0 / np.sqrt(max(lam[0], 1e-300))),
                    "second_sd": float(1.0 / np.sqrt(max(lam[1], 1e-300))),
                    "a_ratio": float(np.exp(2 * 1.645 * sd[0])),
                    # both noise sds scaled by this factor give the Laplace a q95/q05 = 20 (the sd scales with them)
                    "noise_factor_for_20": float(np.log(20.0) / (2 * 1.645 * sd[0])),
                    "a_ratio_strains_only": float(np.exp(2 * 1.645 * np.sqrt(strains_only[0, 0]))),
                    "corr_a_b": float(cov[0, 1] / (sd[0] * sd[1]))})
    return out


def subject_rows(sims: list[dict], data_source: str = "fe", emulator: str = "chapter") -> list[dict]:
    """The 24 calibration cases: every simulation noise-free and noisy.

    ``data_source="emulator"`` replaces the FE outputs by the emulator's at the
    ellipsoid's projection and scale (:func:`emulator_outputs`); the noise is the same.
    """
    import numpy as np

    rng = np.random.default_rng(NOISE_SEED)
    rows = []
    for k, sim in enumerate(sims):
        if not sim["converged"]:
            continue
        y = np.asarray(sim["outputs"], float) if data_source == "fe" else emulator_outputs(sim, emulator)
        for noisy in (False, True):
            yy, v0 = y.copy(), sim["reference_volume_ml"]
            if noisy:
                yy[0] += SIGMA_V * rng.standard_normal()
                yy[1:] += SIGMA_S * rng.standard_normal(24)
                v0 += SIGMA_V * rng.standard_normal()
            rows.append({"subject": f"SYNTHETIC-V{sim['volume_ml']:g}-T{THETAS.index(tuple(sim['theta'])) + 1}"
                                    + ("-noisy" if noisy else ""),
                         "y": yy, "reference_volume_ml": v0, "theta": sim["theta"], "volume_ml": sim["volume_ml"],
                         "scale": sim["scale"], "noisy": noisy, "v20_ml": sim.get("v20_ml"),
                         "v30_ml": sim.get("v30_ml")})
    return rows


def calibrate_all(rows, workdir: Path, chains: int, warmup: int, samples: int, emulator: str, tag: str = "",
                  geometry: str = "infer", representation_error: str = "floor", derived_draws: int = 100,
                  derived_pressures: str = "5,10,15,20,25,30") -> list[dict]:
    """Calibrate each case through the CLI (in-process, so the sampler is compiled once).

    ``geometry="infer"``: ``--geometry infer`` with the reference volume as a data column;
    ``"known"``: ``--geometry`` the ellipsoid's template nodes (.npy). Results go to
    ``results_<tag>.json`` (``results.json`` without a tag).
    """
    import numpy as np

    from lvcore.cli import main
    from lvcore.domain.outputs import OUTPUT_COLUMNS

    res_path = workdir / (f"results_{tag}.json" if tag else "results.json")
    out = json.loads(res_path.read_text()) if res_path.is_file() else []   # resumable: cases done are kept
    done = {r["subject"] for r in out}
    runs = workdir / "runs" / tag if tag else workdir / "runs"
    for row in rows:
        if row["subject"] in done:
            print(f"{row['subject']:28s} done (results_{tag or ''}.json), skipped", flush=True)
            continue
        d = runs / row["subject"]
        d.mkdir(parents=True, exist_ok=True)
        csv = d / "data.csv"
        extra = (",reference_volume_ml", f",{row['reference_volume_ml']:.6g}") if geometry == "infer" else ("", "")
        csv.write_text("subject," + ",".join(OUTPUT_COLUMNS) + extra[0] + "\n" + row["subject"] + ","
                       + ",".join(f"{v:.8g}" for v in row["y"]) + extra[1] + "\n")
        if geometry == "infer":
            geo = ["--geometry", "infer", "--representation-error", representation_error]
        else:
            np.save(d / "geometry.npy", template_nodes(row["scale"]))
            geo = ["--geometry", str(d / "geometry.npy")]
        t0 = time.perf_counter()
        code = main(["calibrate", "--data", str(csv), *geo, "--emulator", emulator,
                     "--model", "iid", "--chains", str(chains), "--warmup", str(warmup), "--samples", str(samples),
                     "--derived-draws", str(derived_draws), "--derived-pressures", derived_pressures,
                     "--out", str(d / "out"), "--json"])
        wall = time.perf_counter() - t0
        rec = json.loads((d / "out" / "summary.json").read_text())[0] if (d / "out" / "summary.json").is_file() else {}
        truth = dict(zip(("a", "b", "af", "bf"), row["theta"]))
        inside = {n: bool(rec[n]["q05"] <= truth[n] <= rec[n]["q95"]) for n in truth} if rec else {}
        ratio = rec["a"]["q95"] / rec["a"]["q05"] if rec else float("nan")
        covered = bool(rec) and all(inside.values())
        edpvr = {int(e["pressure_mmhg"]): e for e in ((rec.get("derived") or {}).get("edpvr") or [])}
        v_inside = {}
        for p in (20, 30):
            true_v, q = row.get(f"v{p}_ml"), edpvr.get(p)
            if true_v is not None and q and q.get("q05") is not None:
                v_inside[f"V{p}"] = bool(q["q05"] <= true_v <= q["q95"])
        out.append({"subject": row["subject"], "volume_ml": row["volume_ml"], "noisy": row["noisy"],
                    "theta": row["theta"], "exit": code, "covered": covered, "inside": inside, "a_ratio": ratio,
                    "v_inside": v_inside, "true_v": {"V20": row.get("v20_ml"), "V30": row.get("v30_ml")},
                    "edpvr": {f"V{p}": [edpvr[p]["q05"], edpvr[p]["median"], edpvr[p]["q95"]] for p in (20, 30)
                              if p in edpvr and edpvr[p].get("q05") is not None},
                    "notes": rec.get("notes", []),
                    "a": rec.get("a"), "scale": rec.get("geometry", {}).get("posterior", {}).get("scale"),
                    "theta_q": {n: [rec[n]["q05"], rec[n]["median"], rec[n]["q95"]] for n in truth} if rec else {},
                    "sigma_s": (float(np.sqrt(rec["sigma_s2"]["median"])) if rec and "sigma_s2" in rec else None),
                    "flags": rec.get("verdict", {}).get("flags", []), "wall_s": wall, "tag": tag,
                    "geometry": geometry, "representation_error": representation_error if geometry == "infer" else None})
        print(f"{row['subject']:28s} exit {code}  covered {covered}  a q05-q95 "
              f"{rec.get('a', {}).get('q05', float('nan')):.3g}-{rec.get('a', {}).get('q95', float('nan')):.3g} "
              f"(true {truth['a']:g})  inside {inside}  ({wall:.0f} s)", flush=True)
        res_path.write_text(json.dumps(out, indent=1))
    return out


def table(results: list[dict]) -> str:
    """The Markdown table of BENCHMARKS.md and the criterion lines (the verdict that flags defects only).

    A case is *right* when all four true theta and its true V20 lie in their 90 % intervals; every case that
    is not right must be flagged (exit 4), and no case may exit 4 on weak identification alone (the verdict no
    longer has such a flag: weak identification is a note).
    """
    lines = ["| V0 (mL) | noise | true theta (a, b, af, bf) | all four in 90 % | a q05-q95 (kPa) | a q95/q05 "
             "| true V20 (mL) | V20 q05-q95 (mL) | V20 in | exit | flags |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        a = r["a"] or {}
        out = [n for n, ok in (r.get("inside") or {}).items() if not ok]
        short = [f.split(";")[0].split(" (")[0][:80] for f in r["flags"]]
        v20 = (r.get("edpvr") or {}).get("V20")
        tv = (r.get("true_v") or {}).get("V20")
        vin = (r.get("v_inside") or {}).get("V20")
        lines.append(f"| {r['volume_ml']:g} | {'5 mL / 0.03' if r['noisy'] else 'none'} | "
                     f"{', '.join(f'{v:g}' for v in r['theta'])} | {'yes' if not out else 'no (' + ', '.join(out) + ')'} "
                     f"| {a.get('q05', float('nan')):.3g}-{a.get('q95', float('nan')):.3g} | {r['a_ratio']:.0f} | "
                     f"{'-' if tv is None else f'{tv:.1f}'} | {'-' if not v20 else f'{v20[0]:.1f}-{v20[2]:.1f}'} | "
                     f"{'-' if vin is None else ('yes' if vin else 'no')} | {r['exit']} | {'; '.join(short) or '-'} |")
    n = len(results)
    right = [r for r in results if r["covered"] and (r.get("v_inside") or {}).get("V20", False)]
    wrong_unflagged = [r["subject"] for r in results if r not in right and r["exit"] != 4]
    weak_only = [r["subject"] for r in results if r["exit"] == 4 and r["flags"]
                 and all(f.startswith("IDENTIFIABILITY") for f in r["flags"])]
    misfit_unflagged = [r["subject"] for r in results if any(f.startswith("MISFIT") for f in r["flags"])
                        and r["exit"] != 4]
    lines.append("")
    lines.append(f"right (four theta and V20 inside) {len(right)}/{n}; exit 4 {sum(r['exit'] == 4 for r in results)}; "
                 f"not right and not flagged: {len(wrong_unflagged)} {wrong_unflagged}; exit 4 for weak identification "
                 f"alone: {len(weak_only)}; misfit not flagged: {len(misfit_unflagged)}")
    return "\n".join(lines)


def reverdict(workdir: Path, tag: str) -> list[dict]:
    """Re-apply the posterior-predictive MISFIT check of the current verdict to the saved runs of ``tag``.

    Runs sampled before :func:`lvcore.inference.verdict.posterior_misfit` existed keep their posterior
    (netCDF) and every other flag; the MISFIT flags are recomputed (with the representation error
    when the run had the floor) and the exit code follows (4 with any flag, 1 when not converged).
    ``exit_at_run`` keeps the code the run returned.
    """
    from dataclasses import replace

    import arviz as az

    from lvcore.inference import verdict
    from lvcore.inference.representation_error import load_representation_error

    path = workdir / f"results_{tag}.json"
    results = json.loads(path.read_text())
    for r in results:
        out = workdir / "runs" / tag / r["subject"] / "out"
        rec = json.loads((out / "summary.json").read_text())[0]
        idata = az.from_netcdf(rec["netcdf"] if Path(rec["netcdf"]).is_file() else out / Path(rec["netcdf"]).name)
        floor = (rec.get("geometry") or {}).get("representation_error")

        class _Fw:   # the floor the run used: the asset's covariance at the mesh's own factor (strain_scale)
            representation = (replace(load_representation_error(5), strain_scale=float(floor.get("strain_scale", 1.0)))
                              if floor else None)

        class _Res:
            model = rec["model"]

        _Res.idata = idata
        structure, misfit = verdict.posterior_misfit(_Res, _Fw)
        flags = [f for f in rec.get("flags", []) if not f.startswith("MISFIT")] + [f"MISFIT: {f}" for f in misfit]
        r.setdefault("exit_at_run", r["exit"])
        r["flags"], r["residual_structure"], r["reverdict"] = flags, structure, True
        r["exit"] = 1 if not rec["converged"] else (4 if flags else 0)
    path.write_text(json.dumps(results, indent=1))
    return results


def compare(results_by_tag: dict) -> str:
    """One row per case, per variant: a's q95/q05, whether all four theta are inside, the exit code."""
    tags = list(results_by_tag)
    by = {t: {r["subject"]: r for r in rs} for t, rs in results_by_tag.items()}
    subjects = sorted({s for t in tags for s in by[t]},
                      key=lambda s: (float(s.split("-V")[1].split("-")[0]), s.split("-")[2], "noisy" in s))
    lines = ["| case | " + " | ".join(f"{t}: a q95/q05, all four in, exit" for t in tags) + " |",
             "|---|" + "---|" * len(tags)]
    for sub in subjects:
        cells = []
        for t in tags:
            r = by[t].get(sub)
            if r is None:
                cells.append("-")
                continue
            out = [n for n, ok in (r.get("inside") or {}).items() if not ok]
            mark = "yes" if not out else "no (" + ", ".join(out) + ")"
            bad = " **unflagged miss**" if not r["covered"] and r["exit"] != 4 else ""
            cells.append(f"{r['a_ratio']:.0f}, {mark}, {r['exit']}{bad}")
        lines.append(f"| {sub.replace('SYNTHETIC-', '')} | " + " | ".join(cells) + " |")
    lines.append("")
    for t in tags:
        rs = list(by[t].values())
        cov = sum(r["covered"] for r in rs)
        inside = sum(all((r.get("inside") or {"x": False}).values()) for r in rs)
        ratios = sorted(r["a_ratio"] for r in rs)
        miss = [r["subject"] for r in rs if not r["covered"] and r["exit"] != 4]
        lines.append(f"{t}: {len(rs)} cases; covered {cov}; all four inside {inside}; a q95/q05 median "
                     f"{ratios[len(ratios) // 2]:.0f} (min {ratios[0]:.0f}, max {ratios[-1]:.0f}); not covered and "
                     f"not flagged: {len(miss)} {miss}")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--workdir", default="build/real_data")
    p.add_argument("--steps", default="simulate,calibrate")
    p.add_argument("--emulator", default="chapter")
    p.add_argument("--chains", type=int, default=4)
    p.add_argument("--warmup", type=int, default=1000)
    p.add_argument("--samples", type=int, default=1000)
    p.add_argument("--only", default=None, help="comma-separated subject names to calibrate")
    p.add_argument("--geometry", choices=("infer", "known"), default="infer",
                   help="infer (--geometry infer --reference-volume) or known (the ellipsoid's template nodes)")
    p.add_argument("--representation-error", choices=("floor", "off"), default="floor",
                   help="with --geometry infer: the CLI's --representation-error (default floor)")
    p.add_argument("--data-source", choices=("fe", "emulator"), default="fe",
                   help="fe: the FE simulations; emulator: the emulator's outputs at the projection (no model error)")
    p.add_argument("--tag", default="", help="results_<tag>.json and runs/<tag>/ (default: results.json, runs/)")
    p.add_argument("--derived-draws", type=int, default=100,
                   help="posterior draws behind each case's derived EDPVR (V20, V30; lvcore calibrate's option)")
    p.add_argument("--derived-pressures", default="5,10,15,20,25,30",
                   help="the derived EDPVR's pressures (lvcore calibrate's option; 20,30 is enough for the criterion)")
    args = p.parse_args(argv)
    work = Path(args.workdir)
    steps = args.steps.split(",")
    if "calibrate" in steps:
        from lvcore.inference.samplers import use_host_devices

        use_host_devices(args.chains)
    sims = (simulate_all(work) if "simulate" in steps
            else json.loads((work / "simulations.json").read_text()) if ("calibrate" in steps or "projection" in steps)
            else [])
    if steps == ["reverdict"]:   # the current MISFIT check on saved runs: --tag a,b
        for t in args.tag.split(","):
            print(table(reverdict(work, t)))
        return 0
    if steps == ["compare"]:   # the variants side by side: --tag a,b,c (results_<tag>.json; "" = results.json)
        # a variant may span several files: "floor=floor_nf+floor_noisy"
        res = {}
        for spec in args.tag.split(","):
            name, _, files = spec.partition("=")
            res[name] = [r for f in (files or name).split("+") for r in json.loads((work / f"results_{f}.json").read_text())]
        print(compare(res))
        return 0
    if steps == ["table"]:   # the table of the results of --tag (every results*.json without one)
        files = ([work / f"results_{t}.json" for t in args.tag.split(",")] if args.tag
                 else sorted(work.glob("results*.json")))
        results = [r for f in files for r in json.loads(f.read_text())]
        print(table(results))
        return 0
    if steps == ["fisher"]:   # the Laplace approximation of a's precision with the geometry known (no sampling)
        sims = json.loads((work / "simulations.json").read_text())
        rows = fisher_all(sims, args.emulator)
        (work / "fisher.json").write_text(json.dumps(rows, indent=1))
        print("| V0 (mL) | true theta | Laplace sd of log a, b, af, bf | a q95/q05 (Laplace, no prior) | "
              "corr(log a, log b) | least-informed direction (log a, b, af, bf): sd | next: sd | sigma_S for 20 |")
        print("|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['volume_ml']:g} | {', '.join(f'{v:g}' for v in r['theta'])} | "
                  f"{', '.join(f'{v:.2f}' for v in r['sd_log'])} | {r['a_ratio']:.2g} | {r['corr_a_b']:+.2f} | "
                  f"({', '.join(f'{v:+.2f}' for v in r['weakest_direction'])}): {r['weakest_sd']:.2g} | "
                  f"{r['second_sd']:.2g} | {SIGMA_S * r['noise_factor_for_20']:.2g} |")
        ratios = sorted(r["a_ratio"] for r in rows)
        print(f"\nLaplace a q95/q05 with sigma_S {SIGMA_S:g}, sigma_V {SIGMA_V:g} mL, geometry known, no model error, "
              f"no prior: median {ratios[len(ratios) // 2]:.2g} (min {ratios[0]:.2g}, max {ratios[-1]:.2g}); "
              f"below 20 in {sum(r < 20 for r in ratios)} of {len(ratios)} (the prior box's own 90 % interval of a "
              "spans a factor 17.4)")
        return 0
    if "projection" in steps:
        project_all(work, sims)
    if "calibrate" in steps and sims and any("v20_ml" not in r for r in sims if r["converged"]):
        sims = add_true_edpvr(work, sims)
    if "calibrate" in steps:
        rows = subject_rows(sims, args.data_source, args.emulator)
        if args.only:
            order = args.only.split(",")   # in the order given
            rows = sorted((r for r in rows if r["subject"] in order), key=lambda r: order.index(r["subject"]))
        results = calibrate_all(rows, work, args.chains, args.warmup, args.samples, args.emulator, args.tag,
                                args.geometry, args.representation_error, args.derived_draws, args.derived_pressures)
        print(table(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
