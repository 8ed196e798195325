"""``lfproc merge INPUT... -o OUT.exr``: merge an exposure bracket into one HDR light field."""

from __future__ import annotations

from pathlib import Path

from ._common import add_json, add_value_policies, add_output, emit, parse_floats
from lfproc.errors import InputError
from lfproc.dataset import read_exposure_file
from lfproc.hdr import merge_files
from lfproc.hdr._bracket import format_response, plot_response, unused_options, RESPONSE_SUFFIXES
from lfproc.io import write_lightfield
from lfproc.io._atomic import atomic_outputs, check_output
from lfproc.lightfield import LightField


def register(sub, common) -> None:
    p = sub.add_parser(
        "merge", parents=[common], help="merge an exposure bracket into an HDR light field",
        description="Merge INPUTs (Lytro captures, lfproc light-field EXRs or view folders, camera raws, 8/16-bit "
                    "JPEG/PNG/TIFF with EXIF) taken with different exposures into one HDR light field (1x1 views "
                    "for 2-D images). ml: noise-aware inverse-variance estimator, writes the variance (raw or "
                    "linear data: needs a camera profile and ISOs; 8-bit images: recovered camera response, "
                    "noise measured on the bracket, no profile or ISO); debevec: Debevec & Malik hat weights in "
                    "the log domain, with camera-response recovery for 8-bit images. Default: "
                    "debevec for 8-bit images or without a profile, ml otherwise. Pixels saturated in every "
                    "exposure get the shortest exposure's saturation value and are counted.")
    p.add_argument("inputs", nargs="+", type=Path, metavar="INPUT", help="the bracket, one file per exposure")
    add_output(p, help="output light field (.exr)")
    p.add_argument("--method", choices=("ml", "debevec"), default=None, help="merging estimator")
    p.add_argument("--profile", default=None, help="camera profile name or JSON file (raw or linear data; refused for 8-bit images, "
                                                         "whose response and noise come from the bracket)")
    p.add_argument("--exposures-s", default=None, help="comma-separated exposure times in seconds, one per input "
                                                         "(overrides the metadata)")
    p.add_argument("--exposures-file", type=Path, default=None, metavar="LIST",
                   help="exposure list file (overrides the metadata): 'NAME SECONDS' lines (seconds as 0.125 or "
                        "1/8), 'SECONDS' lines in the inputs' order, JSON, or Debevec's HDRShop list "
                        "('NAME 1/t F_STOP ...' lines, as memorial.hdr_image_list.txt: recognised by its 3-5 "
                        "fields or a '1/shutter_speed' comment; the second field is 1/t)")
    p.add_argument("--isos", default=None, help="comma-separated ISO values (one, or one per input)")
    p.add_argument("--white-db", type=Path, default=None, help="white-image database for Lytro captures")
    p.add_argument("--iterations", type=int, default=None,
                   help="ml: weight updates after the start (read-noise weights; 8-bit images: hat-weighted mean); "
                        "default 2")
    p.add_argument("--seed", type=int, default=None,
                   help="8-bit images: seed of the response-recovery pixel sampling (default 0)")
    p.add_argument("--response-out", type=Path, default=None, metavar="FILE",
                   help="also write the camera response the merge recovered from 8-bit images, f^-1(z) and "
                        "g(z) = ln f^-1(z) per code and channel (FILE.csv or FILE.json), and its plot FILE.png")
    p.add_argument("--mask", type=Path, default=None,
                   help="also write the saturated-everywhere mask as a 1-channel light field (.exr)")
    add_value_policies(p, what="light-field (EXR) input")
    add_json(p)
    p.set_defaults(run=run)


#: the CLI options of merge_files' parameters, for its messages
_OPTION_NAMES = {"profile": "--profile", "exposures_s": "--exposures-s", "isos": "--isos", "white_db": "--white-db",
                 "max_iter": "--iterations", "method": "--method", "random_state": "--seed"}


def run(args) -> int:
    import numpy as np

    if args.output.suffix.lower() != ".exr":
        raise InputError(f"{args.output}: expected an output path ending in .exr")
    check_output(args.output, force=args.force)
    if args.mask is not None:
        check_output(args.mask, force=args.force)
    response_plot = None
    if args.response_out is not None:
        if args.response_out.suffix.lower() not in RESPONSE_SUFFIXES:
            raise InputError(f"--response-out {args.response_out}: expected a file ending in "
                             f"{' or '.join(RESPONSE_SUFFIXES)}, got {args.response_out.suffix or 'no suffix'}")
        response_plot = args.response_out.with_suffix(".png")
        check_output(args.response_out, force=args.force)
        check_output(response_plot, force=args.force)
    if args.exposures_s and args.exposures_file is not None:
        raise InputError("--exposures-s and --exposures-file: expected one source of exposure times, got both")
    if args.iterations is not None and args.method == "debevec":
        raise InputError("--iterations: has no effect with --method debevec (ml weight updates); drop it")
    if args.iterations is not None and args.method is None and all(
            p.suffix.lower() in (".jpg", ".jpeg") for p in args.inputs):  # JPEGs are 8-bit: known before reading
        raise InputError("--iterations: has no effect with method debevec, the default for 8-bit images (it does "
                         "not iterate; ml weight updates only); drop it or give --method ml")
    # options whose effect depends on the inputs and the method chosen for them: refused after the merge
    # (before anything is written) when it ignored them (e.g. --iterations on 8-bit images: default debevec)
    given = [name for name, value in (("max_iter", args.iterations), ("random_state", args.seed),
                                      ("isos", args.isos), ("profile", args.profile)) if value is not None]
    if args.iterations is not None and args.iterations < 0:
        raise InputError(f"--iterations: expected a non-negative integer, got {args.iterations}")
    exposures = parse_floats(args.exposures_s, option="--exposures-s") if args.exposures_s else None
    if args.exposures_file is not None:
        exposures = read_exposure_file(args.exposures_file, args.inputs, bare_order="inputs")
    isos = parse_floats(args.isos, option="--isos") if args.isos else None
    merged, info = merge_files(args.inputs, method=args.method, profile=args.profile, exposures_s=exposures,
                               isos=isos, white_db=args.white_db,
                               max_iter=2 if args.iterations is None else args.iterations,
                               random_state=0 if args.seed is None else args.seed, option_names=_OPTION_NAMES,
                               nonfinite=args.nonfinite, negative=args.negative)
    for name, why in unused_options(given, method=info["method"], mapping=merged.attrs["input_mapping"])[:1]:
        raise InputError(f"{_OPTION_NAMES[name]}: has no effect {why}; drop it")
    response_text = None
    if args.response_out is not None:
        if info.get("response") is None:
            raise InputError(f"--response-out: no camera response was recovered: the inputs are linear data "
                             f"({merged.attrs['input_mapping']}), not 8-bit images; drop it")
        response_text = format_response(info["response"], suffix=args.response_out.suffix, metadata={
            "method": info["method"],
            "response_kind": info.get("response_kind"),
            "normalisation": "g(128) = 0",
            "exposures_s": merged.attrs["exposures_s"],
            "sources": merged.attrs["sources"],
            "merged": str(args.output),
            "lfproc_version": merged.attrs["lfproc_version"],
        }, where=f"--response-out {args.response_out}")
    outputs = [args.output]
    if args.mask is not None:
        outputs.append(args.mask)
    if response_text is not None:
        outputs += [args.response_out, response_plot]
    with atomic_outputs(outputs, force=args.force) as staged:  # every output or none
        write_lightfield(merged, staged[0])
        if args.mask is not None:
            mask = np.asarray(info["saturated_everywhere"], dtype=np.float32)
            if mask.ndim == 5:
                mask = mask.max(axis=-1, keepdims=True)
            write_lightfield(LightField(data=mask, source=f"saturated-everywhere mask of {args.output}"), staged[1])
        if response_text is not None:
            staged[-2].write_text(response_text, encoding="utf-8")
            plot_response(staged[-1], info["response"], title=f"camera response recovered by lfproc merge "
                                                                f"({info['method']})")
    v, u = merged.views
    h, w = merged.size
    result = {
        "output": str(args.output),
        "method": info["method"],
        "views": [v, u],
        "size": [h, w],
        "exposures_s": merged.attrs["exposures_s"],
        "units": merged.units,
        "dynamic_range_stops": round(float(info["dynamic_range_stops"]), 3),
        "saturated_everywhere_count": info["saturated_everywhere_count"],
        "saturated_everywhere_fraction": info["saturated_everywhere_fraction"],
        "dark_everywhere_count": info["dark_everywhere_count"],
        "negative_clipped": info["negative_clipped"],
        "has_variance": merged.variance is not None,
    }
    if args.mask is not None:
        result["mask"] = str(args.mask)
    if response_text is not None:
        result["response"] = str(args.response_out)
        result["response_plot"] = str(response_plot)
    emit(result, as_json=args.json)
    return 0
