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
