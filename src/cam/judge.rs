//! The simulator as the judge of every job relievo writes: each file cut
//! in turn into the stock it states, every move's engagement measured,
//! the result compared with the relief.

use super::layout::Plan;
use crate::cutter::dropcutter::HeightField;
use crate::error::Result;
use crate::gcode::{Kind, Program};
use crate::grid::Grid;
use crate::relief::Relief;
use crate::sim::{self, Engagement, MoveCut, Over, Stock};
use crate::tool::Tool;

pub struct Judged {
    pub stock: Stock,
    /// The cut surface (0 = stock top).
    pub cut: Grid<f32>,
    pub engagement: Engagement,
    /// Residual material over the relief: max and mean, mm.
    pub residual: (f64, f64),
    /// The deepest cut into the relief: at the cells, and exactly along
    /// every flat's move (`sim::move_gouge`; a ball's were checked so as
    /// they were made).
    pub gouge: f64,
    /// Per file: every segment's cut, and the tool stretches.
    moves: Vec<(Vec<MoveCut>, sim::ToolRuns)>,
}

/// The programs (in stock-top Z once `z_shift` is taken off) cut in turn.
pub fn run(
    progs: &[Program],
    relief: &Relief,
    plan: &Plan,
    z_shift: f64,
    cell: f64,
) -> Result<Judged> {
    let stock = plan.stock_in_job(cell, relief.height_mm);
    let (w, h) = stock.cells();
    let mut cut = Grid::new(w, h, 0.0f32);
    let mut engagement = Engagement::default();
    let mut moves = Vec::new();
    let at = (plan.shift.x, plan.shift.y);
    // (built only for a job with a flat end mill)
    let mut surface = None;
    let mut along = 0.0f64;
    for prog in progs {
        let shifted = prog.lowered(z_shift);
        let (_, m, runs) = sim::cut_program_measured(&stock, &mut cut, &shifted, None)?;
        engagement.absorb(Engagement::measure(&shifted, &m, &runs, stock.pitch));
        if runs.iter().any(|r| r.2.is_flat()) {
            let surface = surface.get_or_insert_with(|| HeightField::of_relief(relief));
            along = along.max(sim::move_gouge(&shifted, &runs, surface, at, false).mm);
        }
        moves.push((m, runs));
    }
    let (at_cells, res, mean, _) = sim::deviation(&stock, &cut, relief, at);
    let gouge = at_cells.max(along);
    Ok(Judged {
        stock,
        cut,
        engagement,
        residual: (res, mean),
        gouge,
        moves,
    })
}

/// The first move over its tool's limits: (file index, what).
pub fn first_over(
    j: &Judged,
    progs: &[Program],
    limits: &dyn Fn(&Tool) -> (f64, f64),
) -> Option<(usize, Over)> {
    j.moves
        .iter()
        .zip(progs)
        .enumerate()
        .find_map(|(k, ((m, runs), prog))| {
            Engagement::first_over(prog, m, runs, j.stock.pitch, limits).map(|o| (k, o))
        })
}

/// Refuse a job whose moves span more than the machine's travel, with
/// the figures.
pub fn fits_travel(
    prog: &Program,
    m: &crate::machine::Machine,
    file: &std::path::Path,
) -> Result<()> {
    let (lo, hi) = prog.bounds();
    let span = hi - lo;
    if span.x > m.travel.x + 1e-6 || span.y > m.travel.y + 1e-6 || span.z > m.travel.z + 1e-6 {
        crate::bail!(
            "{}: its moves span {:.1} x {:.1} x {:.1} mm, more than {}'s travel {} x {} x {} mm",
            file.display(),
            span.x,
            span.y,
            span.z,
            m.name,
            m.travel.x,
            m.travel.y,
            m.travel.z
        );
    }
    Ok(())
}

/// Rapid and cutting travel over all programs, mm.
pub fn travel(progs: &[Program]) -> (f64, f64) {
    let (mut rapid, mut feed) = (0.0, 0.0);
    for s in progs.iter().flat_map(|p| &p.segments) {
        let l = (s.b - s.a).length();
        match s.kind {
            Kind::Rapid => rapid += l,
            Kind::Feed => feed += l,
        }
    }
    (rapid, feed)
}
