//! vkterrain: a headless Vulkan terrain renderer for embedded boards.
//!
//! Data flows through the modules in this order:
//! [`dataset`] -> [`lod`] (LOD methods) -> [`render`] (frames in flight) -> [`readback`]
//! (the frame interface) -> [`output`] (PNG, ring). [`driver`] owns device, memory and sync;
//! [`scene`] holds cameras and scripted paths; [`gpu_constants`] is shared with the shaders;
//! [`eval`] measures rendered frames against the exact surface.

pub mod cli;
pub mod clipmap;
pub mod config;
pub mod dataset;
pub mod driver;
pub mod error;
pub mod eval;
pub mod frame;
pub mod geo;
/// Constants shared by Rust and WGSL (generated into every shader by `build.rs`).
pub mod gpu_constants;
pub mod lod;
pub mod output;
pub mod readback;
pub mod render;
pub mod scene;
/// `serve`'s control channel and Zenoh side.
pub mod service;
pub mod slots;

pub use error::{Error, Result};
