//! The terrain pass and its targets: the colour and depth images of one frame slot, and one
//! `begin_pass`/`end_pass` pair that hides the two ways Vulkan renders into them: dynamic
//! rendering (Vulkan 1.3) and, where that is missing or `device.force_legacy` is set, a classic
//! render pass with a framebuffer per slot.
//!
//! Both paths share one barrier sequence: the images stay in attachment layouts inside the pass
//! and explicit barriers outside it do every transition (see `create_render_pass`).

use std::sync::Arc;

use ash::vk;

use crate::driver::Gpu;
use crate::driver::barrier::{Barriers, ImageAccess, color_range, depth_range};
use crate::driver::memory::{Image, ImageDesc};
use crate::driver::pipeline::{COLOR_FORMAT, DEPTH_FORMAT, TargetFormats, create_render_pass};
use crate::error::{Result, VkResultExt};

/// How the terrain pass is begun: the target formats every pipeline is built for, and the
/// classic render pass on the legacy path (owned here, destroyed with it).
pub struct TerrainPass {
    gpu: Arc<Gpu>,
    pub formats: TargetFormats,
}

impl TerrainPass {
    pub fn new(gpu: &Arc<Gpu>) -> Result<Self> {
        let render_pass = if gpu.modern {
            vk::RenderPass::null()
        } else {
            create_render_pass(gpu)?
        };
        Ok(TerrainPass {
            gpu: gpu.clone(),
            formats: TargetFormats {
                color: COLOR_FORMAT,
                depth: DEPTH_FORMAT,
                render_pass,
            },
        })
    }

    fn legacy(&self) -> bool {
        self.formats.render_pass != vk::RenderPass::null()
    }
}

impl Drop for TerrainPass {
    fn drop(&mut self) {
        if self.legacy() {
            // Pipelines reference the render pass only at creation: destroying it while they
            // live is allowed by the spec.
            unsafe {
                self.gpu
                    .device
                    .destroy_render_pass(self.formats.render_pass, None)
            };
        }
    }
}

/// The colour and depth targets of one frame slot.
pub struct Targets {
    gpu: Arc<Gpu>,
    pub color: Image,
    pub depth: Image,
    pub extent: vk::Extent2D,
    /// Legacy path only (null with dynamic rendering).
    framebuffer: vk::Framebuffer,
}

impl Targets {
    /// Targets of `extent` for `pass`; `label` names them in validation messages.
    pub fn new(
        gpu: &Arc<Gpu>,
        pass: &TerrainPass,
        extent: vk::Extent2D,
        label: &str,
    ) -> Result<Self> {
        let color = Image::new(
            gpu,
            &ImageDesc {
                name: &format!("color {label}"),
                format: pass.formats.color,
                extent,
                layers: 1,
                mips: 1,
                usage: vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
                aspect: vk::ImageAspectFlags::COLOR,
            },
        )?;
        let depth = Image::new(
            gpu,
            &ImageDesc {
                name: &format!("depth {label}"),
                format: pass.formats.depth,
                extent,
                layers: 1,
                mips: 1,
                usage: vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT
                    | vk::ImageUsageFlags::TRANSFER_SRC,
                aspect: vk::ImageAspectFlags::DEPTH,
            },
        )?;
        let framebuffer = if pass.legacy() {
            let views = [color.view, depth.view];
            unsafe {
                gpu.device.create_framebuffer(
                    &vk::FramebufferCreateInfo::default()
                        .render_pass(pass.formats.render_pass)
                        .attachments(&views)
                        .width(extent.width)
                        .height(extent.height)
                        .layers(1),
                    None,
                )
            }
            .vk("vkCreateFramebuffer")?
        } else {
            vk::Framebuffer::null()
        };
        Ok(Targets {
            gpu: gpu.clone(),
            color,
            depth,
            extent,
            framebuffer,
        })
    }

    /// Begins the terrain pass, clearing colour to `sky` and depth to the far plane (0,
    /// reversed-Z). The targets' previous contents (N frames ago, last read by the readback
    /// copy) are discarded, but the transition still waits for that copy.
    pub fn begin_pass(&self, cmd: vk::CommandBuffer, pass: &TerrainPass, sky: [f32; 3]) {
        let b = Barriers::new(&self.gpu);
        b.image(
            cmd,
            self.color.raw,
            color_range(),
            ImageAccess::TransferSrcDiscard,
            ImageAccess::ColorAttachment,
        );
        b.image(
            cmd,
            self.depth.raw,
            depth_range(),
            ImageAccess::TransferSrcDiscard,
            ImageAccess::DepthAttachment,
        );
        let sky = vk::ClearValue {
            color: vk::ClearColorValue {
                float32: [sky[0], sky[1], sky[2], 1.0],
            },
        };
        let far = vk::ClearValue {
            depth_stencil: vk::ClearDepthStencilValue {
                depth: 0.0,
                stencil: 0,
            },
        };
        let area = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent: self.extent,
        };
        let d = &self.gpu.device;
        if pass.legacy() {
            let clear = [sky, far];
            unsafe {
                d.cmd_begin_render_pass(
                    cmd,
                    &vk::RenderPassBeginInfo::default()
                        .render_pass(pass.formats.render_pass)
                        .framebuffer(self.framebuffer)
                        .render_area(area)
                        .clear_values(&clear),
                    vk::SubpassContents::INLINE,
                )
            };
            return;
        }
        let attachment = |view, layout, clear| {
            vk::RenderingAttachmentInfo::default()
                .image_view(view)
                .image_layout(layout)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .clear_value(clear)
        };
        let color = [attachment(
            self.color.view,
            vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
            sky,
        )];
        let depth = attachment(
            self.depth.view,
            vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL,
            far,
        );
        unsafe {
            d.cmd_begin_rendering(
                cmd,
                &vk::RenderingInfo::default()
                    .render_area(area)
                    .layer_count(1)
                    .color_attachments(&color)
                    .depth_attachment(&depth),
            )
        };
    }

    /// Viewport and scissor of the columns `(first, count)` over the full height.
    pub fn set_columns(&self, cmd: vk::CommandBuffer, (x, width): (u32, u32)) {
        let d = &self.gpu.device;
        let height = self.extent.height;
        unsafe {
            d.cmd_set_viewport(
                cmd,
                0,
                &[vk::Viewport {
                    x: x as f32,
                    y: 0.0,
                    width: width as f32,
                    height: height as f32,
                    min_depth: 0.0,
                    max_depth: 1.0,
                }],
            );
            d.cmd_set_scissor(
                cmd,
                0,
                &[vk::Rect2D {
                    offset: vk::Offset2D { x: x as i32, y: 0 },
                    extent: vk::Extent2D { width, height },
                }],
            );
        }
    }

    /// Ends the terrain pass and makes both targets transfer sources (whether or not depth is
    /// read back, so every frame starts from the same state).
    pub fn end_pass(&self, cmd: vk::CommandBuffer, pass: &TerrainPass) {
        let d = &self.gpu.device;
        unsafe {
            if pass.legacy() {
                d.cmd_end_render_pass(cmd);
            } else {
                d.cmd_end_rendering(cmd);
            }
        }
        let b = Barriers::new(&self.gpu);
        b.image(
            cmd,
            self.color.raw,
            color_range(),
            ImageAccess::ColorAttachment,
            ImageAccess::TransferSrc,
        );
        b.image(
            cmd,
            self.depth.raw,
            depth_range(),
            ImageAccess::DepthAttachment,
            ImageAccess::TransferSrc,
        );
    }
}

impl Drop for Targets {
    fn drop(&mut self) {
        if self.framebuffer != vk::Framebuffer::null() {
            unsafe { self.gpu.device.destroy_framebuffer(self.framebuffer, None) };
        }
    }
}
