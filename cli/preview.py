"""``lfproc preview LF -o OUT.png --kind centre|sheet|epi|histogram``: look at a light field.

``--exposure-from REFERENCE`` tone-maps with the reference's curve (log-average and white
point), so a result and its truth previewed with the same reference share one exposure.
"""

from __future__ import annotations

from pathlib import Path

from ._common import add_json, add_value_policies, add_output, emit
from lfproc.camera.capture import is_capture_file
from lfproc.dictionary import is_dictionary_file, load_dictionary
from lfproc.errors import InputError
from lfproc.io import read_lightfield
from lfproc.io._atomic import check_output
from lfproc.lightfield import LightField
from lfproc.preview import preview_kinds, PREVIEWS, write_capture_preview, write_preview
import lfproc.camera.capture


def register(sub, common) -> None:
    kinds = preview_kinds(LightField)
    listing = "; ".join(f"{k}: {PREVIEWS[k].description}" for k in PREVIEWS)
    p = sub.add_parser(
        "preview", parents=[common], help="write a tone-mapped preview, contact sheet, EPI or histogram",
        description="Tone mapping: Reinhard et al. 2002 global operator (key 0.18, white at the 99.9th "
                    f"percentile), colour ratios kept, sRGB. Kinds: {listing}.")
    p.add_argument("input", type=Path, help="light-field file or folder, an image, a coded capture, or a dictionary (file or default)")
    add_output(p, help="output image (.png, .jpg or .tif)")
    p.add_argument("--kind", default=None,
                   help=f"light fields: {', '.join(kinds)} (default centre); coded captures: "
                        f"{', '.join(preview_kinds(lfproc.camera.capture.Capture))} (default capture); dictionaries: atoms")
    p.add_argument("--exposure", type=float, default=None, metavar="EV",
                   help="extra exposure in stops (light fields; default 0)")
    p.add_argument("--exposure-from", type=Path, default=None, metavar="REFERENCE",
                   help="light field whose tone curve (log-average, white point) is used instead of the input's: "
                        "preview a result and its truth with the same REFERENCE to compare them at one exposure "
                        "(histograms share its range of stops)")
    add_value_policies(p)
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    if args.kind is not None and args.kind not in PREVIEWS:  # before reading a large input
        raise InputError(f"--kind: expected one of {', '.join(PREVIEWS)}; got {args.kind!r}")
    check_output(args.output, force=args.force)

    def _no_exposure_from(what: str) -> None:
        for option, value in (("--exposure-from", args.exposure_from), ("--exposure", args.exposure)):
            if value is not None:
                raise InputError(f"{option}: applies to light-field previews; {args.input} is {what}")

    if is_dictionary_file(args.input):
        _no_exposure_from("a dictionary")
        d = load_dictionary(str(args.input))
        kind = args.kind or "atoms"
        path = write_preview(d, args.output, kind=kind, force=args.force)
        emit({"output": str(path), "kind": kind, "atoms": d.n_atoms, "patch": list(d.patch)}, as_json=args.json)
        return 0
    if is_capture_file(args.input):
        _no_exposure_from("a coded capture")
        summary = write_capture_preview(args.input, args.output, kind=args.kind or "capture", force=args.force)
        emit(summary, as_json=args.json)
        return 0
    if args.exposure_from is not None and not args.exposure_from.exists():
        raise InputError(f"--exposure-from {args.exposure_from}: no such file or folder")
    lf = read_lightfield(args.input, nonfinite=args.nonfinite, negative=args.negative)
    options = {"exposure_ev": 0.0 if args.exposure is None else args.exposure}
    if args.exposure_from is not None:
        options["exposure_from"] = read_lightfield(args.exposure_from, nonfinite=args.nonfinite,
                                                   negative=args.negative)
    kind = args.kind or "centre"
    path = write_preview(lf, args.output, kind=kind, force=args.force, **options)
    from PIL import Image

    with Image.open(path) as im:
        width, height = im.size
    emit({"output": str(path), "kind": kind, "size": [height, width], "views": list(lf.views),
          "dynamic_range_stops": lf.dynamic_range_stops(),
          "exposure_from": None if args.exposure_from is None else str(args.exposure_from)}, as_json=args.json)
    return 0
