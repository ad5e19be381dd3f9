//! Where `vkterrain preprocess` writes: `<out>.partial/`, claimed with a lock, removed on any
//! failure, renamed to `<out>` once complete. `--force` replaces only a vkterrain data set.

use std::fs::File;
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};

use super::manifest;
use crate::error::{Error, Result};

/// Name of the lock file inside the partial directory (removed before it is published).
pub const LOCK_FILE: &str = ".preprocess.lock";

/// `<out>.partial`, held by this process until [`PartialDir::publish`]; dropped without
/// publishing (an error, a panic) it is removed, so a failed run leaves nothing behind.
pub struct PartialDir {
    pub path: PathBuf,
    out: PathBuf,
    lock: Option<File>,
    published: bool,
}

/// `dir` with `suffix` appended to its name (`a/b` + `.partial` = `a/b.partial`).
pub fn sibling(dir: &Path, suffix: &str) -> PathBuf {
    let mut name = dir.file_name().unwrap_or_default().to_os_string();
    name.push(suffix);
    dir.with_file_name(name)
}

fn lock_exclusive(f: &File) -> bool {
    // SAFETY: flock on a file descriptor we own.
    unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

/// Is `dir` a vkterrain data set (its manifest names our format)?
pub fn is_dataset(dir: &Path) -> bool {
    let m = dir.join(manifest::FILE_NAME);
    std::fs::read(&m)
        .ok()
        .filter(|b| b.len() < 64 << 20)
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| v.get("format").and_then(|f| f.as_str()).map(str::to_owned))
        .is_some_and(|f| f == manifest::FORMAT)
}

/// Checks that `out` may be written (absent, an empty directory, or a data set with
/// `force`) before anything is computed.
pub fn check_target(out: &Path, force: bool) -> Result<()> {
    let what = || out.display().to_string();
    let meta = match std::fs::symlink_metadata(out) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(Error::io(out, e)),
    };
    if !meta.is_dir() {
        return Err(Error::invalid(
            what(),
            "exists and is not a directory; --out must name a data set directory (nothing was written)",
        ));
    }
    let empty = std::fs::read_dir(out)
        .map_err(|e| Error::io(out, e))?
        .next()
        .is_none();
    if empty {
        return Ok(());
    }
    if !is_dataset(out) {
        return Err(Error::invalid(
            what(),
            "is a non-empty directory that is not a vkterrain data set; refusing to replace it (even with --force): choose another --out",
        ));
    }
    if !force {
        return Err(Error::invalid(
            what(),
            "a data set already exists here; pass --force to replace it",
        ));
    }
    Ok(())
}

impl PartialDir {
    /// Claims `<out>.partial`: a stale one (its lock free: the run that made it is gone) is
    /// removed; one whose lock is held belongs to a running preprocess and is an error.
    pub fn claim(out: &Path) -> Result<Self> {
        if out.file_name().is_none() {
            return Err(Error::invalid(
                out.display().to_string(),
                "not a directory name",
            ));
        }
        let path = sibling(out, ".partial");
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        // Build the new directory under a private name with its lock held, then rename it into
        // place: the partial directory never exists without a held lock while we run.
        let staging = sibling(out, &format!(".partial.{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&staging);
        std::fs::create_dir(&staging).map_err(|e| Error::io(&staging, e))?;
        let lock = File::create(staging.join(LOCK_FILE)).map_err(|e| Error::io(&staging, e))?;
        if !lock_exclusive(&lock) {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(Error::invalid(staging.display().to_string(), "cannot lock"));
        }
        if std::fs::symlink_metadata(&path).is_ok() {
            let busy = match File::open(path.join(LOCK_FILE)) {
                Ok(f) => !lock_exclusive(&f),
                Err(_) => false,
            };
            if busy {
                let _ = std::fs::remove_dir_all(&staging);
                return Err(Error::invalid(
                    path.display().to_string(),
                    format!(
                        "another vkterrain preprocess is writing {} now (its lock is held); wait for it to finish",
                        out.display()
                    ),
                ));
            }
            // Stale (a killed run): move it aside atomically, then delete.
            let trash = sibling(out, &format!(".partial.stale.{}", std::process::id()));
            std::fs::rename(&path, &trash).map_err(|e| Error::io(&path, e))?;
            std::fs::remove_dir_all(&trash).map_err(|e| Error::io(&trash, e))?;
        }
        std::fs::rename(&staging, &path).map_err(|e| {
            let _ = std::fs::remove_dir_all(&staging);
            Error::io(&path, e)
        })?;
        Ok(PartialDir {
            path,
            out: out.to_path_buf(),
            lock: Some(lock),
            published: false,
        })
    }

    /// Renames the finished directory to `out` (replacing a data set there, which
    /// [`check_target`] allowed) and releases the lock.
    pub fn publish(mut self, force: bool) -> Result<()> {
        check_target(&self.out, force)?;
        let _ = std::fs::remove_file(self.path.join(LOCK_FILE));
        let old = sibling(&self.out, &format!(".old.{}", std::process::id()));
        let replacing = self.out.exists();
        if replacing {
            std::fs::rename(&self.out, &old).map_err(|e| Error::io(&self.out, e))?;
        }
        if let Err(e) = std::fs::rename(&self.path, &self.out) {
            if replacing {
                let _ = std::fs::rename(&old, &self.out);
            }
            return Err(Error::io(&self.out, e));
        }
        self.published = true;
        self.lock.take();
        if replacing {
            std::fs::remove_dir_all(&old).map_err(|e| Error::io(&old, e))?;
        }
        Ok(())
    }
}

impl Drop for PartialDir {
    fn drop(&mut self) {
        if !self.published {
            // Best effort: this runs on the error path, whose error is what gets reported.
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

/// Bytes available to an unprivileged writer on the file system holding `dir` (or its
/// nearest existing ancestor).
pub fn free_bytes(dir: &Path) -> Option<u64> {
    let mut p = dir;
    loop {
        if p.exists() {
            break;
        }
        p = p.parent()?;
        if p.as_os_str().is_empty() {
            p = Path::new(".");
        }
    }
    let c = std::ffi::CString::new(p.as_os_str().as_encoded_bytes()).ok()?;
    let mut s: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: valid C string and out-pointer.
    (unsafe { libc::statvfs(c.as_ptr(), &mut s) } == 0)
        .then(|| s.f_bavail as u64 * s.f_frsize as u64)
}

/// Memory the system can give without swapping (`MemAvailable`), in bytes.
pub fn available_memory() -> Option<u64> {
    std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines()
            .find(|l| l.starts_with("MemAvailable:"))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
            .map(|kib| kib * 1024)
    })
}

/// "1.5 GiB" style sizes for messages.
pub fn human_bytes(b: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < units.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else {
        format!("{v:.1} {}", units[u])
    }
}
