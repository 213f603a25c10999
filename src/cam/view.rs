//! What the user sees of a job before cutting: the toolpath from above
//! (SVG: cuts coloured by depth with a legend, rapids dashed, the origin
//! and a scale bar) and the simulated cut, shaded (PNG).

use super::judge::Judged;
use super::layout::Plan;
use crate::error::Result;
use crate::gcode::{Kind, Program};
use crate::grid::Grid;
use crate::relief::Relief;
use glam::DVec3;
use std::fmt::Write;

/// Depth bands in the SVG legend.
const BANDS: usize = 8;
/// Moves per SVG path: keeps each `d` attribute small enough for common
/// viewers (librsvg refuses attributes over about 10 MB).
const PER_PATH: usize = 2000;

/// Colour of depth share `t` (0 = stock top, 1 = deepest): light to dark.
fn ramp(t: f64) -> String {
    let stops = [
        (250.0, 205.0, 90.0),
        (226.0, 120.0, 40.0),
        (120.0, 30.0, 90.0),
        (25.0, 25.0, 90.0),
    ];
    let t = t.clamp(0.0, 1.0) * (stops.len() - 1) as f64;
    let k = (t.floor() as usize).min(stops.len() - 2);
    let f = t - k as f64;
    let (a, b) = (stops[k], stops[k + 1]);
    let mix = |x: f64, y: f64| (x + (y - x) * f).round() as u8;
    format!(
        "#{:02x}{:02x}{:02x}",
        mix(a.0, b.0),
        mix(a.1, b.1),
        mix(a.2, b.2)
    )
}

/// Top view of the job(s) as SVG, in mm with Y up.
pub fn top_view(progs: &[Program], relief: &Relief, plan: &Plan, z_shift: f64) -> String {
    let (x0, y0, w, h, _) = plan.frame(z_shift).stock;
    let pad = 6.0;
    let legend_h = 14.0;
    let deepest = progs
        .iter()
        .flat_map(|p| &p.segments)
        .map(|s| s.a.z.min(s.b.z) - z_shift)
        .fold(-1e-3, f64::min);
    // SVG y runs down
    let xy = |p: DVec3| (p.x - x0, h - (p.y - y0));
    let mut body = String::new();
    let _ = write!(
        body,
        r##"<rect x="0" y="0" width="{w:.3}" height="{h:.3}" fill="#f6f1e7" stroke="#888" stroke-width="0.2"/>"##
    );
    let (px, py) = (
        plan.shift.x - x0,
        h - (plan.shift.y - y0) - relief.height_mm,
    );
    let _ = write!(
        body,
        r##"<rect x="{px:.3}" y="{py:.3}" width="{:.3}" height="{:.3}" fill="none" stroke="#bbb" stroke-width="0.15" stroke-dasharray="1 1"/>"##,
        relief.width_mm, relief.height_mm
    );
    // cuts by depth band, each band in paths of at most PER_PATH moves
    let band = |z: f64| {
        (((z - z_shift) / deepest) * BANDS as f64)
            .floor()
            .clamp(0.0, BANDS as f64 - 1.0) as usize
    };
    let mut cuts: Vec<Vec<(DVec3, DVec3)>> = vec![Vec::new(); BANDS];
    let mut rapids: Vec<(DVec3, DVec3)> = Vec::new();
    for s in progs.iter().flat_map(|p| &p.segments) {
        if (s.b - s.a).truncate().length() < 1e-9 {
            continue;
        }
        match s.kind {
            Kind::Feed => cuts[band(s.a.z.min(s.b.z))].push((s.a, s.b)),
            Kind::Rapid => rapids.push((s.a, s.b)),
        }
    }
    let path = |moves: &[(DVec3, DVec3)], style: &str, body: &mut String| {
        for chunk in moves.chunks(PER_PATH) {
            let mut d = String::new();
            let mut last: Option<DVec3> = None;
            for &(a, b) in chunk {
                if last != Some(a) {
                    let (x, y) = xy(a);
                    let _ = write!(d, "M{x:.3} {y:.3}");
                }
                let (x, y) = xy(b);
                let _ = write!(d, "L{x:.3} {y:.3}");
                last = Some(b);
            }
            let _ = write!(body, r#"<path d="{d}" fill="none" {style}/>"#);
        }
    };
    for (k, moves) in cuts.iter().enumerate() {
        let c = ramp((k as f64 + 0.5) / BANDS as f64);
        path(
            moves,
            &format!(r#"stroke="{c}" stroke-width="0.08""#),
            &mut body,
        );
    }
    path(
        &rapids,
        r##"stroke="#d23c2a" stroke-width="0.1" stroke-dasharray="0.8 0.5""##,
        &mut body,
    );
    // origin: a cross at X0 Y0
    let (ox, oy) = xy(DVec3::ZERO);
    let _ = write!(
        body,
        r##"<g stroke="#000" stroke-width="0.3"><line x1="{:.3}" y1="{oy:.3}" x2="{:.3}" y2="{oy:.3}"/><line x1="{ox:.3}" y1="{:.3}" x2="{ox:.3}" y2="{:.3}"/></g><text x="{:.3}" y="{:.3}" font-size="2.5" font-family="sans-serif">X0 Y0</text>"##,
        ox - 3.0,
        ox + 3.0,
        oy - 3.0,
        oy + 3.0,
        ox + 1.0,
        oy - 1.0
    );
    // legend and scale bar under the stock
    let ly = h + 4.0;
    let sw = (w / BANDS as f64).min(12.0);
    for k in 0..BANDS {
        let c = ramp((k as f64 + 0.5) / BANDS as f64);
        let _ = write!(
            body,
            r#"<rect x="{:.3}" y="{ly:.3}" width="{sw:.3}" height="2" fill="{c}"/>"#,
            k as f64 * sw
        );
    }
    let _ = write!(
        body,
        r##"<text x="0" y="{:.3}" font-size="2.2" font-family="sans-serif">cut depth 0 to {:.2} mm (light to dark); rapids red dashed</text>"##,
        ly + 5.0,
        -deepest
    );
    let bar = 10.0f64.min(w / 4.0);
    let bx = w - bar;
    let _ = write!(
        body,
        r##"<line x1="{bx:.3}" y1="{:.3}" x2="{w:.3}" y2="{:.3}" stroke="#000" stroke-width="0.4"/><text x="{bx:.3}" y="{:.3}" font-size="2.2" font-family="sans-serif">{bar} mm</text>"##,
        ly + 1.0,
        ly + 1.0,
        ly + 5.0
    );
    let (vw, vh) = (w + 2.0 * pad, h + 2.0 * pad + legend_h);
    format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="{} {} {vw:.3} {vh:.3}" width="{vw:.3}mm" height="{vh:.3}mm">{body}</svg>"#,
        -pad, -pad
    ) + "\n"
}

/// The simulated cut of the job, shaded: light from `light` (azimuth,
/// elevation in degrees; default upper left, 35 degrees up), contrast
/// stretched over the shades present. At the relief's own pitch: where
/// the job was judged on finer cells (an odd number per sample, centred
/// on the samples), the cell at each sample's centre.
pub fn simulated_preview(
    j: &Judged,
    relief: &Relief,
    light: Option<(f64, f64)>,
) -> Result<Vec<u8>> {
    let k = ((relief.pitch_mm() / j.stock.pitch).round() as usize).max(1);
    let (w, h) = (j.cut.w / k, j.cut.h / k);
    let heights = (0..w * h)
        .map(|i| {
            let z = *j.cut.get((i % w) * k + k / 2, (i / w) * k + k / 2);
            (z as f64 + relief.depth_mm).max(0.0) as f32
        })
        .collect();
    let carved = Relief {
        heights: Grid::from_vec(w, h, heights),
        width_mm: j.stock.width,
        height_mm: j.stock.height,
        depth_mm: relief.depth_mm,
    };
    Ok(crate::relief::file::png8(&crate::preview::shade_lit(
        &carved, light,
    )))
}
