#!/usr/bin/env python3
"""Regenerates the GRBL 1.1h conformance corpus (programs.jsonl) from the
firmware's own parser: each program (a short prelude and one line, of a
named family) runs through `gvalidate.exe`, GRBL 1.1h's protocol loop and
gc_execute_line on the host, with a fresh EEPROM holding GRBL's defaults,
and every line's answer is kept as GRBL printed it.

Usage: generate.py [--grbl DIR] [--seed N] [--out FILE]
  --grbl DIR  a built GRBL 1.1h (DIR/grbl-sim/grbl_sim.exe and its objects);
              by default the one the firmware tests build,
              target/tmp/grbl-firmware (`cargo test --release --test firmware`)
Only the standard library; deterministic for a given seed.
"""
import argparse
import json
import os
import random
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def num(r, lo=-50.0, hi=50.0):
    """A number in one of the ways people and CAM programs write them."""
    k = r.randrange(9)
    v = r.uniform(lo, hi)
    if k == 0:
        return str(int(v))
    if k == 1:
        return "%.1f" % v
    if k == 2:
        return "%.3f" % v
    if k == 3:
        return "%.6f" % v
    if k == 4:
        return ("%.2f" % v).rstrip("0")  # "12." forms
    if k == 5:
        s = "%.3f" % abs(v)
        s = s[1:] if s.startswith("0") else s  # ".5"
        return ("-" if v < 0 else "") + s
    if k == 6:
        return ("+" if v >= 0 else "") + "%.2f" % v
    if k == 7:
        return "%.9f" % v  # more digits than a float holds
    return "%d" % int(v * 1000)


def axes(r, letters="XYZ", lo=-50, hi=50, need=0):
    ls = [c for c in letters if r.random() < 0.6]
    while len(ls) < need:
        ls = [c for c in letters if r.random() < 0.6]
    return " ".join(c + num(r, lo, hi) for c in ls)


def start(r):
    return ["G90 G21 G17 G94 G54 G0 X0 Y0 Z0"] if r.random() < 0.7 else []


def fam_motion(r):
    g = r.choice(["G0", "G1", "G00", "G01", "g1", "G0 ", "G1"])
    feed = " F" + num(r, 1, 3000) if r.random() < 0.6 else ""
    pre = start(r) + (["F" + num(r, 1, 2000)] if r.random() < 0.3 else [])
    return pre, "%s %s%s" % (g, axes(r), feed)


def fam_arc_ijk(r):
    plane, offs = r.choice([("G17", "IJ"), ("G18", "IK"), ("G19", "JK")])
    x = {c: r.uniform(-20, 20) for c in "XYZ"}
    c = {k: r.uniform(-15, 15) for k in offs}
    # half the time a target on the circle, else anywhere
    words = []
    if r.random() < 0.5:
        import math
        a_axes = {"G17": "XY", "G18": "ZX", "G19": "YZ"}[plane]
        off = {"G17": "IJ", "G18": "KI", "G19": "JK"}[plane]
        cx, cy = c.get(off[0], 0.0), c.get(off[1], 0.0)
        rad = math.hypot(cx, cy)
        th = math.atan2(-cy, -cx) + r.uniform(-3, 3)
        tx, ty = cx + rad * math.cos(th), cy + rad * math.sin(th)
        tx += r.choice([0, 0, 0.001, 0.003, 0.006, 0.05])
        words.append(a_axes[0] + "%.4f" % tx)
        words.append(a_axes[1] + "%.4f" % ty)
        if r.random() < 0.3:
            other = [a for a in "XYZ" if a not in a_axes][0]
            words.append(other + num(r, -5, 5))
    else:
        words += [k + num(r, -20, 20) for k in "XYZ" if r.random() < 0.5]
    words += [k + "%.4f" % v for k, v in c.items() if r.random() < 0.85]
    g = r.choice(["G2", "G3"])
    feed = " F" + num(r, 10, 2000) if r.random() < 0.8 else ""
    return ["G90 G21 %s G0 X0 Y0 Z0" % plane], "%s %s%s" % (g, " ".join(words), feed)


def fam_arc_r(r):
    plane = r.choice(["G17", "G18", "G19"])
    g = r.choice(["G2", "G3"])
    return (
        ["G90 G21 %s G0 X0 Y0 Z0" % plane, "F300"],
        "%s %s R%s" % (g, axes(r, lo=-30, hi=30), num(r, -30, 30)),
    )


def fam_gnum(r):
    n = r.choice([r.randrange(0, 100), r.randrange(0, 300), r.randrange(250, 270), r.randrange(500, 70000)])
    tail = " " + axes(r) if r.random() < 0.5 else ""
    return start(r), "G%d%s" % (n, tail)


def fam_mnum(r):
    n = r.choice([r.randrange(0, 20), r.randrange(0, 300), r.randrange(250, 270), r.randrange(500, 70000)])
    tail = " S" + num(r, 0, 20000) if r.random() < 0.3 else ""
    return start(r), "M%d%s" % (n, tail)


def fam_fractional(r):
    base = r.choice(["G0", "G1", "G2", "G17", "G20", "G28", "G38", "G43", "G53", "G54", "G59", "G61",
                     "G64", "G80", "G90", "G91", "G92", "G93", "G10", "M3", "M5", "M7", "M30"])
    frac = r.choice([".0", ".1", ".2", ".3", ".5", ".9", ".00", ".10", ".25", ".01", ".4", ".99"])
    tail = " " + axes(r) if r.random() < 0.4 else ""
    return start(r), base + frac + tail


def fam_negative_cmd(r):
    w = r.choice(["G", "M", "T", "N", "S", "F", "P", "L"])
    n = r.choice(["-1", "-3", "-0", "-255", "-256", "-1.5", "-0.0", "-30"])
    lead = r.choice(["", "G4 ", "G10 L2 ", "G1 X1 "]) if w in "PLF" else ""
    return start(r), lead + w + n


def fam_g10(r):
    l = r.choice(["2", "20", "1", "3", "2.0", "20.0", "2.5", "", "256", "258", "-2"])
    p = r.choice(["0", "1", "2", "3", "6", "7", "9", "255", "256", "257", "262", "1.5", "-1", "", "01"])
    words = ["G10"]
    if l:
        words.append("L" + l)
    if p:
        words.append("P" + p)
    a = axes(r)
    if a:
        words.append(a)
    r.shuffle(words)
    tail = " R" + num(r) if r.random() < 0.1 else ""
    return start(r), " ".join(words) + tail


def fam_home_pos(r):
    g = r.choice(["G28", "G30", "G28.1", "G30.1", "G28.2", "G28.3", "G30.2"])
    pre = start(r) + ([r.choice(["G91", "G90"])] if r.random() < 0.4 else [])
    tail = " " + axes(r) if r.random() < 0.6 else ""
    extra = " " + r.choice(["G53", "G0", "G1", "G92", "M3", "G4 P1"]) if r.random() < 0.2 else ""
    return pre, g + tail + extra


def fam_g92(r):
    g = r.choice(["G92", "G92.1", "G92.2", "G92.3", "G92"])
    tail = " " + axes(r) if r.random() < 0.7 else ""
    pre = start(r) + (["G92 X" + num(r)] if r.random() < 0.3 else [])
    return pre, g + tail


def fam_dwell(r):
    p = r.choice(["", " P" + num(r, 0, 5), " P-1", " P0", " P.5", " P" + num(r, -5, 5)])
    tail = " " + axes(r) if r.random() < 0.2 else ""
    return start(r), "G4" + p + tail


def fam_fst(r):
    w = r.choice(["F", "S", "T"])
    v = r.choice([num(r, 0, 5000), num(r, -10, 10), "0", "255", "256", "1000000", "2.5", "-0"])
    lead = r.choice(["", "G1 X1 ", "M3 ", "G0 "])
    return start(r), lead + w + v


def fam_nline(r):
    n = r.choice([r.randrange(0, 10), r.randrange(0, 100000), r.randrange(9999990, 10000010),
                  r.randrange(10 ** 7, 10 ** 9)])
    form = r.choice(["N%d G0 X1", "N%d", "G0 N%d X1", "N%d.5 G0 X1", "N%d N1 G0 X1", "N-%d G0 X1"])
    return start(r), form % n


MODAL_GROUPS = [
    ["G0", "G1", "G2", "G3", "G38.2", "G38.3", "G38.4", "G38.5", "G80"],
    ["G17", "G18", "G19"],
    ["G90", "G91"],
    ["G91.1"],
    ["G93", "G94"],
    ["G20", "G21"],
    ["G40"],
    ["G43.1", "G49"],
    ["G54", "G55", "G56", "G57", "G58", "G59"],
    ["G61"],
    ["M0", "M1", "M2", "M30"],
    ["M3", "M4", "M5"],
    ["M7", "M8", "M9"],
    ["G4", "G10", "G28", "G30", "G28.1", "G30.1", "G53", "G92", "G92.1"],
]


def fam_modal_conflict(r):
    g = r.choice([g for g in MODAL_GROUPS if len(g) > 1])
    a, b = r.sample(g, 2)
    if a.startswith(("M0", "M1", "M2", "M30")) or b.startswith(("M0", "M1", "M2", "M30")):
        a, b = "M3", "M5"
    tail = " " + axes(r) if r.random() < 0.3 else ""
    return start(r), "%s %s%s" % (a, b, tail)


def fam_modal_mix(r):
    words = []
    for g in r.sample(MODAL_GROUPS, r.randrange(1, 5)):
        w = r.choice(g)
        if w in ("M0", "M1", "M2", "M30", "G38.2", "G38.3", "G38.4", "G38.5"):
            continue
        words.append(w)
    if r.random() < 0.7:
        words.append(axes(r, need=1))
    if r.random() < 0.5:
        words.append("F" + num(r, 1, 2000))
    if r.random() < 0.2:
        words.append("P" + num(r, 0, 3))
    if r.random() < 0.1:
        words.append("L" + r.choice(["2", "20"]))
    r.shuffle(words)
    return start(r), " ".join(words)


def fam_repeat(r):
    w = r.choice(["X", "Y", "Z", "F", "S", "I", "P", "T", "G", "M"])
    v1, v2 = num(r, 0, 10), num(r, 0, 10)
    if w == "G":
        return start(r), "G%s G%s X1" % (r.choice(["0", "1", "90"]), r.choice(["0", "1", "90"]))
    if w == "M":
        return start(r), "M%s M%s" % (r.choice(["3", "5", "8"]), r.choice(["3", "5", "8", "9"]))
    lead = "G1 " if w in "XYZF" else ("G2 X1 " if w == "I" else ("G4 " if w == "P" else ""))
    return start(r), "%s%s%s %s%s F100" % (lead, w, v1, w, v2) if w != "F" else "%sF%s F%s X1" % (lead, v1, v2)


def fam_letters(r):
    w = r.choice("ABCDEHOQUVWKJIRL")
    lead = r.choice(["", "G0 ", "G1 X1 F10 ", "M3 ", "G4 P1 "])
    return start(r), "%s%s%s" % (lead, w, num(r, -10, 10))


def fam_number_format(r):
    bad = r.choice(["1.2.3", "--1", "-", "+", ".", "-.", "+.", "1e2", "1E2", "0x10", "1,5",
                    "1 . 5", "- 1", "1-", "", " ", "..5", "5..", "+-1", "1+", "00012", "-0.000",
                    "999999999", "1234567.89", "0.0000001", "3.40282e38", "12345678901234567890"])
    w = r.choice(["X", "Y", "F", "S", "P", "G", "M", "N", "T"])
    lead = {"X": "G1 F100 ", "Y": "G0 ", "F": "G1 X1 ", "P": "G4 ", "S": "M3 "}.get(w, "")
    return start(r), lead + w + bad


def fam_long_line(r):
    words = ["G1"]
    n = r.randrange(4, 30)
    for _ in range(n):
        words.append(r.choice("XYZ") + num(r, 0, 10))
    # keep the axes unique by building from a fresh set
    used, out = set(), ["G1"]
    for w in words[1:]:
        if w[0] in used:
            continue
        used.add(w[0])
        out.append(w)
    pad = r.choice(["", " ", "  ", "   "])
    body = pad.join(out) + " F" + num(r, 10, 100)
    if r.random() < 0.5:
        body += " (" + "c" * r.randrange(0, 120) + ")"
    if r.random() < 0.4:
        body = "G1" + "0" * r.randrange(60, 90) + body[2:]
    if r.random() < 0.3:
        body += " " * r.randrange(50, 200)
    if r.random() < 0.3:
        body += ";" + "x" * r.randrange(50, 150)
    return start(r), body


def fam_comments(r):
    forms = ["(hello)", "G0 X1 (move)", "(a) G0 X1 (b) Y2", "G0 (X1) Y2", "(unclosed G0 X1",
             "G0 X1 ) Y2", "; all comment", "G0 X1 ; Y2", "G0 X1 ;(x) Y2", "((nested)) G0 X1",
             "(MSG, hello)", "%", "% G0 X1", "/G0 X1", "G0 /X1", "G0 X1 /", "()", "G0 X(1)2",
             "G0 X1 (a;b) Y2", "\tG0\tX1", "G0 X1 \x07"]
    return start(r), r.choice(forms)


def move_in_mode(r, pre, moves, span, ij):
    """A prelude that sets a mode, then a move of `moves` within `span`
    mm (arcs with I, J within `ij`, feeds with F)."""
    g = r.choice(moves)
    body = "%s %s" % (g, axes(r, lo=-span, hi=span))
    if g in ("G2", "G3"):
        body += " I%s J%s" % (num(r, -ij, ij), num(r, -ij, ij))
    if g in ("G1", "G2", "G3"):
        body += " F" + num(r, 1, 100)
    return pre, body


def fam_units(r):
    pre = ["G20", "G90 G0 X0 Y0 Z0"] if r.random() < 0.7 else ["G21"]
    moves = ["G0", "G1", "G2", "G3", "G1", "G28", "G92", "G10 L20 P1", "G43.1"]
    return move_in_mode(r, pre, moves, 2, 1)


def fam_relative(r):
    pre = ["G90 G0 X0 Y0 Z0", "G91"] + (["G91.1"] if r.random() < 0.4 else [])
    moves = ["G0", "G1", "G2", "G3", "G28", "G30", "G53", "G10 L20 P1", "G92"]
    return move_in_mode(r, pre, moves, 10, 5)


def fam_inverse_time(r):
    pre = start(r) + (["G93"] if r.random() < 0.6 else [])
    g = r.choice(["G1", "G2", "G3", "G0", "G93 G1", "G94 G1", "G93 G0", "G93"])
    body = "%s %s" % (g, axes(r, lo=-10, hi=10))
    if "2" in g or "3" in g and not g.startswith("G93"):
        body += " I%s J%s" % (num(r, -5, 5), num(r, -5, 5))
    if r.random() < 0.6:
        body += " F" + num(r, 0, 5)
    return pre, body


def fam_tool_length(r):
    g = r.choice(["G43.1", "G49", "G43", "G43.2", "G43.1 G49", "G43.1"])
    a = r.choice(["Z" + num(r, -10, 10), "X1", "Z1 X1", "", "Z-2.5", "Y" + num(r)])
    return start(r), ("%s %s" % (g, a)).strip()


def fam_machine_coords(r):
    g = r.choice(["G53", "G53 G0", "G53 G1", "G0 G53", "G53 G2", "G53 G91 G0", "G53 G28"])
    pre = start(r) + (["F100"] if r.random() < 0.5 else [])
    return pre, ("%s %s" % (g, axes(r))).strip()


def fam_cancel(r):
    g = r.choice(["G80", "G80 X1", "G80 G1", "G40", "G40 X1", "G61", "G64", "G61.1", "G80 F100"])
    return start(r), g


def fam_axis_only(r):
    pre = start(r) + [r.choice(["G0", "G1 F100", "G80", "G2 X0 Y0 I1 J0 F10", "G38.2 Z-1 F10"])][:1]
    pre = [p for p in pre if not p.startswith("G38")]
    return pre, axes(r, need=1) + (" F" + num(r, 1, 500) if r.random() < 0.3 else "")


def fam_spindle_coolant(r):
    words = r.sample(["M3", "M4", "M5", "M7", "M8", "M9", "S" + num(r, 0, 30000), "M3", "M9"],
                     r.randrange(1, 4))
    return start(r), " ".join(words)


def fam_flow(r):
    g = r.choice(["M2", "M30", "M2 G0 X1", "M30 M3", "M1", "M2 M5", "G1 X1 F10 M30"])
    return start(r), g


def fam_dollar(r):
    c = r.choice(["$", "$$", "$#", "$G", "$I", "$N", "$C", "$X", "$H", "$Q", "$ ", "$$$", "$#1",
                  "$G1", "$I1", "$CX", "$XX", "$HX", "$J", "$B", "$RST", "$RST=", "$SLX",
                  "$1", "$100", "$N9", "$N0", "$N1", "$N2", "$$ ", "$ $", "$x", "$g", "$i", "$n",
                  "$c", "$h", "$ #", "$ G", "$=1", "$N=G0"])
    pre = start(r) + ([r.choice(["$C", "G92 X1", "G10 L2 P2 X3", "G55", "M8", "G91", "G43.1 Z1",
                                 "G28.1", "G30.1", "$N0=G21", "$I=shop"])] if r.random() < 0.5 else [])
    return pre, c


SETTINGS = [0, 1, 2, 3, 4, 5, 6, 10, 11, 12, 13, 20, 21, 22, 23, 24, 25, 26, 27, 30, 31, 32,
            100, 101, 102, 110, 111, 112, 120, 121, 122, 130, 131, 132]


def fam_setting_write(r):
    k = r.choice(SETTINGS + [7, 8, 9, 14, 33, 99, 103, 113, 123, 133, 200, 255, 256, 1000])
    v = r.choice([num(r, 0, 1000), num(r, -10, 10), "0", "1", "255", "256", "2", "0.5", "abc",
                  "", "1.5", "3", "65535", "1e3", "-0", "300", "20000"])
    tail = "" if r.random() < 0.9 else r.choice([" ", "x", "=1"])
    write = "$%d=%s%s" % (k, v, tail)
    if r.random() < 0.4:
        return start(r) + [write] if False else [write], "$$"
    return start(r), write


def fam_restore(r):
    c = r.choice(["$RST=$", "$RST=#", "$RST=*", "$RST=x", "$RST=$$", "$RST= $", "$rst=#", "$RST=##"])
    pre = ["$100=80", "G10 L2 P1 X5", "$N0=G20", "$I=mill"]
    follow = r.choice(["$$", "$#", "$N", "$I"])
    if r.random() < 0.5:
        return r.sample(pre, 2) + [c], follow
    return r.sample(pre, r.randrange(0, 3)), c


def fam_startup(r):
    body = r.choice(["G21", "G20 G90", "G0 X1", "G1 X1 F10", "G4 P1", "M3 S100", "G28", "G54",
                     "G10 L2 P1 X1", "$$", "$H", "G1 X1", "", "G2 X1", "(c)", "G91 G0 X1",
                     "G21" + " G90" * 30, "g21", "M30", "M0", "G38.2 Z-1 F10", "$X"])
    n = r.choice(["0", "1", "2", "-1", "1.5", "", "01"])
    if r.random() < 0.5:
        return ["$N%s=%s" % (n, body)] if n in ("0", "1") else [], "$N"
    return start(r), "$N%s=%s" % (n, body)


def fam_build_info(r):
    v = r.choice(["", "shop", "mill 2", "x" * r.randrange(20, 90), "(c)", "a;b", "é"])
    if r.random() < 0.5:
        return ["$I=" + v], "$I"
    return start(r), "$I=" + v


def fam_jog(r):
    body = r.choice(["G91 X%s F%s", "X%s F%s", "G90 X%s F%s", "G53 X%s F%s", "G91 G20 X%s F%s",
                     "G91 X%s", "G91 G1 X%s F%s", "G91 G0 X%s F%s", "G91 M3 X%s F%s",
                     "G91 X%s F%s S100", "G91 G94 X%s F%s", "G91 G93 X%s F%s", "G91 N1 X%s F%s",
                     "G91 G21 X%s Y1 F%s", "F%s X%s", "G4 P1 X%s F%s", "G91 G17 X%s F%s",
                     "G91 G55 X%s F%s", "G91 G43.1 Z%s F%s", "G91 G28 X%s F%s"])
    vals = (num(r, -20, 20), num(r, 1, 2000))
    s = body.count("%s")
    pre = start(r) + (["$130=100", "$22=1", "$20=1"] if r.random() < 0.2 else [])
    return pre, "$J=" + (body % vals[:s])


def fam_soft_limits(r):
    pre = ["$22=1", "$20=1"] if r.random() < 0.8 else ["$20=1"]
    pre += [r.choice(["$130=100", "$131=50", "$132=20", "$130=10.5"])] if r.random() < 0.5 else []
    g = r.choice(["G0", "G1 F100", "G53 G0", "G28", "$J=G91", "$J=G53", "G2 I1 J0 F100", "G91 G0"])
    a = axes(r, lo=-250, hi=250, need=1)
    tail = " F100" if g.startswith("$J") else ""
    return pre, "%s %s%s" % (g, a, tail)


def fam_check_mode(r):
    pre = ["$C"] + [r.choice(["G0 X5", "G1 X1 F10", "M3 S10", "G4 P0.1"])]
    line = r.choice(["$C", "G0 X1", "M2", "$X", "$H", "$G", "G38.2 Z-1 F10", "$J=G91 X1 F10", "G1 Q1"])
    return pre, line


def fam_state_carry(r):
    pre = []
    for _ in range(r.randrange(1, 4)):
        pre.append(r.choice(["G20", "G21", "G91", "G90", "G18", "G19", "G17", "G93", "G94", "F50",
                             "G55", "G92 X2 Y3", "G43.1 Z1", "M3 S100", "M8", "G1 X1 F10",
                             "G10 L20 P0 X0", "G91.1", "G61", "G0 Z1", "G28.1", "T3"]))
    return pre, r.choice(["$G", "$#"]) if r.random() < 0.4 else fam_modal_mix(r)[1]


def fam_blank(r):
    return start(r), r.choice(["", " ", "\t", "   ", ";", "()", "( )", " ; x", "(a)(b)", "\x01"])


def fam_arc_edges(r):
    forms = ["G2 X10 Y0 I5 J0 F100", "G2 X0 Y0 I5 J0 F100", "G2 X10 Y0 R5 F100", "G2 X10 Y0 R-5 F100",
             "G2 X10 Y0 R4.99 F100", "G2 X10 Y0 R5.001 F100", "G2 X0 Y0 R5 F100", "G2 I0 J0 X1 F100",
             "G2 X10 F100", "G2 I5 F100", "G3 X10 Y0 I5.004 J0 F100", "G3 X10 Y0 I5.01 J0 F100",
             "G2 X10 Y0 Z3 I5 F100", "G2 X10 K5 F100", "G18 G2 X10 K5 F100", "G19 G2 Y10 J5 F100",
             "G2 X10 Y0 I5 J0 R5 F100", "G2 X1 Y1 I0.5 J0.5 P2 F100", "G2 X10 Y0 I5 J0 L2 F100",
             "G2 X100 Y0 I50 F100", "G2 X0.0001 Y0 I0.00005 F100", "G3 X-10 Y0 I-5 F100"]
    return ["G90 G21 G17 G0 X0 Y0 Z0"], r.choice(forms)


def fam_coord_systems(r):
    g = r.choice(["G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3", "G60"])
    pre = start(r) + (["G10 L2 P%d X%s" % (r.randrange(1, 7), num(r))] if r.random() < 0.5 else [])
    return pre, "%s %s" % (g, axes(r)) if r.random() < 0.5 else g


FAMILIES = [(n[4:], f, w) for n, f, w in [
    ("fam_motion", fam_motion, 200), ("fam_arc_ijk", fam_arc_ijk, 250), ("fam_arc_r", fam_arc_r, 150),
    ("fam_arc_edges", fam_arc_edges, 60), ("fam_gnum", fam_gnum, 150), ("fam_mnum", fam_mnum, 100),
    ("fam_fractional", fam_fractional, 120), ("fam_negative_cmd", fam_negative_cmd, 80),
    ("fam_g10", fam_g10, 150), ("fam_home_pos", fam_home_pos, 100), ("fam_g92", fam_g92, 60),
    ("fam_dwell", fam_dwell, 60), ("fam_fst", fam_fst, 100), ("fam_nline", fam_nline, 100),
    ("fam_modal_conflict", fam_modal_conflict, 100), ("fam_modal_mix", fam_modal_mix, 250),
    ("fam_repeat", fam_repeat, 80), ("fam_letters", fam_letters, 80),
    ("fam_number_format", fam_number_format, 150), ("fam_long_line", fam_long_line, 120),
    ("fam_comments", fam_comments, 60), ("fam_units", fam_units, 80), ("fam_relative", fam_relative, 80),
    ("fam_inverse_time", fam_inverse_time, 80), ("fam_tool_length", fam_tool_length, 50),
    ("fam_machine_coords", fam_machine_coords, 60), ("fam_cancel", fam_cancel, 30),
    ("fam_axis_only", fam_axis_only, 60), ("fam_spindle_coolant", fam_spindle_coolant, 60),
    ("fam_flow", fam_flow, 30), ("fam_dollar", fam_dollar, 150), ("fam_setting_write", fam_setting_write, 200),
    ("fam_restore", fam_restore, 40), ("fam_startup", fam_startup, 80), ("fam_build_info", fam_build_info, 30),
    ("fam_jog", fam_jog, 120), ("fam_soft_limits", fam_soft_limits, 80), ("fam_check_mode", fam_check_mode, 50),
    ("fam_state_carry", fam_state_carry, 150), ("fam_blank", fam_blank, 20),
    ("fam_coord_systems", fam_coord_systems, 50),
]]


def answers(out_text, n_lines):
    """Split gvalidate's output into each input line's answer (the lines it
    printed up to and including its ok or error)."""
    per, cur = [], []
    for l in out_text.replace("\r", "").split("\n"):
        if not l or l.startswith("EXITING"):
            continue
        cur.append(l)
        if l == "ok" or l.startswith("error:"):
            per.append(cur)
            cur = []
    if cur:
        per.append(cur)  # printed but never answered (an alarm at the end)
    return per[:n_lines] if len(per) > n_lines else per


VALIDATOR_OBJECTS = (
    "validator.o overridden_report.o ../grbl/protocol.o ../grbl/planner.o ../grbl/settings.o "
    "../grbl/print.o ../grbl/nuts_bolts.o ../grbl/stepper.o ../grbl/gcode.o "
    "../grbl/spindle_control.o ../grbl/motion_control.o ../grbl/limits.o "
    "../grbl/coolant_control.o ../grbl/probe.o ../grbl/system.o ../grbl/jog.o avr/interrupt.o "
    "avr/pgmspace.o avr/io.o avr/eeprom.o grbl_eeprom_extensions.o system_declares.o"
).split()


def validator_on_defaults(grbl, scratch):
    """gvalidate.exe's own objects relinked with defaults_shim.c, which
    restores GRBL's default settings before the protocol loop starts."""
    src = os.path.join(grbl, "src", "grbl-sim")
    shim = os.path.join(scratch, "defaults_shim.o")
    exe = os.path.join(scratch, "gvalidate_defaults.exe")
    subprocess.run(["gcc", "-c", os.path.join(HERE, "defaults_shim.c"), "-o", shim], check=True)
    wrap = "-Wl,--wrap=plan_check_full_buffer,--wrap=protocol_buffer_synchronize"
    subprocess.run(["gcc", "-O3", "-o", exe, wrap] + VALIDATOR_OBJECTS + [shim, "-lm", "-lrt", "-pthread"],
                   cwd=src, check=True)
    return exe


def firmware_dir(given):
    """The built firmware: `given`, else the firmware tests' build."""
    grbl = given or os.path.join(HERE, "../../../target/tmp/grbl-firmware")
    if not os.path.exists(os.path.join(grbl, "grbl-sim", "grbl_sim.exe")):
        sys.exit("no GRBL 1.1h built at %s: run `cargo test --release --test firmware` "
                 "(it builds one there), or give --grbl DIR" % grbl)
    return os.path.abspath(grbl)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grbl")
    ap.add_argument("--seed", type=int, default=47)
    ap.add_argument("--out", default=os.path.join(HERE, "programs.jsonl"))
    a = ap.parse_args()
    scratch = tempfile.mkdtemp(prefix="conformance-")
    try:
        gvalidate = validator_on_defaults(firmware_dir(a.grbl), scratch)
        run = os.path.join(scratch, "run")
        os.makedirs(run)
        r = random.Random(a.seed)
        programs, seen = [], set()
        for name, fam, count in FAMILIES:
            tries = 0
            made = 0
            while made < count and tries < count * 20:
                tries += 1
                pre, line = fam(r)
                key = "\n".join(pre + [line])
                if key in seen:
                    continue
                seen.add(key)
                made += 1
                programs.append((name, pre + [line]))
        kept = 0
        with open(a.out + ".tmp", "w") as out:
            for name, lines in programs:
                if os.path.exists(os.path.join(run, "EEPROM.DAT")):
                    os.remove(os.path.join(run, "EEPROM.DAT"))
                src = os.path.join(run, "p.nc")
                with open(src, "w", encoding="latin-1") as f:
                    f.write("".join(l + "\n" for l in lines))
                try:
                    p = subprocess.run([gvalidate, src], cwd=run, capture_output=True, timeout=5)
                except subprocess.TimeoutExpired:
                    continue  # a hold the validator never leaves (M0, M1)
                got = answers(p.stdout.decode("latin-1"), len(lines))
                out.write(json.dumps({"f": name, "in": lines, "out": got}, ensure_ascii=False) + "\n")
                kept += 1
        os.replace(a.out + ".tmp", a.out)
        print("%d programs in %d families -> %s" % (kept, len(FAMILIES), a.out))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
