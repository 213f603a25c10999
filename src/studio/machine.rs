//! The studio's Machine panel, server side: one connection to a GRBL
//! controller (`grbl::session`) at a time, reached by small JSON calls
//! (connect, a line, a realtime byte, jog, zero, probe, frame) and a
//! WebSocket that pushes the readout as it changes. Every call needs the
//! page's secret, checked before anything touches the port.

use super::server::Reply;
use super::work::Studio;
use crate::grbl::port::SerialLink;
use crate::grbl::session::{self, JobRun, Realtime, Session};
use crate::grbl::touchoff::{Routine, Setter, TouchOff};
use crate::ops::send::SendJob;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// The studio's one machine connection, and a job file the carver
/// brought (instead of the studio's own job).
#[derive(Default)]
pub struct Slot {
    session: Mutex<Option<Arc<Session>>>,
    /// Where the file is kept, and its name as the carver knows it.
    uploaded: Mutex<Option<(PathBuf, String)>>,
    uploads: std::sync::atomic::AtomicUsize,
    /// The tool setter's reference: its top in work Z as the tool that set
    /// Z0 reads it (kept across connections: the machine keeps its zero).
    setter_top: Arc<Mutex<Option<f64>>>,
}

impl Slot {
    pub fn get(&self) -> Option<Arc<Session>> {
        self.session
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    fn set(&self, s: Option<Arc<Session>>) -> Option<Arc<Session>> {
        std::mem::replace(
            &mut *self.session.lock().unwrap_or_else(|e| e.into_inner()),
            s,
        )
    }
}

/// Largest job file the page may bring (bytes).
pub const MAX_NC: usize = 64 << 20;

/// A job file from the page: read as the sender reads it (every line
/// one GRBL takes), kept in the studio's folder for Run and Check.
pub fn upload(studio: &Studio, name: &str, body: &[u8]) -> Reply {
    let Ok(text) = std::str::from_utf8(body) else {
        return Reply::error(400, format!("{name}: not a text file"));
    };
    let lines = match crate::grbl::sender::job_lines(text, name) {
        Ok(l) if !l.is_empty() => l,
        Ok(_) => return Reply::error(400, format!("{name}: no G-code in it")),
        Err(e) => return Reply::error(400, e.0),
    };
    let n = studio.machine.uploads.fetch_add(1, Ordering::SeqCst);
    let path = studio.dir.join(format!("upload-{n}.nc"));
    if let Err(e) = std::fs::write(&path, body) {
        return Reply::error(500, format!("{}: {e}", path.display()));
    }
    *studio
        .machine
        .uploaded
        .lock()
        .unwrap_or_else(|e| e.into_inner()) = Some((path, name.to_string()));
    Reply::json(200, json!({"name": name, "lines": lines.len()}))
}

/// What a call sends: whichever fields it needs.
#[derive(serde::Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Call {
    port: String,
    baud: Option<u32>,
    line: String,
    name: String,
    x: Option<f64>,
    y: Option<f64>,
    z: Option<f64>,
    feed: Option<f64>,
    axes: String,
    /// probe: the touch plate's thickness, mm.
    thickness: Option<f64>,
    /// setter: where the tool setter stands, machine "X,Y,Z" mm.
    setter: String,
    /// setter: "reference" (the tool that set Z0) or "apply" (a new tool).
    step: String,
    /// frame: safe Z, mm above work zero.
    safe_z: Option<f64>,
    /// run: in GRBL's check mode only (nothing moves).
    check: bool,
    /// run: from the journal's safe resume point.
    resume: bool,
    /// run: the job file the page brought, not the studio's job.
    uploaded: bool,
}

/// The serial ports found on this machine.
pub fn ports() -> Reply {
    let found = serialport::available_ports()
        .map(|p| p.into_iter().map(|p| p.port_name).collect::<Vec<_>>())
        .unwrap_or_default();
    Reply::json(200, json!({ "ports": found }))
}

/// The readout now, console included (the page's first look).
pub fn state(studio: &Studio) -> Reply {
    match studio.machine.get() {
        Some(s) => Reply::json(200, readout_json(&s.shared.now(), 0)),
        None => Reply::json(200, json!({"connected": false})),
    }
}

/// A POST to `/api/machine/{what}` with `call`.
pub fn post(studio: &Studio, what: &str, call: Call) -> Reply {
    if what == "connect" {
        return connect(studio, &call);
    }
    if what == "disconnect" {
        studio.machine.set(None);
        return Reply::json(200, json!({"connected": false}));
    }
    let Some(s) = studio.machine.get() else {
        return Reply::error(409, "no machine connected");
    };
    let line = |l: Result<String, String>| match l {
        Ok(l) => s.line(&l),
        Err(e) => Err(e),
    };
    let done = match what {
        "line" => s.line(&call.line),
        "realtime" => match Realtime::named(&call.name) {
            Some(rt) => s.realtime(rt),
            None => Err(format!("'{}': no such realtime command", call.name)),
        },
        "jog" => line(session::jog_line(
            [call.x, call.y, call.z],
            call.feed.unwrap_or(1000.0),
        )),
        "zero" => line(session::zero_line(&call.axes)),
        "home" => s.line("$H"),
        "unlock" => s.line("$X"),
        "probe" => probe(&s, &call),
        "setter" => setter(studio, &s, &call),
        "frame" => frame(studio, &s, &call),
        "run" => run(studio, &s, &call),
        "stop" => {
            s.stop();
            Ok(())
        }
        "continue" => {
            s.go_on();
            Ok(())
        }
        _ => return Reply::error(404, format!("no such machine call: {what}")),
    };
    match done {
        Ok(()) => Reply::json(200, json!({"ok": true})),
        Err(e) => Reply::error(400, e),
    }
}

fn connect(studio: &Studio, call: &Call) -> Reply {
    let port = call.port.trim();
    if port.is_empty() {
        return Reply::error(400, "connect: name the port");
    }
    // one connection: the old one closes first (its port too)
    studio.machine.set(None);
    match SerialLink::open(port, call.baud.unwrap_or(115200)) {
        Ok(link) => {
            let s = Arc::new(Session::open(Box::new(link), port));
            let r = readout_json(&s.shared.now(), 0);
            studio.machine.set(Some(s));
            Reply::json(200, r)
        }
        Err(e) => Reply::error(400, e.0.replace("--port ", "")),
    }
}

/// A Z touch-off on a plate under the tool (`grbl::touchoff`: fast
/// probe, back off, slow probe, work Z from the trigger point); at a
/// job's tool change, through its sender.
fn probe(s: &Session, call: &Call) -> Result<(), String> {
    let t = call.thickness.unwrap_or(0.0);
    if !(t.is_finite() && (0.0..100.0).contains(&t)) {
        return Err(format!("probe: plate thickness {t} mm?"));
    }
    let feed = call.feed.unwrap_or(100.0);
    if !(feed.is_finite() && feed > 0.0) {
        return Err(format!("probe feed {feed}: must be positive, mm/min"));
    }
    s.routine(Routine::Plate(TouchOff {
        thickness: t,
        at: None,
        feed,
        travel: 50.0,
    }))
}

/// The tool setter: measure the tool that set Z0 (the reference), or a
/// new tool, whose difference moves work Z0.
fn setter(studio: &Studio, s: &Session, call: &Call) -> Result<(), String> {
    let at = crate::ops::settings::parse_xyz(call.setter.trim())
        .map(Setter::at)
        .map_err(|e| format!("tool setter: {e} (the setter's machine position)"))?;
    let top = studio.machine.setter_top.clone();
    s.routine(match call.step.as_str() {
        "reference" => Routine::SetterReference(at, top),
        "apply" => Routine::SetterApply(at, top),
        other => return Err(format!("tool setter: '{other}': reference or apply?")),
    })
}

/// Run (or check) the job the studio made with `relievo send`'s own
/// sender and journal, watched and steered by the page. A stop is the
/// sender's (feed hold, spindle off once held), then a soft reset, which
/// GRBL needs to drop what it has buffered.
fn run(studio: &Studio, s: &Session, call: &Call) -> Result<(), String> {
    let (path, name) = if call.uploaded {
        let up = studio
            .machine
            .uploaded
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        up.clone().ok_or("run: bring a job file first")?
    } else {
        match studio.last_job() {
            Some(j) => (j.dir.join("job.nc"), "job.nc".to_string()),
            None => return Err("run: make a job first (the Job tab)".into()),
        }
    };
    let job = SendJob {
        job: path,
        check_only: call.check,
        rx_buffer: 128,
        remote: Some(s.remote()),
        ..SendJob::default()
    };
    let journal = job.journal_path();
    let job = SendJob {
        resume: call.resume.then(|| journal.clone()),
        ..job
    };
    let (shared, stop, check) = (s.shared.clone(), s.remote().stop, call.check);
    let shown = JobRun {
        name: if call.resume {
            format!("{name} (resumed)")
        } else {
            name
        },
        check,
        ..JobRun::default()
    };
    s.lend(
        shown,
        Box::new(move |port| {
            let ran = job.run(port, &AtomicBool::new(false));
            if stop.load(Ordering::SeqCst) {
                let _ = port.write_all(&[crate::grbl::SOFT_RESET]);
            }
            match ran {
                Ok(_) if check => {
                    let n = shared.now().job.map_or(0, |j| j.total);
                    shared.end_job(format!("check passed: {n} lines"), true, false)
                }
                Ok((out, n)) => shared.end_job(
                    format!("done: {n} lines in {:.0} s", out.seconds),
                    true,
                    false,
                ),
                Err(e) => shared.end_job(e.0, false, !check && journal.exists()),
            }
        }),
    )
}

/// Trace the last job's XY bounds at safe Z, to see it fits the stock.
fn frame(studio: &Studio, s: &Session, call: &Call) -> Result<(), String> {
    let Some(j) = studio.last_job() else {
        return Err("frame: make a job first".into());
    };
    let segs = &j.program.segments;
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for g in segs
        .iter()
        .filter(|g| matches!(g.kind, crate::gcode::Kind::Feed))
    {
        for p in [g.a, g.b] {
            lo = [lo[0].min(p.x), lo[1].min(p.y)];
            hi = [hi[0].max(p.x), hi[1].max(p.y)];
        }
    }
    if !(lo[0].is_finite() && hi[0] > lo[0] && hi[1] > lo[1]) {
        return Err("frame: the job cuts nothing".into());
    }
    let z = call.safe_z.unwrap_or(5.0);
    let feed = call.feed.unwrap_or(1500.0);
    let n = crate::gcode::emit::num;
    s.line(&format!("G90G21G0Z{}", n(z)))?;
    for (x, y) in [
        (lo[0], lo[1]),
        (hi[0], lo[1]),
        (hi[0], hi[1]),
        (lo[0], hi[1]),
        (lo[0], lo[1]),
    ] {
        s.line(&format!("G1X{}Y{}F{}", n(x), n(y), n(feed)))?;
    }
    Ok(())
}

/// The readout as the page takes it, with the console lines after
/// `console_after` only.
fn readout_json(r: &session::Readout, console_after: u64) -> Value {
    let mut v = serde_json::to_value(r).unwrap_or_else(|_| json!({}));
    let fresh: Vec<&session::Said> = r.console.iter().filter(|c| c.seq > console_after).collect();
    v["console"] = json!(fresh);
    v["alarm"] = match r.alarm {
        Some((code, meaning)) => json!({"code": code, "meaning": meaning}),
        None => Value::Null,
    };
    v
}

/// Push the readout over the WebSocket `ws` as it changes, until the
/// page goes or the link ends.
pub fn live(ws: Box<dyn tiny_http::ReadWrite + Send>, studio: &Studio) {
    use tungstenite::protocol::{Role, WebSocket};
    let mut ws = WebSocket::from_raw_socket(ws, Role::Server, None);
    let Some(s) = studio.machine.get() else {
        let _ = ws.send(json!({"connected": false}).to_string().into());
        let _ = ws.close(None);
        return;
    };
    let (mut seen, mut said) = (u64::MAX, 0);
    loop {
        let r = s.shared.after(seen, 10.0);
        seen = r.seq;
        let msg = readout_json(&r, said);
        said = r.console.back().map_or(said, |c| c.seq);
        if ws.send(msg.to_string().into()).is_err() || !r.connected {
            break;
        }
        // this session replaced by another: the page opens a new socket
        if !studio
            .machine
            .get()
            .is_some_and(|now| Arc::ptr_eq(&now, &s))
        {
            break;
        }
    }
    let _ = ws.close(None);
    let _ = ws.flush();
}
