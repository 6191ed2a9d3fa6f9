"""Both views drawn into one framebuffer equal each view rendered on its own (issue 22)."""

import numpy as np
import pytest

from lipgen.mesh.procedural import lip_mesh
from lipgen.rig.camera import MirrorRig, PinholeCamera, default_rig
from lipgen.rig.scene import Light
from lipgen.subject.face import FaceModel

pytestmark = pytest.mark.render
render = pytest.importorskip("lipgen.rig.render")


def _scene(face, k):
    V = face.mesh.vertices.copy()
    V[:, 1] -= 0.3 * k * np.clip(-V[:, 1], 0, 25)
    return face.scene(V)


@pytest.mark.parametrize("dist", [None, (-0.12, 0.03, 0.0, 0.0, 0.0)])
def test_one_pass_equals_a_pass_per_view(dist):
    rig = default_rig(160, 120)
    if dist is not None:  # the lens of the hard preset: each view renders wider, then resamples
        c = rig.camera
        rig = MirrorRig(PinholeCamera(c.K, c.R, c.t, c.width, c.height, dist, c.name), rig.mirror_normal,
                        rig.mirror_offset, rig.mirror_side, rig.split)
    face = FaceModel(lip_mesh(1))
    got = {}
    for one_pass in (True, False):  # one context at a time: pyrender's EGL close ends the display
        with render.RigRenderer(rig, one_pass=one_pass) as r:
            assert r._one_pass == one_pass
            if one_pass:  # the side-by-side pass is taken (the draw order agrees between the views)
                r._sync(_scene(face, 0), False)
                views = [(v.node, *v.size) for v in r._views]
                assert render._onepass.render_side_by_side(r._renderer, r._scene, views, r._flags) is not None
            # a second frame re-uploads geometry into the same framebuffer
            got[one_pass] = [(r.render_views(_scene(face, k), depth=True, labels=True),
                              r.render(_scene(face, k)).image) for k in range(2)]
    for (a, fa), (b, fb) in zip(got[True], got[False], strict=True):
        for (ca, za, la), (cb, zb, lb) in zip(a, b, strict=True):
            assert ca.shape == cb.shape and ca.dtype == cb.dtype == np.uint8
            assert np.abs(ca.astype(int) - cb.astype(int)).max() <= 1  # same samples, same resolve
            assert np.mean(ca != cb) < 1e-3
            drawn = zb > 0
            assert drawn.any() and np.array_equal(za > 0, drawn)
            # within two steps of the 24-bit depth buffer at that distance (znear 20, zfar 5000)
            step = za[drawn] ** 2 * (5000.0 - 20.0) / (20.0 * 5000.0) * 2.0**-24
            assert np.all(np.abs(za[drawn] - zb[drawn]) <= 2 * step + 1e-6 * za[drawn])
            assert np.array_equal(la, lb)
        assert fa.shape == fb.shape == (120, 160, 3)
        assert np.abs(fa.astype(int) - fb.astype(int)).max() <= 1


def test_one_pass_keeps_the_shadow_maps_of_textured_surfaces_in_the_second_view():
    """The hard preset's look (skin textures, a shadow-casting light): each view's material textures
    go on the units after the shadow map's. Before, the second view bound the skin texture on the
    shadow map's unit and shaded its shadows from the texture (up to 93 grey levels off on 0.3 % of
    a 640x480 real view)."""
    from lipgen.dataset.settings import GenerateSettings
    from lipgen.dataset.simulation import face_look

    s = GenerateSettings.from_preset("hard", frames=2, calib_frames=0, size=(320, 240))
    face = FaceModel(lip_mesh(1), face_look(s))
    scene = face.scene(face.mesh.vertices)
    assert any(m.texture is not None for it in scene.items for m in it.materials)
    assert any(lt.shadows for lt in scene.lights)
    got = {}
    for one_pass in (True, False):
        with render.RigRenderer(default_rig(320, 240), shadows=True, one_pass=one_pass) as r:
            got[one_pass] = r.render_views(scene)
    for (ca, _, _), (cb, _, _) in zip(got[True], got[False], strict=True):
        diff = np.abs(ca.astype(int) - cb.astype(int)).max(axis=-1)
        assert diff.max() <= 4 and np.mean(diff > 0) < 1e-3, (diff.max(), np.mean(diff > 0))


def test_multisampling_can_be_turned_off_and_back_to_the_same_bytes():
    """``samples=0`` draws without multisampling (edges aliased, a pixel shaded and covered once);
    back at pyrender's 4 the frames are the bytes they were."""
    from OpenGL import GL

    face = FaceModel(lip_mesh(1))
    with render.RigRenderer(default_rig(160, 120)) as r:
        assert r.samples == 4
        before = r.render(_scene(face, 1)).image
        r.samples = 0
        aliased = r.render(_scene(face, 1)).image
        gl = r._renderer
        gl._platform.make_current()
        try:
            GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, gl._renderer._main_cb_ms)
            assert GL.glGetRenderbufferParameteriv(GL.GL_RENDERBUFFER, GL.GL_RENDERBUFFER_SAMPLES) == 0
        finally:
            gl._platform.make_uncurrent()
        r.samples = 4
        after = r.render(_scene(face, 1)).image
        for bad in (-1, 17, 2.0, True, "4"):
            with pytest.raises(ValueError, match="samples"):
                r.samples = bad
    assert after.tobytes() == before.tobytes()
    differ = (aliased != before).any(axis=-1)
    assert 0 < differ.mean() < 0.1  # edges only: the background and the surfaces' insides agree
    with pytest.raises(ValueError, match="one-pass"):
        render.RigRenderer(default_rig(160, 120), one_pass=False, samples=0)


def test_overdraw_counts_bound_the_drawn_samples():
    """The bench's overdraw figure: every covered pixel holds at least one sample that passed the
    depth test, at most 4 (pyrender's multisampling), and no sample passes that was not rasterized;
    the frame is the same before and after counting, and the renderer's class is restored."""
    from lipgen.bench.frame_parts import overdraw

    rig = default_rig(160, 120)
    face = FaceModel(lip_mesh(1))
    with render.RigRenderer(rig) as r:
        before = r.render(_scene(face, 1)).image
        cls = type(r._renderer._renderer)
        got = overdraw(r)
        assert type(r._renderer._renderer) is cls
        views = [(v.node, *v.size) for v in r._views]
        drawn = render._onepass.render_side_by_side(r._renderer, r._scene, views, r._flags)
        covered = sum(int((~(c == c[0, 0]).all(axis=-1)).sum()) for c, _ in drawn)
        np.testing.assert_array_equal(r.render(_scene(face, 1)).image, before)
    assert covered <= got["passing"] <= got["rasterized"]
    assert got["passing"] <= 4 * sum(w * h for _, w, h in views)
    assert 0.0 <= got["hidden_fraction"] < 1.0


_LIGHTS = {
    "default": None,  # three directional lights (with shadows: one directional, two far point lights)
    "one_point": (Light("point", (1.0, 0.9, 0.8), 4e5, position=(40.0, 60.0, 300.0)),),
    "two_and_a_point": (Light("directional", direction=(0.2, -0.3, -1.0)),
                        Light("directional", (0.8, 0.9, 1.0), 1.0, (-0.6, 0.1, -0.8), shadows=False),
                        Light("point", intensity=2e5, position=(-50.0, 20.0, 250.0))),
}


@pytest.mark.parametrize("lights", sorted(_LIGHTS))
@pytest.mark.parametrize("shadows", [False, True])
def test_fixed_light_loops_draw_the_same_pixels(shadows, lights):
    """The one-pass renderer's shader with its light loops bounded at compile time draws the same
    bytes as pyrender's (loops bounded by the n_*_lights uniforms), with and without shadow maps,
    for several mixes of light kinds (so several compiled bounds, one program per mix)."""
    rig = default_rig(160, 120)
    face = FaceModel(lip_mesh(1))
    V = face.mesh.vertices.copy()
    V[:, 1] -= 0.3 * np.clip(-V[:, 1], 0, 25)
    scene = face.scene(V, lights=_LIGHTS[lights])
    with render.RigRenderer(rig, shadows=shadows) as r:
        one_pass = r._renderer._renderer
        got = {}
        for fixed in (True, False):
            one_pass.fixed_lights = fixed
            got[fixed] = r.render(scene).image
        programs = one_pass._lipgen_fixed_cache._program_cache.values()
        assert programs and all("lipgen_mesh_fixed" in p.fragment_shader for p in programs)  # drawn with
    np.testing.assert_array_equal(got[True], got[False])
    assert got[True].std() > 5  # a lit face, not an empty frame


def test_fixed_light_shader_needs_pyrenders_loops(tmp_path):
    """A shader without pyrender's three light loops is left to pyrender (None)."""
    path = tmp_path / "mesh.frag"
    path.write_text("void main() { for (int i = 0; i < n_directional_lights; i++) {} }\n")
    assert render._onepass.fixed_light_shader(str(path)) is None
    assert render._onepass.fixed_light_shader(str(tmp_path / "other.frag")) is None


def test_fixed_light_shader_is_written_again_when_its_folder_has_gone():
    """The copy lives in a temporary folder that a forked child's exit can remove; the cached path
    must not outlive it."""
    import os
    import shutil

    source = os.path.join(os.path.dirname(pytest.importorskip("pyrender").__file__), "shaders", "mesh.frag")
    first = render._onepass.fixed_light_shader(source)
    assert first is not None and os.path.exists(first)
    shutil.rmtree(os.path.dirname(first))
    again = render._onepass.fixed_light_shader(source)
    assert again != first and os.path.exists(again)
    with open(again) as fh:
        assert "i < LIPGEN_N_DIRECTIONAL" in fh.read()
