"""``lfproc refocus LF -o OUT.exr --slope S``: shift-and-sum refocusing, one image or a focal stack."""

from __future__ import annotations

from pathlib import Path

from ._common import add_json, add_output, add_value_policies, emit, parse_floats
from lfproc.errors import InputError
from lfproc.io import read_lightfield, write_image
from lfproc.io._atomic import atomic_dir, check_output
from lfproc.refocus import check_slopes, focal_stack

#: Suffixes of a single linear HDR output.
HDR_SUFFIXES = (".exr", ".hdr")


def register(sub, common) -> None:
    p = sub.add_parser(
        "refocus", parents=[common], help="refocus a light field (shift-and-sum over the views), linear HDR",
        description="Average the views of LF, each shifted by SLOPE pixels per view step towards the centre view "
                    "(as LFToolbox's LFFiltShiftSum), so the plane of disparity SLOPE is in focus; values stay "
                    "linear. One slope: OUT is an image (.exr or .hdr). Several slopes (--slope -1 0 1): a focal "
                    "stack, OUT is a folder of slope_<S>.exr images with focal_stack.json. Slopes use the light "
                    "field's disparity convention (positive: nearer than the zero-disparity plane).")
    p.add_argument("input", type=Path, metavar="LF", help="light field (lfproc EXR or folder of views)")
    add_output(p, help="OUT.exr/OUT.hdr for one slope, a folder for several")
    p.add_argument("--slope", required=True, nargs="+", metavar="S",
                   help="disparity in focus, pixels per view step; several (--slope -1 0 1, or --slope=-1,0,1) give "
                        "a focal stack")
    add_value_policies(p)
    add_json(p)
    p.set_defaults(run=run)


def _name(slope: float) -> str:
    return f"slope_{slope:+.4g}.exr"


def run(args) -> int:
    import json

    text = ",".join(args.slope)
    slopes = parse_floats(text, option="--slope")
    out = Path(args.output)
    if len(slopes) == 1 and out.suffix.lower() not in HDR_SUFFIXES:
        raise InputError(f"--output: one slope gives one linear HDR image: expected a .exr or .hdr file, got {out}")
    if len(slopes) > 1 and out.suffix:
        raise InputError(f"--output: {len(slopes)} slopes give a focal stack: expected a folder name without a "
                         f"suffix, got {out}")
    check_output(out, force=args.force)
    lf = read_lightfield(args.input, nonfinite=args.nonfinite, negative=args.negative)
    slopes = check_slopes(slopes, lf, name="--slope")
    stack = focal_stack(lf, slopes)
    if len(slopes) == 1:
        write_image(out, stack[0], force=args.force)
        files = [str(out)]
    else:
        names = [_name(s) for s in slopes]
        if len(set(names)) != len(names):
            raise InputError(f"--slope: expected different slopes, got {text}")
        with atomic_dir(out, force=args.force) as tmp:
            for name, image in zip(names, stack):
                write_image(tmp / name, image)
            (tmp / "focal_stack.json").write_text(json.dumps(
                {"source": str(args.input), "units": lf.units, "slopes": slopes, "files": names}, indent=1))
        files = [str(out / n) for n in names]
    v, u = lf.views
    emit({"output": str(out), "views": [v, u], "size": list(lf.size), "slopes": slopes,
          "files": len(files), "units": lf.units}, as_json=args.json)
    return 0
