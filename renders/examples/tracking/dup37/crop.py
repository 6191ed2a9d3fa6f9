import sys, numpy as np, imageio.v3 as iio
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.pipeline import Reconstruction
name, f = sys.argv[1], int(sys.argv[2]); marks = [int(x) for x in sys.argv[3].split(",")]
ds = Dataset(f"/work/sets/{name}"); t = load_truth(ds)
r = Reconstruction.load(sys.argv[4])   # the reconstruction to draw
views = ds.rig.split_views(np.asarray(ds[f].image))
tiles = []
for v in range(2):
    img = np.asarray(views[v]).copy()
    c = t["uv"][f, v, marks].mean(0); u0, r0 = c.round().astype(int)
    crop = np.kron(img[r0-30:r0+30, u0-30:u0+30], np.ones((5, 5, 1), np.uint8)).copy()
    for m in range(17):
        for uv, col in ((t["uv"][f, v, m], [0, 255, 0]), (r.uv[v][f, m], [255, 0, 255])):
            if not np.all(np.isfinite(uv)): continue
            x, y = ((uv - c + 30) * 5 + 2).round().astype(int)
            if 2 <= y < 298 and 2 <= x < 298: crop[y-2:y+3, x-2:x+3] = col
    tiles.append(crop)
iio.imwrite(f"/work/b37/crop_{name}_{f}.png", np.concatenate(tiles, 1))
