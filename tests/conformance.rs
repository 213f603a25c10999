//! GRBL 1.1h conformance: the corpus in tests/data/conformance (programs
//! of a prelude and one line, with the answers GRBL 1.1h's own protocol
//! loop and parser printed, recorded by its generate.py) run through
//! relievo's simulated GRBL, its check mode as `send --check-only` uses
//! it, and `simulate`'s program reader. No firmware is needed here.

use relievo::grbl::sim::SimGrbl;
use relievo::machine::Machine;
use serde_json::Value;
use std::collections::BTreeMap;

struct Program {
    family: String,
    lines: Vec<String>,
    /// What GRBL printed for each line, up to and including its answer.
    out: Vec<Vec<String>>,
}

fn corpus() -> Vec<Program> {
    include_str!("data/conformance/programs.jsonl")
        .lines()
        .map(|l| {
            let v: Value = serde_json::from_str(l).expect("a JSON program");
            let strs = |v: &Value| -> Vec<String> {
                v.as_array()
                    .unwrap()
                    .iter()
                    .map(|s| s.as_str().unwrap().to_string())
                    .collect()
            };
            Program {
                family: v["f"].as_str().unwrap().to_string(),
                lines: strs(&v["in"]),
                out: v["out"].as_array().unwrap().iter().map(strs).collect(),
            }
        })
        .collect()
}

/// GRBL 1.1h's default settings (its defaults.h, the generic build), as
/// the corpus's EEPROM held them.
fn grbl_defaults() -> Machine {
    Machine::parse(
        r#"name = "GRBL 1.1h defaults"
dialect = "grbl-1.1"
rx_buffer = 128
junction_deviation = 0.01
[travel]
x = 200.0
y = 200.0
z = 200.0
[max_rate]
x = 500.0
y = 500.0
z = 500.0
[acceleration]
x = 10.0
y = 10.0
z = 10.0
[steps_per_mm]
x = 250.0
y = 250.0
z = 250.0
[spindle]
min = 0.0
max = 1000.0
"#,
        "GRBL defaults",
    )
    .unwrap()
}

/// A program's last answer: ok or error:N, with any ALARM and [PRB:] lines.
fn verdict(out: &[Vec<String>]) -> String {
    let Some(last) = out.last() else {
        return "nothing".into();
    };
    last.iter()
        .filter(|l| {
            *l == "ok"
                || l.starts_with("error:")
                || l.starts_with("ALARM")
                || l.starts_with("[PRB:")
        })
        .cloned()
        .collect::<Vec<_>>()
        .join(" ")
}

/// Each line of a program through a fresh simulated GRBL: what it printed
/// for each line, up to its answer.
fn through_sim(p: &Program, check: bool) -> Vec<Vec<String>> {
    let mut s = SimGrbl::new(&grbl_defaults());
    s.take_output();
    let mut t = 0.0;
    let mut send = |s: &mut SimGrbl, line: &str| -> Vec<String> {
        // the corpus holds GRBL's bytes one char each (Latin-1)
        for b in line.chars().map(|c| c as u8).chain([b'\n']) {
            s.receive(b);
        }
        let mut heard = String::new();
        loop {
            heard.extend(s.take_output().into_iter().map(|b| b as char));
            let mut lines: Vec<String> = heard
                .lines()
                .map(|l| l.trim_end_matches('\r').to_string())
                .filter(|l| !l.is_empty())
                .collect();
            // up to the answer (a reset's welcome may follow it)
            if let Some(k) = lines
                .iter()
                .position(|l| l == "ok" || l.starts_with("error:"))
            {
                lines.truncate(k + 1);
                // the validator's machine is at rest before the next
                // line: so is this one
                while let Some(at) = s.next_event().filter(|&at| at < t + 1e6) {
                    t = at.max(t);
                    s.advance(t);
                }
                s.take_output();
                return lines;
            }
            // on to the machine's next event (a move's end, a dwell's)
            match s.next_event() {
                Some(at) if at < t + 1e6 => {
                    t = at.max(t);
                    s.advance(t);
                }
                _ => {
                    let mut v = lines;
                    v.push("(no answer)".into());
                    return v;
                }
            }
        }
    };
    if check {
        send(&mut s, "$C");
    }
    let mut out = Vec::new();
    // GRBL's validator stops at a reset ($RST=, $C off): the lines after
    // it went unread
    for l in p.lines.iter().take(p.out.len()) {
        let a = send(&mut s, l);
        let refused = a.last().is_some_and(|l| l.starts_with("error:"));
        out.push(a);
        if refused {
            break; // the recording ends at the first refusal
        }
    }
    out
}

/// Programs of G-code alone (what a job holds).
fn gcode_only(p: &Program) -> bool {
    !p.lines.iter().any(|l| l.trim_start().starts_with('$'))
}

/// The first error's code and line in GRBL's answers, if any.
fn first_error(out: &[Vec<String>]) -> Option<(usize, String)> {
    out.iter().enumerate().find_map(|(k, a)| {
        a.last()
            .filter(|l| l.starts_with("error:"))
            .map(|l| (k + 1, l.clone()))
    })
}

struct Tally {
    name: &'static str,
    total: usize,
    wrong: BTreeMap<String, Vec<String>>,
}

impl Tally {
    fn new(name: &'static str) -> Tally {
        Tally {
            name,
            total: 0,
            wrong: BTreeMap::new(),
        }
    }
    fn judge(&mut self, p: &Program, ok: bool, what: impl FnOnce() -> String) {
        self.total += 1;
        if !ok {
            self.wrong.entry(p.family.clone()).or_default().push(what());
        }
    }
    fn share(&self) -> f64 {
        let bad: usize = self.wrong.values().map(Vec::len).sum();
        1.0 - bad as f64 / self.total as f64
    }
    /// The rate, and the disagreements by family.
    fn report(&self) -> String {
        let mut s = format!(
            "{}: {:.2}% of {} programs agree\n",
            self.name,
            100.0 * self.share(),
            self.total
        );
        for (f, v) in &self.wrong {
            s += &format!("  {f}: {}\n", v.len());
            for w in v.iter().take(4) {
                s += &format!("    {w}\n");
            }
        }
        s
    }
}

fn show(lines: &[String]) -> String {
    lines.join(" | ")
}

#[test]
fn the_corpus_is_large_and_covers_grbls_families() {
    let c = corpus();
    assert!(c.len() >= 3000, "{} programs", c.len());
    let families: std::collections::BTreeSet<&str> = c.iter().map(|p| p.family.as_str()).collect();
    assert!(families.len() >= 40, "{} families", families.len());
    let refused = c.iter().filter(|p| first_error(&p.out).is_some()).count();
    assert!(refused >= 1000, "{refused} refused programs");
}

#[test]
fn the_simulated_grbl_answers_as_grbl_1_1h() {
    let mut verdicts = Tally::new("relievo grbl-sim, verdict");
    let mut bytes = Tally::new("relievo grbl-sim, every line byte for byte");
    for p in corpus() {
        let got = through_sim(&p, false);
        let (g, w) = (verdict(&got), verdict(&p.out));
        verdicts.judge(&p, g == w, || format!("{:?}: {g}, GRBL {w}", p.lines));
        bytes.judge(&p, got == p.out, || {
            let k = got
                .iter()
                .zip(&p.out)
                .position(|(a, b)| a != b)
                .unwrap_or(got.len().min(p.out.len()));
            format!(
                "{:?} line {}: '{}', GRBL '{}'",
                p.lines,
                k + 1,
                got.get(k).map_or("-".into(), |l| show(l)),
                p.out.get(k).map_or("-".into(), |l| show(l))
            )
        });
    }
    println!("{}\n{}", verdicts.report(), bytes.report());
    assert!(verdicts.share() >= 0.999, "{}", verdicts.report());
}

#[test]
fn check_mode_and_the_program_reader_judge_as_grbl_1_1h() {
    let mut check = Tally::new("send --check-only (check mode)");
    let mut reader = Tally::new("simulate (program reader)");
    for p in corpus().iter().filter(|p| gcode_only(p)) {
        let want = first_error(&p.out);
        let got = first_error(&through_sim(p, true));
        check.judge(p, got == want, || {
            format!("{:?}: {got:?}, GRBL {want:?}", p.lines)
        });
        let text: String = p.lines.iter().map(|l| format!("{l}\n")).collect();
        let read = match relievo::gcode::program(&text) {
            Ok(_) => None,
            Err(e) => {
                let e = e.0;
                // "line N: GRBL error:C ..."
                let n = e
                    .strip_prefix("line ")
                    .and_then(|r| r.split(':').next())
                    .and_then(|n| n.parse::<usize>().ok());
                let code = e
                    .split_whitespace()
                    .find(|w| w.starts_with("error:"))
                    .map(str::to_string);
                n.zip(code)
            }
        };
        reader.judge(p, read == want, || {
            format!("{:?}: {read:?}, GRBL {want:?}", p.lines)
        });
    }
    println!("{}\n{}", check.report(), reader.report());
    assert!(check.share() >= 0.995, "{}", check.report());
    assert!(reader.share() >= 0.995, "{}", reader.report());
}

/// Feed holds recorded on the firmware (holds.jsonl, by record_holds.py):
/// the simulated GRBL, held where the firmware's report said the hold
/// began, stands within 0.05 mm of where the firmware stood.
#[test]
fn a_feed_hold_decelerates_as_grbl_1_1h() {
    let holds = include_str!("data/conformance/holds.jsonl");
    let mut worst = 0.0f64;
    let mut n = 0;
    for l in holds.lines() {
        let v: Value = serde_json::from_str(l).unwrap();
        let xyz = |k: &str| {
            let a = v[k].as_array().unwrap();
            glam::DVec3::new(
                a[0].as_f64().unwrap(),
                a[1].as_f64().unwrap(),
                a[2].as_f64().unwrap(),
            )
        };
        let (line, onset, stop) = (v["in"].as_str().unwrap(), xyz("onset"), xyz("stop"));
        let mut s = SimGrbl::new(&grbl_defaults());
        for b in line.bytes().chain([b'\n']) {
            s.receive(b);
        }
        // on to where the firmware's hold began (0.1 ms steps)
        let mut t = 0.0;
        while s.position().length() < onset.length() {
            t += 1e-4;
            s.advance(t);
            assert!(t < 60.0, "{line}: never reached {onset}");
        }
        s.receive(b'!');
        s.advance(t + 0.01);
        let st = String::from_utf8_lossy(&s.take_output()).to_string();
        s.receive(b'?');
        let st = st + &String::from_utf8_lossy(&s.take_output());
        assert!(st.contains("<Hold:1|"), "{line}: {st}");
        s.advance(t + 30.0);
        s.receive(b'?');
        let st = String::from_utf8_lossy(&s.take_output()).to_string();
        assert!(st.starts_with("<Hold:0|"), "{line}: {st}");
        let off = (s.position() - stop).length();
        println!(
            "{line}: held at {onset}, GRBL stood at {stop}, relievo at {:.3} ({off:.3} mm)",
            s.position()
        );
        worst = worst.max(off);
        n += 1;
        // cycle start goes on to the move's end
        s.receive(b'~');
        s.advance(t + 90.0);
        s.receive(b'?');
        let st = String::from_utf8_lossy(&s.take_output()).to_string();
        assert!(st.starts_with("<Idle|"), "{line}: {st}");
    }
    assert!(n >= 9, "{n} holds");
    assert!(worst <= 0.05, "worst {worst:.3} mm");
}

/// A status report's fields, the state first.
fn fields(r: &str) -> Vec<(&str, &str)> {
    r.trim_start_matches('<')
        .trim_end_matches('>')
        .split('|')
        .map(|f| f.split_once(':').unwrap_or((f, "")))
        .collect()
}

/// Whether relievo's report `got` says what the firmware's `want` said:
/// the same state and fields; standing, the same values (positions within
/// 0.05 mm, where an event mid-move left it); moving, values are a
/// matter of microseconds and go unjudged.
fn same_report(want: &str, got: &str) -> bool {
    let (w, g) = (fields(want), fields(got));
    let state = |f: &[(&str, &str)]| format!("{}:{}", f[0].0, f[0].1);
    if state(&w) != state(&g) || !w.iter().map(|f| f.0).eq(g.iter().map(|f| f.0)) {
        return false;
    }
    let standing = !["Run:", "Jog:", "Hold:1", "Door:2", "Door:3", "Home:"].contains(&&*state(&w));
    w.iter()
        .zip(&g)
        .skip(1)
        .all(|((name, a), (_, b))| match *name {
            "MPos" | "WPos" => {
                let p = |s: &str| {
                    s.split(',')
                        .map(|v| v.parse::<f64>().unwrap())
                        .collect::<Vec<_>>()
                };
                let tol = if standing { 0.05 } else { 1.0 };
                p(a).iter().zip(p(b)).all(|(a, b)| (a - b).abs() <= tol)
            }
            "FS" | "Bf" if !standing => true,
            _ => a == b,
        })
}

/// Bytes `text` into the machine, then status reports aside: the lines
/// it printed, and its last report.
fn heard(s: &mut SimGrbl, text: &str) -> (Vec<String>, Option<String>) {
    for c in text.chars() {
        s.receive(c as u8);
    }
    let out: String = s.take_output().into_iter().map(|b| b as char).collect();
    let lines: Vec<String> = out.split("\r\n").map(str::to_string).collect();
    let lines = &lines[..lines.len().saturating_sub(1)];
    let report = lines.iter().rev().find(|l| l.starts_with('<')).cloned();
    let rest = lines
        .iter()
        .filter(|l| !l.starts_with('<'))
        .cloned()
        .collect();
    (rest, report)
}

/// Protocol scenarios recorded on the firmware (transcripts.jsonl, by
/// record_transcripts.py: holds and resumes, resets, jogs and their cancel,
/// alarms and unlocking, overrides, check mode, status masks and counters,
/// the door, sleep, the receive buffer overflowing) replayed on relievo's
/// simulated GRBL: each step's bytes at the same point of the machine's
/// motion, the same lines printed, the same closing status report.
#[test]
fn protocol_scenarios_run_as_on_grbl_1_1h() {
    let mut steps = 0;
    let mut wrong = Vec::new();
    let transcripts = include_str!("data/conformance/transcripts.jsonl");
    for t in transcripts.lines() {
        let v: Value = serde_json::from_str(t).unwrap();
        let name = v["name"].as_str().unwrap();
        let mut s = SimGrbl::new(&grbl_defaults());
        s.take_output();
        let mut now = 0.0;
        for (k, step) in v["steps"].as_array().unwrap().iter().enumerate() {
            let text = step["send"].as_str().unwrap();
            let until = &step["until"];
            let mut said;
            if until == "answers" {
                said = heard(&mut s, text).0;
                let answered = |l: &Vec<String>| {
                    l.iter()
                        .filter(|l| *l == "ok" || l.starts_with("error:"))
                        .count()
                };
                // as the recorder: up to 3 s (GRBL takes no line in a hold)
                let start = now;
                while answered(&said) < text.matches('\n').count() {
                    match s.next_event() {
                        Some(at) if at < start + 3.0 => now = at.max(now),
                        _ => {
                            now = start + 3.0;
                            s.advance(now);
                            break;
                        }
                    }
                    s.advance(now);
                    said.extend(heard(&mut s, "").0);
                }
            } else if let Some(w) = until["wait"].as_f64() {
                said = heard(&mut s, text).0;
                now += w;
                s.advance(now);
            } else {
                // on to where the firmware's report said it was, then its
                // polls and the bytes
                let axis = until["at"][0].as_u64().unwrap() as usize;
                let trig = step["trigger"].as_str().unwrap();
                let pos = fields(trig)[1].1.split(',').nth(axis).unwrap();
                let pos: f64 = pos.parse().unwrap();
                let passed = |s: &SimGrbl| {
                    let p = s.position().to_array()[axis];
                    if pos > 0.0 {
                        p >= pos - 5e-4
                    } else {
                        p <= pos + 5e-4
                    }
                };
                while !passed(&s) && now < 120.0 {
                    now += 1e-4;
                    s.advance(now);
                }
                let polls = step["polls"].as_u64().unwrap() as usize;
                said = heard(&mut s, &"?".repeat(polls)).0;
                said.extend(heard(&mut s, text).0);
                now += until["then"].as_f64().unwrap();
                s.advance(now);
            }
            // the recorder's pace: a poll 50 ms after the last answer,
            // 150 ms for its report before the next step
            if until == "answers" {
                now += 0.05;
                s.advance(now);
            }
            let (more, report) = heard(&mut s, "?");
            said.extend(more);
            now += 0.15;
            s.advance(now);
            said.extend(heard(&mut s, "").0);
            let want: Vec<String> = step["heard"]
                .as_array()
                .unwrap()
                .iter()
                .map(|l| l.as_str().unwrap().to_string())
                .collect();
            let want_report = step["report"].as_str().unwrap_or("");
            let got_report = report.unwrap_or_default();
            steps += 1;
            if said != want || !same_report(want_report, &got_report) {
                wrong.push(format!(
                    "{name} step {} ({text:?}):\n    GRBL    {} {want_report}\n    relievo {} {got_report}",
                    k + 1,
                    show(&want),
                    show(&said)
                ));
            }
        }
    }
    println!(
        "{} of {steps} steps as GRBL 1.1h's ({} scenarios)",
        steps - wrong.len(),
        transcripts.lines().count()
    );
    assert!(transcripts.lines().count() >= 20);
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
