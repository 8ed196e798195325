"""``lfproc convert IN OUT``: between light-field and image layouts."""

from __future__ import annotations

from pathlib import Path

from lfproc.io import read_lightfield, write_lightfield


def register(sub, common) -> None:
    p = sub.add_parser(
        "convert", parents=[common], help="convert between light-field files, folders of views and images",
        description="Read IN (lfproc EXR, folder of view_RR_CC files, or a single image) and write OUT: a path "
                    "ending in .exr gives one multi-part EXR; any other path a folder of views in --format.")
    p.add_argument("input", type=Path, help="light-field file, folder of views, or image")
    p.add_argument("output", type=Path, help="OUT.exr, or a folder name")
    p.add_argument("--format", dest="folder_format", choices=("exr", "png", "png16", "tiff", "hdr"), default="exr",
                   help="view format when OUT is a folder (png = 8-bit, png16/tiff = 16-bit sRGB)")
    p.add_argument("--dtype", choices=("float32", "half"), default="float32", help="EXR sample type")
    p.add_argument("--transfer", choices=("srgb", "linear"), default="srgb",
                   help="encoding of 8/16-bit outputs (and decoding of such inputs)")
    p.add_argument("--nonfinite", choices=("raise", "zero", "clip"), default="raise",
                   help="what to do with NaN/Inf input samples (default: refuse)")
    p.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    p.set_defaults(run=run)


def run(args) -> int:
    from lfproc.io import check_output

    check_output(args.output, force=args.force)
    lf = read_lightfield(args.input, nonfinite=args.nonfinite, transfer=args.transfer)
    write_lightfield(lf, args.output, force=args.force, dtype=args.dtype, folder_format=args.folder_format,
                     transfer=args.transfer)
    v, u = lf.views
    h, w = lf.size
    print(f"wrote {args.output} ({v}x{u} views of {h}x{w})")
    return 0
