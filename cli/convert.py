"""``lfproc convert IN OUT``: between light-field and image layouts."""

from __future__ import annotations

from pathlib import Path

from lfproc.io import read_lightfield, write_lightfield

from ._common import add_value_policies
from lfproc.errors import SaturationWarning
from lfproc.io._atomic import check_output
from lfproc.preview import display_transform


def register(sub, common) -> None:
    p = sub.add_parser(
        "convert", parents=[common], help="convert between light-field files, folders of views and images",
        description="Read IN (lfproc EXR, folder of view_RR_CC files, or a single image) and write OUT: a path "
                    "ending in .exr gives one multi-part EXR; an image suffix (.hdr, .png, .tif, .jpg) one image "
                    "(1x1 light fields); any other path (out, out.views) a folder of views in --format, with the "
                    "centre view's disparity as disparity.pfm when the input has one. 8/16-bit outputs hold [0, 1]: "
                    "scale with --exposure-ev and/or compress with --tonemap; samples still above 1 are clipped, "
                    "with a warning.")
    p.add_argument("input", type=Path, help="light-field file, folder of views, or image")
    p.add_argument("output", type=Path, help="OUT.exr, OUT.hdr/.png/.tif (one view), or a folder name")
    p.add_argument("--format", dest="folder_format", choices=("exr", "png", "png16", "tiff", "hdr"), default="exr",
                   help="view format when OUT is a folder (png = 8-bit, png16/tiff = 16-bit sRGB); png16 also makes "
                        "a single .png output 16-bit")
    p.add_argument("--exposure-ev", type=float, default=0.0, metavar="EV",
                   help="multiply the values by 2^EV first (e.g. -3 to bring highlights under 1)")
    p.add_argument("--tonemap", choices=("none", "reinhard", "drago"), default="none",
                   help="compress the range into [0, 1] with OpenCV's tone mapper (all views as one image)")
    p.add_argument("--dtype", choices=("float32", "half"), default="float32", help="EXR sample type")
    p.add_argument("--transfer", choices=("srgb", "linear"), default="srgb",
                   help="encoding of 8/16-bit outputs (and decoding of such inputs)")
    add_value_policies(p)
    p.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    p.set_defaults(run=run)


def run(args) -> int:
    import sys
    import warnings

    check_output(args.output, force=args.force)
    lf = read_lightfield(args.input, nonfinite=args.nonfinite, negative=args.negative, transfer=args.transfer)
    if args.exposure_ev != 0 or args.tonemap != "none":
        lf = display_transform(lf, exposure_ev=args.exposure_ev, tonemap=args.tonemap)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SaturationWarning)
        write_lightfield(lf, args.output, force=args.force, dtype=args.dtype, folder_format=args.folder_format,
                         transfer=args.transfer)
    for w in caught:
        if issubclass(w.category, SaturationWarning):
            print(f"lfproc convert: warning: {w.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    v, u = lf.views
    h, w = lf.size
    extra = " and its disparity" if lf.disparity is not None and args.output.suffix.lower() not in (
        ".hdr", ".pic", ".png", ".tif", ".tiff", ".jpg", ".jpeg") else ""
    print(f"wrote {args.output} ({v}x{u} views of {h}x{w}){extra}")
    return 0
