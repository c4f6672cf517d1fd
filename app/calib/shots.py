"""Shots of a clip: which sampled frames show one and the same static view of the court.

Broadcast clips cut between cameras (replays, close-ups, another angle) and zoom or pan; a
background over frames of different views is garbage. Frames are compared through a small grey
signature (`view_signature`: `SIGNATURE_WIDTH_PX` wide, blurred), so the cost per sample is the same
at every resolution.

Same view or not (`view_shift_px`): on the pixels where the reference signature has structure (the
`STRUCTURE_FRACTION` strongest gradients: court lines, wall junctions, adverts, players), the grey
difference divided by the gradient is how far that edge moved along its normal (first order,
valid up to about the blur width; beyond it the ratio stays large, which is all the test needs).
A pixel whose structure vanished in the other frame (an edge moved away, a player left) counts as
moved infinitely far. The median over the structured pixels is robust to players and other moving
things (a minority of the structure), while a pan, a zoom or a cut moves most of it. An edge only
shows motion across itself, and most of a court's edges run across the image, so a sideways pan
hardly moves them: the medians are taken separately over mostly-upright and mostly-lying edges
and the larger counts (a sideways pan by 1 signature px of a synthetic court view: 0.33 over all
edges, 1.08 over the upright ones). Exposure is removed first: auto-exposure scales and offsets the whole frame
alike, so the gain is the median ratio of the two gradients over the structured pixels and the
offset the median remaining difference there (medians again: players do not move them; grey-level
percentiles of the whole frame would, once the players are large in it).

Segmentation (`ShotSegmenter`, online, one sample at a time, in time order): a shot's first sample
is its anchor; every later sample within `VIEW_SHIFT_TOLERANCE_PX` of the anchor extends the shot.
Comparing with the anchor rather than with the previous sample also ends a shot during a slow zoom,
pan or drift, where neighbouring samples barely differ, and during a dissolve. A sample that does
not match starts a new shot; the boundary is a cut when the view changed abruptly, by more than
`CUT_SHIFT_PX` from the previous sample (another camera, or a zoom or pan of more than ~1 % of the
frame between two samples), and a camera move otherwise. A new shot's anchor is compared with the
views seen before, so a view that returns after a replay is one view with several time ranges.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from app.calib.edges import to_grey

# Signatures are this many pixels wide (height by the frame's aspect ratio): enough to see a pan of
# a fraction of a pixel of a 640-wide frame, cheap at every frame size (~0.6 ms from 1080p).
SIGNATURE_WIDTH_PX = 320
# Blur of the signature (px): widens edges so that the first-order shift stays valid over ~1 px
# and the sensor and codec noise averages out.
SIGNATURE_BLUR_PX = 1.0
# The structured pixels of a signature: the strongest fifth of its gradients (every court view
# has lines and wall junctions covering more than that in the blurred signature) ...
STRUCTURE_FRACTION = 0.2
# ... but never gradients below this (grey levels per signature pixel; sensor noise of sigma 2 grey
# levels in a 640-wide frame stays below 0.35 in 99 % of the signature's pixels): a blank or black
# frame has no structure to compare.
GRADIENT_FLOOR = 2.0
# A signature with fewer structured pixels than this fraction shows nothing to compare (a fade,
# a blank frame): no other frame is the same view as it.
MIN_STRUCTURED_FRACTION = 0.01
# An orientation class (upright or lying edges) with less than this share of the structured pixels
# is too small to tell a pan from the players crossing it, and is left out.
MIN_ORIENTATION_SHARE = 0.1
# Exposure changes the contrast of one view by at most this factor either way; a frame whose
# structure is that much weaker or stronger is another view or a fade (and a free gain would
# explain vanished structure away as a darker exposure).
MAX_EXPOSURE_GAIN = 2.0
# A structured pixel still has structure in another frame when its gradient there is at least this
# fraction of the structure threshold (an edge that moved by a fraction of the blur width keeps it).
SURVIVING_GRADIENT_FRACTION = 0.5
# Two samples show the same view when the view shift is at most this (signature pixels): about a
# 0.4 % zoom or a 0.3 px pan of the signature (1.8 px of a 1080p frame). Measured: static clips
# with players <= 0.13 (the real broadcast clip, any reference frame) and <= 0.05 (synthetic, through
# the codec); a sideways pan of 0.5 signature px 0.51-0.58; a zoom by 0.3 % 0.21-0.25, by 0.5 %
# 0.33-0.39.
VIEW_SHIFT_TOLERANCE_PX = 0.3
# A new shot starts with a cut when the view shift from the previous sample exceeds this (signature
# px, ~1 % of the frame width). Measured on synthetic court views: a cut to another camera position
# or to a close-up: inf; a zoom by 1 % between samples: 0.6-0.8, by 2 %: 1.3-1.8, by 5 %: 8 or inf.
CUT_SHIFT_PX = 3.0


@dataclass(frozen=True)
class ViewSignature:
    """A frame reduced for comparing views.

    frame_shape: the full frame's (H, W, C); only frames of one shape can be one view.
    grey, gradient: float32 (h, SIGNATURE_WIDTH_PX), grey levels and grey levels per pixel.
    structured: int64 (n,) flat indices of the structured pixels; threshold: their gradient bound.
    upright: bool (n,) per structured pixel, whether its edge is closer to upright than to lying
    (the gradient is mostly horizontal).
    """

    frame_shape: tuple[int, ...]
    grey: np.ndarray
    gradient: np.ndarray
    structured: np.ndarray
    threshold: float
    upright: np.ndarray

    @property
    def has_structure(self) -> bool:
        return self.structured.size >= MIN_STRUCTURED_FRACTION * self.grey.size


def view_signature(frame: np.ndarray) -> ViewSignature:
    """The signature of a BGR or grey uint8 frame (H, W[, 3])."""
    grey = to_grey(frame)
    height, width = grey.shape
    small_height = max(8, round(SIGNATURE_WIDTH_PX * height / width))
    small = cv2.resize(grey, (SIGNATURE_WIDTH_PX, small_height), interpolation=cv2.INTER_AREA)
    blurred = cv2.GaussianBlur(small.astype(np.float32), (0, 0), SIGNATURE_BLUR_PX)
    # 3x3 Sobel has gain 8 on a unit ramp: /8 gives grey levels per pixel
    gx = cv2.Sobel(blurred, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(blurred, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    gradient = cv2.magnitude(gx, gy)
    flat = gradient.ravel()
    k = int((1.0 - STRUCTURE_FRACTION) * flat.size)
    threshold = max(GRADIENT_FLOOR, float(np.partition(flat, k)[k]))
    structured = np.flatnonzero(flat > threshold)
    upright = np.abs(gx.ravel()[structured]) > np.abs(gy.ravel()[structured])
    return ViewSignature(tuple(np.shape(frame)), blurred, gradient, structured, threshold, upright)


def view_shift_px(reference: ViewSignature, current: ViewSignature) -> float:
    """Shift (signature px) of the reference's structure in `current`; inf if incomparable.

    The larger of the medians over upright and over lying edges. Not symmetric: it asks where the
    reference's edges went.
    """
    if reference.frame_shape != current.frame_shape or not reference.has_structure:
        return float("inf")
    idx = reference.structured
    reference_gradient = reference.gradient.ravel()[idx]
    # exposure: current = gain * reference + offset, both from medians over the structure
    gain = _median(current.gradient.ravel()[idx] / reference_gradient)
    if not MAX_EXPOSURE_GAIN**-1 <= gain <= MAX_EXPOSURE_GAIN:
        return float("inf")
    diff = current.grey.ravel()[idx] / gain - reference.grey.ravel()[idx]
    shift = np.abs(diff - _median(diff)) / reference_gradient
    vanished = (
        current.gradient.ravel()[idx] / gain < SURVIVING_GRADIENT_FRACTION * reference.threshold
    )
    shift[vanished] = np.inf
    largest = 0.0
    for in_class in (reference.upright, ~reference.upright):
        class_shift = shift[in_class]
        if class_shift.size >= MIN_ORIENTATION_SHARE * shift.size:
            largest = max(largest, _median(class_shift))
    return largest


def _median(values: np.ndarray) -> float:
    """The upper median (a selection: cheaper than np.median, no mean of two middles)."""
    middle = values.size // 2
    return float(np.partition(values, middle)[middle])


@dataclass
class Shot:
    """A run of consecutive samples showing one view, from its first to its last sample.

    Frame indices count the clip's frames from 0; times are the frames' timestamps (s).
    """

    first_frame: int
    last_frame: int
    first_s: float
    last_s: float
    view: int  # index of the view (the same view recurs in several shots)
    starts_with: str  # "start", "cut" or "camera_move": what ended the shot before
    n_samples: int = 1

    def duration_s(self, frame_interval_s: float) -> float:
        """From the first sample's frame to the end of the last one's (shown for one interval)."""
        return self.last_s - self.first_s + frame_interval_s


@dataclass
class ShotSegmenter:
    """Online shot segmentation: `add` the samples of a clip in time order.

    tolerance_px: the largest view shift (`view_shift_px`) within one view.
    max_views_compared: a new shot's anchor is compared with at most this many earlier views (the
    longest ones): bounds the cost on clips that pan all the time.
    max_views_remembered: anchors are kept for at most this many views (the longest ones; a
    signature is ~0.5 MB), so a clip that pans for minutes does not pile them up.
    """

    tolerance_px: float = VIEW_SHIFT_TOLERANCE_PX
    max_views_compared: int = 8
    max_views_remembered: int = 32
    shots: list[Shot] = field(default_factory=list)
    # per view: the anchor of its first shot (None once forgotten), and its samples so far
    view_anchors: list[ViewSignature | None] = field(default_factory=list)
    view_samples: list[int] = field(default_factory=list)
    _anchor: ViewSignature | None = None
    _previous: ViewSignature | None = None

    def add(self, frame_index: int, time_s: float, signature: ViewSignature) -> tuple[Shot, bool]:
        """Add the next sample; returns its shot and whether that shot starts with this sample."""
        if self.shots and (
            frame_index <= self.shots[-1].last_frame or time_s < self.shots[-1].last_s
        ):
            raise ValueError(
                f"samples must come in time order: frame {frame_index} at {time_s} s after "
                f"frame {self.shots[-1].last_frame} at {self.shots[-1].last_s} s"
            )
        previous, self._previous = self._previous, signature
        if self._anchor is not None and view_shift_px(self._anchor, signature) <= self.tolerance_px:
            shot = self.shots[-1]
            shot.last_frame = frame_index
            shot.last_s = time_s
            shot.n_samples += 1
            self.view_samples[shot.view] += 1
            return shot, False
        if previous is None:
            starts_with = "start"
        elif view_shift_px(previous, signature) > CUT_SHIFT_PX:
            starts_with = "cut"
        else:
            starts_with = "camera_move"
        view = self._earlier_view(signature)
        if view is None:
            view = len(self.view_anchors)
            self.view_anchors.append(signature)
            self.view_samples.append(0)
            self._forget_short_views()
        self.view_samples[view] += 1
        self._anchor = signature
        shot = Shot(frame_index, frame_index, time_s, time_s, view, starts_with)
        self.shots.append(shot)
        return shot, True

    def _remembered_longest_first(self) -> list[int]:
        order = np.argsort(-np.asarray(self.view_samples), kind="stable")
        return [int(view) for view in order if self.view_anchors[view] is not None]

    def _earlier_view(self, signature: ViewSignature) -> int | None:
        if not signature.has_structure:
            return None
        for view in self._remembered_longest_first()[: self.max_views_compared]:
            anchor = self.view_anchors[view]
            if anchor is not None and view_shift_px(anchor, signature) <= self.tolerance_px:
                return view
        return None

    def _forget_short_views(self) -> None:
        """Drop the anchors of the shortest views beyond `max_views_remembered` (not the newest)."""
        newest = len(self.view_anchors) - 1
        remembered = [v for v in self._remembered_longest_first() if v != newest]
        for view in remembered[max(0, self.max_views_remembered - 1) :]:
            self.view_anchors[view] = None


def view_durations_s(shots: list[Shot], frame_interval_s: float) -> dict[int, float]:
    """Seconds each view is on screen (sum over its shots), by view index."""
    durations: dict[int, float] = {}
    for shot in shots:
        durations[shot.view] = durations.get(shot.view, 0.0) + shot.duration_s(frame_interval_s)
    return durations


def longest_view(shots: list[Shot], frame_interval_s: float) -> int:
    """The view on screen longest (the earliest of equals)."""
    if not shots:
        raise ValueError("no shots")
    durations = view_durations_s(shots, frame_interval_s)
    return max(durations, key=lambda view: (durations[view], -view))
