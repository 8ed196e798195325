"""Benchmark: reconstruction quality on light fields made of real HDR photographs, with the figures a user sees.

Usage::

    python benchmarks/reconstruct_realistic.py [--set test|tune|holdout|all] [--size H W] [--captures "2 random,1 random"]
                                               [--mask-period P|none] [--seeds N] [--first-seed I] [--json OUT.json]
                                               [--save DIR]

Scenes: :mod:`quality_scenes` (two real HDR photographs of the shared data as layers with exact
occlusion; ``TUNE`` and ``TEST`` are disjoint: choose settings on the first, report on the
second). Each scene is captured with ``lfproc.camera.simulate.simulate_capture`` (profile
``paper-medium`` unless the capture name says otherwise, ISO 100/400/800/1600, seed of the
scene) and reconstructed with lfproc's defaults (``lfproc.recon.reconstruct(capture)``).

Printed per scene and capture, beside PU21-PSNR / PU21-SSIM (:func:`lfproc.metrics.evaluate`):

* ``dec``: the worst decade's median error in stops (``|log2(Y_result / Y_truth)|`` over the
  samples, pixels x views, in each decade of the truth's luminance above the noise floor);
* ``zeros``: the share of samples above the noise floor returned as 0;
* ``hi``: the energy kept in the brightest 1 % of the truth's samples (1 = all);
* ``detail``: Laplacian energy of the PU21 error over that of the truth (1.0 = no detail), and in brackets the same
  away from the brightest 1 % of the truth's samples (``hdr_figures``' ``detail_ratio_off_highlights``; since stop
  47: the lights hold most of the truth's fine detail in PU21, so the first figure can be small while the rest of
  the picture is grainy);
* seconds of the reconstruction (an upper bound on a shared machine), with a float32 GEMM rate
  measured at the start and the end of the run as the reference for the machine's speed, and
  the run's peak memory.

After the table, per scene and capture (the first seed's run): the same median error for each decade at or below the
noise floor, with its share of the samples (``hdr_figures``' ``stops_below_floor``; since stop 33): one measurement
does not resolve those samples, but they are the picture's shadows.

The noise floor of a capture (:func:`lfproc.camera.capture.noise_floor`) is the light-field
luminance at which one measurement at the highest ISO has as much signal as read noise:
``read_noise_e / (t * radiance_scale * r)`` with ``r`` the mean total mask transmittance of a
pixel (the views' codes summed).

``--seeds N`` captures every cell N times (seeds: the scene's, then +1000, +2000...: other masks, ISO
maps and noise; ``--first-seed I`` starts at the scene's + 1000 I, to add seeds to an earlier run) and prints
the means of PU21-PSNR (with its standard deviation over the seeds),
SSIM, detail and seconds, and the worst of the other figures (largest decade error and zeros,
smallest highlight energy). An ordering between two captures that is smaller than the spread
over seeds is not one; a few emitters make PU21 swing by +-0.5 dB between noise draws.

Capture names: ``"<shots> <iso pattern>"`` with pattern random, row or block, optionally
followed by a profile suffix ``none``/``low``/``medium``/``high`` (the paper's noise levels),
e.g. ``"2 random high"``; ``"4 bracketing"`` is the paper's bracketing baseline (global ISO, 2-4
shots at growing exposures, each reconstructed alone, merged with Debevec weights).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import quality_scenes  # noqa: E402
from reconstruct import gemm_rate  # noqa: E402


def parse_capture(name: str) -> dict:
    parts = name.split()
    if len(parts) not in (2, 3) or not parts[0].isdigit() or parts[1] not in ("random", "row", "block", "bracketing"):
        raise SystemExit(f"--captures: expected names like '2 random', '2 random high' or '4 bracketing', got {name!r}")
    noise = parts[2] if len(parts) == 3 else "medium"
    if parts[1] == "bracketing":  # the paper's baseline: global-ISO shots at growing exposures, each reconstructed
        return dict(shots=int(parts[0]), baseline="bracketing", profile=f"paper-{noise}")
    return dict(shots=int(parts[0]), iso_pattern_kind=parts[1], profile=f"paper-{noise}")


def capture_cell(lf, scene: str, name: str, index: int, period, transmittance: str | None = None, **design):
    """The capture ``name`` (:func:`parse_capture`) of ``lf``, the scene ``scene``'s ``index``-th seed (the scene's
    seed + 1000 ``index``), mask period ``period`` (None: not periodic) and transmittances ``transmittance`` (None:
    ``lfproc simulate``'s default); ``design``: more fields of ``CaptureDesign`` (``radiance_scale``...)."""
    from lfproc.camera.simulate import simulate_capture

    seed = quality_scenes.SETS["all"][scene][-1] + 1000 * index
    if transmittance is not None:
        design["mask_transmittance"] = transmittance
    return simulate_capture(lf, mask_period=period, random_state=seed, **parse_capture(name), **design)


def reconstruct_capture(cap, method: str, options: dict):
    """One reconstruction with ``method`` ("gmm" or "dictionary"); a bracketing capture's shots are reconstructed
    alone and merged with Debevec weights (``lfproc.recon.reconstruct_per_shot``, the paper's baseline)."""
    from lfproc.recon import reconstruct, reconstruct_gmm, reconstruct_per_shot

    if cap.parameters.get("baseline") is not None:
        return reconstruct_per_shot(cap, merges=["debevec"], method=method, **options)["debevec"]
    return (reconstruct_gmm if method == "gmm" else reconstruct)(cap, **options)


def figures(result, truth, floor: float) -> dict:
    """PU21 and the HDR figures (:func:`lfproc.metrics.evaluate` computes both in one pass)."""
    from lfproc.metrics import evaluate

    sc = evaluate(result, truth, scale_tolerance_stops=None, noise_floor=floor)
    return {k: sc[k] for k in ("pu21_psnr_db", "pu21_ssim", "max_decade_stops", "zeros_above_floor",
                               "highlight_energy", "detail_ratio", "detail_ratio_off_highlights",
                               "highlight_detail_share", "stops_by_decade", "stops_below_floor", "emitters_dominate")}


def combine(runs: list[dict]) -> dict:
    """The figures of one cell over several seeds: means of PU21-PSNR (and its standard deviation), SSIM, detail
    and seconds; the worst of the decade error, zeros and highlight energy; every run kept under ``runs``."""
    out = {k: float(np.mean([r[k] for r in runs]))
           for k in ("pu21_psnr_db", "pu21_ssim", "detail_ratio", "detail_ratio_off_highlights", "seconds")}
    out["pu21_psnr_db_sd"] = float(np.std([r["pu21_psnr_db"] for r in runs]))
    out["max_decade_stops"] = float(np.max([r["max_decade_stops"] for r in runs]))
    out["zeros_above_floor"] = float(np.max([r["zeros_above_floor"] for r in runs]))
    out["highlight_energy"] = float(np.min([r["highlight_energy"] for r in runs]))
    out["runs"] = runs
    return out


def main() -> None:
    from lfproc.camera import MASK_TRANSMITTANCES
    from lfproc.camera.capture import noise_floor

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--set", choices=sorted(quality_scenes.SETS), default="test")
    parser.add_argument("--scenes", default=None, help="comma-separated scene names (default: the whole set)")
    parser.add_argument("--size", type=int, nargs=2, default=[434, 625], metavar=("H", "W"))
    parser.add_argument("--captures", default="2 random,1 random")
    parser.add_argument("--mask-period", default="4", help="mask tile period in pixels, or 'none' (default 4)")
    parser.add_argument("--mask-transmittance", choices=MASK_TRANSMITTANCES, default=None,
                        help="the mask's transmittances (lfproc simulate --mask-transmittance; default: its default)")
    parser.add_argument("--data", type=Path, default=quality_scenes.DATA)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--save", type=Path, default=None, help="write truth and results as .npy here (for pictures)")
    parser.add_argument("--method", choices=("dictionary", "gmm"), default="dictionary",
                        help="lfproc.recon.reconstruct (dictionary) or lfproc.recon.reconstruct_gmm (gmm)")
    parser.add_argument("--options", default="{}", help="JSON keywords for the reconstruction function")
    parser.add_argument("--seeds", type=int, default=1, help="captures per cell (seeds: scene's + 1000 i); means")
    parser.add_argument("--first-seed", type=int, default=0, metavar="I",
                        help="the first i of the seeds (default 0): add seeds to a run made before")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error(f"--seeds: expected a number of captures >= 1, got {args.seeds}")
    if args.first_seed < 0:
        parser.error(f"--first-seed: expected a number >= 0, got {args.first_seed}")
    os.environ.setdefault("LFPROC_PROGRESS", "0")
    warnings.simplefilter("ignore")  # saturation warnings of the brightest scenes: expected
    period = None if args.mask_period.lower() == "none" else int(args.mask_period)
    options = json.loads(args.options)
    names = [c.strip() for c in args.captures.split(",")]
    scenes = args.scenes.split(",") if args.scenes else list(quality_scenes.SETS[args.set])
    print(f"{args.method} {options}, 5x5 x {args.size[0]}x{args.size[1]}, mask period {period}, "
          f"{args.mask_transmittance or 'default'} mask transmittances; per cell: PU21-PSNR dB / SSIM / worst decade "
          "(stops) / zeros / highlight energy / detail ratio (away from the brightest 1 %) / seconds")
    print("| scene | stops | " + " | ".join(names) + " |")
    print("|---|---|" + "---|" * len(names))
    rate = gemm_rate()
    print(f"float32 GEMM rate (2048^3, best of 3) at the start: {rate / 1e9:.1f} GFLOP/s", flush=True)
    rows = []
    for scene in scenes:
        lf = quality_scenes.make_scene(scene, tuple(args.size), data=args.data)
        d = lf.data[lf.data > 0]
        stops = float(np.log2(d.max() / np.percentile(d, 0.1)))
        row = {"scene": scene, "stops": stops, "size": args.size, "mask_period": period}
        cells = []
        for name in names:
            runs = []
            for i in range(args.first_seed, args.first_seed + args.seeds):
                cap = capture_cell(lf, scene, name, i, period, args.mask_transmittance)
                t = time.perf_counter()
                out = reconstruct_capture(cap, args.method, options)
                seconds = time.perf_counter() - t
                f = figures(out, lf, noise_floor(cap))  # lfproc.camera.capture.noise_floor
                f["seconds"] = seconds
                runs.append(f)
                if args.save and i == args.first_seed:
                    args.save.mkdir(parents=True, exist_ok=True)
                    np.save(args.save / f"{scene}__{name.replace(' ', '_')}.npy", out.data)
            f = runs[0] if len(runs) == 1 else combine(runs)
            row[name] = f
            spread = f" ±{f['pu21_psnr_db_sd']:.2f}" if len(runs) > 1 else ""
            cells.append(f"{f['pu21_psnr_db']:.2f}{spread} / {f['pu21_ssim']:.3f} / {f['max_decade_stops']:.2f} / "
                         f"{100 * f['zeros_above_floor']:.2f}% / {f['highlight_energy']:.2f} / "
                         f"{f['detail_ratio']:.2f} ({f['detail_ratio_off_highlights']:.2f}) / {f['seconds']:.0f}s")
        if args.save:
            np.save(args.save / f"{scene}__truth.npy", lf.data)
        rows.append(row)
        print(f"| {scene} | {stops:.1f} | " + " | ".join(cells) + " |", flush=True)
    for row in rows:  # left out of the worst decade, but a user sees them (first seed's run)
        for name in names:
            first = row[name].get("runs", [row[name]])[0]
            below = first["stops_below_floor"]
            total = sum(d["samples"] for d in first["stops_by_decade"] + below)
            print(f"below the noise floor, {row['scene']} {name}: " + (" ".join(
                f"{d['decade'][0]:g}:{d['median_stops']:.2f} ({100 * d['samples'] / total:.0f}%)" for d in below)
                or "none"))
    for name in names:
        vals = [r[name] for r in rows]
        print(f"mean {name}: PU21-PSNR {np.mean([v['pu21_psnr_db'] for v in vals]):.2f} dB, "
              f"SSIM {np.mean([v['pu21_ssim'] for v in vals]):.3f}, worst decade "
              f"{np.max([v['max_decade_stops'] for v in vals]):.2f} stops, zeros "
              f"{100 * np.max([v['zeros_above_floor'] for v in vals]):.2f}% (max), highlight energy "
              f"{np.min([v['highlight_energy'] for v in vals]):.2f} (min), detail "
              f"{np.mean([v['detail_ratio'] for v in vals]):.2f} (away from the brightest 1 % "
              f"{np.mean([v['detail_ratio_off_highlights'] for v in vals]):.2f}), "
              f"{np.mean([v['seconds'] for v in vals]):.0f} s")
    print(f"float32 GEMM rate at the end: {gemm_rate() / 1e9:.1f} GFLOP/s (times are comparable between runs only "
          f"at similar rates); peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float))


if __name__ == "__main__":
    main()
