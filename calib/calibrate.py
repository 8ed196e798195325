"""Measure a camera profile from bias, dark and flat frames (or an EMVA 1288 data set).

Per ISO, following EMVA Standard 1288 (release 3.1, 2016, and release 4.0 Linear, 2021) and
Janesick's photon transfer method (J. R. Janesick, "Photon Transfer", SPIE Press, 2007); every
figure also per CFA position when the frames have a CFA:

1. **Black level / bias frame**: master bias = mean of the bias frames; black level =
   its mean (minus the dark signal of the bias exposure, when the dark current is known).
2. **Read noise**: temporal variance of bias pairs, ``mean(((A - mu_A) - (B - mu_B))^2) / 2``
   (the difference removes the fixed pattern), minus the dark-current variance of the bias
   exposure; ``read_noise_dn = sqrt(var - 1/12)`` (quantisation removed, as
   :mod:`lfproc.camera.sensor` adds it separately); ``read_noise_e = read_noise_dn / K``.
3. **DSNU**: spatial variance of the master bias minus ``var_read / N`` (EMVA correction),
   pooled over the 2x2 CFA positions.
4. **Gain** ``K`` (DN/e-): slope through the origin of ``var - var_dark(t)`` against
   ``mean - mean_dark(t)`` of the flat pairs, using the pairs without clipped pixels below
   70 % of the variance-maximum signal (photon transfer, EMVA 1288).
5. **Saturation**: the output code where over-exposed flats pile up (``saturation_dn``);
   ``full_well_e = (saturation_dn - black) / K`` (well or ADC, whichever clips first, as
   :meth:`CameraProfile.saturation_dn`); the EMVA saturation capacity at the variance
   maximum is reported too (``saturation_capacity_emva_e``), with the mean output there,
   EMVA's ``mu_y.sat`` (``saturation_mean_dn``, dark level included; called
   ``saturation_variance_max_dn`` before, a name that read like a variance: older profiles
   are read with the new name).
6. **Dark current**: slope of the dark level against exposure time over bias and dark
   frames (at least three exposure times) divided by ``K`` (mean method, stored in the
   profile) and slope of the dark temporal variance divided by ``K^2`` (variance method).
7. **Hot pixels**: pixels of the longest-exposure master dark more than ``hot_pixel_sigma``
   robust standard deviations above the median; they are left out of every statistic.
8. **PRNU**: from the flat level nearest 50 % saturation:
   ``sqrt(s_y^2 - var_t / n - s_dark^2) / signal``.
   **Flat field** (the per-pixel PRNU map, stored in the profile's ``flat_field``): per ISO,
   the dark-subtracted master flats of every level without a clipped pixel, summed with
   weights ``n_frames`` (so brighter levels, whose relative noise is lower, count more) over
   the summed mean signal; the dark level of each pixel is its master bias (which holds the
   DSNU) plus the mean dark current over the exposure. The ISOs' maps are averaged with
   inverse-variance weights and normalised to mean 1 per CFA position (the channels' mean
   response is colour, not non-uniformity). ``flat_field_std`` is the relative standard
   deviation of a map value from the temporal noise of the flats and the bias master.
   The master bias frames are stored too, with ``bias_frame_std_dn = sqrt(var_read / n_bias)``.
9. **Read-noise split across ISOs**: least squares ``var_read(S) = K(S)^2 sigma_pre^2 +
   sigma_post^2`` (Hasinoff): ``sigma_pre`` (e-) before, ``sigma_post`` (DN) after the ISO gain.
10. **Dynamic range and SNR** (EMVA 1288): ``DR = mu_e.sat / (sigma_y.dark / K + 1/2)`` with the
    variance-maximum saturation capacity, ``SNR_max = sqrt(mu_e.sat)``; also
    ``full_well_e / read_noise_e`` in stops.

A figure the frames cannot give is ``None`` and its reason is in ``unknown`` (keys like
``isos.100.gain_dn_per_e``). Frames are read one at a time and reduced to running sums, so
memory stays at a few frames whatever the stack size.
"""

from __future__ import annotations

import math
import os
from collections import defaultdict
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from lfproc._shared.validation import check_positive
from lfproc._shared.progress import progress
from lfproc._shared.reprs import short_repr
from lfproc._version import __version__
from lfproc.errors import CalibrationError, InputError, MissingFileError

from .emva import SIGMA2_Q, EmvaDescriptor, evaluate, is_descriptor, read_descriptor, reduce_descriptor
from .frames import FrameChecker, FrameRecord, _channel_names, read_frame, read_manifest
from lfproc.sensor._profile import MONO
from lfproc.sensor import CameraProfile, IsoFigures

__all__ = ["calibrate", "find_calibration_input", "CalibrationResult", "DEFAULT_ISO_KEY", "MANIFEST_NAMES"]

DEFAULT_ISO_KEY = "default"
#: EMVA 1288 figures copied into the profile's ``source["emva1288"]`` (per ISO key) for ``profile show``.
EMVA_SOURCE_KEYS = ("quantum_efficiency", "temporal_dark_noise_dn", "saturation_mean_dn",
                    "saturation_capacity_emva_e", "absolute_sensitivity_threshold_e", "snr_max_db",
                    "dynamic_range_emva_db")
_CLIP_PILE_FRACTION = 0.01  # a frame whose maximum code holds >= 1 % of its pixels is clipped there
_CLIPPED_PAIR_FRACTION = 1e-4  # flat pairs with more clipped pixels stay out of the gain fit
_BLACK_CLIP_FRACTION = 1e-3


@short_repr
@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` measured.

    Parameters
    ----------
    profile : CameraProfile
        The measured profile (master bias frames in ``bias_frames``).
    figures : dict
        ISO as a string (``"default"`` for EMVA data) -> figures (units in the names;
        ``None`` = unknown).
    unknown : dict
        Figure (``isos.<ISO>.<name>``) -> why the frames cannot give it.
    read_noise_model : dict
        The pre/post-amplifier split (``sigma_pre_e``, ``sigma_post_dn``) or its reason.
    curves : dict
        ISO -> data of the photon-transfer and dark plots (lists).
    hot_pixels : dict
        ISO -> boolean hot-pixel mask (H, W).
    notes : list of str
        Remarks on the measurement (e.g. figures taken from a fallback).
    source : dict
        The input (path, kind, frame counts) and the options used.
    iso_keys : dict
        Key of ``figures`` -> the ISO the profile stores it under (``{"default": 100}`` for EMVA
        data); each figure dict also holds it as ``"iso"``.

    Examples
    --------
    >>> from lfproc.calib import calibrate, simulate_frames
    >>> manifest = simulate_frames("paper-medium", "frames", isos=[100, 400], size=(64, 64), random_state=0)
    >>> result = calibrate(manifest)
    >>> sorted(result.figures), result.profile.iso_values, result.iso("400")
    (['100', '400'], [100, 400], 400)
    >>> fig = result.profile.iso_figures(400)        # paper-medium: 0.819 DN/e-, 2 e-, black 64
    >>> round(fig.gain_dn_per_e, 2), round(fig.read_noise_e), round(fig.black_level_dn)
    (0.81, 2, 64)
    """

    profile: CameraProfile
    figures: dict[str, dict[str, Any]]
    unknown: dict[str, str]
    read_noise_model: dict[str, Any]
    curves: dict[str, dict[str, Any]] = field(default_factory=dict)
    hot_pixels: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    notes: list[str] = field(default_factory=list)
    source: dict[str, Any] = field(default_factory=dict)
    iso_keys: dict[str, int] = field(default_factory=dict)

    def iso(self, key: str) -> int | None:
        """The ISO the profile stores the figures of ``key`` under (``"default"`` -> 100 for EMVA data)."""
        if key in self.iso_keys:
            return self.iso_keys[key]
        return int(key) if str(key).isdigit() else None

    def iso_label(self, key: str) -> str:
        """``"ISO 100"``: the ISO of ``key`` as the profile stores it."""
        iso = self.iso(key)
        return f"ISO {iso if iso is not None else key}"

    def to_json(self) -> dict[str, Any]:
        """``{"isos": {ISO: figures}, "read_noise_model", "unknown", "notes", "source"}``."""
        return {"isos": self.figures, "read_noise_model": self.read_noise_model, "unknown": self.unknown,
                "notes": self.notes, "source": self.source, "profile": self.profile.name}


# -- statistics of frame sets ----------------------------------------------------------------
def _views(shape) -> dict[str, tuple[slice, slice]]:
    out = {"all": (slice(None), slice(None))}
    if shape[0] >= 2 and shape[1] >= 2:
        for r in (0, 1):
            for c in (0, 1):
                out[f"p{r}{c}"] = (slice(r, None, 2), slice(c, None, 2))
    return out


_POS = ("p00", "p01", "p10", "p11")


@dataclass
class _SetStats:
    kind: str
    exposure_s: float
    group: str
    paths: list[Path]
    n: int = 0
    n_pairs: int = 0
    master: np.ndarray | None = None
    mean: dict[str, float] = field(default_factory=dict)
    pair_var: dict[str, float] = field(default_factory=dict)
    spatial_var: dict[str, float] = field(default_factory=dict)
    max_code: int = 0
    frac_at_max: float = 0.0
    zero_fraction: float = 0.0
    temperature_c: float | None = None


def _reduce_set(records: list[FrameRecord], checker: FrameChecker, mask: np.ndarray | None,
                cfa: str | None) -> _SetStats:
    """Read a set's frames once: running sum, pair variances (consecutive pairs), clip stats."""
    r0 = records[0]
    st = _SetStats(kind=r0.kind, exposure_s=r0.exposure_s, group=r0.group, paths=[r.path for r in records])
    total = None
    pair_sums: dict[str, float] = defaultdict(float)
    pending = None
    max_code, count_at_max, n_pix, zeros = -1, 0, 0, 0
    for rec in records:
        frame = read_frame(rec.path)
        checker.check(frame, cfa_override=cfa)
        x = frame.data
        if mask is None:
            mask = np.ones(x.shape, dtype=bool)
        xf = x.astype(np.float64)
        total = xf.copy() if total is None else total + xf
        m = int(x.max())
        c = int(np.count_nonzero(x == m))
        if m > max_code:
            max_code, count_at_max = m, c
        elif m == max_code:
            count_at_max += c
        n_pix += x.size
        zeros += int(np.count_nonzero(x == 0))
        if pending is None:
            pending = xf
        else:
            d = pending - xf
            for name, (rs, cs) in _views(x.shape).items():
                sel = d[rs, cs][mask[rs, cs]]
                pair_sums[name] += float(sel.var() / 2) if sel.size else float("nan")
            st.n_pairs += 1
            pending = None
        st.n += 1
    st.master = total / st.n
    for name, (rs, cs) in _views(st.master.shape).items():
        sel = st.master[rs, cs][mask[rs, cs]]
        st.mean[name] = float(sel.mean())
        st.spatial_var[name] = float(sel.var(ddof=1)) if sel.size > 1 else float("nan")
    if st.n_pairs:
        st.pair_var = {k: v / st.n_pairs for k, v in pair_sums.items()}
    st.max_code = max_code
    st.frac_at_max = count_at_max / n_pix
    st.zero_fraction = zeros / n_pix
    temps = [r.temperature_c for r in records if r.temperature_c is not None]
    st.temperature_c = float(np.mean(temps)) if temps else None
    return st


def _pooled(values: dict[str, float], key_all: str = "all") -> float:
    """Mean of the per-CFA-position values (removes channel offsets), or the ``all`` value."""
    pos = [values[p] for p in _POS if p in values and math.isfinite(values[p])]
    return float(np.mean(pos)) if len(pos) == 4 else values[key_all]


def _fit_line(x, y) -> tuple[float, float]:
    slope, intercept = np.polyfit(np.asarray(x, float), np.asarray(y, float), 1)
    return float(slope), float(intercept)


def _hot_mask(master: np.ndarray, sigma: float) -> tuple[np.ndarray, float]:
    med = float(np.median(master))
    mad = float(np.median(np.abs(master - med)))
    robust = max(1.4826 * mad, 1.0)
    threshold = med + sigma * robust
    return master > threshold, threshold


# -- per-ISO calibration ----------------------------------------------------------------------
@dataclass
class _IsoCalibration:
    """The state of one ISO's calibration while its steps (module notes) fill it in order.

    The steps read what the previous ones measured; a figure the frames cannot give is ``None``
    with its reason in ``unknown`` (in the order the steps find them: the report lists them so).
    """
    key: str
    unknown: dict[str, str]
    checker: FrameChecker
    notes: list[str] = field(default_factory=list)
    bias_keys: list = field(default_factory=list)
    dark_keys: list = field(default_factory=list)
    flat_keys: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    views: list[str] = field(default_factory=list)
    fig: dict[str, Any] = field(default_factory=dict)
    mask: np.ndarray | None = None
    bias_master: np.ndarray | None = None
    t_bias: float | None = None
    bias_pairs: int = 0
    points: list = field(default_factory=list)  # dark points: (t, mean per view, pair var per view or None, n)
    var_points: list = field(default_factory=list)
    times: list = field(default_factory=list)
    var_times: list = field(default_factory=list)
    mean_slope: dict = field(default_factory=dict)
    var_slope: dict = field(default_factory=dict)
    read_var: dict[str, float] | None = None
    black: dict[str, float] | None = None
    flat_stats: list = field(default_factory=list)
    saturation_dn: float | None = None
    ptc: list = field(default_factory=list)  # (signal, variance per view, clipped fraction, set)
    gain: dict[str, float] | None = None
    s2_dark: float | None = None
    flat: np.ndarray | None = None
    flat_relvar: float | None = None

    @property
    def K(self) -> float | None:
        return self.gain["all"] if self.gain else None

    def unk(self, name: str, why: str) -> None:
        self.unknown[f"isos.{self.key}.{name}"] = why

    def dark_mean(self, t, v):
        return self.black[v] + (self.mean_slope[v] or 0.0) * t

    def dark_var(self, t, v):
        return self.read_var[v] + max(self.var_slope[v] or 0.0, 0.0) * t


def _iso_reduce(st: _IsoCalibration, records: list[FrameRecord], *, cfa: str | None, hot_pixel_sigma: float) -> None:
    """Group the frames into sets, find the hot pixels (step 7) in the longest dark set, reduce every set."""
    sets: dict[tuple, list[FrameRecord]] = {}
    for r in records:
        sets.setdefault((r.kind, r.exposure_s, r.group), []).append(r)
    st.bias_keys = [k for k in sets if k[0] == "bias"]
    st.dark_keys = sorted((k for k in sets if k[0] == "dark"), key=lambda k: k[1])
    st.flat_keys = sorted((k for k in sets if k[0] == "flat"), key=lambda k: (k[1], k[2]))
    # hot pixels from the longest dark set
    hot_count = None
    if st.dark_keys:
        longest = _reduce_set(sets[st.dark_keys[-1]], st.checker, None, cfa)
        hot, threshold = _hot_mask(longest.master, hot_pixel_sigma)
        st.mask = ~hot
        hot_count = int(hot.sum())
        if st.mask.sum() < 0.5 * st.mask.size:
            raise CalibrationError(f"ISO {st.key}: more than half the pixels of the dark frames are hot; "
                                   f"check {longest.paths[0]}")
    else:
        st.unk("hot_pixels", "no dark frames")
    keys = st.bias_keys + st.dark_keys + st.flat_keys
    st.stats = {k: _reduce_set(sets[k], st.checker, st.mask, cfa) for k in progress(keys, desc=f"ISO {st.key}")}
    stats = st.stats
    shape = st.checker.first.shape
    st.views = list(_views(shape))
    st.fig = {"n_bias": sum(stats[k].n for k in st.bias_keys), "n_dark": sum(stats[k].n for k in st.dark_keys),
              "n_flat": sum(stats[k].n for k in st.flat_keys), "hot_pixels": hot_count,
              "hot_pixel_fraction": None if hot_count is None else hot_count / float(np.prod(shape))}
    temps = [stats[k].temperature_c for k in st.bias_keys + st.dark_keys if stats[k].temperature_c is not None]
    st.fig["temperature_c"] = float(np.mean(temps)) if temps else None


def _iso_bias_and_dark(st: _IsoCalibration) -> None:
    """The master bias (step 1) and the dark level and variance against exposure time (step 6)."""
    stats, bias_keys = st.stats, st.bias_keys
    if bias_keys:
        n = sum(stats[k].n for k in bias_keys)
        st.bias_master = sum(stats[k].master * stats[k].n for k in bias_keys) / n
        st.t_bias = float(sum(stats[k].exposure_s * stats[k].n for k in bias_keys) / n)
        st.bias_pairs = sum(stats[k].n_pairs for k in bias_keys)
        if max(stats[k].zero_fraction for k in bias_keys) > _BLACK_CLIP_FRACTION:
            st.notes.append("bias frames have many 0 DN pixels: the black level clips the read noise, which is "
                            "then underestimated")
    st.points = [(stats[k].exposure_s, stats[k].mean, stats[k].pair_var or None, stats[k].n)
                 for k in bias_keys + st.dark_keys]
    st.times = sorted({p[0] for p in st.points})
    st.var_points = [p for p in st.points if p[2]]
    st.var_times = sorted({p[0] for p in st.var_points})
    st.mean_slope = {v: None for v in st.views}
    st.var_slope = {v: None for v in st.views}
    if len(st.times) >= 3:
        for v in st.views:
            st.mean_slope[v], _ = _fit_line([p[0] for p in st.points], [p[1][v] for p in st.points])
    else:
        why = f"bias/dark frames at {len(st.times)} exposure time(s); the dark current needs at least 3"
        st.unk("dark_current_e_per_s", why)
    if len(st.var_times) >= 3:
        for v in st.views:
            st.var_slope[v], _ = _fit_line([p[0] for p in st.var_points], [p[2][v] for p in st.var_points])
    else:
        st.unk("dark_current_var_e_per_s",
               f"bias/dark pairs at {len(st.var_times)} exposure time(s); the variance method needs at least 3")


def _iso_read_variance(st: _IsoCalibration) -> None:
    """Step 2: the read variance (quantisation included) per view, from bias pairs or the dark pairs' intercept."""
    stats, views = st.stats, st.views
    if st.bias_pairs:
        st.read_var = {}
        for v in views:
            val = sum(stats[k].pair_var[v] * stats[k].n_pairs for k in st.bias_keys if stats[k].n_pairs) / st.bias_pairs
            if st.var_slope[v] is not None and st.var_slope[v] > 0:
                val -= st.var_slope[v] * st.t_bias
            st.read_var[v] = val
        st.fig["read_noise_method"] = f"{st.bias_pairs} bias pair(s)"
    elif len(st.var_times) >= 2:
        st.read_var = {v: _fit_line([p[0] for p in st.var_points], [p[2][v] for p in st.var_points])[1]
                       for v in views}
        st.fig["read_noise_method"] = "intercept of the dark pair variance against exposure time"
    else:
        n_bias = st.fig["n_bias"]
        why = (f"the read noise needs a pair of bias frames; ISO {st.key} has {n_bias} bias frame(s)"
               + (" and no dark pairs at two exposure times" if st.dark_keys else ""))
        for name in ("read_noise_dn", "read_noise_e", "dsnu_dn"):
            st.unk(name, why)


def _iso_black_level(st: _IsoCalibration) -> None:
    """Step 1: the black level per view (the bias level less its dark signal, or the dark levels' intercept)."""
    stats, views = st.stats, st.views
    if st.bias_keys:
        st.black = {v: float(np.average([stats[k].mean[v] for k in st.bias_keys],
                                        weights=[stats[k].n for k in st.bias_keys])) for v in views}
        if st.mean_slope["all"] is not None:
            st.black = {v: st.black[v] - st.mean_slope[v] * st.t_bias for v in views}
    elif len(st.times) >= 2:
        st.black = {v: _fit_line([p[0] for p in st.points], [p[1][v] for p in st.points])[1] for v in views}
        st.notes.append("no bias frames: black level from the intercept of the dark level against exposure time")
    else:
        st.unk("black_level_dn", "no bias frames and dark frames at fewer than two exposure times")


def _iso_saturation_code(st: _IsoCalibration) -> None:
    """Step 5, first part: the code where over-exposed flats pile up."""
    st.flat_stats = [st.stats[k] for k in st.flat_keys]
    singles = [s for s in st.flat_stats if s.n_pairs == 0]
    if singles:
        st.notes.append(f"{len(singles)} flat level(s) with a single frame (no pair): " + ", ".join(
            str(s.paths[0].name) for s in singles[:3]) + (" ..." if len(singles) > 3 else ""))
    sat_candidates = [s.max_code for s in st.flat_stats if s.frac_at_max >= _CLIP_PILE_FRACTION]
    st.saturation_dn = float(max(sat_candidates)) if sat_candidates else None
    if st.saturation_dn is None:
        st.unk("saturation_dn", "no flat frame reaches saturation (no pile-up at a top code)" if st.flat_stats
               else "no flat frames")


def _iso_photon_transfer(st: _IsoCalibration) -> None:
    """Step 4: the photon transfer curve of the flat pairs and the gain, its slope through the origin below
    70 % of the variance maximum (the EMVA saturation level, step 5, is found on the way)."""
    if not st.flat_stats:
        st.unk("gain_dn_per_e", "no flat frames")
        return
    if st.black is None or st.read_var is None:
        st.unk("gain_dn_per_e", "the photon transfer needs the black level and the read noise (bias pairs)")
        return
    saturation_dn, views = st.saturation_dn, st.views
    for s in st.flat_stats:
        if not s.n_pairs:
            continue
        clipped = s.frac_at_max if (saturation_dn is not None and s.max_code >= saturation_dn) else 0.0
        sig = {v: s.mean[v] - st.dark_mean(s.exposure_s, v) for v in views}
        var = {v: s.pair_var[v] - st.dark_var(s.exposure_s, v) for v in views}
        st.ptc.append((sig, var, clipped, s))
    ptc = st.ptc
    ptc.sort(key=lambda p: p[0]["all"])
    usable = [p for p in ptc if p[2] <= _CLIPPED_PAIR_FRACTION and p[0]["all"] > 0]
    if not ptc:
        st.unk("gain_dn_per_e", f"the {len(st.flat_stats)} flat level(s) at ISO {st.key} have no frame pairs; the "
               "photon transfer needs pairs")
        return
    if not usable:
        st.unk("gain_dn_per_e", f"all {st.fig['n_flat']} flat frames at ISO {st.key} are saturated "
               f"(clipped at {saturation_dn:g} DN)" if saturation_dn is not None else
               f"no flat pair at ISO {st.key} has a signal above the dark level")
        return
    variances = np.array([p[1]["all"] for p in ptc])
    imax = int(np.argmax(variances))
    saturated = saturation_dn is not None and imax < len(ptc) - 1
    if saturated:
        limit = 0.7 * ptc[imax][0]["all"]
        fit = [p for p in usable if p[0]["all"] <= limit]
        st.fig["saturation_mean_dn"] = ptc[imax][0]["all"] + st.dark_mean(ptc[imax][3].exposure_s, "all")
    else:
        fit = usable
        st.fig["saturation_mean_dn"] = None
        st.unk("saturation_mean_dn", "the flat variance never falls after its maximum")
    if len(fit) < 2:
        st.unk("gain_dn_per_e", f"only {len(fit)} unclipped flat pair(s) below 70 % of saturation at ISO "
               f"{st.key}; the photon transfer slope needs at least 2")
        return
    gain = {}
    for v in views:
        x = np.array([p[0][v] for p in fit])
        y = np.array([p[1][v] for p in fit])
        gain[v] = float(np.dot(x, y) / np.dot(x, x))
    if not gain["all"] > 0:
        st.unk("gain_dn_per_e", f"the photon transfer slope is not positive ({gain['all']:g})")
    else:
        st.gain = gain
        st.fig["gain_fit_points"] = len(fit)


def _iso_noise_figures(st: _IsoCalibration) -> None:
    """The figures of steps 1, 2 and 6 in electrons: black level, read noise, dark current (both methods)."""
    fig, black, read_var, K = st.fig, st.black, st.read_var, st.K
    fig["gain_dn_per_e"] = K
    fig["black_level_dn"] = _pooled(black) if black else None
    fig["black_level_per_channel_dn"] = [black[p] for p in _POS] if black and "p00" in black else None
    fig["read_noise_var_dn2"] = read_var["all"] if read_var else None
    rn_dn = math.sqrt(max(_pooled(read_var) - SIGMA2_Q, 0.0)) if read_var else None
    if read_var and _pooled(read_var) < SIGMA2_Q:
        st.notes.append("read variance below the quantisation noise (1/12 DN^2): read noise recorded as 0")
    fig["read_noise_dn"] = rn_dn
    fig["read_noise_e"] = rn_dn / K if (rn_dn is not None and K) else None
    if rn_dn is not None and not K:
        st.unk("read_noise_e", "the gain is unknown")
    fig["temporal_dark_noise_dn"] = math.sqrt(max(_pooled(read_var), 0.0)) if read_var else None
    # dark current
    for name, slope, scale in (("dark_current_e_per_s", st.mean_slope["all"], 1),
                               ("dark_current_var_e_per_s", st.var_slope["all"], 2)):
        if slope is None:
            fig[name] = None
        elif not K:
            fig[name] = None
            st.unk(name, "the gain is unknown")
        else:
            value = slope / K**scale
            if value < 0:
                st.notes.append(f"{name}: measured slope is negative ({value:.4g} e-/s); recorded as 0")
                value = 0.0
            fig[name] = value


def _iso_dsnu_and_saturation(st: _IsoCalibration) -> None:
    """Step 3 (DSNU from the master bias) and step 5's figures (full well, EMVA saturation capacity)."""
    fig, K = st.fig, st.K
    if st.bias_master is not None and st.read_var is not None:
        n_bias = fig["n_bias"]
        s2 = {v: stats_var - st.read_var[v] / n_bias for v, stats_var in _spatial(st.bias_master, st.mask).items()}
        dsnu = math.sqrt(max(_pooled(s2), 0.0))
        fig["dsnu_dn"] = dsnu
        fig["dsnu_e"] = dsnu / K if K else None
        st.s2_dark = max(_pooled(s2), 0.0)
    else:
        fig["dsnu_dn"] = fig["dsnu_e"] = None
        st.s2_dark = None
        st.unk("dsnu_dn", "needs bias frames with a pair")
    # saturation / full well
    saturation_dn = st.saturation_dn
    fig["saturation_dn"] = saturation_dn
    if saturation_dn is not None and K and st.black:
        fig["full_well_e"] = (saturation_dn - fig["black_level_dn"]) / K
    else:
        fig["full_well_e"] = None
        if saturation_dn is not None:
            st.unk("full_well_e", "the gain or the black level is unknown")
        else:
            st.unk("full_well_e", st.unknown[f"isos.{st.key}.saturation_dn"])
    if K and fig.get("saturation_mean_dn") is not None:
        fig["saturation_capacity_emva_e"] = (fig["saturation_mean_dn"] - fig["black_level_dn"]) / K
    else:
        fig["saturation_capacity_emva_e"] = None
        st.unk("saturation_capacity_emva_e", "needs the gain and flats beyond the variance maximum")


def _iso_prnu_and_flat_field(st: _IsoCalibration) -> None:
    """Step 8: the PRNU from the flat level nearest half saturation, the flat field and the master bias's noise."""
    fig, K, ptc, views = st.fig, st.K, st.ptc, st.views
    fig["prnu"] = None
    if K and st.s2_dark is not None and ptc and (st.gain is not None):
        top = fig["full_well_e"] * K if fig["full_well_e"] else max(p[0]["all"] for p in ptc)
        candidates = [p for p in ptc if p[2] <= _CLIPPED_PAIR_FRACTION and p[0]["all"] > 0]
        if candidates:
            sig, var, _, s = min(candidates, key=lambda p: abs(p[0]["all"] - 0.5 * top))
            temporal = {v: s.pair_var[v] for v in views}
            s2 = {v: sv - temporal[v] / s.n - st.s2_dark for v, sv in _spatial(s.master, st.mask).items()}
            fig["prnu"] = math.sqrt(max(_pooled(s2), 0.0)) / sig["all"]
    if fig["prnu"] is None:
        st.unk("prnu", "needs the gain, the DSNU and an unclipped flat pair")
    read_var = st.read_var
    st.flat, st.flat_relvar, why = _flat_field(
        st.flat_stats, st.bias_master, n_bias=fig["n_bias"], read_var=read_var["all"] if read_var else None,
        t_bias=st.t_bias, dark_slope=st.mean_slope["all"], saturation_dn=st.saturation_dn, gain=K, mask=st.mask)
    fig["flat_field_std"] = math.sqrt(st.flat_relvar) if st.flat_relvar is not None else None
    if why:
        st.unk("flat_field", why)
    fig["bias_frame_std_dn"] = (math.sqrt(max(read_var["all"], 0.0) / fig["n_bias"])
                                if (st.bias_master is not None and read_var) else None)


def _iso_dynamic_range(st: _IsoCalibration) -> None:
    """Step 10: EMVA dynamic range and SNR, and full well over read noise in stops."""
    fig = st.fig
    if fig["saturation_capacity_emva_e"] and fig["temporal_dark_noise_dn"] is not None:
        s_dark = math.sqrt(max(fig["temporal_dark_noise_dn"] ** 2, 0.24))
        threshold = s_dark / st.K + 0.5
        fig["absolute_sensitivity_threshold_e"] = threshold
        fig["dynamic_range_emva"] = fig["saturation_capacity_emva_e"] / threshold
        fig["dynamic_range_emva_db"] = 20 * math.log10(fig["dynamic_range_emva"])
        fig["snr_max"] = math.sqrt(fig["saturation_capacity_emva_e"])
        fig["snr_max_db"] = 20 * math.log10(fig["snr_max"])
    else:
        for k in ("absolute_sensitivity_threshold_e", "dynamic_range_emva", "dynamic_range_emva_db", "snr_max",
                  "snr_max_db"):
            fig[k] = None
        st.unk("dynamic_range_emva", "needs the EMVA saturation capacity and the dark noise")
    if fig["full_well_e"] and fig["read_noise_e"]:
        fig["dynamic_range_stops"] = math.log2(fig["full_well_e"] / fig["read_noise_e"])
    else:
        fig["dynamic_range_stops"] = None
    fig["quantum_efficiency"] = None  # no photon counts: see calibrate()


def _iso_channels(st: _IsoCalibration) -> None:
    """Black level, read noise and gain per CFA channel, and which of them differ between channels."""
    if "p00" not in st.views:
        return
    black, read_var, gain, K = st.black, st.read_var, st.gain, st.K
    channels = {}
    for p, name in zip(_POS, _channel_names(st.checker.cfa)):
        ch = {"black_level_dn": black[p] if black else None,
              "read_noise_dn": math.sqrt(max(read_var[p] - SIGMA2_Q, 0.0)) if read_var else None,
              "gain_dn_per_e": gain[p] if gain else None}
        ch["read_noise_e"] = ch["read_noise_dn"] / ch["gain_dn_per_e"] if (ch["read_noise_dn"] is not None
                                                                            and ch["gain_dn_per_e"]) else None
        channels[name] = ch
    st.fig["channels"] = channels
    differ = []
    if gain and max(abs(gain[p] / K - 1) for p in _POS) > 0.05:
        differ.append("gain")
    if black and max(black[p] for p in _POS) - min(black[p] for p in _POS) > 1.0:
        differ.append("black level")
    st.fig["channels_differ"] = differ


def _iso_curves(st: _IsoCalibration) -> dict[str, Any]:
    """The dark and photon-transfer curves the report plots."""
    points, var_points, ptc = st.points, st.var_points, st.ptc
    return {
        "dark_exposure_s": [p[0] for p in points],
        "dark_mean_dn": [p[1]["all"] for p in points],
        "dark_var_exposure_s": [p[0] for p in var_points],
        "dark_var_dn2": [p[2]["all"] for p in var_points],
        "dark_mean_slope_dn_per_s": st.mean_slope["all"],
        "dark_var_slope_dn2_per_s": st.var_slope["all"],
        "black_level_dn": st.fig["black_level_dn"],
        "read_var_dn2": st.fig["read_noise_var_dn2"],
        "flat_signal_dn": [p[0]["all"] for p in ptc],
        "flat_var_dn2": [p[1]["all"] for p in ptc],
        "flat_clipped_fraction": [p[2] for p in ptc],
        "flat_exposure_s": [p[3].exposure_s for p in ptc],
        "gain_dn_per_e": st.K,
        "read_noise_e": st.fig.get("read_noise_e"),
    }


def _calibrate_iso(iso_key: str, records: list[FrameRecord], *, cfa: str | None, hot_pixel_sigma: float,
                   unknown: dict[str, str]) -> tuple[dict[str, Any], dict[str, Any], np.ndarray | None,
                                                     np.ndarray | None, FrameChecker, tuple | None]:
    """The figures of one ISO, in the order of the module notes' steps (their numbers in the helpers' notes)."""
    st = _IsoCalibration(key=iso_key, unknown=unknown, checker=FrameChecker(f"ISO {iso_key}"))
    _iso_reduce(st, records, cfa=cfa, hot_pixel_sigma=hot_pixel_sigma)
    _iso_bias_and_dark(st)
    _iso_read_variance(st)
    _iso_black_level(st)
    _iso_saturation_code(st)
    _iso_photon_transfer(st)
    _iso_noise_figures(st)
    _iso_dsnu_and_saturation(st)
    _iso_prnu_and_flat_field(st)
    _iso_dynamic_range(st)
    _iso_channels(st)
    st.fig["notes"] = st.notes
    curves = _iso_curves(st)
    hot = None if st.mask is None else ~st.mask
    flat = None if st.flat is None else (st.flat, st.flat_relvar)
    return st.fig, curves, st.bias_master, hot, st.checker, flat


def _flat_field(flat_stats: list, bias_master: np.ndarray | None, *, n_bias: int, read_var: float | None,
                t_bias: float | None, dark_slope: float | None, saturation_dn: float | None, gain: float | None,
                mask: np.ndarray | None) -> tuple[np.ndarray | None, float | None, str | None]:
    """One ISO's flat-field map (not yet normalised), its relative variance, or the reason there is none."""
    if bias_master is None or read_var is None or not n_bias:
        return None, None, "needs bias frames with a pair (the per-pixel dark level and its noise)"
    if saturation_dn is not None:
        unclipped = [s for s in flat_stats if s.max_code < saturation_dn]
    else:
        unclipped = [s for s in flat_stats if s.frac_at_max < _CLIP_PILE_FRACTION]
    num = np.zeros(bias_master.shape)
    den = var_num = 0.0
    n_total = 0
    for s in unclipped:
        dark = bias_master + (dark_slope or 0.0) * (s.exposure_s - (t_bias or 0.0))
        signal = s.master - dark
        level = float(signal[mask].mean()) if mask is not None else float(signal.mean())
        var_t = s.pair_var.get("all") if s.pair_var else (gain * level + read_var if gain else None)
        if level <= 0 or var_t is None:
            continue
        num += s.n * signal
        den += s.n * level
        var_num += s.n * var_t  # var(n * master) = n * var_t
        n_total += s.n
    if not n_total:
        return None, None, "no flat level without clipped pixels and with a measurable temporal noise"
    var_num += n_total**2 * read_var / n_bias  # every level subtracts the same master bias
    return num / den, var_num / den**2, None


def _normalise_flat(flat: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """Divide each CFA position (each 2x2 phase) by its mean over the usable pixels."""
    out = flat.copy()
    views = _views(flat.shape)
    for rs, cs in [views[p] for p in _POS] if "p00" in views else [views["all"]]:
        sel = flat[rs, cs] if mask is None else flat[rs, cs][mask[rs, cs]]
        out[rs, cs] /= sel.mean()
    return out


def _spatial(image: np.ndarray, mask: np.ndarray | None) -> dict[str, float]:
    out = {}
    for name, (rs, cs) in _views(image.shape).items():
        sel = image[rs, cs] if mask is None else image[rs, cs][mask[rs, cs]]
        out[name] = float(sel.var(ddof=1)) if sel.size > 1 else float("nan")
    return out


def _read_noise_split(figures: dict[str, dict[str, Any]]) -> dict[str, Any]:
    pts = [(f["gain_dn_per_e"] ** 2, f["read_noise_dn"] ** 2) for f in figures.values()
           if f.get("gain_dn_per_e") and f.get("read_noise_dn") is not None]
    if len({round(x, 12) for x, _ in pts}) < 2:
        return {"sigma_pre_e": None, "sigma_post_dn": None,
                "unknown": f"the split needs read noise and gain at two or more ISOs; {len(pts)} ISO(s) have both"}
    slope, intercept = _fit_line([p[0] for p in pts], [p[1] for p in pts])
    out: dict[str, Any] = {"model": "read_noise_dn^2 = gain^2 * sigma_pre_e^2 + sigma_post_dn^2",
                           "sigma_pre_e2": slope, "sigma_post_dn2": intercept, "n_isos": len(pts)}
    out["sigma_pre_e"] = math.sqrt(slope) if slope >= 0 else None
    out["sigma_post_dn"] = math.sqrt(max(intercept, 0.0))
    if intercept < 0:
        out["note"] = f"fitted sigma_post^2 is negative ({intercept:.4g} DN^2, no post-amplifier noise measurable); 0 recorded"
    if slope < 0:
        out["unknown"] = "the read variance falls with the gain; no pre-amplifier noise can be fitted"
    return out


def _median(values):
    vals = [v for v in values if v is not None]
    return float(np.median(vals)) if vals else None


# -- public entry ------------------------------------------------------------------------------
MANIFEST_NAMES = ("manifest.json", "manifest.csv")


def find_calibration_input(path: str | os.PathLike) -> Path:
    """The calibration input ``path`` names: the file itself, or, for a folder, the frame manifest
    (``manifest.json``, else ``manifest.csv``) or the one EMVA 1288 descriptor inside it.

    Parameters
    ----------
    path : str or os.PathLike
        A manifest, a descriptor, or a folder holding one.

    Returns
    -------
    pathlib.Path
        ``path`` itself when it is a file, else the input found in the folder.

    Raises
    ------
    MissingFileError
        ``path`` does not exist.
    InputError
        A folder holding neither, or several descriptors and no manifest (they are named).

    Examples
    --------
    >>> from lfproc.calib import find_calibration_input, simulate_frames
    >>> _ = simulate_frames("paper-low", "emva", format="emva", size=(16, 16))
    >>> find_calibration_input("emva")
    PosixPath('emva/emva1288.txt')
    """
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such file or folder; expected a frame manifest (.csv/.json), an EMVA "
                               "1288 descriptor, or a folder holding one")
    if not path.is_dir():
        return path
    for name in MANIFEST_NAMES:
        if (path / name).is_file():
            return path / name
    descriptors = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in (".txt", "")
                         and is_descriptor(p))
    if len(descriptors) == 1:
        return descriptors[0]
    if descriptors:
        raise InputError(f"{path}: a folder with {len(descriptors)} EMVA 1288 descriptors "
                         f"({', '.join(p.name for p in descriptors)}); name the one to use")
    found = sorted(p.name for p in path.iterdir())
    listing = ", ".join(found[:6]) + (" ..." if len(found) > 6 else "") if found else "nothing"
    raise InputError(f"{path}: a folder; expected a frame manifest ({' or '.join(MANIFEST_NAMES)}) or an EMVA 1288 "
                     f"descriptor (a .txt file starting with 'v' and 'n' lines) inside it, found {listing}")


def calibrate(
    frames_or_manifest,
    *,
    name: str | None = None,
    adc_bits: int | None = None,
    cfa_pattern: str | None = None,
    iso: int | None = None,
    hot_pixel_sigma: float = 6.0,
    frames_root: str | os.PathLike | None = None,
) -> CalibrationResult:
    """Measure a camera profile from calibration frames.

    Parameters
    ----------
    frames_or_manifest : str, Path, list of FrameRecord or EmvaDescriptor
        A manifest (CSV or JSON), an EMVA 1288 descriptor file, a folder holding one of them
        (:func:`find_calibration_input`), frame records (see
        :func:`lfproc.calib.frames.read_manifest`) or a parsed descriptor.
    name : str, optional
        Profile name (default: the manifest's ``name``, else the input's file stem).
    adc_bits : int, optional
        ADC resolution; default: the raw files' white level, the descriptor's ``n`` line, the
        manifest's ``adc_bits``, else the largest code seen (recorded in ``source``).
    cfa_pattern : str, optional
        Bayer layout when the frames do not carry it (PNG/TIFF); "RGGB" with a recorded
        ``unknown`` entry otherwise.
    iso : int, optional
        ISO under which EMVA 1288 figures are stored in the profile (EMVA data give none;
        default 100, recorded in ``unknown``). ``figures`` use the key ``"default"``.
    hot_pixel_sigma : float
        Hot-pixel threshold in robust standard deviations of the longest master dark.
    frames_root : str or Path, optional
        A folder the frames of a manifest/descriptor may lie in; by default they must lie in
        the manifest's (descriptor's) folder.

    Returns
    -------
    CalibrationResult
        The measured profile, every figure per ISO, the unknowns and the plot data.

    Raises
    ------
    CalibrationError
        Frames of mixed size/bit depth/CFA in one ISO (named), or no ISO gives a gain or a
        saturation level (the reasons are named).
    InputError, FileFormatError, MissingFileError
        Bad manifest rows (named), unreadable frames (named).
    """
    check_positive("hot_pixel_sigma", hot_pixel_sigma)
    options: dict[str, Any] = {}
    source_path = None
    if isinstance(frames_or_manifest, EmvaDescriptor):
        return _calibrate_emva(frames_or_manifest, name=name, adc_bits=adc_bits, cfa_pattern=cfa_pattern, iso=iso)
    if isinstance(frames_or_manifest, (str, os.PathLike)):
        source_path = find_calibration_input(frames_or_manifest)
        if source_path.is_file() and source_path.suffix.lower() not in (".csv", ".json") and is_descriptor(source_path):
            return _calibrate_emva(read_descriptor(source_path, root=frames_root), name=name, adc_bits=adc_bits,
                                   cfa_pattern=cfa_pattern, iso=iso)
        records, options = read_manifest(source_path, root=frames_root)
    else:
        records = list(frames_or_manifest)
        if not records or not all(isinstance(r, FrameRecord) for r in records):
            raise InputError("frames: expected a manifest path, an EMVA 1288 descriptor or a list of FrameRecord")
    missing = [r for r in records if r.iso is None]
    if missing:
        raise InputError(f"{missing[0].where or missing[0].path}: missing ISO; every frame needs its ISO")
    cfa = cfa_pattern or options.get("cfa_pattern") or next((r.cfa_pattern for r in records if r.cfa_pattern), None)
    if cfa is not None and str(cfa).upper() == MONO.upper():
        cfa = MONO
    by_iso: dict[int, list[FrameRecord]] = {}
    for r in records:
        key = int(round(r.iso))
        if abs(key - r.iso) > 1e-6:
            raise InputError(f"{r.where or r.path}: ISO: expected a whole number, found {r.iso:g}")
        by_iso.setdefault(key, []).append(r)
    m = _measure_isos(by_iso, cfa=cfa, hot_pixel_sigma=hot_pixel_sigma)
    return _build(m, name=name or options.get("name") or (source_path.stem if source_path else "calibrated"),
                  adc_bits=adc_bits or options.get("adc_bits") or (m.bit_source[0] if m.bit_source else None),
                  bits_from=("argument" if adc_bits else "manifest" if options.get("adc_bits") else
                             m.bit_source[1] if m.bit_source else None),
                  max_code=m.max_code, cfa=cfa or m.frame_cfa, input_path=source_path, kind="frames")


@dataclass
class _Measured:
    """What the frames gave, per ISO key: figures, curves, hot-pixel maps, master bias frames and the
    unknown figures' reasons; the combined flat field; for EMVA data the ISO of each key and extra source
    entries; for frames the CFA they carry, the bit depth's source and the largest saturation code."""
    figures: dict[str, dict[str, Any]] = field(default_factory=dict)
    curves: dict[str, dict[str, Any]] = field(default_factory=dict)
    hot_pixels: dict[str, np.ndarray] = field(default_factory=dict)
    bias_frames: dict[int, np.ndarray] = field(default_factory=dict)
    unknown: dict[str, str] = field(default_factory=dict)
    flat_field: np.ndarray | None = None
    flat_field_std: float | None = None
    bias_frame_std_dn: dict | None = None
    iso_keys: dict | None = None
    extra_source: dict | None = None
    frame_cfa: str | None = None
    bit_source: tuple | None = None
    max_code: int = 0


def _measure_isos(by_iso: dict[int, list[FrameRecord]], *, cfa, hot_pixel_sigma: float) -> _Measured:
    """Calibrate every ISO (:func:`_calibrate_iso`), check one frame size throughout, combine the flat fields."""
    m = _Measured()
    flats: dict[int, tuple[np.ndarray, float]] = {}
    shapes = {}
    for key in sorted(by_iso):
        fig, cur, bias, hot, checker, flat = _calibrate_iso(str(key), by_iso[key], cfa=cfa,
                                                            hot_pixel_sigma=hot_pixel_sigma, unknown=m.unknown)
        if flat is not None:
            flats[key] = flat
        m.figures[str(key)] = fig
        m.curves[str(key)] = cur
        shapes[key] = checker.first.shape
        if hot is not None:
            m.hot_pixels[str(key)] = hot
        if bias is not None:
            m.bias_frames[key] = bias.astype(np.float32)
        m.frame_cfa = m.frame_cfa or checker.first.cfa_pattern
        if checker.first.white_level_dn and checker.first.source != "image":
            m.bit_source = (checker.first.bit_depth, f"white level of {checker.first.path.name}")
        for v in (fig.get("saturation_dn"),):
            if v:
                m.max_code = max(m.max_code, int(v))
    m.unknown["quantum_efficiency"] = ("a frame manifest gives no photon counts, so no quantum efficiency, "
                                       "responsivity or linearity (an EMVA 1288 descriptor's 'b' lines give them)")
    if len(set(shapes.values())) > 1:
        detail = ", ".join(f"ISO {k}: {s[0]}x{s[1]}" for k, s in shapes.items())
        raise CalibrationError(f"frames of different sizes across ISOs ({detail}); one sensor mode per calibration")
    if flats:  # the ISOs' maps, inverse-variance weighted (the PRNU is a property of the pixel)
        weights = {k: 1.0 / relvar for k, (_, relvar) in flats.items()}
        total = sum(weights.values())
        combined = sum(weights[k] * fm for k, (fm, _) in flats.items()) / total
        good = None
        for hot in m.hot_pixels.values():
            good = ~hot if good is None else good & ~hot
        m.flat_field = _normalise_flat(combined, good).astype(np.float32)
        m.flat_field_std = math.sqrt(1.0 / total)
    m.bias_frame_std_dn = {k: m.figures[str(k)]["bias_frame_std_dn"] for k in m.bias_frames
                           if m.figures[str(k)].get("bias_frame_std_dn") is not None}
    return m


def _build(m: _Measured, *, name, adc_bits, bits_from, max_code, cfa, input_path, kind) -> CalibrationResult:
    """The camera profile and the calibration result of what the frames (or EMVA data) gave."""
    figures, curves, hot_pixels, bias_frames, unknown = m.figures, m.curves, m.hot_pixels, m.bias_frames, m.unknown
    iso_keys, extra_source, flat_field, flat_field_std = m.iso_keys, m.extra_source, m.flat_field, m.flat_field_std
    bias_frame_std_dn = m.bias_frame_std_dn
    with_gain = {k: f for k, f in figures.items() if f.get("gain_dn_per_e")}
    if not with_gain:
        reasons = "; ".join(f"ISO {k}: {unknown.get(f'isos.{k}.gain_dn_per_e', 'unknown')}" for k in figures)
        raise CalibrationError(f"the frames give no system gain at any ISO ({reasons})")
    wells = [f["full_well_e"] for f in figures.values() if f.get("full_well_e")]
    if not wells:
        reasons = "; ".join(f"ISO {k}: {unknown.get(f'isos.{k}.full_well_e', 'unknown')}" for k in figures)
        raise CalibrationError(f"the frames give no saturation level at any ISO ({reasons}); add over-exposed flats")
    profile_unknown = dict(unknown)
    source: dict[str, Any] = {"kind": "calibrated", "method": kind, "lfproc_version": __version__,
                              "input": str(input_path) if input_path else None}
    if adc_bits is None:
        adc_bits = max(8, int(math.ceil(math.log2(max_code + 1)))) if max_code else 16
        bits_from = f"the largest saturation code ({max_code} DN)"
    source["adc_bits_from"] = bits_from
    if cfa is None:
        cfa = "RGGB"
        profile_unknown["cfa_pattern"] = "the frames carry no CFA layout (PNG/TIFF) and none was given; RGGB recorded"
    read_model = _read_noise_split(figures)
    source["read_noise_model"] = {k: v for k, v in read_model.items()}
    temps = [f.get("temperature_c") for f in figures.values() if f.get("temperature_c") is not None]
    if temps:
        source["temperature_c"] = float(np.mean(temps))
    if extra_source:
        source.update(extra_source)
    isos = {}
    for key, f in figures.items():
        iso_int = iso_keys[key] if iso_keys else int(key)
        isos[iso_int] = IsoFigures(
            gain_dn_per_e=f.get("gain_dn_per_e"), read_noise_e=f.get("read_noise_e"),
            read_noise_dn=f.get("read_noise_dn"), dark_current_e_per_s=f.get("dark_current_e_per_s"),
            black_level_dn=f.get("black_level_dn"), full_well_e=f.get("full_well_e"), dsnu_dn=f.get("dsnu_dn"),
            prnu=f.get("prnu"),
        )
        if iso_keys:  # EMVA: rename the unknown keys to the ISO the profile uses
            for k in list(profile_unknown):
                if k.startswith(f"isos.{key}."):
                    profile_unknown[f"isos.{iso_int}." + k.split(".", 2)[2]] = profile_unknown.pop(k)
    white = float(2**adc_bits - 1)
    blacks = [f["black_level_dn"] for f in figures.values() if f.get("black_level_dn") is not None]
    black = _median(blacks)
    if black is None:
        raise CalibrationError("the frames give no black level at any ISO; add bias frames")
    dark = _median(f.get("dark_current_e_per_s") for f in figures.values())
    if dark is None:
        profile_unknown["dark_current_e_per_s"] = "no ISO gives a dark current; 0 recorded"
    prnu = _median(f.get("prnu") for f in figures.values())
    if prnu is None:
        profile_unknown["prnu"] = "no ISO gives a PRNU; 0 recorded"
    dsnu = _median(f.get("dsnu_e") for f in figures.values())
    if dsnu is None:
        profile_unknown["dsnu_e"] = "no ISO gives a DSNU; 0 recorded"
    if max(max_code, 0) > white:
        raise CalibrationError(f"codes up to {max_code} DN do not fit adc_bits={adc_bits}; pass the right adc_bits")
    profile = CameraProfile(
        name=name, adc_bits=int(adc_bits), white_level_dn=white, black_level_dn=max(black, 0.0),
        full_well_e=float(max(wells)), isos=isos, gamma=1.0, cfa_pattern=cfa,
        dark_current_e_per_s=dark or 0.0, prnu=prnu or 0.0, dsnu_e=dsnu or 0.0, fixed_pattern_seed=0,
        description=f"Measured by lfproc calibrate {__version__} from {input_path or 'frames'}",
        bias_frames=bias_frames, unknown=profile_unknown, source=source,
        bias_frame_std_dn=bias_frame_std_dn or {}, flat_field=flat_field, flat_field_std=flat_field_std or 0.0,
    )
    # one saturation code everywhere: the profile's (full well or ADC, whichever clips first)
    for key, f in figures.items():
        iso_int = iso_keys[key] if iso_keys else int(key)
        if f.get("gain_dn_per_e") and f.get("full_well_e"):
            f["saturation_dn"] = profile.saturation_dn(iso_int)
    source["emva1288"] = {str(iso_keys[key] if iso_keys else key): {k: f.get(k) for k in EMVA_SOURCE_KEYS}
                          for key, f in figures.items()}
    profile = replace(profile, source=dict(source))
    keys = {key: int(iso_keys[key] if iso_keys else int(key)) for key in figures}
    notes = [f"ISO {keys[k]}: {n}" for k, f in figures.items() for n in f.get("notes", [])]
    for key, f in figures.items():
        f["iso"] = keys[key]
    return CalibrationResult(profile=profile, figures=figures, unknown=unknown, read_noise_model=read_model,
                             curves=curves, hot_pixels=hot_pixels, notes=notes, source=source, iso_keys=keys)


def _emva_maps(data, res, fig, iso_int, saturation_dn, cfa_pattern, unknown, key):
    """Per-pixel maps of an EMVA 1288 data set from its stacks: the master bias (the dark stack's
    mean image less the mean dark signal of its exposure) and the flat field (bright minus dark
    stack, mean 1 per CFA position, or overall for a monochrome sensor)."""
    bias_frames: dict[int, np.ndarray] = {}
    bias_std: dict[int, float] = {}
    flat = flat_std = None
    K = res["K"]
    if data.dark_image is None:
        unknown[f"isos.{key}.bias_frame"] = "the descriptor has no dark stack (a 'd' step with more than two images)"
        unknown[f"isos.{key}.flat_field"] = unknown[f"isos.{key}.bias_frame"]
        return bias_frames, bias_std, flat, flat_std
    sd = data.spatial_dark
    t_dark = sd.get("exposure_ns", 0.0) * 1e-9
    dark_signal = (res["u_I_mean"] or 0.0) * K * t_dark
    bias_frames[iso_int] = (data.dark_image - np.float32(dark_signal)).astype(np.float32)
    bias_std[iso_int] = math.sqrt(sd["var_mean"] / sd["L"])
    fig["bias_frame_std_dn"] = bias_std[iso_int]
    if data.bright_image is None:
        unknown[f"isos.{key}.flat_field"] = "the descriptor has no bright stack (a 'b' step with more than two images)"
    elif saturation_dn is not None and data.spatial["max_code"] >= saturation_dn:
        unknown[f"isos.{key}.flat_field"] = (f"the bright stack reaches the saturation code ({saturation_dn:g} DN): "
                                            "a flat field needs unclipped frames")
    else:
        sb = data.spatial
        signal_image = data.bright_image.astype(np.float64) - data.dark_image
        signal = float(signal_image.mean())
        if signal <= 0:
            unknown[f"isos.{key}.flat_field"] = "the bright stack is not above the dark stack"
        else:
            if cfa_pattern in (None, MONO):
                flat = (signal_image / signal).astype(np.float32)
            else:
                flat = _normalise_flat(signal_image, None).astype(np.float32)
            flat_std = math.sqrt(sb["var_mean"] / sb["L"] + sd["var_mean"] / sd["L"]) / signal
            fig["flat_field_std"] = flat_std
    return bias_frames, bias_std, flat, flat_std


def _calibrate_emva(desc: EmvaDescriptor, *, name, adc_bits, cfa_pattern, iso) -> CalibrationResult:
    data = reduce_descriptor(desc)
    res, unk_emva = evaluate(data)
    key = DEFAULT_ISO_KEY
    iso_int = int(iso) if iso is not None else 100
    unknown = {f"isos.{key}.{k}": v for k, v in unk_emva.items()}
    K = res["K"]
    notes = list(data.notes)
    # The profile's saturation code: where the over-exposed pairs pile up (as for frame manifests);
    # the EMVA mean at the variance maximum (mu_y.sat) lies below it and is kept as its own figure.
    saturation_dn = data.clip_code(_CLIP_PILE_FRACTION)
    if saturation_dn is None and res["u_y_sat"] is not None:
        saturation_dn = float(round(res["u_y_sat"]))
        notes.append("no bright pair piles up at a top code: the saturation code is the mean at the variance "
                     "maximum (EMVA mu_y.sat), rounded")
    full_well = (saturation_dn - res["black_level_dn"]) / K if saturation_dn is not None else None
    fig = {
        "gain_dn_per_e": K,
        "read_noise_e": res["sigma_d"],
        "read_noise_dn": res["sigma_d"] * K,
        "temporal_dark_noise_dn": res["sigma_y_dark"],
        "black_level_dn": res["black_level_dn"],
        "full_well_e": full_well,
        "saturation_dn": saturation_dn,
        "saturation_mean_dn": res["u_y_sat"],
        "saturation_capacity_emva_e": res["u_e_sat"],
        "saturation_capacity_emva_photons": res["u_p_sat"],
        "absolute_sensitivity_threshold_e": res["u_e_min"],
        "absolute_sensitivity_threshold_photons": res["u_p_min"],
        "dark_current_e_per_s": res["u_I_mean"],
        "dark_current_var_e_per_s": res["u_I_var"],
        "dsnu_dn": res["DSNU1288_DN"],
        "dsnu_e": res["DSNU1288"],
        "prnu": res["PRNU1288"] / 100 if res["PRNU1288"] is not None else None,
        "quantum_efficiency": res["QE"],
        "responsivity_dn_per_photon": res["R"],
        "linearity_error_min_percent": res["LE_min"],
        "linearity_error_max_percent": res["LE_max"],
        "dynamic_range_emva": res["DR"],
        "dynamic_range_emva_db": res["DR_dB"],
        "snr_max": res["SNR_max"],
        "snr_max_db": res["SNR_max_dB"],
        "emva1288": {k: v for k, v in res.items() if k != "curves"},
        "notes": notes,
    }
    if fig["dark_current_e_per_s"] is not None and fig["dark_current_e_per_s"] < 0:
        fig["notes"].append(f"dark current from the mean is negative ({fig['dark_current_e_per_s']:.4g} e-/s); 0 recorded")
        fig["dark_current_e_per_s"] = 0.0
    for src, dst in (("u_p_sat", "full_well_e"), ("u_e_sat", "saturation_capacity_emva_e"),
                     ("u_p_sat", "saturation_capacity_emva_photons"), ("u_y_sat", "saturation_mean_dn"),
                     ("u_I_mean", "dark_current_e_per_s"), ("u_I_var", "dark_current_var_e_per_s"),
                     ("DSNU1288", "dsnu_e"), ("PRNU1288", "prnu"), ("QE", "quantum_efficiency"),
                     ("QE", "absolute_sensitivity_threshold_photons"), ("LE_min", "linearity_error_min_percent"),
                     ("LE_max", "linearity_error_max_percent"), ("DR", "dynamic_range_emva_db"),
                     ("SNR_max", "snr_max_db")):
        if src in unk_emva and fig[dst] is None:
            unknown[f"isos.{key}.{dst}"] = unk_emva[src]
    if fig["full_well_e"] and fig["read_noise_e"]:
        fig["dynamic_range_stops"] = math.log2(fig["full_well_e"] / fig["read_noise_e"])
    c = res["curves"]
    curves = {key: {
        "dark_exposure_s": c["texp_s"], "dark_mean_dn": c["u_ydark"], "dark_var_exposure_s": c["texp_s"],
        "dark_var_dn2": c["s2_ydark"], "dark_mean_slope_dn_per_s": (res["u_I_mean"] or 0) * K if res["u_I_mean"] is not None else None,
        "dark_var_slope_dn2_per_s": res["u_I_var"] * K**2 if res["u_I_var"] is not None else None,
        "black_level_dn": res["black_level_dn"], "read_var_dn2": res["sigma_y_dark"] ** 2,
        "flat_signal_dn": (np.array(c["u_y"]) - np.array(c["u_ydark"])).tolist(),
        "flat_var_dn2": (np.array(c["s2_y"]) - np.array(c["s2_ydark"])).tolist(),
        "flat_clipped_fraction": [0.0] * len(c["u_y"]), "gain_dn_per_e": K,
        "flat_exposure_s": c["texp_s"], "flat_photons": c["u_p"], "read_noise_e": res["sigma_d"],
        "flat_dark_var_dn2": c["s2_ydark"],
    }}
    unknown_all = dict(unknown)
    if iso is None:
        unknown_all["iso"] = f"EMVA 1288 data give no ISO; the figures are stored under ISO {iso_int}"
    extra = {"emva1288_release": desc.release}
    if cfa_pattern is None:
        # an EMVA 1288 data set is one channel: a monochrome sensor (a colour camera is measured per channel)
        cfa_pattern = MONO
        extra["cfa_pattern_from"] = "EMVA 1288 data are one channel: recorded as a monochrome sensor (give --cfa " \
                                    "for a Bayer sensor)"
    bias_frames, bias_std, flat_field, flat_std = _emva_maps(data, res, fig, iso_int, saturation_dn, cfa_pattern,
                                                            unknown_all, key)
    measured = _Measured(figures={key: fig}, curves=curves, hot_pixels={}, bias_frames=bias_frames,
                         unknown=unknown_all, flat_field=flat_field, flat_field_std=flat_std, bias_frame_std_dn=bias_std,
                         iso_keys={key: iso_int}, extra_source=extra)
    return _build(measured, name=name or (desc.path.stem if desc.path else "emva1288"), adc_bits=adc_bits or desc.bits,
                  bits_from="argument" if adc_bits else "descriptor 'n' line", max_code=int(saturation_dn or 0),
                  cfa=cfa_pattern, input_path=desc.path, kind="emva1288")
