#!/usr/bin/env python3
"""Records protocol scenarios on GRBL 1.1h itself (grbl_sim.exe, the
firmware on simulated hardware, on its default settings and a fresh
EEPROM) into transcripts.jsonl: what the firmware printed for each step of
a scenario, for tests/conformance.rs to hold relievo's simulated GRBL to.

A scenario is a list of steps; each sends bytes (lines and realtime
commands) and then waits, in one of three ways both this recorder and the
test's replay understand:
  "answers"          until every line sent is answered (ok / error:N), or
                     3 s (GRBL takes no line in a hold)
  {"at": [axis, v], "then": s}
                     polling '?' until the machine passes v on that axis,
                     then the bytes go at once, and s seconds more
  {"wait": s}        s seconds, without a poll
and then polls '?' once (unless "poll" is false). Kept per step:
  heard    every line but status reports, in order
  report   the status report of the closing poll
  trigger  the last report of an "at" wait, and polls: how many '?' it took
           (GRBL's report counters count them: the replay sends as many)

No scenario overflows the receive buffer: grbl_sim.exe reads its stdin only
while GRBL's receive ring has room (simulate_serial in its serial.c), as a
pipe with flow control would, where the AVR's UART drops the bytes. That
case is the simulated GRBL's unit test (src/grbl/sim).

Usage: record_transcripts.py [--grbl DIR] [--out FILE] [--only A,B]
  --only A,B  record these scenarios again, keeping the others
  --grbl DIR  a built GRBL 1.1h, as for generate.py (by default the one
              the firmware tests build, target/tmp/grbl-firmware)
grbl_sim.exe runs in real time: 5 to 20 s a scenario. Run it on a quiet
host (its two threads spin); the waits leave room for it to lag.
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

RESET, HOLD, START, STATUS = "\x18", "!", "~", "?"
DOOR, JOG_CANCEL, SPINDLE_STOP = "\x84", "\x85", "\x9e"
FEED_UP, FEED_DOWN, FEED_RESET = "\x91", "\x92", "\x90"
RAPID_50, SPINDLE_UP = "\x96", "\x9a"


def at(axis, v, then):
    return {"at": [axis, v], "then": then}


def wait(s):
    return {"wait": s}


A = "answers"

# name -> steps (bytes to send, how to wait)
SCENARIOS = {
    "hold_and_resume": [
        ("G1 X30 F400\n", A), (HOLD, at(0, 8.0, 2.0)), (START, wait(5.0))],
    "reset_mid_move": [
        ("G1 X30 F400\n", A), (RESET, at(0, 10.0, 1.5)), ("G0 X1\n", A),
        ("$X\n", A), ("G0 X0\n", A), ("", wait(3.0))],
    "reset_in_a_finished_hold": [
        ("G1 X30 F400\n", A), (HOLD, at(0, 6.0, 2.0)), (RESET, wait(1.5)),
        ("$X\n", A)],
    "reset_when_idle": [
        ("G1 X2 F400\n", A), ("", wait(1.5)), (RESET, wait(1.5)), ("G0 X0\n", A),
        ("", wait(1.5))],
    "jog_and_cancel": [
        ("$J=G91 X30 F600\n", A), (JOG_CANCEL, at(0, 5.0, 1.0)),
        ("$J=G91 Y-4 F300\n$J=G91 Y-4 F300\n", A), ("", wait(2.5))],
    "gcode_while_jogging": [
        ("$J=G91 X20 F300\n", A), ("G1 X1 F100\n", A), ("$J=G91 X1 F300\n", A),
        (JOG_CANCEL, at(0, 2.0, 1.0)), ("G1 X0 F600\n", A), ("", wait(2.0))],
    "alarm_and_unlock": [
        ("G38.2 Z-2 F300\n", A), ("", wait(1.0)), ("G0 X1\n", A), ("$H\n", A), ("$#\n", A),
        ("$X\n", A), ("G0 X1\n", A), ("", wait(1.0))],
    # one override byte a step: GRBL folds the bytes that arrive between
    # two of its realtime checks into one step (12 coarse steps sent at
    # once moved it 11 times)
    "feed_override": [
        ("G1 X40 F300\n", A), (FEED_UP, at(0, 3.0, 0.4)), (FEED_UP, wait(0.4)),
        (FEED_DOWN, wait(0.4)), ("\x94", wait(0.4)), ("\x93", wait(0.4)),
        (FEED_RESET, wait(0.4)), (FEED_DOWN, wait(0.4)), (RESET, at(0, 30.0, 1.5)),
        ("", wait(0.3)), ("", wait(0.3))],
    "rapid_and_spindle_override": [
        (RAPID_50 + SPINDLE_UP * 2, wait(0.3)), ("M3 S1000\n", A), ("", wait(0.3)),
        ("G0 X50\n", A), ("", at(0, 20.0, 8.0)), ("M5\n", A), ("", wait(0.3))],
    "check_mode_on_the_wire": [
        ("$C\n", A), ("G1 X10 F100\nG2 X1 Y1 I1\n", A), ("M3 S500\n", A), ("", wait(0.5)),
        ("$C\n", A), ("", wait(1.5)), ("G4 P0\n", A)],
    "status_masks": [
        ("G10 L20 P1 X3 Y-2 Z1.5\n", A), ("", wait(0.2)), ("$10=0\n", A), ("", wait(0.2)),
        ("$10=2\n", A), ("", wait(0.2)), ("$10=3\n", A), ("G1 X5 F200\n", A),
        ("", at(0, 0.8, 2.5)), ("$10=1\n", A)],
    "report_counters": [
        ("", wait(0.2))] + [(STATUS, wait(0.1))] * 12 + [
        ("G10 L20 P1 X1\n", A), ("", wait(0.1)), ("", wait(0.1))],
    "accessories": [
        ("M3 S1200 M8\n", A), ("", wait(0.2)), ("M4\n", A), ("", wait(0.2)),
        ("M9 M5\n", A), ("", wait(0.2))],
    "spindle_stop_in_a_hold": [
        ("M3 S1000\nG1 X30 F400\n", A), (HOLD, at(0, 5.0, 2.0)),
        (SPINDLE_STOP, wait(0.5)), (SPINDLE_STOP, wait(0.5)), (SPINDLE_STOP, wait(0.5)),
        (START, wait(7.0))],
    "safety_door": [
        ("M3 S1000\nG1 X30 F400\n", A), (DOOR, at(0, 5.0, 2.0)),
        ("G1 X0\n", wait(0.5)), (START, wait(0.5)), ("", wait(7.0))],
    "door_when_idle": [
        (DOOR, wait(0.5)), ("G0 X1\n", A), ("$X\n", A), (START, wait(1.0)), ("G0 X2\n", A),
        ("", wait(1.5))],
    "hold_when_idle": [
        (HOLD, wait(0.3)), ("G1 X2 F300\n", wait(0.5)), ("", wait(1.0)), (START, wait(1.5))],
    "program_pause": [
        ("G1 X2 F300\nM0\n", A), ("", wait(1.5)), ("G1 X0\n", A), (START, wait(1.0)),
        ("", wait(1.0))],
    "sleep": [
        ("$SLP\n", A), ("G0 X1\n", A), ("$X\n", A), (RESET, wait(1.5)), ("$X\n", A)],
    "startup_lines": [
        ("$N0=G20 G91\n", A), ("$N1=S250 G4P0\n", A), ("$N\n", A), (RESET, wait(1.5)),
        ("$G\n", A), ("$N0=\n$N1=\n", A), (RESET, wait(1.5)), ("$G\n", A)],
    "inverse_time": [
        ("G93 G1 X10 F30\n", A), ("", wait(1.2)), ("", wait(1.5)), ("G2 X30 I10 F15\n", wait(12.0)), ("G94 G0 X0\n", A), ("", wait(2.0))],
    "dwell_and_hold": [
        ("G4 P1.5\n", wait(0.3)), (HOLD, wait(0.5)), (START, wait(2.0))],
}

REPORT = re.compile(r"^<([A-Za-z]+)(?::\d)?\|[MW]Pos:(-?[\d.]+),(-?[\d.]+),(-?[\d.]+)")


def reader(stream, q):
    for raw in iter(stream.readline, b""):
        q.put(raw.decode("latin-1").rstrip("\r\n"))


class Firmware:
    def __init__(self, exe):
        self.dir = tempfile.mkdtemp(prefix="transcript-")
        self.p = subprocess.Popen([exe, "-n", "-s", "/dev/null", "-b", "/dev/null"],
                                  cwd=self.dir, stdin=subprocess.PIPE,
                                  stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        self.q = queue.Queue()
        threading.Thread(target=reader, args=(self.p.stdout, self.q), daemon=True).start()

    def send(self, text):
        self.p.stdin.write(text.encode("latin-1"))
        self.p.stdin.flush()

    def line(self, timeout):
        try:
            return self.q.get(timeout=timeout)
        except queue.Empty:
            return None

    def drain(self, until):
        """Lines heard up to wall time `until`."""
        out = []
        while True:
            left = until - time.time()
            l = self.line(max(left, 0.0))
            if l is None:
                return out
            out.append(l)

    def close(self):
        self.p.kill()
        shutil.rmtree(self.dir, ignore_errors=True)


def report_of(lines):
    rs = [l for l in lines if l.startswith("<")]
    return rs[-1] if rs else None


def record(exe, steps):
    fw = Firmware(exe)
    try:
        fw.drain(time.time() + 1.5)  # the welcome (a fresh EEPROM: error:7 and $$)
        out = []
        for text, until in steps:
            rec = {"send": text, "until": until}
            heard = []
            if until == A:
                fw.send(text)
                want = text.count("\n")
                deadline = time.time() + 3  # a line GRBL holds stays unanswered
                while want and time.time() < deadline:
                    l = fw.line(0.1)
                    if l is None:
                        continue
                    heard.append(l)
                    if l == "ok" or l.startswith("error:"):
                        want -= 1
                heard += fw.drain(time.time() + 0.05)
            elif "wait" in until:
                fw.send(text)
                heard += fw.drain(time.time() + until["wait"])
            else:
                axis, v = until["at"]
                polls, trig = 0, None
                deadline = time.time() + 60
                while trig is None and time.time() < deadline:
                    time.sleep(0.01)
                    fw.send(STATUS)
                    polls += 1
                    while True:  # up to the report: the trigger goes at once
                        l = fw.line(0.5)
                        if l is None or l.startswith("<"):
                            break
                        heard.append(l)
                    m = l and REPORT.match(l)
                    if m and (float(m[2 + axis]) >= v if v > 0 else float(m[2 + axis]) <= v):
                        trig = l
                        fw.send(text)
                if trig is None:
                    sys.exit("never reached %r" % until)
                rec["polls"], rec["trigger"] = polls, trig
                heard += fw.drain(time.time() + until["then"])
            rec["heard"] = [l for l in heard if not l.startswith("<")]
            fw.send(STATUS)
            got = fw.drain(time.time() + 0.15)
            rec["report"] = report_of(got)
            rec["heard"] += [l for l in got if not l.startswith("<")]
            out.append(rec)
        return out
    finally:
        fw.close()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grbl")
    ap.add_argument("--out", default=os.path.join(HERE, "transcripts.jsonl"))
    ap.add_argument("--only")
    a = ap.parse_args()
    exe = os.path.join(firmware_dir(a.grbl), "grbl-sim", "grbl_sim.exe")
    kept = {}
    if a.only and os.path.exists(a.out):
        for l in open(a.out):
            t = json.loads(l)
            kept[t["name"]] = t
    for name, steps in SCENARIOS.items():
        if a.only and name not in a.only.split(","):
            continue
        kept[name] = {"f": "transcript", "name": name, "steps": record(exe, steps)}
        print(json.dumps(kept[name], indent=1), file=sys.stderr)
    with open(a.out, "w") as f:
        for name in SCENARIOS:
            if name in kept:
                f.write(json.dumps(kept[name]) + "\n")
    print("%d transcripts -> %s" % (len(kept), a.out))


if __name__ == "__main__":
    sys.exit(main())
