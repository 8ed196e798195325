"""``lfproc simulate HDR_LF -o CAPTURE``: a multi-ISO coded-mask capture of a light field."""

from __future__ import annotations

from pathlib import Path

from lfproc.camera.iso import DEFAULT_BLOCK_PX

from ._common import add_json, add_value_policies, add_output, emit, parse_floats
from lfproc._shared.validation import check_count
from lfproc.errors import InputError
from lfproc.camera.capture import MAX_SHOTS
from lfproc.camera.projection import MASK_TRANSMITTANCES
from lfproc.camera.simulate import DEFAULT_MASK_TRANSMITTANCE, NOISE_PROFILES, simulate_file


def _period(text: str):
    import argparse

    if text.lower() in ("none", "default"):
        return None if text.lower() == "none" else "default"
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a period in pixels or 'none', got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a period of at least 1 pixel, got {value}")
    return value


def register(sub, common) -> None:
    p = sub.add_parser(
        "simulate", parents=[common], help="simulate a multi-ISO coded-mask capture of an HDR light field",
        description="Project HDR_LF through a colour-coded mask and a Bayer CFA onto a sensor with a per-pixel ISO "
                    "pattern (Poisson, dark-current and read noise, saturation, quantisation) and write a capture "
                    "file. The light field is scaled to electrons/s by --radiance-scale, by default so that the "
                    "brightest expected signal just saturates the lowest ISO. Prints the sampling rate and the "
                    "saturated and black-clipped fractions.")
    p.add_argument("input", type=Path, metavar="HDR_LF", help="HDR light field (lfproc EXR or folder of views)")
    add_output(p, help="capture file to write (suggested suffix .capture.npz)")
    noise = p.add_mutually_exclusive_group()
    noise.add_argument("--profile", help="camera profile: shipped name or JSON file")
    noise.add_argument("--noise", choices=("none", "low", "medium", "high"),
                       help="the paper's simulated sensor at this noise level (profile paper-LEVEL; default low)")
    p.add_argument("--iso-pattern", default="random", metavar="random|row|block|dual|FILE",
                   help="per-pixel ISO layout, or a .npy/16-bit image of ISO values (default random)")
    p.add_argument("--isos", default="100,400,800,1600", help="ISO set, comma-separated (default 100,400,800,1600)")
    p.add_argument("--block-px", type=int, default=None,
                   help=f"block side in pixels for --iso-pattern block (even; default {DEFAULT_BLOCK_PX})")
    p.add_argument("--shots", type=int, default=None, help="number of shots (default 1; bracketing 2)")
    p.add_argument("--exposure-s", type=float, default=0.004, help="exposure time of a shot in seconds")
    p.add_argument("--gamma", type=float, default=None, help="power-law sensor response (default: the profile's)")
    p.add_argument("--mask", choices=("random", "shifted"), default="random", help="mask model (default random)")
    p.add_argument("--mask-transmittance", choices=MASK_TRANSMITTANCES, default=DEFAULT_MASK_TRANSMITTANCE,
                   help=f"the mask's transmittances (default {DEFAULT_MASK_TRANSMITTANCE}): every level equally likely "
                        "(uniform, the paper's), 0/1 (binary: finer detail, small lights worse) or 1, 0 or a small "
                        "level (mixed: finer detail, small lights kept)")
    p.add_argument("--mask-period", type=_period, default="default", metavar="N|none",
                   help="tile the mask with this period in pixels (default 4 for a random mask, none for shifted: "
                        "patches share one operator; 'none': one code per pixel, minutes to reconstruct at the Lytro "
                        "size)")
    p.add_argument("--baseline", choices=("individual-iso", "bracketing"), default=None,
                   help="the paper's baselines: one global-ISO shot per ISO, or exposure bracketing at the lowest "
                        "ISO (relative exposures 0.5,8 / 0.5,2,8 / 0.5,2,4,8)")
    p.add_argument("--relative-exposures", default=None, help="exposure of each shot relative to --exposure-s")
    p.add_argument("--radiance-scale", type=float, default=None,
                   help="electrons/s per light-field unit (default: automatic, recorded in the capture)")
    p.add_argument("--reference-exposure-s", type=float, default=0.004,
                   help="exposure at which the automatic radiance scale saturates the scene's brightest expected "
                        "signal (default 0.004); --exposure-s longer than this saturates more, as in a camera")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: drawn and recorded)")
    add_value_policies(p, negative="raise", what="light-field")
    p.add_argument("--dictionary", default="default", metavar="default|FILE",
                   help="the dictionary the capture is meant for: a warning when its views differ from the light "
                        "field's (default: the shipped one)")
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    if args.block_px is not None and args.iso_pattern != "block":
        raise InputError(f"--block-px: has no effect with --iso-pattern {args.iso_pattern} (block only); drop it")
    profile = args.profile or NOISE_PROFILES[args.noise or "low"]

    shots = args.shots if args.shots is not None else (2 if args.baseline == "bracketing" else 1)
    check_count("--shots", shots, high=MAX_SHOTS)
    rel = None if args.relative_exposures is None else parse_floats(args.relative_exposures,
                                                                    option="--relative-exposures")
    _, summary = simulate_file(
        args.input, args.output, force=args.force,
        profile=profile,
        iso_pattern_kind=args.iso_pattern,
        isos=parse_floats(args.isos, option="--isos"),
        block_px=DEFAULT_BLOCK_PX if args.block_px is None else args.block_px,
        shots=shots,
        exposure_s=args.exposure_s,
        gamma=args.gamma,
        mask=args.mask,
        mask_transmittance=args.mask_transmittance,
        mask_period=args.mask_period,
        baseline=args.baseline,
        relative_exposures=rel,
        radiance_scale=args.radiance_scale,
        reference_exposure_s=args.reference_exposure_s,
        random_state=args.seed,
        nonfinite=args.nonfinite,
        negative=args.negative,
        dictionary=args.dictionary,
    )
    emit(summary, as_json=args.json)
    return 0
