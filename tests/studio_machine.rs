//! The studio's Machine panel in a real browser against the simulated
//! GRBL on a pseudo-terminal (`relievo grbl-sim`), judged on screenshots:
//! connect, the live readout, jog, zero, a refused line told with GRBL's
//! meaning, hold and cycle start. And the panel's calls refused, with the
//! port seeing not one byte, without the page's secret or from another
//! site.

mod common;

use common::browser::{
    connect, lines_past, make_job, run_to_end, wait_text, work_xy, Browser, Studio,
};
use common::scratch;
use std::io::{Read, Write};
use std::path::Path;
use std::process::Child;

/// `relievo grbl-sim` at `link`; killed when dropped.
struct GrblSim(Child);

impl GrblSim {
    fn start(link: &Path, speed: &str) -> GrblSim {
        GrblSim::with(link, speed, &[])
    }

    fn with(link: &Path, speed: &str, more: &[&str]) -> GrblSim {
        let child = common::bin()
            .args(["grbl-sim", "--speed", speed, "--link"])
            .arg(link)
            .args(more)
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        for _ in 0..100 {
            if link.exists() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        assert!(link.exists(), "grbl-sim made no {}", link.display());
        GrblSim(child)
    }
}

impl Drop for GrblSim {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The mean colour of an image's middle third.
fn middle(img: &image::RgbaImage) -> [f64; 3] {
    let (w, h) = img.dimensions();
    let mut sum = [0.0; 3];
    let mut n = 0.0;
    for y in h / 3..2 * h / 3 {
        for x in w / 3..2 * w / 3 {
            let p = img.get_pixel(x, y);
            for k in 0..3 {
                sum[k] += p[k] as f64;
            }
            n += 1.0;
        }
    }
    sum.map(|s| s / n)
}

/// Where the tool's red marker is drawn on the job map: the centroid of
/// its pure red pixels.
fn marker(img: &image::RgbaImage) -> Option<(f64, f64)> {
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0.0);
    for (x, y, p) in img.enumerate_pixels() {
        if p[0] > 220 && p[1] < 90 && p[2] < 90 {
            (sx, sy, n) = (sx + x as f64, sy + y as f64, n + 1.0);
        }
    }
    (n > 20.0).then(|| (sx / n, sy / n))
}

#[test]
fn a_carver_drives_the_machine_from_the_page() {
    let d = scratch("studio-machine");
    let Some(b) = Browser::start(&d) else {
        return;
    };
    let link = d.join("grbl");
    let _grbl = GrblSim::start(&link, "5");
    let studio = Studio::start(&[]);
    b.goto(&studio.url);
    b.click("#machine-tab");
    b.script("document.getElementById('m-port').value = ''");
    b.keys("#m-port", link.to_str().unwrap());
    b.click("#m-conn");
    wait_text(&b, "#m-state", "the machine Idle", |t| t == "Idle");
    let idle = b.shot("#m-state");
    let [r, g, _] = middle(&idle);
    assert!(g > r + 40.0, "the Idle badge is green: {:?}", middle(&idle));

    // a 10 mm step along X, then its work zero
    b.script("document.getElementById('m-step').value = '10'");
    b.click("[data-jog='x+']");
    wait_text(&b, "#m-wx", "work X at 10", |t| t == "10.000");
    assert_eq!(b.text("#m-mx"), "10.000");
    b.click("[data-zero='x']");
    wait_text(&b, "#m-wx", "work X zeroed", |t| t == "0.000");
    assert_eq!(b.text("#m-mx"), "10.000", "machine X stays");

    // a line GRBL refuses, told with its meaning, in red
    b.keys("#m-line", "G1 X1 Q7\n");
    let said = wait_text(&b, "#m-console", "the refusal", |t| t.contains("error:20"));
    assert!(
        said.contains("unsupported or invalid G-code command"),
        "{said}"
    );
    let red = b.shot("#m-console .got.error");
    assert!(
        red.pixels().any(|p| p[0] > 200 && p[1] < 170 && p[2] < 170),
        "the refusal is drawn in red"
    );

    // a long move held and started again: the badge turns amber in Hold
    b.keys("#m-line", "G1 X60 F600\n");
    wait_text(&b, "#m-state", "Run", |t| t == "Run");
    b.click("[data-rt='hold']");
    wait_text(&b, "#m-state", "Hold", |t| t.starts_with("Hold"));
    let held = middle(&b.shot("#m-state"));
    assert!(
        held[0] > held[2] + 60.0 && held[1] > held[2] + 30.0,
        "the Hold badge is amber: {held:?}"
    );
    // Hold:1 brakes along the path, as GRBL does; Hold:0 stands
    wait_text(&b, "#m-state", "Hold:0", |t| t == "Hold:0");
    let x_held = b.text("#m-wx");
    std::thread::sleep(std::time::Duration::from_millis(800));
    assert_eq!(b.text("#m-wx"), x_held, "held means standing");
    b.click("[data-rt='start']");
    wait_text(&b, "#m-wx", "the move's end", |t| t == "60.000");
    wait_text(&b, "#m-state", "Idle again", |t| t == "Idle");
    let panel = b.shot("#machine-panel");
    panel.save(d.join("machine-panel.png")).unwrap();
    eprintln!(
        "the Machine panel: {}",
        d.join("machine-panel.png").display()
    );
    b.click("#m-conn");
    wait_text(&b, "#m-state", "disconnected", |t| t == "not connected");
}

/// Issue 46's acceptance on the page: the studio's 60 x 40 mm demo job,
/// made on the page, checked in GRBL's check mode and run through its tool
/// change (the page says which tool to fit, the carver jogs there and goes
/// on) to its last line, which the machine executes, on `relievo grbl-sim`
/// at 100 times real time; the readout and the tool's marker follow the
/// machine. Screenshots in the test's folder.
#[test]
fn the_page_runs_the_job_through_its_tool_change() {
    let d = scratch("studio-machine-job");
    let Some(b) = Browser::start(&d) else {
        return;
    };
    let link = d.join("grbl");
    let log = d.join("ran.log");
    let _grbl = GrblSim::with(&link, "100", &["--log", log.to_str().unwrap()]);
    let studio = Studio::start(&[]);
    b.goto(&studio.url);
    make_job(
        &b,
        &[
            ("[data-more=cut][data-name=stock]", "60x40x8"),
            ("#width", "60"),
            ("#resolution", "256"),
        ],
    );
    let made = std::fs::read_to_string(studio_job(&b)).unwrap();
    assert!(
        made.contains("(stock: 60.00 x 40.00 x 8.00 mm"),
        "{}",
        &made[..400]
    );
    connect(&b, &link);

    // jogged to where the stock's corner is, and zeroed there
    b.script("document.getElementById('m-step').value = '10'");
    b.click("[data-jog='x+']");
    wait_text(&b, "#m-wx", "jogged X", |t| t == "10.000");
    b.click("[data-jog='y+']");
    wait_text(&b, "#m-wy", "jogged Y", |t| t == "10.000");
    b.click("[data-zero='x']");
    wait_text(&b, "#m-wx", "work X zeroed", |t| t == "0.000");
    b.click("[data-zero='y']");
    wait_text(&b, "#m-wy", "work Y zeroed", |t| t == "0.000");
    assert_eq!(b.text("#m-mx"), "10.000", "machine X stays");

    // the tool's marker on the job map, where the machine reports it
    let map0 = b.wait("the marker", 10, || marker(&b.shot("#m-map")));
    let at0 = work_xy(&b);

    let executed = || {
        std::fs::read_to_string(&log)
            .map(|t| t.lines().count())
            .unwrap_or(0)
    };
    let jogs = executed();
    b.click("#m-check");
    let said = b.wait("the check", 120, || {
        let t = b.text("#m-jobtext");
        t.contains("check passed").then_some(t)
    });
    eprintln!("{said}");
    assert_eq!(executed(), jogs, "the check moved nothing");
    b.shot("#machine-panel")
        .save(d.join("checked.png"))
        .unwrap();

    b.click("#m-run");
    let pause = b.wait("the tool change", 240, || {
        let t = b.text("#m-pausetext");
        t.contains("M0").then_some(t)
    });
    assert!(pause.contains("ball:3.175"), "which tool to fit: {pause}");
    let amber = middle(&b.shot("#m-pause"));
    assert!(
        amber[0] > amber[2] + 40.0,
        "the pause is shown amber: {amber:?}"
    );
    let at1 = work_xy(&b);
    let map1 = marker(&b.shot("#m-map")).expect("the marker at the change");
    let (dx, dy) = (at1.0 - at0.0, at1.1 - at0.1);
    assert!(dx.abs() > 5.0, "the job moved the tool: {at0:?} -> {at1:?}");
    let scale = (map1.0 - map0.0) / dx;
    assert!(scale > 1.0, "the marker follows X: {map0:?} -> {map1:?}");
    assert!(
        (map1.1 - map0.1 + scale * dy).abs() < 3.0,
        "the marker follows Y: {map0:?} -> {map1:?}, {dy} mm at {scale} px/mm"
    );
    // the readout is the machine's: machine X is work X plus the zero
    let mx: f64 = b.text("#m-mx").parse().unwrap();
    assert!((mx - at1.0 - 10.0).abs() < 0.002, "{mx} vs work {}", at1.0);
    b.shot("#machine-panel")
        .save(d.join("tool-change.png"))
        .unwrap();
    // the sender stopped before the M0: the machine stands Idle, and the
    // carver jogs (a tool change's probing and zeroing go the same way)
    wait_text(&b, "#m-state", "Idle at the change", |t| t == "Idle");
    let z = b.text("#m-wz");
    b.script("document.getElementById('m-step').value = '10'");
    b.click("[data-jog='z+']");
    wait_text(&b, "#m-wz", "jogged up 10 mm", |t| {
        t.parse::<f64>().ok() == z.parse::<f64>().ok().map(|z| z + 10.0)
    });
    let done = run_to_end(&b, "the job's end");
    assert!(done.starts_with("done"), "{done}");
    let bar = b.shot("#m-progress");
    let (w, h) = bar.dimensions();
    let p = bar.get_pixel(w - 3, h / 2);
    assert!(p[2] > p[0] + 40, "the bar is full: {p:?}");
    // every line the sender counted the machine executed, but the M0 (the
    // machine stood Idle for the change instead) and with the few lines
    // that put it back where the job was after the change
    let n: usize = done
        .trim_start_matches("done: ")
        .split(' ')
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{done}"));
    let ran = executed() - jogs - 1; // and the jog at the change
    eprintln!("{done}; the machine ran {ran} lines");
    assert!((n - 1..n + 8).contains(&ran), "{ran} lines ran of {n}");
    let job = std::fs::read_to_string(studio_job(&b)).unwrap();
    assert!(
        job.lines().count() >= n,
        "the job the page ran is the studio's"
    );
    b.shot("#machine-panel")
        .save(d.join("job-done.png"))
        .unwrap();
    eprintln!(
        "screenshots: {}/{{checked,tool-change,job-done}}.png",
        d.display()
    );
}

/// A job stopped midway from the page (hold, spindle off, reset) is
/// resumed from the journal's safe point, through its tool change, to its
/// end.
#[test]
fn the_page_stops_and_resumes_a_job_from_its_journal() {
    let d = scratch("studio-machine-resume");
    let Some(b) = Browser::start(&d) else {
        return;
    };
    let link = d.join("grbl");
    let _grbl = GrblSim::with(&link, "400", &[]);
    let studio = Studio::start(&[]);
    b.goto(&studio.url);
    make_job(&b, &[("#width", "40"), ("#resolution", "128")]);
    connect(&b, &link);
    b.click("#m-run");
    lines_past(&b, 500, 60);
    b.click("#m-stop");
    let stopped = b.wait("the stop", 60, || {
        let t = b.text("#m-jobtext");
        t.contains("stopped").then_some(t)
    });
    assert!(stopped.contains("resume"), "{stopped}");
    b.wait("the resume offer", 10, || {
        b.script("return !document.getElementById('m-resume').hidden")
            .as_bool()
            .filter(|v| *v)
    });
    b.click("#m-unlock");
    wait_text(&b, "#m-state", "unlocked", |t| t == "Idle");
    b.click("#m-resume");
    let done = run_to_end(&b, "the resumed job's end");
    assert!(done.starts_with("done"), "{done}");
}

/// A short job with a tool change (11 lines, ending at work X3 Y1 Z5).
const TOOL_CHANGE_JOB: &str = "G21 G90 G94\nG0 Z2\nG1 X2 Y1 F600\nG0 Z5\nM5\n\
    M0 (tool: ball:1 for the details)\nG0 X1 Y1\nG1 Z0 F300\nG1 X3 F600\nG0 Z5\nM2\n";

/// The work offset along Z as the readout shows it: machine Z less work Z.
fn wco_z(b: &Browser) -> f64 {
    let v = |css| b.text(css).parse::<f64>().unwrap();
    v("#m-mz") - v("#m-wz")
}

/// The console's newest line that contains `what`, once there.
fn console_note(b: &Browser, what: &str, want: &str) -> String {
    let t = b.wait(what, 60, || {
        let t = b.text("#m-console");
        t.contains(want).then_some(t)
    });
    t.lines()
        .rfind(|l| l.contains(want))
        .unwrap_or_default()
        .to_string()
}

/// Probing from the page on `relievo grbl-sim`, which models a touch
/// plate (10 mm at machine X40 Y40) and tools of 0 and 3.2 mm: the touch
/// plate sets work Z0; the tool setter (the same block, as a setter at
/// machine X40 Y40, probed from Z20) measures the tool that set it; at a
/// job's tool change the carver fits the longer tool, the page measures
/// it and moves work Z0 by its 3.2 mm, and the job goes on to its end.
#[test]
fn the_page_probes_and_measures_a_new_tool_on_the_setter() {
    let d = scratch("studio-machine-setter");
    let Some(b) = Browser::start(&d) else {
        return;
    };
    let link = d.join("grbl");
    let grbl = GrblSim::with(
        &link,
        "20",
        &["--plate", "10@40,40", "--tool-lengths", "0,3.2"],
    );
    let studio = Studio::start(&[]);
    b.goto(&studio.url);
    connect(&b, &link);
    b.keys("#m-line", "G0 X40 Y40 Z20\n");
    wait_text(&b, "#m-mz", "over the plate", |t| t == "20.000");
    // the plate: work Z0 where the tip would meet the plate's bottom
    b.script("document.getElementById('m-plate').value = '10'");
    b.click("#m-probe-go");
    let said = console_note(&b, "the touch-off", "touch-off:");
    assert!(!said.contains("error") && !said.contains("ALARM"), "{said}");
    b.wait("work Z0 on the plate's base", 30, || {
        (wco_z(&b).abs() < 0.002).then_some(())
    });
    // the setter: the tool that set Z0 reads the setter's top at Z10
    b.keys("#m-setter", "40,40,20");
    b.click("#m-setter-ref");
    let said = console_note(&b, "the reference", "tool setter:");
    assert!(said.contains("work Z10.000"), "{said}");

    let job = d.join("change.nc");
    std::fs::write(&job, TOOL_CHANGE_JOB).unwrap();
    b.keys("#m-nc", job.to_str().unwrap());
    wait_text(&b, "#m-source", "the file chosen", |t| {
        t.contains("(11 lines)")
    });
    b.click("#m-run");
    let pause = b.wait("the tool change", 60, || {
        let t = b.text("#m-pausetext");
        t.contains("M0").then_some(t)
    });
    assert!(pause.contains("ball:1"), "{pause}");
    let table = b.text("#m-pausetool");
    assert!(
        table.contains("ball:1 is not in") || table.contains("tool table"),
        "{table}"
    );
    wait_text(&b, "#m-state", "Idle at the change", |t| t == "Idle");
    // the carver fits the 3.2 mm longer tool (the simulator's hand)
    let before = wco_z(&b);
    // SAFETY: kill(2) on the simulator's own process id
    assert_eq!(unsafe { libc::kill(grbl.0.id() as i32, libc::SIGUSR1) }, 0);
    b.click("#m-setter-new");
    let said = console_note(&b, "the new tool measured", "tool setter: the new tool");
    assert!(said.contains("3.200 mm longer"), "{said}");
    b.wait("work Z0 moved by the new tool's length", 30, || {
        ((wco_z(&b) - before - 3.2).abs() < 0.002).then_some(())
    });
    b.shot("#machine-panel").save(d.join("setter.png")).unwrap();
    let done = run_to_end(&b, "the job's end");
    assert!(done.starts_with("done"), "{done}");
    // the new tool's tip ends where the job says: work Z5 over the base
    wait_text(&b, "#m-wz", "the job's last Z", |t| t == "5.000");
    assert!((wco_z(&b) - 3.2).abs() < 0.002, "{}", wco_z(&b));
}

/// The job the studio made, as the page downloads it.
fn studio_job(b: &Browser) -> std::path::PathBuf {
    b.click("#dl-nc");
    b.downloaded("job.nc")
}

/// A pseudo-terminal this test holds the other end of, to see every byte
/// a studio writes to it.
struct Pty {
    master: std::fs::File,
    path: String,
}

impl Pty {
    fn open() -> Pty {
        use std::os::fd::FromRawFd;
        // SAFETY: posix_openpt/grantpt/unlockpt/ptsname on the fd just
        // opened; ptsname's buffer is copied at once
        unsafe {
            let fd = libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY | libc::O_NONBLOCK);
            assert!(fd >= 0, "posix_openpt");
            assert_eq!(libc::grantpt(fd), 0);
            assert_eq!(libc::unlockpt(fd), 0);
            let name = std::ffi::CStr::from_ptr(libc::ptsname(fd))
                .to_string_lossy()
                .into_owned();
            Pty {
                master: std::fs::File::from_raw_fd(fd),
                path: name,
            }
        }
    }

    /// Bytes that arrived from the studio since the last call.
    fn arrived(&mut self) -> Vec<u8> {
        let mut got = Vec::new();
        let mut buf = [0u8; 4096];
        while let Ok(n) = self.master.read(&mut buf) {
            if n == 0 {
                break;
            }
            got.extend_from_slice(&buf[..n]);
        }
        got
    }
}

#[test]
fn another_site_cannot_drive_the_machine() {
    let mut pty = Pty::open();
    let studio = Studio::start(&[]);
    let authority = studio.url.trim_start_matches("http://").to_string();
    let port = authority.rsplit_once(':').unwrap().1.to_string();
    let page = common::browser::agent()
        .get(&studio.url)
        .call()
        .unwrap()
        .body_mut()
        .read_to_string()
        .unwrap();
    let at = page.find("name=\"relievo-secret\" content=\"").unwrap() + 31;
    let secret = page[at..at + 32].to_string();
    let ask = |path: &str, host: &str, origin: Option<&str>, key: &str, body: &str| {
        let mut s = std::net::TcpStream::connect(&authority).unwrap();
        let origin = origin
            .map(|o| format!("Origin: {o}\r\n"))
            .unwrap_or_default();
        let key = if key.is_empty() {
            String::new()
        } else {
            format!("X-Relievo-Secret: {key}\r\n")
        };
        write!(
            s,
            "POST {path} HTTP/1.1\r\nHost: {host}\r\n{origin}{key}Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        )
        .unwrap();
        let mut text = String::new();
        s.read_to_string(&mut text).unwrap();
        let code: u16 = text.split_whitespace().nth(1).unwrap().parse().unwrap();
        (code, text)
    };
    let ours = format!("127.0.0.1:{port}");
    let connect = format!("{{\"port\":\"{}\"}}", pty.path);
    let evil = Some("http://evil.example");
    let rebound = format!("rebind.example:{port}");
    for (path, body) in [
        ("/api/machine/connect", connect.as_str()),
        ("/api/machine/line", "{\"line\":\"G0 Z5\"}"),
        ("/api/machine/realtime", "{\"name\":\"reset\"}"),
        ("/api/machine/jog", "{\"x\":10}"),
    ] {
        for (host, origin, key) in [
            (ours.as_str(), None, ""),
            (ours.as_str(), None, "0123456789abcdef0123456789abcdef"),
            (ours.as_str(), evil, secret.as_str()),
            (rebound.as_str(), None, secret.as_str()),
        ] {
            let (code, text) = ask(path, host, origin, key, body);
            assert_eq!(code, 403, "{path} {host} {origin:?} {key}: {text}");
        }
    }
    // a WebSocket without the secret is refused too
    let (code, _) = {
        let mut s = std::net::TcpStream::connect(&authority).unwrap();
        write!(
            s,
            "GET /api/machine/live HTTP/1.1\r\nHost: {ours}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
        )
        .unwrap();
        let mut buf = [0u8; 512];
        let n = s.read(&mut buf).unwrap();
        let text = String::from_utf8_lossy(&buf[..n]).to_string();
        let code: u16 = text.split_whitespace().nth(1).unwrap().parse().unwrap();
        (code, text)
    };
    assert_eq!(code, 403);
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert_eq!(pty.arrived(), b"", "the port saw bytes");
    // the page itself connects: the port hears status polls, nothing else
    let (code, text) = ask("/api/machine/connect", &ours, None, &secret, &connect);
    assert_eq!(code, 200, "{text}");
    std::thread::sleep(std::time::Duration::from_millis(700));
    let heard = pty.arrived();
    assert!(
        !heard.is_empty() && heard.iter().all(|&b| b == b'?'),
        "connecting sends only '?': {heard:?}"
    );
}
