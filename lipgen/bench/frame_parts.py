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
single pass's fixed and per-pixel cost: the one-pass renderer now beats it, because its shader
costs less per pixel than pyrender's (the light loops bounded at compile time,
:func:`lipgen.rig._onepass.fixed_light_shader`; ``both_views_pyrender_shader_over_single`` is
the both-views pass with pyrender's own shader, in the same rounds).

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

Issue 22, measured again (frame22f, the bench's frame, CPU medians of 10-12 interleaved rounds,
``LP_NUM_THREADS=1``, load 6-9; ratios to one full-frame pyrender pass):

- **Overdraw** (:func:`overdraw`, occlusion queries): the raw frame rasterizes 550,743 samples
  and 549,277 pass the depth test in pyrender's draw order, so a depth pre-pass or another draw
  order could skip at most 0.3 % of the shading (pyrender's ``mesh.frag`` neither discards nor
  writes depth, so llvmpipe's early depth test is already on).
- **Where a both-views pass goes:** 1.46 in all; with a one-line fragment shader 0.36 (the
  rasterizer, multisampling, clear, resolve and read-back), so pyrender's lighting is about 1.1 of
  the 1.46; without multisampling 1.11; the empty pass 0.15. The render bench's scene has no
  shadows, so a cheaper shadow filter does not move ``ratio_to_limit``.
- **Why the lighting costs so much:** llvmpipe shades blocks of 8 pixels, the whole block when
  any pixel is covered. A full-screen quad of 2 triangles shades 307,200 pixels in about 37-42 ms
  of CPU; the same quad cut into 37.5-pixel triangles costs 2x, into 9.4-pixel ones 4x. The face's
  122,000 covered pixels cost 51 ms of shading, about 3x the full-block rate.
- **The cure: the light loops.** pyrender's shader loops over its lights up to uniform counts;
  llvmpipe runs those loops lane by lane, with dynamic indexing into the light arrays. Bounded at
  compile time (:func:`lipgen.rig._onepass.fixed_light_shader`), the same pixels cost 0.73 of
  one pass for both views, against 1.50 with pyrender's shader (same rounds, load 7.4). Turning
  the Fresnel ``pow(x, 5.0)`` into products saved 12 % with pyrender's loops but nothing once the
  loops are bounded (0.728 against 0.729), so it is not kept: pyrender's arithmetic stays as is.
- **A deferred pass, tried and not kept** (branch ``frame22f-deferred``, commit b12b2de): a
  geometry pass writing each sample's position, normal, material slot and base colour to
  multisampled float textures, then pyrender's own ``mesh.frag`` text in full-screen passes,
  once per pixel where the covered samples agree and once per sample (``glSampleMaski``) where
  they differ. The pixels were bit-identical on both views, but the pass cost 6.3x the forward
  one: llvmpipe's ``texelFetch`` from multisampled float textures is slow (marking the pixels
  whose samples differ, 12 fetches per pixel, 51 ms; the per-pixel shading 49 ms; the per-sample
  shading, 36 % of covered samples, 172 ms).
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["frame_parts", "coverage", "overdraw"]


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


def overdraw(renderer) -> dict:
    """Samples the raw frame's one pass rasterizes and the samples that pass the depth test.

    Counted with ``GL_SAMPLES_PASSED`` occlusion queries around every draw of the one-pass
    renderer, once with the depth test passing every sample and once as drawn.

    Parameters
    ----------
    renderer : RigRenderer
        With a frame's scene already drawn, one-pass.

    Returns
    -------
    dict
        ``rasterized``, ``passing`` (samples, ints) and ``hidden_fraction`` (the share of the
        rasterized samples that a perfect depth pre-pass would not shade); empty when the views
        draw the meshes in different orders.
    """
    from OpenGL import GL

    from lipgen.rig import _onepass

    r = renderer._renderer._renderer
    base = type(r)
    state = {"always": False, "n": 0}

    class Counting(base):
        def _bind_and_draw_primitive(self, primitive, pose, program, flags):
            if state["always"]:
                GL.glDepthFunc(GL.GL_ALWAYS)
            q = int(np.ravel(GL.glGenQueries(1))[0])
            GL.glBeginQuery(GL.GL_SAMPLES_PASSED, q)
            super()._bind_and_draw_primitive(primitive=primitive, pose=pose, program=program, flags=flags)
            GL.glEndQuery(GL.GL_SAMPLES_PASSED)
            state["n"] += int(np.ravel(GL.glGetQueryObjectuiv(q, GL.GL_QUERY_RESULT))[0])
            GL.glDeleteQueries(1, [q])
            GL.glDepthFunc(GL.GL_LESS)

    views = [(v.node, *v.size) for v in renderer._views]
    counts = {}
    r.__class__ = Counting
    try:
        for always in (True, False):
            state["always"], state["n"] = always, 0
            if _onepass.render_side_by_side(renderer._renderer, renderer._scene, views,
                                            renderer._flags) is None:
                return {}
            counts[always] = state["n"]
    finally:
        r.__class__ = base
    return {"rasterized": counts[True], "passing": counts[False],
            "hidden_fraction": 1.0 - counts[False] / max(counts[True], 1)}


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

    def both_pyrender_shader():  # the light loops bounded by uniforms, as pyrender's shader has them
        one_pass = renderer._renderer._renderer
        one_pass.fixed_lights = False
        try:
            return both()
        finally:
            one_pass.fixed_lights = True

    drawn = both()
    if drawn is None:  # the views sort the meshes differently: no one-pass figure
        return {}
    raw_cov = float(np.mean([covered(c) for c, _ in drawn]))
    single_cov = covered(single()[0])
    fns = {"single": single, "both": both, "both_pyrender_shader": both_pyrender_shader, "empty": empty}
    t = _rounds(fns, "single", reps)
    fixed, per = t["empty"]["cpu_s"], max(t["single"]["cpu_s"] - t["empty"]["cpu_s"], 0.0)
    bound = t["single"]["cpu_s"] / (fixed + per * raw_cov / max(single_cov, 1e-9))
    return {"covered_raw": raw_cov, "covered_single": single_cov, "empty_over_single": t["empty"]["ratio"],
            "both_views_over_single": t["both"]["ratio"],
            "both_views_pyrender_shader_over_single": t["both_pyrender_shader"]["ratio"],
            "bound_ratio_to_limit": float(bound)}
