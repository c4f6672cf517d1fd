import numpy as np
import pytest
from scipy.spatial import cKDTree

from app.calib import camera, court, render

FLOOR_EDGE_PREFIXES = (
    "short",
    "half",
    "box",
    "left_floor",
    "right_floor",
    "back_floor",
    "front_floor",
)


def floor_model() -> court.CourtModel:
    model = court.court_model()
    return model.subset([n for n in model.edge_names if n.startswith(FLOOR_EDGE_PREFIXES)])


def test_rasterised_court_lights_the_projected_nodes(target_genome):
    model = court.court_model()
    image = render.rasterize_court(target_genome, model, (1920, 1080))
    assert image.dtype == np.uint8 and set(np.unique(image)) == {0, 255}
    for u, v in camera.project_visible(target_genome, model.nodes):
        window = image[int(round(v)) - 1 : int(round(v)) + 2, int(round(u)) - 1 : int(round(u)) + 2]
        assert window.max() == 255


@pytest.mark.parametrize("t_z_m", [8.5, 3.0])
def test_drawn_lines_are_real_images_of_the_court_even_past_the_lens_fold(target_genome, t_z_m):
    # a strong barrel lens (fold at r = 0.75); at t_z = 3 m a fifth of the court lies past
    # the fold, where the polynomial would draw it back into the picture as ghost loops
    g = target_genome.copy()
    g[6] = t_z_m
    g[10:15] = [-0.6, 0.0, 0.0, 0.0, 0.0]
    model = floor_model()
    vertices = np.concatenate(render.court_polylines(g, model))
    floor_xy, status = camera.pixel_to_floor(g, vertices)
    assert np.all(status == camera.RAY_OK)
    court_lines = court.sample_edges(model, 0.005).points[:, :2]
    distance_m, _ = cKDTree(court_lines).query(floor_xy)
    assert distance_m.max() < 0.05
