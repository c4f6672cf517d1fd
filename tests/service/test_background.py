"""Player-free background from frames, whole or a band of rows at a time from a spool of an
upload's images. (A clip's frames: tests/test_shots.py.)"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from app.calib import background, scene, synthetic
from app.media import frames as worker_media

SIZE = (480, 270)


@pytest.fixture(scope="module")
def clip() -> tuple[list[np.ndarray], np.ndarray]:
    genome = synthetic.typical_target_camera(SIZE)
    frames = scene.render_clip_frames(genome, SIZE, 9, 11, n_players=2)
    truth = scene.render_court_image(genome, SIZE, rng=11)
    return frames, truth


def test_one_frame_is_its_own_background() -> None:
    frame = np.random.default_rng(0).integers(0, 255, (20, 30, 3), dtype=np.uint8)
    bg, mask = background.background_from_frames([frame])
    np.testing.assert_array_equal(bg, frame)
    assert mask.shape == (20, 30) and mask.dtype == np.uint8 and not mask.any()


@pytest.mark.parametrize("method", background.METHODS)
def test_players_are_removed(clip, method: str) -> None:
    frames, truth = clip
    touched = np.zeros(truth.shape[:2], bool)
    for frame in frames:
        touched |= cv2.absdiff(frame, truth).max(axis=2) > 0
    assert touched.mean() > 0.005  # the players really cover something
    bg, mask = background.background_from_frames(frames, method=method)
    error = cv2.absdiff(bg, truth).max(axis=2)
    assert error[touched].mean() < 1.0
    assert (error[touched] > 10).mean() < 0.01
    # players only crossed these pixels: the background is trusted almost everywhere
    assert (mask > 0).mean() < 0.02
    # while the frames themselves are far from the truth where players are
    assert cv2.absdiff(frames[0], truth).max(axis=2)[touched].mean() > 5


def test_mask_marks_where_a_player_lingered_not_where_one_passed() -> None:
    rng = np.random.default_rng(3)
    base = rng.integers(60, 200, (120, 160, 3), dtype=np.uint8)
    frames = [base.copy() for _ in range(9)]
    for frame in frames[:6]:  # standing still in 6 of 9 frames: the median shows the player
        frame[20:50, 20:40] = (20, 20, 160)
    frames[7][70:100, 100:120] = (10, 120, 10)  # crossing once
    for method in background.METHODS:
        bg, mask = background.background_from_frames(frames, method=method)
        assert mask[30:40, 25:35].all(), method
        assert not mask[75:95, 105:115].any(), method
        np.testing.assert_array_equal(bg[70:100, 100:120], base[70:100, 100:120])


def test_frames_must_agree_in_size_and_type() -> None:
    a = np.zeros((10, 10, 3), np.uint8)
    with pytest.raises(ValueError, match="one size"):
        background.background_from_frames([a, np.zeros((10, 12, 3), np.uint8)])
    with pytest.raises(ValueError, match="uint8"):
        background.background_from_frames([a.astype(np.float32)])
    with pytest.raises(ValueError, match="at least one"):
        background.background_from_frames([])
    with pytest.raises(ValueError, match="unknown background method"):
        background.background_from_frames([a, a], method="mode")


@pytest.mark.parametrize(
    "n_frames, band_rows, method",
    [(9, 16, "median_inlier_mean"), (8, 7, "median_inlier_mean"), (2, 270, "median_inlier_mean")]
    + [(3, 1000, "median_inlier_mean"), (9, 16, "median"), (8, 7, "frame_difference_mean")],
)
def test_the_banded_background_is_identical_to_the_whole_frame_one(
    clip, n_frames: int, band_rows: int, method: str
) -> None:
    frames, _ = clip
    stack = np.stack(frames[:n_frames])
    want_bg, want_mask = background.background_from_frames(list(stack), method=method)
    assert want_mask.any()  # the players leave something to mask
    reads: list[tuple[int, int]] = []

    def read_rows(top: int, bottom: int) -> np.ndarray:
        reads.append((top, bottom))
        return stack[:, top:bottom].copy()

    height, width = stack.shape[1:3]
    bg, mask = background.background_from_bands(
        n_frames, height, width, read_rows, band_rows, method=method
    )
    np.testing.assert_array_equal(bg, want_bg)
    np.testing.assert_array_equal(mask, want_mask)
    # it did read in bands (with their halo), never the whole frames at once, when bands are small
    if band_rows < height // 2:
        assert max(b - t for t, b in reads) < height


def test_one_frame_through_the_bands_is_its_own_background() -> None:
    frame = np.random.default_rng(0).integers(0, 255, (20, 30, 3), dtype=np.uint8)
    bg, mask = background.background_from_bands(
        1, 20, 30, lambda top, bottom: frame[None, top:bottom]
    )
    np.testing.assert_array_equal(bg, frame)
    assert not mask.any()


def test_frame_spool_reads_back_any_rows(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    frames = rng.integers(0, 255, (4, 50, 64, 3), dtype=np.uint8)
    with worker_media.FrameSpool(64, 50) as spool:
        for frame in frames:
            spool.append(frame)
        assert spool.n_frames == 4
        for top, bottom in [(0, 50), (0, 1), (49, 50), (13, 37)]:
            np.testing.assert_array_equal(spool.read_rows(top, bottom), frames[:, top:bottom])
        with pytest.raises(ValueError):
            spool.append(frames[0][:, :32])
        with pytest.raises(ValueError):
            spool.read_rows(10, 51)


def test_spooled_images_give_the_same_background_as_decoded_ones(clip, tmp_path: Path) -> None:
    from app.settings import Settings

    frames, _ = clip
    paths = []
    for i, frame in enumerate(frames[:5]):
        path = tmp_path / f"{i}.png"
        cv2.imwrite(str(path), frame)
        paths.append(path)
    settings = Settings(data_dir=tmp_path / "data")
    want = background.background_from_frames([cv2.imread(str(path)) for path in paths])
    with worker_media.spool_images(paths, settings) as spool:
        got = background.background_from_bands(
            spool.n_frames, spool.height, spool.width, spool.read_rows
        )
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
