"""Realistic HDR light fields for the reconstruction-quality benchmarks: real HDR photographs as layers.

Usage::

    python benchmarks/quality_scenes.py --out DIR [--size H W] [--set tune|test|holdout|all]

Every scene is two real HDR photographs of the shared data (``../shared/data/hdr``,
``hdr_cc0``) as fronto-parallel layers (:func:`lfproc.synth.render_layers`: exact
occlusion, bilinear sub-pixel translation): a background that fills the view and a
foreground cut out by a smooth random shape (about half of the view), at the disparities of
the scene's row (integer -1 / +1, or sub-pixel as a lenslet camera gives). The photographs
are resized to cover the view (aspect kept, centre crop, ``cv2.INTER_AREA``), so at the
Lytro size (434 x 625) they keep their own texture density and at 96 x 128 they are
reduced ("dense" scenes). The foreground keeps its photograph's dynamic range and is scaled to
``2 ** gain_stops`` times the background's median luminance.

Two disjoint sets: ``TUNE`` (choose settings on these; their photographs train the shipped patch prior,
``train_patch_model.py``) and ``TEST`` (report on these), which share no photograph (a test checks it); and
``HOLDOUT`` (stop 46), the test photographs in new compositions, never looked at while choosing settings. Until stop 32
the fourth test scene was ``sunrise-desk``, whose ``ScanLines_Desk`` is also desk-cannon's (so tuned on and trained
on); it is ``sunrise-interior`` since. Written as ``DIR/<name>.exr`` light fields (``lfproc.io``), so the CLI can use
them.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

DATA = Path(os.environ.get("LFPROC_SHARED_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data"))

#: name -> (background photo, foreground photo, background disparity, foreground disparity, gain stops, seed)
TUNE = {
    "desk-cannon": ("hdr/ScanLines_Desk.exr", "hdr/ScanLines_Cannon.exr", -1.0, 1.0, 0.0, 1),
    "sunset-carrots": ("hdr_cc0/sunset.exr", "hdr/ScanLines_Carrots.exr", -0.5, 0.75, -1.0, 2),
    "forest-stilllife": ("hdr_cc0/forest.exr", "hdr/ScanLines_StillLife.exr", -1.0, 1.0, 1.0, 3),
}
TEST = {
    "city-interior": ("hdr_cc0/city.exr", "hdr_cc0/interior.exr", -1.0, 1.0, 0.0, 11),
    "courtyard-candle": ("hdr_cc0/courtyard.exr", "hdr/ScanLines_CandleGlass.exr", -1.0, 1.0, -1.0, 12),
    "night-studio": ("hdr_cc0/night.exr", "hdr_cc0/studio.exr", -1.0, 1.0, 1.0, 13),
    "sunrise-interior": ("hdr_cc0/sunrise.exr", "hdr_cc0/interior.exr", -0.4, 0.6, 0.0, 14),
}
#: Made at stop 46 (2026-12-07) and never tuned on: the test scenes' photographs in new pairs, layouts, gains and
#: disparities (two off the search grid), to see whether figures reached by rules chosen while looking at the test
#: scenes hold on compositions nobody looked at. They share photographs with ``TEST`` (the shared data has no others
#: outside ``TUNE``), so they are a check of the compositions, not of new photographs.
HOLDOUT = {
    "interior-night": ("hdr_cc0/interior.exr", "hdr_cc0/night.exr", -0.75, 0.5, 1.0, 21),
    "courtyard-studio": ("hdr_cc0/courtyard.exr", "hdr_cc0/studio.exr", 1.0, -0.25, -2.0, 22),
    "sunrise-candle": ("hdr_cc0/sunrise.exr", "hdr/ScanLines_CandleGlass.exr", -0.3, 0.9, 0.0, 23),
}
SETS = {"tune": TUNE, "test": TEST, "holdout": HOLDOUT, "all": {**TUNE, **TEST, **HOLDOUT}}


def _photo(path: Path, shape: tuple[int, int]) -> np.ndarray:
    import cv2

    from lfproc.io import read_image

    img, _ = read_image(path, negative="clip", nonfinite="zero")
    img = np.asarray(img, np.float32)
    if img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    img = img[..., :3]
    h, w = shape
    f = max(h / img.shape[0], w / img.shape[1])
    rh, rw = max(h, round(img.shape[0] * f)), max(w, round(img.shape[1] * f))
    img = cv2.resize(img, (rw, rh), interpolation=cv2.INTER_AREA if f < 1 else cv2.INTER_CUBIC)
    t, l = (rh - h) // 2, (rw - w) // 2
    return np.maximum(img[t:t + h, l:l + w], 0)


def _shape(shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """A smooth random shape covering about half of the raster, anti-aliased over about one pixel."""
    from scipy.ndimage import gaussian_filter

    h, w = shape
    noise = gaussian_filter(rng.standard_normal((h, w)), sigma=min(h, w) / 6, mode="wrap")
    noise -= np.median(noise)
    grad = float(np.median(np.hypot(*np.gradient(noise))))  # the field's change per pixel near its zero level
    return np.clip(0.5 + noise / (grad + 1e-12), 0, 1).astype(np.float32)


def make_scene(name: str, size: tuple[int, int] = (434, 625), views: int = 5, data: Path = DATA):
    """The light field of scene ``name`` (``TUNE``, ``TEST`` or ``HOLDOUT``) at ``size``."""
    from lfproc import LightField
    from lfproc.lightfield import luminance
    from lfproc.synth import Layer, render_layers

    back, front, d_back, d_front, gain, seed = SETS["all"][name]
    rng = np.random.default_rng(seed)
    h, w = size
    m = int(np.ceil(max(abs(d_back), abs(d_front)) * (views // 2))) + 2
    shape = (h + 2 * m, w + 2 * m)
    b = _photo(data / back, shape)
    f = _photo(data / front, shape)
    f *= np.float32(2.0 ** gain * np.median(luminance(b)) / max(float(np.median(luminance(f))), 1e-30))
    alpha = _shape(shape, rng)
    layers = [Layer(b, np.ones(shape, np.float32), d_back, name=back), Layer(f, alpha, d_front, name=front)]
    lf, disparity = render_layers(layers, size=(h, w), views=views)
    return LightField(lf, units="relative", colour_space="linear-srgb", disparity=disparity, source=f"scene:{name}",
                      attrs={"scene": name, "layers": [back, front], "disparities_px": [d_back, d_front],
                             "gain_stops": gain, "seed": seed, "size": [h, w]})


def main() -> None:
    from lfproc.io import write_lightfield

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--size", type=int, nargs=2, default=[434, 625], metavar=("H", "W"))
    parser.add_argument("--set", choices=sorted(SETS), default="all")
    parser.add_argument("--data", type=Path, default=DATA)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name in SETS[args.set]:
        lf = make_scene(name, tuple(args.size), data=args.data)
        d = lf.data[lf.data > 0]
        print(f"{name}: {np.log2(d.max() / np.percentile(d, 0.1)):.1f} stops")
        write_lightfield(lf, args.out / f"{name}.exr", force=True)


if __name__ == "__main__":
    main()
