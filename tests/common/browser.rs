//! A real browser for the studio's tests: Debian's Chromium, headless,
//! driven over WebDriver by its ChromeDriver; screenshots as images.

use serde_json::{json, Value};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CHROMIUM: &str = "/usr/bin/chromium";
const DRIVER: &str = "/usr/bin/chromedriver";

/// An HTTP client that hands back every status (errors are checked here).
pub fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(Duration::from_secs(120)))
        .build()
        .into()
}

/// `relievo studio` on a free port; killed when dropped.
pub struct Studio {
    child: Child,
    pub url: String,
}

impl Studio {
    pub fn start(args: &[&str]) -> Studio {
        let mut child = super::bin()
            .args(["studio", "--port", "0"])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("relievo studio starts");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let url = line
            .trim()
            .strip_prefix("relievo studio on ")
            .unwrap_or_else(|| panic!("studio said: {line}"))
            .trim_end_matches('/')
            .to_string();
        Studio { child, url }
    }

    /// Whether the process still runs.
    pub fn alive(&mut self) -> bool {
        self.child.try_wait().unwrap().is_none()
    }
}

impl Drop for Studio {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

pub struct Browser {
    driver: Child,
    base: String,
    http: ureq::Agent,
    pub downloads: PathBuf,
}

impl Browser {
    /// A headless Chromium saving downloads into `downloads`; `None` when
    /// Chromium is not installed and RELIEVO_REQUIRE_BROWSER is not set
    /// (.ci/run installs it and sets it).
    pub fn start(downloads: &Path) -> Option<Browser> {
        if !Path::new(CHROMIUM).exists() || !Path::new(DRIVER).exists() {
            assert!(
                std::env::var("RELIEVO_REQUIRE_BROWSER").is_err(),
                "{CHROMIUM} and {DRIVER} are required (apt-get install chromium chromium-driver)"
            );
            eprintln!("skipped: no {CHROMIUM} / {DRIVER}");
            return None;
        }
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let driver = Command::new(DRIVER)
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver starts");
        let http = agent();
        let root = format!("http://127.0.0.1:{port}");
        let t = Instant::now();
        while http.get(format!("{root}/status")).call().is_err() {
            assert!(
                t.elapsed() < Duration::from_secs(20),
                "chromedriver did not answer"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        let profile = downloads.join("profile");
        let caps = json!({"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {
                "binary": CHROMIUM,
                "args": ["--headless", "--no-sandbox", "--disable-gpu",
                         "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                         "--disable-quic", "--no-first-run", "--disable-background-networking",
                         "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage",
                         "--window-size=1280,800",
                         format!("--user-data-dir={}", profile.display())],
                "prefs": {"download.default_directory": downloads.display().to_string(),
                          "download.prompt_for_download": false}
            }
        }}});
        let mut r = http
            .post(format!("{root}/session"))
            .send_json(&caps)
            .unwrap();
        let v: Value = r.body_mut().read_json().unwrap();
        let session = v["value"]["sessionId"]
            .as_str()
            .unwrap_or_else(|| panic!("no session: {v}"))
            .to_string();
        let b = Browser {
            driver,
            base: format!("{root}/session/{session}"),
            http,
            downloads: downloads.to_path_buf(),
        };
        b.cmd(
            "POST",
            "/goog/cdp/execute",
            json!({"cmd": "Browser.setDownloadBehavior",
                   "params": {"behavior": "allow", "downloadPath": downloads.display().to_string()}}),
        );
        Some(b)
    }

    /// One WebDriver command; its `value`, panicking on a WebDriver error.
    pub fn cmd(&self, method: &str, path: &str, body: Value) -> Value {
        let url = format!("{}{path}", self.base);
        let mut r = match method {
            "GET" => self.http.get(&url).call(),
            "DELETE" => self.http.delete(&url).call(),
            _ => self.http.post(&url).send_json(&body),
        }
        .unwrap_or_else(|e| panic!("{method} {path}: {e}"));
        let v: Value = r.body_mut().read_json().unwrap();
        if let Some(e) = v["value"]["error"].as_str() {
            panic!("{method} {path}: {e}: {}", v["value"]["message"]);
        }
        v["value"].clone()
    }

    pub fn goto(&self, url: &str) {
        self.cmd("POST", "/url", json!({ "url": url }));
    }

    /// The element matching a CSS selector.
    pub fn find(&self, css: &str) -> String {
        let v = self.cmd(
            "POST",
            "/element",
            json!({"using": "css selector", "value": css}),
        );
        v.as_object()
            .and_then(|o| o.values().next())
            .and_then(|x| x.as_str())
            .unwrap()
            .to_string()
    }

    pub fn click(&self, css: &str) {
        let e = self.find(css);
        self.cmd("POST", &format!("/element/{e}/click"), json!({}));
    }

    /// Type into an element (a file input takes a path).
    pub fn keys(&self, css: &str, text: &str) {
        let e = self.find(css);
        self.cmd(
            "POST",
            &format!("/element/{e}/value"),
            json!({ "text": text }),
        );
    }

    pub fn text(&self, css: &str) -> String {
        let e = self.find(css);
        self.cmd("GET", &format!("/element/{e}/text"), json!({}))
            .as_str()
            .unwrap_or("")
            .to_string()
    }

    pub fn script(&self, js: &str) -> Value {
        self.cmd("POST", "/execute/sync", json!({"script": js, "args": []}))
    }

    /// A screenshot of one element.
    pub fn shot(&self, css: &str) -> image::RgbaImage {
        use base64::Engine;
        let e = self.find(css);
        let b64 = self.cmd("GET", &format!("/element/{e}/screenshot"), json!({}));
        let png = base64::engine::general_purpose::STANDARD
            .decode(b64.as_str().unwrap())
            .unwrap();
        image::load_from_memory(&png).unwrap().to_rgba8()
    }

    /// Wait until `f` holds, polling; panics with `what` after `secs`.
    pub fn wait<T>(&self, what: &str, secs: u64, mut f: impl FnMut() -> Option<T>) -> T {
        let t = Instant::now();
        loop {
            if let Some(v) = f() {
                return v;
            }
            assert!(
                t.elapsed() < Duration::from_secs(secs),
                "waited {secs} s for {what}"
            );
            std::thread::sleep(Duration::from_millis(150));
        }
    }

    /// A downloaded file, once complete.
    pub fn downloaded(&self, name: &str) -> PathBuf {
        let p = self.downloads.join(name);
        self.wait(&format!("the download of {name}"), 60, || {
            let partial = self.downloads.join(format!("{name}.crdownload"));
            (p.exists() && !partial.exists()).then(|| p.clone())
        })
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.http.delete(&self.base).call();
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

/// The share of pixels that differ by more than `tol` in some channel.
pub fn changed(a: &image::RgbaImage, b: &image::RgbaImage, tol: u8) -> f64 {
    if a.dimensions() != b.dimensions() {
        return 1.0;
    }
    let n = a
        .pixels()
        .zip(b.pixels())
        .filter(|(p, q)| p.0.iter().zip(q.0).any(|(x, y)| x.abs_diff(y) > tol))
        .count();
    n as f64 / (a.width() * a.height()) as f64
}

// ---- the Machine panel ----

/// The studio's job made on the page with `settings` (a control's CSS
/// selector and its value, each told to the page as a carver's change
/// is). Returns the job's summary.
pub fn make_job(b: &Browser, settings: &[(&str, &str)]) -> String {
    for (css, value) in settings {
        // (the page builds its controls once its script has run)
        b.wait(&format!("the control {css}"), 30, || {
            let found = b.script(&format!("return document.querySelector('{css}') !== null;"));
            found.as_bool().unwrap_or(false).then_some(())
        });
        b.script(&format!(
            "const e = document.querySelector('{css}'); e.value = '{value}'; \
             for (const k of ['input', 'change']) \
               e.dispatchEvent(new Event(k, {{bubbles: true}}));"
        ));
    }
    b.click("#tabs button[data-tab=job]");
    let summary = b.wait("the job", 240, || {
        let s = b.text("#summary");
        s.contains("lines").then_some(s)
    });
    eprintln!("the job: {summary}");
    summary
}

/// The Machine tab connected to the machine at `link`, Idle.
pub fn connect(b: &Browser, link: &Path) {
    b.click("#machine-tab");
    b.script("document.getElementById('m-port').value = ''");
    b.keys("#m-port", link.to_str().unwrap());
    b.click("#m-conn");
    wait_text(b, "#m-state", "the machine Idle", |t| t == "Idle");
}

/// Once the running job's line count on the page passes `n` (at most
/// `secs` seconds).
pub fn lines_past(b: &Browser, n: usize, secs: u64) {
    b.wait("some progress", secs, || {
        let t = b.text("#m-jobtext");
        t.split(": ")
            .nth(1)
            .and_then(|x| x.split(' ').next())
            .and_then(|k| k.parse::<usize>().ok())
            .filter(|&k| k > n)
    });
}

/// The job's end, once the page tells it; a tool change on the way is
/// continued (the carver has fitted the tool).
pub fn run_to_end(b: &Browser, what: &str) -> String {
    loop {
        let (t, p) = b.wait(what, 300, || {
            let t = b.text("#m-jobtext");
            let p = b.text("#m-pausetext");
            (t.starts_with("done")
                || t.contains("stopped")
                || t.contains("error")
                || p.contains("M0"))
            .then_some((t, p))
        });
        if p.contains("M0") && !t.starts_with("done") {
            b.click("#m-continue");
            b.wait("the change left", 30, || {
                (!b.text("#m-pausetext").contains("M0")).then_some(())
            });
            continue;
        }
        return t;
    }
}

/// The readout's work X and Y.
pub fn work_xy(b: &Browser) -> (f64, f64) {
    let v = |css| b.text(css).parse::<f64>().unwrap();
    (v("#m-wx"), v("#m-wy"))
}

/// The text of `css` once `f` accepts it (30 s at most).
pub fn wait_text(b: &Browser, css: &str, what: &str, f: impl Fn(&str) -> bool) -> String {
    b.wait(what, 30, || {
        let t = b.text(css);
        f(&t).then_some(t)
    })
}
