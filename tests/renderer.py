"""The project's synthetic court renderer, imported in this one place by the page's tests (it may
move from app.calib.synthetic to app.calib.scene: then only this line changes)."""

from app.calib.synthetic import render_clip_frames, typical_target_camera, write_video

__all__ = ["render_clip_frames", "typical_target_camera", "write_video"]
