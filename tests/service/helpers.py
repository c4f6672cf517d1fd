"""Small builders of upload content for the service tests (synthetic, made in the test)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from app.calib import scene


def png_bytes(width: int = 64, height: int = 48, seed: int = 0) -> bytes:
    rng = np.random.default_rng(seed)
    image = rng.integers(0, 255, (height, width, 3), dtype=np.uint8)
    ok, buf = cv2.imencode(".png", image)
    assert ok
    return buf.tobytes()


def jpeg_bytes(width: int = 64, height: int = 48, seed: int = 0) -> bytes:
    rng = np.random.default_rng(seed)
    image = rng.integers(0, 255, (height, width, 3), dtype=np.uint8)
    ok, buf = cv2.imencode(".jpg", image)
    assert ok
    return buf.tobytes()


def video_bytes(
    tmp_path: Path, width: int = 160, height: int = 120, n_frames: int = 10, fps: float = 25.0
) -> bytes:
    frames = [np.full((height, width, 3), 10 * i % 250, np.uint8) for i in range(n_frames)]
    path = tmp_path / f"clip_{width}x{height}_{n_frames}.mp4"
    scene.write_video(frames, path, fps=fps)
    return path.read_bytes()


def court_clip_bytes(
    tmp_path: Path,
    genome: np.ndarray,
    image_size: tuple[int, int],
    n_frames: int,
    seed: int,
    n_players: int = 2,
) -> bytes:
    frames = scene.render_clip_frames(genome, image_size, n_frames, seed, n_players=n_players)
    path = tmp_path / f"court_{seed}.mp4"
    scene.write_video(frames, path)
    return path.read_bytes()


def files(*contents: bytes, name: str = "upload.bin") -> list[tuple[str, tuple[str, bytes, str]]]:
    """Multipart 'files' parts with a misleading name and content type: the server must sniff."""
    return [
        ("files", (f"{i}-{name}", data, "application/octet-stream"))
        for i, data in enumerate(contents)
    ]
