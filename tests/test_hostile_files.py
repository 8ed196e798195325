"""Hostile files: paths leading out of their folder, links and '..' in archives, serial numbers
that are paths, compression bombs; and every command given a damaged file exits 2 with one
line naming the file, no traceback and no output left behind."""

from __future__ import annotations

import io
import json
import os
import sys
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fuzzlib  # noqa: E402

from lfproc.sensor import load_profile, save_profile  # noqa: E402
from lfproc.cli.main import main  # noqa: E402
from lfproc.errors import UnsafeFileError  # noqa: E402
from lfproc.lytro.caldata import WhiteFrame, white_metadata, write_caldata_tar  # noqa: E402
from lfproc.lytro.caldata import read_caldata  # noqa: E402
from lfproc.lytro.whites import load_white_db  # noqa: E402

SERIAL = "B5152102610"


def _tree(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _one_line(capfd, command: str) -> str:
    """stderr of the last command, at the file-descriptor level (C libraries included)."""
    out, err = capfd.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one line on stderr, got {len(lines)}:\n{err}"
    assert lines[0].startswith(f"lfproc {command}: error: "), lines[0]
    assert "Traceback" not in err
    return lines[0]


# -- profiles and their bias sidecar ---------------------------------------------------------
@pytest.fixture
def profile_dir(tmp_path):
    folder = tmp_path / "profiles"
    folder.mkdir()
    base = load_profile("paper-low")
    import dataclasses

    prof = dataclasses.replace(base, name="cam",
                               bias_frames={iso: np.full((8, 8), 200.5, np.float32) for iso in base.iso_values})
    save_profile(prof, folder / "cam.json")
    return folder


@pytest.mark.parametrize("sidecar, match", [
    ("../../../../etc/passwd", r"field 'bias_frame_file': '../../../../etc/passwd' leads outside"),
    ("/etc/passwd", r"field 'bias_frame_file': '/etc/passwd' is an absolute path"),
    ("link.npz", r"field 'bias_frame_file': 'link.npz' leads outside"),
])
def test_profile_sidecar_outside_its_folder_is_refused(profile_dir, capfd, sidecar, match):
    os.symlink("/etc/passwd", profile_dir / "link.npz")
    doc = json.loads((profile_dir / "cam.json").read_text())
    doc["bias_frame_file"] = sidecar
    (profile_dir / "cam.json").write_text(json.dumps(doc))
    with pytest.raises(UnsafeFileError, match=match):
        load_profile(profile_dir / "cam.json")
    capfd.readouterr()
    assert main(["profile", "show", str(profile_dir / "cam.json")]) == 2
    line = _one_line(capfd, "profile")
    assert str(profile_dir / "cam.json") in line and "outside" in line or "absolute" in line


def test_profile_sidecar_checked_against_the_profile(profile_dir):
    from lfproc.errors import FileFormatError

    good = load_profile(profile_dir / "cam.json")
    assert sorted(good.bias_frames) == good.iso_values and good.bias_frames[100].shape == (8, 8)
    side = profile_dir / "cam.bias.npz"
    # another shape than the profile records, an ISO the profile lacks, a NaN frame
    for arrays, match in (({"iso_100": np.zeros((9, 8), np.float32)}, r"is 9 x 8; the profile says 8 x 8"),
                          ({"iso_123": np.zeros((8, 8), np.float32)}, r"member 'iso_123' is not iso_<ISO> of an ISO"),
                          ({"iso_100": np.full((8, 8), np.nan, np.float32)}, "holds NaN or Inf"),
                          ({"iso_100": np.zeros((2, 2, 2), np.float32)}, "expected a 2-D numeric bias frame")):
        np.savez_compressed(side, **arrays)
        with pytest.raises(FileFormatError, match=match):
            load_profile(profile_dir / "cam.json")


def test_bias_sidecar_compression_bomb_is_refused(profile_dir, capfd):
    side = profile_dir / "cam.bias.npz"
    np.savez_compressed(side, iso_100=np.zeros((10240, 10240), np.uint8))  # 100 MiB of zeros in ~100 kB
    assert side.stat().st_size < 1 << 20
    doc = json.loads((profile_dir / "cam.json").read_text())
    doc.pop("bias_frame_shape")
    (profile_dir / "cam.json").write_text(json.dumps(doc))
    tracemalloc.start()
    try:
        with pytest.raises(UnsafeFileError, match=r"cam.bias.npz: the arrays would expand from \d+ to 104857728 "
                                                  r"bytes.*compression bomb"):
            load_profile(profile_dir / "cam.json")
        assert tracemalloc.get_traced_memory()[1] < 16 << 20
    finally:
        tracemalloc.stop()
    capfd.readouterr()
    assert main(["profile", "show", str(profile_dir / "cam.json")]) == 2
    assert "compression bomb" in _one_line(capfd, "profile")


# -- white-image database ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def fuzz_work(tmp_path_factory):
    return tmp_path_factory.mktemp("hostile")


@pytest.fixture
def white_db(fuzz_work, tmp_path):
    reader = fuzzlib.make_white_db_reader(fuzz_work)
    seed = reader.seeds[0]
    folder = tmp_path / "db"
    fuzzlib.write_case(folder, seed, seed.files)
    return folder


@pytest.mark.parametrize("entry_file, match", [
    ("../../../../etc/passwd", "leads outside"), ("/etc/passwd", "is an absolute path"),
    ("link.npz", "leads outside"),
])
def test_white_database_entries_outside_the_folder_are_refused(white_db, fuzz_work, tmp_path, capfd, entry_file,
                                                               match):
    os.symlink("/etc/passwd", white_db / "link.npz")
    index = json.loads((white_db / "whites.json").read_text())
    assert len(load_white_db(white_db).entries) == 2
    index["whites"][1]["file"] = entry_file
    (white_db / "whites.json").write_text(json.dumps(index))
    with pytest.raises(UnsafeFileError, match=rf"whites.json: field 'file of MOD_0001': '{entry_file}' {match}"):
        load_white_db(white_db)
    lfr = tmp_path / "IMG_0001.LFR"
    lfr.write_bytes(fuzzlib._small_lfr(fuzz_work))
    capfd.readouterr()
    assert main(["decode", str(lfr), "--white-db", str(white_db), "-o", str(tmp_path / "out.exr")]) == 2
    assert "whites.json" in _one_line(capfd, "decode")
    assert not (tmp_path / "out.exr").exists()


# -- caldata tars ------------------------------------------------------------------------------
def _caldata_members(tmp_path) -> list[tuple[str, bytes]]:
    rng = np.random.default_rng(7)
    frames = [WhiteFrame(raw=rng.integers(600, 900, (8, 16)).astype(np.uint16),
                         metadata=white_metadata(height=8, width=16), name="MOD_0000")]
    p = write_caldata_tar(tmp_path / "seed.tar", frames, serial=SERIAL)
    members = fuzzlib.read_tar_members(p.read_bytes())
    p.unlink()
    return members


@pytest.mark.parametrize("change, match", [
    (lambda m: [("../../evil.txt", b"x")] + m, r"member '../../evil.txt' leads outside the archive"),
    (lambda m: [("/tmp/evil.txt", b"x")] + m, r"member '/tmp/evil.txt' leads outside the archive"),
    (lambda m: m + [("unitdata/MOD_0009.RAW", None, "symlink", "/etc/passwd")], r"is a link \(to '/etc/passwd'\)"),
    (lambda m: m + [("unitdata/MOD_0009.RAW", None, "hardlink", "/etc/passwd")], "is a link"),
])
def test_caldata_tar_with_escaping_or_link_members_is_refused(tmp_path, capfd, change, match):
    tar = tmp_path / f"caldata-{SERIAL}.tar"
    tar.write_bytes(fuzzlib.build_tar(change(_caldata_members(tmp_path))))
    before = _tree(tmp_path)
    with pytest.raises(UnsafeFileError, match=match):
        read_caldata(tar)
    capfd.readouterr()
    assert main(["whites", str(tar), "-o", str(tmp_path / "db")]) == 2
    assert str(tar) in _one_line(capfd, "whites")
    assert _tree(tmp_path) == before  # no database, no temporaries, nothing extracted


@pytest.mark.parametrize("where", ["unit_info", "txt"])
@pytest.mark.parametrize("serial", ["../../../somewhere/evil", "ABSOLUTE"])
def test_caldata_serial_number_that_is_a_path_is_refused(tmp_path, capfd, where, serial):
    out = tmp_path / "deep" / "er"
    out.mkdir(parents=True)
    if serial == "ABSOLUTE":
        serial = str(tmp_path / "abs" / "evil")
    members = _caldata_members(tmp_path)
    for i, (name, data) in enumerate(members):
        if where == "unit_info" and name.endswith("unit_info.json"):
            doc = json.loads(data)
            doc["camera"]["serialNumber"] = serial
            members[i] = (name, json.dumps(doc).encode())
        if where == "txt":
            if name.endswith("unit_info.json"):
                members[i] = None
            elif name.endswith(".TXT"):
                members[i] = (name, data.replace(SERIAL.encode(), serial.encode()))
    tar = out / "caldata-x.tar"
    tar.write_bytes(fuzzlib.build_tar([m for m in members if m is not None]))
    before = _tree(tmp_path)
    with pytest.raises(UnsafeFileError, match=r"serial number .* cannot be used in a file name"):
        read_caldata(tar)
    capfd.readouterr()
    assert main(["whites", str(tar), "-o", str(out / "db")]) == 2
    line = _one_line(capfd, "whites")
    assert "serial number" in line and str(tar) in line
    assert _tree(tmp_path) == before
    assert not (tmp_path / "somewhere").exists() and not (tmp_path / "abs").exists()


def test_gzip_posing_as_caldata_tar_is_refused_without_expanding_it(tmp_path, capfd):
    """A 128 MiB member in a 130 kB gzip named like a pairing tar (the default expansion floor is 64 MiB)."""
    members = _caldata_members(tmp_path)
    tar = tmp_path / f"caldata-{SERIAL}.tar"
    tar.write_bytes(fuzzlib.bomb_gzip_tar(members, ".RAW", 128 << 20))
    assert tar.stat().st_size < 1 << 20
    tracemalloc.start()
    try:
        with pytest.raises(UnsafeFileError, match="gzip-compressed tar expands beyond .*compression bomb"):
            read_caldata(tar)
        assert tracemalloc.get_traced_memory()[1] < 16 << 20
    finally:
        tracemalloc.stop()
    before = _tree(tmp_path)
    capfd.readouterr()
    assert main(["whites", str(tar), "-o", str(tmp_path / "db")]) == 2
    assert "compression bomb" in _one_line(capfd, "whites")
    assert _tree(tmp_path) == before


# -- capture files -----------------------------------------------------------------------------
def test_capture_compression_bomb_is_refused(tmp_path, capfd):
    """A header consistent with 96 MiB of arrays that compress to about 100 kB."""
    from lfproc.camera.capture import HEADER_NAME, load_capture
    from lfproc.camera.simulate import simulate_capture
    from lfproc.synth import synthesize

    cap = simulate_capture(synthesize("layers", size=(16, 16), views=3, random_state=0), profile="paper-low",
                           shots=1, mask_period=4, random_state=0)
    members = dict(fuzzlib.read_zip_members(cap.save(tmp_path / "seed.capture.npz").read_bytes()))
    header = json.loads(members[HEADER_NAME])
    n = 4096
    header["size"] = [n, n]
    header["arrays"]["dn"]["shape"] = header["arrays"]["iso"]["shape"] = [1, n, n]

    def npy(array_shape, dtype):
        buf = io.BytesIO()
        np.lib.format.write_array_header_1_0(buf, {"descr": np.dtype(dtype).str, "fortran_order": False,
                                                   "shape": array_shape})
        return buf.getvalue() + bytes(int(np.prod(array_shape)) * np.dtype(dtype).itemsize)

    bomb = tmp_path / "bomb.capture.npz"
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=9) as zf:
        zf.writestr(HEADER_NAME, json.dumps(header))
        zf.writestr("dn.npy", npy((1, n, n), np.uint16))
        zf.writestr("iso.npy", npy((1, n, n), np.float32))
        zf.writestr("mask.npy", members["mask.npy"])
    assert bomb.stat().st_size < 1 << 20
    tracemalloc.start()
    try:
        with pytest.raises(UnsafeFileError, match=r"bomb.capture.npz: the capture's arrays would expand from \d+ to "
                                                  r"\d+ bytes.*compression bomb"):
            load_capture(bomb)
        assert tracemalloc.get_traced_memory()[1] < 16 << 20
    finally:
        tracemalloc.stop()
    capfd.readouterr()
    assert main(["info", str(bomb)]) == 2
    assert "compression bomb" in _one_line(capfd, "info")


# -- EXR parts the library cannot decode ------------------------------------------------------
def test_exr_with_undecodable_parts_says_so_in_one_line(tmp_path, capfd):
    from lfproc.io import read_lightfield, write_lightfield
    from lfproc.errors import FileFormatError
    from lfproc.synth import synthesize

    good = tmp_path / "lf.exr"
    write_lightfield(synthesize("layers", size=(16, 16), views=3, random_state=1), good)
    data = good.read_bytes()
    bad = tmp_path / "bad.exr"
    bad.write_bytes(data[: len(data) * 2 // 3])  # the last views' chunks are cut off
    capfd.readouterr()
    with pytest.raises(FileFormatError, match=r"bad.exr: OpenEXR could not decode parts (view_0\d_0\d, )+view_03_03; "
                                              r"the file is corrupt or truncated \(.*EXR_ERR"):
        read_lightfield(bad)
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # the library's own lines are kept off the terminal
    assert main(["info", str(bad)]) == 2
    line = _one_line(capfd, "info")
    assert "could not decode parts" in line and "missing" not in line


# -- every command, given damaged files --------------------------------------------------------
def _lfproc_error_cases(reader, n, tmp_path, base_seed=11):
    """The first ``n`` fuzz cases the reader refuses with an lfproc error (library level)."""
    out = []
    i = 0
    while len(out) < n and i < 40 * n:
        seed, files, _ = fuzzlib.build_case(reader, i, base_seed)
        outcome = fuzzlib.run_case(reader, tmp_path / "probe", seed, files, trace_memory=False)
        if outcome.kind == "lfproc":
            out.append((i, seed, files))
        i += 1
    return out


COMMANDS = [
    ("lytro-container", "info", lambda f, t, aux: ["info", str(f)]),
    ("lytro-capture", "decode", lambda f, t, aux: ["decode", str(f), "--white-db", str(aux["db"]), "-o",
                                                   str(t / "out.exr")]),
    ("exr", "info", lambda f, t, aux: ["info", str(f)]),
    ("exr", "convert", lambda f, t, aux: ["convert", str(f), str(t / "out.exr")]),
    ("exr", "evaluate", lambda f, t, aux: ["evaluate", str(f), str(aux["lf"])]),
    ("exr", "preview", lambda f, t, aux: ["preview", str(f), "-o", str(t / "out.png")]),
    ("profile", "profile", lambda f, t, aux: ["profile", "show", str(f)]),
    ("profile", "simulate", lambda f, t, aux: ["simulate", str(aux["lf"]), "--profile", str(f), "-o",
                                               str(t / "out.capture.npz")]),
    ("manifest", "calibrate", lambda f, t, aux: ["calibrate", str(f), "-o", str(t / "out.json")]),
    ("capture", "info", lambda f, t, aux: ["info", str(f)]),
    ("capture", "preview", lambda f, t, aux: ["preview", str(f), "-o", str(t / "out.png")]),
    ("caldata", "whites", lambda f, t, aux: ["whites", str(f), "-o", str(t / "out_db")]),
    ("white-db", "decode", lambda f, t, aux: ["decode", str(aux["lfr"]), "--white-db", str(f.parent), "-o",
                                              str(t / "out.exr")]),
    ("emva", "calibrate", lambda f, t, aux: ["calibrate", str(f), "-o", str(t / "out.json")]),
]


@pytest.fixture(scope="module")
def aux(fuzz_work):
    from lfproc.io import write_lightfield
    from lfproc.synth import synthesize

    lf = fuzz_work / "aux_lf.exr"
    write_lightfield(synthesize("layers", size=(16, 16), views=3, random_state=2), lf, force=True)
    reader = fuzzlib.make_white_db_reader(fuzz_work)
    db = fuzz_work / "aux_db"
    fuzzlib.write_case(db, reader.seeds[0], reader.seeds[0].files)
    lfr = fuzz_work / "aux_IMG.LFR"
    lfr.write_bytes(fuzzlib._small_lfr(fuzz_work))
    return {"lf": lf, "db": db, "lfr": lfr}


@pytest.mark.parametrize("reader_name, command, args", COMMANDS, ids=[f"{c[0]}-{c[1]}" for c in COMMANDS])
def test_commands_refuse_damaged_files_in_one_line(reader_name, command, args, fuzz_work, aux, tmp_path, capfd):
    reader = fuzzlib.READERS[reader_name](fuzz_work)
    cases = _lfproc_error_cases(reader, 3, tmp_path)
    assert len(cases) == 3
    for i, seed, files in cases:
        case = tmp_path / f"case{i}"
        main_file = fuzzlib.write_case(case, seed, files)
        out = tmp_path / "out"
        out.mkdir(exist_ok=True)
        before = _tree(tmp_path)
        capfd.readouterr()
        assert main(args(main_file, out, aux)) == 2, f"case {i}"
        line = _one_line(capfd, command)
        assert any(name in line for name in [str(case), *files]), f"case {i}: {line}"
        assert _tree(tmp_path) == before, f"case {i} left {_tree(tmp_path) - before}"
