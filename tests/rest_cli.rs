//! Rest machining judged by the cut simulator: a 3.175 mm ball finishes,
//! a 1 mm ball follows only where it left more than the threshold.

mod common;
use common::*;
use relievo::cutter::dropcutter::HeightField;
use relievo::tool::Tool;

/// The simulated cut of a carve (`extra` flags added) at the relief's
/// samples, mm from the stock top; with the relief's heights and depth.
fn cut(d: &std::path::Path, name: &str, model: Option<&str>, extra: &[&str]) -> Carved {
    let job = d.join(format!("{name}.nc"));
    let mut args = vec!["carve"];
    if let Some(m) = model {
        args.push(m);
        if m.ends_with(".stl") {
            args.extend(["--up", "y"]);
        }
    }
    args.extend([
        "--resolution",
        "240",
        "--width",
        "60",
        "--depth",
        "3",
        "--tool",
        "ball:3.175",
        "--stepover",
        "10%",
        "--machine",
        "shapeoko",
        "--allow-deep-cuts",
        "-q",
        "-o",
        job.to_str().unwrap(),
    ]);
    args.extend(extra);
    ok(&run(&args));
    let relief = d.join(format!("{name}-relief.png"));
    let png = d.join(format!("{name}-cut.png"));
    let report = simulate_report(&job, &relief, &png, &["--machine", "shapeoko"]);
    let gouge = report["max_gouge_mm"].as_f64().unwrap();
    assert!(gouge <= 0.001, "{name}: gouge {gouge} mm");
    let (w, h, target, depth) = relief_mm(&relief);
    let (cw, ch, fine, _) = relief_mm(&png);
    let k = cw / w;
    assert!(cw == k * w && ch == k * h && k % 2 == 1);
    let got = (0..w * h)
        .map(|i| fine[((i / w) * k + k / 2) * cw + (i % w) * k + k / 2] - depth)
        .collect();
    // the most each sample's cells stand above the continuous relief
    let r = relievo::relief::file::load(&relief, None, None).unwrap();
    let surface = relievo::cutter::surface::Lattice::of(&r);
    let (cell, height) = (r.width_mm / cw as f64, r.height_mm);
    let mut over = vec![f64::MIN; w * h];
    for cj in 0..ch {
        for ci in 0..cw {
            let (x, y) = ((ci as f64 + 0.5) * cell, height - (cj as f64 + 0.5) * cell);
            let t = surface
                .height_at(x, y, |a, b| *r.heights.get(a, b) as f64)
                .unwrap();
            let i = (cj / k) * w + ci / k;
            over[i] = over[i].max(fine[cj * cw + ci] - t);
        }
    }
    Carved {
        w,
        h,
        got,
        over,
        target: target.iter().map(|t| t - depth).collect(),
        text: std::fs::read_to_string(&job).unwrap(),
    }
}

struct Carved {
    w: usize,
    h: usize,
    /// The cut at each sample, mm (0 = stock top).
    got: Vec<f64>,
    /// The relief at each sample, same frame.
    target: Vec<f64>,
    /// The most the cut stands above the continuous relief over each
    /// sample's simulated cells.
    over: Vec<f64>,
    text: String,
}

/// Acceptance: where the big ball left more than the threshold and the
/// small ball reaches, the rest pass leaves at most the small ball's
/// scallop + 0.01 mm; and it cuts nowhere farther than its reach (its
/// radius, a stepover and a sample) from a place it left more than the
/// threshold.
fn rest_finishes(name: &str, model: Option<&str>, extra: &[&str]) {
    let d = scratch(name);
    let big = cut(&d, "big", model, extra);
    let rest = cut(&d, "rest", model, &[extra, &["--rest", "ball:1"]].concat());
    assert!(rest.text.contains("for rest") && rest.text.contains("M0"));
    let (w, h) = (big.w, big.h);
    let pitch = 60.0 / w as f64;
    let hf = HeightField::new(relievo::Grid::from_vec(w, h, big.target.clone()), pitch);
    let small = Tool::parse("ball:1").unwrap();
    let reach = reachable(&hf, &small, w, h);
    let (r, s, threshold) = (0.5, 0.1, 0.03);
    // the small ball's scallop, its rows along X: s / cos(a) apart along
    // a slope a across them
    let scallop_at = |i: usize| {
        let (x, y) = (i % w, i / w);
        let (y0, y1) = (y.saturating_sub(1), (y + 1).min(h - 1));
        let t = &big.target;
        let slope = (t[y1 * w + x] - t[y0 * w + x]).abs() / ((y1 - y0) as f64 * pitch);
        let se = (s * (1.0 + slope * slope).sqrt()).min(2.0 * r);
        r - (r * r - (se / 2.0).powi(2)).sqrt()
    };
    // what the big ball left over what the small ball can reach (in a
    // crease sharper than it, the small ball's own envelope)
    let low = |i: usize| reach[i].max(big.target[i]);
    let creased = |i: usize| big.got[i] - low(i) > threshold;
    // where the big ball left more than the threshold over the relief:
    // on the simulated cells, between sample centres too, as the rest
    // pass finds it
    let left = |i: usize| big.over[i] > threshold;
    let (mut creases, mut worst_before, mut worst_after) = (0, 0.0f64, f64::MIN);
    for i in (0..w * h).filter(|&i| creased(i)) {
        creases += 1;
        worst_before = worst_before.max(big.got[i] - low(i));
        worst_after = worst_after.max(rest.got[i] - low(i) - scallop_at(i));
    }
    // the rest pass's cut, against where the big ball left too much
    let reach_mm = r + s + 2.0 * pitch;
    let k = (reach_mm / pitch).ceil() as isize;
    let (mut cut_cells, mut stray) = (0, 0);
    for i in 0..w * h {
        if rest.got[i] >= big.got[i] - 1e-3 {
            continue;
        }
        cut_cells += 1;
        let (x, y) = ((i % w) as isize, (i / w) as isize);
        let near = (-k..=k).any(|dy| {
            (-k..=k).any(|dx| {
                let (xx, yy) = (x + dx, y + dy);
                xx >= 0
                    && yy >= 0
                    && xx < w as isize
                    && yy < h as isize
                    && ((dx * dx + dy * dy) as f64).sqrt() * pitch <= reach_mm
                    && left(yy as usize * w + xx as usize)
            })
        });
        if !near {
            stray += 1;
        }
    }
    let lines = |t: &str| t.lines().count();
    eprintln!(
        "{name}: {creases} samples the 3.175 mm ball left over {threshold} mm above the 1 mm \
         ball's reach (up to {worst_before:.3} mm); after the rest pass at most {worst_after:.4} \
         mm over the small ball's scallop; the rest pass cut {cut_cells} samples, {stray} away \
         from them; {} lines, {} without rest",
        lines(&rest.text),
        lines(&big.text)
    );
    assert!(creases > 20, "{name}: too few creases to judge ({creases})");
    assert!(
        worst_after <= 0.01,
        "{name}: the rest pass leaves {worst_after} mm over the small ball's scallop"
    );
    assert_eq!(
        stray, 0,
        "{name}: the rest pass cut where the big ball finished"
    );
    std::fs::remove_dir_all(d).unwrap();
}

#[test]
fn rest_finishes_the_demo() {
    rest_finishes("rest-demo", None, &[]);
}

#[test]
fn rest_finishes_fandisk() {
    rest_finishes("rest-fandisk", Some(&fixture("fandisk.obj")), &[]);
}

/// The fandisk and Suzanne have a background, held flat by default: it
/// meets the subject in a crease all round (on the fandisk the foot of a
/// 67 degree wall, where only a pencil pass in the corner reaches). The
/// same on the free background, which rises to meet the subject.
#[test]
fn rest_finishes_on_a_free_background() {
    for (name, model) in [
        ("rest-fandisk-free", fixture("fandisk.obj")),
        ("rest-suzanne-free", fixture("suzanne.stl")),
    ] {
        rest_finishes(name, Some(&model), &["--free-background"]);
    }
}

#[test]
fn rest_finishes_suzanne() {
    rest_finishes("rest-suzanne", Some(&fixture("suzanne.stl")), &[]);
}
