"""``lipgen mesh``: write the default lips (or check a mesh) as OBJ/PLY/NPZ and a picture."""

from __future__ import annotations

import argparse
import sys

_EPILOG = """\
examples:
  lipgen mesh                                   # summary of the default lips (resolution 0)
  lipgen mesh -r 2 --out lips.obj --plot lips.png
  lipgen mesh --from lips.obj --plot check.png  # re-read a written mesh and draw it

OBJ and PLY files get a JSON sidecar (lips.obj -> lips.obj.json) with the regions (one code per
face), anchors, markers (name and node index, thesis order) and the nose point; .npz holds all of
it in one file. Units are millimetres: +x is the subject's left, +y up, +z out of the face.
Existing files are never replaced unless --force is given.
"""


def add_parser(sub) -> None:
    p = sub.add_parser(
        "mesh",
        help="write the default procedural lips (OBJ/PLY/NPZ + annotations) and draw them",
        description="Build the default procedural lips at a resolution (0: 201 nodes like the "
        "thesis's 204; each step 4x the faces), print a summary, and optionally write them to a "
        "file and draw a picture (regions coloured, markers numbered 1-16, anchors, nose; front "
        "and profile views).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("-r", "--resolution", type=int, default=0, help="refinement level 0-6 (default 0)")
    p.add_argument("--from", dest="source", metavar="FILE",
                   help="read this mesh (.npz, or .obj/.ply with its sidecar) instead of building one")
    p.add_argument("--out", metavar="FILE", help="write the mesh to FILE (.obj, .ply or .npz)")
    p.add_argument("--plot", metavar="PNG", help="draw the mesh to this picture")
    p.add_argument("--views", default="front,profile,oblique",
                   help="comma-separated views for --plot: front, profile, oblique, below "
                   "(default: front,profile,oblique)")
    p.add_argument("--strip-anchors-only", action="store_true",
                   help="anchor only the far end of the strip, as the thesis does (default: also the "
                   "outer border of the skin, which keeps the grounded stiffness well conditioned)")
    p.add_argument("--force", action="store_true", help="replace existing output files")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from pathlib import Path

    from lipgen.commands._output import check_file_output, check_not_input, check_picture_output
    from lipgen.mesh.io import read_mesh, sidecar_path, write_mesh
    from lipgen.mesh.procedural import lip_mesh

    targets = [Path(args.plot)] if args.plot else []
    if args.out:
        targets += [Path(args.out)] + ([] if args.out.lower().endswith(".npz") else [sidecar_path(args.out)])
    for path in targets:
        if args.plot and path == Path(args.plot):
            check_picture_output(path, args.force, "--plot")
        else:
            check_file_output(path, args.force, "--out")
        check_not_input(path, (args.source,) + ((sidecar_path(args.source),) if args.source else ()),
                        "--plot" if args.plot and path == Path(args.plot) else "--out")
    views = ()
    if args.plot:  # before anything is written: a bad view name used to come after --out was
        from lipgen.mesh.plot import VIEWS

        views = tuple(v.strip() for v in args.views.split(",") if v.strip())
        bad = [v for v in views if v not in VIEWS]
        if bad or not views:
            raise ValueError(f"unknown view(s) {bad} in --views {args.views!r}; use {sorted(VIEWS)}")
    if args.source:
        mesh = read_mesh(args.source)
    else:
        mesh = lip_mesh(args.resolution, anchor_border=not args.strip_anchors_only)
    out = sys.stdout
    out.write(f"{mesh.name}: {mesh.n_nodes} nodes, {mesh.n_faces} faces, topology {mesh.topology_id}\n")
    for name in mesh.region_names:
        out.write(f"  region {name:6s} {int(mesh.region_mask(name).sum()):7d} faces\n")
    out.write(f"  anchors {len(mesh.anchors)} nodes; nose at {mesh.nose.round(2).tolist()} mm\n")
    for k, (name, node, pos) in enumerate(zip(mesh.marker_names, mesh.markers, mesh.marker_positions,
                                              strict=True)):
        out.write(f"  marker {k + 1:2d} {name:20s} node {int(node):6d}  {pos.round(2).tolist()}\n")
    if args.out:
        for path in write_mesh(mesh, args.out, overwrite=args.force):
            out.write(f"wrote {path}\n")
    if args.plot:
        from lipgen.mesh.plot import plot_mesh

        plot_mesh(mesh, args.plot, views=views)
        out.write(f"wrote {args.plot}\n")
    return 0
