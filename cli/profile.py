"""``lfproc profile show PROFILE [--json]``: the figures of a camera profile.

PROFILE is a shipped profile name (``illum``, ``paper-none``, ``paper-low``,
``paper-medium``, ``paper-high``) or a profile JSON path.
"""

from __future__ import annotations

from lfproc.calib.calibrate import EMVA_SOURCE_KEYS
from lfproc.sensor import describe_profile, load_profile

from ._common import add_json, emit

__all__ = ["describe_profile", "register", "run_show", "print_profile"]

_ISO_KEYS = ("gain_dn_per_e", "read_noise_e", "read_noise_dn", "dark_current_e_per_s", "black_level_dn", "full_well_e",
             "dsnu_dn", "prnu")


def register(sub, common) -> None:
    p = sub.add_parser("profile", parents=[common], help="inspect camera profiles",
                       description="Camera profiles: 'lfproc profile show PROFILE [--json]'.")
    actions = p.add_subparsers(dest="profile_command", metavar="ACTION", required=True)
    show = actions.add_parser("show", parents=[common], help="print a profile's figures",
                              description="Print a camera profile (shipped name or JSON path): levels, "
                              "per-ISO gain, read noise, dark current, full well, unknown figures.")
    show.add_argument("profile", metavar="PROFILE", help="shipped profile name or profile JSON path")
    add_json(show)
    show.set_defaults(run=run_show)


def run_show(args) -> int:
    doc = describe_profile(load_profile(args.profile))
    if args.json:
        emit(doc, as_json=True)
        return 0
    print_profile(doc)
    return 0


def print_profile(doc: dict) -> None:
    """Print a :func:`describe_profile` dict as text (``profile show``, ``info PROFILE.json``)."""
    head = {k: doc[k] for k in ("name", "description", "adc_bits", "white_level_dn", "black_level_dn", "full_well_e",
                                "gamma", "cfa_pattern", "dark_current_e_per_s", "prnu", "dsnu_e")}
    if head["cfa_pattern"] == "mono":
        head["cfa_pattern"] = "mono (monochrome sensor)"
    if doc["bias_frames"]:
        head["bias_frames"] = ", ".join(f"ISO {k}: {v[0]}x{v[1]}" for k, v in doc["bias_frames"].items())
    if doc["flat_field"]:
        head["flat_field"] = f"{doc['flat_field'][0]}x{doc['flat_field'][1]} (relative std {doc['flat_field_std']:.3g})"
    emit(head, as_json=False)
    print()
    emva = (doc.get("source") or {}).get("emva1288") or {}
    emva_keys = sorted({k for figs in emva.values() if isinstance(figs, dict) for k in figs},
                       key=lambda k: _EMVA_ORDER.index(k) if k in _EMVA_ORDER else len(_EMVA_ORDER))
    width = max(len(k) for k in _ISO_KEYS + ("saturation_dn",) + tuple(emva_keys))
    isos = list(doc["isos"])
    print(f"{'ISO':<{width}}  " + "  ".join(f"{i:>10}" for i in isos))
    for key in _ISO_KEYS:
        print(f"{key:<{width}}  " + "  ".join(_cell(doc["isos"][i][key]) for i in isos))
    print(f"{'saturation_dn':<{width}}  " + "  ".join(_cell(doc["saturation_dn"][i]) for i in isos))
    if emva_keys:
        print()
        print(f"{'EMVA 1288 (calibration)':<{width}}  " + "  ".join(f"{i:>10}" for i in isos))
        for key in emva_keys:
            print(f"{key:<{width}}  " + "  ".join(_cell((emva.get(i) or {}).get(key)) for i in isos))
    for key, why in sorted(doc["unknown"].items()):
        print(f"unknown {key}: {why}")


_EMVA_ORDER = EMVA_SOURCE_KEYS


def _cell(value) -> str:
    text = "unknown" if value is None else f"{value:.5g}"
    return f"{text:>10}"
