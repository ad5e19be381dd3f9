//! What `vkterrain serve` offers besides the ring: camera control (a Unix datagram socket and,
//! with the `zenoh` feature, Zenoh), with one validation and one set of counters for both, and
//! frames, metadata and status over Zenoh (`docs/zenoh.md`).

pub mod control;
pub mod settings;
#[cfg(feature = "zenoh")]
pub mod zenoh;

pub use settings::{ServiceConfig, ZenohSettings};
