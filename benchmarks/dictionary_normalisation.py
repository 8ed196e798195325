"""Which patch normalisation to learn HDR dictionaries with: measured, not guessed.

Trains two dictionaries on the same synthetic patches, one with every patch scaled to unit l2
norm (``l2``, lfproc's choice) and one on the raw radiance (``none``), and scores the
10-sparse (``--sparsity``) approximation of light fields neither saw: lfproc synth scenes
textured with the HDR photographs of ``../shared/data/hdr`` (PU21-PSNR and relative error,
beside a separable DCT dictionary of the same size).

    python benchmarks/dictionary_normalisation.py                 # tiny-size dictionaries, ~3 min
    python benchmarks/dictionary_normalisation.py --patch 5,5,8,8,3 --atoms 2560 --patches 30000
"""

from __future__ import annotations

import argparse
import glob
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_lightfields(shared: Path, size: int):
    from lfproc.synth import synthesize

    photos = sorted(glob.glob(str(shared / "hdr" / "ScanLines_*.exr")))
    if not photos:
        raise SystemExit(f"no HDR photographs in {shared / 'hdr'} (set --shared)")
    kinds = ["layers", "lamps", "window", "checker"]
    return [synthesize(kinds[i % 4], size=(size, size), views=5, baseline_px=1.0, textures=[p], random_state=9000 + i)
            for i, p in enumerate(photos)]


def main():
    from lfproc.dictionary import evaluate_dictionary, train_dictionary

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--patch", default="5,5,4,4,3")
    ap.add_argument("--atoms", type=int, default=1200)
    ap.add_argument("--patches", type=int, default=12000)
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("--sparsity", type=int, default=10)
    ap.add_argument("--size", type=int, default=128, help="view size of the test light fields")
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "data")
    args = ap.parse_args()
    patch = tuple(int(v) for v in args.patch.split(","))
    tests = test_lightfields(args.shared, args.size)
    print(f"patch {list(patch)}, {args.atoms} atoms, {args.patches} synthetic training patches, "
          f"{args.iterations} iterations; {len(tests)} textured test light fields of {args.size}^2")
    print(f"{'normalise':>9} {'train s':>8} {'PU21-PSNR':>10} {'rel. error':>10} {'DCT PU21':>9} {'DCT rel.':>9}")
    for norm in ("l2", "none"):
        t0 = time.perf_counter()
        d = train_dictionary(preset="default", synthetic=True, patch=patch, atoms=args.atoms, patches=args.patches,
                             max_iter=args.iterations, n_nonzero_coefs=args.sparsity, normalise=norm, random_state=0)
        seconds = time.perf_counter() - t0
        r = evaluate_dictionary(d, tests)
        print(f"{norm:>9} {seconds:>8.0f} {r['pu21_psnr_db']:>10.2f} {r['relative_error']:>10.3f} "
              f"{r['dct_pu21_psnr_db']:>9.2f} {r['dct_relative_error']:>9.3f}", flush=True)


if __name__ == "__main__":
    main()
