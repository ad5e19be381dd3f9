//! One frame's command buffer, in order: clipmap uploads, each view's LOD prepass, the terrain
//! pass with one viewport per view, the frame analysis (when set), the readback copies;
//! timestamps between the stages.

use super::analysis::AnalysisFrame;
use super::delivery::Stamp;
use super::{FrameRequest, Renderer, view_columns};
use crate::error::Result;
use crate::slots::FrameSlot;

impl Renderer {
    /// Records frame `index` of `requests` (one per view; the sky is the first's) into slot
    /// `frame`; the colour is copied into `color_dst` (a sink's zero-copy target) or else the
    /// slot's readback buffer.
    pub(super) fn record(
        &mut self,
        frame: FrameSlot,
        index: u64,
        requests: &[FrameRequest],
        color_dst: Option<ash::vk::Buffer>,
    ) -> Result<()> {
        let sky = requests[0].sky.unwrap_or(self.options.light.sky);
        let slot = &self.slots[frame.index()];
        let cmd = slot.begin()?;
        // New atlas nodes first: after every earlier frame's sampling, before this frame's.
        self.clipmap.record_uploads(cmd, frame);
        for view in self.layout.view_slots_of(frame) {
            self.method
                .record_prepass(cmd, view, self.terrain.set(view));
        }
        slot.timestamps.write(cmd, Stamp::AfterPrepass);
        slot.targets.begin_pass(cmd, &self.pass, sky);
        for (v, view) in self.layout.view_slots_of(frame).enumerate() {
            let columns = view_columns(self.options.width, self.layout.views, v);
            slot.targets.set_columns(cmd, columns);
            self.method.record_draw(cmd, view, self.terrain.set(view));
        }
        slot.targets.end_pass(cmd, &self.pass);
        slot.timestamps.write(cmd, Stamp::AfterTerrain);
        if let Some(stage) = &mut self.analysis {
            let cameras: Vec<_> = requests.iter().map(|r| r.camera).collect();
            let columns: Vec<_> = (0..self.layout.views)
                .map(|v| view_columns(self.options.width, self.layout.views, v))
                .collect();
            stage.record(
                cmd,
                &AnalysisFrame {
                    index,
                    slot: frame,
                    cameras: &cameras,
                    columns: &columns,
                    targets: &slot.targets,
                },
            )?;
        }
        slot.readback
            .record(&self.gpu, cmd, &slot.targets, color_dst);
        slot.timestamps.write(cmd, Stamp::AfterReadback);
        slot.end()
    }
}
