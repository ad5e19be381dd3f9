//! Test support (feature `test-support`): PGM's reference-sphere distance evaluated on the GPU
//! (`sphere_distance` in `shaders/include/pgm_sphere.wgsl`, the function the vertex stage
//! calls) for given spheres and rays (`shaders/pgm_probe.wgsl`). Tests compare the results
//! with [`super::earth::Sphere::distance`].

use std::sync::Arc;

use super::earth::Sphere;
use crate::driver::Gpu;
use crate::error::Result;
use crate::gpu_constants::PGM_PROBE_WORKGROUP;

/// One probed ray as the probe shader reads and writes it (`SphereProbe` in
/// `shaders/pgm_probe.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SphereProbe {
    /// In: radius, height, largest distance, the ray's depression sine.
    pub sphere: [f32; 4],
    /// In: [`Sphere::gpu_terms`]; out: w the distance (m).
    pub horizon: [f32; 4],
}

/// One ray to probe: the sphere, the largest distance (m) and the ray's depression sine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphereRay {
    pub sphere: Sphere,
    pub max_distance: f64,
    pub sin_depression: f64,
}

impl SphereRay {
    /// The probe's input: the values rounded to f32 as `PgmUniforms` carries them.
    fn input(&self) -> SphereProbe {
        let [sin_h, d_h, e_h] = self.sphere.gpu_terms();
        SphereProbe {
            sphere: [
                self.sphere.radius as f32,
                self.sphere.height as f32,
                self.max_distance as f32,
                self.sin_depression as f32,
            ],
            horizon: [sin_h, d_h, e_h, 0.0],
        }
    }
}

/// The GPU's distance (m) for each ray. Waits.
pub fn sphere_distances(gpu: &Arc<Gpu>, rays: &[SphereRay]) -> Result<Vec<f32>> {
    if rays.is_empty() {
        return Ok(Vec::new());
    }
    let header = [rays.len() as u32, 0, 0, 0];
    let items: Vec<SphereProbe> = rays.iter().map(SphereRay::input).collect();
    let io = [bytemuck::bytes_of(&header), bytemuck::cast_slice(&items)].concat();
    let out = crate::driver::probe::run(
        gpu,
        crate::driver::shaders::PGM_PROBE_SPV,
        c"probe_sphere",
        &[],
        &io,
        (rays.len() as u32).div_ceil(PGM_PROBE_WORKGROUP),
    )?;
    let items: Vec<SphereProbe> = bytemuck::pod_collect_to_vec(&out[size_of_val(&header)..]);
    Ok(items.iter().map(|p| p.horizon[3]).collect())
}
