"""Calibration frames a camera profile predicts, for round-trip tests of the calibration.

Every frame comes from :func:`lfproc.camera.sensor.expose`, the same noise model as the capture
simulator (Poisson photons and dark current, Gaussian read noise, PRNU/DSNU, full well,
ADC clipping, rounding, black level). Flats use a uniform irradiance and vary the
exposure time, as a calibration bench does.

``format="manifest"`` writes, per ISO, 16 bias frames (1/8000 s), dark frames at three
exposure times (two pairs each) and flat pairs (two pairs each) at 10-90 % of the
saturation capacity and beyond it (110 %, 150 %), as 16-bit PNG, plus ``manifest.csv`` and
``manifest.json``. ``format="emva"`` writes one ISO as an EMVA 1288 data set: 50 exposure
steps from dark to beyond saturation (a bright pair and a dark pair each), a 50-frame dark
stack and a 50-frame bright stack at 50 % saturation, and ``emva1288.txt``.
Both write ``simulation.json`` with the parameters, the seed, the lfproc version and the
figures the profile predicts.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from lfproc._shared.deprecate import renamed_keywords
from lfproc._shared.validation import check_choice
from lfproc._shared.random import check_random_state
from lfproc._shared.progress import progress
from lfproc._version import __version__
from lfproc.errors import InputError
from lfproc.io._atomic import atomic_dir

from .emva import EmvaDescriptor, EmvaStep, format_descriptor
from .frames import FrameRecord, write_manifest
from lfproc.sensor import CameraProfile, expose, load_profile

__all__ = ["simulate_frames", "expected_figures", "BIAS_EXPOSURE_S", "FLAT_LEVELS"]

BIAS_EXPOSURE_S = 1.0 / 8000.0
FLAT_LEVELS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.1, 1.5)
_FLAT_SATURATION_S = 0.01  # exposure at which the flats reach saturation
_EMVA_SATURATION_S = 0.1
_EMVA_STEPS = 50
_EMVA_STACK = 50


def expected_figures(profile: CameraProfile, iso: float) -> dict[str, float]:
    """What a calibration of ``profile``'s frames at ``iso`` should measure.

    ``saturation_capacity_e = (saturation_dn - black) / gain`` (full well or ADC,
    whichever clips first)."""
    figs = profile.require(iso, "gain_dn_per_e", "read_noise_e", "dark_current_e_per_s", "black_level_dn",
                           "full_well_e")
    sat = profile.saturation_dn(iso)
    figs["saturation_dn"] = sat
    figs["saturation_capacity_e"] = (sat - figs["black_level_dn"]) / figs["gain_dn_per_e"]
    figs["read_noise_dn"] = figs["read_noise_e"] * figs["gain_dn_per_e"]
    return figs


def _write_png(path: Path, frame: np.ndarray) -> None:
    import cv2

    if not cv2.imwrite(str(path), frame.astype(np.uint16)):
        raise OSError(f"{path}: OpenCV could not write the PNG frame")


def _dark_times(fig: dict[str, float]) -> tuple[float, float, float]:
    """Three dark exposure times (s): up to 4 s, shorter when the dark signal would exceed a
    quarter of the saturation capacity."""
    t_max = 4.0
    rate = fig["dark_current_e_per_s"]
    if rate > 0:
        t_max = min(t_max, 0.25 * fig["saturation_capacity_e"] / rate)
    return (t_max / 4, t_max / 2, t_max)


#: Largest simulated calibration frame (a side, and pixels in all).
MAX_FRAME_SIDE = 16384
MAX_FRAME_PIXELS = 1 << 24


@renamed_keywords(seed="random_state")
def simulate_frames(
    profile,
    out_dir: str | os.PathLike,
    *,
    format: str = "manifest",
    isos=None,
    size: tuple[int, int] = (128, 128),
    random_state: int | None = 0,
    force: bool = False,
) -> Path:
    """Write the calibration frames ``profile`` predicts.

    Parameters
    ----------
    profile : CameraProfile, shipped name or JSON path
        The camera whose frames are simulated.
    out_dir : str or Path
        Output folder (written atomically; refused if it exists unless ``force``).
    format : {"manifest", "emva"}
        Bias, dark and flat frames as 16-bit PNGs with ``manifest.csv``/``manifest.json``, or an
        EMVA 1288 data set (descriptor ``emva1288.txt`` and its frames).
    isos : sequence of float, optional
        ISOs to simulate (default: all the profile's ISOs; for ``"emva"``, its lowest ISO).
        ``"emva"`` takes one ISO.
    size : (H, W)
        Frame size in pixels.
    random_state : int, optional
        Seed of the temporal noise (the fixed pattern follows ``profile.fixed_pattern_seed``); recorded
        as ``"seed"``. The keyword ``seed`` is deprecated.
    force : bool
        Replace an existing ``out_dir``.

    Returns
    -------
    Path
        The manifest (``manifest.csv``) or the descriptor (``emva1288.txt``).

    Examples
    --------
    >>> from lfproc.calib import calibrate, simulate_frames
    >>> descriptor = simulate_frames("paper-medium", "emva", format="emva", size=(32, 32), random_state=0)
    >>> descriptor
    PosixPath('emva/emva1288.txt')
    >>> fig = calibrate(descriptor).profile.iso_figures(100)     # EMVA data are stored as ISO 100
    >>> round(fig.gain_dn_per_e, 2), round(fig.black_level_dn)     # paper-medium: 0.20475 DN/e-, 64 DN
    (0.2, 64)
    """
    profile = load_profile(profile)
    check_choice("format", format, ("manifest", "emva"))
    try:
        h, w = (int(s) for s in size)
    except (TypeError, ValueError):
        raise InputError(f"size: expected (H, W), got {size!r}") from None
    if h < 2 or w < 2:
        raise InputError(f"size: expected at least 2x2 pixels, got {h}x{w}")
    if max(h, w) > MAX_FRAME_SIDE or h * w > MAX_FRAME_PIXELS:
        raise InputError(f"size: expected at most {MAX_FRAME_SIDE} pixels a side and {MAX_FRAME_PIXELS} pixels in all "
                         f"(simulated frames are written by the hundred), got {h} x {w}")
    iso_list = profile.iso_values if isos is None else [float(i) for i in isos]
    if format == "emva":
        if isos is None:
            iso_list = iso_list[:1]
        if len(iso_list) != 1:
            raise InputError(f"isos: an EMVA 1288 data set has one ISO; got {len(iso_list)} ({iso_list})")
    for iso in iso_list:
        profile.require(iso, "gain_dn_per_e", "read_noise_e", "full_well_e")
    seed = random_state
    rng = check_random_state(seed)
    out_dir = Path(out_dir)
    params: dict[str, Any] = {"lfproc_version": __version__, "profile": profile.name, "format": format,
                              "isos": [float(i) for i in iso_list], "size": [h, w], "seed": seed,
                              "expected": {str(int(i)): expected_figures(profile, i) for i in iso_list}}
    with atomic_dir(out_dir, force=force) as tmp:
        if format == "manifest":
            result = _write_manifest_set(profile, tmp, iso_list, (h, w), rng, params)
        else:
            result = _write_emva_set(profile, tmp, iso_list[0], (h, w), rng, params)
        (tmp / "simulation.json").write_text(json.dumps(params, indent=1))
    return out_dir / result


def _write_manifest_set(profile, tmp: Path, iso_list, shape, rng, params) -> str:
    frames_dir = tmp / "frames"
    frames_dir.mkdir()
    records: list[FrameRecord] = []
    zero = np.zeros(shape)
    plan = []
    for iso in iso_list:
        fig = expected_figures(profile, iso)
        tag = f"iso{int(iso)}"
        for k in range(16):
            plan.append((iso, "bias", BIAS_EXPOSURE_S, zero, f"{tag}_bias_{k:02d}", ""))
        for t in _dark_times(fig):
            for k in range(4):
                plan.append((iso, "dark", t, zero, f"{tag}_dark_{t:.4g}s_{k}", ""))
        irradiance = np.full(shape, fig["saturation_capacity_e"] / _FLAT_SATURATION_S)
        for level in FLAT_LEVELS:
            t = level * _FLAT_SATURATION_S
            for k in range(4):
                plan.append((iso, "flat", t, irradiance, f"{tag}_flat_{int(round(level * 100)):03d}_{k}", ""))
    for iso, kind, t, irr, stem, group in progress(plan, desc="simulate frames"):
        frame = expose(irr, exposure_s=t, iso=iso, profile=profile, random_state=rng)
        path = frames_dir / f"{stem}.png"
        _write_png(path, frame)
        records.append(FrameRecord(path=path, kind=kind, iso=float(iso), exposure_s=float(t), group=group,
                                   cfa_pattern=profile.cfa_pattern, temperature_c=None))
    options = {"name": f"{profile.name}-simulated", "adc_bits": profile.adc_bits, "cfa_pattern": profile.cfa_pattern}
    write_manifest(records, tmp / "manifest.csv", relative_to=tmp)
    write_manifest(records, tmp / "manifest.json", relative_to=tmp, options=options)
    params["flat_levels"] = list(FLAT_LEVELS)
    params["bias_exposure_s"] = BIAS_EXPOSURE_S
    return "manifest.csv"


def _write_emva_set(profile, tmp: Path, iso: float, shape, rng, params) -> str:
    fig = expected_figures(profile, iso)
    img = tmp / "images"
    img.mkdir()
    zero = np.zeros(shape)
    photons_per_s = fig["saturation_capacity_e"] / _EMVA_SATURATION_S  # quantum efficiency 1 in lfproc's model
    bright = np.full(shape, photons_per_s)
    steps: list[EmvaStep] = []
    t_top = 1.1 * _EMVA_SATURATION_S
    times = [t_top * max(k, 0.02) / (_EMVA_STEPS - 1) for k in range(_EMVA_STEPS)]

    def shoot(irr, t, name):
        path = img / f"{name}.png"
        _write_png(path, expose(irr, exposure_s=t, iso=iso, profile=profile, random_state=rng))
        return path

    for k, t in enumerate(progress(times, desc="simulate EMVA steps")):
        ns = round(t * 1e9)
        t = ns * 1e-9
        steps.append(EmvaStep("bright", float(ns), photons_per_s * t,
                              (shoot(bright, t, f"b{k:03d}_a"), shoot(bright, t, f"b{k:03d}_b"))))
        steps.append(EmvaStep("dark", float(ns), None, (shoot(zero, t, f"d{k:03d}_a"), shoot(zero, t, f"d{k:03d}_b"))))
    ns = round(0.5 * _EMVA_SATURATION_S * 1e9)
    t = ns * 1e-9
    steps.append(EmvaStep("dark", float(ns), None, tuple(shoot(zero, t, f"sd{k:03d}") for k in range(_EMVA_STACK))))
    steps.append(EmvaStep("bright", float(ns), photons_per_s * t,
                          tuple(shoot(bright, t, f"sb{k:03d}") for k in range(_EMVA_STACK))))
    desc = EmvaDescriptor(release="3.1", bits=profile.adc_bits, width=shape[1], height=shape[0], steps=tuple(steps))
    (tmp / "emva1288.txt").write_text(format_descriptor(desc, base=tmp))
    params["iso"] = float(iso)
    params["photons_per_s"] = photons_per_s
    params["emva_steps"] = _EMVA_STEPS
    params["emva_stack"] = _EMVA_STACK
    return "emva1288.txt"
