#!/usr/bin/env bash
# Do two relievo binaries make the same files? For a change that must not
# change any output (a refactor): the named set of jobs, reliefs,
# simulations, reports and the studio's downloads made by each, then
# compared byte for byte.
#   bench/same-outputs.sh BEFORE_BINARY AFTER_BINARY
set -euo pipefail
cd "$(dirname "$0")/.."
F=$PWD/fixtures
make_set() { # BINARY DIR
  local B=$1 O=$2
  rm -rf "$O"; mkdir -p "$O/demo"
  (
    cd "$O"
    export RELIEVO_CONFIG=$O/none.toml
    (cd demo && "$B" -q carve)
    "$B" -q relief "$F/suzanne.stl" -o suz.png --resolution 512
    "$B" -q toolpath suz.png -o suz-rw.nc --finish raster+waterline --svg suz-rw.svg
    "$B" -q simulate suz-rw.nc --relief suz.png --report suz-rw.json --deviation suz-rw-dev.png
    "$B" -q relief "$F/stanford-bunny.obj" -o bunny.png --resolution 2048
    "$B" -q toolpath bunny.png -o bunny.nc --tool ball:1
    "$B" -q simulate bunny.nc --relief bunny.png --report bunny-sim.json
    "$B" -q toolpath suz.png -o flat2.nc --tool flat:2 --rough flat:6
    "$B" -q simulate flat2.nc --relief suz.png --report flat2.json
    "$B" -q toolpath suz.png -o taper.nc --tool taperball:0.25:10 --finish waterline
    "$B" -q simulate taper.nc --relief suz.png --report taper.json
    "$B" -q toolpath suz.png -o tiles.nc --tile 50x40 --z-zero bottom --stock 120x80x12
    "$B" -q toolpath suz.png -o rest.nc --tool ball:3.175 --rest ball:1
    "$B" -q simulate rest.nc --relief suz.png --report rest.json
    "$B" -q toolpath suz.png -o cut.nc --cutout --stock 120x90x12
    "$B" -q toolpath suz.png -o vbit.nc --tool vbit:60:6 --units in --arcs on
    # the studio's downloads for the demo (its POSTs carry the page's secret)
    local port=$((17000 + RANDOM % 1000))
    "$B" -q studio --port $port >/dev/null 2>&1 &
    local pid=$!
    sleep 1.5
    local url=http://127.0.0.1:$port
    local secret
    secret=$(curl -s "$url/" | sed -n 's/.*name="relievo-secret" content="\([0-9a-f]*\)".*/\1/p')
    curl -s -X POST -H "X-Relievo-Secret: $secret" -d '{}' "$url/api/job" -o /dev/null
    for f in job.nc job.svg relief.png relief.json relief.stl; do
      curl -s "$url/api/download/$f" -o "studio-$f"
    done
    kill $pid
    rm -f none.toml
  )
}
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
make_set "$(realpath "$1")" "$T/before"
make_set "$(realpath "$2")" "$T/after"
echo "$(find "$T/before" -type f | wc -l) files each"
diff -rq "$T/before" "$T/after" && echo "identical"
