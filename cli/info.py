"""``lfproc info PATH [--json]``: what a file holds."""

from __future__ import annotations

from pathlib import Path

from lfproc.info import describe

from ._common import add_json, add_value_policies, emit
from lfproc.cli.profile import print_profile


def register(sub, common) -> None:
    p = sub.add_parser("info", parents=[common], help="describe a light field, image, capture or profile file",
                       description="Print the shape, value range, dynamic range, saturation and metadata of a file: "
                                   "a light field (EXR, folder of views), an image, a Lytro file, a coded capture "
                                   "(.capture.npz) or a camera profile (JSON).")
    p.add_argument("path", type=Path, help="light-field file or folder, image, Lytro file, capture or profile")
    add_value_policies(p, what="")
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    doc = describe(args.path, nonfinite=args.nonfinite, negative=args.negative)
    if doc.get("kind") == "camera_profile" and not args.json:
        print(f"kind  camera_profile\npath  {doc['path']}")
        print_profile(doc)
        return 0
    emit(doc, as_json=args.json)
    return 0
