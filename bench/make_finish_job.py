#!/usr/bin/env python3
"""Write a ~1,000,000-line ball-end finishing raster over a relief, for
timing the cut simulator (bench/run.sh). The tool follows the relief
sample under its tip (not a drop-cutter: it gouges, which is fine for a
speed test): rows every 4 pixels, one point per pixel.

usage: make_finish_job.py RELIEF.png OUT.nc [rows_every_px]
"""
import json
import sys

import numpy as np
from PIL import Image

src, dst = sys.argv[1], sys.argv[2]
every = int(sys.argv[3]) if len(sys.argv) > 3 else 4
side = json.load(open(src[:-4] + ".json"))
v = np.asarray(Image.open(src), dtype=np.float64) / 65535.0
h, w = v.shape
p = side["width_mm"] / w
z = (v - 1.0) * side["depth_mm"]
out = ["(tool: ball:3.175)", "G21 G90 G17 G94", "M3 S12000", "G0 Z3"]
xs = (np.arange(w) + 0.5) * p
for k, j in enumerate(range(0, h, every)):
    y = side["height_mm"] - (j + 0.5) * p
    cols = range(w) if k % 2 == 0 else range(w - 1, -1, -1)
    out.append(f"G0 X{xs[cols[0]]:.3f} Y{y:.3f}")
    out.append(f"G1 Z{z[j, cols[0]]:.4f} F600")
    out.extend(f"X{xs[i]:.3f} Z{z[j, i]:.4f}" for i in cols)
    out.append("G0 Z3")
out += ["M5", "M30"]
open(dst, "w").write("\n".join(out) + "\n")
print(f"{dst}: {len(out)} lines")
