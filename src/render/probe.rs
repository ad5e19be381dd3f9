//! Test support (feature `test-support`): evaluate the shaders' shared functions through the
//! exact set-0 state a view had in the last rendered frame, and read the results back.

use super::Renderer;
use crate::clipmap::probe::ProbeKind;
use crate::error::{Error, Result};

impl Renderer {
    /// Tests and tools: GPU heights at level-0 sample positions for the state of the last
    /// rendered frame, `[clipmap_height, single-texture bilinear]` each. Call after
    /// [`Renderer::finish`]; waits for the GPU.
    pub fn probe_heights(&self, points: &[[f32; 2]]) -> Result<Vec<[f32; 2]>> {
        self.probe_in_view(0, points, ProbeKind::Heights)
    }

    /// [`Renderer::probe_heights`] through the state view `view` had in the last frame.
    pub fn probe_heights_in_view(&self, view: usize, points: &[[f32; 2]]) -> Result<Vec<[f32; 2]>> {
        self.probe_in_view(view, points, ProbeKind::Heights)
    }

    /// Tests and tools: what `kind` evaluates at `points` through the state view `view` had in
    /// the last rendered frame. Call after [`Renderer::finish`]; waits for the GPU.
    pub fn probe_in_view(
        &self,
        view: usize,
        points: &[[f32; 2]],
        kind: ProbeKind,
    ) -> Result<Vec<[f32; 2]>> {
        if self.next_frame == 0 || !self.in_flight.is_empty() {
            return Err(Error::invalid(
                "probe_heights",
                "needs a rendered, finished frame",
            ));
        }
        if view >= self.options.views {
            return Err(Error::invalid(
                "probe_heights",
                format!("view {view} of {}", self.options.views),
            ));
        }
        let frame = self.layout.frame_slot(self.next_frame - 1);
        crate::clipmap::probe::probe(
            &self.gpu,
            self.terrain.descriptors.layout,
            self.terrain.set(self.layout.view_slot(frame, view)),
            points,
            kind,
        )
    }
}
