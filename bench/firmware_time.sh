#!/usr/bin/env bash
# How long does a job take on GRBL 1.1h itself, and what do relievo's
# estimates say? The firmware (grbl_sim.exe, built by
# ../shared/peers/grbl/build.sh) runs the job on a pseudo-terminal, fed by
# `relievo send`; its machine time is read from its own step log (-r 0.01
# -s FILE: the simulated clock every 10 ms of motion and at each block's
# end), from the first move's start to the last move's end, so the host's
# speed does not count. Beside it: `relievo simulate`'s estimate and the
# job header's, both less the dwells before the first move (GRBL dwells
# before its first block, where the step log does not yet run). And
# relievo's simulated GRBL's machine time on the same job, in its own
# clock (benches/grbl_time.rs). The firmware is given the machine file's
# rates, accelerations, steps, travel and junction deviation first ($100-
# $132, $11, into its EEPROM), so all four run the same machine.
#   bench/firmware_time.sh GRBL_SIM_EXE JOB.nc RELIEF.png [MACHINE]
set -euo pipefail
cd "$(dirname "$0")/.."
FW=$(realpath "$1"); JOB=$(realpath "$2"); RELIEF=$(realpath "$3"); MACHINE=${4:-grbl-generic}
B=${RELIEVO:-$PWD/target/release/relievo}
T=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$T"' EXIT
pin=(); command -v taskset >/dev/null && pin=(taskset -c 0)
settings=$(python3 - "machines/$MACHINE.toml" <<'EOF'
import sys, tomllib
m = tomllib.load(open(sys.argv[1], 'rb'))
print(f"$11={m['junction_deviation']}")
for base, key in ((100, 'steps_per_mm'), (110, 'max_rate'), (120, 'acceleration'), (130, 'travel')):
    for k, axis in enumerate('xyz'):
        if key in m:
            print(f"${base + k}={m[key][axis]}")
EOF
)
(cd "$T" && { sleep 1.5; for l in $settings; do printf '%s\n' "$l"; sleep 0.2; done; printf '$$\n'; sleep 1.5; } | "$FW" -n -s /dev/null -b /dev/null > "$T/settings.log" 2>&1 || true)
(cd "$T" && socat PTY,raw,echo=0,link="$T/tty" \
  "EXEC:'${pin[*]} $FW -n -r 0.01 -s $T/steps.log -b /dev/null',pty,raw,echo=0") &
for _ in $(seq 50); do [ -e "$T/tty" ] && break; sleep 0.1; done
sleep 1.5
wall0=$(date +%s.%N)
"$B" -q send --port "$T/tty" --on-pause continue --journal "$T/j" "$JOB"
wall=$(echo "$(date +%s.%N) - $wall0" | bc)
"$B" -q simulate "$JOB" --relief "$RELIEF" --machine "$MACHINE" --report "$T/sim.json" -o "$T/cut.png"
cargo bench -q --bench grbl_time -- "$JOB" "$MACHINE" 2>/dev/null | tail -1
python3 - "$T/steps.log" "$T/sim.json" "$JOB" "$wall" <<'EOF'
import json, re, sys
steps, report, job, wall = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
times = [float(l.split()[0]) for l in open(steps) if l[:1] not in ('#', '') and l.strip()]
firmware = times[-1] - times[0]
lead = 0.0
header = None
for l in open(job):
    m = re.match(r'\(estimated time: (?:(\d+)h )?(\d+)m (\d+)s', l)
    if m: header = int(m[1] or 0) * 3600 + int(m[2]) * 60 + int(m[3])
    code = l.split('(')[0].upper().replace(' ', '')
    if re.search(r'G0?[01].*[XYZ]|^[XYZ]', code) and not code.startswith('G4'): break
    d = re.match(r'G0?4P([\d.]+)', code)
    if d: lead += float(d[1])
sim = json.load(open(report))['time_s'] - lead
print(f"firmware machine time {firmware:.3f} s (wall {wall:.1f} s); simulate {sim:.3f} s "
      f"(ratio {sim / firmware:.4f})" + (f"; header {header - lead:.0f} s (ratio {(header - lead) / firmware:.4f})" if header else "")
      + f"; dwells before the first move {lead:g} s left out")
EOF
