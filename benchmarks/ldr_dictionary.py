"""Benchmark: which dictionary for the per-shot baselines -- the HDR one, or one trained on LDR patches?

The paper reconstructs each shot of its individual-ISO and bracketing baselines "with an LDR
dictionary". lfproc's per-shot mode (:mod:`lfproc.bench.baselines`) uses the same
dictionary as the joint method. This script measures the difference on small scenes:

* ``hdr``: ``lfproc dictionary train --synthetic --preset tiny`` (K-SVD on the synthetic HDR
  training scenes);
* ``ldr``: the same training scenes, each clipped at a random level 1/2 to 1/16 of its peak
  (what a single ISO 100 to 1600 exposure keeps of it), same preset and seed.

Both reconstruct the individual-ISO (4 shots) and bracketing (3 shots) captures of two
test scenes per shot, merged with Debevec hat weights and with the ML merge, scored with
PU21-PSNR and log-PSNR against the truth. Usage::

    python benchmarks/ldr_dictionary.py [--size 48] [--noise low]

Prints one line per scene, baseline, merge and dictionary. About 15 s on the shared 2-core
machine. Measured (lfproc.recon defaults, noise low, 48 x 48): the two dictionaries differ by at
most 0.03 dB PU21-PSNR and 0.07 dB log-PSNR on every line (16.8-21.4 dB PU21), so the per-shot
baselines use the joint method's dictionary.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def clipped(lfs, rng):
    from lfproc import LightField

    out = []
    for lf in lfs:
        level = float(lf.data.max()) / 2.0 ** rng.uniform(1, 4)
        out.append(LightField(np.minimum(lf.data, level), units=lf.units))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=int, default=48)
    parser.add_argument("--noise", default="low")
    args = parser.parse_args()

    from lfproc.bench import reconstruct_per_shot
    from lfproc.camera.simulate import NOISE_PROFILES, simulate_capture
    from lfproc.dictionary import get_preset, train_dictionary
    from lfproc.dictionary._train import synthetic_lightfields
    from lfproc.metrics import evaluate
    from lfproc.synth import synthesize

    preset = get_preset("tiny")
    t0 = time.perf_counter()
    hdr = train_dictionary(preset="tiny", synthetic=True, random_state=0)
    t_hdr = time.perf_counter() - t0
    scenes = list(synthetic_lightfields(preset.synthetic_scenes, size=preset.synthetic_size, random_state=0))
    t0 = time.perf_counter()
    ldr = train_dictionary(clipped(scenes, np.random.default_rng(0)), preset="tiny", random_state=0)
    t_ldr = time.perf_counter() - t0
    print(f"trained: hdr {t_hdr:.0f} s, ldr {t_ldr:.0f} s (tiny preset: patch {hdr.patch}, {hdr.n_atoms} atoms)")
    tests = {"layers": synthesize("layers", size=(args.size, args.size), random_state=11),
             "window": synthesize("window", size=(args.size, args.size), random_state=12)}
    print(f"{'scene':8s} {'baseline':16s} {'merge':8s} {'dict':4s} {'PU21-PSNR':>9s} {'log-PSNR':>9s}")
    for name, lf in tests.items():
        for baseline, shots in (("individual-iso", 4), ("bracketing", 3)):
            capture = simulate_capture(lf, profile=NOISE_PROFILES[args.noise], baseline=baseline, shots=shots,
                                       mask_period=4, random_state=1)
            for label, dictionary in (("hdr", hdr), ("ldr", ldr)):
                out = reconstruct_per_shot(capture, dictionary, merges=("debevec", "ml"))
                for merge, result in out.items():
                    s = evaluate(result, lf, scale_tolerance_stops=None)
                    print(f"{name:8s} {baseline:16s} {merge:8s} {label:4s} {s['pu21_psnr_db']:9.2f} "
                          f"{s['log_psnr_db']:9.2f}", flush=True)


if __name__ == "__main__":
    main()
