"""``lfproc capture import RAW... -o CAPTURE``: a capture file from a real camera's raw files.

One raw file (DNG or any raw LibRaw reads, or a 16-bit PNG/TIFF mosaic) per shot, the mask
codes, the per-pixel ISO layout, the camera profile and the exposure times make a capture
file that ``lfproc info``, ``lfproc preview`` and the reconstruction read like a simulated one.

``--mask CODES``: a ``.npy`` array of mask transmittances in [0, 1] in the layout of
:class:`lfproc.camera.projection.MaskCode` -- ``(S, V, U, Ph, Pw, 3)`` for ``--mask-kind
random`` (one code per shot, view, pixel and colour; ``Ph x Pw`` is one tile of
``--mask-period`` pixels, or the whole sensor without a period) or ``(S, Bh, Bw, 3)`` for
``--mask-kind shifted`` (one base pattern per shot, shifted ``--mask-shift`` pixels per view
step) -- or an existing capture file whose mask (and views) are reused.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from lfproc.camera.iso import DEFAULT_BLOCK_PX, ISO_PATTERNS
from lfproc.errors import InputError, LfprocWarning

from ._common import add_json, add_output, emit, parse_floats
from lfproc.camera.capture import capture_from_raw, is_capture_file
from lfproc.camera.simulate import capture_summary
from lfproc.io._atomic import check_output
from lfproc.sensor import fixed_pattern_correction


def register(sub, common) -> None:
    p = sub.add_parser(
        "capture", parents=[common], help="make capture files from a real camera's raw files",
        description="Capture files. 'import': one raw file per shot plus the mask codes, the ISO layout, the camera "
                    "profile and the exposure times -> a capture file (as 'lfproc simulate' writes).")
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    i = actions.add_parser(
        "import", parents=[common], help="build a capture file from raw files (one per shot)",
        description="Read one raw file per shot (DNG or another raw format LibRaw reads, or a single-channel 16-bit "
                    "PNG/TIFF Bayer mosaic) and write a capture file with the mask codes, the per-pixel ISO map, "
                    "the camera profile and the exposure times. CODES is a .npy of mask transmittances in [0, 1]: "
                    "(S, V, U, Ph, Pw, 3) for --mask-kind random, (S, Bh, Bw, 3) for --mask-kind shifted (S shots, "
                    "V x U views, Ph x Pw pixels: one tile of --mask-period, or the whole sensor); or an existing "
                    "capture file whose mask is reused.")
    i.add_argument("raw", nargs="+", type=Path, metavar="RAW", help="raw file of each shot, in shot order")
    i.add_argument("--mask", required=True, type=Path, metavar="CODES",
                   help="mask codes (.npy, see above) or a capture file whose mask is reused")
    i.add_argument("--mask-kind", choices=("random", "shifted"), default="random",
                   help="layout of the .npy codes (default random)")
    i.add_argument("--mask-period", type=int, default=None,
                   help="the codes hold one tile of this many pixels, repeated over the sensor (default: none)")
    i.add_argument("--mask-shift", type=int, default=1, help="pixels of mask shift per view step (shifted)")
    i.add_argument("--views", type=int, nargs=2, metavar=("V", "U"), default=None,
                   help="angular views (default: from random codes or the donor capture, else 5 5)")
    i.add_argument("--iso-layout", required=True, metavar="row|block|dual|random|FILE",
                   help="per-pixel ISO layout of the sensor, or an ISO map file (.npy or 16-bit image)")
    i.add_argument("--isos", default=None, help="ISO set of a named layout, comma-separated (e.g. 100,400,800,1600)")
    i.add_argument("--block-px", type=int, default=None,
                   help=f"block side in pixels for --iso-layout block (even; default {DEFAULT_BLOCK_PX})")
    i.add_argument("--seed", type=int, default=None, help="seed of --iso-layout random (the sensor's layout)")
    i.add_argument("--profile", required=True, help="camera profile: shipped name or JSON file (lfproc calibrate)")
    i.add_argument("--exposures-s", required=True, metavar="T[,T...]",
                   help="exposure time of each shot in seconds (one value: the same for every shot)")
    i.add_argument("--cfa-pattern", choices=("RGGB", "GRBG", "GBRG", "BGGR"), default=None,
                   help="Bayer layout (default: the raw files', else the profile's)")
    i.add_argument("--gamma", type=float, default=None, help="power-law response of the codes (default: the profile's)")
    add_output(i, help="capture file to write (suggested suffix .capture.npz)")
    add_json(i)
    i.set_defaults(run=run_import)


def run_import(args) -> int:
    check_output(args.output, force=args.force)
    exposures = parse_floats(args.exposures_s, option="--exposures-s")
    if len(exposures) not in (1, len(args.raw)):
        raise InputError(f"--exposures-s: expected 1 or {len(args.raw)} exposure times (one per RAW), "
                         f"got {len(exposures)}")
    layout = args.iso_layout
    if args.block_px is not None and layout != "block":
        raise InputError(f"--block-px: has no effect with --iso-layout {layout} (block only); drop it")
    isos = None
    if layout in ISO_PATTERNS:
        if args.isos is None:
            raise InputError(f"--iso-layout {layout}: --isos is required (the ISO values of the pattern)")
        isos = parse_floats(args.isos, option="--isos")
        if layout == "random" and args.seed is None:
            raise InputError("--iso-layout random: --seed is required (the seed that drew the sensor's ISO layout)")
    elif not (Path(layout).suffix or Path(layout).exists()):
        raise InputError(f"--iso-layout: expected one of {', '.join(ISO_PATTERNS)} or an ISO map file; got {layout!r}")
    elif args.isos is not None:
        raise InputError(f"--isos: has no effect with an ISO map file ({layout} gives every pixel's ISO); drop it")
    mask = args.mask if is_capture_file(args.mask) else {
        "kind": args.mask_kind, "codes": args.mask, "period": args.mask_period, "shift": args.mask_shift}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LfprocWarning)
        capture = capture_from_raw(
            args.raw, mask=mask, iso_layout=layout, profile=args.profile, exposures_s=exposures,
            views=tuple(args.views) if args.views else None, cfa_pattern=args.cfa_pattern, gamma=args.gamma,
            isos=isos, block_px=DEFAULT_BLOCK_PX if args.block_px is None else args.block_px,
            random_state=args.seed,
        )
    for w in caught:  # one line each, as the errors
        print(f"lfproc capture: warning: {w.message}", file=sys.stderr)
    capture.save(args.output, force=args.force)
    summary = capture_summary(capture, path=args.output)
    summary.pop("seed", None)
    summary["cfa_pattern"] = capture.cfa_pattern
    summary["raw_files"] = [str(p) for p in args.raw]
    frames = capture.parameters["frames"]
    if "black_level_dn" in frames[0]:
        summary["raw_black_level_dn"] = frames[0]["black_level_dn"]
        summary["raw_white_level_dn"] = frames[0]["white_level_dn"]
    fp = fixed_pattern_correction(capture.profile, capture.size, capture.iso[0])
    summary["fixed_pattern"] = {"prnu": fp.gain_source, "dsnu": fp.offset_source}
    emit(summary, as_json=args.json)
    return 0

