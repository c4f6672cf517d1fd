import numpy as np
import pytest

from app.calib import court


def test_wsf_graph_has_22_nodes_and_32_edges():
    model = court.court_model("wsf")
    assert model.nodes.shape == (22, 3)
    assert model.edges.shape == (32, 2)
    assert len(set(model.edge_names)) == 32
    # every node is used by some edge and no edge is degenerate
    assert set(np.unique(model.edges)) == set(range(22))
    assert np.all(model.edge_lengths_m() > 0)


def test_line_centres_follow_the_wsf_table():
    model = court.court_model("wsf")
    assert model.node("T") == pytest.approx([3.2, 5.465, 0.0])
    assert model.node("box_left_inner_back") == pytest.approx([1.625, 7.115, 0.0])
    assert model.node("box_right_inner_back") == pytest.approx([4.775, 7.115, 0.0])
    assert model.node("service_left")[2] == pytest.approx(-1.805)
    assert model.node("front_out_right")[2] == pytest.approx(-4.595)
    assert model.node("back_out_left") == pytest.approx([0.0, 9.75, -2.155])
    assert model.node("tin_left")[2] == pytest.approx(-0.455)
    # walls above the floor have negative z (z points down)
    assert np.all(model.nodes[:, 2] <= 0)


def test_other_specs_are_data():
    assert court.court_model("psa").node("tin_right")[2] == pytest.approx(-0.405)
    doubles = court.court_model("doubles")
    assert doubles.node("floor_back_right") == pytest.approx([7.62, 9.75, 0.0])
    assert doubles.node("T")[0] == pytest.approx(3.81)
    with pytest.raises(ValueError, match="unknown court spec"):
        court.get_spec("tennis")


def test_sampling_keeps_end_nodes_and_spacing():
    model = court.court_model()
    samples = court.sample_edges(model, 0.07)
    assert samples.offsets[0] == 0 and samples.offsets[-1] == samples.n_points
    for e, (a, b) in enumerate(model.edges):
        chunk = samples.points[samples.offsets[e] : samples.offsets[e + 1]]
        assert chunk[0] == pytest.approx(model.nodes[a])
        assert chunk[-1] == pytest.approx(model.nodes[b])
        assert np.linalg.norm(np.diff(chunk, axis=0), axis=1).max() <= 0.07 + 1e-12
    # ~1500 samples at the 1080p spacing, fewer for smaller images
    assert 1300 < samples.n_points < 1800
    small = court.sample_edges(model, court.spacing_for_image(800))
    assert small.n_points < samples.n_points


def test_subset_and_grids():
    model = court.court_model()
    floor_only = model.subset(["front_floor", "half_court"])
    assert floor_only.edges.shape == (2, 2)
    with pytest.raises(ValueError):
        model.subset(["nope"])
    grid = court.floor_grid("wsf", 16, 16)
    assert grid.shape == (256, 3)
    assert grid[:, 0].max() == pytest.approx(6.4) and grid[:, 1].max() == pytest.approx(9.75)
    box = court.bounding_box_grid(model, 5)
    assert box.shape == (125, 3) and box[:, 2].min() == pytest.approx(-4.595)
