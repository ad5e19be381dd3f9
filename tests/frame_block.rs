//! The frame's block (set 0 binding 0) is a uniform buffer on most devices and a read-only
//! storage buffer on Mesa's lavapipe before 24 (`driver::shaders::FrameBlock`,
//! docs/architecture.md, "Uniform buffers on Mesa 22.3"). Both variants of every shader must
//! draw the same frames: every method renders the same poses with each, validation on (a
//! variant whose declaration did not match set 0's table would be a validation error).

mod common;

use std::sync::Arc;

use common::poses::poses;
use vkterrain::dataset::Heightmap;
use vkterrain::dataset::procedural::{self, ProceduralParams};
use vkterrain::driver::shaders::{FRAME_BLOCK_ENV, FrameBlock};
use vkterrain::driver::{Gpu, GpuOptions};
use vkterrain::lod::chunked::{ChunkDraw, ChunkedSettings};
use vkterrain::lod::{MethodConfig, MethodKind};
use vkterrain::readback::OwnedFrame;
use vkterrain::render::FrameRequest;

fn gpu_with(block: FrameBlock) -> Arc<Gpu> {
    let gpu = Gpu::new(&GpuOptions {
        validation: true,
        frame_block: Some(block),
        ..GpuOptions::default()
    })
    .expect("a Vulkan device with validation layers (make deps)");
    assert_eq!(gpu.frame_block, block);
    gpu
}

fn frames(gpu: &Arc<Gpu>, data: &Heightmap, method: MethodConfig) -> Vec<OwnedFrame> {
    let requests: Vec<FrameRequest> = poses(data, 5)
        .into_iter()
        .map(|camera| FrameRequest {
            camera,
            sky: None,
            lod_viewer: None,
        })
        .collect();
    common::render_method(gpu, data, method, common::options(96, 64, 2), &requests)
}

#[test]
fn every_method_draws_the_same_frames_with_either_frame_block() {
    let data = procedural::generate(&ProceduralParams {
        size: 129,
        spacing: 30.0,
        ..Default::default()
    })
    .unwrap();
    let uniform = gpu_with(FrameBlock::Uniform);
    let storage = gpu_with(FrameBlock::Storage);
    let mut methods: Vec<(String, MethodConfig)> = MethodKind::ALL
        .iter()
        .map(|&kind| (format!("{kind:?}"), kind.into()))
        .collect();
    if uniform.enabled.mesh_shader {
        let mesh = ChunkedSettings {
            draw: ChunkDraw::Mesh,
            ..Default::default()
        };
        methods.push(("Chunked (mesh shaders)".into(), mesh.into()));
    }
    for (name, method) in methods {
        let a = frames(&uniform, &data, method.clone());
        let b = frames(&storage, &data, method);
        assert_eq!(a.len(), b.len(), "{name}");
        // The frames say something: the poses see terrain, and not all alike.
        assert!(a.iter().any(|f| f.triangles > 0), "{name}: nothing drawn");
        assert!(
            a.windows(2).any(|w| w[0].rgba != w[1].rgba),
            "{name}: every pose drew the same picture"
        );
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!(
                x.rgba == y.rgba && x.depth == y.depth && x.triangles == y.triangles,
                "{name}: frame {i} differs between the uniform and the storage frame block"
            );
        }
    }
}

#[test]
fn the_frame_block_comes_from_the_driver_or_the_environment() {
    // A storage block only where uniform inlining rebuilds shaders: lavapipe before Mesa 24.
    use ash::vk::DriverId;
    let lavapipe = |info| FrameBlock::for_driver(DriverId::MESA_LLVMPIPE, info);
    assert_eq!(lavapipe("Mesa 22.3.6 (LLVM 15.0.6)"), FrameBlock::Storage);
    assert_eq!(lavapipe("Mesa 23.3.0"), FrameBlock::Storage);
    assert_eq!(lavapipe("Mesa 24.0.5-1ubuntu1"), FrameBlock::Uniform);
    assert_eq!(
        lavapipe("Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)"),
        FrameBlock::Uniform
    );
    assert_eq!(lavapipe("a build without a release"), FrameBlock::Uniform);
    let other = |id| FrameBlock::for_driver(id, "Mesa 22.3.6");
    assert_eq!(other(DriverId::MESA_RADV), FrameBlock::Uniform);
    assert_eq!(other(DriverId::NVIDIA_PROPRIETARY), FrameBlock::Uniform);
    assert_eq!(FrameBlock::parse(" Storage ").unwrap(), FrameBlock::Storage);
    let e = FrameBlock::parse("push").unwrap_err().to_string();
    assert!(
        e.contains(FRAME_BLOCK_ENV) && e.contains("\"push\"") && !e.contains('\n'),
        "{e}"
    );
    // The device here gets the rule's answer unless the environment names one.
    let gpu = common::gpu(false);
    let expected = match std::env::var(FRAME_BLOCK_ENV) {
        Ok(v) if !v.trim().is_empty() => FrameBlock::parse(&v).unwrap(),
        _ => FrameBlock::for_device(&gpu.info),
    };
    assert_eq!(gpu.frame_block, expected);
    common::assert_no_validation_messages(&gpu);
}
