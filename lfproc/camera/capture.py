"""Capture files of the multi-ISO coded-mask camera, calibrated observations, previews.

A *capture* is what the camera records (``S`` shots) plus everything needed to interpret
it: the sensor images in DN, per shot the mask code, the ISO map and the exposure time,
the CFA layout, the response exponent ``gamma``, the camera profile, and, for simulated
captures, the scale from the light field's relative units to electrons per second and a
reference to the ground truth. Loading needs no random seed and no simulator state.

File format (``schema "lfproc.capture"``, ``schema_version 1``; suggested suffix
``.capture.npz``): a ZIP archive, readable by :func:`numpy.load`, whose first member is
``lfproc-capture.json``, a UTF-8 JSON header::

    {"schema": "lfproc.capture", "schema_version": 1, "lfproc_version": "...",
     "shots": S, "size": [H, W], "views": [V, U], "channels": 3,
     "cfa_pattern": "RGGB", "gamma": 1.0, "exposures_s": [t_1, ...],
     "isos": [100, 400, ...], "iso_pattern": {...}, "mask": {"kind", "period", "shift", "codes_shape"},
     "sampling_rate": S / (3 V U), "radiance_scale": K or null, "units": "e-/s",
     "profile": {camera profile JSON}, "ground_truth": {"path", "sha256"} or null,
     "parameters": {...}, "arrays": {name: {"shape", "dtype"}}}

followed by ``.npy`` members: ``dn`` (``(S, H, W)`` uint16, black level included), ``iso``
(``(S, H, W)`` float32 ISO of every pixel), ``mask`` (the codes of
:class:`lfproc.camera.projection.MaskCode`: ``(S, V, U, Ph, Pw, 3)`` for ``random``, ``(S, Bh, Bw, 3)``
for ``shifted``; one tile when the mask is periodic; uint8 levels ``k`` meaning transmittance
``k / 255`` when every code is such a level, as the simulator's are, else float32) and
optionally ``bias`` (``(S, H, W)`` float32 bias frames in DN) and the embedded profile's
measured maps, ``profile_flat_field`` (``(H, W)``) and ``profile_bias_<ISO>`` (its master bias
frames), which the calibrated observations use (:func:`lfproc.camera.sensor.fixed_pattern_correction`).

Radiance units: ``observations`` returns ``T`` in electrons per second reaching each
pixel. For a simulated capture, ``L_e = radiance_scale * L_relative``, so a light field
reconstructed from ``T`` divided by ``radiance_scale`` is in the input's relative units.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import zipfile
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import _untrusted as ut
from .._shared.frozen import ReadOnlyState, freeze, frozen_array
from .._shared.hashing import file_sha256
from .._shared.jsonable import to_jsonable
from .._version import __version__
from ..sensor import calibrated_observation, CameraProfile, iso_maps, load_profile, Observation
from .._shared.deps import require
from .._shared.random import check_random_state
from ..errors import FileFormatError, InputError, LfprocError, LfprocWarning, MissingFileError, ShapeError
from ..io._atomic import atomic_file
from .iso import _num, DEFAULT_BLOCK_PX, describe_iso_pattern, iso_pattern, ISO_PATTERNS
from .projection import (
    build_operator, CFA_PATTERNS, decode_levels, encode_levels, MASK_KINDS, MaskCode, ProjectionOperator,
    sampling_rate, transmittance_map,
)
from .._shared.validation import check_choice
from .._shared.warn import warn_saturation
from .._shared.zipfiles import zip_first_member
from ..io.images import imread

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "HEADER_NAME",
    "Capture",
    "load_capture",
    "is_capture_file",
    "local_signal",
    "noise_floor",
    "capture_from_raw",
    "capture_streams",
    "read_sensor_frame",
    "observations",
    "describe_capture",
    "file_sha256",
]

SCHEMA = "lfproc.capture"
SCHEMA_VERSION = 1
HEADER_NAME = "lfproc-capture.json"
_ARRAYS = ("dn", "iso", "mask", "bias")
#: Most measured profile maps (profile_flat_field, profile_bias_<ISO>) one capture file may embed.
MAX_PROFILE_MAPS = 64


@dataclass(frozen=True, eq=False)
class Capture(ReadOnlyState):
    """A coded multi-ISO capture (see the module documentation).

    Parameters
    ----------
    dn : ndarray of shape (S, H, W), uint16
        Sensor images in DN, black level included.
    iso : ndarray of shape (S, H, W)
        ISO of every pixel of every shot (each value must be in ``profile``).
    exposures_s : sequence of S floats
        Exposure time of each shot in seconds.
    mask : MaskCode
        Mask codes of the S shots.
    profile : CameraProfile or name
    views : (V, U)
    cfa_pattern : str
        Row-major Bayer layout from the top-left pixel (default: the profile's).
    gamma : float, optional
        Response exponent (default: the profile's).
    bias_dn : ndarray of shape (S, H, W), optional
        Bias frames (DN); default: black level plus mean dark signal.
    radiance_scale : float, optional
        Electrons per second per unit of the simulated light field.
    ground_truth : dict, optional
        ``{"path": ..., "sha256": ...}`` of the simulated light field.
    iso_pattern : dict
        How the ISO map was made (``{"kind": "row", "isos": [...]}``...).
    parameters : dict
        Further parameters (simulation options, seed, source files).
    """

    dn: np.ndarray
    iso: np.ndarray
    exposures_s: tuple[float, ...]
    mask: MaskCode
    profile: Any
    views: tuple[int, int] = (5, 5)
    cfa_pattern: str | None = None
    gamma: float | None = None
    bias_dn: np.ndarray | None = None
    radiance_scale: float | None = None
    ground_truth: dict | None = None
    iso_pattern: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)

    def __post_init__(self):
        profile = load_profile(self.profile)
        object.__setattr__(self, "profile", profile)
        dn = np.asarray(self.dn)
        if dn.ndim == 2:
            dn = dn[None]
        if dn.ndim != 3:
            raise ShapeError(f"capture dn: expected sensor images of shape (S, H, W), got {dn.shape}")
        if dn.size == 0:
            raise ShapeError(f"capture dn: every axis needs at least one element, got shape {dn.shape}")
        if dn.dtype != np.uint16:
            if np.issubdtype(dn.dtype, np.floating):
                bad = int(np.count_nonzero(~np.isfinite(dn)))
                frac = int(np.count_nonzero(np.isfinite(dn) & (dn != np.round(dn))))
                if bad or frac:
                    raise InputError(
                        f"capture dn: expected integer sensor codes, found {bad} NaN or Inf and {frac} fractional values"
                    )
            elif not np.issubdtype(dn.dtype, np.integer):
                raise InputError(f"capture dn: expected uint16 sensor codes, got {dn.dtype}")
            if dn.min() < 0 or dn.max() > 65535:
                raise InputError(
                    f"capture dn: expected codes in [0, 65535], found range [{dn.min():g}, {dn.max():g}]"
                )
        dn = frozen_array(self.dn, dtype=np.uint16)
        if dn.ndim == 2:
            dn = dn[None]
        s, h, w = dn.shape
        iso = np.asarray(self.iso, dtype=np.float32)
        try:
            iso = np.broadcast_to(iso, dn.shape) if iso.ndim < 3 else iso
        except ValueError:
            raise ShapeError(f"capture iso: expected a scalar, (H, W) or (S, H, W) = {dn.shape} map, got {iso.shape}") from None
        if iso.shape != dn.shape:
            raise ShapeError(f"capture iso: expected shape {dn.shape}, got {iso.shape}")
        if not np.isfinite(iso).all():
            raise InputError("capture iso: expected finite ISO values, found NaN or Inf")
        iso = frozen_array(iso)  # broadcast views and caller arrays are copied once, fresh conversions kept
        for value in np.unique(iso):
            profile.iso_figures(float(value))  # ProfileError naming the available ISOs
        exposures = np.atleast_1d(np.asarray(self.exposures_s, dtype=np.float64))
        if exposures.size == 1 and s > 1:
            exposures = np.repeat(exposures, s)
        if exposures.shape != (s,):
            raise ShapeError(f"capture exposures_s: expected {s} exposure times (one per shot), got {exposures.size}")
        if not (np.isfinite(exposures).all() and (exposures > 0).all()):
            raise InputError(f"capture exposures_s: expected positive finite seconds, got {exposures.tolist()}")
        if not isinstance(self.mask, MaskCode):
            raise InputError(f"capture mask: expected a MaskCode, got {type(self.mask).__name__}")
        if self.mask.shots != s:
            raise ShapeError(f"capture mask: codes for {self.mask.shots} shots, the capture has {s} sensor images")
        views = (int(self.views[0]), int(self.views[1]))
        cfa = (self.cfa_pattern or profile.cfa_pattern).upper()
        if cfa not in CFA_PATTERNS:
            raise InputError(f"capture cfa_pattern: expected one of {', '.join(CFA_PATTERNS)}, got {cfa!r}")
        gamma = float(profile.gamma if self.gamma is None else self.gamma)
        if not (math.isfinite(gamma) and gamma >= 1):
            raise InputError(f"capture gamma: expected a value >= 1, got {gamma}")
        bias = None
        if self.bias_dn is not None:
            bias = np.asarray(self.bias_dn, dtype=np.float32)
            try:
                bias = np.broadcast_to(bias, dn.shape)
            except ValueError:
                raise ShapeError(f"capture bias_dn: expected a map broadcastable to {dn.shape}, got {bias.shape}") from None
            if not np.isfinite(bias).all():
                raise InputError("capture bias_dn: expected finite bias codes, found NaN or Inf")
            bias = frozen_array(bias)
        if self.radiance_scale is not None and not (math.isfinite(self.radiance_scale) and self.radiance_scale > 0):
            raise InputError(f"capture radiance_scale: expected a positive number, got {self.radiance_scale}")
        object.__setattr__(self, "dn", dn)
        object.__setattr__(self, "iso", iso)
        object.__setattr__(self, "exposures_s", tuple(float(t) for t in exposures))
        object.__setattr__(self, "views", views)
        object.__setattr__(self, "cfa_pattern", cfa)
        object.__setattr__(self, "gamma", gamma)
        object.__setattr__(self, "bias_dn", bias)
        object.__setattr__(self, "iso_pattern", dict(self.iso_pattern))
        object.__setattr__(self, "parameters", dict(self.parameters))
        self.mask.check(views=views, size=(h, w))

    # -- figures ------------------------------------------------------------------------
    def __repr__(self) -> str:
        """A one-line summary (the arrays are not printed)."""
        h, w = self.size
        isos = ", ".join(f"{v:g}" for v in self.isos)
        times = ", ".join(f"{t:g}" for t in self.exposures_s)
        truth = (self.ground_truth or {}).get("path")
        return (f"Capture({self.shots} shot(s) of {h} x {w} pixels, views={self.views[0]}x{self.views[1]}, "
                f"ISOs=[{isos}], exposures_s=[{times}], profile={self.profile.name!r}, "
                f"mask={self.mask.kind!r}, cfa={self.cfa_pattern!r}, sampling_rate={100 * self.sampling_rate:.2f} %"
                + (f", ground_truth={truth!r}" if truth else "") + ")")

    __str__ = __repr__

    @property
    def shots(self) -> int:
        return int(self.dn.shape[0])

    @property
    def size(self) -> tuple[int, int]:
        return int(self.dn.shape[1]), int(self.dn.shape[2])

    @property
    def isos(self) -> list[float]:
        return [float(v) for v in np.unique(self.iso)]

    @property
    def sampling_rate(self) -> float:
        """``S / (3 V U)``, a fraction."""
        return sampling_rate(shots=self.shots, views=self.views, channels=3)

    def saturated_fraction(self, *, pixels: str = "all", saturation_margin_dn: float = 0.5) -> float:
        """Share of saturated pixels: at or above their ISO's saturation code minus the margin (the
        ``saturated`` mask of :func:`observations`, without computing the rest).

        ``pixels="all"`` counts every pixel of every shot; ``"least-sensitive"`` only the pixels
        of the lowest ISO x exposure of the capture, where highlights must come from: a
        saturated one there has lost its radiance for good (this is what
        :class:`lfproc.errors.SaturationWarning` tests).
        """
        check_choice("pixels", pixels, ("all", "least-sensitive"))
        codes = np.zeros(self.iso.shape, np.float64)
        for value in self.isos:
            codes[self.iso == value] = self.profile.saturation_dn(value)
        saturated = self.dn >= codes - saturation_margin_dn
        if pixels == "all":
            return float(saturated.mean())
        sensitivity = self.iso * np.asarray(self.exposures_s, np.float32)[:, None, None]
        least = sensitivity <= sensitivity.min() * (1 + 1e-6)
        return float(saturated[least].mean())

    def operator(self, *, dtype=np.float32) -> ProjectionOperator:
        """The projection operator ``Phi`` of this capture (:mod:`lfproc.camera.projection`)."""
        return build_operator(self.mask, views=self.views, size=self.size, cfa_pattern=self.cfa_pattern, dtype=dtype)

    # -- file -----------------------------------------------------------------------------
    def header(self) -> dict[str, Any]:
        """The JSON header written in front of the arrays."""
        arrays = self._arrays()
        return {
            "schema": SCHEMA,
            "schema_version": SCHEMA_VERSION,
            "lfproc_version": __version__,
            "shots": self.shots,
            "size": list(self.size),
            "views": list(self.views),
            "channels": 3,
            "cfa_pattern": self.cfa_pattern,
            "gamma": self.gamma,
            "exposures_s": list(self.exposures_s),
            "isos": [_num(v) for v in self.isos],
            "iso_pattern": self.iso_pattern,
            "mask": self.mask.to_json(),
            "sampling_rate": self.sampling_rate,
            "radiance_scale": self.radiance_scale,
            "units": "e-/s",
            "profile": self.profile.to_json(),
            "ground_truth": self.ground_truth,
            "parameters": self.parameters,
            "arrays": {k: {"shape": list(a.shape), "dtype": str(a.dtype)} for k, a in arrays.items()},
        }

    def _arrays(self) -> dict[str, np.ndarray]:
        levels = encode_levels(self.mask.codes)
        out = {"dn": self.dn, "iso": self.iso, "mask": self.mask.codes if levels is None else levels}
        if self.bias_dn is not None:
            out["bias"] = self.bias_dn
        if self.profile.flat_field is not None:
            out["profile_flat_field"] = np.asarray(self.profile.flat_field, dtype=np.float32)
        for iso, frame in sorted(self.profile.bias_frames.items()):
            out[f"profile_bias_{iso}"] = np.asarray(frame, dtype=np.float32)
        return out

    def save(self, path: str | os.PathLike, *, force: bool = False) -> Path:
        """Write the capture file atomically (refuses to overwrite without ``force``)."""
        path = Path(path)
        header = json.dumps(to_jsonable(self.header()), indent=1).encode()
        with atomic_file(path, force=force) as tmp:
            with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=6) as zf:
                zf.writestr(_member(HEADER_NAME), header, compresslevel=6)
                for name, array in self._arrays().items():
                    buf = io.BytesIO()
                    np.lib.format.write_array(buf, np.ascontiguousarray(array), allow_pickle=False)
                    zf.writestr(_member(f"{name}.npy"), buf.getvalue(), compresslevel=6)
        return path


#: Timestamp of every member of a capture file: fixed, so that the same capture always gives
#: the same bytes (files can be compared by hash); 1980-01-01 is the earliest a ZIP can hold.
_ZIP_DATE_TIME = (1980, 1, 1, 0, 0, 0)


def _member(name: str) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=_ZIP_DATE_TIME)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16  # a regular file, rw-r--r--
    info.create_system = 3  # Unix, whatever the writing machine
    return info


def is_capture_file(path: str | os.PathLike) -> bool:
    """True when ``path`` is a ZIP archive whose first member is the capture header.

    Parameters
    ----------
    path : str or path-like
        The file to test (only its first ZIP member name is read; a missing or non-ZIP
        file gives False).

    Returns
    -------
    bool
    """
    return zip_first_member(path) == HEADER_NAME


#: Limits of capture files (checked on the header before any array is read).
MAX_SHOTS = 256
MAX_VIEWS = 64
MAX_HEADER_BYTES = 16 << 20


def _read_header(path: Path, zf: zipfile.ZipFile) -> dict[str, Any]:
    """The JSON header, every field checked (types, ranges, finiteness, sizes against each
    other and against the limits) before any array is read; returns plain values."""
    try:
        info = zf.getinfo(HEADER_NAME)
    except KeyError:
        raise FileFormatError(f"{path}: not an lfproc capture (no {HEADER_NAME} member)") from None
    if info.file_size > MAX_HEADER_BYTES:
        raise FileFormatError(f"{path}: capture header of {info.file_size} bytes exceeds the limit of {MAX_HEADER_BYTES}")
    try:
        with zf.open(info) as fh:
            data = ut.read_capped(fh, MAX_HEADER_BYTES, source=path, what="capture header")
    except ut.UnsafeFileError:
        raise
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, zlib.error, NotImplementedError) as exc:
        raise FileFormatError(f"{path}: capture header is corrupt ({type(exc).__name__}: {str(exc)[:120]})") from None
    try:
        value = ut.parse_json(data, source=path, what="capture header")
    except FileFormatError as exc:
        raise FileFormatError(str(exc).replace("capture header: not valid JSON", "capture header is not valid JSON")) \
            from None
    doc = ut.Node(value, path, error=FileFormatError)
    if not doc.is_dict():
        raise FileFormatError(f"{path}: capture header: expected a JSON object")
    header = doc.value
    if header.get("schema") != SCHEMA:
        raise FileFormatError(f"{path}: field 'schema': expected {SCHEMA!r}, found {ut.show(header.get('schema'))}")
    if header.get("schema_version") != SCHEMA_VERSION or isinstance(header.get("schema_version"), bool):
        raise FileFormatError(
            f"{path}: field 'schema_version': expected {SCHEMA_VERSION}, found {ut.show(header.get('schema_version'))} "
            "(written by a different lfproc version)"
        )
    required = ("shots", "size", "views", "cfa_pattern", "gamma", "exposures_s", "mask", "profile", "arrays")
    for key in required:
        if header.get(key) is None:
            raise FileFormatError(f"{path}: capture header: missing field {key!r}")
    if not isinstance(header["mask"], dict) or "kind" not in header["mask"]:
        raise FileFormatError(f"{path}: capture header: field 'mask': expected an object with 'kind'")
    shots = doc["shots"].as_int(low=1, high=MAX_SHOTS)
    size = ut.check_dims(doc["size"].as_ints(length=2), source=path, what="field 'size'")
    views = tuple(doc["views"].as_ints(length=2, low=1, high=MAX_VIEWS))
    mask = doc["mask"]
    kind = mask["kind"].as_str(choices=MASK_KINDS)
    period = mask.opt_int("period", low=1, high=max(size))
    shift = mask.opt_int("shift", 1, low=0, high=max(size))
    out = {
        "shots": shots,
        "size": list(size),
        "views": list(views),
        "cfa_pattern": doc["cfa_pattern"].as_str(max_len=8),
        "gamma": doc["gamma"].as_float(low=1, high=16),
        # exposures from 1 ns to 11 days; shorter ones underflow the radiance (DN / (gain * t))
        "exposures_s": doc["exposures_s"].as_floats(length=shots, low=1e-9, high=1e6),
        "mask": {"kind": kind, "period": period, "shift": shift},
        "profile": doc["profile"].as_dict(),
        "radiance_scale": doc.opt_float("radiance_scale", low=1e-30, high=1e30),
        "ground_truth": doc.opt_dict("ground_truth").value or None,
        "iso_pattern": doc.opt_dict("iso_pattern").value,
        "parameters": doc.opt_dict("parameters").value,
    }
    # array shapes and dtypes: as the header says, and as shots/size/views/mask require
    s, (h, w) = shots, size
    sensor = [s, h, w]
    arrays_node = doc["arrays"]
    arrays_node.as_dict()
    arrays: dict[str, dict[str, Any]] = {}
    for name in _ARRAYS:
        entry = arrays_node.get(name)
        if entry is None:
            if name == "bias":
                continue
            raise arrays_node.fail(f"missing the {name!r} array")
        shape = entry["shape"].as_ints(min_len=1, max_len=8, low=0, high=ut.MAX_PIXELS)
        dtype = entry["dtype"].as_str(max_len=16)
        allowed = {"dn": ("uint16",), "iso": ("float32",), "bias": ("float32",), "mask": ("uint8", "float32")}[name]
        if dtype not in allowed:
            raise entry.fail(f"expected dtype {' or '.join(allowed)}, found {ut.show(dtype)}")
        if name != "mask" and shape != sensor:
            raise entry.fail(f"expected shape {sensor} (shots, height, width), found {shape}")
        arrays[name] = {"shape": shape, "dtype": dtype}
    codes = arrays["mask"]["shape"]
    if kind == "random":
        tile = [period, period] if period is not None else [h, w]
        want = [s, views[0], views[1], *tile, 3]
        if codes != want:
            raise arrays_node.fail(f"'mask': a random mask of {s} shots, {views[0]}x{views[1]} views and "
                                   f"{'period ' + str(period) if period else 'no period'} needs shape {want}, found {codes}")
    else:
        need = (h + shift * (views[0] - 1), w + shift * (views[1] - 1)) if period is None else (period, period)
        if len(codes) != 4 or codes[0] != s or codes[3] != 3 or (period is not None and tuple(codes[1:3]) != need) \
                or (period is None and (codes[1] < need[0] or codes[2] < need[1] or codes[1] > 2 * need[0] + 64
                                        or codes[2] > 2 * need[1] + 64)):
            raise arrays_node.fail(f"'mask': a shifted mask of {s} shots for {views[0]}x{views[1]} views of "
                                   f"{h} x {w} pixels needs shape [{s}, >={need[0]}, >={need[1]}, 3], found {codes}")
    # the embedded profile's measured maps: profile_flat_field and profile_bias_<ISO>, 2-D float32
    extra = [name for name, _ in arrays_node.items() if name not in _ARRAYS]
    if len(extra) > MAX_PROFILE_MAPS:
        raise arrays_node.fail(f"{len(extra)} extra arrays, more than the {MAX_PROFILE_MAPS} profile maps allowed")
    for name in extra:
        if name != "profile_flat_field" and not re.fullmatch(r"profile_bias_[0-9]{1,7}", name):
            raise arrays_node.fail(f"unknown array {ut.show(name)} (expected dn, iso, mask, bias, profile_flat_field "
                                   "or profile_bias_<ISO>)")
        entry = arrays_node[name]
        shape = list(ut.check_dims(entry["shape"].as_ints(length=2), source=path, what=f"array {name!r}"))
        dtype = entry["dtype"].as_str(max_len=16)
        if dtype != "float32":
            raise entry.fail(f"expected dtype float32, found {ut.show(dtype)}")
        arrays[name] = {"shape": shape, "dtype": dtype}
    for name, entry in arrays.items():
        ut.check_nbytes(entry["shape"], entry["dtype"], source=path, what=f"array {name!r}")
    out["arrays"] = arrays
    return out


def _read_array(path: Path, zf: zipfile.ZipFile, name: str, header: dict) -> np.ndarray:
    """One array, its ``.npy`` header checked against the capture header before the data are read."""
    want = header["arrays"][name]
    try:
        info = zf.getinfo(f"{name}.npy")
    except KeyError:
        raise FileFormatError(f"{path}: capture has no {name!r} array") from None
    try:
        with zf.open(info) as fh:
            return ut.read_npy(fh, info.file_size, source=path, what=f"array {name!r}",
                               expect_shape=tuple(want["shape"]), expect_dtype=want["dtype"])
    except FileFormatError as exc:
        text = str(exc)
        if "expected shape" in text or "expected dtype" in text:
            raise FileFormatError(f"{path}: array {name!r}: header says {want['shape']} {want['dtype']}, "
                                  f"{text.split(': ', 2)[-1]}") from None
        raise
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, zlib.error, NotImplementedError) as exc:
        raise FileFormatError(f"{path}: array {name!r} is corrupt ({type(exc).__name__}: {str(exc)[:120]})") from None


def load_capture(path: str | os.PathLike) -> Capture:
    """Read a capture file (see the module documentation); errors name the file and field.

    The header is read and checked first (:mod:`lfproc._untrusted`: types, ranges, array
    shapes against shots/size/views/mask, total expanded size against the file's size), and
    each array's own header against it, so nothing is allocated that the file does not
    plausibly hold.

    Parameters
    ----------
    path : str or path-like
        A capture file written by :meth:`Capture.save` (``lfproc simulate``, ``lfproc capture``).

    Returns
    -------
    Capture
        With read-only arrays, the camera profile stored in the file, and the file's
        parameters and ground-truth reference.

    Raises
    ------
    MissingFileError
        No such file.
    FileFormatError
        Not a capture file, another schema version, a field or array that is missing, of the
        wrong type or shape, or larger than the file can hold.

    Examples
    --------
    A round trip through :meth:`Capture.save`:

    >>> import numpy as np
    >>> from lfproc.synth import synthesize
    >>> from lfproc.camera import load_capture, simulate_capture
    >>> from lfproc.camera.capture import noise_floor
    >>> lf = synthesize("window", size=(24, 24), views=5, random_state=0)
    >>> capture = simulate_capture(lf, shots=2, mask_period=4, random_state=0)
    >>> capture.save("capture.npz").name
    'capture.npz'
    >>> back = load_capture("capture.npz")
    >>> bool(np.array_equal(back.dn, capture.dn)), bool(np.array_equal(back.iso, capture.iso))
    (True, True)
    >>> back.exposures_s == capture.exposures_s, back.radiance_scale == capture.radiance_scale
    (True, True)
    >>> back.dn.flags.writeable  # the arrays read are read-only
    False
    >>> bool(noise_floor(back) == noise_floor(capture) > 0)  # radiance of one read-noise sigma
    True
    """
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such capture file")
    if not zipfile.is_zipfile(path):
        raise FileFormatError(f"{path}: not an lfproc capture (expected a ZIP/.npz archive with {HEADER_NAME})")
    try:
        with zipfile.ZipFile(path) as zf:
            header = _read_header(path, zf)
            names = ["dn", "iso", "mask"] + (["bias"] if "bias" in header["arrays"] else [])
            names += sorted(name for name in header["arrays"] if name.startswith("profile_"))
            total = sum(ut.check_nbytes(header["arrays"][n]["shape"], header["arrays"][n]["dtype"]) for n in names)
            ut.check_expansion(total, path.stat().st_size, source=path, what="the capture's arrays")
            arrays = {name: _read_array(path, zf, name, header) for name in names}
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, zlib.error, NotImplementedError) as exc:
        if isinstance(exc, LfprocError):
            raise
        raise FileFormatError(f"{path}: corrupt capture archive ({type(exc).__name__}: {str(exc)[:120]})") from None
    for name in ("iso", "bias", *(n for n in arrays if n.startswith("profile_"))):
        if name in arrays and not np.isfinite(arrays[name]).all():
            raise FileFormatError(f"{path}: array {name!r} holds NaN or Inf values")
    maps = {name: arrays.pop(name) for name in list(arrays) if name.startswith("profile_")}
    profile_bias = {int(name.removeprefix("profile_bias_")): a for name, a in maps.items()
                    if name.startswith("profile_bias_")}
    profile = CameraProfile.from_json(header["profile"], where=f"{path}: embedded profile", bias_frames=profile_bias,
                                      flat_field=maps.get("profile_flat_field"))
    m = header["mask"]
    try:
        codes = decode_levels(arrays["mask"]) if arrays["mask"].dtype == np.uint8 else arrays["mask"]
        mask = MaskCode(kind=m["kind"], codes=codes, period=m["period"], shift=m["shift"])
        capture = Capture(
            dn=arrays["dn"],
            iso=arrays["iso"],
            exposures_s=header["exposures_s"],
            mask=mask,
            profile=profile,
            views=tuple(header["views"]),
            cfa_pattern=header["cfa_pattern"],
            gamma=header["gamma"],
            bias_dn=arrays.get("bias"),
            radiance_scale=header["radiance_scale"],
            ground_truth=header["ground_truth"],
            iso_pattern=header["iso_pattern"],
            parameters=header["parameters"],
        )
    except InputError as exc:
        raise FileFormatError(f"{path}: {exc}") from None
    if capture.shots != header["shots"] or list(capture.size) != list(header["size"]):
        raise FileFormatError(
            f"{path}: header says {header['shots']} shots of {header['size']}, arrays hold {capture.shots} of "
            f"{list(capture.size)}"
        )
    return capture


# -- calibrated observations --------------------------------------------------------------

def observations(capture: Capture, *, warn_saturation: bool = True, **options) -> Observation:
    """Radiance estimates ``T`` (e-/s), their variance and weights for every shot (paper eqs. 5-7).

    Parameters
    ----------
    capture : Capture
    warn_saturation : bool
        Emit :class:`lfproc.errors.SaturationWarning` when more than
        :data:`lfproc.errors.SATURATION_WARNING_FRACTION` of the pixels are saturated.
    **options
        Passed to :func:`lfproc.camera.sensor.calibrated_observation` (``saturation_margin_dn``,
        ``variance_from``, ``radiance_estimate`` of shape (S, H, W), ``read_floor_e``: the
        reconstructions pass :data:`READ_FLOOR_E`...). ``variance_from="local"``
        (capture level only) takes the photon-noise signal of every measurement from its
        neighbours instead of itself (:func:`local_signal`).

    Returns
    -------
    Observation
        With arrays of shape ``(S, H, W)``: ``radiance`` (T), ``variance``, ``weight``
        (``1/std(T)``, 0 where saturated or black-clipped), ``saturated``, ``black_clipped``.

    Raises
    ------
    InputError
        Not a capture, or ``radiance_estimate`` with ``variance_from="local"``.
    """
    if not isinstance(capture, Capture):
        raise InputError(f"observations: expected a Capture, got {type(capture).__name__}")
    estimate = options.pop("radiance_estimate", None)
    if options.get("variance_from") == "local":
        if estimate is not None:
            raise InputError("observations: variance_from='local' computes its own signal; drop radiance_estimate")
        plug_in = observations(capture, warn_saturation=False,
                               **{k: v for k, v in options.items() if k != "variance_from"})
        estimate = local_signal(capture, plug_in)
        options["variance_from"] = "estimate"
    per_shot = []
    for s in range(capture.shots):
        kw = dict(options)
        if estimate is not None:
            kw["radiance_estimate"] = np.asarray(estimate)[s]
        per_shot.append(calibrated_observation(
            capture.dn[s],
            exposure_s=capture.exposures_s[s],
            iso=capture.iso[s],
            profile=capture.profile,
            gamma=capture.gamma,
            bias_dn=None if capture.bias_dn is None else capture.bias_dn[s],
            **kw,
        ))
    obs = Observation(*(freeze(np.stack([getattr(o, f) for o in per_shot])) for f in
                        ("radiance", "variance", "weight", "saturated", "black_clipped")))
    if warn_saturation:
        _warn_saturation(capture, stacklevel=4)
    return obs


def local_signal(capture: Capture, obs: Observation, *, radius: int = 1) -> np.ndarray:
    """A leave-one-out local estimate of every measurement's expected ``T`` (e-/s), ``(S, H, W)``.

    The photon-noise variance of ``T`` needs the expected signal. ``T`` itself (the plug-in)
    gives a measurement that fell low a smaller variance, so a larger weight, and every weighted
    fit comes out low: by about one electron per pixel (Neyman's chi-square; 0.853 of a flat
    scene at 8 electrons, 0.996 with this estimate: tests/camera/test_capture.py), black where the
    scene has a few electrons per pixel. Here measurement ``i`` gets ``r_i sum_j T_j / sum_j r_j`` over the usable
    measurements ``j != i`` of the same shot and Bayer colour in the ``(2 radius + 1)^2``
    neighbourhood of its colour plane (``r``: the pixel's total mask transmittance,
    :func:`lfproc.camera.projection.transmittance_map`), which does not depend on its own noise;
    where it has no usable neighbour it keeps its own ``T``. Negative ``T`` count as 0.

    Known limit: a measurement far above its neighbours (a light a few pixels wide) gets a low estimate, so a variance
    too small. Measured on the test scenes of ``benchmarks/reconstruct_realistic.py`` (the truth's whitened residuals,
    stop 22): chi-square 0.86-1.02 per measurement below 1e5 e-/s, 1.3-4.3 at 3e5-1e6 and 1.6-17.8 above. Keeping ``T``
    where it exceeds the estimate by 3 of its standard deviations brings the bright end to 0.6-1.0 (14 measurements:
    2.1), but lowered the reconstruction (Lytro size, 2 random: 41.49 -> 41.37 dB, city-interior's worst decade 0.38 ->
    0.42 stops), so it is not done.
    """
    from scipy.ndimage import uniform_filter

    T = np.maximum(obs.radiance.astype(np.float64), 0.0)
    use = obs.weight > 0
    r = transmittance_map(capture.mask, views=capture.views, cfa_pattern=capture.cfa_pattern, size=T.shape[1:])
    out = T.copy()
    k = 2 * int(radius) + 1
    for s in range(T.shape[0]):
        for a in (0, 1):  # the four Bayer colour planes
            for b in (0, 1):
                plane = np.s_[s, a::2, b::2]
                t = np.where(use[plane], T[plane], 0.0)
                rr = np.where(use[plane], r[plane], 0.0)
                st = uniform_filter(t, k, mode="constant") * (k * k) - t  # neighbours' sums, the pixel left out
                sr = uniform_filter(rr, k, mode="constant") * (k * k) - rr
                ok = sr > 1e-6 * max(float(rr.max()), 1e-30)
                est = out[plane]
                est[ok] = r[plane][ok] * np.maximum(st[ok], 0.0) / sr[ok]
    return out


#: The read noise (electrons) the reconstructions' weights assume at least (``observations(..., read_floor_e=...)``)
#: and the noise floor's electron (:func:`noise_floor`): a Poisson count of about one electron is 0, 1 or 2, not
#: known to a fraction of an electron as a sensor without read noise (``paper-none``) would otherwise claim.
READ_FLOOR_E = 1.0


def noise_floor(capture: Capture) -> float:
    """The light-field radiance at which one measurement has as much signal as read noise, and at least one electron.

    ``max(read_noise_e, 1) / (t r radiance_scale)`` at the capture's highest ISO and shortest
    exposure ``t``, with ``r`` the mean total transmittance of a pixel (the mask codes summed over
    the views): below it no single measurement sees the scene above its noise (units of the light
    field the capture was simulated from; e-/s for a real capture, whose scale is 1). The electron:
    a sensor without read noise (``paper-none``) still has photon noise, and one electron is the
    signal whose photon noise equals it (without it that floor would be 0 and the figures would
    count samples of a thousandth of an electron). Used as the noise floor of
    :func:`lfproc.metrics.hdr_figures`.

    Parameters
    ----------
    capture : Capture

    Returns
    -------
    float

    Raises
    ------
    InputError
        Not a :class:`Capture`.

    Examples
    --------
    >>> from lfproc.camera import noise_floor, simulate_capture
    >>> from lfproc.synth import synthesize
    >>> lf = synthesize("layers", size=(16, 16), random_state=0)
    >>> a = noise_floor(simulate_capture(lf, exposure_s=0.004, random_state=0))
    >>> b = noise_floor(simulate_capture(lf, exposure_s=0.002, random_state=0))  # half the light: twice the floor
    >>> round(b / a, 6)
    2.0
    """
    if not isinstance(capture, Capture):
        raise InputError(f"noise_floor: expected a Capture, got {type(capture).__name__}")
    read = max(float(iso_maps(capture.profile, max(capture.isos), (1,))["read_noise_e"][0]), READ_FLOOR_E)
    r = float(np.mean(capture.mask.codes)) * capture.views[0] * capture.views[1]
    scale = 1.0 if capture.radiance_scale is None else float(capture.radiance_scale)
    return read / (float(np.min(capture.exposures_s)) * max(r, 1e-30) * scale)


def _warn_saturation(capture: Capture, *, stacklevel: int) -> None:
    """SaturationWarning when too many of the least sensitive pixels (lowest ISO x exposure) saturate."""
    sens = capture.iso * np.asarray(capture.exposures_s, np.float32)[:, None, None]
    at = np.unravel_index(int(np.argmin(sens)), sens.shape)
    where = f"ISO {_num(capture.iso[at])} at {capture.exposures_s[at[0]]:g} s"
    warn_saturation(capture.saturated_fraction(pixels="least-sensitive"), "capture",
                    samples=f"least sensitive pixels ({where})", stacklevel=stacklevel + 1,
                    consequence="their radiance is lost for good; use a shorter exposure or a smaller radiance scale")


def describe_capture(path: str | os.PathLike) -> dict[str, Any]:
    """Figures of a capture file for ``lfproc info`` (first key ``kind = "capture"``).

    Parameters
    ----------
    path : str or path-like
        A capture file written by :meth:`Capture.save`.

    Returns
    -------
    dict
        ``kind``, ``path``, ``shots``, ``size`` ``[H, W]``, ``views`` ``[V, U]``,
        ``sampling_rate_percent``, saturated and black-clipped fractions (overall and
        ``per_iso``), ``isos``, ``exposures_s``, ``cfa_pattern``, ``gamma``, ``mask``,
        ``iso_pattern``, ``profile``, ``radiance_scale``, ``dn_min``/``dn_max``,
        ``ground_truth`` and ``parameters``.

    Raises
    ------
    MissingFileError, FileFormatError
        As :func:`load_capture`.
    """
    capture = load_capture(path)
    obs = observations(capture, warn_saturation=False)  # the figures below report it
    per_iso = {}
    for value in capture.isos:
        sel = capture.iso == value
        per_iso[str(_num(value))] = {
            "fraction": float(sel.mean()),
            "saturated_fraction": float(obs.saturated[sel].mean()),
            "black_clipped_fraction": float(obs.black_clipped[sel].mean()),
        }
    return {
        "kind": "capture",
        "path": str(path),
        "shots": capture.shots,
        "size": list(capture.size),
        "views": list(capture.views),
        "sampling_rate_percent": 100.0 * capture.sampling_rate,
        "saturated_fraction": obs.saturated_fraction,
        "black_clipped_fraction": obs.black_clipped_fraction,
        "isos": [_num(v) for v in capture.isos],
        "per_iso": per_iso,
        "exposures_s": list(capture.exposures_s),
        "cfa_pattern": capture.cfa_pattern,
        "gamma": capture.gamma,
        "mask": capture.mask.to_json(),
        "iso_pattern": capture.iso_pattern,
        "profile": capture.profile.name,
        "radiance_scale": capture.radiance_scale,
        "dn_min": int(capture.dn.min()),
        "dn_max": int(capture.dn.max()),
        "ground_truth": capture.ground_truth,
        "parameters": capture.parameters,
    }


# -- real captures ---------------------------------------------------------------------------

_CV_SUFFIXES = (".png", ".tif", ".tiff")


def read_sensor_frame(path: str | os.PathLike) -> tuple[np.ndarray, dict[str, Any]]:
    """Read one sensor image in DN: a raw file (rawpy ``raw_image_visible``) or a 16-bit PNG/TIFF.

    Returns
    -------
    dn : ndarray of shape (H, W), uint16
    meta : dict (``format``; for raw files ``cfa_pattern``, ``black_level_dn``, ``white_level_dn``)
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path}: no such sensor image")
    if path.suffix.lower() in _CV_SUFFIXES:
        import cv2

        image = imread(path, cv2.IMREAD_UNCHANGED, what="sensor image")
        if image.ndim != 2 or image.dtype != np.uint16:
            raise FileFormatError(
                f"{path}: expected a single-channel 16-bit sensor image (raw Bayer mosaic), found "
                f"{image.dtype} with shape {image.shape}"
            )
        return image, {"format": path.suffix.lower().lstrip(".")}
    rawpy = require("rawpy", purpose="reading camera raw files")
    try:
        with rawpy.imread(str(path)) as raw:
            dn = np.array(raw.raw_image_visible, dtype=np.uint16, copy=True)
            pattern = np.asarray(raw.raw_pattern)
            desc = raw.color_desc.decode()
            meta = {
                "format": "raw",
                "black_level_dn": [float(b) for b in raw.black_level_per_channel],
                "white_level_dn": float(raw.white_level),
            }
            if pattern.shape == (2, 2):
                meta["cfa_pattern"] = "".join("G" if desc[i] in "G" else desc[i] for i in pattern.reshape(-1))
    except (rawpy.LibRawError, OSError) as exc:
        raise FileFormatError(f"{path}: not a raw file rawpy can read ({type(exc).__name__}: {exc})") from None
    return dn, meta


def capture_streams(random_state) -> tuple[np.random.Generator, np.random.Generator, np.random.Generator]:
    """The three independent generators a simulated capture draws from: its ISO layout's, its mask's and its
    noise's (:meth:`numpy.random.Generator.spawn` of ``random_state``'s generator).

    One seed so gives the same mask and noise whatever the layout (:func:`lfproc.camera.simulate.simulate_capture`),
    and :func:`capture_from_raw` redraws a simulated capture's ``random`` layout from its seed.

    Parameters
    ----------
    random_state : int, Generator or None
        As everywhere in lfproc (:func:`lfproc._shared.random.check_random_state`).

    Returns
    -------
    tuple of three Generator
        The layout's, the mask's and the noise's.

    Examples
    --------
    >>> from lfproc.camera.iso import iso_pattern
    >>> layout, mask, noise = capture_streams(0)
    >>> a = iso_pattern("random", size=(4, 4), random_state=layout)
    >>> bool((a == iso_pattern("random", size=(4, 4), random_state=capture_streams(0)[0])).all())
    True
    """
    layout, mask, noise = check_random_state(random_state).spawn(3)
    return layout, mask, noise


def _mask_from(mask, *, views) -> tuple[MaskCode, tuple[int, int], str | None]:
    """The mask of :func:`capture_from_raw`, the views it implies and the file it came from."""
    if isinstance(mask, (str, os.PathLike)):
        path = Path(mask)
        if not path.is_file():
            raise MissingFileError(f"{path}: no such mask code file or capture file")
        if not is_capture_file(path):
            raise FileFormatError(f"{path}: a mask given as a path must be an lfproc capture file (its mask is "
                                  "reused); pass .npy codes as {'kind': ..., 'codes': PATH}")
        donor = load_capture(path)
        return donor.mask, donor.views if views is None else views, str(path)
    source = None
    if isinstance(mask, Mapping):
        codes = mask.get("codes")
        if isinstance(codes, (str, os.PathLike)):
            codes_path = Path(codes)
            source = str(codes_path)
            if not codes_path.is_file():
                raise MissingFileError(f"{codes_path}: no such mask code file")

            with open(codes_path, "rb") as fh:  # header checked against the file's size before reading
                codes = ut.read_npy(fh, codes_path.stat().st_size, source=codes_path, what="mask codes")
        if codes is None or "kind" not in mask:
            raise InputError("mask: expected a MaskCode or a mapping with 'kind' and 'codes'")
        try:
            mask = MaskCode(kind=mask["kind"], codes=codes, period=mask.get("period"),
                            shift=int(mask.get("shift", 1)))
        except InputError as exc:  # ShapeError included
            raise type(exc)(f"{source}: {exc}" if source else str(exc)) from None
    if not isinstance(mask, MaskCode):
        raise InputError(f"mask: expected a MaskCode, a mapping or a capture file, got {type(mask).__name__}")
    if views is None:
        views = tuple(int(v) for v in mask.codes.shape[1:3]) if mask.kind == "random" else (5, 5)
    return mask, views, source


def capture_from_raw(
    raw_paths: Sequence[str | os.PathLike],
    *,
    mask: MaskCode | Mapping[str, Any] | str | os.PathLike,
    iso_layout,
    profile,
    exposures_s,
    views: tuple[int, int] | None = None,
    cfa_pattern: str | None = None,
    gamma: float | None = None,
    bias_dn=None,
    isos: Sequence[float] | None = None,
    block_px: int = DEFAULT_BLOCK_PX,
    random_state=None,
) -> Capture:
    """Build a capture from real sensor images (one per shot), a mask description, an ISO layout and a profile.

    Parameters
    ----------
    raw_paths : sequence of paths
        One sensor image per shot: raw files (read with rawpy, ``raw_image_visible``; DNG
        included) or single-channel 16-bit PNG/TIFF mosaics. All of one size and CFA layout.
    mask : MaskCode, mapping or path
        The mask codes; or ``{"kind": "random"|"shifted", "codes": array or .npy path,
        "period": P or None, "shift": 1}`` (codes in the layout of
        :class:`lfproc.camera.projection.MaskCode`: ``(S, V, U, Ph, Pw, 3)`` for ``random``,
        ``(S, Bh, Bw, 3)`` for ``shifted``, transmittances in [0, 1]); or the path of a capture
        file whose mask (and views) are reused.
    iso_layout : float, ndarray (H, W) or (S, H, W), or str
        ISO of every pixel; a string names a pattern of :func:`lfproc.camera.iso.iso_pattern`
        (``row``, ``block``, ``dual``, ``random``) built with ``isos``, or an ISO map file
        (stored explicitly either way).
    profile : CameraProfile, name or path
    exposures_s : float or sequence of floats (one per shot)
    views : (V, U), optional
        Default: the random codes' views, the donor capture's, else 5 x 5.
    cfa_pattern : str, optional
        Default: the raw files' pattern when rawpy reports one, else the profile's.
    gamma : float, optional (default: the profile's)
    bias_dn : float or ndarray, optional (default: black level plus mean dark signal)
    isos, block_px, random_state : for a named ``iso_layout`` (``block_px``: the block side of
        ``block``; ``random_state`` seeds ``random`` as the simulator does, :func:`capture_streams`).

    Returns
    -------
    Capture

    Raises
    ------
    InputError, ShapeError
        No images, images of other sizes or CFA layouts, a named layout without ``isos``, a bad mask.

    Warns
    -----
    LfprocWarning
        A raw file's black level differs from the profile's by more than 2 DN (another camera or mode?).
    """
    import warnings

    paths = [Path(p) for p in ([raw_paths] if isinstance(raw_paths, (str, os.PathLike)) else raw_paths)]
    if not paths:
        raise InputError("capture_from_raw: expected at least one sensor image")
    profile = load_profile(profile)
    frames, metas = zip(*(read_sensor_frame(p) for p in paths))
    for p, f in zip(paths[1:], frames[1:]):
        if f.shape != frames[0].shape:
            raise ShapeError(f"{p}: sensor image of {f.shape[0]}x{f.shape[1]} pixels, but {paths[0]} has "
                             f"{frames[0].shape[0]}x{frames[0].shape[1]}; all shots must come from one sensor mode")
    dn = np.stack(frames)
    raw_cfa = {m.get("cfa_pattern") for m in metas} - {None}
    if len(raw_cfa) > 1:
        raise InputError(f"capture_from_raw: the raw files differ in CFA layout ({', '.join(sorted(raw_cfa))}); "
                         "all shots must come from one sensor")
    if cfa_pattern is None and len(raw_cfa) == 1:
        cfa_pattern = raw_cfa.pop()
    for p, m in zip(paths, metas):
        if "black_level_dn" in m:
            black = float(np.mean(m["black_level_dn"]))
            known = {float(profile.black_level_dn)} | {float(f.black_level_dn) for f in profile.isos.values()
                                                       if f.black_level_dn is not None}
            if min(abs(black - b) for b in known) > 2:
                warnings.warn(f"{p}: black level {black:g} DN, but camera profile {profile.name!r} has "
                              f"{', '.join(f'{b:g}' for b in sorted(known))} DN; is it this camera's profile?",
                              LfprocWarning, stacklevel=2)
    mask, views, mask_source = _mask_from(mask, views=views)
    iso_info: dict[str, Any] = {"kind": "given"}
    if isinstance(iso_layout, (str, os.PathLike)):
        name = str(iso_layout)
        if name in ISO_PATTERNS and isos is None:
            raise InputError(f"iso_layout {name!r}: pass isos= (the ISO values of the pattern)")
        iso_map = iso_pattern(iso_layout, size=dn.shape[1:], isos=isos if isos is not None else (100,),
                              block_px=block_px, random_state=capture_streams(random_state)[0])  # the simulator's
        seed = random_state if isinstance(random_state, (int, np.integer)) else None
        iso_info = describe_iso_pattern(name, isos if name in ISO_PATTERNS else np.unique(iso_map),
                                        block_px=block_px, random_state=None if seed is None else int(seed))
    else:
        iso_map = np.asarray(iso_layout, dtype=np.float32)
    parameters: dict[str, Any] = {
        "source": "raw", "lfproc_version": __version__,
        "frames": [{"path": str(p), "sha256": file_sha256(p), **m} for p, m in zip(paths, metas)]}
    if mask_source:
        parameters["mask_source"] = mask_source
    try:
        return Capture(
            dn=dn,
            iso=iso_map,
            exposures_s=exposures_s,
            mask=mask,
            profile=profile,
            views=views,
            cfa_pattern=cfa_pattern,
            gamma=gamma,
            bias_dn=bias_dn,
            iso_pattern=iso_info,
            parameters=parameters,
        )
    except ShapeError as exc:
        if mask_source and "mask" in str(exc):
            raise ShapeError(f"{mask_source}: {exc}") from None
        raise


#: Former names of this module, now in the presentation layer (lfproc.preview).
_MOVED_TO_PREVIEW = ("render_capture_preview", "write_capture_preview", "PREVIEW_KINDS")


def __getattr__(name):  # the capture previews moved to lfproc.preview (presentation)
    if name in _MOVED_TO_PREVIEW:
        import importlib
        import warnings

        warnings.warn(f"lfproc.camera.capture.{name} moved to lfproc.preview; import it from there",
                      DeprecationWarning, stacklevel=2)
        # deprecated old path only: a stage must not import presentation, so it is looked up on use
        preview = importlib.import_module("lfproc.preview._capture")
        return getattr(preview, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
