import sys, numpy as np
from PIL import Image, ImageDraw
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.dots import ink_gray
ds = Dataset(sys.argv[1]); f = int(sys.argv[2]); v = int(sys.argv[3]); names = list(ds.marks)
t = load_truth(ds); img = ds.rig.split_views(ds[f].image)[v]
c = np.nanmean(t['uv'][f, v], 0).astype(int)
x0, y0 = c[0] - 30, c[1] - 35
crop = np.asarray(img)[y0:y0 + 70, x0:x0 + 100]
S = 6
im = Image.fromarray(crop).resize((100 * S, 70 * S), Image.NEAREST).convert('RGB')
d = ImageDraw.Draw(im)
for i, n in enumerate(names):
    u, w = (t['uv'][f, v, i] - [x0, y0] + 0.5) * S
    d.ellipse([u - 4, w - 4, u + 4, w + 4], outline=(0, 255, 0)); d.text((u + 5, w - 5), n[:10], fill=(0, 255, 0))
for p in sys.argv[5:]:
    u, w = (np.array([float(a) for a in p.split(',')]) - [x0, y0] + 0.5) * S
    d.line([u - 6, w, u + 6, w], fill=(255, 0, 0)); d.line([u, w - 6, u, w + 6], fill=(255, 0, 0))
im.save(sys.argv[4])
