//! The sender against the simulated GRBL machine: in memory (simulated
//! time at 115200 baud) and over a real pseudo-terminal with the real
//! serial code (`relievo grbl-sim` in one process, `relievo send` in
//! another).

mod common;
use common::*;
use relievo::grbl::port::MemPort;
use relievo::grbl::sender;
use relievo::grbl::sender::Stall;
use relievo::grbl::sim::{Faults, SimGrbl};
use relievo::machine::Machine;
use relievo::ops::send::SendJob;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

const BAUD: u32 = 115200;

/// A job of `n` short distinct moves after a header line: a spiral of
/// 0.02 mm segments, so GRBL's planner keeps full speed through the
/// corners and executes them faster than the link brings them.
fn write_job(dir: &Path, n: usize) -> (PathBuf, Vec<String>) {
    write_spiral(dir, n, 0.02)
}

/// A spiral job of `n` moves `seg` mm long.
fn write_spiral(dir: &Path, n: usize, seg: f64) -> (PathBuf, Vec<String>) {
    let mut text = String::from("(test job)\nG21 G90 G94\nG1 X15 Y10 F6000\n");
    let mut lines = vec!["G21G90G94".to_string(), "G1X15Y10F6000".to_string()];
    for k in 1..=n {
        let r = 5.0 + k as f64 * 2e-5;
        let t = k as f64 * seg / r;
        let (x, y) = (10.0 + r * t.cos(), 10.0 + r * t.sin());
        let l = format!(
            "G1X{}Y{}",
            relievo::gcode::emit::num(x),
            relievo::gcode::emit::num(y)
        );
        text.push_str(&l);
        text.push('\n');
        lines.push(l);
    }
    let p = dir.join("job.nc");
    std::fs::write(&p, text).unwrap();
    (p, lines)
}

fn port(faults: Faults) -> MemPort {
    let mut sim = SimGrbl::new(&Machine::load("shapeoko").unwrap());
    sim.faults = faults;
    MemPort::new(sim, BAUD)
}

/// Let the machine finish what it has queued (an `ok` means queued, not
/// executed).
fn finish(p: &mut MemPort) {
    use relievo::grbl::port::Port;
    let t = p.now() + 1e5;
    p.sim.advance(t);
}

/// How the machine ran the job lines, from its log of executed lines
/// (re-entry lines left out): `lines[..a]` in the first run, then
/// `lines[s..]` after the resume. Panics when a line was skipped or ran
/// out of order.
fn runs(log: &[String], lines: &[String]) -> (usize, usize) {
    let index: std::collections::HashMap<&String, usize> =
        lines.iter().enumerate().map(|(k, l)| (l, k)).collect();
    let ran: Vec<usize> = log.iter().filter_map(|l| index.get(l).copied()).collect();
    let a = ran.iter().enumerate().take_while(|(i, k)| i == *k).count();
    let s = ran.get(a).copied().unwrap_or(lines.len());
    assert!(s <= a, "lines {a}..{s} were skipped");
    let rest: Vec<usize> = ran[a..].to_vec();
    let want: Vec<usize> = (s..lines.len()).collect();
    assert!(
        rest == want,
        "after the first {a} lines the machine ran {} lines, not {s}..{} in order",
        rest.len(),
        lines.len()
    );
    (a, s)
}

fn job(path: &Path) -> SendJob {
    SendJob {
        job: path.to_path_buf(),
        rx_buffer: 128,
        ..Default::default()
    }
}

/// Acceptance 1: 100,000 lines, each executed once and in order, no
/// overflow, >= 90% of the link's byte budget with character counting.
#[test]
fn hundred_thousand_lines_in_memory() {
    let d = scratch("send-100k");
    let (path, lines) = write_job(&d, 100_000);
    let no = AtomicBool::new(false);
    let mut p = port(Faults::default());
    let (o, n) = job(&path).run(&mut p, &no).unwrap();
    assert_eq!(n, lines.len());
    finish(&mut p);
    assert_eq!(p.sim.overflow, 0, "receive buffer overflowed");
    assert!(p.sim.log == lines, "executed lines differ from the job");
    let u = o.utilisation(BAUD);
    // send-and-wait on the first 5,000 lines, for comparison
    let (small, _) = write_job(&d, 5_000);
    let mut q = port(Faults::default());
    let sr = SendJob {
        send_response: true,
        ..job(&small)
    };
    let (o2, _) = sr.run(&mut q, &no).unwrap();
    let u2 = o2.utilisation(BAUD);
    eprintln!(
        "100,000 lines in {:.1} simulated s: link utilisation {:.1}% with character counting, {:.1}% send-response",
        o.seconds,
        100.0 * u,
        100.0 * u2
    );
    assert!(u >= 0.9, "utilisation {u}");
    assert!(u2 < u);
    std::fs::remove_dir_all(d).unwrap();
}

/// Acceptance 3: error at line N stops there, names it, and nothing beyond
/// what was already buffered is sent.
#[test]
fn error_stops_at_its_line() {
    let d = scratch("send-error");
    let (path, lines) = write_job(&d, 2_000);
    let mut p = port(Faults {
        error_at: Some((500, 33)),
        ..Default::default()
    });
    let e = job(&path).run(&mut p, &AtomicBool::new(false)).unwrap_err();
    // the 500th G-code line is file line 501 (the comment comes first)
    assert!(e.0.contains("line 501") && e.0.contains("error:33"), "{e}");
    assert!(e.0.contains("invalid target"), "{e}");
    let upto: usize = lines[..500].iter().map(|l| l.len() + 1).sum();
    assert!(p.written <= upto + 127 + 16, "{} bytes written", p.written);
    assert!(!p.sim.log.contains(&lines[499]));
    std::fs::remove_dir_all(d).unwrap();
}

/// After an error the spindle stops (issue 15): it kept turning over the
/// refused job.
#[test]
fn an_error_stops_the_spindle() {
    let d = scratch("send-error-spindle");
    let (path, _) = write_job(&d, 300);
    let text = std::fs::read_to_string(&path).unwrap().replacen(
        "G21 G90 G94\n",
        "G21 G90 G94\nM3 S10000\n",
        1,
    );
    std::fs::write(&path, text).unwrap();
    for at in [100, 299] {
        let mut p = port(Faults {
            error_at: Some((at, 33)),
            ..Default::default()
        });
        let e = job(&path).run(&mut p, &AtomicBool::new(false)).unwrap_err();
        assert!(e.0.contains("error:33"), "{e}");
        assert_eq!(p.sim.spindle_rpm(), 0.0, "error at line {at}");
    }
    // an alarm stops it too (GRBL resets), and the message says where
    // the job stands
    let mut p = port(Faults {
        alarm_at: Some((150, 1)),
        ..Default::default()
    });
    let e = job(&path).run(&mut p, &AtomicBool::new(false)).unwrap_err();
    assert!(
        e.0.contains("ALARM:1") && e.0.contains("the journal says"),
        "{e}"
    );
    assert_eq!(p.sim.spindle_rpm(), 0.0, "alarm");
    std::fs::remove_dir_all(d).unwrap();
}

/// A job line carrying a realtime byte is refused before anything is sent
/// (a '!' held the machine and the job ended "acknowledged").
#[test]
fn realtime_bytes_in_job_lines_are_refused() {
    let d = scratch("send-realtime");
    for (bad, byte) in [
        ("G1 X1 ! Y2", "0x21"),
        ("G1 X~2", "0x7e"),
        ("G1 X?1", "0x3f"),
        ("G1 X\u{85}1", "0xc2"),
    ] {
        let path = d.join("rt.nc");
        std::fs::write(&path, format!("G21 G90\nG1 X0 F100\n{bad}\nM30\n")).unwrap();
        let mut p = port(Faults::default());
        let e = job(&path).run(&mut p, &AtomicBool::new(false)).unwrap_err();
        assert!(e.0.contains("rt.nc: line 3") && e.0.contains(byte), "{e}");
        assert!(p.sim.log.is_empty(), "lines were sent: {:?}", p.sim.log);
    }
    // inside a comment the byte is never sent, so it is fine
    let path = d.join("ok.nc");
    std::fs::write(&path, "(what? stop!)\nG21 G90\nG1 X1 F100 ; done!\n").unwrap();
    job(&path)
        .run(&mut port(Faults::default()), &AtomicBool::new(false))
        .unwrap();
    std::fs::remove_dir_all(d).unwrap();
}

#[test]
fn alarm_stops_with_its_meaning() {
    let d = scratch("send-alarm");
    let (path, _) = write_job(&d, 1_000);
    let mut p = port(Faults {
        alarm_at: Some((300, 1)),
        ..Default::default()
    });
    let e = job(&path).run(&mut p, &AtomicBool::new(false)).unwrap_err();
    assert!(e.0.contains("ALARM:1") && e.0.contains("hard limit"), "{e}");
    std::fs::remove_dir_all(d).unwrap();
}

/// Acceptance 3 (and issue 15): a disconnect is one clear error; the
/// journal says what is known to have run and what is in doubt; the
/// board resets on reconnection while moves were still queued (they are
/// lost, although GRBL had acknowledged them), and resuming from the
/// journal completes the job with no line skipped and only lines in doubt
/// run twice.
#[test]
fn disconnect_then_resume_from_the_journal() {
    let d = scratch("send-disconnect");
    // moves of a few steps of the Shapeoko's 40 steps/mm: each surely
    // takes a planner block, so the journal can tell what has run
    let (path, lines) = write_spiral(&d, 3_000, 0.1);
    let mut p = port(Faults {
        disconnect_after: Some(20_000),
        ..Default::default()
    });
    let no = AtomicBool::new(false);
    let j = job(&path);
    let e = j.run(&mut p, &no).unwrap_err();
    assert!(
        e.0.contains("disconnected") && e.0.contains("--resume") && e.0.contains("may or may not"),
        "{e}"
    );
    let rec = relievo::grbl::resume::Record::read(&j.journal_path()).unwrap();
    let (executed, acked, sent) = (rec.executed.unwrap(), rec.acked.unwrap(), rec.sent.unwrap());
    assert!(executed < acked && acked < sent, "{rec:?}");
    // what the journal says ran did run, at the moment of the cut
    let ran_at_cut = p.sim.log.len();
    assert!(
        ran_at_cut >= executed - 1,
        "{ran_at_cut} ran, journal {executed}"
    );
    // reconnect at once: the board resets in motion and raises ALARM:3;
    // the sender refuses to resume into an alarm; the operator unlocks
    p.reconnect();
    let refused = SendJob {
        resume: Some(j.journal_path()),
        ..job(&path)
    }
    .run(&mut p, &no)
    .unwrap_err();
    assert!(
        refused.0.contains("alarm") && refused.0.contains("unlock"),
        "{refused}"
    );
    {
        let mut r = sender::Replies::new(&mut p);
        assert_eq!(r.command("$X", 5.0).unwrap().last().unwrap(), "ok");
    }
    let lost = p.sim.log.len();
    assert!(
        lost < acked - 1,
        "acknowledged lines were lost in the reset"
    );
    SendJob {
        resume: Some(j.journal_path()),
        ..job(&path)
    }
    .run(&mut p, &no)
    .unwrap();
    finish(&mut p);
    let (a, s) = runs(&p.sim.log, &lines);
    eprintln!(
        "cut after {sent} sent, {acked} acknowledged, {executed} known run (file lines); the \
         reset lost the queued moves: {a} job lines had run; the resume ran {} of them again",
        a - s
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// A job that moves relatively inside the lines in doubt is not resumed:
/// running them twice would move twice.
#[test]
fn a_relative_job_is_refused_inside_its_doubt() {
    let d = scratch("send-g91");
    let path = d.join("g91.nc");
    let mut text = String::from("G21 G90\nG0 X10 Y10\nG91\n");
    for k in 0..400 {
        text.push_str(&format!(
            "G1 X{} F3000\n",
            if k % 2 == 0 { 0.5 } else { -0.5 }
        ));
    }
    std::fs::write(&path, text).unwrap();
    let mut p = port(Faults {
        disconnect_after: Some(2_000),
        ..Default::default()
    });
    let no = AtomicBool::new(false);
    let e = job(&path).run(&mut p, &no).unwrap_err();
    assert!(e.0.contains("unsafe") && e.0.contains("G91"), "{e}");
    p.reconnect();
    let journal = job(&path).journal_path();
    let e = SendJob {
        resume: Some(journal.clone()),
        ..job(&path)
    }
    .run(&mut p, &no)
    .unwrap_err();
    assert!(
        e.0.contains("cannot resume safely")
            && e.0.contains("G91")
            && e.0.contains("--resume-from"),
        "{e}"
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// Acceptance 4: --check reports the bad line and moves nothing.
#[test]
fn check_mode_reports_and_moves_nothing() {
    let d = scratch("send-check");
    let path = d.join("bad.nc");
    std::fs::write(
        &path,
        "G21 G90\nG1 X1 Y1 F500\nG1 X2 Y2\nG38.1 Z-1 F10\nG1 X3\n",
    )
    .unwrap();
    let mut p = port(Faults::default());
    let e = SendJob {
        check: true,
        ..job(&path)
    }
    .run(&mut p, &AtomicBool::new(false))
    .unwrap_err();
    assert!(e.0.contains("line 4") && e.0.contains("error:20"), "{e}");
    assert!(p.sim.log.is_empty(), "moved: {:?}", p.sim.log);
    std::fs::remove_dir_all(d).unwrap();
}

/// Acceptance 5: noise in the replies neither crashes the sender nor
/// loses a line.
#[test]
fn garbled_replies_lose_nothing() {
    let d = scratch("send-garble");
    let (path, lines) = write_job(&d, 5_000);
    let mut p = port(Faults {
        garble: 0.3,
        ..Default::default()
    });
    job(&path).run(&mut p, &AtomicBool::new(false)).unwrap();
    finish(&mut p);
    assert!(p.sim.log == lines);
    std::fs::remove_dir_all(d).unwrap();
}

/// Start `relievo grbl-sim` with `args`: its process and the
/// pseudo-terminal it serves.
fn grbl_sim(args: &[&str]) -> (std::process::Child, String) {
    use std::io::{BufRead, BufReader};
    let mut sim = bin()
        .arg("grbl-sim")
        .args(args)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut dev = String::new();
    BufReader::new(sim.stdout.take().unwrap())
        .read_line(&mut dev)
        .unwrap();
    let dev = dev.trim().to_string();
    assert!(dev.starts_with("/dev/"), "grbl-sim printed '{dev}'");
    (sim, dev)
}

/// Acceptance 2: the real serial code over a pseudo-terminal, the
/// simulated machine in another process.
#[test]
fn send_over_a_pseudo_terminal() {
    let d = scratch("send-pty");
    let (path, lines) = write_job(&d, 2_000);
    let log = d.join("executed.log");
    let (mut sim, dev) = grbl_sim(&[
        "--machine",
        "shapeoko",
        "--speed",
        "20",
        "--log",
        log.to_str().unwrap(),
    ]);
    let out = run(&["send", path.to_str().unwrap(), "--port", &dev, "--check"]);
    // acknowledged is not yet executed: the machine still runs the
    // moves in its planner (in its own time) when `send` returns
    let read = || -> Vec<String> {
        std::fs::read_to_string(&log)
            .unwrap_or_default()
            .lines()
            .map(str::to_string)
            .collect()
    };
    let t0 = std::time::Instant::now();
    while read().len() < lines.len() && t0.elapsed().as_secs_f64() < 10.0 {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let _ = sim.kill();
    let _ = sim.wait();
    ok(&out);
    let executed = read();
    assert!(
        executed == lines,
        "{} of {} lines executed",
        executed.len(),
        lines.len()
    );
    eprintln!("{}", String::from_utf8_lossy(&out.stderr).trim());
    std::fs::remove_dir_all(d).unwrap();
}

/// The real serial path stops on an error too: one error line naming the
/// job line and GRBL's meaning, a non-zero exit.
#[test]
fn error_over_a_pseudo_terminal() {
    let d = scratch("send-pty-error");
    let (path, _) = write_job(&d, 500);
    let (mut sim, dev) = grbl_sim(&["--speed", "20", "--error-at", "120:22"]);
    let out = run(&["send", path.to_str().unwrap(), "--port", &dev, "-q"]);
    let _ = sim.kill();
    let _ = sim.wait();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("line 121") && err.contains("error:22") && err.contains("feed rate"),
        "{err}"
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// Issue 10: the ETA comes from the job's time estimate with the
/// controller's own rates (`$$`), which agrees with the simulated
/// machine's run time on a feed-bound job.
#[test]
fn the_eta_clock_follows_the_machine_time() {
    let d = scratch("send-clock");
    let path = d.join("feed.nc");
    let mut text = String::from("G21 G90 G94\nG1 X10 Y10 F600\n");
    for k in 1..=400 {
        let t = k as f64 * 0.05;
        text.push_str(&format!(
            "G1X{}Y{}\n",
            relievo::gcode::emit::num(10.0 + 5.0 * t.cos()),
            relievo::gcode::emit::num(10.0 + 5.0 * t.sin())
        ));
    }
    std::fs::write(&path, &text).unwrap();
    let mut p = port(Faults::default());
    let settings = {
        let mut r = sender::Replies::new(&mut p);
        r.handshake(2.5).unwrap();
        r.command("$$", 2.0).unwrap()
    };
    let lines = sender::load_job(&path).unwrap();
    // the machine stands at work X0 Y0 Z0, as the simulated GRBL starts
    let clock = sender::clock(&lines, &text, &settings, Some(glam::DVec3::ZERO)).unwrap();
    assert_eq!(clock.len(), lines.len());
    assert!(clock.windows(2).all(|w| w[0] <= w[1]));
    let (o, _) = job(&path).run(&mut p, &AtomicBool::new(false)).unwrap();
    finish(&mut p);
    let estimate = *clock.last().unwrap();
    // the stream ends when the last line is acknowledged, up to a
    // planner's worth of moves before the machine is done
    let machine = o.seconds;
    eprintln!("estimated {estimate:.2} s, streamed in {machine:.2} simulated s");
    assert!(
        (estimate - machine).abs() <= 0.1 * machine,
        "estimate {estimate} s, machine {machine} s"
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// Issue 10, acceptance 7: a job as another CAM program's GRBL post
/// writes it (G54, a G40 G49 G80 preamble, T1, M8 ... M9) simulates and
/// streams; every line reaches the machine and runs.
#[test]
fn a_foreign_post_simulates_and_streams() {
    let d = scratch("send-foreign");
    let path = d.join("foreign.nc");
    let text = "%\n(made by another CAM program)\nG90 G94 G17\nG21\nG54\nG40 G49 G80\nT1\n\
                M3 S12000\nM8\nG0 Z5\nG0 X10 Y10\nG1 Z-0.5 F300\nG1 X20 Y10 F800\n\
                G2 X30 Y20 I0 J10\nG1 X30 Y30\nG0 Z5\nM9\nM5\nM30\n%\n";
    std::fs::write(&path, text).unwrap();
    let relief = d.join("r.png");
    demo_relief(&relief, "64");
    simulate_report(
        &path,
        &relief,
        &d.join("cut.png"),
        &["--tool", "ball:3", "--stock", "60x40x10"],
    );
    let mut p = port(Faults::default());
    job(&path).run(&mut p, &AtomicBool::new(false)).unwrap();
    finish(&mut p);
    assert_eq!(p.sim.log, grbl_lines(text));
    assert!(p.sim.errors.is_empty(), "{:?}", p.sim.errors);
    std::fs::remove_dir_all(d).unwrap();
}

/// Issue 10: at an M0 (a tool change) the machine holds once the moves
/// before it are done; `--on-pause continue` resumes it and the job
/// completes with every line run once, in order; asking with no terminal
/// stops with the line and the way on.
#[test]
fn an_m0_pause_holds_and_continues() {
    let d = scratch("send-m0");
    let (path, _) = write_spiral(&d, 400, 0.1);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut with_pause = String::new();
    for (k, l) in text.lines().enumerate() {
        with_pause.push_str(l);
        with_pause.push('\n');
        if k == 200 {
            with_pause.push_str("M0 (fit the 1 mm ball, zero Z)\n");
        }
    }
    std::fs::write(&path, &with_pause).unwrap();
    let want = grbl_lines(&with_pause);
    let mut p = port(Faults::default());
    let go = SendJob {
        on_pause: sender::OnPause::Continue,
        ..job(&path)
    };
    go.run(&mut p, &AtomicBool::new(false)).unwrap();
    finish(&mut p);
    assert_eq!(p.sim.log, want);
    // asked with no terminal (the test's stdin): a clear stop at the M0
    let mut p = port(Faults::default());
    let e = job(&path).run(&mut p, &AtomicBool::new(false)).unwrap_err();
    assert!(
        e.0.contains("paused at job line 202") && e.0.contains("--on-pause continue"),
        "{e}"
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// Check mode runs a job with a tool change to its last line: GRBL's
/// check mode answers the M0 and goes on, and so does the sender (it
/// waited for a hold that never came). A bad line after the M0 is found;
/// without it the check passes and nothing moves.
#[test]
fn check_mode_runs_through_a_tool_change() {
    let d = scratch("send-check-m0");
    let (path, _) = write_spiral(&d, 300, 0.1);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut with_pause = String::new();
    for (k, l) in text.lines().enumerate() {
        with_pause.push_str(l);
        with_pause.push('\n');
        if k == 100 {
            with_pause.push_str("M5\nM0 (fit the 1 mm ball, zero Z)\nM3 S10000\n");
        }
    }
    std::fs::write(&path, &with_pause).unwrap();
    for check_only in [true, false] {
        let mut p = port(Faults::default());
        let j = SendJob {
            check_only,
            check: !check_only,
            on_pause: sender::OnPause::Continue,
            ..job(&path)
        };
        j.run(&mut p, &AtomicBool::new(false)).unwrap();
        if check_only {
            assert!(p.sim.log.is_empty(), "moved: {:?}", &p.sim.log[..3]);
        }
    }
    let bad = d.join("bad.nc");
    std::fs::write(&bad, format!("{with_pause}G1 X1 Q7\n")).unwrap();
    let n = with_pause.lines().count() + 1;
    let mut p = port(Faults::default());
    let e = SendJob {
        check_only: true,
        ..job(&bad)
    }
    .run(&mut p, &AtomicBool::new(false))
    .unwrap_err();
    assert!(
        e.0.contains(&format!("line {n}")) && e.0.contains("error:20"),
        "{e}"
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// A machine left in check mode (by a check cut short, here or by another
/// program) would only check the job a carver sent to be cut: the sender
/// leaves check mode first, and the job runs.
#[test]
fn a_machine_left_in_check_mode_cuts_the_job() {
    use relievo::grbl::port::Port;
    let d = scratch("send-left-checking");
    let (path, lines) = write_spiral(&d, 50, 0.1);
    for check_only in [false, true] {
        let mut p = port(Faults::default());
        p.write_all(b"$C\n").unwrap();
        let mut r = sender::Replies::new(&mut p);
        assert_eq!(
            r.status().unwrap().map(|s| s.state),
            Some(relievo::grbl::state::State::Check)
        );
        SendJob {
            check_only,
            ..job(&path)
        }
        .run(&mut p, &AtomicBool::new(false))
        .unwrap();
        finish(&mut p);
        if check_only {
            assert!(p.sim.log.is_empty(), "moved: {:?}", &p.sim.log[..3]);
        } else {
            assert_eq!(p.sim.log.last(), lines.last(), "the job ran to its end");
        }
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// A controller that goes on answering status polls but neither moves nor
/// acknowledges is not waited on for ever: past the derived limit (the
/// planner's time for what it holds, twice, plus 20 s) the sender stops
/// (feed hold, spindle off) and says where it waited. A long dwell is not
/// a stall: its own time is allowed for; a fixed limit can be given.
#[test]
fn a_frozen_controller_is_not_waited_on_for_ever() {
    let d = scratch("send-frozen");
    let (path, _) = write_spiral(&d, 300, 0.1);
    let mut p = port(Faults {
        freeze_at: Some(120),
        ..Default::default()
    });
    let e = job(&path).run(&mut p, &AtomicBool::new(false)).unwrap_err();
    assert!(
        e.0.contains("but acknowledged no line for") && e.0.contains("spindle was stopped"),
        "{e}"
    );
    assert!(e.0.contains("waiting on job line 1"), "{e}");
    let number = |after: &str| -> f64 {
        let rest = &e.0[e.0.find(after).unwrap() + after.len()..];
        rest.split(' ').next().unwrap().parse().unwrap()
    };
    let (silent, limit) = (number("acknowledged no line for "), number("(limit "));
    assert!(
        (20.0..30.0).contains(&limit) && silent > limit && silent < limit + 2.0,
        "stopped within the derived limit: {e}"
    );
    // the spindle is off, and nothing was sent after the frozen line
    assert_eq!(p.sim.spindle_rpm(), 0.0, "{e}");
    // a 90 s dwell under the derived limit, and under a fixed 60 s one,
    // runs to the end
    let dwell = d.join("dwell.nc");
    std::fs::write(&dwell, "G21 G90\nG1 X1 F500\nG4 P90\nG1 X2\nG1 X3\n").unwrap();
    for stall in [None, Some(Stall::Seconds(60.0))] {
        let mut p = port(Faults::default());
        SendJob {
            stall,
            ..job(&dwell)
        }
        .run(&mut p, &AtomicBool::new(false))
        .unwrap();
        finish(&mut p);
        assert_eq!(p.sim.log.len(), 5, "{:?}", p.sim.log);
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// The job's `(tool: SPEC ...)` comments in order.
fn tool_specs(text: &str) -> Vec<String> {
    text.lines()
        .filter_map(|l| l.strip_prefix("(tool: "))
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_string)
        .collect()
}

/// The simulated machine's tool-tip path as a job: the header of `text`
/// (its frame), then every move the tip made, each tool's comment where
/// it went in.
fn tip_job(text: &str, tips: &[relievo::grbl::sim::TipMove]) -> String {
    let specs = tool_specs(text);
    let mut out: String = text
        .lines()
        .take_while(|l| l.starts_with('('))
        .filter(|l| !l.starts_with("(tool: "))
        .map(|l| format!("{l}\n"))
        .collect();
    let n = relievo::gcode::emit::num;
    let mut tool = usize::MAX;
    for t in tips {
        if t.tool != tool {
            tool = t.tool;
            out.push_str(&format!("(tool: {})\n", specs[tool.min(specs.len() - 1)]));
        }
        out.push_str(&format!(
            "{} X{} Y{} Z{}\n",
            if t.rapid { "G0" } else { "G1 F1000" },
            n(t.to.x),
            n(t.to.y),
            n(t.to.z)
        ));
    }
    out
}

/// Issue 10 acceptance 1: a roughing + finishing job whose M0 tool change
/// puts in a tool 7.3 mm longer, streamed with `--on-pause probe` and a
/// 20 mm touch plate on the roughing's touch-off pad: the sender pauses
/// at the M0, probes, sets Z0 for the new tool and completes; every job
/// line runs once, in order; the tool tip's path on the machine cuts what
/// the job cuts, within 1 um. Without the probe the same job's finish
/// runs 7.3 mm low, and the simulated cut of the tip's path shows it.
#[test]
fn a_tool_change_touches_off_on_the_plate() {
    use relievo::grbl::sim::Plate;
    let d = scratch("send-touchoff");
    let path = d.join("job.nc");
    ok(&run(&[
        "carve",
        "--resolution",
        "100",
        "--width",
        "60",
        "--depth",
        "3",
        "--safe-z",
        "15",
        "--machine",
        "shapeoko",
        "-q",
        "-o",
        path.to_str().unwrap(),
    ]));
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(tool_specs(&text).len(), 2, "roughing and finishing");
    // the pad the roughing leaves: "(touch-off pad: 8 mm square at X.. Y.., ...)"
    let pad = text
        .lines()
        .find_map(|l| l.strip_prefix("(touch-off pad: "))
        .expect("a touch-off pad");
    let at: Vec<f64> = pad
        .split_whitespace()
        .filter_map(|w| w.trim_end_matches(',').strip_prefix(['X', 'Y']))
        .map(|v| v.parse().unwrap())
        .collect();
    let plate = format!("20@{},{}", at[0], at[1]);
    let want = grbl_lines(&text);
    let relief = d.join("job-relief.png");
    let job_cut = d.join("job-cut.png");
    let job_report = simulate_report(&path, &relief, &job_cut, &["--machine", "shapeoko"]);
    let (w, h, job_z, _) = relief_mm(&job_cut);
    use sender::OnPause;
    for on_pause in [OnPause::Probe, OnPause::Setter, OnPause::Continue] {
        let probe = on_pause != OnPause::Continue;
        let mut sim = SimGrbl::new(&Machine::load("shapeoko").unwrap());
        sim.plate = Some(Plate::parse(&plate).unwrap());
        sim.tool_lengths = vec![0.0, 7.3];
        let mut p = MemPort::new(sim, BAUD);
        let go = SendJob {
            on_pause,
            plate: Some(sender::TouchOff::parse(&plate).unwrap()),
            // the same block as a tool setter, probed from Z40
            setter: Some(sender::Setter::at([at[0], at[1], 40.0])),
            ..job(&path)
        };
        if let Err(e) = go.run(&mut p, &AtomicBool::new(false)) {
            let n = p.sim.log.len();
            p.sim.take_output();
            p.sim.receive(b'?');
            eprintln!("status: {}", String::from_utf8_lossy(&p.sim.take_output()));
            panic!(
                "{e}\nlast lines run: {:?}",
                &p.sim.log[n.saturating_sub(12)..]
            );
        }
        finish(&mut p);
        // every job line once, in order; the touch-off's own lines right
        // after the M0
        let m0 = want.iter().position(|l| l == "M0").unwrap();
        // (the setter's reference, measured before the job, comes first)
        let lead = (0..p.sim.log.len())
            .find(|&k| p.sim.log[k..].starts_with(&want[..5]))
            .unwrap();
        assert_eq!(
            lead > 0,
            on_pause == OnPause::Setter,
            "{:?}",
            &p.sim.log[..lead]
        );
        let log = &p.sim.log[lead..];
        let extra = log.len() - want.len();
        assert_eq!(log[..=m0], want[..=m0]);
        assert_eq!(log[m0 + 1 + extra..], want[m0 + 1..]);
        if probe {
            assert!(log[m0 + 1..m0 + 1 + extra]
                .iter()
                .any(|l| l.contains("G38.2")));
        } else {
            assert_eq!(extra, 0);
        }
        // the tip's path, cut by the simulator
        let tips = d.join("tips.nc");
        std::fs::write(&tips, tip_job(&text, &p.sim.tips)).unwrap();
        let tips_cut = d.join("tips-cut.png");
        let report = simulate_report(&tips, &relief, &tips_cut, &["--machine", "shapeoko"]);
        let (tw, th, tip_z, _) = relief_mm(&tips_cut);
        assert_eq!((tw, th), (w, h));
        let worst = job_z
            .iter()
            .zip(&tip_z)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let gouge = report["max_gouge_mm"].as_f64().unwrap();
        let finish_low = p
            .sim
            .tips
            .iter()
            .filter(|t| t.tool == 1 && !t.rapid)
            .map(|t| t.to.z)
            .fold(f64::INFINITY, f64::min);
        let job_low = relievo::gcode::program(&text)
            .unwrap()
            .segments
            .iter()
            .skip_while(|s| s.line <= text.lines().position(|l| l.trim() == "M0").unwrap() + 1)
            .map(|s| s.b.z)
            .fold(f64::INFINITY, f64::min);
        eprintln!(
            "{on_pause:?}: {} extra lines; the tip's cut differs from the job's by up to \
             {worst:.5} mm; gouge {gouge:.4} mm (the job alone: {:.4}); the finish's deepest \
             tip Z {finish_low:.4} against the job's {job_low:.4}",
            extra,
            job_report["max_gouge_mm"].as_f64().unwrap()
        );
        if probe {
            assert!(worst <= 0.001, "the tip's cut is {worst} mm off the job's");
            assert!((finish_low - job_low).abs() <= 0.001);
        } else {
            assert!(((job_low - finish_low) - 7.3).abs() <= 0.001);
            assert!(
                gouge > 2.0,
                "the simulator shows the cut {gouge} mm too deep"
            );
        }
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// Issue 10: `relievo machine jog|zero|probe|settings` over the real
/// serial code, against the simulated GRBL with a 20 mm touch plate at
/// machine X10 Y0.
#[test]
fn machine_jogs_zeroes_and_probes() {
    let (mut sim, dev) = grbl_sim(&[
        "--machine",
        "shapeoko",
        "--speed",
        "20",
        "--plate",
        "20@10,0",
    ]);
    let status_until = |want: &str| {
        let t0 = std::time::Instant::now();
        loop {
            let o = run(&["machine", "status", "--port", &dev]);
            let s = String::from_utf8_lossy(&o.stdout).to_string();
            if s.contains(want) || t0.elapsed().as_secs() > 10 {
                return s;
            }
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
    };
    ok(&run(&[
        "machine", "jog", "--port", &dev, "--x", "10", "--z", "30", "--feed", "3000",
    ]));
    let s = status_until("MPos:10.000,0.000,30.000");
    assert!(s.contains("<Idle|MPos:10.000,0.000,30.000"), "{s}");
    ok(&run(&["machine", "zero", "--port", &dev, "--axes", "xy"]));
    // the plate's top is 20 mm over the stock top: Z0 lands on the stock
    let o = run(&["machine", "probe", "--port", &dev, "--plate", "20"]);
    ok(&o);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("[G54:10.000,0.000,0.000]"), "{out}");
    assert!(out.contains("[PRB:10.000,0.000,20.000:1]"), "{out}");
    let o = run(&["machine", "settings", "--port", &dev]);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stdout).contains("$100=40.000"));
    let o = run(&["machine", "jog", "--port", &dev]);
    assert!(!o.status.success());
    let _ = sim.kill();
    let _ = sim.wait();
}

/// The page's tool change stops the job before its M0 with the machine
/// standing Idle, where the page jogs. GRBL can report Idle once while
/// the moves it holds have yet to start (the report and the cycle start
/// due in one pass of its realtime loop print the report first): taken
/// for standing, that report would let the jog go to a running machine,
/// which GRBL refuses with error:8. The sender waits for two Idle reports
/// in a row.
#[test]
fn a_page_pause_is_not_fooled_by_an_idle_report_before_the_cycle_starts() {
    use relievo::grbl::remote::{Remote, Step, Told};
    use std::sync::{Arc, Mutex};
    let d = scratch("send-stale-idle");
    let path = d.join("change.nc");
    std::fs::write(
        &path,
        "G21 G90 G94\nG0 Z2\nG1 X20 Y1 F600\nG0 Z5\nM0 (fit the 1 mm ball)\n\
         G0 X1 Y1\nG1 Z0 F300\nG0 Z5\nM2\n",
    )
    .unwrap();
    // (the listener jogs at the pause, and goes on once the jog is answered)
    let heard: Arc<Mutex<Vec<String>>> = Arc::default();
    let me: Arc<Mutex<Option<Remote>>> = Arc::default();
    let jogging = Arc::new(Mutex::new(None::<String>));
    let (h, m, j) = (heard.clone(), me.clone(), jogging.clone());
    let rm = Remote::new(move |t| {
        let rm = m.lock().unwrap().clone().unwrap();
        match t {
            Told::Paused(Some(_)) => {
                *j.lock().unwrap() = Some(String::new());
                rm.push_step(Step::Line("$J=G91G21Z-3F600".into()));
            }
            Told::Heard(l) => {
                h.lock().unwrap().push(l.to_string());
                let mut j = j.lock().unwrap();
                if j.as_deref() == Some("") && (l == "ok" || l.starts_with("error:")) {
                    *j = Some(l.to_string());
                    rm.go_on();
                }
            }
            _ => {}
        }
    });
    *me.lock().unwrap() = Some(rm.clone());
    let mut p = port(Faults {
        stale_idle_after: Some(4),
        ..Faults::default()
    });
    let run = SendJob {
        remote: Some(rm),
        ..job(&path)
    };
    let (o, n) = run.run(&mut p, &AtomicBool::new(false)).unwrap();
    let heard = heard.lock().unwrap();
    let stale = heard
        .iter()
        .position(|l| l.starts_with("<Idle|"))
        .expect("an Idle report");
    eprintln!(
        "the first Idle report, heard while the job ran: {}",
        heard[stale]
    );
    assert_eq!(
        jogging.lock().unwrap().as_deref(),
        Some("ok"),
        "the jog at the pause: {:?}",
        &heard[stale..]
    );
    assert!(o.errors.is_empty() && n == 9, "{:?}", o.errors);
    std::fs::remove_dir_all(d).unwrap();
}
