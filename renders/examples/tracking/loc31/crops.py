import numpy as np, sys
from PIL import Image, ImageDraw
from lipgen.dataset.layout import Dataset
from lipgen.recon.dots import ink_gray, refine_centroids
tiles = []
for name in ("base", "sensor0", "bayer0", "png"):
    ds = Dataset(f"tog/{name}"); rig = ds.rig
    row = []
    for i in (6, 12):
        t = ds.truth(i); views = rig.split_views(ds[i].image)
        for v in (0, 1):
            uv = np.asarray(t["uv"][v]); vis = np.asarray(t["visible"][v], bool)
            got = refine_centroids(ink_gray(views[v]), uv, 1.26, window=1.25)
            for p in (5, 10, 11, 14):
                if not vis[p]: continue
                c = np.round(uv[p]).astype(int); r = 7
                crop = views[v][c[1]-r:c[1]+r+1, c[0]-r:c[0]+r+1]
                if crop.shape[:2] != (2*r+1, 2*r+1): continue
                S = 12
                im = Image.fromarray(crop).resize(((2*r+1)*S, (2*r+1)*S), Image.NEAREST)
                d = ImageDraw.Draw(im)
                for q, col in ((uv[p], (0, 255, 0)), (got[p], (255, 0, 255))):
                    x = (q[0] - c[0] + r + 0.5) * S; y = (q[1] - c[1] + r + 0.5) * S
                    d.line([x-6, y, x+6, y], fill=col, width=2); d.line([x, y-6, x, y+6], fill=col, width=2)
                d.text((2, 2), f"{name} f{i} {'VR'[v]} p{p} e={np.linalg.norm(got[p]-uv[p]):.2f}", fill=(255,255,0))
                row.append(im)
    tiles.append(row[:8])
W = max(len(r) for r in tiles); tw = tiles[0][0].size[0]
out = Image.new("RGB", (W * tw, len(tiles) * tw))
for j, r in enumerate(tiles):
    for i, im in enumerate(r): out.paste(im, (i * tw, j * tw))
out.save("crops.png")
