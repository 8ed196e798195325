"""Benchmark: the lights refit (``lfproc.recon._lights``) alone, on a first estimate saved once.

Usage::

    python benchmarks/refit_stage.py dump SCENE OUT.pkl [--size H W] [--capture "2 random"] [--seed-index I]
    python benchmarks/refit_stage.py run OUT.pkl [NAME=VALUE ...] [--save DIR] [--threads]
    python benchmarks/refit_stage.py bound OUT.pkl TOP LEFT SIZE [--disparities D[,D...]]
    python benchmarks/refit_stage.py misfit OUT.pkl RESULT.npy [--thresholds 20,8,4]

``dump`` captures a scene of :mod:`quality_scenes` as :mod:`reconstruct_realistic` does (mask period 4, the
scene's seed + 1000 ``I``) and runs ``reconstruct_gmm`` up to the refit, then saves what the refit receives (the
first light field, the measurements, their weights and bounds, the capture) with the truth. ``run`` applies the
refit to it with the module's settings, or with ``NAME=VALUE`` overrides of ``lfproc.recon._lights``'s upper-case
settings (``RATIO=4 PASSES=1``), on a pool of one thread per core with one-thread BLAS as ``reconstruct_gmm`` runs
it, and prints the seconds, the windows per pass ``[found, refitted]``, PU21-PSNR, the detail ratio and the median
error in stops of each decade of the truth's luminance above the noise floor, as :mod:`reconstruct_realistic` scores
a cell (``lfproc.metrics.evaluate``: PU21-PSNR the mean of the views'), and the pooled PU21-PSNR (one over every
view, ``pu21_psnr``), which this script printed alone until stop 24: the two can disagree on a change (the stop-24
colour fit on city-interior: pooled 52.428 -> 52.584 dB, the views' mean 53.782 -> 53.768).

Why: the whole reconstruction of a Lytro-size capture takes 1-3 minutes, the refit a tenth of that; a setting of
the refit is compared on the same first estimate in seconds, and a change elsewhere cannot move the figures. Until
stop 21 ``run`` called the refit serially with threaded BLAS, which on these small matrices was slower and counted
more of the refit's cost than the reconstruction pays (back to back, quiet machine: desk-cannon 16 -> 5 s,
night-studio 46 -> 22 s, the same figures); times measured before then are upper bounds. The
dump is a scratch file (Python's pickle: it loads only with the same lfproc version, and only files you made).
Figures measured this way are of the refit stage alone; confirm a change with :mod:`reconstruct_realistic`.
Since stop 44 ``run`` also applies the reconstruction's last step, the gain where the result contradicts the
measurements (``lfproc.recon._gain``, on the refit's output), and prints its figures as ``gain``; ``--save`` writes it
as ``<dump>__gain.npy``. ``misfit`` asks how much of a result's error lies where the result contradicts the measurements: where the local
chi-square (``lfproc.recon._lights.misfit_map`` of the result, in light-field units as ``run --save`` writes it) is
above each threshold, it prints the share of pixels, the share of those the result predicts too bright, and the
figures of the result with the truth put there (all views, the pixels dilated by 3), for all of them and for the
too-bright ones: what a solver that makes the result agree with the data there could gain at most (stop 43).
Since stop 31 ``run`` solves a pass of many windows on worker processes as ``reconstruct_gmm`` does
(``lfproc.recon._lights``, "Why processes"); ``--threads`` keeps every window on the thread pool (the same figures,
for timing the two).
"""

from __future__ import annotations

import argparse
import inspect
import os
import pickle
import sys
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))
import quality_scenes  # noqa: E402
from reconstruct_realistic import capture_cell  # noqa: E402


class _Dumped(Exception):
    pass


def _fail(message: str) -> None:
    """Bad input: one line on stderr, exit code 2 (as argparse and the lfproc command)."""
    print(f"refit_stage.py: {message}", file=sys.stderr)
    raise SystemExit(2)


def dump(scene: str, out: Path, size: tuple[int, int], capture: str, seed_index: int,
         transmittance: str | None = None) -> None:
    import lfproc.recon._gmm as gmm

    if scene not in quality_scenes.SETS["all"]:
        _fail(f"SCENE: expected one of {', '.join(sorted(quality_scenes.SETS['all']))}, got {scene!r}")
    if out.exists():
        _fail(f"{out}: exists; remove it first")
    lf = quality_scenes.make_scene(scene, size)
    cap = capture_cell(lf, scene, capture, seed_index, 4, transmittance)
    record = {}

    def keep(*args, **kwargs):  # refit_lights' arguments by its own signature (a changed call cannot break this)
        a = inspect.signature(original).bind(*args, **kwargs).arguments
        record.update(first=a["first"], T=a["T"], W=a["W"], W_bound=a["W_bound"], capture=a["capture"],
                      margin=a["margin"], truth=lf.data, disparities=tuple(a["disparities"]), scene=scene,
                      capture_name=capture, seed_index=seed_index)
        raise _Dumped

    original = gmm.refit_lights
    gmm.refit_lights = keep
    try:
        gmm.reconstruct_gmm(cap)
    except _Dumped:
        pass
    finally:
        gmm.refit_lights = original
    if not record:
        _fail(f"{scene}: the reconstruction did not reach the refit (LIGHTS_REFIT off?)")
    tmp = out.with_name(out.name + ".part")
    with open(tmp, "wb") as f:
        pickle.dump(record, f)
    os.replace(tmp, out)
    print(f"{out}: {scene}, {capture}, seed index {seed_index}, first estimate {record['first'].shape}")


def _load(path: Path) -> dict:
    """A dump of :func:`dump`, checked (bad input: one line, exit code 2)."""
    from lfproc.camera.capture import Capture

    if not path.is_file():
        _fail(f"{path}: not found (make it with 'refit_stage.py dump')")
    try:
        with open(path, "rb") as f:
            d = pickle.load(f)
        missing = {"T", "W", "W_bound", "capture", "disparities", "first", "margin", "truth"} - set(d)
        if missing:
            raise KeyError(", ".join(sorted(missing)))
        cap, first = d["capture"], d["first"]
        arrays = [d[k] for k in ("T", "W", "W_bound", "first", "truth")]
        if not all(isinstance(a, np.ndarray) for a in arrays) or first.ndim != 5 or d["T"].ndim != 3 \
                or not d["T"].shape == d["W"].shape == d["W_bound"].shape or first.shape != d["truth"].shape:
            raise TypeError("its arrays are not those of a capture (S, H, W) and a light field (V, U, H, W, 3)")
        if not isinstance(cap, Capture):
            raise TypeError(f"'capture' is a {type(cap).__name__}, not a Capture")
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, KeyError, TypeError, ValueError) as e:
        _fail(f"{path}: not a dump of 'refit_stage.py dump' of this lfproc version ({type(e).__name__}: {e})")
    return d


def run(path: Path, settings: list[str], save: Path | None = None, threads: bool = False) -> None:
    import lfproc.recon._gmm as gmm
    import lfproc.recon._lights as lights
    from lfproc.recon._gain import measured_gain
    from lfproc import LightField
    from lfproc._shared.parallel import available_cpus
    from lfproc.camera.capture import noise_floor
    from lfproc.metrics import evaluate, pu21_psnr

    for item in settings:
        name, sep, value = item.partition("=")
        if not sep or not name.isupper() or not hasattr(lights, name):
            _fail(f"{item!r}: expected NAME=VALUE with NAME an upper-case setting of lfproc.recon._lights")
        old = getattr(lights, name)
        try:
            setattr(lights, name, bool(int(value)) if isinstance(old, bool) else type(old)(float(value)))
        except ValueError:
            _fail(f"{item!r}: expected a number for {name}, got {value!r}")
    if save is not None and not save.is_dir():
        _fail(f"--save {save}: expected an existing directory")
    d = _load(path)
    cap, first = d["capture"], d["first"]
    t = time.perf_counter()
    with threadpool_limits(1), ThreadPoolExecutor(max_workers=available_cpus()) as pool:  # as reconstruct_gmm
        out, info = lights.refit_lights(first, d["T"], d["W"], d["W_bound"], cap, d["disparities"], d["margin"], pool,
                                        0 if threads else available_cpus())
    seconds = time.perf_counter() - t
    stages = [("first", first), ("refit", out)]
    if gmm.MEASURED_GAIN:  # the reconstruction's last step (lfproc.recon._gain), on the refit's output
        t = time.perf_counter()
        stages.append(("gain", measured_gain(out, d["T"], d["W"], d["W_bound"], cap, d["disparities"])[0]))
        gain_seconds = time.perf_counter() - t
    truth = LightField(d["truth"], units="relative")
    for name, x in stages:
        x = x / cap.radiance_scale
        f = evaluate(LightField(x.astype(np.float32), units="relative"), truth, scale_tolerance_stops=None,
                     noise_floor=noise_floor(cap))  # as reconstruct_realistic scores a cell
        decades = " ".join(f"{s['decade'][0]:g}:{s['median_stops']:.2f}" for s in f["stops_by_decade"])
        print(f"{name}: PU21-PSNR {f['pu21_psnr_db']:.3f} dB (pooled {pu21_psnr(x, d['truth']):.3f}); "
              f"detail {f['detail_ratio']:.3f}; stops by decade {decades}")
        if save is not None:
            np.save(save / f"{path.stem}__{name}.npy", x.astype(np.float32))
    if save is not None:
        np.save(save / f"{path.stem}__truth.npy", d["truth"])
    print(f"{path.name} {' '.join(settings)}: {seconds:.0f} s, windows per pass {info['passes']}"
          + (f"; gain {gain_seconds:.1f} s" if gmm.MEASURED_GAIN else ""))


def bound(path: Path, top: int, left: int, size: int, disparities: tuple | None = None) -> None:
    """Per decade of the truth's luminance in the centre view of the window ``(top, left, size)``: how well the
    capture can fix a pixel's light at all. A lower bound on the standard deviation of a grey light on one pixel (the
    inverse square root of the diagonal of the Fisher information of its luminance, a grey light being that luminance
    in each colour: the squared weights of the usable measurements that see it, every other unknown known: "alone"),
    and the Cramér-Rao bound with every pixel of the window and its margin unknown and no prior (the diagonal of the
    Fisher information's pseudo-inverse: "jointly"), in stops above the truth (``log2(1 + bound / truth)``), at each
    disparity of the dump's grid, or of ``disparities`` (a wall between the grid's: sunrise-interior's at 0.6)."""
    from scipy import sparse

    from lfproc.camera.projection import patch_operators
    from lfproc.errors import InputError
    from lfproc.lightfield import luminance
    from lfproc.recon._gmm import shear_matrix
    from lfproc.recon._lights import _window_matrix

    d = _load(path)
    cap, first = d["capture"], d["first"]
    nv, nu, h, w = first.shape[:4]
    r = d["margin"]
    if size < 1 or not (r <= top <= h - r - size and r <= left <= w - r - size):
        _fail(f"window {top} {left} {size}: expected a window of size >= 1 inside the margin {r} of the "
              f"{h} x {w} views")
    e = size + 2 * r
    shears = {}
    for disparity in d["disparities"] if disparities is None else disparities:  # all checked before any output
        try:
            shears[disparity] = sparse.csr_array(shear_matrix((nv, nu), size, r, disparity))
        except InputError as err:  # a disparity whose views leave the dump's margin: the library's own message
            _fail(f"--disparities: {err}")
    weights = d["W"][:, top:top + size, left:left + size].reshape(-1)
    ops = patch_operators(cap.mask, views=cap.views, cfa_pattern=cap.cfa_pattern, tops=[top], lefts=[left],
                          size=size, sensor_size=cap.size)
    cols, vals = ops.cols[0].astype(np.intp), ops.vals[0].astype(np.float64)
    truth = luminance(d["truth"][nv // 2, nu // 2, top:top + size, left:left + size].astype(np.float64))
    decades = np.floor(np.log10(np.maximum(truth, 1e-30))).astype(int)
    shown = [k for k in sorted(set(decades.ravel())) if k >= -1]
    counts = ", ".join(f"1e{k}: {int((decades == k).sum())}" for k in shown)
    print(f"{path.name}: window {top} {left} {size}; pixels per decade of the truth {counts}; median one-sigma bound "
          f"in stops at each disparity, each pixel alone and all jointly")
    for disparity, shear in shears.items():
        m = _window_matrix(cols, vals, shear)
        m = m.toarray() if sparse.issparse(m) else np.asarray(m)
        grey = m.reshape(len(m), e * e, 3).sum(axis=2) * weights[:, None]  # a grey light of luminance 1 on a pixel
        seen = np.abs(grey).sum(axis=0) > 0
        fisher = grey[:, seen].T @ grey[:, seen]
        cells = []
        for how, var in (("alone", np.diag(fisher) ** -1.0), ("jointly", np.diag(np.linalg.pinv(fisher)))):
            sd = np.full(e * e, np.inf)  # no usable measurement sees the pixel: no bound (inf)
            sd[seen] = np.sqrt(np.maximum(var, 0.0))
            sd = sd.reshape(e, e)[r:r + size, r:r + size] / float(cap.radiance_scale)  # light-field units
            stops = np.log2(1.0 + sd / np.maximum(truth, 1e-30))
            cells.append(how + " " + ", ".join(f"1e{k}: {np.median(stops[decades == k]):.2f}" for k in shown))
        print(f"  {disparity:+.2f}: " + "; ".join(cells))


def misfit(path: Path, result: Path, thresholds: tuple[float, ...]) -> None:
    """Where ``result`` (a light field in the dump's truth units, ``(V, U, H, W, 3)``) contradicts the dump's
    measurements, and the figures with the truth there (module docstring)."""
    from scipy import ndimage

    from lfproc import LightField
    from lfproc.camera.capture import noise_floor
    from lfproc.camera.projection import build_operator
    from lfproc.metrics import evaluate
    from lfproc.recon._lights import MISFIT_SIZE, misfit_map

    d = _load(path)
    if not result.is_file():
        _fail(f"{result}: not found (a light field saved by 'refit_stage.py run --save')")
    try:
        x = np.load(result, allow_pickle=False)
    except (OSError, ValueError, EOFError) as e:
        _fail(f"{result}: not a .npy array ({type(e).__name__}: {e})")
    if not isinstance(x, np.ndarray):  # an .npz archive
        _fail(f"{result}: not a .npy array (a {type(x).__name__})")
    if x.shape != d["truth"].shape or not np.issubdtype(x.dtype, np.floating) or not np.isfinite(x).all():
        _fail(f"{result}: expected finite floats of the dump's shape {d['truth'].shape}, got {x.dtype} {x.shape}")
    cap, truth = d["capture"], d["truth"]
    op = build_operator(cap.mask, views=cap.views, size=cap.size, cfa_pattern=cap.cfa_pattern, dtype=np.float64)
    scaled = x.astype(np.float64) * float(cap.radiance_scale)
    chi2 = misfit_map(scaled, d["T"], d["W"], d["W_bound"], op)
    residual = np.where(d["W"] > 0, (d["T"] - op.forward(scaled)) * d["W"], 0.0).sum(axis=0)
    bright = ndimage.uniform_filter(residual, MISFIT_SIZE, mode="nearest") < 0  # predicted above measured

    def figures(lf):
        f = evaluate(LightField(lf.astype(np.float32), units="relative"), LightField(truth, units="relative"),
                     scale_tolerance_stops=None, noise_floor=noise_floor(cap))
        worst = max((s["median_stops"] for s in f["stops_by_decade"]), default=float("nan"))
        return (f"PU21-PSNR {f['pu21_psnr_db']:.3f} dB, SSIM {f['pu21_ssim']:.4f}, detail {f['detail_ratio']:.3f}, "
                f"worst decade {worst:.2f}")

    print(f"{result.name} against {path.name}: {figures(x)}")
    for level in thresholds:
        over = chi2 > level
        cells = []
        for name, where in (("all", over), ("too bright", over & bright)):
            put = ndimage.binary_dilation(where, iterations=3)
            cells.append(f"{name} {put.mean():.4f} of pixels: "
                         + figures(np.where(put[None, None, ..., None], truth, x)))
        print(f"  chi-square > {level:g}: {over.mean():.4f} of pixels ({(over & bright).mean():.4f} too bright); "
              f"truth there, " + "; ".join(cells))


def _numbers(text: str) -> tuple[float, ...]:
    """Comma-separated finite numbers (``--disparities``, ``--thresholds``), or ``()`` when ``text`` is not that."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        return ()
    return values if all(np.isfinite(values)) else ()


def main() -> None:
    from lfproc.camera import MASK_TRANSMITTANCES

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("dump", help="save the refit's input for a scene and capture")
    p.add_argument("scene")
    p.add_argument("out", type=Path)
    p.add_argument("--size", type=int, nargs=2, default=[434, 625], metavar=("H", "W"))
    p.add_argument("--capture", default="2 random")
    p.add_argument("--seed-index", type=int, default=0)
    p.add_argument("--mask-transmittance", choices=MASK_TRANSMITTANCES, default=None,
                   help="the mask's transmittances (default: lfproc simulate's)")
    p = sub.add_parser("run", help="refit a saved first estimate, with settings overridden")
    p.add_argument("path", type=Path)
    p.add_argument("settings", nargs="*")
    p.add_argument("--threads", action="store_true",
                   help="solve every window on the thread pool, as before stop 31 (default: worker processes)")
    p.add_argument("--save", type=Path, default=None,
                   help="a directory: write <dump>__truth.npy, __first.npy and __refit.npy there (light-field units)")
    p = sub.add_parser("bound", help="how well the capture fixes each pixel's light in a window (a lower bound)")
    p.add_argument("path", type=Path)
    p.add_argument("top", type=int)
    p.add_argument("left", type=int)
    p.add_argument("size", type=int)
    p.add_argument("--disparities", default=None, metavar="D[,D...]",
                   help="the disparities to bound at (default: the dump's grid)")
    p = sub.add_parser("misfit", help="how much of a result's error lies where it contradicts the measurements")
    p.add_argument("path", type=Path)
    p.add_argument("result", type=Path)
    p.add_argument("--thresholds", default="20,8,4", metavar="C[,C...]",
                   help="local chi-square levels (misfit_map) above which a pixel counts as a misfit")
    args = parser.parse_args()
    os.environ.setdefault("LFPROC_PROGRESS", "0")
    warnings.simplefilter("ignore")  # saturation warnings of the brightest scenes: expected
    if args.command == "dump":
        if args.seed_index < 0:
            parser.error(f"--seed-index: expected a number >= 0, got {args.seed_index}")
        dump(args.scene, args.out, tuple(args.size), args.capture, args.seed_index, args.mask_transmittance)
    elif args.command == "bound":
        disparities = None
        if args.disparities is not None:
            disparities = _numbers(args.disparities)
            if not disparities:
                parser.error(f"--disparities: expected numbers like 0.6 or -1,0.5, got {args.disparities!r}")
        bound(args.path, args.top, args.left, args.size, disparities)
    elif args.command == "misfit":
        thresholds = _numbers(args.thresholds)
        if not thresholds or min(thresholds) < 0:
            parser.error(f"--thresholds: expected numbers >= 0 like 20 or 20,8,4, got {args.thresholds!r}")
        misfit(args.path, args.result, thresholds)
    else:
        run(args.path, args.settings, args.save, args.threads)


if __name__ == "__main__":
    main()
