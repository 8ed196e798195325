"""Reconstruction with disparity-sheared Gaussian patch models (piecewise-linear estimation).

Why: a patch of a Lambertian surface is, in every view, a translated copy of the centre view's
patch, ``L(v, u, y, x, c) = C(y - dv d, x - du d, c)`` for a disparity ``d`` (pixels per view
step; ``dv, du`` the view's offset from the centre, the convention of :mod:`lfproc.synth`). So
a 4-D patch of ``V x U x P x P x 3`` samples is fixed by a 2-D patch ``x`` of the centre view,
extended by a margin ``R`` (``E = P + 2R`` pixels square, 3 colours) and one disparity:
``L_p = S_d x`` with ``S_d`` a bilinear translation per view. With two shots there are two
measurements per pixel against three colours per pixel: the problem is close to demosaicing,
not to recovering 75 samples per pixel from 2 as a generic dictionary must.

The prior on ``x / s`` (``s`` the patch's mean level, so dark and bright patches share one
model) is a Gaussian mixture (``k`` components, a mean and a full covariance each) learned
from real HDR photographs (:func:`train_patch_model`). For a capture ``y = A_d x + n`` of a
patch (``A_d = Phi_p S_d``, ``n`` Gaussian with the calibrated variances) every pair
(disparity, component) gives the linear MMSE estimate (Wiener filter)
``x = mu + Sigma A^T (A Sigma A^T + N)^-1 (y - A mu)`` and its evidence ``log N(y; A mu,
A Sigma A^T + N)``; the pair of largest evidence wins (the piecewise-linear estimator of Yu,
Sapiro and Mallat, IEEE TIP 2012, with the disparity as part of the model, as the sheared
atoms of Vagharshakyan et al., TPAMI 2018). The systems are ``m x m`` (``m`` measurements of a
patch, 128 for two 8 x 8 shots), solved by batched Cholesky factorisations in the whitened
form ``W K W + I`` (``W = diag(w)``), which keeps saturated measurements out exactly.

Saturated measurements are lower bounds, not missing data (``saturation="bound"``): one with
unsaturated neighbours of its colour above its bound takes their level as a weak datum (on the
bright side of an edge: :func:`_impute_saturated`); after a first estimate, the others whose
prediction falls below their saturation level join the data at that level (with their
photon-noise weight) and the patch is solved again, so lights are not shrunk below what the
sensor saw.

Components. The shipped model has four (hard EM from contrast quantiles, :func:`train_patch_model`):
patches of different contrast get different covariances, and the evidence of the right one ranks the
disparities better. With ``search="staged"`` every (disparity, component) is tried at scale 1 on the
search grid only; the disparity is chosen on the pooled evidence, then the component the same way at that
disparity, and the estimate grid tries the scales alone. Measured on the tune scenes at 96 x 128 (3 seeds,
2 random shots, mean PU21-PSNR): one component 26.95 dB; four, every (component, scale) on the estimate grid
too 27.95 (2.0x the time); four, staged as above 27.77 (1.5x); three 27.73; six 27.61; four with the
disparity searched under their moment-matched single Gaussian 26.90 (so the gain is in the disparity search,
not in the estimate's component). Lytro size, tune: 36.74 -> 37.68 dB (every pair on both grids 37.75);
the default command-line path 39.3 -> 52.3 s (every pair: 77.2 s).

Oriented components (``train_patch_model(orientations=...)``; measured, not the default). Contrast alone gives
components that differ in how much a patch varies, not in which direction: a window's mullions and a curtain's folds
(city-interior's 10-100 decade, its worst, 0.24 stops: the bright samples lose 10-20 % to their neighbours, the
energy of the neighbourhood kept within 3 %) are blurred across. The piecewise-linear estimator of Yu, Sapiro and
Mallat starts its components from oriented edges; here some components start from the coherent patches of the upper
half of contrast by their edge's orientation (:func:`_initial_labels`), then the same hard EM. Tune scenes, 96 x 128,
seeds 0-2, 2 random shots (``benchmarks/reconstruct_realistic.py --set tune --size 96 128 --seeds 3``, a model
file in ``--options``): four contrast components (the shipped model) 28.03 dB, eight 27.93, four and four oriented
28.18 (every scene higher), four and eight oriented (coherence 0.3) 28.22, four and four without the EM 28.10: the
gain is the orientation, not the count. At Lytro size it did not hold on the tune scenes: 37.95 -> 37.92 dB
(desk-cannon 25.98 -> 25.89, sunset-carrots 52.96 -> 52.92, forest-stilllife 34.91 -> 34.95); the test scenes
41.89 -> 42.07 (city-interior 54.53 -> 54.88, its worst decade 0.24 -> 0.23; courtyard-candle 32.94 -> 33.07;
night-studio 48.72 -> 49.03; sunrise-desk 31.35 -> 31.30) and at 96 x 128 (seeds 0-2, random / row / block) 35.72 /
35.55 / 35.65 -> 35.69 / 35.61 / 35.65. The tune scenes decide, so the shipped model keeps its four contrast
components (``python benchmarks/train_patch_model.py`` remakes it, bit for bit; ``--components 8 --orientations 4``
the oriented one).

Two grids. The disparity is searched on patches every ``search_stride`` pixels (default 4),
its evidence pooled over neighbouring patches; the estimates are made every ``stride`` pixels
(default 2) at the disparity of the nearest search patch, with the component and scale of
largest evidence there. With a mask of period 4 a stride of 2 overlaps every pixel with
patches of four mask phases, whose errors differ and average out; a stride equal to the period
prints the mask's period on the result (a grid over smooth regions, measured on the tune
scenes: detail ratio 1.23 at stride 4, 0.99 at stride 2).

Overlapping patches are combined per pixel with weights ``window / ((t^2 + n^2) max(1, chi2))``: a
centre-weighted window, ``t`` the larger of the patch's level and the brightest pixel of its
centre-view estimate (an error relative to the patch's brightest part: a patch across the edge
of a light has a low mean but the light's error), ``n`` the radiance one of its measurements
resolves (the median of ``1 / (w r)``: without it, patches estimated near 0 in a region at the
noise floor outweigh their neighbours and print dark blobs), and the patch's reduced chi-square
(a patch that fits its data badly, an occlusion edge, counts less).

Refinement (consensus). The patches are estimated independently, each from its own ``8 x 8`` pixels of
measurements, and their average is not one Lambertian light field: overlapping patches disagree,
most where the views translate (at disparity 1 an ``E x E`` centre patch is seen through ``P x P``
pixels of coded sums). A second pass re-estimates every patch from the first light field's samples
in its window, all views, under the hypothesis it chose (:func:`_refine`): one step of expected
patch log-likelihood (EPLL, Zoran and Weiss, ICCV 2011) with the sheared model, which makes the
views of each patch agree. Pixels a shot saw saturated keep the larger of the two estimates: the
prior pulls lights down. Measured on 128 x 160 crops of the three tune scenes (PU21-PSNR / detail
ratio / energy of the brightest 1 %, means): 29.00 dB / 0.92 / 0.951 without the pass, 29.33 / 0.78
/ 0.936 with it everywhere, 29.13 / 0.82 / 0.950 with the saturated pixels' larger estimate. Radiance
is positive: the pass keeps each sample as the mean of its Gaussian estimate truncated at 0
(:func:`._batched.truncated_mean`), not the estimate clipped at 0, so no sample comes back as exactly 0
(``POSITIVE_STD``).

Small lights. A Gaussian patch prior cannot hold a light of a few pixels: it explains the coded
sums by a blob, at whatever disparity fits (at disparity 0 any coded sums are fitted pixel by pixel),
and the light's energy spreads over its neighbours. Measured on the 2 x 2 pixel lamp of the test
scene city-interior (a 64 x 64 crop, disparity 1): 53 % of its energy kept at the default exposure,
20 % when nothing saturates. So a patch with a measurement brighter than ``LIGHTS_BRIGHT`` times its
level (a saturated one at its bound) by ``LIGHTS_SIGNIFICANCE`` of its standard deviations is also
fitted as the Gaussian plus a sparse layer of point sources
(:func:`_point_sources`: each pixel a source of its own variance, re-estimated from the data, as in
sparse Bayesian learning, Tipping 2001; Wipf and Rao 2004), at every other disparity of the search,
and the fit of largest evidence replaces the Gaussian one when its evidence is larger. The sources
bypass the refinement pass (its Gaussian prior would spread them again). Measured: the lamp keeps
58 % (51 % when nothing saturates); the tune scenes at 96 x 128 (means): PU21-PSNR 25.47 -> 25.82 dB,
detail ratio 0.84 -> 0.77, energy of the brightest 1 % (smallest) 0.59 -> 0.66. Settings chosen on
the tune scenes: without the significance, the noise of dark patches triggered the fit (city-interior
at Lytro size took twice the time, for +0.05 dB at 96 x 128); a bad fit (chi-square > 4) as a
further trigger gained nothing for 10 % more time; every disparity instead of every other +0.03 dB
for 40 % more; any saturated measurement as a trigger
+0.15 dB at 96 x 128 but -0.2 dB on the layered scene of tests/recon/test_reconstruct_gmm.py (bright
regions are saturated at the high ISOs without being lights). Cost at Lytro size (quiet machine):
city-interior 53.9 s without, 59.3 s with (44.29 -> 44.76 dB, detail ratio 1.18 -> 1.00).

Lights refitted against the measurements (:mod:`lfproc.recon._lights`, ``LIGHTS_REFIT``). The point sources
keep a light's energy near it, but the overlapping patches still blur it (the lamp above: the centre view peaks
at 0.35-0.40 of the truth, the energy spread over 4 x 4 pixels). After the refinement, each small light of the
centre view (8 times the median of its 9 x 9 neighbourhood) is refitted in a window of at most 20 pixels (a
longer light: several windows along it) from that window's own measurements: the centre view at one disparity as
a background near the estimate (or near the neighbourhood's median, whichever prior the evidence favours) plus a
non-negative light layer of one colour on the light's pixels (non-negative least squares), accepted when it
halves the chi-square. Measured on the tune scenes at Lytro size: 35.13 -> 36.67 dB, detail ratio 0.87 -> 0.60,
the lamp of city-interior's crop 58 % -> 90 % of its energy on its pixels (the first version).

A gain where the result contradicts the measurements (:mod:`lfproc.recon._gain`, ``MEASURED_GAIN``, stop 44). The
patches across a dark region beside a bright one average the bright side into it, and the refit fits lights only: the
test scene courtyard-candle's doorway came back 4.3 times the truth where its measurements said otherwise. Last, where
the local chi-square still exceeds 4, each scene point is scaled per colour by the ratio of measured to predicted
local sums where the views see it. Refit-stage dumps (Lytro size, 2 random shots): courtyard-candle 32.94 -> 33.59 dB,
the doorway 4.31 -> 1.21 times the truth; the tune scenes desk-cannon 25.98 -> 26.33, forest-stilllife 34.87 -> 35.13.

A floor under the weights (``READ_FLOOR_E``). A measurement's weight is ``1 / std`` under the sensor's noise
model: photon noise of the local signal, read noise, quantisation. Without read noise (``paper-none``) a dark
measurement at a high ISO is then known to a fraction of an electron (its quantisation step), while its photon
count, of mean near one electron, is 0, 1 or 2: the Gaussian model claims more than such a count holds, and the
fits follow it (the noise-free captures of the test scenes scored below the low-noise ones, night-studio by
0.07-0.08 dB at both seeds measured). The weights assume at least one electron of read noise, the electron of
:func:`lfproc.camera.capture.noise_floor` (the signal whose photon noise equals it); a profile with more read
noise keeps its own weights bit for bit (``paper-low`` 1.1 e-, ``-medium`` 2.0, ``-high`` 2.8). Measured:
``benchmarks/reconstruct_realistic.py --method gmm``, Lytro size, 2 random noise-free shots (``"2 random none"``),
the test scenes' mean PU21-PSNR 41.71 -> 41.80 dB at seed index 0 (city-interior 54.14 -> 54.39, night-studio
48.30 -> 48.39, the others within 0.01), 42.06 -> 42.13 at index 1 (night-studio 48.73 -> 48.86); the low-noise
captures, unchanged, 41.76 and 41.83 (night-studio 48.38 and 48.80). The tune scenes 37.94 -> 38.00; two electrons
instead of one, on two of them: sunset-carrots 53.61 against 53.79, desk-cannon 25.94 both.

The mask must be periodic (``mask_period``): every patch of a phase then shares ``A_d`` and
``A_d Sigma A_d^T`` (computed once per phase, disparity and component).
"""

from __future__ import annotations

import math
import os
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import NamedTuple
from pathlib import Path

import numpy as np
from scipy import sparse
from threadpoolctl import threadpool_limits

from .._shared.validation import check_choice
from .._shared.progress import progress
from .._version import __version__
from ..errors import FileFormatError, InputError, MissingFileError, ShapeError, option_name
from ..lightfield import LightField
from .._shared.parallel import available_cpus
from ._batched import back_substitute, truncated_mean, whitened_system
from ._gain import measured_gain
from ._lights import refit_lights
from ._shear import shear_matrix
from ._reconstruct import _gather, _int_option
from .. import _untrusted as ut
from .._shared.patches import patch_grid
from .._shared.random import check_random_state
from ..camera.capture import READ_FLOOR_E, Capture, load_capture, observations
from ..camera.projection import patch_operators, transmittance_map
from ..io._atomic import atomic_file

__all__ = ["PatchModel", "train_patch_model", "load_patch_model", "reconstruct_gmm", "gmm_fits", "shear_matrix",
           "DEFAULT_DISPARITIES", "SATURATION_MODES"]

#: Disparities tried by default (pixels per view step): a lenslet camera's range, in quarter pixels.
DEFAULT_DISPARITIES = (-1.0, -0.75, -0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0)
SATURATION_MODES = ("bound", "ignore")
SEARCHES = ("joint", "staged")
#: Multipliers of the model's covariances tried per patch (a Gaussian scale mixture: smooth to high-contrast patches).
DEFAULT_SCALES = (0.1, 1.0, 10.0)
#: Relative standard deviation of the first estimate in the refinement pass (:func:`_refine`; 0: no refinement).
#: Chosen on crops of the tune scenes (0.1, 0.3, 0.5, 1, 3): 1 gave the best PU21-PSNR and detail ratio.
REFINE_SIGMA = 1.0
#: Bayer weights of the patch level ``s``: the mean of R, G, G, B over the patch's P x P pixels.
_LEVEL_WEIGHTS = np.array([0.25, 0.5, 0.25])
_DATA = Path(__file__).resolve().parent / "data"


@dataclass(frozen=True, eq=False)
class PatchModel:
    """A Gaussian mixture over extended centre-view patches ``x / s`` (module notes).

    Parameters
    ----------
    means : ndarray of shape (k, E * E * 3)
    covariances : ndarray of shape (k, E * E * 3, E * E * 3)
    weights : ndarray of shape (k,)
        Mixture weights (sum 1).
    patch : int
        ``P``: the reconstructed patch (pixels square).
    margin : int
        ``R``: pixels around the patch the views can reach (``E = P + 2 R``).
    attrs : dict
        Provenance (lfproc version, training data, parameters).
    """

    means: np.ndarray
    covariances: np.ndarray
    weights: np.ndarray
    patch: int
    margin: int
    attrs: dict = field(default_factory=dict)

    def __post_init__(self):
        e = self.patch + 2 * self.margin
        n2 = e * e * 3
        k = len(self.weights)
        if self.means.shape != (k, n2) or self.covariances.shape != (k, n2, n2):
            raise ShapeError(f"patch model: expected means ({k}, {n2}) and covariances ({k}, {n2}, {n2}) for "
                             f"patches of {self.patch} pixels with a margin of {self.margin}, got "
                             f"{self.means.shape} and {self.covariances.shape}")
        for name in ("means", "covariances", "weights"):
            if not np.isfinite(getattr(self, name)).all():
                raise FileFormatError(f"patch model: {name} hold NaN or Inf")
        if (self.weights <= 0).any():
            raise FileFormatError("patch model: mixture weights must be positive")
        for j, cov in enumerate(self.covariances):
            if not np.allclose(cov, cov.T, rtol=1e-5, atol=1e-8 * max(float(np.abs(cov).max()), 1e-30)):
                raise FileFormatError(f"patch model: covariance {j} is not symmetric")
            try:
                np.linalg.cholesky(cov)
            except np.linalg.LinAlgError:
                raise FileFormatError(f"patch model: covariance {j} is not positive definite") from None

    def __repr__(self) -> str:
        return (f"PatchModel(components={len(self.weights)}, patch={self.patch}, margin={self.margin}, "
                f"source={self.attrs.get('source', '?')!r})")

    @property
    def components(self) -> int:
        return len(self.weights)

    def save(self, path: str | os.PathLike, *, force: bool = False) -> Path:
        """Write the model as ``.npz`` (float32 arrays and a JSON record of its provenance)."""
        import json

        path = Path(path)
        with atomic_file(path, force=force) as tmp:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, means=self.means.astype(np.float32), covariances=self.covariances.astype(np.float32),
                                    weights=self.weights.astype(np.float64),
                                    header=np.array(json.dumps({"format": "lfproc-patch-model", "version": 1,
                                                                "patch": self.patch, "margin": self.margin,
                                                                "attrs": self.attrs})))
        return path


def load_patch_model(model: str | os.PathLike | PatchModel = "default") -> PatchModel:
    """Read a patch model: ``"default"`` (the shipped one) or a file written by :meth:`PatchModel.save`.

    The file is untrusted: its header is checked (types, ranges) and every array's shape and
    dtype are checked against it before any data is read (:mod:`lfproc._untrusted`).

    Parameters
    ----------
    model : str, path-like or PatchModel, default "default"
        ``"default"``, a path, or a :class:`PatchModel` (returned as is).

    Returns
    -------
    PatchModel

    Raises
    ------
    MissingFileError
        No such file.
    FileFormatError
        Not a patch model, a header of the wrong types or out of range, arrays of other shapes
        or dtypes, NaN/Inf, covariances that are not symmetric positive definite.
    """
    if isinstance(model, PatchModel):
        return model
    if not isinstance(model, (str, os.PathLike)):
        raise InputError(f"patch model: expected 'default', a path or a PatchModel, got {type(model).__name__}")
    path = _DATA / "gaussian_patch_model.npz" if str(model) == "default" else Path(model)
    if not path.is_file():
        raise MissingFileError(f"{path}: patch model file not found")
    text = ut.read_npz(path, names=["header"], source=path, max_bytes=1 << 20)["header"]
    if text.dtype.kind != "U" or text.ndim != 0:
        raise FileFormatError(f"{path}: not an lfproc patch model (header of dtype {text.dtype}, shape {text.shape})")
    header = ut.Node(ut.parse_json(str(text), source=path, what="header"), source=path)
    if not header.is_dict() or header.get("format") is None or header["format"].value != "lfproc-patch-model":
        raise FileFormatError(f"{path}: not an lfproc patch model (no header format 'lfproc-patch-model')")
    patch = header["patch"].as_int(low=2, high=64)
    margin = header["margin"].as_int(low=0, high=16)
    attrs = header["attrs"].as_dict() if header.has("attrs") else {}
    n2 = (patch + 2 * margin) ** 2 * 3
    def check(name, shape, dtype):
        if dtype.kind != "f":
            raise FileFormatError(f"{path}: array {name!r}: expected floating point, found {dtype}")
        want = {"weights": 1, "means": 2, "covariances": 3}[name]
        if len(shape) != want or not 1 <= shape[0] <= 64 or any(d != n2 for d in shape[1:]):
            raise FileFormatError(f"{path}: array {name!r}: expected {want} dimensions, 1..64 components of "
                                  f"{n2} samples (patch {patch}, margin {margin}), found shape {shape}")

    arrays = ut.read_npz(path, names=["means", "covariances", "weights"], source=path, check=check)
    arrays = {name: np.asarray(value, dtype=np.float64) for name, value in arrays.items()}
    try:
        return PatchModel(arrays["means"], arrays["covariances"], arrays["weights"], patch, margin,
                          attrs=dict(attrs, path=str(path)))
    except (ShapeError, FileFormatError) as exc:
        raise FileFormatError(f"{path}: {exc}") from None


def _level(patches: np.ndarray, patch: int, margin: int) -> np.ndarray:
    """``s``: the Bayer-weighted mean of the central ``P x P`` pixels of extended patches ``(N, E E 3)``."""
    e = patch + 2 * margin
    w = np.zeros((e, e, 3))
    w[margin:margin + patch, margin:margin + patch] = _LEVEL_WEIGHTS / (patch * patch)
    return patches @ w.reshape(-1)


def train_patch_model(images, *, patch: int = 8, margin: int = 2, components: int = 1, orientations: int = 0,
                      n_patches: int = 60000, max_iter: int = 5, clip: float = 50.0, random_state=0) -> PatchModel:
    """Learn a :class:`PatchModel` from linear HDR images (e.g. real HDR photographs).

    Patches of ``E = patch + 2 margin`` pixels are drawn uniformly (the same number from each
    image), divided by their level ``s`` (module notes; patches of level below ``1e-6`` of the
    image mean are skipped) and clipped at ``clip`` (a light in a dark patch would otherwise
    dominate the covariances). One component: the sample mean and covariance. More: hard-EM
    (assign each patch to its most likely component, refit), started from contrast quantiles;
    with ``orientations``, that many of the components start from the edges: the patches of the
    upper half of contrast whose structure tensor is coherent (:data:`ORIENT_COHERENCE`), by
    their edge's orientation (module notes: oriented components). Every covariance gets a ridge
    of ``1e-3`` of its mean variance.

    Parameters
    ----------
    images : sequence of ndarray (H, W, 3)
        Linear radiance, each larger than ``E`` pixels.
    patch, margin, components, n_patches, max_iter, clip
        See above.
    orientations : int, default 0
        Components (of ``components``) started from oriented edges, 0 .. ``components - 2``.
    random_state : None, int or Generator

    Returns
    -------
    PatchModel

    Raises
    ------
    ShapeError
        A training image that is not ``(H, W, 3)`` larger than ``E`` pixels.
    InputError
        ``orientations`` outside ``0 .. components - 2``.
    """
    rng = check_random_state(random_state)
    orientations = _int_option("orientations", orientations, low=0)
    if orientations and orientations > components - 2:
        raise InputError(f"orientations: expected 0 .. components - 2 = {components - 2}, got {orientations}")
    e = patch + 2 * margin
    per = n_patches // max(len(images), 1) + 1
    rows = []
    for img in images:
        img = np.asarray(img, dtype=np.float64)
        if img.ndim != 3 or img.shape[2] != 3 or min(img.shape[:2]) <= e:
            raise ShapeError(f"training images: expected (H, W, 3) larger than {e} pixels, got {img.shape}")
        ys = rng.integers(0, img.shape[0] - e, 2 * per)
        xs = rng.integers(0, img.shape[1] - e, 2 * per)
        ii = np.arange(e)
        pats = img[ys[:, None, None] + ii[None, :, None], xs[:, None, None] + ii[None, None, :]].reshape(len(ys), -1)
        s = _level(pats, patch, margin)
        ok = s > 1e-6 * max(float(img.mean()), 1e-30)
        rows.append(np.minimum(pats[ok][:per] / s[ok][:per, None], clip))
    x = np.concatenate(rows)[:n_patches]
    n2 = x.shape[1]

    def fit(sel):
        mu = sel.mean(axis=0)
        cov = np.cov(sel, rowvar=False)
        cov += 1e-3 * np.trace(cov) / n2 * np.eye(n2)
        return mu, cov

    if components == 1:
        mu, cov = fit(x)
        means, covs, weights = mu[None], cov[None], np.ones(1)
    else:
        labels = _initial_labels(x, e, components - orientations, orientations)
        for _ in range(max_iter):
            parts = [fit(x[labels == j]) if (labels == j).sum() > n2 else fit(x) for j in range(components)]
            weights = np.array([max((labels == j).mean(), 1e-3) for j in range(components)])
            weights /= weights.sum()
            ll = np.empty((len(x), components))
            for j, (mu, cov) in enumerate(parts):
                chol = np.linalg.cholesky(cov)
                z = np.linalg.solve(chol, (x - mu).T)
                ll[:, j] = -0.5 * (z * z).sum(axis=0) - np.log(np.diag(chol)).sum() + math.log(weights[j])
            labels = ll.argmax(axis=1)
        means = np.stack([p[0] for p in parts])
        covs = np.stack([p[1] for p in parts])
    return PatchModel(means, covs, weights, patch, margin,
                      attrs={"lfproc_version": __version__, "patches": int(len(x)), "images": len(images),
                             "components": components, "orientations": orientations, "clip": clip,
                             "max_iter": max_iter,
                             "random_state": random_state if isinstance(random_state, (int, type(None))) else "generator"})


#: Oriented components (:func:`train_patch_model`): a patch starts in one when its structure tensor's coherence
#: ``(l1 - l2) / (l1 + l2)`` (luminance gradients summed over the patch) is above this.
ORIENT_COHERENCE = 0.5


def _initial_labels(x: np.ndarray, e: int, n_contrast: int, n_orient: int) -> np.ndarray:
    """The hard-EM start of :func:`train_patch_model`: ``n_contrast`` contrast quantiles (log standard deviation),
    then the coherent patches of the upper half of contrast moved to ``n_orient`` components by their edge's
    orientation (bins of ``180 / n_orient`` degrees, the first centred on a horizontal edge)."""
    contrast = np.log(x.std(axis=1) + 1e-6)
    labels = np.searchsorted(np.quantile(contrast, np.linspace(0, 1, n_contrast + 1)[1:-1]), contrast)
    if not n_orient:
        return labels
    lum = x.reshape(len(x), e, e, 3) @ _LEVEL_WEIGHTS
    gy, gx = np.gradient(lum, axis=(1, 2))
    jxx, jyy, jxy = (gx * gx).sum(axis=(1, 2)), (gy * gy).sum(axis=(1, 2)), (gx * gy).sum(axis=(1, 2))
    angle = 0.5 * np.arctan2(2 * jxy, jxx - jyy)  # of the gradient, (-pi/2, pi/2]
    coherence = np.hypot(jxx - jyy, 2 * jxy) / np.maximum(jxx + jyy, 1e-30)
    bins = np.floor((angle / math.pi + 0.5) * n_orient + 0.5).astype(np.intp) % n_orient
    edge = (labels >= n_contrast // 2) & (coherence > ORIENT_COHERENCE)
    return np.where(edge, n_contrast + bins, labels)


def gmm_fits(capture) -> bool:
    """Whether :func:`reconstruct_gmm` can reconstruct ``capture``: its mask is random and periodic (the
    default of :func:`lfproc.camera.simulate_capture`). ``lfproc reconstruct --method auto`` chooses gmm then.

    Parameters
    ----------
    capture : Capture

    Returns
    -------
    bool
    """
    return capture.mask.kind == "random" and capture.mask.period is not None


def _check_capture(capture, model: PatchModel, stride: int, name: str = "stride"):
    if not gmm_fits(capture):
        raise InputError("reconstruct_gmm: needs a capture with a periodic random mask (simulate with "
                         f"{option_name('mask_period', '--mask-period')} 4, the default); this capture's mask is {capture.mask.kind!r} with period {capture.mask.period}")
    h, w = capture.size
    if model.patch > min(h, w):
        raise ShapeError(f"patch model: patches of {model.patch} pixels do not fit the capture's sensor of {h} x {w}")
    if not 1 <= stride <= model.patch:
        raise InputError(f"{name}: expected 1..{model.patch} (the model's patch size), got {stride}")


def reconstruct_gmm(capture, model="default", *, stride: int = 2, search_stride: int | None = None,
                    disparities=DEFAULT_DISPARITIES,
                    scales=DEFAULT_SCALES, pool_radius: int = 1, search: str = "staged", saturation: str = "bound",
                    chunk: int = 256, threads: int | None = None, progress_bar: bool | None = None) -> LightField:
    """Reconstruct the HDR light field of a capture with a disparity-sheared Gaussian patch model.

    Parameters
    ----------
    capture : Capture or path of a capture file
        With a periodic random mask (``mask_period``).
    model : PatchModel, ``"default"`` or path, default "default"
        The patch prior (:func:`train_patch_model`); ``"default"`` is the shipped one.
    stride : int, default 2
        Spacing of the estimated patches, 1 .. the patch (2 for a period-4 mask: module notes).
    search_stride : int, optional
        Spacing of the disparity-search patches (default: half the patch).
    disparities : sequence of float, default DEFAULT_DISPARITIES
        Disparities tried per patch (pixels per view step), within the model's margin.
    scales : sequence of float, default DEFAULT_SCALES
        Multipliers of the chosen component's covariance tried per patch; ``(1,)``: none.
    pool_radius : int, default 1
        Disparity evidence summed over ``(2 r + 1)^2`` neighbouring patches (0: each alone).
    search : {"joint", "staged"}, default "staged"
        Every (disparity, component, scale) per patch, or the disparity and the component at scale 1
        on the search grid first and the other scales only there (module notes: components).
    saturation : {"bound", "ignore"}, default "bound"
        Use saturated measurements as lower bounds (module notes) or leave them out.
    chunk : int, default 256
        Patches solved at once (memory: about ``chunk * m^2 * 16`` bytes per thread).
    threads : int, optional
        Chunks (and the lights refit's windows, :mod:`._lights`) solved at once (default: the CPUs); the same output.
    progress_bar : bool, optional
        Show progress (None: when stderr is a terminal).

    Returns
    -------
    LightField
        ``(V, U, H, W, 3)``, light-field units (or e-/s); ``attrs["reconstruction"]``: settings, figures.

    Raises
    ------
    InputError
        No periodic random mask, a bad stride, disparities beyond the margin.
    ShapeError
        The model's patch does not fit the capture.

    Examples
    --------
    >>> from lfproc import evaluate, simulate_capture
    >>> from lfproc.recon import reconstruct_gmm
    >>> from lfproc.synth import synthesize
    >>> truth = synthesize("window", size=(24, 24), views=5, random_state=0)
    >>> result = reconstruct_gmm(simulate_capture(truth, shots=2, mask_period=4, random_state=0), progress_bar=False)
    >>> result.shape, bool(10 < evaluate(result, truth)["pu21_psnr_db"] < 40)  # PU21-PSNR in dB
    ((5, 5, 24, 24, 3), True)
    """
    started = time.perf_counter()
    if isinstance(capture, (str, os.PathLike)):
        capture = load_capture(capture)
    if not isinstance(capture, Capture):
        raise InputError(f"reconstruct_gmm: expected a Capture or a capture file, got {type(capture).__name__}")
    model = load_patch_model(model)
    opt = _checked_options(capture, model, stride=stride, search_stride=search_stride, disparities=disparities,
                           scales=scales, pool_radius=pool_radius, search=search, saturation=saturation, chunk=chunk,
                           threads=threads)
    nv, nu = capture.views
    p, scales, disparities = model.patch, opt["scales"], opt["disparities"]
    # S_d (V U P P 3, E E 3): at most 4 non-zeros a row (bilinear), so sparse
    shears_sparse = [sparse.csr_matrix(np.kron(shear_matrix((nv, nu), p, model.margin, d), np.eye(3)))
                     for d in disparities]
    data = _measurements(capture, saturation)
    g = _Grids(capture, p, opt["stride"], opt["search_stride"])
    win = np.outer(*2 * [np.sin(np.pi * ((np.arange(p) + 0.5) / p)) ** 2 + 1e-3])  # sin^2 window of the patch
    bar = progress(total=len(g.gt) + len(g.ct), desc="reconstruct (gmm)", unit="patch",
                   disable=None if progress_bar is None else not progress_bar)
    log_pi = np.log(model.weights)
    n_s = len(scales)
    scores = np.full((len(g.ct), len(disparities) * model.components * n_s), -np.inf)
    # "staged": the disparity at the scale nearest the model's own (1) only
    first = [int(np.argmin(np.abs(np.log(scales))))] if search == "staged" else list(range(n_s))
    cjobs, jobs = _jobs(g.cphase, opt["chunk"]), _jobs(g.phase, opt["chunk"])

    try:
        with threadpool_limits(1), ThreadPoolExecutor(max_workers=opt["threads"]) as pool:
            keys = np.unique(g.ops.index)
            phases = dict(zip(keys, pool.map(lambda ph: _phase_matrices(g.ops, ph, shears_sparse, model), keys)))
            # pass 1, search grid: the evidence of every hypothesis (disparity, component, scale)
            for (ph, sel), out in zip(cjobs, pool.map(lambda j: _evidence(
                    data.T, data.W, g.ct[j[1]], g.cl[j[1]], p, phases[j[0]], log_pi, scales, first), cjobs)):
                scores[sel] = out
                bar.update(len(sel))
            chosen_d = _chosen_disparity(scores, g, len(disparities), opt["pool_radius"])
            chosen_k = (_chosen_component(scores, g, len(disparities), model.components, opt["pool_radius"])
                        if search == "staged" and model.components > 1 else None)  # module notes: components

            def solve(job):  # pass 2, estimate grid: the component and scale of largest evidence at that disparity
                ph, sel = job
                norm = _normalised(data.T, data.W, g.gt[sel], g.gl[sel], p, phases[ph]["rowsum"])
                chosen, alpha = _best_at_disparity(norm[0], norm[1], phases[ph], log_pi, scales, chosen_d[sel],
                                                   None if chosen_k is None else chosen_k[sel])
                est = _estimate(data, g.gt[sel], g.gl[sel], p, phases[ph], chosen, shears_sparse, model, (nv, nu),
                                scales, alpha=alpha, norm=norm)
                return _prepared(est, g.gt[sel], g.gl[sel], win, capture.size[1], ("patches", "sources"))

            acc, lights, info = _combined(jobs, _in_order(pool, solve, jobs), g, (nv, nu, *capture.size, 3), bar)
            if REFINE_SIGMA:
                acc = _refine(acc - lights, g.gt, g.gl, info, model, shears_sparse, scales, win, pool, opt["chunk"],
                              data.saturated.any(axis=0)) + lights
            acc, refit, gain = _against_measurements(acc, data, capture, disparities, model.margin, pool,
                                                     opt["threads"])
    finally:
        bar.close()
    record = {"lfproc_version": __version__, "method": "gmm", "model": repr(model), "model_attrs": model.attrs,
              **{k: opt[k] for k in ("stride", "search_stride", "disparities", "scales", "pool_radius")},
              "search": search, "saturation": saturation, "refine_sigma": REFINE_SIGMA, "positive_std": POSITIVE_STD,
              "lights": LIGHTS, "lights_refit": refit, "measured_gain": gain,
              "disparity_counts": np.bincount(chosen_d, minlength=len(disparities)).tolist(), "patches": int(len(g.gt))}
    return _result(acc, capture, record, started)


def _against_measurements(acc, data, capture, disparities, margin, pool, threads):
    """The small lights refitted against the measurements themselves (:mod:`lfproc.recon._lights`), then a gain where
    the result still contradicts them (:mod:`lfproc.recon._gain`), each when on; the light field and their records."""
    refit, gain = {"windows": 0, "refitted": 0}, {"iterations": 0, "pixels": []}
    if LIGHTS_REFIT:
        acc, refit = refit_lights(acc, *data.raw, capture, disparities, margin, pool, threads)
    if MEASURED_GAIN:
        acc, gain = measured_gain(acc, *data.raw, capture, disparities)
    return acc, refit, gain


def _combined(jobs, estimates, g, shape, bar):
    """The first light field: the patch estimates added in the jobs' fixed order (the output does not depend on the
    threads), divided by their weights; the point sources' share of it (module notes: small lights); and each
    patch's hypothesis, weight and noise (for :func:`_refine`)."""
    acc, lights = _Sums(shape), _Sums(shape)
    hyp, weight, noise = np.zeros((len(g.gt), 3), np.intp), np.zeros(len(g.gt)), np.zeros(len(g.gt))
    for (_, sel), est in zip(jobs, estimates):
        acc.add(est)
        if "sources_weighted" in est:
            lights.add(est, "sources", weigh=False)  # divided by the patches' weights
        hyp[sel], weight[sel], noise[sel] = est["hypothesis"], est["weight"], est["noise"]
        bar.update(len(sel))
    lights = lights.result(acc.weights)
    return acc.result(), np.maximum(lights, 0.0, out=lights), (hyp, weight, noise)


def _checked_options(capture, model, *, stride, search_stride, disparities, scales, pool_radius, search, saturation,
                     chunk, threads) -> dict:
    """The options of :func:`reconstruct_gmm`, checked (one line naming the option) and normalised."""
    check_choice("saturation", saturation, SATURATION_MODES)
    check_choice("search", search, SEARCHES)
    out = {"threads": _int_option("threads", available_cpus() if threads is None else threads),
           "chunk": _int_option("chunk", chunk), "stride": _int_option("stride", stride),
           "search_stride": _int_option("search_stride", model.patch // 2 if search_stride is None else search_stride),
           "pool_radius": _int_option("pool_radius", pool_radius, low=0)}
    _check_capture(capture, model, out["stride"])
    _check_capture(capture, model, out["search_stride"], name="search_stride")
    try:
        out["disparities"] = [float(d) for d in disparities]
    except (TypeError, ValueError):
        raise InputError(f"disparities: expected numbers, got {disparities!r}") from None
    if not out["disparities"] or not all(math.isfinite(d) for d in out["disparities"]):
        raise InputError(f"disparities: expected at least one finite number, got {disparities!r}")
    try:
        out["scales"] = sorted({float(v) for v in scales})
    except (TypeError, ValueError):
        raise InputError(f"scales: expected positive numbers, got {scales!r}") from None
    if not out["scales"] or not all(math.isfinite(v) and v > 0 for v in out["scales"]):
        raise InputError(f"scales: expected positive numbers, got {scales!r}")
    return out


class _Data(NamedTuple):
    """The measurements of a capture as :func:`reconstruct_gmm` uses them, ``(S, H, W)`` each."""

    T: np.ndarray  #: calibrated radiance (e-/s)
    W: np.ndarray  #: weights 1/std, 0 where unusable
    W_sat: np.ndarray  #: weights of saturated measurements used as bounds, 0 elsewhere
    saturated: np.ndarray  #: saturated measurements (bounds or imputed), as 1.0, 0.0 elsewhere
    raw: tuple  #: (T, W, W_sat) before the imputation (saturated measurements as bounds only; :mod:`._lights`)


def _measurements(capture, saturation: str) -> _Data:
    """The observations (local photon-noise signal), saturated ones imputed or kept as bounds (module notes)."""
    # READ_FLOOR_E (lfproc.camera.capture, both methods): module notes, "A floor under the weights"
    obs = observations(capture, variance_from="local", read_floor_e=READ_FLOOR_E)
    T = np.asarray(obs.radiance, np.float64)
    W = np.asarray(obs.weight, np.float64)
    var = np.asarray(obs.variance, np.float64)
    if not (W > 0).any():
        raise InputError("capture: every measurement has weight zero (all saturated or black-clipped); nothing to "
                         "reconstruct from")
    sat = np.asarray(obs.saturated) & (saturation == "bound")
    W_sat = np.where(sat, 1.0 / np.sqrt(np.maximum(var, 1e-30)), 0.0)
    raw = (T, W, W_sat)
    if saturation == "bound":
        r = transmittance_map(capture.mask, views=capture.views, cfa_pattern=capture.cfa_pattern, size=capture.size)
        T, W, W_sat = _impute_saturated(T, W, sat, W_sat, r)
    return _Data(T, W, W_sat, np.asarray(obs.saturated, np.float64), raw)


class _Grids:
    """The estimate grid (every ``stride`` pixels), the search grid (every ``search_stride``) and their operators."""

    def __init__(self, capture, p: int, stride: int, search_stride: int):
        self.tops, self.lefts = patch_grid(capture.size, p, stride)
        self.gt, self.gl = np.repeat(self.tops, len(self.lefts)), np.tile(self.lefts, len(self.tops))
        self.ctops, self.clefts = patch_grid(capture.size, p, search_stride)
        self.ct, self.cl = np.repeat(self.ctops, len(self.clefts)), np.tile(self.clefts, len(self.ctops))
        self.ops = patch_operators(capture.mask, views=capture.views, cfa_pattern=capture.cfa_pattern,
                                   tops=np.concatenate([self.gt, self.ct]), lefts=np.concatenate([self.gl, self.cl]),
                                   size=p, sensor_size=capture.size)
        # patches of one phase share their matrix Phi_p
        self.phase, self.cphase = self.ops.index[:len(self.gt)], self.ops.index[len(self.gt):]


def _chosen_disparity(scores: np.ndarray, g: _Grids, n_d: int, radius: int) -> np.ndarray:
    """The disparity (index) of every estimate patch: the search grid's evidence pooled over the neighbouring
    patches (one patch's evidence alone is noisy), read at the nearest search patch."""
    return _at_estimates(_pooled(scores.reshape(len(g.ct), n_d, -1).max(axis=2), g, radius), g).argmax(axis=1)


def _pooled(per: np.ndarray, g: _Grids, radius: int) -> np.ndarray:
    """Evidence ``(search patches, hypotheses)`` pooled over the neighbouring search patches (:func:`_pool`)."""
    return _pool(per.reshape(len(g.ctops), len(g.clefts), -1), radius)


def _at_estimates(pooled: np.ndarray, g: _Grids) -> np.ndarray:
    """The pooled search-grid evidence ``(rows, columns, hypotheses)`` read at each estimate patch's nearest search
    patch, ``(estimate patches, hypotheses)``."""
    iy, ix = _nearest(g.ctops, g.tops), _nearest(g.clefts, g.lefts)
    return pooled[iy[:, None], ix[None, :]].reshape(len(g.gt), -1)


def _in_order(pool, fn, jobs, ahead: int = 8):
    """``pool.map(fn, jobs)`` with at most ``ahead`` results waiting: the patch estimates of a whole
    light field would otherwise pile up in memory when they are made faster than they are added."""
    pending = deque()
    for job in jobs:
        pending.append(pool.submit(fn, job))
        if len(pending) >= ahead:
            yield pending.popleft().result()
    while pending:
        yield pending.popleft().result()


def _prepared(est: dict, tops, lefts, win, width: int, keys=("patches",)) -> dict:
    """Patch estimates made ready for :class:`_Sums` (in the worker thread, so that the main thread only adds).

    Each estimate of ``keys`` (after the first, only those not all 0) times its weight ``window x patch weight``
    (``"<key>_weighted"``), pixel-major ``(B P P, V U 3)``, and the flat sensor pixel of each row (``"pixels"``),
    with the patches sorted into classes whose corners agree modulo the patch size: the patches of one class do not
    overlap, so each class is added with one fancy-indexed sum (no repeated indices), ``"classes"`` its row slices,
    in a fixed order.
    """
    p, b_n = len(win), len(tops)
    cls = (tops % p) * p + lefts % p
    order = np.argsort(cls, kind="stable")
    cls = cls[order]
    cuts = np.r_[0, np.flatnonzero(np.diff(cls)) + 1, b_n] * p * p
    q = (win[None] * est["weight"][order, None, None]).reshape(-1)  # (B P P,)
    ii = np.arange(p)
    pixels = (tops[order, None, None] + ii[:, None]) * width + lefts[order, None, None] + ii[None, :]
    out = {k: v for k, v in est.items() if k not in keys}
    out.update(pixels=pixels.reshape(-1), q=q, classes=list(zip(cuts[:-1], cuts[1:])))
    for key in keys:
        if key != keys[0] and not est[key].any():  # the first always; the others (point sources) when not all 0
            continue
        x = est[key][order].transpose(0, 3, 4, 1, 2, 5)  # (B, P, P, V, U, 3)
        out[key + "_weighted"] = (x.reshape(b_n * p * p, -1) * q[:, None])
    return out


class _Sums:
    """A light field's sums of weighted patch estimates and of their weights, pixel-major ``(H W, V U 3)`` (each
    fancy-indexed row is contiguous: three times faster to add than ``(V, U, H, W, 3)``, measured); :meth:`result`
    is the ``(V, U, H, W, 3)`` light field, the sums over the weights."""

    def __init__(self, shape):
        self.shape = shape
        self.sums = np.zeros((shape[2] * shape[3], shape[0] * shape[1] * shape[4]))
        self.weights = np.zeros(shape[2] * shape[3])

    def add(self, est: dict, key: str = "patches", weigh: bool = True) -> None:
        """Add ``est[key]`` and (``weigh``) its weights (:func:`_prepared`), class by class in a fixed order."""
        for start, stop in est["classes"]:
            rows = est["pixels"][start:stop]
            self.sums[rows] += est[key + "_weighted"][start:stop]
            if weigh:
                self.weights[rows] += est["q"][start:stop]

    def result(self, weights: np.ndarray | None = None) -> np.ndarray:
        """The sums over ``weights`` (default: their own), ``(V, U, H, W, 3)``."""
        nv, nu, h, w, c = self.shape
        out = self.sums / np.maximum(self.weights if weights is None else weights, 1e-300)[:, None]
        return np.ascontiguousarray(out.reshape(h, w, nv, nu, c).transpose(2, 3, 0, 1, 4))


def _jobs(phase: np.ndarray, chunk: int) -> list:
    """Chunks of at most ``chunk`` patches of one phase: ``[(phase, indices), ...]``, in a fixed order."""
    return [(ph, members[start:start + chunk]) for ph in np.unique(phase) for members in [np.flatnonzero(phase == ph)]
            for start in range(0, len(members), chunk)]


def _result(data: np.ndarray, capture, record: dict, started: float) -> LightField:
    """The light field of the combined estimates (clipped at 0, in the light field's units) and its record."""
    record["negative_fraction_clipped"] = float((data < 0).mean())
    np.maximum(data, 0, out=data)
    if capture.radiance_scale is not None:
        data /= float(capture.radiance_scale)
        units = capture.parameters.get("light_field_units") or "relative"
    else:
        units = "e-/s"
    record.update(radiance_scale=capture.radiance_scale, capture_ground_truth=capture.ground_truth,
                  seconds=time.perf_counter() - started)
    return LightField(data=data.astype(np.float32), units=units,
                      colour_space="camera-rgb" if capture.radiance_scale is None else "linear-srgb",
                      source="lfproc.reconstruct_gmm", attrs={"reconstruction": record})


#: Saturated measurements (:func:`_impute_saturated`): neighbourhood radius (colour-plane pixels), relative std.
_IMPUTE_RADIUS = 2
_IMPUTE_REL_STD = 1.0
RAISE_BOUNDS = True  # the bounds of a wholly saturated region (below)


def _impute_saturated(T, W, sat, W_sat, r):
    """Saturated measurements given the radiance of their unsaturated neighbours that is above their bound.

    A saturated measurement says only ``L >= B`` (``B = T / r``, its saturation level over its
    transmittance ``r``). The unsaturated measurements of the same Bayer colour within
    ``_IMPUTE_RADIUS`` colour-plane pixels (every shot) whose ``L = T / r`` is at least ``B`` are
    on the bright side of any edge; the midpoint of their mean and their maximum becomes the
    measurement's value, with a relative standard deviation of ``_IMPUTE_REL_STD`` (a weak datum:
    it keeps the patch prior from interpolating across the edge, the measurements decide the rest).
    Where fewer than two such neighbours exist the measurement stays a bound, raised
    (``RAISE_BOUNDS``) to the largest bound of the saturated measurements of its colour within
    the same radius: a less sensitive pixel nearby that saturated says the radiance there is at
    least its own, higher, bound.

    Why: a light seen by a quarter of the pixels (the lowest ISO) has most of its pixels saturated;
    a Gaussian patch prior interpolates them from both sides of the light's edge and darkens the
    edge. Measured (tests/test_reconstruct_gmm.py's light, 16 pixels square, 12 stops above its
    floor, medium noise): 69 % of its energy kept without, 88 % with. The statistic and the standard
    deviation were chosen on crops of the tune scenes (mean, maximum and their midpoint; 0.25,
    0.5, 1): the mean loses peaks, the maximum adds texture that is not there. The raised bounds:
    a region saturated in every measurement (no unsaturated neighbour at all) came back at the
    mean of its bounds, a quarter of the largest, or (with no usable measurement in a patch, before
    :func:`_normalised` took the bounds' level) at 1e-15 of it (tests/recon/test_reconstruct_gmm.py's
    square; docs/bench-quick's window); raised, at 1.2 times the largest. Tune scenes, 2 random:
    96 x 128 (3 seeds) 27.92 dB without, 27.91 with; Lytro size 37.65 -> 37.70 dB (sunset-carrots
    52.79 -> 52.88, its worst decade 0.72 -> 0.28 stops, brightest 1 % 0.97 -> 1.02 of their energy).
    """
    shots = T.shape[0]
    L = np.where(r > 0, T / np.maximum(r, 1e-30), 0.0)
    usable = W > 0
    total, count, lifted = np.zeros_like(T), np.zeros_like(T), L.copy()
    rad = _IMPUTE_RADIUS
    for a in (0, 1):
        for b in (0, 1):
            lp = np.pad(L[:, a::2, b::2], ((0, 0), (rad, rad), (rad, rad)))
            up = np.pad(usable[:, a::2, b::2], ((0, 0), (rad, rad), (rad, rad)))
            bound = L[:, a::2, b::2]
            sp = sat[:, a::2, b::2]
            h2, w2 = bound.shape[1:]
            tot, cnt, top = np.zeros(bound.shape), np.zeros(bound.shape), np.zeros(bound.shape)
            raised = bound.copy()
            sat_p = np.pad(sat[:, a::2, b::2], ((0, 0), (rad, rad), (rad, rad)))
            for dy in range(2 * rad + 1):
                for dx in range(2 * rad + 1):
                    for s2 in range(shots):
                        cand = lp[s2, dy:dy + h2, dx:dx + w2]
                        ok = up[s2, dy:dy + h2, dx:dx + w2][None] & (cand[None] >= bound) & sp
                        top = np.maximum(top, np.where(ok, cand[None], 0.0))
                        tot += np.where(ok, cand[None], 0.0)
                        cnt += ok
                        if RAISE_BOUNDS:
                            raised = np.maximum(raised, np.where(sat_p[s2, dy:dy + h2, dx:dx + w2][None] & sp,
                                                                 cand[None], 0.0))
            mean = tot / np.maximum(cnt, 1)
            total[:, a::2, b::2] = 0.5 * (mean + top)
            count[:, a::2, b::2] = cnt
            lifted[:, a::2, b::2] = raised
    fill = sat & (count >= 2)
    value = np.where(fill, r * total, np.where(sat, r * lifted, T))
    weight = np.where(fill, 1.0 / (_IMPUTE_REL_STD * np.maximum(value, 1e-30)), W)
    return value, weight, np.where(fill, 0.0, W_sat)


def _phase_matrices(ops, ph, shears_sparse, model) -> dict:
    """What every patch of one phase shares: ``A`` per disparity, ``A mu``, ``A Sigma`` and ``A Sigma A^T`` per component."""
    phi = ops.dense(ph).astype(np.float64)  # (m, V U P P 3)
    out = {"rowsum": phi.sum(axis=1), "hyp": []}
    for di, sh in enumerate(shears_sparse):
        a = np.ascontiguousarray((sh.T @ phi.T).T)  # (m, n2) = Phi_p S_d
        for k in range(model.components):
            a_cov = a @ model.covariances[k]
            out["hyp"].append((di, k, a, a_cov @ a.T, a @ model.means[k], a_cov))
    return out


def _nearest(grid: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index of the element of the sorted ``grid`` nearest to each of ``at``."""
    i = np.searchsorted(grid, at)
    lo, hi = np.clip(i - 1, 0, len(grid) - 1), np.clip(i, 0, len(grid) - 1)
    return np.where(np.abs(grid[lo] - at) <= np.abs(grid[hi] - at), lo, hi)


def _normalised(T, W, tops, lefts, p, rowsum):
    """The patches' measurements and weights in units of their level ``s`` (module notes), and ``s``."""
    y = _gather(T, tops, lefts, p)
    w = _gather(W, tops, lefts, p)
    use = w > 0
    # a patch with no usable measurement (saturated everywhere) takes the level of its bounds
    use |= ~use.any(axis=1, keepdims=True) & (y > 0)
    level = np.where(use, y, 0).sum(axis=1) / np.maximum((use * rowsum).sum(axis=1), 1e-12)
    level = np.maximum(level, 1e-12 * max(float(level.max()), 1e-30))
    return y / level[:, None], w * level[:, None], level


def _evidence(T, W, tops, lefts, p, phase, log_pi, scales, which):
    """Log evidence of every hypothesis (disparity, component, scale) of a chunk of patches, ``(B, D K S)``,
    ``-inf`` for the scales not in ``which`` (indices)."""
    yn, wn, _ = _normalised(T, W, tops, lefts, p, phase["rowsum"])
    n_s = len(scales)
    out = np.full((len(yn), len(phase["hyp"]) * n_s), -np.inf)
    for j, (di, k, a, kmat, a_mu, a_cov) in enumerate(phase["hyp"]):
        for si in which:
            out[:, j * n_s + si] = _wiener(scales[si] * kmat, a_mu, yn, wn, log_pi[k] - math.log(n_s),
                                           want_solution=False)[0]
    return out


def _chosen_component(scores: np.ndarray, g: _Grids, n_d: int, n_k: int, radius: int) -> np.ndarray:
    """The component of every estimate patch: at each search patch, every component's evidence at the disparity
    its pooled evidence chose; pooled over the neighbouring patches in turn and read at the nearest search patch
    (as :func:`_chosen_disparity`)."""
    per_dk = scores.reshape(len(g.ct), n_d, n_k, -1).max(axis=3)
    d_at = _pooled(per_dk.max(axis=2), g, radius).reshape(len(g.ct), -1).argmax(axis=1)
    return _at_estimates(_pooled(per_dk[np.arange(len(g.ct)), d_at], g, radius), g).argmax(axis=1)


def _pool(per_d: np.ndarray, radius: int) -> np.ndarray:
    """Sum of each disparity's evidence over the ``(2 radius + 1)^2`` neighbouring patches of the grid."""
    if radius == 0:
        return per_d
    from scipy.ndimage import uniform_filter

    rel = per_d - per_d.max(axis=2, keepdims=True)  # relative evidence: a patch with a large one does not dominate
    return uniform_filter(np.maximum(rel, -50.0), size=(2 * radius + 1, 2 * radius + 1, 1), mode="nearest")


def _best_at_disparity(yn, wn, phase, log_pi, scales, chosen_d, chosen_k=None):
    """The hypothesis (component, scale) of largest evidence of each patch at its disparity ``chosen_d`` (and
    component ``chosen_k`` when given: only the scales are tried), and its ``alpha`` (:func:`_wiener`), so
    :func:`_estimate` does not factorise again."""
    n_s = len(scales)
    best = np.full(len(yn), -np.inf)
    chosen = np.zeros(len(yn), np.intp)
    alpha = np.zeros_like(yn)
    key = chosen_d if chosen_k is None else chosen_d * (int(chosen_k.max()) + 1) + chosen_k
    for pair in np.unique(key):
        rows = np.flatnonzero(key == pair)
        d = chosen_d[rows[0]]
        for j, (di, k, a, kmat, a_mu, a_cov) in enumerate(phase["hyp"]):
            if di != d or (chosen_k is not None and k != chosen_k[rows[0]]):
                continue
            for si, sc in enumerate(scales):
                score, al = _wiener(sc * kmat, a_mu, yn[rows], wn[rows], log_pi[k] - math.log(n_s))
                better = score > best[rows]
                best[rows[better]] = score[better]
                chosen[rows[better]] = j * n_s + si
                alpha[rows[better]] = al[better]
    return chosen, alpha


def _estimate(data: _Data, tops, lefts, p, phase, chosen, shears_sparse, model, views, scales, alpha=None,
              norm=None) -> dict:
    """The estimate of each patch under its chosen hypothesis, its overlap weight and its noise (the radiance one
    measurement resolves), and the point sources' share of it (``sources``, 0 but where :func:`_point_sources` won)
    (``alpha``: the first solution of every patch, ``norm``: its :func:`_normalised` measurements, when known)."""
    yn, wn, level = _normalised(data.T, data.W, tops, lefts, p, phase["rowsum"]) if norm is None else norm
    ws = _gather(data.W_sat, tops, lefts, p) * level[:, None]
    b_n = len(yn)
    patches = np.zeros((b_n, shears_sparse[0].shape[0]))
    sources = np.zeros_like(patches)
    weight, noise = np.zeros(b_n), np.zeros(b_n)
    n_s = len(scales)
    for h in np.unique(chosen):
        g = np.flatnonzero(chosen == h)
        di, k, a, kmat, a_mu, a_cov = phase["hyp"][h // n_s]
        sc = scales[h % n_s]
        wg = wn[g].copy()
        al = _wiener(sc * kmat, a_mu, yn[g], wg, 0.0)[1] if alpha is None else alpha[g]
        x = model.means[k][None] + sc * (wg * al) @ a_cov
        for _ in range(2):  # saturated measurements below their level join the data as bounds (module notes)
            low = (ws[g] > 0) & (x @ a.T < yn[g])
            redo = np.flatnonzero(low.any(axis=1))  # only the patches with a bound to add are solved again
            if not len(redo):
                break
            wg[redo] = np.where(low[redo], ws[g[redo]], wn[g[redo]])
            al = _wiener(sc * kmat, a_mu, yn[g[redo]], wg[redo], 0.0)[1]
            x[redo] = model.means[k][None] + sc * (wg[redo] * al) @ a_cov
        res = (x @ a.T - yn[g]) * wg
        chi2 = (res * res).sum(axis=1) / np.maximum((wg > 0).sum(axis=1), 1)
        patches[g] = np.maximum(np.asarray((shears_sparse[di] @ x.T).T), 0.0) * level[g, None]  # radiance >= 0
        if LIGHTS:  # patches a few bright pixels may explain: the Gaussian plus point sources (module notes)
            # a measurement above LIGHTS_BRIGHT times the level (T / r, level units; a saturated one at its bound
            # or imputed level) by LIGHTS_SIGNIFICANCE of its standard deviations (not the noise of a dark patch)
            excess = (yn[g] - LIGHTS_BRIGHT * phase["rowsum"][None]) * np.maximum(wg, ws[g])
            flag = np.flatnonzero(excess.max(axis=1) > LIGHTS_SIGNIFICANCE)
            if len(flag):
                best = _wiener(sc * kmat, a_mu, yn[g[flag]], wg[flag], 0.0, want_solution=False)[0]
                for dd in range(0, len(shears_sparse), 2):  # every other disparity of the search
                    _, _, a2, kmat2, a_mu2, a_cov2 = phase["hyp"][dd * model.components + k]
                    xt, sp, c2, ev = _point_sources(a2, sc * kmat2, a_mu2, sc * a_cov2, model.means[k], yn[g[flag]],
                                                    wg[flag])
                    win_ = np.flatnonzero(ev > best)
                    if not len(win_):
                        continue
                    best[win_] = ev[win_]
                    rows = g[flag[win_]]
                    patches[rows] = np.maximum(np.asarray((shears_sparse[dd] @ xt[win_].T).T), 0.0) * level[rows, None]
                    sources[rows] = np.asarray((shears_sparse[dd] @ sp[win_].T).T) * level[rows, None]
                    chi2[flag[win_]] = c2[win_]
        # the error of a patch is relative to its brightest part (its mean understates it across the edge of a light)
        centre = patches[g].reshape(len(g), views[0], views[1], p, p, 3)[:, views[0] // 2, views[1] // 2]
        top = np.maximum(centre.mean(axis=3).max(axis=(1, 2)), level[g])
        # ... but not below its noise: the radiance one measurement resolves (std 1 / (w r), the median over the
        # patch's usable measurements); else the patches estimated near 0 in a dark region outweigh the others
        noise[g] = level[g] * _median_noise(wn[g], phase["rowsum"])
        weight[g] = 1.0 / ((top ** 2 + noise[g] ** 2) * np.maximum(chi2, 1.0))
    j = chosen // n_s  # phase["hyp"] is ordered (disparity, component)
    hypothesis = np.stack([j // model.components, j % model.components, chosen % n_s], axis=1)
    return {"patches": patches.reshape(b_n, *views, p, p, 3), "weight": weight, "hypothesis": hypothesis,
            "noise": noise, "sources": sources.reshape(b_n, *views, p, p, 3)}


#: Small lights (module notes): patches with a measurement brighter than LIGHTS_BRIGHT times their level
#: (``T / r`` in level units) by LIGHTS_SIGNIFICANCE standard deviations are also fitted as the Gaussian plus
#: point sources (:func:`_point_sources`: LIGHTS_ITERS solves, the first with a prior std LIGHTS_TAU per pixel,
#: then the LIGHTS_ACTIVE strongest pixels; _LIGHT_COLOUR: a factor of a source's colour covariance, mostly
#: grey). LIGHTS = False: the Gaussian alone. LIGHTS_BRIGHT chosen on the tune scenes at 96 x 128 (3 / 6 / 12:
#: 26.17 / 26.02 / 25.88 dB, 1.8 / 1.3 / 0.9 x the time of the first pass; measured before the significance
#: condition, with saturated measurements as a further trigger). A patch whose sources win keeps the
#: hypothesis of its Gaussian fit for the refinement (which sees the light field without the sources).
LIGHTS = True
LIGHTS_SIGNIFICANCE = 3.0
LIGHTS_BRIGHT = 6.0
LIGHTS_ITERS = 4
LIGHTS_TAU = 3.0
LIGHTS_ACTIVE = 16
#: Small lights refitted in windows against the measurements after the refinement (:mod:`lfproc.recon._lights`).
LIGHTS_REFIT = True
#: Then a gain per pixel and colour where the light field contradicts the measurements (:mod:`lfproc.recon._gain`).
MEASURED_GAIN = True
_LIGHT_COLOUR = np.linalg.cholesky(np.full((3, 3), 1.0) + 0.25 * np.eye(3)) / math.sqrt(3.25)


def _point_sources(a, kmat, a_mu, a_cov, mu, y, w):
    """The patch as the Gaussian plus a sparse layer of point sources, batched: ``x = mu + Sigma A^T W alpha + s``.

    Each pixel ``p`` of the centre patch (``E x E``) may hold a source ``s_p ~ N(0, d_p^2 C)`` (``C``: the colour
    covariance ``_LIGHT_COLOUR C_h C_h^T``, mostly grey). The ``d_p`` are re-estimated from the data
    (reweighted least squares, as sparse Bayesian learning: ``d_p^2 <- |s_p|^2`` where the source's luminance
    is positive, else 0): first every pixel at ``LIGHTS_TAU`` (one covariance shared by the batch), then only the
    ``LIGHTS_ACTIVE`` pixels of largest ``d_p`` (the others pruned), ``LIGHTS_ITERS`` solves in all. Returns
    the estimate, its source layer (both ``(B, E E 3)``, level units), the reduced chi-square and the log
    evidence of the last solve (comparable with :func:`_wiener`'s).
    """
    b_n, m = y.shape
    n_pix = a.shape[1] // 3
    ac = a.reshape(m, n_pix, 3) @ _LIGHT_COLOUR  # (m, n_pix, 3)
    flat = ac.reshape(m, -1)
    score, alpha = _wiener(kmat + LIGHTS_TAU ** 2 * (flat @ flat.T), a_mu, y, w, 0.0)
    wa = w * alpha
    sw = LIGHTS_TAU ** 2 * np.einsum("mpc,bm->bpc", ac, wa)  # whitened sources (B, n_pix, 3)
    act = np.broadcast_to(np.arange(n_pix), (b_n, n_pix))
    k_n = min(LIGHTS_ACTIVE, n_pix)
    for _ in range(LIGHTS_ITERS - 1):
        d2 = np.where((sw @ _LIGHT_COLOUR.T).mean(axis=2) > 0, (sw * sw).sum(axis=2), 0.0)
        top = np.argsort(-d2, axis=1, kind="stable")[:, :k_n]
        act = np.take_along_axis(act, top, axis=1)
        d2 = np.take_along_axis(d2, top, axis=1) + 1e-12
        aca = ac[:, act].transpose(1, 0, 2, 3)  # (B, m, K, 3)
        acd = (aca * np.sqrt(d2)[:, None, :, None]).reshape(b_n, m, -1)
        k_b = np.matmul(acd, acd.transpose(0, 2, 1))
        k_b += kmat[None]
        score, alpha = _wiener(k_b, a_mu, y, w, 0.0)  # one covariance per patch
        wa = w * alpha
        sw = d2[..., None] * np.einsum("bmkc,bm->bkc", aca, wa)  # (B, K, 3)
    spike = np.zeros((b_n, n_pix, 3))
    np.put_along_axis(spike, act[..., None], sw @ _LIGHT_COLOUR.T, axis=1)
    spike = spike.reshape(b_n, -1)
    x = mu[None] + wa @ a_cov + spike
    res = (x @ a.T - y) * w
    chi2 = (res * res).sum(axis=1) / np.maximum((w > 0).sum(axis=1), 1)
    return x, spike, chi2, score


def _refine(first, tops, lefts, patch_info, model, shears_sparse, scales, win, pool, chunk, saturated) -> np.ndarray:
    """Every estimate patch again, from the first light field's samples, under its chosen hypothesis (module notes).

    The first light field's patch ``z`` (all views, divided by its level ``s``, the centre view's
    as in :func:`_level`) is taken as data of relative standard deviation ``REFINE_SIGMA`` of the
    patch's shear: ``c = (S^T S / r^2 + Sigma^-1)^-1 (S^T z / r^2 + Sigma^-1 mu)``, one ``E E 3``
    square matrix per hypothesis (disparity, component, scale), and ``s S c`` is combined as in
    the first pass (same window and weights, in a fixed order). Pixels a shot saw saturated
    (``saturated``, ``(H, W)``) keep the larger of the two estimates: the prior pulls lights down.
    ``patch_info``: each patch's hypothesis, weight and noise (:func:`_estimate`); a sample is the mean of its
    estimate truncated at 0 (:func:`._batched.truncated_mean`, std ``POSITIVE_STD`` times the patch's noise), never
    exactly 0.
    """
    hyp, weight, noise = patch_info
    nv, nu = first.shape[:2]
    p = len(win)
    r2 = REFINE_SIGMA ** 2
    unique, which = np.unique(hyp, axis=0, return_inverse=True)
    keys = [tuple(k) for k in unique]
    cov_inv = {k: np.linalg.inv(model.covariances[k]) for k in {key[1] for key in keys}}  # once per component
    mats = {}
    for di, k, si in keys:
        sh = shears_sparse[di]
        ci = cov_inv[k] / scales[si]
        m = np.linalg.inv((sh.T @ sh).toarray() / r2 + ci)
        mats[(di, k, si)] = (m / r2, m @ (ci @ model.means[k]))
    windows = np.lib.stride_tricks.sliding_window_view(first, (p, p), axis=(2, 3))  # (V, U, H', W', 3, P, P)
    jobs = _jobs(which.reshape(-1), chunk)  # (index into keys, patches)

    def solve(job):
        (di, k, si), sel = keys[job[0]], job[1]
        z = windows[:, :, tops[sel], lefts[sel]].transpose(2, 0, 1, 4, 5, 3)  # (B, V, U, P, P, 3)
        level = np.maximum(_level(z[:, nv // 2, nu // 2].reshape(len(sel), -1), p, 0), 1e-300)
        m, offset = mats[(di, k, si)]
        c = np.asarray((shears_sparse[di].T @ (z.reshape(len(sel), -1) / level[:, None]).T).T) @ m + offset[None]
        x = np.asarray((shears_sparse[di] @ c.T).T) * level[:, None]
        x = truncated_mean(x, POSITIVE_STD * noise[sel, None])
        est = {"patches": x.reshape(len(sel), nv, nu, p, p, 3), "weight": weight[sel]}
        return _prepared(est, tops[sel], lefts[sel], win, first.shape[3])

    sums = _Sums(first.shape)
    for est in _in_order(pool, solve, jobs):
        sums.add(est)
    acc = sums.result()
    return np.where(saturated[None, None, :, :, None], np.maximum(first, acc), acc)


#: The refinement's samples are ``E[X | X > 0]``, ``X ~ N(estimate, (POSITIVE_STD n)^2)`` with ``n`` the patch's
#: noise (the radiance one measurement resolves): clipped at 0 (the earlier rule), an estimate near the noise
#: floor came back as exactly 0 (sunrise-desk at 96 x 128: 17 samples above the floor). Chosen on the tune scenes
#: (0.1, 0.25, 0.5, 1): 0.1 leaves PU21-PSNR, SSIM and the other figures as they were (128 x 160 crops: 29.12
#: against 29.13 dB; 96 x 128: 25.47 dB both); the larger ones add energy near the floor (0.5: -0.8 dB on crops).
POSITIVE_STD = 0.1


def _median_noise(wn: np.ndarray, rowsum: np.ndarray) -> np.ndarray:
    """Per patch, the median of ``1 / (w r)`` over its usable measurements (level units); 0 when none.

    Sorted rows (the unusable ones last, as ``inf``) and the middle of each row's usable count: ``numpy.nanmedian``
    gave the same and took 3.4 of the default path's 120 CPU seconds (its small-array path, masked arrays)."""
    use = wn > 0
    sig = np.sort(np.where(use, 1.0 / np.maximum(wn * rowsum[None], 1e-300), np.inf), axis=1)
    n = use.sum(axis=1)
    rows = np.arange(len(sig))
    lo, hi = sig[rows, np.maximum(n - 1, 0) // 2], sig[rows, np.minimum(n // 2, sig.shape[1] - 1)]
    return np.where(n > 0, (lo + hi) / 2, 0.0)


def _wiener(kmat, a_mu, y, w, log_prior, want_solution=True):
    """Evidence of ``y`` under ``N(A mu, K + W^-2)`` and ``alpha = (W K W + I)^-1 W (y - A mu)``, batched
    (``kmat``: ``(m, m)`` shared by the batch, or ``(B, m, m)``, one per patch).

    ``r = W (y - A mu)`` is factorised with the matrix: the Cholesky factor of ``[[W K W + I, r], [r^T, r^T r + 1]]``
    is ``[[L, 0], [z^T, d]]`` with ``z = L^-1 r`` (``d > 0``: ``z^T z = r^T (W K W + I)^-1 r <= r^T r``): with two
    threads the evidence alone cost 0.64 of ``cholesky`` then ``solve_triangular`` (256 patches of 64 measurements,
    measured). The system is formed and ``alpha`` back-substituted by compiled kernels (:mod:`._batched`: scipy's
    batched triangular solve loops in Python and holds the GIL); the factorisation is numpy's.
    """
    m = w.shape[1]
    r = w * (y - a_mu[None])
    chol = np.linalg.cholesky(whitened_system(kmat, w, r))
    z = chol[:, m, :m]
    score = -0.5 * (z * z).sum(axis=1) - np.log(np.diagonal(chol, axis1=1, axis2=2)[:, :m]).sum(axis=1) + log_prior
    if not want_solution:
        return score, None
    return score, back_substitute(chol)
