"""The scene of a real recording: head, teeth and tongue, ink as ink, shadows (issue 15).

Geometry is checked against its own definitions (the tip of the nose, the seam to the lips, the
jaw's motion, the ink's centroid); rendering against the truth: the rendered dot centroids land
on the truth projections, and what the ray-cast visibility says is hidden by teeth or lips is
what the label render shows in front.
"""

import json

import numpy as np
import pytest

from lipgen.mesh.procedural import lip_mesh
from lipgen.rig.camera import default_rig
from lipgen.rig.scene import Scene
from lipgen.rig.visibility import occluded
from lipgen.subject.face import FaceLook, FaceModel, look_record
from lipgen.subject.head import face_depth, head_shape
from lipgen.subject.ink import SECTORS, ink_style
from lipgen.subject.mouth import MouthInterior

HARD = FaceLook(head=True, mouth=True, dot_irregularity=1.0, dot_smudge=0.5, texture_seed=3)


@pytest.fixture(scope="module")
def mesh():
    return lip_mesh(1)


@pytest.fixture(scope="module")
def face(mesh):
    return FaceModel(mesh, HARD)


def _open(mesh, drop, band=1.0):
    """The lips with the lower face dropped by up to ``drop`` mm (a crude jaw opening), the
    stretch spread over ``band`` mm below the mouth line."""
    V0 = mesh.vertices
    V = V0.copy()
    V[:, 1] -= drop * np.clip((-V0[:, 1] - 0.5) / band, 0, 1)
    return V


def test_head_seam_nose_and_relief(face, mesh):
    V = _open(mesh, 6.0)
    Vf = face._face_vertices(V)
    # the border's inserted points stay on the lip border's (moved) edges: no crack at the seam
    W = face._weights
    assert W is not None
    K = len(W)
    inserted = Vf[mesh.n_nodes:mesh.n_nodes + K - len(face.loop)]
    border = W @ V[face.loop]
    np.testing.assert_allclose(inserted, border[np.flatnonzero((np.arange(K) % (K // len(face.loop))) > 0)],
                               atol=1e-12)
    # the nose's tip is the mesh's nose point; the nostrils are on its underside
    np.testing.assert_array_equal(face.nose_vertices[0], mesh.nose)
    nostril = face.nose_material == 1
    assert 20 <= nostril.sum()
    tri = face.nose_vertices[face.nose_faces[nostril]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.mean(n[:, 1] < 0) > 0.7, "nostrils open downwards"
    # the nasolabial fold is a crease in the relief: lower than the skin either side of it
    shape = head_shape(5)

    def relief(q):
        return face_depth(*q, shape) - face_depth(*q)

    for p, normal in (((36.0, 7.0), (0.86, 0.5)), ((41.0, -13.0), (1.0, 0.07))):
        p, normal = np.array(p), np.array(normal) / np.linalg.norm(normal)
        side = [p + s * 1.5 * shape.fold_width * normal for s in (-1, 1)]
        assert relief(p) < min(relief(q) for q in side) - 0.3 * shape.fold_depth


def test_jaw_carries_lower_teeth_and_tongue_only_down(mesh):
    m = MouthInterior(mesh)
    rest = m.surfaces(mesh.vertices)
    opened = m.surfaces(_open(mesh, 8.0))
    off = opened["lower_teeth"][0] - rest["lower_teeth"][0]
    assert off[:, 1].max() < -5 and np.allclose(off, off[0]) and np.isclose(off[0, 2], 0.5 * off[0, 1])
    np.testing.assert_array_equal(opened["upper_teeth"][0], rest["upper_teeth"][0])
    tongue = opened["tongue"][0] - rest["tongue"][0]
    np.testing.assert_allclose(tongue, np.broadcast_to(off[0], tongue.shape))
    raised = mesh.vertices.copy()
    raised[:, 1] += 3.0
    np.testing.assert_array_equal(m.surfaces(raised)["lower_teeth"][0], rest["lower_teeth"][0])
    # the teeth sit behind the lips: every tooth vertex is behind the lips' front at its height
    lips = mesh.vertices
    for V, _, _ in (rest["upper_teeth"], rest["lower_teeth"]):
        assert V[:, 2].max() < lips[np.abs(lips[:, 0]) < 3, 2].max() - 5


def test_ink_style_is_seeded_and_keeps_the_centroid():
    a, b = ink_style(4, 17, 1.0, 0.5), ink_style(4, 17, 1.0, 0.5)
    assert json.dumps(a.to_dict()) == json.dumps(b.to_dict())
    assert a.to_dict() != ink_style(5, 17, 1.0, 0.5).to_dict()
    assert a.scale.std() > 0.05 and 0.7 <= a.scale.min() and a.scale.max() <= 1.45
    ang = 2 * np.pi * (np.arange(4096) + 0.5) / 4096
    for k in range(17):
        knots = 2 * np.pi * np.arange(SECTORS + 1) / SECTORS
        r = np.interp(ang, knots, np.append(a.outline(k), a.outline(k)[0]))
        x, y = r * np.cos(ang), r * np.sin(ang)
        area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
        cx = np.sum((x + np.roll(x, -1)) * (x * np.roll(y, -1) - np.roll(x, -1) * y)) / (6 * area)
        cy = np.sum((y + np.roll(y, -1)) * (x * np.roll(y, -1) - np.roll(x, -1) * y)) / (6 * area)
        assert np.hypot(cx, cy) < 0.02 * a.scale[k], (k, cx, cy)
        assert np.ptp(a.outline(k) / a.scale[k]) > 0.005  # not a circle
    assert a.halo_opacity(0.0) == 0 and a.halo_opacity(1.0) == 0.5
    with pytest.raises(ValueError, match="ink strength"):
        ink_style(0, 3, 1.5)


def test_record_matches_the_face(face, mesh):
    rec = look_record(HARD, len(mesh.markers) + 1)
    assert rec == face.record()
    assert rec["head"] == face.head.to_dict() and rec["ink"]["smudge"] == 0.5
    json.dumps(rec)
    assert look_record(FaceLook(), 17) == {"head": None, "mouth": None, "ink": None, "seed": 0,
                                           "units": rec["units"]}
    with pytest.raises(ValueError, match="dot_smudge"):
        FaceLook(dot_smudge=2.0)


# ---- rendering -------------------------------------------------------------------------------
render = pytest.importorskip("lipgen.rig.render")
from test_render import _dot_centroids, _fully_seen  # noqa: E402  (after the skip)


@pytest.mark.render
def test_rendered_ink_lands_on_the_truth_with_head_mouth_and_shadows(face, mesh):
    rig = default_rig()
    errors = []
    with render.RigRenderer(rig, shadows=True) as r:
        for drop, age in ((0.0, 0.0), (7.0, 1.0)):
            V = _open(mesh, drop, band=8.0)  # no dot stretched many times over across its width
            scene = face.scene(V, age=age)
            bare = Scene(tuple(i for i in scene.items if i.name not in ("dots", "smudge")), scene.lights,
                         scene.ambient, scene.background)
            assert ("smudge" in [i.name for i in scene.items]) == (age > 0)
            views, bg = r.render_views(scene, labels=True), r.render_views(bare)
            X, N = face.marks(V)
            uv, _, inside = rig.project(X)
            surf = face.surfaces(V)
            tris, rims = face.occluders(surf), face.dot_rims(surf)
            for k, cam in enumerate(rig.views):
                seen = _fully_seen(cam, X, N, inside[k], tris, rims)
                c = _dot_centroids(views[k][0], bg[k][0], views[k][2], len(X))
                assert np.isfinite(c[seen]).all(), "a fully visible dot was not drawn"
                errors.append(c[seen] - uv[k][seen])
    err = np.vstack(errors)
    rms = np.sqrt(np.mean(np.sum(err**2, axis=1)))
    assert len(err) >= 40 and rms < 0.5, (len(err), rms)
    assert np.abs(err.mean(axis=0)).max() < 0.15, err.mean(axis=0)


@pytest.mark.render
def test_teeth_and_lips_hide_what_the_visibility_truth_says(face, mesh):
    """Points on the tongue and the lower teeth: the ray-cast truth and the label render agree on
    which are seen and which are hidden (by the upper teeth, the lips, the face)."""
    rig = default_rig()
    V = _open(mesh, 12.0)
    surf = face.surfaces(V)
    tris = face.occluders(surf)
    with render.RigRenderer(rig) as r:
        views = r.render_views(face.scene(V), labels=True)
    agree, n_seen, n_hidden = [], 0, 0
    for part, label in (("tongue", 5), ("lower_teeth", 4)):
        Vp, Fp, Np = surf[part]
        tn = np.cross(Vp[Fp[:, 1]] - Vp[Fp[:, 0]], Vp[Fp[:, 2]] - Vp[Fp[:, 0]])
        area = np.linalg.norm(tn, axis=1)
        Fp, tn = Fp[area > 1e-9], tn[area > 1e-9] / area[area > 1e-9, None]  # skip degenerate ones
        P = Vp[Fp].mean(axis=1) + 0.05 * tn  # face centres, just off the (curved) surface
        for k, cam in enumerate(rig.views):
            uv = cam.project(P)
            ok = cam.inside(uv, margin=-3) & (np.sum((cam.center - P) * tn, axis=1) > 0)
            hidden = occluded(cam, P[ok], tris)
            lab = views[k][2]
            px = np.round(uv[ok]).astype(int)
            # only pixels whose 3x3 neighbourhood has one label: away from outlines
            win = np.stack([lab[px[:, 1] + dy, px[:, 0] + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)], 1)
            clear = (win == win[:, 4:5]).sum(axis=1) >= 4  # not a lone pixel on an outline
            shown = win[:, 4] == label
            agree.append((shown == ~hidden)[clear])
            n_seen += int((~hidden & clear).sum())
            n_hidden += int((hidden & clear).sum())
    agree = np.concatenate(agree)
    print("teeth/tongue points seen", n_seen, "hidden", n_hidden, "agreement", agree.mean())
    assert n_seen >= 10 and n_hidden >= 100, (n_seen, n_hidden)
    assert agree.mean() > 0.95, agree.mean()


@pytest.mark.render
def test_shadows_without_acne_and_cast_by_the_nose(mesh):
    from lipgen.rig.scene import Light, Material, MeshItem
    from lipgen.subject.head import ellipsoid

    rig = default_rig(320, 240)
    # a convex body cannot shadow itself: with shadows its lit side must render as without
    V, F, N = ellipsoid(np.array([0.0, 5.0, -20.0]), 40.0 * np.eye(3), 48, 96)
    lights = (Light("directional", intensity=3.0, direction=(-0.3, -0.45, -1.0)),
              Light("directional", intensity=1.0, direction=(0.0, -1.0, -0.2)))  # grazing
    ball = Scene((MeshItem("ball", V, F, (Material("m", (0.8, 0.7, 0.6), 0.7),), None, N),), lights)
    face = FaceModel(mesh, FaceLook(head=True))
    s = face.scene(mesh.vertices)
    with render.RigRenderer(rig, shadows=True) as r:  # one GL context at a time
        a = r.render(ball).image.astype(int)
        fa = r.render(s, labels=True)
    with render.RigRenderer(rig) as plain:
        b = plain.render(ball).image.astype(int)
        fb = plain.render(s).image.astype(int)
    assert np.abs(a - b).max() <= 2, np.abs(a - b).max()
    skin = fa.labels == 1
    darker = (fb - fa.image.astype(int)).sum(axis=2) > 30
    assert 50 < (darker & skin).sum() < 0.3 * skin.sum()  # the nose's shadow, not acne everywhere


def test_scene_conditions_are_checked_and_recorded():
    from lipgen.rig.conditions import ImageConditions

    with pytest.raises(ValueError, match="ink"):
        ImageConditions(ink=1.5)
    with pytest.raises(ValueError, match="smudge"):
        ImageConditions(smudge=-0.1)
    with pytest.raises(ValueError, match="head"):
        ImageConditions(head="yes")
    c = ImageConditions(head=True, mouth=True, ink=0.5, smudge=0.2)
    assert ImageConditions.from_dict(json.loads(json.dumps(c.to_dict()))) == c and not c.is_ideal
    old = c.to_dict()
    for k in ("head", "mouth", "ink", "smudge"):
        old.pop(k)  # a manifest written before these existed reads as the plain scene
    plain = ImageConditions.from_dict(old)
    assert (plain.head, plain.mouth, plain.ink, plain.smudge) == (False, False, 0.0, 0.0)


def test_head_mesh_sets_the_tessellation_and_keeps_the_surface(mesh):
    """The head's tessellation (``FaceLook.head_mesh``): the default is the mesh the ``default``
    preset always drew; a coarser proxy has the counts asked for and lies on the same relief."""
    from lipgen.dataset.presets import PRESETS
    from lipgen.rig.conditions import ImageConditions
    from lipgen.subject.head import HEAD_MESH

    assert HEAD_MESH == (28, 4, 36, 64) == ImageConditions().head_mesh == FaceLook().head_mesh
    assert PRESETS["default"].image.conditions.head_mesh == HEAD_MESH
    k = len(FaceModel(mesh, HARD).loop)
    for rings, subdiv, nr, ns in (HEAD_MESH, PRESETS["hard"].image.conditions.head_mesh, (9, 2, 12, 20)):
        look = FaceLook(head=True, mouth=True, texture_seed=3, head_mesh=(rings, subdiv, nr, ns))
        f = FaceModel(mesh, look)
        assert len(f.proxy_faces) == 2 * rings * k * subdiv
        assert len(f.nose_faces) == ns * (2 * nr - 1)
        np.testing.assert_array_equal(f.nose_vertices[0], mesh.nose)
        # the outer ring lies on the head's relief (the rings inside blend into the lips' border)
        P = f.proxy_rest[-k * subdiv:]
        np.testing.assert_allclose(P[:, 2], face_depth(P[:, 0], P[:, 1], f.head), atol=1e-9)
    with pytest.raises(ValueError, match="head_mesh must be 4 whole numbers"):
        ImageConditions(head_mesh=(28, 0, 36, 64))
    with pytest.raises(ValueError, match="blur_step_px must be in"):
        ImageConditions(blur_step_px=0.0)


def test_a_subjects_textures_are_made_once_from_its_seed(mesh, monkeypatch):
    """Face models of one subject share its read-only textures, drawn once per process from the
    subject's seed; another seed or strength draws again. (Small stand-ins for the 1024x1024 maps,
    drawn from the generator they are given, count the draws.)"""
    from lipgen.subject import face, skin

    calls = []

    def texture(rng, strength):
        calls.append(strength)
        return rng.integers(0, 256, (4, 4, 3), dtype=np.uint8)

    monkeypatch.setattr(skin, "skin_texture", texture)
    monkeypatch.setattr(skin, "lip_texture", texture)
    face._subject_textures.cache_clear()
    try:
        a = FaceModel(mesh, FaceLook(texture=1.0, texture_seed=3))
        b = FaceModel(mesh, FaceLook(texture=1.0, texture_seed=3, dot_diameter=2.0))
        assert len(calls) == 2
        other = FaceModel(mesh, FaceLook(texture=1.0, texture_seed=4))
        weaker = FaceModel(mesh, FaceLook(texture=0.5, texture_seed=3))
        assert calls == [1.0, 1.0, 1.0, 1.0, 0.5, 0.5]
    finally:
        face._subject_textures.cache_clear()  # the stand-ins must not outlive this test
    rng = np.random.default_rng([3, 7])
    tone = skin.skin_tone(rng)
    want = (texture(rng, 1.0), texture(rng, 1.0))
    for k, tex in enumerate(want):
        assert a.materials[k].texture is b.materials[k].texture
        assert not a.materials[k].texture.flags.writeable
        np.testing.assert_array_equal(a.materials[k].texture, tex)
        assert not np.array_equal(other.materials[k].texture, tex)
        assert weaker.materials[k].texture is not a.materials[k].texture
    assert a.materials[0].color == pytest.approx(tone)
