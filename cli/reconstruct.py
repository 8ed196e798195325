"""``lfproc reconstruct CAPTURE -o OUT.exr``: the HDR light field of a coded multi-ISO capture."""

from __future__ import annotations

from pathlib import Path

from ._common import add_json, add_output, emit
from lfproc.camera.capture import load_capture
from lfproc.dictionary import load_dictionary
from lfproc.errors import InputError
from lfproc.io import write_lightfield
from lfproc.io._atomic import check_output


def register(sub, common) -> None:
    p = sub.add_parser(
        "reconstruct", parents=[common], help="reconstruct the HDR light field of a coded multi-ISO capture",
        description="Two methods. gmm (the default for simulate's periodic masks): for every patch, try "
                    "disparities and covariance scales of a Gaussian prior on a sheared centre-view patch, keep "
                    "the one of largest evidence, take its linear MMSE estimate, and combine the overlapping "
                    "patches. dictionary (the paper's): solve the weighted lasso argmin_a 1/2 ||W (Phi_p D a - "
                    "T_p)||^2 + mu ||a||_1 per patch and average the estimates D a. Both use the calibrated "
                    "observations T of every shot (weights 1/std(T), saturated measurements as bounds or left "
                    "out). The output is in the units of the light field the capture was simulated from (e-/s "
                    "for real captures), so `lfproc evaluate OUT TRUTH` compares directly.")
    p.add_argument("capture", type=Path, metavar="CAPTURE", help="capture file (lfproc simulate / capture import)")
    add_output(p, help="light field to write (OUT.exr, or a folder of EXR views)")
    p.add_argument("--method", default="auto", choices=("auto", "gmm", "dictionary"),
                   help="gmm: disparity-sheared Gaussian patch models (lfproc.recon.reconstruct_gmm; needs a "
                        "periodic random mask, simulate's default); dictionary: the sparse code of a learned "
                        "dictionary per patch (the paper's method, lfproc.recon.reconstruct); auto (default): gmm "
                        "when the capture's mask is periodic and random and no option of the dictionary method is "
                        "given, else dictionary")
    p.add_argument("--model", default=None, metavar="default|FILE",
                   help="with --method gmm: the patch model, the shipped 'default' or a .npz of "
                        "lfproc.recon.train_patch_model")
    p.add_argument("--disparities", default=None, metavar="D,D,...",
                   help="with --method gmm: disparities tried per patch, pixels per view step (default "
                        "-1,-0.75,...,1)")
    p.add_argument("--scales", default=None, metavar="S,S,...",
                   help="with --method gmm: multipliers of the model's covariances tried per patch (default "
                        "0.1,1,10)")
    p.add_argument("--search", default=None, choices=("staged", "joint"),
                   help="with --method gmm: choose the disparity at one covariance scale, then the scale (staged, "
                        "default), or over every disparity and scale at once (joint: about twice the time; on the "
                        "tune scenes at Lytro size +0.4 dB PU21-PSNR, 35.08 against 34.70)")
    p.add_argument("--dictionary", default="default", metavar="default|FILE",
                   help="dictionary: the shipped 'default' or a dictionary .npz file")
    p.add_argument("--solver", default="admm", metavar="admm|fista|omp",
                   help="admm (default; batched, one factor per operator phase), fista, or omp (fast greedy mode)")
    p.add_argument("--stride", type=int, default=None,
                   help="patch spacing in pixels, 1..patch size (default 2 with gmm, 4 with dictionary)")
    p.add_argument("--mu", type=float, default=None,
                   help="l1 weight in units of the noise level of the patch's correlations with the atoms (default "
                        "0.5); with --scale noise relative to the patch's norm; with --scale patch relative to a "
                        "unit-norm patch (the paper's: 1e-4)")
    p.add_argument("--max-iter", type=int, default=None, help="iteration limit (default 100 ADMM, 1000 FISTA)")
    p.add_argument("--tol", type=float, default=None,
                   help="relative change that stops a patch (default 1e-3 ADMM, 2^-15 = 3.0517578125e-05 FISTA; "
                        "the paper's: --tol 3.0517578125e-05 --max-iter 300)")
    p.add_argument("--sparsity", type=int, default=None, help="atoms per patch for omp (default: the dictionary's)")
    p.add_argument("--scale", default=None, metavar="universal|noise|patch|global",
                   help="HDR scale: the chi-square data term with the l1 weight at its noise level (universal, "
                        "default), the chi-square data term with the l1 weight relative to the patch's norm (noise), "
                        "per-patch codes and data term (patch: the paper-faithful reading), or one scale for the "
                        "capture (global)")
    p.add_argument("--overlap", default=None, metavar="scale-window-fit|scale-window|scale|window|mean",
                   help="how overlapping patch estimates are weighted: by the patch's scale, a centre window and "
                        "the patch's fit (scale-window-fit, default), fewer of these, or plain averages (mean: the "
                        "paper's)")
    p.add_argument("--variance", default=None, metavar="local|measurement",
                   help="the signal in each measurement's photon-noise variance (its weight): its neighbours' (local, "
                        "default) or its own value (measurement: the plug-in, biased low)")
    p.add_argument("--paper", action="store_true",
                   help="the paper's settings: --scale patch --overlap mean --variance measurement --mu 1e-4 "
                        "--tol 2^-15 --max-iter 300 "
                        "(options given explicitly win)")
    p.add_argument("--threads", type=int, default=None, help="blocks solved at once in this process (default: CPUs)")
    p.add_argument("--per-shot", default=None, metavar="debevec|ml", dest="per_shot",
                   help="the paper's baselines (captures of global-ISO shots: simulate --baseline individual-iso|"
                        "bracketing): reconstruct every shot alone and merge them view by view with Debevec hat "
                        "weights or the noise-aware ML merge (lfproc.recon.reconstruct_per_shot)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="solve blocks of patches on a local Dask cluster of N processes")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="address of a running Dask scheduler (tcp://host:8786)")
    add_json(p)
    p.set_defaults(run=run)


def _numbers(text: str, option: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{option}: expected comma-separated numbers, got {text!r}") from None


def _dictionary_options(args) -> list[str]:
    """The options of --method dictionary given on the command line."""
    given = [f"--{name.replace('_', '-')}" for name in ("mu", "tol", "max_iter", "sparsity", "scale", "overlap",
                                                         "variance", "per_shot", "workers", "scheduler")
             if getattr(args, name) is not None]
    given += ["--paper"] if args.paper else []
    given += ["--dictionary"] if args.dictionary != "default" else []
    given += ["--solver"] if args.solver != "admm" else []
    return given


def _run_gmm(args, capture=None) -> int:
    # lfproc.recon loads scipy.linalg: imported when the command runs, so `lfproc --help` starts fast
    from lfproc.recon import load_patch_model, reconstruct_gmm

    ignored = _dictionary_options(args)
    if ignored:
        raise InputError(f"{', '.join(ignored)}: options of --method dictionary; --method gmm takes --model, "
                         "--disparities, --scales, --search, --stride and --threads")
    check_output(args.output, force=args.force)
    capture = load_capture(args.capture) if capture is None else capture
    model = load_patch_model(args.model or "default")
    options = {"stride": 2 if args.stride is None else args.stride, "threads": args.threads}
    if args.disparities is not None:
        options["disparities"] = _numbers(args.disparities, "--disparities")
    if args.scales is not None:
        options["scales"] = _numbers(args.scales, "--scales")
    if args.search is not None:
        options["search"] = args.search
    lf = reconstruct_gmm(capture, model, **options).replace(source=str(args.capture))
    write_lightfield(lf, args.output, force=args.force)
    rec = lf.attrs["reconstruction"]
    emit({"output": str(args.output), "capture": str(args.capture), "method": "gmm", "model": rec["model"],
          "patches": rec["patches"], "stride": rec["stride"], "disparities": rec["disparities"],
          "disparity_counts": rec["disparity_counts"], "scales": rec["scales"], "units": lf.units,
          "shape": list(lf.shape), "seconds": rec["seconds"]}, as_json=args.json)
    return 0


def run(args) -> int:
    # lfproc.recon loads scipy.linalg: imported when the command runs, so `lfproc --help` starts fast
    from lfproc.recon import DEFAULTS, PAPER, gmm_fits, reconstruct, reconstruct_per_shot

    capture, method = None, args.method
    if method == "auto":
        gmm_given = any(v is not None for v in (args.model, args.disparities, args.scales, args.search))
        if gmm_given or not _dictionary_options(args):
            capture = load_capture(args.capture)
            method = "gmm" if gmm_fits(capture) or gmm_given else "dictionary"
        else:
            method = "dictionary"
    if method == "gmm":
        return _run_gmm(args, capture)
    given = [o for o, v in (("--model", args.model), ("--disparities", args.disparities), ("--scales", args.scales),
                            ("--search", args.search)) if v is not None]
    if given:
        raise InputError(f"{', '.join(given)}: options of --method gmm, not of --method dictionary")

    check_output(args.output, force=args.force)
    capture = load_capture(args.capture) if capture is None else capture
    dictionary = load_dictionary(args.dictionary)

    base = PAPER if args.paper else DEFAULTS  # options given explicitly win
    # tol and max_iter: the paper's numbers, or None for the library's per-solver defaults
    options = {"mu": base["mu"], "tol": PAPER["tol"] if args.paper else None,
               "max_iter": PAPER["max_iter"] if args.paper else None}
    options.update({k: v for k, v in (("mu", args.mu), ("tol", args.tol), ("max_iter", args.max_iter)) if v is not None})
    options.update({k: getattr(args, k) or base[k] for k in ("scale", "overlap", "variance")})
    options.update(solver=args.solver, stride=4 if args.stride is None else args.stride, n_nonzero_coefs=args.sparsity,
                   workers=args.workers, scheduler=args.scheduler, threads=args.threads)
    if args.per_shot is not None:
        lf = reconstruct_per_shot(capture, dictionary, merges=[args.per_shot], **options)[args.per_shot]
    else:
        lf = reconstruct(capture, dictionary, **options)
    lf = lf.replace(source=str(args.capture))
    write_lightfield(lf, args.output, force=args.force)
    rec = lf.attrs["reconstruction"]
    summary = {
        "output": str(args.output),
        "capture": str(args.capture),
        "method": "dictionary",
        "dictionary": dictionary.name or dictionary.preset,
        "solver": rec["solver"],
        "patches": rec["patches"],
        "operators": rec["operators"],
        "stride": rec["stride"],
        "mu": rec["mu"],
        "scale": rec["scale"],
        "overlap": rec["overlap"],
        "tol": rec["tol"],
        "max_iter": rec["max_iter"],
        "iterations_mean": rec["iterations_mean"],
        "empty_patches": rec["empty_patches"],
        "units": lf.units,
        "shape": list(lf.shape),
        "seconds": rec["seconds"],
    }
    emit(summary, as_json=args.json)
    return 0
