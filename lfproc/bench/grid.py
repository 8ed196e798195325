"""The bench's grid: presets, cells and jobs.

The settings are the experiments of Miandji, Nguyen, Hajisharif, Unger and Guillemot,
"Compressive HDR light field imaging using a single multi-ISO sensor", IEEE TCI 2021, section
IV.

A **cell** is one row of ``results.csv``: one scene, one acquisition (``method``, ISO
pattern, shots, ISO set, noise level, relative exposure) and, for the per-shot baselines,
one merge. A **job** is the work that produces cells: one simulated capture and its
reconstruction(s); the two merges of a per-shot baseline share a job (the per-shot
reconstructions are the expensive part), every other job has one cell.

Methods (the ``method`` column):

``joint``            lfproc's joint multi-ISO reconstruction, ISO pattern random, row or block
``dual-iso``         the same with the dual-ISO row pattern (lowest and highest ISO of the set)
``individual-iso``   one global-ISO shot per ISO of the set, each reconstructed, then merged
``bracketing``       2-4 shots at the lowest ISO, exposures (0.5, 8) / (0.5, 2, 8) / (0.5, 2, 4, 8),
                     each reconstructed, then merged
``bracketing-joint`` the same shots reconstructed jointly in one solve (lfproc's variant)

Presets (one function builds both; the numbers are in :data:`PRESETS`):

``quick``  scenes cropped to their central 48 x 48 pixels; noise ``low``, ISO set
           (100, 400, 800, 1600) unless said otherwise; joint and dual-ISO for every pattern x
           1, 2, 3 shots; 2 shots with random, row and dual patterns for the two wider ISO
           sets; 2 random-pattern shots at noise none, medium, high and at relative exposures
           4, 32, 256 (lfproc's addition: a saturation sweep); the baselines (individual ISO,
           bracketing 2/3/4 with both merges, bracketing-joint 2/3/4). 35 cells per scene.
``paper``  full size; the full grid pattern x shots (1, 2, 3) x ISO set (3) x noise (4), the
           exposure sweep, and the baselines at every noise level. 191 cells per scene.

Seeds. Every cell records its seed: a hash of the bench seed, the scene and the
acquisition's *draw group* -- ``(method, shots)`` -- but not the ISO pattern, ISO set, noise
level or exposure, so cells that differ only in those share the mask codes, the random ISO
map and the noise stream (common random numbers: their differences are less noisy; the
simulator draws layout, mask and noise from separate streams, :func:`lfproc.camera.capture.capture_streams`,
so a random layout does not move the mask). With the pattern in the group, as before, random, row
and block captures had different masks: on the realistic test scenes at 96 x 128 that alone put block
0.43 dB ahead of random (docs/benchmarks.md, stop 17).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from typing import Any

from .._shared.validation import check_choice
from ..errors import InputError

__all__ = ["METHODS", "NOISE_LEVELS", "ISO_SETS", "PATTERNS", "PRESETS", "Preset", "Cell", "Job", "get_preset",
           "grid_cells", "group_jobs", "REFERENCE"]

METHODS = ("joint", "dual-iso", "individual-iso", "bracketing", "bracketing-joint")
PATTERNS = ("random", "row", "block", "dual")
NOISE_LEVELS = ("none", "low", "medium", "high")
#: The paper's three ISO sets (Miandji et al., IEEE TCI 2021, section IV-B); every one is in the
#: shipped paper-* profiles.
ISO_SETS = ((100, 400, 800, 1600), (100, 800, 1600, 3200), (100, 1600, 3200, 6400))
SHOTS = (1, 2, 3)
BRACKETING_SHOTS = (2, 3, 4)
#: Version of the cell files' content; changing what a cell computes bumps it (old cells are ignored).
CELL_SCHEMA = 2  # 2: the ML merge of the per-shot baselines takes 6 fixed-point updates


@dataclass(frozen=True)
class Preset:
    """Grid and settings of a bench preset (module notes).

    Parameters
    ----------
    name : str
        ``"quick"`` or ``"paper"``.
    description : str
        One line for the report and ``--help``.
    crop : tuple of 2 int or None
        Central crop ``(H, W)`` of every scene's views, in pixels (None: full size).
    noise_levels : tuple of str
        Noise levels of the grid (``none``, ``low``, ``medium``, ``high``).
    iso_sets : tuple of tuple of int
        ISO sets of the grid; the first is the reference.
    full_grid : bool
        Every pattern x shots x ISO set x noise level (``paper``), or the reduced grid (``quick``).
    exposures : tuple of float
        Relative exposures of the saturation sweep.
    baseline_noise : tuple of str
        Noise levels at which the per-shot baselines run.
    mask_period : int or None
        Mask tiling period in pixels (None: no tiling).
    recon : dict, default {}
        Reconstruction options (``method`` and the method's options), overridden by the
        ``recon_options`` of :func:`lfproc.bench.run_bench`.
    exposure_s : float, default 0.004
        Exposure time of a shot in seconds.
    """

    name: str
    description: str
    crop: tuple[int, int] | None
    noise_levels: tuple[str, ...]
    iso_sets: tuple[tuple[int, ...], ...]
    full_grid: bool
    exposures: tuple[float, ...]
    baseline_noise: tuple[str, ...]
    mask_period: int | None
    recon: dict[str, Any] = field(default_factory=dict)
    exposure_s: float = 0.004


#: The settings the main tables use (the paper's Table I setting as lfproc reads it).
REFERENCE = {"iso_set": ISO_SETS[0], "noise": "low", "exposure": 1.0}

PRESETS = {
    "quick": Preset(
        name="quick",
        description="two small scenes in minutes: central 48 x 48 crop; every pattern x 1-3 shots at the reference "
                    "settings, the wider ISO sets and other noise levels at 2 shots, a saturation sweep, the baselines",
        crop=(48, 48), noise_levels=NOISE_LEVELS, iso_sets=ISO_SETS, full_grid=False,
        exposures=(4.0, 32.0, 256.0), baseline_noise=("low",), mask_period=4, recon={}),
    "paper": Preset(
        name="paper",
        description="the full grid at full size: pattern x shots x ISO set x noise, the saturation sweep, the "
                    "baselines at every noise level",
        crop=None, noise_levels=NOISE_LEVELS, iso_sets=ISO_SETS, full_grid=True, exposures=(4.0, 32.0, 256.0),
        baseline_noise=NOISE_LEVELS, mask_period=None, recon={}),
}


def get_preset(name: str) -> Preset:
    """The bench preset of this name (a :class:`Preset` is returned as is).

    Parameters
    ----------
    name : {"quick", "paper"} or Preset

    Returns
    -------
    Preset

    Raises
    ------
    InputError
        An unknown name.

    Examples
    --------
    >>> from lfproc.bench import get_preset
    >>> p = get_preset("quick")
    >>> p.crop, p.mask_period, p.full_grid
    ((48, 48), 4, False)
    """
    if isinstance(name, Preset):
        return name
    check_choice("preset", name, tuple(PRESETS))
    return PRESETS[name]


def _iso_text(isos) -> str:
    return ",".join(str(int(v)) for v in isos)


@dataclass(frozen=True)
class Cell:
    """One row of results.csv (module notes).

    Parameters
    ----------
    scene : str
        Scene name.
    method : str
        One of :data:`METHODS`.
    iso_pattern : str
        ISO pattern (one of :data:`PATTERNS`; the baselines use a global ISO).
    shots : int
        Number of shots.
    isos : tuple of int
        ISO set.
    noise : str
        Noise level (one of :data:`NOISE_LEVELS`).
    exposure : float, default 1.0
        Relative exposure (the saturation sweep).
    merge : str, default ""
        Merge of the per-shot baselines (``"debevec"`` or ``"ml"``; empty for the others).
    """

    scene: str
    method: str
    iso_pattern: str
    shots: int
    isos: tuple[int, ...]
    noise: str
    exposure: float = 1.0
    merge: str = ""

    @property
    def draw_group(self) -> tuple:
        # bracketing and bracketing-joint share their captures: the comparison isolates the solve
        kind = {"individual-iso": "individual-iso", "bracketing": "bracketing", "bracketing-joint": "bracketing"}
        return (kind.get(self.method, "joint"), self.shots)

    @property
    def job_key(self) -> tuple:
        return (self.scene, self.method, self.iso_pattern, self.shots, self.isos, self.noise, self.exposure)

    def describe(self) -> dict[str, Any]:
        d = asdict(self)
        d["isos"] = _iso_text(self.isos)
        return d

    def label(self) -> str:
        parts = [self.scene, self.method]
        if self.merge:
            parts.append(self.merge)
        if self.method in ("joint", "dual-iso"):
            parts.append(self.iso_pattern)
        parts += [f"{self.shots} shot{'s' if self.shots > 1 else ''}", f"ISO {_iso_text(self.isos)}",
                  f"noise {self.noise}"]
        if self.exposure != 1.0:
            parts.append(f"exposure x{self.exposure:g}")
        return ", ".join(parts)


@dataclass
class Job:
    """The cells one simulated capture serves (module notes)."""

    key: tuple
    cells: list[Cell]

    @property
    def cell(self) -> Cell:
        return self.cells[0]

    @property
    def cost(self) -> float:
        """Rough relative cost: reconstructions x measurements each."""
        c = self.cell
        if c.method in ("individual-iso", "bracketing"):
            return float(c.shots)  # one single-shot solve per shot
        return 0.6 + 0.4 * c.shots


def _joint(scene, pattern, shots, isos, noise, exposure=1.0) -> Cell:
    method = "dual-iso" if pattern == "dual" else "joint"
    return Cell(scene=scene, method=method, iso_pattern=pattern, shots=shots, isos=tuple(isos), noise=noise,
                exposure=float(exposure))


def _baselines(scene, isos, noise) -> list[Cell]:
    cells = [Cell(scene, "individual-iso", "global", len(isos), tuple(isos), noise, 1.0, m) for m in ("debevec", "ml")]
    for n in BRACKETING_SHOTS:
        cells += [Cell(scene, "bracketing", "global", n, tuple(isos), noise, 1.0, m) for m in ("debevec", "ml")]
        cells.append(Cell(scene, "bracketing-joint", "global", n, tuple(isos), noise, 1.0))
    return cells


def grid_cells(preset: Preset | str, scenes: list[str]) -> list[Cell]:
    """Every cell of the grid for these scene names, without duplicates, in a fixed order.

    Parameters
    ----------
    preset : Preset or {"quick", "paper"}
    scenes : list of str
        Scene names (at least one).

    Returns
    -------
    list of Cell

    Raises
    ------
    InputError
        No scenes, or an unknown preset.

    Examples
    --------
    >>> from lfproc.bench import grid_cells
    >>> len(grid_cells("quick", ["lamps"])), len(grid_cells("quick", ["lamps", "window"]))
    (35, 70)
    >>> len(grid_cells("paper", ["lamps"]))
    191
    >>> grid_cells("quick", ["lamps"])[0].label()
    'lamps, joint, random, 1 shot, ISO 100,400,800,1600, noise low'
    """
    preset = get_preset(preset)
    if not scenes:
        raise InputError("scenes: expected at least one light field, got none")
    ref_isos, ref_noise = REFERENCE["iso_set"], REFERENCE["noise"]
    out: list[Cell] = []
    for scene in scenes:
        if preset.full_grid:
            for isos in preset.iso_sets:
                for noise in preset.noise_levels:
                    for pattern in PATTERNS:
                        for shots in SHOTS:
                            out.append(_joint(scene, pattern, shots, isos, noise))
        else:
            for pattern in PATTERNS:
                for shots in SHOTS:
                    out.append(_joint(scene, pattern, shots, ref_isos, ref_noise))
            for isos in preset.iso_sets[1:]:
                for pattern in ("random", "row", "dual"):
                    out.append(_joint(scene, pattern, 2, isos, ref_noise))
            for noise in preset.noise_levels:
                out.append(_joint(scene, "random", 2, ref_isos, noise))
        for exposure in preset.exposures:
            out.append(_joint(scene, "random", 2, ref_isos, ref_noise, exposure))
        for noise in preset.baseline_noise:
            out += _baselines(scene, ref_isos, noise)
    seen = set()
    unique = []
    for c in out:
        if c not in seen:
            seen.add(c)
            unique.append(c)
    return unique


def group_jobs(cells: list[Cell]) -> list[Job]:
    """Cells grouped by the capture they need (module notes), in first-seen order."""
    jobs: dict[tuple, Job] = {}
    for c in cells:
        jobs.setdefault(c.job_key, Job(key=c.job_key, cells=[])).cells.append(c)
    return list(jobs.values())


def cell_seed(base_seed: int, cell: Cell) -> int:
    """The cell's simulation seed (module notes: shared within a draw group)."""
    text = json.dumps([int(base_seed), cell.scene, *cell.draw_group])
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:6], "big")


def cell_id(cell: Cell, context: dict[str, Any]) -> str:
    """A file-name-safe identity of a cell and everything its result depends on."""
    text = json.dumps({"cell": cell.describe(), "context": context, "schema": CELL_SCHEMA}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]
