//! Image models: a grayscale depth PNG (white = near) becomes a depth map;
//! an RGB normal map (tangent space, +Y up) becomes a slope field.

use super::file::decode;
use super::gradient::SlopeSource;
use crate::error::Result;
use crate::grid::Grid;
use crate::scene::raster::DepthMap;
use std::path::Path;

pub enum ImageModel {
    Depth(DepthMap),
    Slopes(SlopeSource),
}

pub fn load_png(path: &Path) -> Result<ImageModel> {
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    Ok(image_model(decode(path)?, name))
}

/// A decoded image as a model: gray is depth, colour a normal map. `name`
/// names the depth map's one object.
pub fn image_model(img: image::DynamicImage, name: String) -> ImageModel {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let gray = !img.color().has_color()
        || img
            .to_rgb16()
            .pixels()
            .all(|p| p[0] == p[1] && p[1] == p[2]);
    if gray {
        let h_data: Vec<f32> = img
            .into_luma16()
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect();
        let hgrid = Grid::from_vec(w, h, h_data);
        let id = hgrid.map(|v| (*v > 0.0) as u16);
        return ImageModel::Depth(DepthMap {
            h: hgrid,
            id,
            objects: vec![name],
            surfaces: None,
        });
    }
    // Normal map: n = 2c - 1; slope = -n_xy / n_z in image-width units (the
    // surface is taken as isotropic: depth measured in pixels like x and y).
    let rgba = img.into_rgba16();
    let mut gx = Grid::new(w, h, 0.0f32);
    let mut gy = Grid::new(w, h, 0.0f32);
    let mut mask = Grid::new(w, h, false);
    for (i, p) in rgba.pixels().enumerate() {
        let c = |k: usize| p[k] as f32 / 65535.0 * 2.0 - 1.0;
        let (nx, ny, nz) = (c(0), c(1), c(2));
        let background = p[3] == 0 || (p[0] == 0 && p[1] == 0 && p[2] == 0);
        if background {
            continue;
        }
        let nz = nz.max(1e-3);
        // rows run down the image while tangent-space +Y points up
        gx.data[i] = -nx / nz;
        gy.data[i] = ny / nz;
        mask.data[i] = true;
    }
    ImageModel::Slopes(SlopeSource { gx, gy, mask })
}
