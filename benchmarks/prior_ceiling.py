"""Benchmark: how far a better Gaussian patch prior could take ``reconstruct_gmm`` (its ceiling).

Usage::

    python benchmarks/prior_ceiling.py [--set tune|test|all] [--scenes a,b] [--crop Y0 Y1 X0 X1 | --crop none]
                                       [--captures "2 random"] [--own-components 4] [--rounds 1]

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


def row(name: str, result, truth, floor: float, seconds: float) -> str:
    sc = figures(result, truth, floor)  # as reconstruct_realistic.py scores a cell
    decades = " ".join(f"1e{np.log10(d['decade'][0]):.0f}: {d['median_stops']:.2f}" for d in sc["stops_by_decade"])
    return (f"  {name:10s} PU21-PSNR {sc['pu21_psnr_db']:6.2f} dB  SSIM {sc['pu21_ssim']:.3f}  detail "
            f"{sc['detail_ratio']:.2f}  sharpness {sharpness(result.data, truth.data):.2f}  stops by decade "
            f"{decades}  {seconds:5.1f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--set", choices=sorted(quality_scenes.SETS), default="tune")
    parser.add_argument("--scenes", help="comma-separated scene names (default: the whole set)")
    parser.add_argument("--crop", nargs="+", metavar="Y0 Y1 X0 X1", help="default: 128 x 160 at the centre; 'none'")
    parser.add_argument("--captures", default="2 random")
    parser.add_argument("--own-components", type=int, default=4)
    parser.add_argument("--rounds", type=int, default=1)
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

    from lfproc.camera import noise_floor
    from lfproc.lightfield import LightField
    from lfproc.recon import load_patch_model, reconstruct_gmm

    base = load_patch_model("default")

    for name in names:
        full = quality_scenes.make_scene(name)
        truth = LightField(np.ascontiguousarray(full.data[:, :, y0:y1, x0:x1]))
        for cap_name in captures:
            print(f"{name}, rows {y0}:{y1}, columns {x0}:{x1}, {cap_name}:", flush=True)
            cap = capture_cell(truth, name, cap_name, 0, 4)
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


if __name__ == "__main__":
    main()
