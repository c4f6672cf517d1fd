import cv2
import numpy as np
import pytest

from app.calib import edges, render, scene
from app.calib.court import court_model


def test_canny_finds_a_painted_line_on_both_borders():
    image = np.full((120, 200, 3), (170, 190, 215), np.uint8)  # maple-ish floor
    image[58:64, :] = (40, 40, 190)  # a red line 6 px wide
    found = edges.extract_edges(image)
    rows = np.flatnonzero(found[:, 100])
    assert found.dtype == np.uint8 and set(np.unique(found)) <= {0, 255}
    assert len(rows) == 2 and abs(rows[0] - 58) <= 1 and abs(rows[1] - 63) <= 1


def test_thresholds_follow_the_scene_texture():
    rng = np.random.default_rng(3)
    flat = np.full((200, 200), 128, np.uint8)
    textured = np.clip(128 + rng.normal(0, 25, (200, 200)), 0, 255).astype(np.uint8)
    textured = cv2.GaussianBlur(textured, (0, 0), 1.0)
    low_flat, high_flat = edges.canny_thresholds(flat)
    low_tex, high_tex = edges.canny_thresholds(textured)
    assert high_flat == edges.MIN_HIGH_THRESHOLD
    assert high_tex > high_flat
    assert low_tex == pytest.approx(edges.LOW_OVER_HIGH * high_tex)


def test_grey_bgr_and_bgra_give_the_same_edges(target_genome):
    image = scene.render_court_image(target_genome, (480, 270), rng=5)
    bgra = cv2.cvtColor(image, cv2.COLOR_BGR2BGRA)
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    from_bgr = edges.extract_edges(image)
    assert from_bgr.mean() > 0
    assert np.array_equal(from_bgr, edges.extract_edges(bgra))
    assert np.array_equal(from_bgr, edges.extract_edges(grey))


def test_rejects_bad_images():
    with pytest.raises(ValueError, match="uint8"):
        edges.extract_edges(np.zeros((50, 50), np.float32))
    with pytest.raises(ValueError, match="shape"):
        edges.extract_edges(np.zeros((50, 50, 2), np.uint8))
    with pytest.raises(ValueError, match="too small"):
        edges.extract_edges(np.zeros((4, 50), np.uint8))


def test_is_edge_image(target_genome):
    edge_image = render.rasterize_court(target_genome, court_model(), (640, 360))
    assert edges.is_edge_image(edge_image)
    assert edges.is_edge_image(cv2.cvtColor(edge_image, cv2.COLOR_GRAY2BGR))
    # a lossy save keeps it an edge image
    ok, jpeg = cv2.imencode(".jpg", edge_image, [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert ok and edges.is_edge_image(cv2.imdecode(jpeg, cv2.IMREAD_GRAYSCALE))

    photo = scene.render_court_image(target_genome, (640, 360), rng=1)
    assert not edges.is_edge_image(photo)
    assert not edges.is_edge_image(np.zeros((360, 640), np.uint8))  # nothing on it
    assert not edges.is_edge_image(np.full((360, 640), 255, np.uint8))  # all white
    coloured = cv2.cvtColor(edge_image, cv2.COLOR_GRAY2BGR)
    coloured[edge_image > 0] = (0, 0, 255)
    assert not edges.is_edge_image(coloured)
