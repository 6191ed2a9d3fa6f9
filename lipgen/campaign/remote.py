"""Campaigns into an object store (``--out s3://bucket/runs/noise``), through fsspec.

Any fsspec URL is accepted: ``s3://`` (s3fs), ``gs://`` (gcsfs), ``abfs://`` (adlfs),
``file://`` (a local or mounted folder, handy to try the store path), ``memory://`` (one process
only: for tests of the store itself). A plain path (no ``scheme://``) is a folder, written in
place (:mod:`lipgen.campaign.store`).

How the work reaches the store: each task works in a local staging folder on its worker
(``$LIPGEN_STAGING`` or the temp folder, ``lipgen-stage/``) and uploads what it made, one whole
object per file, so a reader never sees half a file (object stores replace objects atomically;
on ``file://`` each file is written under a temporary name and renamed). A frame's truth npz
is uploaded after its images: a frame counts as written once its truth is in the store, so a
campaign stopped mid-chunk resumes at the frames whose truth is missing. The index
(``campaign.json``, and ``campaign.parquet``) is rewritten whole after every stage.

A store has no lock that dies with its holder: ``.campaign.lock`` is an object written at the
start and deleted at the end. A campaign killed outright leaves it; delete it by hand, once sure
no campaign is running, to resume.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import hashlib
import json
import os
import platform
import shutil
import tempfile
from pathlib import Path

from lipgen.campaign.store import INDEX, LOCK, CampaignError, check_index, index_table_bytes

__all__ = ["Store", "is_uri", "open_store", "staging_dir", "job_files", "prepare_in_store",
           "render_chunk_in_store", "run_stage_in_store"]

PARQUET = "campaign.parquet"


def is_uri(out) -> bool:
    """Whether ``out`` names a store URL (``scheme://...``) rather than a folder path."""
    return isinstance(out, str) and "://" in out


class Store:
    """A campaign's root in an fsspec filesystem; paths are relative to it, with ``/``.

    Parameters
    ----------
    uri : str
        ``scheme://path``, e.g. ``s3://bucket/runs/noise`` or ``file:///data/runs/noise``.

    Raises
    ------
    CampaignError
        fsspec is missing, the scheme is unknown or its package is not installed, or the URL
        names no folder.
    """

    def __init__(self, uri: str) -> None:
        try:
            import fsspec
        except ImportError:
            raise CampaignError(f"--out {uri!r} is a store URL, which needs fsspec: "
                                "pip install 'lipgen[cluster]' (or pip install fsspec)") from None
        scheme = uri.split("://", 1)[0]
        try:
            fs, root = fsspec.core.url_to_fs(uri)
        except ValueError as exc:
            known = ", ".join(sorted(p for p in fsspec.available_protocols() if len(p) > 1)[:12])
            raise CampaignError(f"--out {uri!r}: unknown storage scheme {scheme!r} ({exc}); fsspec knows "
                                f"{known}, ...") from None
        except ImportError as exc:
            raise CampaignError(f"--out {uri!r}: the {scheme}:// scheme needs a package that is not "
                                f"installed ({exc})") from None
        root = root.rstrip("/")
        if not root.strip("/"):
            raise CampaignError(f"--out {uri!r} names no folder in the store; give one, e.g. {scheme}://bucket/runs/x")
        self.uri, self.fs, self.root = uri, fs, root
        protocols = fs.protocol if isinstance(fs.protocol, tuple) else (fs.protocol,)
        self.local = "file" in protocols or "local" in protocols
        self.in_process = "memory" in protocols

    def path(self, rel: str) -> str:
        """The store path of ``rel`` (relative to the campaign's root)."""
        return f"{self.root}/{rel}" if rel else self.root

    def exists(self, rel: str) -> bool:
        """Whether ``rel`` exists (file or folder)."""
        return self.fs.exists(self.path(rel))

    def isfile(self, rel: str) -> bool:
        """Whether ``rel`` is a file."""
        return self.fs.isfile(self.path(rel))

    def files(self, rel: str = "") -> set[str]:
        """The files under ``rel``, relative to ``rel``."""
        base = self.path(rel)
        if not self.fs.isdir(base):
            return set()
        return {p[len(base.rstrip("/")) + 1:] for p in self.fs.find(base)}

    def read_bytes(self, rel: str) -> bytes:
        """The content of file ``rel``."""
        return self.fs.cat_file(self.path(rel))

    def write_bytes(self, rel: str, data: bytes) -> None:
        """Write file ``rel`` whole (a reader sees the old or the new content, never a part)."""
        dest = self.path(rel)
        if self.local:  # a filesystem: write aside, then rename
            self.fs.makedirs(dest.rsplit("/", 1)[0], exist_ok=True)
            tmp = f"{dest}.tmp-{os.getpid()}"
            self.fs.pipe_file(tmp, data)
            self.fs.mv(tmp, dest)
        else:  # an object store replaces an object in one go
            self.fs.pipe_file(dest, data)

    def put_file(self, local: Path, rel: str) -> None:
        """Upload local file ``local`` to ``rel``, whole."""
        self.write_bytes(rel, Path(local).read_bytes())

    def get_file(self, rel: str, local: Path) -> None:
        """Download ``rel`` to ``local`` (written aside, then renamed)."""
        local = Path(local)
        local.parent.mkdir(parents=True, exist_ok=True)
        tmp = local.with_name(f".{local.name}.tmp-{os.getpid()}")
        tmp.write_bytes(self.read_bytes(rel))
        os.replace(tmp, local)

    def get_tree(self, rel: str, local: Path) -> list[str]:
        """Download every file under ``rel`` into folder ``local``; returns their relative paths."""
        names = sorted(self.files(rel))
        for name in names:
            self.get_file(f"{rel}/{name}", Path(local) / name)
        return names

    def remove(self, rel: str) -> None:
        """Delete file ``rel`` if it exists."""
        if self.isfile(rel):
            self.fs.rm_file(self.path(rel))


def open_store(uri: str) -> Store:
    """The :class:`Store` of ``uri`` (see :class:`Store` for the errors)."""
    return Store(uri)


# --- the driver's side: folder checks, lock, index ---------------------------------------------


def check_store(store: Store, fingerprint: str, resume: bool) -> dict | None:
    """:func:`lipgen.campaign.store.prepare_folder` for a store: the existing index when
    resuming, None for a new or empty location; nothing is ever deleted."""
    if store.isfile(""):
        raise CampaignError(f"{store.uri} is a file, not a campaign folder; choose another --out")
    names = store.files("") - {LOCK}
    if not names:
        return None
    if INDEX not in names:
        raise CampaignError(f"{store.uri} is not empty and is not a campaign (no {INDEX}); nothing was "
                            "written or deleted. Choose a new or empty location")
    return check_index(store.uri, read_store_index(store), fingerprint, resume)


def read_store_index(store: Store) -> dict:
    """The campaign index kept in ``store``."""
    try:
        index = json.loads(store.read_bytes(INDEX))
    except FileNotFoundError:
        raise CampaignError(f"{store.uri} is not a campaign (no {INDEX})") from None
    except ValueError as exc:
        raise CampaignError(f"{store.uri}/{INDEX} is not readable JSON ({exc})") from exc
    return index


def write_store_index(store: Store, index: dict) -> None:
    """Write the index (JSON, then the parquet table) into ``store``, each whole."""
    index["updated"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    store.write_bytes(INDEX, json.dumps(index, indent=1).encode())
    table = index_table_bytes(index)
    if table is not None:
        store.write_bytes(PARQUET, table)


class store_lock:
    """Hold ``.campaign.lock`` in ``store`` for a campaign's run; refuse if it is there."""

    def __init__(self, store: Store) -> None:
        self.store = store

    def __enter__(self):
        if self.store.isfile(LOCK):
            holder = self.store.read_bytes(LOCK).decode(errors="replace").strip()
            raise CampaignError(f"another campaign is running into {self.store.uri} (lock {LOCK}: {holder}); "
                                f"if none is (a campaign killed outright), delete {self.store.uri}/{LOCK}")
        self.store.write_bytes(LOCK, f"pid {os.getpid()} on {platform.node()} since "
                                     f"{_dt.datetime.now(_dt.UTC).isoformat(timespec='seconds')}\n".encode())
        return self.store.path(LOCK)

    def __exit__(self, *exc) -> None:
        self.store.remove(LOCK)


# --- the workers' side: stage locally, upload whole files --------------------------------------


def staging_dir(uri: str, name: str) -> Path:
    """This machine's staging folder of item ``name`` of the campaign at ``uri``."""
    base = Path(os.environ.get("LIPGEN_STAGING") or tempfile.gettempdir()) / "lipgen-stage"
    return base / hashlib.sha256(uri.encode()).hexdigest()[:16] / "items" / name


def job_files(job, settings) -> list[str]:
    """The files one job writes, relative to the dataset, in upload order (the truth last)."""
    from lipgen.dataset.manifest import calib_paths, extra_paths, frame_paths

    kind, i = job
    if kind == "calib":
        return [p.as_posix() for p in calib_paths("", i)]
    png, npz = frame_paths("", i)
    depth, mask = extra_paths("", i)
    extras = ([depth] if settings.depth else []) + ([mask] if settings.masks else [])
    return [p.as_posix() for p in (*extras, png, npz)]


def prepare_in_store(uri: str, name: str, settings: dict):
    """:func:`lipgen.campaign.stages.prepare` for a store: simulate, lay out the dataset in the
    staging folder, upload what is not yet in the store (the manifest first); the jobs still to
    do are those whose files are not all in the store."""
    from lipgen.campaign.stages import prepare
    from lipgen.dataset.layout import GenerateSettings

    store, rel = Store(uri), f"items/{name}/dataset"
    local = staging_dir(uri, name) / "dataset"
    shutil.rmtree(local, ignore_errors=True)  # the store is the truth; a stale local copy is not
    have = store.files(rel)
    if "manifest.json" in have:  # prepare then checks that the store holds this very dataset
        store.get_file(f"{rel}/manifest.json", local / "manifest.json")
    ctx, jobs, seconds = prepare(str(local), settings)
    s = GenerateSettings.from_dict(settings)
    jobs = [j for j in jobs if not set(job_files(j, s)) <= have]
    laid = sorted(p.relative_to(local).as_posix() for p in local.rglob("*") if p.is_file())
    for f in sorted(laid, key=lambda f: f != "manifest.json"):
        if f not in have:
            store.put_file(local / f, f"{rel}/{f}")
    return ctx, jobs, seconds


def render_chunk_in_store(uri: str, name: str, ctx, jobs: list) -> dict:
    """:func:`lipgen.campaign.stages.render_chunk` for a store: render into this machine's
    staging folder, upload each frame's files (its truth last), then drop the local copies."""
    from lipgen.campaign.stages import render_chunk
    from lipgen.dataset.layout import GenerateSettings

    store, rel = Store(uri), f"items/{name}/dataset"
    local = staging_dir(uri, name) / "dataset"
    for f in ("manifest.json", "mesh.npz"):
        if not (local / f).is_file():  # a machine that did not prepare this item
            store.get_file(f"{rel}/{f}", local / f)
    ctx = dataclasses.replace(ctx, out=str(local), mesh_path=str(local / "mesh.npz"))
    s = GenerateSettings.from_dict(ctx.settings)
    for job in jobs:
        for f in job_files(tuple(job), s):
            (local / f).parent.mkdir(parents=True, exist_ok=True)
    out = render_chunk(ctx, jobs)
    for job in jobs:
        for f in job_files(tuple(job), s):
            store.put_file(local / f, f"{rel}/{f}")
            (local / f).unlink()
    return out


def run_stage_in_store(stage: str, uri: str, name: str, options: dict) -> dict:
    """:func:`lipgen.campaign.stages.run_stage` for a store: download the item, run the stage
    in a temporary folder, upload the files it wrote or changed."""
    from lipgen.campaign.stages import run_stage

    store = Store(uri)
    with tempfile.TemporaryDirectory(prefix="lipgen-stage-") as tmp:
        item = Path(tmp) / name
        store.get_tree(f"items/{name}", item)

        def state() -> dict:
            return {p.relative_to(item).as_posix(): (p.stat().st_size, p.stat().st_mtime_ns)
                    for p in item.rglob("*") if p.is_file()}

        before = state()
        out = run_stage(stage, str(item), options)
        for f, st in sorted(state().items()):
            if before.get(f) != st:
                store.put_file(item / f, f"items/{name}/{f}")
    return out
