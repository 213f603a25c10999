//! GRBL 1.1's language: a corpus of hand-written lines, each with the
//! answer GRBL 1.1h's own parser (gcode.c, default build) gives, run
//! through relievo's parser and modal state, the simulated GRBL, and the
//! simulator's program reader.

use glam::DVec3;
use relievo::gcode::modal::Modal;
use relievo::gcode::parse::parse_line;
use relievo::grbl::sim::SimGrbl;
use relievo::machine::Machine;

/// (line number in the corpus file, expected answer, line).
fn corpus() -> Vec<(usize, String, String)> {
    let text = include_str!("data/grbl_corpus.txt");
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.starts_with('#'))
        .map(|(k, l)| {
            let (want, line) = l.split_once('\t').expect("ANSWER<tab>LINE");
            (k + 1, want.to_string(), line.to_string())
        })
        .collect()
}

fn answer(r: Result<(), u32>) -> String {
    match r {
        Ok(()) => "ok".into(),
        Err(c) => format!("error:{c}"),
    }
}

#[test]
fn the_corpus_is_large_and_covers_the_language() {
    let c = corpus();
    assert!(c.len() >= 200, "{} lines", c.len());
    let refused = c.iter().filter(|l| l.1 != "ok").count();
    assert!(refused >= 100, "{refused} refused lines");
    let all: String = c.iter().map(|l| l.2.to_ascii_uppercase() + " ").collect();
    for w in [
        "G0 ", "G1 ", "G2 ", "G3 ", "G4 ", "G10 ", "G17", "G18", "G19", "G20", "G21", "G28 ",
        "G30 ", "G28.1", "G30.1", "G38.2", "G40", "G43.1", "G49", "G53 ", "G54", "G55", "G56",
        "G57", "G58", "G59", "G61", "G80", "G90", "G91", "G91.1", "G92 ", "G92.1", "G93", "G94",
        "M0", "M1", "M2", "M30", "M3 ", "M4 ", "M5", "M7", "M8", "M9", " F", " I", " J", " K",
        " L", "N", " P", " R", " S", "T", " X", " Y", " Z",
    ] {
        assert!(all.contains(w), "the corpus never uses {w}");
    }
}

#[test]
fn the_parser_answers_as_grbl() {
    let mut m = Modal::new(DVec3::ZERO);
    let mut wrong = Vec::new();
    for (k, want, line) in corpus() {
        let got = answer(
            m.apply(&parse_line(&line, k))
                .map(|_| ())
                .map_err(|r| r.code),
        );
        if got != want {
            wrong.push(format!("corpus line {k} '{line}': {got}, GRBL {want}"));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn the_simulated_grbl_answers_as_grbl() {
    let mut s = SimGrbl::new(&Machine::load("shapeoko").unwrap());
    s.take_output();
    let mut t = 0.0;
    let mut wrong = Vec::new();
    for (k, want, line) in corpus() {
        for b in line.bytes().chain([b'\n']) {
            s.receive(b);
        }
        let mut heard = String::new();
        let got = loop {
            heard.push_str(&String::from_utf8_lossy(&s.take_output()));
            if let Some(a) = heard
                .lines()
                .find(|l| *l == "ok" || l.starts_with("error:") || l.starts_with("ALARM"))
            {
                break a.to_string();
            }
            t += 0.05;
            assert!(t < 3600.0, "corpus line {k} '{line}': no answer");
            s.advance(t);
            // M0 holds, and answers when cycle start releases it
            if line.trim() == "M0" {
                s.receive(b'~');
            }
        };
        if got != want {
            wrong.push(format!("corpus line {k} '{line}': {got}, GRBL {want}"));
        }
        if got == "ok" && (line.contains("M2") || line.contains("M30")) {
            assert!(heard.contains("[MSG:Pgm End]"), "{line}: {heard}");
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// `simulate` reads a job through the same state: the lines GRBL takes
/// make a program, and each line GRBL refuses, put after them, is the
/// program's error with GRBL's code and the line's number.
#[test]
fn the_program_reader_answers_as_grbl() {
    let c = corpus();
    let mut text = String::new();
    let mut n = 0;
    for (k, want, line) in &c {
        if want == "ok" {
            text.push_str(line);
            text.push('\n');
            n += 1;
            continue;
        }
        let bad = format!("{text}{line}\n");
        let e = relievo::gcode::program(&bad).unwrap_err().0;
        assert!(
            e.starts_with(&format!("line {}: GRBL {want} ", n + 1)),
            "corpus line {k} '{line}': {e}, GRBL {want}"
        );
    }
    relievo::gcode::program(&text).expect("every line GRBL takes reads");
}
