"""Benchmark: 8-bit JPEG brackets merged by lfproc (debevec, ml) and by OpenCV, against a known HDR image.

Usage: ``python benchmarks/merge_8bit.py [--data ../shared/data] [--exposures 16] [--size 512 768]
[--repeat 3] [--images NAME ...] [--step EV] [--memorial] [--deciles]``

Reference: each real HDR photograph (``hdr/ScanLines_*.exr``, ``hdr_cc0/*.exr`` of the shared
data) is resized (area) to ``--size`` and turned into an 8-bit JPEG bracket by
:func:`lfproc.bracket.simulate_ldr_bracket`: exposures 1 EV apart (``--step``) centred on the median
luminance (``--step`` stops apart), a camera-like response (highlight shoulder + sRGB), photon noise (20 000 e- full
well) and 3 e- read noise, 8-bit rounding, JPEG quality 90 with 4:2:0 chroma (OpenCV). The
photograph is the reference: the error is the RMS of ln(luminance) after one fitted gain
(:func:`lfproc.metrics.log_luminance_error`), over the pixels well exposed (codes 8..247 in all
channels) in at least one exposure. Times: best of ``--repeat`` wall-clock runs, response
recovery included (OpenCV: CalibrateDebevec + MergeDebevec with their defaults; lfproc:
merge_debevec / merge_ml_codes8 with theirs, 2 threads).

``--memorial``: the configuration of Debevec's Memorial bracket (16 frames one stop apart, 1/32 s to
1024 s; that bracket itself is not on this machine): ``--exposures 16`` with those times. ``--deciles``:
per image, the deciles of the reference luminance among the pixels that at least two frames expose
well (codes 8..247 in all channels), and in each the median ratio of lfproc ml's merged luminance to
lfproc debevec's (no gain fitted: both are relative to g(128) = 0), and the log2-luminance RMSE
(gain fitted) of OpenCV, lfproc debevec and lfproc ml over those pixels. Numpy warnings raised by
the merges are counted and reported (run with ``python -W error::RuntimeWarning`` to make them fatal).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
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


def luminance(rgb):
    return np.asarray(rgb, np.float64) @ np.array([0.2126, 0.7152, 0.0722])


def print_deciles(name, hdr, codes, r_cv, r_deb, r_ml, *, n_warnings: int) -> dict:
    """The per-decile table of ``--deciles`` (module notes); returns its numbers."""
    from lfproc.metrics import log_luminance_error

    good = ((codes >= 8) & (codes <= 247)).all(axis=-1).sum(axis=0)  # frames that expose each pixel well
    mask = good >= 2
    y_ref = luminance(hdr)
    mask &= y_ref > 0
    edges = np.quantile(y_ref[mask], np.linspace(0, 1, 11))
    which = np.clip(np.searchsorted(edges, y_ref, side="right") - 1, 0, 9)
    y_deb, y_ml = luminance(r_deb), luminance(r_ml)
    rmse = {k: log_luminance_error(r, hdr, mask=mask) / np.log(2) for k, r in
            (("opencv", r_cv), ("debevec", r_deb), ("ml", r_ml))}
    print(f"  {name}: {mask.mean():.0%} of pixels exposed well by >= 2 frames; numpy warnings: {n_warnings}")
    print(f"  {'decile':>6s} {'ref lum range':>21s} {'ml/deb':>7s} {'rmse cv':>8s} {'rmse deb':>8s} {'rmse ml':>8s}")
    ratios = []
    for d in range(10):
        sel = mask & (which == d)
        ratio = float(np.median(y_ml[sel] / np.maximum(y_deb[sel], 1e-30)))
        ratios.append(ratio)
        per = [log_luminance_error(r, hdr, mask=sel) / np.log(2) for r in (r_cv, r_deb, r_ml)]
        print(f"  {d + 1:6d} {edges[d]:10.3g}-{edges[d + 1]:<10.3g} {ratio:7.3f} " + " ".join(f"{e:8.4f}" for e in per))
    worst = max(ratios, key=lambda r: abs(r - 1))
    print(f"  log2-luminance RMSE: opencv {rmse['opencv']:.4f}, lfproc debevec {rmse['debevec']:.4f}, "
          f"lfproc ml {rmse['ml']:.4f}; worst ml/debevec decile ratio {worst:.3f} "
          f"({'within' if abs(worst - 1) <= 0.10 else 'NOT within'} 10 %); lower than OpenCV: "
          f"debevec {'yes' if rmse['debevec'] < rmse['opencv'] else 'NO'}, ml {'yes' if rmse['ml'] < rmse['opencv'] else 'NO'}")
    return {"ratios": ratios, "rmse": rmse}


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
    p.add_argument("--step", type=float, default=1.0, metavar="EV", help="stops between exposures (default 1)")
    p.add_argument("--memorial", action="store_true", help="16 exposures one stop apart, 1/32 s to 1024 s")
    p.add_argument("--deciles", action="store_true", help="per-decile ML/Debevec ratios and log2 RMSEs (see above)")
    args = p.parse_args(argv)
    if args.memorial:
        args.exposures = 16
    if not args.data.is_dir():
        print(f"no shared data at {args.data} (give --data)", file=sys.stderr)
        return 2
    n = args.exposures
    if args.memorial:
        args.step = 1.0
    times = [2.0 ** (k - 5) for k in range(n)] if args.memorial else [2.0 ** (args.step * (k - n // 2)) for k in range(n)]
    h, w = args.size
    print(f"{n} exposures {args.step:g} EV apart ({times[0]:g} s to {times[-1]:g} s), {h} x {w}, JPEG q90; error = RMS ln-luminance (gain fitted), well-exposed pixels")
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

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            t_cv, r_cv = best_of(opencv, args.repeat)
            t_deb, (r_deb, _) = best_of(lambda: merge_debevec(codes, exposures_s=times, random_state=0, n_threads=2),
                                        args.repeat)
            t_ml, (r_ml, _, _) = best_of(lambda: merge_ml_codes8(codes, exposures_s=times, random_state=0,
                                                                 n_threads=2), args.repeat)
        numpy_warnings = [w for w in caught if issubclass(w.category, RuntimeWarning)]
        for w in numpy_warnings:
            print(f"  numpy warning: {w.category.__name__}: {w.message} ({w.filename}:{w.lineno})")
        if args.deciles:
            print_deciles(name, hdr, codes, r_cv, r_deb, r_ml, n_warnings=len(numpy_warnings))
        errs = [log_luminance_error(r, hdr, mask=mask) for r in (r_cv, r_deb, r_ml)]
        totals += errs
        cells = [f"{e:.4f} {tm:5.2f}s" for e, tm in zip(errs, (t_cv, t_deb, t_ml))]
        print(f"{name:28s} {cells[0]:>16s} {cells[1]:>16s} {cells[2]:>16s}  ({mask.mean():.0%} of pixels)")
    print(f"{'mean error':28s} {totals[0] / len(args.images):16.4f} {totals[1] / len(args.images):16.4f} "
          f"{totals[2] / len(args.images):16.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
