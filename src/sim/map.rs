//! The deviation map: the simulated cut against the relief as a picture
//! with its scale. Residual is shown as its mean over one finishing
//! stepover, so that the scallops between rows, sampled by stock cells of
//! another pitch, do not beat into moire bands; gouges are shown cell by
//! cell. The colours are the studio's: grey within 1 um, red gouge, blue
//! material left, each full at the scale written under the map.

use crate::grid::Grid;

/// Within this (mm) a cell counts as on the relief.
const ON: f32 = 1e-3;

/// The scale of a map: `m` rounded up to 1, 2 or 5 times a power of ten.
pub fn nice_scale(m: f64) -> f64 {
    let m = m.max(0.01);
    let e = 10f64.powf(m.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|k| k * e)
        .find(|v| *v >= m * (1.0 - 1e-9))
        .unwrap_or(10.0 * e)
}

/// Colour of a deviation `d` (mm) on a map of scale `s`.
pub fn colour(d: f32, s: f64) -> [u8; 3] {
    if d.is_nan() {
        return [0, 0, 0];
    }
    let t = if d.abs() < ON {
        0.0
    } else {
        (d as f64 / s).clamp(-1.0, 1.0)
    };
    let end = if t < 0.0 {
        [0.85, 0.1, 0.1]
    } else {
        [0.1, 0.25, 0.9]
    };
    let k = t.abs();
    end.map(|e| ((0.78 + (e - 0.78) * k) * 255.0).round() as u8)
}

/// Material left as its mean over a window `len` cells long along each
/// axis (a box with fractional ends, rows then columns): over one
/// stepover, scallops average to the same value whatever their phase
/// against the cells, so they cannot beat; a maximum would not do, as a
/// scallop's cusp falls between cells. Gouges and NaN stay as they are.
pub fn smoothed(dev: &Grid<f32>, len: f64) -> Grid<f32> {
    if len <= 1.0 {
        return dev.clone();
    }
    let half = len / 2.0;
    let pass = |src: &Grid<f32>, along_x: bool| {
        let mut out = src.clone();
        let (n, m) = if along_x {
            (src.w, src.h)
        } else {
            (src.h, src.w)
        };
        let mut line = vec![0.0f32; n];
        for j in 0..m {
            for (i, v) in line.iter_mut().enumerate() {
                *v = if along_x {
                    *src.get(i, j)
                } else {
                    *src.get(j, i)
                };
            }
            for i in 0..n {
                let (lo, hi) = (i as f64 + 0.5 - half, i as f64 + 0.5 + half);
                let (mut sum, mut wsum) = (0.0f64, 0.0f64);
                for (k, v) in line
                    .iter()
                    .enumerate()
                    .take(((hi.ceil()) as usize).min(n))
                    .skip(lo.floor().max(0.0) as usize)
                {
                    let w = (hi.min(k as f64 + 1.0) - lo.max(k as f64)).max(0.0);
                    if !v.is_nan() {
                        sum += w * *v as f64;
                        wsum += w;
                    }
                }
                let v = if wsum > 0.0 {
                    (sum / wsum) as f32
                } else {
                    f32::NAN
                };
                if along_x {
                    out.set(i, j, v);
                } else {
                    out.set(j, i, v);
                }
            }
        }
        out
    };
    let left = dev.map(|d| if d.is_nan() { f32::NAN } else { d.max(0.0) });
    let mean = pass(&pass(&left, true), false);
    let mut out = dev.clone();
    for (o, e) in out.data.iter_mut().zip(&mean.data) {
        if !o.is_nan() && *o > -ON {
            *o = *e;
        }
    }
    out
}

/// 5 x 7 glyphs of what the legend writes (rows top down, 5 bits each).
fn glyph(c: char) -> [u8; 7] {
    match c {
        '0' => [14, 17, 19, 21, 25, 17, 14],
        '1' => [4, 12, 4, 4, 4, 4, 14],
        '2' => [14, 17, 1, 2, 4, 8, 31],
        '3' => [30, 1, 1, 14, 1, 1, 30],
        '4' => [2, 6, 10, 18, 31, 2, 2],
        '5' => [31, 16, 30, 1, 1, 17, 14],
        '6' => [6, 8, 16, 30, 17, 17, 14],
        '7' => [31, 1, 2, 4, 8, 8, 8],
        '8' => [14, 17, 17, 14, 17, 17, 14],
        '9' => [14, 17, 17, 15, 1, 2, 12],
        '.' => [0, 0, 0, 0, 0, 12, 12],
        '-' => [0, 0, 0, 31, 0, 0, 0],
        'm' => [0, 0, 26, 21, 21, 21, 21],
        'g' => [0, 15, 17, 17, 15, 1, 14],
        'o' => [0, 0, 14, 17, 17, 17, 14],
        'u' => [0, 0, 17, 17, 17, 19, 13],
        'e' => [0, 0, 14, 17, 31, 16, 14],
        'l' => [12, 4, 4, 4, 4, 4, 14],
        'f' => [6, 9, 8, 28, 8, 8, 8],
        't' => [8, 8, 28, 8, 8, 9, 6],
        _ => [0; 7],
    }
}

/// An RGB picture being drawn.
struct Canvas {
    w: usize,
    h: usize,
    rgb: Vec<u8>,
}

impl Canvas {
    fn put(&mut self, x: usize, y: usize, c: [u8; 3]) {
        if x < self.w && y < self.h {
            let i = 3 * (y * self.w + x);
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }
    /// Text at (x, y), its glyphs `size` pixels a dot; returns its width.
    fn text(&mut self, x: usize, y: usize, s: &str, size: usize, draw: bool) -> usize {
        for (k, c) in s.chars().enumerate() {
            for (row, bits) in glyph(c).iter().enumerate() {
                for col in 0..5 {
                    if draw && bits & (16 >> col) != 0 {
                        for dy in 0..size {
                            for dx in 0..size {
                                self.put(
                                    x + (k * 6 + col) * size + dx,
                                    y + row * size + dy,
                                    [255; 3],
                                );
                            }
                        }
                    }
                }
            }
        }
        s.chars().count() * 6 * size
    }
}

/// A number as the legend writes it.
fn label(v: f64) -> String {
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.to_string()
    }
}

/// The map as RGB rows, the legend under it: a colour bar from -scale
/// (gouge) to +scale (left) with its figures in mm. The picture is at
/// least 240 pixels wide (a narrow map is padded with black).
pub fn picture(dev: &Grid<f32>, scale: f64) -> (usize, usize, Vec<u8>) {
    let w = dev.w.max(240);
    let size = if w >= 720 { 2 } else { 1 };
    let strip = 30 * size;
    let mut c = Canvas {
        w,
        h: dev.h + strip,
        rgb: vec![0; 3 * w * (dev.h + strip)],
    };
    for y in 0..dev.h {
        for x in 0..dev.w {
            c.put(x, y, colour(*dev.get(x, y), scale));
        }
    }
    let (x0, x1) = (8 * size, w - 8 * size);
    let top = dev.h + 4 * size;
    for x in x0..x1 {
        let t = (x - x0) as f64 / (x1 - 1 - x0) as f64 * 2.0 - 1.0;
        let col = colour((t * scale) as f32, scale);
        for y in top..top + 8 * size {
            c.put(x, y, col);
        }
    }
    let ty = top + 11 * size;
    let lo = format!("{} gouge", label(-scale));
    let hi = format!("{} mm left", label(scale));
    c.text(x0, ty, &lo, size, true);
    let mid = c.text(0, 0, "0", size, false);
    c.text((x0 + x1 - mid) / 2, ty, "0", size, true);
    let hw = c.text(0, 0, &hi, size, false);
    c.text(x1.saturating_sub(hw), ty, &hi, size, true);
    (c.w, c.h, c.rgb)
}

/// The largest finishing stepover a relievo job states (mm): in its
/// header, or where a job that roughs first changes to the finishing tool.
pub fn finishing_stepover(job: &str) -> Option<f64> {
    job.lines()
        .filter(|l| l.starts_with("(strategy: finishing"))
        .filter_map(|l| {
            let rest = l.split("stepover ").nth(1)?;
            rest.split(' ').next()?.parse::<f64>().ok()
        })
        .fold(None, |m, s| Some(m.map_or(s, |m: f64| m.max(s))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_are_round() {
        assert_eq!(nice_scale(0.021), 0.05);
        assert_eq!(nice_scale(0.05), 0.05);
        assert_eq!(nice_scale(0.13), 0.2);
        assert_eq!(nice_scale(0.0), 0.01);
        assert_eq!(label(-0.05), "-0.05");
        assert_eq!(label(0.2), "0.2");
    }

    /// Scallops 0.32 mm apart sampled every 0.066 mm beat into bands;
    /// their mean over a stepover is flat, a gouge stays.
    #[test]
    fn the_mean_over_a_stepover_has_no_beat() {
        let (s, p, r) = (0.32f64, 0.066f64, 1.5875f64);
        let mut dev = Grid::new(40, 200, 0.0f32);
        for y in 0..200 {
            // a ball's scallop: the nearest row's profile, cusps between
            let u = (y as f64 * p / s)
                .fract()
                .min(1.0 - (y as f64 * p / s).fract())
                * s;
            let d = r - (r * r - u * u).sqrt();
            for x in 0..40 {
                dev.set(x, y, d as f32);
            }
        }
        dev.set(20, 100, -0.01);
        let raw: Vec<f32> = (0..200).map(|y| *dev.get(5, y)).collect();
        let mean = smoothed(&dev, s / p);
        let row: Vec<f32> = (5..195).map(|y| *mean.get(5, y)).collect();
        let spread = |v: &[f32]| {
            v.iter().copied().fold(f32::MIN, f32::max) - v.iter().copied().fold(f32::MAX, f32::min)
        };
        assert!(spread(&raw) > 0.007, "{}", spread(&raw));
        assert!(spread(&row) < 0.0005, "mean spread {}", spread(&row));
        assert_eq!(*mean.get(20, 100), -0.01);
    }

    #[test]
    fn the_legend_is_written_under_the_map() {
        let dev = Grid::new(100, 50, 0.01f32);
        let (w, h, rgb) = picture(&dev, 0.05);
        assert_eq!((w, h), (240, 80));
        let px = |x: usize, y: usize| &rgb[3 * (y * w + x)..3 * (y * w + x) + 3];
        // the bar: red at the left end, blue at the right
        assert!(px(9, 55)[0] > 200 && px(9, 55)[2] < 60);
        assert!(px(230, 55)[2] > 200 && px(230, 55)[0] < 60);
        // figures in white under it
        assert!((65..80).any(|y| (8..60).any(|x| px(x, y) == [255, 255, 255])));
    }

    /// A job that roughs first states its finishing strategy at the tool
    /// change, after the roughing's moves: the default carve's map beat
    /// into bands when only the header was read.
    #[test]
    fn stepovers_from_every_strategy_line() {
        let job = "(strategy: roughing, layers 1.290 mm, stepover 1.270 mm, stock)\n\
                   G0 Z5\nG1 X10 Z-1\nM0\n\
                   (strategy: finishing, raster zigzag, angle 0 deg, stepover 0.3175 mm +)\n\
                   G1 X0\n(strategy: finishing, raster, stepover 0.1 mm)\n";
        assert_eq!(finishing_stepover(job), Some(0.3175));
        assert_eq!(finishing_stepover("G0 X1\n"), None);
    }
}
