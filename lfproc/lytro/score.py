"""Scoring a decode against the views a virtual capture saw (``truth.exr`` of ``lfproc virtual-illum``).

One definition, used by the tests, ``lfproc demo`` and ``benchmarks/decode_illum.py``:

* **Samples scored**: every view, pixel and colour inside a ``border``-pixel margin whose truth the
  capture could record. A truth value at or above the capture's saturation level (the value that
  fills the ADC, or the full well, at full transmission: :func:`clip_level`) was clipped by the
  sensor and carries no information; it is left out. Samples the decoder itself flags as unusable
  are *scored* (a decoder does not choose what it is judged on), so two decoders are compared
  on the same samples.
* **Peak**: the 99.9th percentile of the scored truth values, not their maximum: a scene with a
  small, very bright source (a sun 500 times brighter than the rest) would otherwise give an
  inflated figure.
* ``PSNR = 10 log10(peak^2 / mean((decoded - truth)^2))``, linear values.

A decoder whose output has another scale (PlenoptiCam normalises its views) is scored after a
least-squares gain ``g = <d, t> / <d, d>`` over the scored samples (``fit_gain=True``); the gain
is reported.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ShapeError
from ..sensor import load_profile

__all__ = ["clip_level", "decode_psnr", "score_decode", "PEAK_PERCENTILE", "BORDER_PX"]

PEAK_PERCENTILE = 99.9
BORDER_PX = 4


def clip_level(info: dict[str, Any], *, profile="illum") -> float:
    """The truth value (decoder units: 1.0 = as bright as the white image) at which the capture
    of ``info`` (``truth.json`` of ``lfproc virtual-illum``) saturates a pixel at full
    transmission: ``min(full well, (white - black) / gain) / white-image electrons``."""
    prof = load_profile(profile)
    iso = next((c.get("iso") for c in info.get("captures", []) if c.get("file") == info.get("truth_capture")), 100)
    gain = prof.iso_figures(iso).gain_dn_per_e
    black = prof.require(iso, "black_level_dn")["black_level_dn"]
    sat_e = min(prof.require(iso, "full_well_e")["full_well_e"], (prof.white_level_dn - black) / gain)
    white_e = float(info["white_scale_e_per_s"]) * float(info["white_exposure_s"])
    return float(sat_e / white_e)


def _crop(decoded: np.ndarray, truth: np.ndarray, border: int):
    if decoded.ndim != 5 or truth.ndim != 5 or decoded.shape[:2] != truth.shape[:2] or decoded.shape[4] != truth.shape[4]:
        raise ShapeError(f"score: decoded {decoded.shape} and truth {truth.shape} must be (V, U, H, W, C) light "
                         "fields with the same views and channels")
    h, w = min(decoded.shape[2], truth.shape[2]), min(decoded.shape[3], truth.shape[3])
    if h <= 2 * border or w <= 2 * border:
        raise ShapeError(f"score: {h} x {w} views leave nothing inside a {border}-pixel border")
    sl = (slice(None), slice(None), slice(border, h - border), slice(border, w - border))
    return decoded[sl], truth[sl]


def decode_psnr(decoded: np.ndarray, truth: np.ndarray, *, clip: float | None = None, border: int = BORDER_PX,
                mask: np.ndarray | None = None, fit_gain: bool = False,
                peak_percentile: float = PEAK_PERCENTILE, peak: float | None = None) -> dict[str, float]:
    """PSNR of ``decoded`` against ``truth`` (both ``(V, U, H, W, C)``) as the module describes.

    ``clip``: truth values at or above it are left out (None: none are). ``mask`` (same shape as
    the cropped arrays' samples, optional) restricts the scored samples further; ``peak``
    overrides the percentile (to score parts of a light field on one scale). Returns
    ``psnr_db``, ``peak``, ``rmse``, ``gain`` (1 unless fitted), ``scored_fraction``.
    """
    a, b = _crop(np.asarray(decoded, np.float64), np.asarray(truth, np.float64), border)
    ok = np.isfinite(a) & np.isfinite(b)
    if clip is not None:
        ok &= b < clip
    if mask is not None:
        ok &= mask
    if not ok.any():
        raise ShapeError("score: no sample left to score")
    x, y = a[ok], b[ok]
    gain = float(np.dot(x, y) / np.dot(x, x)) if fit_gain and np.dot(x, x) > 0 else 1.0
    peak = float(np.percentile(y, peak_percentile)) if peak is None else float(peak)
    mse = float(np.mean((gain * x - y) ** 2))
    return {"psnr_db": float(10 * np.log10(peak ** 2 / mse)) if mse > 0 else float("inf"), "peak": peak,
            "rmse": float(np.sqrt(mse)), "gain": gain, "scored_fraction": float(ok.mean())}


def score_decode(decoded: np.ndarray, truth: np.ndarray, *, clip: float | None = None, border: int = BORDER_PX,
                 fit_gain: bool = False) -> dict[str, Any]:
    """Scores of a 5x5 (or n x n) decode: the centre view and all views (see :func:`decode_psnr`).

    Parameters
    ----------
    decoded, truth : array_like of shape (V, U, H, W, C)
        The decoded light field and its ground truth (same views and channels; the spatial
        sizes may differ, the common top-left part is scored).
    clip : float, optional
        Truth values at or above it are left out (:func:`clip_level`); None keeps all.
    border : int, default 4
        Pixels left out at every side of every view.
    fit_gain : bool, default False
        Score ``g * decoded`` with the least-squares gain ``g`` (for decoders with another scale).

    Returns
    -------
    dict
        ``psnr_centre_db`` and ``psnr_all_views_db`` (dB, linear values, peak = the 99.9th
        percentile of the scored truth), ``peak``, ``gain`` and ``gain_centre`` (1 unless
        fitted), ``scored_fraction``, ``clip_level``, ``border_px``, ``peak_percentile``.

    Raises
    ------
    lfproc.errors.ShapeError
        Mismatched shapes, views smaller than the border, or no sample left to score.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.lytro import score_decode
    >>> rng = np.random.default_rng(0)
    >>> truth = rng.random((3, 3, 16, 16, 3))
    >>> scores = score_decode(truth + 0.01 * rng.standard_normal(truth.shape), truth)
    >>> round(scores["psnr_all_views_db"], 1), scores["border_px"]    # noise std 0.01, peak ~1: 40 dB
    (40.0, 4)
    >>> score_decode(0.5 * truth, truth, fit_gain=True)["gain"]
    2.0
    """
    decoded = np.asarray(decoded)
    truth = np.asarray(truth)
    c = decoded.shape[0] // 2, decoded.shape[1] // 2
    centre = decode_psnr(decoded[c[0]:c[0] + 1, c[1]:c[1] + 1], truth[c[0]:c[0] + 1, c[1]:c[1] + 1], clip=clip,
                         border=border, fit_gain=fit_gain)
    every = decode_psnr(decoded, truth, clip=clip, border=border, fit_gain=fit_gain)
    return {"psnr_centre_db": centre["psnr_db"], "psnr_all_views_db": every["psnr_db"], "peak": every["peak"],
            "gain": every["gain"], "gain_centre": centre["gain"], "scored_fraction": every["scored_fraction"],
            "clip_level": clip, "border_px": border, "peak_percentile": PEAK_PERCENTILE}
