//! The clipmap's part of every frame, as the render loop sees it: the host [`Clipmap`] (when
//! heights stream) beside its device mirror [`ClipmapGpu`] (a disabled placeholder otherwise,
//! so set 0's bindings always exist).
//!
//! Per frame: [`ClipmapStage::prepare`] (host, the frame slot's previous GPU work complete) runs
//! one update for every view, stages the new nodes and writes each view's quadtree;
//! [`ClipmapStage::record_uploads`] records the staged copies first in the frame's command
//! buffer, before anything samples the atlas.

use std::sync::Arc;

use ash::vk;
use glam::{DVec2, DVec3};

use super::Clipmap;
use super::gpu::ClipmapGpu;
use crate::driver::Gpu;
use crate::error::{Error, Result};
use crate::slots::{FrameSlot, SlotLayout};

pub struct ClipmapStage {
    host: Option<Clipmap>,
    pub device: ClipmapGpu,
    layout: SlotLayout,
}

impl ClipmapStage {
    /// The stage for `host` (None: heights from the single texture) drawn with `layout`.
    pub fn new(gpu: &Arc<Gpu>, host: Option<Clipmap>, layout: SlotLayout) -> Result<Self> {
        let device = match &host {
            Some(c) => {
                if c.views.len() != layout.views {
                    return Err(Error::invalid(
                        "clipmap",
                        format!(
                            "made for {} views but the renderer draws {}",
                            c.views.len(),
                            layout.views
                        ),
                    ));
                }
                ClipmapGpu::new(
                    gpu,
                    Some(&c.geometry),
                    &c.settings,
                    c.settings.node_count,
                    layout,
                )?
            }
            None => ClipmapGpu::new(gpu, None, &Default::default(), 2, layout)?,
        };
        Ok(ClipmapStage {
            host,
            device,
            layout,
        })
    }

    /// The host clipmap, when heights come through one.
    pub fn host(&self) -> Option<&Clipmap> {
        self.host.as_ref()
    }

    /// Host side of frame slot `frame` for views whose LOD viewers stand at `viewers` (metres,
    /// in view order): one update for all views (the union of their wanted nodes, one atlas),
    /// the new nodes staged, each view's quadtree written. Returns the terrain height under each
    /// viewer as the clipmap samples it now (clamped into the data: the lookup extrapolates
    /// outside it), from memory; `None`s without a clipmap.
    pub fn prepare(&mut self, frame: FrameSlot, viewers: &[DVec3]) -> Result<Vec<Option<f64>>> {
        let Some(cm) = &mut self.host else {
            return Ok(vec![None; viewers.len()]);
        };
        let spacing = cm.geometry.spacing;
        let in_samples: Vec<DVec2> = viewers
            .iter()
            .map(|v| DVec2::new(v.x / spacing, v.y / spacing))
            .collect();
        let uploads = cm.update(&in_samples);
        let last = DVec2::new(
            cm.geometry.width as f64 - 1.0,
            cm.geometry.height as f64 - 1.0,
        );
        let ground = in_samples
            .iter()
            .enumerate()
            .map(|(v, p)| {
                let p = p.clamp(DVec2::ZERO, last);
                Some(cm.sample_height(v, [p.x as f32, p.y as f32]) as f64)
            })
            .collect();
        self.device
            .stage_uploads(frame, &cm.geometry, &cm.atlas, &uploads)?;
        for (view_slot, quadtree) in self.layout.view_slots_of(frame).zip(&cm.views) {
            self.device
                .write_quadtree(view_slot, &cm.geometry, quadtree)?;
        }
        Ok(ground)
    }

    /// Records frame slot `frame`'s staged uploads: after every earlier frame's sampling of
    /// those layers, before this frame's.
    pub fn record_uploads(&mut self, cmd: vk::CommandBuffer, frame: FrameSlot) {
        self.device.record_uploads(cmd, frame);
    }
}
