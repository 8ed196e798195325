"""The sensor model of Miandji et al. (eqs. 3-7): exposure and calibration.

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

Fixed pattern (:func:`fixed_pattern_correction`): a sensor's PRNU (per-pixel gain ``g``, mean
1) and DSNU (per-pixel offset ``o``, electrons) enter the forward model as
``e = Poisson(t (E g + I_dark)) + N(0, sigma_read^2) + o``. The calibrated observation corrects
them (dark-signal correction: ``h o`` is subtracted from the linearised signal; flat-field
correction: the signal is divided by ``g``), so ``T`` estimates ``E`` per pixel:
``T = (I_max ((I - I_bias) / I_max)^gamma - h o) / (h t g)`` with variance
``(h^2 t (T g + I_dark) + sigma_read_dn^2 + sigma_q^2) / (h t g)^2 + T^2 var(g) / g^2 + var(o) / (t g)^2``,
where ``var(g)`` and ``var(o)`` are the uncertainties of the maps used: 0 for a simulated
sensor (its maps are drawn from the profile's ``fixed_pattern_seed``, exactly known), the
estimation variance recorded by ``lfproc calibrate`` for measured maps (``flat_field_std``,
``bias_frame_std_dn``), and the PRNU/DSNU themselves (``prnu^2``, ``dsnu_e^2``) where a
measured profile has no map that fits the image (the fixed pattern is then uncorrected
and acts as one more noise term of known variance).

Both take scalar or per-pixel ISO maps, so one call models a multi-ISO sensor.

Reference: E. Miandji, H.-N. Nguyen, S. Hajisharif, J. Unger and C. Guillemot, "Compressive
HDR Light Field Imaging Using a Single Multi-ISO Sensor", IEEE Transactions on Computational
Imaging, 2021 (section III-B, the noise model and calibration of multi-ISO sensors).
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np

from .._shared.frozen import ReadOnlyState, freeze, frozen_array
from .._shared.validation import check_positive
from .._shared.random import check_random_state
from .._shared.reprs import short_repr
from ._profile import load_profile
from ..errors import InputError, ShapeError

__all__ = ["expose", "calibrated_observation", "Observation", "iso_maps", "fixed_pattern", "FixedPattern",
           "fixed_pattern_correction"]


def iso_maps(profile, iso, shape: tuple[int, ...]) -> dict[str, np.ndarray]:
    """Per-pixel gain (DN/e-), read noise (e-), dark current (e-/s), black level (DN),
    full well (e-) and saturation code (DN) for a scalar ISO or an ISO map of ``shape``.

    Parameters
    ----------
    profile : CameraProfile or str
        A profile or a shipped profile's name or a profile file (see :func:`load_profile`).
    iso : float or array_like
        One ISO, or an ISO per pixel broadcastable to ``shape``; every value must be in the
        profile.
    shape : tuple of int
        Shape of the maps.

    Returns
    -------
    dict of str to ndarray
        float64 maps of ``shape``: ``gain_dn_per_e``, ``read_noise_e``,
        ``dark_current_e_per_s``, ``black_level_dn``, ``full_well_e``, ``saturation_dn``.

    Raises
    ------
    lfproc.errors.ProfileError
        An ISO is not in the profile, or one of its figures is unknown.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.sensor import iso_maps
    >>> m = iso_maps("paper-medium", np.array([[100, 400]]), (1, 2))
    >>> m["gain_dn_per_e"].tolist(), m["read_noise_e"].tolist(), m["saturation_dn"].tolist()
    ([[0.20475, 0.819]], [[2.0, 2.0]], [[4095.0, 4095.0]])
    """
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

    Parameters
    ----------
    profile : CameraProfile or str
        A profile, a shipped profile's name or a profile file.
    shape : tuple of int
        ``(H, W)`` of the sensor image.

    Returns
    -------
    prnu : ndarray of shape (H, W), float64
        Per-pixel gain, ``max(1 + prnu * N(0, 1), 0)``; ones when the profile's ``prnu`` is 0.
    dsnu : ndarray of shape (H, W), float64
        Per-pixel offset in electrons, ``dsnu_e * N(0, 1)``; zeros when ``dsnu_e`` is 0.

    Examples
    --------
    >>> import dataclasses
    >>> import numpy as np
    >>> from lfproc.sensor import fixed_pattern, load_profile
    >>> profile = dataclasses.replace(load_profile("paper-medium"), prnu=0.01, dsnu_e=2.0)
    >>> gain, offset = fixed_pattern(profile, (64, 64))
    >>> round(float(gain.mean()), 2), round(float(gain.std()), 2), round(float(offset.std()), 1)
    (1.0, 0.01, 2.0)
    >>> bool(np.array_equal(fixed_pattern(profile, (64, 64))[0], gain))   # the same sensor, the same maps
    True
    """
    profile = load_profile(profile)
    rng = np.random.default_rng(profile.fixed_pattern_seed)
    # a pixel's gain cannot be negative: with a large PRNU the normal draw is cut at zero
    prnu = np.maximum(1.0 + profile.prnu * rng.standard_normal(shape), 0.0) if profile.prnu else np.ones(shape)
    dsnu = profile.dsnu_e * rng.standard_normal(shape) if profile.dsnu_e else np.zeros(shape)
    return prnu, dsnu


@short_repr
@dataclass(frozen=True)
class FixedPattern:
    """Fixed-pattern maps of one sensor image and how well they are known (all ``(H, W)``).

    Made by :func:`fixed_pattern_correction`; the arrays are stored read-only, float64.

    Parameters
    ----------
    gain : array_like of shape (H, W)
        PRNU gain map; the signal is divided by it (ones where not corrected).
    offset_e : array_like of shape (H, W)
        DSNU offset in electrons, subtracted (zeros where not corrected).
    gain_var : array_like of shape (H, W)
        Variance of the true gain around ``gain`` (0 where exact).
    offset_var_e2 : array_like of shape (H, W)
        Variance of the true offset around ``offset_e``, electrons squared (0 where exact).
    gain_source, offset_source : str, default "none"
        Where the maps come from (``none``, ``simulated``, ``flat_field``, ``bias_frames``,
        ``uncorrected``, possibly with the reason).
    """

    gain: np.ndarray
    offset_e: np.ndarray
    gain_var: np.ndarray
    offset_var_e2: np.ndarray
    gain_source: str = "none"
    offset_source: str = "none"

    def __post_init__(self):
        # read-only like every array lfproc hands out (a copy only when the caller kept a writable reference)
        for name in ("gain", "offset_e", "gain_var", "offset_var_e2"):
            object.__setattr__(self, name, frozen_array(getattr(self, name), dtype=np.float64))

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.gain.shape)


def _has_fixed_pattern(profile) -> bool:
    return bool(profile.prnu or profile.dsnu_e or profile.flat_field is not None or profile.bias_frames)


def _fixed_pattern_maps(profile, shape: tuple[int, int], iso, *, simulate: bool) -> FixedPattern:
    """The maps of :func:`fixed_pattern_correction`; with ``simulate`` the parts a measured
    profile does not know come from the seed maps (a plausible sensor with its statistics)."""
    shape = tuple(int(n) for n in shape)
    known = not profile.measured or simulate
    seed_gain, seed_offset = (fixed_pattern(profile, shape) if (profile.prnu or profile.dsnu_e) and known
                              else (None, None))
    gain, gain_var, gain_src = np.ones(shape), np.zeros(shape), "none"
    flat = profile.flat_field
    misfit = "" if flat is None or flat.shape == shape else (
        f" (the profile's flat_field map is {flat.shape[0]}x{flat.shape[1]}, the image {shape[0]}x{shape[1]})")
    if flat is not None and not misfit:
        gain = np.asarray(flat, dtype=np.float64)
        gain_var = np.full(shape, float(profile.flat_field_std) ** 2)
        gain_src = "flat_field"
    elif profile.prnu and known:
        gain, gain_src = seed_gain, "simulated" + misfit
    elif profile.prnu:
        gain_var = np.full(shape, float(profile.prnu) ** 2)
        gain_src = "uncorrected" + (misfit or " (measured profile without a flat_field map)")
    offset, offset_var, offset_src = np.zeros(shape), np.zeros(shape), "none"
    if profile.dsnu_e and known:
        offset, offset_src = seed_offset, "simulated"
    elif profile.dsnu_e:
        offset_var = np.full(shape, float(profile.dsnu_e) ** 2)
        offset_src = "uncorrected (measured profile without bias frames that fit the image)"
    frames = {k: f for k, f in profile.bias_frames.items() if tuple(f.shape) == shape}
    if frames and iso is not None:
        iso_arr = np.broadcast_to(np.asarray(iso, dtype=np.float64), shape)
        used = []
        for value in np.unique(iso_arr):
            key = int(round(float(value)))
            if key not in frames:
                continue
            sel = iso_arr == value
            h = profile.require(value, "gain_dn_per_e")["gain_dn_per_e"]
            frame = np.asarray(frames[key], dtype=np.float64)
            offset[sel] = (frame - frame.mean())[sel] / h
            offset_var[sel] = (float(profile.bias_frame_std_dn.get(key, 0.0)) / h) ** 2
            used.append(key)
        if used:
            offset_src = "bias_frames (ISO " + ", ".join(map(str, used)) + ")"
    return FixedPattern(gain=freeze(np.array(gain, dtype=np.float64)), offset_e=freeze(offset),
                        gain_var=freeze(gain_var), offset_var_e2=freeze(offset_var),
                        gain_source=gain_src, offset_source=offset_src)


def fixed_pattern_correction(profile, shape: tuple[int, int], iso=None) -> FixedPattern:
    """The PRNU and DSNU maps that correct a sensor image of ``shape``, and their uncertainty.

    From the profile, in this order (see the module documentation for the model):

    * PRNU: a measured ``flat_field`` map of the image's size (variance ``flat_field_std^2``);
      else, for a simulated sensor (a profile not measured by ``lfproc calibrate``), the map
      :func:`fixed_pattern` draws from ``fixed_pattern_seed`` (exact); else, for a measured
      profile with ``prnu > 0`` but no fitting map, no correction and variance ``prnu^2``.
    * DSNU: per ISO, the measured master bias frame of the image's size (offset = frame minus
      its mean, over the ISO's gain; variance ``bias_frame_std_dn^2 / h^2``); else the
      simulated sensor's map (exact); else, measured without frames, no correction and
      variance ``dsnu_e^2``.

    Parameters
    ----------
    profile : CameraProfile or name
    shape : (H, W)
        Size of the sensor image.
    iso : float or ndarray (H, W), optional
        ISO of every pixel (selects the bias frames; without it they are not used).

    Returns
    -------
    FixedPattern
        The maps (read-only, float64) and where they come from.
    """
    return _fixed_pattern_maps(load_profile(profile), shape, iso, simulate=False)


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
        Apply the profile's PRNU/DSNU maps (when it has any): its measured ``flat_field`` and
        bias frames where they fit the image, else the maps drawn from ``fixed_pattern_seed``.
    random_state : int, Generator or None

    Returns
    -------
    ndarray of shape (H, W), uint16
        Sensor codes (DN, black level included), in ``[0, white_level_dn]``.

    Raises
    ------
    lfproc.errors.ShapeError
        ``irradiance_e_per_s`` is not 2-D.
    lfproc.errors.InputError
        Negative or non-finite irradiance, ``exposure_s <= 0`` or ``gamma < 1``.
    lfproc.errors.ProfileError
        An ISO is not in the profile.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.sensor import calibrated_observation, expose
    >>> E = np.full((64, 64), 1000.0)        # 1000 e-/s on every pixel
    >>> dn = expose(E, exposure_s=0.01, iso=400, profile="paper-medium", random_state=0)
    >>> dn.shape, dn.dtype
    ((64, 64), dtype('uint16'))
    >>> obs = calibrated_observation(dn, exposure_s=0.01, iso=400, profile="paper-medium")
    >>> round(float(obs.radiance.mean()) / 1000, 2)    # the irradiance, recovered on average
    1.0
    >>> bool(abs(obs.radiance.std() / np.sqrt(obs.variance.mean()) - 1) < 0.05)   # the noise, predicted
    True
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
    if fixed_pattern_noise and _has_fixed_pattern(profile):
        maps = _fixed_pattern_maps(profile, E.shape, iso, simulate=True)
        prnu, dsnu = maps.gain, maps.offset_e
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


@short_repr
@dataclass(frozen=True, eq=False)
class Observation(ReadOnlyState):
    """Calibrated observations of a sensor image (all arrays ``(H, W)``, or ``(S, H, W)`` for
    the shots of a capture).

    Made by :func:`calibrated_observation`. The arrays are stored read-only (float32 and
    bool; see :func:`lfproc._util.frozen_array`); ``saturated_fraction`` and
    ``black_clipped_fraction`` are the masks' means.

    Parameters
    ----------
    radiance : array_like
        Radiance estimate ``T`` in e-/s.
    variance : array_like
        Variance of ``T``, (e-/s)^2; the shape of ``radiance``.
    weight : array_like
        ``1 / std(T)``, 0 where the pixel is unusable.
    saturated, black_clipped : array_like of bool
        Pixels at the saturation code, and pixels clipped at code 0.

    Raises
    ------
    lfproc.errors.ShapeError
        An array's shape differs from ``radiance``'s.
    lfproc.errors.InputError
        A mask is not boolean.
    """

    radiance: np.ndarray
    variance: np.ndarray
    weight: np.ndarray
    saturated: np.ndarray
    black_clipped: np.ndarray

    def __post_init__(self):
        shape = np.shape(self.radiance)
        for name, dtype in (("radiance", np.float32), ("variance", np.float32), ("weight", np.float32),
                            ("saturated", bool), ("black_clipped", bool)):
            value = getattr(self, name)
            if np.shape(value) != shape:
                raise ShapeError(f"observation {name}: expected shape {shape} (that of radiance), got {np.shape(value)}")
            if dtype is bool and np.asarray(value).dtype != bool:
                raise InputError(f"observation {name}: expected a boolean mask, got dtype {np.asarray(value).dtype}")
            object.__setattr__(self, name, frozen_array(value, dtype=dtype))

    @property
    def saturated_fraction(self) -> float:
        return float(self.saturated.mean())

    @property
    def black_clipped_fraction(self) -> float:
        return float(self.black_clipped.mean())


def _sensor_codes(dn) -> np.ndarray:
    """``dn`` as float64 codes of one 2-D sensor image, checked (numeric, finite)."""
    dn = np.asarray(dn)
    if not (np.issubdtype(dn.dtype, np.integer) or np.issubdtype(dn.dtype, np.floating)):
        raise InputError(f"sensor image: expected DN codes (integers or floats), got dtype {dn.dtype}")
    dn = dn.astype(np.float64, copy=False)
    if dn.ndim != 2:
        raise ShapeError(f"sensor image: expected shape (H, W), got {dn.shape}")
    n_bad = int(np.count_nonzero(~np.isfinite(dn)))
    if n_bad:
        raise InputError(f"sensor image: expected finite DN codes, found {n_bad} NaN or Inf values")
    return dn


def _bias_map(bias_dn, m: dict, t: float, shape) -> np.ndarray:
    """The bias (DN) under every pixel: ``bias_dn`` broadcast, or the black level plus the mean dark signal."""
    h = m["gain_dn_per_e"]
    if bias_dn is None:
        bias = m["black_level_dn"] + h * t * m["dark_current_e_per_s"]
    else:
        try:
            bias = np.broadcast_to(np.asarray(bias_dn, dtype=np.float64), shape)
        except (TypeError, ValueError):
            raise ShapeError(f"bias_dn: expected a number or a map of shape {shape}, got {np.shape(bias_dn)}") from None
        if not np.isfinite(bias).all():
            raise InputError("bias_dn: expected finite DN values, found NaN or Inf")
    return bias


def _fixed_pattern_of(correct_fixed_pattern, profile, iso, shape):
    """The fixed-pattern maps to correct with (None: no correction)."""
    if isinstance(correct_fixed_pattern, FixedPattern):
        fp = correct_fixed_pattern
        if fp.shape != shape:
            raise ShapeError(f"fixed pattern: maps of shape {fp.shape} do not fit the sensor image {shape}")
    elif correct_fixed_pattern is True:
        fp = _fixed_pattern_maps(profile, shape, iso, simulate=False) if _has_fixed_pattern(profile) else None
    elif correct_fixed_pattern is False:
        fp = None
    else:
        raise InputError(f"correct_fixed_pattern: expected True, False or a FixedPattern, got {correct_fixed_pattern!r}")
    return fp


def _variance_signal(variance_from: str, radiance_estimate, T: np.ndarray) -> np.ndarray:
    """The signal (e-/s) in the photon-noise variance: the estimate given, or the measurement ``T``."""
    if variance_from == "estimate":
        if radiance_estimate is None:
            raise InputError("variance_from='estimate' needs radiance_estimate")
        try:
            signal = np.broadcast_to(np.asarray(radiance_estimate, dtype=np.float64), T.shape)
        except (TypeError, ValueError):
            raise ShapeError(
                f"radiance_estimate: expected a map of shape {T.shape}, got {np.shape(radiance_estimate)}"
            ) from None
        if not np.isfinite(signal).all():
            raise InputError("radiance_estimate: expected finite values, found NaN or Inf")
        signal = np.maximum(signal, 0)
    elif variance_from == "measurement":
        signal = np.maximum(T, 0)
    else:
        raise InputError(f"variance_from: expected 'measurement' or 'estimate', got {variance_from!r}")
    return signal


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
    correct_fixed_pattern: "bool | FixedPattern" = True,
    read_floor_e: float = 0.0,
) -> Observation:
    """Radiance estimate ``T``, its variance and weights from sensor codes (Miandji et al. 2021, eqs. 5-7).

    Parameters
    ----------
    dn : ndarray of shape (H, W)
        Sensor codes (DN, black level included).
    exposure_s, iso, profile, gamma : as for :func:`expose`.
    bias_dn : float or ndarray (H, W), optional
        Bias frame. Default: the black level plus the mean dark signal ``h t I_dark`` (and the
        DSNU is corrected from the profile). A given bias frame is taken to hold the DSNU already:
        only the flat-field correction is applied then.
    saturation_margin_dn : float
        Codes at or above ``saturation - margin`` are saturated (weight 0).
    variance_from : {"measurement", "estimate"}
        Plug-in signal of the photon-noise term: ``T`` itself (default) or
        ``radiance_estimate`` (e.g. the current HDR estimate of an iterative merge).
    correct_fixed_pattern : bool or FixedPattern
        True (default): correct the PRNU and DSNU with :func:`fixed_pattern_correction` of
        the profile for ``dn``'s shape and add the maps' uncertainty to the variance (a no-op
        for a profile without fixed pattern); a :class:`FixedPattern` of ``dn``'s shape: use
        those maps; False: no correction (for codes that are not a sensor image, e.g. a table
        of codes or decoded views).
    read_floor_e : float, default 0
        Read noise (electrons) the variance assumes at least: ``max(read noise, read_floor_e)``.
        Without read noise (``paper-none``) a dark measurement is otherwise known to its
        quantisation step, a fraction of an electron, while its photon count of about one
        electron is 0, 1 or 2; 1 (the electron of :func:`lfproc.camera.noise_floor`) is what
        the reconstructions use. A profile with at least that much read noise is unchanged.

    Returns
    -------
    Observation
        Radiance (e-/s), variance, weights and the saturated/black-clipped masks, of ``dn``'s
        shape.

    Raises
    ------
    lfproc.errors.InputError
        Bad codes, ``exposure_s <= 0``, ``gamma < 1``, an unknown ``variance_from`` or a negative
        ``read_floor_e``.
    lfproc.errors.ProfileError
        An ISO is not in the profile.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.sensor import calibrated_observation
    >>> dn = np.array([[64, 72, 4095]])     # black, a little signal, saturated (paper-medium: 12 bit, black 64)
    >>> obs = calibrated_observation(dn, exposure_s=0.01, iso=400, profile="paper-medium")
    >>> obs.saturated.tolist(), [round(float(x)) for x in obs.radiance[0, :2]]
    ([[False, False, True]], [-1, 976])
    >>> float(obs.weight[0, 2])
    0.0
    """
    profile = load_profile(profile)
    t = check_positive("exposure_s", exposure_s)
    floor = check_positive("read_floor_e", read_floor_e, allow_zero=True)
    dn = _sensor_codes(dn)
    gamma = profile.gamma if gamma is None else check_positive("gamma", gamma)
    if gamma < 1:
        # the response I = I_max (h e / I_max)^(1/gamma) of expose() needs gamma >= 1 (as the profile does)
        raise InputError(f"gamma: expected a value >= 1, got {gamma}")
    m = iso_maps(profile, iso, dn.shape)
    h = m["gain_dn_per_e"]
    bias = _bias_map(bias_dn, m, t, dn.shape)
    fp = _fixed_pattern_of(correct_fixed_pattern, profile, iso, dn.shape)
    imax = float(profile.white_level_dn)
    rel = (dn - bias) / imax
    linear_dn = imax * _power(rel, gamma)  # h * electrons
    g = 1.0
    if fp is not None:
        if bias_dn is None:
            linear_dn = linear_dn - h * fp.offset_e  # dark-signal (DSNU) correction
        g = fp.gain  # flat-field (PRNU) correction
    T = linear_dn / (h * t * g)
    signal = _variance_signal(variance_from, radiance_estimate, T)
    # quantisation noise: uniform over one code step, the step's width mapped through the power
    # law (1/12 DN^2 when gamma = 1; never zero, also at the black level)
    if gamma == 1:
        var_q = 1.0 / 12.0
    else:
        half = 0.5 / imax
        var_q = (imax * (_power(rel + half, gamma) - _power(rel - half, gamma))) ** 2 / 12.0
    read_dn2 = (np.maximum(m["read_noise_e"], floor) * h) ** 2
    var_dn = h**2 * t * (signal * g + m["dark_current_e_per_s"]) + read_dn2 + var_q
    variance = var_dn / (h * t * g) ** 2
    if fp is not None:  # the maps' own uncertainty (module documentation)
        variance = variance + signal**2 * fp.gain_var / g**2
        if bias_dn is None:
            variance = variance + fp.offset_var_e2 / (t * g) ** 2
    saturated = dn >= m["saturation_dn"] - saturation_margin_dn
    black_clipped = dn <= 0
    usable = ~(saturated | black_clipped)
    weight = np.where(usable, 1.0 / np.sqrt(variance), 0.0)
    return Observation(
        radiance=freeze(T.astype(np.float32)),
        variance=freeze(variance.astype(np.float32)),
        weight=freeze(weight.astype(np.float32)),
        saturated=freeze(saturated),
        black_clipped=freeze(black_clipped),
    )

