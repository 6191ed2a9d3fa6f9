"""Both view cameras of the rig drawn into one framebuffer, read back once.

pyrender draws one camera per ``render`` call: it binds and clears the whole framebuffer, draws,
resolves the multisampled buffer, reads depth (and linearises it) and colour back, and releases
the context. The rig needs two cameras (the real and the virtual view) whose images are the two
halves of one raw frame, so per frame it paid every fixed cost twice and read back a depth map
nobody asked for.

Here the two views are drawn side by side into one framebuffer of the size of both: each view in
its own viewport, with a scissor box so the clear of one view does not wipe the other. The
multisample resolve and the read-back happen once, after the last view, into a preallocated
buffer, and depth is resolved and read only when it is asked for. pyrender does the drawing
itself (its shaders, materials, lights and shadow maps are untouched): the renderer object is
given a subclass of :class:`pyrender.Renderer` that overrides three framebuffer methods, and a
plain render (the label pass, any other caller) behaves exactly as before.

Rasterisation at an integer pixel offset samples the same positions, so a view drawn here equals
the same view drawn alone (``tests/test_render_onepass.py``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["install", "render_side_by_side"]


def _one_pass_class(pr):
    from OpenGL import GL

    class OnePassRenderer(pr.Renderer):
        """pyrender's renderer that can draw a view into a region of a larger framebuffer."""

        region = None  # (x, y, w, h) of the view being drawn, or None for a plain render
        framebuffer_size = None  # (W, H) while drawing regions
        read_back = None  # after the last region: ("color" or "color+depth", buffer)

        def _configure_main_framebuffer(self):
            if self.region is None:
                return super()._configure_main_framebuffer()
            w, h = self.viewport_width, self.viewport_height
            self.viewport_width, self.viewport_height = self.framebuffer_size
            try:
                return super()._configure_main_framebuffer()
            finally:
                self.viewport_width, self.viewport_height = w, h

        def _configure_forward_pass_viewport(self, flags):
            super()._configure_forward_pass_viewport(flags)
            if self.region is not None:
                x, y, w, h = self.region
                GL.glViewport(x, y, w, h)
                GL.glScissor(x, y, w, h)  # glClear in the forward pass clears this view only
                GL.glEnable(GL.GL_SCISSOR_TEST)

        def _read_main_framebuffer(self, scene, flags):
            if self.region is None:
                return super()._read_main_framebuffer(scene, flags)
            GL.glDisable(GL.GL_SCISSOR_TEST)
            if self.read_back is None:
                return None
            want_depth, color = self.read_back
            W, H = self.framebuffer_size
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb_ms)
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, self._main_fb)
            GL.glBlitFramebuffer(0, 0, W, H, 0, 0, W, H, GL.GL_COLOR_BUFFER_BIT, GL.GL_LINEAR)
            if want_depth:
                GL.glBlitFramebuffer(0, 0, W, H, 0, 0, W, H, GL.GL_DEPTH_BUFFER_BIT, GL.GL_NEAREST)
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb)
            GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
            GL.glReadPixels(0, 0, W, H, GL.GL_RGB, GL.GL_UNSIGNED_BYTE, color)
            depth = None
            if want_depth:
                depth = np.empty((H, W), np.float32)
                GL.glReadPixels(0, 0, W, H, GL.GL_DEPTH_COMPONENT, GL.GL_FLOAT, depth)
            return color, depth

    return OnePassRenderer


def install(offscreen, pr) -> bool:
    """Give ``offscreen`` (a ``pyrender.OffscreenRenderer``) the one-pass renderer.

    Returns False, changing nothing, when its platform draws without framebuffer objects (then
    every view is rendered on its own, as pyrender does).
    """
    if not offscreen._platform.supports_framebuffers():
        return False
    offscreen._renderer.__class__ = _one_pass_class(pr)  # adds methods only; no state to convert
    return True


def _linear_depth(d: np.ndarray, znear: float, zfar: float) -> np.ndarray:
    """Window depth (0-1) to distance along the camera axis, 0 where nothing was drawn: the same
    float32 arithmetic as pyrender's read-back."""
    inf = d == 1.0
    d = 2.0 * d - 1.0
    ok = ~inf
    d[ok] = (2.0 * znear * zfar) / (zfar + znear - d[ok] * (zfar - znear))
    d[inf] = 0.0
    return d


def render_side_by_side(offscreen, scene, views, flags, depth: bool = False,
                        buffer: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """Draw each view into its own region of one framebuffer and read the result back once.

    Parameters
    ----------
    offscreen : pyrender.OffscreenRenderer
        After :func:`install` returned True.
    scene : pyrender.Scene
        Its ``main_camera_node`` is set to each view's node in turn.
    views : list of (node, width, height)
        Camera nodes (pyrender ``IntrinsicsCamera`` s) and their image sizes, left to right.
    flags : int
        ``pyrender.RenderFlags`` (OFFSCREEN is added).
    depth : bool
        Also read the depth buffer (linear, mm; 0 where nothing was drawn).
    buffer : (H, W, 3) uint8, optional
        Where the colour is read to (reused from frame to frame); H is the tallest view, W the
        sum of the widths.

    Returns
    -------
    list of (color (h, w, 3) uint8, depth (h, w) float32 or None)
        One per view, top-down rows (views into ``buffer``; copy to keep past the next call).
    """
    from pyrender.constants import RenderFlags

    W = sum(int(w) for _, w, _ in views)
    H = max(int(h) for _, _, h in views)
    if buffer is None or buffer.shape != (H, W, 3):
        buffer = np.empty((H, W, 3), np.uint8)
    r = offscreen._renderer
    offscreen._platform.make_current()
    r.point_size = offscreen.point_size
    r.framebuffer_size = (W, H)
    x = 0
    try:
        for k, (node, w, h) in enumerate(views):
            scene.main_camera_node = node
            r.viewport_width, r.viewport_height = int(w), int(h)
            r.region = (x, H - int(h), int(w), int(h))  # GL rows count from the bottom
            r.read_back = (depth, buffer) if k == len(views) - 1 else None
            result = r.render(scene, flags | RenderFlags.OFFSCREEN)
            x += int(w)
    finally:
        r.region = r.read_back = None
        offscreen._platform.make_uncurrent()
    color, z = result
    color = color[::-1]
    z = None if z is None else z[::-1]
    out, x = [], 0
    for node, w, h in views:
        w, h = int(w), int(h)
        zi = None
        if z is not None:
            cam = node.camera
            zi = _linear_depth(np.ascontiguousarray(z[:h, x:x + w]), cam.znear, cam.zfar)
        out.append((color[:h, x:x + w], zi))
        x += w
    return out
