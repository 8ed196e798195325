"""Fuzzing every reader with damaged and hostile files (cases built by ``tests/fuzzlib.py``).

Each case must end in success or an lfproc error (``LfprocError``), never another exception,
within a time budget (SIGALRM) and a memory budget (tracemalloc peak below 256 MiB plus 50
times the input's size). Seeds are files lfproc writes (light-field EXR, capture ``.npz``,
profile JSON + bias sidecar, manifests, caldata tars of the virtual Illum's layout, white
databases, Illum ``.LFR``) and, when ``../shared/data/lytro`` is present, the real Lytro
containers. ``benchmarks/fuzz_readers.py`` runs the same cases by the ten thousand.

Hypothesis strategies then put arbitrary JSON values into the metadata fields each reader
takes (Lytro frame metadata, profile, capture header, white-database entry, manifest rows,
the EXR ``lfproc`` attribute).
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fuzzlib  # noqa: E402

from lfproc import _untrusted as ut  # noqa: E402
from lfproc.errors import LfprocError  # noqa: E402

#: Cases per reader in the normal run (a few hundred each; the benchmark runs 10,000+).
CASES = {"lytro-container": 150, "lytro-capture": 200, "exr": 150, "profile": 150, "manifest": 120, "capture": 150,
         "caldata": 150, "white-db": 150, "emva": 300}
BASE_SEED = 2026


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


@pytest.fixture(autouse=True)
def small_bombs(monkeypatch):
    """Compression bombs of 64 MiB against a 4 MiB expansion floor: the rule is the same as with
    the defaults (1 GiB bombs, 64 MiB floor; see the benchmark) and the suite stays fast."""
    monkeypatch.setattr(ut, "EXPANSION_FLOOR", 4 << 20)
    monkeypatch.setattr(fuzzlib, "BOMB_BYTES", 64 << 20)


def _run(reader, n, tmp_path, base_seed=BASE_SEED):
    kinds: Counter = Counter()
    bad = []
    for i in range(n):
        seed, files, mutator = fuzzlib.build_case(reader, i, base_seed)
        outcome = fuzzlib.run_case(reader, tmp_path / "case", seed, files, budget_s=5.0)
        kinds[outcome.kind] += 1
        if outcome.kind not in ("ok", "lfproc"):
            bad.append(f"case {i} ({seed.name}, {mutator}): {outcome.kind}: {outcome.detail}")
        elif outcome.warnings:  # numpy warnings on hostile values: a value went unchecked (and the CLI
            bad.append(f"case {i} ({seed.name}, {mutator}): warned: {outcome.warnings[0]}")  # prints 2 lines)
    return kinds, bad


#: Cases per reader in the fast run (``-m "not slow"``): the first cases of the same sequence.
FAST_CASES = 20


@pytest.mark.parametrize("name", list(fuzzlib.READERS))
@pytest.mark.parametrize("fast", [True, pytest.param(False, marks=pytest.mark.slow)], ids=["fast", "full"])
def test_reader_survives_damaged_and_hostile_files(name, fast, work, tmp_path):
    n = FAST_CASES if fast else CASES[name]
    reader = fuzzlib.READERS[name](work)
    kinds, bad = _run(reader, n, tmp_path)
    assert not bad, f"{len(bad)} of {n} cases outside success/LfprocError:\n" + "\n".join(bad[:20])
    # the mutations reach both outcomes: some inputs are refused, some still read
    assert kinds["lfproc"] > n // 10 and (fast or kinds["ok"] > 0), kinds


@pytest.mark.slow  # 100 cases on the real containers
def test_real_lytro_containers_survive_mutations(lytro_dir, work, tmp_path):
    """The real containers of ../shared/data/lytro (skipped with the reason when absent)."""
    reader = fuzzlib.make_lytro_container_reader(work)
    reader.seeds = [s for s in reader.seeds if s.extra.get("real")]
    assert len(reader.seeds) >= 4
    kinds, bad = _run(reader, 100, tmp_path, base_seed=7)
    assert not bad, "\n".join(bad[:20])
    assert kinds["lfproc"] > 10 and kinds["ok"] > 0, kinds


def test_outcomes_are_classified(work, tmp_path):
    """The harness itself: a crash, a hang and a memory blow-up are reported as such."""
    import time

    def crash(path, seed):
        raise KeyError("x")

    def hang(path, seed):
        time.sleep(5)

    def hog(path, seed):
        return np.ones(40 << 20, np.uint8)

    seed = fuzzlib.Seed("s", {"a.bin": b"x"}, "a.bin")
    for target, kind, kw in ((crash, "crash", {}), (hang, "hang", {"budget_s": 0.2}),
                             (hog, "memory", {"memory_budget": 8 << 20})):
        reader = fuzzlib.Reader("t", "t", [seed], [(1, fuzzlib.mutate_file_bytes)], target)
        assert fuzzlib.run_case(reader, tmp_path / "c", seed, seed.files, **kw).kind == kind


# -- Hypothesis: arbitrary JSON values in the metadata fields ---------------------------------
json_values = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-2**70, max_value=2**70)
    | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=12)
    | st.sampled_from(["../../../../etc/passwd", "/etc/passwd", "sha1-" + "0" * 40, "B01", "F01", "r,gr:gb,b"]),
    lambda children: st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=6), children, max_size=3),
    max_leaves=8)
SETTINGS = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _paths_of(doc, limit=400):
    return [p for p in fuzzlib._paths(doc) if p][:limit]


def _set(doc, path, value):
    doc = json.loads(json.dumps(doc))
    parent = fuzzlib._get(doc, path[:-1])
    parent[path[-1]] = value
    return doc


def _refuses_cleanly(call):
    try:
        call()
    except LfprocError:
        pass


@pytest.fixture(scope="module")
def docs(work):
    """Metadata documents of each reader, from files lfproc writes."""
    from lfproc.sensor import load_profile
    from lfproc.lytro.container import illum_metadata
    from lfproc.lytro.caldata import white_metadata
    from lfproc.synth import synthesize
    from lfproc.camera.simulate import simulate_capture

    cap = simulate_capture(synthesize("layers", size=(16, 16), views=3, random_state=0), profile="paper-low",
                           shots=1, random_state=0)
    path = cap.save(work / "hyp.capture.npz", force=True)
    import zipfile

    with zipfile.ZipFile(path) as zf:
        members = [(i.filename, zf.read(i)) for i in zf.infolist()]
    white_db = fuzzlib.make_white_db_reader(work)
    index = json.loads(white_db.seeds[0].files["whites.json"])
    return {"illum": illum_metadata(height=24, width=32), "white": white_metadata(height=8, width=16),
            "profile": load_profile("paper-low").to_json(), "capture": (path, members), "white_entry": index["whites"][0],
            "exr": {"lfproc_version": "0", "views": [3, 3], "size": [16, 16], "channels": 3, "units": "relative",
                    "colour_space": "linear-srgb", "exposure_s": 0.01, "iso": 100, "saturation_level": None,
                    "source": "x", "attrs": {}}}


@pytest.mark.slow  # Hypothesis on full Lytro frames
@SETTINGS
@given(data=st.data())
def test_lytro_frame_metadata_fields(docs, data):
    from lfproc.lytro.capture import _packing, _size, frame_fields

    doc = docs[data.draw(st.sampled_from(["illum", "white"]))]
    path = data.draw(st.sampled_from(_paths_of(doc)))
    meta = _set(doc, path, data.draw(json_values))
    _refuses_cleanly(lambda: (frame_fields(meta, {"camera": {"serialNumber": "B5"}}, source="m.json"),
                              _size(meta, "m.json"), _packing(meta, "m.json")))


@SETTINGS
@given(data=st.data())
def test_profile_fields(docs, data):
    from lfproc.sensor import CameraProfile

    path = data.draw(st.sampled_from(_paths_of(docs["profile"])))
    doc = _set(docs["profile"], path, data.draw(json_values))
    _refuses_cleanly(lambda: CameraProfile.from_json(doc, where="p.json").saturation_dn(100))


@SETTINGS
@given(data=st.data())
def test_capture_header_fields(docs, data, tmp_path_factory):
    from lfproc.camera.capture import HEADER_NAME, load_capture

    src, members = docs["capture"]
    header = json.loads(dict(members)[HEADER_NAME])
    path = data.draw(st.sampled_from([p for p in _paths_of(header) if p[0] != "profile" or len(p) < 3]))
    header = _set(header, path, data.draw(json_values))
    out = tmp_path_factory.mktemp("hyp") / "c.capture.npz"
    out.write_bytes(fuzzlib.build_zip([(HEADER_NAME, fuzzlib._dump(header).encode())] + members[1:]))
    _refuses_cleanly(lambda: load_capture(out))


@SETTINGS
@given(data=st.data())
def test_white_database_entry_fields(docs, data):
    from lfproc.lytro.whites import WhiteEntry

    path = data.draw(st.sampled_from(_paths_of(docs["white_entry"])))
    entry = _set(docs["white_entry"], path, data.draw(json_values))
    _refuses_cleanly(lambda: WhiteEntry.from_dict(entry, where="whites.json"))


@SETTINGS
@given(row=st.fixed_dictionaries({"path": json_values | st.just("a.png"), "kind": json_values | st.just("bias"),
                                  "iso": json_values, "exposure_s": json_values},
                                 optional={"temperature_c": json_values, "group": json_values,
                                           "cfa_pattern": json_values}))
def test_manifest_rows(row, tmp_path_factory):
    from lfproc.calib.frames import read_manifest

    folder = tmp_path_factory.mktemp("m")
    (folder / "m.json").write_text(fuzzlib._dump({"frames": [row]}))
    _refuses_cleanly(lambda: read_manifest(folder / "m.json"))


@SETTINGS
@given(data=st.data())
def test_exr_lfproc_attribute(docs, data):
    from lfproc.io.lightfield_files import _exr_metadata

    path = data.draw(st.sampled_from(_paths_of(docs["exr"])))
    doc = _set(docs["exr"], path, data.draw(json_values))
    _refuses_cleanly(lambda: _exr_metadata(Path("lf.exr"), fuzzlib._dump(doc)))
