//! LOD methods behind one seam: the renderer, the evaluator and the benchmarks only see
//! [`LodMethod`], so brute force and later methods are interchangeable.

pub mod brute;

use ash::vk;

use crate::error::{Error, Result};
use crate::render::pipeline::TargetFormats;
use crate::render::terrain::TerrainGpu;
use crate::scene::Camera;

/// The methods vkterrain knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MethodKind {
    /// Every height sample is a vertex: the exact reference.
    Brute,
}

impl MethodKind {
    pub const ALL: &[(&'static str, MethodKind)] = &[("brute", MethodKind::Brute)];

    pub fn parse(name: &str) -> Result<Self> {
        Self::ALL
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, k)| *k)
            .ok_or_else(|| {
                let names: Vec<_> = Self::ALL.iter().map(|(n, _)| *n).collect();
                Error::invalid(
                    "method",
                    format!(
                        "unknown method {name:?} (expected one of {})",
                        names.join(", ")
                    ),
                )
            })
    }

    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, k)| *k == self)
            .map(|(n, _)| *n)
            .unwrap_or("?")
    }
}

/// What a method gets to build its GPU state.
pub struct MethodContext<'a> {
    pub gpu: &'a std::sync::Arc<crate::driver::Gpu>,
    pub terrain: &'a TerrainGpu,
    pub formats: TargetFormats,
    pub slots: usize,
}

/// The view a frame is rendered for.
#[derive(Clone, Copy, Debug)]
pub struct ViewState {
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
}

/// One LOD method. Per frame the renderer calls `update` (host side, slot free), then records
/// `record_prepass` outside and `record_draw` inside the terrain render pass; set 0 (frame
/// uniforms + terrain textures) is bound by the method with its own pipeline layout.
pub trait LodMethod {
    fn name(&self) -> &'static str;
    /// Host-side per-frame work for `slot` (uniforms, CPU selection). The slot's previous GPU
    /// work is complete when this is called.
    fn update(&mut self, slot: usize, view: &ViewState) -> Result<()>;
    /// Compute work before the render pass (tiling, culling); none by default.
    fn record_prepass(&mut self, _cmd: vk::CommandBuffer, _slot: usize) {}
    /// Draws inside the terrain pass; `frame_set` is descriptor set 0 of this slot.
    fn record_draw(&mut self, cmd: vk::CommandBuffer, slot: usize, frame_set: vk::DescriptorSet);
    /// Triangles the last `record_draw` of `slot` submits (including zero-area ones).
    fn triangles(&self, slot: usize) -> u64;
}

/// Creates a method by kind.
pub fn create(kind: MethodKind, ctx: &MethodContext<'_>) -> Result<Box<dyn LodMethod>> {
    Ok(match kind {
        MethodKind::Brute => Box::new(brute::BruteForce::new(ctx)?),
    })
}
