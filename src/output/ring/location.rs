//! Where a ring lives and who may have made it: the ring directory, the producer's checks on it
//! and the readers' checks on a segment (docs/ring.md, "Threat model").
//!
//! Rings are files in a directory that only the service's user can write (by default
//! `/run/vkterrain`, a systemd `RuntimeDirectory`), not in the world-writable `/dev/shm`, so no
//! other user can create a ring name first (squatting) or put a fake ring where readers look.
//! Readers accept a segment only if it belongs to the expected user and nobody else may write it.

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

use super::layout::validate_name;
use super::sys;
use crate::error::{Error, Result};

/// Ring directory when neither the config (`ring.dir`) nor [`DIR_ENV`] says otherwise.
pub const DEFAULT_DIR: &str = "/run/vkterrain";
/// Environment variable naming the ring directory (all readers and the producer honour it).
pub const DIR_ENV: &str = "VKTERRAIN_RING_DIR";
/// Environment variable naming the user (name or uid) readers expect to own the rings.
pub const OWNER_ENV: &str = "VKTERRAIN_RING_OWNER";

/// The ring directory from [`DIR_ENV`], else [`DEFAULT_DIR`].
pub fn default_dir() -> PathBuf {
    std::env::var_os(DIR_ENV)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(DEFAULT_DIR))
}

/// The expected owner from [`OWNER_ENV`], if set.
pub fn owner_from_env() -> Result<Option<u32>> {
    match std::env::var(OWNER_ENV) {
        Ok(v) if !v.trim().is_empty() => sys::user_id(v.trim()).map(Some),
        _ => Ok(None),
    }
}

/// A ring's directory and name: the segment is `<dir>/<name>`, the producer's name lock
/// `<dir>/.<name>.lock` (names never start with a dot, so the two cannot collide).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RingLocation {
    pub dir: PathBuf,
    pub name: String,
}

impl RingLocation {
    pub fn new(dir: impl Into<PathBuf>, name: &str) -> Result<Self> {
        validate_name(name)?;
        Ok(RingLocation {
            dir: dir.into(),
            name: name.to_string(),
        })
    }

    /// `name` in [`default_dir`].
    pub fn named(name: &str) -> Result<Self> {
        Self::new(default_dir(), name)
    }

    pub fn segment_path(&self) -> PathBuf {
        self.dir.join(&self.name)
    }

    pub fn lock_path(&self) -> PathBuf {
        self.dir.join(format!(".{}.lock", self.name))
    }

    /// Where a producer builds a new segment before renaming it over the name.
    pub fn temp_path(&self) -> PathBuf {
        self.dir
            .join(format!(".{}.new{}", self.name, std::process::id()))
    }
}

impl std::fmt::Display for RingLocation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.segment_path().display())
    }
}

fn writable_by_others(mode: u32) -> bool {
    mode & 0o022 != 0
}

/// The producer's directory check (creating it when missing, mode 0700, or 0750 and `group`):
/// it must be ours and writable by nobody else, and every directory above it must belong to
/// root or us and either be writable by nobody else or be sticky (`/tmp`, `/dev/shm`: others may
/// create names there but not replace ours, and a directory someone else made first fails the
/// owner check). So no other user can put or replace anything in it.
pub fn prepare_dir(dir: &Path, group: Option<u32>) -> Result<PathBuf> {
    let what = "ring directory";
    let me = sys::euid();
    if std::fs::symlink_metadata(dir).is_err() {
        let mode = if group.is_some() { 0o750 } else { 0o700 };
        let mut b = std::fs::DirBuilder::new();
        std::os::unix::fs::DirBuilderExt::mode(&mut b, mode);
        match b.create(dir) {
            Ok(()) => {
                if let Some(gid) = group {
                    std::os::unix::fs::chown(dir, None, Some(gid))
                        .map_err(|e| Error::io(dir, e))?;
                }
                std::fs::set_permissions(dir, std::fs::Permissions::from_mode(mode))
                    .map_err(|e| Error::io(dir, e))?;
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => {
                return Err(Error::invalid(
                    what,
                    format!(
                        "cannot create {}: {e} (set ring.dir or {DIR_ENV} to a directory this user may create, e.g. under $XDG_RUNTIME_DIR, or run under systemd with RuntimeDirectory=vkterrain)",
                        dir.display()
                    ),
                ));
            }
        }
    }
    let canonical = dir.canonicalize().map_err(|e| Error::io(dir, e))?;
    let m = std::fs::metadata(&canonical).map_err(|e| Error::io(&canonical, e))?;
    if !m.is_dir() {
        return Err(Error::invalid(
            what,
            format!("{} is not a directory", canonical.display()),
        ));
    }
    if m.uid() != me {
        return Err(Error::invalid(
            what,
            format!(
                "{} belongs to uid {}, not to this service (uid {me}): someone else created it",
                canonical.display(),
                m.uid()
            ),
        ));
    }
    if writable_by_others(m.mode()) {
        return Err(Error::invalid(
            what,
            format!(
                "{} is writable by group or others (mode {:o}): anyone could put a fake ring there",
                canonical.display(),
                m.mode() & 0o7777
            ),
        ));
    }
    for a in canonical.ancestors().skip(1) {
        let m = std::fs::metadata(a).map_err(|e| Error::io(a, e))?;
        let sticky = m.mode() & 0o1000 != 0;
        if (m.uid() != 0 && m.uid() != me) || (writable_by_others(m.mode()) && !sticky) {
            return Err(Error::invalid(
                what,
                format!(
                    "{} is inside {}, which uid {} (mode {:o}) could rename or replace",
                    canonical.display(),
                    a.display(),
                    m.uid(),
                    m.mode() & 0o7777
                ),
            ));
        }
    }
    Ok(canonical)
}

/// Whose rings a reader accepts in `dir`: `explicit` if given; otherwise the directory's owner,
/// but only if neither the directory nor any directory above it can be written by anyone but
/// root and that owner (then nobody else can have made anything in it).
pub fn expected_owner(dir: &Path, explicit: Option<u32>) -> Result<u32> {
    if let Some(uid) = explicit {
        return Ok(uid);
    }
    let canonical = dir.canonicalize().map_err(|e| Error::io(dir, e))?;
    let m = std::fs::metadata(&canonical).map_err(|e| Error::io(&canonical, e))?;
    let owner = m.uid();
    for a in canonical.ancestors() {
        let m = std::fs::metadata(a).map_err(|e| Error::io(a, e))?;
        if (m.uid() != 0 && m.uid() != owner) || writable_by_others(m.mode()) {
            return Err(Error::invalid(
                "ring directory",
                format!(
                    "{} can be written by others ({} is uid {}, mode {:o}), so its owner proves nothing: name the expected owner ({OWNER_ENV} or --ring-owner)",
                    canonical.display(),
                    a.display(),
                    m.uid(),
                    m.mode() & 0o7777
                ),
            ));
        }
    }
    Ok(owner)
}

/// A reader's check of an opened segment: a regular file of the expected owner that nobody else
/// may write.
pub fn check_segment(st: &libc::stat, owner: u32, path: &Path) -> Result<()> {
    let bad = |m: String| {
        Err(Error::invalid(
            "ring segment",
            format!("{}: {m}", path.display()),
        ))
    };
    if st.st_mode & libc::S_IFMT != libc::S_IFREG {
        return bad("not a regular file".into());
    }
    if st.st_uid != owner {
        return bad(format!(
            "belongs to uid {}, not to the expected owner uid {owner}: refusing a ring someone else made",
            st.st_uid
        ));
    }
    if writable_by_others(st.st_mode) {
        return bad(format!(
            "writable by group or others (mode {:o}): anyone could forge frames",
            st.st_mode & 0o7777
        ));
    }
    Ok(())
}
