"""Benchmark: building the default lips at resolutions 0-4.

The baseline, measured in the same run, is :class:`~lipgen.mesh.LipMesh`'s own validation of the
finished arrays (duplicate-face and area checks): the ratio says how much the procedural surface
and its nested grid cost on top of what any mesh of that size costs to accept.
"""

from __future__ import annotations

from lipgen.bench.measure import growth_exponent, peak_memory, time_call
from lipgen.mesh.lipmesh import LipMesh
from lipgen.mesh.procedural import lip_mesh

NAME = "mesh"


def run(quick: bool) -> dict:
    levels = range(3) if quick else range(5)
    rows = []
    for r in levels:
        mesh, mem = peak_memory(lambda r=r: lip_mesh(r))
        build = time_call(lambda r=r: lip_mesh(r), repeat=3 if quick else 5)
        validate = time_call(lambda m=mesh: LipMesh(m.vertices, m.faces, m.regions, m.anchors, m.markers,
                                                    m.marker_names, m.nose), repeat=3 if quick else 5)
        rows.append({"resolution": r, "nodes": mesh.n_nodes, "faces": mesh.n_faces,
                     "build_s": build["best_s"], "validate_s": validate["best_s"],
                     "build_over_validate": build["best_s"] / validate["best_s"],
                     "peak_mib": mem["peak_mib"], "memory_method": mem["method"]})
    big = [row for row in rows if row["nodes"] >= 2000]
    return {
        "levels": rows,
        "growth_exponent": growth_exponent([r["nodes"] for r in big], [r["build_s"] for r in big])
        if len(big) >= 2 else None,
        "note": "build = lip_mesh(r) best of repeats; baseline = LipMesh validation of the same arrays",
    }
