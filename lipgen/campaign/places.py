"""Where a campaign is kept: a folder (local or shared), or an object store through fsspec.

The driver (:mod:`lipgen.campaign.run`) talks to either through the same calls: check that the
place may receive this campaign, hold its lock, read and write the index, tell whether a
finished dataset lost files, and submit each item's tasks with the arguments they need there.
"""

from __future__ import annotations

from pathlib import Path

from lipgen.campaign.remote import (
    Store,
    check_store,
    is_uri,
    job_files,
    prepare_in_store,
    read_store_index,
    render_chunk_in_store,
    run_stage_in_store,
    store_lock,
    write_store_index,
)
from lipgen.campaign.stages import prepare, render_chunk, run_stage
from lipgen.campaign.store import campaign_lock, item_dir, prepare_folder, read_index, write_index

__all__ = ["FolderPlace", "StorePlace", "place_of"]


class FolderPlace:
    """A campaign folder, local or on a filesystem every worker mounts at the same path."""

    def __init__(self, root) -> None:
        self.root = Path(root)
        self.uri = str(self.root)

    def check(self, fingerprint: str, resume: bool) -> dict | None:
        """The index to resume, or None (new); ``CampaignError`` if the folder is not for us."""
        return prepare_folder(self.root, fingerprint, resume)

    def create(self) -> None:
        """Make the folder."""
        self.root.mkdir(parents=True, exist_ok=True)

    def lock(self):
        """The campaign's lock (a context)."""
        return campaign_lock(self.root)

    def read_index(self) -> dict:
        """The index."""
        return read_index(self.root)

    def write_index(self, index: dict) -> None:
        """Write the index (JSON and parquet), atomically."""
        write_index(self.root, index)

    def incomplete(self, name: str, settings: dict) -> bool:
        """Whether item ``name``'s dataset lacks a frame or calibration file (no image is read)."""
        from lipgen.dataset.layout import Dataset
        from lipgen.errors import DatasetError

        dataset = item_dir(self.root, name) / "dataset"
        try:
            ds = Dataset(dataset)
        except DatasetError:
            return True
        calib = ds.manifest["calibration"]["frames"]
        calib_ok = all((dataset / f[k]).is_file() for f in calib for k in ("raw", "truth"))
        return bool(ds.missing()) or not calib_ok

    def submit_prepare(self, ex, name: str, settings: dict):
        """Submit the simulate-and-lay-out task of item ``name``."""
        item_dir(self.root, name).mkdir(parents=True, exist_ok=True)
        return ex.submit(prepare, str(item_dir(self.root, name) / "dataset"), settings)

    def submit_chunk(self, ex, name: str, ctx, jobs: list):
        """Submit one chunk of frames of item ``name``."""
        return ex.submit(render_chunk, ctx, jobs)

    def submit_stage(self, ex, stage: str, name: str, options: dict):
        """Submit a stage after generate of item ``name``."""
        return ex.submit(run_stage, stage, str(item_dir(self.root, name)), options)


class StorePlace(FolderPlace):
    """A campaign in an object store (``s3://``, ``gs://``, ``file://`` ...; see
    :mod:`lipgen.campaign.remote`)."""

    def __init__(self, uri: str) -> None:
        self.store = Store(uri)
        self.uri = uri

    def check(self, fingerprint: str, resume: bool) -> dict | None:
        """The index to resume, or None (new); ``CampaignError`` if the location is not for us."""
        return check_store(self.store, fingerprint, resume)

    def create(self) -> None:
        """Nothing: an object store has no folders to make."""

    def lock(self):
        """The campaign's lock object (a context)."""
        return store_lock(self.store)

    def read_index(self) -> dict:
        """The index."""
        return read_store_index(self.store)

    def write_index(self, index: dict) -> None:
        """Write the index (JSON and parquet), each object whole."""
        write_store_index(self.store, index)

    def incomplete(self, name: str, settings: dict) -> bool:
        """Whether item ``name``'s dataset in the store lacks a file its settings ask for."""
        from lipgen.dataset.layout import GenerateSettings

        s = GenerateSettings.from_dict(settings)
        have = self.store.files(f"items/{name}/dataset")
        want = {"manifest.json", "mesh.npz"}
        want.update(f for i in range(s.calib_frames) for f in job_files(("calib", i), s))
        want.update(f for i in range(s.frames) for f in job_files(("frame", i), s))
        return not want <= have

    def submit_prepare(self, ex, name: str, settings: dict):
        """Submit the simulate-and-lay-out task of item ``name`` (staged, then uploaded)."""
        return ex.submit(prepare_in_store, self.uri, name, settings)

    def submit_chunk(self, ex, name: str, ctx, jobs: list):
        """Submit one chunk of frames of item ``name`` (staged, then uploaded)."""
        return ex.submit(render_chunk_in_store, self.uri, name, ctx, jobs)

    def submit_stage(self, ex, stage: str, name: str, options: dict):
        """Submit a stage after generate of item ``name`` (downloaded, run, uploaded)."""
        return ex.submit(run_stage_in_store, stage, self.uri, name, options)


def place_of(out):
    """A :class:`StorePlace` for a URL (``scheme://...``), else a :class:`FolderPlace`."""
    return StorePlace(out) if is_uri(out) else FolderPlace(out)
