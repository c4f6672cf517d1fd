"""Player-free background of a fixed camera from several frames, and where players were.

Estimators (frames: BGR uint8 (H, W, 3), one size):
- `temporal_median`: per pixel and channel, the median over the frames. Right wherever a player
  covers a pixel in fewer than half of the frames; keeps one frame's sensor and codec noise.
- `frame_difference_mean`: a frame's pixel counts as static when it barely differs from the
  frames before and after it (frame differencing); the background is the average of each pixel over
  the frames where it was static (noise averages out), the median where it never was. A player who
  stands still across neighbouring samples looks static, though.
- `median_inlier_mean`: the motion masks are the pixels differing from the median instead of from
  the neighbours; the average is over the frames that agree with the median. The median's
  robustness with the average's noise reduction.
`bench/background_methods.py` measures them on synthetic clips (players over a known empty court,
per-frame sensor noise, an MPEG-4 round trip): `median_inlier_mean` is closest to the player-free
truth (its error on the pixels players touched is at the level of averaging the empty clip itself),
`frame_difference_mean` next, the plain median last; so `background_from_frames` uses it.

The moving mask marks the pixels where the background cannot be trusted: many of the frames
disagree with it there, so the estimate may still show part of a player. Pixels a player only
crossed are NOT in it: their background is clean and often holds the court lines the fit needs
most (the T).

Clips (`background_from_clip`): one pass over the clip, never holding it. Every frame is decoded
(`grab`: a decoder can only start at keyframes, so seeking decodes from the keyframe before; 300
seeks into a 60 s 1080p clip took 7-13 s where reading it through took ~2 s, bench.clip_background),
but only samples `sample_interval_s` apart are converted to BGR and reduced to a view signature;
`shots` splits the samples into shots of one static view. Full frames are kept only for the view on
screen now (an evenly spread sample of at most 2 x `n_frames` frames) and for the longest other
view (`n_frames` of them), so memory stays bounded whatever the clip's length or number of shots.
The background is made from the longest view's frames alone (a view that returns after a replay
counts with all its shots), so its moving mask is that view's too. The returned info says which
time ranges were used.

Memory of a clip: the kept frames are at most 3 x the frames the background uses (2 x for the view
on screen, 1 x for the longest other one), plus the frame being sampled. With a byte budget
(`max_frames_bytes`, the worker's `max_clip_frames_mb`) the number of frames is lowered for large
frames so that those 3 x fit in it (never below `MIN_CLIP_FRAMES`), and the background is made
from the kept frames a band of rows at a time (`background_from_bands`, identical to
`background_from_frames`), so the median and mean steps never copy whole frames.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

import cv2
import numpy as np

from app.calib.shots import ShotSegmenter, longest_view, view_durations_s, view_signature

# A channel differing by more than this many grey levels between two frames is motion (sensor and
# compression noise stay well below it; a player or a shadow is far above).
MOTION_THRESHOLD = 25
# Where at least this fraction of the frames disagree with the background, it is not trusted: a
# player covering a pixel in 1/3 of the frames and one covering it in 2/3 look the same from the
# frames alone (the disagreeing third), and only the first gives a clean median.
UNTRUSTED_FRACTION = 0.25
# Masks grow by this fraction of the image width (soft player outlines, shadows' penumbra).
DILATE_FRACTION = 0.004
MEDIAN_STRIP_ROWS = 64
METHODS = ("median", "frame_difference_mean", "median_inlier_mean")


def _check_frames(frames: Sequence[np.ndarray]) -> list[np.ndarray]:
    if len(frames) == 0:
        raise ValueError("need at least one frame")
    checked = []
    for i, frame in enumerate(frames):
        arr = np.asarray(frame)
        if arr.dtype != np.uint8 or arr.ndim != 3 or arr.shape[2] != 3:
            raise ValueError(f"frame {i} must be BGR uint8 (H, W, 3), got {arr.dtype} {arr.shape}")
        if arr.shape != np.shape(frames[0]):
            raise ValueError(
                f"all frames must have one size; frame {i} is {arr.shape[1]}x{arr.shape[0]}, "
                f"frame 0 is {np.shape(frames[0])[1]}x{np.shape(frames[0])[0]}"
            )
        checked.append(arr)
    return checked


def _dilate(mask: np.ndarray, width_px: int) -> np.ndarray:
    radius = max(1, round(DILATE_FRACTION * width_px))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    return cv2.dilate(mask, kernel)


def temporal_median(frames: Sequence[np.ndarray]) -> np.ndarray:
    """Per-pixel, per-channel median over the frames: BGR uint8 (H, W, 3)."""
    stack = _check_frames(frames)
    height = stack[0].shape[0]
    out = np.empty_like(stack[0])
    # strips keep the temporary (n, rows, W, 3) copy small for long 4K clips
    n = len(stack)
    for top in range(0, height, MEDIAN_STRIP_ROWS):
        strip = np.stack([f[top : top + MEDIAN_STRIP_ROWS] for f in stack])
        rows = slice(top, top + MEDIAN_STRIP_ROWS)
        if n % 2:  # the middle value itself: a selection, no float conversion
            out[rows] = np.partition(strip, n // 2, axis=0)[n // 2]
        else:
            middle = np.partition(strip, (n // 2 - 1, n // 2), axis=0)
            pair = middle[n // 2 - 1].astype(np.uint16) + middle[n // 2]
            out[rows] = ((pair + 1) // 2).astype(np.uint8)
    return out


def _changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """uint8 (H, W) 255 where any channel differs by more than MOTION_THRESHOLD."""
    height, width = a.shape[:2]
    diff = cv2.absdiff(a, b).reshape(height * width, 3)
    # cv2's row reduction: ~20x faster than numpy's max over a length-3 last axis
    channel_max = cv2.reduce(diff, 1, cv2.REDUCE_MAX).reshape(height, width)
    _, moving = cv2.threshold(channel_max, MOTION_THRESHOLD, 255, cv2.THRESH_BINARY)
    return moving


def frame_motion_masks(frames: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Per frame, uint8 (H, W) 255 where it differs from its previous or next frame (dilated)."""
    stack = _check_frames(frames)
    if len(stack) == 1:
        return [np.zeros(stack[0].shape[:2], np.uint8)]
    width = stack[0].shape[1]
    pair_changed = [_changed(stack[i], stack[i + 1]) for i in range(len(stack) - 1)]
    masks = []
    for i in range(len(stack)):
        before = pair_changed[i - 1] if i > 0 else pair_changed[0]
        after = pair_changed[i] if i < len(pair_changed) else pair_changed[-1]
        masks.append(_dilate(cv2.bitwise_or(before, after), width))
    return masks


def frame_difference_mean(
    frames: Sequence[np.ndarray],
    masks: Sequence[np.ndarray] | None = None,
    median: np.ndarray | None = None,
) -> np.ndarray:
    """Average of each pixel over the frames where it was static; median where it never was."""
    stack = _check_frames(frames)
    masks = frame_motion_masks(stack) if masks is None else masks
    total = np.zeros(stack[0].shape, np.float32)
    count = np.zeros(stack[0].shape[:2], np.float32)
    ones = np.ones(stack[0].shape[:2], np.float32)
    for frame, moving in zip(stack, masks, strict=True):
        static = cv2.bitwise_not(moving)
        cv2.accumulate(frame, total, mask=static)
        cv2.accumulate(ones, count, mask=static)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / count[:, :, None]
    never_static = count == 0
    if np.any(never_static):
        median = temporal_median(stack) if median is None else median
        mean[never_static] = median[never_static]
    return np.clip(np.rint(mean), 0, 255).astype(np.uint8)


def median_inlier_mean(frames: Sequence[np.ndarray]) -> np.ndarray:
    """Average over the frames that agree with the median (a player is an outlier of the median)."""
    stack = _check_frames(frames)
    median = temporal_median(stack)
    width = stack[0].shape[1]
    masks = [_dilate(_changed(frame, median), width) for frame in stack]
    return frame_difference_mean(stack, masks, median)


def untrusted_mask(
    frames: Sequence[np.ndarray], background: np.ndarray, fraction: float = UNTRUSTED_FRACTION
) -> np.ndarray:
    """uint8 (H, W) 255 where the frames differ from the background in >= `fraction` of them."""
    stack = _check_frames(frames)
    if len(stack) == 1:
        return np.zeros(stack[0].shape[:2], np.uint8)
    votes = np.zeros(stack[0].shape[:2], np.int32)
    for frame in stack:
        votes += _changed(frame, background) > 0
    mask = np.where(votes >= max(1, int(np.ceil(fraction * len(stack)))), 255, 0).astype(np.uint8)
    return _dilate(mask, stack[0].shape[1])


def background_from_frames(
    frames: Sequence[np.ndarray], method: str = "median_inlier_mean"
) -> tuple[np.ndarray, np.ndarray]:
    """(background BGR uint8 (H, W, 3), moving_mask uint8 (H, W) 255 = do not trust) from frames.

    One frame: that frame and an empty mask.
    """
    stack = _check_frames(frames)
    _check_method(method)
    if len(stack) == 1:
        return stack[0].copy(), np.zeros(stack[0].shape[:2], np.uint8)
    return _background_and_mask(stack, method)


def _check_method(method: str) -> None:
    if method not in METHODS:
        raise ValueError(f"unknown background method {method!r}; known: {', '.join(METHODS)}")


def _background_and_mask(stack: list[np.ndarray], method: str) -> tuple[np.ndarray, np.ndarray]:
    if method == "median":
        background = temporal_median(stack)
    elif method == "frame_difference_mean":
        background = frame_difference_mean(stack)
    else:
        background = median_inlier_mean(stack)
    return background, untrusted_mask(stack, background)


# Rows per band of `background_from_bands` (plus the halo both sides): with 16 frames of 4096
# pixels across, one band of all frames is ~40 MB, against ~450 MB for the frames themselves.
BAND_ROWS = 128


def background_from_bands(
    n_frames: int,
    height: int,
    width: int,
    read_rows: Callable[[int, int], np.ndarray],
    band_rows: int = BAND_ROWS,
    method: str = "median_inlier_mean",
) -> tuple[np.ndarray, np.ndarray]:
    """`background_from_frames` computed one band of rows at a time, so that no more than a
    band of every frame is in memory besides the frames themselves, wherever `read_rows` reads
    them from (`app.media.frames.FrameSpool` keeps them in a temporary file, `background_from_clip`
    in memory).

    `read_rows(top, bottom)` -> uint8 (n_frames, bottom - top, width, 3): those rows of every
    frame. The result is identical to `background_from_frames` on the whole frames, with any of
    its methods: every step is per pixel except two mask dilations (radius r each: the motion
    masks, then the untrusted mask), so a band read with 2 r extra rows on both sides is exact
    on the band itself.
    """
    if n_frames < 1 or height < 1 or width < 1:
        raise ValueError(f"need frames of a positive size, got {n_frames} of {width}x{height}")
    _check_method(method)
    if n_frames == 1:
        return np.ascontiguousarray(read_rows(0, height)[0]), np.zeros((height, width), np.uint8)
    halo = 2 * max(1, round(DILATE_FRACTION * width))
    background = np.empty((height, width, 3), np.uint8)
    moving_mask = np.empty((height, width), np.uint8)
    for top in range(0, height, band_rows):
        bottom = min(height, top + band_rows)
        first, last = max(0, top - halo), min(height, bottom + halo)
        band = read_rows(first, last)
        if band.shape != (n_frames, last - first, width, 3) or band.dtype != np.uint8:
            raise ValueError(f"read_rows({first}, {last}) gave {band.dtype} {band.shape}")
        band_background, band_mask = _background_and_mask(list(band), method)
        background[top:bottom] = band_background[top - first : bottom - first]
        moving_mask[top:bottom] = band_mask[top - first : bottom - first]
    return background, moving_mask


# ----------------------------------------------------------------------------------------------
# Clips

# (frame index from 0, timestamp in seconds, BGR uint8 frame)
ClipSample = tuple[int, float, np.ndarray]

# Pixels per second of clip converted to BGR and reduced to signatures: sets the sampling interval
# by frame size (every frame of 640x360 up to 50 fps, every 5th of 1080p at 25 fps). Conversion and
# signature cost ~1.4 ms per 1080p frame here: ~10 ms per second of clip at every size.
SAMPLED_PIXELS_PER_S = 12e6
# Samples at least this often: cuts are located to within one interval, and a replay or a
# close-up lasts seconds.
MAX_SAMPLE_INTERVAL_S = 0.5
# Timestamps are rounded (often to milliseconds): a frame this close to the next sample time is due.
TIMESTAMP_SLACK_S = 1e-3
# Without a view on screen this long (unless the whole clip is one view) there is no background: a
# shorter stretch is a transition or a glimpse, with too little player movement to remove them.
MIN_STATIC_VIEW_S = 1.0
# A clip keeps at most this many full frames per frame of its background: 2 for the view on screen
# (its SpreadSample), 1 for the longest other view.
KEPT_FRAMES_PER_FRAME_USED = 3
# A memory budget never lowers a clip's background below this many frames (a median needs a
# majority of frames without the player; 3 is the fewest that has one).
MIN_CLIP_FRAMES = 3


class ClipError(ValueError):
    """The clip gives no background; `code` names why ("corrupt_video", "no_static_view", ...)."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code

    def __reduce__(self) -> tuple[type[ClipError], tuple[str, str]]:
        # crosses process boundaries (workers, process pools) intact
        return (ClipError, (self.code, str(self)))


def sample_interval_s(width_px: int, height_px: int) -> float:
    """Seconds between the samples of a clip of this frame size (see SAMPLED_PIXELS_PER_S)."""
    if width_px < 1 or height_px < 1:
        raise ValueError(f"frame size must be positive, got {width_px}x{height_px}")
    return min(width_px * height_px / SAMPLED_PIXELS_PER_S, MAX_SAMPLE_INTERVAL_S)


def video_samples(
    path: str | os.PathLike[str],
    interval_s: float | None = None,
    max_duration_s: float | None = None,
) -> Iterator[ClipSample]:
    """Frames of a video file at least `interval_s` apart (default: by frame size), in order.

    Every frame is decoded (`grab`), only the samples are converted (`retrieve`). Timestamps are
    the decoder's (variable frame rates stay right), else index / frame rate. Frames after
    `max_duration_s` are not read.
    """
    capture = cv2.VideoCapture(os.fspath(path))
    try:
        if not capture.isOpened():
            raise ClipError("corrupt_video", "the video could not be opened (corrupt or truncated)")
        if interval_s is None:
            interval_s = sample_interval_s(
                max(1, int(capture.get(cv2.CAP_PROP_FRAME_WIDTH))),
                max(1, int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))),
            )
        fps = capture.get(cv2.CAP_PROP_FPS)
        index = 0
        previous_s = -np.inf
        next_sample_s = -np.inf
        while capture.grab():
            time_s = capture.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
            if not (np.isfinite(time_s) and time_s > previous_s):
                if not fps > 0:
                    raise ClipError(
                        "video_no_timestamps", "the video's frames have no timestamps or frame rate"
                    )
                time_s = index / fps
            if max_duration_s is not None and time_s > max_duration_s:
                break
            if time_s >= next_sample_s - TIMESTAMP_SLACK_S:
                ok, frame = capture.retrieve()
                if ok and frame is not None and frame.size > 0:
                    yield index, time_s, frame
                    next_sample_s = time_s + interval_s
                # not kept beside the next frame (the caller may have dropped it)
                del frame
            previous_s = time_s
            index += 1
    finally:
        capture.release()


def clip_frames_within(n_frames: int, frame_bytes: int, max_frames_bytes: int | None) -> int:
    """Frames for a clip's background: `n_frames`, fewer when the frames kept for them
    (KEPT_FRAMES_PER_FRAME_USED x, of `frame_bytes` each) would take more than
    `max_frames_bytes` (None: no limit), but at least MIN_CLIP_FRAMES (or `n_frames` if fewer)."""
    if n_frames < 1 or frame_bytes < 1:
        raise ValueError(f"need n_frames >= 1 and frame_bytes >= 1, got {n_frames}, {frame_bytes}")
    if max_frames_bytes is None:
        return n_frames
    fit = max_frames_bytes // (KEPT_FRAMES_PER_FRAME_USED * frame_bytes)
    return min(n_frames, max(MIN_CLIP_FRAMES, fit))


class SpreadSample:
    """At most `capacity` items spread evenly over a stream of unknown length.

    Every `stride`-th item is kept; when full, every other kept item goes and the stride doubles.
    """

    def __init__(self, capacity: int) -> None:
        self.capacity = max(2, capacity)
        self.items: list[tuple[int, np.ndarray]] = []
        self.stride = 1
        self.seen = 0

    def add(self, item: tuple[int, np.ndarray]) -> None:
        if self.seen % self.stride == 0:
            self.items.append(item)
            if len(self.items) >= self.capacity:
                self.items = self.items[::2]
                self.stride *= 2
        self.seen += 1

    def pick(self, n: int) -> list[tuple[int, np.ndarray]]:
        """`n` of the kept items, evenly spread (all of them if there are no more)."""
        if len(self.items) <= n:
            return list(self.items)
        picks = np.round(np.linspace(0, len(self.items) - 1, n)).astype(int)
        return [self.items[i] for i in picks]

    def shrink(self, n: int) -> None:
        """Keep only `pick(n)`; later items still come at the current stride."""
        self.items = self.pick(n)


def background_from_clip(
    source: str | os.PathLike[str] | Iterable[ClipSample],
    n_frames: int = 15,
    max_duration_s: float | None = None,
    min_static_view_s: float = MIN_STATIC_VIEW_S,
    method: str = "median_inlier_mean",
    max_frames_bytes: int | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """(background, moving_mask, info) of the longest static view of a clip.

    source: a video file, or samples (frame index, timestamp s, BGR uint8 frame) in time order
    (e.g. from `video_samples`; spaced as the caller likes; frames are kept as given, so each must
    be its own array, not a buffer the caller reuses). Up to `n_frames` frames of the chosen
    view, spread over its shots, make the background (`background_from_bands` over them: the
    same as `background_from_frames`). max_frames_bytes: the most memory the kept frames may
    take (None: no limit); from the first sample's size, the frames are lowered to
    `clip_frames_within(n_frames, frame bytes, max_frames_bytes)` so that the 3 x as many kept
    fit in it.
    info: the shots found and what was used; times in seconds, frame indices from 0, ranges
    inclusive of their last frame: {"samples", "shots", "views", "cuts_s", "camera_moves_s",
    "view_duration_s", "time_ranges_s": [[start, end], ...], "frame_ranges": [[first, last], ...],
    "frames_used", "frame_indices_used", "frames_limited_by_memory" (the budget allowed fewer
    than `n_frames` frames and the view had more samples than it allowed),
    "timings_s": {"decode", "segmentation", "background"}}.
    Raises ClipError when the clip has no frame or no view lasting `min_static_view_s`.
    """
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    if max_frames_bytes is not None and max_frames_bytes < 1:
        raise ValueError(f"max_frames_bytes must be >= 1 or None, got {max_frames_bytes}")
    _check_method(method)
    if isinstance(source, str | os.PathLike):
        samples: Iterator[ClipSample] = video_samples(source, max_duration_s=max_duration_s)
    else:
        samples = iter(source)
    timings = {"decode": 0.0, "segmentation": 0.0, "background": 0.0}
    segmenter = ShotSegmenter()
    kept: dict[int, SpreadSample] = {}
    first: tuple[int, float] | None = None
    last = (0, 0.0)
    n_keep = n_frames  # lowered by the memory budget once the frame size is known
    try:
        while True:
            start = time.perf_counter()
            sample = next(samples, None)
            timings["decode"] += time.perf_counter() - start
            if sample is None:
                break
            start = time.perf_counter()
            index, time_s, frame = sample
            if max_duration_s is not None and time_s > max_duration_s:
                break
            if first is None:
                frame_bytes = max(1, np.asarray(frame).nbytes)
                n_keep = clip_frames_within(n_frames, frame_bytes, max_frames_bytes)
            first = first or (index, time_s)
            last = (index, time_s)
            shot, new_shot = segmenter.add(index, time_s, view_signature(frame))
            if new_shot:
                # full frames only for the view on screen and the longest other one, whose
                # sample can shrink to what the background takes: <= 3 n_keep frames in all
                durations = view_durations_s(segmenter.shots, _frame_interval_s(first, last))
                others = [view for view in durations if view != shot.view]
                longest_other = max(others, key=durations.__getitem__) if others else None
                for view in list(kept):
                    if view == longest_other:
                        kept[view].shrink(n_keep)
                    elif view != shot.view:
                        del kept[view]
            kept.setdefault(shot.view, SpreadSample(2 * n_keep)).add((index, frame))
            # a frame not kept goes now, not once the next one has been decoded beside it
            del sample, frame
            timings["segmentation"] += time.perf_counter() - start
    finally:
        close = getattr(samples, "close", None)
        if close is not None:
            close()
    if first is None:
        raise ClipError("video_no_frames", "the video has no decodable frame")
    shots = segmenter.shots
    frame_interval_s = _frame_interval_s(first, last)
    durations = view_durations_s(shots, frame_interval_s)
    # the longest view is one of the two kept: only the open view grew after the last choice
    view = longest_view([s for s in shots if s.view in kept], frame_interval_s)
    if len(shots) > 1 and durations[view] < min_static_view_s:
        raise ClipError(
            "no_static_view",
            f"the clip has no static view of the court longer than {min_static_view_s:g} s "
            f"(the longest lasts {durations[view]:.2f} s; {len(shots)} shots)",
        )
    picked = kept.pop(view).pick(n_keep)
    kept.clear()
    start = time.perf_counter()
    frames = _check_frames([f for _, f in picked])
    height, width = frames[0].shape[:2]

    def read_rows(top: int, bottom: int) -> np.ndarray:
        return np.stack([f[top:bottom] for f in frames])

    background, moving_mask = background_from_bands(
        len(frames), height, width, read_rows, method=method
    )
    timings["background"] = time.perf_counter() - start
    used = [s for s in shots if s.view == view]
    view_samples = sum(s.n_samples for s in used)
    info: dict[str, Any] = {
        "samples": sum(s.n_samples for s in shots),
        "shots": len(shots),
        "views": len(durations),
        "cuts_s": [_round_s(s.first_s) for s in shots if s.starts_with == "cut"],
        "camera_moves_s": [_round_s(s.first_s) for s in shots if s.starts_with == "camera_move"],
        "view_duration_s": _round_s(durations[view]),
        "time_ranges_s": [
            [_round_s(s.first_s), _round_s(s.last_s + frame_interval_s)] for s in used
        ],
        "frame_ranges": [[s.first_frame, s.last_frame] for s in used],
        "frames_used": len(picked),
        "frame_indices_used": [i for i, _ in picked],
        "frames_limited_by_memory": n_keep < n_frames and view_samples > n_keep,
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
    }
    return background, moving_mask, info


def _frame_interval_s(first: tuple[int, float], last: tuple[int, float]) -> float:
    """Mean seconds per frame between two (frame index, timestamp) samples; 0 for one frame."""
    frames = last[0] - first[0]
    return (last[1] - first[1]) / frames if frames > 0 else 0.0


def _round_s(seconds: float) -> float:
    return round(float(seconds), 3)
