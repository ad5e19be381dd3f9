// Temporary diagnostic: where are UDLOD's "holes" (sky inside the reference silhouette)?
use std::path::PathBuf;
use vkterrain::cli::render::{RenderArgs, prepare};
use vkterrain::lod::{MethodConfig, UdlodSettings};
use vkterrain::readback::{CollectSink};
use vkterrain::render::Renderer;

fn main() -> anyhow::Result<()> {
    let a: Vec<String> = std::env::args().collect();
    let p = prepare(&RenderArgs { config: Some(PathBuf::from(&a[1])), ..Default::default() })?;
    let tau: f64 = a[2].parse()?;
    let frames: Vec<u64> = a[3].split(',').map(|s| s.parse().unwrap()).collect();
    let gpu = p.config.open_gpu()?;
    let data = p.data.require_grid("x")?;
    let mut opts = p.config.render_options();
    opts.readback_depth = true;
    let (w, h) = (opts.width as usize, opts.height as usize);
    let render = |m: MethodConfig| -> anyhow::Result<Vec<_>> {
        let mut sink = CollectSink::default();
        let mut r = Renderer::new(&gpu, data, m, opts.clone())?;
        for &k in &frames { r.render(p.scenario.camera(k), &mut sink)?; }
        r.finish(&mut sink)?;
        Ok(sink.frames)
    };
    let b = render(MethodConfig::Brute {})?;
    let g: u32 = a[4].parse()?;
    let u = render(UdlodSettings { tau_px: tau, grid_size: g, ..Default::default() }.into())?;
    for (fb, fu) in b.iter().zip(&u) {
        let (bd, ud) = (fb.depth.as_ref().unwrap(), fu.depth.as_ref().unwrap());
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let inside = (y - 1..=y + 1).all(|yy| (x - 1..=x + 1).all(|xx| bd[yy * w + xx] > 0.0));
                if inside && ud[y * w + x] <= 0.0 {
                    let enclosed = (y - 1..=y + 1).all(|yy| (x - 1..=x + 1).all(|xx| (yy, xx) == (y, x) || ud[yy * w + xx] > 0.0));
                    // rows up to the reference's sky
                    let mut up = 0;
                    while y >= up + 1 && bd[(y - up - 1) * w + x] > 0.0 { up += 1; if up > 50 { break; } }
                    let dist = fb.camera.linear_depth(bd[y * w + x]);
                    println!("frame {} px ({x},{y}) enclosed {enclosed} ref-terrain rows above {up} ref dist {dist:.0}", fb.index);
                }
            }
        }
    }
    Ok(())
}
#[allow(dead_code)]
fn unused() {}
