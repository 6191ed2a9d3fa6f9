import sys, numpy as np
sys.path.insert(0, "/work/b35")
from ffh import setup
from lipgen.dataset.layout import Dataset
from lipgen.evaluate.scoring import load_truth
from lipgen.recon.dots import ink_gray
from PIL import Image, ImageDraw
path, k, v = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
g = setup(path); ds = Dataset(path); t = load_truth(ds)
img = g["rig"].split_views(np.asarray(ds[k].image))[v]; uv = t["uv"][k, v]
lo = np.floor(np.nanmin(uv[:-1], 0) - 15).astype(int); hi = np.ceil(np.nanmax(uv[:-1], 0) + 15).astype(int)
ch = int(sys.argv[5]) if len(sys.argv) > 5 else -1
crop = ink_gray(img)[lo[1]:hi[1], lo[0]:hi[0]] if ch < 0 else img[lo[1]:hi[1], lo[0]:hi[0], ch] / 255.
a, b = np.percentile(crop, [1, 99]); crop = np.clip((crop - a) / (b - a), 0, 1)
s = 6
im = Image.fromarray((crop * 255).astype(np.uint8)).convert("RGB").resize((crop.shape[1]*s, crop.shape[0]*s), Image.NEAREST)
d = ImageDraw.Draw(im)
for (c, r) in uv[:-1]:
    x, y = (c - lo[0] + 0.5)*s, (r - lo[1] + 0.5)*s
    d.ellipse([x-5, y-5, x+5, y+5], outline=(0, 255, 0))
im.save(sys.argv[4])
