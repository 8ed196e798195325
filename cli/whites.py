"""``lfproc whites CALDATA -o DB_DIR``: white-image database with lenslet grids."""

from __future__ import annotations

from pathlib import Path

from ._common import add_json, add_output, emit
from lfproc.io._atomic import check_output
from lfproc.lytro.whites import build_white_db


def register(sub, common) -> None:
    p = sub.add_parser(
        "whites", parents=[common], help="build a white-image database (lenslet grids) from Lytro calibration data",
        description="Read CALDATA (caldata-<serial>.tar, a folder of MOD_xxxx.RAW/.TXT, or a data.C.N archive), "
                    "drop dark frames, estimate each white image's hexagonal lenslet grid and write DB_DIR "
                    "(whites.json index + compressed white images) for 'lfproc decode --white-db'.")
    p.add_argument("caldata", type=Path, help="calibration data of a Lytro camera")
    add_output(p, help="database folder to create")
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    check_output(args.output, force=args.force)
    db = build_white_db(args.caldata, args.output, force=args.force)
    emit({"output": str(args.output), "white_images": len(db.entries), "skipped": list(db.skipped),
          "whites": [{"name": e.name, "serial": e.serial, "zoom_step": e.zoom_step, "focus_step": e.focus_step,
                      "spacing_x_px": e.grid.spacing_x_px, "spacing_y_px": e.grid.spacing_y_px,
                      "rotation_rad": e.grid.rotation_rad} for e in db.entries]},
         as_json=args.json)
    return 0
