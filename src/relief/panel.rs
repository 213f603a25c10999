//! Shaping the whole panel after the relief is made, as carvers do in
//! Aspire or Carveco: a fade of the heights toward one side, and a tilt
//! (a plane added) so that a scene leans back or a plaque drains water.

use crate::bail;
use crate::error::Result;
use crate::grid::Grid;
use rayon::prelude::*;

/// A direction in the picture: degrees counter-clockwise from the right
/// (0 = right, 90 = top, 180 = left, 270 = bottom).
fn direction(s: &str, what: &str) -> Result<f64> {
    let d = match s.trim().to_ascii_lowercase().as_str() {
        "right" => 0.0,
        "top" | "up" => 90.0,
        "left" => 180.0,
        "bottom" | "down" => 270.0,
        t => match t.parse::<f64>() {
            Ok(v) if v.is_finite() => v,
            _ => bail!(
                "{what}: direction '{s}' must be right, top, left, bottom or degrees counter-clockwise from the right"
            ),
        },
    };
    Ok(d)
}

/// Heights fade linearly toward one side: at the far side in `toward`
/// they are multiplied by 1 - `amount`, at the opposite side by 1.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Fade {
    pub toward_deg: f64,
    pub amount: f64,
}

/// A plane added to the relief, rising at `angle_deg` toward `toward_deg`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Tilt {
    pub angle_deg: f64,
    pub toward_deg: f64,
}

impl Fade {
    /// `DIR[:AMOUNT]`, amount 0..1 (default 1: fades to nothing).
    pub fn parse(s: &str) -> Result<Fade> {
        let (dir, amount) = s.split_once(':').unwrap_or((s, "1"));
        let toward_deg = direction(dir, "--fade")?;
        let amount: f64 = match amount.trim().parse() {
            Ok(a) if (0.0..=1.0).contains(&a) => a,
            _ => bail!("--fade {s}: the amount '{amount}' must be a number from 0 to 1"),
        };
        Ok(Fade { toward_deg, amount })
    }
}

impl Tilt {
    /// `DEG[:DIR]`: the angle in degrees (under 45) and the side the panel
    /// rises toward (default top).
    pub fn parse(s: &str) -> Result<Tilt> {
        let (angle, dir) = s.split_once(':').unwrap_or((s, "top"));
        let angle_deg: f64 = match angle.trim().parse() {
            Ok(a) if (0.0..45.0).contains(&a) => a,
            _ => bail!("--tilt {s}: the angle '{angle}' must be degrees from 0 to under 45"),
        };
        Ok(Tilt {
            angle_deg,
            toward_deg: direction(dir, "--tilt")?,
        })
    }

    /// How much the plane rises over a panel of `w_mm` x `h_mm`.
    pub fn rise(&self, w_mm: f64, h_mm: f64) -> f64 {
        let (s, c) = self.toward_deg.to_radians().sin_cos();
        self.angle_deg.to_radians().tan() * (c.abs() * w_mm + s.abs() * h_mm)
    }
}

/// Position of every sample along a picture direction, 0 at the back
/// side and 1 at the side it points to (pixel centres, y up).
fn along(w: usize, h: usize, toward_deg: f64) -> impl Fn(usize, usize) -> f64 + Sync {
    let (s, c) = toward_deg.to_radians().sin_cos();
    let at = move |x: f64, y: f64| c * x + s * y;
    let corners = [
        (0.0, 0.0),
        (w as f64, 0.0),
        (0.0, h as f64),
        (w as f64, h as f64),
    ];
    let (lo, hi) = corners
        .iter()
        .map(|&(x, y)| at(x, y))
        .fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(v), h.max(v)));
    let span = (hi - lo).max(1e-12);
    move |x, y| (at(x as f64 + 0.5, (h - y) as f64 - 0.5) - lo) / span
}

/// Change every height by `f(height, position along toward_deg)`.
fn along_each(heights: &mut Grid<f32>, toward_deg: f64, f: impl Fn(f32, f64) -> f32 + Sync) {
    let w = heights.w;
    let pos = along(w, heights.h, toward_deg);
    heights
        .data
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, v) in row.iter_mut().enumerate() {
                *v = f(*v, pos(x, y));
            }
        });
}

/// Multiply heights (mm above 0) by the fade.
pub fn fade(heights: &mut Grid<f32>, f: &Fade) {
    along_each(heights, f.toward_deg, |v, s| {
        v * (1.0 - f.amount * s) as f32
    });
}

/// Add the tilt's plane (0 at the low side, `rise` at the high side).
pub fn tilt(heights: &mut Grid<f32>, t: &Tilt, w_mm: f64, h_mm: f64) {
    let rise = t.rise(w_mm, h_mm);
    along_each(heights, t.toward_deg, |v, s| v + (rise * s) as f32);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fade_and_tilt_parse_and_act_along_their_direction() {
        assert_eq!(
            Fade::parse("top:0.5").unwrap(),
            Fade {
                toward_deg: 90.0,
                amount: 0.5
            }
        );
        assert!(Fade::parse("top:2").is_err() && Fade::parse("sideways").is_err());
        assert!(Tilt::parse("50").is_err());
        let t = Tilt::parse("10:right").unwrap();
        assert!((t.rise(100.0, 50.0) - 100.0 * 10f64.to_radians().tan()).abs() < 1e-9);
        let mut g = Grid::new(10, 4, 1.0f32);
        fade(&mut g, &Fade::parse("top").unwrap());
        // the top row nearly vanishes, the bottom row keeps nearly all
        assert!(*g.get(3, 0) < 0.15 && *g.get(3, 3) > 0.85);
        let mut g = Grid::new(10, 4, 0.0f32);
        tilt(&mut g, &t, 100.0, 40.0);
        assert!(*g.get(0, 2) < *g.get(9, 2) && (*g.get(9, 2) - *g.get(9, 0)).abs() < 1e-6);
    }
}
