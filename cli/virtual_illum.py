"""``lfproc virtual-illum LF.exr -o OUT_DIR``: render a light field with the virtual Lytro Illum."""

from __future__ import annotations

import re
from pathlib import Path

from ._common import add_json, add_value_policies, add_output, emit, parse_floats
from lfproc.io import read_lightfield
from lfproc.io._atomic import check_output
from lfproc.lytro.virtual import make_virtual_illum


def register(sub, common) -> None:
    p = sub.add_parser(
        "virtual-illum", parents=[common], help="render a light field into Illum .LFR captures + calibration data",
        description="Render LF through a virtual Lytro Illum (hexagonal microlens array, vignetting, Bayer GRBG, "
                    "photon and read noise, 10-bit packing): OUT_DIR gets one IMG_nnnn.LFR per exposure, "
                    "caldata-<serial>.tar with white images and a dark frame, truth.exr (the central 5x5 views a "
                    "decoder should return for the 0 EV capture) and truth.json (grids, scales, seed).")
    p.add_argument("lightfield", type=Path, help="RGB light field (lfproc EXR or folder of views); camera RGB")
    add_output(p, help="output folder")
    p.add_argument("--sensor", choices=("full", "small"), default="full",
                   help="full = the real 7728 x 5368 sensor; small = an 800 x 600 crop for fast tests")
    p.add_argument("--exposures-ev", default="-2,-1,0,1,2", help="exposure offsets in EV (default -2,-1,0,1,2)")
    # let "--exposures-ev -2,-1,0" through: argparse otherwise takes "-2,-1,0" for an option
    p._negative_number_matcher = re.compile(r"^-\d[\d.,+-]*$")
    p.add_argument("--seed", type=int, default=0, help="fixes the camera (serial, grid, hot pixels) and the noise")
    p.add_argument("--exposure-s", type=float, default=0.01, help="exposure time of the 0 EV capture (s)")
    p.add_argument("--iso", type=float, default=100, help="ISO of the captures (a value of the illum profile)")
    add_value_policies(p)
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    evs = parse_floats(args.exposures_ev, option="--exposures-ev")
    check_output(args.output, force=args.force)
    lf = read_lightfield(args.lightfield, nonfinite=args.nonfinite, negative=args.negative)
    info = make_virtual_illum(lf, args.output, sensor=args.sensor, exposures_ev=evs, random_state=args.seed,
                              base_exposure_s=args.exposure_s, iso=args.iso, force=args.force)
    emit({"output": str(args.output), "serial": info["serial"], "sensor_size": info["sensor_size"],
          "captures": [c["file"] for c in info["captures"]], "caldata": info["caldata"],
          "truth": "truth.exr", "truth_capture": info["truth_capture"],
          "spacing_x_px": info["grid"]["spacing_x_px"], "rotation_rad": info["grid"]["rotation_rad"]},
         as_json=args.json)
    return 0
