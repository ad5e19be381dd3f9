//! Camera control: one JSON object per message, e.g.
//! `{"pose":{"position":[x,y,z],"yaw_deg":0,"pitch_deg":-20,"roll_deg":0},"fov_deg":60}`,
//! `{"pose":{"lat_deg":46.5,"lon_deg":8.0,"height_m":3000,"height_ref":"msl","heading_deg":90,"pitch_deg":-10}}`,
//! `{"resolution":[640,360]}`, `{"scripted":true}`,
//! `{"consumer":{"name":"detector","received":100,"lost":3}}`. Anything malformed or out of
//! range is rejected and counted; nothing a client sends can stop the renderer. The same
//! [`Control`] handles the Unix socket ([`ControlSocket`]) and Zenoh.

use std::collections::BTreeMap;
use std::os::fd::AsRawFd;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geo::{GeoPose, HeightRef};
use crate::output::lock::{PathLock, lock_path_for};
use crate::output::ring::sys;
use crate::scene::Camera;

/// Largest accepted position coordinate (metres): far beyond any data set, finite.
const MAX_COORD_M: f64 = 1.0e7;
/// Accepted resolution change range per side.
const RES_RANGE: std::ops::RangeInclusive<u32> = 16..=8192;
/// Control messages handled per frame at most, so a flood cannot starve rendering.
pub const MAX_MESSAGES_PER_FRAME: usize = 256;
/// Consumers remembered in the status.
pub const MAX_CONSUMERS: usize = 64;
/// A consumer not heard from for this long gives its entry up when the table is full.
pub const CONSUMER_TTL: Duration = Duration::from_secs(60);
/// Largest control message (bytes).
pub const MAX_MESSAGE: usize = 65535;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ControlMsg {
    pose: Option<Pose>,
    fov_deg: Option<f64>,
    resolution: Option<[u32; 2]>,
    scripted: Option<bool>,
    consumer: Option<ConsumerReport>,
}

/// A pose in world metres (`position`, `yaw_deg`, `pitch_deg`, `roll_deg`) or on the earth
/// (`lat_deg`, `lon_deg`, `height_m`, `height_ref`, `heading_deg`, `pitch_deg`, `roll_deg`;
/// `docs/coordinates.md`): exactly one of the two forms.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Pose {
    position: Option<[f64; 3]>,
    yaw_deg: Option<f64>,
    lat_deg: Option<f64>,
    lon_deg: Option<f64>,
    height_m: Option<f64>,
    #[serde(default)]
    height_ref: HeightRef,
    heading_deg: Option<f64>,
    pitch_deg: f64,
    #[serde(default)]
    roll_deg: f64,
}

/// Turns a WGS84 pose into the camera it places (`current` gives the field of view and clip
/// planes): `serve` installs one when its data set lies on the earth.
pub type GeoResolver = Box<dyn Fn(&GeoPose, &Camera) -> Result<Camera>>;

#[derive(Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct ConsumerReport {
    name: String,
    received: u64,
    lost: u64,
}

struct Consumer {
    report: ConsumerReport,
    /// The sender's process (kernel-checked credentials on the Unix socket).
    pid: Option<u32>,
    seen: Instant,
}

/// What the render loop should change after control messages, and their counters.
#[derive(Default)]
pub struct Control {
    pub live: Option<Camera>,
    pub resize: Option<(u32, u32)>,
    pub accepted: u64,
    pub rejected: u64,
    pub last_error: Option<String>,
    consumers: BTreeMap<String, Consumer>,
    /// WGS84 poses -> cameras; none: the data set has no world frame (such poses are rejected).
    pub geo: Option<GeoResolver>,
}

impl Control {
    /// Validates and applies one message, counting it as accepted or rejected. `sender`: the
    /// sending process, when known.
    pub fn handle(&mut self, bytes: &[u8], current: &Camera, sender: Option<u32>) {
        match self.apply(bytes, current, sender) {
            Ok(()) => self.accepted += 1,
            Err(e) => self.reject(e),
        }
    }

    /// Counts a message rejected before it could be parsed (too long, transport error).
    pub fn reject(&mut self, reason: String) {
        self.rejected += 1;
        if self.rejected <= 10 {
            tracing::warn!("control message rejected: {reason}");
        }
        self.last_error = Some(reason);
    }

    /// Consumers' reports: name -> (received, lost).
    pub fn consumers(&self) -> BTreeMap<String, (u64, u64)> {
        self.consumers
            .iter()
            .map(|(k, c)| (k.clone(), (c.report.received, c.report.lost)))
            .collect()
    }

    /// Frees table entries of consumers whose process is gone or that went quiet.
    fn reclaim(&mut self) {
        let now = Instant::now();
        self.consumers.retain(|_, c| {
            c.pid.is_none_or(sys::pid_alive) && now.duration_since(c.seen) < CONSUMER_TTL
        });
    }

    /// The camera a pose message places (world metres or WGS84).
    fn posed(&self, p: &Pose, cam: &Camera) -> Result<Camera, String> {
        let mut cam = *cam;
        match (p.position, p.yaw_deg, p.lat_deg, p.lon_deg, p.height_m, p.heading_deg) {
            (Some(position), Some(yaw), None, None, None, None) => {
                if position
                    .iter()
                    .any(|v| !v.is_finite() || v.abs() > MAX_COORD_M)
                {
                    return Err(format!("position outside +-{MAX_COORD_M} m"));
                }
                cam.position = glam::DVec3::from_array(position);
                (cam.yaw_deg, cam.pitch_deg, cam.roll_deg) = (yaw, p.pitch_deg, p.roll_deg);
                if !(cam.yaw_deg.abs() <= 3600.0 && cam.roll_deg.abs() <= 3600.0) {
                    return Err("yaw/roll outside +-3600 deg".into());
                }
                Ok(cam)
            }
            (None, None, Some(lat_deg), Some(lon_deg), Some(height_m), Some(heading_deg)) => {
                let geo = GeoPose {
                    lat_deg,
                    lon_deg,
                    height_m,
                    height_ref: p.height_ref,
                    heading_deg,
                    pitch_deg: p.pitch_deg,
                    roll_deg: p.roll_deg,
                };
                if !(heading_deg.abs() <= 3600.0 && p.roll_deg.abs() <= 3600.0) {
                    return Err("heading/roll outside +-3600 deg".into());
                }
                geo.validate("pose").map_err(|e| e.to_string())?;
                let resolve = self.geo.as_ref().ok_or(
                    "a WGS84 pose needs a data set on the earth (georeferenced, or [dataset] anchor)",
                )?;
                resolve(&geo, &cam).map_err(|e| e.to_string())
            }
            _ => Err(
                "pose: give either position + yaw_deg (world metres) or lat_deg + lon_deg + height_m + heading_deg (WGS84)"
                    .into(),
            ),
        }
    }

    /// Applies one message; errors are reasons to reject it.
    fn apply(&mut self, bytes: &[u8], current: &Camera, sender: Option<u32>) -> Result<(), String> {
        if bytes.len() > MAX_MESSAGE {
            return Err("message too long".into());
        }
        let text = std::str::from_utf8(bytes).map_err(|_| "not UTF-8".to_string())?;
        let msg: ControlMsg = serde_json::from_str(text.trim()).map_err(|e| e.to_string())?;
        let mut cam = self.live.unwrap_or(*current);
        let mut changed = false;
        if let Some(p) = &msg.pose {
            cam = self.posed(p, &cam)?;
            changed = true;
        }
        if let Some(f) = msg.fov_deg {
            if !(f.is_finite() && (1.0..=170.0).contains(&f)) {
                return Err(format!("fov_deg {f} is outside 1..=170"));
            }
            cam.vfov_deg = f;
            changed = true;
        }
        cam.validate().map_err(|e| e.to_string())?;
        let resize = match msg.resolution {
            Some([w, h]) if RES_RANGE.contains(&w) && RES_RANGE.contains(&h) => Some((w, h)),
            Some([w, h]) => {
                return Err(format!(
                    "resolution {w}x{h} is outside {RES_RANGE:?} per side"
                ));
            }
            None => None,
        };
        if let Some(c) = &msg.consumer {
            if c.name.is_empty() || c.name.len() > 64 || c.name.chars().any(char::is_control) {
                return Err("consumer report: bad name".into());
            }
            if self.consumers.len() >= MAX_CONSUMERS && !self.consumers.contains_key(&c.name) {
                self.reclaim();
                if self.consumers.len() >= MAX_CONSUMERS {
                    return Err(format!(
                        "consumer report: {MAX_CONSUMERS} live consumers already registered"
                    ));
                }
            }
        }
        if msg.pose.is_none()
            && msg.fov_deg.is_none()
            && resize.is_none()
            && msg.scripted.is_none()
            && msg.consumer.is_none()
        {
            return Err("empty message".into());
        }
        // Everything checked: apply.
        if changed {
            self.live = Some(cam);
        }
        if msg.scripted == Some(true) {
            self.live = None;
        }
        if resize.is_some() {
            self.resize = resize;
        }
        if let Some(c) = msg.consumer {
            self.consumers.insert(
                c.name.clone(),
                Consumer {
                    report: c,
                    pid: sender,
                    seen: Instant::now(),
                },
            );
        }
        Ok(())
    }
}

/// The control socket (mode 0600), ours while we live: a lock beside it (`<path>.lock`) makes a
/// second service refuse the path instead of taking it over; only then is a stale socket
/// replaced. Removed on drop.
pub struct ControlSocket {
    sock: UnixDatagram,
    path: PathBuf,
    buf: Vec<u8>,
    _lock: PathLock,
}

impl ControlSocket {
    pub fn bind(path: &Path) -> Result<Self> {
        use std::os::unix::fs::{FileTypeExt, PermissionsExt};
        let lock = PathLock::acquire(
            &lock_path_for(path),
            &format!("control socket {}", path.display()),
        )?;
        if let Ok(m) = std::fs::symlink_metadata(path) {
            if m.file_type().is_socket() {
                // Stale: whoever bound it no longer holds the lock.
                std::fs::remove_file(path).map_err(|e| Error::io(path, e))?;
            } else {
                return Err(Error::invalid(
                    "control socket",
                    format!("{}: exists and is not a socket", path.display()),
                ));
            }
        }
        let sock = UnixDatagram::bind(path).map_err(|e| {
            Error::io(
                path,
                std::io::Error::new(e.kind(), format!("cannot bind control socket: {e}")),
            )
        })?;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600))
            .map_err(|e| Error::io(path, e))?;
        sock.set_nonblocking(true).map_err(|e| Error::io(path, e))?;
        // Ask the kernel for each sender's credentials (who reported as a consumer).
        let one: libc::c_int = 1;
        // SAFETY: valid socket and option value.
        unsafe {
            libc::setsockopt(
                sock.as_raw_fd(),
                libc::SOL_SOCKET,
                libc::SO_PASSCRED,
                (&one as *const libc::c_int).cast(),
                size_of::<libc::c_int>() as libc::socklen_t,
            )
        };
        Ok(ControlSocket {
            sock,
            path: path.to_path_buf(),
            buf: vec![0u8; MAX_MESSAGE + 1],
            _lock: lock,
        })
    }

    /// Handles the datagrams waiting (at most [`MAX_MESSAGES_PER_FRAME`]).
    pub fn drain(&mut self, ctl: &mut Control, current: &Camera) {
        for _ in 0..MAX_MESSAGES_PER_FRAME {
            match recv_with_pid(&self.sock, &mut self.buf) {
                Ok((n, _, true)) => {
                    let _ = n;
                    ctl.reject("message too long".into());
                }
                Ok((n, pid, false)) => {
                    let (bytes, _) = self.buf.split_at(n);
                    ctl.handle(bytes, current, pid);
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                Err(e) => {
                    tracing::warn!("control socket: {e}");
                    break;
                }
            }
        }
    }
}

impl Drop for ControlSocket {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// One datagram, the sender's pid (`SCM_CREDENTIALS`, checked by the kernel) and whether it
/// was truncated.
fn recv_with_pid(
    sock: &UnixDatagram,
    buf: &mut [u8],
) -> std::io::Result<(usize, Option<u32>, bool)> {
    let mut iov = libc::iovec {
        iov_base: buf.as_mut_ptr().cast(),
        iov_len: buf.len(),
    };
    // Room for one ucred control message (CMSG_SPACE(sizeof(struct ucred)) is 32 on Linux).
    let mut cbuf = [0u64; 8];
    // SAFETY: zeroed msghdr is valid; pointers reference live buffers for the call.
    let mut msg: libc::msghdr = unsafe { std::mem::zeroed() };
    msg.msg_iov = &mut iov;
    msg.msg_iovlen = 1;
    msg.msg_control = cbuf.as_mut_ptr().cast();
    msg.msg_controllen = size_of_val(&cbuf) as _;
    // SAFETY: valid socket and message header.
    let n = unsafe { libc::recvmsg(sock.as_raw_fd(), &mut msg, libc::MSG_DONTWAIT) };
    if n < 0 {
        return Err(std::io::Error::last_os_error());
    }
    let mut pid = None;
    // SAFETY: walking the control messages the kernel filled in, within msg_controllen.
    unsafe {
        let mut c = libc::CMSG_FIRSTHDR(&msg);
        while !c.is_null() {
            if (*c).cmsg_level == libc::SOL_SOCKET && (*c).cmsg_type == libc::SCM_CREDENTIALS {
                let cred = std::ptr::read_unaligned(libc::CMSG_DATA(c) as *const libc::ucred);
                pid = u32::try_from(cred.pid).ok().filter(|&p| p > 0);
            }
            c = libc::CMSG_NXTHDR(&msg, c);
        }
    }
    let truncated = msg.msg_flags & libc::MSG_TRUNC != 0;
    Ok((n as usize, pid, truncated))
}
