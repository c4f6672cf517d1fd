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
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

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
    if method not in METHODS:
        raise ValueError(f"unknown background method {method!r}; known: {', '.join(METHODS)}")
    if len(stack) == 1:
        return stack[0].copy(), np.zeros(stack[0].shape[:2], np.uint8)
    if method == "median":
        background = temporal_median(stack)
    elif method == "frame_difference_mean":
        background = frame_difference_mean(stack)
    else:
        background = median_inlier_mean(stack)
    return background, untrusted_mask(stack, background)
