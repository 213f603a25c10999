#!/usr/bin/env python3
"""The depth-PNG relief pipeline of DESIGN.md section 2 in numpy + scipy's
DCT, as a baseline for relievo's speed (bench/run.sh). Same steps as
`relievo relief DEPTH.png`: slopes, per-edge outline zeroing, compression,
Neumann Poisson by DCT, min to 0, scale, 16-bit PNG out.

usage: numpy_relief.py IN.png OUT.png [alpha theta depth]
"""
import sys
import time

import numpy as np
from PIL import Image
from scipy import fft


def relief(h, alpha, theta, depth):
    H, W = h.shape
    n = max(W, H)
    gx = np.zeros_like(h)
    gy = np.zeros_like(h)
    gx[:, :-1] = n * (h[:, 1:] - h[:, :-1])
    gy[:-1, :] = n * (h[1:, :] - h[:-1, :])
    gx[np.abs(gx) > theta] = 0.0
    gy[np.abs(gy) > theta] = 0.0
    m = np.hypot(gx, gy)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(m > 0, np.log1p(alpha * m) / (alpha * m), 0.0)
    gx *= c / n
    gy *= c / n
    d = np.zeros_like(h)
    ex = gx.copy()
    ex[:, -1] = 0.0
    ey = gy.copy()
    ey[-1, :] = 0.0
    d += ex
    d[:, 1:] -= ex[:, :-1]
    d += ey
    d[1:, :] -= ey[:-1, :]
    f = fft.dctn(d, type=2, workers=2)
    lx = 2.0 * np.cos(np.pi * np.arange(W) / W) - 2.0
    ly = 2.0 * np.cos(np.pi * np.arange(H) / H) - 2.0
    lam = ly[:, None] + lx[None, :]
    lam[0, 0] = 1.0
    f /= lam
    f[0, 0] = 0.0
    u = fft.idctn(f, type=2, workers=2)
    u -= u.min()
    return u / u.max() * depth


def main():
    src, dst = sys.argv[1], sys.argv[2]
    alpha, theta, depth = (float(x) for x in (sys.argv[3:6] or [4, 8, 5]))
    t0 = time.perf_counter()
    h = np.asarray(Image.open(src), dtype=np.float64) / 65535.0
    t1 = time.perf_counter()
    r = relief(h, alpha, theta, depth)
    t2 = time.perf_counter()
    Image.fromarray(np.round(r / depth * 65535).astype(np.uint16)).save(dst)
    t3 = time.perf_counter()
    print(f"numpy+scipy: load {1e3*(t1-t0):.0f} ms, relief {1e3*(t2-t1):.0f} ms, "
          f"save {1e3*(t3-t2):.0f} ms, total {1e3*(t3-t0):.0f} ms")


if __name__ == "__main__":
    main()
