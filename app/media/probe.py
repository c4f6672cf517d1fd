"""Whether stored media is usable, checked the same way by the API (at upload) and the worker.

Order matters for memory: sizes come from headers first (no pixels decoded), every limit is
checked on those sizes, and only then is anything decoded, one image at a time and never more than
`DECODE_SLOTS` at once per process.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path

import cv2

from app.calib.limits import MIN_IMAGE_HEIGHT_PX, MIN_IMAGE_WIDTH_PX
from app.media import sniff
from app.settings import Settings

# Full decodes at once per process: each holds one image's pixels (<= max_image_pixels bytes, as
# grey). Uploads beyond that wait their turn instead of multiplying the API's memory.
DECODE_SLOTS = threading.BoundedSemaphore(2)


class MediaError(Exception):
    """Media that cannot be used; `code` is the API's (or the job's) error code."""

    def __init__(self, code: str, message: str, status: int = 422) -> None:
        super().__init__(message)
        self.code = code
        self.message = message
        self.status = status


@dataclass
class StoredFile:
    name: str  # file name inside the job directory
    media_type: str
    size_bytes: int


@dataclass(frozen=True)
class MediaSummary:
    kind: str  # "images" or "video"
    image_size: tuple[int, int]  # (width, height)
    duration_s: float | None = None


def image_size(path: Path, media_type: str, index: int, settings: Settings) -> tuple[int, int]:
    """(width, height) from the image's header, within the pipeline's minimum and the pixel limit."""
    header = sniff.image_header(path, media_type)
    if header is None or header.width <= 0 or header.height <= 0:
        raise MediaError("corrupt_image", f"file #{index + 1} is not a readable {media_type} image")
    width, height = header.width, header.height
    if width < MIN_IMAGE_WIDTH_PX or height < MIN_IMAGE_HEIGHT_PX:
        raise MediaError(
            "image_too_small",
            f"file #{index + 1} is {width}x{height} pixels; calibration needs at least "
            f"{MIN_IMAGE_WIDTH_PX}x{MIN_IMAGE_HEIGHT_PX}",
        )
    if width * height > settings.max_image_pixels:
        raise MediaError(
            "image_too_large",
            f"file #{index + 1} is {width}x{height} pixels; the limit is "
            f"{settings.max_image_pixels} pixels per image",
        )
    return width, height


class PixelBudget:
    """Pixels of one upload's images, counted from their headers: what decoding them will cost."""

    def __init__(self, settings: Settings) -> None:
        self.limit = settings.max_upload_pixels
        self.total = 0

    def add(self, size: tuple[int, int]) -> None:
        self.total += size[0] * size[1]
        if self.total > self.limit:
            raise MediaError(
                "too_many_pixels",
                f"the images hold more than {self.limit} pixels together; send fewer or smaller "
                "images",
                status=413,
            )


def check_upload(directory: Path, files: list[StoredFile], settings: Settings) -> MediaSummary:
    """Checks that need the bytes on disk: decodable, within the limits, one size.

    Blocking (decodes images, opens the video): run it in a thread pool.
    """
    kinds = {sniff.media_kind(f.media_type) for f in files}
    if kinds == {"video"}:
        if len(files) != 1:
            raise MediaError("too_many_videos", "upload one video clip, not several")
        return check_video(directory / files[0].name, settings)
    if kinds != {"images"}:
        raise MediaError("mixed_media", "upload either images or one video clip, not both together")
    sizes = checked_image_sizes([directory / f.name for f in files], settings)
    for i, f in enumerate(files):
        check_image_decodes(directory / f.name, f.media_type, i, sizes[i])
    return MediaSummary("images", sizes[0])


def checked_image_sizes(paths: list[Path], settings: Settings) -> list[tuple[int, int]]:
    """Every image's size from its header, checked one by one, together, and for sameness."""
    budget = PixelBudget(settings)
    sizes = []
    for i, path in enumerate(paths):
        size = image_size(path, media_type_of(path), i, settings)
        budget.add(size)
        sizes.append(size)
    if len(set(sizes)) > 1:
        listed = ", ".join(f"#{i + 1}: {w}x{h}" for i, (w, h) in enumerate(sizes))
        raise MediaError(
            "mixed_image_sizes",
            f"all images must come from the same camera at the same size; got {listed}",
        )
    return sizes


def media_type_of(path: Path) -> str:
    """The type of a stored file: the store names files by their sniffed type."""
    suffix = path.suffix.lstrip(".").lower()
    for media_type, extension in sniff.EXTENSIONS.items():
        if extension == suffix:
            return media_type
    raise MediaError("corrupt_image", f"stored file {path.name!r} has no known media type")


def check_image_decodes(path: Path, media_type: str, index: int, size: tuple[int, int]) -> None:
    if not sniff.image_is_complete(path, media_type):
        raise MediaError(
            "corrupt_image", f"file #{index + 1} is truncated (the {media_type} has no end)"
        )
    # grey: one byte per pixel is enough to prove the whole stream decodes
    with DECODE_SLOTS:
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None or image.shape[:2] != (size[1], size[0]):
        raise MediaError("corrupt_image", f"file #{index + 1} could not be decoded")


def decode_image(path: Path, index: int) -> cv2.typing.MatLike:
    """A checked image's pixels (BGR), decoded under the per-process limit."""
    with DECODE_SLOTS:
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise MediaError("corrupt_image", f"image #{index + 1} could not be decoded")
    return image


def _frame_size_error(width: int, height: int, settings: Settings) -> MediaError | None:
    if width < MIN_IMAGE_WIDTH_PX or height < MIN_IMAGE_HEIGHT_PX:
        return MediaError(
            "video_frame_too_small",
            f"video frames are {width}x{height}; calibration needs at least "
            f"{MIN_IMAGE_WIDTH_PX}x{MIN_IMAGE_HEIGHT_PX}",
        )
    if width > settings.max_video_width_px or height > settings.max_video_height_px:
        return MediaError(
            "video_frame_too_large",
            f"video frames are {width}x{height}; the limit is "
            f"{settings.max_video_width_px}x{settings.max_video_height_px}",
        )
    return None


def check_video(path: Path, settings: Settings) -> MediaSummary:
    """Opens, has a decodable first frame, within the size and duration limits."""
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise MediaError(
                "corrupt_video", "the video could not be opened (corrupt or truncated)"
            )
        # the container's declared size first: refuse absurd frames before decoding one
        width = int(capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        declared_error = _frame_size_error(width, height, settings)
        if declared_error is not None and declared_error.code == "video_frame_too_large":
            raise declared_error
        fps = capture.get(cv2.CAP_PROP_FPS)
        n_frames = capture.get(cv2.CAP_PROP_FRAME_COUNT)
        duration_s = float(n_frames / fps) if fps > 0 and n_frames > 0 else None
        if duration_s is not None and duration_s > settings.max_video_duration_s:
            raise MediaError(
                "video_too_long",
                f"the clip lasts {duration_s:.0f} s; the limit is "
                f"{settings.max_video_duration_s:.0f} s",
            )
        ok, frame = capture.read()
        if not ok or frame is None or frame.size == 0:
            raise MediaError("video_no_frames", "the video has no decodable frame")
        frame_h, frame_w = frame.shape[:2]
        frame_error = _frame_size_error(frame_w, frame_h, settings)
        if frame_error is not None:
            raise frame_error
        return MediaSummary("video", (frame_w, frame_h), duration_s)
    finally:
        capture.release()
