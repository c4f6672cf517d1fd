"""bench.real takes a clip annotation through the worker's background stage, as an upload is."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from app.calib import camera
from app.calib.court import court_model
from bench import real
from tests import clips

SIZE = (640, 360)


def test_a_clip_annotation_is_calibrated_from_the_clips_longest_view(tmp_path: Path) -> None:
    """A clip that opens on a close-up (a cut, as the dev set's broadcast clip does) and then
    holds the main camera: its annotation's still is the close-up, and what bench.real hands
    the pipeline is the main view's background, not that still."""
    genome = clips.main_camera(SIZE)
    main = clips.render_clip_frames(genome, SIZE, 30, 41)
    close_up = clips.render_clip_frames(clips.close_up_camera(SIZE), SIZE, 6, 42)
    clips.write_video(close_up + main, tmp_path / "match.mp4")
    cv2.imwrite(str(tmp_path / "still.png"), close_up[0])
    nodes = court_model().keypoints()
    names = ["T", "short_left", "short_right", "floor_back_left", "floor_back_right"]
    pixels = camera.project_visible(genome, np.array([nodes[n] for n in names]))
    annotation = {
        "image": "still.png",
        "media": "match.mp4",
        "keypoints": {n: p.tolist() for n, p in zip(names, pixels, strict=True)},
        "check_fit": {"genome": genome.tolist()},
    }
    (tmp_path / "match.json").write_text(json.dumps(annotation))

    (loaded,) = real.load_annotations(tmp_path)
    assert loaded.media == tmp_path / "match.mp4"
    picture, moving_mask, described = real.calibration_input(loaded)
    assert "2 shots" in described
    assert picture.shape == main[0].shape
    # the background is the main view with the players taken out, nowhere near the close-up
    main_error = np.median(np.abs(picture.astype(float) - main[0].astype(float)))
    close_up_error = np.median(np.abs(picture.astype(float) - close_up[0].astype(float)))
    assert main_error < 4.0 < close_up_error, (main_error, close_up_error)
    assert moving_mask is None or moving_mask.shape == picture.shape[:2]

    # a still is handed over as it is
    del annotation["media"]
    (tmp_path / "match.json").write_text(json.dumps(annotation))
    (still,) = real.load_annotations(tmp_path)
    picture, moving_mask, described = real.calibration_input(still)
    assert still.media is None and described == "" and moving_mask is None
    assert np.array_equal(picture, still.image)
