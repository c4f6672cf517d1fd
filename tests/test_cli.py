"""`squashcal calibrate` as a user runs it: a real subprocess on a synthetic image."""

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.calib import camera, scene, synthetic

SIZE = (960, 540)
FAST = ["--bundle", "n16-tdm-roulette-single-dist", "--max-generations", "300"]


def squashcal(*args: str | Path) -> subprocess.CompletedProcess[str]:
    """Run the installed console script if there is one, else `python -m app.cli`."""
    script = Path(sys.executable).with_name("squashcal")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "app.cli"]
    return subprocess.run(
        [*command, "calibrate", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=Path(__file__).resolve().parents[1],
        env={**os.environ, "PYTHONWARNINGS": "error"},
    )


def assert_one_line_error(proc: subprocess.CompletedProcess[str], *fragments: str) -> None:
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert lines[0].startswith("squashcal calibrate: error: ")
    for fragment in fragments:
        assert fragment in lines[0]


@pytest.fixture(scope="module")
def truth() -> np.ndarray:
    return synthetic.typical_target_camera(SIZE)


@pytest.fixture(scope="module")
def image_path(tmp_path_factory, truth) -> Path:
    path = tmp_path_factory.mktemp("cli") / "court.png"
    cv2.imwrite(str(path), scene.render_court_image(truth, SIZE, rng=2))
    return path


def test_calibrate_writes_the_result_and_the_overlay(tmp_path, image_path, truth):
    out, overlay = tmp_path / "result.json", tmp_path / "overlay.png"
    proc = squashcal(image_path, "--seed", "3", "--out", out, "--overlay", overlay)
    assert proc.returncode == 0, proc.stderr
    assert len(proc.stdout.strip().splitlines()) == 1 and str(out) in proc.stdout
    assert "good" in proc.stdout and "expected floor error at the T" in proc.stdout
    doc = json.loads(out.read_text())
    assert doc["seed"] == 3 and doc["spec"] == "wsf" and doc["generations"] == 0
    assert doc["bundle"] is None and doc["verdict"]["label"] == "good"
    assert doc["opencv"]["image_size"] == list(SIZE)
    assert doc["timings_s"]["search"] > 0
    genome, size = camera.camera_from_json(doc["opencv"])
    assert size == SIZE
    grid = np.array([[1.0, 3.0], [3.2, 5.465], [5.4, 8.0]])
    floor, _ = camera.pixel_to_floor(genome, camera.floor_to_pixel(truth, grid))
    assert np.abs(floor - grid).max() < 0.03
    drawn = cv2.imread(str(overlay))
    assert drawn is not None and drawn.shape == (SIZE[1], SIZE[0], 3)


def test_start_camera_in_opencv_or_genome_form(tmp_path, image_path, truth):
    start = synthetic.wiggle_camera(truth, "near", np.random.default_rng(5))
    forms = {
        "opencv.json": camera.to_opencv(start, SIZE),
        "genome.json": [float(v) for v in start],
    }
    for name, form in forms.items():
        start_path, out = tmp_path / name, tmp_path / f"out-{name}"
        start_path.write_text(json.dumps(form))
        proc = squashcal(image_path, "--start", start_path, *FAST, "--out", out)
        assert proc.returncode == 0, proc.stderr
        doc = json.loads(out.read_text())
        # the paper's GA ran from the search's best camera, the start being one of the hints
        assert 1 <= doc["generations"] <= 300 and doc["bundle"] == "n16-tdm-roulette-single-dist"
        genome, _ = camera.camera_from_json(doc["opencv"])
        grid = np.array([[1.0, 3.0], [3.2, 5.465], [5.4, 8.0]])
        floor, _ = camera.pixel_to_floor(genome, camera.floor_to_pixel(truth, grid))
        assert np.abs(floor - grid).max() < 0.03


def test_bad_input_gives_one_line_and_a_nonzero_exit(tmp_path, image_path):
    out = tmp_path / "out.json"
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4)
    not_json = tmp_path / "start.json"
    not_json.write_text("{not json")
    wrong_camera = tmp_path / "camera.json"
    wrong_camera.write_text(json.dumps({"K": [[1, 0], [0, 1]]}))
    cases = [
        ((tmp_path / "missing.png", "--out", out), ("image not found",)),
        ((corrupt, "--out", out), ("not a readable image",)),
        ((image_path, "--start", not_json, "--out", out), ("not valid JSON",)),
        ((image_path, "--start", wrong_camera, "--out", out), ("bad start camera",)),
        ((image_path, "--start", tmp_path / "nope.json", "--out", out), ("cannot read",)),
        ((image_path, "--bundle", "n99-best", "--out", out), ("unknown bundle",)),
        ((image_path, "--spec", "tennis", "--out", out), ("unknown court spec",)),
        ((image_path, "--out", tmp_path / "no" / "dir" / "out.json"), ("does not exist",)),
        ((image_path, "--out", tmp_path), ("is a directory",)),
        ((image_path, "--max-generations", "0", "--out", out), ("max-generations",)),
    ]
    for args, fragments in cases:
        assert_one_line_error(squashcal(*args), *fragments)
    assert not out.exists()


def test_an_image_without_a_court_is_refused(tmp_path):
    noise = np.random.default_rng(9).integers(0, 256, (SIZE[1], SIZE[0], 3), dtype=np.uint8)
    path, out = tmp_path / "noise.png", tmp_path / "out.json"
    cv2.imwrite(str(path), noise)
    proc = squashcal(path, *FAST, "--out", out)
    assert_one_line_error(proc, "court not found")
    assert proc.returncode == 3
    assert not out.exists()
