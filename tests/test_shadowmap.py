"""The summed-out shadow filters (lipgen.rig._shadowmap) draw the same pixels as pyrender's own.

pyrender's 3 x 3 bilinear PCF and lipgen's 4 x 4 weighted sum (four gathers, or 16 reads) are
the same filter summed in another order, so a shadowed frame of the hard preset's scene (head,
mouth, ink, a turned head, the key light casting shadows) must come out byte for byte as with
pyrender's shader, and with visible shadows (else the comparison would prove nothing).
"""

import numpy as np
import pytest

from lipgen.dataset.film import realize
from lipgen.dataset.presets import PRESETS
from lipgen.mesh.procedural import lip_mesh
from lipgen.rig.camera import default_rig
from lipgen.subject.face import FaceLook, FaceModel

render = pytest.importorskip("lipgen.rig.render")
pytestmark = pytest.mark.render


def _pose(deg: float) -> np.ndarray:
    a = np.radians(deg)
    P = np.eye(4)
    P[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    return P


def test_the_16_read_shadow_filter_draws_pyrenders_pixels():
    from pyrender.shader_program import ShaderProgramCache

    from lipgen.rig import _shadowmap

    assert _shadowmap.patched_mesh_shader() is not None, "pyrender's shader changed: the filter is not used"
    mesh = lip_mesh(1)
    face = FaceModel(mesh, FaceLook(head=True, mouth=True, dot_irregularity=1.0, dot_smudge=0.5,
                                    texture=1.0, texture_seed=4))
    lights = realize(PRESETS["hard"].image.conditions, seed=7)["lights"]
    scenes = [face.scene(mesh.vertices, _pose(d), lights=lights, age=0.5) for d in (-6.0, 9.0)]
    rig = default_rig(320, 240)
    out = {}
    for name in ("gather", "fetch", "pyrender", "none"):
        with render.RigRenderer(rig, shadows=name != "none") as r:  # one GL context at a time
            cache = r._renderer._renderer._program_cache
            if name == "gather":
                assert type(cache) is not ShaderProgramCache, "the gathered filter was not installed"
            if name == "fetch":
                assert _shadowmap.install(r._renderer, gather=False)
            if name == "pyrender":
                cache.clear()
                r._renderer._renderer._program_cache = ShaderProgramCache()
            out[name] = [r.render(s).image for s in scenes]
    for a, f, b, c in zip(out["gather"], out["fetch"], out["pyrender"], out["none"], strict=True):
        assert np.array_equal(a, b), np.abs(a.astype(int) - b).max()
        assert np.array_equal(f, b), np.abs(f.astype(int) - b).max()
        shadowed = (a.astype(int).sum(axis=2) < c.astype(int).sum(axis=2) - 30).mean()
        assert shadowed > 0.002, shadowed  # the nose and the folds cast shadows in these frames
