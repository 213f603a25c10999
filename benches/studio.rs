//! The studio's design loop in a real browser (headless Chromium, its
//! WebGL in software), on the Stanford bunny at 1024 px: from a slider
//! change (the depth, one step) to the new relief drawn, and from a new
//! view angle (the yaw, one degree) to its relief drawn, as the page
//! measures them (input event to the frame after the draw).
//! `cargo bench --bench studio` (the bunny from fixtures/ and Chromium).

#[path = "../tests/common/mod.rs"]
mod common;

use common::browser::{Browser, Studio};

/// Press `key` on `control` `n` times, one relief at a time; the page's
/// timings of each (ms: input to drawn, and the request alone).
fn steps(b: &Browser, control: &str, key: &str, n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for _ in 0..n {
        let drawn = b.script("return studio.drawn").as_u64().unwrap();
        b.keys(control, key);
        b.wait("the relief drawn", 60, || {
            (b.script("return studio.drawn").as_u64().unwrap() > drawn).then_some(())
        });
        let s = b.script("const r = studio.stats.relief; return r[r.length - 1]");
        out.push((
            s["total_ms"].as_f64().unwrap(),
            s["request_ms"].as_f64().unwrap(),
        ));
    }
    out
}

fn report(what: &str, v: &[(f64, f64)]) {
    let mut t: Vec<f64> = v.iter().map(|x| x.0).collect();
    let mut r: Vec<f64> = v.iter().map(|x| x.1).collect();
    t.sort_by(f64::total_cmp);
    r.sort_by(f64::total_cmp);
    println!(
        "{what}: input to drawn median {:.0} ms, max {:.0} ms (the request alone: median {:.0} ms, max {:.0} ms), {} changes",
        t[t.len() / 2],
        t[t.len() - 1],
        r[r.len() / 2],
        r[r.len() - 1],
        t.len()
    );
}

fn main() {
    let dir = common::scratch("bench-studio");
    let Some(b) = Browser::start(&dir) else {
        return;
    };
    let bunny = common::fixture("stanford-bunny.obj");
    let studio = Studio::start(&[&bunny]);
    b.goto(&studio.url);
    let at = |px: &str| {
        b.wait("the relief", 120, || {
            b.text("#status").contains(px).then_some(())
        })
    };
    at("relief ");
    b.keys("#resolution", "1024");
    at("relief 1024 × ");
    // warm: the first depth change shapes the field once
    steps(&b, "#depth", "\u{E012}", 1);
    report(
        "depth slider, 1024 px bunny",
        &steps(&b, "#depth", "\u{E012}", 15),
    );
    report(
        "view angle (yaw), 1024 px bunny",
        &steps(&b, "#yaw", "\u{E014}", 15),
    );
    drop(studio);
}
