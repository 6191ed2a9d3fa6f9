"""The Blender Cycles backend: the same scene and truth as pyrender, rendered dots on the truth.

The centroid of each rendered ink dot is measured from the image alone, as in
``test_render.py``: each renderer draws the frame with and without the dots, and the darkening
(as a fraction of the darkest ink pixel) weights the pixels of the dot's region. The regions come
from pyrender's label render (Cycles draws colour only), dilated by 2 px, because subsurface
scattering and the denoiser spread a dot's darkening a little wider than the rasterised dot;
the same regions serve both renderers. The truth projections come from :class:`MirrorRig`.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from lipgen.rig.camera import MirrorRig, PinholeCamera, default_rig
from lipgen.rig.scene import Scene

pytestmark = [pytest.mark.render, pytest.mark.blender]


def _centroids(img, bg, labels, n_dots, grow=2):
    """(n_dots, 2) darkening-weighted centroids (NaN where pyrender drew fewer than 2 pixels)."""
    from scipy import ndimage

    g = img.astype(float).mean(axis=2)
    b = bg.astype(float).mean(axis=2)
    out = np.full((n_dots, 2), np.nan)
    for k in range(n_dots):
        mine = labels == 10 + k
        if mine.sum() < 2:
            continue
        others = (labels >= 10) & ~mine
        region = (ndimage.binary_dilation(mine, iterations=grow)
                  & ~ndimage.binary_dilation(others, iterations=1))
        ink = g[region].min()
        w = np.clip((b - g) / np.maximum(b - ink, 1.0), 0, 1) * region
        yy, xx = np.nonzero(w)
        out[k] = np.sum(xx * w[yy, xx]) / w.sum(), np.sum(yy * w[yy, xx]) / w.sum()
    return out


def centroid_offsets(rig, face, frames, cycles_kw=None) -> dict:
    """Rendered dot centroid minus truth projection, px, per renderer: ``{"pyrender": (k, 2),
    "cycles": (k, 2)}`` over the fully visible dots (those ``test_render`` counts) of ``frames``."""
    from test_render import _fully_seen

    from lipgen.rig.cycles import CyclesRenderer
    from lipgen.rig.render import RigRenderer

    errors = {"pyrender": [], "cycles": []}
    with RigRenderer(rig) as pr, CyclesRenderer(rig, **(cycles_kw or {})) as cr:
        for V, P in frames:
            scene = face.scene(V, P)
            bare = Scene(tuple(i for i in scene.items if i.name != "dots"), scene.lights, scene.ambient,
                         scene.background)
            labelled = pr.render_views(scene, labels=True)
            pairs = {"pyrender": (labelled, pr.render_views(bare)),
                     "cycles": (cr.render_views(scene), cr.render_views(bare))}
            X, N = face.marks(V, P)
            uv, _, inside = rig.project(X)
            surf = face.surfaces(V, P)
            tris, rims = face.occluders(surf), face.dot_rims(surf)
            for k, cam in enumerate(rig.views):
                seen = _fully_seen(cam, X, N, inside[k], tris, rims, margin=2)
                for name, (views, bg) in pairs.items():
                    c = _centroids(views[k][0], bg[k][0], labelled[k][2], len(X))
                    assert np.isfinite(c[seen]).all(), f"{name}: a fully visible dot was not drawn"
                    errors[name].append(c[seen] - uv[k][seen])
    return {k: np.vstack(v) for k, v in errors.items()}


@pytest.fixture(scope="module")
def face():
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.subject.face import FaceLook, FaceModel

    return FaceModel(lip_mesh(1), FaceLook(dot_diameter=4.0))


def _rms(e):
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


_DISTORTED = (-0.15, 0.05, 0.002, -0.001, 0.0)


def _check_dots_land(face, dist, cycles_kw):
    pytest.importorskip("bpy")
    pytest.importorskip("pyrender")
    from test_render import _frames

    base = default_rig(320, 240)
    cam = base.camera
    rig = base if dist is None else MirrorRig(PinholeCamera(cam.K, cam.R, cam.t, cam.width, cam.height, dist),
                                              base.mirror_normal, base.mirror_offset)
    err = centroid_offsets(rig, face, _frames(face.mesh, 1, seed=3), cycles_kw)
    assert len(err["cycles"]) >= 15
    for name, e in err.items():
        assert _rms(e) < 0.5, f"{name}: dot centroids {_rms(e):.3f} px RMS from the truth"
        assert np.abs(e.mean(axis=0)).max() < 0.2, f"{name}: common offset {e.mean(axis=0)} px"
    # the two renderers agree with each other dot by dot
    assert _rms(err["cycles"] - err["pyrender"]) < 0.5


@pytest.mark.slow(cover=("tests/test_cycles.py::test_cycles_dots_land_on_the_truth_without_the_denoiser",
                         "tests/test_cycles.py::test_cycles_draws_the_same_picture_as_pyrender[plain]"))
@pytest.mark.parametrize("dist", [None, _DISTORTED], ids=["pinhole", "distorted"])
def test_cycles_dots_land_on_the_truth_like_pyrender(face, dist):
    """Both renderers put each dot's centroid on its truth projection, through a lens with and
    without distortion, at 320x240 with 8 samples (denoised).

    Tolerances: pyrender's own test allows 0.5 px RMS and 0.15 px of common offset at 640x480;
    here the dots (4 mm) are 3-4 px across, and Cycles adds path-tracing noise that the denoiser
    smooths into the dot's edge. A convention slip (half a pixel, a flipped shift, the mirror's
    flip) moves every dot by >= 0.5 px in common, far beyond 0.2 px.
    """
    _check_dots_land(face, dist, {"samples": 8, "threads": 1})


def test_cycles_dots_land_on_the_truth_without_the_denoiser(face):
    """The same check through the distorted lens with 4 samples and no denoiser (a sixth of the
    CPU: the denoiser is most of a denoised frame's cost; measured 0.36 px RMS, 0.02 px common
    offset, 0.26 px from pyrender). The denoised path is drawn by the picture tests below."""
    _check_dots_land(face, _DISTORTED, {"samples": 4, "denoise": False, "threads": 1})


@pytest.mark.slow(cover="tests/test_cycles.py::test_generate_with_cycles_at_one_frame_and_one_sample")
def test_generate_with_cycles_writes_the_same_truth_and_repeats_its_frames(tmp_path):
    """``generate`` with Cycles: the truth files are byte for byte pyrender's (the truth never
    depends on the renderer), the manifest records the renderer and its samples, and the same
    settings give the same frames."""
    _check_generate_with_cycles(tmp_path, {"frames": 2, "calib_frames": 1}, 4)


def test_generate_with_cycles_at_one_frame_and_one_sample(tmp_path):
    """The same checks on one frame, no chessboard, at 1 sample."""
    _check_generate_with_cycles(tmp_path, {"frames": 1, "calib_frames": 0}, 1)


def _check_generate_with_cycles(tmp_path, counts: dict, samples: int) -> None:
    pytest.importorskip("bpy")
    pytest.importorskip("pyrender")
    from PIL import Image

    from lipgen.dataset.generate import generate
    from lipgen.dataset.layout import GenerateSettings

    def read_manifest(folder):
        return json.loads((folder / "manifest.json").read_text())

    base = {**counts, "size": (160, 120), "seed": 5}
    pr = generate(tmp_path / "pr", GenerateSettings(**base), progress=False)
    cy = [generate(tmp_path / f"cy{k}", GenerateSettings(**base, renderer="cycles", cycles_samples=samples),
                   progress=False) for k in range(2)]
    settings = read_manifest(cy[0])["settings"]
    assert settings["renderer"] == "cycles" and settings["cycles_samples"] == samples
    assert "renderer" not in read_manifest(pr)["settings"]
    frames = [f"{k:06d}" for k in range(counts["frames"])]
    calib = [f"{k:06d}" for k in range(counts["calib_frames"])]
    truths = [f"truth/{f}.npz" for f in frames] + [f"calib/{f}.npz" for f in calib]
    for sub in truths:
        with np.load(pr / sub) as a, np.load(cy[0] / sub) as b:
            assert a.files == b.files
            for k in a.files:
                np.testing.assert_array_equal(a[k], b[k], err_msg=f"{sub}: {k}")
    for sub in [f"raw/{f}.png" for f in frames] + [f"calib/{f}.png" for f in calib]:
        images = [np.asarray(Image.open(d / sub)) for d in (pr, *cy)]
        assert images[0].shape == images[1].shape == (120, 160, 3)
        np.testing.assert_array_equal(images[1], images[2], err_msg=f"cycles is not repeatable: {sub}")
        # the same picture, drawn differently: the mean brightness agrees within 10 grey levels
        assert abs(images[0].mean() - images[1].mean()) < 10


@pytest.mark.parametrize("texture", [0.0, 1.0], ids=["plain", "textured"])
def test_cycles_draws_the_same_picture_as_pyrender(texture):
    """The same scene in both renderers: the same light level (Cycles' sun of strength E is
    pyrender's directional light of intensity E; the world is the ambient light) and the same
    picture, pixel by pixel, up to shading differences (path-traced shadows, subsurface
    scattering, the denoiser). A texture drawn black or flipped, or a view shifted, fails."""
    pytest.importorskip("bpy")
    pytest.importorskip("pyrender")
    from lipgen.mesh.procedural import lip_mesh
    from lipgen.rig.cycles import CyclesRenderer
    from lipgen.rig.render import RigRenderer
    from lipgen.subject.face import FaceLook, FaceModel

    rig = default_rig(160, 120)
    face = FaceModel(lip_mesh(1), FaceLook(texture=texture, texture_seed=4))
    scene = face.scene(face.mesh.vertices)
    with RigRenderer(rig) as pr:
        a = pr.render_views(scene)
    with CyclesRenderer(rig, samples=4, threads=1) as cr:
        b = cr.render_views(scene)
    for (x, _, _), (y, _, _) in zip(a, b, strict=True):
        x, y = x.astype(float), y.astype(float)
        assert np.abs(x.mean(axis=(0, 1)) - y.mean(axis=(0, 1))).max() < 8
        gx, gy = x.mean(axis=2).ravel(), y.mean(axis=2).ravel()
        assert np.corrcoef(gx, gy)[0, 1] > 0.9


def _light_ratios(cycles_kw) -> np.ndarray:
    """Cycles' radiance over pyrender's, in linear light, on a grey matte plane lit by a
    directional light, a point light, or the ambient light alone."""
    pytest.importorskip("bpy")
    pytest.importorskip("pyrender")
    from lipgen.rig.cycles import CyclesRenderer
    from lipgen.rig.render import RigRenderer
    from lipgen.rig.scene import Light, Material, MeshItem

    rig = default_rig(160, 120)
    V = np.array([[-200, -200, 0], [200, -200, 0], [200, 200, 0], [-200, 200, 0.0]])
    plane = MeshItem("plane", V, np.array([[0, 1, 2], [0, 2, 3]]), (Material("grey", (0.5, 0.5, 0.5), 1.0),),
                     normals=np.tile([0, 0, 1.0], (4, 1)))
    black = (0.0, 0.0, 0.0)
    scenes = [Scene((plane,), (Light("directional", intensity=1.0, direction=(0, 0, -1.0)),), black, black),
              Scene((plane,), (Light("point", intensity=2e4, position=(0, 5, 150.0)),), black, black),
              Scene((plane,), (), (0.5, 0.5, 0.5), black)]
    with RigRenderer(rig) as pr:
        a = [pr.render_views(s)[1][0][50:70, 30:50].mean() / 255 for s in scenes]
    with CyclesRenderer(rig, threads=1, **cycles_kw) as cr:
        b = [cr.render_views(s)[1][0][50:70, 30:50].mean() / 255 for s in scenes]
    from lipgen.rig.scene import srgb_to_linear

    return srgb_to_linear(np.array(b)) / np.array(a) ** 2.2


@pytest.mark.slow(cover="tests/test_cycles.py::test_cycles_lights_are_pyrender_lights_without_the_denoiser")
def test_cycles_lights_are_pyrender_lights():
    """A grey matte plane lit by a directional light, a point light, or the ambient light alone:
    the same radiance in both renderers within 10 % in linear light (measured 4-7 %: pyrender
    scales diffuse light by 1 - F and encodes with gamma 2.2 rather than the sRGB curve)."""
    ratio = _light_ratios({"samples": 16})
    assert np.all(np.abs(ratio - 1) < 0.1), ratio


def test_cycles_lights_are_pyrender_lights_without_the_denoiser():
    """The same lights with 4 samples and no denoiser (a sixth of the CPU; measured 4-7 % too: the
    20x20-pixel mean of a flat plane leaves little path-tracing noise)."""
    ratio = _light_ratios({"samples": 4, "denoise": False})
    assert np.all(np.abs(ratio - 1) < 0.1), ratio
