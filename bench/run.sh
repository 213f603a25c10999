#!/usr/bin/env bash
# Relief benchmarks (release mode). MODELS_DIR (default fixtures/) holds the
# models; the numpy comparison needs python3 with numpy, scipy, pillow.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q
R=target/release/relievo
M=${1:-fixtures}
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
wall() { /usr/bin/time -f "  wall %e s, peak RSS %M KB" "$@"; }

echo "== bunny (69451 triangles), 1024 px"
wall $R -v relief $M/stanford-bunny.obj --resolution 1024 -o "$T/b1k.png"
echo "== bunny, 4096 px"
wall $R -v relief $M/stanford-bunny.obj --resolution 4096 -o "$T/b4k.png"
echo "== flat background (masked multigrid CG) against the free (DCT) solve: spot, 2048 and 4096 px"
for res in 2048 4096; do
  wall $R -v relief fixtures/spot.obj --resolution $res -o "$T/free$res.png"
  wall $R -v relief fixtures/spot.obj --resolution $res --flat-background -o "$T/flat$res.png"
done
echo "== 2048 px depth PNG (the bunny's depth buffer), relievo vs numpy+scipy"
$R -q relief $M/stanford-bunny.obj --resolution 2048 -o "$T/x.png" --depth-out "$T/depth2k.png"
wall $R -v relief "$T/depth2k.png" -o "$T/r2k.png" --alpha 4 --silhouette 8 --depth 5
if python3 -c 'import numpy, scipy, PIL' 2>/dev/null; then
  wall python3 bench/numpy_relief.py "$T/depth2k.png" "$T/n2k.png" 4 8 5
else
  echo "  (numpy/scipy/pillow missing: pip install numpy scipy pillow)"
fi

echo "== simulator: ~1M-line finishing job on a 2048 x 2048 stock"
$R -q relief $M/stanford-bunny.obj --resolution 2048 --fov 0 -o "$T/sq.png" --width 100
if python3 -c 'import numpy, PIL' 2>/dev/null; then
  python3 bench/make_finish_job.py "$T/sq.png" "$T/finish.nc" 4
  wall $R -v simulate "$T/finish.nc" --relief "$T/sq.png" --stock 100x100x8 -o "$T/cut.png" --report "$T/report.json"
fi

echo "== toolpath: 2048 px, 100 mm relief, 3.175 ball, 10% stepover raster (CL + path + G-code)"
wall $R -v toolpath "$T/sq.png" -o "$T/finish-cam.nc" --machine shapeoko
echo "== the same, raster+waterline"
wall $R -v toolpath "$T/sq.png" -o "$T/finish-rw.nc" --machine shapeoko --finish raster+waterline
