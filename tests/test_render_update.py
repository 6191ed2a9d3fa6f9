"""A moving subject's vertex buffers written in place give the pixels of freshly built meshes (issue 22)."""

import numpy as np
import pytest

from lipgen.rig.camera import MirrorRig, PinholeCamera, default_rig
from lipgen.rig.scene import Light
from lipgen.subject.face import FaceLook, FaceModel

pytestmark = pytest.mark.render
render = pytest.importorskip("lipgen.rig.render")


def _frames(face, n):
    V0 = face.mesh.vertices
    return [V0 + np.outer(np.clip(-V0[:, 1], 0, 25) * (0.04 * k), [0.0, -1.0, 0.0]) for k in range(n)]


@pytest.mark.parametrize("shadows", [False, True])
def test_vertices_written_in_place_equal_new_meshes(shadows):
    from lipgen.mesh.procedural import lip_mesh

    c = default_rig(160, 120).camera  # the hard preset's lens: wider views, resampled depth and labels
    base = default_rig(160, 120)
    rig = MirrorRig(PinholeCamera(c.K, c.R, c.t, c.width, c.height, (-0.12, 0.03, 0.0, 0.0, 0.0), c.name),
                    base.mirror_normal, base.mirror_offset, base.mirror_side, base.split)
    face = FaceModel(lip_mesh(1), FaceLook(texture=0.6, texture_seed=3))
    lights = (Light("directional", (1.0, 0.97, 0.92), 3.2, (-0.3, -0.45, -1.0), shadows=True),
              Light("directional", (0.9, 0.95, 1.0), 1.4, (0.7, -0.1, -0.8)))
    scenes = [face.scene(V, lights=lights) for V in _frames(face, 3)]
    kept = {}
    with render.RigRenderer(rig, shadows=shadows) as r:
        for k, sc in enumerate(scenes):
            moved = r.render_views(sc, depth=True, labels=True)
            if k == 0:
                nodes = {n for e in r._items.values() for n in e["colour"] + [m for m, _ in e["label"]]}
        kept = {n for e in r._items.values() for n in e["colour"] + [m for m, _ in e["label"]]}
        assert kept == nodes, "the meshes are kept; only their vertex data change"
        r.clear()  # a fresh scene: new meshes for the last frame
        fresh = r.render_views(scenes[-1], depth=True, labels=True)
    for (ca, za, la), (cb, zb, lb) in zip(moved, fresh, strict=True):
        assert np.array_equal(ca, cb) and np.array_equal(za, zb) and np.array_equal(la, lb)
    assert (moved[1][0] != moved[1][0][0, 0]).any(), "the face is drawn"


def test_another_pyrender_release_falls_back_to_public_paths(monkeypatch):
    """With a pyrender release other than the one its internals were read from, the renderer uses
    neither the one-pass renderer nor in-place uploads, and draws the same pixels."""
    from lipgen.mesh.procedural import lip_mesh

    rig = default_rig(160, 120)
    face = FaceModel(lip_mesh(1), FaceLook(texture=0.6, texture_seed=3))
    scenes = [face.scene(V) for V in _frames(face, 2)]
    with render.RigRenderer(rig) as r:
        assert r._one_pass and r._in_place
        known = [r.render_views(sc, labels=True) for sc in scenes]
    pr = render.import_pyrender()
    monkeypatch.setattr(pr, "__version__", "0.2.0", raising=False)
    with render.RigRenderer(rig) as r:
        assert not r._one_pass and not r._in_place
        other = [r.render_views(sc, labels=True) for sc in scenes]
    for a, b in zip(known, other, strict=True):
        for (ca, _, la), (cb, _, lb) in zip(a, b, strict=True):
            assert np.abs(ca.astype(int) - cb.astype(int)).max() <= 1 and np.array_equal(la, lb)


def test_close_frees_the_context_without_a_full_collection(monkeypatch):
    """``close`` frees pyrender's OpenGL objects and context as ``OffscreenRenderer.delete`` does,
    without its ``gc.collect()`` (a walk of the whole heap, 0.35 s of CPU per renderer in a test
    worker); a renderer made after it draws the same pixels, and another pyrender release gets
    pyrender's own ``delete``."""
    import gc

    from lipgen.mesh.procedural import lip_mesh

    rig = default_rig(160, 120)
    scene = FaceModel(lip_mesh(1), FaceLook(texture=0.6, texture_seed=3)).scene(lip_mesh(1).vertices)
    collections = []
    monkeypatch.setattr(gc, "collect", lambda *a: collections.append(a) or 0)
    drawn = []
    for _ in range(2):
        with render.RigRenderer(rig) as r:
            offscreen, inner = r._renderer, r._renderer._renderer
            drawn.append(r.render_views(scene, depth=True, labels=True))
        assert r._renderer is None and offscreen._renderer is None and offscreen._platform is None
        assert inner._main_fb is None and not inner._meshes and not inner._program_cache._program_cache
        inner.delete()  # what the finaliser runs when the collector takes it later: nothing left to free
    assert not collections
    for a, b in zip(*drawn, strict=True):
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    pr = render.import_pyrender()
    monkeypatch.setattr(pr, "__version__", "0.2.0", raising=False)
    with render.RigRenderer(rig) as r:
        r.render_views(scene)
    assert len(collections) == 1
