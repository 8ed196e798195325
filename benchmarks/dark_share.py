"""Benchmark: what a reconstruction does to the darkest part of a scene (PU21 barely sees it).

Usage::

    python benchmarks/reconstruct_realistic.py --save DIR ...        # results and truths as .npy
    python benchmarks/dark_share.py DIR [DIR2 ...] [--capture "2 random"] [--fraction 0.3]

For every scene saved in each folder: over the darkest ``--fraction`` of the truth's centre-view
luminance (PU21 weights), the median of result / truth and the share of pixels below a quarter
of the truth (dark blotches). Used in docs/benchmarks.md for the gmm overlap weights' noise bound.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def main() -> None:
    from lfproc.metrics import PU21_LUMA

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folders", type=Path, nargs="+")
    parser.add_argument("--capture", default="2 random")
    parser.add_argument("--fraction", type=float, default=0.3)
    args = parser.parse_args()
    tag = args.capture.replace(" ", "_")
    for folder in args.folders:
        for truth_path in sorted(folder.glob("*__truth.npy")):
            scene = truth_path.name.split("__")[0]
            result_path = folder / f"{scene}__{tag}.npy"
            if not result_path.is_file():
                continue
            truth, result = np.load(truth_path), np.load(result_path)
            v, u = truth.shape[0] // 2, truth.shape[1] // 2
            t, r = truth[v, u] @ PU21_LUMA, result[v, u] @ PU21_LUMA
            dark = (t < np.quantile(t, args.fraction)) & (t > 0)
            ratio = r[dark] / t[dark]
            print(f"{folder.name} {scene}: darkest {100 * args.fraction:.0f} %: median result/truth "
                  f"{np.median(ratio):.3f}, below a quarter of the truth {100 * np.mean(ratio < 0.25):.1f} %")


if __name__ == "__main__":
    main()
