import json

import cv2
import numpy as np
import pytest

from app.calib import camera, edges, pipeline, render, synthetic
from app.calib.court import court_model, floor_grid, spacing_for_image
from app.calib.fitness import distance_map

SIZE = (1280, 720)
GENERATIONS = 800  # enough here: the start search does the coarse work, refinement the fine


def club_camera() -> np.ndarray:
    """A wide club camera just behind the glass back wall, off-centre, yawed and rolled a little,
    with barrel distortion: far from the default start (centred, 2 m back, no distortion)."""
    genome = pipeline.look_at_genomes(
        np.array([[3.8, 10.6, -3.2]]),
        np.array([[3.0, 3.8, 0.0]]),
        np.deg2rad([1.0]),
        np.array([530.0]),
        SIZE,
    )[0]
    genome[camera.GENE["k1"]] = -0.08
    return genome


def floor_errors_cm(truth: np.ndarray, result: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Floor error (cm) of the 16 x 16 floor grid points the true camera sees, and which of them
    are mid-court (1 m or more from the side walls, 2-8 m from the front wall)."""
    grid = floor_grid()[:, :2]
    pixels = camera.floor_to_pixel(truth, grid)
    width, height = SIZE
    seen = (
        (pixels[:, 0] >= 0)
        & (pixels[:, 0] <= width - 1)
        & (pixels[:, 1] >= 0)
        & (pixels[:, 1] <= height - 1)
    )
    floor, status = camera.pixel_to_floor(result, pixels[seen])
    errors = np.where(status == camera.RAY_OK, np.linalg.norm(floor - grid[seen], axis=1), np.inf)
    x, y = grid[seen, 0], grid[seen, 1]
    mid = (x >= 1.0) & (x <= 5.4) & (y >= 2.0) & (y <= 8.0)
    return 100.0 * errors, mid


@pytest.fixture(scope="module")
def truth() -> np.ndarray:
    return club_camera()


@pytest.fixture(scope="module")
def photo(truth) -> np.ndarray:
    return synthetic.render_court_image(truth, SIZE, rng=11)


@pytest.fixture(scope="module")
def result(photo) -> pipeline.CalibrationResult:
    return pipeline.calibrate(photo, seed=0, max_generations=GENERATIONS)


def test_calibrates_a_club_camera_with_no_start_camera(truth, result):
    start_errors, _ = floor_errors_cm(truth, pipeline.default_start_genome(SIZE))
    assert np.mean(start_errors) > 50.0  # the default start is nowhere near
    errors, mid = floor_errors_cm(truth, result.genome)
    assert mid.sum() > 50
    assert np.mean(errors) < 2.0
    assert np.max(errors[mid]) < 2.0
    assert result.quality["inlier_excess"] > 0.9
    assert result.quality["supported_edges"] >= 15


def test_result_json_holds_an_opencv_camera_that_reproduces_the_projection(result):
    doc = json.loads(json.dumps(result.to_json()))
    for key in ("opencv", "genome", "fitness", "generations", "seed", "bundle", "spec"):
        assert key in doc
    assert set(doc["timings_s"]) >= {"edges", "optimise", "refine", "total"}
    assert doc["timings_s"]["optimise"] > 0
    assert doc["stop_reason"] in ("stalled", "max_generations", "time_budget")
    assert doc["generations"] >= 1 and doc["seed"] == 0 and doc["spec"] == "wsf"
    assert doc["quality"]["inlier_fraction"] > 0.8
    cv = doc["opencv"]
    assert cv["image_size"] == list(SIZE)
    points = court_model().nodes[:14]  # the floor nodes: all in view of this camera
    ours = camera.project_visible(result.genome, points)
    theirs, _ = cv2.projectPoints(
        points, np.array(cv["rvec"]), np.array(cv["tvec"]), np.array(cv["K"]), np.array(cv["dist"])
    )
    assert np.abs(theirs[:, 0] - ours).max() < 1e-6
    genome, size = camera.camera_from_json(doc)
    assert size == SIZE
    assert genome == pytest.approx(result.genome, abs=1e-9)


def test_refinement_beats_the_ga_alone(truth, result):
    ga_errors, _ = floor_errors_cm(truth, result.ga_genome)
    errors, _ = floor_errors_cm(truth, result.genome)
    assert np.mean(errors) < 0.5 * np.mean(ga_errors)


def test_refinement_reaches_sub_pixel_accuracy_from_near_the_answer(truth, photo):
    model = court_model()
    samples, _ = pipeline.fitting_samples(model, spacing_for_image(SIZE[0]))
    dmap = distance_map(edges.extract_edges(photo))
    rng = np.random.default_rng(8)
    grid = floor_grid()
    for _ in range(3):
        start = synthetic.wiggle_camera(truth, "near", rng)
        start[camera.DISTORTION_GENES] = truth[camera.DISTORTION_GENES]
        refined = pipeline.refine_fully(start, samples, dmap, None, SIZE)
        seen = np.all(
            np.abs(camera.project_visible(truth, grid) - np.array(SIZE) / 2) < np.array(SIZE) / 2,
            axis=1,
        )
        before = synthetic.mean_reprojection_error(truth, start, grid[seen])
        after = synthetic.mean_reprojection_error(truth, refined, grid[seen])
        assert after < 0.2 < 2.0 < before


def test_moving_players_are_masked_out(truth):
    frame = synthetic.render_clip_frames(truth, SIZE, 4, rng=11)[3]
    empty = synthetic.render_court_image(truth, SIZE, rng=11)
    moving = np.any(frame != empty, axis=2).astype(np.uint8) * 255
    assert 0.005 < (moving > 0).mean() < 0.2  # players are in the picture
    edge_image = pipeline.prepare_edge_image(frame, moving)
    assert not edge_image[moving > 0].any()
    masked = pipeline.calibrate(frame, seed=0, max_generations=GENERATIONS, moving_mask=moving)
    errors, mid = floor_errors_cm(truth, masked.genome)
    assert np.mean(errors) < 2.0
    assert np.max(errors[mid]) < 2.0


def test_an_edge_image_is_used_as_it_is(truth):
    edge_image = render.rasterize_court(truth, court_model(), SIZE)
    assert np.array_equal(pipeline.prepare_edge_image(edge_image), edge_image)
    fitted = pipeline.calibrate(edge_image, seed=1, max_generations=GENERATIONS)
    errors, mid = floor_errors_cm(truth, fitted.genome)
    assert np.mean(errors) < 3.0


def test_a_start_camera_is_used_and_the_same_seed_repeats_exactly(truth):
    rng = np.random.default_rng(4)
    start = synthetic.wiggle_camera(truth, "near", rng)
    edge_image = render.rasterize_court(truth, court_model(), SIZE)
    runs = [
        pipeline.calibrate(edge_image, start_genome=start, seed=7, max_generations=300)
        for _ in range(2)
    ]
    assert np.array_equal(runs[0].genome, runs[1].genome)
    assert runs[0].start_genome == pytest.approx(start)
    assert "grid_candidates" not in runs[0].quality  # no start search when a start is given
    errors, _ = floor_errors_cm(truth, runs[0].genome)
    assert np.mean(errors) < 3.0


def test_progress_reports_each_stage_in_order(truth):
    edge_image = render.rasterize_court(truth, court_model(), SIZE)
    calls: list[tuple[str, float, dict]] = []
    pipeline.calibrate(
        edge_image, max_generations=200, progress=lambda s, f, i: calls.append((s, f, i))
    )
    stages = [c[0] for c in calls]
    assert stages[0] == "edges" and stages[-1] == "refining"
    order = {"edges": 0, "optimising": 1, "refining": 2}
    assert [order[s] for s in stages] == sorted(order[s] for s in stages)
    assert all(0.0 <= f <= 1.0 for _, f, _ in calls)
    assert calls[-1][1] == 1.0
    assert any("generation" in info for s, _, info in calls if s == "optimising")


def _photo_like_clutter(rng: np.random.Generator) -> np.ndarray:
    """Smooth multi-scale noise with posters and frames: many edges, some of them long and
    straight, none forming a court."""
    width, height = SIZE
    image = np.zeros((height, width, 3), np.float32)
    for cells in (4, 16, 64):
        layer = rng.normal(0, 40.0 / np.sqrt(cells), (cells * height // width + 1, cells, 3))
        image += cv2.resize(layer.astype(np.float32), SIZE, interpolation=cv2.INTER_CUBIC)
    image += 120.0
    for _ in range(25):
        x0, y0 = rng.integers(0, width - 60), rng.integers(0, height - 60)
        x1, y1 = x0 + rng.integers(30, 300), y0 + rng.integers(30, 200)
        colour = tuple(float(c) for c in rng.uniform(0, 255, 3))
        cv2.rectangle(image, (int(x0), int(y0)), (int(x1), int(y1)), colour, -1)
    for _ in range(12):
        p0 = tuple(int(v) for v in rng.integers(0, [width, height]))
        p1 = tuple(int(v) for v in rng.integers(0, [width, height]))
        cv2.line(image, p0, p1, (40.0, 40.0, 190.0), 3)
    return np.clip(image, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("kind", ["plain", "uniform_noise", "photo_like"])
def test_no_court_raises_court_not_found(kind):
    rng = np.random.default_rng(21)
    width, height = SIZE
    if kind == "plain":
        image = np.full((height, width, 3), (90, 120, 150), np.uint8)
    elif kind == "uniform_noise":
        image = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
    else:
        image = _photo_like_clutter(rng)
    with pytest.raises(pipeline.CourtNotFound, match="^court not found: ") as info:
        pipeline.calibrate(image, seed=0, max_generations=GENERATIONS)
    if kind != "plain":
        assert info.value.quality["inlier_excess"] < pipeline.MIN_INLIER_EXCESS or (
            info.value.quality["supported_edges"] < pipeline.MIN_SUPPORTED_EDGES
        )


def test_bad_input_raises_value_error(photo):
    with pytest.raises(ValueError, match="uint8"):
        pipeline.calibrate(photo.astype(np.float32))
    with pytest.raises(ValueError, match="too small"):
        pipeline.calibrate(photo[:20, :20])
    with pytest.raises(ValueError, match="moving_mask"):
        pipeline.calibrate(photo, moving_mask=np.zeros((10, 10), np.uint8))
    with pytest.raises(ValueError, match="bundle"):
        pipeline.calibrate(photo, bundle="no-such-bundle")
    with pytest.raises(ValueError, match="spec"):
        pipeline.calibrate(photo, spec="tennis")
    with pytest.raises(ValueError, match="finite"):
        pipeline.calibrate(photo, start_genome=np.full(15, np.nan))
    with pytest.raises(ValueError, match="max_generations"):
        pipeline.calibrate(photo, max_generations=0)


def test_lens_fold_guard():
    genome = club_camera()
    assert not pipeline.lens_folds_in_image(genome, SIZE)
    assert np.isfinite(camera.lens_fold_radius(genome))  # folds, but outside the picture
    genome[camera.GENE["k1"]] = -0.6
    assert pipeline.lens_folds_in_image(genome, SIZE)
    genome[camera.GENE["k1"]] = 0.1
    assert camera.lens_fold_radius(genome) == np.inf


def test_painted_lines_are_fitted_by_their_borders():
    model = court_model()
    samples, owners = pipeline.fitting_samples(model, 0.1)
    half_court = model.edge_names.index("half_court")
    runs = np.flatnonzero(owners == half_court)
    assert len(runs) == 2
    xs = [samples.points[samples.offsets[r] : samples.offsets[r + 1], 0] for r in runs]
    assert sorted(float(x.mean()) for x in xs) == pytest.approx([3.175, 3.225])
    front_floor = model.edge_names.index("front_floor")  # a wall/floor junction: one run
    assert np.sum(owners == front_floor) == 1


def test_overlay_draws_the_court_on_a_copy(truth, photo):
    overlay = pipeline.draw_overlay(photo, truth)
    assert overlay.shape == photo.shape and overlay.dtype == np.uint8
    green = (overlay[:, :, 1] == 255) & (overlay[:, :, 0] == 0) & (overlay[:, :, 2] == 0)
    assert green.mean() > 0.005
    t_pixel = np.rint(camera.floor_to_pixel(truth, np.array([[3.2, 5.465]]))[0]).astype(int)
    assert green[t_pixel[1], t_pixel[0]]
    grey = cv2.cvtColor(photo, cv2.COLOR_BGR2GRAY)
    assert pipeline.draw_overlay(grey, truth).shape == photo.shape
    assert not np.array_equal(overlay, photo)
