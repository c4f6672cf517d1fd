"""Receiving a calibration upload: stream the multipart body to disk with a running byte count,
identify each file by its bytes and size each image from its header as soon as it is stored; the
checks that need whole files are `app.media.probe.check_upload`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from fastapi import Request
from python_multipart import MultipartParser
from python_multipart.multipart import parse_options_header

from app.api.errors import ApiError
from app.media import probe, sniff
from app.media.probe import MediaError, StoredFile
from app.settings import Settings

FILE_FIELD = "files"
FORM_FIELDS = ("start_camera", "seed", "bundle")
MAX_FORM_FIELD_BYTES = 64 * 1024
MAX_SEED = 2**63 - 1


@dataclass
class ReceivedUpload:
    files: list[StoredFile]
    fields: dict[str, str]


@dataclass
class _Part:
    headers: dict[str, str] = field(default_factory=dict)
    field_name: str = ""
    is_file: bool = False
    handle: BinaryIO | None = None
    head: bytes = b""
    tmp_path: Path | None = None
    size: int = 0
    value: bytearray = field(default_factory=bytearray)


def _content_disposition(value: str) -> tuple[str | None, bool]:
    """(field name, has a filename) from a part's Content-Disposition header."""
    kind, params = parse_options_header(value)
    if kind != b"form-data":
        return None, False
    name = params.get(b"name")
    return (name.decode("utf-8", "replace") if name is not None else None), b"filename" in params


class _Receiver:
    """Callbacks for python-multipart's push parser; raises ApiError as soon as a limit is hit."""

    def __init__(self, target_dir: Path, settings: Settings) -> None:
        self.target_dir = target_dir
        self.settings = settings
        self.files: list[StoredFile] = []
        self.fields: dict[str, str] = {}
        self.total_file_bytes = 0
        self.pixels = probe.PixelBudget(settings)
        self.part: _Part | None = None
        self._header_field = bytearray()
        self._header_value = bytearray()

    # -- header callbacks
    def on_part_begin(self) -> None:
        self.part = _Part()

    def on_header_field(self, data: bytes, start: int, end: int) -> None:
        self._header_field += data[start:end]

    def on_header_value(self, data: bytes, start: int, end: int) -> None:
        self._header_value += data[start:end]

    def on_header_end(self) -> None:
        assert self.part is not None
        self.part.headers[bytes(self._header_field).decode("latin-1").lower()] = bytes(
            self._header_value
        ).decode("latin-1")
        self._header_field.clear()
        self._header_value.clear()

    def on_headers_finished(self) -> None:
        part = self.part
        assert part is not None
        name, has_filename = _content_disposition(part.headers.get("content-disposition", ""))
        if name is None:
            raise ApiError(422, "invalid_multipart", "a multipart part has no form-data name")
        part.field_name = name
        if name == FILE_FIELD:
            if not has_filename:
                raise ApiError(422, "invalid_multipart", "the 'files' parts must be files")
            if len(self.files) >= self.settings.max_files:
                raise ApiError(
                    413,
                    "too_many_files",
                    f"at most {self.settings.max_files} files per upload",
                )
            part.is_file = True
            part.tmp_path = self.target_dir / f"part{len(self.files):03d}.tmp"
            part.handle = part.tmp_path.open("wb")
        elif name not in FORM_FIELDS:
            raise ApiError(
                422,
                "unknown_field",
                f"unknown form field {name!r}; expected 'files' and optionally "
                + ", ".join(repr(f) for f in FORM_FIELDS),
            )

    # -- data
    def on_part_data(self, data: bytes, start: int, end: int) -> None:
        part = self.part
        assert part is not None
        chunk = data[start:end]
        if not part.is_file:
            part.value += chunk
            if len(part.value) > MAX_FORM_FIELD_BYTES:
                raise ApiError(
                    413, "field_too_large", f"form field {part.field_name!r} is too large"
                )
            return
        self.total_file_bytes += len(chunk)
        if self.total_file_bytes > self.settings.max_upload_bytes:
            raise ApiError(
                413,
                "upload_too_large",
                f"the upload exceeds the limit of {self.settings.max_upload_bytes} bytes",
            )
        if len(part.head) < sniff.SNIFF_BYTES:
            part.head += chunk[: sniff.SNIFF_BYTES - len(part.head)]
            # reject a wrong file type as soon as its signature is visible, not after the upload
            if len(part.head) >= sniff.SNIFF_BYTES and sniff.sniff_type(part.head) is None:
                raise _unsupported(len(self.files))
        assert part.handle is not None
        part.handle.write(chunk)
        part.size += len(chunk)

    def on_part_end(self) -> None:
        part = self.part
        assert part is not None
        self.part = None
        if not part.is_file:
            if part.field_name in self.fields:
                raise ApiError(422, "duplicate_field", f"form field {part.field_name!r} repeated")
            try:
                self.fields[part.field_name] = part.value.decode("utf-8")
            except UnicodeDecodeError:
                raise ApiError(
                    422, "invalid_field", f"form field {part.field_name!r} is not UTF-8 text"
                ) from None
            return
        assert part.handle is not None and part.tmp_path is not None
        part.handle.close()
        index = len(self.files)
        if part.size == 0:
            raise ApiError(422, "empty_file", f"file #{index + 1} is empty (zero bytes)")
        media_type = sniff.sniff_type(part.head)
        if media_type is None:
            raise _unsupported(index)
        name = f"{index:03d}.{sniff.EXTENSIONS[media_type]}"
        path = self.target_dir / name
        part.tmp_path.rename(path)
        if sniff.media_kind(media_type) == "images":
            # from the header, before the next part is read: a bomb costs nothing but its bytes
            self.pixels.add(probe.image_size(path, media_type, index, self.settings))
        self.files.append(StoredFile(name, media_type, part.size))

    def close_open_file(self) -> None:
        if self.part is not None and self.part.handle is not None:
            self.part.handle.close()


def _unsupported(index: int) -> ApiError:
    return ApiError(
        415,
        "unsupported_media_type",
        f"file #{index + 1} is not a PNG or JPEG image or an MP4/MOV/MKV/WebM/AVI video "
        "(recognised by its content, not its name)",
    )


async def receive_upload(request: Request, target_dir: Path, settings: Settings) -> ReceivedUpload:
    """Stream the multipart body into `target_dir` (which must exist and be empty).

    On any error the caller deletes `target_dir`; nothing is kept of a rejected upload.
    """
    content_type, params = parse_options_header(request.headers.get("content-type", ""))
    boundary = params.get(b"boundary")
    if content_type != b"multipart/form-data" or not boundary:
        raise ApiError(
            415,
            "unsupported_media_type",
            "send the upload as multipart/form-data with one or more 'files' parts",
        )
    declared = request.headers.get("content-length")
    # multipart framing adds a little; anything far beyond the limit is refused before reading
    if declared is not None and declared.isdigit() and int(declared) > _body_limit(settings):
        raise ApiError(
            413,
            "upload_too_large",
            f"the upload exceeds the limit of {settings.max_upload_bytes} bytes",
        )
    _check_boundary(boundary)
    receiver = _Receiver(target_dir, settings)
    callbacks: Any = {
        name: getattr(receiver, name)
        for name in (
            "on_part_begin",
            "on_part_data",
            "on_part_end",
            "on_header_field",
            "on_header_value",
            "on_header_end",
            "on_headers_finished",
        )
    }
    received = 0
    try:
        parser = MultipartParser(boundary, callbacks)
        async for chunk in request.stream():
            received += len(chunk)
            if received > _body_limit(settings):
                raise ApiError(
                    413,
                    "upload_too_large",
                    f"the upload exceeds the limit of {settings.max_upload_bytes} bytes",
                )
            parser.write(chunk)
        parser.finalize()
    except (ApiError, MediaError):
        raise
    except Exception as exc:  # the multipart parser's own errors: malformed body
        raise ApiError(422, "invalid_multipart", f"malformed multipart body: {exc}") from None
    finally:
        receiver.close_open_file()
    if receiver.part is not None:
        raise ApiError(422, "invalid_multipart", "the multipart body ended in the middle of a part")
    if not receiver.files:
        raise ApiError(422, "no_files", "the upload has no 'files' part")
    return ReceivedUpload(receiver.files, receiver.fields)


# RFC 2046 section 5.1.1: 1 to 70 characters from this set, not ending with a space
_BOUNDARY_CHARS = frozenset(
    b"0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ'()+_,-./:=? "
)
MAX_BOUNDARY_CHARS = 70


def _check_boundary(boundary: bytes) -> None:
    """Refuse a boundary the RFC does not allow before the parser sees it (it raises on some)."""
    if (
        len(boundary) > MAX_BOUNDARY_CHARS
        or boundary.endswith(b" ")
        or not set(boundary) <= _BOUNDARY_CHARS
    ):
        raise ApiError(
            422,
            "invalid_multipart",
            f"the multipart boundary must be 1 to {MAX_BOUNDARY_CHARS} letters, digits or "
            "'()+_,-./:=? (RFC 2046)",
        )


def _body_limit(settings: Settings) -> int:
    return settings.max_upload_bytes + 64 * 1024 + 1024 * settings.max_files


def parse_job_params(fields: dict[str, str], image_size: tuple[int, int]) -> dict[str, Any]:
    """The optional form fields, checked: start camera (genome or OpenCV JSON), seed, bundle."""
    from app.calib import camera

    params: dict[str, Any] = {"start_genome": None, "seed": 0, "bundle": None}
    raw_camera = fields.get("start_camera", "").strip()
    if raw_camera:
        try:
            genome, size = camera.camera_from_json(json.loads(raw_camera))
        except json.JSONDecodeError as exc:
            raise ApiError(
                422, "invalid_start_camera", f"start_camera is not JSON: {exc}"
            ) from None
        except RecursionError:
            # a camera is a flat list or a shallow object; thousands of nested brackets are not
            raise ApiError(
                422, "invalid_start_camera", "start_camera is nested too deeply to be a camera"
            ) from None
        except ValueError as exc:
            raise ApiError(422, "invalid_start_camera", f"start_camera: {exc}") from None
        if size is not None and tuple(size) != tuple(image_size):
            raise ApiError(
                422,
                "invalid_start_camera",
                f"start_camera is for {size[0]}x{size[1]} images but the upload is "
                f"{image_size[0]}x{image_size[1]}",
            )
        if not np.all(np.isfinite(genome)) or genome[0] <= 0 or genome[1] <= 0:
            raise ApiError(
                422, "invalid_start_camera", "start_camera needs finite numbers, positive focal"
            )
        params["start_genome"] = [float(v) for v in genome]
    raw_seed = fields.get("seed", "").strip()
    if raw_seed:
        try:
            seed = int(raw_seed)
        except ValueError:
            raise ApiError(422, "invalid_seed", "seed must be a whole number") from None
        if not 0 <= seed <= MAX_SEED:
            raise ApiError(422, "invalid_seed", f"seed must be between 0 and {MAX_SEED}")
        params["seed"] = seed
    raw_bundle = fields.get("bundle", "").strip()
    if raw_bundle:
        from app.calib.ga import get_bundle

        try:
            params["bundle"] = get_bundle(raw_bundle).name
        except ValueError as exc:
            raise ApiError(422, "unknown_bundle", str(exc)) from None
    return params
