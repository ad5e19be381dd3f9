//! One frame's command buffer, in order: clipmap uploads, each view's LOD prepass, the terrain
//! pass with one viewport per view, the readback copies; timestamps between the stages.

use super::delivery::Stamp;
use super::{Renderer, view_columns};
use crate::error::Result;
use crate::slots::FrameSlot;

impl Renderer {
    /// Records frame slot `frame`; the colour is copied into `color_dst` (a sink's zero-copy
    /// target) or else the slot's readback buffer.
    pub(super) fn record(
        &mut self,
        frame: FrameSlot,
        sky: [f32; 3],
        color_dst: Option<ash::vk::Buffer>,
    ) -> Result<()> {
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
        slot.readback
            .record(&self.gpu, cmd, &slot.targets, color_dst);
        slot.timestamps.write(cmd, Stamp::AfterReadback);
        slot.end()
    }
}
