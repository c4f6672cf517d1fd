"""Player-free background of a fixed camera from several frames, and where players were.

Two estimators (both over the same frames, BGR uint8 (H, W, 3), one size):
- `temporal_median`: per pixel and channel, the median over the frames. Right wherever a player
  covers a pixel in fewer than half of the frames; keeps the sensor noise of one frame.
- `frame_difference_mean`: a frame's pixel counts as static when it barely differs from the
  frames before and after it (frame differencing); the background is the average of each pixel over
  the frames where it was static (noise averages out), falling back to the median where it never was.
`background_from_frames` uses the one bench/background_methods.py measured better on synthetic clips.

The moving mask marks the pixels where the background cannot be trusted: a player stood there in
many of the frames, so the estimate may still show part of a player. Pixels a player only crossed
are NOT in it: their background is clean and often holds the court lines the fit needs most (the T).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

# A channel differing by more than this many grey levels between two frames is motion (sensor and
# compression noise stay well below it; a player or a shadow is far above).
MOTION_THRESHOLD = 25
# A pixel covered in at least this fraction of the frames is not trusted (the median breaks at 1/2).
UNTRUSTED_FRACTION = 0.35
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
    for top in range(0, height, MEDIAN_STRIP_ROWS):
        strip = np.stack([f[top : top + MEDIAN_STRIP_ROWS] for f in stack])
        out[top : top + MEDIAN_STRIP_ROWS] = np.rint(np.median(strip, axis=0)).astype(np.uint8)
    return out


def _changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """uint8 (H, W) 255 where any channel differs by more than MOTION_THRESHOLD."""
    diff = cv2.absdiff(a, b).max(axis=2)
    return np.where(diff > MOTION_THRESHOLD, 255, 0).astype(np.uint8)


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
    frames: Sequence[np.ndarray], masks: Sequence[np.ndarray] | None = None
) -> np.ndarray:
    """Average of each pixel over the frames where it was static; median where it never was."""
    stack = _check_frames(frames)
    masks = frame_motion_masks(stack) if masks is None else masks
    total = np.zeros(stack[0].shape, np.float32)
    count = np.zeros(stack[0].shape[:2], np.float32)
    for frame, moving in zip(stack, masks, strict=True):
        static = (moving == 0).astype(np.float32)
        total += frame.astype(np.float32) * static[:, :, None]
        count += static
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / count[:, :, None]
    never_static = count == 0
    if np.any(never_static):
        mean[never_static] = temporal_median(stack)[never_static]
    return np.clip(np.rint(mean), 0, 255).astype(np.uint8)


def median_inlier_mean(frames: Sequence[np.ndarray]) -> np.ndarray:
    """Average over the frames that agree with the median (a player is an outlier of the median)."""
    stack = _check_frames(frames)
    median = temporal_median(stack)
    width = stack[0].shape[1]
    masks = [_dilate(_changed(frame, median), width) for frame in stack]
    return frame_difference_mean(stack, masks)


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
    frames: Sequence[np.ndarray], method: str = "frame_difference_mean"
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
    elif method == "median_inlier_mean":
        background = median_inlier_mean(stack)
    else:
        background = frame_difference_mean(stack)
    return background, untrusted_mask(stack, background)
