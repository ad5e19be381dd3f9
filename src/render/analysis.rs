//! An optional stage recorded after the terrain pass of every frame: the evaluator's frame
//! analysis (`src/eval/gpu/`) measures the frame where it is, on the GPU, and collects its
//! results when the frame is delivered. The render loop knows only this seam; the stage owns
//! its pipelines and buffers. It runs after the `AfterTerrain` timestamp, so the method's pass
//! times never contain it.

use ash::vk;

use super::targets::Targets;
use crate::error::Result;
use crate::scene::Camera;
use crate::slots::FrameSlot;

/// What the analysis of one frame sees while it is recorded.
pub struct AnalysisFrame<'a> {
    /// The frame's index in the run (0, 1, ...).
    pub index: u64,
    pub slot: FrameSlot,
    /// One camera per view, in view order.
    pub cameras: &'a [Camera],
    /// Columns `(first, count)` of each view.
    pub columns: &'a [(u32, u32)],
    /// The frame's colour and depth targets, transfer sources (after the terrain pass).
    pub targets: &'a Targets,
}

/// A stage recorded into every frame's command buffer after the terrain pass and before the
/// readback copies.
pub trait FrameAnalysis: Send {
    /// Records the analysis of `frame` (host-side updates of buffers the frame's slot owns
    /// are allowed: the slot's previous GPU work is complete).
    fn record(&mut self, cmd: vk::CommandBuffer, frame: &AnalysisFrame<'_>) -> Result<()>;
    /// Frame `index` in `slot` has completed on the GPU: read its results (called before the
    /// frame goes to the sink).
    fn complete(&mut self, slot: FrameSlot, index: u64) -> Result<()>;
}
