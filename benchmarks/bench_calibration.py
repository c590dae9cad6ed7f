"""Benchmark one calibration: wall time (compilation included), ESS and ESS/s per model and sampler.

    python benchmarks/bench_calibration.py                      # the real 'chapter' emulator
    python benchmarks/bench_calibration.py --forward analytic   # SYNTHETIC closed-form stand-in
    python benchmarks/bench_calibration.py --app                # the Calibration page's click, compile vs sampling

Runs (4 chains x 1000 warm-up + 1000 draws by default): volume (NUTS), iid
(NUTS), discrepancy (HMC-within-Gibbs, Algorithm 4) and discrepancy (joint
NUTS). Data: one SYNTHETIC data set, forward(theta_ref) + noise (sigma_V = 5 mL,
sigma_S = 0.03) plus a smooth strain discrepancy, so model (iii) has work to do.
Set OMP_NUM_THREADS=1 etc.; targets (2 cores): iid <= 20 s, discrepancy <= 60 s.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--forward", default="emulator", choices=("emulator", "analytic"))
    p.add_argument("--emulator", default="chapter")
    p.add_argument("--h", default="0.5,-0.4,0.3,-0.2,0.1", help="PC scores bound into the emulator")
    p.add_argument("--chains", type=int, default=4)
    p.add_argument("--warmup", type=int, default=1000)
    p.add_argument("--samples", type=int, default=1000)
    p.add_argument("--chain-method", default="auto")
    p.add_argument("--runs", default=p_default_runs())
    p.add_argument("--dense-mass", action="store_true", help="dense NUTS mass matrix (default: diagonal)")
    p.add_argument("--profile", action="store_true",
                   help="split each run into its fixed cost (trace, lower, compile or cache load, init: a 5 + 5 run, "
                        "twice) and its sampling (the full run minus the fixed cost), wall and process CPU seconds")
    p.add_argument("--sweep", default=None, metavar="W:S1/S2,...",
                   help="warm-up lengths and draws to compare by ESS per CPU second (2 and 4 chains), "
                        "e.g. 300:250/500/1000,500:250/500/1000")
    p.add_argument("--datasets", type=int, default=1,
                   help="SYNTHETIC data sets per setting (seeds 0..n-1; --sweep reports the worst minimum ESS)")
    p.add_argument("--app", action="store_true",
                   help="the Calibration page's work in this process, at the page's defaults (subject, emulator, iid + "
                        "discrepancy at samplers.INTERACTIVE): the app's warm-up (trace, lower, compile or cache load: "
                        "lvcore.app.warmup) against a click (sampling and the verdict's best fit), one by one and in "
                        "threads as the page runs them; wall and process CPU seconds, ESS and R-hat per run")
    p.add_argument("--discrepancy-block", default="marginal", choices=("marginal", "chapter"),
                   help="HMC-within-Gibbs block 4 (samplers.DISCREPANCY_BLOCKS; default the app's, marginal)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if args.app:
        from lvcore.app.process import setup_process

        setup_process(args.chains)
        return app_profile(args)
    from lvcore.inference.samplers import use_host_devices

    use_host_devices(args.chains)

    import numpy as np

    import lvcore  # noqa: F401
    from lvcore.exceptions import EmulatorError
    from lvcore.inference import diagnostics, kernels, samplers
    from lvcore.inference.coverage import simulate_data
    from lvcore.emulator.forward import load_emulator_forward
    from lvcore.testing.analytic import AnalyticForward

    h = [float(v) for v in args.h.split(",")]
    if args.forward == "analytic":
        forward = AnalyticForward()
    else:
        try:
            forward = load_emulator_forward(args.emulator, h)
        except EmulatorError as err:
            print(f"{err}\n(use --forward analytic for the SYNTHETIC closed-form stand-in)", file=sys.stderr)
            return 2
    theta = {"a": 0.6, "b": 5.0, "af": 1.5, "bf": 5.0}
    x = kernels.strain_grid()
    disc = 0.03 * np.cos(x[:, 0] - 1.0) + 0.02 * (x[:, 1] - 1.5) / 1.5
    y = simulate_data(forward, theta, np.random.default_rng(0), discrepancy=disc)
    cfg = samplers.SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains,
                                 chain_method=args.chain_method, dense_mass=args.dense_mass,
                                 discrepancy_block=args.discrepancy_block)
    if args.profile:
        return profile(args, forward, y, cfg, samplers, diagnostics)
    if args.sweep:
        return sweep(args, forward, theta, disc, cfg, samplers, diagnostics, simulate_data)
    rows = []
    for name in args.runs.split(","):
        model, sampler = (name, "auto") if name != "discrepancy-nuts" else ("discrepancy", "nuts")
        run = samplers.run_model(model, y, forward, cfg, sampler=sampler)
        conv = diagnostics.check_convergence(run)
        eps = diagnostics.ess_per_second(run)
        rows.append({"run": name, "sampler": run.method, "wall_s": round(run.wall_s, 1),
                     "min_ess_theta": round(eps["min"] * run.wall_s), "ess_per_s_min_theta": round(eps["min"], 1),
                     "max_rhat": round(conv.max_rhat, 3), "divergent": conv.n_divergent,
                     "mean_steps": float(np.mean(run.sample_stats["n_steps"]))})
        if not args.json:
            r = rows[-1]
            print(f"{name:18s} {r['sampler']:9s} wall {r['wall_s']:6.1f} s  min ESS(theta) {r['min_ess_theta']:6d}  "
                  f"ESS/s {r['ess_per_s_min_theta']:7.1f}  R-hat {r['max_rhat']:.3f}  div {r['divergent']}  "
                  f"steps/iter {r['mean_steps']:.0f}", flush=True)
    meta = {"forward": getattr(forward, "label", ""), "chains": args.chains, "warmup": args.warmup,
            "samples": args.samples, "dense_mass": args.dense_mass, "chain_method": getattr(samplers.resolve_chain_method(cfg), "__name__", samplers.resolve_chain_method(cfg)),
            "load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
    if args.json:
        print(json.dumps({"meta": meta, "rows": rows}, indent=2))
    else:
        print(json.dumps(meta))
    return 0


def _timed(fn):
    """``(result, wall s, process CPU s)`` of ``fn()`` (CPU over all threads of this process)."""
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def _runs(text):
    return [(name, "auto") if name != "discrepancy-nuts" else ("discrepancy", "nuts") for name in text.split(",")]


def profile(args, forward, y, cfg, samplers, diagnostics) -> int:
    """Fixed cost (tracing, lowering, XLA compile or persistent-cache load, init) against sampling, per run."""
    import dataclasses

    tiny = dataclasses.replace(cfg, num_warmup=5, num_samples=5)
    print(f"{'run':18s} {'stage':34s} {'wall s':>8s} {'CPU s':>8s}  min ESS(theta)", flush=True)
    rows = []
    for (model, sampler), name in zip(_runs(args.runs), args.runs.split(",")):
        for stage, c in (("first 5 + 5 (compile or cache load)", tiny), ("second 5 + 5 (fixed cost)", tiny),
                         (f"{cfg.num_chains} x ({cfg.num_warmup} + {cfg.num_samples})", cfg)):
            run, wall, cpu = _timed(lambda c=c: samplers.run_model(model, y, forward, c, sampler=sampler))
            ess = round(diagnostics.ess_per_second(run)["min"] * run.wall_s) if c is cfg else None
            rows.append({"run": name, "stage": stage, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
                         "min_ess_theta": ess})
            print(f"{name:18s} {stage:34s} {wall:8.2f} {cpu:8.2f}  {'' if ess is None else ess}", flush=True)
        fixed, full = rows[-2], rows[-1]
        print(f"{name:18s} {'=> sampling (full - fixed)':34s} {full['wall_s'] - fixed['wall_s']:8.2f} "
              f"{full['cpu_s'] - fixed['cpu_s']:8.2f}", flush=True)
    print(json.dumps({"load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                      "forward": getattr(forward, "label", "")}))
    return 0


def app_profile(args) -> int:
    """The Calibration page's click in this process (``--app``): warm-up, then sampling + best fit."""
    import dataclasses
    from concurrent.futures import ThreadPoolExecutor

    import lvcore  # noqa: F401
    from lvcore.app import warmup
    from lvcore.app.controls import DEFAULT_SUBJECT
    from lvcore.emulator.io import load_emulator
    from lvcore.inference import calibrate as cal
    from lvcore.inference import guards, samplers
    from lvcore.inference.cli import DEFAULT_EMULATOR
    from lvcore.inference.data import read_measured_csv
    from lvcore.inference.request import build_request
    from lvcore.resources import bundled_volunteers, volunteer_files

    cfg = dataclasses.replace(samplers.INTERACTIVE, num_chains=args.chains, discrepancy_block=args.discrepancy_block)
    models = [m for m in args.runs.split(",") if m in ("volume", "iid", "discrepancy")] or ["iid", "discrepancy"]
    if args.runs == p_default_runs():
        models = ["iid", "discrepancy"]
    load = os.getloadavg()
    print(f"{'stage':52s} {'wall s':>7s} {'CPU s':>7s}", flush=True)
    stage = lambda label, wall, cpu: print(f"{label:52s} {wall:7.2f} {cpu:7.2f}", flush=True)  # noqa: E731
    (_, wall, cpu) = _timed(lambda: warmup.warm(models=models))
    stage(f"warm-up: {', '.join(models)} samplers + best fit (compile)", wall, cpu)
    emu = load_emulator(DEFAULT_EMULATOR)

    def request_of(name):   # the Calibration page's request (lvcore.inference.request)
        vol = volunteer_files(name)
        data = read_measured_csv(vol.measured)[0]
        return build_request(emu, DEFAULT_EMULATOR, guards.resolve_geometry(str(vol.geometry)), row=data,
                             allow_extrapolation=True)

    subjects = [DEFAULT_SUBJECT] + [n for n in bundled_volunteers() if n != DEFAULT_SUBJECT][:1]
    rows = []
    for name in subjects:
        request = request_of(name)
        tasks = {m: (lambda m=m: cal.calibrate(request.y, request.forward, m, config=cfg)) for m in models}
        tasks["best fit"] = request.consistency
        for label, task in tasks.items():
            res, wall, cpu = _timed(task)
            stage(f"{name}: {label} alone", wall, cpu)
            if label in models:
                c = res.convergence
                print(f"    {label}: max R-hat {c.max_rhat:.3f}, min bulk ESS {c.min_ess_bulk:.0f} (all monitored; "
                      f"theta {float(res.summary.loc[['a', 'b', 'af', 'bf'], 'ess_bulk'].min()):.0f}), "
                      f"{c.n_divergent} divergent, {c.rounds} round(s)", flush=True)
                rows.append({"subject": name, "model": label, "wall_s": wall, "cpu_s": cpu, "max_rhat": c.max_rhat,
                             "min_ess_bulk": c.min_ess_bulk, "divergent": c.n_divergent})

        def together():
            with ThreadPoolExecutor(len(tasks)) as pool:
                return [f.result() for f in [pool.submit(t) for t in tasks.values()]]
        _, wall, cpu = _timed(together)
        stage(f"{name}: {' + '.join(tasks)} in threads (the click)", wall, cpu)
    print(json.dumps({"load_average_before": load, "load_average": os.getloadavg(),
                      "time": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "emulator": DEFAULT_EMULATOR,
                      "config": f"{cfg.num_chains} x ({cfg.num_warmup} + {cfg.num_samples})", "rows": rows}))
    return 0


def p_default_runs() -> str:
    return "volume,iid,discrepancy,discrepancy-nuts"


def sweep(args, forward, theta, disc, cfg, samplers, diagnostics, simulate_data) -> int:
    """ESS per CPU second of chain counts, warm-up lengths and draws, from prefixes of long runs.

    For each warm-up length W of ``--sweep`` (``W:S1/S2/...``), 4 chains run W + max(S) iterations on
    each of ``--datasets`` SYNTHETIC data sets (the first run compiles, the others are timed); a
    setting (C chains, W, S) is scored on the first C chains' first S draws: the worst bulk ESS of
    theta and of every monitored parameter (theta, sigma_S^2, v, GP hyperparameters), the worst R-hat,
    and its CPU cost, estimated as the fixed cost (a 5 + 5 run) plus C (W + S) iterations at the
    measured per-iteration CPU time. Wall on 2 idle cores is about CPU / min(C, 2).
    """
    import dataclasses

    import numpy as np

    datasets = [simulate_data(forward, theta, np.random.default_rng(k), discrepancy=disc)
                for k in range(max(2, args.datasets))]
    print(f"{'run':12s} {'setting':16s} {'est. CPU s':>10s} {'ESS theta':>9s} {'ESS all':>8s} {'R-hat':>6s} "
          f"{'ESS(theta)/CPU-s':>16s}", flush=True)
    out = []
    for (model, sampler), name in zip(_runs(args.runs), args.runs.split(",")):
        tiny = dataclasses.replace(cfg, num_chains=4, num_warmup=5, num_samples=5)
        samplers.run_model(model, datasets[0], forward, tiny, sampler=sampler)
        _, _, fixed = _timed(lambda: samplers.run_model(model, datasets[1], forward, tiny, sampler=sampler))
        for item in args.sweep.split(","):
            w, draws = item.split(":")
            w, draws = int(w), sorted(int(v) for v in draws.split("/"))
            config = dataclasses.replace(cfg, num_chains=4, num_warmup=w, num_samples=draws[-1])
            runs, per_iter = [], []
            for k, y in enumerate(datasets):
                run, wall, cpu = _timed(lambda: samplers.run_model(model, y, forward, dataclasses.replace(config, seed=k),
                                                                   sampler=sampler))
                runs.append(run)
                if k:  # the first run compiled this setting's program
                    per_iter.append((cpu - fixed) / (4 * (w + draws[-1])))
            it = float(np.median(per_iter))
            for c in (2, 4):
                for n in draws:
                    ess_t, ess_all, rhat = [], [], []
                    for run in runs:
                        sub = {k: v[:c, :n] for k, v in run.samples.items()}
                        table = diagnostics.summary_table(sub)
                        ess_t.append(float(table.loc[[v for v in ("a", "b", "af", "bf") if v in table.index],
                                                     "ess_bulk"].min()))
                        ess_all.append(float(table["ess_bulk"].min()))
                        rhat.append(float(table["r_hat"].max()))
                    cost = fixed + c * (w + n) * it
                    row = {"run": name, "chains": c, "warmup": w, "draws": n, "cpu_s": round(cost, 2),
                           "ess_theta": round(min(ess_t)), "ess_all": round(min(ess_all)), "rhat": round(max(rhat), 3)}
                    out.append(row)
                    print(f"{name:12s} {f'{c} x ({w} + {n})':16s} {cost:10.1f} {row['ess_theta']:9d} "
                          f"{row['ess_all']:8d} {row['rhat']:6.3f} {row['ess_theta'] / cost:16.1f}", flush=True)
        print(f"{name}: fixed cost {fixed:.2f} CPU-s, {it * 1e3:.2f} CPU-ms per chain iteration", flush=True)
    print(json.dumps({"load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                      "forward": getattr(forward, "label", ""), "datasets": max(2, args.datasets)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
