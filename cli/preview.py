"""``lfproc preview LF -o OUT.png --kind centre|sheet|epi|histogram``: look at a light field."""

from __future__ import annotations

from pathlib import Path

from ._common import add_json, add_output, emit


def register(sub, common) -> None:
    from lfproc.lightfield import LightField
    from lfproc.preview import PREVIEWS, preview_kinds

    kinds = preview_kinds(LightField)
    listing = "; ".join(f"{k}: {PREVIEWS[k].description}" for k in kinds)
    p = sub.add_parser(
        "preview", parents=[common], help="write a tone-mapped preview, contact sheet, EPI or histogram",
        description="Tone mapping: Reinhard et al. 2002 global operator (key 0.18, white at the 99.9th "
                    f"percentile), colour ratios kept, sRGB. Kinds: {listing}.")
    p.add_argument("input", type=Path, help="light-field file or folder, or an image")
    add_output(p, help="output image (.png, .jpg or .tif)")
    p.add_argument("--kind", default="centre", help=f"one of {', '.join(kinds)} (default: centre)")
    p.add_argument("--exposure", type=float, default=0.0, metavar="EV", help="extra exposure in stops")
    p.add_argument("--nonfinite", choices=("raise", "zero", "clip"), default="raise",
                   help="what to do with NaN/Inf samples (default: refuse the file)")
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    from lfproc.io import check_output, read_lightfield
    from lfproc.capture import is_capture_file, write_capture_preview
    from lfproc.preview import PREVIEWS, write_preview

    if is_capture_file(args.input):  # coded captures: sensor image, ISO map, mask
        emit(write_capture_preview(args.input, args.output, kind=args.kind, force=args.force), as_json=args.json)
        return 0
    if args.kind not in PREVIEWS:  # before reading a large input
        from lfproc.errors import InputError

        raise InputError(f"--kind: expected one of {', '.join(PREVIEWS)}; got {args.kind!r}")
    check_output(args.output, force=args.force)
    lf = read_lightfield(args.input, nonfinite=args.nonfinite)
    path = write_preview(lf, args.output, kind=args.kind, force=args.force, exposure_ev=args.exposure)
    from PIL import Image

    with Image.open(path) as im:
        width, height = im.size
    emit({"output": str(path), "kind": args.kind, "size": [height, width], "views": list(lf.views),
          "dynamic_range_stops": lf.dynamic_range_stops()}, as_json=args.json)
    return 0
