#!/usr/bin/env python3
"""Records feed holds on GRBL 1.1h itself (grbl_sim.exe, the firmware on
simulated hardware, on its default settings) into holds.jsonl: a move is
sent, and once the machine is cruising, '!' and '?' go together. The
report that '?' brings is where the hold began (GRBL reports before it
acts on the hold); the machine then decelerates along its path, and the
report once it stands in Hold:0 is where it stopped.

Usage: record_holds.py [--grbl DIR] [--out FILE]
  --grbl DIR  a built GRBL 1.1h, as for generate.py (by default the one
              the firmware tests build, target/tmp/grbl-firmware)
grbl_sim.exe runs in real time: about 10 s a scenario. Run it on a quiet
host (its two threads spin).
"""
import argparse
import json
import os
import re
import sys
import time

from generate import firmware_dir
from record_transcripts import Firmware

HERE = os.path.dirname(os.path.abspath(__file__))

# (the move, the axis to watch, where to hold on it: mm past the start)
SCENARIOS = [
    ("G1 X60 F300", 0, 15.0),
    ("G1 X60 F400", 0, 20.0),
    ("G1 X60 F500", 0, 25.0),
    ("G1 Y60 F500", 1, 30.0),
    ("G1 Z-40 F300", 2, -12.0),
    ("G1 X40 Y30 F500", 0, 16.0),
    ("G0 X60", 0, 30.0),
    ("G0 Y-50", 1, -20.0),
    ("G1 X30 Y-40 Z-10 F450", 0, 12.0),
]

STATUS = re.compile(r"<([A-Za-z]+)(?::\d)?\|MPos:(-?[\d.]+),(-?[\d.]+),(-?[\d.]+)")


def record(exe, line, axis, at):
    fw = Firmware(exe)

    def status(timeout=2.0):
        end = time.time() + timeout
        while time.time() < end:
            l = fw.line(0.05)
            m = l and STATUS.match(l.strip())
            if m:
                return m[1], [float(m[k]) for k in (2, 3, 4)], l.strip()
        return None

    try:
        time.sleep(1.5)  # the welcome
        fw.send(line + "\n")
        onset = None
        deadline = time.time() + 60
        while time.time() < deadline:
            fw.send("?")
            st = status()
            if st and (st[1][axis] >= at if at > 0 else st[1][axis] <= at):
                fw.send("!?")
                onset = status()
                break
            time.sleep(0.02)
        stop = None
        while onset and time.time() < deadline:
            time.sleep(0.1)
            fw.send("?")
            st = status()
            if st and st[0] == "Hold" and st[2].startswith("<Hold:0"):
                stop = st
                break
        return {"f": "hold", "in": line, "onset": onset[1], "onset_report": onset[2],
                "stop": stop[1], "stop_report": stop[2]}
    finally:
        fw.close()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grbl")
    ap.add_argument("--out", default=os.path.join(HERE, "holds.jsonl"))
    a = ap.parse_args()
    exe = os.path.join(firmware_dir(a.grbl), "grbl-sim", "grbl_sim.exe")
    out = []
    for line, axis, at in SCENARIOS:
        r = record(exe, line, axis, at)
        print(r, file=sys.stderr)
        out.append(r)
    with open(a.out, "w") as f:
        for r in out:
            f.write(json.dumps(r) + "\n")
    print("%d holds -> %s" % (len(out), a.out))


if __name__ == "__main__":
    sys.exit(main())
