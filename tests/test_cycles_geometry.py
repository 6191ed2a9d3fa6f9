"""Depth and label masks with the Cycles backend (issue 15).

They are geometry, rasterised by pyrender from the same scene through the same view cameras and
lens: the bytes must be pyrender's own, and they must describe Cycles' picture: the background
where Cycles drew the background colour, the ink where Cycles drew dark dots, and depths that put
the nose tip where the truth does.
"""

from __future__ import annotations

import numpy as np
import pytest

from lipgen.rig.camera import MirrorRig, PinholeCamera, default_rig
from lipgen.subject.face import DOT_LABEL0, FaceLook, FaceModel

pytestmark = [pytest.mark.render, pytest.mark.blender]


@pytest.mark.slow(cover="tests/test_cycles_geometry.py::test_cycles_depth_and_masks_fit_an_undenoised_one_sample_picture")
def test_cycles_depth_and_masks_are_pyrenders_and_fit_the_cycles_picture():
    _check_depth_and_masks({"samples": 4})


def test_cycles_depth_and_masks_fit_an_undenoised_one_sample_picture():
    """The same checks on Cycles' cheapest picture (1 sample, no denoiser): the background is
    the world colour on every sample, and the dots are dark in any of them."""
    _check_depth_and_masks({"samples": 1, "denoise": False})


def _check_depth_and_masks(cycles_kw):
    pytest.importorskip("bpy")
    pytest.importorskip("pyrender")
    from scipy import ndimage

    from lipgen.mesh.procedural import lip_mesh
    from lipgen.rig.cycles import CyclesRenderer
    from lipgen.rig.render import RigRenderer

    base = default_rig(320, 240)
    c = base.camera
    rig = MirrorRig(PinholeCamera(c.K, c.R, c.t, c.width, c.height, (-0.15, 0.05, 0.002, -0.001, 0.0)),
                    base.mirror_normal, base.mirror_offset)
    face = FaceModel(lip_mesh(1), FaceLook(dot_diameter=4.0))
    scene = face.scene(face.mesh.vertices)
    with CyclesRenderer(rig, threads=1, **cycles_kw) as cr:  # one GL context at a time: this one first
        cy = cr.render(scene, depth=True, labels=True)
        views = cr.render_views(scene, depth=True)
    assert views[0][2] is None and views[0][1].shape == (rig.virtual_view.height, rig.virtual_view.width)
    with RigRenderer(rig) as pr:
        ref = pr.render(scene, depth=True, labels=True)
    assert np.array_equal(cy.labels, ref.labels) and np.array_equal(cy.depth, ref.depth)

    # the masks describe Cycles' picture (the eroded regions: edges blend in both renderers)
    grey = cy.image.astype(float).mean(axis=2)
    lab = cy.labels
    inner = {k: ndimage.binary_erosion(lab == k, iterations=2) for k in (0, 1)}
    background = np.round(255 * np.asarray(scene.background)).mean()
    mirror_bg = background * 0.9  # the mirror half is dimmed by its reflectance
    raw_bg = grey[inner[0]]
    assert inner[0].sum() > 1000 and np.all((raw_bg > mirror_bg - 3) & (raw_bg < background + 3))
    dots = ndimage.binary_erosion(lab >= DOT_LABEL0, iterations=1)
    assert dots.sum() > 20 and np.median(grey[dots]) < 0.5 * np.median(grey[inner[1]])
    assert ((cy.depth > 0) == (lab > 0)).mean() > 0.99  # silhouette pixels: depth and labels resolve apart

    # depth is the view camera's z: at the nose tip's pixel, the truth's depth of the nose tip
    X, _ = face.marks(face.mesh.vertices)
    uv, z, inside = rig.project(X[-1:])
    for k, view in enumerate(("virtual", "real")):
        assert inside[k, 0]
        u, v = np.round(rig.to_raw(view, uv[k])[0]).astype(int)
        assert abs(cy.depth[v, u] - z[k, 0]) < 0.5, (view, cy.depth[v, u], z[k, 0])
