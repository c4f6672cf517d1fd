"""The realistic court renderer (scene.py): images, clips, video files."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from app.calib import camera, cases, court, scene, scene_styles, synthetic

FULL_HD = (1920, 1080)


def _is_red(bgr: np.ndarray) -> np.ndarray:
    b, g, r = (bgr[..., k].astype(int) for k in range(3))
    return (r > 130) & (r > g + 70) & (r > b + 70)


def _pixels_at(image: np.ndarray, px: np.ndarray) -> np.ndarray:
    idx = np.round(px).astype(int)
    return image[idx[:, 1], idx[:, 0]]


def test_rendered_court_has_red_lines_at_the_projected_line_centres():
    g = synthetic.typical_target_camera(FULL_HD)
    image = scene.render_court_image(g, FULL_HD, rng=0)
    assert image.shape == (1080, 1920, 3) and image.dtype == np.uint8
    model = court.court_model()
    for name, (a, b) in zip(model.edge_names, model.edges, strict=True):
        if name not in court.PAINTED_EDGES:
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
    assert np.array_equal(image, scene.render_court_image(g, FULL_HD, rng=0))


def test_rendered_court_edges_follow_the_model():
    # Canny on the render finds the court: the model's projected lines lie on or next to edges
    size = (960, 540)
    g = synthetic.typical_target_camera(size)
    grey = cv2.cvtColor(scene.render_court_image(g, size, rng=1), cv2.COLOR_BGR2GRAY)
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
        head = camera.floor_to_pixel(g, xy, plane_z_m=-scene.PLAYER_HEIGHT_M)[0]
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
    court_image = scene.render_court_image(g, size, "wsf", rng)
    paths = scene.player_paths(n_frames, 2, rng)
    frames = scene.render_clip_frames(g, size, n_frames, np.random.default_rng(7))
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
    paths = scene.player_paths(100, 2, np.random.default_rng(1))
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
    frames = scene.render_clip_frames(g, size, 6, 3)
    path = tmp_path / "clip.mp4"
    scene.write_video(frames, path, fps=25)
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
        scene.write_video([], tmp_path / "empty.mp4")


# ----------------------------------------------------------------------------------------------
# The domain-randomised scenes


def _clean(style: scene.SceneStyle) -> scene.SceneStyle:
    """The same scene without players, graphics or the video chain: pixels are the ray caster's."""
    return replace(
        style,
        players=(),
        overlays=(),
        noise_sigma=0.0,
        jpeg_quality=0,
        blur_px=0.0,
        vignetting=0.0,
        exposure=1.0,
        white_balance=(1.0, 1.0, 1.0),
        gamma=1.0,
        saturation=1.0,
        contrast=1.0,
        horizontal_softness=1.0,
        sharpen=0.0,
        bloom=0.0,
    )


FLOOR_LINE_EDGES = (
    "half_court",
    "box_left_side",
    "box_right_side",
    "box_left_back",
    "box_right_back",
    "short_left_inner",
    "short_right_inner",
)


def _line_offsets(image: np.ndarray, genome: np.ndarray, colour, spec: str = "wsf") -> list[float]:
    """Sub-pixel offset of the painted line from each projected model line centre, at seven points
    per floor line: the centroid, across the line, of how far each pixel has moved from the local
    floor colour towards the line colour (linear in the paint's coverage of the pixel)."""
    img = image.astype(np.float32)
    line = np.array(colour, np.float32)
    model = court.court_model(spec)
    height, width = image.shape[:2]
    offsets = []
    for name in FLOOR_LINE_EDGES:
        ia, ib = model.edges[model.edge_names.index(name)]
        a, b = model.nodes[ia], model.nodes[ib]
        for t in np.linspace(0.2, 0.8, 7):
            p0, p1 = a + t * (b - a), a + (t + 0.01) * (b - a)
            px = camera.project_visible(genome, np.array([p0, p1]))
            inside = 8 < px[0, 0] < width - 8 and 8 < px[0, 1] < height - 8
            if not np.all(np.isfinite(px)) or not inside:
                continue
            d = (px[1] - px[0]) / np.linalg.norm(px[1] - px[0])
            n = np.array([-d[1], d[0]])
            s = np.linspace(-5.0, 5.0, 101)
            pts = (px[0][None, :] + s[:, None] * n[None, :]).astype(np.float32)
            profile = cv2.remap(img, pts[None, :, 0], pts[None, :, 1], cv2.INTER_LINEAR)[0]
            floor = np.median(profile, axis=0)
            towards = line - floor
            w = np.clip(
                (profile - floor) @ towards / max(float(towards @ towards), 1e-6), 0.0, None
            )
            if w.sum() > 0:
                offsets.append(float((w * s).sum() / w.sum()))
    return offsets


@pytest.mark.parametrize(("preset", "seed"), [("club", 1), ("glass", 2), ("glass", 5)])
def test_painted_lines_are_centred_on_the_model_lines(preset, seed):
    size = (800, 450)
    g = synthetic.typical_target_camera(size)
    style = _clean(scene_styles.sample_style(seed, preset))
    style = replace(style, line_alpha=1.0, line_wear=0.0, line_glow=0.0)
    image = scene.render_scene(g, size, "wsf", style, seed)
    colour = style.line_colours[0]
    offsets = _line_offsets(image, g, colour)
    assert len(offsets) >= 28
    # on the line centre the pixels have the line's colour, a line width beside they do not
    assert np.median(np.abs(offsets)) < 0.1 and np.percentile(np.abs(offsets), 90) < 0.35
    model = court.court_model()
    ia, ib = model.edges[model.edge_names.index("half_court")]
    along = model.nodes[ia] + np.linspace(0.1, 0.9, 9)[:, None] * (
        model.nodes[ib] - model.nodes[ia]
    )
    on = _pixels_at(image, camera.project_visible(g, along)).astype(float)
    beside = _pixels_at(image, camera.project_visible(g, along + [0.2, 0.0, 0.0])).astype(float)
    assert np.linalg.norm(on - colour, axis=1).max() < np.linalg.norm(beside - colour, axis=1).min()


def test_a_shifted_camera_misses_the_lines():
    # the measure above can fail: half a line width of camera error shows up as an offset
    size = (800, 450)
    g = synthetic.typical_target_camera(size)
    style = replace(_clean(scene_styles.sample_style(1, "club")), line_wear=0.0, line_alpha=1.0)
    image = scene.render_scene(g, size, "wsf", style, 1)
    moved = g.copy()
    moved[camera.GENE["c_u"]] += 1.5
    moved[camera.GENE["c_v"]] += 1.5
    assert np.median(np.abs(_line_offsets(image, moved, style.line_colours[0]))) > 0.5


def _mirror_probe(reflect: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A glass court seen from behind; pixels of the short line's mirror image beyond the left
    glass wall, and of mirrored plain floor next to it."""
    size = (640, 360)
    g = synthetic.typical_target_camera(size)
    style = _clean(scene_styles.sample_style(3, "glass"))
    style = replace(
        style,
        floor=scene.Material("flat", (60, 60, 60), 1.0, (0.0, 0.0, 0.0, 0.0)),
        floor_gloss=0.0,
        line_colours=((240, 240, 240),) * 4,
        line_glow=0.0,
        line_wear=0.0,
        stands=(False, False),
        adverts=(),
        glass_reflect_side=reflect,
        side_joint_spacing_m=0.0,
    )
    image = scene.render_scene(g, size, "wsf", style, 0).astype(float)
    short_y = court.court_model().node("short_left")[1]
    mirrored_line = np.array([[-x, short_y, 0.0] for x in (0.4, 0.6, 0.8)])
    mirrored_floor = mirrored_line + [0.0, 0.5, 0.0]
    return (
        image,
        _pixels_at(image, camera.project_visible(g, mirrored_line)),
        _pixels_at(image, camera.project_visible(g, mirrored_floor)),
    )


def test_glass_side_walls_mirror_the_floor_lines():
    image_on, line_on, floor_on = _mirror_probe(0.08)
    image_off, line_off, floor_off = _mirror_probe(0.0)
    # with reflections the short line seems to continue beyond the side wall: brighter there
    # than the mirrored plain floor beside it; without them both look the same
    assert (line_on.mean(axis=1) - floor_on.mean(axis=1)).min() > 15
    assert np.abs(line_off.mean(axis=1) - floor_off.mean(axis=1)).max() < 5
    assert (line_on.mean(axis=1) - line_off.mean(axis=1)).min() > 10


def test_overlays_land_where_requested():
    size = (640, 360)
    g = synthetic.typical_target_camera(size)
    base = _clean(scene_styles.sample_style(4, "club"))
    box = scene.Overlay("box", (0.1, 0.7, 0.4, 0.8), "", ((20, 200, 250),), 1.0, 0)
    bar = scene.Overlay("score_bar", (0.5, 0.05, 0.95, 0.12), "A. SMITH|B. JONES", seed=3)
    plain = scene.render_scene(g, size, "wsf", base, 0)
    drawn = scene.render_scene(g, size, "wsf", replace(base, overlays=(box, bar)), 0)
    changed = np.any(drawn != plain, axis=2)
    inside = np.zeros(changed.shape, bool)
    inside[252:288, 64:256] = True  # the box: rows 0.7-0.8 of 360, columns 0.1-0.4 of 640
    inside[18:43, 320:608] = True  # the score bar
    assert not (changed & ~inside).any()
    assert np.all(drawn[255:285, 70:250] == (20, 200, 250))
    assert changed[18:43, 320:608].mean() > 0.5
    letterbox = scene.Overlay("letterbox", (0.0, 0.1, 1.0, 0.9))
    boxed = scene.render_scene(g, size, "wsf", replace(base, overlays=(letterbox,)), 0)
    assert boxed[:36].max() == 0 and boxed[324:].max() == 0
    assert np.array_equal(boxed[36:324], plain[36:324])


def test_players_stand_behind_a_railing():
    size = (640, 360)
    g = synthetic.typical_target_camera(size)
    style = _clean(scene_styles.sample_style(2, "club"))
    # a railing of thick posts between the camera and the court, its top at 1.2 m
    style = replace(
        style,
        railing=True,
        railing_y=10.75,
        railing_height_m=1.2,
        railing_mid_bars=0,
        railing_post_spacing_m=0.6,
        railing_bar_m=0.08,
        railing_colour=(0, 0, 255),
    )
    person = scene.Person(3.2, 5.0, (255, 0, 0), (255, 0, 0), (255, 0, 0), arm=0.0)
    empty = scene.render_scene(g, size, "wsf", style, 0)
    with_player = scene.render_scene(g, size, "wsf", replace(style, players=(person,)), 0)
    changed = np.any(empty != with_player, axis=2)
    railing = (empty[:, :, 2] > 200) & (empty[:, :, 0] < 40) & (empty[:, :, 1] < 40)
    assert changed.sum() > 200 and railing.sum() > 200
    assert not (changed & cv2.erode(railing.astype(np.uint8), np.ones((3, 3))).astype(bool)).any()


def test_scenes_render_deterministically():
    size = (320, 180)
    g = synthetic.typical_target_camera(size)
    style = scene_styles.sample_style(7, "glass")
    a = scene.render_scene(g, size, "wsf", style, 5)
    assert np.array_equal(a, scene.render_scene(g, size, "wsf", style, 5))
    assert not np.array_equal(a, scene.render_scene(g, size, "wsf", style, 6))
    assert scene_styles.sample_style(7, "glass") == style
    assert scene_styles.sample_style(8, "glass") != style


def _strong_barrel_camera(size: tuple[int, int]) -> np.ndarray:
    """A wide-angle club camera (f 620 px, k1 -0.14, k2 0.01 at 1920 x 1080) behind the back
    wall: its lens compresses the side walls almost to a fold (dr_d/dr 0.07 at r 2.1)."""
    scale = size[0] / 1920
    rotation, _ = cv2.Rodrigues(np.array([-0.8384, 0.0022, 0.0533]))
    return cases.make_genome(
        -rotation.T @ np.array([-2.772, -3.222, 11.222]),
        rotation,
        620.0 * scale,
        620.0 * scale,
        ((size[0] - 1) / 2, (size[1] - 1) / 2),
        (-0.1438, 0.01, -0.0003, 0.0026, 0.0),
    )


@pytest.mark.parametrize("size", [(960, 540), (1920, 1080)])
def test_the_ray_grid_follows_a_strong_barrel_lens_where_it_compresses_most(size):
    g = _strong_barrel_camera(size)
    coarse = scene.RAY_GRID_STEPS_PX[0]
    # bilinear rays on the coarse grid stray off the lens model where the lens compresses
    assert scene.ray_grid_error_px(g, size, coarse, scene.ray_grid(g, size, coarse)) > 0.5
    ray_x, ray_y, ray_ok, step_px, _, _ = scene.camera_rays(g, size)
    assert step_px < coarse
    error_px = scene.ray_grid_error_px(g, size, step_px, (ray_x, ray_y, ray_ok))
    assert error_px <= scene.RAY_GRID_MAX_ERROR_PX


def test_a_mild_lens_keeps_the_coarse_ray_grid():
    size = (1280, 720)
    g = synthetic.typical_target_camera(size)
    assert scene.camera_rays(g, size)[3] == scene.RAY_GRID_STEPS_PX[0]
