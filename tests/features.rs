//! Optional device features: `VKTERRAIN_MASK_FEATURES` / `GpuOptions::mask_features` hide a
//! feature the device offers, so the "missing feature" errors of the methods that need one
//! can be tested on any machine; unknown names are one-line errors.

mod common;

use vkterrain::driver::{Feature, Gpu, GpuOptions};

fn gpu_with_mask(mask: &[&str]) -> vkterrain::Result<std::sync::Arc<Gpu>> {
    Gpu::new(&GpuOptions {
        validation: true,
        mask_features: mask.iter().map(|s| s.to_string()).collect(),
        ..GpuOptions::default()
    })
}

#[test]
fn a_masked_feature_is_disabled_and_named_in_one_line() {
    let plain = common::gpu(false);
    if !plain.info.caps.tessellation_shader {
        panic!("this test needs a device offering tessellationShader (lavapipe does)");
    }
    // Offered and not masked: enabled.
    assert!(plain.enabled.tessellation_shader);
    plain.require(Feature::TessellationShader, "test").unwrap();
    drop(plain);
    let gpu = gpu_with_mask(&["tessellationShader"]).unwrap();
    assert!(!gpu.enabled.tessellation_shader);
    assert_eq!(gpu.masked, vec![Feature::TessellationShader]);
    let e = gpu
        .require(Feature::TessellationShader, "method tess")
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "method tess needs the Vulkan feature tessellationShader, which is masked by VKTERRAIN_MASK_FEATURES"
    );
    common::assert_no_validation_messages(&gpu);
}

#[test]
fn unknown_feature_names_are_rejected() {
    let e = gpu_with_mask(&["warpDrive"])
        .err()
        .expect("an error")
        .to_string();
    assert!(e.contains("unknown feature \"warpDrive\""), "{e}");
    assert!(
        e.contains("tessellationShader, geometryShader, meshShader"),
        "{e}"
    );
    assert!(!e.contains('\n'));
    // Case-insensitive Vulkan names.
    assert_eq!(
        Feature::parse("TESSELLATIONSHADER").unwrap(),
        Feature::TessellationShader
    );
}
