"""The global search (segments.py, search.py): lines, vanishing groups, hypotheses, verification."""

import numpy as np
import pytest

from app.calib import (
    camera,
    court,
    lines,
    parallel,
    placement,
    scene,
    search,
    segments,
    synthetic,
    verify,
)
from app.calib.court import floor_grid

SIZE = (960, 540)


def _image_lines(genome: np.ndarray, names: list[str]) -> segments.ImageLines:
    """The exact image lines of some court edges (pinhole cameras only), as the search gets them."""
    model = court.court_model()
    normals, offsets, extents = [], [], []
    for name in names:
        a, b = model.nodes[model.edges[model.edge_names.index(name)]]
        p, q = camera.project_visible(genome, np.array([a, b]))
        d = (q - p) / np.linalg.norm(q - p)
        n = np.array([-d[1], d[0]])
        normals.append(n)
        offsets.append(float(n @ p))
        extents.append([p, q])
    count = len(names)
    return segments.ImageLines(
        normal=np.array(normals),
        offset=np.array(offsets),
        extent=np.array(extents),
        support_px=np.linspace(200.0, 100.0, count),
        contrast=np.full(count, 20.0),
        ridge_share=np.ones(count),
        members=tuple((i,) for i in range(count)),
    )


def _floor_error_px(truth: np.ndarray, genomes: np.ndarray, walls_too: bool = False) -> np.ndarray:
    """Median pixel error of the floor grid (or of the court's nodes, walls included)."""
    grid = court.court_model().nodes if walls_too else floor_grid()
    true_px = camera.project_visible(truth, grid)
    seen = np.all(np.isfinite(true_px), axis=1)
    est_px, _ = camera.project_points(camera.as_population(genomes), grid[seen])
    return np.median(np.linalg.norm(est_px - true_px[seen][None], axis=2), axis=1)


FLOOR_LINES = ["short_left_inner", "box_left_back", "left_floor_box", "half_court", "box_left_side"]
WALL_CORNERS = ["front_left_corner_high", "front_right_corner_high"]


def _pinhole_target() -> np.ndarray:
    genome = synthetic.typical_target_camera(SIZE)
    genome[camera.DISTORTION_GENES] = 0.0
    return genome


def test_floor_hypotheses_contain_the_camera_that_made_the_lines():
    truth = _pinhole_target()
    image_lines = _image_lines(truth, FLOOR_LINES)
    groups = search.vanishing_groups(image_lines)
    assert len(groups) >= 2
    hypotheses = search.floor_hypotheses(image_lines, groups, court.court_model(), SIZE, None)
    assert len(hypotheses) > 0
    assert _floor_error_px(truth, hypotheses).min() < 0.1
    # every hypothesis is a camera held as people film: level, looking down at the court
    r, _ = camera.court_extrinsics(hypotheses)
    down_in_camera = r[:, :, 2]
    assert np.all(down_in_camera[:, 1] > 0)


def _with_legs(image_lines: segments.ImageLines, legs: list[tuple[np.ndarray, np.ndarray]]):
    """The image lines plus the outline of a player's legs (segments (p, q)), as strong as the
    court's lines."""
    normals, offsets = [], []
    for p, q in legs:
        d = (q - p) / np.linalg.norm(q - p)
        normals.append([-d[1], d[0]])
        offsets.append(float(np.array([-d[1], d[0]]) @ p))
    count = len(image_lines) + len(legs)
    return segments.ImageLines(
        normal=np.vstack([image_lines.normal, normals]),
        offset=np.concatenate([image_lines.offset, offsets]),
        extent=np.concatenate([image_lines.extent, np.array([[p, q] for p, q in legs])]),
        support_px=np.concatenate([image_lines.support_px, np.full(len(legs), 150.0)]),
        contrast=np.full(count, 20.0),
        ridge_share=np.ones(count),
        members=tuple((i,) for i in range(count)),
    )


def test_the_second_search_takes_court_lines_that_longer_lines_of_their_direction_outrank():
    """A tiled floor around the court, or glass panes' frames, give more lines of the court's
    two floor directions, longer than the court's own: with the 10 strongest lines of each
    vanishing group taken into quadruples the court's are left out; the second search takes
    16."""
    truth = _pinhole_target()
    court_lines = _image_lines(truth, FLOOR_LINES)
    # tile joints running across the court (y constant) in front of and behind it, and along it
    # (x constant) beside it, every one of them longer than any court line
    joints = [((x, -1.0), (x, 11.0)) for x in (-2.1, -1.8, -1.5, -1.2, -0.9, 7.3, 7.6, 7.9, 8.2)]
    joints += [((-2.0, y), (8.4, y)) for y in (-0.9, -0.6, -0.3, 10.35, 10.65, 10.95)]
    joints += [((-2.0, y), (8.4, y)) for y in (11.25, 11.55, 11.85)]
    ends = np.array([[[x0, y0, 0.0], [x1, y1, 0.0]] for (x0, y0), (x1, y1) in joints])
    pixels = camera.project_visible(truth, ends.reshape(-1, 3)).reshape(-1, 2, 2)
    assert np.all(np.isfinite(pixels))
    tiled = _with_legs(court_lines, list(pixels))
    tiled = segments.ImageLines(
        normal=tiled.normal,
        offset=tiled.offset,
        extent=tiled.extent,
        support_px=np.concatenate(
            [court_lines.support_px, np.full(len(tiled) - len(court_lines), 400.0)]
        ),
        contrast=tiled.contrast,
        ridge_share=tiled.ridge_share,
        members=tiled.members,
    )
    groups = search.vanishing_groups(tiled)
    model = court.court_model()
    for lines_per_group, found in (
        (search.QUADRUPLE_LINES_PER_GROUP, False),
        (search.QUADRUPLE_LINES_PER_GROUP_SECOND_SEARCH, True),
    ):
        hypotheses = search.floor_hypotheses(
            tiled, groups, model, SIZE, None, lines_per_group=lines_per_group
        )
        # near: within 1 % of the width, where the polish converges (joints 0.3 m apart make
        # near-copies that the distinct filter may keep instead of the exact one)
        near = len(hypotheses) > 0 and _floor_error_px(truth, hypotheses).min() < 0.01 * SIZE[0]
        assert near == found, lines_per_group


def test_vanishing_triads_find_the_floor_when_a_player_takes_the_half_court_line():
    # Behind the court: the floor's lines across are parallel in the picture, the half-court
    # line runs straight up it, one box side is seen. A player standing on the half-court line
    # adds four leg outlines meeting just above it: the greedy groups give the legs and the
    # half-court line a point of their own, and the box side is left alone; the triad of the
    # across lines and the walls' corners puts the box side and the half-court line together.
    truth = _pinhole_target()
    model = court.court_model()
    names = [
        "short_left_inner",
        "short_right_inner",
        "box_left_back",
        "box_right_back",
        "front_floor",
        "half_court",
        "box_left_side",
        "front_left_corner_high",
        "front_right_corner_high",
    ]
    half_court = camera.project_visible(
        truth, model.nodes[model.edges[model.edge_names.index("half_court")]]
    )
    top = half_court[np.argmin(half_court[:, 1])]
    meeting = top + np.array([0.0, -60.0])
    legs = []
    for offset_px in (-100.0, -37.5, 37.5, 100.0):
        p = top + np.array([offset_px, 200.0])
        legs.append((p, p + 0.5 * (meeting - p)))
    image_lines = _with_legs(_image_lines(truth, names), legs)
    groups = search.vanishing_groups(image_lines)
    greedy = search.floor_hypotheses(image_lines, groups, model, SIZE, None)
    assert _floor_error_px(truth, greedy).min() > 10.0
    triads = search.vanishing_triads(image_lines, SIZE)
    with_triads = search.floor_hypotheses(image_lines, groups, model, SIZE, None, triads)
    assert _floor_error_px(truth, with_triads).min() < 0.1


FRONT_WALL_LINES = ["service", "tin", "front_out", "front_floor"]


def _low_tripod_behind_back_wall() -> np.ndarray:
    """A phone 1.1 m high, 1.5 m behind the back wall and off-centre, looking at the front wall:
    the floor is seen at a grazing angle."""
    from app.calib.cases import look_at_rotation, make_genome

    centre = np.array([4.5, 11.3, -1.1])
    rotation = look_at_rotation(centre, np.array([3.2, 0.0, -1.0]), 0.0)
    f = 0.65 * SIZE[0]
    return make_genome(centre, rotation, f, f, ((SIZE[0] - 1) / 2, (SIZE[1] - 1) / 2), np.zeros(5))


@pytest.mark.parametrize("with_corners", [True, False])
def test_front_wall_hypotheses_contain_the_camera_that_made_the_lines(with_corners):
    truth = _low_tripod_behind_back_wall()
    corners = ["front_left_corner_mid", "front_right_corner_mid"] if with_corners else []
    image_lines = _image_lines(truth, FRONT_WALL_LINES + corners)
    groups = search.vanishing_groups(image_lines)
    model = court.court_model()
    hypotheses = search.front_wall_hypotheses(image_lines, groups, model, SIZE, None)
    # the floor hypotheses cannot make this camera: no floor line along the court is seen
    assert len(search.floor_hypotheses(image_lines, groups, model, SIZE, None)) == 0
    assert len(hypotheses) > 0
    # the wall is seen nearly face-on: the focal length comes from a grid (27% steps) and the
    # camera is a start for the polish, not the answer
    errors = _floor_error_px(truth, hypotheses, walls_too=True)
    assert errors.min() < 0.05 * SIZE[0]
    best = hypotheses[np.argmin(errors)]
    assert abs(best[0] / truth[0] - 1.0) < 0.15
    r, _ = camera.court_extrinsics(hypotheses)
    assert np.all(r[:, 1, 2] > 0)  # level: the court's down is down in the picture


def test_front_wall_seen_at_an_angle_gives_the_focal_length():
    from app.calib.cases import look_at_rotation, make_genome

    # high on the left side wall, looking across at the front wall: the wall is seen at an angle,
    # so its homography pins the focal length; 0.77 of the width lies between the grid's steps
    centre = np.array([0.3, 6.5, -3.2])
    rotation = look_at_rotation(centre, np.array([4.0, 0.0, -1.5]), 0.0)
    f = 0.77 * SIZE[0]
    truth = make_genome(centre, rotation, f, f, ((SIZE[0] - 1) / 2, (SIZE[1] - 1) / 2), np.zeros(5))
    corners = ["front_left_corner_mid", "front_right_corner_mid"]
    image_lines = _image_lines(truth, FRONT_WALL_LINES + corners)
    groups = search.vanishing_groups(image_lines)
    hypotheses = search.front_wall_hypotheses(image_lines, groups, court.court_model(), SIZE, None)
    errors = _floor_error_px(truth, hypotheses, walls_too=True)
    best = hypotheses[np.argmin(errors)]
    assert errors.min() < 0.5
    assert abs(best[0] / f - 1.0) < 0.01


@pytest.mark.parametrize("frame", ["cropped", "anamorphic"])
def test_front_wall_with_the_side_walls_gives_a_cropped_or_anamorphic_camera(frame):
    truth = _low_tripod_behind_back_wall()
    if frame == "cropped":
        truth[camera.GENE["c_u"]] += 0.25 * SIZE[0]  # the principal point far off the centre
        truth[camera.GENE["c_v"]] += 0.15 * SIZE[1]
    else:
        truth[camera.GENE["f_v"]] = 0.75 * truth[camera.GENE["f_u"]]
    # the front wall's lines and corners, and the side walls' floor junctions seen at a grazing
    # angle (their vanishing point is the wall's normal)
    names = FRONT_WALL_LINES + ["front_left_corner_mid", "front_right_corner_mid"]
    with_sides = _image_lines(truth, names + ["left_floor_front", "right_floor_front"])
    model = court.court_model()
    found = search.front_wall_hypotheses(
        with_sides, search.vanishing_groups(with_sides), model, SIZE, None
    )
    errors = _floor_error_px(truth, found, walls_too=True)
    best = int(np.argmin(errors))
    assert errors[best] < 1.0
    for gene in ("f_u", "f_v", "c_u", "c_v"):
        assert found[best, camera.GENE[gene]] == pytest.approx(truth[camera.GENE[gene]], abs=3.0)
    # without the side walls the wall alone cannot tell such a camera
    alone = _image_lines(truth, names)
    without = search.front_wall_hypotheses(alone, search.vanishing_groups(alone), model, SIZE, None)
    assert len(without) == 0 or _floor_error_px(truth, without, walls_too=True).min() > 2.0


def test_no_camera_stands_where_players_play():
    model = court.court_model()

    def at(x: float, y: float, height_m: float) -> np.ndarray:
        from app.calib.cases import look_at_rotation, make_genome

        centre = np.array([x, y, -height_m])
        rotation = look_at_rotation(centre, np.array([3.2, 4.0, 0.0]), 0.0)
        return make_genome(centre, rotation, 500.0, 500.0, (479.5, 269.5), np.zeros(5))

    # mid-court at head height, and by the front wall's middle: where players run and swing
    inside = [at(3.2, 5.0, 1.5), at(1.6, 2.3, 1.1)]
    # behind the back wall, on a tripod against it, in a front corner, high on a wall, above
    outside = [
        at(3.2, 13.0, 3.0),
        at(3.2, 9.0, 1.2),
        at(0.5, 0.5, 2.0),
        at(3.2, 6.0, 2.5),
        at(3.2, 4.0, 6.0),
    ]
    assert placement.in_play_volume(np.array(inside), model).all()
    assert not placement.in_play_volume(np.array(outside), model).any()


def test_a_cropped_photo_is_found_with_the_vertical():
    truth = _pinhole_target()
    truth[camera.GENE["c_u"]] += 0.3 * SIZE[0]  # the principal point far right of the centre
    truth[camera.GENE["c_v"]] -= 0.1 * SIZE[1]
    floor_only = _image_lines(truth, FLOOR_LINES)
    model = court.court_model()
    without = search.floor_hypotheses(
        floor_only, search.vanishing_groups(floor_only), model, SIZE, None
    )
    with_walls = _image_lines(truth, FLOOR_LINES + WALL_CORNERS)
    groups = search.vanishing_groups(with_walls)
    found = search.floor_hypotheses(with_walls, groups, model, SIZE, None)
    # square pixels at the centre cannot explain the floor; with the walls' vertical they can
    assert len(without) == 0 or _floor_error_px(truth, without).min() > 2.0
    best = int(np.argmin(_floor_error_px(truth, found)))
    assert _floor_error_px(truth, found)[best] < 1.0
    assert found[best, camera.GENE["c_u"]] == pytest.approx(truth[camera.GENE["c_u"]], abs=5.0)


def test_an_anamorphic_frame_is_found_with_the_vertical():
    truth = _pinhole_target()
    truth[camera.GENE["f_v"]] = 0.75 * truth[camera.GENE["f_u"]]  # 1440 columns shown as 1920
    truth[camera.GENE["alpha"]] += 0.1  # looking down more: the across lines stay parallel
    image_lines = _image_lines(truth, FLOOR_LINES + WALL_CORNERS)
    groups = search.vanishing_groups(image_lines)
    found = search.floor_hypotheses(image_lines, groups, court.court_model(), SIZE, None)
    # the floor and one vertical direction fit square pixels with a principal point off centre
    # just as well (it is the verification on every line, the service line's height among them,
    # that tells them apart); the frame's own camera must be among the hypotheses
    errors = _floor_error_px(truth, found, walls_too=True)
    anamorphic = np.abs(found[:, 1] / found[:, 0] - 0.75) < 0.02
    assert anamorphic.any()
    assert errors[anamorphic].min() < 0.5


def _worst_node_error_px(truth: np.ndarray, genomes: np.ndarray) -> np.ndarray:
    """Largest pixel error over the court's nodes (floor and walls) in front of the camera."""
    nodes = court.court_model().nodes
    true_px = camera.project_visible(truth, nodes)
    seen = np.all(np.isfinite(true_px), axis=1)
    est_px, _ = camera.project_points(camera.as_population(genomes), nodes[seen])
    return np.max(np.linalg.norm(est_px - true_px[seen][None], axis=2), axis=1)


def test_an_anamorphic_frame_facing_down_the_court_is_found_by_its_aspect_variants():
    truth = _pinhole_target()
    truth[camera.GENE["f_v"]] = 0.75 * truth[camera.GENE["f_u"]]
    image_lines = _image_lines(truth, FLOOR_LINES)  # no wall line: no vertical to lean on
    model = court.court_model()
    square = search.floor_hypotheses(
        image_lines, search.vanishing_groups(image_lines), model, SIZE, None
    )
    # square pixels explain the floor, but their walls miss by tens of pixels
    assert _floor_error_px(truth, square).min() < 1.0
    assert _worst_node_error_px(truth, square).min() > 20.0
    variants, rows = search.aspect_variants(square, model, SIZE)
    assert np.all((rows >= 0) & (rows < len(square)))
    # the same floors under other aspects: the frame's own camera is among them
    errors = _worst_node_error_px(truth, variants)
    best = int(np.argmin(errors))
    assert errors[best] < 2.0
    assert variants[best, 1] / variants[best, 0] == pytest.approx(0.75, abs=0.01)
    floor_px = camera.floor_to_pixel(variants[best], floor_grid()[:, :2])
    square_px = camera.floor_to_pixel(square[rows[best]], floor_grid()[:, :2])
    assert np.nanmax(np.linalg.norm(floor_px - square_px, axis=1)) < 2.0


def test_could_be_orthogonal_and_vertical():
    centre = np.array([639.5, 359.5])
    horizontal_at_infinity = np.array([1.0, 0.0, 0.0])
    above = np.array([640.0, -900.0, 1.0])
    below = np.array([650.0, 5000.0, 1.0])
    beside = np.array([5000.0, 340.0, 1.0])
    assert search.could_be_orthogonal(horizontal_at_infinity, above, centre, 1280)
    assert not search.could_be_orthogonal(horizontal_at_infinity, beside, centre, 1280)
    assert search.could_be_orthogonal(above, below, centre, 1280)
    assert search.could_be_vertical(below, centre)
    assert not search.could_be_vertical(beside, centre)
    assert not search.could_be_vertical(np.array([0.0, 1.0, 0.0]), centre)


@pytest.fixture(scope="module")
def rendered() -> tuple[np.ndarray, np.ndarray, lines.EvidenceMaps]:
    truth = synthetic.typical_target_camera(SIZE)
    image = scene.render_court_image(truth, SIZE, rng=3)
    return truth, image, lines.evidence_maps(lines.line_evidence(image))


def test_the_true_camera_outscores_moved_ones(rendered):
    truth, _, maps = rendered
    model = court.court_model()
    samples = verify.verify_samples(model)
    moved = np.repeat(truth[None], 4, axis=0)
    moved[0, camera.GENE["t_x"]] += 0.15
    moved[1, camera.GENE["alpha"]] += 0.01
    moved[2, camera.GENE["f_u"] : camera.GENE["f_v"] + 1] *= 1.05
    moved[3, camera.GENE["t_z"]] += 1.0
    cameras = np.vstack([truth[None], moved])
    tolerance = verify.verify_tolerance_px(SIZE[0])
    supported, visible, llr = verify.edge_support(cameras, samples, maps, tolerance)
    assert np.argmax(llr) == 0
    assert supported[0].sum() / visible[0].sum() > 0.7
    coarse = verify.coarse_scores(cameras, model, maps, (verify.rank_tolerance_px(SIZE[0]),))[:, 0]
    assert np.argmax(coarse) == 0


def test_scores_split_over_threads_equal_the_serial_ones(rendered, monkeypatch):
    truth, _, maps = rendered
    model = court.court_model()
    samples = verify.verify_samples(model)
    rng = np.random.default_rng(0)
    # enough cameras that every thread gets rows, and a count no thread count divides evenly
    cameras = np.repeat(truth[None], 4 * parallel.MIN_ROWS_PER_THREAD + 3, axis=0)
    cameras[:, camera.GENE["t_x"] : camera.GENE["t_z"] + 1] += rng.normal(0, 0.3, (len(cameras), 3))
    tolerances = (verify.rank_tolerance_px(SIZE[0]), verify.verify_tolerance_px(SIZE[0]))

    def scores() -> list[np.ndarray]:
        return [
            *verify.edge_support(cameras, samples, maps, tolerances[1]),
            verify.coarse_scores(cameras, model, maps, tolerances),
        ]

    monkeypatch.setattr(parallel, "thread_count", lambda: 4)
    split = scores()
    monkeypatch.setattr(parallel, "thread_count", lambda: 1)
    serial = scores()
    for a, b in zip(split, serial, strict=True):
        assert np.array_equal(a, b)
    assert parallel.row_chunks(10, 4) == [(0, 2), (2, 5), (5, 7), (7, 10)]
    assert parallel.row_chunks(2, 4) == [(0, 1), (1, 2)]


def test_one_image_line_is_evidence_for_one_court_line(rendered):
    """A camera laying two court lines on the same marks is not paid twice for them."""
    truth, _, maps = rendered
    one = verify.verify_samples(court.court_model().subset(["half_court"]))
    twice = verify.VerifySamples(
        points=np.vstack([one.points, one.points]),
        directions=np.vstack([one.directions, one.directions]),
        edge=np.concatenate([one.edge, one.edge + 1]),
        painted=np.concatenate([one.painted, one.painted]),
        p_hit=np.concatenate([one.p_hit, one.p_hit]),
        spacing_m=one.spacing_m,
        n_edges=2,
    )
    tolerance = verify.verify_tolerance_px(SIZE[0])
    supported_one, visible_one, llr_one = verify.edge_support(truth, one, maps, tolerance)
    supported_twice, visible_twice, llr_twice = verify.edge_support(truth, twice, maps, tolerance)
    assert llr_one[0] > 0
    # the second copy only adds the misses of its unsupported samples
    assert 0.9 * llr_one[0] < llr_twice[0] <= llr_one[0]
    # what each edge's verdict sees is unchanged
    assert np.allclose(supported_twice[0], supported_one[0, 0])
    assert np.allclose(visible_twice[0], visible_one[0, 0])


def test_a_line_grazing_the_lens_does_not_win_on_a_few_samples(rendered):
    truth, _, maps = rendered
    samples = verify.verify_samples(court.court_model())
    tolerance = verify.verify_tolerance_px(SIZE[0])
    _, visible, _ = verify.edge_support(truth, samples, maps, tolerance)
    # no sample stands for more than a share of the diagonal: an edge's visible length is bounded
    per_sample_cap = verify.MAX_SAMPLE_SHARE_OF_DIAGONAL * np.hypot(*SIZE)
    counts = np.bincount(samples.edge, minlength=samples.n_edges)
    assert np.all(visible[0] <= counts * per_sample_cap + 1e-6)


def test_floor_share(rendered):
    truth, _, _ = rendered
    model = court.court_model()
    share = placement.floor_shares(truth, model, SIZE)[0]
    # the floor polygon drawn and counted
    floor = np.zeros(SIZE[::-1], np.uint8)
    corners = camera.floor_to_pixel(truth, np.array([[0, 0], [6.4, 0], [6.4, 9.75], [0, 9.75]]))
    import cv2

    cv2.fillPoly(floor, [np.round(corners).astype(np.int32)], 1)
    assert share == pytest.approx(floor.mean(), abs=0.03)
    looking_up = truth.copy()
    looking_up[camera.GENE["alpha"]] -= 0.6
    assert placement.floor_shares(looking_up, model, SIZE)[0] < share / 3


def test_distinct_best_keeps_cameras_apart(rendered):
    truth, _, _ = rendered
    model = court.court_model()
    near = np.repeat(truth[None], 3, axis=0)
    near[1, camera.GENE["t_x"]] += 0.001
    near[2, camera.GENE["t_x"]] += 1.0
    chosen = verify.distinct_best(near, np.array([3.0, 2.0, 1.0]), model, SIZE, 3)
    assert list(chosen) == [0, 2]


def test_chains_segments_and_the_lens(rendered):
    truth, image, _ = rendered
    evidence = lines.line_evidence(image)
    chains = segments.chains_of(evidence)
    assert len(chains) > 10
    lens = segments.estimate_undistortion(chains, SIZE)
    # the typical target's barrel lens (k1 -0.12 at f = 1000 px): lambda = k1 (R / f)^2 < 0
    assert -0.2 < lens.lam < -0.03
    pieces = segments.segments_of(chains, lens, 20.0)
    image_lines = segments.merge_collinear(pieces)
    assert len(image_lines) < len(pieces)
    # the half-court line is one long line through its projection
    model = court.court_model()
    a, b = model.nodes[model.edges[model.edge_names.index("half_court")]]
    ends = lens.apply(camera.project_visible(truth, np.array([a, b])))
    distance = np.abs(ends @ image_lines.normal.T - image_lines.offset[None, :]).max(axis=0)
    assert distance.min() < 1.5


def _chains(polylines: list[np.ndarray]) -> segments.Chains:
    points = np.concatenate(polylines)
    start = np.concatenate([[0], np.cumsum([len(p) for p in polylines])]).astype(np.int64)
    return segments.Chains(points, start, np.ones(len(points), bool), np.full(len(points), 20.0))


def _through_lens(undistorted: np.ndarray, focal_px: float, k1: float, k2: float) -> np.ndarray:
    """Pixels of ideal-pinhole points (pixels, square and centred) through a Brown lens."""
    centre = camera.picture_centre(SIZE)
    normalised = (undistorted - centre) / focal_px
    r2 = np.sum(normalised * normalised, axis=1, keepdims=True)
    return centre + focal_px * normalised * (1.0 + k1 * r2 + k2 * r2 * r2)


def test_the_lens_the_court_lines_agree_on_is_a_candidate_beside_a_straight_graphic():
    # A strong wide-angle lens (k1 -0.25, k2 0.03 at f = 0.55 of the width, the corners near
    # where the lens folds) bends eight court lines beyond what one division-model term
    # straightens exactly; a score graphic's long edges run straight across the picture (drawn
    # on it, not seen through the lens), with more points than any court line. The lens is
    # what the court lines agree on, as with them alone; the graphic's "no lens" is a second
    # candidate.
    rng = np.random.default_rng(3)
    centre = camera.picture_centre(SIZE)
    focal = 0.55 * SIZE[0]
    polylines = []
    for k in range(8):
        angle = np.pi * k / 8 + 0.1
        direction = np.array([np.cos(angle), np.sin(angle)])
        normal = np.array([-direction[1], direction[0]])
        along = np.linspace(-400.0, 400.0, 400)[:, None] * direction
        pixels = _through_lens(centre + 80.0 * (1 + k % 4) * normal + along, focal, -0.25, 0.03)
        inside = camera.pixels_in_image(pixels, SIZE)
        polylines.append(pixels[inside] + rng.normal(0.0, 0.15, (int(inside.sum()), 2)))
    court_alone = segments.undistortion_candidates(_chains(polylines), SIZE)
    assert len(court_alone) == 1 and court_alone[0].lam < -0.3
    for row in (30.0, 500.0):
        polylines.append(np.column_stack([np.linspace(20.0, 940.0, 1500), np.full(1500, row)]))
    candidates = segments.undistortion_candidates(_chains(polylines), SIZE)
    assert len(candidates) == 2
    assert candidates[0].lam == pytest.approx(court_alone[0].lam, abs=0.02)
    assert abs(candidates[1].lam) < 0.03


@pytest.mark.parametrize(
    ("centre", "behind"),
    [
        ([3.2, -5.0, -2.0], True),  # behind the front wall, below its top: sees no court
        ([3.2, -5.0, -7.0], False),  # high above it, looking down over it
        # 13 m behind it and 6 m high: the wall's top hides the whole floor (the line of sight
        # over a 4.57 m top reaches the floor 39 m beyond the wall); 11 m high sees the back
        ([3.2, -13.0, -6.0], True),
        ([3.2, -13.0, -11.0], False),
        # beside the court, beyond a side wall's plane: it sees the floor through that wall
        ([-2.0, -1.5, -2.0], False),
        ([3.2, -0.2, -2.0], False),  # mounted on the front wall
        ([3.2, 12.0, -2.0], False),  # behind the back wall
    ],
)
def test_a_camera_behind_the_front_wall_is_implausible(centre, behind):
    genome = search.look_at_genomes(
        np.array([centre]), np.array([[3.2, 5.0, 0.0]]), np.zeros(1), np.array([800.0]), SIZE
    )
    assert placement.behind_front_wall(genome, court.court_model())[0] == behind
    assert placement.implausible_placement(genome, court.court_model())[0] == behind
