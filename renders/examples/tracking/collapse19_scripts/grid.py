"""Frame 0, per view: marks found within 1.5 px / dots found, over detector scale x min_contrast."""
import sys
from pathlib import Path
import numpy as np
from lipgen.dataset.layout import Dataset
from lipgen.recon.dots import DotSettings, detect_dots
from lipgen.rig.camera import VIEWS

def main(name, frame=0):
    ds = Dataset(Path('/work/data')/name)
    views = ds.rig.split_views(np.asarray(ds[frame].image))
    tr = ds.truth(frame)
    for v, img in enumerate(views):
        truv = np.asarray(tr['uv'])[v]; vis = np.asarray(tr['visible'])[v]
        rows = []
        for s in (1.28, 1.6, 2.0, 2.5):
            cells = []
            for mc in (0.08, 0.06, 0.05, 0.04):
                uv, st = detect_dots(img, DotSettings(sigma=s, min_contrast=mc))
                d = np.linalg.norm(truv[:, None] - uv[None], axis=2).min(1) if len(uv) else np.full(len(truv), np.inf)
                cells.append(f'{int((vis & (d < 1.5)).sum()):2d}/{len(uv):3d}')
            rows.append(f'  s={s:4.2f}: ' + '  '.join(cells))
        print(f'{name} f{frame} {VIEWS[v]} (vis {int(vis.sum())}) mc 0.08 / 0.06 / 0.05 / 0.04')
        print('\n'.join(rows))

if __name__ == '__main__':
    for n in sys.argv[1:]:
        main(n)
