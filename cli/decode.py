"""``lfproc decode CAPTURE --white-db DB_DIR -o OUT.exr``: Lytro capture to sub-aperture views."""

from __future__ import annotations

from pathlib import Path

from ._common import add_json, add_output, emit
from lfproc.io import write_lightfield
from lfproc.io._atomic import check_output
from lfproc.lytro.decode import decode_capture


def register(sub, common) -> None:
    p = sub.add_parser(
        "decode", parents=[common], help="decode a Lytro raw capture into its central n x n views",
        description="Decode CAPTURE (Illum .LFR, F01 raw .lfp, .RAW + .TXT) with the white image chosen from "
                    "--white-db (geometry hash, else serial and nearest zoom/focus) or given by --white; write "
                    "linear camera RGB (or --colour srgb) with exposure metadata and per-sample variance.")
    p.add_argument("capture", type=Path, help="Lytro raw capture")
    p.add_argument("--white-db", type=Path, help="white-image database folder ('lfproc whites')")
    p.add_argument("--white", type=Path, help="explicit white image (database .npz or MOD_xxxx.RAW/.TXT)")
    p.add_argument("--views", type=int, default=5, help="odd number of views per side to keep (default 5)")
    p.add_argument("--colour", choices=("linear", "srgb"), default="linear",
                   help="linear camera RGB (default) or linear sRGB with white balance, CCM and exposure bias")
    p.add_argument("--demosaic", choices=("opencv-ea", "malvar2004", "bilinear"), default="opencv-ea",
                   help="demosaicing method (default: OpenCV edge-aware)")
    p.add_argument("--no-verify", action="store_true", help="do not check the container's SHA-1 hashes")
    add_output(p, help="output light field (.exr or folder)")
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    check_output(args.output, force=args.force)
    lf = decode_capture(args.capture, white_db=args.white_db, white=args.white, n_views=args.views,
                        colour=args.colour, demosaic_method=args.demosaic, verify=not args.no_verify)
    write_lightfield(lf, args.output, force=args.force)
    v, u = lf.views
    h, w = lf.size
    emit({"output": str(args.output), "views": [v, u], "size": [h, w], "colour_space": lf.colour_space,
          "exposure_s": lf.exposure_s, "iso": lf.iso, "white_image": lf.attrs["white_image"]["name"],
          "selected_by": lf.attrs["white_image"]["selected_by"],
          "usable_fraction": lf.attrs["decode"]["usable_fraction"]}, as_json=args.json)
    return 0
