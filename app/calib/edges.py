"""Image -> binary edge image (255 on edges, 0 elsewhere), the input of the fitness map.

The paper extracts edges with Canny on the grey image (section VII-B). Canny needs two gradient
thresholds; fixed numbers suit one exposure and not the next, so they are chosen from the image:
the median Sobel gradient magnitude measures the texture/noise level of the scene (most pixels are
floor, wall or crowd, not court lines), and the thresholds sit at fixed multiples of it, with an
absolute floor so a flat image does not turn its sensor noise into edges. Painted court lines
(contrast of tens of grey levels over ~2 px) are well above both.

The calibration itself fits richer evidence (`lines.line_evidence`: painted-line ridges and
junction steps); `extract_edges` is the paper's own input, kept for the paper's protocol and for
comparisons (bench.background_methods).
"""

from __future__ import annotations

import cv2
import numpy as np

# Canny thresholds as multiples of the median L2 Sobel magnitude (3x3 Sobel, the operator Canny
# applies). The high threshold starts edges, the low one continues them (hysteresis).
HIGH_OVER_MEDIAN = 4.0
LOW_OVER_HIGH = 0.4
# Lowest high threshold: a step of ~12 grey levels seen by the unnormalised 3x3 Sobel (gain 4).
MIN_HIGH_THRESHOLD = 48.0
# Light smoothing before Canny: sensor noise and JPEG blocks otherwise break lines into dashes.
BLUR_SIGMA_PX = 1.0


def to_grey(image: np.ndarray) -> np.ndarray:
    """uint8 grey (H, W) from grey (H, W), BGR (H, W, 3) or BGRA (H, W, 4)."""
    img = np.asarray(image)
    if img.ndim == 2:
        grey = img
    elif img.ndim == 3 and img.shape[2] == 1:
        grey = img[:, :, 0]
    elif img.ndim == 3 and img.shape[2] == 3:
        grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    elif img.ndim == 3 and img.shape[2] == 4:
        grey = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    else:
        raise ValueError(f"image must be (H, W), (H, W, 3) or (H, W, 4), got shape {img.shape}")
    if grey.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got {grey.dtype}")
    if grey.shape[0] < 8 or grey.shape[1] < 8:
        raise ValueError(f"image is too small: {grey.shape[1]}x{grey.shape[0]} px")
    return np.ascontiguousarray(grey)


def canny_thresholds(grey: np.ndarray) -> tuple[float, float]:
    """(low, high) Canny thresholds for a (blurred) uint8 grey image, from its median gradient."""
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)
    median = float(np.median(cv2.magnitude(gx, gy)))
    high = max(HIGH_OVER_MEDIAN * median, MIN_HIGH_THRESHOLD)
    return LOW_OVER_HIGH * high, high


def extract_edges(image: np.ndarray) -> np.ndarray:
    """Canny edges of the grey image with automatic thresholds: uint8 (H, W), 255 on edges."""
    grey = to_grey(image)
    blurred = cv2.GaussianBlur(grey, (0, 0), BLUR_SIGMA_PX)
    low, high = canny_thresholds(blurred)
    edges = cv2.Canny(blurred, low, high, apertureSize=3, L2gradient=True)
    return edges


def is_edge_image(image: np.ndarray) -> bool:
    """True if `image` already is a white-on-black line image (e.g. a rendered or saved edge map).

    Near-binary (lossy compression tolerated: 99.5% of pixels within 24 levels of 0 or 255), mostly
    black, with some white, and grey (colour images count only if their channels are equal).
    """
    img = np.asarray(image)
    if img.dtype != np.uint8:
        return False
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[:, :, :3]
        if img.shape[2] == 1:
            img = img[:, :, 0]
        elif not (
            np.array_equal(img[:, :, 0], img[:, :, 1])
            and np.array_equal(img[:, :, 0], img[:, :, 2])
        ):
            return False
        else:
            img = img[:, :, 0]
    if img.ndim != 2 or img.size == 0:
        return False
    dark = img <= 24
    bright = img >= 231
    bright_fraction = float(bright.mean())
    near_binary = float((dark | bright).mean()) >= 0.995
    return near_binary and 0.0 < bright_fraction <= 0.25
