"""Court-line evidence: which pixels look like the centre of a painted line, or a surface junction.

Canny (the paper's choice, `edges.py`) marks every brightness step: both borders of each painted
line, plank seams, adverts, text, glass reflections. A painted line is something more specific: a
thin band of one colour with the same surface on both sides. So:

1. Ridges. The image is taken to CIE Lab (lines may differ from the floor in lightness only, as a
   white line on blue, or in colour only, as a red line on maple). At a few Gaussian scales, each
   channel's Hessian says how strongly a pixel sits on a band (|largest eigenvalue| minus
   |smallest|, scale-normalised) and which way the band runs. The best channel and scale win per
   pixel; non-maximum suppression across the band keeps its centre line.
2. The band test. A ridge candidate must differ from both sides a band-width away, in the same
   direction (both darker or both lighter in colour space), while the two sides agree with each
   other. That rejects what the Hessian also answers to: the shoulders of a brightness step
   (junctions, advert borders) and ramps.
3. Steps. Surface junctions (wood floor against a white wall) are steps, not bands: Canny edges
   on the lightness that are not a ridge's own borders are kept as a second kind of evidence.
4. Orientation and sub-pixel position for every evidence pixel, so that fitting can require the
   model line's direction and reach sub-pixel accuracy (the integer pixel grid alone biases an
   axis-aligned line by up to half a pixel).
5. What is not court is masked: pixels where players moved (`ignore`), and static clutter (text,
   logos, crowds): places where evidence of many directions crowds together, which a court line
   never does.

Thresholds are in colour-difference units (CIE76 delta E: 2-3 is a just noticeable difference),
relative to the image's own noise level where that matters.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np

from app.calib import edges

# Gaussian scales (px) of the ridge detector. A band of width w answers best near sigma = w / 2;
# painted lines are 50 mm, 1-3 px far away at 640 px wide, up to ~12 px near a 1080p camera.
RIDGE_SIGMAS_PX = (1.0, 1.8, 3.2, 5.6)
# Scales above this run on a half-resolution copy (same answer, a quarter of the work).
HALF_RESOLUTION_ABOVE_SIGMA_PX = 2.5
# A band must stand out from both sides by this colour difference (delta E), and by this many
# times the image's noise level.
MIN_RIDGE_CONTRAST = 5.0
RIDGE_CONTRAST_OVER_NOISE = 4.0
# ... and its two sides may differ from each other by at most this share of that contrast.
MAX_SIDE_ASYMMETRY = 0.6
# Canny on the lightness for steps (thresholds in L units x Sobel gain, from the median gradient).
STEP_HIGH_OVER_MEDIAN = 5.0
STEP_LOW_OVER_HIGH = 0.4
MIN_STEP_HIGH = 24.0
STEP_TENSOR_SIGMA_PX = 2.0
# Clutter: within a window this many px across, evidence pixels whose directions spread over many
# orientation bins (text, crowds, foliage of logos) are not trusted.
CLUTTER_WINDOW_PX = 24
CLUTTER_MIN_DENSITY = 0.08
CLUTTER_MIN_DIRECTIONS = 4.0

RIDGE = 1
STEP = 2


@dataclass(frozen=True)
class LineEvidence:
    """Evidence of court lines in one image (H, W).

    kind: uint8 (H, W): 0 nothing, RIDGE (centre of a painted band) or STEP (a junction edge).
    normal_rad: float32 (H, W): direction across the line at evidence pixels, in [0, pi).
    offset_px: float32 (H, W): sub-pixel offset of the line centre from the pixel centre, along
        the normal (cos, sin)(normal_rad).
    contrast: float32 (H, W): colour difference of the band (or the step) to its surroundings.
    width_px: float32 (H, W): the detector scale that answered (about half the band's width).
    ignore: bool (H, W): pixels that say nothing about the court (moving players, clutter).
    noise: the image's noise level (delta E), for reports.
    """

    kind: np.ndarray
    normal_rad: np.ndarray
    offset_px: np.ndarray
    contrast: np.ndarray
    width_px: np.ndarray
    ignore: np.ndarray
    noise: float

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.kind.shape[0]), int(self.kind.shape[1]))

    def mask(self, kinds: int = RIDGE | STEP) -> np.ndarray:
        """bool (H, W): evidence pixels of the given kinds, not ignored."""
        return ((self.kind & np.uint8(kinds)) != 0) & ~self.ignore

    def image(self) -> np.ndarray:
        """BGR uint8 picture of the evidence: ridges white, steps blue, ignored pixels dark red."""
        out = np.zeros((*self.shape, 3), np.uint8)
        out[self.ignore] = (0, 0, 70)
        out[(self.kind == RIDGE) & ~self.ignore] = (255, 255, 255)
        out[(self.kind == STEP) & ~self.ignore] = (255, 140, 40)
        return out


def to_lab(image: np.ndarray) -> np.ndarray:
    """float32 (H, W, 3) CIE Lab (L 0..100) of a BGR, BGRA or grey uint8 image."""
    img = np.asarray(image)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = cv2.cvtColor(img[:, :, 0], cv2.COLOR_GRAY2BGR)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image must be a uint8 grey, BGR or BGRA array, got {img.shape}")
    return cv2.cvtColor(img.astype(np.float32) * np.float32(1.0 / 255.0), cv2.COLOR_BGR2Lab)


def noise_level(lab: np.ndarray) -> float:
    """Noise of the lightness channel (delta E): robust spread of a Laplacian residual."""
    lightness = lab[:, :, 0]
    residual = cv2.Laplacian(lightness, cv2.CV_32F, ksize=1)
    # for white noise sigma, the 4-neighbour Laplacian has spread sqrt(20) sigma
    mad = float(np.median(np.abs(residual - np.median(residual))))
    return 1.4826 * mad / np.sqrt(20.0)


@numba.njit(cache=True, nogil=True)
def _best_ridge(
    hxx: np.ndarray,
    hxy: np.ndarray,
    hyy: np.ndarray,
    scale2: float,
    best: np.ndarray,
    normal: np.ndarray,
    sigma_of_best: np.ndarray,
    sigma: float,
) -> None:
    """Fold one scale's Hessians (H, W, 3 channels each) into the running best ridge response.

    Response of a channel: scale2 * (|l_big| - |l_small|) where l_big is the eigenvalue of larger
    magnitude (curvature across a band) and l_small the other (along it: near 0 on a line, as
    large on a blob). The normal is l_big's eigenvector.
    """
    h, w = best.shape
    for y in range(h):
        for x in range(w):
            top = best[y, x]
            for c in range(3):
                a = hxx[y, x, c]
                b = hxy[y, x, c]
                d = hyy[y, x, c]
                half_trace = 0.5 * (a + d)
                root = np.sqrt(0.25 * (a - d) * (a - d) + b * b)
                l1 = half_trace + root
                l2 = half_trace - root
                if abs(l1) >= abs(l2):
                    big, small = l1, l2
                else:
                    big, small = l2, l1
                response = scale2 * (abs(big) - abs(small))
                if response > top:
                    top = response
                    # eigenvector of `big`: the better conditioned of two equivalent forms
                    if abs(a - big) < abs(d - big):
                        vx, vy = big - d, b
                    else:
                        vx, vy = b, big - a
                    angle = np.arctan2(vy, vx)
                    if angle < 0.0:
                        angle += np.pi
                    if angle >= np.pi:
                        angle -= np.pi
                    normal[y, x] = angle
                    sigma_of_best[y, x] = sigma
            best[y, x] = top


def _hessians(channels: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    blurred = cv2.GaussianBlur(channels, (0, 0), sigma)
    # 3-tap second differences of the blurred image (OpenCV's ksize=1 kernels [1, -2, 1])
    hxx = cv2.Sobel(blurred, cv2.CV_32F, 2, 0, ksize=1)
    hyy = cv2.Sobel(blurred, cv2.CV_32F, 0, 2, ksize=1)
    hxy = cv2.Sobel(blurred, cv2.CV_32F, 1, 1, ksize=3) * np.float32(0.25)
    return hxx, hxy, hyy


def ridge_response(lab: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best ridge response (H, W), its normal direction (rad, [0, pi)) and scale (px) per pixel.

    Scales above HALF_RESOLUTION_ABOVE_SIGMA_PX are searched on a half-resolution copy and their
    winner brought back to full resolution, where it competes with the fine scales'."""
    h, w = lab.shape[:2]
    best = np.zeros((h, w), np.float32)
    normal = np.zeros((h, w), np.float32)
    sigma_map = np.zeros((h, w), np.float32)
    coarse_sigmas = [s for s in RIDGE_SIGMAS_PX if s > HALF_RESOLUTION_ABOVE_SIGMA_PX]
    for sigma in RIDGE_SIGMAS_PX:
        if sigma <= HALF_RESOLUTION_ABOVE_SIGMA_PX:
            hxx, hxy, hyy = _hessians(lab, sigma)
            _best_ridge(hxx, hxy, hyy, sigma * sigma, best, normal, sigma_map, sigma)
    if coarse_sigmas:
        half = cv2.resize(lab, ((w + 1) // 2, (h + 1) // 2), interpolation=cv2.INTER_AREA)
        best_half = np.zeros(half.shape[:2], np.float32)
        normal_half = np.zeros(half.shape[:2], np.float32)
        sigma_half = np.zeros(half.shape[:2], np.float32)
        for sigma in coarse_sigmas:
            hxx, hxy, hyy = _hessians(half, sigma / 2.0)
            # second derivatives per half-res pixel are 4 times those per full-res pixel; the
            # scale normalisation uses the full-res sigma
            _best_ridge(
                hxx, hxy, hyy, 0.25 * sigma * sigma, best_half, normal_half, sigma_half, sigma
            )
        size = (w, h)
        best_up = cv2.resize(best_half, size, interpolation=cv2.INTER_LINEAR)
        wins = best_up > best
        best[wins] = best_up[wins]
        # angles and scales do not interpolate: nearest half-res pixel
        normal[wins] = cv2.resize(normal_half, size, interpolation=cv2.INTER_NEAREST)[wins]
        sigma_map[wins] = cv2.resize(sigma_half, size, interpolation=cv2.INTER_NEAREST)[wins]
    return best, normal, sigma_map


@numba.njit(cache=True, nogil=True)
def _ridge_centres(
    response: np.ndarray,
    normal: np.ndarray,
    sigma_map: np.ndarray,
    lab: np.ndarray,
    min_contrast: float,
    max_asymmetry: float,
    kind: np.ndarray,
    offset: np.ndarray,
    contrast_out: np.ndarray,
) -> None:
    """Non-maximum suppression across the band plus the band test; writes RIDGE into `kind`."""
    h, w = response.shape
    for y in range(2, h - 2):
        for x in range(2, w - 2):
            r0 = response[y, x]
            if r0 <= 0.0:
                continue
            angle = normal[y, x]
            nx = np.cos(angle)
            ny = np.sin(angle)
            # neighbours across the band, bilinear
            fa = _bilinear(response, x + nx, y + ny)
            fb = _bilinear(response, x - nx, y - ny)
            if fa > r0 or fb >= r0:
                continue
            # the band test: sample a band-width away on both sides
            reach = max(2.0, 2.2 * sigma_map[y, x])
            xa, ya = x + reach * nx, y + reach * ny
            xb, yb = x - reach * nx, y - reach * ny
            if xa < 0 or xb < 0 or xa > w - 1 or xb > w - 1 or ya < 0 or yb < 0:
                continue
            if ya > h - 1 or yb > h - 1:
                continue
            da = 0.0
            db = 0.0
            dab = 0.0
            dot = 0.0
            for c in range(3):
                centre = lab[y, x, c]
                side_a = _bilinear3(lab, xa, ya, c)
                side_b = _bilinear3(lab, xb, yb, c)
                ea = centre - side_a
                eb = centre - side_b
                da += ea * ea
                db += eb * eb
                dab += (side_a - side_b) * (side_a - side_b)
                dot += ea * eb
            contrast = np.sqrt(min(da, db))
            if dot <= 0.0 or contrast < min_contrast or np.sqrt(dab) > max_asymmetry * contrast:
                continue
            kind[y, x] = 1
            contrast_out[y, x] = contrast
            # parabola through the response across the band: sub-pixel centre
            curvature = fa - 2.0 * r0 + fb
            t = 0.5 * (fb - fa) / curvature if curvature < 0.0 else 0.0
            offset[y, x] = min(max(t, -0.5), 0.5)


@numba.njit(cache=True, inline="always")
def _bilinear(img: np.ndarray, x: float, y: float) -> float:
    h, w = img.shape
    x = min(max(x, 0.0), w - 1.000001)
    y = min(max(y, 0.0), h - 1.000001)
    ix = int(x)
    iy = int(y)
    fx = x - ix
    fy = y - iy
    top = img[iy, ix] + fx * (img[iy, ix + 1] - img[iy, ix])
    bottom = img[iy + 1, ix] + fx * (img[iy + 1, ix + 1] - img[iy + 1, ix])
    return top + fy * (bottom - top)


@numba.njit(cache=True, inline="always")
def _bilinear3(img: np.ndarray, x: float, y: float, c: int) -> float:
    h, w = img.shape[0], img.shape[1]
    x = min(max(x, 0.0), w - 1.000001)
    y = min(max(y, 0.0), h - 1.000001)
    ix = int(x)
    iy = int(y)
    fx = x - ix
    fy = y - iy
    top = img[iy, ix, c] + fx * (img[iy, ix + 1, c] - img[iy, ix, c])
    bottom = img[iy + 1, ix, c] + fx * (img[iy + 1, ix + 1, c] - img[iy + 1, ix, c])
    return top + fy * (bottom - top)


@numba.njit(cache=True, nogil=True)
def _steps(
    edges: np.ndarray,
    gx: np.ndarray,
    gy: np.ndarray,
    tensor_angle: np.ndarray,
    ridge_kind: np.ndarray,
    ridge_normal: np.ndarray,
    ridge_sigma: np.ndarray,
    kind: np.ndarray,
    normal: np.ndarray,
    offset: np.ndarray,
    contrast_out: np.ndarray,
) -> None:
    """Canny edges that are not the borders of a detected band become STEP evidence."""
    h, w = edges.shape
    for y in range(1, h - 1):
        for x in range(1, w - 1):
            if edges[y, x] == 0 or kind[y, x] != 0:
                continue
            ex = gx[y, x]
            ey = gy[y, x]
            magnitude = np.sqrt(ex * ex + ey * ey)
            if magnitude == 0.0:
                continue
            nx = np.cos(tensor_angle[y, x])
            ny = np.sin(tensor_angle[y, x])
            # a band's border: a ridge pixel with the same orientation within its width across
            border = False
            for s in range(1, 9):
                for sign in (-1.0, 1.0):
                    qx = int(round(x + sign * s * nx))
                    qy = int(round(y + sign * s * ny))
                    if qx < 0 or qy < 0 or qx >= w or qy >= h or ridge_kind[qy, qx] == 0:
                        continue
                    if s > 2.5 * ridge_sigma[qy, qx] + 1.5:
                        continue
                    diff = abs(ridge_normal[qy, qx] - tensor_angle[y, x])
                    diff = min(diff, np.pi - diff)
                    if diff < 0.35:
                        border = True
                        break
                if border:
                    break
            if border:
                continue
            kind[y, x] = 2
            normal[y, x] = tensor_angle[y, x]
            # parabola through the gradient magnitude across the edge
            fa = np.sqrt(_bilinear(gx, x + nx, y + ny) ** 2 + _bilinear(gy, x + nx, y + ny) ** 2)
            fb = np.sqrt(_bilinear(gx, x - nx, y - ny) ** 2 + _bilinear(gy, x - nx, y - ny) ** 2)
            curvature = fa - 2.0 * magnitude + fb
            t = 0.5 * (fb - fa) / curvature if curvature < 0.0 else 0.0
            offset[y, x] = min(max(t, -0.5), 0.5)
            contrast_out[y, x] = magnitude / 4.0  # 3x3 Sobel: gain 4 per unit step of L


def clutter_mask(kind: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """bool (H, W): where evidence is dense and points every which way (text, logos, crowds).

    Court lines are long and straight: around a line pixel, evidence runs one or two ways (two at
    a crossing). Counts of evidence per orientation bin are box-filtered over CLUTTER_WINDOW_PX;
    the effective number of directions (exp of the entropy of the bin shares) and the density say
    whether a window is clutter. Computed on a half-resolution grid (the windows are large).
    """
    n_bins = 8
    h, w = kind.shape
    on = kind != 0
    bins = np.minimum((normal * (n_bins / np.pi)).astype(np.int32), n_bins - 1)
    half = ((w + 1) // 2, (h + 1) // 2)
    window = (CLUTTER_WINDOW_PX // 2, CLUTTER_WINDOW_PX // 2)
    counts = np.empty((n_bins, half[1], half[0]), np.float32)
    for b in range(n_bins):
        share = cv2.resize(
            (on & (bins == b)).astype(np.float32), half, interpolation=cv2.INTER_AREA
        )
        counts[b] = cv2.boxFilter(share, -1, window)
    total = counts.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = counts / np.maximum(total, 1e-9)
        entropy = -np.sum(np.where(share > 0, share * np.log(share), 0.0), axis=0)
    clutter = (total >= CLUTTER_MIN_DENSITY) & (np.exp(entropy) >= CLUTTER_MIN_DIRECTIONS)
    return cv2.resize(clutter.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0


def line_evidence(image: np.ndarray, ignore: np.ndarray | None = None) -> LineEvidence:
    """The line evidence of a BGR (or grey) uint8 image; `ignore` bool (H, W) marks pixels that
    say nothing about the court (e.g. where players moved)."""
    lab = to_lab(image)
    h, w = lab.shape[:2]
    if ignore is not None and np.shape(ignore) != (h, w):
        raise ValueError(f"ignore must have the image's shape ({h}, {w}), got {np.shape(ignore)}")
    noise = noise_level(lab)
    response, normal, sigma_map = ridge_response(lab)
    kind = np.zeros((h, w), np.uint8)
    offset = np.zeros((h, w), np.float32)
    contrast = np.zeros((h, w), np.float32)
    smooth = cv2.GaussianBlur(lab, (0, 0), 0.7)
    min_contrast = max(MIN_RIDGE_CONTRAST, RIDGE_CONTRAST_OVER_NOISE * noise)
    _ridge_centres(
        response,
        normal,
        sigma_map,
        smooth,
        min_contrast,
        MAX_SIDE_ASYMMETRY,
        kind,
        offset,
        contrast,
    )

    lightness = cv2.GaussianBlur(lab[:, :, 0], (0, 0), 1.0)
    gx = cv2.Sobel(lightness, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(lightness, cv2.CV_32F, 0, 1, ksize=3)
    median = float(np.median(cv2.magnitude(gx, gy)))
    high = max(STEP_HIGH_OVER_MEDIAN * median, MIN_STEP_HIGH, 8.0 * 4.0 * noise)
    # Canny wants 8-bit input for its own Sobel; feed it the gradients directly instead
    edges = cv2.Canny(
        gx.astype(np.int16), gy.astype(np.int16), STEP_LOW_OVER_HIGH * high, high, L2gradient=True
    )
    # the normal of a step from the structure tensor: the gradient direction averaged over a few
    # pixels (single Sobel directions jitter with texture and noise and would break chains)
    jxx = cv2.GaussianBlur(gx * gx, (0, 0), STEP_TENSOR_SIGMA_PX)
    jxy = cv2.GaussianBlur(gx * gy, (0, 0), STEP_TENSOR_SIGMA_PX)
    jyy = cv2.GaussianBlur(gy * gy, (0, 0), STEP_TENSOR_SIGMA_PX)
    tensor_angle = (0.5 * np.arctan2(2.0 * jxy, jxx - jyy)) % np.pi
    ridge_kind = kind.copy()
    _steps(
        edges,
        gx,
        gy,
        tensor_angle.astype(np.float32),
        ridge_kind,
        normal.copy(),
        sigma_map,
        kind,
        normal,
        offset,
        contrast,
    )
    sigma_map[kind != 1] = 0.0
    clutter = clutter_mask(kind, normal)
    masked = clutter if ignore is None else (clutter | np.asarray(ignore, dtype=bool))
    return LineEvidence(
        kind=kind,
        normal_rad=normal,
        offset_px=offset,
        contrast=contrast,
        width_px=sigma_map,
        ignore=masked,
        noise=noise,
    )


@dataclass(frozen=True)
class EvidenceMaps:
    """Lookups for fitting a projected court to the evidence.

    points (P, 2): sub-pixel positions of the (not ignored) evidence pixels; normals (P, 2) unit;
    is_ridge (P,) bool. For painted model lines only ridges count, for junctions both kinds:
    dist_ridge / dist_any (float32 (H, W)): distance (px) from each pixel to the nearest such
    evidence pixel; near_ridge / near_any (int32 (H, W)): its index into `points`.
    ignore: bool (H, W) as in LineEvidence.
    """

    points: np.ndarray
    normals: np.ndarray
    is_ridge: np.ndarray
    dist_ridge: np.ndarray
    near_ridge: np.ndarray
    dist_any: np.ndarray
    near_any: np.ndarray
    ignore: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.ignore.shape[0]), int(self.ignore.shape[1]))


def _nearest(mask: np.ndarray, index_of_pixel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance to and index of the nearest True pixel of `mask`, for every pixel."""
    h, w = mask.shape
    if not mask.any():
        return np.full((h, w), np.inf, np.float32), np.full((h, w), -1, np.int32)
    background = np.where(mask, 0, 255).astype(np.uint8)
    dist, labels = cv2.distanceTransformWithLabels(
        background, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL
    )
    ys, xs = np.nonzero(mask)
    label_to_index = np.full(int(labels.max()) + 1, -1, np.int32)
    label_to_index[labels[ys, xs]] = index_of_pixel[ys, xs]
    return dist, label_to_index[labels]


def evidence_maps(evidence: LineEvidence) -> EvidenceMaps:
    """Lookup maps of `evidence` (see EvidenceMaps)."""
    usable = evidence.mask()
    ys, xs = np.nonzero(usable)
    angle = evidence.normal_rad[ys, xs].astype(np.float64)
    offset = evidence.offset_px[ys, xs].astype(np.float64)
    normals = np.column_stack([np.cos(angle), np.sin(angle)])
    points = np.column_stack([xs, ys]).astype(np.float64) + offset[:, None] * normals
    index = np.full(evidence.shape, -1, np.int32)
    index[ys, xs] = np.arange(len(ys), dtype=np.int32)
    ridge_mask = usable & (evidence.kind == RIDGE)
    dist_ridge, near_ridge = _nearest(ridge_mask, index)
    dist_any, near_any = _nearest(usable, index)
    return EvidenceMaps(
        points=points,
        normals=normals,
        is_ridge=evidence.kind[ys, xs] == RIDGE,
        dist_ridge=dist_ridge,
        near_ridge=near_ridge,
        dist_any=dist_any,
        near_any=near_any,
        ignore=evidence.ignore,
    )


def edge_image_evidence(
    edge_image: np.ndarray, ignore: np.ndarray | None = None, as_ridges: bool = False
) -> LineEvidence:
    """Evidence from a binary edge image (nonzero = edge): Canny edges of a photo (STEP: they
    mark both borders of a painted line) or a drawn line image (`as_ridges`: its lines are the
    line centres). Normals from the structure tensor of the edge image."""
    on = np.asarray(edge_image) > 0
    h, w = on.shape
    if ignore is not None and np.shape(ignore) != (h, w):
        raise ValueError(f"ignore must have the image's shape ({h}, {w}), got {np.shape(ignore)}")
    binary = on.astype(np.float32)
    gx = cv2.Sobel(binary, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(binary, cv2.CV_32F, 0, 1, ksize=3)
    jxx = cv2.GaussianBlur(gx * gx, (0, 0), STEP_TENSOR_SIGMA_PX)
    jxy = cv2.GaussianBlur(gx * gy, (0, 0), STEP_TENSOR_SIGMA_PX)
    jyy = cv2.GaussianBlur(gy * gy, (0, 0), STEP_TENSOR_SIGMA_PX)
    # the dominant gradient of a thin line's neighbourhood runs across the line
    normal = ((0.5 * np.arctan2(2.0 * jxy, jxx - jyy)) % np.pi).astype(np.float32)
    kind = np.where(on, RIDGE if as_ridges else STEP, 0).astype(np.uint8)
    return LineEvidence(
        kind=kind,
        normal_rad=normal,
        offset_px=np.zeros((h, w), np.float32),
        contrast=np.where(on, 255.0, 0.0).astype(np.float32),
        width_px=np.where(on, 1.0, 0.0).astype(np.float32),
        ignore=np.zeros((h, w), bool) if ignore is None else np.asarray(ignore, dtype=bool),
        noise=0.0,
    )


def image_size_of(image: np.ndarray) -> tuple[int, int]:
    """(width, height) of a grey (H, W) or colour (H, W, C) image."""
    shape = np.shape(image)
    if len(shape) not in (2, 3) or (len(shape) == 3 and shape[2] not in (1, 3, 4)):
        raise ValueError(f"image must be (H, W), (H, W, 3) or (H, W, 4), got shape {shape}")
    return int(shape[1]), int(shape[0])


# Players' outlines blur over a few pixels; evidence that close to a moving pixel is not trusted.
MOVING_MARGIN_PX = 3


def moving_mask_of(moving_mask: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """bool (H, W): pixels where something moved, grown by MOVING_MARGIN_PX."""
    mask = np.asarray(moving_mask)
    width, height = image_size
    if mask.ndim == 3 and mask.shape[2] == 1:
        mask = mask[:, :, 0]
    if mask.shape != (height, width):
        raise ValueError(
            f"moving_mask must have the image's shape ({height}, {width}), got {mask.shape}"
        )
    grown = cv2.dilate(
        (mask != 0).astype(np.uint8),
        cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * MOVING_MARGIN_PX + 1,) * 2),
    )
    return grown > 0


def line_evidence_of(image: np.ndarray, moving_mask: np.ndarray | None = None) -> LineEvidence:
    """The evidence a calibration fits: ridges and steps of the picture's lines; an image that
    already is a white-on-black line image (e.g. a rendered edge map) is taken as ridges as it
    is."""
    size = image_size_of(image)
    ignore = moving_mask_of(moving_mask, size) if moving_mask is not None else None
    if edges.is_edge_image(image):
        return edge_image_evidence(edges.to_grey(image), ignore, as_ridges=True)
    return line_evidence(image, ignore)
