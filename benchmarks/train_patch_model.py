"""Train the Gaussian patch model of ``lfproc.recon.reconstruct_gmm`` from real HDR photographs.

Usage::

    python benchmarks/train_patch_model.py [--out lfproc/recon/data/gaussian_patch_model.npz] [--components 4]
                                           [--orientations 0] [--patches 60000] [--force]

The training images are the photographs of the ``TUNE`` scenes of :mod:`quality_scenes` (the shared
data's ``hdr/ScanLines_Desk``, ``Cannon``, ``Carrots``, ``StillLife`` and ``hdr_cc0/sunset``,
``forest``), each resized as the scenes resize them for the Lytro size (434 x 625 views), so no
photograph of the ``TEST`` scenes is seen in training. This is the command that made the shipped
model (about a minute on 2 cores).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import quality_scenes  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "lfproc" / "recon" / "data" / "gaussian_patch_model.npz"


def training_images(data=quality_scenes.DATA, shape=(438, 629)):
    names = sorted({f for scene in quality_scenes.TUNE.values() for f in scene[:2]})
    return names, [quality_scenes._photo(data / f, shape) for f in names]


def main() -> None:
    from lfproc.recon import train_patch_model

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--components", type=int, default=4)
    parser.add_argument("--orientations", type=int, default=0,
                        help="of the components, those started from oriented edges (docs/benchmarks.md: 4 of 8 tried)")
    parser.add_argument("--patches", type=int, default=60000)
    parser.add_argument("--margin", type=int, default=2)
    parser.add_argument("--data", type=Path, default=quality_scenes.DATA)
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args()
    if args.orientations and not 0 <= args.orientations <= args.components - 2:
        parser.error(f"--orientations: expected 0 .. --components - 2 = {args.components - 2}, got {args.orientations}")
    t = time.perf_counter()
    names, images = training_images(args.data)
    model = train_patch_model(images, components=args.components, orientations=args.orientations,
                              n_patches=args.patches, margin=args.margin, random_state=0)
    model.attrs.update(source="benchmarks/train_patch_model.py", photographs=names,
                       command=" ".join(["python", "benchmarks/train_patch_model.py"] + sys.argv[1:]))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    model.save(args.out, force=args.force)
    print(f"{args.out}: {model!r}, {time.perf_counter() - t:.0f} s")


if __name__ == "__main__":
    main()
