//! Frames for other processes: a ring of slots in a shared memory-mapped file in a directory
//! only the service can write (`/run/vkterrain/<name>` by default).
//!
//! [`layout`] is the `#[repr(C)]` format shared with the C and Python consumers;
//! [`location`] says where rings live and whom readers trust; [`producer::RingProducer`]
//! publishes frames (it is a [`FrameSink`](crate::readback::FrameSink)) with a per-slot seqlock
//! and never waits for readers, by copy or with the GPU writing into the slot ([`zero_copy`]);
//! [`reader::RingReader`] is the Rust consumer. `docs/ring.md` describes the protocol and the
//! threat model.

pub mod layout;
pub mod location;
pub mod producer;
pub mod reader;
pub mod settings;
pub mod sys;
pub mod zero_copy;

pub use layout::{FrameMeta, Geometry, Layout, validate_name};
pub use location::RingLocation;
pub use producer::{ProducerOptions, RingProducer};
pub use reader::{FrameRef, Next, ReaderStats, RingReader};
pub use settings::RingConfig;
pub use zero_copy::ZeroCopyRequest;
