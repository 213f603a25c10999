//! Stage 1: a model (mesh, depth PNG or normal PNG) and a camera in, a
//! depth buffer or a gradient field out.

pub mod camera;
pub mod demo;
pub mod mesh;
pub mod raster;

pub use camera::{Camera, Up, View};
pub use mesh::Mesh;
pub use raster::DepthMap;

use crate::bail;
use crate::error::{Error, Result};

/// Render `mesh` as seen by `cam`, long side `long_px` times `supersample`;
/// with `smooth` (a crease angle in degrees), surfaces carry slopes from
/// smooth vertex normals.
/// A relief of more than `max_pixels` is refused before any memory is
/// taken for it (the 16384 px demo, 159 million pixels, took 10 GB), the
/// error saying `why` the limit is what it is. `progress` is told the share
/// of the picture drawn.
pub fn render(
    mesh: &Mesh,
    cam: &Camera,
    long_px: usize,
    supersample: usize,
    (max_pixels, why): (usize, &str),
    smooth: Option<f64>,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<DepthMap> {
    let pos: Vec<glam::DVec3> = mesh.positions.iter().map(|p| p.as_dvec3()).collect();
    let pr = cam.project(&pos, long_px, supersample);
    let (w, h) = (pr.w / supersample, pr.h / supersample);
    if w * h > max_pixels {
        let size = |px: usize| {
            let p = cam.project(&pos, px, 1);
            p.w * p.h
        };
        let mut fit = (long_px as f64 * (max_pixels as f64 / (w * h) as f64).sqrt()) as usize;
        while fit > 8 && size(fit) > max_pixels {
            fit -= 1;
        }
        bail!(
            "--resolution {long_px}: the relief would be {w} x {h} = {:.1} million pixels, \
             more than the {:.1} million {why}; use --resolution {fit} or less",
            (w * h) as f64 / 1e6,
            max_pixels as f64 / 1e6
        );
    }
    let ids: Vec<u16> = mesh.tri_object.iter().map(|o| o + 1).collect();
    let slopes = smooth.map(|angle| corner_slopes(mesh, &pos, &pr, angle));
    let (h, id, surfaces) = raster::rasterize(
        &pr.points,
        &mesh.triangles,
        &ids,
        slopes.as_deref(),
        (pr.w, pr.h),
        (progress, raster::MAX_PIXEL_TESTS),
    )
    .map_err(|deep| {
        Error(format!(
            "{:.2} million triangles, many of them large and stacked deep behind each \
             other, would take more than {} billion pixel tests to draw at {} x {} px; \
             decimate the mesh or lower --resolution",
            deep.triangles as f64 / 1e6,
            raster::MAX_PIXEL_TESTS / 1_000_000_000,
            pr.w,
            pr.h
        ))
    })?;
    Ok(DepthMap {
        h,
        id,
        objects: mesh.objects.clone(),
        surfaces: Some(surfaces),
    })
}

/// Each triangle corner's depth slope in the image from its smooth normal;
/// a corner whose normal faces away or is seen edge-on keeps its face's
/// own slope.
fn corner_slopes(
    mesh: &Mesh,
    pos: &[glam::DVec3],
    pr: &camera::Projection,
    crease_deg: f64,
) -> Vec<raster::CornerSlopes> {
    use rayon::prelude::*;
    let normals = mesh.corner_normals(crease_deg);
    mesh.triangles
        .par_iter()
        .zip(normals.par_iter())
        .map(|(t, n)| {
            let p = t.map(|i| pos[i as usize]);
            let mut face = (p[1] - p[0]).cross(p[2] - p[0]);
            if face.dot(pr.frame.to_eye(p[0])) < 0.0 {
                face = -face; // seen from its back: its normals turn too
            }
            // (the face's own slope only where a corner's is not seen)
            let flat = || pr.frame.plane_slope(p[0], face);
            let mut out = [[0.0f32; 2]; 3];
            for k in 0..3 {
                // the file's normals may face either way: the face decides
                let mut nk = n[k].as_dvec3();
                if nk.dot(face) < 0.0 {
                    nk = -nk;
                }
                let s = pr
                    .frame
                    .plane_slope(p[k], nk)
                    .or_else(flat)
                    .unwrap_or([0.0; 2]);
                out[k] = [s[0] as f32, s[1] as f32];
            }
            out
        })
        .collect()
}
