"""``lfproc calibrate``: measure a camera profile, or simulate the frames a profile predicts.

* ``lfproc calibrate INPUT -o PROFILE.json [--report DIR] [--json] [--force]``: INPUT is a
  frame manifest (CSV/JSON), an EMVA 1288 descriptor, or a folder holding one of them (as
  ``calibrate simulate-frames`` writes).
* ``lfproc calibrate simulate-frames --profile PROFILE -o DIR [--format manifest|emva]
  [--seed N] [--size H W] [--iso ISO ...] [--force]``.

``--json`` prints one object; its key ``isos`` maps each ISO (a string, ``"default"`` for
EMVA data) to its figures (``null`` = unknown).
"""

from __future__ import annotations

from pathlib import Path

from lfproc.errors import InputError

from ._common import add_json, emit, parse_size
from lfproc.calib.calibrate import calibrate
from lfproc.calib.report import EMVA_COLUMNS, PROFILE_COLUMNS, write_report
from lfproc.calib.simulate_frames import simulate_frames
from lfproc.io._atomic import atomic_outputs, check_output
from lfproc.sensor import save_profile
from lfproc.sensor._profile import profile_outputs

SIMULATE = "simulate-frames"


def register(sub, common) -> None:
    p = sub.add_parser(
        "calibrate", parents=[common], help="measure a camera profile from bias/dark/flat frames",
        description="lfproc calibrate INPUT -o PROFILE.json: measure black level, read noise, gain, dark current, "
        "saturation and full well per ISO from a frame manifest (CSV/JSON) or an EMVA 1288 descriptor. "
        f"lfproc calibrate {SIMULATE} --profile PROFILE -o DIR: write the frames a profile predicts.",
    )
    p.add_argument("input", metavar="INPUT", help="manifest (.csv/.json), EMVA 1288 descriptor, a folder holding one "
                   f"(manifest.json, manifest.csv or one descriptor), or the word {SIMULATE}")
    p.add_argument("-o", "--output", required=True, type=Path,
                   help="profile JSON to write (calibrate) or output folder (simulate-frames)")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.add_argument("--report", type=Path, metavar="DIR", help="write PNG plots and a Markdown summary to DIR")
    p.add_argument("--name", help="profile name (default: from the input)")
    p.add_argument("--adc-bits", type=int, help="ADC resolution (default: from the frames)")
    p.add_argument("--cfa", choices=("RGGB", "GRBG", "GBRG", "BGGR", "mono"),
                   help="CFA layout when the frames lack one; 'mono' for a monochrome sensor (the default for EMVA "
                        "1288 data; frame manifests default to RGGB, recorded as unknown)")
    p.add_argument("--frames-root", type=Path, metavar="DIR",
                   help="folder the frames may lie in (default: the manifest's folder; paths leading elsewhere are "
                        "refused)")
    add_json(p)
    g = p.add_argument_group(f"{SIMULATE} options")
    g.add_argument("--profile", help="camera profile: shipped name or JSON path")
    g.add_argument("--format", choices=("manifest", "emva"), default=None, help="frame set layout (default manifest)")
    g.add_argument("--seed", type=int, default=None, help="random seed (default 0)")
    g.add_argument("--size", nargs=2, metavar=("H", "W"), help="frame size in pixels (default 128 128)")
    g.add_argument("--iso", type=float, action="append", help="ISO to simulate (repeatable; default all)")
    p.set_defaults(run=run)


def _simulate(args) -> int:
    if args.report or args.name or args.adc_bits or args.cfa or args.frames_root:
        raise InputError(f"{SIMULATE}: --report, --name, --adc-bits, --cfa and --frames-root apply to calibration, "
                         "not simulation")
    if not args.profile:
        raise InputError(f"{SIMULATE}: --profile is required (a shipped profile name or a profile JSON)")
    size = parse_size(args.size, option="--size") if args.size else (128, 128)
    path = simulate_frames(args.profile, args.output, format=args.format or "manifest", isos=args.iso, size=size,
                           random_state=0 if args.seed is None else args.seed, force=args.force)
    emit({"output": str(args.output), "index": str(path), "format": args.format or "manifest",
          "size": list(size), "seed": 0 if args.seed is None else args.seed}, as_json=args.json)
    return 0


def run(args) -> int:
    if args.input == SIMULATE:
        return _simulate(args)
    given = [o for o, v in (("--profile", args.profile), ("--format", args.format), ("--seed", args.seed),
                            ("--size", args.size), ("--iso", args.iso)) if v is not None]
    if given:
        raise InputError(f"{', '.join(given)}: only for 'lfproc calibrate {SIMULATE}'")

    check_output(args.output, force=args.force)
    if args.report is not None:
        check_output(args.report, force=args.force)
    result = calibrate(args.input, name=args.name, adc_bits=args.adc_bits, cfa_pattern=args.cfa,
                       frames_root=args.frames_root)
    # the profile, its sidecars and the report are published together: a run killed at any
    # moment leaves all of them or none (and a re-run as it was then succeeds)
    outputs = profile_outputs(result.profile, args.output)
    if args.report is not None:
        outputs.append(args.report)
    with atomic_outputs(outputs, force=args.force) as staged:
        save_profile(result.profile, staged[0])
        if args.report is not None:
            write_report(result, staged[-1])
    out = {"profile": str(args.output), "name": result.profile.name}
    if args.report is not None:
        out["report"] = str(args.report)
    if args.json:
        out["isos"] = result.figures
        out["read_noise_model"] = result.read_noise_model
        out["unknown"] = result.unknown
        out["notes"] = result.notes
        emit(out, as_json=True)
    else:
        emit(out, as_json=False)
        _table(result)
    return 0


def _table(result) -> None:
    """The profile's figures, then the EMVA 1288 figures (the same tables as the report's summary)."""
    isos = list(result.figures)
    profile = result.profile
    print(f"sensor  {'monochrome' if profile.is_mono else 'Bayer ' + profile.cfa_pattern}, {profile.adc_bits} bit")
    width = max(len(k) for k, _ in PROFILE_COLUMNS + EMVA_COLUMNS)
    for title, columns in (("profile figures", PROFILE_COLUMNS), ("EMVA 1288 figures", EMVA_COLUMNS)):
        print()
        print(f"{title:<{width}}  " + "  ".join(f"{'ISO ' + k:>12}" for k in isos))
        for key, _ in columns:
            cells = []
            for iso in isos:
                v = result.figures[iso].get(key)
                text = "unknown" if v is None else (f"{v:.6g}" if isinstance(v, float) else str(v))
                cells.append(f"{text:>12}")
            print(f"{key:<{width}}  " + "  ".join(cells))
    print()
    for k, why in sorted(result.unknown.items()):
        print(f"unknown {k}: {why}")
