"""Benchmark: reconstruction settings and capture options compared on the same scenes.

Usage::

    python benchmarks/reconstruct_tuning.py                      # the tuning scenes, the README's configs
    python benchmarks/reconstruct_tuning.py --configs '[{}, {"stride": 2}]' --scenes 0,3
    python benchmarks/reconstruct_tuning.py --scenes 0,3 --configs '[{}]' \\
        --capture '{"iso_pattern_kind": "block", "block_px": 8}'

``--scenes tune`` (the default) are the three scenes the defaults of ``lfproc.reconstruct`` were
chosen on: ``layers`` + ``ScanLines_Cannon.exr`` (seed 21), ``window`` + ``city.exr`` (22),
``lamps`` + ``sunset.exr`` (23), none of them in ``reconstruct_quality.py``'s evaluation; a list
of numbers picks those evaluation scenes instead (``reconstruct_quality.SCENES``, 0-based).
Scenes are 5 x 5 x ``--size`` (default 434 x 625), captured as ``reconstruct_quality.py`` does
(``2 random``, profile ``paper-medium``, mask period 4, the scene's seed) with ``--capture``
changing ``simulate_capture`` options. Every config (``lfproc.reconstruct`` keyword arguments,
a JSON list) prints one line: per scene PU21-PSNR / PU21-SSIM / mean iterations / the median
|log2 error| of the pixels darker than 1/1000 of the scene's maximum (where a reconstruction
that shrinks dark patches to zero shows ~20 stops), the mean PSNR and the seconds per scene.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from reconstruct_quality import CAPTURES, DATA, SCENES, scene  # noqa: E402  (the evaluation scenes and captures)

TUNE_SCENES = [("layers", "hdr/ScanLines_Cannon.exr", 21), ("window", "hdr_cc0/city.exr", 22),
               ("lamps", "hdr_cc0/sunset.exr", 23)]
#: The settings compared in README ("Choosing the new defaults"); ``_OLD``: the weights and overlaps of
#: the earlier stops (plug-in photon variance, no fit weights).
_OLD = {"overlap": "scale-window", "variance": "measurement"}
README_CONFIGS = [
    {"scale": "noise", "mu": 1.0, "max_iter": 50, "tol": 1e-2, **_OLD},
    {"scale": "noise", "mu": 0.1, "max_iter": 50, "tol": 1e-2, **_OLD},
    {"scale": "noise", "mu": 0.1, "max_iter": 150, "tol": 1e-3, **_OLD},
    {"scale": "universal", "mu": 1.0, "max_iter": 50, "tol": 1e-2, **_OLD},
    {"scale": "universal", "mu": 0.5, "max_iter": 50, "tol": 1e-2, **_OLD},
    {"scale": "universal", "mu": 0.25, "max_iter": 50, "tol": 1e-2, **_OLD},
    {"scale": "universal", "mu": 0.5, "max_iter": 150, "tol": 1e-3, **_OLD},
    {"mu": 0.25, **_OLD},  # the defaults of stop 3
    {"mu": 0.25, "max_iter": 150, **_OLD},
    {"mu": 0.25, "max_iter": 300, "tol": 1e-4, **_OLD},
    {"mu": 0.18, **_OLD},
    {"mu": 0.125, **_OLD},
    {"mu": 0.25, "debias": 30, **_OLD},
    {"mu": 0.25, "variance": "measurement"},  # + fit weights
    {"mu": 0.25},  # + the neighbours' photon variance
    {"mu": 0.35},
    {},  # mu 0.5: the defaults
]


def main() -> None:
    from lfproc.camera.simulate import simulate_capture
    from lfproc.metrics import evaluate
    from lfproc.recon import reconstruct

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", default="tune", help="'tune' or comma-separated evaluation scene numbers")
    parser.add_argument("--configs", default=None, help="JSON list of reconstruct options (default: README's)")
    parser.add_argument("--capture", default="{}", help="JSON object of simulate_capture options to change")
    parser.add_argument("--size", type=int, nargs=2, default=[434, 625], metavar=("H", "W"))
    parser.add_argument("--data", type=Path, default=DATA,
                        help="the shared data folder (default $LFPROC_SHARED_DATA or ../shared/data)")
    args = parser.parse_args()
    scenes = TUNE_SCENES if args.scenes == "tune" else [SCENES[int(i)] for i in args.scenes.split(",")]
    configs = README_CONFIGS if args.configs is None else json.loads(args.configs)
    capture_options = {**CAPTURES["2 random"], "profile": "paper-medium", "mask_period": 4, **json.loads(args.capture)}
    os.environ.setdefault("LFPROC_PROGRESS", "0")
    warnings.simplefilter("ignore")  # saturation warnings of the brightest scenes: expected
    data = []
    for kind, texture, seed in scenes:
        lf = scene(kind, args.data / texture, seed, args.size)
        data.append((lf, simulate_capture(lf, random_state=seed, **capture_options)))
    print("scenes: " + "; ".join(f"{k} + {Path(t).name} (seed {s})" for k, t, s in scenes)
          + f"; capture {json.dumps(capture_options)}")
    for config in configs:
        cells, start = [], time.perf_counter()
        for lf, capture in data:
            out = reconstruct(capture, **config)
            score = evaluate(out, lf, scale_tolerance_stops=None)
            truth, result = lf.data.mean(-1), out.data.mean(-1)
            dark = truth < 1e-3 * truth.max()
            dark_err = (float(np.median(np.abs(np.log2(np.maximum(result[dark], 1e-9) / truth[dark]))))
                        if dark.any() else float("nan"))
            cells.append((score["pu21_psnr_db"], score["pu21_ssim"], out.attrs["reconstruction"]["iterations_mean"],
                          dark_err))
        seconds = (time.perf_counter() - start) / len(data)
        print(f"{json.dumps(config)}: " + " | ".join(f"{p:.2f} / {s:.3f} / {i:.0f} it / dark {d:.2f}"
                                                   for p, s, i, d in cells)
              + f" | mean {np.mean([c[0] for c in cells]):.2f} dB, {seconds:.0f} s per scene", flush=True)


if __name__ == "__main__":
    main()
