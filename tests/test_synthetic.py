import cv2
import numpy as np
import pytest

from app.calib import camera, court, synthetic

FULL_HD = (1920, 1080)


def test_typical_target_sees_the_whole_court_at_any_aspect_ratio():
    model = court.court_model()
    for size in [(1920, 1080), (1280, 720), (800, 600), (1080, 1920)]:
        g = synthetic.typical_target_camera(size)
        px = camera.project_visible(g, model.nodes)
        assert np.all(np.isfinite(px))
        width, height = size
        assert px[:, 0].min() > 0.05 * width and px[:, 0].max() < 0.95 * width
        assert px[:, 1].min() > 0.05 * height and px[:, 1].max() < 0.95 * height
    assert synthetic.typical_target_camera(FULL_HD)[:4] == pytest.approx([1500, 1500, 960, 540])


@pytest.mark.parametrize("distance", synthetic.DISTANCES)
def test_wiggle_moves_exactly_seven_genes_by_the_table3_offset(distance):
    target = synthetic.typical_target_camera()
    offsets = synthetic.TABLE3_OFFSETS[distance]
    chosen = np.zeros(15, int)
    signs = set()
    for seed in range(200):
        start = synthetic.wiggle_camera(target, distance, seed)
        delta = start - target
        moved = delta != 0
        assert moved.sum() == 7
        assert np.abs(delta[moved]) == pytest.approx(offsets[moved], rel=1e-9)
        chosen += moved
        signs |= set(np.sign(delta[moved]))
    # every gene gets picked, with both signs, about 7/15 of the time
    assert chosen.min() > 0.3 * 200 and chosen.max() < 0.65 * 200
    assert signs == {-1.0, 1.0}
    assert np.array_equal(
        synthetic.wiggle_camera(target, distance, 5), synthetic.wiggle_camera(target, distance, 5)
    )


def test_table3_rows_follow_the_paper():
    far = synthetic.TABLE3_OFFSETS["far"]
    assert far == pytest.approx(
        [100, 100, 100, 100, 1.0, 2.0, 1.0, 0.2, 0.2, 0.2, 0.5, 0.5, 0.2, 0.1, 3.0]
    )
    near = synthetic.TABLE3_OFFSETS["near"]
    assert near == pytest.approx(
        [10, 10, 10, 10, 0.1, 0.1, 0.1, 0.01, 0.01, 0.01, 0.1, 0.1, 0.025, 0.01, 0.5]
    )
    with pytest.raises(ValueError, match="unknown distance"):
        synthetic.wiggle_camera(near, "close", 0)


def _edge_image(size=FULL_HD):
    g = synthetic.typical_target_camera(size)
    return synthetic.render_edge_image(g, court.court_model(), size)


def test_noise_types_each_add_their_own_pattern():
    edges = _edge_image()
    spacing = synthetic.noise_line_spacing_px(edges.shape[0])
    added = {}
    for kind in synthetic.NOISE_TYPES:
        noisy = synthetic.add_noise(edges, kind, np.random.default_rng(3))
        assert noisy.dtype == np.uint8 and noisy.shape == edges.shape
        assert np.all(noisy >= edges)  # noise only adds edge pixels
        added[kind] = (noisy > 0) & (edges == 0)
    assert not added["none"].any()
    kinds = [k for k in synthetic.NOISE_TYPES if k != "none"]
    for kind in kinds:
        assert added[kind].sum() > 1000, kind
    for i, a in enumerate(kinds):
        for b in kinds[i + 1 :]:
            assert not np.array_equal(added[a], added[b]), (a, b)

    blank = np.zeros_like(edges)
    salt = synthetic.add_noise(blank, "salt", 1) > 0
    assert salt.sum() == synthetic.SALT_DOTS
    rows = np.flatnonzero((synthetic.add_noise(blank, "horizontal", 1) > 0).all(axis=1))
    assert len(rows) >= edges.shape[0] // spacing and set(np.diff(rows)) == {spacing}
    assert (synthetic.add_noise(blank, "horizontal", 1) > 0).any(axis=1).sum() == len(rows)
    cols = np.flatnonzero((synthetic.add_noise(blank, "vertical", 1) > 0).all(axis=0))
    assert set(np.diff(cols)) == {spacing}
    grid = synthetic.add_noise(blank, "grid", 1) > 0
    assert grid.all(axis=1).any() and grid.all(axis=0).any()
    diag = synthetic.add_noise(blank, "grid45", 1) > 0
    r, c = np.nonzero(diag)
    assert not diag.all(axis=1).any() and not diag.all(axis=0).any()
    # every pixel lies on one of two families of 45-degree lines
    step = round(spacing * np.sqrt(2))
    on_sum = (r + c) % step == np.bincount((r + c) % step).argmax()
    on_diff = (r - c) % step == np.bincount((r - c) % step).argmax()
    assert np.all(on_sum | on_diff) and on_sum.any() and on_diff.any()


def test_noise_layout_scales_with_the_image():
    counts = []
    for size in [(1920, 1080), (960, 540)]:
        blank = np.zeros((size[1], size[0]), np.uint8)
        lines = synthetic.add_noise(blank, "horizontal", 0) > 0
        counts.append(lines.all(axis=1).sum())
        assert (synthetic.add_noise(blank, "salt", 0) > 0).sum() == synthetic.SALT_DOTS
    assert abs(counts[0] - counts[1]) <= 1
    with pytest.raises(ValueError, match="unknown noise"):
        synthetic.add_noise(blank, "speckle", 0)


def test_metrics_are_zero_for_the_same_camera_and_measure_a_known_shift():
    model = court.court_model()
    target = synthetic.typical_target_camera()
    errors = synthetic.protocol_errors(target, target, model)
    assert set(errors) == {"G_c", "G_b", "G_p"}
    assert all(v == 0.0 for v in errors.values())

    shifted = target.copy()
    shifted[2] += 3.0
    shifted[3] -= 4.0  # the principal point moves every pixel by (3, -4): 5 px
    assert all(
        v == pytest.approx(5.0) for v in synthetic.protocol_errors(target, shifted, model).values()
    )
    grid = court.floor_grid("wsf", 16, 16)
    assert len(grid) == 256
    assert synthetic.mean_reprojection_error(target, shifted, grid) == pytest.approx(5.0)

    behind = target.copy()
    behind[6] = -3.0  # the court origin is now behind the camera
    assert synthetic.mean_reprojection_error(target, behind, grid) == np.inf
    assert synthetic.mean_reprojection_error(behind, target, grid) == np.inf


def _is_red(bgr: np.ndarray) -> np.ndarray:
    b, g, r = (bgr[..., k].astype(int) for k in range(3))
    return (r > 130) & (r > g + 70) & (r > b + 70)


def _pixels_at(image: np.ndarray, px: np.ndarray) -> np.ndarray:
    idx = np.round(px).astype(int)
    return image[idx[:, 1], idx[:, 0]]


def test_rendered_court_has_red_lines_at_the_projected_line_centres():
    g = synthetic.typical_target_camera(FULL_HD)
    image = synthetic.render_court_image(g, FULL_HD, rng=0)
    assert image.shape == (1080, 1920, 3) and image.dtype == np.uint8
    model = court.court_model()
    for name, (a, b) in zip(model.edge_names, model.edges, strict=True):
        if name not in synthetic.PAINTED_EDGES:
            continue
        along = np.linspace(0.1, 0.9, 9)[:, None]
        points = model.nodes[a] + along * (model.nodes[b] - model.nodes[a])
        px = camera.project_visible(g, points)
        assert _is_red(_pixels_at(image, px)).all(), name

    # plain wood a few line widths beside the floor lines: not red, light and warm
    t = model.node("T")
    beside = np.array([[t[0] + 0.25, t[1] + 0.4], [t[0] - 0.3, t[1] - 0.25], [1.0, 8.0]])
    wood = _pixels_at(image, camera.floor_to_pixel(g, beside)).astype(int)
    assert not _is_red(wood).any()
    assert np.all((wood[:, 2] > wood[:, 1]) & (wood[:, 1] > wood[:, 0]) & (wood[:, 2] > 150))
    # plaster on the front wall between the service and out lines is light and neutral
    wall = _pixels_at(image, camera.project_visible(g, np.array([[3.2, 0.0, -3.0]]))).astype(int)
    assert wall.min() > 180 and wall.max() - wall.min() < 25
    # the same seed gives the same image
    assert np.array_equal(image, synthetic.render_court_image(g, FULL_HD, rng=0))


def test_rendered_court_edges_follow_the_model():
    # Canny on the render finds the court: the model's projected lines lie on or next to edges
    size = (960, 540)
    g = synthetic.typical_target_camera(size)
    grey = cv2.cvtColor(synthetic.render_court_image(g, size, rng=1), cv2.COLOR_BGR2GRAY)
    edges = cv2.Canny(grey, 40, 120)
    distance = cv2.distanceTransform((edges == 0).astype(np.uint8), cv2.DIST_L2, 3)
    samples = court.sample_edges(court.court_model(), 0.1).points
    px = camera.project_visible(g, samples)
    near = distance[np.round(px[:, 1]).astype(int), np.round(px[:, 0]).astype(int)]
    assert np.median(near) < 2.0


def _player_boxes(g, positions):
    boxes = []
    for xy in positions:
        foot = camera.floor_to_pixel(g, xy)[0]
        head = camera.floor_to_pixel(g, xy, plane_z_m=-synthetic.PLAYER_HEIGHT_M)[0]
        height = np.hypot(*(head - foot))
        lo = np.minimum(foot, head) - 0.5 * height
        hi = np.maximum(foot, head) + 0.5 * height
        boxes.append((lo, hi, foot, head, height))
    return boxes


def test_clip_players_move_cover_lines_and_leave_the_court_unchanged_elsewhere():
    size = (640, 360)
    n_frames = 8
    g = synthetic.typical_target_camera(size)
    rng = np.random.default_rng(7)
    court_image = synthetic.render_court_image(g, size, "wsf", rng)
    paths = synthetic.player_paths(n_frames, 2, rng)
    frames = synthetic.render_clip_frames(g, size, n_frames, np.random.default_rng(7))
    assert len(frames) == n_frames
    red_court = _is_red(court_image)
    covered_red = 0
    centroids = []
    for frame, positions in zip(frames, paths, strict=True):
        assert frame.shape == court_image.shape and frame.dtype == np.uint8
        changed = np.any(frame != court_image, axis=2)
        inside = np.zeros_like(changed)
        for lo, hi, foot, head, height in _player_boxes(g, positions):
            x0, y0 = np.maximum(np.floor(lo).astype(int), 0)
            x1, y1 = np.ceil(hi).astype(int) + 1
            inside[y0:y1, x0:x1] = True
            # the body between feet and head is painted over, and it is person-sized
            mid = np.round(foot + 0.5 * (head - foot)).astype(int)
            assert changed[mid[1], mid[0]]
            column = changed[:, mid[0]]
            rows = np.flatnonzero(column[max(0, int(head[1]) - 5) : int(foot[1]) + 5])
            assert len(rows) > 0.8 * height
        assert changed.any() and not (changed & ~inside).any()
        covered_red += (red_court & changed).sum()
        ys, xs = np.nonzero(changed)
        centroids.append((xs.mean(), ys.mean()))
    assert covered_red > 0  # players hide painted lines in some frames
    steps = np.linalg.norm(np.diff(np.array(centroids), axis=0), axis=1)
    assert np.all(steps > 1.0)
    # every floor pixel is free in most frames, so a temporal median recovers the court
    median = np.median(np.stack(frames), axis=0)
    assert np.mean(np.abs(median - court_image)) < 1.0


def test_player_paths_are_smooth_loops_over_the_floor_lines():
    paths = synthetic.player_paths(100, 2, np.random.default_rng(1))
    assert paths.shape == (100, 2, 2)
    steps = np.linalg.norm(np.diff(paths, axis=0), axis=2)
    assert steps.max() < 0.4 and steps.min() > 0.0
    # each loop closes: the last frame is one step away from the first
    assert np.linalg.norm(paths[-1] - paths[0], axis=1).max() < 0.4
    # the players pass over the short line and the half-court line
    t = court.court_model().node("T")
    for p in range(2):
        assert np.ptp(np.sign(paths[:, p, 1] - t[1])) == 2
        assert np.ptp(np.sign(paths[:, p, 0] - t[0])) == 2


def test_video_round_trip(tmp_path):
    size = (320, 240)
    g = synthetic.typical_target_camera(size)
    frames = synthetic.render_clip_frames(g, size, 6, 3)
    path = tmp_path / "clip.mp4"
    synthetic.write_video(frames, path, fps=25)
    capture = cv2.VideoCapture(str(path))
    assert capture.isOpened()
    assert capture.get(cv2.CAP_PROP_FPS) == pytest.approx(25.0)
    read = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        read.append(frame)
    capture.release()
    assert len(read) == len(frames)
    for a, b in zip(frames, read, strict=True):
        assert b.shape == a.shape
        assert np.mean(np.abs(a.astype(int) - b.astype(int))) < 6.0
    with pytest.raises(ValueError):
        synthetic.write_video([], tmp_path / "empty.mp4")
