"""What a Lytro container holds, and writing it out (``lfproc extract``).

Processed Lytro files hold no raw lenslet image but what Lytro's software rendered from one:
first-generation (F01) ``-stk.lfp`` focal stacks (JPEGs at several refocus depths ``lambda``
plus a small depth lookup table), ``-dm.lfp`` depth and confidence maps, Illum desktop
``.LFP`` files (a focus stack of JPEGs and a depth map); raw captures (``.LFR``) hold the
lenslet image, its metadata and a thumbnail. As LFToolbox's ``LFReadLFP`` and plenpy's
readers do, :func:`extract_lfp` writes every section the table of contents names:

==========================  =============================================================
what                        written as
==========================  =============================================================
table of contents           ``table_of_contents.json``
frame metadata              ``metadata.json``, ``private_metadata.json`` (from sections or
                            inline in the table of contents)
JPEG / PNG images           the embedded bytes as they are: ``focus_stack_00_lambda-8.92.jpg``,
                            ``thumbnail_00.jpg``, ``image_00.jpg``...
depth maps, depth LUTs,     float32 little-endian samples as an OpenEXR image (channel ``Y``,
confidence maps             lossless; depths are Lytro's refocus ``lambda`` and can be negative:
                            ``read_image(path, negative="keep")``) plus a colour-mapped PNG
                            preview with a colour bar in those units
F01 videos (H.264 streams   the stream as stored (``section_NN_video.h264``) and its frames
of a refocus stack or a     decoded by OpenCV as 8-bit PNGs, named by what they hold:
parallax sweep)             ``refocus_stack_frame_000_lambda-8.81.png``,
                            ``parallax_frame_000_x0.21_y0.121.png`` (the frame's
                            ``metadataArray`` entry)
raw lenslet image           ``raw_lenslet.bin`` (packed bytes as stored; ``lfproc decode``
                            turns a capture into views)
anything else               ``section_<n>_<kind>.bin`` / ``.json``
==========================  =============================================================

``extracted.json`` lists every file with its table-of-contents path, SHA-1, kind, shape and
parameters (``lambda``, ``focus``). A section the table of contents names but the file lacks
is listed under ``missing``.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .._version import __version__
from ..errors import LfpFormatError
from .container import LfpContainer, _last_key, _norm_sha1, _parse_json, _sniff, read_lfp
from ..io import write_image
from ..io._atomic import atomic_dir

__all__ = ["lfp_contents", "contents_summary", "has_raw_image", "require_raw_image", "extract_lfp",
           "FLOAT_MAP_KEYS"]

#: Table-of-contents keys of float32 maps (depth, confidence), and their file names.
FLOAT_MAP_KEYS = {"depthMap": "depth_map", "depthLut": "depth_lut", "confidenceMap": "confidence_map"}
_FRAME_JSON = {"metadataRef": "metadata", "privateMetadataRef": "private_metadata"}
#: File-name stem of the frames of a first-generation (F01) video, by the type of its acceleration.
_VIDEO_NAMES = {"refocusStack": "refocus_stack", "edofParallax": "parallax"}
#: Colour bar label of the float maps' previews.
_MAP_LABELS = {"depth_map": "depth: Lytro refocus lambda", "depth_lut": "depth: Lytro refocus lambda",
               "confidence_map": "confidence"}


def has_raw_image(c: LfpContainer) -> bool:
    """Whether the container holds its frame's raw sensor image."""
    ref = c.frame().get("imageRef")
    return bool(ref) and c.by_sha1(str(ref)) is not None


def _walk(obj, path: str = "", chain: tuple = ()) -> Iterator[tuple[str, str, tuple]]:
    """``(toc path, sha1, ancestors from the nearest up)`` of every ``sha1-`` reference."""
    if isinstance(obj, dict):
        for key, value in obj.items():
            sub = f"{path}.{key}" if path else str(key)
            if isinstance(value, str) and value[:5].lower() == "sha1-" and len(value) == 45 and key != "derivations":
                yield sub, _norm_sha1(value), (obj,) + chain
            else:
                yield from _walk(value, sub, (obj,) + chain)
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            yield from _walk(value, f"{path}[{i}]", chain)


def _dims(chain: tuple, n_floats: int) -> tuple[int, int] | None:
    """(height, width) of a float map: the nearest ancestor's width/height, else a square."""
    for node in chain:
        if isinstance(node, dict) and isinstance(node.get("width"), int) and isinstance(node.get("height"), int):
            if node["width"] * node["height"] == n_floats:
                return node["height"], node["width"]
    side = int(round(n_floats ** 0.5))
    return (side, side) if side * side == n_floats else None


def _number(x: float) -> str:
    return f"{x:.3g}".replace("+", "")


def lfp_contents(c: LfpContainer) -> list[dict[str, Any]]:
    """Every section the table of contents names, classified (one dict each, in TOC order):
    ``path``, ``sha1``, ``kind`` (``raw_lenslet``, ``white_image``, ``metadata``,
    ``private_metadata``, ``focus_stack``, ``thumbnail``, ``image``, ``depth_map``,
    ``depth_lut``, ``confidence_map``, ``video``, ``json``, ``data``), ``representation``,
    ``present`` (the section is in the file), ``size`` (bytes), ``shape`` and ``params``."""
    frame_image = _norm_sha1(c.frame().get("imageRef", "")) if c.frame().get("imageRef") else None
    out = []
    for path, sha, chain in _walk(c.toc or {}):
        key = _last_key(path)
        parent = chain[0]
        sec = c.by_sha1(sha)
        rep = parent.get("representation") if isinstance(parent, dict) else None
        if sec is not None and not rep:
            rep = _sniff(sec.data)
        item: dict[str, Any] = {"path": path, "sha1": sha, "representation": rep, "present": sec is not None,
                                "size": sec.size if sec is not None else None, "shape": None, "params": {}}
        container_key = _last_key(path.rsplit(".", 1)[0]) if "." in path else ""
        if key in _FRAME_JSON and ".frame." in f".{path}":
            item["kind"] = _FRAME_JSON[key]
        elif key == "imageRef" and sha == frame_image:
            item["kind"] = "raw_lenslet"
        elif key == "modulationDataRef":
            item["kind"] = "white_image"
        elif container_key in FLOAT_MAP_KEYS:
            item["kind"] = FLOAT_MAP_KEYS[container_key]
            if sec is not None and sec.size % 4 == 0:
                item["shape"] = _dims(chain, sec.size // 4)
        elif rep in ("jpeg", "png"):
            lowered = path.lower()
            if "thumbnail" in lowered:
                item["kind"] = "thumbnail"
            elif "imagearray" in lowered or "perimage" in lowered:
                item["kind"] = "focus_stack"
            else:
                item["kind"] = "image"
            w, h = parent.get("width"), parent.get("height")
            if isinstance(w, int) and isinstance(h, int):
                item["shape"] = (h, w)
            if item["kind"] == "focus_stack" and not item["shape"]:
                for node in chain[1:]:
                    if isinstance(node, dict) and isinstance(node.get("width"), int) and "height" in node:
                        item["shape"] = (node["height"], node["width"])
                        break
        elif rep == "h264":
            item["kind"] = "video"
            meta = parent.get("metadataArray") if isinstance(parent, dict) else None
            item["frames"] = [m for m in meta if isinstance(m, dict)] if isinstance(meta, list) else []
            kind_of = next((n.get("type") for n in chain if isinstance(n, dict) and isinstance(n.get("type"), str)), "")
            item["video"] = _VIDEO_NAMES.get(kind_of.rsplit(".", 1)[-1], "video")
        elif rep == "json":
            item["kind"] = "json"
        else:
            item["kind"] = "data"
        for p in ("lambda", "focus"):
            if isinstance(parent, dict) and isinstance(parent.get(p), (int, float)):
                item["params"][p] = float(parent[p])
        out.append(item)
    for key, kind in (("metadata", "metadata"), ("privateMetadata", "private_metadata")):
        if isinstance(c.frame().get(key), dict):  # desktop LFPs keep it inline in the table of contents
            out.append({"path": f"frame.{key} (inline)", "sha1": None, "representation": "json", "present": True,
                        "size": None, "shape": None, "params": {}, "kind": kind})
    return out


def contents_summary(items: list[dict[str, Any]]) -> str:
    """What the sections hold, in words: ``12 focus-stack JPEGs (1080 x 1080), a 20 x 20 depth_lut``."""
    parts = []
    present = [i for i in items if i["present"]]
    stack = [i for i in present if i["kind"] == "focus_stack"]
    if stack:
        shapes = {tuple(i["shape"]) for i in stack if i["shape"]}
        size = f" ({next(iter(shapes))[1]} x {next(iter(shapes))[0]})" if len(shapes) == 1 else ""
        parts.append(f"{len(stack)} focus-stack {stack[0]['representation'].upper()}s{size}")
    for kind, word in (("depth_map", "depth map"), ("depth_lut", "depth lookup table"),
                       ("confidence_map", "confidence map")):
        for i in (i for i in present if i["kind"] == kind):
            shape = f"{i['shape'][1]} x {i['shape'][0]} " if i["shape"] else ""
            parts.append(f"a {shape}{word}")
    for kind, word in (("thumbnail", "thumbnail"), ("image", "image"), ("video", "video"), ("white_image",
                                                                                         "white image")):
        n = sum(i["kind"] == kind for i in present)
        if n:
            parts.append(f"{n} {word}{'s' if n > 1 else ''}")
    meta = [i for i in items if i["kind"] in ("metadata", "private_metadata")]
    if meta:
        parts.append("frame metadata" if all(i["present"] for i in meta) else "no frame metadata (referenced, absent)")
    return ", ".join(parts) or "no sections"


def _float_map(data: bytes, shape) -> np.ndarray:
    a = np.frombuffer(data, dtype="<f4").astype(np.float32)
    return a.reshape(shape) if shape else a.reshape(1, -1)


def _map_preview(values: np.ndarray, out: Path, *, label: str, title: str) -> None:
    """A colour-mapped PNG of a float map with a colour bar in its units (viridis; nearest
    neighbour, so the map's own pixels show)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    h, w = values.shape
    side = 4.0 * max(h, w) / min(h, w) if min(h, w) else 4.0
    fig = Figure(figsize=(min(side, 8.0) * w / max(h, w) + 1.6, min(side, 8.0) * h / max(h, w) + 0.6),
                 layout="constrained")
    ax = fig.add_subplot()
    shown = ax.imshow(values, cmap="viridis", interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.colorbar(shown, ax=ax, label=label)
    fig.savefig(out, dpi=100)


def _video_frames(video: Path, folder: Path, stem: str, frames_meta: list, files: list) -> dict[str, Any]:
    """Decode an embedded H.264 stream (OpenCV) into ``<stem>_frame_NNN[_lambda..|_x.._y..].png``
    files (8-bit, lossless from the decoded frames); each frame gets its ``metadataArray`` entry
    (``lambda`` of a refocus stack, ``coord`` of a parallax sweep) as parameters."""
    import cv2

    cap = cv2.VideoCapture(str(video))
    written = []
    try:
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            m = len(written)
            meta = frames_meta[m] if m < len(frames_meta) else {}
            params: dict[str, float] = {}
            if isinstance(meta.get("lambda"), (int, float)):
                params["lambda"] = float(meta["lambda"])
            coord = meta.get("coord")
            if isinstance(coord, dict):
                params.update({k: float(v) for k, v in coord.items()
                               if k in ("x", "y") and isinstance(v, (int, float))})
            suffix = "".join(f"_{k}{_number(v)}" for k, v in params.items())
            fname = f"{stem}_frame_{m:03d}{suffix}.png"
            if not cv2.imwrite(str(folder / fname), frame):
                raise OSError(f"{folder / fname}: could not write a video frame")
            files.append({"file": fname, "kind": "video_frame", "video": video.name, "stream": stem,
                          "index": m, "params": params, "shape": list(frame.shape[:2])})
            written.append(fname)
    finally:
        cap.release()
    out: dict[str, Any] = {"frames": len(written), "frame_files": f"{stem}_frame_*.png" if written else None}
    if not written:
        out["frames_note"] = "OpenCV could not decode the stream (no H.264 decoder in this build?); kept as is"
    elif frames_meta and len(frames_meta) != len(written):
        out["frames_note"] = (f"the table of contents describes {len(frames_meta)} frames, the stream holds "
                              f"{len(written)}")
    return out


def extract_lfp(path: str | os.PathLike, out_dir: str | os.PathLike, *, force: bool = False,
                verify: bool = True) -> dict[str, Any]:
    """Write what a Lytro container holds into ``out_dir`` (see the module documentation).

    One file per section, named by its kind, plus ``table_of_contents.json`` and ``extracted.json``.

    Parameters
    ----------
    path : str or os.PathLike
        A Lytro LFP/LFR container.
    out_dir : str or os.PathLike
        Output folder, written atomically.
    force : bool, default False
        Replace an existing ``out_dir``.
    verify : bool, default True
        Check every section's SHA-1.

    Returns
    -------
    dict
        The content of ``extracted.json``: ``source``, ``sha1_verified``,
        ``raw_lenslet_image``, ``holds`` (a summary), ``files`` (one entry per file written,
        with its ``kind`` and table-of-contents ``path``) and ``missing`` (sections referenced
        but absent).

    Raises
    ------
    MissingFileError, LfpFormatError, ChecksumError
        As :func:`lfproc.lytro.container.read_lfp`.
    OutputExistsError
        ``out_dir`` exists and ``force`` is false.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.lytro import extract_lfp
    >>> from lfproc.lytro.container import illum_metadata, write_lfr
    >>> raw = np.random.default_rng(0).integers(64, 1024, size=(8, 12), dtype=np.uint16)
    >>> _ = write_lfr("tiny.LFR", raw=raw, metadata=illum_metadata(height=8, width=12))
    >>> out = extract_lfp("tiny.LFR", "tiny")
    >>> out["raw_lenslet_image"], out["missing"]
    (True, [])
    >>> sorted(f["file"] for f in out["files"] if f["kind"] in ("metadata", "raw_lenslet", "thumbnail"))
    ['metadata.json', 'raw_lenslet.bin', 'thumbnail_00.jpg']
    """
    import cv2

    path = Path(path)
    c = read_lfp(path, verify=verify)
    items = lfp_contents(c)
    files: list[dict[str, Any]] = []
    missing = [{"path": i["path"], "sha1": i["sha1"], "kind": i["kind"]} for i in items if not i["present"]]
    counters: dict[str, int] = {}
    written_sha: dict[str, str] = {}
    with atomic_dir(out_dir, force=force) as tmp:
        (tmp / "table_of_contents.json").write_text(json.dumps(c.toc, indent=1))
        files.append({"file": "table_of_contents.json", "kind": "table_of_contents"})
        for item in items:
            if not item["present"]:
                continue
            kind = item["kind"]
            if item["sha1"] is None:  # inline frame metadata
                n = counters.get(kind, 0)
                counters[kind] = n + 1
                fname = f"{kind}.json" if n == 0 else f"{kind}_{n:02d}.json"
                inline = c.frame()["metadata" if kind == "metadata" else "privateMetadata"]
                (tmp / fname).write_text(json.dumps(inline, indent=1))
                files.append({"file": fname, "kind": kind, "path": item["path"]})
                continue
            data = c.by_sha1(item["sha1"]).data
            entry = {"kind": kind, "path": item["path"], "sha1": item["sha1"], "params": item["params"]}
            if item["sha1"] in written_sha:  # the same section named twice
                entry["file"] = written_sha[item["sha1"]]
                files.append(entry)
                continue
            n = counters.get(kind, 0)
            counters[kind] = n + 1
            if kind in ("metadata", "private_metadata"):
                fname = f"{kind}.json" if n == 0 else f"{kind}_{n:02d}.json"
                (tmp / fname).write_text(json.dumps(_parse_json(data, f"{path}: {item['path']}"), indent=1))
            elif kind in ("focus_stack", "thumbnail", "image"):
                suffix = "".join(f"_{k}{_number(v)}" for k, v in item["params"].items())
                fname = f"{kind}_{n:02d}{suffix}.{'jpg' if item['representation'] == 'jpeg' else 'png'}"
                (tmp / fname).write_bytes(data)
                img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
                entry["shape"] = list(img.shape[:2]) if img is not None else item["shape"]
            elif kind in FLOAT_MAP_KEYS.values():
                values = _float_map(data, item["shape"])
                base = kind if n == 0 else f"{kind}_{n:02d}"
                fname = f"{base}.exr"
                write_image(tmp / fname, values[..., None])
                lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
                _map_preview(values, tmp / f"{base}.png", label=_MAP_LABELS[kind], title=f"{base} ({path.name})")
                entry.update({"shape": list(values.shape), "min": lo, "max": hi, "preview": f"{base}.png",
                              "encoding": "float32 little-endian", "values": _MAP_LABELS[kind]})
            elif kind == "raw_lenslet":
                fname = "raw_lenslet.bin" if n == 0 else f"raw_lenslet_{n:02d}.bin"
                (tmp / fname).write_bytes(data)
            elif kind == "json":
                fname = f"section_{len(files):02d}_json.json"
                (tmp / fname).write_text(json.dumps(_parse_json(data, f"{path}: {item['path']}"), indent=1))
            else:
                ext = {"video": "h264"}.get(kind, "bin")
                fname = f"section_{len(files):02d}_{re.sub(r'[^a-z0-9]+', '_', kind)}.{ext}"
                (tmp / fname).write_bytes(data)
                if kind == "video":  # its frames too, named by what the stream holds
                    name = item["video"]
                    k = counters.get(f"video:{name}", 0)
                    counters[f"video:{name}"] = k + 1
                    stem = name if k == 0 else f"{name}_{k:02d}"
                    entry.update(_video_frames(tmp / fname, tmp, stem, item["frames"], files))
            entry["file"] = fname
            written_sha[item["sha1"]] = fname
            files.append(entry)
        doc = {"lfproc_version": __version__, "source": str(path), "sha1_verified": c.sha1_verified,
               "raw_lenslet_image": has_raw_image(c), "holds": contents_summary(items), "files": files,
               "missing": missing}
        (tmp / "extracted.json").write_text(json.dumps(doc, indent=1))
    return doc


def require_raw_image(c: LfpContainer) -> None:
    """Raise :class:`LfpFormatError` naming what the file holds when it has no raw lenslet image."""
    if has_raw_image(c):
        return
    raise LfpFormatError(
        f"{c.path}: no raw lenslet image to decode; the file holds {contents_summary(lfp_contents(c))} "
        f"(processed Lytro files hold rendered pictures, not the capture); 'lfproc extract {c.path} -o DIR' "
        "writes them out")
