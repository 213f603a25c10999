//! The studio's computations: the model on the bench, the relief of the
//! current settings and the job cut from it, each made by the same library
//! calls as `relievo relief`, `toolpath` and `simulate`. One computation
//! runs at a time; a request that a newer one overtook is dropped, not
//! queued, and a running one stops at its next stage.

use super::settings::{carve_command, relief_command, CutSettings, ReliefSettings};
use crate::bail;
use crate::error::{Error, Result};
use crate::ops::relief::{ReliefJob, Sight};
use crate::ops::simulate::{SimSummary, SimulateJob};
use crate::relief::gradient::Field;
use crate::relief::{file, Params, Relief};
use crate::scene::mesh::Mesh;
use crate::timing::Timings;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering::SeqCst};
use std::sync::{Arc, Mutex, MutexGuard};

/// Why a computation gave no result.
#[derive(Debug)]
pub enum Fail {
    /// A newer request came first: this one's answer would be stale.
    Superseded,
    /// The settings or the model were refused (shown in the page).
    Bad(Error),
}

impl From<Error> for Fail {
    fn from(e: Error) -> Fail {
        Fail::Bad(e)
    }
}

/// The model on the bench.
pub struct Model {
    /// As the command line names it (`None` = the demo scene).
    pub name: Option<String>,
    pub path: Option<PathBuf>,
    /// The mesh, loaded once (the demo scene's too); `None` for a PNG,
    /// which is read where it is seen.
    pub mesh: Option<Arc<Mesh>>,
    /// Bumped by every new model, so nothing made of the last one is reused.
    pub version: u64,
}

/// A relief and how it was made.
pub struct Made {
    pub model_version: u64,
    pub settings: ReliefSettings,
    pub job: ReliefJob,
    pub params: Params,
    pub relief: Relief,
    pub warnings: Vec<String>,
    pub command: String,
    pub timings: Timings,
}

impl Made {
    /// The relief file and its sidecar, as `relievo relief` writes them.
    pub fn files(&self) -> (Vec<u8>, Vec<u8>) {
        file::encode_relief(&self.relief, self.job.meta(&self.params))
    }
}

/// A job, its simulated cut and its moves.
pub struct JobMade {
    pub relief: Arc<Made>,
    pub cut: CutSettings,
    pub summary: crate::cam::CamSummary,
    pub sim: SimSummary,
    pub program: crate::gcode::Program,
    pub command: String,
    /// Where its files are (job.nc, job.svg).
    pub dir: PathBuf,
}

/// What the camera saw, kept while only relief settings change, and its
/// shaped field, kept while the compression and the silhouette stay too.
struct Seen {
    model_version: u64,
    key: crate::ops::settings::ReliefSettings,
    sight: Arc<Sight>,
    shaped: Option<((f64, f64), Arc<Shaped>)>,
}

/// A shaped field and the object names its ids refer to.
type Shaped = (Field, Vec<String>);

pub struct Studio {
    /// Scratch folder: uploads, the job's files.
    pub dir: PathBuf,
    /// What every request that changes anything must carry: the page
    /// this studio serves holds it, a page from elsewhere cannot read it.
    pub secret: String,
    model: Mutex<Arc<Model>>,
    seen: Mutex<Option<Seen>>,
    relief: Mutex<Option<Arc<Made>>>,
    job: Mutex<Option<Arc<JobMade>>>,
    newest: AtomicU64,
    versions: AtomicU64,
    uploads: AtomicU64,
    work: Mutex<()>,
    /// The Machine panel's connection to a controller.
    pub machine: super::machine::Slot,
}

/// A lock that a panicked holder left usable (its data is replaced whole).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The settings that decide what the camera sees.
fn sight_key(s: &ReliefSettings) -> crate::ops::settings::ReliefSettings {
    crate::ops::settings::ReliefSettings {
        view: s.view,
        up: s.up,
        yaw: s.yaw,
        pitch: s.pitch,
        roll: s.roll,
        fov: s.fov,
        resolution: s.resolution,
        smooth: s.smooth,
        faceted: s.faceted,
        flat_background: s.flat_background,
        free_background: s.free_background,
        ..crate::ops::settings::ReliefSettings::default()
    }
}

/// 128 unpredictable bits as hex: hashes keyed by the process's random
/// hasher keys (drawn from the operating system) over the clock.
fn new_secret() -> String {
    use std::hash::{BuildHasher, Hasher};
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    (0..2u64)
        .map(|k| {
            let mut h = std::collections::hash_map::RandomState::new().build_hasher();
            h.write_u64(k);
            h.write_u128(now);
            format!("{:016x}", h.finish())
        })
        .collect()
}

/// Largest relief the studio makes (pixels on the long side).
pub const MAX_RESOLUTION: usize = 4096;

impl Studio {
    /// A studio on `model` (`None` = the demo scene), its scratch files in
    /// a new folder under `dir`.
    pub fn new(model: Option<&Path>, dir: &Path) -> Result<Studio> {
        sweep(dir);
        let dir = dir.join(format!("relievo-studio-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| Error(format!("{}: {e}", dir.display())))?;
        let s = Studio {
            dir,
            secret: new_secret(),
            model: Mutex::new(Arc::new(Model {
                name: None,
                path: None,
                mesh: None,
                version: 0,
            })),
            seen: Mutex::new(None),
            relief: Mutex::new(None),
            job: Mutex::new(None),
            newest: AtomicU64::new(0),
            versions: AtomicU64::new(0),
            uploads: AtomicU64::new(0),
            work: Mutex::new(()),
            machine: Default::default(),
        };
        s.open(model.map(|p| (p.to_path_buf(), p.display().to_string())))?;
        Ok(s)
    }

    pub fn model(&self) -> Arc<Model> {
        lock(&self.model).clone()
    }

    /// Put a model on the bench (`None` = the demo scene): loaded and
    /// checked before it replaces the current one.
    pub fn open(&self, file: Option<(PathBuf, String)>) -> Result<Arc<Model>> {
        let is_png = file
            .as_ref()
            .is_some_and(|(p, _)| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")));
        let mesh = match &file {
            None => Some(crate::scene::demo::scene()),
            Some((p, _)) if !is_png => Some(crate::scene::mesh::load(p)?),
            Some((p, _)) => {
                crate::relief::image_input::load_png(p)?;
                None
            }
        };
        if let Some(m) = &mesh {
            if m.triangles.is_empty() {
                bail!(
                    "{}: no triangles",
                    file.as_ref().map_or("demo".into(), |f| f.1.clone())
                );
            }
        }
        let (path, name) = file.map_or((None, None), |(p, n)| (Some(p), Some(n)));
        let m = Arc::new(Model {
            name,
            path,
            mesh: mesh.map(Arc::new),
            version: self.versions.fetch_add(1, SeqCst) + 1,
        });
        // whatever runs now is about the old model
        self.newest.fetch_add(1, SeqCst);
        let old = std::mem::replace(&mut *lock(&self.model), m.clone());
        // an upload replaced is deleted (its mesh, if any, is in memory)
        if let Some(dir) = old.path.as_deref().and_then(Path::parent) {
            if dir.starts_with(&self.dir) && m.path.as_deref().and_then(Path::parent) != Some(dir) {
                let _ = std::fs::remove_dir_all(dir);
            }
        }
        Ok(m)
    }

    /// Save an upload under its own name (its extension tells its type)
    /// and open it.
    pub fn upload(&self, name: &str, bytes: &[u8]) -> Result<Arc<Model>> {
        let base = Path::new(name)
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let ext = Path::new(&base)
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if !["obj", "stl", "png"].contains(&ext.as_str()) {
            bail!("{base}: not an OBJ, STL or PNG file (by its name)");
        }
        if bytes.is_empty() {
            bail!("{base}: the file is empty");
        }
        let n = self.uploads.fetch_add(1, SeqCst) + 1;
        let safe: String = base
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let dir = self.dir.join(format!("upload-{n}"));
        std::fs::create_dir_all(&dir).map_err(|e| Error(format!("{}: {e}", dir.display())))?;
        let path = dir.join(safe);
        std::fs::write(&path, bytes).map_err(|e| Error(format!("{}: {e}", path.display())))?;
        let opened = self.open(Some((path.clone(), base.clone())));
        if opened.is_err() {
            let _ = std::fs::remove_dir_all(&dir);
        }
        opened.map_err(|e| Error(e.0.replace(&path.display().to_string(), &base)))
    }

    /// Take a ticket: every request newer than it makes it stale.
    fn ticket(&self) -> u64 {
        self.newest.fetch_add(1, SeqCst) + 1
    }

    fn live(&self, ticket: u64) -> std::result::Result<(), Fail> {
        if self.newest.load(SeqCst) == ticket {
            Ok(())
        } else {
            Err(Fail::Superseded)
        }
    }

    /// The relief of `s`, reusing what the camera saw when only relief
    /// settings changed.
    pub fn relief(&self, s: &ReliefSettings) -> std::result::Result<Arc<Made>, Fail> {
        let ticket = self.ticket();
        let _one = lock(&self.work);
        self.live(ticket)?;
        self.relief_now(s, ticket)
    }

    fn relief_now(&self, s: &ReliefSettings, ticket: u64) -> std::result::Result<Arc<Made>, Fail> {
        let model = self.model();
        if let Some(m) = lock(&self.relief).as_ref() {
            if m.model_version == model.version && m.settings == *s {
                return Ok(m.clone());
            }
        }
        if !(8..=MAX_RESOLUTION).contains(&s.resolution) {
            return Err(Fail::Bad(Error(format!(
                "--resolution {}: the studio makes 8 to {MAX_RESOLUTION} pixels",
                s.resolution
            ))));
        }
        let job = s
            .settings
            .clone()
            .job(model.path.clone(), self.dir.join("relief.png"));
        let mut params = job.validate()?;
        let mut t = Timings::default();
        let key = sight_key(s);
        let shaping = (params.alpha, params.silhouette);
        let cached = lock(&self.seen)
            .as_ref()
            .filter(|c| c.model_version == model.version && c.key == key)
            .map(|c| {
                let shaped = c.shaped.as_ref().filter(|f| f.0 == shaping);
                (c.sight.clone(), shaped.map(|f| f.1.clone()))
            });
        let (sight, shaped) = match cached {
            Some(c) => c,
            None => {
                let sight = Arc::new(job.see(
                    model.mesh.as_deref(),
                    &mut t,
                    &crate::progress::Progress::none(),
                )?);
                (sight, None)
            }
        };
        self.live(ticket)?;
        let shaped = match shaped {
            Some(f) => f,
            None => Arc::new(job.field(&sight, &params, &mut t)),
        };
        *lock(&self.seen) = Some(Seen {
            model_version: model.version,
            key,
            sight,
            shaped: Some((shaping, shaped.clone())),
        });
        self.live(ticket)?;
        let (relief, warnings) = job.relief_from(&shaped.0, &shaped.1, &mut params, &mut t)?;
        let made = Arc::new(Made {
            model_version: model.version,
            settings: s.clone(),
            command: relief_command(model.name.as_deref(), s),
            job,
            params,
            relief,
            warnings,
            timings: t,
        });
        *lock(&self.relief) = Some(made.clone());
        Ok(made)
    }

    /// The job of `c` on the relief of `s`, checked by the simulator.
    pub fn job(
        &self,
        s: &ReliefSettings,
        c: &CutSettings,
    ) -> std::result::Result<Arc<JobMade>, Fail> {
        let ticket = self.ticket();
        let _one = lock(&self.work);
        self.live(ticket)?;
        let made = self.relief_now(s, ticket)?;
        if let Some(j) = lock(&self.job).as_ref() {
            if Arc::ptr_eq(&j.relief, &made) && j.cut == *c {
                return Ok(j.clone());
            }
        }
        self.live(ticket)?;
        // a folder per job: a download of the last one is never half
        // overwritten by the next
        let dir = self.dir.join(format!("job-{ticket}"));
        std::fs::create_dir_all(&dir).map_err(|e| Error(format!("{}: {e}", dir.display())))?;
        let relief_path = dir.join("relief.png");
        let (png, json) = made.files();
        let write = |p: &Path, b: &[u8]| {
            std::fs::write(p, b).map_err(|e| Error(format!("{}: {e}", p.display())))
        };
        write(&relief_path, &png)?;
        write(&file::sidecar_path(&relief_path), &json)?;
        let nc = dir.join("job.nc");
        if c.split || c.tile.is_some() {
            return Err(Fail::Bad(Error(
                "--split and --tile make several job files; the studio makes one (use the \
                 command line shown)"
                    .into(),
            )));
        }
        let mut tp = c.settings.clone().job(
            nc.clone(),
            "relief.png".into(),
            made.settings.material.clone(),
        );
        tp.svg = Some(dir.join("job.svg"));
        let summary = tp.run(&made.relief)?;
        self.live(ticket)?;
        let sim = SimulateJob {
            jobs: vec![nc.clone()],
            relief: relief_path,
            output: dir.join("cut.png"),
            machine: c.machine.clone(),
            ..SimulateJob::default()
        }
        .run()?;
        let text = crate::input::read_text(&nc, crate::input::MAX_FILE)?;
        let program = crate::cam::layout::Frame::program(&text)?;
        let model = self.model();
        let j = Arc::new(JobMade {
            command: carve_command(model.name.as_deref(), s, c),
            relief: made,
            cut: c.clone(),
            summary,
            sim,
            program,
            dir,
        });
        // the job before this one is no longer offered
        if let Some(old) = lock(&self.job).replace(j.clone()) {
            let _ = std::fs::remove_dir_all(&old.dir);
        }
        Ok(j)
    }

    /// The last relief and job made, for downloads.
    pub fn last_relief(&self) -> Option<Arc<Made>> {
        lock(&self.relief).clone()
    }
    pub fn last_job(&self) -> Option<Arc<JobMade>> {
        lock(&self.job).clone()
    }
}

/// Remove the scratch folders of studios that no longer run (one stopped
/// by Ctrl-C leaves its uploads behind).
fn sweep(base: &Path) {
    let Ok(entries) = std::fs::read_dir(base) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        let Some(pid) = name
            .strip_prefix("relievo-studio-")
            .and_then(|p| p.parse::<i32>().ok())
        else {
            continue;
        };
        // SAFETY: signal 0 only asks whether the process exists
        let gone = unsafe { libc::kill(pid, 0) } == -1
            && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH);
        if gone {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

impl Drop for Studio {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn relief(v: serde_json::Value) -> ReliefSettings {
        ReliefSettings::from_json(&v).unwrap()
    }

    fn stages(m: &Made) -> Vec<&str> {
        m.timings.stages.iter().map(|s| s.0.as_str()).collect()
    }

    fn studio(name: &str) -> Studio {
        let dir = std::env::temp_dir().join(format!("relievo-studio-unit-{name}"));
        Studio::new(None, &dir).unwrap()
    }

    #[test]
    fn only_the_camera_renders_again() {
        let s = studio("reuse");
        let r = relief(json!({"resolution": 64}));
        let first = s.relief(&r).unwrap();
        assert!(stages(&first).contains(&"rasterize"));
        // depth: neither rendered nor shaped again
        let r = relief(json!({"resolution": 64, "depth": 2.0}));
        let second = s.relief(&r).unwrap();
        assert_eq!(stages(&second), ["poisson"]);
        assert_eq!(second.relief.depth_mm, 2.0);
        // the same settings: the same relief, nothing made
        assert!(Arc::ptr_eq(&second, &s.relief(&r).unwrap()));
        // compression: shaped again from the same rendering
        let r = relief(json!({"resolution": 64, "depth": 2.0, "alpha": 8.0}));
        let third = s.relief(&r).unwrap();
        assert!(stages(&third).contains(&"gradients") && !stages(&third).contains(&"rasterize"));
        // the view: rendered again
        let r = relief(json!({"resolution": 64, "depth": 2.0, "alpha": 8.0, "yaw": 10.0}));
        assert!(stages(&s.relief(&r).unwrap()).contains(&"rasterize"));
        // a new model: nothing of the old one is reused
        s.open(None).unwrap();
        assert!(stages(&s.relief(&r).unwrap()).contains(&"rasterize"));
    }

    #[test]
    fn an_upload_replaced_is_deleted() {
        let s = studio("uploads");
        let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        let first = s.upload("a.obj", obj).unwrap();
        let first = first.path.clone().unwrap();
        assert!(first.exists());
        let second = s.upload("b b.obj", obj).unwrap();
        assert_eq!(second.name.as_deref(), Some("b b.obj"));
        assert!(!first.exists() && second.path.as_ref().unwrap().exists());
        // a refused upload leaves the bench and its file as they were
        assert!(s.upload("c.obj", b"garbage").is_err());
        assert!(second.path.as_ref().unwrap().exists());
        assert_eq!(s.model().version, second.version);
        s.open(None).unwrap();
        assert!(!second.path.as_ref().unwrap().exists());
    }

    #[test]
    fn a_dead_studio_s_scratch_is_swept() {
        let base = std::env::temp_dir().join("relievo-studio-unit-sweep");
        let dead = base.join("relievo-studio-999999999");
        std::fs::create_dir_all(dead.join("upload-1")).unwrap();
        std::fs::write(dead.join("upload-1/a.obj"), "v 0 0 0").unwrap();
        let s = Studio::new(None, &base).unwrap();
        assert!(!dead.exists());
        assert!(s.dir.exists());
    }

    #[test]
    fn an_overtaken_request_is_dropped_not_queued() {
        let s = Arc::new(studio("drop"));
        let r = relief(json!({"resolution": 64}));
        // hold the bench so that both requests wait, the older first
        let one = lock(&s.work);
        let wait_for = |n: u64| {
            while s.newest.load(SeqCst) < n {
                std::thread::yield_now();
            }
        };
        let before = s.newest.load(SeqCst);
        let older = {
            let (s, r) = (s.clone(), r.clone());
            std::thread::spawn(move || s.relief(&r))
        };
        wait_for(before + 1);
        let newer = {
            let (s, r) = (s.clone(), relief(json!({"resolution": 64, "depth": 1.0})));
            std::thread::spawn(move || s.relief(&r))
        };
        wait_for(before + 2);
        drop(one);
        assert!(matches!(older.join().unwrap(), Err(Fail::Superseded)));
        let made = newer.join().unwrap().unwrap();
        assert_eq!(made.relief.depth_mm, 1.0);
        // a bad setting is an error, not a dropped request
        let bad = relief(json!({"resolution": 64, "fade": "sideways"}));
        assert!(matches!(s.relief(&bad), Err(Fail::Bad(_))));
    }
}
