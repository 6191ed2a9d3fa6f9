"""``lipgen blender-extension``: build the installable Blender add-on zip(s)."""

from __future__ import annotations

import sys


def add_parser(sub) -> None:
    from lipgen.blender.packaging import BUNDLED, PLATFORMS

    p = sub.add_parser(
        "blender-extension",
        help="build the Blender extension zip(s): the add-on plus lipgen and its wheels",
        description="Build the LipGen Blender extension (Blender 4.2+): one zip per platform, each "
        "holding the add-on, a lipgen wheel and the wheels of " + ", ".join(BUNDLED) + " for "
        "that platform (numpy is Blender's own). Wheels are downloaded with pip once and kept "
        "in a cache. Every zip is checked with Blender's extension validator. Install a zip in "
        "Blender with Edit > Preferences > Get Extensions > Install from Disk.",
    )
    p.add_argument("--out", required=True, help="folder for the zips (created if missing)")
    p.add_argument("--platform", action="append", dest="platforms", metavar="NAME",
                   choices=sorted(PLATFORMS),
                   help="build only this Blender platform (repeatable); default: all of "
                   + ", ".join(PLATFORMS))
    p.add_argument("--wheel-cache", default=None,
                   help="wheel cache folder (default ~/.cache/lipgen/wheels)")
    p.add_argument("--offline", action="store_true", help="use only wheels already in the cache")
    p.add_argument("--source", default=None, help="add-on folder (default: blender_addon/ of this "
                   "source tree)")
    p.add_argument("--blender", default=None, help="a blender executable to build and validate "
                   "with (default: the tool inside the pip bpy module)")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from lipgen.blender.packaging import build_extension

    build = build_extension(args.out, platforms=args.platforms, cache=args.wheel_cache,
                            offline=args.offline, source=args.source, blender=args.blender)
    for platform, path in sorted(build.zips.items()):
        sys.stdout.write(f"{platform}\t{path}\t{path.stat().st_size / 2**20:.1f} MiB\tvalid\n")
    for platform, why in sorted(build.skipped.items()):
        sys.stdout.write(f"{platform}\tskipped: {why}\n")
    return 0
