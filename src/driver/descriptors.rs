//! Descriptor sets: one layout, a pool sized for exactly `count` sets of it, and the sets,
//! owned together so every user (set 0 of the terrain, each method's set 1, the test probes)
//! gets the same creation and the same cleanup on every error path.
//!
//! Each set is declared once, as a [`Binding`] table next to its owner (`frame::terrain`,
//! `lod::udlod`, `lod::pgm`, [`PROBE_SET`]): binding number, descriptor type, stages and the
//! WGSL variable bound there. The layout, the pool and the descriptor writes are built from
//! the table, and `tests/shader_interface.rs` checks every table against the shaders (naga's
//! reflection of each composed shader's `@group/@binding` globals).

use std::sync::Arc;

use ash::vk;

use super::Gpu;
use crate::error::{Error, Result, VkResultExt};

/// One binding of a descriptor set, as the shaders declare it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Binding {
    /// `@binding(n)` in the WGSL.
    pub binding: u32,
    /// One descriptor of this type.
    pub ty: vk::DescriptorType,
    /// The stages that may read it.
    pub stages: vk::ShaderStageFlags,
    /// The WGSL variable bound there (the key [`DescriptorSets::write`] takes).
    pub name: &'static str,
}

impl Binding {
    pub const fn new(
        binding: u32,
        ty: vk::DescriptorType,
        stages: vk::ShaderStageFlags,
        name: &'static str,
    ) -> Self {
        Binding {
            binding,
            ty,
            stages,
            name,
        }
    }
}

/// `a | b` for stage masks in constant tables.
pub const fn stages(a: vk::ShaderStageFlags, b: vk::ShaderStageFlags) -> vk::ShaderStageFlags {
    vk::ShaderStageFlags::from_raw(a.as_raw() | b.as_raw())
}

/// The set of a test probe's input/output buffer (`probe` in `shaders/*_probe.wgsl`; the
/// last set of the probe's pipeline).
pub const PROBE_SET: &[Binding] = &[Binding::new(
    0,
    vk::DescriptorType::STORAGE_BUFFER,
    vk::ShaderStageFlags::COMPUTE,
    "probe",
)];

/// What a descriptor points at (whole buffers; images in `SHADER_READ_ONLY_OPTIMAL`).
#[derive(Clone, Copy, Debug)]
pub enum Resource {
    Buffer(vk::Buffer),
    Image(vk::ImageView),
    Sampler(vk::Sampler),
}

impl Resource {
    /// Can a descriptor of type `ty` point at this resource?
    fn fits(&self, ty: vk::DescriptorType) -> bool {
        use vk::DescriptorType as T;
        match self {
            Resource::Buffer(_) => ty == T::UNIFORM_BUFFER || ty == T::STORAGE_BUFFER,
            Resource::Image(_) => ty == T::SAMPLED_IMAGE || ty == T::STORAGE_IMAGE,
            Resource::Sampler(_) => ty == T::SAMPLER,
        }
    }
}

pub struct DescriptorSets {
    gpu: Arc<Gpu>,
    table: &'static [Binding],
    pub layout: vk::DescriptorSetLayout,
    pool: vk::DescriptorPool,
    /// `count` sets of `layout`, written by [`DescriptorSets::write`].
    pub sets: Vec<vk::DescriptorSet>,
}

impl DescriptorSets {
    /// `count` sets laid out as `table` (one descriptor per entry).
    pub fn new(gpu: &Arc<Gpu>, table: &'static [Binding], count: usize) -> Result<Self> {
        let d = &gpu.device;
        let layout_bindings: Vec<_> = table
            .iter()
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b.binding)
                    .descriptor_type(b.ty)
                    .descriptor_count(1)
                    .stage_flags(b.stages)
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
            table,
            layout,
            pool: vk::DescriptorPool::null(),
            sets: Vec::new(),
        };
        let mut sizes: Vec<vk::DescriptorPoolSize> = Vec::new();
        for b in table {
            match sizes.iter_mut().find(|s| s.ty == b.ty) {
                Some(s) => s.descriptor_count += count as u32,
                None => sizes.push(vk::DescriptorPoolSize {
                    ty: b.ty,
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

    /// Points every binding of set `index` at its resource: `resources` names each entry of
    /// the table by its WGSL variable, once, with a resource its type can hold. A missing,
    /// unknown, repeated or mistyped name is an error and nothing is written.
    pub fn write(&self, index: usize, resources: &[(&str, Resource)]) -> Result<()> {
        let set = *self
            .sets
            .get(index)
            .ok_or_else(|| Error::invalid("descriptor set", format!("no set {index}")))?;
        let planned = plan_writes(self.table, resources)?;
        let buffers: Vec<[vk::DescriptorBufferInfo; 1]> = planned
            .iter()
            .map(|(_, r)| match *r {
                Resource::Buffer(buffer) => [vk::DescriptorBufferInfo {
                    buffer,
                    offset: 0,
                    range: vk::WHOLE_SIZE,
                }],
                _ => [vk::DescriptorBufferInfo::default()],
            })
            .collect();
        let images: Vec<[vk::DescriptorImageInfo; 1]> = planned
            .iter()
            .map(|(_, r)| match *r {
                Resource::Image(image_view) => [vk::DescriptorImageInfo {
                    sampler: vk::Sampler::null(),
                    image_view,
                    image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                }],
                Resource::Sampler(sampler) => [vk::DescriptorImageInfo {
                    sampler,
                    ..Default::default()
                }],
                Resource::Buffer(_) => [vk::DescriptorImageInfo::default()],
            })
            .collect();
        let writes: Vec<vk::WriteDescriptorSet> = planned
            .iter()
            .enumerate()
            .map(|(i, (b, r))| {
                let w = vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(b.binding)
                    .descriptor_type(b.ty);
                match r {
                    Resource::Buffer(_) => w.buffer_info(&buffers[i]),
                    Resource::Image(_) | Resource::Sampler(_) => w.image_info(&images[i]),
                }
            })
            .collect();
        unsafe { self.gpu.device.update_descriptor_sets(&writes, &[]) };
        Ok(())
    }
}

/// Pairs each table entry with the resource named after its WGSL variable; errors name the
/// first mismatch (an entry without a resource, a name the table lacks, a name given twice, a
/// resource of the wrong kind).
pub fn plan_writes(
    table: &'static [Binding],
    resources: &[(&str, Resource)],
) -> Result<Vec<(Binding, Resource)>> {
    let err = |m: String| Error::invalid("descriptor writes", m);
    for (k, (name, _)) in resources.iter().enumerate() {
        if !table.iter().any(|b| b.name == *name) {
            return Err(err(format!("{name:?} is not a binding of this set")));
        }
        if resources[..k].iter().any(|(n, _)| n == name) {
            return Err(err(format!("{name:?} is given twice")));
        }
    }
    table
        .iter()
        .map(|b| {
            let (_, r) = resources
                .iter()
                .find(|(n, _)| *n == b.name)
                .ok_or_else(|| {
                    err(format!(
                        "no resource for binding {} {:?}",
                        b.binding, b.name
                    ))
                })?;
            if !r.fits(b.ty) {
                return Err(err(format!(
                    "binding {} {:?} is a {:?}, given {r:?}",
                    b.binding, b.name, b.ty
                )));
            }
            Ok((*b, *r))
        })
        .collect()
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

#[cfg(test)]
mod tests {
    use super::*;

    const TABLE: &[Binding] = &[
        Binding::new(
            0,
            vk::DescriptorType::UNIFORM_BUFFER,
            vk::ShaderStageFlags::VERTEX,
            "u",
        ),
        Binding::new(
            2,
            vk::DescriptorType::SAMPLER,
            vk::ShaderStageFlags::FRAGMENT,
            "s",
        ),
    ];

    #[test]
    fn writes_follow_the_table_and_reject_mismatches() {
        let buffer = Resource::Buffer(vk::Buffer::null());
        let sampler = Resource::Sampler(vk::Sampler::null());
        // Given in any order, written in table order.
        let plan = plan_writes(TABLE, &[("s", sampler), ("u", buffer)]).unwrap();
        assert_eq!(
            plan.iter().map(|(b, _)| b.binding).collect::<Vec<_>>(),
            [0, 2]
        );
        let fails = |r: &[(&str, Resource)], words: &str| {
            let e = plan_writes(TABLE, r).unwrap_err().to_string();
            assert!(e.contains(words), "{e}");
        };
        fails(&[("u", buffer)], "no resource for binding 2");
        fails(
            &[("u", buffer), ("s", sampler), ("t", buffer)],
            "\"t\" is not",
        );
        fails(&[("u", buffer), ("u", buffer), ("s", sampler)], "twice");
        fails(&[("u", sampler), ("s", sampler)], "binding 0 \"u\"");
    }
}
