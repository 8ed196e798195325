"""Lytro raw packings: known bytes, round trips, agreement with imageio's unpacker, errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lfproc.errors import LfpFormatError, ShapeError
from lfproc.lytro.raw import (pack_raw10, pack_raw12, pack_raw16, raw_byte_count, unpack_raw, unpack_raw10,
                              unpack_raw12, unpack_raw16)


def test_sensor_byte_counts_match_real_file_sizes():
    assert raw_byte_count(5368, 7728, 10) == 51_854_880  # Illum .RAW
    assert raw_byte_count(3280, 3280, 12) == 16_137_600  # F01 frame


def test_raw10_known_bytes():
    # p_k = (b_k << 2) | ((b4 >> 2k) & 3): 1023 -> b0=255 low 3; 0; 512 -> 128 low 0; 3 -> 0 low 3
    raw = np.array([[1023, 0, 512, 3]], dtype=np.uint16)
    packed = pack_raw10(raw)
    assert packed == bytes([255, 0, 128, 0, 0b11_00_00_11])
    np.testing.assert_array_equal(unpack_raw10(packed, 1, 4), raw)
    # a second group: all pixels 1 -> high bytes 0, low bits 01 in each field
    assert pack_raw10(np.ones((1, 4), np.uint16)) == bytes([0, 0, 0, 0, 0b01010101])


def test_raw12_known_bytes_big_endian():
    raw = np.array([[0xABC, 0x123]], dtype=np.uint16)
    assert pack_raw12(raw) == bytes([0xAB, 0xC1, 0x23])
    np.testing.assert_array_equal(unpack_raw12(bytes([0xAB, 0xC1, 0x23]), 1, 2), raw)


def test_raw16_little_endian():
    raw = np.array([[1, 513]], dtype=np.uint16)
    assert pack_raw16(raw) == bytes([1, 0, 1, 2])
    np.testing.assert_array_equal(unpack_raw16(bytes([1, 0, 1, 2]), 1, 2), raw)


# -- Hypothesis against a bit-by-bit reference ---------------------------------------------------
# Independent reference: the packings written out pixel by pixel in plain Python from their
# specifications (the layout the known-bytes tests above spell out), not lfproc's vectorised code.
# derandomize=True: the same examples on every run (also the suite's profile, conftest.py).

def _ref_pack10(raw) -> bytes:
    """Illum RAW10: per 4 pixels, their high 8 bits in 4 bytes, then one byte of the low 2 bits,
    pixel k in bits 2k..2k+1."""
    out = bytearray()
    flat = [int(v) for v in np.asarray(raw).ravel()]
    for g in range(0, len(flat), 4):
        group = flat[g:g + 4]
        out += bytes(p >> 2 for p in group)
        out.append(sum((p & 3) << (2 * k) for k, p in enumerate(group)))
    return bytes(out)


def _ref_unpack10(data: bytes, h: int, w: int) -> np.ndarray:
    pixels = []
    for g in range(0, len(data), 5):
        b = data[g:g + 5]
        pixels += [(b[k] << 2) | ((b[4] >> (2 * k)) & 3) for k in range(4)]
    return np.array(pixels, dtype=np.uint16).reshape(h, w)


def _ref_pack12(raw) -> bytes:
    """F01 RAW12, big-endian: per 2 pixels, p0's high 8 bits, p0's low 4 bits then p1's high 4, p1's low 8."""
    out = bytearray()
    flat = [int(v) for v in np.asarray(raw).ravel()]
    for p0, p1 in zip(flat[0::2], flat[1::2]):
        out += bytes([p0 >> 4, ((p0 & 15) << 4) | (p1 >> 8), p1 & 255])
    return bytes(out)


def _ref_unpack12(data: bytes, h: int, w: int) -> np.ndarray:
    pixels = []
    for g in range(0, len(data), 3):
        b0, b1, b2 = data[g:g + 3]
        pixels += [(b0 << 4) | (b1 >> 4), ((b1 & 15) << 8) | b2]
    return np.array(pixels, dtype=np.uint16).reshape(h, w)


def test_references_reproduce_the_known_bytes():
    """The references themselves against the hand-computed bytes of the known-bytes tests."""
    assert _ref_pack10(np.array([[1023, 0, 512, 3]])) == bytes([255, 0, 128, 0, 0b11_00_00_11])
    assert _ref_pack12(np.array([[0xABC, 0x123]])) == bytes([0xAB, 0xC1, 0x23])


@settings(max_examples=60, deadline=None, derandomize=True)
@given(h=st.integers(1, 6), w4=st.integers(1, 6), seed=st.integers(0, 2**32 - 1))
def test_raw10_round_trip(h, w4, seed):
    raw = np.random.default_rng(seed).integers(0, 1024, (h, 4 * w4), dtype=np.uint16)
    packed = pack_raw10(raw)
    assert packed == _ref_pack10(raw)
    assert len(packed) == raw_byte_count(h, 4 * w4, 10) == 5 * h * w4
    out = unpack_raw10(packed, h, 4 * w4)
    assert out.dtype == np.uint16
    np.testing.assert_array_equal(out, raw)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(data=st.binary(min_size=15, max_size=15))
def test_raw10_unpack_then_pack_is_identity_on_bytes(data):
    out = unpack_raw10(data, 3, 4)
    np.testing.assert_array_equal(out, _ref_unpack10(data, 3, 4))
    assert pack_raw10(out) == data


@settings(max_examples=60, deadline=None, derandomize=True)
@given(h=st.integers(1, 6), w2=st.integers(1, 6), seed=st.integers(0, 2**32 - 1))
def test_raw12_round_trip(h, w2, seed):
    raw = np.random.default_rng(seed).integers(0, 4096, (h, 2 * w2), dtype=np.uint16)
    packed = pack_raw12(raw)
    assert packed == _ref_pack12(raw) and len(packed) == raw_byte_count(h, 2 * w2, 12) == 3 * h * w2
    np.testing.assert_array_equal(unpack_raw12(packed, h, 2 * w2), raw)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(data=st.binary(min_size=12, max_size=12))
def test_raw12_unpack_then_pack_is_identity_on_bytes(data):
    out = unpack_raw12(data, 2, 4)
    np.testing.assert_array_equal(out, _ref_unpack12(data, 2, 4))
    assert pack_raw12(out) == data


def test_unpack_agrees_with_imageio(monkeypatch):
    lytro = pytest.importorskip("imageio.plugins.lytro")
    rng = np.random.default_rng(3)
    raw10 = rng.integers(0, 1024, (6, 16), dtype=np.uint16)
    monkeypatch.setattr(lytro, "LYTRO_ILLUM_IMAGE_SIZE", raw10.shape)
    theirs = lytro.LytroIllumRawFormat.rearrange_bits(np.frombuffer(pack_raw10(raw10), np.uint8).astype(np.uint16))
    np.testing.assert_array_equal(np.rint(theirs * 1023).astype(np.uint16), raw10)
    raw12 = rng.integers(0, 4096, (4, 6), dtype=np.uint16)
    monkeypatch.setattr(lytro, "LYTRO_F01_IMAGE_SIZE", raw12.shape)
    theirs = lytro.LytroF01RawFormat.rearrange_bits(np.frombuffer(pack_raw12(raw12), np.uint8).astype(np.uint16))
    np.testing.assert_array_equal(np.rint(theirs * 4095).astype(np.uint16), raw12)


def test_unpack_dispatch_by_metadata_packing():
    raw = np.arange(8, dtype=np.uint16).reshape(2, 4)
    np.testing.assert_array_equal(unpack_raw(pack_raw10(raw), 2, 4, bits_per_pixel=10, endianness="little"), raw)
    np.testing.assert_array_equal(unpack_raw(pack_raw12(raw), 2, 4, bits_per_pixel=12, endianness="big"), raw)
    with pytest.raises(LfpFormatError, match=r"cam\.raw: unsupported pixel packing 12 bit little"):
        unpack_raw(b"\0" * 12, 2, 4, bits_per_pixel=12, endianness="little", source="cam.raw")


def test_wrong_buffer_size_names_source_and_sizes():
    with pytest.raises(LfpFormatError, match=r"x\.RAW: wrong raw size: a 8 x 2 10-bit image needs 20 bytes, found 19"):
        unpack_raw10(b"\0" * 19, 2, 8, source="x.RAW")
    with pytest.raises(LfpFormatError, match="needs 6 bytes, found 7"):
        unpack_raw12(b"\0" * 7, 2, 2)


def test_pack_rejects_bad_values_and_shapes():
    with pytest.raises(ShapeError, match=r"0\.\.1023.*found 0\.\.1024"):
        pack_raw10(np.array([[0, 1, 2, 1024]], dtype=np.uint16))
    with pytest.raises(ShapeError, match="divisible by 4"):
        pack_raw10(np.zeros((1, 6), np.uint16))
    with pytest.raises(ShapeError, match="divisible by 2"):
        pack_raw12(np.zeros((1, 3), np.uint16))
    with pytest.raises(ShapeError, match="integer counts"):
        pack_raw10(np.zeros((1, 4), np.float32))
    with pytest.raises(ShapeError, match="2-D"):
        pack_raw10(np.zeros(4, np.uint16))
    with pytest.raises(ShapeError, match="divisible by 4"):
        unpack_raw10(b"\0" * 5, 1, 3)
