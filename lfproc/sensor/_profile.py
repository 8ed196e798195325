"""Camera profiles: the sensor figures that tie lfproc together.

A profile holds, for one sensor, its ADC and levels and, per ISO, the gain, read noise,
dark current and full well. It sets the noise model of the simulators
(:mod:`lfproc.camera.sensor`), the weights of the HDR merge and those of the reconstruction.

File format: versioned JSON (``schema: "lfproc.camera_profile"``, ``schema_version: 1``)
with units in the field names; optional master bias frames (one per ISO) live in a sidecar
``.npz`` named in ``bias_frame_file`` (relative to the JSON), with the standard deviation of
their per-pixel estimate in ``bias_frame_std_dn``; an optional measured flat-field map (the
per-pixel PRNU gain, mean 1 per CFA position) lives in a sidecar ``.npz`` named in
``flat_field_file`` (array ``flat_field``), with the relative standard deviation of its
per-pixel estimate in ``flat_field_std``. :func:`lfproc.camera.sensor.fixed_pattern_correction`
uses these maps to correct sensor images. A figure the calibration could not determine
is ``null`` and its reason is in ``unknown``. Loading checks the schema and names the
field that is wrong.

Shipped profiles (``load_profile(NAME)``): ``illum`` (a nominal Lytro Illum) and
``paper-none``, ``paper-low``, ``paper-medium``, ``paper-high`` (the simulated sensor of
the paper, Table VI noise levels: E. Miandji, H.-N. Nguyen, S. Hajisharif, J. Unger and
C. Guillemot, "Compressive HDR Light Field Imaging Using a Single Multi-ISO Sensor", IEEE
Transactions on Computational Imaging, 2021). Their 12-bit ADC, 20000 e- full well and 64 DN
black level are lfproc's choice (the paper does not give them); the gain is the paper's
``h = ISO / 100 * (2^12 - 1) / FWD``.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from lfproc import _untrusted as ut
from lfproc._shared.frozen import FrozenDict, frozen_array
from lfproc._shared.reprs import short_repr
from lfproc._version import __version__
from lfproc.errors import FileFormatError, MissingFileError, ProfileError, UnsafeFileError
from lfproc.io._atomic import atomic_outputs

__all__ = [
    "MONO",
    "BAYER_PATTERNS",
    "describe_profile",
    "CameraProfile",
    "IsoFigures",
    "load_profile",
    "save_profile",
    "is_profile_file",
    "bias_sidecar_path",
    "flat_sidecar_path",
    "profile_outputs",
    "paper_gain_dn_per_e",
    "SHIPPED_PROFILES",
    "SCHEMA",
    "SCHEMA_VERSION",
]

SCHEMA = "lfproc.camera_profile"
SCHEMA_VERSION = 1
_PROFILE_DIR = Path(__file__).resolve().parent / "profiles"
SHIPPED_PROFILES = ("illum", "paper-none", "paper-low", "paper-medium", "paper-high")
#: ``cfa_pattern`` of a monochrome sensor (no colour filter array).
MONO = "mono"
BAYER_PATTERNS = ("RGGB", "GRBG", "GBRG", "BGGR")
_CFA = BAYER_PATTERNS + (MONO,)


#: Keys of ``source["emva1288"]`` renamed since they were first written (old -> new); profiles
#: with the old names are read with the new ones.
RENAMED_EMVA_KEYS = {"saturation_variance_max_dn": "saturation_mean_dn"}


def _upgrade_source(source: dict[str, Any]) -> dict[str, Any]:
    """``source`` with the EMVA keys of older profiles renamed (:data:`RENAMED_EMVA_KEYS`)."""
    emva = source.get("emva1288")
    if isinstance(emva, dict):
        upgraded = {}
        for iso, figs in emva.items():
            if isinstance(figs, dict):
                figs = {RENAMED_EMVA_KEYS.get(k, k): v for k, v in figs.items()}
            upgraded[iso] = figs
        source = {**source, "emva1288": upgraded}
    return source


def paper_gain_dn_per_e(iso: float, *, adc_bits: int, full_well_e: float) -> float:
    """The paper's theoretical gain ``h = (ISO / 100) * (2^bits - 1) / FWD`` in DN per electron.

    At ISO 100 the full well fills the ADC's range; each doubling of the ISO doubles the gain
    (Miandji et al., IEEE TCI 2021).

    Parameters
    ----------
    iso : float
        ISO setting.
    adc_bits : int
        ADC resolution in bits.
    full_well_e : float
        Full-well depth in electrons.

    Returns
    -------
    float
        Gain in DN per electron.

    Examples
    --------
    >>> from lfproc.sensor import paper_gain_dn_per_e
    >>> paper_gain_dn_per_e(100, adc_bits=12, full_well_e=20000)
    0.20475
    >>> paper_gain_dn_per_e(800, adc_bits=12, full_well_e=20000)
    1.638
    """
    return (float(iso) / 100.0) * (2**adc_bits - 1) / float(full_well_e)


@dataclass(frozen=True)
class IsoFigures:
    """Figures of one ISO setting. ``None`` means unknown (see the profile's ``unknown``).

    Parameters
    ----------
    gain_dn_per_e : float or None
        System gain ``h`` in DN per electron.
    read_noise_e : float or None
        Read-noise standard deviation in electrons.
    read_noise_dn : float or None, optional
        The same in DN (``h * read_noise_e`` for a consistent profile).
    dark_current_e_per_s : float or None, optional
        Dark current in electrons per second (default: the profile's).
    black_level_dn : float or None, optional
        Black level of this ISO in DN (default: the profile's).
    full_well_e : float or None, optional
        Full well in electrons (default: the profile's).
    dsnu_dn : float or None, optional
        Dark-signal non-uniformity measured at this ISO, DN.
    prnu : float or None, optional
        Photo-response non-uniformity measured at this ISO (relative).

    Examples
    --------
    >>> from lfproc.sensor import load_profile
    >>> figures = load_profile("paper-medium").iso_figures(100)
    >>> figures.gain_dn_per_e, figures.read_noise_e, figures.black_level_dn
    (0.20475, 2.0, 64.0)
    """

    gain_dn_per_e: float | None
    read_noise_e: float | None
    read_noise_dn: float | None = None
    dark_current_e_per_s: float | None = None
    black_level_dn: float | None = None
    full_well_e: float | None = None
    dsnu_dn: float | None = None
    prnu: float | None = None

    def to_json(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@short_repr
@dataclass(frozen=True)
class CameraProfile:
    """A sensor's calibration (see the module documentation).

    Parameters
    ----------
    name : str
    adc_bits : int
        ADC resolution; ``white_level_dn`` defaults to ``2**adc_bits - 1``.
    white_level_dn : float
        Largest output code ``I_max`` (DN).
    black_level_dn : float
        Offset ``I_0`` added to every pixel (DN), unless an ISO gives its own.
    full_well_e : float
        Full-well depth (electrons) where electrons saturate.
    gamma : float
        Power-law response exponent (1 = linear raw).
    cfa_pattern : str
        Bayer layout as a row-major string from the top-left pixel, e.g. ``"RGGB"``, or
        ``"mono"`` for a monochrome sensor (no colour filters; the coded-mask camera simulator
        needs a Bayer layout and refuses it).
    isos : dict
        ISO (int) -> :class:`IsoFigures`.
    dark_current_e_per_s : float
        Default dark current for ISOs that do not give one.
    prnu, dsnu_e : float
        Photo-response non-uniformity (relative std of the per-pixel gain) and dark-signal
        non-uniformity (std of the per-pixel offset, electrons). 0 = uniform sensor.
    fixed_pattern_seed : int
        Seed of the sensor's fixed-pattern maps (the same sensor always has the same maps).
    bias_frames : dict, optional
        ISO -> master bias frame (DN, ``(H, W)``), as measured by ``lfproc calibrate``.
    bias_frame_std_dn : dict, optional
        ISO -> standard deviation (DN) of each pixel of that master bias (read noise over
        the square root of the number of frames averaged); missing = treated as exact.
    flat_field : ndarray (H, W), optional
        Measured per-pixel PRNU gain map (mean 1 per CFA position) from flat frames.
    flat_field_std : float
        Relative standard deviation of each value of ``flat_field`` as an estimate (0 = exact).

    ``isos``, ``bias_frames`` and ``bias_frame_std_dn`` are stored as read-only mappings and
    the bias frames and flat field as read-only arrays (copied once unless already
    read-only), so a validated profile cannot be changed; use :func:`dataclasses.replace`
    to derive a new one.
    unknown : dict
        Field name -> reason, for figures the calibration could not determine.
    """

    name: str
    adc_bits: int
    white_level_dn: float
    black_level_dn: float
    full_well_e: float
    isos: dict[int, IsoFigures]
    gamma: float = 1.0
    cfa_pattern: str = "RGGB"
    dark_current_e_per_s: float = 0.0
    prnu: float = 0.0
    dsnu_e: float = 0.0
    fixed_pattern_seed: int = 0
    description: str = ""
    bias_frames: dict[int, np.ndarray] = field(default_factory=dict)
    unknown: dict[str, str] = field(default_factory=dict)
    source: dict[str, Any] = field(default_factory=dict)
    bias_frame_std_dn: dict[int, float] = field(default_factory=dict)
    flat_field: np.ndarray | None = field(default=None, repr=False)
    flat_field_std: float = 0.0

    def __post_init__(self):
        _check_number(self.adc_bits, "adc_bits", integer=True, low=1, high=32)
        _check_number(self.white_level_dn, "white_level_dn", low=1)
        _check_number(self.black_level_dn, "black_level_dn", low=0)
        if self.black_level_dn >= self.white_level_dn:
            raise ProfileError(
                f"profile {self.name}: black_level_dn ({self.black_level_dn}) must be below white_level_dn "
                f"({self.white_level_dn})"
            )
        _check_number(self.full_well_e, "full_well_e", low=0, strict=True)
        _check_number(self.gamma, "gamma", low=1)
        _check_number(self.dark_current_e_per_s, "dark_current_e_per_s", low=0)
        _check_number(self.prnu, "prnu", low=0)
        _check_number(self.dsnu_e, "dsnu_e", low=0)
        _check_number(self.flat_field_std, "flat_field_std", low=0)
        for iso, std in self.bias_frame_std_dn.items():
            _check_number(std, f"bias_frame_std_dn.{iso}", low=0)
        if self.flat_field is not None:
            ff = np.asarray(self.flat_field)
            if ff.ndim != 2 or not np.issubdtype(ff.dtype, np.floating) or not np.isfinite(ff).all() or (ff <= 0).any():
                raise ProfileError(f"profile {self.name}: flat_field: expected an (H, W) map of positive finite gains, "
                                   f"found {ff.dtype} of shape {ff.shape}")
            object.__setattr__(self, "flat_field", frozen_array(self.flat_field))
        if self.cfa_pattern not in _CFA:
            raise ProfileError(f"profile {self.name}: cfa_pattern: expected one of {', '.join(_CFA)}, got {self.cfa_pattern!r}")
        if not self.isos:
            raise ProfileError(f"profile {self.name}: isos: expected at least one ISO")
        for iso, figs in self.isos.items():
            if not isinstance(figs, IsoFigures):
                raise ProfileError(f"profile {self.name}: isos.{iso}: expected ISO figures")
            for f in fields(IsoFigures):
                value = getattr(figs, f.name)
                if value is not None:
                    _check_number(value, f"isos.{iso}.{f.name}", low=0, strict=f.name == "gain_dn_per_e")
        object.__setattr__(self, "isos", FrozenDict(self.isos))
        frames = {}
        for iso, frame in dict(self.bias_frames).items():
            arr = np.asarray(frame)
            if arr.ndim != 2 or arr.size == 0 or not (np.issubdtype(arr.dtype, np.number) and np.isfinite(arr).all()):
                raise ProfileError(
                    f"profile {self.name}: bias frame of ISO {iso}: expected a finite 2-D array, found "
                    f"{arr.dtype} of shape {arr.shape}"
                )
            frames[iso] = frozen_array(frame)
        object.__setattr__(self, "bias_frames", FrozenDict(frames))
        object.__setattr__(self, "bias_frame_std_dn", FrozenDict(self.bias_frame_std_dn))
        if self.flat_field is not None:
            object.__setattr__(self, "flat_field", frozen_array(self.flat_field))

    def __setstate__(self, state):
        # pickle and copy.deepcopy bring new (writeable) bias arrays: make them read-only again
        for name, value in state.items():
            if name == "bias_frames":
                value = FrozenDict({k: frozen_array(v) for k, v in value.items()})
            elif name == "flat_field" and value is not None:
                value = frozen_array(value)
            object.__setattr__(self, name, value)

    # -- lookups ---------------------------------------------------------------------
    @property
    def iso_values(self) -> list[int]:
        return sorted(self.isos)

    @property
    def is_mono(self) -> bool:
        """True for a monochrome sensor (``cfa_pattern == "mono"``)."""
        return self.cfa_pattern == MONO

    def iso_figures(self, iso: float) -> IsoFigures:
        """Figures of one ISO; :class:`ProfileError` naming the available ISOs otherwise."""
        value = float(iso)
        key = int(round(value)) if math.isfinite(value) else None
        if key not in self.isos or abs(key - value) > 1e-6:
            raise ProfileError(
                f"ISO {iso:g} is not in camera profile {self.name!r}; it has ISO {', '.join(map(str, self.iso_values))}"
            )
        return self.isos[key]

    def require(self, iso: float, *names: str) -> dict[str, float]:
        """The named per-ISO figures, falling back to profile-wide ones; error if unknown."""
        figs = self.iso_figures(iso)
        out = {}
        for name in names:
            value = getattr(figs, name, None)
            if value is None and name == "dark_current_e_per_s":
                value = self.dark_current_e_per_s
            if value is None and name == "black_level_dn":
                value = self.black_level_dn
            if value is None and name == "full_well_e":
                value = self.full_well_e
            if value is None and name == "read_noise_e" and figs.read_noise_dn is not None and figs.gain_dn_per_e:
                value = figs.read_noise_dn / figs.gain_dn_per_e
            if value is None:
                why = self.unknown.get(f"isos.{int(iso)}.{name}") or self.unknown.get(name) or "not in the profile"
                raise ProfileError(f"camera profile {self.name!r}: ISO {iso:g} has no {name} ({why})")
            out[name] = float(value)
        return out

    def saturation_dn(self, iso: float) -> float:
        """Output code where a pixel of this ISO saturates: full well or ADC, whichever first."""
        figs = self.require(iso, "gain_dn_per_e", "black_level_dn", "full_well_e")
        signal = figs["gain_dn_per_e"] * figs["full_well_e"]
        if self.gamma != 1:
            signal = self.white_level_dn * (min(signal, self.white_level_dn) / self.white_level_dn) ** (1 / self.gamma)
        return float(min(self.white_level_dn, round(signal + figs["black_level_dn"])))

    @property
    def measured(self) -> bool:
        """True for a profile measured by ``lfproc calibrate`` (``source.kind == "calibrated"``): its
        ``prnu``/``dsnu_e`` describe a real sensor whose maps are only known where measured
        (``flat_field``, ``bias_frames``); otherwise they are a simulated sensor's, drawn from
        ``fixed_pattern_seed``."""
        return self.source.get("kind") == "calibrated"

    def with_noise(self, *, read_noise_e: float, dark_current_e_per_s: float, name: str | None = None) -> "CameraProfile":
        """A copy with the same read noise (e-) and dark current (e-/s) at every ISO."""
        isos = {
            iso: replace(
                f,
                read_noise_e=read_noise_e,
                read_noise_dn=read_noise_e * f.gain_dn_per_e if f.gain_dn_per_e else None,
                dark_current_e_per_s=dark_current_e_per_s,
            )
            for iso, f in self.isos.items()
        }
        return replace(self, isos=isos, dark_current_e_per_s=dark_current_e_per_s, name=name or self.name)

    # -- serialisation -----------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        """The profile as a JSON-serialisable dict (bias frames and flat field excluded: see :func:`save_profile`)."""
        doc = {
            "schema": SCHEMA,
            "schema_version": SCHEMA_VERSION,
            "lfproc_version": __version__,
            "name": self.name,
            "description": self.description,
            "adc_bits": self.adc_bits,
            "white_level_dn": self.white_level_dn,
            "black_level_dn": self.black_level_dn,
            "full_well_e": self.full_well_e,
            "gamma": self.gamma,
            "cfa_pattern": self.cfa_pattern,
            "dark_current_e_per_s": self.dark_current_e_per_s,
            "prnu": self.prnu,
            "dsnu_e": self.dsnu_e,
            "fixed_pattern_seed": self.fixed_pattern_seed,
            "isos": {str(iso): self.isos[iso].to_json() for iso in self.iso_values},
            "unknown": dict(self.unknown),
            "source": dict(self.source),
        }
        # written only when present, so profiles without measured maps keep their JSON unchanged
        if self.bias_frame_std_dn:
            doc["bias_frame_std_dn"] = {str(k): float(v) for k, v in sorted(self.bias_frame_std_dn.items())}
        if self.flat_field is not None or self.flat_field_std:
            doc["flat_field_std"] = float(self.flat_field_std)
        return doc

    @classmethod
    def from_json(cls, doc: dict[str, Any], *, where: str = "profile", bias_frames=None,
                  flat_field=None) -> "CameraProfile":
        """Build and validate a profile from its JSON dict; errors name the field.

        Every field is checked for type, finiteness and a plausible range
        (:mod:`lfproc._untrusted`) before the profile is built.
        """
        n = ut.Node(doc, where, error=ProfileError)
        if not n.is_dict():
            raise ProfileError(f"{where}: expected a JSON object")
        if doc.get("schema") != SCHEMA:
            raise ProfileError(f"{where}: field 'schema': expected {SCHEMA!r}, found {ut.show(doc.get('schema'))}")
        version = doc.get("schema_version")
        if version != SCHEMA_VERSION or isinstance(version, bool):
            raise ProfileError(f"{where}: field 'schema_version': expected {SCHEMA_VERSION}, found {ut.show(version)}")
        required = ("name", "adc_bits", "white_level_dn", "black_level_dn", "full_well_e", "isos")
        for key in required:
            if key not in doc or doc[key] is None:
                raise ProfileError(f"{where}: missing field {key!r}")
        isos_node = n["isos"]
        if not isos_node.is_dict() or not isos_node.value:
            raise ProfileError(f"{where}: field 'isos': expected an object from ISO to figures")
        if len(isos_node.value) > MAX_ISOS:
            raise ProfileError(f"{where}: field 'isos': {len(isos_node.value)} ISOs, above the limit of {MAX_ISOS}")
        isos = {}
        names = {f.name for f in fields(IsoFigures)}
        for key, figs in isos_node.items():
            if not (isinstance(key, str) and key.isascii() and key.isdigit() and len(key) <= 7 and int(key) > 0):
                raise ProfileError(f"{where}: field 'isos': key {ut.show(key)} is not an ISO number")
            if not figs.is_dict():
                raise ProfileError(f"{where}: field 'isos.{key}': expected an object")
            extra = set(figs.value) - names
            if extra:
                raise ProfileError(f"{where}: field 'isos.{key}': unknown keys {', '.join(sorted(map(str, extra)))}")
            values = {}
            for name in names:
                values[name] = figs.opt_float(name, low=_FIGURE_LOWER.get(name, 0),
                                              high=_FIGURE_LIMITS.get(name, 1e12))
            isos[int(key)] = IsoFigures(**values)
        kwargs = {}
        for key, checks in (("gamma", dict(low=1, high=16)), ("dark_current_e_per_s", dict(low=0, high=1e12)),
                            ("prnu", dict(low=0, high=1)), ("dsnu_e", dict(low=0, high=1e9))):
            value = n.opt_float(key, **checks)
            if value is not None:
                kwargs[key] = value
        if n.has("cfa_pattern"):
            kwargs["cfa_pattern"] = n["cfa_pattern"].as_str(choices=_CFA)
        if n.has("fixed_pattern_seed"):
            kwargs["fixed_pattern_seed"] = n["fixed_pattern_seed"].as_int(low=0, high=2**63 - 1)
        flat_std = n.opt_float("flat_field_std", low=0, high=1e3)
        if flat_std is not None:
            kwargs["flat_field_std"] = flat_std
        std_node = n.opt_dict("bias_frame_std_dn")
        if len(std_node.value) > MAX_ISOS:
            raise ProfileError(f"{where}: field 'bias_frame_std_dn': {len(std_node.value)} ISOs, above the limit of "
                               f"{MAX_ISOS}")
        std = {}
        for key, value in std_node.items():
            if not (isinstance(key, str) and key.isascii() and key.isdigit() and len(key) <= 7 and int(key) > 0):
                raise ProfileError(f"{where}: field 'bias_frame_std_dn': keys must be ISO numbers, found {ut.show(key)}")
            std[int(key)] = value.as_float(low=0, high=2.0**32)
        if std:
            kwargs["bias_frame_std_dn"] = std
        if n.has("description"):
            kwargs["description"] = n["description"].as_str(max_len=1 << 16)
        unknown = {}
        for key, reason in n.opt_dict("unknown").items():
            unknown[key] = reason.as_str(max_len=1 << 12) if not isinstance(reason.value, (int, float)) else str(reason.value)
        kwargs.update(
            name=n["name"].as_str(max_len=256),
            adc_bits=n["adc_bits"].as_int(low=1, high=32),
            white_level_dn=n["white_level_dn"].as_float(low=1, high=2.0**32),
            black_level_dn=n["black_level_dn"].as_float(low=0, high=2.0**32),
            full_well_e=n["full_well_e"].as_float(low=1, high=_FIGURE_LIMITS["full_well_e"]),
            source=_upgrade_source(dict(n.opt_dict("source").value)),
        )
        try:
            return cls(isos=isos, unknown=unknown, bias_frames=bias_frames or {}, flat_field=flat_field, **kwargs)
        except ProfileError as exc:
            raise ProfileError(f"{where}: {exc}") from None


#: Most ISO settings in one profile.
MAX_ISOS = 256
#: Upper bounds of per-ISO figures read from files (far above any real sensor).
#: Lower bounds of figures read from files: a gain below 1e-6 DN/e- or a full well below one
#: electron is no sensor, and would make the radiance (DN / (gain * t)) overflow.
_FIGURE_LOWER = {"gain_dn_per_e": 1e-6, "full_well_e": 1.0}
_FIGURE_LIMITS = {"gain_dn_per_e": 1e6, "read_noise_e": 1e9, "read_noise_dn": 1e9, "dark_current_e_per_s": 1e12,
                  "black_level_dn": 2.0**32, "full_well_e": 1e12, "dsnu_dn": 1e9, "prnu": 1.0}


def _check_number(value, name: str, *, integer: bool = False, low=None, high=None, strict: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ProfileError(f"field {name!r}: expected a number, found {ut.show(value)}")
    try:
        finite = math.isfinite(float(value))
    except OverflowError:
        finite = False
    if not finite:
        raise ProfileError(f"field {name!r}: expected a finite number, found {ut.show(value)}")
    if integer and int(value) != value:
        raise ProfileError(f"field {name!r}: expected an integer, found {value!r}")
    if low is not None and (value < low or (strict and value == low)):
        raise ProfileError(f"field {name!r}: expected a value {'>' if strict else '>='} {low}, found {value!r}")
    if high is not None and value > high:
        raise ProfileError(f"field {name!r}: expected a value <= {high}, found {value!r}")


def describe_profile(profile: CameraProfile) -> dict[str, Any]:
    """The profile as one JSON-ready dict: its JSON form, the bias frames' shapes and the
    saturation code of every ISO (:meth:`CameraProfile.saturation_dn`, ``None`` when unknown).
    ``lfproc profile show`` and ``lfproc info`` print it.

    Parameters
    ----------
    profile : CameraProfile
        The profile to describe.

    Returns
    -------
    dict
        ``kind`` (``"camera_profile"``), the fields of :meth:`CameraProfile.to_json`,
        ``bias_frames`` (ISO as str -> frame shape), ``flat_field`` (its shape or None) and
        ``saturation_dn`` (ISO as str -> code or None).

    Examples
    --------
    >>> from lfproc.sensor import describe_profile, load_profile
    >>> doc = describe_profile(load_profile("paper-medium"))
    >>> doc["kind"], doc["adc_bits"], doc["cfa_pattern"], doc["saturation_dn"]["800"]
    ('camera_profile', 12, 'RGGB', 4095.0)
    """
    doc = profile.to_json()
    doc = {"kind": "camera_profile", **doc}
    doc["bias_frames"] = {str(iso): list(frame.shape) for iso, frame in sorted(profile.bias_frames.items())}
    doc["flat_field"] = None if profile.flat_field is None else list(profile.flat_field.shape)
    doc["saturation_dn"] = {}
    for iso in profile.iso_values:
        try:
            doc["saturation_dn"][str(iso)] = profile.saturation_dn(iso)
        except ProfileError:  # an ISO without gain: its saturation is unknown
            doc["saturation_dn"][str(iso)] = None
    return doc


def is_profile_file(path: str | os.PathLike) -> bool:
    """True when ``path`` is a JSON file whose ``schema`` is a camera profile's.

    Only the first 4 KiB are read; the profile is not validated (:func:`load_profile` does).

    Parameters
    ----------
    path : str or os.PathLike
        Any path.

    Returns
    -------
    bool
        False for a missing file, a folder, another suffix or another JSON document.

    Examples
    --------
    >>> from lfproc.sensor import is_profile_file, load_profile, save_profile
    >>> _ = save_profile(load_profile("illum"), "illum.json")
    >>> is_profile_file("illum.json"), is_profile_file("missing.json")
    (True, False)
    """
    path = Path(path)
    if not path.is_file() or path.suffix.lower() != ".json":
        return False
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(4096)
    except (OSError, UnicodeDecodeError):
        return False
    return f'"{SCHEMA}"' in head


def load_profile(name_or_path: str | os.PathLike | CameraProfile) -> CameraProfile:
    """Load a shipped profile by name (see :data:`SHIPPED_PROFILES`) or a profile JSON file.

    Parameters
    ----------
    name_or_path : str, os.PathLike or CameraProfile
        A shipped profile's name (``illum``, ``paper-none``, ``paper-low``, ``paper-medium``,
        ``paper-high``), a profile JSON file (with its bias and flat-field sidecars), or a
        profile, returned as is.

    Returns
    -------
    CameraProfile
        The validated profile.

    Raises
    ------
    lfproc.errors.MissingFileError
        Neither a shipped name nor an existing file.
    lfproc.errors.FileFormatError
        The file is not JSON.
    lfproc.errors.ProfileError
        The JSON or a sidecar does not hold a valid profile (the message names the field).

    Examples
    --------
    >>> from lfproc.sensor import load_profile
    >>> p = load_profile("paper-medium")
    >>> p.adc_bits, p.white_level_dn, p.black_level_dn, p.full_well_e, p.cfa_pattern
    (12, 4095.0, 64.0, 20000.0, 'RGGB')
    >>> p.iso_values
    [100, 200, 400, 800, 1600, 3200, 6400]
    >>> fig = p.iso_figures(400)
    >>> fig.gain_dn_per_e, fig.read_noise_e, fig.dark_current_e_per_s
    (0.819, 2.0, 1.0)
    """
    if isinstance(name_or_path, CameraProfile):
        return name_or_path
    text = str(name_or_path)
    if text in SHIPPED_PROFILES:
        path = _PROFILE_DIR / f"{text}.json"
    else:
        path = Path(text)
        if not path.exists():
            raise MissingFileError(
                f"{path}: no such camera profile file (shipped profiles: {', '.join(SHIPPED_PROFILES)})"
            )
    try:
        doc = ut.load_json(path, max_bytes=MAX_PROFILE_BYTES).value
    except UnsafeFileError:
        raise
    except FileFormatError as exc:
        why = str(exc).removeprefix(f"{path}: ")
        raise FileFormatError(f"{path}: not a JSON camera profile ({why})") from None
    bias = {}
    sidecar = doc.get("bias_frame_file") if isinstance(doc, dict) else None
    if sidecar is not None:
        bias = _read_bias_sidecar(path, doc, sidecar)
    flat = None
    sidecar = doc.get("flat_field_file") if isinstance(doc, dict) else None
    if sidecar is not None:
        flat = _read_flat_sidecar(path, sidecar)
    return CameraProfile.from_json(doc, where=str(path), bias_frames=bias, flat_field=flat)


def bias_sidecar_path(path: str | os.PathLike) -> Path:
    """Where :func:`save_profile` writes the bias frames of a profile saved at ``path``."""
    path = Path(path)
    return path.with_name(f"{path.stem}.bias.npz")


def flat_sidecar_path(path: str | os.PathLike) -> Path:
    """Where :func:`save_profile` writes the flat-field map of a profile saved at ``path``."""
    path = Path(path)
    return path.with_name(f"{path.stem}.flat.npz")


def profile_outputs(profile: CameraProfile, path: str | os.PathLike) -> list[Path]:
    """The files :func:`save_profile` writes for ``profile`` at ``path``: the JSON first, then its
    bias and flat-field sidecars when the profile has them."""
    path = Path(path)
    return ([path] + ([bias_sidecar_path(path)] if profile.bias_frames else [])
            + ([flat_sidecar_path(path)] if profile.flat_field is not None else []))


#: Largest profile JSON (bytes); shipped ones have about 2 kB.
MAX_PROFILE_BYTES = 16 << 20
#: Largest bias frame (pixels) in a sidecar.
MAX_BIAS_PIXELS = 1 << 27


def _read_bias_sidecar(path: Path, doc: dict, sidecar: Any) -> dict[int, np.ndarray]:
    """The bias frames of a profile's sidecar ``.npz``: it must lie in the profile's folder;
    members ``iso_<ISO>`` of ISOs of the profile, 2-D, all of one shape (the
    ``bias_frame_shape`` the profile records, when it does), finite; expansion capped."""
    if not isinstance(sidecar, str) or not sidecar.strip():
        raise ProfileError(f"{path}: field 'bias_frame_file': expected a file name, found {ut.show(sidecar)}")
    side = ut.resolve_inside(path.parent, sidecar, source=path, field="bias_frame_file")
    if not side.is_file():
        raise ProfileError(f"{path}: field 'bias_frame_file': {side} does not exist")
    shape = None
    if isinstance(doc.get("bias_frame_shape"), list):
        shape = ut.Node(doc, path, error=ProfileError)["bias_frame_shape"].as_ints(length=2, low=1,
                                                                                   high=ut.MAX_DIMENSION)
    isos = doc.get("isos") if isinstance(doc.get("isos"), dict) else {}
    members = ut.npz_members(side)
    bias = {}
    for name in members:
        if not re.fullmatch(r"iso_\d{1,7}", name) or str(int(name[4:])) not in isos:
            raise FileFormatError(f"{side}: member {ut.show(name)} is not iso_<ISO> of an ISO of {path.name} "
                                  f"({', '.join(f'iso_{k}' for k in isos)})")

    def check(name, array_shape, dtype):
        nonlocal shape
        if len(array_shape) != 2 or dtype.kind not in "uif":
            raise FileFormatError(f"{side}: array {name!r}: expected a 2-D numeric bias frame, found {dtype} "
                                  f"{array_shape}")
        ut.check_dims(array_shape, source=side, what=f"bias frame {name}", max_pixels=MAX_BIAS_PIXELS)
        if shape is not None and tuple(array_shape) != tuple(shape):
            raise FileFormatError(f"{side}: array {name!r} is {array_shape[0]} x {array_shape[1]}; "
                                  f"{'the profile says' if doc.get('bias_frame_shape') else 'the first frame is'} "
                                  f"{shape[0]} x {shape[1]}")
        shape = tuple(array_shape)

    arrays = ut.read_npz(side, check=check)
    for name, frame in arrays.items():
        if not np.isfinite(frame).all():
            raise FileFormatError(f"{side}: array {name!r} holds NaN or Inf values")
        bias[int(name[4:])] = frame
    return bias


def _read_flat_sidecar(path: Path, sidecar: Any) -> np.ndarray:
    """The flat-field map of a profile's sidecar ``.npz``, checked like the bias sidecar: it must
    lie in the profile's folder and hold one array ``flat_field``, 2-D float, at most
    ``MAX_BIAS_PIXELS`` pixels (expansion capped); finite and positive (checked here and by
    :class:`CameraProfile`)."""
    if not isinstance(sidecar, str) or not sidecar.strip():
        raise ProfileError(f"{path}: field 'flat_field_file': expected a file name, found {ut.show(sidecar)}")
    side = ut.resolve_inside(path.parent, sidecar, source=path, field="flat_field_file")
    if not side.is_file():
        raise ProfileError(f"{path}: field 'flat_field_file': {side} does not exist")

    def bad(why: str) -> ProfileError:
        return ProfileError(f"{path}: field 'flat_field_file': {side} is not a flat-field map "
                            f"(.npz with array 'flat_field'): {why}")

    members = ut.npz_members(side)
    if set(members) != {"flat_field"}:
        raise bad(f"found {', '.join(map(ut.show, sorted(members))) or 'no arrays'}")

    def check(name, array_shape, dtype):
        if len(array_shape) != 2 or dtype.kind != "f":
            raise bad(f"expected a 2-D float array, found {dtype} {tuple(array_shape)}")
        ut.check_dims(array_shape, source=side, what="flat-field map", max_pixels=MAX_BIAS_PIXELS)

    return ut.read_npz(side, names=["flat_field"], check=check)["flat_field"]


def save_profile(profile: CameraProfile, path: str | os.PathLike, *, force: bool = False) -> Path:
    """Write a profile as JSON, its bias frames in a sidecar ``<stem>.bias.npz`` and its flat-field
    map in ``<stem>.flat.npz``: all of them or none (:func:`lfproc.io.atomic_outputs`).

    Parameters
    ----------
    profile : CameraProfile
        The profile.
    path : str or os.PathLike
        The JSON file (the sidecars go next to it).
    force : bool, default False
        Replace existing outputs.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    lfproc.errors.OutputExistsError
        An output exists and ``force`` is false.

    Examples
    --------
    >>> from lfproc.sensor import load_profile, save_profile
    >>> profile = load_profile("paper-high")
    >>> save_profile(profile, "camera.json")
    PosixPath('camera.json')
    >>> back = load_profile("camera.json")
    >>> back.name, back.iso_figures(200) == profile.iso_figures(200)
    ('paper-high', True)
    """
    path = Path(path)
    doc = profile.to_json()
    outputs = profile_outputs(profile, path)
    with atomic_outputs(outputs, force=force) as staged:
        if profile.bias_frames:
            with open(staged[1], "wb") as fh:
                np.savez_compressed(fh, **{f"iso_{iso}": frame for iso, frame in profile.bias_frames.items()})
            doc["bias_frame_file"] = bias_sidecar_path(path).name
            shapes = {tuple(np.shape(frame)) for frame in profile.bias_frames.values()}
            if len(shapes) == 1:
                doc["bias_frame_shape"] = list(shapes.pop())
        if profile.flat_field is not None:
            with open(staged[-1], "wb") as fh:
                np.savez_compressed(fh, flat_field=np.asarray(profile.flat_field, dtype=np.float32))
            doc["flat_field_file"] = flat_sidecar_path(path).name
        staged[0].write_text(json.dumps(doc, indent=2))
    return path
