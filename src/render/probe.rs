//! Test support (feature `test-support`): evaluate the shaders' shared functions through the
//! exact set-0 state a view had in the last rendered frame, and read the results back.

use std::ffi::CStr;

use super::Renderer;
use crate::clipmap::probe::ProbeKind;
use crate::driver::shaders::Spirv;
use crate::error::{Error, Result};
use crate::lod::udlod::levels::Tile;
use crate::lod::udlod::probe::ProbedVertex;
use crate::slots::ViewSlot;

/// One point of the terrain-helper probes (`ProbePoint` in `shaders/terrain_probe.wgsl` and
/// its GLSL twin `shaders/glsl/terrain_probe.comp`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TerrainProbePoint {
    /// In: xy the integer sample for `sample_height` and `project`'s cell.
    pub cell: [i32; 4],
    /// In: xy a position (samples) for `height_at`, zw the fraction `project` adds.
    pub pos: [f32; 4],
    /// Out: x `sample_height(cell)`, y `height_at(pos.xy)`.
    pub heights: [f32; 4],
    /// Out: `project(cell, pos.zw, height_at(pos.xy))`.
    pub clip: [f32; 4],
}

impl Renderer {
    /// Tests: runs the terrain-helper probe `entry` of `spv` (WGSL's `terrain_probe` or the
    /// GLSL port's `terrain_probe.comp`) over `points` through the set 0 view `view` had in
    /// the last rendered frame. Call after [`Renderer::finish`]; waits for the GPU.
    pub fn probe_terrain_helpers(
        &self,
        view: usize,
        spv: Spirv,
        entry: &CStr,
        points: &[TerrainProbePoint],
    ) -> Result<Vec<TerrainProbePoint>> {
        let slot = self.last_view_slot("probe_terrain_helpers", view)?;
        let header = [points.len() as u32, 0, 0, 0];
        let io = [bytemuck::bytes_of(&header), bytemuck::cast_slice(points)].concat();
        let groups = (points.len() as u32)
            .div_ceil(crate::gpu_constants::TERRAIN_PROBE_WORKGROUP)
            .max(1);
        let out = crate::driver::probe::run(
            &self.gpu,
            spv,
            entry,
            &[(self.terrain.descriptors.layout, self.terrain.set(slot))],
            &io,
            groups,
        )?;
        Ok(bytemuck::pod_collect_to_vec(&out[size_of_val(&header)..]))
    }

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
        let slot = self.last_view_slot("probe_heights", view)?;
        crate::clipmap::probe::probe(
            &self.gpu,
            self.terrain.variant,
            self.terrain.descriptors.layout,
            self.terrain.set(slot),
            points,
            kind,
        )
    }

    /// Tests and tools: the method's vertex morph on the GPU (UDLOD's `morphed_vertex`) for
    /// each `(tile, local vertex)` through the state view `view` had in the last rendered
    /// frame. Call after [`Renderer::finish`]; waits for the GPU. An error for a method
    /// without a morph.
    pub fn probe_morph_in_view(
        &self,
        view: usize,
        inputs: &[(Tile, [u32; 2])],
    ) -> Result<Vec<ProbedVertex>> {
        let slot = self.last_view_slot("probe_morph", view)?;
        let frame = (self.terrain.descriptors.layout, self.terrain.set(slot));
        self.method
            .probe_vertices(slot, frame, inputs)?
            .ok_or_else(|| {
                Error::invalid(
                    "probe_morph",
                    format!("method {} has no vertex morph", self.method.name()),
                )
            })
    }

    /// Tests: chunked LOD's vertex placement (`chunk_sample`, WGSL or the GLSL port) for each
    /// `(chunk, local vertex)` through the set 0 and method set 1 view `view` had in the last
    /// rendered frame. Call after [`Renderer::finish`]; waits for the GPU. An error for a
    /// method without a set to probe.
    pub fn probe_chunk_samples(
        &self,
        view: usize,
        port: crate::lod::chunked::probe::Port,
        inputs: &[(Tile, [u32; 2])],
    ) -> Result<Vec<[i32; 2]>> {
        let slot = self.last_view_slot("probe_chunk_samples", view)?;
        let frame = (self.terrain.descriptors.layout, self.terrain.set(slot));
        let set = self.method.probe_set(slot).ok_or_else(|| {
            Error::invalid(
                "probe_chunk_samples",
                format!("method {} has no set to probe", self.method.name()),
            )
        })?;
        crate::lod::chunked::probe::probe(&self.gpu, frame, set, port, self.terrain.variant, inputs)
    }

    /// The view slot view `view` used in the last rendered frame, once that frame is done.
    fn last_view_slot(&self, what: &str, view: usize) -> Result<ViewSlot> {
        if self.next_frame == 0 || !self.in_flight.is_empty() {
            return Err(Error::invalid(what, "needs a rendered, finished frame"));
        }
        if view >= self.options.views {
            return Err(Error::invalid(
                what,
                format!("view {view} of {}", self.options.views),
            ));
        }
        let frame = self.layout.frame_slot(self.next_frame - 1);
        Ok(self.layout.view_slot(frame, view))
    }
}
