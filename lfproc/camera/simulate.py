"""Simulated captures of the multi-ISO coded-mask camera.

The camera, its sensor model, baselines and settings are those of Miandji, Nguyen, Hajisharif,
Unger and Guillemot, "Compressive HDR light field imaging using a single multi-ISO sensor", IEEE
TCI 2021 (sections III and IV).

:func:`simulate_capture` projects an HDR light field through the coded mask and the Bayer
CFA (:mod:`lfproc.camera.projection`) and exposes each shot on a sensor with a per-pixel ISO map
(:func:`lfproc.camera.sensor.expose`: Poisson photon and dark-current noise, Gaussian read noise,
full well and ADC saturation, power-law response, quantisation, black level). The result is a
:class:`lfproc.camera.capture.Capture`.

Radiance scale (lfproc's rule). Light fields are usually in relative units; the sensor
needs electrons per second. ``L_e = K * L``, with ``K = radiance_scale`` given explicitly, or
by default chosen so that the brightest *expected* sensor signal just reaches saturation at
the lowest ISO in use and the *reference* exposure ``reference_exposure_s`` (a constant,
:data:`REFERENCE_EXPOSURE_S` = 4 ms, the default shot)::

    K = e_sat(ISO_min) / (reference_exposure_s * mean_transmittance * max_{p, c} sum_{v, u} L(v, u, p, c))

The scale belongs to the scene, not to the shot: a shot of ``exposure_s`` longer than the
reference saturates more pixels and collects proportionally more signal, as in a camera
(before, ``K`` was recomputed from ``exposure_s`` and cancelled it).

where ``e_sat`` is the electron count at which a pixel of that ISO saturates (full well or
ADC, whichever first) and ``mean_transmittance = 0.5`` (masks are uniform in [0, 1]). The
scale does not depend on the mask draw, so acquisitions of one scene with the same
ISO set (joint, individual-ISO, bracketing, any exposure) see the same electrons per
second. ``K`` is recorded in the capture (``radiance_scale``) with the reference exposure
(``parameters["reference_exposure_s"]``).

ISO patterns (:func:`iso_pattern`): ``random`` (i.i.d. per pixel), ``row`` (rows alternate ISO
in 2-row units, so a Bayer quad shares one ISO, as in Magic Lantern's dual ISO), ``block``
(square blocks of ``block_px`` pixels, an even number; the ISOs of the set are laid out in a
``g x g`` arrangement of blocks, ``g = ceil(sqrt(n))``), ``dual`` (the row pattern with the
lowest and the highest ISO of the set: (100, 1600) for the default set), or a file (``.npy``
or a single-channel integer image, values = ISO). The ISO map is the same in every shot (it
is a property of the sensor); each shot has its own mask code.

Random streams. The ISO layout, the mask and the noise are drawn from three independent streams of
``random_state`` (:func:`lfproc.camera.capture.capture_streams`), so one seed gives the same mask codes and
noise draws whatever the ISO pattern or noise level: designs compared at one seed differ by their design
alone. Before (stop 16 and earlier) the ``random`` layout drew from the one stream first and moved every
later draw, so comparing patterns at one seed compared different masks too. Measured
(``reconstruct_realistic.py --method gmm --size 96 128 --seeds 3``, the test scenes, mean PU21-PSNR of
2 random / 2 row / 2 block shots): with one stream 34.89 / 34.71 (stop 15) / 35.32 dB (block ahead by 0.43 dB,
city-interior by 1.5 dB), with the streams 35.27 / 35.23 / 35.30 dB (within 0.07 dB, each scene's seeds
spread by 0.1-0.8 dB), while block keeps the least of the brightest 1 %'s energy (0.70 of the truth's at
worst against 0.89 for random): its 8-pixel blocks of ISO 1600 saturate together on a light.

Mask period. A random mask tiled with a period (``mask_period``, 4 by default) lets patches
share one operator per phase; without tiling (``mask_period=None``: one code per pixel) the
quality is the same on the realistic bench (27.25 against 27.11 dB at 96 x 128), but every patch
has its own operator: minutes instead of seconds at the Lytro size.

Mask transmittances (``mask_transmittance``): ``"uniform"`` (the paper's model: every level of ``[0, 1]`` equally
likely), ``"binary"`` (0 or 1) or ``"mixed"`` (the default since stop 49: 1, 0 or a small level below 1/4:
:data:`lfproc.camera.projection.MIXED_SHARES`). All pass half the light. At a disparity other than 0 a pixel's coded
sum mixes ``V x U`` neighbouring pixels of the centre view; the mean code only blurs them, and what tells them apart
is the code's deviation from its mean, of variance 1/12 for uniform codes, 1/4 binary, 0.23 mixed. What binary codes
lack: small transmittances, through which a light a few pixels wide is seen unsaturated by the shots at high ISO.
Measured (``benchmarks/reconstruct_realistic.py --method gmm --mask-transmittance ...``, 2 random shots, medium noise,
seed 0; ``docs/benchmarks.md``, stop 30), uniform / binary / mixed: tune scenes at the Lytro size 37.95 / 38.46 /
38.73 dB; test scenes 41.89 / 42.94 / 42.72 dB; binary codes lose city-interior's lamp with one shot (53.07 -> 50.76
dB) and with block ISO (0.47 of the brightest 1 %'s energy), mixed codes with one shot too (41.77 dB), until the
lights refit's compact light (stop 42). Stop 41 (``docs/benchmarks.md``) measured mixed codes on every two-shot row of
the test scenes: 0.8-1.7 dB above uniform codes on each mean (noise none / low / medium / high 48.87 / 48.82 / 48.65 /
48.45, row 48.64, block 48.00 dB), but city-interior's lamp keeps 0.78-0.80 of its energy with row and block ISO, and
with one shot it is lost on three draws of three (uniform codes: two of three). Stop 48 measured them on compositions
nobody tuned for (holdout 43.36 -> 44.76 dB, worst decade 0.85 -> 0.49 stops) and stop 49 made them the default, every
README figure measured again (``docs/benchmarks.md``): two shots 47.94 -> 48.86 dB on the test scenes, row 48.83,
block 48.17; one shot 42.85 -> 41.99 and 4-shot bracketing 39.92 -> 37.78 (city-interior's lamp). The tests whose
known answers were measured with uniform codes ask for them.

Baselines (the paper's section III-B and Table IV): ``baseline="individual-iso"`` takes one shot per ISO of the
set, each with one global ISO; ``baseline="bracketing"`` takes 2, 3 or 4 shots at the lowest
ISO of the set with relative exposures ``[0.5, 8]``, ``[0.5, 2, 8]``, ``[0.5, 2, 4, 8]``
(times ``exposure_s``).
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._shared.deprecate import resolve_options
from .._shared.validation import check_choice, check_count, check_positive
from .._shared.random import check_random_state
from .._shared.frozen import freeze
from .._version import __version__
from .iso import DEFAULT_BLOCK_PX, DEFAULT_ISOS, ISO_PATTERNS, _num, describe_iso_pattern, iso_pattern
from .capture import MAX_SHOTS, Capture, _warn_saturation, capture_streams, file_sha256, observations
from ..sensor import expose, load_profile
from ..errors import InputError, ShapeError, ViewCountWarning, option_name
from ..lightfield import LightField, clean_nonfinite
from .projection import MASK_KINDS, MASK_TRANSMITTANCES, build_operator, make_mask
from .. import _untrusted as ut
from ..dictionary import SHIPPED
from ..dictionary._files import dictionary_patch
from ..io import read_lightfield
from ..io._atomic import check_output

__all__ = [
    "ISO_PATTERNS",
    "BASELINES",
    "BRACKETING_EXPOSURES",
    "DEFAULT_ISOS",
    "NOISE_PROFILES",
    "iso_pattern",
    "auto_radiance_scale",
    "REFERENCE_EXPOSURE_S",
    "DEFAULT_MASK_PERIOD",
    "DEFAULT_MASK_TRANSMITTANCE",
    "simulate_capture",
    "CaptureDesign",
    "simulate_file",
    "capture_summary",
]

BASELINES = ("individual-iso", "bracketing")
#: Relative exposures of the bracketing baseline by number of shots (the paper's Table IV).
BRACKETING_EXPOSURES = {2: (0.5, 8.0), 3: (0.5, 2.0, 8.0), 4: (0.5, 2.0, 4.0, 8.0)}
#: ``--noise LEVEL`` -> shipped camera profile (paper Table VI noise levels).
NOISE_PROFILES = {"none": "paper-none", "low": "paper-low", "medium": "paper-medium", "high": "paper-high"}
_NEEDED = ("gain_dn_per_e", "read_noise_e", "dark_current_e_per_s", "black_level_dn", "full_well_e")


def _check_isos(profile, isos: Sequence[float]) -> list[float]:
    values = [float(v) for v in isos]
    if not values:
        raise InputError("isos: expected at least one ISO value")
    for v in values:
        if not math.isfinite(v) or v <= 0:
            raise InputError(f"isos: expected positive ISO values, got {v}")
        profile.require(v, *_NEEDED)  # ProfileError: ISO not in profile, or a needed figure missing
    return values


def _saturation_electrons(profile, iso: float) -> float:
    figs = profile.require(iso, "gain_dn_per_e", "black_level_dn", "full_well_e")
    sat_dn = profile.saturation_dn(iso)
    imax = float(profile.white_level_dn)
    linear_dn = imax * (max(sat_dn - figs["black_level_dn"], 0.0) / imax) ** profile.gamma
    return min(figs["full_well_e"], linear_dn / figs["gain_dn_per_e"])


#: Default tile of a random mask (pixels): patches of a phase share one operator, so a Lytro-size capture
#: reconstructs in seconds (benchmarks/reconstruct_realistic.py; lfproc.recon.reconstruct_gmm needs a tile).
DEFAULT_MASK_PERIOD = 4

#: Default distribution of the mask's transmittances (:func:`lfproc.camera.make_mask`; module notes "Mask
#: transmittances"): 1, 0 or a small level (stop 49; "uniform": the paper's codes; "binary" resolves finer detail
#: and loses small lights).
DEFAULT_MASK_TRANSMITTANCE = "mixed"

#: Exposure (s) at which the automatic radiance scale makes the brightest expected signal saturate.
REFERENCE_EXPOSURE_S = 0.004


def auto_radiance_scale(
    lf: np.ndarray,
    *,
    profile,
    iso: float,
    exposure_s: float,
    mean_transmittance: float = 0.5,
) -> float:
    """The default ``radiance_scale`` (module documentation): electrons/s per light-field unit.

    Parameters
    ----------
    lf : ndarray of shape (V, U, H, W, C)
    profile : CameraProfile or name
    iso : float
        The lowest ISO in use.
    exposure_s : float
        Reference exposure time (s): :data:`REFERENCE_EXPOSURE_S` in :func:`simulate_capture`,
        whatever the shots' exposure.
    mean_transmittance : float
        Expected mask transmittance.
    """
    profile = load_profile(profile)
    peak = float(np.asarray(lf, dtype=np.float64).sum(axis=(0, 1)).max())
    if not peak > 0:
        raise InputError("light field: all samples are zero; cannot choose a radiance scale (give radiance_scale)")
    return _saturation_electrons(profile, iso) / (check_positive("exposure_s", exposure_s) * mean_transmittance * peak)


def _check_memory(shots: int, nv: int, nu: int, h: int, w: int) -> None:
    """Refuse, before anything is allocated, a simulation whose projection operator (one
    float32 weight per shot, view and pixel) would exceed lfproc's array limit."""
    ut.check_nbytes((shots, nv, nu, h, w), np.float32, what=f"simulating {shots} shots of {nv} x {nu} views of "
                    f"{h} x {w} pixels: the projection operator", error=InputError)


def _check_dictionary_views(dictionary, views: tuple[int, int]) -> None:
    """Warn when ``dictionary``'s patch has other views than the light field (reconstruct would refuse)."""
    name, patch = dictionary_patch(dictionary)
    if tuple(patch[:2]) != tuple(views):
        label = f"the shipped dictionary {name!r}" if name in SHIPPED else f"dictionary {name!r}"
        warnings.warn(ViewCountWarning(
            f"the light field has {views[0]} x {views[1]} views; {label} has {patch[0]} x {patch[1]} views, so "
            f"reconstruct will refuse this capture with it (train a dictionary for {views[0]} x {views[1]} views: "
            f"{option_name('lfproc.dictionary.train_dictionary', 'lfproc dictionary train')})"), stacklevel=3)


@dataclass(frozen=True)
class CaptureDesign:
    """How a capture is taken: the options of :func:`simulate_capture` besides the light field,
    the random state and the records (see its parameters for each field). Values are validated
    by :func:`simulate_capture`.

    Parameters
    ----------
    profile, iso_pattern_kind, isos, shots, exposure_s, gamma, mask, mask_period, mask_shift, block_px
        The keywords of :func:`simulate_capture` of the same names, with the same defaults.
    baseline, relative_exposures, radiance_scale, reference_exposure_s, noise
        As well.

    Examples
    --------
    >>> from lfproc.camera import CaptureDesign, simulate_capture
    >>> from lfproc.synth import synthesize
    >>> design = CaptureDesign(profile="paper-medium", shots=2)
    >>> capture = simulate_capture(synthesize("layers", size=(16, 16), random_state=0), design=design, random_state=0)
    >>> capture.shots, capture.iso.shape
    (2, (2, 16, 16))
    """
    profile: Any = "paper-low"
    iso_pattern_kind: str | os.PathLike = "random"
    isos: Sequence[float] = DEFAULT_ISOS
    shots: int = 1
    exposure_s: float = 0.004
    gamma: float | None = None
    mask: str = "random"
    mask_transmittance: str = DEFAULT_MASK_TRANSMITTANCE
    mask_period: int | None | str = "default"
    mask_shift: int = 1
    block_px: int = DEFAULT_BLOCK_PX
    baseline: str | None = None
    relative_exposures: Sequence[float] | None = None
    radiance_scale: float | None = None
    reference_exposure_s: float = REFERENCE_EXPOSURE_S
    noise: bool = True


def _light_field_data(lf) -> np.ndarray:
    """The radiance of ``lf`` (a LightField or an array ``(V, U, H, W, 3)``), checked: 3 colours, finite, >= 0."""
    if isinstance(lf, LightField):
        data = lf.data
    else:
        data = np.asarray(lf, dtype=np.float32)
        if data.ndim != 5:
            raise ShapeError(f"light field: expected shape (V, U, H, W, C), got {data.shape}")
        data, _ = clean_nonfinite(data, policy="raise", negative="raise", name="light field")
    if data.shape[-1] != 3:
        raise ShapeError(f"light field: a Bayer sensor needs 3 colour channels, this one has {data.shape[-1]}")
    if (data < 0).any() or not np.isfinite(data).all():
        raise InputError("light field: expected finite, non-negative radiance")
    return data


def _checked_design(design: CaptureDesign, profile, shape) -> CaptureDesign:
    """``design`` validated against the profile and the light field's ``shape`` (V, U, H, W, C): exposure,
    gamma, mask and baseline names, the shot count (and the memory it needs), the ISO set."""
    nv, nu, h, w, _ = shape
    exposure_s = check_positive("exposure_s", design.exposure_s)
    gamma = design.gamma
    if gamma is not None:
        gamma = check_positive("gamma", gamma)
        if gamma < 1:
            raise InputError(f"gamma: expected a value >= 1, got {gamma}")
    check_choice("mask", design.mask, MASK_KINDS)
    check_choice("mask_transmittance", design.mask_transmittance, MASK_TRANSMITTANCES)
    if design.baseline is not None:
        check_choice("baseline", design.baseline, BASELINES)
    shots, relative_exposures = design.shots, design.relative_exposures
    if isinstance(shots, bool) or not isinstance(shots, (int, np.integer, float)) or not np.isfinite(shots) \
            or int(shots) != shots or int(shots) < 1:
        raise InputError(f"shots: expected an integer >= 1, got {shots!r}")
    shots = check_count("shots", shots, high=MAX_SHOTS)
    if relative_exposures is not None:
        check_count("relative exposures (one per shot)", len(list(relative_exposures)), high=MAX_SHOTS)
    _check_memory(max(shots, len(relative_exposures or ())), nv, nu, h, w)
    return replace(design, profile=profile, exposure_s=exposure_s, gamma=gamma, shots=shots,
                   isos=_check_isos(profile, design.isos))


def _seeded(random_state) -> tuple[np.random.Generator, Any]:
    """The generator of ``random_state`` and the seed recorded for it (None draws one; a Generator: "generator")."""
    if random_state is None:
        seed: Any = int(np.random.SeedSequence().entropy % (2**63))
        return check_random_state(seed), seed
    rng = check_random_state(random_state)
    return rng, int(random_state) if isinstance(random_state, (int, np.integer)) else "generator"


def _shot_plan(design: CaptureDesign, size: tuple[int, int], rng) -> tuple[np.ndarray, dict, list[float]]:
    """Per-shot ISO maps ``(S, H, W)``, the ISO layout's record and the relative exposures, for the
    design's baseline or ISO pattern (module documentation)."""
    h, w = size
    isos, shots, relative_exposures = design.isos, design.shots, design.relative_exposures
    if design.baseline == "individual-iso":
        shots = len(isos)
        iso_maps = np.stack([np.full((h, w), v, dtype=np.float32) for v in isos])
        iso_info = {"kind": "global", "baseline": design.baseline, "isos": [_num(v) for v in isos]}
        rel = [1.0] * shots if relative_exposures is None else [float(r) for r in relative_exposures]
    elif design.baseline == "bracketing":
        if relative_exposures is None:
            if shots not in BRACKETING_EXPOSURES:
                raise InputError(f"shots: the bracketing baseline takes 2, 3 or 4 shots, got {shots}")
            rel = list(BRACKETING_EXPOSURES[shots])
        else:
            rel = [float(r) for r in relative_exposures]
            shots = len(rel)
        iso0 = min(isos)
        iso_maps = np.full((shots, h, w), iso0, dtype=np.float32)
        iso_info = {"kind": "global", "baseline": design.baseline, "isos": [_num(iso0)]}
    else:
        one = iso_pattern(design.iso_pattern_kind, size=(h, w), isos=isos, block_px=design.block_px,
                          random_state=rng)
        used = np.unique(one)
        _check_isos(design.profile, used)
        iso_maps = np.broadcast_to(one, (shots, h, w)).copy()
        iso_info = describe_iso_pattern(design.iso_pattern_kind, used, block_px=design.block_px)
        rel = [1.0] * shots if relative_exposures is None else [float(r) for r in relative_exposures]
    if len(rel) != shots:
        raise InputError(f"relative exposures: expected {shots} values (one per shot), got {len(rel)}")
    return iso_maps, iso_info, rel


def _scale_of(design: CaptureDesign, data: np.ndarray, iso_min: float) -> tuple[float, str, float]:
    """The radiance scale (e-/s per light-field unit), its rule, and the checked reference exposure."""
    reference_exposure_s = check_positive("reference_exposure_s", design.reference_exposure_s)
    if design.radiance_scale is None:
        scale = auto_radiance_scale(data, profile=design.profile, iso=iso_min, exposure_s=reference_exposure_s)
        return scale, ("auto: brightest expected signal (mean transmittance 0.5) saturates the lowest ISO at "
                       "reference_exposure_s"), reference_exposure_s
    return check_positive("radiance_scale", design.radiance_scale), "given", reference_exposure_s


def _mask_period(design: CaptureDesign) -> int | None:
    mask_period = design.mask_period
    if isinstance(mask_period, str):
        if mask_period != "default":
            raise InputError(f"mask_period: expected a period in pixels, None or 'default', got {mask_period!r}")
        mask_period = DEFAULT_MASK_PERIOD if design.mask == "random" else None
    return mask_period


def _parameters(design: CaptureDesign, lf, *, seed, profile, iso_info, rel, mask_period, scale_rule,
                reference_exposure_s) -> dict[str, Any]:
    """The simulation's record in the capture (``parameters`` of its file)."""
    return {
        "source": "simulate",
        "lfproc_version": __version__,
        "seed": seed,
        "profile": profile.name,
        "iso_pattern": iso_info["kind"],
        "isos_requested": [_num(v) for v in design.isos],
        "shots": len(rel),
        "exposure_s": design.exposure_s,
        "relative_exposures": rel,
        "gamma": design.gamma,
        "mask": design.mask,
        "mask_transmittance": design.mask_transmittance,
        "mask_period": mask_period,
        "mask_shift": int(design.mask_shift),
        "baseline": design.baseline,
        "noise": bool(design.noise),
        "radiance_scale_rule": scale_rule,
        "reference_exposure_s": reference_exposure_s if design.radiance_scale is None else None,
        "light_field_source": lf.source if isinstance(lf, LightField) else None,
        "light_field_units": lf.units if isinstance(lf, LightField) else None,
    }


def simulate_capture(
    lf: LightField | np.ndarray,
    *,
    design: CaptureDesign | None = None,
    random_state=None,
    ground_truth: dict | None = None,
    dictionary=None,
    **design_options,
) -> Capture:
    """Simulate a capture of a light field (see the module documentation).

    Parameters
    ----------
    lf : LightField or ndarray of shape (V, U, H, W, 3)
        Linear HDR radiance (relative units unless ``radiance_scale`` says otherwise);
        finite and non-negative.
    design : CaptureDesign, optional
        The capture's design: every parameter below from ``profile`` to ``noise``. Give either
        ``design`` or its fields as keywords (``**design_options``), not both.
    profile : CameraProfile, shipped name or path, default "paper-low"
        Camera profile (``paper-none|low|medium|high`` for the paper's noise levels).
    iso_pattern_kind : {"random", "row", "block", "dual"} or path, default "random"
        Per-pixel ISO layout (ignored by the baselines, which use global ISOs).
    isos : sequence of float, default (100, 400, 800, 1600)
        The ISO set; each must be in the profile.
    shots : int, default 1
        Number of shots (each its own mask code). For ``bracketing``: 2, 3 or 4.
    exposure_s : float, default 0.004
        Exposure time of a shot (s); the reference for ``relative_exposures``.
    gamma : float, optional
        Power-law response (default: the profile's).
    mask : {"random", "shifted"}, default "random"
    mask_transmittance : {"uniform", "binary", "mixed"}, default "mixed"
        Every level equally likely (the paper's), 0 / 1, or 0 / 1 / small levels (module notes).
    mask_period : int, None or "default", default "default"
        Tile the mask with this period (pixels); ``"default"``: :data:`DEFAULT_MASK_PERIOD` (4) for
        ``random``, none for ``shifted``; None: no tiling (module documentation).
    mask_shift : int, default 1
        Pixels of mask shift per view step (``shifted``).
    block_px : int, default 8 (the ``block`` ISO pattern's)
    baseline : {None, "individual-iso", "bracketing"}, default None
    relative_exposures : sequence of float, optional
        Exposure of each shot relative to ``exposure_s`` (default 1, or the bracketing table).
    radiance_scale : float, optional
        Electrons per second per light-field unit; default: automatic (module documentation).
    reference_exposure_s : float, default 0.004
        Exposure (s) at which the automatic scale saturates the brightest expected signal.
    noise : bool, default True
        False: noiseless expected codes (still quantised and clipped).
    random_state : int, Generator or None
        Seeds the mask, the random ISO map and the noise. None draws a seed and records it.
    ground_truth : dict, optional
        ``{"path", "sha256"}`` of the light-field file, recorded in the capture.
    dictionary : Dictionary, shipped name, path or None
        The dictionary the capture is meant for: a :class:`~lfproc.errors.ViewCountWarning` when
        its views differ from the light field's (:func:`lfproc.recon.reconstruct` would refuse
        the capture). None (default): no check (``lfproc simulate`` checks ``"default"``).

    Returns
    -------
    Capture

    Raises
    ------
    TypeError
        ``design`` together with field keywords, or an unknown keyword.

    Warns
    -----
    ViewCountWarning
        The light field's views do not match ``dictionary``'s patch.
    SaturationWarning
        More than :data:`lfproc.errors.SATURATION_WARNING_FRACTION` of the least sensitive pixels
        are saturated.

    Examples
    --------
    >>> from lfproc.synth import synthesize
    >>> from lfproc.camera import simulate_capture
    >>> lf = synthesize("window", size=(24, 24), views=5, random_state=0)  # 5 x 5 views, 24 x 24 px
    >>> capture = simulate_capture(lf, shots=2, mask_period=4, random_state=0)
    >>> capture.shots, capture.dn.shape, capture.isos
    (2, (2, 24, 24), [100.0, 400.0, 800.0, 1600.0])
    >>> f"{100 * capture.sampling_rate:.2f} %"  # 2 sensor images for 5 * 5 * 3 unknowns per pixel
    '2.67 %'
    """
    design = resolve_options(CaptureDesign, design, design_options, func_name="simulate_capture", argument="design")
    profile = load_profile(design.profile)
    data = _light_field_data(lf)
    nv, nu, h, w, _ = data.shape
    design = _checked_design(design, profile, data.shape)
    rng, seed = _seeded(random_state)
    iso_rng, mask_rng, noise_rng = capture_streams(rng)  # module notes: random streams
    iso_maps, iso_info, rel = _shot_plan(design, (h, w), iso_rng)
    shots = len(rel)
    exposures = [check_positive("exposure_s", design.exposure_s * r) for r in rel]

    # -- radiance scale, mask, projection, exposure -------------------------------------------
    scale, scale_rule, reference_exposure_s = _scale_of(design, data, float(iso_maps.min()))
    mask_period = _mask_period(design)
    code = make_mask(design.mask, shots=shots, views=(nv, nu), size=(h, w), period=mask_period,
                     shift=design.mask_shift, random_state=mask_rng, transmittance=design.mask_transmittance)
    cfa = profile.cfa_pattern
    op = build_operator(code, views=(nv, nu), size=(h, w), cfa_pattern=cfa)
    irradiance = op.forward(data) * np.float32(scale)  # (S, H, W) e-/s
    dn = np.stack([
        expose(irradiance[s].astype(np.float64), exposure_s=exposures[s], iso=iso_maps[s], profile=profile,
               gamma=design.gamma, noise=design.noise, random_state=noise_rng)
        for s in range(shots)
    ])
    parameters = _parameters(design, lf, seed=seed, profile=profile, iso_info=iso_info, rel=rel,
                             mask_period=mask_period, scale_rule=scale_rule,
                             reference_exposure_s=reference_exposure_s)
    capture = Capture(dn=freeze(dn), iso=freeze(iso_maps), exposures_s=exposures, mask=code, profile=profile,
                      views=(nv, nu), cfa_pattern=cfa, gamma=design.gamma, radiance_scale=scale,
                      ground_truth=ground_truth, iso_pattern=iso_info, parameters=parameters)
    _warn_saturation(capture, stacklevel=4)
    if dictionary is not None:  # last: a capture that cannot be made is refused first
        _check_dictionary_views(dictionary, (nv, nu))
    return capture


def capture_summary(capture: Capture, *, path: str | os.PathLike | None = None) -> dict[str, Any]:
    """Figures of a capture: shots, size, sampling rate, saturated and black-clipped fractions."""
    obs = observations(capture, warn_saturation=False)  # reported in the figures
    per_iso = {}
    for value in capture.isos:
        sel = capture.iso == value
        per_iso[str(_num(value))] = {
            "saturated_fraction": float(obs.saturated[sel].mean()),
            "black_clipped_fraction": float(obs.black_clipped[sel].mean()),
        }
    out: dict[str, Any] = {"kind": "capture"}
    if path is not None:
        out["output"] = str(path)
    rate = 100.0 * capture.sampling_rate
    out.update({
        "shots": capture.shots,
        "size": list(capture.size),
        "views": list(capture.views),
        "sampling_rate": f"{rate:.2f} %",
        "sampling_rate_percent": rate,
        "saturated_fraction": obs.saturated_fraction,
        "black_clipped_fraction": obs.black_clipped_fraction,
        "isos": [_num(v) for v in capture.isos],
        "per_iso": per_iso,
        "exposures_s": list(capture.exposures_s),
        "iso_pattern": capture.iso_pattern.get("kind"),
        "mask": capture.mask.kind,
        "profile": capture.profile.name,
        "radiance_scale": capture.radiance_scale,
        "seed": capture.parameters.get("seed"),
    })
    return out


def simulate_file(
    input_path: str | os.PathLike,
    output_path: str | os.PathLike,
    *,
    force: bool = False,
    nonfinite: str = "raise",
    negative: str = "raise",
    dictionary="default",
    **options,
) -> tuple[Capture, dict[str, Any]]:
    """Read a light field, simulate a capture (:func:`simulate_capture` ``options``), write it.

    ``dictionary`` (default: the shipped ``"default"``) is the dictionary the capture is meant
    for: a :class:`~lfproc.errors.ViewCountWarning` when its views differ (None: no check).

    NaN/Inf or negative radiance in the input is refused unless ``nonfinite`` (``"zero"``,
    ``"clip"``) or ``negative`` (``"clip"``: set to 0, as for the tiny negatives of lossy EXR
    compression) say otherwise (:func:`lfproc.lightfield.clean_nonfinite`). The capture records
    the input's path and SHA-256 as its ground truth.

    Parameters
    ----------
    input_path : str or path-like
        The HDR light field to read (any format :func:`lfproc.io.read_lightfield` reads).
    output_path : str or path-like
        The capture file to write (``.npz``, see :meth:`Capture.save`).
    force : bool, default False
        Overwrite ``output_path`` when it exists.
    nonfinite : {"raise", "zero", "clip"}, default "raise"
        What to do with NaN/Inf input samples.
    negative : {"raise", "clip"}, default "raise"
        What to do with negative input samples.
    dictionary : str, path-like, Dictionary or None, default "default"
        The dictionary the capture is meant for (checked for the number of views only).
    **options
        Passed to :func:`simulate_capture` (``iso_pattern_kind``, ``shots``, ``random_state``, ...).

    Returns
    -------
    capture : Capture
        The simulated capture, as written.
    summary : dict
        Its figures (:func:`capture_summary`), with the output path.

    Raises
    ------
    OutputExistsError
        ``output_path`` exists and ``force`` is false.
    MissingFileError, FileFormatError
        The input cannot be read.
    InputError
        NaN/Inf or negative radiance refused, or an invalid option.
    """
    check_output(output_path, force=force)
    lf = read_lightfield(input_path, nonfinite=nonfinite, negative=negative)
    truth = {"path": str(Path(input_path).resolve()), "sha256": file_sha256(input_path)}
    capture = simulate_capture(lf, ground_truth=truth, dictionary=dictionary, **options)
    capture.save(output_path, force=force)
    return capture, capture_summary(capture, path=output_path)
