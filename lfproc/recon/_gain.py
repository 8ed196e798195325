"""A gain per pixel and colour where a light field contradicts its measurements.

Why: the patch prior's estimate can disagree with the capture over whole regions the measurements resolve. On the test
scene courtyard-candle (Lytro size, 2 random shots, medium noise) a doorway of 0.1-0.6 beside a wall of 5-17 comes
back 4.3 times the truth (median over its pixels): the first pass's overlapping patches are scaled by the wall, and
the lights refit (:mod:`._lights`) looks for lights, not for shadows. Its measurements say so (the local chi-square of
:func:`._lights.misfit_map` 74.7 per measurement there, the truth's 0.54), yet no stage of the reconstruction asked
them again.

What: a sensor pixel's coded sum sees the light field at its own position only (every view, its CFA colour), so where
the light field is ``g`` times too bright there the measurement says ``1 / g``. Per colour, the ratio of the
measurements' local sums to the prediction's (same-colour pixels of every shot, a Gaussian of ``SIGMA`` pixels: a
normalised convolution, which fills the colours a pixel's filter does not measure) is that gain, up to noise. A
gain per position would scale the views at a position alike, but the views at one position show different scene
points (parallax); so the gain is moved to the scene: a centre-view point's gain is the geometric mean of the
ratios where the views see it (its disparity from the light field's own views, :func:`disparity_map`), and every
view takes its points' gains (Lambertian, as the patch prior). Applied only where the local chi-square exceeds
``THRESHOLD`` (dilated by ``DILATE`` pixels, the edge feathered by a Gaussian of one pixel), each gain within
``1 / CLIP .. CLIP``, ``ITERATIONS`` times (each with the chi-square again, until none exceeds it). Saturated
measurements count at their bound where the prediction falls below it. The result is positive where the input is.

Measured (stop 44 of ``docs/benchmarks.md``, 2026-12-07): ``benchmarks/refit_stage.py dump`` then ``run --save`` (Lytro
size, 2 random shots, medium noise, seed index 0, uniform codes), this step applied to the refit's output by a scratch
script, PU21-PSNR dB / PU21-SSIM / detail ratio:

* courtyard-candle (test) 32.938 / 0.9456 / 0.691 -> 33.586 / 0.9467 / 0.673; its doorway's median ratio to the truth
  4.31 -> 1.21 (90th percentile 13.3 -> 8.2: its edges stay bright), the decades' errors unchanged to 0.01 stops;
* desk-cannon (tune) 25.984 / 0.8549 / 0.744 -> 26.327 / 0.8564 / 0.742 (the brightest 1 % 0.945 -> 0.949 of their
  energy); forest-stilllife (tune) 34.871 / 0.9382 / 0.594 -> 35.132 / 0.9389 / 0.584;
* 2-5 s a Lytro-size light field (8 iterations, 3,800-21,400 pixels gated in the first, 200-2,900 in the last).

Tried on the same dumps (courtyard-candle / desk-cannon, PU21-PSNR): one gain per position, the views alike (no
disparity) 33.24 / 26.19; the disparity of the truth instead of the estimate's 33.72 (the estimate's map agrees with the
truth's on 31 % of the pixels, within a quarter pixel on 54 %); 16 iterations 33.62 / 26.34 at twice the time;
``THRESHOLD`` 3 33.66 / 26.37 at 2.5 times; ``DILATE`` 2 33.57 / 26.32; ``SIGMA`` 0.7 33.55 / 26.32; the views' median
ratio instead of their mean 33.43 / 26.29; a threshold of 2 or 1 fits the noise (the views alike: 33.22 / 33.15 dB, SSIM
0.940 / 0.932, the 0.001-0.01 decade 0.16 -> 0.29 / 0.41 stops). A gain per pixel solved by damped least squares instead
(``scipy.sparse.linalg.lsqr`` on the gated pixels' whitened measurements, damping 1 / 3): 33.19 / 33.68 dB, detail 1.025
/ 0.696, SSIM 0.936 / 0.945: speckle, as every per-pixel fit of :mod:`._lights` printed. The doorway's edges are beyond
this step: at an edge pixel the coded sums are mostly the wall's rays, whose photon noise hides the doorway's (the
planted doorway of ``tests/recon/test_gain.py``, 4 times too bright: 2.00 -> 0.53 stops, its energy 4.00 -> 1.54 times
the truth's).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..camera.capture import noise_floor
from ..camera.projection import build_operator
from ._lights import local_chi2

#: the Gaussian (pixels) of the local sums; the local chi-square above which the gain applies; its dilation (pixels);
#: the largest gain (and smallest, its inverse) of one iteration; the iterations
SIGMA = 0.5
THRESHOLD = 4.0
DILATE = 3
CLIP = 4.0
ITERATIONS = 8


def disparity_map(lf: np.ndarray, disparities, floor: float) -> np.ndarray:
    """Per centre-view pixel ``(H, W)``, the disparity of ``disparities`` whose views agree best with the centre view:
    the sum over views of ``|log l_v(y + dv d, x + du d) - log l_c(y, x)|`` (luminance, at least ``floor``), summed
    over 5 x 5 pixels, smallest."""
    nv, nu = lf.shape[:2]
    lum = np.log(np.maximum(lf.mean(axis=-1), floor))
    centre = lum[nv // 2, nu // 2]
    best = np.full(centre.shape, np.inf)
    out = np.zeros(centre.shape)
    for d in disparities:
        cost = np.zeros(centre.shape)
        for v in range(nv):
            for u in range(nu):
                if v == nv // 2 and u == nu // 2:
                    continue
                # view (v, u) at (y + dv d, x + du d): ndimage.shift moves by minus that
                cost += np.abs(ndimage.shift(lum[v, u], (-(v - nv // 2) * d, -(u - nu // 2) * d), order=1,
                                             mode="nearest") - centre)
        cost = ndimage.uniform_filter(cost, 5, mode="nearest")
        better = cost < best
        out[better], best[better] = d, cost[better]
    return out


def _bilinear(img: np.ndarray, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``img`` ``(H, W, C)`` at the points ``(y, x)`` (any shape, clamped to the image), bilinear: ``(..., C)``."""
    h, w = img.shape[:2]
    y = np.clip(y, 0, h - 1)
    x = np.clip(x, 0, w - 1)
    y0 = np.minimum(np.floor(y).astype(np.intp), h - 2)
    x0 = np.minimum(np.floor(x).astype(np.intp), w - 2)
    fy, fx = (y - y0)[..., None], (x - x0)[..., None]
    return ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x0 + 1])
            + fy * ((1 - fx) * img[y0 + 1, x0] + fx * img[y0 + 1, x0 + 1]))


def _ratio(pred, T, W, W_bound, onehot) -> np.ndarray:
    """``(H, W, 3)``: per colour, the local sum of the measurements over the prediction's (module notes)."""
    use = (W > 0) | ((W_bound > 0) & (pred < T))  # a saturated one at its bound where predicted below it
    num = np.where(use, T, 0.0).sum(axis=0)
    den = np.where(use, pred, 0.0).sum(axis=0)
    out = np.ones(onehot.shape)
    for c in range(onehot.shape[-1]):
        n = ndimage.gaussian_filter(num * onehot[..., c], SIGMA, mode="nearest")
        d = ndimage.gaussian_filter(den * onehot[..., c], SIGMA, mode="nearest")
        ok = d > 0
        out[..., c][ok] = n[ok] / d[ok]
    return np.clip(out, 1.0 / CLIP, CLIP)


def measured_gain(lf: np.ndarray, T: np.ndarray, W: np.ndarray, W_bound: np.ndarray, capture, disparities
                  ) -> tuple[np.ndarray, dict]:
    """The light field ``lf`` ``(V, U, H, W, 3)`` scaled where it contradicts its measurements (module notes).

    ``T, W, W_bound``: the measurements ``(S, H, W)``, their weights (0 where saturated) and the saturated ones'
    weights as bounds, in ``lf``'s units (e-/s); ``capture``: their :class:`~lfproc.camera.capture.Capture`;
    ``disparities``: those the disparity map chooses from (above the capture's noise floor). ``lf`` is not modified.
    Returns the new light field and ``{"iterations": n, "pixels": [pixels gated in each iteration]}``.
    """
    op = build_operator(capture.mask, views=capture.views, size=capture.size, cfa_pattern=capture.cfa_pattern,
                        dtype=np.float64)
    floor = noise_floor(capture) * float(capture.radiance_scale or 1.0)
    nv, nu, h, w = lf.shape[:4]
    onehot = np.eye(lf.shape[-1])[op.cfa_index]  # (H, W, C): each pixel's CFA colour
    dy, dx = np.meshgrid(np.arange(nv) - nv // 2, np.arange(nu) - nu // 2, indexing="ij")
    dy, dx = dy.reshape(-1, 1).astype(float), dx.reshape(-1, 1).astype(float)
    reach = int(np.ceil(max(abs(float(d)) for d in disparities) * max(nv // 2, nu // 2))) + 2
    out, pred, disparity, gated = lf, op.forward(lf), None, []
    for _ in range(ITERATIONS):
        gate = local_chi2(pred, T, W, W_bound) > THRESHOLD
        if not gate.any():
            break
        if disparity is None:
            disparity = disparity_map(lf, disparities, floor)
        weight = ndimage.gaussian_filter(ndimage.binary_dilation(gate, iterations=DILATE).astype(float), 1.0)
        gy, gx = np.nonzero(weight > 1e-3)
        gated.append(int(gate.sum()))
        log_ratio = np.log(_ratio(pred, T, W, W_bound, onehot))
        # the scene points the gated pixels show in any view, and their gains: the mean log ratio over the views
        near = np.zeros((h, w), bool)
        near[gy, gx] = True
        py, px = np.nonzero(ndimage.binary_dilation(near, iterations=reach))
        d = disparity[py, px][None]
        scene = np.zeros((h, w, 3))
        scene[py, px] = _bilinear(log_ratio, py[None] + dy * d, px[None] + dx * d).mean(axis=0)
        # every view's gated pixels take the gain of the point they show
        d = disparity[gy, gx][None]
        gain = np.exp(weight[gy, gx][None, :, None] * _bilinear(scene, gy[None] - dy * d, gx[None] - dx * d))
        out = out.copy() if out is lf else out
        out[:, :, gy, gx] *= gain.reshape(nv, nu, -1, 3)
        # the prediction changes at the gated pixels only (a sensor pixel sees its own position)
        seen = (out[:, :, gy, gx] * onehot[gy, gx]).sum(axis=-1)  # (V, U, n): each view at the pixel's colour
        pred[:, gy, gx] = np.einsum("svun,vun->sn", op.weights[:, :, :, gy, gx], seen)
    return (lf.copy() if out is lf else out), {"iterations": len(gated), "pixels": gated}

