"""Benchmark: how far a better Gaussian patch prior could take ``reconstruct_gmm`` (its ceiling).

Usage::

    python benchmarks/prior_ceiling.py [--set tune|test|all] [--scenes a,b] [--crop Y0 Y1 X0 X1 | --crop none]
                                       [--captures "2 random"] [--own-components 4] [--rounds 1] [--scene-exposure]
                                       [--global-disparity D [--global-weights 0.1:10,1:10]]

For each scene of :mod:`quality_scenes` (a crop of it, by default the 128 x 160 pixels at its centre; ``--crop none``:
the whole 434 x 625 frame) and each capture of ``--captures`` (the names of ``reconstruct_realistic.py``), the capture is
reconstructed three ways with :func:`lfproc.recon.reconstruct_gmm`:

* ``shipped``: the shipped patch model (four components learned from the tune photographs);
* ``adapted``: the shipped components plus ``--own-components`` learned from the previous result's centre view (the
  image's own statistics, as the piecewise-linear estimator of Yu, Sapiro and Mallat re-learns its Gaussians; repeated
  ``--rounds`` times), a prior a reconstruction could use;
* ``oracle``: the shipped components plus ``--own-components`` learned from the truth's centre view: no reconstruction
  can have it; what a Gaussian mixture that knows the scene's own patch statistics reaches from the same measurements.

Printed per run: PU21-PSNR and -SSIM (the crop's own peak at 1000 cd/m2, as ``lfproc evaluate``), the detail ratio,
``sharpness`` (the Laplacian energy of the centre view's log2 luminance over the truth's: 1 keeps the truth's fine
detail, below 1 is blur), the median error in stops of each decade of the truth's luminance above the capture's noise
floor (``1e1`` is 10-100 in light-field units; ``reconstruct_realistic.py``'s figures), and the seconds (the ``adapted`` and ``oracle``
times include learning the components). The gap between ``shipped`` and ``oracle`` bounds what any re-training of the
Gaussian components (more data, other components) can give on that scene; a representation that is not a Gaussian
mixture is needed beyond it.

With ``--global-disparity D`` (an integer, the crop's true disparity: a crop of one layer), two classical priors that
are not patch priors are measured on the same capture: the centre view ``C`` of one Lambertian light field at that
disparity, solved over the whole crop at once (:func:`global_deconvolution`, conjugate gradients on the normal
equations) from the weighted measurements with a quadratic prior on the gradients of its luminance (weight ``LAM``) and
of its two colour differences (``MU``), for each ``LAM:MU`` of ``--global-weights`` (rows ``tikhonov``). It knows
the true disparity, which no reconstruction does, and uses every measurement of the crop at once; where it still
scores below ``shipped``, the patch prior is not the weak part. (Reweighted passes towards a total variation of the
luminance relative to its level were tried at stop 30 and scored below these: they free the noise of dark regions.)

``--scene-exposure`` captures the crop at the whole scene's radiance scale (the electrons the crop gets in the
scene's own capture, as ``reconstruct_realistic.py`` sees it) instead of exposing for the crop's own peak (the
default, as until stop 30): a dark crop is then as dark as in the scene.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import quality_scenes  # noqa: E402
from reconstruct_realistic import capture_cell, figures, parse_capture  # noqa: E402

CROP = (128, 160)


def _crop(parser, value: list[str] | None, size: tuple[int, int]) -> tuple[int, int, int, int]:
    h, w = size
    if value is None:
        y0, x0 = (h - CROP[0]) // 2, (w - CROP[1]) // 2
        return y0, y0 + CROP[0], x0, x0 + CROP[1]
    if value == ["none"]:
        return 0, h, 0, w
    try:
        y0, y1, x0, x1 = (int(v) for v in value)
    except ValueError:
        parser.error(f"--crop: expected Y0 Y1 X0 X1 (integers) or 'none', got {' '.join(value)}")
    if not (0 <= y0 < y1 <= h and 0 <= x0 < x1 <= w and y1 - y0 >= 16 and x1 - x0 >= 16):
        parser.error(f"--crop: expected 0 <= Y0 < Y1 <= {h}, 0 <= X0 < X1 <= {w}, at least 16 pixels a side, "
                     f"got {y0} {y1} {x0} {x1}")
    return y0, y1, x0, x1


def _centre(lf: np.ndarray) -> np.ndarray:
    return lf[lf.shape[0] // 2, lf.shape[1] // 2]


def sharpness(result: np.ndarray, truth: np.ndarray) -> float:
    """Laplacian energy of the centre view's log2 luminance, result over truth (2-pixel border left out)."""
    from scipy.ndimage import laplace

    from lfproc.lightfield import luminance

    def energy(lf):
        lap = laplace(np.log2(luminance(_centre(lf)) + 1e-6))[2:-2, 2:-2]
        return float((lap * lap).sum())

    return energy(result) / max(energy(truth), 1e-30)


def with_own_components(base, image: np.ndarray, k: int):
    """The model ``base``'s components plus ``k`` learned from ``image`` ``(H, W, 3)``, half the weight each."""
    from lfproc.recon import PatchModel, train_patch_model

    own = train_patch_model([image], components=k, n_patches=20000, random_state=0)
    weights = np.concatenate([base.weights, own.weights]) / 2
    return PatchModel(np.concatenate([base.means, own.means]), np.concatenate([base.covariances, own.covariances]),
                      weights, base.patch, base.margin, attrs={"source": "benchmarks/prior_ceiling.py"})


def _shear(c: np.ndarray, d: int, views: tuple[int, int]) -> np.ndarray:
    """The Lambertian light field ``(V, U, H, W, 3)`` of centre view ``c`` at integer disparity ``d`` (edges
    replicated): view ``(v, u)`` pixel ``(y, x)`` shows ``c[y - (v - V // 2) d, x - (u - U // 2) d]``."""
    nv, nu = views
    h, w = c.shape[:2]
    p = max(nv // 2, nu // 2) * abs(d)
    cp = np.pad(c, ((p, p), (p, p), (0, 0)), mode="edge")
    out = np.empty((nv, nu, h, w, c.shape[2]))
    for v in range(nv):
        for u in range(nu):
            sy, sx = p - (v - nv // 2) * d, p - (u - nu // 2) * d
            out[v, u] = cp[sy:sy + h, sx:sx + w]
    return out


def _shear_adjoint(lf: np.ndarray, d: int) -> np.ndarray:
    """The adjoint of :func:`_shear` (the replicated edges folded back)."""
    nv, nu, h, w, nc = lf.shape
    p = max(nv // 2, nu // 2) * abs(d)
    cp = np.zeros((h + 2 * p, w + 2 * p, nc))
    for v in range(nv):
        for u in range(nu):
            sy, sx = p - (v - nv // 2) * d, p - (u - nu // 2) * d
            cp[sy:sy + h, sx:sx + w] += lf[v, u]
    if p:
        cp[p] += cp[:p].sum(0)
        cp[-p - 1] += cp[-p:].sum(0)
        cp[:, p] += cp[:, :p].sum(1)
        cp[:, -p - 1] += cp[:, -p:].sum(1)
    return cp[p:p + h, p:p + w]


#: Luminance and two colour differences (the quadratic prior's coordinates).
_OPPONENT = np.array([[1 / 3, 1 / 3, 1 / 3], [1 / 2, 0, -1 / 2], [-1 / 4, 1 / 2, -1 / 4]])


def global_deconvolution(cap, d: int, lam: float, mu: float, *, start=None):
    """Centre view ``(H, W, 3)`` of the Lambertian light field at disparity ``d`` that minimises
    ``sum (w (y - K A S_d C))^2 + lam |grad Y(C)|^2 + mu |grad (colour differences)|^2`` (``w`` the measurements'
    weights, saturated ones left out; ``K`` the capture's radiance scale), by conjugate gradients (300 at most, from
    ``start``)."""
    from scipy.sparse.linalg import LinearOperator, cg

    from lfproc.camera.capture import READ_FLOOR_E, observations

    obs = observations(cap, variance_from="local", read_floor_e=READ_FLOOR_E, warn_saturation=False)
    op = cap.operator(dtype=np.float64)
    w2 = np.where(np.asarray(obs.saturated), 0.0, np.asarray(obs.weight, float) ** 2)
    k = float(cap.radiance_scale or 1.0)
    h, w = cap.size
    shape = (h, w, 3)
    prior = np.array([lam, mu, mu])

    def gradient_term(c):
        z = c @ _OPPONENT.T
        out = np.zeros_like(z)
        for ax in (0, 1):
            g = np.diff(z, axis=ax)
            lo, hi = [slice(None)] * 3, [slice(None)] * 3
            lo[ax], hi[ax] = slice(None, -1), slice(1, None)
            out[tuple(lo)] -= g
            out[tuple(hi)] += g
        return (out * prior) @ _OPPONENT

    def normal(x):
        c = x.reshape(shape)
        data = _shear_adjoint(op.adjoint(w2 * op.forward(_shear(c, d, cap.views))), d)
        return (k * k * data + gradient_term(c)).ravel()

    a = LinearOperator((h * w * 3, h * w * 3), matvec=normal, dtype=float)
    b = (k * _shear_adjoint(op.adjoint(w2 * np.asarray(obs.radiance, float)), d)).ravel()
    x0 = None if start is None else np.asarray(start, float).ravel()
    x, _ = cg(a, b, x0=x0, maxiter=300, rtol=1e-6)
    return np.maximum(x.reshape(shape), 1e-6)


def _weights(parser, value: str) -> list[tuple[float, float]]:
    out = []
    for item in value.split(","):
        try:
            lam, mu = (float(v) for v in item.split(":"))
        except ValueError:
            parser.error(f"--global-weights: expected LAM:MU pairs like 0.1:10,1:10, got {value!r}")
        if not (lam > 0 and mu > 0):
            parser.error(f"--global-weights: expected positive weights, got {item!r}")
        out.append((lam, mu))
    return out


def row(name: str, result, truth, floor: float, seconds: float) -> str:
    sc = figures(result, truth, floor)  # as reconstruct_realistic.py scores a cell
    decades = " ".join(f"1e{np.log10(d['decade'][0]):.0f}: {d['median_stops']:.2f}" for d in sc["stops_by_decade"])
    return (f"  {name:10s} PU21-PSNR {sc['pu21_psnr_db']:6.2f} dB  SSIM {sc['pu21_ssim']:.3f}  detail "
            f"{sc['detail_ratio']:.2f}  sharpness {sharpness(result.data, truth.data):.2f}  stops by decade "
            f"{decades}  {seconds:5.1f} s")


def _capture(full, truth, name: str, cap_name: str, scene_exposure: bool):
    """The crop's capture; with ``scene_exposure`` at the radiance scale of the whole scene's capture."""
    if not scene_exposure:
        return capture_cell(truth, name, cap_name, 0, 4)
    scale = capture_cell(full, name, cap_name, 0, 4).radiance_scale
    return capture_cell(truth, name, cap_name, 0, 4, radiance_scale=scale)


def _global_rows(cap, truth, floor, d, weights, start) -> None:
    from lfproc.lightfield import LightField

    for lam, mu in weights:
        t = time.perf_counter()
        c = global_deconvolution(cap, d, lam, mu, start=start)
        lf = LightField(_shear(c, d, cap.views))
        print(row(f"tikhonov {lam:g}:{mu:g}", lf, truth, floor, time.perf_counter() - t), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--set", choices=sorted(quality_scenes.SETS), default="tune")
    parser.add_argument("--scenes", help="comma-separated scene names (default: the whole set)")
    parser.add_argument("--crop", nargs="+", metavar="Y0 Y1 X0 X1", help="default: 128 x 160 at the centre; 'none'")
    parser.add_argument("--captures", default="2 random")
    parser.add_argument("--own-components", type=int, default=4)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--scene-exposure", action="store_true", help="the crop at the whole scene's radiance scale")
    parser.add_argument("--global-disparity", type=int, default=None, metavar="D",
                        help="also the global Lambertian deconvolutions at this integer disparity")
    parser.add_argument("--global-weights", default="0.1:10,1:10,3:10", metavar="LAM:MU,...")
    args = parser.parse_args()
    scenes = quality_scenes.SETS[args.set]
    names = list(scenes) if args.scenes is None else args.scenes.split(",")
    for n in names:
        if n not in quality_scenes.SETS["all"]:
            parser.error(f"--scenes: unknown scene {n!r}; expected some of {', '.join(quality_scenes.SETS['all'])}")
    captures = [c.strip() for c in args.captures.split(",")]
    for c in captures:
        try:
            parse_capture(c)
        except SystemExit as exc:
            parser.error(str(exc))
    if not 1 <= args.own_components <= 32:
        parser.error(f"--own-components: expected 1..32, got {args.own_components}")
    if args.rounds < 1:
        parser.error(f"--rounds: expected a number >= 1, got {args.rounds}")
    y0, y1, x0, x1 = _crop(parser, args.crop, (434, 625))
    if args.global_disparity is not None and not -2 <= args.global_disparity <= 2:
        parser.error(f"--global-disparity: expected an integer in -2..2, got {args.global_disparity}")
    weights = _weights(parser, args.global_weights)

    from lfproc.camera import noise_floor
    from lfproc.lightfield import LightField
    from lfproc.recon import load_patch_model, reconstruct_gmm

    base = load_patch_model("default")

    for name in names:
        full = quality_scenes.make_scene(name)
        truth = LightField(np.ascontiguousarray(full.data[:, :, y0:y1, x0:x1]))
        for cap_name in captures:
            print(f"{name}, rows {y0}:{y1}, columns {x0}:{x1}, {cap_name}:", flush=True)
            cap = _capture(full, truth, name, cap_name, args.scene_exposure)
            floor = noise_floor(cap)
            t = time.perf_counter()
            result = reconstruct_gmm(cap, progress_bar=False)
            print(row("shipped", result, truth, floor, time.perf_counter() - t), flush=True)
            for r in range(args.rounds):
                t = time.perf_counter()
                model = with_own_components(base, _centre(result.data), args.own_components)
                result = reconstruct_gmm(cap, model, progress_bar=False)
                print(row(f"adapted {r + 1}", result, truth, floor, time.perf_counter() - t), flush=True)
            t = time.perf_counter()
            oracle = reconstruct_gmm(cap, with_own_components(base, _centre(truth.data), args.own_components),
                                     progress_bar=False)
            print(row("oracle", oracle, truth, floor, time.perf_counter() - t), flush=True)
            if args.global_disparity is not None:
                _global_rows(cap, truth, floor, args.global_disparity, weights, _centre(result.data))


if __name__ == "__main__":
    main()
