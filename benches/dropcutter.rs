//! Drop-cutter benchmark: the CL points of a 10% stepover raster of a
//! 3.175 mm ball over a 2048 px, 100 mm relief of the Stanford bunny.
//! `cargo bench --bench dropcutter` (the bunny from fixtures/).

use rayon::prelude::*;
use relievo::cutter::dropcutter::HeightField;
use relievo::ops::relief::ReliefJob;
use relievo::tool::Tool;
use std::time::Instant;

fn main() {
    let model =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/stanford-bunny.obj");
    let dir = std::env::temp_dir().join("relievo-bench-dc");
    std::fs::create_dir_all(&dir).unwrap();
    let job = ReliefJob {
        model: Some(model),
        resolution: 2048,
        camera: relievo::scene::Camera {
            fov: 0.0,
            ..Default::default()
        },
        width_mm: 100.0,
        output: dir.join("r.png"),
        ..Default::default()
    };
    let relief = job
        .run(&relievo::progress::Progress::none())
        .expect("relief")
        .relief;
    let depth = relief.depth_mm;
    let z = relief.heights.map(|v| *v as f64 - depth);
    let t = Instant::now();
    let hf = HeightField::new(z, relief.pitch_mm());
    let pyramid = t.elapsed();
    for spec in ["ball:3.175", "flat:6", "vbit:60:12", "ball:12"] {
        let tool = Tool::parse(spec).unwrap();
        let stepover = 0.1 * tool.radius() * 2.0;
        let rows = (relief.height_mm / stepover) as usize + 1;
        let n = relief.heights.w;
        let t = Instant::now();
        let cl: Vec<Vec<f64>> = (0..rows)
            .into_par_iter()
            .map(|r| {
                let y = r as f64 * stepover;
                let mut stack = Vec::new();
                let mut hint = None;
                (0..n)
                    .map(|i| {
                        match hf.drop_from(
                            &tool,
                            (i as f64 + 0.5) * relief.pitch_mm(),
                            y,
                            hint,
                            &mut stack,
                        ) {
                            Some((z, c)) => {
                                hint = Some(c);
                                z
                            }
                            None => -depth,
                        }
                    })
                    .collect()
            })
            .collect();
        let points: usize = cl.iter().map(Vec::len).sum();
        println!(
            "{spec}: {points} CL points ({rows} rows, stepover {stepover:.3} mm) in {:.0} ms, {:.0}k points/s (pyramid {:.0} ms, {} threads)",
            t.elapsed().as_secs_f64() * 1e3,
            points as f64 / t.elapsed().as_secs_f64() / 1e3,
            pyramid.as_secs_f64() * 1e3,
            rayon::current_num_threads()
        );
    }
}
