"""Input limits of the pipeline itself, in a module light enough for the API to import."""

from __future__ import annotations

# Smaller pictures hold too few pixels of court line to fit 15 camera parameters to.
MIN_IMAGE_WIDTH_PX = 64
MIN_IMAGE_HEIGHT_PX = 48
