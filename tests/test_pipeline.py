"""The whole calibration (pipeline.calibrate) on rendered courts: accuracy with no start camera,
the OpenCV export, the optional GA, players masked out, hints, progress, refusals."""

import json

import cv2
import numpy as np
import pytest

from app.calib import camera, cases, pipeline, refine, render, scene, search, synthetic, verify
from app.calib.court import court_model, floor_grid

SIZE = (1280, 720)


def club_camera() -> np.ndarray:
    """A wide club camera just behind the glass back wall, off-centre, yawed and rolled a little,
    with barrel distortion: far from any default start."""
    genome = search.look_at_genomes(
        np.array([[3.8, 10.6, -3.2]]),
        np.array([[3.0, 3.8, 0.0]]),
        np.deg2rad([1.0]),
        np.array([530.0]),
        SIZE,
    )[0]
    genome[camera.GENE["k1"]] = -0.08
    return genome


def floor_errors_cm(
    truth: np.ndarray, result: np.ndarray, spec: str = "wsf"
) -> tuple[np.ndarray, np.ndarray]:
    """Floor error (cm) of the 16 x 16 floor grid points the true camera sees, and which of them
    are mid-court (1 m or more from the side walls, 2-8 m from the front wall)."""
    grid = floor_grid(spec)[:, :2]
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
    return scene.render_court_image(truth, SIZE, rng=11)


@pytest.fixture(scope="module")
def result(photo) -> pipeline.CalibrationResult:
    return pipeline.calibrate(photo)


def test_calibrates_a_club_camera_with_no_start_camera(truth, result):
    start_errors, _ = floor_errors_cm(truth, search.default_start_genome(SIZE))
    assert np.mean(start_errors) > 50.0  # a default placement is nowhere near
    errors, mid = floor_errors_cm(truth, result.genome)
    assert mid.sum() > 50
    assert np.mean(errors) < 1.0
    assert np.max(errors[mid]) < 1.5
    assert result.verdict.label == "good"
    assert result.quality["supported_edges"] >= 15
    assert result.quality["wall_edges_supported"] >= 3
    assert result.refined_from in ("lines", "grid")
    assert result.generations == 0 and result.ga_genome is None  # no GA unless asked for


def test_reported_uncertainty_is_small_and_covers_the_error(truth, result):
    floor_cm = result.uncertainty["floor_error_cm"]
    assert 0.0 < floor_cm["T"] < 3.0
    t_true = np.array([[3.2, 5.465]])
    pixel = camera.floor_to_pixel(truth, t_true)
    found, _ = camera.pixel_to_floor(result.genome, pixel)
    # the error at the T is within a few standard deviations (plus the render's own blur)
    assert 100.0 * np.linalg.norm(found - t_true) < 4.0 * floor_cm["T"] + 1.0
    assert set(result.uncertainty["parameters"]) >= {"f_u", "t_x", "t_y", "t_z", "alpha"}


def test_result_json_holds_an_opencv_camera_that_reproduces_the_projection(result):
    doc = json.loads(json.dumps(result.to_json()))
    for key in ("opencv", "genome", "verdict", "camera_model", "uncertainty", "refined_from"):
        assert key in doc
    assert doc["verdict"]["label"] == "good" and doc["verdict"]["reasons"]
    assert set(doc["timings_s"]) >= {"edges", "search", "refine", "total"}
    assert doc["stop_reason"] == "search" and doc["spec"] == "wsf"
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


def test_the_papers_ga_runs_between_search_and_refinement_when_asked(truth, photo):
    ran = pipeline.calibrate(photo, bundle="n16-tdm-roulette-single-dist", max_generations=40)
    assert 1 <= ran.generations <= 40
    assert ran.ga_genome is not None and np.isfinite(ran.ga_fitness)
    assert ran.timings_s["optimise"] > 0
    assert [c["stage"] for c in ran.convergence] == ["search", "ga"]
    errors, _ = floor_errors_cm(truth, ran.genome)
    assert np.mean(errors) < 1.0


def test_moving_players_are_masked_out(truth):
    frame = scene.render_clip_frames(truth, SIZE, 4, rng=11)[3]
    empty = scene.render_court_image(truth, SIZE, rng=11)
    moving = np.any(frame != empty, axis=2).astype(np.uint8) * 255
    assert 0.005 < (moving > 0).mean() < 0.2  # players are in the picture
    evidence = pipeline.evidence_image(frame, moving)
    assert not evidence[moving > 0].any()
    masked = pipeline.calibrate(frame, moving_mask=moving)
    errors, mid = floor_errors_cm(truth, masked.genome)
    assert np.mean(errors) < 2.0
    assert np.max(errors[mid]) < 2.0


def test_an_edge_image_is_used_as_it_is(truth):
    edge_image = render.rasterize_court(truth, court_model(), SIZE)
    fitted = pipeline.calibrate(edge_image)
    errors, _ = floor_errors_cm(truth, fitted.genome)
    assert np.mean(errors) < 2.0
    assert pipeline.evidence_image(edge_image)[edge_image > 0].mean() > 200  # taken as ridges


def test_a_wrong_start_camera_does_not_take_over_and_runs_repeat_exactly(truth, photo):
    wrong = synthetic.wiggle_camera(truth, "far", np.random.default_rng(4))
    assert np.mean(floor_errors_cm(truth, wrong)[0]) > 30.0
    runs = [pipeline.calibrate(photo, start_genome=wrong) for _ in range(2)]
    assert np.array_equal(runs[0].genome, runs[1].genome)
    errors, _ = floor_errors_cm(truth, runs[0].genome)
    assert np.mean(errors) < 1.0


def test_a_good_start_camera_is_polished(truth):
    near = synthetic.wiggle_camera(truth, "near", np.random.default_rng(5))
    edge_image = render.rasterize_court(truth, court_model(), SIZE)
    fitted = pipeline.calibrate(edge_image, start_genome=near)
    assert np.mean(floor_errors_cm(truth, fitted.genome)[0]) < 2.0


def test_progress_reports_each_stage_in_order(photo):
    calls: list[tuple[str, float, dict]] = []
    pipeline.calibrate(photo, progress=lambda s, f, i: calls.append((s, f, i)))
    stages = [c[0] for c in calls]
    assert stages[0] == "edges" and stages[-1] == "refining"
    order = {"edges": 0, "optimising": 1, "refining": 2}
    assert [order[s] for s in stages] == sorted(order[s] for s in stages)
    assert all(0.0 <= f <= 1.0 for _, f, _ in calls)
    assert calls[-1][1] == 1.0
    assert any("hypotheses" in info for s, _, info in calls if s == "optimising")


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
    with pytest.raises(pipeline.CourtNotFound, match="^court not found: "):
        pipeline.calibrate(image)


@pytest.mark.parametrize("kind", ["badminton", "tennis", "volleyball", "checkerboard", "text_page"])
def test_another_sports_court_or_a_pattern_is_not_taken_for_a_squash_court(kind):
    negative = cases.make_negative(kind, 100)
    with pytest.raises(pipeline.CourtNotFound) as info:
        pipeline.calibrate(negative.image)
    assert info.value.reasons


def test_a_badminton_court_whose_lines_a_squash_floor_fits_is_refused_for_its_service_boxes():
    # bench.synthetic's negative badminton 7006: a squash camera lays its short line, floor
    # lines and front wall onto the badminton court's lines and net and passed every other rule;
    # nothing lies where its half-court line and service boxes go
    negative = cases.make_negative("badminton", 7006)
    with pytest.raises(pipeline.CourtNotFound) as info:
        pipeline.calibrate(negative.image)
    assert any("service boxes" in reason for reason in info.value.reasons), info.value.reasons


@pytest.mark.slow
def test_a_room_with_court_like_lines_is_refused():
    # bench.synthetic's negative room 1001: lines on floor and walls that a wrong squash camera
    # half explains (13 edges supported, walls included, with an earlier search, whose camera
    # the floor-share rule refused: test_quality covers that rule)
    negative = cases.make_negative("room", 1001)
    with pytest.raises(pipeline.CourtNotFound) as info:
        pipeline.calibrate(negative.image)
    assert info.value.reasons


def test_a_view_of_the_front_wall_alone_is_refused_because_the_floor_is_not_pinned():
    # the front wall's lines and the wall corners fit many cameras: with no floor line along the
    # court, feet cannot be placed, so the verdict must refuse and say to film more of the floor
    truth = search.look_at_genomes(
        np.array([[3.2, 4.0, -1.8]]),
        np.array([[3.2, 0.0, -2.6]]),
        np.zeros(1),
        np.array([747.0]),
        SIZE,
    )[0]
    photo = scene.render_court_image(truth, SIZE, rng=5)
    with pytest.raises(pipeline.CourtNotFound) as info:
        pipeline.calibrate(photo)
    assert any("floor" in reason for reason in info.value.reasons)


def test_a_doubles_court_is_calibrated_under_its_own_spec():
    truth = search.look_at_genomes(
        np.array([[3.81, 11.5, -3.5]]),
        np.array([[3.81, 4.5, 0.0]]),
        np.zeros(1),
        np.array([700.0]),
        SIZE,
    )[0]
    photo = scene.render_court_image(truth, SIZE, spec="doubles", rng=3)
    fitted = pipeline.calibrate(photo, spec="doubles")
    assert fitted.spec == "doubles"
    assert np.mean(floor_errors_cm(truth, fitted.genome, "doubles")[0]) < 2.0


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
    assert not refine.lens_folds_in_image(genome, SIZE)
    assert np.isfinite(camera.lens_fold_radius(genome))  # folds, but outside the picture
    genome[camera.GENE["k1"]] = -0.6
    assert refine.lens_folds_in_image(genome, SIZE)
    genome[camera.GENE["k1"]] = 0.1
    assert camera.lens_fold_radius(genome) == np.inf


def largest_k2_left_over_px(focal_px: float, image_size: tuple[int, int]) -> float:
    """The most plausible k2's largest displacement over the picture less what k1 and the focal
    length absorb (least squares over the radius)."""
    r = np.linspace(0.0, 0.5 * np.hypot(*image_size) / focal_px, 200)
    displacement_px = refine.PLAUSIBLE_K2 * r**5 * focal_px
    basis = np.column_stack([r, r**3]) * focal_px
    absorbed, *_ = np.linalg.lstsq(basis, displacement_px, rcond=None)
    return float(np.abs(displacement_px - basis @ absorbed).max())


@pytest.mark.parametrize(
    ("focal_px", "image_size", "could_show"),
    [(2700.0, (1280, 720), False), (900.0, (1920, 1080), True), (1500.0, (640, 360), False)],
)
def test_a_second_radial_term_is_tried_only_where_it_could_move_a_line_by_a_pixel(
    focal_px, image_size, could_show
):
    genome = np.zeros(camera.N_GENES)
    genome[camera.GENE["f_u"]] = genome[camera.GENE["f_v"]] = focal_px
    assert refine.second_radial_term_could_show(genome, image_size) is could_show
    assert (largest_k2_left_over_px(focal_px, image_size) > 1.0) is could_show


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


def test_an_anamorphic_frame_refused_with_square_pixels_is_found_by_the_second_search() -> None:
    """bench.synthetic's anamorphic_cropped 1007 (1280 x 720 shown from a 4:3 picture, f_v / f_u =
    0.75): square pixels explain its floor but not its walls, and the usual search is refused;
    the search with the anamorphic aspects finds it. (The case changes as the usual search
    improves: 1008 was such a case until the vanishing triads found it in the usual search.)"""
    from bench.synthetic import FOUND_FLOOR_CM, FOUND_LINES_PX, camera_errors

    case = cases.make_case("anamorphic_cropped", 1007)
    size = (case.image.shape[1], case.image.shape[0])
    result = pipeline.calibrate(case.image, spec=case.spec)
    assert "square_pixel_pass" in result.timings_s  # the first search was refused
    assert result.timings_s["total"] > result.timings_s["square_pixel_pass"]
    aspect = result.genome[camera.GENE["f_v"]] / result.genome[camera.GENE["f_u"]]
    assert aspect == pytest.approx(0.75, abs=0.01)
    floor_cm, lines_px = camera_errors(case.genome, result.genome, case.spec, size)
    assert floor_cm <= FOUND_FLOOR_CM and lines_px <= FOUND_LINES_PX, (floor_cm, lines_px)
    assert "aspect" in result.camera_model


def test_a_strong_lens_the_least_squares_plumb_line_misjudged_is_straightened() -> None:
    """bench.synthetic's wide_angle 5008 (1920 x 1080, k1 = -0.18, k2 = 0.015 at f = 0.49 of the
    width): the least-squares plumb-line estimate of the lens said -0.16, the lines it
    straightened gave no hypothesis near the court, and only the second search's stronger
    multiple of it found one. The chains' consensus (`segments.undistortion_candidates`) says a
    stronger lens, and the usual search has the court among its candidates."""
    from app.calib import lines, segments
    from bench.search_recall import NEAR_SHARE_OF_WIDTH, floor_grid_errors_px

    case = cases.make_case("wide_angle", 5008)
    size = (case.image.shape[1], case.image.shape[0])
    evidence = lines.line_evidence_of(case.image)
    lens = segments.undistortion_candidates(segments.chains_of(evidence), size)[0]
    assert lens.lam < -0.25
    model = court_model(case.spec)
    found = search.search_cameras(
        evidence, lines.evidence_maps(evidence), model, size, None, verify.verify_samples(model)
    )
    errors = floor_grid_errors_px(case.genome, found.candidates, case.spec, size)
    assert errors.min() <= NEAR_SHARE_OF_WIDTH * size[0]


def test_a_club_view_through_a_strong_lens_has_its_lines_right_to_the_picture_edge() -> None:
    """bench.synthetic's club 5007 (1920 x 1080, f = 787 px, k1 = -0.196, k2 = 0.020): accepted
    before the lens starts with the floor 0.7 cm right and the lines 25 px RMS off (the side
    wall's line at the picture's left edge 150 px off, the evidence there set aside as off the
    court). Calibrated from no start, the lines come within the benchmark's 2 px."""
    from bench.synthetic import FOUND_FLOOR_CM, FOUND_LINES_PX, camera_errors

    case = cases.make_case("club", 5007)
    size = (case.image.shape[1], case.image.shape[0])
    result = pipeline.calibrate(case.image, spec=case.spec)
    assert "k2" in result.camera_model
    floor_cm, lines_px = camera_errors(case.genome, result.genome, case.spec, size)
    assert floor_cm <= FOUND_FLOOR_CM and lines_px <= FOUND_LINES_PX, (floor_cm, lines_px)


def test_a_lens_refit_that_fits_the_floor_lines_worse_does_not_replace_the_fit() -> None:
    """bench.synthetic's club 7007 (a wide lens with decentring, a glass back wall with its
    frame): the lens starts find a camera that costs 7 % less on all of the evidence by laying
    the back wall's out line on the glass wall's frame, 4.5 px RMS off, and fits the floor's
    lines worse; the fit from before them, within the benchmark's 2 px, stands."""
    from bench.synthetic import FOUND_FLOOR_CM, FOUND_LINES_PX, camera_errors

    case = cases.make_case("club", 7007)
    size = (case.image.shape[1], case.image.shape[0])
    result = pipeline.calibrate(case.image, spec=case.spec)
    floor_cm, lines_px = camera_errors(case.genome, result.genome, case.spec, size)
    assert floor_cm <= FOUND_FLOOR_CM and lines_px <= FOUND_LINES_PX, (floor_cm, lines_px)


def test_the_lens_starts_do_not_turn_a_refused_camera_into_an_accepted_one() -> None:
    """bench.synthetic's corner_side 7037: the first search's camera is refused; refitted from
    the lens starts and judged on the evidence on its own court, it passed at 6.3 cm off, and
    the second search, which finds the court, did not run. The lens starts only sharpen a
    camera the verdict takes."""
    from bench.synthetic import FOUND_FLOOR_CM, camera_errors

    case = cases.make_case("corner_side", 7037)
    size = (case.image.shape[1], case.image.shape[0])
    result = pipeline.calibrate(case.image, spec=case.spec)
    assert "square_pixel_pass" in result.timings_s  # the first search's camera was refused
    floor_cm, _ = camera_errors(case.genome, result.genome, case.spec, size)
    assert floor_cm <= FOUND_FLOOR_CM, floor_cm
