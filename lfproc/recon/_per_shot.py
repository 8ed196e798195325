"""The paper's baselines as reconstruction modes on top of :func:`lfproc.recon.reconstruct`.

Miandji et al. ("Compressive HDR light field imaging using a single multi-ISO sensor",
IEEE TCI 2021, section III-B) compare the joint multi-ISO reconstruction with acquisitions that
reconstruct every shot on its own and merge the results:

* **individual ISO** -- one single-ISO coded shot per ISO of the set
  (``simulate_capture(..., baseline="individual-iso")``);
* **exposure bracketing** -- 2, 3 or 4 coded shots at the lowest ISO with relative exposures
  ``[0.5, 8]``, ``[0.5, 2, 8]``, ``[0.5, 2, 4, 8]`` (``baseline="bracketing"``).

:func:`reconstruct_per_shot` is that mode: every shot of the capture is reconstructed alone
(:func:`split_shots`, then :func:`lfproc.recon.reconstruct` with the same dictionary and
options), *re-exposed* into the sensor codes its shot would have recorded for each view
sample (:func:`reexpose`), and the shots are merged view by view with lfproc's HDR merge:
``"debevec"`` (Debevec & Malik's hat weights on the normalised codes, the paper's choice;
:func:`lfproc.merge.merge_debevec`) and/or ``"ml"`` (the noise-aware maximum-likelihood merge,
:func:`lfproc.merge.merge_ml`, with the capture's camera profile). lfproc's own variant of
bracketing, all shots reconstructed *jointly in one solve*, needs no code here: it is
:func:`lfproc.recon.reconstruct` of the bracketing capture (the solve weighs every shot by
its own exposure and noise).

Choices lfproc makes where the paper is silent or different (each documented here and in
the bench report):

* **Dictionary.** The paper reconstructs each LDR shot with a dictionary trained on LDR
  data. lfproc reconstructs each shot with the *same* dictionary as the joint method: its
  patches are l2-normalised, so it is free of scale, and lfproc's reconstruction drops the
  saturated and black-clipped measurements (weight 0) instead of fitting their clipped
  values, which leaves nothing LDR-specific for a dictionary to learn. What remains of
  "LDR" is which samples a shot can vouch for, and that is the next point.
* **Re-exposure and saturation guard.** A reconstructed view sample ``L`` is mapped to the
  code a pixel of the shot's ISO ``i`` and exposure ``t`` would give if it saw that view
  with the mask's mean total transmittance ``r`` (``sum over views`` of the mean code:
  about 12.5 for 5 x 5 views of a uniform [0, 1] mask; one ``r`` for all the shots merged,
  lowered if needed so that the least exposed shot's reconstruction stays below saturation:
  a view brighter than the mean of the views at its pixel must not come out clipped in every
  shot): ``e = t (K r L + I_dark)`` electrons
  (``K`` the capture's ``radiance_scale``), clipped at the full well, times the gain
  ``h(i)``, through the profile's power law, plus the black level, clipped at the white
  level. Samples above the shot's saturation come out saturated, so both merges ignore
  them, as they would ignore a clipped LDR pixel. Samples the shot could not measure
  (a sensor pixel saturated in that shot, or one of its 3 x 3 neighbours, whose Bayer
  colours share the support) are set to the white level too: the per-shot solve fills them
  in from the dictionary alone, and a merge must not trust that.
* **Units.** The merged radiance (e-/s of that ideal pixel for ``ml``, relative for
  ``debevec``) is converted back to the units of the light field the capture was simulated
  from, like :func:`lfproc.recon.reconstruct`'s output, so it is scored the same way.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._shared.validation import check_choice
from .._version import __version__
from ..errors import InputError, SaturationWarning
from ..lightfield import LightField
from ..camera.capture import Capture, load_capture, observations
from ..camera.simulate import _saturation_electrons
from ..dictionary import Dictionary, load_dictionary
from ..hdr import merge_debevec, merge_ml
from ._gmm import reconstruct_gmm
from ._reconstruct import reconstruct

__all__ = ["MERGES", "split_shots", "reexpose", "merge_reconstructions", "reconstruct_per_shot"]

#: Merges :func:`reconstruct_per_shot` offers (see :mod:`lfproc.merge`).
MERGES = ("debevec", "ml")
_ML_UPDATES = 6


def split_shots(capture) -> list:
    """One single-shot :class:`~lfproc.camera.capture.Capture` per shot of ``capture`` (nothing copied in place).

    Parameters
    ----------
    capture : Capture

    Returns
    -------
    list of Capture
        ``capture.shots`` captures of one shot each (its DN, ISO map, exposure, mask code and
        bias); ``parameters["split_from_shot"]`` records the shot.

    Raises
    ------
    InputError
        ``capture`` is not a :class:`~lfproc.camera.capture.Capture`.

    Examples
    --------
    >>> from lfproc.camera import simulate_capture
    >>> from lfproc.recon import split_shots
    >>> from lfproc.synth import synthesize
    >>> lf = synthesize("window", size=(24, 24), views=5, random_state=0)
    >>> capture = simulate_capture(lf, baseline="individual-iso", mask_period=4, random_state=0)
    >>> [(s.shots, s.isos) for s in split_shots(capture)]  # one global ISO per shot
    [(1, [100.0]), (1, [400.0]), (1, [800.0]), (1, [1600.0])]
    """
    if not isinstance(capture, Capture):
        raise InputError(f"split_shots: expected a Capture, got {type(capture).__name__}")
    out = []
    for s in range(capture.shots):
        mask = dataclasses.replace(capture.mask, codes=capture.mask.codes[s:s + 1])
        out.append(dataclasses.replace(
            capture,
            dn=capture.dn[s:s + 1],
            iso=capture.iso[s:s + 1],
            exposures_s=(capture.exposures_s[s],),
            mask=mask,
            bias_dn=None if capture.bias_dn is None else capture.bias_dn[s:s + 1],
            parameters={**capture.parameters, "split_from_shot": s},
        ))
    return out


def _mean_view_transmittance(capture) -> float:
    """Mean over pixels of the total transmittance of a pixel, summed over views (one number per capture)."""
    v_n, u_n = capture.views
    return float(np.mean(capture.mask.codes, dtype=np.float64)) * v_n * u_n


def _radiance_scale(capture) -> float:
    if capture.radiance_scale is None:
        raise InputError("capture: no radiance_scale (a real capture); per-shot merging needs a simulated capture's "
                         "scale to map reconstructions to sensor codes")
    return float(capture.radiance_scale)


def reexpose(lf: LightField, shot, *, transmittance: float | None = None,
             guard: np.ndarray | None = None) -> np.ndarray:
    """Sensor codes (DN, float64) one shot would record for every view sample of ``lf`` (module notes).

    Parameters
    ----------
    lf : LightField
        A reconstruction in the units of the light field the capture was simulated from.
    shot : Capture
        A single-shot capture with one global ISO (what :func:`split_shots` returns for the
        individual-ISO and bracketing captures).
    transmittance : float, optional
        Total transmittance of the ideal pixel (sum over views); default: the shot's mean.
        Shots that are merged must share one value (:func:`merge_reconstructions` passes the
        mean over all of them), else each shot's mask draw would bias its share.
    guard : ndarray of bool, shape (H, W), optional
        Sensor pixels whose samples are set to the white level (saturated).

    Returns
    -------
    ndarray of shape (V, U, H, W, C)

    Raises
    ------
    InputError
        ``shot`` is not a single shot of one global ISO.
    """
    isos = np.unique(shot.iso)
    if shot.shots != 1 or isos.size != 1:
        raise InputError(f"reexpose: expected a single shot with one global ISO, got {shot.shots} shots and ISOs "
                         f"{isos.tolist()}")
    iso = float(isos[0])
    prof = shot.profile
    figs = prof.require(iso, "gain_dn_per_e", "black_level_dn", "full_well_e", "dark_current_e_per_s")
    t = float(shot.exposures_s[0])
    if transmittance is None:
        transmittance = _mean_view_transmittance(shot)
    scale = _radiance_scale(shot) * float(transmittance)
    electrons = t * (lf.data.astype(np.float64) * scale + figs["dark_current_e_per_s"])
    electrons = np.minimum(electrons, figs["full_well_e"])
    imax = float(prof.white_level_dn)
    gamma = float(shot.gamma)
    signal = imax * np.power(np.maximum(figs["gain_dn_per_e"] * electrons / imax, 0.0), 1.0 / gamma)
    dn = np.clip(signal + figs["black_level_dn"], 0.0, imax)
    if guard is not None:
        dn[:, :, np.asarray(guard, dtype=bool), :] = imax
    return dn


def _ideal_transmittance(reconstructions, shots) -> float:
    """One ideal pixel for every shot: the mean total transmittance, lowered where needed so the
    least exposed shot's reconstruction saturates it nowhere (module notes)."""
    r = float(np.mean([_mean_view_transmittance(s) for s in shots]))
    prof = shots[0].profile
    isos = [float(np.unique(s.iso)[0]) for s in shots]
    gains = [prof.require(i, "gain_dn_per_e")["gain_dn_per_e"] for i in isos]
    ref = int(np.argmin([s.exposures_s[0] * g for s, g in zip(shots, gains)]))
    t = float(shots[ref].exposures_s[0])
    dark = prof.require(isos[ref], "dark_current_e_per_s")["dark_current_e_per_s"]
    peak = float(reconstructions[ref].data.max())
    room = _saturation_electrons(prof, isos[ref]) / t - dark
    if peak > 0 and room > 0:
        r = min(r, 0.98 * room / (_radiance_scale(shots[ref]) * peak))
    return r


def _guard(shot, dilate: int) -> np.ndarray:
    from scipy.ndimage import binary_dilation

    sat = observations(shot, warn_saturation=False).saturated[0]
    if dilate > 0 and sat.any():
        sat = binary_dilation(sat, structure=np.ones((2 * dilate + 1, 2 * dilate + 1), bool))
    return sat


def merge_reconstructions(
    reconstructions: Sequence[LightField],
    shots: Sequence,
    *,
    merge: str = "debevec",
    guard_px: int = 1,
) -> LightField:
    """Merge per-shot reconstructions view by view (module notes); returns the light-field units.

    Parameters
    ----------
    reconstructions : sequence of LightField
        ``reconstruct(shot)`` of every shot, in shot order.
    shots : sequence of Capture
        The single-shot captures (:func:`split_shots`).
    merge : {"debevec", "ml"}, default "debevec"
        Debevec-Malik hat weights, or the noise-aware maximum-likelihood merge.
    guard_px : int, default 1
        Radius of the saturation guard (0: only the saturated pixels themselves).

    Returns
    -------
    LightField
        ``(V, U, H, W, 3)`` in the units of the light field the captures were simulated from.

    Raises
    ------
    InputError
        An unknown merge, not one reconstruction per shot, fewer than two shots, a bad ``guard_px``.
    """
    check_choice("merge", merge, MERGES)
    if len(reconstructions) != len(shots) or len(shots) < 2:
        raise InputError(f"merge: expected one reconstruction per shot and at least two shots, got "
                         f"{len(reconstructions)} reconstructions for {len(shots)} shots")
    if isinstance(guard_px, bool) or int(guard_px) != guard_px or guard_px < 0:
        raise InputError(f"guard_px: expected a non-negative integer, got {guard_px!r}")
    prof = shots[0].profile
    r = _ideal_transmittance(reconstructions, shots)
    stack = np.stack([reexpose(lf, s, transmittance=r, guard=_guard(s, int(guard_px)))
                      for lf, s in zip(reconstructions, shots)])
    t = np.array([s.exposures_s[0] for s in shots])
    iso = np.array([float(np.unique(s.iso)[0]) for s in shots])
    scale = _radiance_scale(shots[0]) * r
    if merge == "ml":
        # the codes are ideal (noise-free) samples; merge_ml weighs them by the noise each shot
        # would have had there, which is what tells a short, low-gain shot from a long one
        # more fixed-point updates than merge_ml's default 2: reconstructions put samples right at
        # the edges of the shots' ranges, where the weights take a few more updates to settle
        radiance, _, info = merge_ml(stack, exposures_s=t, isos=iso, profile=prof, gamma=float(shots[0].gamma),
                                     max_iter=_ML_UPDATES, n_threads=1)
        data = radiance / scale
    else:
        if float(shots[0].gamma) != 1.0:
            raise InputError("merge debevec: the per-shot merge of linear codes needs a linear sensor (gamma 1)")
        # the gain enters the exposure (as ISO does in lfproc.merge.merge_lightfields): with
        # exposures t * h(ISO) the merged value is (dn - black) / (span t h) = electrons/s / span
        gains = np.array([prof.require(i, "gain_dn_per_e")["gain_dn_per_e"] for i in iso])
        span = float(prof.white_level_dn) - float(prof.black_level_dn)
        radiance, info = merge_debevec(stack, exposures_s=t * gains, white_level=float(prof.white_level_dn),
                                       black_level=float(prof.black_level_dn), n_threads=1)
        data = radiance * span / scale
    data = np.maximum(np.nan_to_num(data, nan=0.0, posinf=0.0), 0).astype(np.float32)
    first = reconstructions[0]
    attrs = {"per_shot_merge": {
        "merge": merge, "shots": len(shots), "exposures_s": t.tolist(), "isos": iso.tolist(), "guard_px": int(guard_px),
        "saturated_everywhere_fraction": float(info["saturated_everywhere_fraction"]),
        "lfproc_version": __version__,
    }}
    return LightField(data=data, units=first.units, colour_space=first.colour_space, source=f"per-shot:{merge}",
                      attrs=attrs)


def reconstruct_per_shot(
    capture,
    dictionary="default",
    *,
    merges: Sequence[str] = ("debevec",),
    guard_px: int = 1,
    method: str = "dictionary",
    **options: Any,
) -> dict[str, LightField]:
    """Reconstruct every shot on its own and merge the results (the paper's baselines; module notes).

    Parameters
    ----------
    capture : Capture or path
        A capture whose shots each have one global ISO: ``simulate_capture(...,
        baseline="individual-iso" | "bracketing")``.
    dictionary : as for :func:`lfproc.recon.reconstruct`
        With ``method="dictionary"``; ``method="gmm"`` takes only ``"default"`` here (its model is
        an option, ``model=``).
    merges : sequence of {"debevec", "ml"}
        The merges to return (the per-shot reconstructions are shared).
    guard_px : int
        Radius of the saturation guard (module notes).
    method : {"dictionary", "gmm"}
        Reconstruct each shot with :func:`lfproc.recon.reconstruct` or
        :func:`lfproc.recon.reconstruct_gmm` (a periodic mask).
    **options
        Passed to the reconstruction (solver, mu, max_iter, stride...; for gmm: model, stride...).

    Returns
    -------
    dict
        merge name -> LightField in the units of the simulated light field;
        ``attrs["per_shot_merge"]`` records the merge, and ``attrs["reconstruction"]`` the
        first shot's reconstruction settings, the per-shot records (``per_shot``), the
        patches and empty patches summed over the shots, and the total seconds.

    Raises
    ------
    InputError
        No merges or an unknown one, fewer than two shots, a shot with a per-pixel ISO
        pattern, a dictionary with ``method="gmm"``.

    Examples
    --------
    Exposure bracketing with two coded shots (relative exposures 0.5 and 8), each reconstructed
    with the shipped dictionary, merged both ways:

    >>> from lfproc import evaluate, simulate_capture
    >>> from lfproc.recon import reconstruct_per_shot
    >>> from lfproc.synth import synthesize
    >>> truth = synthesize("window", size=(24, 24), views=5, random_state=0)
    >>> capture = simulate_capture(truth, baseline="bracketing", shots=2, mask_period=4, random_state=0)
    >>> capture.exposures_s
    (0.002, 0.032)
    >>> merged = reconstruct_per_shot(capture, merges=("debevec", "ml"), progress_bar=False)
    >>> sorted(merged), merged["ml"].shape
    (['debevec', 'ml'], (5, 5, 24, 24, 3))
    >>> bool(10 < evaluate(merged["ml"], truth)["pu21_psnr_db"] < 40)
    True
    """
    if not isinstance(capture, Capture):
        capture = load_capture(capture)
    merges = list(merges)
    if not merges:
        raise InputError("merges: expected at least one of debevec, ml")
    for m in merges:
        check_choice("merge", m, MERGES)
    if capture.shots < 2:
        raise InputError(f"capture: per-shot reconstruction and merging needs at least two shots, got {capture.shots}")
    for s in range(capture.shots):
        if np.unique(capture.iso[s]).size != 1:
            raise InputError(f"capture: shot {s + 1} has a per-pixel ISO pattern; per-shot merging takes shots of one "
                             "global ISO each (baseline individual-iso or bracketing)")
    check_choice("method", method, ("dictionary", "gmm"))
    if method == "gmm":
        if not (isinstance(dictionary, str) and dictionary == "default"):
            raise InputError("dictionary: method 'gmm' reconstructs with a patch model (model=...), not a dictionary")
    elif not isinstance(dictionary, Dictionary):
        dictionary = load_dictionary(dictionary)
    started = time.perf_counter()
    observations(capture)  # SaturationWarning when the capture's least sensitive shot saturates
    shots = split_shots(capture)
    with warnings.catch_warnings():
        # each higher-ISO or longer shot saturates by design; the capture was checked as a whole above
        warnings.simplefilter("ignore", SaturationWarning)
        recs = [reconstruct_gmm(s, **options) if method == "gmm" else reconstruct(s, dictionary, **options)
                for s in shots]
    recon_seconds = time.perf_counter() - started
    out = {}
    for m in merges:
        t0 = time.perf_counter()
        lf = merge_reconstructions(recs, shots, merge=m, guard_px=guard_px)
        per = [r.attrs["reconstruction"] for r in recs]
        # the first shot's settings, with the figures summed or averaged over the shots
        record = {**per[0], "patches": int(sum(p["patches"] for p in per)),
                  "empty_patches": int(sum(p.get("empty_patches", 0) for p in per)),
                  "iterations_mean": float(np.mean([p.get("iterations_mean", math.nan) for p in per])),
                  "per_shot": per, "seconds": recon_seconds + time.perf_counter() - t0,
                  "mode": "per-shot", "merge": m}
        out[m] = lf.replace(attrs={**lf.attrs, "reconstruction": record})
    if not all(math.isfinite(float(v.data.max())) for v in out.values()):
        raise InputError("per-shot merge produced non-finite values")  # pragma: no cover - guarded above
    return out
