//! The `relief` command as one library call: options in, files out.
//! The binary only parses flags into `ReliefJob` and prints the summary.

use crate::bail;
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::output::{check_writable, Outputs};
use crate::progress::Progress;
use crate::relief::gradient::{shape_field, Field, Shaping};
use crate::relief::image_input::{load_png, ImageModel};
use crate::relief::panel::{Fade, Tilt};
use crate::relief::{self, file, Background, Method, Params, Relief, Stencil};
use crate::scene::mesh::Mesh;
use crate::scene::raster::DepthMap;
use crate::scene::{self, Camera, Up};
use crate::timing::Timings;
use crate::{export, materials, preview};
use std::path::PathBuf;

/// Most pixels a relief may have, and why: 2^26, for memory. The 8192 px
/// bunny (65 million pixels) with steps, bands, a preview and an STL
/// peaks at 7.6 GB with the flat background (the masked solver's vectors
/// are f32) and 6.4 GB with the free one; 100 and 91 s.
pub fn pixel_limit() -> (usize, &'static str) {
    (file::MAX_PIXELS, "allowed (memory)")
}

/// Longest side accepted for `--resolution` (pixels).
pub const MAX_RESOLUTION: usize = 16384;

#[derive(Clone, Debug)]
pub struct ReliefJob {
    /// OBJ, STL, depth PNG or normal PNG; `None` = the built-in demo scene.
    pub model: Option<PathBuf>,
    /// The camera; its `up` is replaced by the model's default when `up`
    /// is `None`.
    pub camera: Camera,
    /// The model's up axis; `None` = z for STL, y otherwise.
    pub up: Option<Up>,
    pub resolution: usize,
    /// Panel width in mm.
    pub width_mm: f64,
    /// Relief depth in mm; `None` = from the material, else 5 mm.
    pub depth_mm: Option<f64>,
    pub alpha: Option<f64>,
    pub silhouette: f64,
    pub steps_mm: Option<f64>,
    pub background: Background,
    /// `None` = the material's bands (or none).
    pub bands: Option<Vec<f64>>,
    pub emphasize: Vec<(String, f64)>,
    pub stencil: Option<PathBuf>,
    pub stencil_gain: f64,
    pub material: Option<String>,
    pub mirror: bool,
    pub invert: bool,
    pub method: Method,
    /// Smooth shading: slopes from vertex normals, split at creases
    /// sharper than this many degrees (45 by default); `None` = flat facets.
    pub smooth: Option<f64>,
    /// `--fade DIR[:AMOUNT]`, parsed with the other parameters.
    pub fade: Option<String>,
    /// `--tilt DEG[:DIR]`.
    pub tilt: Option<String>,
    pub output: PathBuf,
    pub stl: Option<PathBuf>,
    pub base_mm: f64,
    pub preview: Option<PathBuf>,
    pub depth_out: Option<PathBuf>,
}

impl Default for ReliefJob {
    fn default() -> Self {
        ReliefJob {
            model: None,
            camera: Camera::default(),
            up: None,
            resolution: 512,
            width_mm: 100.0,
            depth_mm: None,
            alpha: None,
            silhouette: 8.0,
            steps_mm: None,
            background: Background::Auto,
            bands: None,
            emphasize: Vec::new(),
            stencil: None,
            stencil_gain: 2.0,
            material: None,
            mirror: false,
            invert: false,
            method: Method::Gradient,
            smooth: Some(DEFAULT_CREASE),
            fade: None,
            tilt: None,
            output: PathBuf::from("relief.png"),
            stl: None,
            base_mm: 2.0,
            preview: None,
            depth_out: None,
        }
    }
}

/// What the camera saw of a model: a rendered mesh (with its object
/// names) or a depth or normal-map picture.
pub enum Sight {
    Mesh(DepthMap, Vec<String>),
    Image(ImageModel),
}

/// Default compression when neither flag nor material sets it.
pub const DEFAULT_ALPHA: f64 = 4.0;
/// Default depth (mm) without `--depth` or `--material`.
pub const DEFAULT_DEPTH: f64 = 5.0;
/// Default crease angle (degrees) of smooth shading: a tessellated curve
/// (a 16-gon turns 22.5 degrees a facet) is smoothed, a box's or a
/// machined part's edges stay sharp.
pub const DEFAULT_CREASE: f64 = 45.0;

/// What a finished run reports.
pub struct Summary {
    pub relief: Relief,
    pub params: Params,
    pub timings: Timings,
    pub silhouette_edges: usize,
    pub written: Vec<PathBuf>,
    /// Things the user should know about the result (a flat relief).
    pub warnings: Vec<String>,
}

impl ReliefJob {
    /// Resolve material defaults into concrete relief parameters.
    pub fn params(&self) -> Result<Params> {
        let mat = self.material.as_deref().map(materials::find).transpose()?;
        let depth = match (self.depth_mm, &mat) {
            (Some(d), _) => d,
            (None, Some(m)) => m.depth_per_100mm * self.width_mm / 100.0,
            (None, None) => DEFAULT_DEPTH,
        };
        let p = Params {
            depth_mm: depth,
            width_mm: self.width_mm,
            alpha: self
                .alpha
                .or(mat.as_ref().and_then(|m| m.alpha))
                .unwrap_or(DEFAULT_ALPHA),
            silhouette: self.silhouette,
            steps_mm: self.steps_mm,
            background: self.background,
            bands: self
                .bands
                .clone()
                .or(mat.map(|m| m.bands))
                .unwrap_or_default(),
            mirror: self.mirror,
            invert: self.invert,
            method: self.method,
            fade: self.fade.as_deref().map(Fade::parse).transpose()?,
            tilt: self.tilt.as_deref().map(Tilt::parse).transpose()?,
        };
        p.validate()?;
        Ok(p)
    }

    /// Check every setting and input before any work: the parameters.
    pub fn validate(&self) -> Result<Params> {
        if self.resolution < 8 || self.resolution > MAX_RESOLUTION {
            bail!(
                "--resolution {}: must be between 8 and {MAX_RESOLUTION} pixels",
                self.resolution
            );
        }
        self.camera.validate()?;
        if let Some(a) = self.smooth.filter(|a| !(0.0..=180.0).contains(a)) {
            bail!("--smooth {a}: the crease angle must be 0 to 180 degrees");
        }
        if !self.base_mm.is_finite() || self.base_mm < 0.0 || self.base_mm > 10_000.0 {
            bail!("--base {}: must be a thickness in mm >= 0", self.base_mm);
        }
        if !self.stencil_gain.is_finite() || self.stencil_gain < 0.0 {
            bail!(
                "--stencil-gain {}: must be a number >= 0",
                self.stencil_gain
            );
        }
        for (name, g) in &self.emphasize {
            if !g.is_finite() || *g < 0.0 {
                bail!("--emphasize {name}={g}: the gain must be a number >= 0");
            }
        }
        if let Some(m) = &self.model {
            if !m.exists() {
                bail!("{}: no such file", m.display());
            }
        }
        if let Some(s) = &self.stencil {
            if !s.exists() {
                bail!("{}: no such file (--stencil)", s.display());
            }
        }
        let outs = [
            Some(&self.output),
            self.stl.as_ref(),
            self.preview.as_ref(),
            self.depth_out.as_ref(),
        ];
        for o in outs.into_iter().flatten() {
            check_writable(o)?;
        }
        check_writable(&file::sidecar_path(&self.output))?;
        self.params()
    }

    /// Load the model (or take `mesh`, already loaded from it) and look at
    /// it: the slow part of a relief, which no relief setting but the
    /// camera, the resolution, the up axis and `--smooth` changes.
    pub fn see(&self, mesh: Option<&Mesh>, t: &mut Timings, progress: &Progress) -> Result<Sight> {
        if self.model_is("png") {
            let path = self.model.as_ref().unwrap();
            let img = t.time("load", || load_png(path))?;
            let (w, h) = match &img {
                ImageModel::Depth(d) => (d.h.w, d.h.h),
                ImageModel::Slopes(s) => (s.gx.w, s.gx.h),
            };
            let (max, why) = pixel_limit();
            if w * h > max {
                bail!(
                    "{}: {w} x {h} = {:.1} million pixels, more than the {:.1} million {why}",
                    path.display(),
                    (w * h) as f64 / 1e6,
                    max as f64 / 1e6
                );
            }
            return Ok(Sight::Image(img));
        }
        let loaded;
        let mesh = match (mesh, &self.model) {
            (Some(m), _) => m,
            (None, Some(path)) => {
                loaded = t.time("load", || scene::mesh::load(path))?;
                &loaded
            }
            (None, None) => {
                loaded = t.time("load", scene::demo::scene);
                &loaded
            }
        };
        let dm = t.time("rasterize", || {
            scene::render(
                mesh,
                &self.camera(),
                self.resolution,
                2,
                pixel_limit(),
                self.smooth,
                &|done| progress.share(done),
            )
            .map_err(|e| Error(format!("{}: {e}", self.model_name())))
        })?;
        if dm.id.data.iter().all(|&i| i == 0) {
            bail!("{}: nothing visible from this view", self.model_name());
        }
        Ok(Sight::Mesh(dm, mesh.objects.clone()))
    }

    /// The shaped field of what was seen.
    pub fn field(&self, sight: &Sight, p: &Params, t: &mut Timings) -> (Field, Vec<String>) {
        let shaping = Shaping {
            alpha: p.alpha,
            threshold: p.silhouette,
        };
        t.time("gradients", || match sight {
            Sight::Image(ImageModel::Depth(d)) => (shape_field(d, 1, shaping), d.objects.clone()),
            Sight::Image(ImageModel::Slopes(s)) => (shape_field(s, 1, shaping), Vec::new()),
            Sight::Mesh(dm, objects) => (shape_field(dm, 2, shaping), objects.clone()),
        })
    }

    /// The relief of what was seen, with its warnings (a flat relief); the
    /// field is returned for what else is made of it.
    pub fn relief(
        &self,
        sight: &Sight,
        p: &mut Params,
        t: &mut Timings,
    ) -> Result<(Relief, Field, Vec<String>)> {
        let (field, objects) = self.field(sight, p, t);
        let (relief, warnings) = self.relief_from(&field, &objects, p, t)?;
        Ok((relief, field, warnings))
    }

    /// The relief of a shaped field (which depends on the view and on
    /// the compression and silhouette settings only), with its warnings.
    /// `p`'s background is then the one made (flat or free), for the
    /// sidecar to say.
    pub fn relief_from(
        &self,
        field: &Field,
        objects: &[String],
        p: &mut Params,
        t: &mut Timings,
    ) -> Result<(Relief, Vec<String>)> {
        let stencils = self.stencils(field, objects)?;
        let relief = relief::build(field, p, &stencils, t)?;
        let warnings = relief::flatness(&relief, field)
            .into_iter()
            .chain(relief::background_rise(&relief, field, p))
            .collect();
        p.background = if relief::holds_background(field, p) {
            Background::Flat
        } else {
            Background::Free
        };
        Ok((relief, warnings))
    }

    /// What the relief's JSON sidecar says of how it was made.
    pub fn meta(&self, p: &Params) -> serde_json::Value {
        serde_json::json!({
            "model": self.model_name(),
            "camera": self.camera(),
            "resolution": self.resolution,
            "smooth": self.smooth.filter(|_| !self.model_is("png")),
            "material": self.material,
            "relief": p,
            "emphasize": self.emphasize,
            "stencil": self.stencil.as_ref().map(|s| (s.display().to_string(), self.stencil_gain)),
        })
    }

    /// The model's up axis and whether it was chosen by its file type.
    pub fn up(&self) -> (Up, bool) {
        match self.up {
            Some(u) => (u, false),
            None if self.model_is("stl") => (Up::Z, true),
            None => (Up::Y, true),
        }
    }

    /// Whether the model file has this extension (any case).
    pub fn model_is(&self, ext: &str) -> bool {
        self.model
            .as_ref()
            .and_then(|m| m.extension())
            .is_some_and(|e| e.eq_ignore_ascii_case(ext))
    }

    /// The camera with the up axis resolved.
    pub fn camera(&self) -> Camera {
        Camera {
            up: self.up().0,
            ..self.camera
        }
    }

    pub fn model_name(&self) -> String {
        self.model
            .as_ref()
            .map(|m| m.display().to_string())
            .unwrap_or_else(|| "demo scene".into())
    }

    fn stencils(&self, field: &Field, objects: &[String]) -> Result<Vec<Stencil>> {
        let mut out = Vec::new();
        for (name, gain) in &self.emphasize {
            let Some(k) = objects.iter().position(|o| o == name) else {
                bail!(
                    "--emphasize {name}: {} has no object named '{name}'; objects: {}",
                    self.model_name(),
                    if objects.is_empty() {
                        "none".into()
                    } else {
                        objects.join(", ")
                    }
                );
            };
            let id = k as u16 + 1;
            let weight = field.id.map(|i| (*i == id) as u8 as f32);
            out.push(Stencil {
                name: name.clone(),
                weight,
                gain: *gain,
            });
        }
        if let Some(path) = &self.stencil {
            let g = file::read_gray(path)?;
            let (w, h) = (field.gx.w, field.gx.h);
            // nearest sample, so any mask size maps onto the relief
            let mut weight = Grid::new(w, h, 0.0f32);
            for y in 0..h {
                for x in 0..w {
                    weight.set(x, y, *g.get(x * g.w / w, y * g.h / h));
                }
            }
            out.push(Stencil {
                name: path.display().to_string(),
                weight,
                gain: self.stencil_gain,
            });
        }
        Ok(out)
    }

    /// Run the whole job and write its outputs (all or nothing).
    pub fn run(&self, progress: &Progress) -> Result<Summary> {
        let mut params = self.validate()?;
        let mut t = Timings::default();
        progress.stage("loading and rendering");
        let sight = self.see(None, &mut t, progress)?;
        progress.stage("integrating");
        let (relief, field, warnings) = self.relief(&sight, &mut params, &mut t)?;
        drop(sight);
        progress.stage("writing");
        let depth_png = self.depth_out.as_ref().map(|_| {
            t.time("encode", || {
                let mut d = field
                    .depth
                    .map(|v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16);
                if self.mirror {
                    d.flip_x();
                }
                file::png16(&d)
            })
        });
        // the field is 30 bytes a pixel: gone before the outputs are made
        let silhouette_edges = field.silhouette_edges;
        drop(field);
        let mut out = Outputs::default();
        let meta = self.meta(&params);
        t.time("encode", || -> Result<()> {
            let (png, json) = file::encode_relief(&relief, meta);
            out.add(&self.output, png);
            out.add(&file::sidecar_path(&self.output), json);
            if let Some(p) = &self.stl {
                let (relief, base) = (&relief, self.base_mm);
                out.add_stream(p, Box::new(move |w| export::write_stl(relief, base, w)));
            }
            if let Some(p) = &self.preview {
                out.add(p, file::png8(&preview::shade(&relief)));
            }
            if let (Some(p), Some(png)) = (&self.depth_out, depth_png) {
                out.add(p, png);
            }
            Ok(())
        })?;
        let mut written = vec![self.output.clone(), file::sidecar_path(&self.output)];
        written.extend(
            [&self.stl, &self.preview, &self.depth_out]
                .into_iter()
                .flatten()
                .cloned(),
        );
        t.time("write", || out.commit())?;
        Ok(Summary {
            relief,
            params,
            timings: t,
            silhouette_edges,
            written,
            warnings,
        })
    }
}
