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
import queue
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time

from generate import firmware_dir

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


def reader(stream, q):
    for raw in iter(stream.readline, b""):
        q.put(raw.decode("latin-1").strip())


def record(exe, line, axis, at):
    run = tempfile.mkdtemp(prefix="hold-")
    p = subprocess.Popen([exe, "-n", "-s", "/dev/null", "-b", "/dev/null"], cwd=run,
                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    q = queue.Queue()
    threading.Thread(target=reader, args=(p.stdout, q), daemon=True).start()

    def send(b):
        p.stdin.write(b)
        p.stdin.flush()

    def status(timeout=2.0):
        end = time.time() + timeout
        while time.time() < end:
            try:
                l = q.get(timeout=0.05)
            except queue.Empty:
                continue
            m = STATUS.match(l)
            if m:
                return m[1], [float(m[k]) for k in (2, 3, 4)], l
        return None

    try:
        time.sleep(1.5)  # the welcome
        send(line.encode() + b"\n")
        onset = None
        deadline = time.time() + 60
        while time.time() < deadline:
            send(b"?")
            st = status()
            if st and (st[1][axis] >= at if at > 0 else st[1][axis] <= at):
                send(b"!?")
                onset = status()
                break
            time.sleep(0.02)
        stop = None
        while onset and time.time() < deadline:
            time.sleep(0.1)
            send(b"?")
            st = status()
            if st and st[0] == "Hold" and st[2].startswith("<Hold:0"):
                stop = st
                break
        return {"f": "hold", "in": line, "onset": onset[1], "onset_report": onset[2],
                "stop": stop[1], "stop_report": stop[2]}
    finally:
        p.kill()
        shutil.rmtree(run, ignore_errors=True)


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
