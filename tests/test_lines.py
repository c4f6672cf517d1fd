"""Line evidence (lines.py) and the evidence off the court under a known camera (surfaces.py)."""

from dataclasses import replace

import numpy as np
import pytest

from app.calib import camera, court, lines, render, scene, scene_styles, surfaces, synthetic

SIZE = (800, 450)
PAINTED_FLOOR = ("half_court", "box_left_side", "box_right_back", "short_left_inner")


def _clean_style(seed: int, preset: str) -> scene.SceneStyle:
    """A scene without players, graphics or camera effects: what is evidence is the court."""
    style = scene_styles.sample_style(seed, preset)
    return replace(
        style,
        players=(),
        overlays=(),
        adverts=(),
        noise_sigma=0.5,
        jpeg_quality=0,
        blur_px=0.0,
        vignetting=0.0,
        line_wear=0.0,
        line_alpha=1.0,
        line_glow=0.0,
        glass_reflect_side=0.0,
        stands=(False, False),
    )


def _line_pixels(genome: np.ndarray, edge: str, n: int = 40) -> np.ndarray:
    model = court.court_model()
    a, b = model.nodes[model.edges[model.edge_names.index(edge)]]
    t = np.linspace(0.15, 0.85, n)[:, None]
    return camera.project_visible(genome, a + t * (b - a))


def _distance_to_evidence(maps: lines.EvidenceMaps, pixels: np.ndarray, ridge: bool) -> np.ndarray:
    """Distance (px) from each pixel to the sub-pixel line through the nearest evidence."""
    near = maps.near_ridge if ridge else maps.near_any
    out = []
    for u, v in pixels:
        k = near[int(round(v)), int(round(u))]
        if k < 0:
            out.append(np.inf)
            continue
        out.append(abs(maps.normals[k] @ (np.array([u, v]) - maps.points[k])))
    return np.array(out)


@pytest.fixture(scope="module")
def club() -> tuple[np.ndarray, np.ndarray]:
    genome = synthetic.typical_target_camera(SIZE)
    return genome, scene.render_scene(genome, SIZE, "wsf", _clean_style(1, "club"), 1)


def test_ridges_sit_on_the_painted_line_centres(club):
    genome, image = club
    evidence = lines.line_evidence(image)
    maps = lines.evidence_maps(evidence)
    for edge in PAINTED_FLOOR:
        d = _distance_to_evidence(maps, _line_pixels(genome, edge), ridge=True)
        # every sample finds its line, to a fraction of a pixel (sub-pixel centres), except near
        # the crossings with other lines, where the nearest ridge may be the other line's
        assert np.mean(d < 1.0) > 0.85, (edge, d)
        assert np.median(d) < 0.3, (edge, d)
    # and a line 0.3 m away from the real one finds nothing of its own
    moved = genome.copy()
    moved[camera.GENE["t_x"]] += 0.3
    d = _distance_to_evidence(maps, _line_pixels(moved, "half_court"), ridge=True)
    assert np.median(d) > 3.0


def test_wall_floor_junctions_are_step_evidence(club):
    genome, image = club
    evidence = lines.line_evidence(image)
    maps = lines.evidence_maps(evidence)
    d = _distance_to_evidence(maps, _line_pixels(genome, "left_floor_box"), ridge=False)
    assert np.mean(d < 1.5) > 0.7
    pixels = np.round(_line_pixels(genome, "left_floor_box")).astype(int)
    nearest = maps.near_any[pixels[:, 1], pixels[:, 0]]
    # a brightness step, not a painted band
    assert np.mean(~maps.is_ridge[nearest[nearest >= 0]]) > 0.5


def test_a_score_graphic_leaves_no_line_evidence():
    genome = synthetic.typical_target_camera(SIZE)
    bar = scene.Overlay("score_bar", (0.25, 0.82, 0.75, 0.92), "N. GOHAR 11|P. SOBHY 9", seed=2)
    style = replace(_clean_style(4, "club"), overlays=(bar,))
    evidence = lines.line_evidence(scene.render_scene(genome, SIZE, "wsf", style, 4))
    rows = slice(int(0.82 * SIZE[1]) + 3, int(0.92 * SIZE[1]) - 3)
    cols = slice(int(0.25 * SIZE[0]) + 3, int(0.75 * SIZE[0]) - 3)
    text_area = evidence.mask()[rows, cols]
    # letters are dense and point every way: clutter, not lines
    assert text_area.mean() < 0.01


def test_a_mirrored_line_is_set_aside_once_the_camera_is_known():
    genome = synthetic.typical_target_camera(SIZE)
    style = replace(
        _clean_style(3, "glass"),
        floor=scene.Material("flat", (60, 60, 60), 1.0, (0.0, 0.0, 0.0, 0.0)),
        line_colours=((240, 240, 240),) * 4,
        glass_reflect_side=0.1,
        side_glass=True,
        side_joint_spacing_m=0.0,
    )
    image = scene.render_scene(genome, SIZE, "wsf", style, 3)
    evidence = lines.line_evidence(image)
    model = court.court_model()
    short_y = model.node("short_left")[1]
    mirrored = camera.project_visible(
        genome, np.array([[-x, short_y, 0.0] for x in (0.5, 0.8, 1.1)])
    )
    real = camera.project_visible(genome, np.array([[x, short_y, 0.0] for x in (0.5, 0.8, 1.1)]))
    at = lambda mask, px: mask[tuple(np.round(px[:, ::-1]).astype(int).T)]  # noqa: E731
    near_mirror = at(_dilated(evidence.mask(lines.RIDGE)), mirrored)
    assert near_mirror.all()  # the reflection looks like a painted line
    on_court = surfaces.evidence_on_court(evidence, genome, model, 2.0)
    assert not at(_dilated(on_court.mask(lines.RIDGE)), mirrored).any()
    assert at(_dilated(on_court.mask(lines.RIDGE)), real).all()


def _dilated(mask: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0


def test_surface_labels_follow_the_court(club):
    genome, _ = club
    labels = surfaces.surface_labels(genome, SIZE, court.court_model())
    t = camera.floor_to_pixel(genome, np.array([[3.2, 5.465]]))[0]
    service = camera.project_visible(genome, np.array([[3.2, 0.0, -1.8]]))[0]
    left_wall = camera.project_visible(genome, np.array([[0.0, 4.0, -1.0]]))[0]
    at = lambda px: labels[int(round(px[1])), int(round(px[0]))]  # noqa: E731
    assert at(t) == surfaces.FLOOR
    assert at(service) == surfaces.FRONT
    assert at(left_wall) == surfaces.LEFT
    assert labels[0, 0] == surfaces.NONE  # the hall above the walls


def test_ignored_pixels_stay_ignored(club):
    _, image = club
    ignore = np.zeros(image.shape[:2], bool)
    ignore[100:200, 200:400] = True
    evidence = lines.line_evidence(image, ignore)
    assert evidence.ignore[100:200, 200:400].all()
    assert not evidence.mask()[100:200, 200:400].any()
    with pytest.raises(ValueError, match="shape"):
        lines.line_evidence(image, ignore[:10])


def test_drawn_line_images_are_ridges_and_canny_edges_are_steps():
    genome = synthetic.typical_target_camera(SIZE)
    drawn = render.rasterize_court(genome, court.court_model(), SIZE)
    as_lines = lines.edge_image_evidence(drawn, as_ridges=True)
    assert np.array_equal(as_lines.kind == lines.RIDGE, drawn > 0)
    as_edges = lines.edge_image_evidence(drawn)
    assert np.array_equal(as_edges.kind == lines.STEP, drawn > 0)
    # the normal of a horizontal drawn line points down the image
    row = int(round(camera.floor_to_pixel(genome, np.array([[3.2, 5.465]]))[0, 1]))
    on_line = as_lines.kind[row] == lines.RIDGE
    angles = as_lines.normal_rad[row][on_line]
    assert np.median(np.abs(np.abs(angles) - np.pi / 2)) < np.deg2rad(10)
