"""Shots of a clip (cuts, zooms, dissolves) and the background of its longest static view."""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import cv2
import numpy as np
import pytest

from app.calib import shots
from app.calib.background import (
    METHODS,
    ClipError,
    SpreadSample,
    background_from_clip,
    background_from_frames,
    clip_frames_within,
    video_samples,
)
from tests import clips

SIZE = (480, 270)  # every frame is a sample at this size (see background.sample_interval_s)
FPS = 25.0
SEED = 5
T = TypeVar("T")


def _decoded(path: Path) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    capture.release()
    return frames


def _through_codec(frame: np.ndarray, path: Path) -> np.ndarray:
    """A still frame as the clip's codec returns it: the reference for a clip's background."""
    clips.write_video([frame] * 3, path)
    return _decoded(path)[1]


def _differs(background: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(mean abs difference, share of pixels off by more than 25 grey levels in some channel)."""
    diff = cv2.absdiff(background, truth).max(axis=2)
    return float(diff.mean()), float((diff > 25).mean())


@pytest.fixture(scope="module")
def main_view() -> tuple[list[np.ndarray], np.ndarray]:
    """60 frames of the main camera with two players, and its empty-court render."""
    genome = clips.main_camera(SIZE)
    frames = clips.render_clip_frames(genome, SIZE, 60, SEED)
    return frames, clips.render_court_image(genome, SIZE, rng=SEED)


@pytest.fixture(scope="module")
def close_up() -> list[np.ndarray]:
    return clips.render_clip_frames(clips.close_up_camera(SIZE), SIZE, 40, SEED + 1)


# ---------------------------------------------------------------------------------------------
# view signatures


def test_a_view_matches_itself_and_not_a_moved_or_blank_one(main_view) -> None:
    frames, _ = main_view
    reference = shots.view_signature(frames[0])
    assert shots.view_shift_px(reference, reference) == 0.0
    # players moved: still the same view
    assert shots.view_shift_px(reference, shots.view_signature(frames[30])) < 0.1
    # the camera panned by 3 px (2 signature px)
    panned = np.roll(frames[0], 3, axis=1)
    assert shots.view_shift_px(reference, shots.view_signature(panned)) > 1.5
    blank = np.full_like(frames[0], 90)
    assert not shots.view_signature(blank).has_structure
    assert shots.view_shift_px(reference, shots.view_signature(blank)) == np.inf
    assert shots.view_shift_px(shots.view_signature(blank), reference) == np.inf
    smaller = cv2.resize(frames[0], (240, 135))
    assert shots.view_shift_px(reference, shots.view_signature(smaller)) == np.inf


def test_exposure_change_is_not_a_new_view(main_view) -> None:
    frames, _ = main_view
    reference = shots.view_signature(frames[0])
    for gain, offset in ((0.85, 12.0), (1.15, -10.0)):  # auto-exposure: the whole frame alike
        exposed = cv2.convertScaleAbs(frames[30], alpha=gain, beta=offset)
        assert shots.view_shift_px(reference, shots.view_signature(exposed)) < 0.15


def test_samples_must_come_in_time_order(main_view) -> None:
    signature = shots.view_signature(main_view[0][0])
    segmenter = shots.ShotSegmenter()
    segmenter.add(5, 0.2, signature)
    with pytest.raises(ValueError, match="time order"):
        segmenter.add(5, 0.2, signature)


def test_segmenter_remembers_few_views_but_the_long_ones(main_view) -> None:
    frames, _ = main_view
    segmenter = shots.ShotSegmenter(max_views_remembered=3)
    scales = [1.0] * 5 + [1.0 + 0.02 * k for k in range(1, 11)] + [1.0] * 3
    for index, scale in enumerate(scales):
        shot, _ = segmenter.add(
            index, index / FPS, shots.view_signature(clips.zoomed(frames[index], scale))
        )
    assert sum(anchor is not None for anchor in segmenter.view_anchors) <= 3
    assert len(segmenter.view_anchors) == 11  # the main view and ten zoom steps
    # the main view came back and was recognised: it was remembered as the longest
    assert shot.view == 0 and [s.view for s in segmenter.shots].count(0) == 2


def test_spread_sample_is_bounded_and_even() -> None:
    sample = SpreadSample(8)
    frame = np.zeros((2, 2, 3), np.uint8)
    for index in range(1000):
        sample.add((index, frame))
        assert len(sample.items) < 8
    indices = [i for i, _ in sample.items]
    assert indices[0] == 0 and len(set(np.diff(indices))) == 1  # evenly spaced
    assert indices[-1] > 1000 - 2 * (indices[1] - indices[0])  # up to the end of the stream
    assert [i for i, _ in sample.pick(3)] == [indices[0], indices[len(indices) // 2], indices[-1]]
    sample.shrink(2)
    assert [i for i, _ in sample.items] == [indices[0], indices[-1]]


# ---------------------------------------------------------------------------------------------
# clips


def test_static_clip_is_one_shot(main_view, tmp_path: Path) -> None:
    frames, truth = main_view
    path = tmp_path / "static.mp4"
    clips.write_video(frames[:40], path, fps=FPS)
    background, moving, info = background_from_clip(path, n_frames=9)
    assert info["shots"] == 1 and info["views"] == 1
    assert info["cuts_s"] == [] and info["camera_moves_s"] == []
    assert info["frame_ranges"] == [[0, 39]]
    assert info["time_ranges_s"] == [[0.0, 1.6]]
    assert info["view_duration_s"] == 1.6
    assert info["frames_used"] == 9 and info["frame_indices_used"][0] == 0
    mean_diff, off = _differs(background, _through_codec(truth, tmp_path / "truth.mp4"))
    assert mean_diff < 2.0 and off < 0.002
    assert (moving > 0).mean() < 0.03


def test_cut_to_a_close_up_and_back(main_view, close_up, tmp_path: Path) -> None:
    """Main view 30 frames, close-up 40, main view 30: the main view (twice) makes the background."""
    frames, truth = main_view
    clip = frames[:30] + close_up + frames[30:]
    path = tmp_path / "cut.mp4"
    clips.write_video(clip, path, fps=FPS)
    background, moving, info = background_from_clip(path)
    assert info["views"] == 2 and info["shots"] == 3
    assert info["cuts_s"] == [1.2, 2.8]
    # the longest single shot is the close-up; the main view is longer over its two shots
    assert info["frame_ranges"] == [[0, 29], [70, 99]]
    assert info["time_ranges_s"] == [[0.0, 1.2], [2.8, 4.0]]
    assert info["view_duration_s"] == 2.4
    used = np.array(info["frame_indices_used"])
    assert len(used) == 15 and np.all((used < 30) | (used >= 70))
    assert used.min() < 10 and used.max() > 90  # spread over both shots
    reference = _through_codec(truth, tmp_path / "truth.mp4")
    mean_diff, off = _differs(background, reference)
    assert mean_diff < 2.0 and off < 0.002
    # the moving mask is the main view's: players only
    assert (moving > 0).mean() < 0.03
    # frames of both views together: the mask says nothing can be trusted
    _, mixed_moving = background_from_frames(_decoded(path)[::7])
    assert (mixed_moving > 0).mean() > 0.5


def test_zoom_starts_a_new_view(main_view, tmp_path: Path) -> None:
    """30 frames wide, a 1 s zoom to 1.12x, 45 frames zoomed: the zoomed view is the background."""
    frames, truth = main_view
    final_scale = 1.12
    ramp = [1.0 + (final_scale - 1.0) * (k + 1) / 25 for k in range(25)]
    scales = [1.0] * 30 + ramp + [final_scale] * 45
    clip = [clips.zoomed(frames[i % len(frames)], s) for i, s in enumerate(scales)]
    path = tmp_path / "zoom.mp4"
    clips.write_video(clip, path, fps=FPS)
    background, moving, info = background_from_clip(path)
    # the zoom is seen as the camera moving between neighbouring frames, not as a cut
    assert info["cuts_s"] == []
    moves = np.array(info["camera_moves_s"])
    assert len(moves) >= 5 and moves.min() >= 30 / FPS and moves.max() <= 55 / FPS
    [[first, last]] = info["frame_ranges"]
    # frame 54 is the first at the final scale; frame 53 is 0.4 % wider, within the tolerance
    assert 53 <= first <= 54 and last == 99
    reference = _through_codec(clips.zoomed(truth, final_scale), tmp_path / "truth.mp4")
    mean_diff, off = _differs(background, reference)
    assert mean_diff < 2.0 and off < 0.002
    assert (moving > 0).mean() < 0.03


def test_dissolve_ends_the_shot(main_view, close_up, tmp_path: Path) -> None:
    """50 frames of the main view, a 12-frame cross-fade to the close-up, 38 frames of it."""
    frames, truth = main_view
    fade = [clips.dissolve(frames[50 + k], close_up[k], (k + 1) / 13) for k in range(10)]
    fade += [clips.dissolve(frames[k], close_up[10 + k], (k + 11) / 13) for k in range(2)]
    clip = frames[:50] + fade + close_up[12:] + close_up[:10]
    path = tmp_path / "dissolve.mp4"
    clips.write_video(clip, path, fps=FPS)
    background, _, info = background_from_clip(path)
    [[first, last]] = info["frame_ranges"]
    # 1/13 of the close-up in frame 50 may pass as the main view; 2/13 in frame 51 does not
    assert first == 0 and last in (49, 50)
    mean_diff, off = _differs(background, _through_codec(truth, tmp_path / "truth.mp4"))
    assert mean_diff < 2.0 and off < 0.002


def test_no_static_view_is_an_error(main_view, tmp_path: Path) -> None:
    frames, _ = main_view
    clip = [clips.zoomed(frame, 1.0 + 0.01 * i) for i, frame in enumerate(frames[:40])]
    path = tmp_path / "zooming.mp4"
    clips.write_video(clip, path, fps=FPS)
    with pytest.raises(ClipError, match="no static view of the court longer than 1 s") as err:
        background_from_clip(path)
    assert err.value.code == "no_static_view"
    # a clip shorter than the minimum is fine when it is one view
    short = tmp_path / "short.mp4"
    clips.write_video(frames[:10], short, fps=FPS)
    assert background_from_clip(short)[2]["frame_ranges"] == [[0, 9]]


def test_samples_from_an_iterator(main_view, close_up) -> None:
    """Frames straight from the caller (no codec), every second frame, with their timestamps."""
    frames, truth = main_view
    clip = frames[:30] + close_up + frames[30:]
    samples = [(i, i / FPS, frame) for i, frame in enumerate(clip) if i % 2 == 0]
    background, moving, info = background_from_clip(samples, n_frames=9)
    assert info["frame_ranges"] == [[0, 28], [70, 98]]
    assert info["time_ranges_s"] == [[0.0, 1.16], [2.8, 3.96]]
    assert info["samples"] == 50
    assert _differs(background, truth)[0] < 1.0
    assert (moving > 0).mean() < 0.03


# ---------------------------------------------------------------------------------------------
# memory of a clip


@pytest.mark.parametrize("method", METHODS)
def test_a_clips_background_is_that_of_the_frames_it_used(main_view, close_up, method) -> None:
    """The clip's background is made band by band from its kept frames: the same arrays as
    background_from_frames on those frames; and the default budget changes nothing at this size."""
    frames, _ = main_view
    clip = frames[:30] + close_up + frames[30:]
    samples = [(i, i / FPS, frame) for i, frame in enumerate(clip)]
    background, moving, info = background_from_clip(samples, n_frames=9, method=method)
    assert info["frames_used"] == 9 and not info["frames_limited_by_memory"]
    used = [clip[i] for i in info["frame_indices_used"]]
    want_background, want_moving = background_from_frames(used, method=method)
    assert want_moving.any()  # a player lingered somewhere: the masks are compared too
    np.testing.assert_array_equal(background, want_background)
    np.testing.assert_array_equal(moving, want_moving)
    budgeted = background_from_clip(
        samples, n_frames=9, method=method, max_frames_bytes=1024 * 10**6
    )
    assert budgeted[2]["frame_indices_used"] == info["frame_indices_used"]
    np.testing.assert_array_equal(budgeted[0], background)
    np.testing.assert_array_equal(budgeted[1], moving)


def test_frames_within_a_memory_budget() -> None:
    budget = 1024 * 10**6  # the worker's default (settings.max_clip_frames_mb)
    for width, height, frames in [
        (640, 360, 15),
        (1920, 1080, 15),
        (2560, 1440, 15),
        (3840, 2160, 13),
        (4096, 4096, 6),
    ]:
        assert clip_frames_within(15, width * height * 3, budget) == frames, (width, height)
    assert clip_frames_within(15, 4096 * 4096 * 3, None) == 15
    # never below 3 frames for a budget, nor above what was asked
    assert clip_frames_within(15, 4096 * 4096 * 3, 1) == 3
    assert clip_frames_within(2, 4096 * 4096 * 3, 1) == 2


def test_a_small_budget_uses_fewer_frames(main_view) -> None:
    frames, _ = main_view
    samples = [(i, i / FPS, frame) for i, frame in enumerate(frames)]
    frame_bytes = frames[0].nbytes
    _, _, info = background_from_clip(samples, max_frames_bytes=3 * 5 * frame_bytes)
    assert info["frames_used"] == 5 and info["frames_limited_by_memory"]
    # a view with fewer samples than the budget allows was not limited by it
    _, _, short = background_from_clip(samples[:4], max_frames_bytes=3 * 5 * frame_bytes)
    assert short["frames_used"] == 4 and not short["frames_limited_by_memory"]


def _court_views(width: int, height: int) -> list[np.ndarray]:
    """Two views of a grey "court" of random light lines: large frames that are cheap to make."""
    rng = np.random.default_rng(SEED)
    courts = []
    for _ in range(2):
        court = np.full((height, width, 3), 90, np.uint8)
        for _ in range(16):
            (x0, y0), (x1, y1) = rng.integers(0, (width, height), size=(2, 2))
            cv2.line(court, (int(x0), int(y0)), (int(x1), int(y1)), (235, 235, 235), width // 250)
        courts.append(court)
    return courts


def _large_clip(courts: list[np.ndarray], views: list[tuple[int, int]]) -> Iterator:
    """Samples made on the fly (each its own array, as a decoder gives them): per (view,
    n_samples), that view's court with a dark square (a player) crossing it."""
    height, width = courts[0].shape[:2]
    side = width // 10
    index = 0
    for view, n in views:
        for _ in range(n):
            frame = courts[view].copy()
            x = (index * side // 4) % (width - side)
            frame[height // 2 : height // 2 + side, x : x + side] = (40, 30, 150)
            yield index, index / FPS, frame
            del frame  # as video_samples: gone unless the consumer keeps it
            index += 1


def _traced_peak(run: Callable[[], T]) -> tuple[T, int]:
    """run()'s result and the peak of the memory traced while it ran (numpy's arrays included)."""
    tracemalloc.start()
    try:
        result = run()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_memory_budget_bounds_a_clip_of_large_frames() -> None:
    """2000x2000 frames (12 MB each) of one view, a cut to another and back (both views' samples
    are kept at their fullest: 2 x 5 of the view on screen, 5 of the other) with a 200 MB budget:
    5 frames, at most 15 kept (180 MB). The peak of all Python and numpy allocations (tracemalloc;
    the source makes each frame as it is read) holds those 15 frames and stays within the budget
    plus one frame (the sample's grey signature and the band work are far smaller). Without a
    budget: 15 frames, and up to 42 kept at once (~500 MB)."""
    width = height = 2000
    frame_bytes = width * height * 3
    budget = 200 * 10**6
    views = [(0, 24), (1, 20), (0, 12)]
    courts = _court_views(width, height)

    (background, moving, info), peak = _traced_peak(
        lambda: background_from_clip(_large_clip(courts, views), max_frames_bytes=budget)
    )
    assert info["shots"] == 3 and info["frame_ranges"] == [[0, 23], [44, 55]]
    assert info["frames_used"] == 5 and info["frames_limited_by_memory"]
    assert background.shape == (height, width, 3) and moving.shape == (height, width)
    assert 15 * frame_bytes <= peak <= budget + frame_bytes, peak / 1e6

    (_, _, unbounded_info), unbounded_peak = _traced_peak(
        lambda: background_from_clip(_large_clip(courts, views))
    )
    assert unbounded_info["frames_used"] == 15
    assert not unbounded_info["frames_limited_by_memory"]
    assert unbounded_peak > 2.5 * peak, (unbounded_peak / 1e6, peak / 1e6)


# ---------------------------------------------------------------------------------------------
# reading a video


def test_video_samples_are_spaced_in_time(tmp_path: Path) -> None:
    path = tmp_path / "numbered.mp4"
    clips.write_video([np.full((48, 64, 3), 4 * i, np.uint8) for i in range(50)], path, fps=FPS)
    samples = list(video_samples(path, interval_s=0.2))
    assert [i for i, _, _ in samples] == list(range(0, 50, 5))
    np.testing.assert_allclose([t for _, t, _ in samples], np.arange(0, 2.0, 0.2), atol=1e-9)
    # codecs shift flat greys by a few levels
    np.testing.assert_allclose([f.mean() for _, _, f in samples], np.arange(0, 200, 20), atol=6)
    limited = list(video_samples(path, interval_s=0.0, max_duration_s=1.0))
    assert [i for i, _, _ in limited] == list(range(26))


def test_unreadable_video(tmp_path: Path) -> None:
    path = tmp_path / "broken.mp4"
    path.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(200))
    with pytest.raises(ClipError) as err:
        background_from_clip(path)
    assert err.value.code in ("corrupt_video", "video_no_frames")


def test_a_clip_error_crosses_process_boundaries_intact():
    import pickle

    error = pickle.loads(pickle.dumps(ClipError("no_static_view", "the camera moves")))
    assert isinstance(error, ClipError)
    assert error.code == "no_static_view" and str(error) == "the camera moves"
