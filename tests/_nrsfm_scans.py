"""One ``DaiScan`` per sequence for the tests that call ``reconstruct_auto`` several times on it.

``DaiScan`` keeps each K's two ``dai`` stages, each bit for bit ``reconstruct(W, k, "dai")``
(tests/test_nrsfm_kscan.py checks it against the exhaustive search). ``scan_smooth`` decides which
Ks to finish from its own record of finished roughness, not from what the scan holds, so a shared
scan changes no answer: it only runs each K's stages once where a test asks for ``k="auto"`` again
with another ``consensus``, ``support`` or ``rho``.
"""

import numpy as np

from lipgen.nrsfm import kchoice
from lipgen.nrsfm.kscan import DaiScan

__all__ = ["share_dai_scans"]


def share_dai_scans(monkeypatch) -> dict:
    """Make ``reconstruct_auto`` reuse one ``DaiScan`` per (tracks, visibility, options) for the rest of
    the test; returns the scans made (key -> DaiScan), for a test to count them."""
    scans: dict = {}

    def shared(W, visible=None, **options):
        tracks = np.asarray(W, dtype=float)
        seen = None if visible is None else np.asarray(visible, dtype=bool).tobytes()
        key = (tracks.shape, tracks.tobytes(), seen, tuple(sorted(options.items())))
        if key not in scans:
            scans[key] = DaiScan(W, visible, **options)
        return scans[key]

    monkeypatch.setattr(kchoice, "DaiScan", shared)
    return scans
