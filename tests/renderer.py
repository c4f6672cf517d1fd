"""The project's synthetic court renderer, imported in this one place by the page's tests (it may
move from app.calib.synthetic to app.calib.scene: then only this line changes)."""

from app.calib.scene import render_clip_frames, write_video
from app.calib.synthetic import typical_target_camera

__all__ = ["render_clip_frames", "typical_target_camera", "write_video"]
