"""``lfproc evaluate RESULT REFERENCE``: HDR quality metrics of a result against a reference.

Prints view-averaged PU21-PSNR, PU21-SSIM, PU2-PSNR, log-PSNR and mean relative error,
then one row per view, then the figures of :func:`lfproc.metrics.hdr_figures`: the median
error in stops per decade of the reference luminance, the share of samples returned as 0 (or
20 stops under),
the energy kept in the brightest 1 %, the PU21 detail ratio, and one line when a few
emitters dominate PU21. ``--json`` prints one object (see :func:`lfproc.metrics.evaluate`);
an infinite PSNR (identical views) is written as the string ``"inf"``.
``--error-map MAP.png`` writes the centre view's error in stops with a colour bar;
``--mask FILE`` and ``--exclude-above VALUE`` restrict every figure.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from lfproc.errors import FileFormatError, InputError, ShapeError
from lfproc.io import read_lightfield
from lfproc.metrics import evaluate, evaluation_mask, metric_luminance

from ._common import add_json, add_value_policies, emit
from lfproc._untrusted import read_npy
from lfproc.camera.capture import load_capture, noise_floor
from lfproc.io._atomic import check_output
from lfproc.io.images import imread
from lfproc.preview import PREVIEW_SUFFIXES, write_error_map

MASK_SUFFIXES = (".png", ".npy")

_COLUMNS = (
    ("pu21_psnr_db", "PU21-PSNR dB", "{:.2f}"),
    ("pu21_ssim", "PU21-SSIM", "{:.4f}"),
    ("pu2_psnr_db", "PU2-PSNR dB", "{:.2f}"),
    ("log_psnr_db", "log-PSNR dB", "{:.2f}"),
    ("linear_psnr_db", "lin-PSNR dB", "{:.2f}"),
    ("mean_relative_error", "rel. error", "{:.4g}"),
)


def register(sub, common) -> None:
    p = sub.add_parser(
        "evaluate", parents=[common], help="compare a result light field or image with a reference (PU21, PU2...)",
        description="Compare RESULT with REFERENCE (each an lfproc EXR, a folder of view_RR_CC files or a single "
                    "image; same views, size and units). Luminance of both is scaled by one factor so that the "
                    "reference peak is --peak-luminance cd/m^2, then PU21-PSNR (peak 256), PU21-SSIM (data range "
                    "256), PU2-PSNR (peak PU2 of the display peak), log-PSNR, a linear PSNR (peak: the reference's "
                    "99.9th percentile) and the mean relative error of the linear values are computed per view "
                    "and averaged over views. --align says how RESULT is brought to the reference's scale. "
                    "Then the figures PU21 hides: the median error in stops per decade of the reference "
                    "luminance, the share of samples returned as 0 (or 20 stops under), the energy kept by the "
                    "brightest 1 %, the detail ratio (Laplacian energy of the PU21 error over the reference's), "
                    "and a line when a few emitters dominate PU21. --mask and --exclude-above restrict every figure.")
    p.add_argument("result", type=Path, help="light field or image to judge")
    p.add_argument("reference", type=Path, help="ground-truth light field or image")
    p.add_argument("--peak-luminance", type=float, default=1000.0, metavar="CD_M2",
                   help="display peak in cd/m^2 that the reference maximum maps to (default 1000)")
    p.add_argument("--scale-tolerance-stops", type=float, default=4.0, metavar="STOPS",
                   help="refuse inputs whose mean values differ by more stops than this (default 4)")
    p.add_argument("--align", choices=("none", "exposure", "gain"), default="none",
                   help="bring RESULT to the reference's scale first: none (refuse different units or exposures; "
                        "default), exposure (multiply by the exposure ratio, e.g. a merge per second against a "
                        "decode), gain (one gain fitted on the data, reported)")
    add_value_policies(p)
    p.add_argument("--mask", type=Path, default=None, metavar="FILE",
                   help="score only these samples: a PNG (white = scored; H x W, applied to every view) or a "
                        ".npy of booleans or 0/1, shape H x W or V x U x H x W")
    p.add_argument("--exclude-above", type=float, default=None, metavar="VALUE",
                   help="leave out samples whose reference luminance is above VALUE (the data's units), e.g. "
                        "emitters; restricts every figure")
    p.add_argument("--noise-floor", type=float, default=None, metavar="VALUE",
                   help="reference luminance at or below which samples are left out of the error in stops and "
                        "the zeros, and reported on a line of their own (default: every sample with a positive "
                        "reference)")
    p.add_argument("--noise-floor-from", type=Path, default=None, metavar="CAPTURE",
                   help="take --noise-floor from the capture the result was reconstructed from: the radiance at "
                        "which one measurement at its highest ISO has as much signal as read noise (at least one "
                        "electron)")
    p.add_argument("--error-map", type=Path, default=None, metavar="MAP.png",
                   help="write the centre view's error in stops (log2 result/reference luminance) with a "
                        "diverging colour map and a colour bar")
    p.add_argument("--force", action="store_true", help="overwrite an existing --error-map file")
    add_json(p)
    p.set_defaults(run=run)


def _cell(fmt: str, value: float) -> str:
    return "inf" if isinstance(value, float) and math.isinf(value) else fmt.format(value)


def format_table(figures: dict) -> str:
    """A short readable table: averages, then one row per view."""
    nv, nu = figures["angular_shape"]
    h, w = figures["size"]
    lines = [f"{nv}x{nu} views of {h}x{w}, reference peak -> {figures['peak_luminance_cd_m2']:g} cd/m^2 "
             f"(x{figures['scale_factor']:.4g}), PU21 {figures['pu21_variant']}, "
             f"align {figures['align']} (result x{figures['gain']:.6g})"]
    header = ["view    "] + [f"{title:>13}" for _, title, _ in _COLUMNS]
    lines.append("".join(header))
    rows = [("mean", figures)]
    if nv * nu > 1:
        rows += [(f"{r['v']:>2},{r['u']:<2}", r) for r in figures["views"]]
    for label, row in rows:
        lines.append(f"{label:<8}" + "".join(f"{_cell(fmt, row[key]):>13}" for key, _, fmt in _COLUMNS))
    return "\n".join(lines)


def _decade(lo: float) -> str:
    k = round(math.log10(lo))
    return f"1e{k:+03d} .. 1e{k + 1:+03d}"


def format_hdr_table(figures: dict) -> str:
    """The figures of :func:`lfproc.metrics.hdr_figures`: error in stops by decade, zeros,
    highlight energy, detail, and a line when a few emitters dominate PU21."""
    floor = figures["noise_floor"]
    lines = [f"error by decade of the reference luminance ({figures['samples_above_floor']} of {figures['samples']} "
             f"samples above the noise floor {floor:g})",
             f"{'decade':<18}{'samples':>10}{'median |stops|':>16}"]
    for d in figures["stops_by_decade"]:
        lines.append(f"{_decade(d['decade'][0]):<18}{d['samples']:>10}{_cell('{:.3f}', d['median_stops']):>16}")
    below = figures["stops_below_floor"]
    if below:  # left out of the worst decade, but a user sees them
        lines.append("below the noise floor (not resolved by one measurement; not in the worst decade): "
                     + ", ".join(f"{_decade(d['decade'][0])} {_cell('{:.3f}', d['median_stops'])} stops "
                                 f"({d['samples']} samples)" for d in below))
    zeros = figures["zeros_above_floor"]
    lines.append(f"worst decade: {_cell('{:.3f}', figures['max_decade_stops'])} stops; returned as 0 (or 20 "
                 f"stops under) above the floor: {'n/a' if math.isnan(zeros) else f'{100 * zeros:.3g} %'}")
    lines.append(f"brightest 1 % keep {100 * figures['highlight_energy']:.1f} % of their energy; detail ratio "
                 f"{figures['detail_ratio']:.3f} (PU21 Laplacian energy of the error / of the reference: 0 all "
                 "detail, 1 none), away from the brightest 1 % "
                 f"{_cell('{:.3f}', figures['detail_ratio_off_highlights'])} (they hold "
                 f"{_cell('{:.0f}', 100 * figures['highlight_detail_share'])} % of the reference's detail)")
    if figures["emitters_dominate"]:
        lines.append(f"PU21 is dominated by a few emitters: the brightest 0.1 % of the reference hold "
                     f"{100 * figures['emitter_share']:.0f} % of its squared error (score without them: "
                     f"--exclude-above {0.99 * figures['emitter_luminance']:.3g})")
    return "\n".join(lines)


def read_mask(path: Path) -> np.ndarray:
    """A boolean mask from a PNG (grey level >= half its range = scored) or a ``.npy``
    (booleans, or integers 0/1), with errors naming ``--mask``."""
    suffix = path.suffix.lower()
    if suffix not in MASK_SUFFIXES:
        raise InputError(f"--mask {path}: expected a .png or .npy file, found {suffix or 'no suffix'!r}")
    if not path.is_file():
        raise InputError(f"--mask {path}: no such file")
    if suffix == ".npy":
        with open(path, "rb") as fh:
            arr = read_npy(fh, path.stat().st_size, source=f"--mask {path}", what="mask")
        if arr.dtype != bool:
            if not np.issubdtype(arr.dtype, np.integer) or not np.isin(arr, (0, 1)).all():
                raise FileFormatError(f"--mask {path}: expected booleans or integers 0/1, found {arr.dtype}"
                                      + ("" if not np.issubdtype(arr.dtype, np.integer) else " with other values"))
            arr = arr.astype(bool)
        if arr.ndim not in (2, 4):
            raise ShapeError(f"--mask {path}: expected shape H x W or V x U x H x W, found {arr.shape}")
        return arr
    import cv2

    raw = imread(path, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH, what="mask image")
    top = np.iinfo(raw.dtype).max if np.issubdtype(raw.dtype, np.integer) else 1.0
    return raw >= top / 2


def _check_mask_shape(mask: np.ndarray, path: Path, reference) -> None:
    nv, nu, h, w, _ = reference.shape
    if mask.shape not in ((h, w), (nv, nu, h, w)):
        found = " x ".join(str(n) for n in mask.shape)
        raise ShapeError(f"--mask {path}: expected {h} x {w} (or {nv} x {nu} x {h} x {w}) like the reference, "
                         f"found {found}")


def run(args) -> int:
    if args.force and args.error_map is None:
        raise InputError("--force: has no effect without --error-map (the only file evaluate writes); drop it")
    if args.error_map is not None:  # before reading anything large

        if args.error_map.suffix.lower() not in PREVIEW_SUFFIXES:
            raise InputError(f"--error-map {args.error_map}: expected a file ending in {', '.join(PREVIEW_SUFFIXES)}")
        check_output(args.error_map, force=args.force)
    for option, value in (("--exclude-above", args.exclude_above), ("--noise-floor", args.noise_floor)):
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise InputError(f"{option}: expected a finite luminance >= 0, got {value:g}")
    floor = args.noise_floor
    if args.noise_floor_from is not None:
        if args.noise_floor is not None:
            raise InputError("--noise-floor and --noise-floor-from: give one of them")

        floor = noise_floor(load_capture(args.noise_floor_from))
    mask = None if args.mask is None else read_mask(args.mask)
    result = read_lightfield(args.result, nonfinite=args.nonfinite, negative=args.negative)
    reference = read_lightfield(args.reference, nonfinite=args.nonfinite, negative=args.negative)
    if mask is not None:
        _check_mask_shape(mask, args.mask, reference)
    if args.exclude_above is not None:
        if not (metric_luminance(reference.data) <= args.exclude_above).any():
            raise InputError(f"--exclude-above {args.exclude_above:g}: every reference sample is brighter; expected "
                             "a value that keeps some (the reference's luminance starts at "
                             f"{float(metric_luminance(reference.data).min()):.4g})")
    figures = evaluate(result, reference, peak_luminance=args.peak_luminance,
                       scale_tolerance_stops=args.scale_tolerance_stops, align=args.align, mask=mask,
                       exclude_above=args.exclude_above, noise_floor=floor)
    figures = {"result": str(args.result), "reference": str(args.reference),
               "mask": None if args.mask is None else str(args.mask)} | figures
    if args.error_map is not None:
        aligned = result if figures["gain"] == 1.0 else result.replace(data=result.data * np.float32(figures["gain"]))
        keep = evaluation_mask(reference, mask=mask, exclude_above=args.exclude_above)
        write_error_map(aligned, reference, args.error_map, force=args.force, mask=keep)
        figures["error_map"] = str(args.error_map)
    if args.json:
        emit(figures, as_json=True)
    else:
        print(format_table(figures))
        print(format_hdr_table(figures))
        if args.error_map is not None:
            print(f"error map: {args.error_map}")
    return 0
