import numpy as np
from lipgen.recon.stereo_init import _similarity_3d


def subject_layout(rest, rec, least=10):
    M = np.where(rec.visible[..., None], rec.markers, np.nan)
    med = np.nanmedian(M, axis=0)
    n = rec.visible.sum(0)
    lay = rest.copy()
    ok = n >= least
    T = _similarity_3d(med[ok], rest[:-1][ok])
    lay[:-1][ok] = med[ok] @ T[:3, :3].T + T[:3, 3]
    return lay, ok


