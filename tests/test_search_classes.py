"""The search finds the court from no start camera in the filming classes of bench.synthetic:
one case per class that the benchmark found (seeds 1000+), judged as the benchmark judges
(floor grid median <= 5 cm, court lines <= 2 px RMS, accepted by the verdict)."""

import pytest

from bench.synthetic import run_case


@pytest.mark.slow
@pytest.mark.parametrize(
    ("class_name", "seed"),
    [
        ("broadcast_glass", 1001),
        ("club", 1004),
        ("tripod_phone", 1002),
        ("wide_angle", 1003),
        ("corner_side", 1004),
        ("zoomed", 1007),
        ("anamorphic_cropped", 1001),
        ("clip", 1011),
    ],
)
def test_the_court_is_found_from_no_start_camera(class_name: str, seed: int) -> None:
    outcome = run_case(class_name, seed)
    assert outcome.accepted, outcome.reason
    assert outcome.right, (outcome.floor_median_cm, outcome.lines_rms_px)
