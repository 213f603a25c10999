//! Stage 1: a model (mesh, depth PNG or normal PNG) and a camera in, a
//! depth buffer or a gradient field out.

pub mod camera;
pub mod demo;
pub mod image_input;
pub mod mesh;
pub mod raster;

pub use camera::{Camera, Up, View};
pub use mesh::Mesh;
pub use raster::DepthMap;

use crate::bail;
use crate::error::Result;

/// Render `mesh` as seen by `cam`, long side `long_px` times `supersample`.
/// A relief of more than `max_pixels` is refused before any memory is
/// taken for it (the 16384 px demo, 159 million pixels, took 10 GB), the
/// error saying `why` the limit is what it is.
pub fn render(
    mesh: &Mesh,
    cam: &Camera,
    long_px: usize,
    supersample: usize,
    (max_pixels, why): (usize, &str),
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
    let (h, id, surfaces) = raster::rasterize(&pr.points, &mesh.triangles, &ids, pr.w, pr.h);
    Ok(DepthMap {
        h,
        id,
        objects: mesh.objects.clone(),
        surfaces: Some(surfaces),
    })
}
