//! The relief file (DESIGN.md section 4): a 16-bit grayscale PNG (0 =
//! lowest, 65535 = top of the depth) with a JSON sidecar giving its size.

use super::Relief;
use crate::bail;
use crate::error::{Context, Result};
use crate::grid::Grid;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub const FORMAT: &str = "relievo-relief/1";

#[derive(Serialize, Deserialize, Debug, Clone)]
pub struct Sidecar {
    pub format: String,
    pub width_mm: f64,
    pub height_mm: f64,
    pub depth_mm: f64,
    pub pixels: [usize; 2],
    /// Size and CRC-32 of the PNG this sidecar was written with: a reader
    /// refuses a PNG that is not it (another run's, half a pair).
    #[serde(default)]
    pub png_bytes: Option<u64>,
    #[serde(default)]
    pub png_crc32: Option<u32>,
    #[serde(default)]
    pub params: serde_json::Value,
}

/// `relief.png` -> `relief.json`.
pub fn sidecar_path(png: &Path) -> PathBuf {
    png.with_extension("json")
}

fn encode(w: usize, h: usize, bytes: &[u8], color: ExtendedColorType) -> Vec<u8> {
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Sub)
        .write_image(bytes, w as u32, h as u32, color)
        .expect("encoding a PNG into memory cannot fail");
    out
}

/// Encode a 16-bit grayscale PNG.
pub fn png16(g: &Grid<u16>) -> Vec<u8> {
    // the encoder takes native-endian samples and writes PNG's big-endian
    let native: Vec<u8> = g.data.iter().flat_map(|v| v.to_ne_bytes()).collect();
    encode(g.w, g.h, &native, ExtendedColorType::L16)
}

/// Encode an 8-bit grayscale PNG.
pub fn png8(g: &Grid<u8>) -> Vec<u8> {
    encode(g.w, g.h, &g.data, ExtendedColorType::L8)
}

/// Encode an 8-bit RGB PNG.
pub fn png_rgb(w: usize, h: usize, rgb: &[u8]) -> Vec<u8> {
    encode(w, h, rgb, ExtendedColorType::Rgb8)
}

/// Quantize to the file's 16 bits.
pub fn quantize(r: &Relief) -> Grid<u16> {
    let k = if r.depth_mm > 0.0 {
        65535.0 / r.depth_mm
    } else {
        0.0
    };
    r.heights
        .map(|v| ((*v as f64) * k).round().clamp(0.0, 65535.0) as u16)
}

/// The PNG and sidecar bytes of a relief.
pub fn encode_relief(r: &Relief, params: serde_json::Value) -> (Vec<u8>, Vec<u8>) {
    let png = png16(&quantize(r));
    let side = Sidecar {
        format: FORMAT.into(),
        width_mm: r.width_mm,
        height_mm: r.height_mm,
        depth_mm: r.depth_mm,
        pixels: [r.heights.w, r.heights.h],
        png_bytes: Some(png.len() as u64),
        png_crc32: Some(crc32fast::hash(&png)),
        params,
    };
    let mut json = serde_json::to_vec_pretty(&side).expect("sidecar serializes");
    json.push(b'\n');
    (png, json)
}

/// Largest image accepted (pixels), to fail clearly rather than run out of memory.
pub const MAX_PIXELS: usize = 1 << 26;

/// Decode an image, refusing sizes outside 2 x 2 .. MAX_PIXELS first (from
/// the header alone).
pub fn decode(path: &Path) -> Result<image::DynamicImage> {
    let what = path.display().to_string();
    decode_with(|| image::ImageReader::open(path).ctx(&what), &what)
}

/// `decode` of an image held in memory.
pub fn decode_bytes(bytes: &[u8], what: &str) -> Result<image::DynamicImage> {
    decode_with(
        || Ok(image::ImageReader::new(std::io::Cursor::new(bytes))),
        what,
    )
}

/// `open` is called twice: once for the header, once to decode.
fn decode_with<R: std::io::BufRead + std::io::Seek>(
    open: impl Fn() -> Result<image::ImageReader<R>>,
    what: &str,
) -> Result<image::DynamicImage> {
    let guessed = || open()?.with_guessed_format().ctx(what);
    let (w, h) = guessed()?.into_dimensions().ctx(what)?;
    let (w, h) = (w as usize, h as usize);
    if w < 2 || h < 2 || w * h > MAX_PIXELS {
        bail!(
            "{what}: image of {w} x {h} pixels is out of range (2 x 2 up to {MAX_PIXELS} pixels)"
        );
    }
    guessed()?.decode().ctx(what)
}

/// A grayscale PNG as values in [0, 1] (8 or 16 bit).
pub fn read_gray(path: &Path) -> Result<Grid<f32>> {
    Ok(gray(decode(path)?))
}

/// An image's luminance as values in [0, 1].
pub fn gray(img: image::DynamicImage) -> Grid<f32> {
    let g = img.into_luma16();
    let (w, h) = (g.width() as usize, g.height() as usize);
    Grid::from_vec(
        w,
        h,
        g.into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect(),
    )
}

/// Load a relief: the sidecar gives its size; a plain heightmap needs
/// `width_mm` and `depth_mm` (which also override a sidecar).
pub fn load(path: &Path, width_mm: Option<f64>, depth_mm: Option<f64>) -> Result<Relief> {
    let what = path.display().to_string();
    let png = crate::input::read(path, crate::input::MAX_FILE)?;
    let g = gray(decode_bytes(&png, &what)?);
    let side_path = sidecar_path(path);
    let side_name = side_path.display().to_string();
    let side = if side_path.exists() {
        let text = crate::input::read_text(&side_path, crate::input::MAX_TEXT)?;
        Some(parse_sidecar(&text, &side_name)?)
    } else {
        None
    };
    let r = relief_from(g, side.as_ref(), &side_name, width_mm, depth_mm, &what)?;
    if let Some(s) = &side {
        let crc = crc32fast::hash(&png);
        let size_ok = s.pixels == [r.heights.w, r.heights.h];
        let sum_ok = s.png_bytes.is_none_or(|n| n == png.len() as u64)
            && s.png_crc32.is_none_or(|c| c == crc);
        if !(size_ok && sum_ok) {
            bail!(
                "{what}: not the PNG its sidecar {side_name} was written with ({} x {} pixels, \
                 {} bytes, CRC-32 {crc:08x}; the sidecar says {} x {}{}); written by another \
                 run? Make the relief again",
                r.heights.w,
                r.heights.h,
                png.len(),
                s.pixels[0],
                s.pixels[1],
                match (s.png_bytes, s.png_crc32) {
                    (Some(n), Some(c)) => format!(", {n} bytes, CRC-32 {c:08x}"),
                    _ => String::new(),
                }
            );
        }
    }
    Ok(r)
}

/// A sidecar from its JSON text; `name` names it in errors.
pub fn parse_sidecar(text: &str, name: &str) -> Result<Sidecar> {
    serde_json::from_str(text).ctx(name)
}

/// A relief from its decoded heights and its sidecar (if there is one,
/// named `side_name`), the flags overriding the sidecar.
pub fn relief_from(
    g: Grid<f32>,
    side: Option<&Sidecar>,
    side_name: &str,
    width_mm: Option<f64>,
    depth_mm: Option<f64>,
    what: &str,
) -> Result<Relief> {
    let width = width_mm.or(side.map(|s| s.width_mm));
    let depth = depth_mm.or(side.map(|s| s.depth_mm));
    let (Some(width), Some(depth)) = (width, depth) else {
        bail!("{what}: no sidecar {side_name}; give --width and --depth in mm");
    };
    // a panel from a hundredth of a millimetre to 10 m, a relief as deep
    if !((1e-2..=1e4).contains(&width) && (1e-3..=1e4).contains(&depth)) {
        bail!(
            "{what}: width {width:?} mm and depth {depth:?} mm must be within 0.01..10000 and \
             0.001..10000 mm"
        );
    }
    let heights = g.map(|v| (*v as f64 * depth) as f32);
    Ok(Relief {
        width_mm: width,
        height_mm: width * g.h as f64 / g.w as f64,
        depth_mm: depth,
        heights,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relief_round_trips_through_png_and_sidecar() {
        let dir = std::env::temp_dir().join(format!("relievo-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let heights = Grid::from_vec(4, 2, vec![0.0, 1.0, 2.0, 3.0, 0.5, 1.5, 2.5, 3.0]);
        let r = Relief {
            heights,
            width_mm: 40.0,
            height_mm: 20.0,
            depth_mm: 3.0,
        };
        let (png, json) = encode_relief(&r, serde_json::json!({"alpha": 4}));
        let p = dir.join("r.png");
        std::fs::write(&p, png).unwrap();
        std::fs::write(sidecar_path(&p), json).unwrap();
        let back = load(&p, None, None).unwrap();
        assert_eq!(
            (back.width_mm, back.height_mm, back.depth_mm),
            (40.0, 20.0, 3.0)
        );
        for (a, b) in back.heights.data.iter().zip(&r.heights.data) {
            assert!((a - b).abs() < 1e-4);
        }
        std::fs::remove_dir_all(dir).unwrap();
    }
}
