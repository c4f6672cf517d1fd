import cv2
import numpy as np
import pytest

from app.calib import camera, court


def random_cameras(rng: np.random.Generator, n: int, base: np.ndarray) -> np.ndarray:
    pop = np.repeat(base[None, :], n, axis=0)
    pop[:, 0:2] += rng.uniform(-300, 300, (n, 2))
    pop[:, 2:4] += rng.uniform(-60, 60, (n, 2))
    pop[:, 4:7] += rng.uniform(-1.0, 1.0, (n, 3))
    pop[:, 7:10] += rng.uniform(-0.1, 0.1, (n, 3))
    pop[:, 10:15] = rng.uniform(
        [-0.3, -0.1, -0.01, -0.01, -0.2], [0.1, 0.1, 0.01, 0.01, 0.2], (n, 5)
    )
    return pop


def test_projection_matches_opencv_to_a_micro_pixel(target_genome):
    rng = np.random.default_rng(1)
    model = court.court_model()
    points = court.sample_edges(model, 0.25).points
    pop = random_cameras(rng, 20, target_genome)
    pixels, depth = camera.project_points(pop, points)
    assert pixels.shape == (20, len(points), 2)
    for g, px, d in zip(pop, pixels, depth, strict=True):
        cv = camera.to_opencv(g, (1920, 1080))
        ref, _ = cv2.projectPoints(
            points,
            np.array(cv["rvec"]),
            np.array(cv["tvec"]),
            np.array(cv["K"]),
            np.array(cv["dist"]),
        )
        front = d > 0
        assert np.abs(ref[:, 0][front] - px[front]).max() < 1e-6


def test_rotation_order_is_rz_ry_rx_in_the_paper_frame(target_genome):
    a, b, c = 0.3, -0.2, 0.1
    rx = cv2.Rodrigues(np.array([a, 0.0, 0.0]))[0]
    ry = cv2.Rodrigues(np.array([0.0, b, 0.0]))[0]
    rz = cv2.Rodrigues(np.array([0.0, 0.0, c]))[0]
    g = target_genome.copy()
    g[7:10] = a, b, c
    r, t = camera.court_extrinsics(g)
    assert r[0] == pytest.approx(rz @ ry @ rx @ camera.PAPER_FROM_COURT_R, abs=1e-15)
    assert t[0] == pytest.approx(g[4:7] - r[0] @ camera.PAPER_ORIGIN_COURT_M, abs=1e-14)
    assert camera.angles_from_rotation(rz @ ry @ rx) == pytest.approx((a, b, c))


def test_opencv_round_trip(target_genome):
    rng = np.random.default_rng(2)
    for g in random_cameras(rng, 10, target_genome):
        back = camera.from_opencv(camera.to_opencv(g))
        assert back == pytest.approx(g, abs=1e-9)
    genome, size = camera.camera_from_json(camera.to_opencv(target_genome, (1920, 1080)))
    assert size == (1920, 1080) and genome == pytest.approx(target_genome)
    genome, size = camera.camera_from_json(list(target_genome))
    assert size is None and genome == pytest.approx(target_genome)


def test_paper_frame_camera_looks_at_the_front_wall(target_genome):
    # the typical camera sees the T near the image centre column and below the front wall lines
    model = court.court_model()
    px = camera.project_visible(target_genome, model.nodes)
    names = model.node_names
    t = px[names.index("T")]
    assert abs(t[0] - 960) < 5
    assert px[names.index("service_left")][1] < t[1]
    assert px[names.index("floor_back_left")][1] > t[1]


def test_pixel_floor_round_trip(target_genome):
    rng = np.random.default_rng(3)
    floor = rng.uniform([0, 0], [6.4, 9.75], (500, 2))
    for g in random_cameras(rng, 5, target_genome):
        px = camera.floor_to_pixel(g, floor)
        back, status = camera.pixel_to_floor(g, px)
        ok = status == camera.RAY_OK
        assert ok.mean() > 0.95
        assert np.abs(back[ok] - floor[ok]).max() < 1e-6


def test_rays_above_the_horizon_miss_the_floor(target_genome):
    # the top image row looks above the horizon of a camera tilted by 0.3 rad? use a level camera
    level = target_genome.copy()
    level[7] = 0.0
    level[10:15] = 0.0
    pts, status = camera.pixel_to_floor(level, np.array([[960.0, 100.0], [960.0, 1000.0]]))
    assert status.tolist() == [camera.RAY_MISSES_FLOOR, camera.RAY_OK]
    assert np.isnan(pts[0]).all() and np.isfinite(pts[1]).all()


def test_behind_camera_points_are_flagged(target_genome):
    behind = np.array([[3.2, 30.0, 0.0]])  # far behind the camera, which sits behind the back wall
    assert np.isnan(camera.project_visible(target_genome, behind)).all()


def test_undistort_refuses_the_folded_part_of_the_lens_model(target_genome):
    g = target_genome.copy()
    g[10:15] = [-0.6, 0.0, 0.0, 0.0, 0.0]  # r_d(r) = r - 0.6 r^3 peaks at r = 0.745, r_d = 0.497
    far_out = np.array([[g[2] + 0.6 * g[0], g[3]]])  # r_d = 0.6 has no preimage
    _, status = camera.pixel_to_floor(g, far_out)
    assert status[0] == camera.RAY_UNDISTORT_FAILED


def test_camera_json_errors_are_clear():
    with pytest.raises(ValueError, match="shape"):
        camera.camera_from_json([1.0, 2.0])
    with pytest.raises(ValueError, match="missing 'tvec'"):
        camera.camera_from_json(
            {"K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "dist": [0] * 5, "rvec": [0] * 3}
        )
    with pytest.raises(ValueError, match="finite"):
        camera.camera_from_json([float("nan")] * 15)
    with pytest.raises(ValueError, match="skew"):
        camera.from_opencv(
            {
                "K": [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]],
                "dist": [0] * 5,
                "rvec": [0] * 3,
                "tvec": [0] * 3,
            }
        )


def _pixel_to_floor_reference(g: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vectorised numpy formulation (undistort, rotate the rays, meet z = 0) that the fused
    kernel replaced: an independent check of it."""
    xd = (pixels[:, 0] - g[2]) / g[0]
    yd = (pixels[:, 1] - g[3]) / g[1]
    x, y, ok = camera.undistort_normalized(xd, yd, g[camera.DISTORTION_GENES])
    r, t = camera.court_extrinsics(g)
    centre = -r[0].T @ t[0]
    rays = np.stack([x, y, np.ones_like(x)], axis=1) @ r[0]
    with np.errstate(all="ignore"):
        s = -centre[2] / rays[:, 2]
    hits = centre[None, :2] + s[:, None] * rays[:, :2]
    status = np.where(
        ~ok,
        camera.RAY_UNDISTORT_FAILED,
        np.where(np.isfinite(s) & (s > 0), camera.RAY_OK, camera.RAY_MISSES_FLOOR),
    )
    hits[status != camera.RAY_OK] = np.nan
    return hits, status


def test_prepared_camera_matches_the_numpy_formulation(target_genome):
    rng = np.random.default_rng(11)
    # pixels inside and far outside the picture: every status occurs
    pixels = rng.uniform([-3000, -3000], [5000, 4000], (2000, 2))
    seen: set[int] = set()
    for g in random_cameras(rng, 8, target_genome):
        prepared = camera.PreparedCamera(g)
        got, status = prepared.pixel_to_floor(pixels)
        want, want_status = _pixel_to_floor_reference(g, pixels)
        np.testing.assert_array_equal(status, want_status)
        ok = status == camera.RAY_OK
        np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9, atol=1e-9)
        assert np.isnan(got[~ok]).all()
        seen |= set(status.tolist())
        # the module function is the same mapping
        again, again_status = camera.pixel_to_floor(g, pixels)
        np.testing.assert_array_equal(again_status, status)
        np.testing.assert_array_equal(again[ok], got[ok])
    assert seen == {camera.RAY_OK, camera.RAY_UNDISTORT_FAILED, camera.RAY_MISSES_FLOOR}


def test_prepared_camera_is_immutable_and_empty_input_is_fine(target_genome):
    g = target_genome.copy()
    prepared = camera.PreparedCamera(g)
    g[0] += 100.0  # the caller's array is not shared
    assert prepared.genome[0] == target_genome[0]
    for array in (prepared.genome, prepared.r, prepared.t, prepared.centre):
        assert not array.flags.writeable
    floor, status = prepared.pixel_to_floor(np.empty((0, 2)))
    assert floor.shape == (0, 2) and status.shape == (0,)


def test_the_projection_kernels_release_the_gil():
    # /project (and the per-calibration mappings) run these; without nogil a request's
    # kernel would block every other thread of the API process
    for kernel in (camera._pixels_to_plane_njit, camera._undistort_njit):
        assert kernel.targetoptions.get("nogil") is True, kernel
