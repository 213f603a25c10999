//! Stage 1: a model (mesh, depth PNG or normal PNG) and a camera in, a
//! depth buffer or a gradient field out.

pub mod camera;
pub mod demo;
pub mod image_input;
pub mod mesh;
pub mod raster;

pub use camera::{Camera, View};
pub use mesh::Mesh;
pub use raster::DepthMap;

/// Render `mesh` as seen by `cam`, long side `long_px` times `supersample`.
pub fn render(mesh: &Mesh, cam: &Camera, long_px: usize, supersample: usize) -> DepthMap {
    let pos: Vec<glam::DVec3> = mesh.positions.iter().map(|p| p.as_dvec3()).collect();
    let pr = cam.project(&pos, long_px, supersample);
    let ids: Vec<u16> = mesh.tri_object.iter().map(|o| o + 1).collect();
    let (h, id) = raster::rasterize(&pr.points, &mesh.triangles, &ids, pr.w, pr.h);
    DepthMap {
        h,
        id,
        objects: mesh.objects.clone(),
    }
}
