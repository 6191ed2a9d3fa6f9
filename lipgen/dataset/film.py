"""Filming a dataset under :class:`~lipgen.rig.conditions.ImageConditions` (used by ``generate``).

- :func:`rig_for`: the rig with the lens distortion of the conditions (recorded in the manifest,
  the calibration truth);
- :func:`realize`: this dataset's lights, exposure and white balance, drawn from its seed;
- :func:`sub_frame_states`: the subject's shape and head pose at the instants of one exposure,
  interpolated in time between the simulated frames (the true motion during the shutter);
- :func:`film_frame`: renders those instants and forms the raw frame
  (:class:`~lipgen.rig.imaging.FrameFormer`).
"""

from __future__ import annotations

import numpy as np

from lipgen.rig.camera import MirrorRig, default_rig
from lipgen.rig.conditions import ImageConditions
from lipgen.rig.pinhole import PinholeCamera
from lipgen.rig.scene import Light
from lipgen.subject.face import default_lights

__all__ = ["rig_for", "realize", "sub_frame_states", "exposure_offsets", "film_frame"]

_LIGHT_STREAM = 5


def rig_for(size: tuple[int, int], conditions: ImageConditions, base=default_rig) -> MirrorRig:
    """The rig ``base(width, height)`` (the default rig) with the lens distortion of ``conditions``."""
    rig = base(*size)
    dist = conditions.lens_distortion
    if dist is None:
        return rig
    c = rig.camera
    cam = PinholeCamera(c.K, c.R, c.t, c.width, c.height, dist, c.name)
    return MirrorRig(cam, rig.mirror_normal, rig.mirror_offset, rig.mirror_side, rig.split)


def _turn(direction, max_deg: float, rng: np.random.Generator) -> tuple[float, float, float]:
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    axis = np.cross(d, rng.standard_normal(3))
    axis /= np.linalg.norm(axis)
    a = np.radians(rng.uniform(0, max_deg))
    out = d * np.cos(a) + np.cross(axis, d) * np.sin(a)  # Rodrigues (axis is normal to d)
    out[2] = min(out[2], -0.2)  # the light stays in front of the face
    return tuple(float(x) for x in out / np.linalg.norm(out))


def realize(conditions: ImageConditions, seed: int) -> dict:
    """This dataset's lighting: ``{"lights": tuple[Light], "exposure": float, "white_balance": (3,)}``.

    With ``light_jitter`` 0 the default lights and the conditions' exposure and white balance;
    otherwise each light turns by up to ``40 * jitter`` degrees and changes intensity by up to
    ``50 * jitter`` %, the exposure varies by up to +-30 % and each colour gain by up to +-8 %
    (times the jitter), all drawn from the dataset seed.
    """
    j = conditions.light_jitter
    base = default_lights()
    if j == 0:
        return {"lights": base, "exposure": conditions.exposure,
                "white_balance": tuple(conditions.white_balance)}
    rng = np.random.default_rng([seed, _LIGHT_STREAM])
    lights = tuple(Light(lt.kind, lt.color, float(lt.intensity * (1 + 0.5 * j * rng.uniform(-1, 1))),
                         direction=_turn(lt.direction, 40.0 * j, rng), shadows=lt.shadows) for lt in base)
    exposure = float(conditions.exposure * (1 + 0.3 * j * rng.uniform(-1, 1)))
    wb = tuple(float(g * (1 + 0.08 * j * rng.uniform(-1, 1))) for g in conditions.white_balance)
    return {"lights": lights, "exposure": exposure, "white_balance": wb}


def lighting_record(real: dict) -> dict:
    """JSON-able form of :func:`realize`'s result (for the manifest)."""
    return {"lights": [{"kind": lt.kind, "color": list(lt.color), "intensity": lt.intensity,
                        "direction": list(lt.direction), "shadows": lt.shadows} for lt in real["lights"]],
            "exposure": real["exposure"], "white_balance": list(real["white_balance"])}


def _orthonormal(R: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def sub_frame_states(vertices: np.ndarray, poses: np.ndarray, i: int,
                     offsets: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Vertices and head pose at times ``i + offsets`` (frame intervals), linear in time between
    the simulated frames (held at the ends of the clip).

    Parameters
    ----------
    vertices : (F, n, 3) float
    poses : (F, 4, 4) float
    i : int
    offsets : (s,) float
    """
    F = len(vertices)
    out = []
    for o in np.asarray(offsets, float):
        t = float(np.clip(i + o, 0, F - 1))
        a = int(np.floor(t))
        b = min(a + 1, F - 1)
        w = t - a
        if w == 0:
            out.append((vertices[a], poses[a]))
            continue
        V = (1 - w) * vertices[a] + w * vertices[b]
        P = (1 - w) * poses[a] + w * poses[b]
        P[:3, :3] = _orthonormal(P[:3, :3])
        out.append((V, P))
    return out


def exposure_offsets(conditions: ImageConditions, span_px: float, step_px: float | None = None) -> np.ndarray:
    """Instants to render across the shutter (frame intervals from the frame time).

    As many as keep the image of any mark moving less than ``step_px`` (by default the
    conditions' ``blur_step_px``) between two instants (``span_px`` is the longest path of a mark's
    image while the shutter is open), at most ``blur_samples``; one instant at the frame time when
    the marks move less than ``step_px``. Still frames so cost one render, fast ones up to
    ``blur_samples``.
    """
    step_px = conditions.blur_step_px if step_px is None else float(step_px)
    if conditions.shutter == 0 or not np.isfinite(span_px) or span_px < step_px:
        return np.zeros(1)
    n = int(min(conditions.blur_samples, 1 + np.ceil(span_px / step_px)))
    return conditions.shutter * (np.arange(n) / (n - 1) - 0.5)


def film_frame(renderer, former, face, states: list, lights: tuple, rng: np.random.Generator,
               depth: bool = False, labels: bool = False, age: float = 0.0):
    """Render the sub-frame ``states`` [(vertices, pose), ...] and form the raw frame.

    ``age`` (0..1) is how far through the clip the frame is (the ink's smudging).

    Returns ``(image (H, W, 3) uint8, depth or None, labels or None)``; depth and labels are
    those of the middle instant (the frame time), as the truth.
    """
    instants, mid = [], None
    centre = len(states) // 2
    for k, (V, P) in enumerate(states):
        views = renderer.render_views(face.scene(V, P, lights=lights, age=age), depth and k == centre,
                                      labels and k == centre)
        instants.append((views[0][0], views[1][0]))
        if k == centre:
            mid = views
    image = former.form(instants, rng)
    rig = former.rig
    z = rig.compose(mid[0][1], mid[1][1]) if depth else None
    lab = rig.compose(mid[0][2], mid[1][2]) if labels else None
    return image, z, lab
