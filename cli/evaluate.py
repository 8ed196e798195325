"""``lfproc evaluate RESULT REFERENCE``: HDR quality metrics of a result against a reference.

Prints view-averaged PU21-PSNR, PU21-SSIM, PU2-PSNR, log-PSNR and mean relative error,
then one row per view. ``--json`` prints one object (see :func:`lfproc.metrics.evaluate`);
an infinite PSNR (identical views) is written as the string ``"inf"``.
"""

from __future__ import annotations

import math
from pathlib import Path

from lfproc.io import read_lightfield
from lfproc.metrics import evaluate

from ._common import add_json, emit

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
                    "and averaged over views. --align says how RESULT is brought to the reference's scale.")
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
    p.add_argument("--nonfinite", choices=("raise", "zero", "clip"), default="raise",
                   help="what to do with NaN/Inf samples in the inputs (default: refuse)")
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


def run(args) -> int:
    result = read_lightfield(args.result, nonfinite=args.nonfinite)
    reference = read_lightfield(args.reference, nonfinite=args.nonfinite)
    figures = evaluate(result, reference, peak_luminance=args.peak_luminance,
                       scale_tolerance_stops=args.scale_tolerance_stops, align=args.align)
    figures = {"result": str(args.result), "reference": str(args.reference)} | figures
    if args.json:
        emit(figures, as_json=True)
    else:
        print(format_table(figures))
    return 0
