//! Graphics pipelines for the terrain pass, built the same way for every LOD method.

use std::sync::Arc;

use ash::vk;

use crate::driver::Gpu;
use crate::driver::shaders::Spirv;
use crate::error::{Result, VkResultExt};

/// Formats of the frame targets, and the render pass used where dynamic rendering is absent.
#[derive(Clone, Copy, Debug)]
pub struct TargetFormats {
    pub color: vk::Format,
    pub depth: vk::Format,
    /// Classic render pass (legacy path); null with dynamic rendering.
    pub render_pass: vk::RenderPass,
}

pub const COLOR_FORMAT: vk::Format = vk::Format::R8G8B8A8_SRGB;
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// Creates the classic render pass (legacy path): layouts stay in attachment-optimal layouts
/// inside the pass; explicit barriers outside the pass do all transitions, as on the
/// dynamic-rendering path, so both paths share one barrier sequence.
pub fn create_render_pass(gpu: &Gpu) -> Result<vk::RenderPass> {
    let attachments = [
        vk::AttachmentDescription::default()
            .format(COLOR_FORMAT)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
            .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
            .initial_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .final_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL),
        vk::AttachmentDescription::default()
            .format(DEPTH_FORMAT)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
            .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
            .initial_layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL)
            .final_layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL),
    ];
    let color_ref = [vk::AttachmentReference {
        attachment: 0,
        layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
    }];
    let depth_ref = vk::AttachmentReference {
        attachment: 1,
        layout: vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
    };
    let subpasses = [vk::SubpassDescription::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .color_attachments(&color_ref)
        .depth_stencil_attachment(&depth_ref)];
    unsafe {
        gpu.device.create_render_pass(
            &vk::RenderPassCreateInfo::default()
                .attachments(&attachments)
                .subpasses(&subpasses),
            None,
        )
    }
    .vk("vkCreateRenderPass")
}

/// A pipeline and its layout, destroyed together.
pub struct Pipeline {
    gpu: Arc<Gpu>,
    pub raw: vk::Pipeline,
    pub layout: vk::PipelineLayout,
}

impl Pipeline {
    /// Binds this pipeline at `point` with `sets` from set 0 on (its layout's), the pair every
    /// pass records before its draws or dispatches.
    pub fn bind(
        &self,
        cmd: vk::CommandBuffer,
        point: vk::PipelineBindPoint,
        sets: &[vk::DescriptorSet],
    ) {
        let d = &self.gpu.device;
        unsafe {
            d.cmd_bind_pipeline(cmd, point, self.raw);
            d.cmd_bind_descriptor_sets(cmd, point, self.layout, 0, sets, &[]);
        }
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        unsafe {
            self.gpu.device.destroy_pipeline(self.raw, None);
            self.gpu.device.destroy_pipeline_layout(self.layout, None);
        }
    }
}

/// What differs between terrain pipelines.
pub struct TerrainPipelineDesc<'a> {
    pub spv: Spirv,
    pub vertex_entry: &'a std::ffi::CStr,
    pub fragment_entry: &'a std::ffi::CStr,
    pub set_layouts: &'a [vk::DescriptorSetLayout],
    pub topology: vk::PrimitiveTopology,
    /// Cull back faces. Off for meshes whose morphing makes sliver triangles that can face away
    /// from the camera while still being part of the visible surface (UDLOD).
    pub cull_back_faces: bool,
}

impl<'a> TerrainPipelineDesc<'a> {
    /// The common case: entry points `vs_main` and `fs_main` of `spv`, a triangle list, back
    /// faces culled.
    pub fn triangles(spv: Spirv, set_layouts: &'a [vk::DescriptorSetLayout]) -> Self {
        TerrainPipelineDesc {
            spv,
            vertex_entry: c"vs_main",
            fragment_entry: c"fs_main",
            set_layouts,
            topology: vk::PrimitiveTopology::TRIANGLE_LIST,
            cull_back_faces: true,
        }
    }
}

/// The tessellation stages of a terrain pipeline (GLSL: `shaders/glsl/`), between the vertex
/// and fragment stages of [`TerrainPipelineDesc::spv`]; the topology must be a patch list.
pub struct TessellationStages {
    pub control_spv: Spirv,
    pub evaluation_spv: Spirv,
    /// Control points per patch.
    pub control_points: u32,
}

/// Builds a terrain pipeline: no vertex buffers (vertices come from indices), reversed-Z depth
/// (GREATER), back faces culled unless the method says otherwise, viewport and scissor dynamic.
pub fn terrain_pipeline(
    gpu: &Arc<Gpu>,
    formats: &TargetFormats,
    desc: &TerrainPipelineDesc<'_>,
) -> Result<Pipeline> {
    build_terrain_pipeline(gpu, formats, desc, None)
}

/// [`terrain_pipeline`] with tessellation control and evaluation stages (entry points `main`).
/// The device must have `tessellationShader` enabled (check with `Gpu::require` first).
pub fn tessellated_terrain_pipeline(
    gpu: &Arc<Gpu>,
    formats: &TargetFormats,
    desc: &TerrainPipelineDesc<'_>,
    tessellation: &TessellationStages,
) -> Result<Pipeline> {
    build_terrain_pipeline(gpu, formats, desc, Some(tessellation))
}

/// A terrain pipeline drawn by task + mesh shaders (GLSL, entry points `main`) with the
/// fragment stage `desc.fragment_entry` of `desc.spv` (`desc.vertex_entry` and `topology`
/// are unused). The device must have `meshShader` enabled (check with `Gpu::require` first).
pub fn mesh_terrain_pipeline(
    gpu: &Arc<Gpu>,
    formats: &TargetFormats,
    desc: &TerrainPipelineDesc<'_>,
    task_spv: Spirv,
    mesh_spv: Spirv,
) -> Result<Pipeline> {
    let mut modules = Modules {
        gpu,
        raw: Vec::new(),
    };
    let mut stages = Vec::new();
    for (stage, spv, entry) in [
        (vk::ShaderStageFlags::TASK_EXT, task_spv, c"main"),
        (vk::ShaderStageFlags::MESH_EXT, mesh_spv, c"main"),
        (
            vk::ShaderStageFlags::FRAGMENT,
            desc.spv,
            desc.fragment_entry,
        ),
    ] {
        let m = modules.add(spv)?;
        stages.push(
            vk::PipelineShaderStageCreateInfo::default()
                .stage(stage)
                .module(m)
                .name(entry),
        );
    }
    let result = create_graphics(gpu, formats, desc, &stages, Geometry::Mesh);
    drop(modules);
    result
}

/// Shader modules destroyed on drop (pipeline creation copies what it needs).
struct Modules<'a> {
    gpu: &'a Gpu,
    raw: Vec<vk::ShaderModule>,
}

impl Modules<'_> {
    fn add(&mut self, spv: Spirv) -> Result<vk::ShaderModule> {
        let m = crate::driver::shaders::module(self.gpu, spv)?;
        self.raw.push(m);
        Ok(m)
    }
}

impl Drop for Modules<'_> {
    fn drop(&mut self) {
        for m in self.raw.drain(..) {
            unsafe { self.gpu.device.destroy_shader_module(m, None) };
        }
    }
}

fn build_terrain_pipeline(
    gpu: &Arc<Gpu>,
    formats: &TargetFormats,
    desc: &TerrainPipelineDesc<'_>,
    tessellation: Option<&TessellationStages>,
) -> Result<Pipeline> {
    let mut modules = Modules {
        gpu,
        raw: Vec::new(),
    };
    let module = modules.add(desc.spv)?;
    let mut stages = vec![
        vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::VERTEX)
            .module(module)
            .name(desc.vertex_entry),
        vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::FRAGMENT)
            .module(module)
            .name(desc.fragment_entry),
    ];
    if let Some(t) = tessellation {
        for (stage, spv) in [
            (vk::ShaderStageFlags::TESSELLATION_CONTROL, t.control_spv),
            (
                vk::ShaderStageFlags::TESSELLATION_EVALUATION,
                t.evaluation_spv,
            ),
        ] {
            let m = modules.add(spv)?;
            stages.push(
                vk::PipelineShaderStageCreateInfo::default()
                    .stage(stage)
                    .module(m)
                    .name(c"main"),
            );
        }
    }
    let geometry = match tessellation {
        Some(t) => Geometry::Tessellated(t.control_points),
        None => Geometry::Vertex,
    };
    let result = create_graphics(gpu, formats, desc, &stages, geometry);
    drop(modules);
    result
}

/// How primitives reach the rasterizer.
#[derive(Clone, Copy)]
enum Geometry {
    Vertex,
    /// Tessellation stages with this many control points per patch.
    Tessellated(u32),
    /// Task + mesh stages: no vertex input or input assembly state.
    Mesh,
}

/// The fixed-function state every terrain pipeline shares, around `stages`.
fn create_graphics(
    gpu: &Arc<Gpu>,
    formats: &TargetFormats,
    desc: &TerrainPipelineDesc<'_>,
    stages: &[vk::PipelineShaderStageCreateInfo<'_>],
    geometry: Geometry,
) -> Result<Pipeline> {
    let d = &gpu.device;
    let layout = pipeline_layout(gpu, desc.set_layouts)?;
    let vertex_input = vk::PipelineVertexInputStateCreateInfo::default();
    let assembly = vk::PipelineInputAssemblyStateCreateInfo::default().topology(desc.topology);
    let tessellation_state = vk::PipelineTessellationStateCreateInfo::default()
        .patch_control_points(match geometry {
            Geometry::Tessellated(n) => n,
            _ => 0,
        });
    let viewport = vk::PipelineViewportStateCreateInfo::default()
        .viewport_count(1)
        .scissor_count(1);
    let raster = rasterization(desc.cull_back_faces);
    let multisample = vk::PipelineMultisampleStateCreateInfo::default()
        .rasterization_samples(vk::SampleCountFlags::TYPE_1);
    let depth = reversed_depth();
    let blend_attachments = [vk::PipelineColorBlendAttachmentState::default()
        .color_write_mask(vk::ColorComponentFlags::RGBA)];
    let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
    let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
    let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
    let color_formats = [formats.color];
    let mut rendering = vk::PipelineRenderingCreateInfo::default()
        .color_attachment_formats(&color_formats)
        .depth_attachment_format(formats.depth);
    let mut info = vk::GraphicsPipelineCreateInfo::default()
        .stages(stages)
        .viewport_state(&viewport)
        .rasterization_state(&raster)
        .multisample_state(&multisample)
        .depth_stencil_state(&depth)
        .color_blend_state(&blend)
        .dynamic_state(&dynamic)
        .layout(layout);
    match geometry {
        Geometry::Mesh => {}
        Geometry::Vertex => {
            info = info
                .vertex_input_state(&vertex_input)
                .input_assembly_state(&assembly);
        }
        Geometry::Tessellated(_) => {
            info = info
                .vertex_input_state(&vertex_input)
                .input_assembly_state(&assembly)
                .tessellation_state(&tessellation_state);
        }
    }
    if gpu.modern {
        info = info.push_next(&mut rendering);
    } else {
        info = info.render_pass(formats.render_pass).subpass(0);
    }
    let result = unsafe { d.create_graphics_pipelines(vk::PipelineCache::null(), &[info], None) };
    match result {
        Ok(p) => Ok(Pipeline {
            gpu: gpu.clone(),
            raw: p[0],
            layout,
        }),
        Err((_, result)) => {
            unsafe { d.destroy_pipeline_layout(layout, None) };
            Err(crate::error::Error::Vulkan {
                call: "vkCreateGraphicsPipelines",
                result,
            })
        }
    }
}

/// Filled polygons, back faces culled or not, counter-clockwise front faces: WebGPU-style
/// clip space with naga's y flip keeps counter-clockwise front-facing.
fn rasterization(cull_back_faces: bool) -> vk::PipelineRasterizationStateCreateInfo<'static> {
    vk::PipelineRasterizationStateCreateInfo::default()
        .polygon_mode(vk::PolygonMode::FILL)
        .cull_mode(if cull_back_faces {
            vk::CullModeFlags::BACK
        } else {
            vk::CullModeFlags::NONE
        })
        .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
        .line_width(1.0)
}

/// Depth test and write with `GREATER`: reversed Z, the near plane at 1.
fn reversed_depth() -> vk::PipelineDepthStencilStateCreateInfo<'static> {
    vk::PipelineDepthStencilStateCreateInfo::default()
        .depth_test_enable(true)
        .depth_write_enable(true)
        .depth_compare_op(vk::CompareOp::GREATER)
}

/// A pipeline layout of `set_layouts` (no push constants).
fn pipeline_layout(
    gpu: &Gpu,
    set_layouts: &[vk::DescriptorSetLayout],
) -> Result<vk::PipelineLayout> {
    let info = vk::PipelineLayoutCreateInfo::default().set_layouts(set_layouts);
    unsafe { gpu.device.create_pipeline_layout(&info, None) }.vk("vkCreatePipelineLayout")
}

/// Builds a compute pipeline for entry point `entry` of a SPIR-V module.
pub fn compute_pipeline(
    gpu: &Arc<Gpu>,
    spv: Spirv,
    entry: &std::ffi::CStr,
    set_layouts: &[vk::DescriptorSetLayout],
) -> Result<Pipeline> {
    let d = &gpu.device;
    let module = crate::driver::shaders::module(gpu, spv)?;
    let layout = pipeline_layout(gpu, set_layouts);
    let layout = match layout {
        Ok(l) => l,
        Err(e) => {
            unsafe { d.destroy_shader_module(module, None) };
            return Err(e);
        }
    };
    let info = vk::ComputePipelineCreateInfo::default()
        .stage(
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(entry),
        )
        .layout(layout);
    let result = unsafe { d.create_compute_pipelines(vk::PipelineCache::null(), &[info], None) };
    unsafe { d.destroy_shader_module(module, None) };
    match result {
        Ok(p) => Ok(Pipeline {
            gpu: gpu.clone(),
            raw: p[0],
            layout,
        }),
        Err((_, e)) => {
            unsafe { d.destroy_pipeline_layout(layout, None) };
            Err(crate::error::Error::Vulkan {
                call: "vkCreateComputePipelines",
                result: e,
            })
        }
    }
}
