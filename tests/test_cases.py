"""The benchmark case generator (cases.py): valid, class-typical, deterministic cases; negatives."""

import hashlib
from dataclasses import replace

import numpy as np
import pytest

from app.calib import camera, cases, scene, scene_styles, synthetic


def _centre(genome: np.ndarray) -> np.ndarray:
    return scene.camera_centre(genome)


@pytest.mark.parametrize("class_name", cases.CASE_CLASSES)
def test_every_class_plans_calibratable_cases(class_name):
    for seed in range(3):
        plan = cases.plan_case(class_name, seed)
        assert np.all(np.isfinite(plan.genome))
        width, height = plan.size
        assert 640 <= width <= 1920 and 360 <= height <= 1440
        assert cases.lens_covers_image(plan.genome, plan.size)
        assert cases.is_calibratable(plan.visible_lines, plan.floor_fraction)
        # recomputing the rule from scratch agrees
        lengths, fraction = cases.court_visibility(plan.genome, plan.size, plan.spec, plan.style)
        assert cases.visible_floor_lines(lengths) == plan.visible_lines
        assert fraction == pytest.approx(plan.floor_fraction)


def test_class_cameras_follow_their_filming_ranges():
    for seed in range(4):
        g = cases.plan_case("tripod_phone", seed).genome
        assert 1.0 <= -_centre(g)[2] <= 1.6
        wide = cases.plan_case("wide_angle", seed).genome
        assert -0.35 <= wide[camera.GENE["k1"]] <= -0.15
        broadcast = cases.plan_case("broadcast_glass", seed)
        c = _centre(broadcast.genome)
        assert 2.5 <= -c[2] <= 8.0 and 2.0 <= c[1] - 9.75 <= 15.0
        assert broadcast.style.side_glass and broadcast.style.back_glass
        r, _ = camera.court_extrinsics(broadcast.genome)
        roll = np.arcsin(r[0][0, 2])  # the image's x axis against the horizontal
        assert abs(roll) < np.radians(2.0)
    odd = 0
    for seed in range(6):
        g = cases.plan_case("anamorphic_cropped", seed).genome
        size = cases.plan_case("anamorphic_cropped", seed).size
        aspect = g[camera.GENE["f_v"]] / g[camera.GENE["f_u"]]
        off_centre = abs(g[camera.GENE["c_u"]] - (size[0] - 1) / 2) > 0.1 * size[0]
        odd += abs(aspect - 1.0) > 0.05 or off_centre
    assert odd == 6


def test_make_case_renders_its_plan_deterministically():
    for class_name, seed in (("club", 0), ("broadcast_glass", 1)):  # small pictures: quick
        case = cases.make_case(class_name, seed)
        plan = cases.plan_case(class_name, seed)
        assert case.image.shape == (case.size[1], case.size[0], 3) and case.image.dtype == np.uint8
        assert np.array_equal(case.genome, plan.genome) and case.size == plan.size
        assert case.style == plan.style and case.spec == plan.spec
        again = cases.make_case(class_name, seed)
        assert np.array_equal(case.image, again.image)
        assert not np.array_equal(case.image, cases.make_case(class_name, seed + 1).image)
    with pytest.raises(ValueError, match="unknown case class"):
        cases.make_case("beach", 0)


def test_some_club_glass_back_walls_carry_no_painted_lines():
    from app.calib import scene_raycast as rc

    plans = [cases.plan_case(name, seed) for name in ("club", "tripod_phone") for seed in range(24)]
    club_glass = [p for p in plans if p.style.preset == "club" and p.style.back_glass]
    bare = [p for p in club_glass if not p.style.back_wall_lines]
    assert 0.2 < len(bare) / len(club_glass) < 0.8
    # broadcast glass courts keep their back wall's lines
    assert all(p.style.back_wall_lines for p in plans if p.style.preset == "glass")

    def back_wall_segments(style: scene.SceneStyle) -> int:
        arrays = scene.build_scene(style, "wsf", np.zeros(3), np.random.default_rng(0), False)
        return int((arrays.segs[:, 6] == rc.S_BACK).sum())

    style = bare[0].style
    assert back_wall_segments(style) == 0
    assert back_wall_segments(replace(style, back_wall_lines=True)) > 0


def test_clips_have_moving_players_and_some_have_a_camera_cut():
    found_cut = False
    for seed in range(6):
        plan = cases.plan_case("clip", seed)
        if plan.filmed_like != "broadcast_glass":
            continue
        clip = cases.make_case("clip", seed)
        assert clip.frames is not None and clip.fps in (25.0, 30.0) and clip.main_shot is not None
        start, stop = clip.main_shot
        assert np.array_equal(clip.image, clip.frames[start])
        assert np.array_equal(clip.genome, plan.genome)
        main = np.stack([f.astype(float) for f in clip.frames[start:stop]])
        moving = np.abs(main - main[0]).max(axis=3) > 60
        assert moving[1:].any(axis=(1, 2)).all()  # the players move between frames
        for k in clip.cut_frames:
            # a cut-away looks nothing like the main shot
            assert not start <= k < stop
            assert np.abs(clip.frames[k].astype(float) - clip.image).mean() > 20
        found_cut = found_cut or bool(clip.cut_frames)
        if found_cut:
            break
    assert found_cut


def test_the_visibility_rule_refuses_views_without_a_court():
    size = (640, 360)
    style = scene_styles.sample_style(0, "club")
    g = synthetic.typical_target_camera(size)
    lengths, fraction = cases.court_visibility(g, size, "wsf", style)
    assert cases.is_calibratable(cases.visible_floor_lines(lengths), fraction)
    # behind a plaster back wall the camera sees nothing of the floor
    walled = replace(style, back_glass=False, back_above_out_m=3.0)
    lengths, fraction = cases.court_visibility(g, size, "wsf", walled)
    assert not cases.visible_floor_lines(lengths)
    # the front wall alone, zoomed in: no floor lines
    centre = _centre(g)
    front = np.array([[0.5, 0.0, -1.0], [5.9, 0.0, -1.0], [0.5, 0.0, -4.0], [5.9, 0.0, -4.0]])
    zoomed = cases.frame_camera(centre, front, size, 1.0, 0.0, (0.0, 0.0, 0.0, 0.0, 0.0))
    lengths, fraction = cases.court_visibility(zoomed, size, "wsf", style)
    assert not cases.is_calibratable(cases.visible_floor_lines(lengths), fraction)
    # a score graphic over the whole picture hides every line
    covered = replace(style, overlays=(scene.Overlay("box", (0.0, 0.0, 1.0, 1.0)),))
    lengths, _ = cases.court_visibility(g, size, "wsf", covered)
    assert not cases.visible_floor_lines(lengths)


def test_negatives_hold_no_squash_court(monkeypatch):
    def no_squash(*args, **kwargs):
        raise AssertionError("a negative painted the squash court's lines")

    monkeypatch.setattr(scene, "painted_segments", no_squash)
    digests = set()
    jobs = [(kind, 0) for kind in cases.NEGATIVE_KINDS] + [("room", 1), ("checkerboard", 1)]
    for kind, seed in jobs:
        negative = cases.make_negative(kind, seed)
        image = negative.image
        assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
        assert image.shape[0] >= 360 and image.std() > 5
        assert negative.style is None or not negative.style.court
        digests.add(hashlib.sha1(image.tobytes()).hexdigest())
    assert len(digests) == len(jobs)
    again = cases.make_negative("room", 1).image
    assert hashlib.sha1(again.tobytes()).hexdigest() in digests
    with pytest.raises(ValueError, match="unknown negative kind"):
        cases.make_negative("squash", 0)


def test_other_sports_layouts_are_not_a_squash_court():
    # no layout holds a 6.4 x 9.75 (or 7.62 x 9.75) rectangle of lines
    for sport in ("badminton", "tennis", "basketball", "volleyball", "futsal"):
        lines, _, (w, length) = cases.sport_layout(sport, 0.0, 0.0, 0)
        assert not (abs(w - 6.4) < 0.3 and abs(length - 9.75) < 0.5)
        assert not (abs(w - 7.62) < 0.3 and abs(length - 9.75) < 0.5)
        assert len(lines) >= 5


def test_a_strong_barrel_lens_gets_the_k2_that_makes_it_physical_to_the_picture_corners():
    size = (1280, 720)
    g = synthetic.typical_target_camera(size)
    g[camera.GENE["f_u"]] = g[camera.GENE["f_v"]] = 0.9 * size[0]
    g[camera.DISTORTION_GENES] = [-0.35, 0.0, 0.0, 0.0, 0.0]
    # the picture's corners are rays at r = 0.79 (38 degrees off axis), well inside the fold
    # (r = 0.98), but there d r_d / d r is 0.35, less than an orthographic lens keeps (0.49)
    assert camera.lens_fold_radius(g) > 0.95
    assert cases.lens_is_physical(g, 0.5)
    assert not cases.lens_is_physical(g, 0.79)
    assert not cases.lens_covers_image(g, size)
    unfolded = cases.unfold_lens(g, size)
    assert unfolded is not None and unfolded[camera.GENE["k2"]] > 0.0
    assert cases.lens_covers_image(unfolded, size)
    weaker = unfolded.copy()
    weaker[camera.GENE["k2"]] -= 0.005
    assert not cases.lens_covers_image(weaker, size)
