"""lfproc._untrusted: the checked accessors every reader uses (JSON, sizes, npz, tar, paths)."""

from __future__ import annotations

import gzip
import io
import json
import math
import os
import tarfile
import tracemalloc
import zipfile

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lfproc import _untrusted as ut
from lfproc.errors import FileFormatError, LfpFormatError, LfprocError, ProfileError, UnsafeFileError


# -- JSON -----------------------------------------------------------------------------------
def test_parse_json_limits_depth_and_size_before_parsing():
    assert ut.parse_json('{"a": [1, {"b": "]]]]"}]}') == {"a": [1, {"b": "]]]]"}]}
    assert ut.json_depth('{"a": [1, {"b": "]]]]"}]}') == 3  # brackets inside strings do not count
    deep = "[" * 100_000 + "]" * 100_000  # would exhaust the recursion limit of the json module
    with pytest.raises(FileFormatError, match=r"x.json: JSON nested 100000 levels deep; the limit is 64"):
        ut.parse_json(deep, source="x.json")
    with pytest.raises(FileFormatError, match="exceeds the limit of 10 bytes"):
        ut.parse_json('{"a": "0123456789"}', source="x.json", max_bytes=10)
    with pytest.raises(FileFormatError, match="an integer with too many digits"):
        ut.parse_json("9" * 5000, source="x.json")
    with pytest.raises(LfpFormatError, match=r"x.TXT: not UTF-8 text \(byte 1\)"):
        ut.parse_json(b"{\xff}", source="x.TXT", error=LfpFormatError)
    # trailing junk after the document: an error unless asked to ignore it (Lytro TXT files)
    with pytest.raises(FileFormatError, match="Extra data"):
        ut.parse_json('{"a": 1} junk')
    assert ut.parse_json('{"a": 1} junk', trailing="ignore") == {"a": 1}


def test_node_names_file_and_field_and_checks_type_range_finiteness():
    doc = ut.Node(ut.parse_json('{"image": {"w": 7728, "h": 5368.0, "iso": NaN, "gain": 1e999, "s": "12",'
                                ' "flag": true, "list": [1, 2, 3]}}'), "cam.json", error=ProfileError)
    image = doc["image"]
    assert image["w"].as_int(low=1, high=10**5) == 7728
    assert image["h"].as_int() == 5368  # an integral float is an integer
    with pytest.raises(ProfileError, match=r"^cam.json: field 'image.iso': expected a finite number, found nan$"):
        image["iso"].as_float()
    with pytest.raises(ProfileError, match=r"field 'image.gain': expected a finite number, found inf"):
        image["gain"].as_float()
    assert image["gain"].as_float(finite=False) == math.inf
    with pytest.raises(ProfileError, match=r"field 'image.s': expected a number, found a string '12'"):
        image["s"].as_float()
    assert image["s"].as_float(parse_str=True) == 12.0
    with pytest.raises(ProfileError, match=r"field 'image.flag': expected a number, found a boolean True"):
        image["flag"].as_int()  # booleans are never numbers
    with pytest.raises(ProfileError, match=r"field 'image.w': expected an integer <= 5000, found 7728"):
        image["w"].as_int(high=5000)
    with pytest.raises(ProfileError, match=r"^cam.json: missing field 'image.missing'$"):
        image["missing"]
    with pytest.raises(ProfileError, match=r"field 'image.list': expected a list of 0..2 items, found 3"):
        image["list"].as_list(max_len=2)
    with pytest.raises(ProfileError, match=r"field 'image.w': expected an object, found an integer 7728"):
        image["w"]["x"]
    assert image.get("missing") is None and image.opt_float("missing", 2.5) == 2.5
    assert doc.at("image.list.1").as_int() == 2 and doc.at("image.nothing.deeper", None) is None
    assert doc.first("image.nothing", "image.w").as_int() == 7728
    assert image["list"].as_ints(length=3, low=0) == [1, 2, 3]


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True, allow_infinity=True)
                    | st.text(max_size=20), lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=5), c,
                                                                                                max_size=4),
                    max_leaves=12))
def test_node_conversions_raise_only_lfproc_errors(value):
    node = ut.Node({"f": value}, "doc.json")["f"]
    for convert in (lambda: node.as_float(low=0, high=1e6), lambda: node.as_int(low=-5, high=5),
                    lambda: node.as_str(max_len=8, choices=("a", "b")), lambda: node.as_bool(),
                    lambda: node.as_floats(length=2), lambda: node.as_dict(), lambda: node["k"],
                    lambda: node.at("a.0.b"), lambda: node.opt_int("x")):
        try:
            out = convert()
        except LfprocError as exc:
            assert str(exc).startswith("doc.json: ")
        else:  # what is returned passed the checks
            if isinstance(out, float):
                assert 0 <= out <= 1e6
            elif isinstance(out, int) and not isinstance(out, bool):
                assert -5 <= out <= 5


# -- sizes, npy/npz ------------------------------------------------------------------------
def test_check_dims_and_nbytes():
    assert ut.check_dims([5368, 7728.0], source="f") == (5368, 7728)
    for bad, match in (([0, 5], "each side must lie in 1..1048576"), ([-1, 5], "each side"),
                       ([1.5, 2], "expected integers"), ([True, 2], "expected integers"), (["3", 2], "expected integers"),
                       ([1 << 20, 1 << 20], "exceeds the limit")):
        with pytest.raises(FileFormatError, match=match):
            ut.check_dims(bad, source="f")
    assert ut.check_nbytes((10, 10), np.float32) == 400
    with pytest.raises(FileFormatError, match="needs 8000000000000 bytes"):
        ut.check_nbytes((10**6, 10**6), np.float64, source="f")


def _npz(path, **arrays):
    np.savez_compressed(path, **arrays)
    return path


def test_read_npz_checks_headers_before_reading(tmp_path):
    p = _npz(tmp_path / "a.npz", raw=np.arange(12, dtype=np.uint16).reshape(3, 4),
             f=np.asfortranarray(np.arange(6.0).reshape(2, 3)))
    out = ut.read_npz(p)
    np.testing.assert_array_equal(out["raw"], np.arange(12).reshape(3, 4))
    np.testing.assert_array_equal(out["f"], np.arange(6.0).reshape(2, 3))
    with pytest.raises(FileFormatError, match=r"array 'raw': expected shape \(4, 3\), found \(3, 4\)"):
        ut.read_npz(p, expect={"raw": ((4, 3), None)})
    with pytest.raises(FileFormatError, match=r"array 'raw': expected dtype float32, found uint16"):
        ut.read_npz(p, expect={"raw": (None, "float32")})
    with pytest.raises(FileFormatError, match=r"no array 'gone' \(the file holds f, raw\)"):
        ut.read_npz(p, names=["gone"])
    # object arrays are never unpickled
    obj = tmp_path / "o.npz"
    with zipfile.ZipFile(obj, "w") as zf:
        buf = io.BytesIO()
        np.lib.format.write_array(buf, np.array([{"a": 1}], dtype=object), allow_pickle=True)
        zf.writestr("x.npy", buf.getvalue())
    with pytest.raises(FileFormatError, match="dtype object is not a plain numeric type"):
        ut.read_npz(obj)
    # a header announcing more than the member holds (here: a different shape)
    lie = tmp_path / "lie.npz"
    with zipfile.ZipFile(p) as zin, zipfile.ZipFile(lie, "w") as zout:
        data = zin.read("raw.npy").replace(b"(3, 4)", b"(9, 4)")
        zout.writestr("raw.npy", data)
    with pytest.raises(FileFormatError, match="header announces 72 bytes of data .* the member holds 24"):
        ut.read_npz(lie)
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not really")
    with pytest.raises(FileFormatError, match="not a readable .npz/ZIP archive"):
        ut.read_npz(tmp_path / "junk.npz")


def test_read_npz_refuses_a_compression_bomb_without_allocating(tmp_path):
    # 32 MiB of zeros in 32 kB; the floor below which any expansion is accepted is lowered to 1 MiB
    # so that a small bomb shows the rule (the default floor is 64 MiB)
    bomb = _npz(tmp_path / "bomb.npz", raw=np.zeros((1 << 12, 1 << 13), np.uint8))
    assert bomb.stat().st_size < 1 << 16
    tracemalloc.start()
    try:
        with pytest.raises(UnsafeFileError, match=r"would expand from \d+ to 33554560 bytes.*compression bomb"):
            ut.read_npz(bomb, floor=1 << 20)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 << 20
    # the same data are accepted under the default floor
    assert ut.read_npz(bomb)["raw"].shape == (1 << 12, 1 << 13)


# -- tar ------------------------------------------------------------------------------------
def _tar(members, *, compress=False):
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w") as tar:
        for name, data, kind, link in members:
            info = tarfile.TarInfo(name)
            if kind == "sym":
                info.type, info.linkname = tarfile.SYMTYPE, link
                tar.addfile(info)
            elif kind == "hard":
                info.type, info.linkname = tarfile.LNKTYPE, link
                tar.addfile(info)
            else:
                info.size = len(data)
                tar.addfile(info, io.BytesIO(data))
    return gzip.compress(buf.getvalue()) if compress else buf.getvalue()


@pytest.mark.parametrize("member, match", [
    (("../evil.txt", b"x", "file", None), r"member '../evil.txt' leads outside the archive"),
    (("/etc/evil.txt", b"x", "file", None), r"member '/etc/evil.txt' leads outside"),
    (("a/../../evil", b"x", "file", None), "leads outside"),
    (("link", None, "sym", "/etc/passwd"), r"member 'link' is a link \(to '/etc/passwd'\)"),
    (("hard", None, "hard", "ok.txt"), r"member 'hard' is a link"),
])
def test_safe_members_refuses_escapes_and_links(tmp_path, member, match):
    p = tmp_path / "t.tar"
    p.write_bytes(_tar([("ok.txt", b"fine", "file", None), member]))
    with ut.open_tar(p) as tar:
        with pytest.raises(UnsafeFileError, match=match):
            ut.safe_members(tar, source=p)


def test_open_tar_reads_compressed_tars_with_an_expansion_cap(tmp_path):
    p = tmp_path / "t.tar.gz"
    p.write_bytes(_tar([("a.txt", b"hello", "file", None)], compress=True))
    with ut.open_tar(p) as tar:
        (m,) = ut.safe_members(tar)
        assert ut.read_member(tar, m, max_bytes=10) == b"hello"
        with pytest.raises(FileFormatError, match="has 5 bytes, above the limit of 4"):
            ut.read_member(tar, m, max_bytes=4)
    # a gzip posing as a tar whose member expands to 32 MiB (floor lowered to 1 MiB, as above):
    # refused while the headers are read
    bomb = tmp_path / "bomb.tar"
    with gzip.open(bomb, "wb", compresslevel=9) as gz, tarfile.open(fileobj=gz, mode="w|") as tar:
        info = tarfile.TarInfo("MOD_0000.RAW")
        info.size = 32 << 20
        tar.addfile(info, io.BytesIO(bytes(32 << 20)))
    assert bomb.stat().st_size < 1 << 16
    with pytest.raises(UnsafeFileError, match=r"gzip-compressed tar expands beyond \d+ bytes.*compression bomb"):
        with ut.open_tar(bomb, floor=1 << 20) as tar:
            ut.safe_members(tar)
    # a plain tar whose member announces more bytes than the file holds
    cut = tmp_path / "cut.tar"
    cut.write_bytes(_tar([("a.txt", b"x" * 5000, "file", None)])[:3000])
    with pytest.raises(FileFormatError, match="past the end of the archive|truncated"):
        with ut.open_tar(cut) as tar:
            ut.safe_members(tar)
    (tmp_path / "junk.tar").write_bytes(b"\x1f\x8bjunk")
    with pytest.raises(LfpFormatError, match="corrupt gzip-compressed tar"):
        with ut.open_tar(tmp_path / "junk.tar", error=LfpFormatError) as tar:
            ut.safe_members(tar)


# -- paths ----------------------------------------------------------------------------------
def test_resolve_inside_confines_paths_to_the_folder(tmp_path):
    base = tmp_path / "profile"
    (base / "sub").mkdir(parents=True)
    assert ut.resolve_inside(base, "sub/x.npz", source="p.json") == base / "sub" / "x.npz"
    assert ut.resolve_inside(base, "sub\\x.npz") == base / "sub" / "x.npz"  # Windows separators
    for name, match in (("../../../../etc/passwd", r"p.json: field 'bias': '../../../../etc/passwd' leads outside"),
                        ("/etc/passwd", "'/etc/passwd' is an absolute path"),
                        ("sub/../../x", "leads outside"), ("C:\\evil", "absolute path")):
        with pytest.raises(UnsafeFileError, match=match):
            ut.resolve_inside(base, name, source="p.json", field="bias")
    os.symlink("/etc/passwd", base / "link")
    with pytest.raises(UnsafeFileError, match="'link' leads outside"):
        ut.resolve_inside(base, "link")
    # a folder the user names: absolute paths inside it are fine, others are not
    assert ut.resolve_inside(base, str(tmp_path / "x.png"), root=tmp_path) == tmp_path / "x.png"
    with pytest.raises(UnsafeFileError, match="leads outside"):
        ut.resolve_inside(base, "/etc/passwd", root=tmp_path)
    with pytest.raises(FileFormatError, match="expected a file name, found 5"):
        ut.resolve_inside(base, 5)


def test_safe_filename():
    assert ut.safe_filename("B5152102610") == "B5152102610"
    assert ut.safe_filename("B5_MOD-0001.npz") == "B5_MOD-0001.npz"
    for bad in ("../../../somewhere/evil", "/abs/evil", ".hidden", "a/b", "a\\b", "", "x" * 65, "a..b", 7, None,
                "nul\x00"):
        with pytest.raises(UnsafeFileError, match="cannot be used in a file name"):
            ut.safe_filename(bad, what="serial number")


def test_read_bytes_checks_the_size_first(tmp_path):
    p = tmp_path / "big.json"
    with open(p, "wb") as fh:
        fh.truncate(1 << 40)  # a sparse 1 TiB file: reading it would never end
    with pytest.raises(FileFormatError, match="JSON file of 1099511627776 bytes exceeds the limit"):
        ut.load_json(p)
    (tmp_path / "ok.json").write_text(json.dumps({"a": 1}))
    assert ut.load_json(tmp_path / "ok.json")["a"].as_int() == 1
