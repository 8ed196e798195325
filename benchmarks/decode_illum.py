"""Benchmark: decode a full-size (7728 x 5368) virtual Illum capture.

Renders a textured synthetic light field through the virtual Illum (``--sensor full``), builds
the white-image database, then decodes the 0 EV capture in a fresh subprocess (so its peak
memory is the decoder's own) and reports wall time, peak resident memory (``ru_maxrss``) and
PSNR against ``truth.exr`` (linear, 4-pixel border excluded, samples the decoder flags as
unusable -- clipped highlights -- excluded, peak = largest usable truth value).

Usage::

    python benchmarks/decode_illum.py [--work DIR] [--threads 2] [--demosaic opencv-ea]

``--work`` keeps the rendered capture between runs (rendering takes minutes).

PlenoptiCam (PyPI ``plenopticam``, GPL-3.0; never a dependency of lfproc) is tried on the same
capture when ``$PLENOPTICAM_PYTHON`` (or ``/tmp/pcam/bin/python``) is an interpreter that has it,
through ``benchmarks/_plenopticam_driver.py`` in a subprocess (``--no-plenopticam`` skips it).
Result with plenopticam 0.9.1 (numpy 1.26, scipy 1.11 in a throw-away venv) on the full-size
virtual Illum, seed 0: it reads lfproc's LFR (10-bit GRBG Bayer, metadata) and finds the matching
white image in the caldata tar by geometry hash, but its white-image calibration fails --
``LfpCalibrator failed: 'Geometric MLA arrangement not recognized'`` (own micro-image size
estimate; ~2 min, 7.3 GB peak RSS) and ``'Error in MLA dimension estimation'`` with the size given
as 14 px -- so no views come out and no time/PSNR can be compared. On the reduced
``--sensor small`` capture it cannot even decode the white RAW (``LfpDecoder.decode_raw``
hard-codes the 7728x5368 and 3280x3280 sensor sizes). The benchmark prints PlenoptiCam's one-line
error (or, should a later version get through, its times and view shape; scoring its views
against the truth is then still to be written).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DECODE_CHILD = r"""
import json, os, resource, sys, time
import cv2
cv2.setNumThreads(int(os.environ.get("LFPROC_BENCH_THREADS", "2")))
from lfproc.lytro.decode import decode_capture
t = time.perf_counter()
lf = decode_capture(sys.argv[1], white_db=sys.argv[2], demosaic_method=sys.argv[3])
dt = time.perf_counter() - t
import numpy as np
np.save(sys.argv[4], lf.data)
np.save(sys.argv[4].replace(".npy", "_var.npy"), lf.variance)
print(json.dumps({"decode_s": dt, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "shape": list(lf.shape), "white": lf.attrs["white_image"]}))
"""


def run_plenopticam(capture: Path, caldata: Path, out: Path, *, env: dict) -> dict | str:
    """Run ``_plenopticam_driver.py`` under ``$PLENOPTICAM_PYTHON`` (or ``/tmp/pcam/bin/python``).

    Returns the driver's JSON report, or one line saying why PlenoptiCam did not run or failed.
    """
    python = os.environ.get("PLENOPTICAM_PYTHON", "/tmp/pcam/bin/python")
    if not Path(python).is_file():
        return f"not run: no interpreter at {python} (set PLENOPTICAM_PYTHON to a Python with plenopticam)"
    driver = Path(__file__).with_name("_plenopticam_driver.py")
    res = subprocess.run([python, str(driver), str(capture), str(caldata), str(out)],
                         env=dict(env, PYTHONWARNINGS="ignore", MPLBACKEND="Agg"),
                         capture_output=True, text=True, check=False)
    lines = res.stdout.strip().splitlines()
    try:
        rep = json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        tail = (res.stderr.strip().splitlines() or ["no output"])[-1]
        return f"failed: driver exited {res.returncode}: {tail}"
    if "error" in rep:
        return f"failed: {rep['error']}"
    rep["views"] = str(out)
    rep["psnr_db"] = "not computed: scoring PlenoptiCam's views against truth.exr is not written yet"
    return rep


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, help="folder to keep the rendered capture and database")
    ap.add_argument("--threads", type=int, default=2, help="threads for numpy/OpenCV (default 2)")
    ap.add_argument("--demosaic", default="opencv-ea", choices=("opencv-ea", "malvar2004", "bilinear"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-plenopticam", action="store_true", help="do not try PlenoptiCam")
    args = ap.parse_args(argv)
    env = dict(os.environ, OMP_NUM_THREADS=str(args.threads), OPENBLAS_NUM_THREADS=str(args.threads),
               MKL_NUM_THREADS=str(args.threads), LFPROC_BENCH_THREADS=str(args.threads), LFPROC_PROGRESS="0")
    os.environ.update({k: env[k] for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")})
    import numpy as np

    from lfproc import __version__, read_lightfield
    from lfproc.lytro.decode import UNUSABLE_VARIANCE
    from lfproc.lytro.virtual import illum_grid, make_virtual_illum, output_shape, SENSOR_SIZES
    from lfproc.lytro.whites import build_white_db
    from lfproc.synth import synthesize

    work = args.work or Path(tempfile.mkdtemp(prefix="lfproc-bench-illum-"))
    work.mkdir(parents=True, exist_ok=True)
    cam, db = work / "cam", work / "db"
    report = {"benchmark": "decode_illum", "lfproc_version": __version__, "threads": args.threads,
              "demosaic": args.demosaic, "seed": args.seed}
    if not (cam / "truth.json").is_file():
        size = output_shape(illum_grid(SENSOR_SIZES["full"], random_state=0))
        lf = synthesize("layers", size=size, views=5, baseline_px=0.5, random_state=args.seed)
        t = time.perf_counter()
        make_virtual_illum(lf, cam, sensor="full", exposures_ev=[0], seed=args.seed, force=True)
        report["render_s"] = time.perf_counter() - t
    info = json.loads((cam / "truth.json").read_text())
    if not (db / "whites.json").is_file():
        t = time.perf_counter()
        build_white_db(cam / info["caldata"], db, force=True)
        report["whites_s"] = time.perf_counter() - t
    out = work / "decoded.npy"
    res = subprocess.run([sys.executable, "-c", DECODE_CHILD, str(cam / info["truth_capture"]), str(db),
                          args.demosaic, str(out)], env=env, capture_output=True, text=True, check=False)
    if res.returncode:
        print(res.stderr, file=sys.stderr)
        return 1
    report.update(json.loads(res.stdout.strip().splitlines()[-1]))
    data, var = np.load(out), np.load(str(out).replace(".npy", "_var.npy"))
    truth = read_lightfield(cam / "truth.exr").data
    h, w = min(data.shape[2], truth.shape[2]), min(data.shape[3], truth.shape[3])
    sl = (slice(None), slice(None), slice(4, h - 4), slice(4, w - 4))
    ok = var[sl] < UNUSABLE_VARIANCE
    a, b = data[sl][ok], truth[sl][ok]
    report["psnr_db"] = float(10 * np.log10(float(b.max()) ** 2 / float(np.mean((a - b) ** 2))))
    report["usable_fraction"] = float(ok.mean())
    report["target"] = {"decode_s": 20, "peak_rss_mb": 4096}
    report["plenopticam"] = "skipped (--no-plenopticam)" if args.no_plenopticam else run_plenopticam(
        cam / info["truth_capture"], cam / info["caldata"], work / "plenopticam_views.npy", env=env)
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
