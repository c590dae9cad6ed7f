"""``lvcore design ...`` and ``lvcore campaign run|status|resume``."""
from __future__ import annotations

from lvcore import cli_args
from lvcore.safety import limits
from lvcore.campaigns.designs import METHODS, make_design, save_design
from lvcore.campaigns.space import SPACE_NAMES, get_space
from lvcore.campaigns.runner import CHAIN_MIN_ROWS, IN_PROCESS_MAX_ROWS, RESOLUTIONS
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, STRAIN_LAYERS


def register(subparsers) -> None:
    # lvcore design METHOD --space NAME --n N --seed S --out design.csv
    p = cli_args.command(
        subparsers, "design", _design, help="write a space-filling design (CSV) over a named parameter space",
        description="Write a Sobol, Latin-hypercube, random or exp-warped Latin-hypercube design over a named "
                    "parameter space as CSV, the input of `lvcore campaign run`.")
    p.add_argument("method", choices=METHODS, help="sobol (scrambled), lhs, random, or exp (the chapter's exp-warped LHS)")
    p.add_argument("--space", required=True, choices=SPACE_NAMES, help="named parameter space (see lvcore.campaigns.space)")
    p.add_argument("--n", type=cli_args.int_in(1, limits.MAX_DESIGN_POINTS), required=True,
                   help=f"number of design points, 1 to {limits.MAX_DESIGN_POINTS:,} (lvcore.safety.limits.MAX_DESIGN_POINTS; "
                        "also the most rows `lvcore campaign run` accepts)")
    p.add_argument("--seed", type=cli_args.seed, required=True, help="random seed, an integer from 0 to 2^32 - 1")
    p.add_argument("--pcs", type=cli_args.int_in(0, 20), default=None,
                   help="number of PC scores, 0 to 20 (default: the space's own, 5 for chapter and angles, else 0)")
    p.add_argument("--out", type=cli_args.output_file, required=True,
                   help="output CSV file (its folders are created; an existing file is replaced)")

    sub = cli_args.command_group(
        subparsers, "campaign", help="run, resume or inspect a simulation campaign",
        description="Run a design through the forward model into a resumable HDF5 store, resume an interrupted "
                    "one, or count the converged, failed and pending rows of a store.")

    run = cli_args.command(
        sub, "run", _run, help="run every row of a design; results go to an HDF5 store as they arrive",
        description="Run every row of a design CSV on local workers or a Dask scheduler; each result is committed "
                    "to a new HDF5 store as it arrives, so a campaign that is stopped can be resumed.")
    run.add_argument("design", help="design CSV written by `lvcore design`")
    run.add_argument("--out", type=cli_args.output_file, required=True,
                     help="HDF5 store to create (refused if it exists: use `lvcore campaign resume`)")
    _add_run_options(run)
    run.add_argument("--resolution", choices=RESOLUTIONS, default="default",
                     help="simulator mesh resolution (default: default)")
    run.add_argument("--strain-layer", choices=tuple(STRAIN_LAYERS), default=DEFAULT_STRAIN_LAYER,
                     help="wall layer the 24 regional strains are averaged over, recorded in the store (default: "
                          f"{DEFAULT_STRAIN_LAYER}; the chapter does not say which layer its strains come from)")
    run.add_argument("--forward", default=None, metavar="NAME",
                     help="registered forward model (default 'simulator', the FE simulator); others are registered "
                          "in code with lvcore.core.register_forward")

    res = cli_args.command(
        sub, "resume", _resume, help="run the rows of a store that are not recorded yet",
        description="Run the pending rows of an existing store (and the failed ones with --retry-failed); rows "
                    "that fail the store check are listed and never run.")
    res.add_argument("store", help="HDF5 store written by `lvcore campaign run`")
    _add_run_options(res)
    res.add_argument("--retry-failed", action="store_true", help="also run the failed rows again")

    st = cli_args.command(
        sub, "status", _status, help="counts of converged/failed/pending rows and failure reasons",
        description="Print how many rows of a store converged, failed or are pending, the failure reasons and the "
                    "mean solve time; inconsistent rows are reported and left out of every count.")
    st.add_argument("store", help="HDF5 store")
    st.add_argument("--check", action="store_true",
                    help="list every inconsistent row (state not 0/1/2, record_count not 1, NaN outputs in a "
                         "converged row, inputs outside the space) and exit with 2 if there is one; such rows "
                         "are always excluded from the counts (default: off, the first 10 are listed)")


def _add_run_options(p) -> None:
    """The options of ``campaign run`` and ``campaign resume`` on how rows are run: workers or a scheduler, cold
    solves, the progress bar."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=cli_args.workers, default=None,
                   help=f"local worker processes, 1 to 4 per core ({cli_args.max_local_workers()} here; "
                        f"default: none for at most {IN_PROCESS_MAX_ROWS} rows to run, which run in this process, "
                        "else one per core)")
    g.add_argument("--scheduler", default=None,
                   help="Dask scheduler address tcp://HOST:PORT instead of local workers (default: none)")
    how = p.add_mutually_exclusive_group()
    how.add_argument("--cold", action="store_const", const=False, dest="chained",
                     help="solve every row cold, one task per row (default: cold below "
                          f"{CHAIN_MIN_ROWS} rows to run, where chains cost more, else --chained)")
    how.add_argument("--chained", action="store_const", const=True, dest="chained",
                     help="warm-started continuation chains of nearby rows, split across the workers; same "
                          f"results within the solver tolerance (default: from {CHAIN_MIN_ROWS} rows to run)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _design(args) -> int:
    space = get_space(args.space, n_pcs=args.pcs)
    design = make_design(space, args.method, args.n, args.seed)
    path = save_design(design, args.out)
    print(f"wrote {design.n} {args.method} points over space '{space.name}' ({', '.join(space.names)}) to {path}")
    return 0


def _run(args) -> int:
    from lvcore.campaigns.runner import DEFAULT_FORWARD, run_campaign

    summary = run_campaign(args.design, args.out, workers=args.workers, scheduler=args.scheduler,
                           resolution=args.resolution, forward=args.forward or DEFAULT_FORWARD,
                           progress=not args.no_progress, chained=args.chained, strain_layer=args.strain_layer)
    print(summary.format())
    return 0


def _resume(args) -> int:
    from lvcore.campaigns.runner import resume_campaign

    summary = resume_campaign(args.store, workers=args.workers, scheduler=args.scheduler,
                              retry_failed=args.retry_failed, progress=not args.no_progress, chained=args.chained)
    print(summary.format())
    return 0


def _status(args) -> int:
    from lvcore.campaigns.runner import campaign_status
    from lvcore.exceptions import CampaignError

    summary = campaign_status(args.store)
    print(summary.format(all_problems=args.check))
    if args.check and summary.inconsistent:
        raise CampaignError(f"store '{args.store}' has {summary.inconsistent} inconsistent row(s), listed above; "
                            "they are excluded from every count, from resume and from emulator training")
    return 0
