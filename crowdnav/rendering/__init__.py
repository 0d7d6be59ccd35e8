"""Rendering: pygame frames of a simulator state and episode videos."""

from crowdnav.rendering.renderer import Overlays, Palette, Renderer, RenderOptions
from crowdnav.rendering.video import VIDEO_FORMATS, VideoWriter, write_video

__all__ = ["Overlays", "Palette", "RenderOptions", "Renderer", "VIDEO_FORMATS", "VideoWriter", "write_video"]
