//! Descriptor sets: one layout, a pool sized for exactly `count` sets of it, and the sets,
//! owned together so every user (set 0 of the terrain, each method's set 1, the clipmap probe)
//! gets the same creation and the same cleanup on every error path.

use std::sync::Arc;

use ash::vk;

use super::Gpu;
use crate::error::{Result, VkResultExt};

pub struct DescriptorSets {
    gpu: Arc<Gpu>,
    pub layout: vk::DescriptorSetLayout,
    pool: vk::DescriptorPool,
    /// `count` sets of `layout`, not yet written.
    pub sets: Vec<vk::DescriptorSet>,
}

impl DescriptorSets {
    /// `bindings[i]` is binding `i` (one descriptor of that type, visible to `stages`).
    pub fn new(
        gpu: &Arc<Gpu>,
        bindings: &[vk::DescriptorType],
        stages: vk::ShaderStageFlags,
        count: usize,
    ) -> Result<Self> {
        let d = &gpu.device;
        let layout_bindings: Vec<_> = bindings
            .iter()
            .enumerate()
            .map(|(b, &ty)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b as u32)
                    .descriptor_type(ty)
                    .descriptor_count(1)
                    .stage_flags(stages)
            })
            .collect();
        let layout = unsafe {
            d.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings),
                None,
            )
        }
        .vk("vkCreateDescriptorSetLayout")?;
        // From here on `Drop` releases whatever exists.
        let mut out = DescriptorSets {
            gpu: gpu.clone(),
            layout,
            pool: vk::DescriptorPool::null(),
            sets: Vec::new(),
        };
        let mut sizes: Vec<vk::DescriptorPoolSize> = Vec::new();
        for &ty in bindings {
            match sizes.iter_mut().find(|s| s.ty == ty) {
                Some(s) => s.descriptor_count += count as u32,
                None => sizes.push(vk::DescriptorPoolSize {
                    ty,
                    descriptor_count: count as u32,
                }),
            }
        }
        out.pool = unsafe {
            d.create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default()
                    .max_sets(count as u32)
                    .pool_sizes(&sizes),
                None,
            )
        }
        .vk("vkCreateDescriptorPool")?;
        let layouts = vec![layout; count];
        out.sets = unsafe {
            d.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default()
                    .descriptor_pool(out.pool)
                    .set_layouts(&layouts),
            )
        }
        .vk("vkAllocateDescriptorSets")?;
        Ok(out)
    }
}

impl Drop for DescriptorSets {
    fn drop(&mut self) {
        unsafe {
            let d = &self.gpu.device;
            // Destroying the pool frees its sets.
            if self.pool != vk::DescriptorPool::null() {
                d.destroy_descriptor_pool(self.pool, None);
            }
            d.destroy_descriptor_set_layout(self.layout, None);
        }
    }
}
