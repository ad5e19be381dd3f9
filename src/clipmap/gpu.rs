//! The clipmap on the device: the atlas (2D-array textures, one layer per atlas slot, shared
//! by every view), one quadtree storage buffer per view and frame slot, and one staging buffer
//! per frame slot.
//!
//! Per frame (host, after the slot's previous GPU work completed),
//! [`ClipmapGpu::write_quadtree`] fills each view's quadtree buffer and
//! [`ClipmapGpu::stage_uploads`] copies the frame's new nodes into the slot's staging buffer;
//! [`ClipmapGpu::record_uploads`] records, at the start of the frame's command buffer,
//! per layer: a barrier after every earlier sampling of the layer (earlier frames in the queue),
//! the copy, and a barrier before this frame's shaders. The host never waits for an upload.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::atlas::Atlas;
use super::quadtree::{HEADER_BYTES, ViewQuadtree};
use super::{ClipmapSettings, Geometry, Upload};
use crate::driver::Gpu;
use crate::driver::barrier::{Barriers, ImageAccess};
use crate::driver::memory::{Buffer, Image, ImageDesc};
use crate::error::{Error, Result};
use crate::slots::{FrameSlot, SlotLayout, ViewSlot};

/// Bytes of one layer over the three attachments: height (R32F), normal (RGBA8 snorm, mips),
/// albedo (RGBA8 sRGB, mips); a staging slot holds them in that order.
pub fn layer_bytes(g: &Geometry) -> u64 {
    (g.side() as u64).pow(2) * 4 + g.shading_texels() * 8
}

pub struct ClipmapGpu {
    gpu: Arc<Gpu>,
    /// Heights (R32F), one layer per atlas slot.
    pub atlas: Image,
    /// Unit normals (RGBA8 snorm) and albedo (RGBA8 sRGB) of the same layers.
    pub normals: Image,
    pub albedo: Image,
    /// Whether heights come through the clipmap (false: placeholders).
    pub enabled: bool,
    /// One per view slot.
    pub quadtrees: Vec<Buffer>,
    staging: Vec<Option<Buffer>>,
    staged: Vec<Vec<u16>>,
    side: u32,
    /// Mip sides of the normal and albedo layers.
    mips: Vec<u32>,
    scratch: Vec<u8>,
}

fn layer_range(layer: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: layer,
        layer_count: 1,
    }
}

/// The atlas's size: texels per side of a layer, layers, and quadtree cells (over all levels).
struct AtlasShape {
    side: u32,
    layers: u32,
    cells: u64,
}

impl AtlasShape {
    /// The shape for `geometry` with `settings.atlas_capacity` layers (at least 2), which the
    /// device must allow; `geometry` None: the disabled placeholder's 1x1 texels, 2 layers.
    fn new(
        gpu: &Gpu,
        geometry: Option<&Geometry>,
        settings: &ClipmapSettings,
        node_count: u32,
    ) -> Result<Self> {
        let Some(g) = geometry else {
            return Ok(AtlasShape {
                side: 1,
                layers: 2,
                cells: 1,
            });
        };
        let max_layers = gpu.info.limits.max_image_array_layers;
        if settings.atlas_capacity > max_layers {
            return Err(Error::invalid(
                "clipmap.atlas_capacity",
                format!(
                    "{} exceeds the device's {max_layers} array layers",
                    settings.atlas_capacity
                ),
            ));
        }
        Ok(AtlasShape {
            side: g.side(),
            layers: settings.atlas_capacity.max(2),
            cells: g.levels.len() as u64 * (node_count as u64).pow(2),
        })
    }
}

/// The height, normal and albedo atlases (the last two with `shading_mips` levels), every
/// layer and level ready to be sampled by any shader stage.
fn atlas_images(gpu: &Arc<Gpu>, shape: &AtlasShape, shading_mips: u32) -> Result<[Image; 3]> {
    let make = |name: &str, format, mips: u32| {
        Image::new(
            gpu,
            &ImageDesc {
                name,
                format,
                extent: vk::Extent2D {
                    width: shape.side,
                    height: shape.side,
                },
                layers: shape.layers,
                mips,
                usage: vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST,
                aspect: vk::ImageAspectFlags::COLOR,
            },
        )
    };
    let atlas = make("clipmap height atlas", vk::Format::R32_SFLOAT, 1)?;
    let normals = make(
        "clipmap normal atlas",
        vk::Format::R8G8B8A8_SNORM,
        shading_mips,
    )?;
    let albedo = make(
        "clipmap albedo atlas",
        vk::Format::R8G8B8A8_SRGB,
        shading_mips,
    )?;
    gpu.one_shot(|cmd| {
        for image in [&atlas, &normals, &albedo] {
            Barriers::new(gpu).image(
                cmd,
                image.raw,
                vk::ImageSubresourceRange {
                    layer_count: shape.layers,
                    level_count: image.mips,
                    ..layer_range(0)
                },
                ImageAccess::Undefined,
                ImageAccess::SampledAnyShader,
            )
        }
    })?;
    Ok([atlas, normals, albedo])
}

/// `count` quadtree buffers (one per view slot) of `cells` cells each, zeroed.
fn quadtree_buffers(gpu: &Arc<Gpu>, count: usize, cells: u64) -> Result<Vec<Buffer>> {
    let mut quadtrees = Vec::with_capacity(count);
    for s in 0..count {
        let mut q = Buffer::new(
            gpu,
            &format!("clipmap quadtree {s}"),
            HEADER_BYTES + cells * 4,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::CpuToGpu,
        )?;
        if let Some(m) = q.mapped_mut() {
            m.fill(0);
        }
        quadtrees.push(q);
    }
    Ok(quadtrees)
}

/// A staging buffer of `bytes` per frame slot; `bytes` None (the disabled placeholder): none.
fn staging_buffers(
    gpu: &Arc<Gpu>,
    slots: usize,
    bytes: Option<u64>,
) -> Result<Vec<Option<Buffer>>> {
    let mut staging = Vec::with_capacity(slots);
    for s in 0..slots {
        staging.push(match bytes {
            Some(bytes) => Some(Buffer::new(
                gpu,
                &format!("clipmap staging {s}"),
                bytes,
                vk::BufferUsageFlags::TRANSFER_SRC,
                MemoryLocation::CpuToGpu,
            )?),
            None => None,
        });
    }
    Ok(staging)
}

impl ClipmapGpu {
    /// The device mirror; `geometry` None: a disabled placeholder (tiny atlas, header with
    /// `enabled = 0`) so the bindings exist for the single-texture path. One atlas, a quadtree
    /// per view slot of `layout`, a staging buffer per frame slot.
    pub fn new(
        gpu: &Arc<Gpu>,
        geometry: Option<&Geometry>,
        settings: &ClipmapSettings,
        node_count: u32,
        layout: SlotLayout,
    ) -> Result<Self> {
        let (slots, views) = (layout.frames_in_flight, layout.views);
        let mips: Vec<u32> = match geometry {
            Some(g) => (0..g.shading_mips()).map(|m| g.mip_side(m)).collect(),
            None => vec![1],
        };
        let shape = AtlasShape::new(gpu, geometry, settings, node_count)?;
        let [atlas, normals, albedo] = atlas_images(gpu, &shape, mips.len() as u32)?;
        let quadtrees = quadtree_buffers(gpu, slots * views, shape.cells)?;
        let staging_bytes =
            geometry.map(|g| settings.max_uploads_per_frame as u64 * layer_bytes(g));
        let staging = staging_buffers(gpu, slots, staging_bytes)?;
        Ok(ClipmapGpu {
            gpu: gpu.clone(),
            atlas,
            normals,
            albedo,
            enabled: geometry.is_some(),
            quadtrees,
            staging,
            staged: vec![Vec::new(); slots],
            side: shape.side,
            mips,
            scratch: Vec::new(),
        })
    }

    /// Host side of a frame: the quadtree of `view` into the buffer of view slot `view_slot`
    /// (whose previous GPU work is complete).
    pub fn write_quadtree(
        &mut self,
        view_slot: ViewSlot,
        geometry: &Geometry,
        view: &ViewQuadtree,
    ) -> Result<()> {
        view.gpu_bytes(geometry, &mut self.scratch);
        self.quadtrees[view_slot.index()].write(&self.scratch)
    }

    /// Host side of a frame in frame slot `slot` (whose previous GPU work is complete): the
    /// `uploads` layers into the slot's staging buffer, recorded by [`Self::record_uploads`].
    pub fn stage_uploads(
        &mut self,
        slot: FrameSlot,
        geometry: &Geometry,
        atlas: &Atlas,
        uploads: &[Upload],
    ) -> Result<()> {
        let texels = (self.side as usize).pow(2);
        let per_layer = layer_bytes(geometry) as usize;
        let staging = self.staging[slot.index()]
            .as_mut()
            .and_then(|b| b.mapped_mut())
            .ok_or_else(|| Error::invalid("clipmap", "staging buffer not mapped"))?;
        if uploads.len() * per_layer > staging.len() {
            return Err(Error::invalid("clipmap", "more uploads than staging space"));
        }
        for (k, up) in uploads.iter().enumerate() {
            let dst = &mut staging[k * per_layer..(k + 1) * per_layer];
            if up.shading.len() != per_layer - texels * 4 {
                return Err(Error::invalid(
                    "clipmap",
                    "shading planes of the wrong size",
                ));
            }
            for j in 0..self.side {
                for i in 0..self.side {
                    let t = (j * self.side + i) as usize * 4;
                    dst[t..t + 4].copy_from_slice(&atlas.texel(up.layer, i, j).to_le_bytes());
                }
            }
            dst[texels * 4..].copy_from_slice(&up.shading);
        }
        self.staged[slot.index()] = uploads.iter().map(|u| u.layer).collect();
        Ok(())
    }

    /// Records the slot's staged uploads (before anything of the frame samples the atlas).
    pub fn record_uploads(&mut self, cmd: vk::CommandBuffer, slot: FrameSlot) {
        let layers = std::mem::take(&mut self.staged[slot.index()]);
        let Some(staging) = self.staging[slot.index()].as_ref() else {
            return;
        };
        let b = Barriers::new(&self.gpu);
        let texels = (self.side as u64).pow(2);
        let shading: u64 = self.mips.iter().map(|&m| (m as u64).pow(2)).sum();
        let per_layer = texels * 4 + shading * 8;
        for (k, &layer) in layers.iter().enumerate() {
            let base = k as u64 * per_layer;
            for (image, offset) in [
                (&self.atlas, 0),
                (&self.normals, texels * 4),
                (&self.albedo, texels * 4 + shading * 4),
            ] {
                let range = vk::ImageSubresourceRange {
                    level_count: image.mips,
                    ..layer_range(layer as u32)
                };
                b.image(
                    cmd,
                    image.raw,
                    range,
                    ImageAccess::SampledAnyShader,
                    ImageAccess::TransferDst,
                );
                let mut at = base + offset;
                let regions: Vec<vk::BufferImageCopy> = self.mips[..image.mips as usize]
                    .iter()
                    .enumerate()
                    .map(|(m, &side)| {
                        let r = vk::BufferImageCopy::default()
                            .buffer_offset(at)
                            .image_subresource(vk::ImageSubresourceLayers {
                                aspect_mask: vk::ImageAspectFlags::COLOR,
                                mip_level: m as u32,
                                base_array_layer: layer as u32,
                                layer_count: 1,
                            })
                            .image_extent(vk::Extent3D {
                                width: side,
                                height: side,
                                depth: 1,
                            });
                        at += (side as u64).pow(2) * 4;
                        r
                    })
                    .collect();
                unsafe {
                    self.gpu.device.cmd_copy_buffer_to_image(
                        cmd,
                        staging.raw,
                        image.raw,
                        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                        &regions,
                    )
                };
                b.image(
                    cmd,
                    image.raw,
                    range,
                    ImageAccess::TransferDst,
                    ImageAccess::SampledAnyShader,
                );
            }
        }
    }
}
