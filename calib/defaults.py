"""The profiles lfproc ships, built from their stated assumptions.

``python -m lfproc.calib.defaults`` rewrites ``lfproc/sensor/profiles/*.json``; a test checks that the
shipped files equal what this module builds, so the numbers below are the only source.
"""

from __future__ import annotations

from lfproc.sensor._profile import _PROFILE_DIR
from lfproc.sensor import CameraProfile, IsoFigures, paper_gain_dn_per_e, save_profile

__all__ = ["paper_profile", "illum_profile", "build_all"]

# The paper's simulated sensor (Miandji et al., "Compressive HDR Light Field Imaging Using a
# Single Multi-ISO Sensor", IEEE TCI 2021, section IV). The paper gives the noise levels
# (Table VI) and the gain formula but not the ADC depth, full well or black level: lfproc
# chooses a 12-bit ADC, a 20000 e- full well (as DeepULFCam's sensor model) and a 64 DN
# black level so that read noise below black is kept, not clipped.
PAPER_NOISE = {  # level: (dark current e-/s, read noise e- rms)
    "none": (0.0, 0.0),
    "low": (0.1, 1.1),
    "medium": (1.0, 2.0),
    "high": (10.0, 2.8),
}
PAPER_ISOS = (100, 200, 400, 800, 1600, 3200, 6400)
PAPER_ADC_BITS = 12
PAPER_FULL_WELL_E = 20000.0
PAPER_BLACK_DN = 64.0


def _iso_table(isos, *, adc_bits, full_well_e, read_noise_e, dark_current_e_per_s, black_level_dn):
    table = {}
    for iso in isos:
        gain = paper_gain_dn_per_e(iso, adc_bits=adc_bits, full_well_e=full_well_e)
        table[iso] = IsoFigures(
            gain_dn_per_e=gain,
            read_noise_e=read_noise_e,
            read_noise_dn=read_noise_e * gain,
            dark_current_e_per_s=dark_current_e_per_s,
            black_level_dn=black_level_dn,
            full_well_e=full_well_e,
        )
    return table


def paper_profile(level: str) -> CameraProfile:
    """The paper's simulated multi-ISO sensor at noise level none/low/medium/high."""
    dark, read = PAPER_NOISE[level]
    return CameraProfile(
        name=f"paper-{level}",
        description=f"Simulated sensor of Miandji et al. (multi-ISO HDR LF), noise level '{level}' (Table VI): "
        f"dark current {dark} e-/s, read noise {read} e-; 12-bit ADC, 20000 e- full well and 64 DN black "
        "level chosen by lfproc; gain h = ISO/100 * (2^12-1)/FWD.",
        adc_bits=PAPER_ADC_BITS,
        white_level_dn=2**PAPER_ADC_BITS - 1,
        black_level_dn=PAPER_BLACK_DN,
        full_well_e=PAPER_FULL_WELL_E,
        gamma=1.0,
        cfa_pattern="RGGB",
        dark_current_e_per_s=dark,
        isos=_iso_table(PAPER_ISOS, adc_bits=PAPER_ADC_BITS, full_well_e=PAPER_FULL_WELL_E, read_noise_e=read,
                        dark_current_e_per_s=dark, black_level_dn=PAPER_BLACK_DN),
        source={"kind": "nominal", "reference": "Miandji et al., Compressive HDR Light Field Imaging Using a Single "
                                                "Multi-ISO Sensor, IEEE TCI 2021, Table VI"},
    )


def illum_profile() -> CameraProfile:
    """A nominal Lytro Illum: 10-bit raw, black 64, white 1023, GRBG.

    The levels and the mosaic are those an Illum's frame metadata records, as read by the
    Light Field Toolbox (D. G. Dansereau, O. Pizarro and S. B. Williams, "Decoding, Calibration
    and Rectification for Lenselet-Based Plenoptic Cameras", CVPR 2013).

    The Illum's full well, read noise and dark current are not published; the values here
    (4500 e-, 2.5 e-, 1 e-/s) are typical of 1.4 um-pixel CMOS sensors and are marked as
    nominal. Calibrate a real camera with ``lfproc calibrate`` to replace them.
    """
    isos = (80, 100, 200, 400, 800, 1600, 3200)
    return CameraProfile(
        name="illum",
        description="Nominal Lytro Illum sensor (10-bit, black 64, white 1023, GRBG); full well, read noise and "
        "dark current are typical values, not measurements.",
        adc_bits=10,
        white_level_dn=1023,
        black_level_dn=64,
        full_well_e=4500.0,
        gamma=1.0,
        cfa_pattern="GRBG",
        dark_current_e_per_s=1.0,
        isos=_iso_table(isos, adc_bits=10, full_well_e=4500.0, read_noise_e=2.5, dark_current_e_per_s=1.0,
                        black_level_dn=64.0),
        source={"kind": "nominal", "reference": "Lytro Illum frame metadata (levels, CFA), as decoded by Dansereau "
                                                "et al., CVPR 2013; other figures typical"},
    )


def build_all() -> dict[str, CameraProfile]:
    out = {f"paper-{level}": paper_profile(level) for level in PAPER_NOISE}
    out["illum"] = illum_profile()
    return out


if __name__ == "__main__":  # pragma: no cover
    folder = _PROFILE_DIR  # lfproc/sensor/profiles: the shipped profiles live beside their type
    for name, profile in build_all().items():
        save_profile(profile, folder / f"{name}.json", force=True)
        print(f"wrote {folder / (name + '.json')}")
