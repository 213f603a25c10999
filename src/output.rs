//! All-or-nothing output: every file of a command is first written to a
//! temporary file beside its target, and only when all are written are
//! they renamed into place. A failure leaves no output file behind.

use crate::bail;
use crate::error::Result;
use std::path::{Path, PathBuf};

/// Writes a file's content into its temporary file: a large output (the
/// STL of a 67 million pixel relief is 6.7 GB) goes to disk as it is made
/// instead of being held.
pub type Writer<'a> = Box<dyn FnOnce(&mut dyn std::io::Write) -> std::io::Result<()> + 'a>;

enum Content<'a> {
    Bytes(Vec<u8>),
    Stream(Writer<'a>),
}

#[derive(Default)]
pub struct Outputs<'a> {
    files: Vec<(PathBuf, Content<'a>)>,
}

/// A new temporary file beside `p`, created exclusively (O_EXCL: an
/// existing file or a planted symlink at the name is never opened) under a
/// name no one can predict (a randomly keyed hash).
fn create_temp(p: &Path) -> std::io::Result<(PathBuf, std::fs::File)> {
    use std::hash::BuildHasher;
    let name = p
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    let keys = std::collections::hash_map::RandomState::new();
    let mut k = 0u64;
    loop {
        let tag = keys.hash_one((std::process::id(), k));
        let tmp = p.with_file_name(format!(".{name}.relievo-{tag:016x}.tmp"));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
        {
            Ok(f) => return Ok((tmp, f)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && k < 16 => k += 1,
            Err(e) => return Err(e),
        }
    }
}

/// Fail early, before long work, when `path` cannot be written: its
/// directory must exist and it must not be a directory itself.
pub fn check_writable(path: &Path) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        bail!(
            "{}: cannot write: directory {} does not exist",
            path.display(),
            dir.display()
        );
    }
    if path.is_dir() {
        bail!("{}: cannot write: it is a directory", path.display());
    }
    // only regular files are replaced: renaming over /dev/null or a FIFO
    // would swap the device for a file
    if let Ok(m) = std::fs::metadata(path) {
        if !m.is_file() {
            bail!(
                "{}: cannot write: not a regular file (a device, FIFO or socket)",
                path.display()
            );
        }
    }
    Ok(())
}

impl<'a> Outputs<'a> {
    pub fn add(&mut self, path: &Path, bytes: Vec<u8>) {
        self.files.push((path.to_path_buf(), Content::Bytes(bytes)));
    }

    /// A file whose content `write` streams out when the outputs commit.
    pub fn add_stream(&mut self, path: &Path, write: Writer<'a>) {
        self.files
            .push((path.to_path_buf(), Content::Stream(write)));
    }

    /// Write everything or nothing.
    pub fn commit(self) -> Result<()> {
        let mut written: Vec<PathBuf> = Vec::new();
        let cleanup = |w: &[PathBuf]| w.iter().for_each(|t| drop(std::fs::remove_file(t)));
        let paths: Vec<PathBuf> = self.files.iter().map(|f| f.0.clone()).collect();
        for (path, content) in self.files {
            if let Err(e) = check_writable(&path) {
                cleanup(&written);
                return Err(e);
            }
            let (tmp, f) = match create_temp(&path) {
                Ok(t) => t,
                Err(e) => {
                    cleanup(&written);
                    bail!("{}: cannot write: {e}", path.display());
                }
            };
            interrupt::remove_on_interrupt(&tmp);
            let mut w = std::io::BufWriter::with_capacity(1 << 20, f);
            let result = match content {
                Content::Bytes(bytes) => std::io::Write::write_all(&mut w, &bytes),
                Content::Stream(write) => write(&mut w),
            }
            .and_then(|_| std::io::Write::flush(&mut w));
            written.push(tmp);
            if let Err(e) = result {
                cleanup(&written);
                bail!("{}: cannot write: {e}", path.display());
            }
        }
        for (k, path) in paths.iter().enumerate() {
            if interrupt::holding() {
                // a held output goes with an interruption from the moment
                // it exists under its name
                interrupt::remove_on_interrupt(path);
            }
            if let Err(e) = std::fs::rename(&written[k], path) {
                cleanup(&written[k..]);
                for p in &paths[..k] {
                    drop(std::fs::remove_file(p));
                }
                bail!("{}: cannot write: {e}", path.display());
            }
        }
        written.iter().for_each(|t| interrupt::forget(t));
        Ok(())
    }
}

/// Files to remove if the process is interrupted (SIGINT, SIGTERM) before
/// they are final: temporary files, and, while outputs are held, every
/// output from the moment it is renamed into place (a `carve`'s relief
/// until its job is written). The handler only calls `unlink` and `_exit`, which are safe
/// in a signal handler; paths are held in a fixed table of leaked C strings.
pub mod interrupt {
    use std::ffi::CString;
    use std::path::Path;
    use std::sync::atomic::{AtomicBool, AtomicPtr, Ordering};
    use std::sync::Once;

    const SLOTS: usize = 64;
    static PATHS: [AtomicPtr<libc::c_char>; SLOTS] =
        [const { AtomicPtr::new(std::ptr::null_mut()) }; SLOTS];
    static INSTALL: Once = Once::new();
    static HOLD: AtomicBool = AtomicBool::new(false);

    /// From now on, outputs stay removable on interruption until
    /// `keep_all`; registering them before their rename leaves no moment in
    /// which an interruption keeps one without the others.
    pub fn hold() {
        HOLD.store(true, Ordering::SeqCst);
    }

    /// Whether outputs are held (see `hold`).
    pub fn holding() -> bool {
        HOLD.load(Ordering::SeqCst)
    }

    extern "C" fn on_signal(_: libc::c_int) {
        for slot in &PATHS {
            let p = slot.load(Ordering::SeqCst);
            if !p.is_null() {
                // SAFETY: p is a leaked, NUL-terminated CString
                unsafe { libc::unlink(p) };
            }
        }
        // SAFETY: _exit is async-signal-safe
        unsafe { libc::_exit(130) };
    }

    /// Remove `path` if the process is interrupted from now on.
    pub fn remove_on_interrupt(path: &Path) {
        use std::os::unix::ffi::OsStrExt;
        INSTALL.call_once(|| {
            // SAFETY: installing a handler that only calls unlink and _exit
            unsafe {
                libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
                libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
            }
        });
        let Ok(c) = CString::new(path.as_os_str().as_bytes()) else {
            return;
        };
        let p = c.into_raw();
        for slot in &PATHS {
            if slot
                .compare_exchange(std::ptr::null_mut(), p, Ordering::SeqCst, Ordering::SeqCst)
                .is_ok()
            {
                return;
            }
        }
    }

    /// `path` no longer needs removing (a temporary file renamed away).
    pub fn forget(path: &Path) {
        use std::os::unix::ffi::OsStrExt;
        for slot in &PATHS {
            let p = slot.load(Ordering::SeqCst);
            // SAFETY: p is null or a leaked, NUL-terminated CString
            if !p.is_null()
                && unsafe { std::ffi::CStr::from_ptr(p) }.to_bytes() == path.as_os_str().as_bytes()
            {
                slot.store(std::ptr::null_mut(), Ordering::SeqCst);
            }
        }
    }

    /// The registered files are final: keep them whatever happens.
    pub fn keep_all() {
        HOLD.store(false, Ordering::SeqCst);
        for slot in &PATHS {
            slot.store(std::ptr::null_mut(), Ordering::SeqCst);
        }
    }
}
