import cv2
import numpy as np
import pytest
from scipy.stats import spearmanr

from app.calib import camera, court, fitness, render, synthetic

SIZE = (1920, 1080)


@pytest.fixture(scope="module")
def model() -> court.CourtModel:
    return court.court_model()


@pytest.fixture(scope="module")
def samples(model) -> court.LineSamples:
    return court.sample_edges(model, court.spacing_for_image(SIZE[0]))


@pytest.fixture(scope="module")
def target() -> np.ndarray:
    return synthetic.typical_target_camera(SIZE)


@pytest.fixture(scope="module")
def cluttered_edges(model, target) -> np.ndarray:
    """The target's court lines plus false edges: random lines and salt."""
    rng = np.random.default_rng(5)
    edges = render.rasterize_court(target, model, SIZE)
    for _ in range(15):
        p, q = rng.integers(0, SIZE, 2), rng.integers(0, SIZE, 2)
        cv2.line(edges, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), 255, 1)
    edges[rng.random(edges.shape) < 0.002] = 255
    return edges


def test_distance_map_uses_the_chamfer_constants_of_the_paper():
    edges = np.zeros((9, 9), np.uint8)
    edges[4, 4] = 255
    d = fitness.distance_map(edges)
    assert d.dtype == np.float32 and d.shape == (9, 9)
    assert d[4, 4] == 0.0
    assert d[4, 5] == pytest.approx(0.955, abs=1e-6)
    assert d[3, 4] == pytest.approx(0.955, abs=1e-6)
    assert d[5, 5] == pytest.approx(1.3693, abs=1e-6)
    assert d[4, 6] == pytest.approx(2 * 0.955, abs=1e-5)
    assert d[6, 6] == pytest.approx(2 * 1.3693, abs=1e-5)
    assert d[4, 7] == pytest.approx(3 * 0.955, abs=1e-5)


def test_distance_map_without_edges_is_infinite_and_rejects_bad_shapes():
    assert np.all(np.isinf(fitness.distance_map(np.zeros((4, 5), np.uint8))))
    with pytest.raises(ValueError):
        fitness.distance_map(np.zeros((4, 5, 3), np.uint8))


def test_fitness_map_follows_eq_13():
    edges = np.zeros((50, 200), np.uint8)
    edges[:, 0] = 255  # distance grows with the column: E = col * 0.955 / max
    f = fitness.fitness_map(edges, transformed=False)
    d = fitness.distance_map(edges)
    e = d / d.max()
    assert f.dtype == np.float32
    assert np.all(f[:, 0] == 1.0)  # on the edges
    assert np.all(f[:, -1] == 0.0)  # far away
    expected = 1.0 - np.clip(np.log(e + 1.0) / 0.3, 0.0, 1.0)
    assert f == pytest.approx(expected, abs=1e-6)
    # the clamp sets in at E = e^0.3 - 1
    far = e >= np.exp(0.3) - 1.0 + 1e-6
    assert np.all(f[far] == 0.0) and np.all(f[~far] > 0.0)
    assert np.all(np.diff(f[0]) <= 0.0)


def test_transformed_map_is_2f_minus_1(cluttered_edges):
    f = fitness.fitness_map(cluttered_edges, transformed=False)
    t = fitness.fitness_map(cluttered_edges, transformed=True)
    assert np.abs(t - (2.0 * f - 1.0)).max() <= 1e-6
    assert t.min() == -1.0 and t.max() == 1.0
    assert np.all(t[cluttered_edges > 0] == 1.0)


def test_fitness_map_degenerate_images():
    assert np.all(fitness.fitness_map(np.zeros((3, 4), np.uint8), transformed=False) == 0.0)
    assert np.all(fitness.fitness_map(np.zeros((3, 4), np.uint8)) == -1.0)
    assert np.all(fitness.fitness_map(np.full((3, 4), 255, np.uint8), transformed=False) == 1.0)


def _chebyshev_inside_reference(
    genome: np.ndarray, samples: court.LineSamples, fmap: np.ndarray, steps: int = 400
) -> float:
    """Brute force: each sub-segment cut into `steps` pieces in pixel space; pieces whose midpoint is
    inside the image add F(midpoint) times their Chebyshev length. Exact for inside segments of a
    map that is linear in (u, v), approximate (to 1/steps) at the image border."""
    height, width = fmap.shape
    pixels, depth = camera.project_points(genome, samples.points)
    total = 0.0
    for e in range(len(samples.offsets) - 1):
        for j in range(samples.offsets[e], samples.offsets[e + 1] - 1):
            if depth[j] <= fitness.MIN_DEPTH_M or depth[j + 1] <= fitness.MIN_DEPTH_M:
                continue
            s = (np.arange(steps) + 0.5) / steps
            mid = pixels[j] + s[:, None] * (pixels[j + 1] - pixels[j])
            piece = np.abs(pixels[j + 1] - pixels[j]).max() / steps
            inside = ((mid[:, 0] >= 0) & (mid[:, 0] <= width - 1) & (mid[:, 1] >= 0)) & (
                mid[:, 1] <= height - 1
            )
            iu = np.clip(mid[inside, 0], 0, width - 1)
            iv = np.clip(mid[inside, 1], 0, height - 1)
            total += piece * _bilinear_reference(fmap, iu, iv).sum()
    return total


def _bilinear_reference(fmap: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    height, width = fmap.shape
    iu = np.minimum(np.floor(u).astype(int), width - 2)
    iv = np.minimum(np.floor(v).astype(int), height - 2)
    fu, fv = u - iu, v - iv
    m = fmap.astype(np.float64)
    top = m[iv, iu] * (1 - fu) + m[iv, iu + 1] * fu
    bottom = m[iv + 1, iu] * (1 - fu) + m[iv + 1, iu + 1] * fu
    return top * (1 - fv) + bottom * fv


def test_fitness_integrates_a_linear_map_exactly(target, samples):
    # a map linear in (u, v): bilinear lookups and the trapezoid rule are both exact on it, so
    # this pins the axis order (u = column, v = row) and the Chebyshev weighting
    height, width = 1080, 1920
    vv, uu = np.mgrid[0:height, 0:width]
    fmap = (0.25 + 0.5 * uu / width - 0.2 * vv / height).astype(np.float32)
    pixels, _ = camera.project_points(target, samples.points)
    assert np.all((pixels >= 0) & (pixels <= [width - 1, height - 1]))  # court fully inside
    expected = 0.0
    for e in range(len(samples.offsets) - 1):
        px = pixels[samples.offsets[e] : samples.offsets[e + 1]]
        mids = 0.5 * (px[1:] + px[:-1])
        lengths = np.abs(np.diff(px, axis=0)).max(axis=1)
        expected += float(
            (lengths * (0.25 + 0.5 * mids[:, 0] / width - 0.2 * mids[:, 1] / height)).sum()
        )
    got = fitness.population_fitness(target, samples, fmap)
    assert got.shape == (1,)
    assert got[0] == pytest.approx(expected, rel=1e-5)


def test_samples_outside_the_image_count_nothing(target, samples):
    fmap = np.ones((1080, 1920), np.float32)
    whole = fitness.population_fitness(target, samples, fmap)[0]
    moved = target.copy()
    moved[2] += 3000.0  # principal point far to the right: the court leaves the image
    assert fitness.population_fitness(moved, samples, fmap)[0] == 0.0
    # half out: only the part inside counts, sub-segments crossing the border are clipped
    half = target.copy()
    half[2] += 700.0
    pixels, _ = camera.project_points(half, samples.points)
    assert np.any(pixels[:, 0] > 1919) and np.any(pixels[:, 0] < 1919)
    got = fitness.population_fitness(half, samples, fmap)[0]
    reference = _chebyshev_inside_reference(half, samples, fmap)
    assert 0.0 < got < whole
    assert got == pytest.approx(reference, rel=2e-3)


def test_points_behind_the_camera_count_nothing(target, samples):
    fmap = np.ones((1080, 1920), np.float32)
    # turned around its vertical axis: the court is behind the camera, yet the pinhole formula puts
    # every point exactly where it was (x / z and y / z keep their values)
    cv = camera.to_opencv(target)
    about_face = np.diag([-1.0, 1.0, -1.0])
    rotation = about_face @ cv2.Rodrigues(np.array(cv["rvec"]))[0]
    cv["rvec"] = cv2.Rodrigues(rotation)[0].ravel()
    cv["tvec"] = about_face @ np.array(cv["tvec"])
    turned = camera.from_opencv(cv)
    pixels, depth = camera.project_points(turned, samples.points)
    inside = (pixels >= 0).all(axis=1) & (pixels <= [1919, 1079]).all(axis=1)
    assert np.all(depth < 0) and inside.sum() > 100
    assert fitness.population_fitness(turned, samples, fmap)[0] == 0.0
    # camera 1.5 m above the T looking at the front wall: the back of the court is behind it
    looking_at_front_wall = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # rows: camera axes
    inside_court = camera.from_opencv(
        {
            "K": [[800.0, 0, 960], [0, 800.0, 540], [0, 0, 1]],
            "dist": [0, 0, 0, 0, 0],
            "rvec": cv2.Rodrigues(looking_at_front_wall)[0].ravel(),
            "tvec": -looking_at_front_wall @ [3.2, 5.4, -1.5],
        }
    )
    _, depth = camera.project_points(inside_court, samples.points)
    assert np.any(depth < 0) and np.any(depth > 0)
    got = fitness.population_fitness(inside_court, samples, fmap)[0]
    assert got > 0.0
    assert got == pytest.approx(_chebyshev_inside_reference(inside_court, samples, fmap), rel=2e-3)


def test_non_finite_genome_scores_zero_without_touching_memory_outside_the_map(target, samples):
    fmap = np.ones((1080, 1920), np.float32)
    bad = np.repeat(target[None, :], 3, axis=0)
    bad[0, 0] = np.nan
    bad[1, 4] = np.inf
    bad[2, 7] = np.nan
    assert np.all(fitness.population_fitness(bad, samples, fmap) == 0.0)


def test_population_fitness_shapes_and_checks(target, samples):
    fmap = np.ones((1080, 1920), np.float32)
    pop = np.repeat(target[None, :], 4, axis=0)
    out = fitness.population_fitness(pop, samples, fmap)
    assert out.shape == (4,) and out.dtype == np.float64
    assert np.all(out == out[0])
    with pytest.raises(ValueError):
        fitness.population_fitness(pop[:, :14], samples, fmap)
    with pytest.raises(ValueError):
        fitness.population_fitness(pop, samples, np.ones((1, 1920), np.float32))


@pytest.mark.parametrize("transformed", [False, True])
def test_fast_fitness_ranks_like_the_literal_definition(
    transformed, model, samples, target, cluttered_edges
):
    fmap = fitness.fitness_map(cluttered_edges, transformed=transformed)
    rng = np.random.default_rng(11 + transformed)
    # Table 3 near offsets per gene, scaled from well inside "near" to beyond "far"
    half = np.array([10, 10, 10, 10, 0.1, 0.1, 0.1, 0.01, 0.01, 0.01, 0.1, 0.1, 0.025, 0.01, 0.5])
    for scale in (0.3, 1.0, 3.0, 10.0):
        pop = target + rng.uniform(-1.0, 1.0, (30, 15)) * half * scale
        fast = fitness.population_fitness(pop, samples, fmap)
        literal = fitness.literal_fitness(pop, model, fmap)
        assert spearmanr(fast, literal).statistic >= 0.95, scale
        # same scale too: the Chebyshev weighting counts roughly the rasterised pixels
        assert np.median(fast) == pytest.approx(np.median(literal), rel=0.1)


def test_literal_fitness_is_the_masked_sum(model, target):
    fmap = np.random.default_rng(0).random((1080, 1920)).astype(np.float32)
    mask = render.rasterize_court(target, model, SIZE) > 0
    got = fitness.literal_fitness(target, model, fmap)
    assert got.shape == (1,)
    assert got[0] == pytest.approx(float(fmap[mask].sum(dtype=np.float64)))


def test_scorer_scores_like_population_fitness_call_after_call(target, samples, cluttered_edges):
    fmap = fitness.fitness_map(cluttered_edges)
    scorer = fitness.Scorer(samples, fmap)
    rng = np.random.default_rng(3)
    pop = (
        target
        + rng.normal(0.0, 1.0, (6, 15)) * np.r_[[5.0] * 4, [0.05] * 3, [0.005] * 3, [0.0] * 5]
    )
    expected = fitness.population_fitness(pop, samples, fmap)
    # the scratch buffers are shared between calls: a call must not leak into the next
    for rows in (pop, pop[::-1], pop[2]):
        got = scorer(rows)
        assert np.array_equal(got, fitness.population_fitness(rows, samples, fmap))
    assert np.array_equal(scorer(pop), expected)
    assert len(set(expected.tolist())) == len(expected)  # the genomes really score differently
    with pytest.raises(ValueError):
        scorer(pop[:, :14])
