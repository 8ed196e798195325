"""Reading exposure brackets from files, and merging them (the library side of ``lfproc merge``).

Every input becomes a :class:`~lfproc.lightfield.LightField` with its exposure time and ISO:

=====================================  ==================================================================
input                                  how it is read
=====================================  ==================================================================
Lytro capture (``.lfr``, ``.lfp``)     decoded by :mod:`lfproc.lytro.decode` with one white image for all
lfproc EXR light field, view folder    :func:`lfproc.io.read_lightfield`; ``exposure_s``/``iso`` metadata
camera raw (``.dng``, ``.cr2``...)     rawpy, linear: ``postprocess(gamma=(1, 1), no_auto_bright=True,
                                       output_bps=16)`` with bilinear (linear) demosaicing, unit white
                                       balance, camera colours, no rotation; exposure from rawpy or EXIF
8-bit JPEG/PNG/TIFF                    codes kept (``code / 255``, ``attrs["codes_bits"] = 8``): the
                                       camera response is non-linear and recovered by the merge
16-bit PNG/TIFF                        taken as linear (``value / 65535``, saturation 1)
=====================================  ==================================================================

Exposure time, ISO and exposure bias of 2-D images come from EXIF (Pillow). Given
``exposures_s`` override the metadata. Missing exposure information, or exposure bias values
that contradict the exposure times, raise :class:`~lfproc.errors.InputError` naming the file.
"""

from __future__ import annotations

import math
import os
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._shared.deprecate import renamed_keywords
from .._shared.frozen import freeze
from ..errors import FileFormatError, InputError, MissingFileError, option_name
from ..lytro.decode import decode_capture
from ..lightfield import LightField
from .._shared.jsonable import to_jsonable
from .._shared.random import check_random_state
from .._shared.validation import check_choice
from ..io import read_lightfield
from ..io._atomic import atomic_outputs
from ..io.images import imread
from ._merge import merge_lightfields, MERGE_METHODS
from .._shared.deps import require

__all__ = [
    "LYTRO_SUFFIXES",
    "RAW_SUFFIXES",
    "IMAGE_SUFFIXES_LDR",
    "BRACKET_SUFFIXES",
    "read_exif_exposure",
    "read_bracket",
    "merge_files",
    "CAMERA_RESPONSES",
    "camera_response",
    "simulate_ldr_bracket",
    "RESPONSE_SUFFIXES",
    "write_response",
    "format_response",
    "plot_response",
]

LYTRO_SUFFIXES = (".lfr", ".lfp")
RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2", ".raf", ".orf", ".rw2",
                ".pef", ".srw", ".x3f", ".3fr", ".erf", ".kdc", ".mos", ".mrw", ".iiq", ".rwl")
IMAGE_SUFFIXES_LDR = (".jpg", ".jpeg", ".png", ".tif", ".tiff")
BRACKET_SUFFIXES = LYTRO_SUFFIXES + RAW_SUFFIXES + IMAGE_SUFFIXES_LDR + (".exr",)


def _ratio(value) -> float | None:
    if value is None:
        return None
    try:
        if isinstance(value, tuple) and len(value) == 2:
            v = float(value[0]) / float(value[1])
        else:
            v = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return v if math.isfinite(v) else None


def read_exif_exposure(path: str | os.PathLike) -> dict[str, float | None]:
    """Exposure time (s), ISO, exposure bias (EV) and f-number from a file's EXIF (Pillow).

    Parameters
    ----------
    path : str or os.PathLike
        An image file (JPEG, TIFF, PNG... anything Pillow opens).

    Returns
    -------
    dict
        ``exposure_s``, ``iso``, ``exposure_bias_ev`` and ``f_number`` (floats); a value the file
        does not hold (or a non-positive exposure or ISO) is None. Files Pillow cannot open
        give all None.

    Examples
    --------
    >>> from PIL import Image
    >>> from lfproc.hdr import read_exif_exposure
    >>> exif = Image.Exif()
    >>> exif[33434], exif[34855], exif[33437] = 0.008, 200, 2.8   # ExposureTime, ISOSpeedRatings, FNumber
    >>> Image.new("RGB", (8, 8)).save("shot.jpg", exif=exif)
    >>> read_exif_exposure("shot.jpg")
    {'exposure_s': 0.008, 'iso': 200.0, 'exposure_bias_ev': None, 'f_number': 2.8}
    """
    from PIL import ExifTags, Image, UnidentifiedImageError

    out: dict[str, float | None] = {"exposure_s": None, "iso": None, "exposure_bias_ev": None, "f_number": None}
    try:
        with Image.open(path) as im:
            exif = im.getexif()
    except (UnidentifiedImageError, OSError):
        return out
    tags = dict(exif)
    try:
        tags.update(exif.get_ifd(ExifTags.IFD.Exif))
    except (KeyError, AttributeError):
        pass
    names = {v: k for k, v in ExifTags.TAGS.items()}
    iso = tags.get(names["ISOSpeedRatings"])
    if isinstance(iso, (tuple, list)):
        iso = iso[0] if iso else None
    t = _ratio(tags.get(names["ExposureTime"]))
    out["exposure_s"] = t if t and t > 0 else None
    iso_v = _ratio(iso)
    out["iso"] = iso_v if iso_v and iso_v > 0 else None
    out["exposure_bias_ev"] = _ratio(tags.get(names["ExposureBiasValue"]))
    out["f_number"] = _ratio(tags.get(names["FNumber"]))
    return out


def _read_ldr(path: Path) -> LightField:
    import cv2

    raw = imread(path, cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
    if raw.ndim == 2:
        raw = raw[..., None]
    elif raw.shape[2] == 4:
        raw = raw[..., :3]
    if raw.shape[2] == 3:
        raw = raw[..., ::-1]
    exif = read_exif_exposure(path)
    if raw.dtype == np.uint8:
        data, attrs = raw.astype(np.float32) / 255, {"codes_bits": 8}
    elif raw.dtype == np.uint16:
        data, attrs = raw.astype(np.float32) / 65535, {"codes_bits": 16, "transfer": "linear"}
    else:
        raise FileFormatError(f"{path}: expected 8- or 16-bit samples, found {raw.dtype}")
    attrs["exif"] = exif
    return LightField(data=freeze(np.ascontiguousarray(data))[None, None], units="relative",
                      colour_space="camera-rgb" if data.shape[-1] == 3 else "luminance",
                      exposure_s=exif["exposure_s"], iso=exif["iso"], saturation_level=1.0, source=str(path),
                      attrs=attrs)


def _read_raw(path: Path) -> LightField:
    require("rawpy", purpose="reading camera raw files")
    import rawpy

    try:
        raw = rawpy.imread(str(path))
    except (rawpy.LibRawError, OSError) as exc:  # type: ignore[attr-defined]
        raise FileFormatError(f"{path}: not a camera raw file rawpy can read ({exc})") from None
    with raw:
        rgb = raw.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=False,
                              use_auto_wb=False, user_wb=[1.0, 1.0, 1.0, 1.0], output_color=rawpy.ColorSpace.raw,
                              demosaic_algorithm=rawpy.DemosaicAlgorithm.LINEAR, user_flip=0,
                              adjust_maximum_thr=0.0)
        other = getattr(raw, "other", None)
        t = getattr(other, "shutter_speed", None) if other is not None else None
        iso = getattr(other, "iso_speed", None) if other is not None else None
        black = [float(b) for b in raw.black_level_per_channel]
        white = float(raw.white_level)
    exif = read_exif_exposure(path)
    t = float(t) if t else exif["exposure_s"]
    iso = float(iso) if iso else exif["iso"]
    return LightField(data=freeze(rgb.astype(np.float32) / 65535)[None, None], units="relative", colour_space="camera-rgb",
                      exposure_s=t, iso=iso, saturation_level=1.0, source=str(path),
                      attrs={"raw_black_level": black, "raw_white_level": white, "exif": exif})


def _read_lytro(path: Path, *, white_db) -> LightField:
    if white_db is None:
        raise InputError(f"{path}: decoding a Lytro capture needs a white-image database "
                         f"({option_name('white_db=DB', '--white-db DB')})")
    return decode_capture(path, white_db=white_db)


def _check_bias(lfs: list[LightField], names: list[str]) -> None:
    """EXIF exposure bias values that vary must follow the exposures (log2 t*ISO - bias constant)."""
    bias = [lf.attrs.get("exif", {}).get("exposure_bias_ev") if isinstance(lf.attrs.get("exif"), dict) else None
            for lf in lfs]
    if any(b is None for b in bias) or len(set(bias)) < 2:
        return
    ev = np.array([math.log2(lf.exposure_s * (lf.iso or 100.0)) - b for lf, b in zip(lfs, bias)])
    ref = float(np.median(ev))
    worst = int(np.argmax(np.abs(ev - ref)))
    if abs(ev[worst] - ref) > 0.5:
        raise InputError(
            f"{names[worst]}: EXIF exposure bias {bias[worst]:+g} EV contradicts its exposure time "
            f"{lfs[worst].exposure_s:g} s and ISO against the rest of the bracket (off by {ev[worst] - ref:+.2f} EV); "
            "give --exposures-s"
        )


def read_bracket(
    paths: Sequence[str | os.PathLike],
    *,
    exposures_s: Sequence[float] | None = None,
    isos: Sequence[float] | float | None = None,
    white_db: str | os.PathLike | None = None,
    profile=None,
    nonfinite: str = "raise",
    negative: str = "clip",
) -> list[LightField]:
    """Read a bracket of inputs (see the module table) as light fields with exposure metadata.

    Parameters
    ----------
    paths : sequence of paths (at least two)
    exposures_s : sequence of floats, optional
        Exposure times (s), one per input, overriding the metadata.
    isos : float or sequence, optional
        ISO, one for all or one per input, overriding the metadata.
    white_db : path, optional
        White-image database for Lytro captures (the same white image is used for all).
    profile : camera profile, optional
        Passed to the Lytro decoder.
    nonfinite, negative : str
        Value policies of light-field inputs (EXR files, folders of views), as
        :func:`lfproc.io.read_lightfield`.

    Returns
    -------
    list of LightField
        Same shape, ``exposure_s`` set on every one.

    Raises
    ------
    InputError
        Fewer than two inputs; a count of ``exposures_s`` that does not match; an input with no
        exposure time (and none given); contradictory EXIF exposure bias.
    """
    paths = [Path(p) for p in paths]
    if len(paths) < 2:
        raise InputError(f"a bracket needs at least two inputs (exposures), got {len(paths)}: "
                         f"{', '.join(map(str, paths)) or 'none'}")
    if exposures_s is not None and len(exposures_s) != len(paths):
        raise InputError(f"--exposures-s: expected {len(paths)} values (one per input), got {len(exposures_s)}")
    if isos is not None and np.ndim(isos) and len(isos) not in (1, len(paths)):  # type: ignore[arg-type]
        raise InputError(f"--isos: expected 1 or {len(paths)} values, got {len(isos)}")  # type: ignore[arg-type]
    lfs = []
    for p in paths:
        if not p.exists():
            raise MissingFileError(f"{p}: no such file or folder")
        suffix = p.suffix.lower()
        if p.is_dir() or suffix == ".exr":
            lf = read_lightfield(p, nonfinite=nonfinite, negative=negative)
        elif suffix in LYTRO_SUFFIXES:
            lf = _read_lytro(p, white_db=white_db)
        elif suffix in RAW_SUFFIXES:
            lf = _read_raw(p)
        elif suffix in IMAGE_SUFFIXES_LDR:
            lf = _read_ldr(p)
        else:
            raise FileFormatError(f"{p}: not a bracket input; expected one of {', '.join(BRACKET_SUFFIXES)} "
                                  "or a folder of views")
        lfs.append(lf if lf.source else lf.replace(source=str(p)))
    for i, (lf, p) in enumerate(zip(lfs, paths)):
        changes: dict[str, Any] = {}
        if exposures_s is not None:
            changes["exposure_s"] = float(exposures_s[i])
        if isos is not None:
            changes["iso"] = float(np.broadcast_to(np.asarray(isos, dtype=float), (len(paths),))[i])
        if changes:
            lfs[i] = lf = lf.replace(**changes)
        if lf.exposure_s is None:
            raise InputError(f"{p}: no exposure time in its metadata (EXIF ExposureTime or lfproc exposure_s); "
                             "give --exposures-s")
    if exposures_s is None:
        _check_bias(lfs, [str(p) for p in paths])
    return lfs


@renamed_keywords(n_iter="max_iter")
def merge_files(
    paths: Sequence[str | os.PathLike],
    *,
    method: str | None = None,
    profile=None,
    exposures_s: Sequence[float] | None = None,
    isos: Sequence[float] | float | None = None,
    white_db: str | os.PathLike | None = None,
    max_iter: int = 2,
    random_state=0,
    n_threads: int | None = None,
    option_names: dict[str, str] | None = None,
    nonfinite: str = "raise",
    negative: str = "clip",
) -> tuple[LightField, dict[str, Any]]:
    """Read a bracket of files and merge it (:func:`read_bracket` then :func:`lfproc.merge.merge_lightfields`).

    ``method=None`` chooses: ``debevec`` for 8-bit camera images (non-linear) or when no camera
    profile is known (unless the inputs carry their own variances, as decoded captures do),
    ``ml`` otherwise. Lytro captures default to the ``illum`` profile.

    A parameter that would have no effect is refused (:class:`InputError`) rather than silently
    ignored: ``profile`` with 8-bit images (their response is recovered from the bracket, both
    methods) and ``white_db`` without a Lytro capture. ``option_names`` maps parameter names to
    the names used in messages (the CLI passes its options, e.g. ``{"profile": "--profile"}``).
    ``nonfinite`` and ``negative`` are the value policies of light-field inputs (:func:`read_bracket`).
    ``max_iter`` is the ML merge's fixed-point updates (the keyword ``n_iter`` is deprecated).
    Parameters that have no effect only with the method chosen for these inputs (``max_iter`` with
    ``debevec``...) are listed by :func:`unused_options` (``lfproc merge`` refuses them).

    Parameters
    ----------
    paths : sequence of str or os.PathLike
        The bracket: images, light fields or Lytro captures (all of one kind), at least two.
    method : {"ml", "debevec"}, optional
        The merge (default: chosen as above).
    profile : CameraProfile or str, optional
        Camera profile of linear raw inputs (``ml`` needs one).
    exposures_s : sequence of float, optional
        Exposure times in seconds, one per file (default: from the files' metadata or EXIF).
    isos : float or sequence of float, optional
        ISO of every file, or one for all (default: from the files).
    white_db : str or os.PathLike, optional
        White-image database for Lytro captures (:func:`lfproc.lytro.build_white_db`).
    max_iter : int, default 2
        Fixed-point updates of the ML merge.
    random_state : int, Generator or None, default 0
        Seed of the response recovery's pixel sampling.
    n_threads : int, optional
        Worker threads (default: the available cores).
    option_names : dict, optional
        Parameter name -> name used in messages.
    nonfinite, negative : str
        Value policies of light-field inputs (see :func:`lfproc.lightfield.clean_nonfinite`).

    Returns
    -------
    lf : LightField
        The merged light field (``attrs["sources"]`` are the file paths).
    info : dict
        The merge information (see :func:`lfproc.hdr.merge_lightfields`), plus ``method``.

    Raises
    ------
    lfproc.errors.InputError
        A parameter that has no effect, mixed or missing exposures, too few files.
    lfproc.errors.MissingFileError, lfproc.errors.FileFormatError
        A file is missing or unreadable.
    """
    if method is not None:
        check_choice("method", method, MERGE_METHODS)
    names = option_names or {}
    paths = [Path(p) for p in paths]
    lytro = any(p.suffix.lower() in LYTRO_SUFFIXES for p in paths)
    if white_db is not None and not lytro:
        raise InputError(f"{names.get('white_db', 'white_db')}: has no effect without a Lytro capture (.lfr, .lfp) "
                         "among the inputs; drop it")
    profile_given = profile is not None
    if profile is None and lytro:
        profile = "illum"
    lfs = read_bracket(paths, exposures_s=exposures_s, isos=isos, white_db=white_db, profile=profile,
                       nonfinite=nonfinite, negative=negative)
    if profile_given:
        eight = next((p for p, lf in zip(paths, lfs) if lf.attrs.get("codes_bits") == 8), None)
        if eight is not None:
            raise InputError(f"{names.get('profile', 'profile')}: has no effect on 8-bit images such as {eight} "
                             "(their camera response is recovered from the bracket and the ml weights from its "
                             "noise); drop it")
    if method is None:
        codes8 = any(lf.attrs.get("codes_bits") == 8 for lf in lfs)
        with_variance = all(lf.variance is not None and lf.units != "dn" for lf in lfs)
        method = "debevec" if codes8 or (profile is None and not with_variance) else "ml"
    own_variance = all(lf.variance is not None and lf.units != "dn" for lf in lfs)
    codes8 = any(lf.attrs.get("codes_bits") == 8 for lf in lfs)
    if method == "ml" and not own_variance and not codes8 and isos is None and any(lf.iso is None for lf in lfs):
        bad = next(p for p, lf in zip(paths, lfs) if lf.iso is None)
        raise InputError(f"{bad}: no ISO in its metadata; method ml needs one (give {option_name('isos=', '--isos')})")
    merged, info = merge_lightfields(lfs, method=method, profile=profile, max_iter=max_iter, random_state=random_state,
                                     n_threads=n_threads)
    merged = merged.replace(attrs=dict(merged.attrs) | {"sources": [str(p) for p in paths]})
    info["method"] = method
    return merged, info


def unused_options(given: Collection[str], *, method: str, mapping: str) -> list[tuple[str, str]]:
    """The parameters of ``given`` that :func:`merge_files` ignored: ``(name, why)`` pairs.

    ``method`` and ``mapping`` are those of the merge (``info["method"]`` and the merged light field's
    ``attrs["input_mapping"]``: ``"codes8"`` for 8-bit images, ``"input-variances"`` for inputs with
    their own variances, ``"dn"`` for raw codes).

    ``max_iter``: only the ML merges of sensor codes and of 8-bit images iterate (not ``debevec``,
    not the ML merge of inputs with their own variances, which weighs by them in one pass).
    ``random_state``: only the response recovery of 8-bit images samples pixels. ``isos``: the ML
    merge of 8-bit images measures its noise on the bracket and scales by exposure time only.
    ``profile``: ``debevec`` uses it only for raw (dn) inputs' levels; the ML merge of inputs with
    their own variances does not use it (8-bit images are refused earlier, with their own message).

    Examples
    --------
    >>> from lfproc.hdr._bracket import unused_options
    >>> unused_options({"max_iter", "random_state"}, method="debevec", mapping="codes8")
    [('max_iter', 'with method debevec (it does not iterate; ml weight updates only)')]
    """
    out = []
    given = set(given)
    codes8, own_variance, dn = mapping == "codes8", mapping == "input-variances", mapping == "dn"
    iterates = method == "ml" and (codes8 or not own_variance)
    if "max_iter" in given and not iterates:
        out.append(("max_iter", "with method debevec (it does not iterate; ml weight updates only)"
                    if method == "debevec" else "with method ml on inputs with their own variances (decoded "
                    "captures: weighed by them in one pass, no updates)"))
    if "random_state" in given and not codes8:
        out.append(("random_state", f"on linear inputs (it seeds the camera-response recovery of 8-bit images; "
                                    f"method {method} here needs none)"))
    if "isos" in given and method == "ml" and codes8:
        out.append(("isos", "with method ml on 8-bit images (their noise is measured on the bracket and the "
                            "exposures scale by exposure time only)"))
    if "profile" in given and not codes8 and ((method == "debevec" and not dn) or (method == "ml" and own_variance)):
        out.append(("profile", "with method debevec on linear (non-raw) inputs (it gives raw inputs' black and "
                               "white levels)" if method == "debevec" else
                               "with method ml on inputs with their own variances (they set the weights)"))
    return out


# -- synthetic 8-bit brackets with a known answer --------------------------------------------------

CAMERA_RESPONSES = ("camera", "srgb")


def _srgb_oetf(x: np.ndarray) -> np.ndarray:
    import colour

    return np.asarray(colour.models.eotf_inverse_sRGB(np.clip(x, 0, 1)), dtype=np.float64)


def camera_response(x, kind: str = "camera") -> np.ndarray:
    """Normalised code ``f(x)`` in [0, 1] of linear sensor exposure ``x`` (clipped at 1 for ``srgb``, 2 for ``camera``).

    ``"srgb"``: the sRGB encoding (colour-science), clipping at ``x = 1``. ``"camera"``: a
    camera-JPEG-like curve, an extended-Reinhard highlight shoulder ``y = x (1 + x / 4) / (1 + x)``
    (reaching 1 at ``x = 2``: one stop of highlight roll-off) followed by the sRGB encoding;
    measured consumer-camera responses (e.g. the DoRF database of Grossberg & Nayar) share
    that shape: sRGB-like in the shadows, compressed in the highlights.

    Parameters
    ----------
    x : array_like
        Linear exposure (1 = the exposure that reads 1 in sRGB); negative values read as 0.
    kind : {"camera", "srgb"}, default "camera"
        The curve.

    Returns
    -------
    ndarray
        Codes in [0, 1], float64, the shape of ``x``.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.hdr import camera_response
    >>> x = np.array([0.0, 0.18, 1.0, 2.0, 4.0])
    >>> [round(float(v), 4) for v in camera_response(x)]          # one stop of shoulder above x = 1
    [0.0, 0.4359, 0.8124, 1.0, 1.0]
    >>> [round(float(v), 4) for v in camera_response(x, "srgb")]
    [0.0, 0.4614, 1.0, 1.0, 1.0]
    """
    check_choice("response", kind, CAMERA_RESPONSES)
    x = np.clip(np.asarray(x, dtype=np.float64), 0, None)
    if kind == "camera":
        x = np.minimum(x, 2.0)
        x = x * (1 + x / 4) / (1 + x)
    return _srgb_oetf(x)


def simulate_ldr_bracket(
    radiance,
    exposures_s: Sequence[float],
    *,
    response: str = "camera",
    full_well_e: float = 20000.0,
    read_noise_e: float = 3.0,
    jpeg_quality: int | None = 90,
    mid_grey: float = 0.18,
    random_state=None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """An 8-bit JPEG exposure bracket of a known HDR image, for testing merges against a reference.

    Each exposure ``t``: linear exposure ``x = k L t`` (``k`` puts the median luminance at
    ``mid_grey`` in the median exposure), photo-electrons ``Poisson(x * full_well_e)`` plus
    Gaussian read noise, back to ``x``, the camera response :func:`camera_response`, rounding to
    8-bit codes and a JPEG round trip through OpenCV (4:2:0 chroma subsampling, as cameras do).
    The HDR image is the reference of the merged result (up to the scale ``k``).

    Parameters
    ----------
    radiance : ndarray (H, W, 3) or LightField with one view
        Linear RGB radiance (non-negative, finite).
    exposures_s : sequence of floats
    response : {"camera", "srgb"}
    full_well_e, read_noise_e : float
        Sensor noise (electrons at ``x = 1``; read noise in electrons).
    jpeg_quality : int in 1..100, or None for no JPEG compression
    mid_grey : float
    random_state : int, Generator or None

    Returns
    -------
    codes : ndarray (N, H, W, 3), uint8
    info : dict
        ``scale`` (``k``), ``response`` (kind), ``response_g`` (the true ``g = ln f^-1`` at the
        code centres, ``g(128) = 0``, shape (256,)), ``well_exposed`` (H, W) mask: pixels whose
        three channels are within codes 8..247 in at least one exposure (the pixels any merge can
        recover), and the parameters.
    """
    import cv2

    if isinstance(radiance, LightField):
        if radiance.views != (1, 1):
            raise InputError(f"radiance: expected one view, got a {radiance.views[0]}x{radiance.views[1]} light field")
        radiance = radiance.data[0, 0]
    L = np.asarray(radiance, dtype=np.float64)
    if L.ndim != 3 or L.shape[2] != 3:
        raise InputError(f"radiance: expected an RGB image (H, W, 3), got shape {L.shape}")
    if not np.isfinite(L).all() or (L < 0).any():
        raise InputError("radiance: expected finite non-negative values")
    t = np.asarray(exposures_s, dtype=np.float64)
    if t.ndim != 1 or t.size < 2 or not (np.isfinite(t).all() and (t > 0).all()):
        raise InputError(f"exposures_s: expected two or more positive times, got {list(np.ravel(t))}")
    if jpeg_quality is not None and not 1 <= int(jpeg_quality) <= 100:
        raise InputError(f"jpeg_quality: expected 1..100 or None, got {jpeg_quality}")
    for name, v in (("full_well_e", full_well_e), ("mid_grey", mid_grey)):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"{name}: expected a positive number, got {v}")
    if not (np.isfinite(read_noise_e) and read_noise_e >= 0):
        raise InputError(f"read_noise_e: expected a non-negative number, got {read_noise_e}")
    camera_response(0.5, response)  # validates the name
    rng = check_random_state(random_state)
    Y = L @ np.array([0.2126, 0.7152, 0.0722])
    positive = Y[Y > 0]
    if positive.size == 0:
        raise InputError("radiance: the image is black")
    k = mid_grey / float(np.median(positive)) / float(np.median(t))
    codes = []
    for ti in t:
        e = rng.poisson(np.minimum(L * k * ti * full_well_e, 1e12)).astype(np.float64)
        if read_noise_e > 0:
            e += rng.normal(0.0, read_noise_e, e.shape)
        z = np.clip(np.round(255 * camera_response(e / full_well_e, response)), 0, 255).astype(np.uint8)
        if jpeg_quality is not None:
            ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(z[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
            z = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
        codes.append(np.ascontiguousarray(z))
    # the true inverse response at the code centres (code 0 and 255: a quarter code inside)
    top = 2.0 if response == "camera" else 1.0
    xs = np.geomspace(1e-9, top, 400_001)
    ys = 255 * camera_response(xs, response)
    zc = np.arange(256, dtype=np.float64)
    zc[0], zc[255] = 0.25, 254.75
    g = np.log(np.interp(zc, ys, xs))
    lo, hi = np.interp([8.0, 247.0], ys, xs)
    xt = L[None] * k * t[:, None, None, None]
    well = ((xt >= lo) & (xt <= hi)).all(axis=-1).any(axis=0)
    return np.stack(codes), {
        "scale": k,
        "response": response,
        "response_g": g - g[128],
        "well_exposed": well,
        "exposures_s": t.tolist(),
        "full_well_e": float(full_well_e),
        "read_noise_e": float(read_noise_e),
        "jpeg_quality": None if jpeg_quality is None else int(jpeg_quality),
    }


# -- the camera response a merge recovered ----------------------------------------------------------

RESPONSE_SUFFIXES = (".csv", ".json")


def write_response(
    path: str | os.PathLike,
    response,
    *,
    plot: str | os.PathLike | None = None,
    metadata: dict[str, Any] | None = None,
    force: bool = False,
) -> list[Path]:
    """Write a camera response ``g(z) = ln f^-1(z)`` (as :func:`lfproc.merge.recover_response` returns it).

    The file holds, for each 8-bit code ``z`` and channel, the inverse response ``f^-1(z) = exp(g(z))``
    (the relative exposure that reads ``z``; ``f^-1(128) = 1``), as OpenCV's ``CalibrateDebevec``
    returns it, and ``g`` itself (colour-hdri's ``g_solve``):

    * ``.csv``: a header ``code,R,G,B,ln_R,ln_G,ln_B`` (``Y``/``ln_Y`` for one channel, ``C0``...
      for other counts) and 256 rows;
    * ``.json``: ``{"kind": "camera_response", "codes": [0..255], "channels": [...],
      "inverse_response": [[...] per channel], "log_inverse_response": [[...] per channel], ...}``
      plus ``metadata`` (method, exposures, sources...).

    ``plot`` (a ``.png`` path): ``g`` against the code, one curve per channel. All files are
    written together (:func:`lfproc.io.atomic_outputs`): all or none; an existing one is
    replaced only with ``force``.

    Parameters
    ----------
    path : str or os.PathLike
        Output ``.csv`` or ``.json`` file.
    response : ndarray of shape (256,) or (256, C)
        ``g(z)``, the log inverse response of each code.
    plot : str or os.PathLike, optional
        A ``.png`` plot of ``g``.
    metadata : dict, optional
        Extra JSON fields (``.json`` only); ``title`` also titles the plot.
    force : bool, default False
        Replace existing files.

    Returns
    -------
    list of pathlib.Path
        The paths written.

    Raises
    ------
    lfproc.errors.InputError
        A bad suffix or response shape.
    lfproc.errors.OutputExistsError
        An output exists and ``force`` is false.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.hdr import write_response
    >>> g = np.log(np.arange(1, 257) / 128)        # a linear camera: f^-1(z) = z / 128
    >>> write_response("response.csv", g)
    [PosixPath('response.csv')]
    >>> from pathlib import Path
    >>> print("\\n".join(Path("response.csv").read_text().splitlines()[:3]))
    code,Y,ln_Y
    0,0.0078125,-4.85203026
    1,0.015625,-4.15888308
    """
    path = Path(path)
    text = format_response(response, suffix=path.suffix, metadata=metadata, where=str(path))
    outputs = [path] if plot is None else [path, Path(plot)]
    with atomic_outputs(outputs, force=force) as staged:
        staged[0].write_text(text, encoding="utf-8")
        if plot is not None:
            plot_response(staged[1], response, title=(metadata or {}).get("title"))
    return outputs


def _response_array(response) -> tuple[np.ndarray, list[str]]:
    g = np.asarray(response, dtype=np.float64)
    if g.ndim == 1:
        g = g[:, None]
    if g.ndim != 2 or g.shape[0] != 256 or not np.isfinite(g).all():
        raise InputError(f"response: expected a finite array of shape (256,) or (256, C), got {g.shape}")
    c = g.shape[1]
    return g, {1: ["Y"], 3: ["R", "G", "B"]}.get(c, [f"C{k}" for k in range(c)])


def format_response(response, *, suffix: str, metadata: dict[str, Any] | None = None,
                    where: str = "response file") -> str:
    """The text of a response file (``suffix`` ``.csv`` or ``.json``; see :func:`write_response`)."""
    import csv as _csv
    import io as _io
    import json

    if suffix.lower() not in RESPONSE_SUFFIXES:
        raise InputError(f"{where}: expected a response file ending in {' or '.join(RESPONSE_SUFFIXES)}, "
                         f"got {suffix or 'no suffix'}")
    g, names = _response_array(response)
    x = np.exp(g)
    if suffix.lower() == ".csv":
        buf = _io.StringIO()
        writer = _csv.writer(buf, lineterminator="\n")
        writer.writerow(["code", *names, *(f"ln_{n}" for n in names)])
        for z in range(256):
            writer.writerow([z, *(f"{v:.9g}" for v in x[z]), *(f"{v:.9g}" for v in g[z])])
        return buf.getvalue()
    doc = {
        "kind": "camera_response",
        "definition": "inverse_response[c][z] = f^-1(z): relative exposure reading 8-bit code z in channel c "
                      "(f^-1(128) = 1); log_inverse_response = ln of it (Debevec & Malik's g)",
        "codes": list(range(256)),
        "channels": names,
        "inverse_response": x.T.tolist(),
        "log_inverse_response": g.T.tolist(),
    }
    doc.update(to_jsonable(metadata or {}))
    return json.dumps(doc, indent=1) + "\n"


def plot_response(path: str | os.PathLike, response, *, title: str | None = None) -> None:
    """A PNG plot of ``g(z) = ln f^-1(z)`` against the code, one curve per channel."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    g, names = _response_array(response)
    colours = {"R": "tab:red", "G": "tab:green", "B": "tab:blue", "Y": "black"}
    fig = Figure(figsize=(6.4, 4.4))
    ax = fig.add_subplot()
    codes = np.arange(256)
    for k, name in enumerate(names):
        ax.plot(codes, g[:, k], color=colours.get(name), label=name, linewidth=1.4)
    ax.set_xlabel("8-bit code z")
    ax.set_ylabel("ln exposure  g(z) = ln f$^{-1}$(z)   (g(128) = 0)")
    ax.set_xlim(0, 255)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right")
    ax.set_title(title or "camera response recovered by lfproc merge")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
