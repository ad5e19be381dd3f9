//! "This path is mine while I live": an exclusive open-file-description lock on a small lock
//! file, held for the life of a [`PathLock`]. The kernel drops the lock when the process dies,
//! so a crashed owner never blocks its successor and a pid in a file is never trusted for
//! liveness. Used for ring names, the control socket and the status file of `vkterrain serve`.

use std::io::Write;
use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::output::ring::sys;

/// An exclusive lock on `path`; the lock file is removed on drop (if it is still ours).
pub struct PathLock {
    fd: OwnedFd,
    path: PathBuf,
}

/// Attempts before giving up when the lock file keeps being replaced under us (an owner that
/// is shutting down removes it between our open and our lock).
const ATTEMPTS: usize = 8;

impl PathLock {
    /// Takes the lock at `path` (created with mode 0600, never through a symlink), without
    /// waiting. `what` names the guarded thing in errors, e.g. `ring "vkterrain"`. Fails with
    /// "in use by a live process (pid N)" when another process holds it, and refuses a lock
    /// file that belongs to another user (someone squatting the name).
    pub fn acquire(path: &Path, what: &str) -> Result<Self> {
        for _ in 0..ATTEMPTS {
            let fd = sys::open(path, libc::O_RDWR | libc::O_CREAT, 0o600)
                .map_err(|e| Error::io(path, e))?;
            let st = sys::fstat(&fd).map_err(|e| Error::io(path, e))?;
            if st.st_mode & libc::S_IFMT != libc::S_IFREG {
                return Err(Error::invalid(
                    what,
                    format!("{}: the lock is not a regular file", path.display()),
                ));
            }
            if st.st_uid != sys::euid() {
                return Err(Error::invalid(
                    what,
                    format!(
                        "{}: the lock belongs to uid {}, not to us (uid {}); someone else created it",
                        path.display(),
                        st.st_uid,
                        sys::euid()
                    ),
                ));
            }
            if !sys::ofd_try_lock(&fd, libc::F_WRLCK).map_err(|e| Error::io(path, e))? {
                let pid = std::fs::read_to_string(path)
                    .ok()
                    .and_then(|s| s.trim().parse::<u32>().ok());
                return Err(Error::invalid(
                    what,
                    format!(
                        "in use by a live process ({}); lock {}",
                        pid.map_or("pid unknown".into(), |p| format!("pid {p}")),
                        path.display()
                    ),
                ));
            }
            // The previous owner may have removed the file between our open and our lock: then
            // we locked an orphan and a third process may lock a new file. Retry on the name.
            if !sys::same_file(&fd, path) {
                continue;
            }
            sys::ftruncate(&fd, 0).map_err(|e| Error::io(path, e))?;
            let mut f = std::fs::File::from(fd.try_clone().map_err(|e| Error::io(path, e))?);
            let _ = write!(f, "{}", std::process::id());
            return Ok(PathLock {
                fd,
                path: path.to_path_buf(),
            });
        }
        Err(Error::invalid(
            what,
            format!("{}: the lock file keeps changing", path.display()),
        ))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for PathLock {
    fn drop(&mut self) {
        // Remove the name while still holding the lock; a process that opened it meanwhile sees
        // the file gone after locking (the check in `acquire`) and retries on a fresh one.
        if sys::same_file(&self.fd, &self.path) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// The lock file guarding `path`: `<path>.lock` beside it.
pub fn lock_path_for(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".lock");
    PathBuf::from(s)
}
