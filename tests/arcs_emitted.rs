//! Arcs fitted by the toolpath and written by the emitter read back, through
//! the G-code interpreter, as the very chords the fit checked: the three
//! layers agree on GRBL's chords.

use glam::DVec3;
use relievo::gcode::emit::{Emitter, Settings};
use relievo::toolpath::arcs;

fn no_dwell() -> Settings {
    Settings {
        feed: 1000.0,
        plunge_feed: 300.0,
        rpm: 18000.0,
        safe_z: 5.0,
        dwell: 0.0,
    }
}

/// The ends of a program's feed moves (arcs as their chords).
fn feeds(g: &str) -> Vec<DVec3> {
    let p = relievo::gcode::program(g).unwrap();
    p.segments
        .iter()
        .filter(|s| s.kind == relievo::gcode::Kind::Feed)
        .map(|s| s.b)
        .collect()
}

/// A fitted row written with arcs reads back as the very chords the
/// fit checked.
#[test]
fn arcs_read_back_as_the_checked_chords() {
    let s = no_dwell();
    for (y, rev) in [(3.0, false), (3.3, true)] {
        let mut pts: Vec<DVec3> = (0..=400)
            .map(|i| {
                let x = i as f64 * 0.05;
                DVec3::new(x, y, -2.0 + 0.8 * (x * 0.4).sin() + 0.3 * (x * 0.9).cos())
            })
            .collect();
        if rev {
            pts.reverse();
        }
        let fitted = arcs::fit(&pts, 0.01);
        let mut e = Emitter::new(&[], &s, false, 0.0);
        e.arcs = true;
        e.pass(&fitted, &s, 5.0);
        let g = e.finish(&s);
        assert!(g.contains("G18"), "{g}");
        let cut = feeds(&g);
        assert_eq!(cut.len(), fitted.len(), "one chord per fitted point");
        for (a, b) in cut.iter().zip(&fitted) {
            assert!((*a - *b).length() < 3e-4, "{a} vs {b}");
        }
    }
}
