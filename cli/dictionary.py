"""``lfproc dictionary train|info|eval``: learned HDR light-field dictionaries."""

from __future__ import annotations

import shutil
from pathlib import Path

from ._common import add_json, add_value_policies, add_output, emit, parse_ints
from lfproc.dictionary import (
    evaluate_dictionary, get_preset, load_dictionary, PRESETS, save_dictionary, SHIPPED, train_dictionary,
)
from lfproc.dictionary._files import shipped_path
from lfproc.dictionary._patches import collect_lightfields
from lfproc.errors import InputError
from lfproc.io import read_lightfield
from lfproc.io._atomic import check_output


def register(sub, common) -> None:
    presets = "; ".join(f"{k}: patch {'x'.join(map(str, p.patch))}, {p.atoms} atoms, sparsity {p.sparsity}, "
                        f"{p.iterations} iterations, {p.patches} patches" for k, p in PRESETS.items())
    p = sub.add_parser("dictionary", parents=[common], help="train, describe and evaluate HDR light-field dictionaries",
                       description="Dictionaries of 4-D light-field patches for the reconstruction (K-SVD with "
                                   f"Batch-OMP). Presets: {presets}.")
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)

    t = actions.add_parser("train", parents=[common], help="learn a dictionary with K-SVD",
                           description="Learn a dictionary from HDR light fields (files, view folders, data sets "
                                       "built by 'lfproc dataset build') and/or lfproc's synthetic scenes. A killed "
                                       "run resumes from its checkpoint folder (default OUTPUT.ckpt) when re-run.")
    t.add_argument("inputs", nargs="*", type=Path, metavar="LF", help="training light fields, folders or data sets")
    add_output(t, help="output dictionary (.npz)")
    t.add_argument("--preset", default="default", help=f"sizes: {', '.join(PRESETS)} (default: default)")
    t.add_argument("--synthetic", action="store_true", help="add the preset's procedural training scenes")
    t.add_argument("--patch", default=None, metavar="V,U,P,P,C", help="patch shape (overrides the preset)")
    t.add_argument("--atoms", type=int, default=None, help="number of atoms K (overrides the preset)")
    t.add_argument("--sparsity", type=int, default=None, help="atoms per patch (overrides the preset)")
    t.add_argument("--iterations", type=int, default=None, help="K-SVD iterations (overrides the preset)")
    t.add_argument("--patches", type=int, default=None, help="training patches (overrides the preset)")
    t.add_argument("--normalise", choices=("l2", "none"), default="l2", help="patch normalisation (default l2)")
    t.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    t.add_argument("--dtype", choices=("float16", "float32"), default="float16", help="storage of the atoms")
    t.add_argument("--checkpoint", type=Path, default=None, metavar="DIR",
                   help="checkpoint folder (default: OUTPUT.ckpt, removed when training ends)")
    t.add_argument("--scheduler", default=None, metavar="ADDRESS", help="Dask scheduler for the sparse coding")
    add_value_policies(t, what="training light-field")
    add_json(t)
    t.set_defaults(run=run_train)

    i = actions.add_parser("info", parents=[common], help="describe a dictionary",
                           description="Print a dictionary's size, patch shape, sparsity and provenance.")
    i.add_argument("dictionary", help="dictionary file, or 'default' (the shipped one)")
    add_json(i)
    i.set_defaults(run=run_info)

    e = actions.add_parser("eval", parents=[common], help="sparse-approximation quality on light fields",
                           description="Approximate every patch of the light fields with the dictionary's sparsity "
                                       "(Batch-OMP, overlapping patches averaged) and score relative error and "
                                       "PU21-PSNR, beside a separable 4-D DCT dictionary of the same size.")
    e.add_argument("dictionary", help="dictionary file, or 'default'")
    e.add_argument("inputs", nargs="+", type=Path, metavar="LF", help="light fields to approximate")
    e.add_argument("--sparsity", type=int, default=None, help="atoms per patch (default: the dictionary's)")
    e.add_argument("--stride", type=int, default=None, help="patch grid step in pixels (default: half the patch)")
    e.add_argument("--no-dct", action="store_true", help="skip the DCT comparison")
    e.add_argument("--peak-luminance", type=float, default=1000.0, help="display peak for PU21 (cd/m2)")
    add_value_policies(e)
    add_json(e)
    e.set_defaults(run=run_eval)


def _command(args) -> str:
    parts = ["lfproc", "dictionary", "train", *map(str, args.inputs)]
    if args.synthetic:
        parts.append("--synthetic")
    parts += ["--preset", args.preset]
    for opt in ("patch", "atoms", "sparsity", "iterations", "patches"):
        value = getattr(args, opt)
        if value is not None:
            parts += [f"--{opt}", str(value)]
    if args.normalise != "l2":
        parts += ["--normalise", args.normalise]
    parts += ["--seed", str(args.seed)]
    if args.dtype != "float16":
        parts += ["--dtype", args.dtype]
    return " ".join(parts)  # without -o, so the file does not depend on where it was written


def run_train(args) -> int:
    import time

    get_preset(args.preset)
    patch = None
    if args.patch is not None:
        patch = parse_ints(args.patch, option="--patch")
        if len(patch) != 5:
            raise InputError(f"--patch: expected 5 integers V,U,P,P,C, got {args.patch!r}")
    for opt in ("atoms", "sparsity", "iterations", "patches"):
        value = getattr(args, opt)
        if value is not None and value < (0 if opt == "iterations" else 1):
            raise InputError(f"--{opt}: expected a positive number, got {value}")
    if not args.inputs and not args.synthetic:
        raise InputError("no training data: give light fields (LF ...) and/or --synthetic")
    check_output(args.output, force=args.force)
    files = collect_lightfields(args.inputs)
    lfs = [read_lightfield(f, nonfinite=args.nonfinite, negative=args.negative) for f in files]
    checkpoint = args.checkpoint or args.output.with_name(args.output.name + ".ckpt")
    start = time.perf_counter()
    d = train_dictionary(lfs, preset=args.preset, synthetic=args.synthetic, patch=patch, atoms=args.atoms,
                         n_nonzero_coefs=args.sparsity, max_iter=args.iterations, patches=args.patches,
                         normalise=args.normalise, random_state=args.seed, checkpoint=checkpoint, scheduler=args.scheduler,
                         command=_command(args),
                         sources=[f"{f} ({lf.source})" if lf.source else str(f) for f, lf in zip(files, lfs)])
    save_dictionary(d, args.output, dtype=args.dtype, force=args.force)
    if args.checkpoint is None:
        shutil.rmtree(checkpoint, ignore_errors=True)
    info = d.describe()
    info.update(output=str(args.output), seconds=round(time.perf_counter() - start, 1),
                bytes=args.output.stat().st_size)
    info.pop("name", None)
    emit(info, as_json=args.json)
    return 0


def run_info(args) -> int:
    d = load_dictionary(args.dictionary)
    info = d.describe()
    path = Path(d.name) if d.name not in ("default",) else None

    if d.name in SHIPPED:
        path = shipped_path(d.name)
    if path is not None and path.is_file():
        info["bytes"] = path.stat().st_size
        info["path"] = str(path)
    emit(info, as_json=args.json)
    return 0


def run_eval(args) -> int:
    d = load_dictionary(args.dictionary)
    if args.sparsity is not None and not 1 <= args.sparsity <= min(d.n, d.n_atoms):
        raise InputError(f"--sparsity: expected 1..{min(d.n, d.n_atoms)}, got {args.sparsity}")
    if args.stride is not None and not 1 <= args.stride <= d.patch_px:
        raise InputError(f"--stride: expected 1..{d.patch_px} (the patch size), got {args.stride}")
    if not args.peak_luminance > 0:
        raise InputError(f"--peak-luminance: expected a positive number, got {args.peak_luminance}")
    lfs = [read_lightfield(f, nonfinite=args.nonfinite, negative=args.negative)
           for f in collect_lightfields(args.inputs)]
    result = evaluate_dictionary(d, lfs, n_nonzero_coefs=args.sparsity, stride=args.stride, compare_dct=not args.no_dct,
                                 peak_luminance=args.peak_luminance)
    if not args.json:
        result = {k: v for k, v in result.items() if k != "lightfields"}
    emit(result, as_json=args.json)
    return 0
