//! Image models: a grayscale depth PNG (white = near) becomes a depth map;
//! an RGB normal map (tangent space, +Y up) becomes a slope field.

use super::raster::DepthMap;
use crate::bail;
use crate::error::{Context, Result};
use crate::grid::Grid;
use crate::relief::gradient::SlopeSource;
use std::path::Path;

pub enum ImageModel {
    Depth(DepthMap),
    Slopes(SlopeSource),
}

/// Largest image accepted (pixels), to fail clearly rather than run out of memory.
pub const MAX_PIXELS: usize = 1 << 26;

pub fn load_png(path: &Path) -> Result<ImageModel> {
    let what = path.display().to_string();
    let reader = image::ImageReader::open(path)
        .ctx(&what)?
        .with_guessed_format()
        .ctx(&what)?;
    let (w, h) = reader.into_dimensions().ctx(&what)?;
    let (w, h) = (w as usize, h as usize);
    if w < 2 || h < 2 || w * h > MAX_PIXELS {
        bail!(
            "{what}: image of {w} x {h} pixels is out of range (2 x 2 up to {MAX_PIXELS} pixels)"
        );
    }
    let img = image::ImageReader::open(path)
        .ctx(&what)?
        .with_guessed_format()
        .ctx(&what)?
        .decode()
        .ctx(&what)?;
    let rgba = img.to_rgba16();
    let gray = !img.color().has_color() || rgba.pixels().all(|p| p[0] == p[1] && p[1] == p[2]);
    if gray {
        let h_data: Vec<f32> = img
            .to_luma16()
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect();
        let hgrid = Grid::from_vec(w, h, h_data);
        let id = hgrid.map(|v| (*v > 0.0) as u16);
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        return Ok(ImageModel::Depth(DepthMap {
            h: hgrid,
            id,
            objects: vec![name],
        }));
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
    Ok(ImageModel::Slopes(SlopeSource { gx, gy, mask }))
}
