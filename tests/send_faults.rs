//! Faults on a real pseudo-terminal (issue 15): `relievo grbl-sim` in one
//! process with a fault, `relievo send` in others. Links cut at random
//! byte offsets and resumed; a device that only chatters; a machine that
//! stays in Hold; `machine status` with and without an answer.

mod common;
use common::*;
use relievo::gcode::program;
use relievo::grid::Grid;
use relievo::sim::{cut, Stock};
use relievo::tool::Tool;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

/// A running `relievo grbl-sim`, stopped when dropped (also when a test
/// fails, so that no simulator outlives its test).
struct Sim(Child);

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Start `relievo grbl-sim` with `args`: its process and the
/// pseudo-terminal it serves.
fn grbl_sim(args: &[&str]) -> (Sim, String) {
    use std::io::{BufRead, BufReader};
    let mut sim = bin()
        .arg("grbl-sim")
        .args(args)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut dev = String::new();
    BufReader::new(sim.stdout.take().unwrap())
        .read_line(&mut dev)
        .unwrap();
    let dev = dev.trim().to_string();
    assert!(dev.starts_with("/dev/"), "grbl-sim printed '{dev}'");
    (Sim(sim), dev)
}

/// A job that cuts: a spiral of 0.2 mm moves whose depth varies, every
/// coordinate absolute, the spindle on. Returns its path and its lines as
/// the machine logs them.
fn cutting_job(dir: &Path, n: usize) -> (PathBuf, Vec<String>) {
    // (header lines unlike the re-entry's "M3S10000" and "G0Z5", so that
    // the log tells them apart)
    let mut text = String::from("(tool: ball:3.175)\nG21 G90 G94\nM3 S10000 G94\nG0 Z5 G90\n");
    for k in 0..=n {
        let r = 6.0 + k as f64 * 0.004;
        let t = k as f64 * 0.2 / r;
        let z = -0.4 - 0.3 * (k as f64 / 25.0).sin();
        let f = if k == 0 { " F1500" } else { "" };
        text.push_str(&format!(
            "G1 X{} Y{} Z{}{f}\n",
            relievo::gcode::emit::num(20.0 + r * t.cos()),
            relievo::gcode::emit::num(20.0 + r * t.sin()),
            relievo::gcode::emit::num(z)
        ));
    }
    let p = dir.join("cut.nc");
    std::fs::write(&p, &text).unwrap();
    (p, common::grbl_lines(&text))
}

/// The stock after a program's moves, heights on a 0.1 mm grid.
fn carved(text: &str) -> Grid<f32> {
    let stock = Stock {
        x0: 0.0,
        y0: 0.0,
        width: 40.0,
        height: 40.0,
        thickness: 5.0,
        pitch: 0.1,
    };
    let (w, h) = stock.cells();
    let mut heights = Grid::new(w, h, 0.0f32);
    let prog = program(text).unwrap();
    cut(
        &stock,
        &mut heights,
        &prog.segments,
        Tool::parse("ball:3.175").unwrap(),
    );
    heights
}

/// Read the machine's log until it holds `want` lines of the job (the
/// machine runs its planner after `send` returns), for 10 s at most.
fn executed(log: &Path, lines: &[String]) -> Vec<String> {
    let set: std::collections::HashSet<&String> = lines.iter().collect();
    let t0 = Instant::now();
    loop {
        let got: Vec<String> = std::fs::read_to_string(log)
            .unwrap_or_default()
            .lines()
            .map(str::to_string)
            .collect();
        let tail_done = got.last().is_some_and(|l| l == lines.last().unwrap());
        if (tail_done && got.iter().filter(|l| set.contains(l)).count() >= lines.len())
            || t0.elapsed() > Duration::from_secs(10)
        {
            return got;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// How the machine ran the job: `lines[..a]`, then `lines[s..]` after the
/// resume. Panics when a line was skipped or ran out of order.
fn runs(log: &[String], lines: &[String]) -> (usize, usize) {
    let index: std::collections::HashMap<&String, usize> =
        lines.iter().enumerate().map(|(k, l)| (l, k)).collect();
    let ran: Vec<usize> = log.iter().filter_map(|l| index.get(l).copied()).collect();
    let a = ran.iter().enumerate().take_while(|(i, k)| i == *k).count();
    let s = ran.get(a).copied().unwrap_or(lines.len());
    assert!(s <= a, "job lines {a}..{s} were skipped");
    assert!(
        ran[a..].iter().copied().eq(s..lines.len()),
        "after the first {a} lines the machine ran {:?}..., not {s}.. in order",
        &ran[a..ran.len().min(a + 5)]
    );
    (a, s)
}

/// One cut at byte `at`, then resume until the job is done. Returns the
/// machine's log, what `send` said, and the number of sends.
fn cut_and_resume(
    dir: &Path,
    job: &Path,
    lines: &[String],
    at: usize,
    tag: usize,
) -> (Vec<String>, String, usize) {
    let log = dir.join(format!("executed-{tag}.log"));
    let journal = dir.join(format!("job-{tag}.journal"));
    let (sim, dev) = grbl_sim(&[
        "--machine",
        "3018",
        "--speed",
        "20",
        "--log",
        log.to_str().unwrap(),
        "--disconnect-after",
        &at.to_string(),
    ]);
    let send = |extra: &[&str]| {
        let mut args = vec![
            "send",
            job.to_str().unwrap(),
            "--port",
            &dev,
            "--journal",
            journal.to_str().unwrap(),
            "--link-timeout",
            "1",
            "-q",
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let first = send(&[]);
    let said = String::from_utf8_lossy(&first.stderr).to_string();
    let mut sends = 1;
    if !first.status.success() {
        assert!(said.contains("--resume"), "{said}");
        // the host closes the port; the operator plugs the cable back in
        std::thread::sleep(Duration::from_millis(300));
        loop {
            sends += 1;
            assert!(sends < 6, "{said}");
            let again = send(&["--resume", journal.to_str().unwrap()]);
            if again.status.success() {
                break;
            }
            let e = String::from_utf8_lossy(&again.stderr);
            // a reset while moves were queued: ALARM:3, unlock first
            assert!(e.contains("alarm"), "{e}");
            ok(&run(&["machine", "unlock", "--port", &dev]));
        }
    }
    let log_lines = executed(&log, lines);
    drop(sim);
    (log_lines, said, sends)
}

/// Acceptance 1: 20 cuts at random byte offsets; after resuming, no line
/// is skipped, and the lines run twice leave the cut as the uninterrupted
/// job leaves it (within 1 um).
#[test]
fn twenty_cuts_at_random_offsets_resume_without_a_skip() {
    let d = scratch("faults-cuts");
    let (job, lines) = cutting_job(&d, 500);
    let job_text = std::fs::read_to_string(&job).unwrap();
    let bytes = lines.iter().map(|l| l.len() + 1).sum::<usize>();
    let whole = carved(&job_text);
    // reproducible offsets: a fixed LCG over the job's bytes
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let offsets: Vec<usize> = (0..20)
        .map(|_| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            200 + (seed >> 33) as usize % (bytes - 200)
        })
        .collect();
    let results: Vec<(usize, Vec<String>, usize)> = std::thread::scope(|s| {
        let handles: Vec<_> = offsets
            .chunks(5)
            .enumerate()
            .map(|(c, chunk)| {
                let (d, job, lines) = (&d, &job, &lines);
                s.spawn(move || {
                    chunk
                        .iter()
                        .enumerate()
                        .map(|(k, &at)| {
                            let (log, _, sends) = cut_and_resume(d, job, lines, at, c * 5 + k);
                            (at, log, sends)
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    let mut twice = Vec::new();
    for (at, log, sends) in &results {
        let (a, s) = runs(log, &lines);
        let mut text = log.join("\n");
        text.push('\n');
        let after = carved(&text);
        let worst = whole
            .data
            .iter()
            .zip(&after.data)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0f32, f32::max);
        assert!(
            worst <= 1e-3,
            "cut at byte {at}: the resumed job's cut differs by {worst} mm"
        );
        twice.push(a - s);
        eprintln!(
            "cut at byte {at}: {a} of {} lines had run, resumed at {s} ({} run twice) in {sends} sends; cut within {worst:.1e} mm",
            lines.len(),
            a - s
        );
    }
    eprintln!(
        "20 cuts: lines run twice {:?}, at most {}",
        twice,
        twice.iter().max().unwrap()
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// A relative job cut inside its lines in doubt is not resumed.
#[test]
fn a_relative_job_is_not_resumed_after_a_cut() {
    let d = scratch("faults-g91");
    let job = d.join("g91.nc");
    let mut text = String::from("G21 G90\nG0 X20 Y20 Z5\nG91\n");
    for k in 0..300 {
        text.push_str(&format!("G1 X{} F1200\n", if k % 2 == 0 { 1 } else { -1 }));
    }
    std::fs::write(&job, text).unwrap();
    let journal = d.join("g91.journal");
    let (sim, dev) = grbl_sim(&["--speed", "20", "--disconnect-after", "1500"]);
    let send = |extra: &[&str]| {
        let mut a = vec![
            "send",
            job.to_str().unwrap(),
            "--port",
            &dev,
            "--journal",
            journal.to_str().unwrap(),
            "--link-timeout",
            "1",
            "-q",
        ];
        a.extend_from_slice(extra);
        run(&a)
    };
    let first = send(&[]);
    assert!(!first.status.success());
    let e = String::from_utf8_lossy(&first.stderr);
    assert!(e.contains("unsafe") && e.contains("G91"), "{e}");
    std::thread::sleep(Duration::from_millis(300));
    let again = send(&["--resume", journal.to_str().unwrap()]);
    drop(sim);
    let e = String::from_utf8_lossy(&again.stderr);
    assert!(!again.status.success());
    assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    assert!(
        e.contains("cannot resume safely") && e.contains("G91"),
        "{e}"
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// Acceptance 2: a device that only chatters, and a machine that stays
/// in Hold, end within their stated limits with a clear message.
#[test]
fn a_chatty_device_and_an_endless_hold_end_in_time() {
    let d = scratch("faults-waits");
    let (job, _) = cutting_job(&d, 300);
    let job = job.to_str().unwrap();
    let (sim, dev) = grbl_sim(&["--chatty"]);
    let t0 = Instant::now();
    let out = run(&["send", job, "--port", &dev, "-q"]);
    let chatty = t0.elapsed().as_secs_f64();
    let status = run(&["machine", "status", "--port", &dev]);
    drop(sim);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        e.contains("no status report") && e.contains("nothing was sent"),
        "{e}"
    );
    // welcome drain 0.5 s + status 1 s, with room for a slow machine
    assert!(chatty < 4.0, "{chatty} s");
    let se = String::from_utf8_lossy(&status.stderr);
    assert!(!status.status.success());
    assert!(se.contains("no status report"), "{se}");

    let (sim, dev) = grbl_sim(&["--speed", "20", "--hold-at", "100"]);
    let t0 = Instant::now();
    let out = run(&["send", job, "--port", &dev, "-q", "--hold-limit", "1"]);
    let held = t0.elapsed().as_secs_f64();
    drop(sim);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        e.contains("Hold for 1 s") && e.contains("spindle was stopped") && e.contains("--resume"),
        "{e}"
    );
    assert!(held < 5.0, "{held} s");
    eprintln!("chatty device refused in {chatty:.1} s; endless hold ended in {held:.1} s");
    std::fs::remove_dir_all(d).unwrap();
}

/// Issue 10: `machine status` on a board in Hold reports Hold and leaves
/// it in Hold (it used to soft-reset it: ALARM:3); `send --check-only`
/// validates, says so and runs nothing.
#[test]
fn status_leaves_a_held_board_held_and_check_only_runs_nothing() {
    let d = scratch("faults-status");
    let (job, lines) = cutting_job(&d, 300);
    let log = d.join("executed.log");
    let job = job.to_str().unwrap();
    // (check mode counts lines too: the hold comes in the real run)
    let hold_at = (lines.len() + 100).to_string();
    let (sim, dev) = grbl_sim(&[
        "--speed",
        "20",
        "--hold-at",
        &hold_at,
        "--log",
        log.to_str().unwrap(),
    ]);
    let checked = run(&["send", job, "--port", &dev, "--check-only"]);
    ok(&checked);
    let said = String::from_utf8_lossy(&checked.stderr);
    assert!(
        said.contains(&format!("check passed: {} lines", lines.len())),
        "{said}"
    );
    assert_eq!(std::fs::read_to_string(&log).unwrap_or_default(), "");
    let out = run(&["send", job, "--port", &dev, "-q", "--hold-limit", "1"]);
    assert!(!out.status.success());
    // connecting again to the held machine: no soft reset, refused, held
    let again = run(&["send", job, "--port", &dev, "-q"]);
    assert!(!again.status.success());
    let e = String::from_utf8_lossy(&again.stderr);
    assert!(
        e.contains("GRBL is in Hold") && e.contains("left as it is"),
        "{e}"
    );
    for _ in 0..2 {
        let st = run(&["machine", "status", "--port", &dev]);
        ok(&st);
        let text = String::from_utf8_lossy(&st.stdout);
        assert!(text.starts_with("<Hold"), "{text}");
        assert!(!text.contains("ALARM"), "{text}");
    }
    drop(sim);
    std::fs::remove_dir_all(d).unwrap();
}

/// `machine status` prints the report of a machine that answers.
#[test]
fn machine_status_over_a_pseudo_terminal() {
    let (sim, dev) = grbl_sim(&[]);
    let out = run(&["machine", "status", "--port", &dev]);
    drop(sim);
    ok(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("<Idle|MPos:0.000,0.000,0.000"), "{text}");
}

/// Issue 10: the keys of a job streamed from a terminal. Five '-' lower
/// the feed override to 50% (GRBL keeps it after the job: `machine
/// status` reads Ov:50), space holds the machine (its log stops growing)
/// and space again lets it finish. `send`'s stdin is a pseudo-terminal
/// the test types into.
#[test]
fn terminal_keys_hold_resume_and_override_the_feed() {
    use std::io::Write;
    use std::os::fd::{FromRawFd, OwnedFd};
    let d = scratch("faults-keys");
    let (job, lines) = cutting_job(&d, 300);
    let log = d.join("executed.log");
    let (sim, dev) = grbl_sim(&["--speed", "2", "--log", log.to_str().unwrap()]);
    let (mut master, mut slave) = (0, 0);
    // SAFETY: openpty fills two descriptors, which are owned from here on
    let opened = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(opened, 0, "openpty");
    let mut keys = unsafe { std::fs::File::from_raw_fd(master) };
    let slave = unsafe { OwnedFd::from_raw_fd(slave) };
    let said = d.join("send.txt");
    let mut send = bin()
        .args(["send", job.to_str().unwrap(), "--port", &dev])
        .stdin(Stdio::from(slave))
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&said).unwrap())
        .spawn()
        .unwrap();
    let ran = || {
        std::fs::read_to_string(&log)
            .unwrap_or_default()
            .lines()
            .count()
    };
    let t0 = Instant::now();
    while ran() < 20 && t0.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(20));
    }
    keys.write_all(b"-----").unwrap();
    std::thread::sleep(Duration::from_millis(300));
    keys.write_all(b" ").unwrap();
    // the hold decelerates, then nothing more runs
    std::thread::sleep(Duration::from_millis(700));
    let (held_at, t_hold) = (ran(), Instant::now());
    std::thread::sleep(Duration::from_millis(1000));
    let after_hold = ran();
    let held_for = t_hold.elapsed().as_secs_f64();
    keys.write_all(b" ").unwrap();
    let t1 = Instant::now();
    let status = loop {
        if let Some(s) = send.try_wait().unwrap() {
            break s;
        }
        assert!(t1.elapsed() < Duration::from_secs(60), "send never ended");
        std::thread::sleep(Duration::from_millis(50));
    };
    let text = std::fs::read_to_string(&said).unwrap();
    assert!(status.success(), "{text}");
    let st = run(&["machine", "status", "--port", &dev]);
    ok(&st);
    let report = String::from_utf8_lossy(&st.stdout).to_string();
    // the machine runs its planner after `send` returns
    let log_lines = executed(&log, &lines);
    drop(sim);
    eprintln!(
        "keys: held at log line {held_at} for {held_for:.1} s ({} more ran), then {} lines in all; {}",
        after_hold - held_at,
        log_lines.len(),
        report.trim()
    );
    assert!(
        held_at > 20 && held_at < log_lines.len(),
        "held at {held_at}"
    );
    assert_eq!(after_hold, held_at, "the machine ran on in the hold");
    assert!(report.contains("|Ov:50,100,100"), "{report}");
    runs(&log_lines, &lines);
    std::fs::remove_dir_all(d).unwrap();
}
