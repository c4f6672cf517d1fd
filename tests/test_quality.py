"""The verdict (quality.py): figures of a camera on the line evidence, and the rules that turn
them into good / check / not_a_court."""

import cv2
import numpy as np
import pytest

from app.calib import camera, lines, placement, quality, render, scene, search, verify
from app.calib.court import court_model

SIZE = (1280, 720)


def _camera() -> np.ndarray:
    return search.look_at_genomes(
        np.array([[3.2, 11.0, -3.0]]),
        np.array([[3.2, 4.0, 0.0]]),
        np.zeros(1),
        np.array([600.0]),
        SIZE,
    )[0]


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    return scene.render_court_image(_camera(), SIZE, rng=5)


@pytest.fixture(scope="module")
def maps(photo) -> lines.EvidenceMaps:
    return lines.evidence_maps(lines.line_evidence(photo))


def _figures(genome: np.ndarray, maps: lines.EvidenceMaps) -> dict[str, float]:
    model = court_model()
    figures = quality.quality_figures(genome, verify.verify_samples(model), maps, model, SIZE[0])
    figures["floor_error_t_cm"] = 1.0
    figures["floor_share"] = float(placement.floor_shares(genome, model, SIZE)[0])
    return figures


def test_the_true_camera_is_good(maps):
    figures = _figures(_camera(), maps)
    assert figures["supported_edges"] >= 15
    assert figures["wall_edges_supported"] >= 3
    assert figures["support_excess"] > 0.6
    judged = quality.verdict(figures)
    assert judged.label == "good", judged.reasons
    assert 0.5 < judged.score <= 1.0


@pytest.mark.parametrize(("gene", "offset"), [("t_x", 0.4), ("t_z", 1.0), ("gamma", 0.05)])
def test_a_camera_half_a_metre_off_is_not_a_court(maps, gene, offset):
    moved = _camera().copy()
    moved[camera.GENE[gene]] += offset
    figures = _figures(moved, maps)
    judged = quality.verdict(figures)
    assert judged.label == "not_a_court" and judged.reasons
    assert figures["supported_edges"] < _figures(_camera(), maps)["supported_edges"] - 5


def _typical_right() -> dict[str, float]:
    """Figures of a right camera on a club view (median-like values from bench.synthetic)."""
    return {
        "supported_edges": 20.0,
        "edges_in_view": 26.0,
        "supported_share_of_edges": 0.77,
        "supported_share_of_reliable_edges": 0.9,
        "wall_edges_supported": 7.0,
        "floor_across_supported": 7.0,
        "floor_along_supported": 7.0,
        "support_fraction": 0.8,
        "chance_fraction": 0.1,
        "support_excess": 0.7,
        "absent_fraction": 0.1,
        "floor_error_t_cm": 0.5,
        "floor_share": 0.3,
        "camera_in_play_volume": 0.0,
        "camera_behind_front_wall": 0.0,
    }


def test_typical_right_figures_are_good():
    assert quality.verdict(_typical_right()).label == "good"


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"wall_edges_supported": 0.0}, "another sport"),
        ({"floor_along_supported": 1.0}, "do not pin the floor down"),
        ({"floor_across_supported": 2.0}, "do not pin the floor down"),
        ({"supported_edges": 9.0}, "only 9 court lines"),
        ({"supported_share_of_edges": 0.25}, "only 25% of the court lines"),
        ({"supported_share_of_reliable_edges": 0.4}, "only 40% of the painted court lines"),
        ({"support_excess": 0.2, "support_fraction": 0.3}, "by chance"),
        ({"floor_error_t_cm": 80.0}, "do not pin the camera down"),
        ({"floor_share": 0.01}, "film the floor"),
        ({"absent_fraction": 0.7}, "has no line there"),
        ({"camera_in_play_volume": 1.0}, "where the players play"),
        ({"camera_behind_front_wall": 1.0}, "behind the front wall"),
        ({"pixel_aspect": 0.89, "wall_edges_supported": 2.0}, "non-square pixels"),
        ({"principal_point_offset_share": 0.2, "wall_edges_supported": 2.0}, "off-centre"),
        ({"service_box_edges_in_view": 4.0, "service_box_support": 0.02}, "service boxes"),
    ],
)
def test_each_rule_refuses_with_its_reason(change, words):
    figures = {**_typical_right(), **change}
    judged = quality.verdict(figures)
    assert judged.label == "not_a_court"
    assert any(words in reason for reason in judged.reasons), judged.reasons
    assert len(judged.refused_by) == len(judged.reasons)


@pytest.mark.parametrize(
    ("change", "only_pinning"),
    [
        ({"floor_along_supported": 1.0}, True),
        ({"floor_across_supported": 1.0, "floor_error_t_cm": 80.0}, True),
        ({"floor_along_supported": 1.0, "wall_edges_supported": 0.0}, False),
        ({"camera_behind_front_wall": 1.0}, False),
        ({}, False),  # not refused at all
    ],
)
def test_a_refusal_says_whether_only_the_pinning_rules_refused(change, only_pinning):
    """The pipeline lets a sharper fit of the same court overturn a refusal for lines that do
    not pin the floor, never one that doubts the court is a squash court."""
    judged = quality.verdict({**_typical_right(), **change})
    assert judged.refused_only_by(quality.PINNING_RULES) == only_pinning


@pytest.mark.parametrize(
    ("floor_across", "across", "floor_along", "along", "refused"),
    [
        (1.0, 4.0, 7.0, 7.0, False),  # a far view: the walls' lines across make up for the floor's
        (8.0, 8.0, 1.0, 2.0, False),  # one floor line along and a side wall's out line
        (0.0, 5.0, 7.0, 7.0, True),  # no floor line across: wall lines alone do not pin the floor
        (8.0, 8.0, 0.0, 2.0, True),
        (2.0, 2.0, 7.0, 7.0, True),  # too few across, walls included
        (8.0, 8.0, 1.0, 1.0, True),
    ],
)
def test_wall_lines_count_toward_the_directions_by_the_way_they_run(
    floor_across, across, floor_along, along, refused
):
    figures = {
        **_typical_right(),
        "floor_across_supported": floor_across,
        "across_supported": across,
        "floor_along_supported": floor_along,
        "along_supported": along,
    }
    judged = quality.verdict(figures)
    assert ("floor_directions" in judged.refused_by) == refused, judged.reasons


def test_the_directions_of_the_court_edges():
    model = court_model()
    across, along = quality._edge_directions(model)
    names = np.array(model.edge_names)
    assert {"tin", "service", "front_out", "back_out", "short_left_inner", "front_floor"} <= set(
        names[across]
    )
    assert {"left_out", "right_out", "half_court", "left_floor_box"} <= set(names[along])
    assert not (across | along)[quality._upright_edges(model)].any()


def test_a_camera_with_free_intrinsics_and_wall_lines_passes():
    figures = {**_typical_right(), "pixel_aspect": 0.75, "principal_point_offset_share": 0.3}
    assert quality.verdict({**figures, "wall_edges_supported": 3.0}).label == "good"
    # square pixels at the centre need one wall line only, but one alone asks for a look
    one_wall_line = quality.verdict({**_typical_right(), "wall_edges_supported": 1.0})
    assert one_wall_line.label == "check"
    assert any("one line on the walls" in reason for reason in one_wall_line.reasons)
    assert quality.verdict({**_typical_right(), "wall_edges_supported": 2.0}).label == "good"


def test_doubtful_figures_ask_for_a_check():
    judged = quality.verdict({**_typical_right(), "absent_fraction": 0.45})
    assert judged.label == "check"
    assert any("not seen" in reason for reason in judged.reasons)


@pytest.mark.parametrize(
    ("in_view", "support", "refused"),
    [(4.0, 0.0, True), (2.0, 0.03, True), (1.0, 0.0, False), (4.0, 0.1, False), (0.0, 1.0, False)],
)
def test_the_service_boxes_speak_when_two_of_their_lines_are_in_view(in_view, support, refused):
    """A zoomed view of the front half shows no box line, a view that hides the boxes behind
    a player one: the rule says nothing then."""
    figures = {
        **_typical_right(),
        "service_box_edges_in_view": in_view,
        "service_box_support": support,
    }
    assert ("service_boxes" in quality.verdict(figures).refused_by) == refused


def test_a_court_without_its_service_boxes_is_taken_for_another_sport(photo, maps):
    """The true camera on the court rendered with its half-court line and service boxes
    painted over (another sport's floor has lines across and along where the squash court
    has its short line and side lines, nothing where the boxes go): the other rules pass, this
    one refuses."""
    truth = _camera()
    model = court_model()
    boxes = render.draw_court(
        np.zeros(photo.shape[:2], np.uint8),
        truth,
        model.subset(quality.SERVICE_BOX_EDGES),
        255,
        9,
    )
    painted_over = cv2.inpaint(photo, boxes, 5, cv2.INPAINT_TELEA)
    with_boxes = _figures(truth, maps)
    without = _figures(truth, lines.evidence_maps(lines.line_evidence(painted_over)))
    assert with_boxes["service_box_edges_in_view"] >= 4
    assert with_boxes["service_box_support"] > 0.6
    assert without["service_box_edges_in_view"] == with_boxes["service_box_edges_in_view"]
    assert without["service_box_support"] < quality.MIN_SERVICE_BOX_SUPPORT
    judged = quality.verdict(without)
    assert judged.refused_by == ("service_boxes",), judged.reasons
    assert quality.verdict(with_boxes).label == "good"
