"""What a file is, from its bytes: its media type from the first bytes, an image's size from its
header. Nothing here decodes pixels, so it is safe on any upload before any limit is checked.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

IMAGE_TYPES = ("png", "jpeg")
VIDEO_TYPES = ("mp4", "mov", "mkv", "webm", "avi")
SNIFF_BYTES = 64  # enough for every signature below
EXTENSIONS = {
    "png": "png",
    "jpeg": "jpg",
    "mp4": "mp4",
    "mov": "mov",
    "mkv": "mkv",
    "webm": "webm",
    "avi": "avi",
}
# ISO base media top-level boxes that may come first in a QuickTime/MP4 file
_ISO_BOXES = (b"ftyp", b"moov", b"mdat", b"wide", b"free", b"skip", b"pnot")


def sniff_type(head: bytes) -> str | None:
    """The media type of a file from its first bytes (>= SNIFF_BYTES when the file is that long)."""
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return "png"
    if head.startswith(b"\xff\xd8\xff"):
        return "jpeg"
    if head[:4] == b"RIFF" and head[8:12] == b"AVI ":
        return "avi"
    if head.startswith(b"\x1a\x45\xdf\xa3"):  # EBML: Matroska or WebM, told apart by DocType
        return "webm" if b"webm" in head[:SNIFF_BYTES] else "mkv"
    if len(head) >= 12 and head[4:8] in _ISO_BOXES:
        if head[4:8] == b"ftyp" and head[8:12] == b"qt  ":
            return "mov"
        return "mp4"
    return None


def media_kind(media_type: str) -> str:
    return "images" if media_type in IMAGE_TYPES else "video"


@dataclass(frozen=True)
class ImageHeader:
    width: int
    height: int


def png_header(data: bytes) -> ImageHeader | None:
    """Width and height from the IHDR chunk (bytes 16..24), None if malformed."""
    if len(data) < 24 or data[12:16] != b"IHDR":
        return None
    width, height = struct.unpack(">II", data[16:24])
    return ImageHeader(width, height)


# JPEG start-of-frame markers carry the size; C4 (DHT), C8 (JPG) and CC (DAC) are not frames.
_SOF_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def jpeg_header(data: bytes) -> ImageHeader | None:
    """Width and height from the first start-of-frame segment, None if none is found."""
    i = 2
    n = len(data)
    while i + 4 <= n:
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # no length field
            i += 2
            continue
        (length,) = struct.unpack(">H", data[i + 2 : i + 4])
        if marker in _SOF_MARKERS:
            if i + 9 > n:
                return None
            height, width = struct.unpack(">HH", data[i + 5 : i + 9])
            return ImageHeader(width, height)
        if marker == 0xDA or length < 2:  # start of scan before any frame header: malformed
            return None
        i += 2 + length
    return None


def image_header(
    path: Path, media_type: str, max_header_bytes: int = 1 << 20
) -> ImageHeader | None:
    """Image size read from the file's header only: safe to call before any full decode."""
    with path.open("rb") as f:
        data = f.read(max_header_bytes)
    return png_header(data) if media_type == "png" else jpeg_header(data)


def image_is_complete(path: Path, media_type: str) -> bool:
    """Whether the file ends the way a whole image does (decoders silently accept truncated JPEGs)."""
    size = path.stat().st_size
    with path.open("rb") as f:
        f.seek(max(0, size - 64))
        tail = f.read()
    if media_type == "png":
        return b"IEND" in tail
    return b"\xff\xd9" in tail.rstrip(b"\x00")[-16:]
