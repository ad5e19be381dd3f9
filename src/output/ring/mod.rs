//! Frames for other processes: a ring of slots in POSIX shared memory (`/dev/shm/<name>`).
//!
//! [`layout`] is the `#[repr(C)]` format shared with the C and Python consumers;
//! [`producer::RingProducer`] publishes frames (it is a [`FrameSink`](crate::readback::FrameSink))
//! with a per-slot seqlock and never waits for readers; [`reader::RingReader`] is the Rust
//! consumer. `docs/ring.md` describes the protocol.

pub mod layout;
pub mod producer;
pub mod reader;
pub mod sys;

pub use layout::{FrameMeta, Geometry, validate_name};
pub use producer::{ProducerOptions, RingProducer};
pub use reader::{FrameRef, Next, ReaderStats, RingReader};
