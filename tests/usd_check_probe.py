"""Run by test_blender_addon.py in a plain Python process (usd-core's pxr, never bpy's): validate
USD files written from Blender and read their animation back.

``python usd_check_probe.py OUT.npz FILE.usda [FILE.usda ...]`` writes, per file i: ``errors_i``
(validation issues that are errors), ``warnings_i``, and for a lipgen file the points of the
blend-shape variant (``skel_i``) and of the baked variant (``baked_i``), (F, n, 3) mm.
"""

import shutil
import sys
from pathlib import Path

import numpy as np

from lipgen.usd.export import read_animation, validate


def main(out: str, paths: list[str]) -> None:
    from pxr import Usd

    result = {}
    for i, path in enumerate(paths):
        issues = validate(path)
        result[f"errors_{i}"] = np.array([str(x) for x in issues if x.is_error], dtype=str)
        result[f"warnings_{i}"] = np.array([str(x) for x in issues if not x.is_error], dtype=str)
        stage = Usd.Stage.Open(path)
        vset = stage.GetDefaultPrim().GetVariantSets().GetVariantSet("encoding")
        if not vset.GetVariantNames():
            continue
        result[f"skel_{i}"] = read_animation(path).points
        baked = Path(out).with_name(f"baked_{i}{Path(path).suffix}")
        shutil.copy(path, baked)
        copy = Usd.Stage.Open(str(baked))
        copy.GetDefaultPrim().GetVariantSets().GetVariantSet("encoding").SetVariantSelection("bakedPoints")
        copy.GetRootLayer().Save()
        result[f"baked_{i}"] = read_animation(baked).points
    np.savez(out, **result)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
