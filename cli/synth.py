"""``lfproc synth -o OUT --scene NAME ...``: a synthetic HDR light field with ground truth."""

from __future__ import annotations

from pathlib import Path

from ._common import add_json, add_output, emit, parse_size
from lfproc.io import write_lightfield
from lfproc.io._atomic import check_output
from lfproc.synth import check_scene, SCENES, synthesize


def register(sub, common) -> None:
    import argparse

    listing = "\n".join(f"  {name:<9} {desc}" for name, (_, desc) in SCENES.items())
    p = sub.add_parser(
        "synth", parents=[common], help="synthesise an HDR light field with exact disparity",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Render a procedural HDR scene (textured layers at several depths, occlusion, emitters and "
                    "specular highlights, over 16 stops) into V x V views, with the centre-view disparity\n"
                    "(pixels per view step; positive: a point moves right as the angular column grows).\n\n"
                    f"scenes:\n{listing}")
    add_output(p, help="output: OUT.exr (one multi-part EXR) or a folder name (EXR views)")
    p.add_argument("--scene", default="layers", help=f"scene kind: {', '.join(SCENES)} (default: layers)")
    p.add_argument("--size", nargs=2, metavar=("H", "W"), default=["256", "256"], help="view size in pixels")
    p.add_argument("--views", type=int, default=5, help="odd number of views per side (default 5)")
    p.add_argument("--baseline", type=float, default=1.0, metavar="PX",
                   help="largest |disparity| in pixels per view step (default 1.0)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--texture", action="append", type=Path, default=None, metavar="FILE",
                   help="image to texture the scene's surfaces with (repeat for several)")
    p.add_argument("--dtype", choices=("float32", "half"), default="float32", help="EXR sample type")
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    check_scene(args.scene)
    size = parse_size(args.size, option="--size")
    check_output(args.output, force=args.force)
    lf = synthesize(args.scene, size=size, views=args.views, baseline_px=args.baseline, textures=args.texture,
                    random_state=args.seed)
    write_lightfield(lf, args.output, force=args.force, dtype=args.dtype)
    disp = lf.disparity
    result = {
        "output": str(args.output),
        "scene": args.scene,
        "views": list(lf.views),
        "size": list(lf.size),
        "seed": args.seed,
        "baseline_px": args.baseline,
        "disparity_range_px": [float(disp.min()), float(disp.max())],
        "dynamic_range_stops": lf.dynamic_range_stops(),
        "min": float(lf.data.min()),
        "max": float(lf.data.max()),
    }
    emit(result, as_json=args.json)
    return 0
