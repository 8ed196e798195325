"""The sensor model of the paper (eqs. 3-7; method.md sections 2-3): exposure and calibration.

Forward (:func:`expose`), per pixel, exposure time ``t`` (s), irradiance ``E`` in
electrons per second (after mask, CFA and quantum efficiency), ISO gain
``h`` (DN per electron, from the camera profile):

1. ``e = Poisson(t * (E * prnu + I_dark)) + N(0, sigma_read^2)`` electrons (plus DSNU),
   saturating at the full well ``FWD``;
2. ``I = min(I_max, Q(I_max * (h e / I_max)^(1/gamma)) + I_0)`` DN, clipped at 0, where
   ``Q`` rounds to the nearest integer and ``I_0`` is the black level. The power law acts
   on the signal normalised to ``I_max`` (sign kept for negative read noise), so
   ``gamma`` changes the spacing of the codes, not the range.

Inverse (:func:`calibrated_observation`): the radiance estimate
``T = I_max * ((I - I_bias) / I_max)^gamma / (h t)`` in e-/s, its variance
``(h^2 t (T + I_dark) + sigma_read_dn^2 + sigma_q^2) / (h t)^2`` and the weight
``w = 1 / std(T)``, zero where the pixel is saturated or black-clipped. The default bias
``I_bias = I_0 + h t I_dark`` is what the mean of many black frames taken with the same
settings gives, so ``T`` estimates ``E`` without the dark signal.

Both take scalar or per-pixel ISO maps, so one call models a multi-ISO sensor.
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np

from .._util import check_positive, check_random_state
from ..calib import load_profile
from ..errors import InputError, ShapeError

__all__ = ["expose", "calibrated_observation", "Observation", "iso_maps", "fixed_pattern"]


def iso_maps(profile, iso, shape: tuple[int, ...]) -> dict[str, np.ndarray]:
    """Per-pixel gain (DN/e-), read noise (e-), dark current (e-/s), black level (DN),
    full well (e-) and saturation code (DN) for a scalar ISO or an ISO map of ``shape``."""
    profile = load_profile(profile)
    iso_arr = np.broadcast_to(np.asarray(iso, dtype=np.float64), shape)
    values, inverse = np.unique(iso_arr, return_inverse=True)
    names = ("gain_dn_per_e", "read_noise_e", "dark_current_e_per_s", "black_level_dn", "full_well_e")
    tables = {n: np.empty(len(values)) for n in names + ("saturation_dn",)}
    for i, value in enumerate(values):
        figs = profile.require(value, *names)
        for n in names:
            tables[n][i] = figs[n]
        tables["saturation_dn"][i] = profile.saturation_dn(value)
    inverse = inverse.reshape(shape)
    return {n: t[inverse] for n, t in tables.items()}


def fixed_pattern(profile, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The sensor's PRNU gain map (mean 1) and DSNU offset map (electrons) for ``shape``.

    Drawn from ``profile.fixed_pattern_seed``, so a profile always gives the same maps.
    """
    profile = load_profile(profile)
    rng = np.random.default_rng(profile.fixed_pattern_seed)
    # a pixel's gain cannot be negative: with a large PRNU the normal draw is cut at zero
    prnu = np.maximum(1.0 + profile.prnu * rng.standard_normal(shape), 0.0) if profile.prnu else np.ones(shape)
    dsnu = profile.dsnu_e * rng.standard_normal(shape) if profile.dsnu_e else np.zeros(shape)
    return prnu, dsnu


def _power(x: np.ndarray, p: float) -> np.ndarray:
    return x if p == 1 else np.sign(x) * np.abs(x) ** p


def expose(
    irradiance_e_per_s: np.ndarray,
    *,
    exposure_s: float,
    iso: float | np.ndarray,
    profile,
    gamma: float | None = None,
    noise: bool = True,
    fixed_pattern_noise: bool = True,
    random_state=None,
) -> np.ndarray:
    """Simulate one sensor exposure.

    Parameters
    ----------
    irradiance_e_per_s : ndarray of shape (H, W)
        Photo-electrons per second reaching each pixel (non-negative, finite).
    exposure_s : float
        Exposure time in seconds (> 0).
    iso : float or ndarray of shape (H, W)
        ISO of every pixel; each value must be in the profile.
    profile : CameraProfile or name
    gamma : float, optional
        Power-law response (default: the profile's).
    noise : bool
        False gives the noiseless expected code (still quantised and clipped).
    fixed_pattern_noise : bool
        Apply the profile's PRNU/DSNU maps (when they are non-zero).
    random_state : int, Generator or None

    Returns
    -------
    ndarray of shape (H, W), uint16 (DN, black level included)
    """
    profile = load_profile(profile)
    t = check_positive("exposure_s", exposure_s)
    E = np.asarray(irradiance_e_per_s, dtype=np.float64)
    if E.ndim != 2:
        raise ShapeError(f"irradiance: expected an (H, W) sensor image, got shape {E.shape}")
    if not np.isfinite(E).all() or (E < 0).any():
        raise InputError("irradiance: expected finite, non-negative electrons per second")
    gamma = profile.gamma if gamma is None else check_positive("gamma", gamma)
    if gamma < 1:
        raise InputError(f"gamma: expected a value >= 1, got {gamma}")
    m = iso_maps(profile, iso, E.shape)
    rng = check_random_state(random_state)
    if fixed_pattern_noise and (profile.prnu or profile.dsnu_e):
        prnu, dsnu = fixed_pattern(profile, E.shape)
    else:
        prnu, dsnu = 1.0, 0.0
    mean_e = t * (E * prnu + m["dark_current_e_per_s"])
    if noise:
        electrons = rng.poisson(mean_e).astype(np.float64) + m["read_noise_e"] * rng.standard_normal(E.shape)
    else:
        electrons = mean_e
    electrons = np.minimum(electrons + dsnu, m["full_well_e"])
    imax = float(profile.white_level_dn)
    signal = imax * _power(m["gain_dn_per_e"] * electrons / imax, 1.0 / gamma)
    # Q(signal) + I_0 for an integer I_0; a calibrated (fractional) black level is rounded with
    # the signal so that codes stay integers and saturation lands exactly on I_max.
    dn = np.clip(np.rint(signal + m["black_level_dn"]), 0, imax)
    return dn.astype(np.uint16)


@dataclass(frozen=True)
class Observation:
    """Calibrated observations of a sensor image (all arrays ``(H, W)``).

    ``radiance`` (T, e-/s), ``variance`` (of T, (e-/s)^2), ``weight`` (1/std(T), 0 where
    unusable), ``saturated`` and ``black_clipped`` masks.
    """

    radiance: np.ndarray
    variance: np.ndarray
    weight: np.ndarray
    saturated: np.ndarray
    black_clipped: np.ndarray

    @property
    def saturated_fraction(self) -> float:
        return float(self.saturated.mean())

    @property
    def black_clipped_fraction(self) -> float:
        return float(self.black_clipped.mean())


def calibrated_observation(
    dn: np.ndarray,
    *,
    exposure_s: float,
    iso: float | np.ndarray,
    profile,
    gamma: float | None = None,
    bias_dn: np.ndarray | float | None = None,
    saturation_margin_dn: float = 0.5,
    variance_from: str = "measurement",
    radiance_estimate: np.ndarray | None = None,
) -> Observation:
    """Radiance estimate ``T``, its variance and weights from sensor codes (method.md section 3).

    Parameters
    ----------
    dn : ndarray of shape (H, W)
        Sensor codes (DN, black level included).
    exposure_s, iso, profile, gamma : as for :func:`expose`.
    bias_dn : float or ndarray (H, W), optional
        Bias frame. Default: the black level plus the mean dark signal ``h t I_dark``.
    saturation_margin_dn : float
        Codes at or above ``saturation - margin`` are saturated (weight 0).
    variance_from : {"measurement", "estimate"}
        Plug-in signal of the photon-noise term: ``T`` itself (default) or
        ``radiance_estimate`` (e.g. the current HDR estimate of an iterative merge).

    Returns
    -------
    Observation
    """
    profile = load_profile(profile)
    t = check_positive("exposure_s", exposure_s)
    dn = np.asarray(dn, dtype=np.float64)
    if dn.ndim != 2:
        raise ShapeError(f"sensor image: expected shape (H, W), got {dn.shape}")
    gamma = profile.gamma if gamma is None else float(gamma)
    m = iso_maps(profile, iso, dn.shape)
    h = m["gain_dn_per_e"]
    if bias_dn is None:
        bias = m["black_level_dn"] + h * t * m["dark_current_e_per_s"]
    else:
        bias = np.broadcast_to(np.asarray(bias_dn, dtype=np.float64), dn.shape)
    imax = float(profile.white_level_dn)
    rel = (dn - bias) / imax
    linear_dn = imax * _power(rel, gamma)  # h * electrons
    T = linear_dn / (h * t)
    if variance_from == "estimate":
        if radiance_estimate is None:
            raise InputError("variance_from='estimate' needs radiance_estimate")
        signal = np.maximum(np.broadcast_to(radiance_estimate, dn.shape), 0)
    elif variance_from == "measurement":
        signal = np.maximum(T, 0)
    else:
        raise InputError(f"variance_from: expected 'measurement' or 'estimate', got {variance_from!r}")
    # quantisation noise: uniform over one code step, the step's width mapped through the power
    # law (1/12 DN^2 when gamma = 1; never zero, also at the black level)
    if gamma == 1:
        var_q = 1.0 / 12.0
    else:
        half = 0.5 / imax
        var_q = (imax * (_power(rel + half, gamma) - _power(rel - half, gamma))) ** 2 / 12.0
    read_dn2 = (m["read_noise_e"] * h) ** 2
    var_dn = h**2 * t * (signal + m["dark_current_e_per_s"]) + read_dn2 + var_q
    variance = var_dn / (h * t) ** 2
    saturated = dn >= m["saturation_dn"] - saturation_margin_dn
    black_clipped = dn <= 0
    usable = ~(saturated | black_clipped)
    weight = np.where(usable, 1.0 / np.sqrt(variance), 0.0)
    return Observation(
        radiance=T.astype(np.float32),
        variance=variance.astype(np.float32),
        weight=weight.astype(np.float32),
        saturated=saturated,
        black_clipped=black_clipped,
    )

