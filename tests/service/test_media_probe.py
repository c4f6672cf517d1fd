"""app.media: the same checks on both sides, and a bounded number of decodes at once."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from app.media import frames, probe
from tests.service.conftest import make_settings
from tests.service.helpers import png_bytes


def _write(directory: Path, name: str, data: bytes) -> Path:
    path = directory / name
    path.write_bytes(data)
    return path


def test_decodes_at_once_are_bounded_per_process(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = _write(tmp_path, "000.png", png_bytes(64, 48))
    real_imread = probe.cv2.imread
    lock = threading.Lock()
    running = 0
    peak = 0

    def slow_imread(*args, **kwargs):  # type: ignore[no-untyped-def]
        nonlocal running, peak
        with lock:
            running += 1
            peak = max(peak, running)
        time.sleep(0.05)
        with lock:
            running -= 1
        return real_imread(*args, **kwargs)

    monkeypatch.setattr(probe.cv2, "imread", slow_imread)
    with ThreadPoolExecutor(8) as pool:
        list(pool.map(lambda i: probe.check_image_decodes(path, "png", i, (64, 48)), range(16)))
    assert 1 <= peak <= 2


def test_worker_applies_the_upload_checks_before_decoding(tmp_path: Path) -> None:
    """Media stored by an older API (or put there by hand) meets the same limits in the worker."""
    settings = make_settings(tmp_path / "data", max_upload_pixels=2 * 64 * 48)
    ok = [_write(tmp_path, f"00{i}.png", png_bytes(64, 48, seed=i)) for i in range(2)]
    with frames.spool_images(ok, settings) as spool:
        assert (spool.n_frames, spool.height, spool.width) == (2, 48, 64)
    three = [*ok, _write(tmp_path, "002.png", png_bytes(64, 48, seed=3))]
    with pytest.raises(probe.MediaError) as too_many:
        frames.spool_images(three, settings)
    assert (too_many.value.code, too_many.value.status) == ("too_many_pixels", 413)
    tiny = [_write(tmp_path, "tiny.png", png_bytes(1, 1))]
    with pytest.raises(probe.MediaError) as too_small:
        frames.spool_images(tiny, settings)
    assert too_small.value.code == "image_too_small"
