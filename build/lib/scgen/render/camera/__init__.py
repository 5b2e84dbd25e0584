"""The camera between the scene and the file (one stage, both backends): see scgen.render.camera.stage."""

from scgen.render.camera.lens import render_camera
from scgen.render.camera.stage import record_image

__all__ = ["record_image", "render_camera"]
