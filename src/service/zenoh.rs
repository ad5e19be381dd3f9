//! Frames beyond one board: `vkterrain serve` over Zenoh (`docs/zenoh.md`).
//!
//! Key expressions, per ring name: `<prefix>/<ring>/frame` (every frame: the ring slot's
//! 256-byte metadata, then the RGBA8 pixels, then the depth when the ring has depth),
//! `<prefix>/<ring>/control` (camera control, the control socket's messages, validation and
//! counters), `<prefix>/<ring>/status` (a queryable answering with the status JSON).
//!
//! Frames go through Zenoh shared memory when the subscriber runs on the same machine with
//! shared memory enabled, over the network otherwise (Zenoh decides per peer). The renderer
//! only hands a frame to a sender thread through a queue of `queue` frames: when it is full (a
//! slow network or subscriber) the frame is dropped and counted, never waited for; Zenoh itself
//! drops rather than blocks (`CongestionControl::Drop`).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use crossbeam_channel::{Receiver, Sender, TrySendError};
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::qos::CongestionControl;
use zenoh::shm::{GarbageCollect, PosixShmProviderBackend, ShmProvider, ShmProviderBuilder};

use super::ZenohSettings;
use super::control::{Control, MAX_MESSAGES_PER_FRAME};
use crate::error::{Error, Result};
use crate::output::ring::FrameMeta;
use crate::output::ring::producer::meta_of;
use crate::output::ring::sys;
use crate::readback::FrameView;
use crate::scene::Camera;

#[cfg(target_endian = "big")]
compile_error!("the frame payload is the ring's little-endian FrameMeta in memory order");

/// Control messages queued between Zenoh's callback and the render loop at most.
const CONTROL_QUEUE: usize = 1024;

/// Counters of the Zenoh side, shown in the status.
#[derive(Default)]
pub struct ZenohCounters {
    /// Frames handed to Zenoh.
    pub published: AtomicU64,
    /// Frames dropped because the queue was full or no buffer was free (a slow link).
    pub dropped: AtomicU64,
    /// Frames that went out in a shared-memory buffer.
    pub shm_frames: AtomicU64,
    /// Control messages dropped because the render loop had not caught up (counted as rejected).
    control_overflow: AtomicU64,
}

/// Key expressions of one ring.
pub struct Keys {
    pub frame: String,
    pub control: String,
    pub status: String,
}

impl Keys {
    pub fn of(prefix: &str, ring: &str) -> Self {
        Keys {
            frame: format!("{prefix}/{ring}/frame"),
            control: format!("{prefix}/{ring}/control"),
            status: format!("{prefix}/{ring}/status"),
        }
    }
}

/// A Zenoh session configured from the settings (shared with the subscriber command).
pub fn open_session(settings: &ZenohSettings) -> Result<zenoh::Session> {
    let bad = |e: zenoh::Error| Error::invalid("zenoh", e.to_string());
    let mut c = zenoh::Config::default();
    let json = |v: &Vec<String>| serde_json::to_string(v).unwrap_or_else(|_| "[]".into());
    c.insert_json5("mode", &format!("{:?}", settings.mode))
        .map_err(bad)?;
    c.insert_json5("listen/endpoints", &json(&settings.listen))
        .map_err(bad)?;
    c.insert_json5("connect/endpoints", &json(&settings.connect))
        .map_err(bad)?;
    c.insert_json5(
        "scouting/multicast/enabled",
        if settings.multicast_scouting {
            "true"
        } else {
            "false"
        },
    )
    .map_err(bad)?;
    c.insert_json5(
        "transport/shared_memory/enabled",
        if settings.shared_memory {
            "true"
        } else {
            "false"
        },
    )
    .map_err(bad)?;
    zenoh::open(c)
        .wait()
        .map_err(|e| Error::invalid("zenoh", format!("cannot open a session: {e}")))
}

enum Outgoing {
    Shm(zenoh::shm::ZShmMut),
    Heap(Vec<u8>),
}

/// The Zenoh side of `serve`.
pub struct ZenohBridge {
    keys: Keys,
    tx: Option<Sender<Outgoing>>,
    sender: Option<JoinHandle<()>>,
    control_rx: Receiver<Vec<u8>>,
    status: Arc<Mutex<String>>,
    provider: Option<ShmProvider<PosixShmProviderBackend>>,
    /// The pool size the provider was made for (frames of this many bytes).
    provider_frame: usize,
    shared_memory: bool,
    queue: usize,
    pub counters: Arc<ZenohCounters>,
    overflow_seen: u64,
    _control: zenoh::pubsub::Subscriber<()>,
    _status: zenoh::query::Queryable<()>,
    session: zenoh::Session,
}

impl ZenohBridge {
    pub fn start(settings: &ZenohSettings, ring: &str) -> Result<Self> {
        settings.validate()?;
        let session = open_session(settings)?;
        let keys = Keys::of(&settings.prefix, ring);
        let bad = |e: zenoh::Error| Error::invalid("zenoh", e.to_string());
        let counters = Arc::new(ZenohCounters::default());
        let (control_tx, control_rx) = crossbeam_channel::bounded::<Vec<u8>>(CONTROL_QUEUE);
        let c = counters.clone();
        let control = session
            .declare_subscriber(&keys.control)
            .callback(move |sample| {
                let bytes = sample.payload().to_bytes().into_owned();
                if control_tx.try_send(bytes).is_err() {
                    c.control_overflow.fetch_add(1, Ordering::Relaxed);
                }
            })
            .wait()
            .map_err(bad)?;
        let status = Arc::new(Mutex::new(String::from("{}")));
        let s = status.clone();
        let status_key = keys.status.clone();
        let queryable = session
            .declare_queryable(&keys.status)
            .callback(move |query| {
                let text = s.lock().map(|t| t.clone()).unwrap_or_default();
                let _ = query.reply(&status_key, text).wait();
            })
            .wait()
            .map_err(bad)?;
        let (tx, rx) = crossbeam_channel::bounded::<Outgoing>(settings.queue.max(1));
        let sender = {
            let session = session.clone();
            let key = keys.frame.clone();
            let c = counters.clone();
            std::thread::Builder::new()
                .name("zenoh-frames".into())
                .spawn(move || {
                    for mut out in rx {
                        // publish_ns: when the frame leaves for Zenoh (subscribers measure their
                        // latency from it).
                        let now = sys::monotonic_ns().to_le_bytes();
                        let off = std::mem::offset_of!(FrameMeta, publish_ns);
                        match &mut out {
                            Outgoing::Shm(b) => b.as_mut()[off..off + 8].copy_from_slice(&now),
                            Outgoing::Heap(v) => v[off..off + 8].copy_from_slice(&now),
                        }
                        let payload = match out {
                            Outgoing::Shm(b) => ZBytes::from(b),
                            Outgoing::Heap(v) => ZBytes::from(v),
                        };
                        let r = session
                            .put(&key, payload)
                            .congestion_control(CongestionControl::Drop)
                            .wait();
                        match r {
                            Ok(()) => c.published.fetch_add(1, Ordering::Relaxed),
                            Err(_) => c.dropped.fetch_add(1, Ordering::Relaxed),
                        };
                    }
                })
                .map_err(|e| Error::invalid("zenoh", format!("cannot start sender: {e}")))?
        };
        tracing::info!(key = keys.frame, "publishing frames over zenoh");
        Ok(ZenohBridge {
            keys,
            tx: Some(tx),
            sender: Some(sender),
            control_rx,
            status,
            provider: None,
            provider_frame: 0,
            shared_memory: settings.shared_memory,
            queue: settings.queue.max(1),
            counters,
            overflow_seen: 0,
            _control: control,
            _status: queryable,
            session,
        })
    }

    pub fn keys(&self) -> &Keys {
        &self.keys
    }

    /// A buffer for one frame payload: shared memory when enabled (a pool of `queue + 2`
    /// frames, re-made when the frame size changes), else the heap. None: no buffer free.
    fn buffer(&mut self, len: usize) -> Option<Outgoing> {
        if !self.shared_memory {
            return Some(Outgoing::Heap(vec![0u8; len]));
        }
        if self.provider.is_none() || self.provider_frame != len {
            let pool = len * (self.queue + 2);
            match ShmProviderBuilder::default_backend(pool).wait() {
                Ok(p) => {
                    self.provider = Some(p);
                    self.provider_frame = len;
                }
                Err(e) => {
                    tracing::warn!("zenoh shared memory unavailable, using the heap: {e}");
                    self.shared_memory = false;
                    return Some(Outgoing::Heap(vec![0u8; len]));
                }
            }
        }
        let provider = self.provider.as_ref()?;
        provider
            .alloc(len)
            .with_policy::<GarbageCollect>()
            .wait()
            .ok()
            .map(Outgoing::Shm)
    }

    /// Hands `frame` to the sender thread, or drops it (counted) when the queue is full or no
    /// buffer is free. Never waits.
    pub fn publish(&mut self, frame: &FrameView<'_>) {
        let full = self.tx.as_ref().is_none_or(|tx| tx.is_full());
        if full {
            self.counters.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let meta = meta_of(frame, sys::monotonic_ns());
        let depth = frame.depth.map(|d| d.len() * 4).unwrap_or(0);
        let len = size_of::<FrameMeta>() + frame.rgba.len() + depth;
        let Some(mut out) = self.buffer(len) else {
            self.counters.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        };
        let bytes: &mut [u8] = match &mut out {
            Outgoing::Shm(b) => b.as_mut(),
            Outgoing::Heap(v) => v.as_mut_slice(),
        };
        write_payload(bytes, &meta, frame.rgba, frame.depth);
        if matches!(out, Outgoing::Shm(_)) {
            self.counters.shm_frames.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(tx) = &self.tx
            && let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) = tx.try_send(out)
        {
            self.counters.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Applies the control messages that arrived over Zenoh (at most
    /// [`MAX_MESSAGES_PER_FRAME`]), with the same validation and counters as the socket.
    pub fn drain_control(&mut self, ctl: &mut Control, current: &Camera) {
        let overflow = self.counters.control_overflow.load(Ordering::Relaxed);
        for _ in self.overflow_seen..overflow {
            ctl.reject("zenoh control queue full".into());
        }
        self.overflow_seen = overflow;
        for _ in 0..MAX_MESSAGES_PER_FRAME {
            match self.control_rx.try_recv() {
                Ok(bytes) => ctl.handle(&bytes, current, None),
                Err(_) => break,
            }
        }
    }

    /// What the status queryable answers from now on.
    pub fn set_status(&self, json: String) {
        if let Ok(mut s) = self.status.lock() {
            *s = json;
        }
    }
}

impl Drop for ZenohBridge {
    fn drop(&mut self) {
        // Let the sender finish the queued frames, then close the session.
        self.tx = None;
        if let Some(h) = self.sender.take() {
            let _ = h.join();
        }
        let _ = self.session.close().wait();
    }
}

/// The frame payload: the ring slot's metadata (256 bytes, little-endian), the pixels, the
/// depth (when present).
pub fn write_payload(out: &mut [u8], meta: &FrameMeta, rgba: &[u8], depth: Option<&[f32]>) {
    let m = size_of::<FrameMeta>();
    // SAFETY: FrameMeta is repr(C) plain data without padding (asserted in layout.rs).
    let meta_bytes =
        unsafe { std::slice::from_raw_parts((meta as *const FrameMeta).cast::<u8>(), m) };
    out[..m].copy_from_slice(meta_bytes);
    out[m..m + rgba.len()].copy_from_slice(rgba);
    if let Some(d) = depth {
        // SAFETY: f32 slice viewed as bytes.
        let d = unsafe { std::slice::from_raw_parts(d.as_ptr().cast::<u8>(), d.len() * 4) };
        out[m + rgba.len()..m + rgba.len() + d.len()].copy_from_slice(d);
    }
}

/// A frame payload split into its parts ([`parse_payload`]).
pub struct Payload<'a> {
    pub meta: FrameMeta,
    /// `meta.row_stride * meta.height` bytes of RGBA8.
    pub pixels: &'a [u8],
    /// `width * height` little-endian f32 depths, when the service publishes depth.
    pub depth: Option<&'a [u8]>,
}

/// Splits a frame payload into metadata, pixels and depth, checking every size against the
/// metadata (a subscriber never trusts the network).
pub fn parse_payload(bytes: &[u8]) -> Result<Payload<'_>> {
    let m = size_of::<FrameMeta>();
    let bad = |s: String| Error::invalid("zenoh frame", s);
    if bytes.len() < m {
        return Err(bad(format!(
            "{} bytes is shorter than the metadata",
            bytes.len()
        )));
    }
    // SAFETY: FrameMeta is plain old data; read_unaligned copies any bit pattern.
    let meta: FrameMeta = unsafe { std::ptr::read_unaligned(bytes.as_ptr().cast()) };
    if meta.width == 0 || meta.height == 0 || meta.width > 16384 || meta.height > 16384 {
        return Err(bad(format!(
            "{}x{} is outside 1..=16384",
            meta.width, meta.height
        )));
    }
    if meta.row_stride as u64 != meta.width as u64 * 4 {
        return Err(bad("row_stride is not 4 * width".into()));
    }
    let px = meta.row_stride as usize * meta.height as usize;
    let rest = bytes.len() - m;
    let depth_len = meta.width as usize * meta.height as usize * 4;
    match rest {
        r if r == px => Ok(Payload {
            meta,
            pixels: &bytes[m..],
            depth: None,
        }),
        r if r == px + depth_len => Ok(Payload {
            meta,
            pixels: &bytes[m..m + px],
            depth: Some(&bytes[m + px..]),
        }),
        r => Err(bad(format!(
            "{r} bytes after the metadata, expected {px} (or {} with depth)",
            px + depth_len
        ))),
    }
}
