#!/usr/bin/env python3
"""Lower bounds on the moves a finishing raster needs at a tolerance.

Reads CL rows (`cargo run --release --example cl_rows -- RELIEF OUT`) and
counts, row by row, the fewest pieces a path within the band over the
dropped CL points can be cut into, greedily (longest piece first; for a
property every sub-interval of a feasible interval keeps, greedy is
optimal). Pieces may start anywhere in the band, unlike a G-code path,
which must be continuous: so the count is a lower bound.

  lines: straight pieces within [CL, CL + tol * sqrt(1 + slope^2)]
         (merging measures its band square to the move);
  arcs:  an estimate, not a bound: parabolas within [CL, CL + tol - $12]
         (GRBL cuts an arc into chords that sag about its $12 arc
         tolerance, 0.002 mm, under the arc, so an arc whose chords keep
         the band has about tol - $12 left for its own shape; a circle of
         over ~20 mm radius is a parabola within 0.1 um over the pieces
         found). Chord ends on the circle lie on the arc itself, so a
         rigorous bound would have to allow [CL, CL + tol + sag]; it is
         not computed here.

usage: line_bound.py ROWS.txt [TOL] [EVERY]   (EVERY: every n-th row, scaled)
Needs numpy and scipy.
"""
import sys
import numpy as np
from scipy.optimize import linprog


def feasible(u, z, lo, hi, deg):
    s = u - u[0]
    v = np.vstack([s**k for k in range(deg + 1)]).T
    a = np.vstack([v, -v])
    b = np.concatenate([z + hi, -(z + lo)])
    r = linprog(np.zeros(deg + 1), A_ub=a, b_ub=b,
                bounds=[(None, None)] * (deg + 1), method="highs")
    return r.status == 0


def pieces(u, z, lo, hi, deg):
    n, a, count = len(u), 0, 0
    ok = lambda e: feasible(u[a:e + 1], z[a:e + 1], lo[a:e + 1], hi[a:e + 1], deg)
    while a < n - 1:
        good, step = a + 1, 1
        while a + step < n and ok(a + step):
            good, step = a + step, step * 2
        bad = min(a + step, n)
        while bad - good > 1:
            m = (good + bad) // 2
            if ok(m):
                good = m
            else:
                bad = m
        count, a = count + 1, good
    return count


def main():
    d = np.loadtxt(sys.argv[1])
    tol = float(sys.argv[2]) if len(sys.argv) > 2 else 0.005
    every = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    rows = np.unique(d[:, 0]).astype(int)
    lines = arcs = 0
    for k in rows[::every]:
        r = d[d[:, 0] == k]
        u, z = r[:, 1], r[:, 3]
        wide = np.sqrt(1 + np.gradient(z, u) ** 2)
        zero = np.zeros_like(z)
        lines += pieces(u, z, zero, tol * wide, 1)
        arcs += pieces(u, z, zero, np.full_like(z, tol - 0.002), 2)
    scale = len(rows) / len(rows[::every])
    print(f"{len(rows)} rows: at least {lines * scale:.0f} straight moves, "
          f"{arcs * scale:.0f} arcs or moves (tolerance {tol} mm)")


if __name__ == "__main__":
    main()
