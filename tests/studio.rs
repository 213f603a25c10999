//! `relievo studio` in a real browser (headless Chromium over WebDriver),
//! judged on screenshots: a carver opens a model, moves the depth slider,
//! checks the job and downloads it; the command line shown remakes the
//! relief bit for bit; bad uploads and requests get errors and the studio
//! goes on serving.

mod common;

use common::browser::{agent, changed, Browser, Studio};
use common::{fixture, ok, scratch, simulate_report};
use std::io::{Read, Write};

/// A screenshot of the 3D view once it stops changing.
fn settled(b: &Browser) -> image::RgbaImage {
    let mut last = b.shot("#scene3d");
    b.wait("the view to settle", 60, || {
        std::thread::sleep(std::time::Duration::from_millis(300));
        let now = b.shot("#scene3d");
        let same = changed(&last, &now, 2) == 0.0;
        last = now;
        same.then(|| last.clone())
    })
}

/// What a view shows: the share of its pixels off the background, and
/// the standard deviation of their luminance (a blank view has neither).
fn contrast(img: &image::RgbaImage) -> (f64, f64) {
    let bg = img.get_pixel(2, 2).0;
    let l: Vec<f64> = img
        .pixels()
        .filter(|p| p.0.iter().zip(bg).any(|(a, b)| a.abs_diff(b) > 3))
        .map(|p| 0.3 * p[0] as f64 + 0.59 * p[1] as f64 + 0.11 * p[2] as f64)
        .collect();
    let n = l.len().max(1) as f64;
    let m = l.iter().sum::<f64>() / n;
    let sd = (l.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt();
    (l.len() as f64 / (img.width() * img.height()) as f64, sd)
}

/// Fails when a view shows next to nothing.
fn shows_something(img: &image::RgbaImage, what: &str) {
    let (share, sd) = contrast(img);
    eprintln!(
        "{what}: {:.0}% of the view drawn, luminance deviation {sd:.1}",
        100.0 * share
    );
    assert!(share > 0.08 && sd > 4.0, "{what} is blank");
}

/// Whether the status line tells of a relief `res` pixels on its long side.
fn relief_at(b: &Browser, res: usize) -> bool {
    let (s, err) = status(b);
    !err && (s.starts_with(&format!("relief {res} ×")) || s.contains(&format!("× {res} px")))
}

fn status(b: &Browser) -> (String, bool) {
    let err = b.script("return document.getElementById('status').className === 'error'");
    (b.text("#status"), err.as_bool().unwrap_or(false))
}

#[test]
fn a_carver_designs_checks_and_downloads_a_job() {
    let dir = scratch("studio-e2e");
    let Some(b) = Browser::start(&dir) else {
        return;
    };
    let studio = Studio::start(&[]);
    b.goto(&studio.url);
    b.wait("the demo relief", 60, || relief_at(&b, 512).then_some(()));
    // small enough for two cores, then a shipped model from the file picker
    b.keys("#resolution", "256");
    b.wait("the 256 px demo relief", 60, || {
        relief_at(&b, 256).then_some(())
    });
    b.keys("#file", &fixture("spot.obj"));
    b.wait("spot.obj on the bench", 60, || {
        (b.text("#model-name").starts_with("spot.obj") && relief_at(&b, 256)).then_some(())
    });
    let before = settled(&b);
    before.save(dir.join("relief-before.png")).unwrap();
    shows_something(&before, "the relief view");
    // the depth slider 20 steps down, one relief asked for at each step
    // (the studio drops the ones overtaken): the relief view changes
    b.keys("#depth", &"\u{E012}".repeat(20));
    let after = b.wait("the relief view to change", 60, || {
        let now = b.shot("#scene3d");
        (changed(&before, &now, 4) > 0.03).then_some(now)
    });
    eprintln!(
        "depth 5 -> 3 mm: {:.1}% of the view's pixels changed",
        100.0 * changed(&before, &after, 4)
    );
    b.wait("the 3 mm relief", 60, || {
        status(&b).0.ends_with("× 3.00 mm").then_some(())
    });
    let relief_view = settled(&b);
    relief_view.save(dir.join("relief-after.png")).unwrap();
    // the model as the relief's camera sees it
    b.click("#tabs button[data-tab=model]");
    let model_view = settled(&b);
    model_view.save(dir.join("model.png")).unwrap();
    shows_something(&model_view, "the model view");
    assert!(changed(&relief_view, &model_view, 12) > 0.05);
    // the job: its view differs from the relief's, its summary is shown
    b.click("#tabs button[data-tab=job]");
    let summary = b.wait("the job's summary", 240, || {
        let s = b.text("#summary");
        s.contains("lines").then_some(s)
    });
    eprintln!("job summary: {summary}");
    let shown: f64 = summary
        .split("simulated gouge ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no gouge in {summary}"));
    assert!(shown <= 0.001, "{summary}");
    let job_view = settled(&b);
    job_view.save(dir.join("job.png")).unwrap();
    assert!(changed(&relief_view, &job_view, 12) > 0.05);
    shows_something(&job_view, "the job view");
    let legend = b.script("return getComputedStyle(document.getElementById('legend')).display");
    assert_eq!(legend, "block", "no deviation legend");
    // downloads, judged by the simulator
    for id in ["#dl-nc", "#dl-png", "#dl-json", "#dl-stl", "#dl-svg"] {
        b.click(id);
    }
    let nc = b.downloaded("job.nc");
    let png = b.downloaded("relief.png");
    b.downloaded("relief.json");
    let stl = std::fs::read(b.downloaded("relief.stl")).unwrap();
    let triangles = u32::from_le_bytes(stl[80..84].try_into().unwrap()) as usize;
    assert!(triangles > 2 * 137 * 256 && stl.len() == 84 + 50 * triangles);
    let svg = std::fs::read_to_string(b.downloaded("job.svg")).unwrap();
    assert!(svg.contains("<svg"), "{}", &svg[..svg.len().min(200)]);
    let report = simulate_report(&nc, &png, &dir.join("cut.png"), &[]);
    let gouge = report["max_gouge_mm"].as_f64().unwrap();
    eprintln!(
        "downloaded job.nc: {} lines, simulated gouge {gouge} mm, residual max {} mm",
        report["lines"], report["max_residual_mm"]
    );
    assert!(gouge <= 0.001, "the downloaded job gouges {gouge} mm");
    // the command line shown remakes the relief bit for bit
    let command = b.text("#command");
    let line = command.lines().next().unwrap().to_string();
    eprintln!("command shown: {line}");
    let words: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(&words[..3], ["relievo", "relief", "spot.obj"], "{line}");
    assert!(!line.contains('\''), "{line}");
    let again = scratch("studio-e2e-cli");
    std::fs::copy(fixture("spot.obj"), again.join("spot.obj")).unwrap();
    ok(&common::bin()
        .args(&words[1..])
        .arg("-q")
        .current_dir(&again)
        .output()
        .unwrap());
    let made = std::fs::read(again.join("relief.png")).unwrap();
    assert!(
        made == std::fs::read(&png).unwrap(),
        "`{line}` made a different relief from the studio's"
    );
}

#[test]
fn bad_uploads_and_requests_leave_the_studio_serving() {
    let dir = scratch("studio-bad");
    let Some(b) = Browser::start(&dir) else {
        return;
    };
    let mut studio = Studio::start(&[]);
    b.goto(&studio.url);
    b.wait("the demo relief", 60, || {
        status(&b).0.starts_with("relief").then_some(())
    });
    // garbage and an empty file through the page: an error shown there
    let garbage = dir.join("garbage.obj");
    let noise: Vec<u8> = (0..5000u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    std::fs::write(&garbage, noise).unwrap();
    let empty = dir.join("empty.stl");
    std::fs::write(&empty, b"").unwrap();
    for (file, says) in [(&garbage, "garbage.obj"), (&empty, "empty")] {
        b.keys("#file", file.to_str().unwrap());
        let (msg, _) = b.wait("an upload error", 60, || {
            let s = status(&b);
            (s.1 && s.0.contains(says)).then_some(s)
        });
        eprintln!("{}: {msg}", file.display());
        assert!(!msg.contains(&dir.display().to_string()), "{msg}");
    }
    // a huge file is refused by the page before it is sent...
    b.script("upload(new File([new ArrayBuffer(studio.options.max_upload + 1)], 'huge.stl'))");
    let (msg, _) = b.wait("the huge file's error", 30, || {
        let s = status(&b);
        (s.1 && s.0.contains("huge.stl")).then_some(s)
    });
    assert!(msg.contains("more than the 128 MB"), "{msg}");
    // ...and by the server from its declared length alone
    let host = studio.url.trim_start_matches("http://").to_string();
    // (the secret first: not while a half-sent request holds a connection)
    let secret = secret_of(&studio.url);
    let mut s = std::net::TcpStream::connect(&host).unwrap();
    write!(
        s,
        "POST /api/model?name=huge.stl HTTP/1.1\r\nHost: {host}\r\nX-Relievo-Secret: {secret}\r\nContent-Length: 200000000\r\n\r\nsolid",
    )
    .unwrap();
    let mut head = [0u8; 64];
    let n = s.read(&mut head).unwrap();
    let head = String::from_utf8_lossy(&head[..n]).to_string();
    assert!(head.starts_with("HTTP/1.1 413"), "{head}");
    drop(s);
    // malformed requests: a clear error each
    let http = agent();
    let api = |path: &str, body: &str| {
        let mut r = http
            .post(format!("{}{path}", studio.url))
            .header("X-Relievo-Secret", &secret)
            .content_type("application/json")
            .send(body)
            .unwrap();
        let code = r.status().as_u16();
        (code, r.body_mut().read_to_string().unwrap())
    };
    for (path, body, code, says) in [
        ("/api/relief", "{not json", 400, "bad settings"),
        (
            "/api/relief",
            r#"{"relief": {"colour": 3}}"#,
            400,
            "unknown setting",
        ),
        (
            "/api/relief",
            r#"{"relief": {"fade": "sideways"}}"#,
            400,
            "--fade",
        ),
        (
            "/api/relief",
            r#"{"relief": {"resolution": 100000}}"#,
            400,
            "--resolution",
        ),
        ("/api/job", r#"{"cut": {"tool": "spoon:3"}}"#, 400, "spoon"),
        ("/api/model", "x", 400, "name"),
        ("/api/nothing", "", 404, "no such page"),
    ] {
        let (got, text) = api(path, body);
        eprintln!("{path} {body}: {got} {text}");
        assert_eq!(got, code, "{path} {body}: {text}");
        assert!(text.contains(says), "{path} {body}: {text}");
    }
    // a bad setting typed in the page: its error shown there, then fixed
    b.keys("#fade", "sideways");
    b.wait("the fade error", 60, || {
        let s = status(&b);
        (s.1 && s.0.contains("--fade")).then_some(())
    });
    b.script("const f = document.getElementById('fade'); f.value = ''; f.dispatchEvent(new Event('input'))");
    b.wait("a relief again", 60, || {
        let s = status(&b);
        (!s.1 && s.0.starts_with("relief")).then_some(())
    });
    // and a good file still opens: a depth picture (a dome)
    let dome = dir.join("dome.png");
    let v: Vec<u16> = (0..64 * 48)
        .map(|i| {
            let (x, y) = ((i % 64) as f64 - 32.0, (i / 64) as f64 - 24.0);
            (65535.0 * (1.0 - (x * x + y * y) / 800.0).max(0.0)) as u16
        })
        .collect();
    common::write_png16(&dome, 64, 48, &v);
    b.keys("#file", dome.to_str().unwrap());
    b.wait("the dome's relief", 60, || {
        (b.text("#model-name").starts_with("dome.png") && relief_at(&b, 64)).then_some(())
    });
    assert!(studio.alive(), "the studio died");
    let r = http
        .get(format!("{}/api/model", studio.url))
        .call()
        .unwrap();
    assert_eq!(r.status().as_u16(), 200);
}

/// The studio answers only this machine's own pages: a request naming
/// another host (a DNS name pointed at 127.0.0.1 by another site, DNS
/// rebinding) or posted from another site's page is refused with 403 and
/// changes nothing; the page's own requests go through.
#[test]
fn another_site_cannot_use_the_studio() {
    use std::io::{Read, Write};
    let studio = Studio::start(&[]);
    let authority = studio
        .url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    let port = authority.rsplit_once(':').unwrap().1.to_string();
    let secret = secret_of(&studio.url);
    let ask_as = |method: &str,
                  path: &str,
                  host: &str,
                  origin: Option<&str>,
                  key: &str|
     -> (u16, String) {
        let mut s = std::net::TcpStream::connect(&authority).unwrap();
        let origin = origin
            .map(|o| format!("Origin: {o}\r\n"))
            .unwrap_or_default();
        write!(
            s,
            "{method} {path} HTTP/1.1\r\nHost: {host}\r\n{origin}X-Relievo-Secret: {key}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut text = String::new();
        s.read_to_string(&mut text).unwrap();
        let code = text.split_whitespace().nth(1).unwrap().parse().unwrap();
        (code, text)
    };
    let ask = |method: &str, path: &str, host: &str, origin: Option<&str>| {
        ask_as(method, path, host, origin, &secret)
    };
    let ours = format!("127.0.0.1:{port}");
    assert_eq!(ask("GET", "/api/options", &ours, None).0, 200);
    assert_eq!(ask("GET", "/", &format!("localhost:{port}"), None).0, 200);
    let (code, text) = ask("GET", "/api/model", &format!("rebind.example:{port}"), None);
    assert_eq!(code, 403, "{text}");
    assert!(
        text.contains("refused: the request names host 'rebind.example"),
        "{text}"
    );
    let evil = Some("http://evil.example");
    let (code, text) = ask("POST", "/api/demo", &ours, evil);
    assert_eq!(code, 403, "{text}");
    assert!(text.contains("a page from 'http://evil.example'"), "{text}");
    let page = format!("http://127.0.0.1:{port}");
    assert_eq!(ask("POST", "/api/demo", &ours, Some(&page)).0, 200);
    // without the secret the page holds, or with another, nothing changes
    for key in ["", "0123456789abcdef0123456789abcdef"] {
        let (code, text) = ask_as("POST", "/api/demo", &ours, Some(&page), key);
        assert_eq!(code, 403, "{text}");
        assert!(text.contains("lacks this studio's secret"), "{text}");
    }
}

/// The secret the studio's page holds (a page from another site cannot
/// read it: the browser keeps another origin's response from it).
fn secret_of(url: &str) -> String {
    let page = agent()
        .get(url)
        .call()
        .unwrap()
        .body_mut()
        .read_to_string()
        .unwrap();
    let at = page
        .find("name=\"relievo-secret\" content=\"")
        .expect("the page holds a secret")
        + 31;
    page[at..at + 32].to_string()
}

/// The page holds every setting of the command line's relief and cutting
/// definition: its own controls, and the More section built from the
/// definition the server describes (so a setting added to the definition
/// appears here with nothing else to write). A setting set there reaches
/// the job and its command line.
#[test]
fn every_setting_of_the_command_line_is_in_the_page() {
    use relievo::ops::settings::{CutSettings, Given, ReliefSettings, FILE_MAKING};
    let dir = scratch("studio-settings");
    let Some(b) = Browser::start(&dir) else {
        return;
    };
    let studio = Studio::start(&[]);
    b.goto(&studio.url);
    b.wait("the demo relief", 60, || relief_at(&b, 512).then_some(()));
    let names = |js: &str| -> Vec<String> { serde_json::from_value(b.script(js)).unwrap() };
    let mut shown = names(
        "const own = (a) => [...document.querySelectorAll(`[data-${a}]`)].map(e => e.dataset[a]);
         return Object.keys(reliefSettings()).concat(Object.keys(cutSettings()), own('k'), own('c'))",
    );
    let more =
        names("return [...document.querySelectorAll('[data-more]')].map(e => e.dataset.name)");
    assert!(more.len() >= 20, "the More section holds {more:?}");
    shown.extend(more);
    for name in Given::<ReliefSettings>::names()
        .into_iter()
        .chain(Given::<CutSettings>::names())
        .filter(|n| !FILE_MAKING.contains(&n.as_str()))
    {
        assert!(
            shown.contains(&name),
            "the page has no control for the setting '{name}'"
        );
    }
    // a relief setting and a cutting one from the More section
    b.click("#more summary");
    b.keys("#resolution", "256");
    b.keys("#more-relief [data-name=base]", "3.5");
    b.keys("#more-cut [data-name=safe_z]", "8");
    let section = b.shot("#more");
    section.save(dir.join("more-settings.png")).unwrap();
    let (ink, sd) = contrast(&section);
    eprintln!("More section: {ink:.3} of its pixels inked, sd {sd:.1}");
    assert!(
        ink > 0.02 && sd > 10.0,
        "the More section looks blank ({ink}, {sd})"
    );
    b.click("#tabs button[data-tab=job]");
    let command = b.wait("the job's command line with both settings", 240, || {
        let c = b.text("#command");
        (c.contains("--base 3.5") && c.contains("--safe-z 8")).then_some(c)
    });
    eprintln!("command: {command}");
    let summary = b.wait("the job's summary", 240, || {
        let s = b.text("#summary");
        s.contains("lines").then_some(s)
    });
    assert!(!status(&b).1, "{summary}");
}
