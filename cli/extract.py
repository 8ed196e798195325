"""``lfproc extract LFP -o DIR``: write what a Lytro container holds (images, depth maps, metadata)."""

from __future__ import annotations

from pathlib import Path

from ._common import add_json, add_output, emit
from lfproc.io._atomic import check_output
from lfproc.lytro.extract import extract_lfp


def register(sub, common) -> None:
    p = sub.add_parser(
        "extract", parents=[common], help="write the images, depth maps and metadata a Lytro file holds",
        description="Write every section of a Lytro container (.lfp, .LFR) into DIR: embedded JPEGs (focus "
                    "stacks, thumbnails) as they are, the frames of F01 H.264 videos (refocus stacks, parallax sweeps) "
                    "as PNGs, depth and confidence maps as float32 OpenEXR images with colour-mapped PNG previews "
                    "with a colour bar, the table of contents and the frame metadata as JSON, and extracted.json "
                    "listing "
                    "them. For processed files (F01 -stk/-dm .lfp, Illum desktop .LFP) that hold no raw lenslet "
                    "image; raw captures are decoded with 'lfproc decode'.")
    p.add_argument("lfp", type=Path, metavar="LFP", help="Lytro container (.lfp, .lfr)")
    add_output(p, help="output folder")
    p.add_argument("--no-verify", action="store_true", help="do not check the container's SHA-1 hashes")
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    check_output(args.output, force=args.force)
    doc = extract_lfp(args.lfp, args.output, force=args.force, verify=not args.no_verify)
    kinds: dict[str, int] = {}
    for f in doc["files"]:
        kinds[f["kind"]] = kinds.get(f["kind"], 0) + 1
    emit({"output": str(args.output), "holds": doc["holds"], "raw_lenslet_image": doc["raw_lenslet_image"],
          "files": len(doc["files"]), "kinds": kinds, "missing_sections": len(doc["missing"]),
          "index": str(Path(args.output) / "extracted.json")}, as_json=args.json)
    return 0
