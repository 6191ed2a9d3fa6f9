"""The synthetic subject: what the camera films, with its ground truth.

* :mod:`~lipgen.subject.activation`: muscle-like actions, viseme scripts, activation curves, head motion.
* :mod:`~lipgen.subject.motion`: the truth subject (its own mesh and physics) and its simulation.
* :mod:`~lipgen.subject.face`: the subject's look (skin, vermilion, mouth, ink dots) as a scene.
* :mod:`~lipgen.subject.decal`: ink dots as decals on the surface.

Stages above use these; nothing here knows about cameras' images or reconstruction.
"""

__all__: list[str] = []
