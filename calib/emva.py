"""EMVA 1288 data sets: the descriptor format and the linear-model evaluation.

Descriptor (the standard's own text format, one item a line; ``#`` starts a comment)::

    v 3.1                      release
    n 12 640 480               bits, width, height
    b 1000000 1234.5           bright step: exposure (ns), mean photons per pixel
    i images/b000_a.png        its images (relative to the descriptor; \\ or /)
    i images/b000_b.png
    d 1000000                  dark step: exposure (ns)
    i images/d000_a.png
    i images/d000_b.png

A step with two images is a temporal pair (sensitivity, photon transfer, dark current);
a step with more images is a spatial stack (DSNU, PRNU). A step with one image cannot
give a temporal variance and is skipped (recorded in ``notes``).

Evaluation (EMVA 1288 Release 3.x / Release 4 "Linear"; quantisation noise
``sigma_q^2 = 1/12 DN^2``):

* per pair ``mu_y = mean(y_A + y_B)/2`` and ``sigma_y^2 = mean(((y_A - mu_A) - (y_B - mu_B))^2)/2``;
* saturation index: the maximum of ``sigma_y^2``, searched from the brightest step down;
* ``K`` = slope through the origin of ``sigma_y^2 - sigma_y.dark^2`` against
  ``mu_y - mu_y.dark`` and responsivity ``R`` = slope through the origin of
  ``mu_y - mu_y.dark`` against ``mu_p``, both from 0 to 70 % of the saturation signal;
  ``eta = R / K``;
* ``sigma_y.dark``: the intercept of ``sigma_y.dark^2`` against exposure time when there are
  more than two exposure times, else the first value; lower limit ``0.24 DN^2``;
  ``sigma_d = sqrt(sigma_y.dark^2 - 1/12) / K`` (e-);
* saturation capacity ``mu_p.sat = mu_p`` at the saturation index, ``mu_e.sat = eta mu_p.sat``;
  absolute sensitivity threshold ``mu_p.min = (sigma_y.dark / K + 1/2) / eta``;
  ``SNR_max = sqrt(mu_e.sat)``, ``DR = mu_p.sat / mu_p.min`` (dB: ``20 log10``);
* dark current ``mu_I = d mu_y.dark/dt / K`` and ``mu_I.var = d sigma_y.dark^2/dt / K^2`` (more
  than two exposure times);
* linearity error from the ``1/Y``-weighted fit of ``mu_y - mu_y.dark`` against ``mu_p``
  between 5 % and 95 % of saturation;
* stacks of ``L`` frames: ``s_y^2 = var_spatial(mean image) - sigma_y.stack^2 / L``,
  ``DSNU1288 = s_y.dark / K`` (e-), ``PRNU1288 = sqrt(s_y^2 - s_y.dark^2) / (mu_y - mu_y.dark)``.

A figure the data cannot give is ``None`` with its reason in ``unknown``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfproc import _untrusted as ut
from lfproc._shared.progress import progress
from lfproc._shared.reprs import short_repr
from lfproc.errors import CalibrationError, FileFormatError, MissingFileError
from lfproc.io._atomic import atomic_file

from .frames import FrameChecker, read_frame

__all__ = [
    "EmvaStep",
    "EmvaDescriptor",
    "EmvaData",
    "read_descriptor",
    "write_descriptor",
    "format_descriptor",
    "is_descriptor",
    "reduce_descriptor",
    "evaluate",
    "evaluate_descriptor",
    "pair_statistics",
    "SIGMA2_Q",
]

SIGMA2_Q = 1.0 / 12.0
_DARK_FLOOR_DN2 = 0.24


@dataclass(frozen=True)
class EmvaStep:
    """One step of a descriptor: ``kind`` "bright" or "dark", exposure (ns), mean photons per
    pixel (bright steps; ``None`` for dark ones) and its image paths."""

    kind: str
    exposure_ns: float
    photons: float | None
    images: tuple[Path, ...]
    line: int = 0

    @property
    def exposure_s(self) -> float:
        return self.exposure_ns * 1e-9


@dataclass(frozen=True)
class EmvaDescriptor:
    """A parsed EMVA 1288 descriptor file."""

    release: str
    bits: int
    width: int
    height: int
    steps: tuple[EmvaStep, ...]
    path: Path | None = None


def is_descriptor(path: str | os.PathLike) -> bool:
    """True when the file's first item line is ``v ...`` or ``n ...`` (an EMVA 1288 descriptor)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for raw in fh:
                line = raw.split("#", 1)[0].strip()
                if line:
                    parts = line.split()
                    return parts[0] in ("v", "n") and len(parts) >= 2
    except OSError:
        return False
    return False


#: Most lines / images one descriptor may hold.
MAX_DESCRIPTOR_LINES = 200000


def read_descriptor(path: str | os.PathLike, *, root: str | os.PathLike | None = None) -> EmvaDescriptor:
    """Parse an EMVA 1288 descriptor.

    Image paths are relative to the descriptor and must lie inside its folder (or inside
    ``root``, a folder the caller names, where absolute paths are then allowed).

    Raises
    ------
    MissingFileError
        No such file.
    FileFormatError
        A malformed line (the line number and text are named), no ``n`` line, an image
        before any step.
    UnsafeFileError
        An image path leads outside the descriptor's folder (or ``root``).
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path}: no such EMVA 1288 descriptor file")
    lines = ut.read_text(path, what="text EMVA 1288 descriptor", encoding="utf-8-sig").splitlines()
    if len(lines) > MAX_DESCRIPTOR_LINES:
        raise FileFormatError(f"{path}: {len(lines)} lines, above the limit of {MAX_DESCRIPTOR_LINES}")
    release = ""
    bits = width = height = None
    steps: list[dict[str, Any]] = []
    for number, raw in enumerate(lines, start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        tag, _, rest = line.partition(" ")
        rest = rest.strip()
        where = f"{path}: line {number} ({ut.show(raw.strip(), 80)})"
        try:
            if tag == "v":
                release = rest
            elif tag == "n":
                b, w, h = rest.split()
                bits, width, height = int(b), int(w), int(h)
                if not (1 <= bits <= 32 and 0 < width <= ut.MAX_DIMENSION and 0 < height <= ut.MAX_DIMENSION):
                    raise ValueError
            elif tag == "b":
                t, p = rest.split()
                steps.append({"kind": "bright", "exposure_ns": float(t), "photons": float(p), "images": [],
                              "line": number})
            elif tag == "d":
                (t,) = rest.split()
                steps.append({"kind": "dark", "exposure_ns": float(t), "photons": None, "images": [],
                              "line": number})
            elif tag == "i":
                if not steps:
                    raise FileFormatError(f"{where}: an image line before any 'b' or 'd' step")
                if not rest:
                    raise ValueError
                steps[-1]["images"].append(ut.resolve_inside(path.parent, rest, source=where, field="i", root=root))
            else:
                raise FileFormatError(f"{where}: unknown item {tag!r}; expected v, n, b, d or i")
        except FileFormatError:
            raise
        except ValueError:
            expected = {"n": "n <bits> <width> <height>", "b": "b <exposure_ns> <photons>",
                        "d": "d <exposure_ns>", "i": "i <image path>"}[tag]
            raise FileFormatError(f"{where}: expected '{expected}'") from None
        if tag in ("b", "d") and not (math.isfinite(steps[-1]["exposure_ns"]) and steps[-1]["exposure_ns"] >= 0):
            raise FileFormatError(f"{where}: exposure must be a finite number of ns >= 0")
        if tag == "b" and not (math.isfinite(steps[-1]["photons"]) and steps[-1]["photons"] >= 0):
            raise FileFormatError(f"{where}: photons must be a finite number >= 0")
    if bits is None:
        raise FileFormatError(f"{path}: no 'n <bits> <width> <height>' line; not an EMVA 1288 descriptor")
    if not steps:
        raise FileFormatError(f"{path}: the descriptor has no 'b' or 'd' steps")
    return EmvaDescriptor(
        release=release, bits=bits, width=width, height=height, path=path,
        steps=tuple(EmvaStep(kind=s["kind"], exposure_ns=s["exposure_ns"], photons=s["photons"],
                             images=tuple(s["images"]), line=s["line"]) for s in steps),
    )


def format_descriptor(desc: EmvaDescriptor, *, base: str | os.PathLike) -> str:
    """The descriptor text, image paths relative to ``base`` (forward slashes)."""
    base = Path(base)
    out = [f"v {desc.release or '3.1'}", f"n {desc.bits} {desc.width} {desc.height}"]
    for step in desc.steps:
        if step.kind == "bright":
            out.append(f"b {step.exposure_ns:.17g} {float(step.photons or 0.0):.17g}")
        else:
            out.append(f"d {step.exposure_ns:.17g}")
        for img in step.images:
            img = Path(img)
            try:
                img = img.relative_to(base)
            except ValueError:
                pass
            out.append(f"i {img.as_posix()}")
    return "\n".join(out) + "\n"


def write_descriptor(desc: EmvaDescriptor, path: str | os.PathLike, *, force: bool = False) -> Path:
    """Write ``desc`` atomically to ``path``; image paths are made relative to its folder."""
    path = Path(path)
    with atomic_file(path, force=force) as tmp:
        tmp.write_text(format_descriptor(desc, base=path.parent))
    return path


# -- reduction ------------------------------------------------------------------------------
def pair_statistics(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None) -> tuple[float, float]:
    """Mean and temporal variance of a frame pair (EMVA 1288): ``mean(a + b)/2`` and
    ``mean(((a - mean a) - (b - mean b))^2) / 2`` over the pixels of ``mask``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if mask is not None:
        a, b = a[mask], b[mask]
    d = a - b
    return float((a.mean() + b.mean()) / 2), float(d.var() / 2)


class _StackAccumulator:
    """Per-pixel running sums of a frame stack, shifted by the first frame for accuracy."""

    def __init__(self):
        self.n = 0

    def add(self, frame: np.ndarray) -> None:
        x = np.asarray(frame, dtype=np.float64)
        if self.n == 0:
            self.shift = x.copy()
            self.s1 = np.zeros_like(x)
            self.s2 = np.zeros_like(x)
        d = x - self.shift
        self.s1 += d
        self.s2 += d * d
        self.n += 1

    def mean(self) -> np.ndarray:
        return self.shift + self.s1 / self.n

    def var(self) -> np.ndarray:
        """Per-pixel temporal variance (ddof = 1)."""
        return np.maximum(self.s2 - self.s1 * self.s1 / self.n, 0.0) / (self.n - 1)


@short_repr
@dataclass
class EmvaData:
    """Reduced EMVA 1288 data: temporal arrays (one entry per bright pair, ordered by
    photons), spatial stack figures and the stacks' per-pixel mean images (``None`` when the
    descriptor has no stacks)."""

    texp_s: np.ndarray
    u_p: np.ndarray
    u_y: np.ndarray
    s2_y: np.ndarray
    u_ydark: np.ndarray
    s2_ydark: np.ndarray
    spatial: dict[str, float] | None
    spatial_dark: dict[str, float] | None
    bits: int
    shape: tuple[int, int]
    notes: list[str] = field(default_factory=list)
    max_code: np.ndarray | None = None
    frac_at_max: np.ndarray | None = None
    bright_image: np.ndarray | None = None  # per-pixel mean of the bright stack (DN)
    dark_image: np.ndarray | None = None  # per-pixel mean of the dark stack (DN)

    def clip_code(self, min_fraction: float = 0.01) -> float | None:
        """The output code where over-exposed pairs pile up: the largest code that holds at least
        ``min_fraction`` of a bright pair's pixels, or ``None`` when no pair piles up."""
        if self.max_code is None:
            return None
        piles = [float(m) for m, f in zip(self.max_code, self.frac_at_max) if f >= min_fraction]
        return max(piles) if piles else None


def _read(path: Path, checker: FrameChecker, desc: EmvaDescriptor) -> np.ndarray:
    frame = read_frame(path)
    if frame.shape != (desc.height, desc.width):
        raise CalibrationError(
            f"{path}: frame is {frame.shape[0]}x{frame.shape[1]} pixels; the descriptor's 'n' line says "
            f"{desc.height}x{desc.width} (height x width)"
        )
    checker.check(frame)
    return frame.data


def _stack(paths, checker, desc) -> tuple[dict[str, float], np.ndarray]:
    """Figures of a frame stack and its per-pixel mean image (float32)."""
    acc = _StackAccumulator()
    top = -np.inf
    for p in paths:
        frame = _read(p, checker, desc)
        top = max(top, float(frame.max()))
        acc.add(frame)
    mean = acc.mean()
    return ({"L": acc.n, "avg_mean": float(mean.mean()), "avg_var": float(mean.var(ddof=1)),
             "var_mean": float(acc.var().mean()), "max_code": top},
            mean.astype(np.float32))


def reduce_descriptor(desc: EmvaDescriptor) -> EmvaData:
    """Read every image of ``desc`` once and reduce pairs and stacks to their statistics.

    Raises
    ------
    CalibrationError
        Frames of different size/bit depth, a bright pair without a dark pair at the same
        exposure (when the darks have several exposures), fewer than two bright pairs.
    """
    checker = FrameChecker(f"EMVA 1288 data set {desc.path}")
    notes: list[str] = []
    pairs = {"bright": [], "dark": []}
    stacks = {"bright": [], "dark": []}
    for step in desc.steps:
        n = len(step.images)
        label = f"{step.kind} step at {step.exposure_ns:g} ns (line {step.line})"
        if n == 0:
            notes.append(f"{label} has no images; skipped")
        elif n == 1:
            notes.append(f"{label} has a single image; a temporal variance needs a pair; skipped")
        elif n == 2:
            pairs[step.kind].append(step)
        else:
            stacks[step.kind].append(step)
    dark_by_t: dict[float, tuple[float, float]] = {}
    for step in progress(pairs["dark"], desc="EMVA dark pairs"):
        a, b = (_read(p, checker, desc) for p in step.images)
        dark_by_t.setdefault(step.exposure_ns, [])
        dark_by_t[step.exposure_ns].append(pair_statistics(a, b))
    dark = {t: (float(np.mean([m for m, _ in v])), float(np.mean([s for _, s in v]))) for t, v in dark_by_t.items()}
    if not pairs["bright"]:
        raise CalibrationError(f"{desc.path}: no bright step with an image pair; the photon transfer needs pairs")
    if not dark:
        raise CalibrationError(f"{desc.path}: no dark step with an image pair; the dark signal and noise need pairs")
    rows = []
    for step in progress(pairs["bright"], desc="EMVA bright pairs"):
        if step.exposure_ns in dark:
            u_d, s2_d = dark[step.exposure_ns]
        elif len(dark) == 1:
            u_d, s2_d = next(iter(dark.values()))
        else:
            raise CalibrationError(
                f"{desc.path}: bright step at {step.exposure_ns:g} ns (line {step.line}) has no dark pair at the "
                f"same exposure (dark exposures: {', '.join(f'{t:g}' for t in sorted(dark))} ns)"
            )
        a, b = (_read(p, checker, desc) for p in step.images)
        u_y, s2_y = pair_statistics(a, b)
        top = max(int(a.max()), int(b.max()))
        at_top = (np.count_nonzero(a == top) + np.count_nonzero(b == top)) / (a.size + b.size)
        rows.append((step.photons or 0.0, step.exposure_ns * 1e-9, u_y, s2_y, u_d, s2_d, top, at_top))
    rows.sort(key=lambda r: (r[0], r[1]))
    arr = np.array(rows, dtype=np.float64)
    spatial = spatial_dark = bright_image = dark_image = None
    if stacks["bright"]:
        if len(stacks["bright"]) > 1:
            notes.append(f"{len(stacks['bright'])} bright stacks; the first is used")
        spatial, bright_image = _stack(stacks["bright"][0].images, checker, desc)
        spatial["exposure_ns"] = stacks["bright"][0].exposure_ns
    if stacks["dark"]:
        if len(stacks["dark"]) > 1:
            notes.append(f"{len(stacks['dark'])} dark stacks; the first is used")
        spatial_dark, dark_image = _stack(stacks["dark"][0].images, checker, desc)
        spatial_dark["exposure_ns"] = stacks["dark"][0].exposure_ns
    return EmvaData(texp_s=arr[:, 1], u_p=arr[:, 0], u_y=arr[:, 2], s2_y=arr[:, 3], u_ydark=arr[:, 4],
                    s2_ydark=arr[:, 5], spatial=spatial, spatial_dark=spatial_dark, bits=desc.bits,
                    shape=(desc.height, desc.width), notes=notes, max_code=arr[:, 6], frac_at_max=arr[:, 7],
                    bright_image=bright_image, dark_image=dark_image)


# -- evaluation -----------------------------------------------------------------------------
def _slope_origin(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.dot(x, y) / np.dot(x, x))


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    slope, intercept = np.polyfit(x, y, 1)
    return float(slope), float(intercept)


def saturation_index(s2_y: np.ndarray) -> int:
    """EMVA 1288 saturation index: the variance maximum, scanning from the brightest step down
    and stopping once two consecutive steps are below the running maximum (so that isolated
    noise peaks at low signal do not count)."""
    best, best_i = -np.inf, 0
    for i in range(len(s2_y) - 1, -1, -1):
        prev = s2_y[abs(i - 1)]
        if s2_y[i] >= best or prev >= best:
            best, best_i = s2_y[i], i
        else:
            break
    return int(best_i)


def _linearity(data: EmvaData, Y: np.ndarray, isat: int, out: dict, unknown: dict, *, photons: bool) -> None:
    """EMVA 1288 linearity error ``LE_min``, ``LE_max`` (%) between 5 and 95 % of saturation, 1/Y weighted,
    into ``out`` (``photons``: photon counts and saturation are known; else None with the reason)."""
    if photons:
        lo = int(np.nonzero(Y >= 0.05 * Y[isat])[0].min())
        hi = int(np.nonzero(Y <= 0.95 * Y[isat])[0].max())
        if hi - lo >= 1:
            xs, ys = data.u_p[lo:hi + 1], Y[lo:hi + 1]
            a, b = np.polyfit(xs, ys, 1, w=1.0 / ys)
            dev = 100.0 * (ys - (a * xs + b)) / (a * xs + b)
            out["LE_min"], out["LE_max"] = float(dev.min()), float(dev.max())
    for k in ("LE_min", "LE_max"):
        if k not in out:
            out[k] = None
            unknown[k] = "the linearity needs photon counts and saturation"


def _spatial_nonuniformity(data: EmvaData, K: float, out: dict, unknown: dict) -> None:
    """EMVA 1288 ``DSNU1288`` (e-, and ``_DN``) and ``PRNU1288`` (%) of the dark and bright stacks, into ``out``."""
    sp, spd = data.spatial, data.spatial_dark
    out["DSNU1288"] = out["DSNU1288_DN"] = out["PRNU1288"] = None
    if spd is None:
        unknown["DSNU1288"] = unknown["PRNU1288"] = "the descriptor has no dark stack (a 'd' step with more than two images)"
    else:
        s2_yd = spd["avg_var"] - spd["var_mean"] / spd["L"]
        if s2_yd >= 0:
            out["DSNU1288_DN"] = math.sqrt(s2_yd)
            out["DSNU1288"] = out["DSNU1288_DN"] / K
        else:
            unknown["DSNU1288"] = "the corrected dark spatial variance is negative (no measurable DSNU)"
            s2_yd = 0.0
        if sp is None:
            unknown["PRNU1288"] = "the descriptor has no bright stack (a 'b' step with more than two images)"
        else:
            s2_y = sp["avg_var"] - sp["var_mean"] / sp["L"]
            signal = sp["avg_mean"] - spd["avg_mean"]
            if signal > 0 and s2_y - s2_yd >= 0:
                out["PRNU1288"] = 100.0 * math.sqrt(s2_y - s2_yd) / signal
            else:
                unknown["PRNU1288"] = "the bright stack's spatial variance is not above the dark one"


def evaluate(data: EmvaData) -> tuple[dict[str, Any], dict[str, str]]:
    """EMVA 1288 linear-model figures of reduced data.

    Returns
    -------
    figures : dict
        ``K`` (DN/e-), ``R`` (DN/p), ``QE`` (fraction), ``sigma_y_dark`` (DN), ``sigma_d``
        (e-), ``u_p_sat``, ``u_e_sat``, ``u_p_min``, ``u_e_min``, ``SNR_max``, ``SNR_max_dB``,
        ``DR``, ``DR_dB``, ``u_I_mean``, ``u_I_var`` (e-/s), ``LE_min``, ``LE_max`` (%),
        ``DSNU1288`` (e-), ``DSNU1288_DN``, ``PRNU1288`` (%), ``black_level_dn``,
        ``index_u_ysat``, ``fit_range`` and the temporal arrays (for plots).
    unknown : dict
        Figure -> reason for every figure that is ``None``.

    Raises
    ------
    CalibrationError
        Fewer than two usable points below 70 % of saturation, or a non-positive gain.
    """
    unknown: dict[str, str] = {}
    Y = data.u_y - data.u_ydark
    V = data.s2_y - data.s2_ydark
    isat = saturation_index(data.s2_y)
    if Y[isat] <= 0:
        raise CalibrationError("EMVA 1288: the brightest usable step has no signal above dark; check the bright images")
    imax = int(np.nonzero(Y <= 0.7 * Y[isat])[0].max())
    sel = slice(0, imax + 1)
    if imax + 1 < 2:
        raise CalibrationError(
            f"EMVA 1288: only {imax + 1} bright pair(s) below 70 % of saturation; the gain needs at least 2"
        )
    K = _slope_origin(Y[sel], V[sel])
    if not (K > 0 and math.isfinite(K)):
        raise CalibrationError(f"EMVA 1288: the photon transfer slope is not positive (K = {K:g} DN/e-)")
    out: dict[str, Any] = {"K": K, "inverse_K": 1.0 / K, "index_u_ysat": isat, "fit_range": [0, imax]}
    saturated = isat < len(Y) - 1 and data.s2_y[-1] < data.s2_y[isat]
    if not saturated:
        unknown["u_p_sat"] = "the variance never falls after its maximum: the data do not reach saturation"
    photons = bool(np.all(data.u_p[sel] > 0) and np.any(data.u_p > 0))
    texp = np.unique(data.texp_s)
    if len(texp) <= 2:
        s2_dark = float(data.s2_ydark[0])
        out["dark_noise_method"] = "single exposure"
    else:
        s2_dark = _line(data.texp_s, data.s2_ydark)[1]
        out["dark_noise_method"] = "intercept of the dark variance against exposure time"
    out["sigma_y_dark_measured"] = math.sqrt(max(s2_dark, 0.0))
    s2_dark = max(s2_dark, _DARK_FLOOR_DN2)
    out["sigma_y_dark"] = math.sqrt(s2_dark)
    out["sigma_d"] = math.sqrt(s2_dark - SIGMA2_Q) / K
    if photons:
        R = _slope_origin(data.u_p[sel], Y[sel])
        out["R"] = R
        out["QE"] = R / K
    else:
        out["R"] = out["QE"] = None
        unknown["QE"] = "the bright steps give no photon counts"
    out["u_e_min"] = out["sigma_y_dark"] / K + 0.5
    out["u_p_min"] = out["u_e_min"] / out["QE"] if out["QE"] else None
    if saturated:
        out["u_y_sat"] = float(data.u_y[isat])
        if photons:
            out["u_p_sat"] = float(data.u_p[isat])
            out["u_e_sat"] = out["QE"] * out["u_p_sat"]
        else:
            out["u_p_sat"] = None
            out["u_e_sat"] = float(Y[isat]) / K
        out["SNR_max"] = math.sqrt(out["u_e_sat"])
        out["SNR_max_dB"] = 20 * math.log10(out["SNR_max"])
        out["DR"] = out["u_e_sat"] / out["u_e_min"]
        out["DR_dB"] = 20 * math.log10(out["DR"])
    else:
        for k in ("u_y_sat", "u_p_sat", "u_e_sat", "SNR_max", "SNR_max_dB", "DR", "DR_dB"):
            out[k] = None
            unknown.setdefault(k, unknown["u_p_sat"])
    # dark current and black level
    if len(texp) > 2:
        slope_m, b0 = _line(data.texp_s, data.u_ydark)
        slope_v, _ = _line(data.texp_s, data.s2_ydark)
        out["u_I_mean"] = slope_m / K
        out["black_level_dn"] = b0
        out["u_I_var"] = slope_v / K**2 if slope_v >= 0 else None
        if slope_v < 0:
            unknown["u_I_var"] = f"the dark variance falls with exposure time (slope {slope_v:g} DN^2/s)"
    else:
        out["u_I_mean"] = out["u_I_var"] = None
        unknown["u_I_mean"] = unknown["u_I_var"] = (
            f"dark pairs at {len(texp)} exposure time(s); the dark current needs more than two")
        out["black_level_dn"] = float(data.u_ydark[np.argmin(data.texp_s)])
    _linearity(data, Y, isat, out, unknown, photons=photons and saturated)
    _spatial_nonuniformity(data, K, out, unknown)
    out["curves"] = {k: getattr(data, k).tolist() for k in ("texp_s", "u_p", "u_y", "s2_y", "u_ydark", "s2_ydark")}
    return out, unknown


def evaluate_descriptor(path: str | os.PathLike) -> tuple[EmvaDescriptor, EmvaData, dict[str, Any], dict[str, str]]:
    """Read, reduce and evaluate an EMVA 1288 data set (see :func:`evaluate`)."""
    desc = read_descriptor(path)
    data = reduce_descriptor(desc)
    figures, unknown = evaluate(data)
    return desc, data, figures, unknown
