"""A campaign's folder: its layout, the lock that keeps a second campaign out, and the index.

Layout::

    DIR/campaign.json            the index: plan, fingerprint, and per item its settings, status,
                                 per-stage status, timings, errors, lipgen and package versions
    DIR/.campaign.lock           held (flock) by the running campaign
    DIR/items/NNNN/dataset/      the item's dataset, exactly as ``lipgen generate`` writes it
    DIR/items/NNNN/recon.npz     ``lipgen reconstruct``;  model.npz ``lipgen train``
    DIR/items/NNNN/report/       ``lipgen evaluate`` (report.md, report.json, pictures)
    DIR/items/NNNN/nrsfm.json    monocular NRSfM scores
    DIR/report/                  ``lipgen campaign report DIR``

The folder may be local or on a filesystem every worker mounts at the same path (NFS, a
cluster's shared volume); the lock needs a filesystem with working ``flock``.
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

from lipgen._io import atomic_write_json
from lipgen.errors import LipgenError

__all__ = ["CampaignError", "INDEX", "LOCK", "campaign_lock", "prepare_folder", "read_index", "write_index",
           "versions", "item_dir"]

INDEX, LOCK = "campaign.json", ".campaign.lock"
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
    """Write the index of campaign ``root`` atomically, stamped with the time."""
    index["updated"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    atomic_write_json(Path(root) / INDEX, index)


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
    index = read_index(root)
    if not resume:
        raise CampaignError(f"{root} already holds a campaign; pass --resume to continue it, or choose "
                            "another folder (nothing was overwritten)")
    if index.get("fingerprint") != fingerprint:
        raise CampaignError(f"{root} holds a campaign of another plan (fingerprint "
                            f"{index.get('fingerprint')}, this plan {fingerprint}); resume only with the "
                            "same plan, or choose another folder")
    return index
