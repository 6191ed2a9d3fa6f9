"""A campaign's folder: its layout, the lock that keeps a second campaign out, and the index.

Layout::

    DIR/campaign.json            the index: plan, fingerprint, and per item its settings, status,
                                 per-stage status, timings, errors, lipgen and package versions
    DIR/campaign.parquet         the same index as a table, one row per item (pyarrow; the JSON
                                 stays the one a resume reads)
    DIR/.campaign.lock           held (flock) by the running campaign
    DIR/items/NNNN/dataset/      the item's dataset, exactly as ``lipgen generate`` writes it
    DIR/items/NNNN/recon.npz     ``lipgen reconstruct``;  model.npz ``lipgen train``
    DIR/items/NNNN/report/       ``lipgen evaluate`` (report.md, report.json, pictures)
    DIR/items/NNNN/nrsfm.json    monocular NRSfM scores
    DIR/report/                  ``lipgen campaign report DIR``

The folder may be local or on a filesystem every worker mounts at the same path (NFS, a
cluster's shared volume); the lock needs a filesystem with working ``flock``. An object store
(``s3://...``) goes through fsspec instead: :mod:`lipgen.campaign.remote`.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import fcntl
import json
import os
import platform
from importlib import metadata
from pathlib import Path

from lipgen._io import atomic_write_bytes, atomic_write_json
from lipgen.errors import LipgenError

__all__ = ["CampaignError", "INDEX", "LOCK", "TABLE", "campaign_lock", "prepare_folder", "check_index",
           "read_index", "write_index", "versions", "item_dir", "index_table", "index_table_bytes",
           "index_from_table", "read_index_table"]

INDEX, LOCK, TABLE = "campaign.json", ".campaign.lock", "campaign.parquet"
FORMAT = "lipgen.campaign"
SCHEMA = 1
_PACKAGES = ("lipgen", "numpy", "scipy", "pyrender", "ray")


class CampaignError(LipgenError, ValueError):
    """A campaign folder that is another's, locked, or does not match the plan."""


def versions() -> dict:
    """Versions recorded with every item (the figures depend on them)."""
    out = {"python": platform.python_version(), "host": platform.node()}
    for pkg in _PACKAGES:
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def item_dir(root, name: str) -> Path:
    """The folder of item ``name`` in campaign ``root``."""
    return Path(root) / "items" / name


def read_index(root) -> dict:
    """The campaign index of folder ``root``."""
    p = Path(root) / INDEX
    if not p.is_file():
        raise CampaignError(f"{root} is not a campaign folder (no {INDEX}); run lipgen campaign PLAN --out "
                            f"{root} first")
    try:
        index = json.loads(p.read_text())
    except (OSError, ValueError) as exc:
        raise CampaignError(f"{p} is not readable JSON ({exc})") from exc
    if not isinstance(index, dict) or index.get("format") != FORMAT or index.get("schema_version") != SCHEMA:
        raise CampaignError(f"{p} is not a lipgen campaign index of schema {SCHEMA}")
    return index


def write_index(root, index: dict) -> None:
    """Write the index of campaign ``root`` atomically, stamped with the time: ``campaign.json``
    and (with pyarrow) ``campaign.parquet``."""
    index["updated"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    atomic_write_json(Path(root) / INDEX, index)
    table = index_table_bytes(index)
    if table is not None:
        atomic_write_bytes(Path(root) / TABLE, table)


_META = ("format", "schema_version", "name", "fingerprint", "plan", "swept_keys", "created", "updated",
         "lipgen_version", "versions", "runs")
_STAGE_COLUMNS = (("status", "string"), ("seconds", "float64"), ("task_seconds", "float64"),
                  ("error", "string"))


def index_table(index: dict):
    """The index as a ``pyarrow.Table``: one row per item.

    Columns: ``item``, ``status``, one column per swept key (its values), and per stage
    ``STAGE.status``, ``STAGE.seconds``, ``STAGE.task_seconds``, ``STAGE.error``; the full
    records are kept as JSON text (``settings``, ``swept``, ``stages``) and the campaign's own
    fields (plan, fingerprint, versions, runs ...) in the schema metadata, so
    :func:`index_from_table` gives the index back.
    """
    import pyarrow as pa

    items = index["items"]
    cols: dict = {"item": pa.array([e["name"] for e in items], pa.string()),
                  "status": pa.array([e["status"] for e in items], pa.string())}
    for key in index.get("swept_keys", []):
        values = [e.get("swept", {}).get(key) for e in items]
        try:
            cols[key] = pa.array(values)
        except (pa.ArrowInvalid, pa.ArrowTypeError):  # mixed types: as JSON text
            cols[key] = pa.array([json.dumps(v) for v in values], pa.string())
    stages = list(dict.fromkeys(s for e in items for s in e.get("stages", {})))
    for stage in stages:
        for field, typ in _STAGE_COLUMNS:
            cols[f"{stage}.{field}"] = pa.array([e["stages"].get(stage, {}).get(field) for e in items], typ)
    for field in ("settings", "swept", "stages"):
        cols[field] = pa.array([json.dumps(e.get(field)) for e in items], pa.string())
    meta = {k: json.dumps(index[k]) for k in _META if k in index}
    return pa.table(cols).replace_schema_metadata({"lipgen.campaign": json.dumps(meta)})


def index_table_bytes(index: dict) -> bytes | None:
    """:func:`index_table` as parquet bytes; None when pyarrow is not installed."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    sink = pa.BufferOutputStream()
    pq.write_table(index_table(index), sink)
    return sink.getvalue().to_pybytes()


def index_from_table(table) -> dict:
    """The index dict back from :func:`index_table`'s table."""
    meta = json.loads((table.schema.metadata or {}).get(b"lipgen.campaign", b"{}"))
    index = {k: json.loads(v) for k, v in meta.items()}
    rows = table.select(["item", "status", "settings", "swept", "stages"]).to_pylist()
    index["items"] = [{"name": r["item"], "settings": json.loads(r["settings"]),
                       "swept": json.loads(r["swept"]), "status": r["status"],
                       "stages": json.loads(r["stages"])} for r in rows]
    return index


def read_index_table(root):
    """``campaign.parquet`` of campaign ``root`` as a ``pyarrow.Table`` (needs pyarrow)."""
    from lipgen._optional import require

    pq = require("pyarrow.parquet", "reading campaign.parquet")
    p = Path(root) / TABLE
    if not p.is_file():
        raise CampaignError(f"{root} has no {TABLE}; it is written with campaign.json when pyarrow is "
                            "installed (pip install 'lipgen[cluster]')")
    return pq.read_table(p)


@contextlib.contextmanager
def campaign_lock(root):
    """Hold the folder's lock for the campaign's lifetime; refuse if another process holds it.

    The kernel drops the lock when the holder dies, so a killed campaign can be resumed.
    """
    path = Path(root) / LOCK
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = Path(path).read_text().strip() or "?"
            raise CampaignError(f"another campaign is running into {root} (lock {path} held by {holder}); "
                                "wait for it, or choose another --out") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"pid {os.getpid()} on {platform.node()}\n".encode())
        yield path
    finally:
        os.close(fd)  # closing releases the lock


def prepare_folder(root, fingerprint: str, resume: bool) -> dict | None:
    """Check that ``root`` may receive this campaign, before anything is written.

    Returns the existing index when resuming, else None (a new or empty folder). Nothing is
    ever deleted.

    Raises
    ------
    CampaignError
        ``root`` is a file, holds something that is not a campaign, holds a campaign and
        ``resume`` is False, or holds another plan's campaign.
    """
    root = Path(root)
    if root.exists() and not root.is_dir():
        raise CampaignError(f"{root} exists and is a file, not a campaign folder; choose another --out")
    if not root.is_dir() or not any(p.name != LOCK for p in root.iterdir()):
        return None
    if not (root / INDEX).is_file():
        raise CampaignError(f"{root} is not empty and is not a campaign folder (no {INDEX}); nothing was "
                            "written or deleted. Choose a new or empty folder")
    return check_index(root, read_index(root), fingerprint, resume)


def check_index(where, index: dict, fingerprint: str, resume: bool) -> dict:
    """``index`` (found at ``where``) when this plan may resume it; else a ``CampaignError``."""
    if not isinstance(index, dict) or index.get("format") != FORMAT or index.get("schema_version") != SCHEMA:
        raise CampaignError(f"{where}/{INDEX} is not a lipgen campaign index of schema {SCHEMA}")
    if not resume:
        raise CampaignError(f"{where} already holds a campaign; pass --resume to continue it, or choose "
                            "another folder (nothing was overwritten)")
    if index.get("fingerprint") != fingerprint:
        raise CampaignError(f"{where} holds a campaign of another plan (fingerprint "
                            f"{index.get('fingerprint')}, this plan {fingerprint}); resume only with the "
                            "same plan, or choose another folder")
    return index
