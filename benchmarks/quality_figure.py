"""Figure: centre view and EPI of truth, result and error at one exposure, before and after (README, docs).

Usage::

    python benchmarks/reconstruct_realistic.py --save BEFORE ...                 # lfproc's dictionary method
    python benchmarks/reconstruct_realistic.py --save AFTER --method gmm ...      # the Gaussian patch models
    python benchmarks/quality_figure.py --before BEFORE --after AFTER --scenes city-interior,night-studio \\
        --capture "2 random" -o docs/figures/quality_before_after.png

``--after-capture C`` takes the after column from capture ``C`` of ``--after`` (one run's medium-noise and noise-free
results side by side: ``--before DIR --after DIR --capture "2 random" --after-capture "2 random none"``).
``--zoom N`` shows N x N pixels around the truth's brightest pixel, or around ``--at SCENE=Y,X``, white at its maximum
or at ``--white-percentile P`` of the window (colours around a small light). The refit stage's
outputs (``refit_stage.py run DUMP --save DIR``: ``<scene>__refit.npy``) serve with ``--capture refit``.

One row per scene: the truth, the result before and after (centre view over a horizontal EPI of
the middle row, the 5 views of the centre angular row stretched), all tone-mapped with the truth's
white point (``x / (1 + x)`` of the luminance over its 99th percentile, gamma 2.2), and the error
of each result in stops (log2 of result over truth luminance, centre view, -2..2, blue: too dark).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def _tone(img: np.ndarray, white: float) -> np.ndarray:
    from lfproc.lightfield import luminance

    y = luminance(img)
    scale = (y / white) / (1 + y / white) / np.maximum(y, 1e-30)
    return np.clip(img * scale[..., None], 0, 1) ** (1 / 2.2)


def _epi(lf: np.ndarray, stretch: int = 8) -> np.ndarray:
    return np.repeat(lf[lf.shape[0] // 2, :, lf.shape[2] // 2], stretch, axis=0)


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lfproc.lightfield import luminance

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", type=Path, required=True)
    parser.add_argument("--after", type=Path, required=True)
    parser.add_argument("--scenes", required=True)
    parser.add_argument("--capture", default="2 random")
    parser.add_argument("--after-capture", default=None, metavar="CAPTURE",
                        help="the after column's capture, when not --capture's (noise-free against medium noise)")
    parser.add_argument("--labels", default="before: dictionary (lfproc reconstruct),after: --method gmm")
    parser.add_argument("--zoom", type=int, default=0,
                        help="show N x N pixels around the truth's brightest centre-view pixel (white: its maximum)")
    parser.add_argument("--at", action="append", default=[], metavar="SCENE=Y,X",
                        help="with --zoom: centre that scene's window on centre-view pixel (Y, X), not its brightest")
    parser.add_argument("--white-percentile", type=float, default=None, metavar="P",
                        help="with --zoom: white at this percentile of the window's luminance, not its maximum "
                             "(colour around a small light)")
    parser.add_argument("-o", "--output", type=Path, required=True)
    args = parser.parse_args()
    if args.white_percentile is not None and not 0 < args.white_percentile <= 100:
        parser.error(f"--white-percentile: expected a percentile in (0, 100], got {args.white_percentile}")
    if args.zoom < 0:
        parser.error(f"--zoom: expected a window size in pixels >= 0 (0: whole frames), got {args.zoom}")
    at = {}
    for item in args.at:
        name, _, yx = item.partition("=")
        try:
            at[name] = tuple(int(v) for v in yx.split(","))
            if len(at[name]) != 2:
                raise ValueError
        except ValueError:
            parser.error(f"--at: expected SCENE=Y,X (two integers), got {item!r}")
    scenes = args.scenes.split(",")
    if at and not args.zoom:
        parser.error("--at: expected with --zoom N (it centres the zoomed window), got no --zoom")
    if args.white_percentile is not None and not args.zoom:
        parser.error("--white-percentile: expected with --zoom N (whole frames use the 99th), got no --zoom")
    if set(at) - set(scenes):
        parser.error(f"--at: expected a scene of --scenes ({args.scenes}), got {sorted(set(at) - set(scenes))[0]!r}")
    labels = args.labels.split(",")
    tag = args.capture.replace(" ", "_")
    after_tag = (args.after_capture or args.capture).replace(" ", "_")
    for path in [d / f"{scene}__{t}.npy" for scene in scenes
                 for d, t in ((args.before, "truth"), (args.before, tag), (args.after, after_tag))]:
        if not path.is_file():
            parser.error(f"{path}: expected a result saved by reconstruct_realistic.py --save, got no such file")
    fig, axes = plt.subplots(len(scenes), 5, figsize=(20, 3.6 * len(scenes)), constrained_layout=True, squeeze=False)
    for row, scene in zip(axes, scenes):
        truth = np.load(args.before / f"{scene}__truth.npy")
        results = [np.load(args.before / f"{scene}__{tag}.npy"), np.load(args.after / f"{scene}__{after_tag}.npy")]
        white = float(np.percentile(luminance(truth[2, 2]), 99))
        if args.zoom > min(truth.shape[2:4]):
            parser.error(f"--zoom: expected at most {min(truth.shape[2:4])} pixels ({scene}'s size), got {args.zoom}")
        if args.zoom:  # a window around the brightest light, at its own white point
            lum = luminance(truth[2, 2])
            iy, ix = at.get(scene) or np.unravel_index(np.argmax(lum), lum.shape)
            y0 = int(np.clip(iy - args.zoom // 2, 0, lum.shape[0] - args.zoom))
            x0 = int(np.clip(ix - args.zoom // 2, 0, lum.shape[1] - args.zoom))
            window = (slice(None), slice(None), slice(y0, y0 + args.zoom), slice(x0, x0 + args.zoom))
            truth, results = truth[window], [r[window] for r in results]
            window_lum = luminance(truth[2, 2])
            white = float(window_lum.max() if args.white_percentile is None
                          else np.percentile(window_lum, args.white_percentile))
        panels = [("truth", truth)] + list(zip(labels, results))
        for ax, (name, lf) in zip(row[:3], panels):
            ax.imshow(np.vstack([_tone(lf[2, 2], white), _tone(_epi(lf), white)]), interpolation="nearest")
            ax.set_title(f"{scene}: {name}", fontsize=9)
            ax.axis("off")
        for ax, (name, lf) in zip(row[3:], panels[1:]):
            err = np.log2(np.maximum(luminance(lf[2, 2]), 1e-30) / np.maximum(luminance(truth[2, 2]), 1e-30))
            im = ax.imshow(np.clip(err, -2, 2), cmap="RdBu_r", vmin=-2, vmax=2, interpolation="nearest")
            ax.set_title(f"error in stops, {name.split(':')[0]} (median |e| {np.median(np.abs(err)):.2f})", fontsize=9)
            ax.axis("off")
        fig.colorbar(im, ax=row[3:], fraction=0.04, label="log2(result / truth)")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.output, dpi=60)
    print(args.output)


if __name__ == "__main__":
    main()
