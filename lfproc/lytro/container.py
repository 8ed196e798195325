"""Lytro LFP/LFR containers: reading (any section order, SHA-1 verified) and writing Illum ``.LFR``.

Layout (all integers big-endian)::

    89 4C 46 50 0D 0A 1A 0A 00 00 00 01   file magic "\\x89LFP..."
    00 00 00 00                           header length (0)
    then sections, each:
    89 4C 46 {4D|43} 0D 0A 1A 0A 00 00 00 00   "LFM" (table of contents, JSON) or "LFC" (content)
    int32 data length
    45 bytes ASCII "sha1-<40 hex>"             SHA-1 of the data
    35 NUL bytes
    data, then NUL padding to the next 16-byte boundary

The table of contents (the LFM section, first in desktop LFPs and F01 files, last in Illum
LFRs) names the content sections by their SHA-1 (``"imageRef": "sha1-..."``).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import struct
from copy import deepcopy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .. import _untrusted as ut
from .._shared.deprecate import resolve_options
from .._version import __version__
from ..errors import ChecksumError, InputError, LfpFormatError, MissingFileError, ShapeError
from ..io._atomic import atomic_file
from .raw import pack_raw10
from .._shared.reprs import short_repr

__all__ = [
    "LFP_MAGIC",
    "LfpSection",
    "LfpContainer",
    "read_lfp",
    "is_lfp",
    "build_lfp",
    "sha1_ref",
    "write_lfp",
    "write_lfr",
    "illum_metadata",
    "IllumFrameSettings",
]

LFP_MAGIC = b"\x89LFP\r\n\x1a\n\x00\x00\x00\x01"
_SECTION_MAGIC = {b"\x89LFM\r\n\x1a\n": "LFM", b"\x89LFC\r\n\x1a\n": "LFC"}
_KIND_MAGIC = {"LFM": b"\x89LFM\r\n\x1a\n\x00\x00\x00\x00", "LFC": b"\x89LFC\r\n\x1a\n\x00\x00\x00\x00"}
_SECTION_HEADER = 12 + 4 + 45 + 35  # magic+pad, length, sha1 text, NUL padding
_SHA1_RE = re.compile(rb"sha1-[0-9a-fA-F]{40}")
#: Largest container lfproc reads (it is read whole); real Illum LFRs have about 55 MB.
MAX_LFP_BYTES = 4 << 30


@short_repr
@dataclass(frozen=True)
class LfpSection:
    """One section of a Lytro container.

    Attributes
    ----------
    kind : {"LFM", "LFC"}
        ``LFM`` = table of contents (JSON), ``LFC`` = content.
    sha1 : str
        ``"sha1-<40 lower-case hex>"`` as written in the section header.
    data : bytes
        The section payload.
    name : str or None
        The table-of-contents key that refers to this section (``"imageRef"``,
        ``"metadataRef"``...), None for the table of contents itself and unreferenced data.
    toc_path : str or None
        Full path of that key in the table of contents (``"frames[0].frame.imageRef"``).
    offset : int
        Byte offset of the data in the file.
    """

    kind: str
    sha1: str
    data: bytes = field(repr=False)
    name: str | None = None
    toc_path: str | None = None
    offset: int = 0

    @property
    def size(self) -> int:
        """Payload length in bytes."""
        return len(self.data)

    def json(self) -> dict[str, Any]:
        """The payload parsed as a JSON object (:class:`LfpFormatError` when it is not one)."""
        return _parse_json(self.data, f"section {self.name or self.sha1}")


@short_repr
@dataclass(frozen=True)
class LfpContainer:
    """A parsed LFP/LFR file: its sections, table of contents and verification state."""

    path: Path
    header_kind: str
    sections: list[LfpSection]
    toc: dict[str, Any] | None
    sha1_verified: bool
    refs: dict[str, str] = field(default_factory=dict, repr=False)  # toc path -> sha1

    # -- lookup -----------------------------------------------------------------------------
    def by_sha1(self, sha1: str) -> LfpSection | None:
        """The section whose header hash is ``sha1`` (``"sha1-..."``), or None."""
        sha1 = _norm_sha1(sha1)
        for sec in self.sections:
            if sec.sha1 == sha1:
                return sec
        return None

    def ref(self, ref_name: str) -> str | None:
        """The ``sha1-...`` that the table of contents gives for ``ref_name`` (see :meth:`section`)."""
        if ref_name in self.refs:
            return self.refs[ref_name]
        for prefix in ("frames[0].frame.", "picture.frameArray[0].frame."):
            if prefix + ref_name in self.refs:
                return self.refs[prefix + ref_name]
        for path, sha in self.refs.items():
            if _last_key(path) == ref_name:
                return sha
        return None

    def has(self, ref_name: str) -> bool:
        """Whether ``ref_name`` is in the table of contents and its section is present."""
        sha = ref_name if ref_name.startswith("sha1-") else self.ref(ref_name)
        return sha is not None and self.by_sha1(sha) is not None

    def section(self, ref_name: str) -> LfpSection:
        """The section a table-of-contents reference points to.

        ``ref_name`` is a key such as ``"imageRef"``, ``"metadataRef"``,
        ``"privateMetadataRef"`` (the picture frame's reference is preferred, then the first
        other occurrence), a full path such as ``"thumbnails[0].imageRef"``, or a hash
        ``"sha1-..."``.

        Raises
        ------
        LfpFormatError
            When the table of contents has no such reference, or no section has its hash.
        """
        if ref_name.startswith("sha1-"):
            sha = _norm_sha1(ref_name)
        else:
            sha = self.ref(ref_name)
            if sha is None:
                known = sorted({_last_key(p) for p in self.refs})
                raise LfpFormatError(f"{self.path}: the table of contents has no {ref_name!r} "
                                     f"(it names: {', '.join(known) or 'nothing'})")
        sec = self.by_sha1(sha)
        if sec is None:
            raise LfpFormatError(f"{self.path}: missing section: the table of contents names {ref_name} = "
                                 f"{sha} but no section in the file has that hash")
        return sec

    def json(self, ref_name: str) -> dict[str, Any]:
        """A JSON section (``"metadataRef"``, ``"privateMetadataRef"``...) parsed.

        Desktop LFPs keep the frame metadata inline in the table of contents
        (``frames[0].frame.metadata`` instead of ``metadataRef``); that inline copy is
        returned when the reference is absent.
        """
        if not ref_name.startswith("sha1-") and self.ref(ref_name) is None and ref_name.endswith("Ref"):
            inline = self.frame().get(ref_name[:-3])
            if isinstance(inline, dict):
                return inline
            if inline is not None:
                raise LfpFormatError(f"{self.path}: field 'frame.{ref_name[:-3]}': expected an object, found "
                                     f"{ut.show(inline)}")
        sec = self.section(ref_name)
        return _parse_json(sec.data, f"{self.path}: section {ref_name}")

    def frame(self) -> dict[str, Any]:
        """The first picture frame entry of the table of contents (``{}`` when none)."""
        toc = self.toc or {}
        for getter in (lambda t: t["frames"][0]["frame"], lambda t: t["picture"]["frameArray"][0]["frame"]):
            try:
                out = getter(toc)
            except (KeyError, IndexError, TypeError):
                continue
            if isinstance(out, dict):
                return out
        return {}

    def images(self) -> list[dict[str, Any]]:
        """Embedded images (JPEG, PNG, H.264 blocks, depth maps) named by the table of contents.

        Returns a list of dicts with ``path`` (table-of-contents path of the reference),
        ``sha1``, ``representation`` (from the TOC when given, else sniffed), ``width``,
        ``height`` (None when not given) and ``size`` (bytes).
        """
        out = []
        frame_refs = {"imageRef", "metadataRef", "privateMetadataRef"}
        for path, sha, parent in _walk_refs_with_parent(self.toc or {}):
            key = _last_key(path)
            if key not in ("imageRef", "blockOfImagesRef", "reconstructionFilterRef"):
                continue
            if key in frame_refs and ".frame." in path:  # the raw sensor image, not an embedded picture
                continue
            sec = self.by_sha1(sha)
            if sec is None:
                continue
            parent = parent if isinstance(parent, dict) else {}
            rep = parent.get("representation")
            dims = [parent.get(k) for k in ("width", "height")]
            dims = [d if isinstance(d, int) and not isinstance(d, bool) and 0 <= d <= ut.MAX_DIMENSION else None
                    for d in dims]
            out.append({
                "path": path,
                "sha1": sec.sha1,
                "representation": rep[:64] if isinstance(rep, str) and rep else _sniff(sec.data),
                "width": dims[0],
                "height": dims[1],
                "size": sec.size,
            })
        return out

    def files(self) -> dict[str, LfpSection]:
        """Files of a Lytro Desktop storage archive (``data.C.N``): TOC ``files[].{name,dataRef}``.

        Keys are the stored names (``C:\\T1CALIB\\MOD_0000.RAW``).
        """
        out = {}
        for i, entry in enumerate(_storage_entries(self.toc, self.path)):
            node = ut.Node(entry, self.path, f"files[{i}]", LfpFormatError)
            name = node["name"].as_str(max_len=1024, nonempty=True)
            ref = node["dataRef"].as_str(max_len=64)
            sec = self.by_sha1(ref)
            if sec is None:
                raise LfpFormatError(f"{self.path}: missing section: files[{i}] ({ut.show(name)}) refers to "
                                     f"{ut.show(ref)}, which no section has")
            out[name] = sec
        return out


# -- helpers --------------------------------------------------------------------------------
def _storage_entries(toc: Any, path) -> list:
    """``toc["files"]`` of a storage archive (``[]`` when absent); an error when not a list."""
    if not isinstance(toc, dict) or toc.get("files") is None:
        return []
    files = toc["files"]
    if not isinstance(files, list):
        raise LfpFormatError(f"{path}: field 'files': expected a list of storage entries, found {ut.show(files)}")
    return files


def _norm_sha1(sha: str) -> str:
    sha = str(sha).strip()
    return "sha1-" + sha[5:].lower() if sha[:5].lower() == "sha1-" else sha.lower()


def _last_key(path: str) -> str:
    return re.sub(r"\[\d+\]$", "", path.rsplit(".", 1)[-1])


def _walk_refs_with_parent(obj, path: str = "", parent=None) -> Iterator[tuple[str, str, Any]]:
    if isinstance(obj, dict):
        for key, value in obj.items():
            sub = f"{path}.{key}" if path else str(key)
            if isinstance(value, str) and value[:5].lower() == "sha1-" and len(value) == 45 and key != "derivations":
                yield sub, _norm_sha1(value), obj
            else:
                yield from _walk_refs_with_parent(value, sub, obj)
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            yield from _walk_refs_with_parent(value, f"{path}[{i}]", obj)


def _sniff(data: bytes) -> str:
    if data[:3] == b"\xff\xd8\xff":
        return "jpeg"
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return "png"
    if data[:4] == b"\x00\x00\x00\x01":
        return "h264"
    if data[:1] in (b"{", b"["):
        return "json"
    return "raw"


def _parse_json(data: bytes, what: str) -> dict[str, Any]:
    """A JSON object from Lytro bytes (size and nesting checked by :mod:`lfproc._untrusted`).

    Undecodable bytes are replaced (real TXT files carry stray bytes after the closing
    brace, and that trailing junk is ignored).
    """
    if len(data) > ut.MAX_JSON_BYTES:
        raise LfpFormatError(f"{what}: JSON text of {len(data)} bytes exceeds the limit of {ut.MAX_JSON_BYTES}")
    text = bytes(data).decode("utf-8", errors="replace")
    obj = ut.parse_json(text, source=what, error=LfpFormatError, trailing="ignore", strip_nul=True)
    if not isinstance(obj, dict):
        raise LfpFormatError(f"{what}: expected a JSON object, found {ut.show(obj)}")
    return obj


def is_lfp(path: str | os.PathLike) -> bool:
    """Whether the file at ``path`` starts with the LFP magic bytes.

    Parameters
    ----------
    path : str or os.PathLike
        Any path.

    Returns
    -------
    bool
        True for a Lytro LFP/LFR container (Illum ``.LFR``, F01 ``.lfp``, calibration
        ``data.C.N`` archives); False otherwise, also for an unreadable or missing file.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.lytro import is_lfp
    >>> from lfproc.lytro.container import illum_metadata, write_lfr
    >>> raw = np.random.default_rng(0).integers(64, 1024, size=(8, 12), dtype=np.uint16)
    >>> _ = write_lfr("tiny.LFR", raw=raw, metadata=illum_metadata(height=8, width=12))
    >>> is_lfp("tiny.LFR"), is_lfp("missing.LFR")
    (True, False)
    """
    try:
        with open(path, "rb") as fh:
            return fh.read(len(LFP_MAGIC)) == LFP_MAGIC
    except OSError:
        return False


def read_lfp(path: str | os.PathLike, *, verify: bool = True) -> LfpContainer:
    """Read a Lytro LFP/LFR container.

    Parameters
    ----------
    path : str or Path
        ``.LFR`` (Illum raw), ``.LFP`` (desktop/F01) or Lytro Desktop ``data.C.N`` file.
    verify : bool, default True
        Check every section's data against the SHA-1 in its header.

    Returns
    -------
    LfpContainer

    Raises
    ------
    MissingFileError
        The file does not exist.
    LfpFormatError
        Wrong magic, bad section header, truncated file, bad table of contents.
    ChecksumError
        A section does not match its SHA-1 (only with ``verify=True``).
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path}: no such file")
    buf = ut.read_bytes(path, max_bytes=MAX_LFP_BYTES, error=LfpFormatError, what="Lytro container")
    if len(buf) < 16:
        raise LfpFormatError(f"{path}: truncated file: {len(buf)} bytes, an LFP header needs 16")
    if buf[:12] != LFP_MAGIC:
        raise LfpFormatError(f"{path}: wrong magic: expected an LFP file starting with {LFP_MAGIC[:4]!r}..., "
                             f"found {buf[:12]!r}")
    (header_len,) = struct.unpack(">I", buf[12:16])
    if header_len != 0:
        raise LfpFormatError(f"{path}: unexpected LFP header length {header_len} (expected 0)")
    off = 16
    raw_sections: list[tuple[str, str, int, int]] = []
    while off < len(buf):
        if not buf[off:].strip(b"\x00"):
            break  # trailing padding only
        head = buf[off:off + _SECTION_HEADER]
        if len(head) < 16:
            raise LfpFormatError(f"{path}: truncated file: section {len(raw_sections)} header at byte {off} "
                                 f"is cut off ({len(head)} of {_SECTION_HEADER} bytes)")
        kind = _SECTION_MAGIC.get(head[:8])
        if kind is None:
            raise LfpFormatError(f"{path}: bad section magic at byte {off}: expected \\x89LFM or \\x89LFC, "
                                 f"found {head[:8]!r}")
        (length,) = struct.unpack(">i", head[12:16])
        if length < 0:
            raise LfpFormatError(f"{path}: section {len(raw_sections)} at byte {off} has negative length {length}")
        if len(head) < _SECTION_HEADER:
            raise LfpFormatError(f"{path}: truncated file: section {len(raw_sections)} header at byte {off} "
                                 f"is cut off ({len(head)} of {_SECTION_HEADER} bytes)")
        sha_text = head[16:61]
        if not _SHA1_RE.fullmatch(sha_text):
            raise LfpFormatError(f"{path}: section {len(raw_sections)} at byte {off} has no valid "
                                 f"'sha1-<40 hex>' tag (found {sha_text[:45]!r})")
        start = off + _SECTION_HEADER
        end = start + length
        if end > len(buf):
            raise LfpFormatError(f"{path}: truncated file: section {len(raw_sections)} ({kind}, "
                                 f"{sha_text.decode()}) needs {length} bytes from byte {start}, "
                                 f"only {len(buf) - start} left")
        raw_sections.append((kind, _norm_sha1(sha_text.decode("ascii")), start, end))
        off = (end + 15) // 16 * 16
    if not raw_sections:
        raise LfpFormatError(f"{path}: truncated file: no sections after the LFP header")

    if verify:
        for i, (kind, sha, start, end) in enumerate(raw_sections):
            actual = "sha1-" + hashlib.sha1(memoryview(buf)[start:end]).hexdigest()
            if actual != sha:
                raise ChecksumError(f"{path}: SHA-1 mismatch in section {i} ({kind}, {end - start} bytes): "
                                    f"header says {sha}, data hash {actual}; the file is corrupt "
                                    "(verify=False reads it anyway)")

    toc = None
    toc_index = None
    for i, (kind, sha, start, end) in enumerate(raw_sections):
        if kind == "LFM":
            toc = _parse_json(buf[start:end], f"{path}: table of contents")
            toc_index = i
            break
    refs: dict[str, str] = {}
    if isinstance(toc, dict):
        for p, sha, _parent in _walk_refs_with_parent(toc):
            refs[p] = sha
        for i, entry in enumerate(_storage_entries(toc, path)):
            if isinstance(entry, dict) and isinstance(entry.get("dataRef"), str):
                refs[f"files[{i}].dataRef"] = _norm_sha1(entry["dataRef"])
    # Name each section after the reference that names it (picture frame first).
    names: dict[str, tuple[str, str]] = {}
    for p, sha in sorted(refs.items(), key=lambda kv: (".frame." not in kv[0], kv[0])):
        names.setdefault(sha, (_last_key(p), p))
    sections = []
    for i, (kind, sha, start, end) in enumerate(raw_sections):
        name, toc_path = (None, None) if i == toc_index else names.get(sha, (None, None))
        sections.append(LfpSection(kind=kind, sha1=sha, data=bytes(buf[start:end]), name=name,
                                   toc_path=toc_path, offset=start))
    return LfpContainer(path=path, header_kind="LFP", sections=sections, toc=toc, sha1_verified=bool(verify),
                        refs=refs)


# -- writing --------------------------------------------------------------------------------
def _section_bytes(kind: str, data: bytes) -> bytes:
    sha = ("sha1-" + hashlib.sha1(data).hexdigest()).encode("ascii")
    head = _KIND_MAGIC[kind] + struct.pack(">i", len(data)) + sha + b"\x00" * 35
    pad = (-len(data)) % 16
    return head + data + b"\x00" * pad


def sha1_ref(data: bytes) -> str:
    """``"sha1-<hex>"`` of ``data``, as used by LFP tables of contents."""
    return "sha1-" + hashlib.sha1(data).hexdigest()


def build_lfp(toc: dict[str, Any], payloads: list[bytes], *, toc_first: bool = True) -> bytes:
    """Bytes of an LFP container holding ``toc`` (JSON, LFM) and ``payloads`` (LFC sections).

    ``toc_first=True`` is the desktop/F01 order, ``False`` the Illum ``.LFR`` order (content,
    then the table of contents).
    """
    toc_bytes = json.dumps(toc, indent=4).encode("ascii")
    if toc_first:
        # imageio's F01 reader expects exactly 5 NUL bytes after a leading table of contents;
        # trailing JSON whitespace makes that true without changing the document.
        toc_bytes += b" " * ((11 - len(toc_bytes)) % 16)
    content = [_section_bytes("LFC", p) for p in payloads]
    lfm = _section_bytes("LFM", toc_bytes)
    parts = [LFP_MAGIC, b"\x00\x00\x00\x00"] + ([lfm] + content if toc_first else content + [lfm])
    return b"".join(parts)


def write_lfp(path: str | os.PathLike, *, toc: dict[str, Any], payloads: list[bytes], toc_first: bool = True,
              force: bool = False) -> Path:
    """Write an LFP container (see :func:`build_lfp`) atomically; return the path."""
    data = build_lfp(toc, payloads, toc_first=toc_first)
    with atomic_file(path, force=force) as tmp:
        Path(tmp).write_bytes(data)
    return Path(path)


def _deep_update(base: dict, extra: dict) -> dict:
    for key, value in extra.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            _deep_update(base[key], value)
        else:
            base[key] = value
    return base


@dataclass(frozen=True)
class IllumFrameSettings:
    """The capture settings an Illum frame's metadata records (the fields of :func:`illum_metadata`)."""
    height: int = 5368
    width: int = 7728
    zoom_step: int = 0
    focus_step: int = 0
    exposure_s: float = 1 / 60
    iso: float = 100
    black_level: float = 64
    white_level: float = 1023
    modulation_exposure_bias_ev: float = 0.0
    white_balance: dict[str, float] | None = None
    ccm: Any = None
    mla_rotation_rad: float = 0.0


def illum_metadata(settings: IllumFrameSettings | None = None, *, extra: dict | None = None,
                   **fields) -> dict[str, Any]:
    """Illum frame metadata (the layout of a real Illum ``.LFR``) for the given capture settings.

    Field layout follows a real Illum picture's frame metadata (``image.pixelFormat``,
    ``image.color.ccm``, ``devices.{sensor,shutter,lens,mla}``, ``camera.model = "ILLUM"``).
    ``extra`` is merged in last (nested dicts are merged, other values replace).

    Parameters
    ----------
    settings : IllumFrameSettings, optional
        Every setting below (``height``, ``width``, ``zoom_step``, ``focus_step``, ``black_level``,
        ``white_level``, ``white_balance``, ``ccm``, ``mla_rotation_rad`` and the ones listed); or give
        them as keywords (``**fields``), not both.
    exposure_s : float
        Frame exposure duration in seconds.
    iso : float
        ISO speed (``image.iso``).
    modulation_exposure_bias_ev : float
        ``image.modulationExposureBias`` in EV (stops).
    """
    f = resolve_options(IllumFrameSettings, settings, fields, func_name="illum_metadata", argument="settings")
    height, width, iso, exposure_s = f.height, f.width, f.iso, f.exposure_s
    black_level, white_level, white_balance, ccm = f.black_level, f.white_level, f.white_balance, f.ccm
    levels_b = {c: black_level for c in ("r", "gr", "gb", "b")}
    levels_w = {c: white_level for c in ("r", "gr", "gb", "b")}
    wb = {"r": 1.0, "gr": 1.0, "gb": 1.0, "b": 1.0}
    if white_balance:
        wb.update({"r": float(white_balance.get("r", 1.0)), "b": float(white_balance.get("b", 1.0))})
        g = float(white_balance.get("g", white_balance.get("gr", 1.0)))
        wb.update({"gr": g, "gb": float(white_balance.get("gb", g))})
    ccm_list = (np.eye(3) if ccm is None else np.asarray(ccm, dtype=float).reshape(3, 3)).ravel().tolist()
    meta: dict[str, Any] = {
        "schema": "http://schema.lytro.com/lfp/lytro_illum_public/1.3.5/lytro_illum_public_schema.json",
        "generator": f"lfproc {__version__}",
        "image": {
            "width": int(width),
            "height": int(height),
            "orientation": 1,
            "modulationExposureBias": float(f.modulation_exposure_bias_ev),
            "limitExposureBias": 0.0,
            "pixelPacking": {"bitsPerPixel": 10, "endianness": "little"},
            "pixelFormat": {"black": levels_b, "white": levels_w, "rightShift": 0},
            "iso": float(iso),
            "originOnSensor": {"x": 0, "y": 0},
            "mosaic": {"tile": "r,gr:gb,b", "upperLeftPixel": "gr"},
            "color": {"whiteBalanceGain": wb, "ccm": ccm_list},
        },
        "devices": {
            "sensor": {
                "pixelPitch": 1.4e-06,
                "pixelWidth": int(width),
                "pixelHeight": int(height),
                "bitsPerPixel": 10,
                "mosaic": {"tile": "r,gr:gb,b", "upperLeftPixel": "gr"},
                "baseIso": 80,
                "iso": float(iso),
                "analogGain": {c: float(iso) / 80.0 for c in ("r", "gr", "gb", "b")},
                "normalizedResponses": [{"r": 1.0, "gr": 1.0, "gb": 1.0, "b": 1.0, "cct": 5100}],
            },
            "shutter": {"mechanism": "focalPlaneCurtain", "frameExposureDuration": float(exposure_s),
                        "pixelExposureDuration": float(exposure_s), "maxSyncSpeed": 0.004},
            "mla": {"config": "com.lytro.mla.3", "rotation": float(f.mla_rotation_rad), "tiling": "hexUniformRowMajor",
                    "scaleFactor": {"x": 1.0, "y": 1.0}, "lensPitch": 2e-05,
                    "sensorOffset": {"x": 0.0, "y": 0.0, "z": 3.7e-05}},
            "lens": {"zoomStep": int(f.zoom_step), "focusStep": int(f.focus_step), "fNumber": 2.0,
                     "exitPupilOffset": {"z": 10000}, "focalLength": 0.0095, "infinityLambda": 15.0,
                     "opticalCenterOffset": {"x": 0.0, "y": 0.0}},
        },
        "camera": {"make": "Lytro, Inc.", "model": "ILLUM", "firmware": f"lfproc {__version__}"},
        "settings": {"exposure": {"compensation": 0, "mode": "manual"}},
        "algorithms": {"awb": {"computed": {"gain": dict(wb)}}},
        "picture": {"totalFrames": 1, "frameIndex": 0},
    }
    if extra:
        _deep_update(meta, deepcopy(extra))
    return meta


def _thumbnail_jpeg(raw: np.ndarray, max_width: int = 704) -> tuple[bytes, int, int]:
    import cv2

    h, w = raw.shape
    h2, w2 = h // 2 * 2, w // 2 * 2
    quad = raw[:h2, :w2].astype(np.float32).reshape(h2 // 2, 2, w2 // 2, 2)
    # GRBG: G at (0,0) and (1,1), R at (0,1), B at (1,0)
    r, b = quad[:, 0, :, 1], quad[:, 1, :, 0]
    g = 0.5 * (quad[:, 0, :, 0] + quad[:, 1, :, 1])
    rgb = np.stack([b, g, r], axis=-1)  # OpenCV order
    rgb = np.clip((rgb - 64.0) / (1023.0 - 64.0), 0, 1) ** (1 / 2.2) * 255.0
    scale = min(1.0, max_width / rgb.shape[1])
    tw, th = max(1, round(rgb.shape[1] * scale)), max(1, round(rgb.shape[0] * scale))
    small = cv2.resize(rgb, (tw, th), interpolation=cv2.INTER_AREA) if scale < 1 else rgb
    ok, enc = cv2.imencode(".jpg", np.ascontiguousarray(small.astype(np.uint8)), [cv2.IMWRITE_JPEG_QUALITY, 85])
    if not ok:  # pragma: no cover - OpenCV always encodes uint8 BGR
        raise OSError("could not encode the LFR thumbnail as JPEG")
    return enc.tobytes(), tw, th


def _png(image: np.ndarray) -> bytes:
    import cv2

    ok, enc = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover
        raise OSError("could not encode PNG")
    return enc.tobytes()


def _lfr_frame_metadata(path, metadata, shape: tuple[int, int]) -> dict[str, Any]:
    """A copy of an Illum frame's ``metadata`` checked against a raw image of ``shape`` (H, W), with the
    image size, the 10-bit packing and the camera make and model filled in."""
    height, width = shape
    if not isinstance(metadata, dict):
        raise InputError(f"{path}: metadata must be a dict, got {type(metadata).__name__}")
    meta = deepcopy(metadata)
    model = meta.get("camera", {}).get("model", "ILLUM")
    if str(model).upper() not in ("ILLUM", "B01"):
        raise InputError(f"{path}: write_lfr writes Illum captures; metadata camera.model is {model!r}")
    image = meta.setdefault("image", {})
    for key, value in (("width", width), ("height", height)):
        if key in image and int(image[key]) != value:
            raise ShapeError(f"{path}: metadata image.{key} = {image[key]} does not match raw of shape "
                             f"{tuple(shape)} (H, W)")
        image[key] = int(value)
    packing = image.setdefault("pixelPacking", {"bitsPerPixel": 10, "endianness": "little"})
    if int(packing.get("bitsPerPixel", 10)) != 10 or str(packing.get("endianness", "little")) != "little":
        raise InputError(f"{path}: Illum LFRs are 10-bit little-endian; metadata image.pixelPacking is {packing}")
    image["pixelPacking"] = {"bitsPerPixel": 10, "endianness": "little"}
    meta.setdefault("camera", {}).setdefault("model", "ILLUM")
    meta["camera"].setdefault("make", "Lytro, Inc.")
    return meta


def _lfr_thumbnail(path, arr: np.ndarray, thumbnail) -> tuple[bytes, int, int]:
    """The JPEG thumbnail of an LFR (``thumbnail`` given, or a quick rendering of ``arr``), width, height."""
    if thumbnail is None:
        thumb, tw, th = _thumbnail_jpeg(arr)
    else:
        import cv2

        t = np.asarray(thumbnail)
        if t.ndim != 3 or t.shape[2] != 3 or t.dtype != np.uint8:
            raise ShapeError(f"{path}: thumbnail must be uint8 of shape (h, w, 3), got {t.dtype} {t.shape}")
        ok, enc = cv2.imencode(".jpg", np.ascontiguousarray(t[..., ::-1]))
        thumb, th, tw = enc.tobytes(), t.shape[0], t.shape[1]
    return thumb, tw, th


def _hot_pixel_section(path, hot_pixels, width: int, height: int) -> bytes:
    """The hot-pixel section (HOTPIXEL.BIN layout: count, then the x and the y coordinates, uint16)."""
    hp = np.zeros((0, 2), dtype=np.uint16) if hot_pixels is None else np.asarray(hot_pixels, dtype=np.int64)
    if hp.ndim != 2 or hp.shape[1] != 2 or (hp.size and (hp.min() < 0 or hp[:, 0].max() >= width
                                                         or hp[:, 1].max() >= height)):
        raise ShapeError(f"{path}: hot_pixels must be (x, y) pairs inside the {width} x {height} image")
    hot = struct.pack("<I", hp.shape[0]) + hp[:, 0].astype("<u2").tobytes() + hp[:, 1].astype("<u2").tobytes()
    return hot


def write_lfr(path: str | os.PathLike, *, raw: np.ndarray, metadata: dict[str, Any],
              private_metadata: dict[str, Any] | None = None, serial: str = "B5000000000",
              geometry_correction: bytes | None = None, hot_pixels=None, thumbnail: np.ndarray | None = None,
              force: bool = False) -> Path:
    """Write an Illum-style ``.LFR`` raw capture.

    The file has the layout of a real Illum LFR: 11 content sections (frame metadata, private
    metadata, 10-bit packed raw image, JPEG thumbnail, geometry-correction table, hot-pixel
    list, exposure histogram, aberration-correction data and metadata, reconstruction filter
    and its metadata), then the table of contents. Every section carries its SHA-1.

    Parameters
    ----------
    path : str or Path
        Output ``.LFR`` path (written atomically; see ``force``).
    raw : ndarray of shape (H, W), integer
        Raw counts 0..1023 (DN), GRBG mosaic; ``H * W`` divisible by 4.
    metadata : dict
        Illum frame metadata (see :func:`illum_metadata`). ``image.width/height`` and
        ``image.pixelPacking`` are filled in; when present they must agree with ``raw``.
        ``camera.model`` must be ``"ILLUM"`` when given.
    private_metadata : dict, optional
        Private frame metadata; default ``{"camera": {"serialNumber": serial}, ...}``.
    serial : str
        Camera serial number used when ``private_metadata`` is None.
    geometry_correction : bytes, optional
        Content of the geometry-correction table (``MOD_xxxx.GCT`` of the matching white
        image); its SHA-1 becomes ``frames[0].frame.geometryCorrectionRef``. Default: a
        JSON description of the microlens array from ``metadata``.
    hot_pixels : array_like of shape (N, 2), optional
        ``(x, y)`` pixel coordinates stored in the hot-pixel section (HOTPIXEL.BIN layout).
    thumbnail : ndarray of shape (h, w, 3), uint8, optional
        RGB thumbnail; default: a quick rendering of ``raw``.
    force : bool
        Overwrite an existing file.

    Returns
    -------
    Path
    """
    arr = np.asarray(raw)
    if arr.ndim != 2:
        raise ShapeError(f"{path}: raw must be a 2-D array (H, W), got shape {arr.shape}")
    height, width = arr.shape
    meta = _lfr_frame_metadata(path, metadata, arr.shape)

    packed = pack_raw10(arr)
    if private_metadata is None:
        private_metadata = {
            "schema": "http://schema.lytro.com/lfp/lytro_illum_private/1.1.1/lytro_illum_private_schema.json",
            "generator": f"lfproc {__version__}",
            "camera": {"serialNumber": str(serial)},
            "devices": {"sensor": {"serialNumber": hashlib.sha1(str(serial).encode()).hexdigest()[:8].upper()}},
        }
    elif not isinstance(private_metadata, dict):
        raise InputError(f"{path}: private_metadata must be a dict, got {type(private_metadata).__name__}")

    thumb, tw, th = _lfr_thumbnail(path, arr, thumbnail)

    mla = meta.get("devices", {}).get("mla", {})
    if geometry_correction is None:
        geometry_correction = json.dumps({"generator": f"lfproc {__version__}", "kind": "geometryCorrection",
                                          "mla": mla, "width": width, "height": height},
                                         sort_keys=True).encode("ascii")
    hot = _hot_pixel_section(path, hot_pixels, width, height)
    histogram = np.bincount(arr.ravel().astype(np.int64), minlength=1024)[:1024].astype("<u4").tobytes()
    aberration = np.zeros((2, 2, 2), dtype="<f4").tobytes()  # identity: zero displacement everywhere
    aberration_meta = json.dumps({"generator": f"lfproc {__version__}", "representation": "float32",
                                  "width": 2, "height": 2, "channels": 2, "meaning": "identity"}).encode("ascii")
    recon_filter = _png(np.array([[0, 0, 0], [0, 255, 0], [0, 0, 0]], dtype=np.uint8))
    recon_meta = json.dumps({"generator": f"lfproc {__version__}", "representation": "png",
                             "width": 3, "height": 3, "kernel": "identity"}).encode("ascii")
    meta_bytes = json.dumps(meta, indent=4).encode("ascii")
    private_bytes = json.dumps(private_metadata, indent=4).encode("ascii")

    frame_payloads = {
        "aberrationCorrectionRef": aberration,
        "hotPixelRef": hot,
        "exposureHistogramRef": histogram,
        "aberrationCorrectionMetadataRef": aberration_meta,
        "geometryCorrectionRef": geometry_correction,
        "reconstructionFilterRef": recon_filter,
        "reconstructionFilterMetadataRef": recon_meta,
        "metadataRef": meta_bytes,
        "privateMetadataRef": private_bytes,
        "imageRef": packed,
    }
    toc = {
        "derivations": [],
        "views": [],
        "schema": "http://schema.lytro.com/lfp/picture/2.1.4/picture_schema.json",
        "annotations": [],
        "thumbnails": [{"width": int(tw), "imageRef": sha1_ref(thumb), "colorSpace": "sRGB",
                        "representation": "jpeg", "height": int(th)}],
        "frames": [{"assignedProperties": {}, "accelerations": [],
                    "frame": {key: sha1_ref(data) for key, data in frame_payloads.items()}}],
        "generators": ["lightning", f"lfproc {__version__}"],
    }
    payloads = [meta_bytes, private_bytes, packed, thumb] + [
        frame_payloads[k] for k in ("geometryCorrectionRef", "hotPixelRef", "exposureHistogramRef",
                                    "aberrationCorrectionRef", "aberrationCorrectionMetadataRef",
                                    "reconstructionFilterRef", "reconstructionFilterMetadataRef")]
    return write_lfp(path, toc=toc, payloads=payloads, toc_first=False, force=force)
