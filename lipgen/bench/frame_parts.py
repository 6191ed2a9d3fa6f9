"""Per-frame parts of ``lipgen generate`` against their baselines, and the raw frame's coverage bound.

Used by the ``render`` suite (:mod:`lipgen.bench.render`). Every figure is a ratio of CPU times
measured in the same run, interleaved round by round (medians of per-round ratios):

- ``noise_over_float``: the integer sensor noise (:func:`lipgen.rig.noise.add_rounded_gaussian`)
  over the float path it replaced (a float32 normal draw, multiply, add, round, clip);
- ``visibility_over_all_pairs``: the culled visibility ray cast of one frame's truth (marks and
  dot rims, both views) over the same cast against every triangle;
- ``truth_over_raw``: a frame's whole truth (:func:`lipgen.dataset.simulation.frame_truth`) over
  its raw frame.

``coverage`` explains the raw frame's ratio to one pyrender pass: on Mesa's llvmpipe the cost of a
pass is a fixed part (clear, resolve, read-back, Python) plus a part proportional to the pixels
the surfaces cover (fragment shading). The raw frame shows the face twice (the direct and the
mirror view), so it covers more pixels than one full-frame pass through the real camera, which
sees the face once. ``bound_ratio_to_limit`` is the best ratio a raw frame can reach at the
single pass's fixed and per-pixel cost.

Profiled again (speed2, 640x480 ``easy`` face, CPU per pass, medians of 15 interleaved rounds,
load 25): one full-frame pass 37.7 ms; both views in one pass 54.7 ms; one view alone 25.9 ms;
the empty pass 11.1 ms (clear, the 4-sample resolve, about 4 ms, and a read-back of 0.2 ms: not
where the time goes); the whole raw frame (scene upload, both views, mirror dimming and
composition) 59.1 ms. The face covers 0.244 of the full frame but 0.308 of the direct view and
0.487 of the mirror view (the mirror view sees it larger), 1.63 times the pixels in all, and
fixed + per-pixel cost predicts 54.5 ms for both views. Per-view culling saves nothing: no
triangle lies outside either viewport, and the back faces (about 17 % per view) are culled by GL
before rasterization already. Sensor noise and the visibility truth are not part of the raw
frame. The bound is so about 0.69 at today's fixed cost (0.87 even if clearing and resolving were
free), short of 0.85 for any renderer that draws the same pixels on llvmpipe.
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["frame_parts", "coverage"]


def _cpu(fn) -> float:
    c0 = time.process_time()
    fn()
    return time.process_time() - c0


def _rounds(fns: dict, base: str, reps: int) -> dict:
    """Median per-round CPU ratio of each of ``fns`` to ``fns[base]`` (interleaved), and medians."""
    for fn in fns.values():
        fn()
    t = {k: [] for k in fns}
    for _ in range(reps):
        for k, fn in fns.items():
            t[k].append(_cpu(fn))
    b = np.maximum(np.asarray(t[base]), 1e-9)
    return {k: {"cpu_s": float(np.median(v)), "ratio": float(np.median(np.asarray(v) / b))}
            for k, v in t.items()}


def frame_parts(rig, face, vertices: np.ndarray, render, reps: int) -> dict:
    """The ratios named in the module docstring, for the frame of ``face`` at ``vertices``.

    Parameters
    ----------
    rig : MirrorRig
    face : FaceModel
    vertices : (n, 3) float
        The lip model's nodes, mm.
    render : callable
        ``render(scene) -> RenderedFrame`` (the raw frame's renderer).
    reps : int
        Interleaved rounds.
    """
    from lipgen.dataset.simulation import frame_truth
    from lipgen.rig.noise import add_rounded_gaussian
    from lipgen.rig.visibility import occluded, segment_hits

    image = render(face.scene(vertices)).image
    rng = np.random.default_rng(0)

    def float_noise():
        noise = rng.standard_normal(image.shape, dtype=np.float32) * np.float32(1.0)
        return np.clip(np.round(image + noise), 0, 255).astype(np.uint8)

    noise = _rounds({"float": float_noise, "integer": lambda: add_rounded_gaussian(image, 1.0, rng)},
                    "float", reps)
    surf = face.surfaces(vertices)
    tris = face.occluders(surf)
    X, _ = face.marks(vertices)
    queries = np.vstack([X, *[r[::2] for r in face.dot_rims(surf)]])

    def culled():
        return [occluded(cam, queries, tris) for cam in rig.views]

    def all_pairs():
        n, m = len(queries), len(tris)
        for cam in rig.views:
            hit = segment_hits(np.broadcast_to(cam.center, (n * m, 3)), np.repeat(queries, m, 0),
                               np.tile(tris, (n, 1, 1)))
            hit.reshape(n, m).any(axis=1)

    vis = _rounds({"all_pairs": all_pairs, "culled": culled}, "all_pairs", max(2, reps // 3))
    truth = _rounds({"raw": lambda: render(face.scene(vertices)),
                     "truth": lambda: frame_truth(rig, face, vertices, np.eye(4))}, "raw", reps)
    return {"noise_over_float": noise["integer"]["ratio"], "noise_cpu_s": noise["integer"]["cpu_s"],
            "visibility_over_all_pairs": vis["culled"]["ratio"], "visibility_cpu_s": vis["culled"]["cpu_s"],
            "truth_over_raw": truth["truth"]["ratio"], "queries": len(queries), "triangles": len(tris)}


def coverage(renderer, single, reps: int) -> dict:
    """Covered pixels and the fixed cost of a pass; the best raw/single ratio they allow.

    Parameters
    ----------
    renderer : RigRenderer
        With a frame's scene already drawn (its meshes are hidden for the empty pass, then shown).
    single : callable
        ``single() -> (color (H, W, 3), depth)``: one full-frame pyrender pass of that scene.
    reps : int
        Interleaved rounds.
    """
    from lipgen.rig import _onepass

    views = [(v.node, *v.size) for v in renderer._views]
    nodes = list(renderer._scene.mesh_nodes)
    shown = {n: n.mesh.is_visible for n in nodes}

    def both():
        return _onepass.render_side_by_side(renderer._renderer, renderer._scene, views, renderer._flags)

    def empty():
        for n in nodes:
            n.mesh.is_visible = False
        try:
            return both()
        finally:
            for n in nodes:
                n.mesh.is_visible = shown[n]

    def covered(img):
        return float(1.0 - (img == img[0, 0]).all(axis=-1).mean())  # the corner pixel is background

    drawn = both()
    if drawn is None:  # the views sort the meshes differently: no one-pass figure
        return {}
    raw_cov = float(np.mean([covered(c) for c, _ in drawn]))
    single_cov = covered(single()[0])
    t = _rounds({"single": single, "both": both, "empty": empty}, "single", reps)
    fixed, per = t["empty"]["cpu_s"], max(t["single"]["cpu_s"] - t["empty"]["cpu_s"], 0.0)
    bound = t["single"]["cpu_s"] / (fixed + per * raw_cov / max(single_cov, 1e-9))
    return {"covered_raw": raw_cov, "covered_single": single_cov, "empty_over_single": t["empty"]["ratio"],
            "both_views_over_single": t["both"]["ratio"], "bound_ratio_to_limit": float(bound)}
