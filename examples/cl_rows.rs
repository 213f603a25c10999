//! The finishing raster's CL rows of a relief, one point per line as
//! `row x y z` (mm): what `bench/line_bound.py` bounds the line count of.
//! Prints the rows' merged moves and `fewest::bound`'s count.
//!
//! `cargo run --release --example cl_rows -- RELIEF.png OUT.txt [TOOL] [STEPOVER_MM]`
use relievo::cutter::dropcutter::HeightField;
use relievo::error::Context;
use relievo::toolpath::{fewest, merge::merge, raster};
use std::io::{BufWriter, Write};

fn main() -> relievo::Result<()> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 3 {
        relievo::bail!("usage: cl_rows RELIEF.png OUT.txt [TOOL] [STEPOVER_MM]");
    }
    let r = relievo::relief::file::load(std::path::Path::new(&a[1]), None, None)?;
    let tool = relievo::tool::Tool::parse(a.get(3).map_or("ball:3.175", |s| s.as_str()))?;
    let stepover: f64 = match a.get(4) {
        Some(s) => s.parse().ctx("stepover")?,
        None => 0.2 * tool.radius(),
    };
    let z = relievo::Grid::from_vec(
        r.heights.w,
        r.heights.h,
        r.heights.data.iter().map(|v| *v as f64).collect(),
    );
    let hf = HeightField::new(z, r.pitch_mm());
    let step = raster::point_spacing(&hf, &tool);
    let rows = raster::rows(r.width_mm, r.height_mm, 0.0, stepover, step);
    let cl = raster::drop_rows(&hf, &tool, &rows, -1e3);
    let mut o = BufWriter::new(std::fs::File::create(&a[2]).ctx(&a[2])?);
    for (k, row) in cl.iter().enumerate() {
        for p in row {
            writeln!(o, "{k} {} {} {}", p.x, p.y, p.z).ctx(&a[2])?;
        }
    }
    // the rows merged at the default tolerance against the bound
    let tol = 0.005;
    let moves: usize = cl
        .iter()
        .map(|r| merge(r, tol).len().saturating_sub(1))
        .sum();
    let bound: usize = cl.iter().map(|r| fewest::bound(r, tol)).sum();
    eprintln!(
        "{} rows: merged into {moves} moves at {tol} mm; no path within the band takes fewer than {bound}",
        cl.len()
    );
    Ok(())
}
