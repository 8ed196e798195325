"""Benchmark: 8-bit JPEG brackets merged by lfproc (debevec, ml) and by OpenCV, against a known HDR image.

Usage: ``python benchmarks/merge_8bit.py [--data ../shared/data] [--exposures 16] [--size 512 768]
[--repeat 3] [--images NAME ...]``

Reference: each real HDR photograph (``hdr/ScanLines_*.exr``, ``hdr_cc0/*.exr`` of the shared
data) is resized (area) to ``--size`` and turned into an 8-bit JPEG bracket by
:func:`lfproc.bracket.simulate_ldr_bracket`: exposures 1 EV apart centred on the median
luminance, a camera-like response (highlight shoulder + sRGB), photon noise (20 000 e- full
well) and 3 e- read noise, 8-bit rounding, JPEG quality 90 with 4:2:0 chroma (OpenCV). The
photograph is the reference: the error is the RMS of ln(luminance) after one fitted gain
(:func:`lfproc.metrics.log_luminance_error`), over the pixels well exposed (codes 8..247 in all
channels) in at least one exposure. Times: best of ``--repeat`` wall-clock runs, response
recovery included (OpenCV: CalibrateDebevec + MergeDebevec with their defaults; lfproc:
merge_debevec / merge_ml_codes8 with theirs, 2 threads).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

DEFAULT_IMAGES = ("hdr/ScanLines_Desk.exr", "hdr/ScanLines_StillLife.exr", "hdr/ScanLines_CandleGlass.exr",
                  "hdr_cc0/courtyard.exr", "hdr_cc0/forest.exr", "hdr_cc0/city.exr")


def best_of(fn, repeat: int):
    best, out = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def main(argv=None) -> int:
    import cv2

    from lfproc.hdr import simulate_ldr_bracket
    from lfproc.io import read_lightfield
    from lfproc.hdr import merge_debevec, merge_ml_codes8
    from lfproc.metrics import log_luminance_error

    root = Path(__file__).resolve().parents[1]
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=root.parent / "shared" / "data")
    p.add_argument("--exposures", type=int, default=16)
    p.add_argument("--size", type=int, nargs=2, default=(512, 768), metavar=("H", "W"))
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--images", nargs="*", default=list(DEFAULT_IMAGES))
    args = p.parse_args(argv)
    if not args.data.is_dir():
        print(f"no shared data at {args.data} (give --data)", file=sys.stderr)
        return 2
    n = args.exposures
    times = [2.0 ** (k - n // 2) for k in range(n)]
    h, w = args.size
    print(f"{n} exposures 1 EV apart, {h} x {w}, JPEG q90; error = RMS ln-luminance (gain fitted), well-exposed pixels")
    print(f"{'image':28s} {'opencv':>16s} {'lfproc debevec':>16s} {'lfproc ml':>16s}")
    totals = np.zeros(3)
    for name in args.images:
        path = args.data / name
        if not path.exists():
            print(f"{name}: not found, skipped")
            continue
        hdr = read_lightfield(path, negative="clip").data[0, 0]
        hdr = cv2.resize(hdr, (w, h), interpolation=cv2.INTER_AREA)
        codes, sim = simulate_ldr_bracket(hdr, times, random_state=0)
        mask = sim["well_exposed"]
        bgr = [np.ascontiguousarray(c[..., ::-1]) for c in codes]
        tt = np.array(times, np.float32)

        def opencv():
            resp = cv2.createCalibrateDebevec().process(bgr, tt)
            return cv2.createMergeDebevec().process(bgr, tt, resp)[..., ::-1]

        t_cv, r_cv = best_of(opencv, args.repeat)
        t_deb, (r_deb, _) = best_of(lambda: merge_debevec(codes, exposures_s=times, random_state=0, n_threads=2),
                                    args.repeat)
        t_ml, (r_ml, _, _) = best_of(lambda: merge_ml_codes8(codes, exposures_s=times, random_state=0, n_threads=2),
                                     args.repeat)
        errs = [log_luminance_error(r, hdr, mask=mask) for r in (r_cv, r_deb, r_ml)]
        totals += errs
        cells = [f"{e:.4f} {tm:5.2f}s" for e, tm in zip(errs, (t_cv, t_deb, t_ml))]
        print(f"{name:28s} {cells[0]:>16s} {cells[1]:>16s} {cells[2]:>16s}  ({mask.mean():.0%} of pixels)")
    print(f"{'mean error':28s} {totals[0] / len(args.images):16.4f} {totals[1] / len(args.images):16.4f} "
          f"{totals[2] / len(args.images):16.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
