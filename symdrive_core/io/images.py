"""Images, masks and id maps through OpenImageIO; every write is atomic.

Float images are [H, W, C] float32 (linear values as stored; 8-bit files map to [0, 1]).
Masks are [H, W] float32 in [0, 1]; id maps are [H, W] integer arrays.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from . import check_regular
from .atomic import atomic_path


def _first_line(message: str) -> str:
    """OpenImageIO's messages run over several lines; the first says what is wrong."""
    lines = [ln.strip() for ln in (message or "").splitlines() if ln.strip()]
    return lines[0] if lines else "unknown error"


def _oiio():
    import OpenImageIO as oiio  # imported lazily: the add-on's numpy-only modules never need it
    return oiio


# Larger declared images are refused before their pixels are allocated (a 16384 x 16384 RGBA
# float image is 4 GiB already).
MAX_IMAGE_SIDE = 16384


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_END = b"IEND\xaeB`\x82"  # the end chunk's type and CRC: the last 8 bytes of a whole PNG


def _truncated_png(path: Path) -> bool:
    """A PNG whose last KB holds no end chunk: its header reads, its pixels run out (a header
    check alone lets it through, and the first reader of its pixels fails)."""
    with open(path, "rb") as f:
        if f.read(len(PNG_SIGNATURE)) != PNG_SIGNATURE:
            return False
        f.seek(max(f.seek(0, os.SEEK_END) - 1024, 0))
        return PNG_END not in f.read()


def image_size(path: str | os.PathLike, field: str | None = None) -> tuple[int, int, int]:
    """(width, height, channels) from an image file's header alone; nothing is decoded.

    Only regular files are opened, a side larger than ``MAX_IMAGE_SIDE`` is an error, and so is a
    PNG cut off before its end chunk (its last KB is read, not its pixels).
    """
    path = Path(path)
    check_regular(path, field)
    oiio = _oiio()
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InputError(path, f"cannot read image: {_first_line(oiio.geterror())}", field)
    try:
        spec = inp.spec()
        width, height, channels = int(spec.width), int(spec.height), int(spec.nchannels)
    finally:
        inp.close()
    if width < 1 or height < 1 or channels < 1:
        raise InputError(path, f"image header declares {width}x{height} with {channels} channels", field)
    if width > MAX_IMAGE_SIDE or height > MAX_IMAGE_SIDE:
        raise InputError(path, f"image is {width}x{height}; sides above {MAX_IMAGE_SIDE} pixels are not read",
                         field)
    if _truncated_png(path):
        raise InputError(path, "truncated: a PNG without its end chunk (IEND), as a copy cut off writes it", field)
    return width, height, channels


def read_image(path: str | os.PathLike, *, channels: int | None = None) -> np.ndarray:
    """Read an image as float32 [H, W, C]; ``channels`` keeps the first C (or repeats grey, of a
    grey image with or without alpha: alpha comes associated, as of RGBA, so grey is over black)."""
    oiio = _oiio()
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file not found")
    image_size(path)  # a regular file of a sane size, checked before any pixel is allocated
    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        raise InputError(path, f"cannot read image: {_first_line(buf.geterror())}")
    pixels = buf.get_pixels(oiio.FLOAT)
    if pixels is None or buf.has_error:
        raise InputError(path, f"cannot read image: {_first_line(buf.geterror())}")
    img = np.asarray(pixels, dtype=np.float32)
    if img.ndim == 2:
        img = img[:, :, None]
    if channels is not None:
        if img.shape[2] in (1, 2) and channels > img.shape[2]:
            img = np.repeat(img[:, :, :1], channels, axis=2)
        elif img.shape[2] < channels:
            raise InputError(path, f"expected {channels} channels, file has {img.shape[2]}")
        img = img[:, :, :channels]
    return np.ascontiguousarray(img)


def write_image(path: str | os.PathLike, image: np.ndarray, *, dtype: str | None = None) -> Path:
    """Write [H, W] or [H, W, C]; 8-bit formats (PNG/JPEG) are clipped to [0, 1] and rounded.

    ``dtype`` overrides the stored type: "uint8", "uint16", "half" or "float". EXR defaults to
    half for RGB(A) and float for single-channel data.
    """
    oiio = _oiio()
    path = Path(path)
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3:
        raise ValueError(f"write_image({path}): expected [H, W] or [H, W, C], got shape {img.shape}")
    ext = path.suffix.lower()
    if dtype is None:
        dtype = {".png": "uint8", ".jpg": "uint8", ".jpeg": "uint8", ".exr": "half" if img.shape[2] > 1 else "float"}.get(ext, "float")
    type_desc = {"uint8": oiio.UINT8, "uint16": oiio.UINT16, "half": oiio.HALF, "float": oiio.FLOAT}[dtype]
    data = img.astype(np.float32)
    if dtype in ("uint8", "uint16"):
        data = np.clip(np.nan_to_num(data), 0.0, 1.0)
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], type_desc)
    if ext == ".exr":
        spec.attribute("compression", "zip")
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise OSError(f"{path}: no image writer for this extension ({oiio.geterror()})")
        try:
            if not out.open(str(tmp), spec) or not out.write_image(np.ascontiguousarray(data)):
                raise OSError(f"{path}: cannot write image: {out.geterror()}")
        finally:
            out.close()
    return path


def read_mask(path: str | os.PathLike) -> np.ndarray:
    """Single-channel mask [H, W] float32 in [0, 1] (first channel of a multi-channel file)."""
    return read_image(path)[:, :, 0]


def write_mask(path: str | os.PathLike, mask: np.ndarray) -> Path:
    m = np.asarray(mask, dtype=np.float32)
    if m.ndim == 3:
        m = m[:, :, 0]
    return write_image(path, m)


def read_id_map(path: str | os.PathLike) -> np.ndarray:
    """Integer id map [H, W] (0 = background), stored as 16-bit PNG or float EXR."""
    oiio = _oiio()
    path = Path(path)
    img = read_image(path)[:, :, 0]
    spec = oiio.ImageInput.open(str(path))
    fmt = spec.spec().format if spec else None
    if spec:
        spec.close()
    if fmt is not None and fmt == oiio.UINT16:
        return np.rint(img * 65535.0).astype(np.int32)
    if fmt is not None and fmt == oiio.UINT8:
        return np.rint(img * 255.0).astype(np.int32)
    return np.rint(img).astype(np.int32)


def write_id_map(path: str | os.PathLike, ids: np.ndarray) -> Path:
    """Exact integer ids: 16-bit PNG (ids < 65536) or float EXR."""
    ids = np.asarray(ids)
    if ids.min(initial=0) < 0 or ids.max(initial=0) > 65535:
        raise ValueError(f"write_id_map({path}): ids must lie in 0..65535")
    path = Path(path)
    if path.suffix.lower() == ".exr":
        return write_image(path, ids.astype(np.float32), dtype="float")
    return write_image(path, ids.astype(np.float64) / 65535.0, dtype="uint16")
