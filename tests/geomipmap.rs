//! GeoMipMapping (Tabakovic's ATLOD), validation on: crack pixels over 200 poses with the
//! border permutations against the same poses without them (the control: T-junction cracks),
//! and fewer triangles than brute force, fewer still as the distance factor shrinks. Popping
//! (no morphing) is measured by `vkterrain eval` (docs/geomipmap.md).

mod common;

use vkterrain::dataset::Heightmap;
use vkterrain::dataset::procedural::{self, ProceduralParams};
use vkterrain::lod::{CullBox, GeomipmapSettings, MethodConfig, MethodKind};
use vkterrain::readback::{CollectSink, OwnedFrame};
use vkterrain::render::{FrameRequest, Renderer};
use vkterrain::scene::Camera;

const W: u32 = 96;
const H: u32 = 64;

fn terrain() -> Heightmap {
    procedural::generate(&ProceduralParams {
        size: 257,
        spacing: 30.0,
        ..Default::default()
    })
    .unwrap()
}

use common::poses::poses;

fn render(data: &Heightmap, method: impl Into<MethodConfig>, cams: &[Camera]) -> Vec<OwnedFrame> {
    let gpu = common::gpu(false);
    let mut sink = CollectSink::default();
    {
        let mut r = Renderer::new(&gpu, data, method, common::options(W, H, 2)).unwrap();
        for c in cams {
            r.render(
                FrameRequest {
                    camera: *c,
                    sky: Some([1.0, 0.0, 1.0]),
                    lod_viewer: None,
                },
                &mut sink,
            )
            .unwrap();
        }
        r.finish(&mut sink).unwrap();
    }
    common::assert_no_validation_messages(&gpu);
    sink.frames
}

/// Crack pixels: the method shows sky where brute force shows terrain, with the method's own
/// terrain on both sides (left and right, or above and below). A coarse level's lower skyline
/// is not counted (the sky there joins the sky above); a crack between blocks is.
fn cracks(reference: &OwnedFrame, method: &OwnedFrame) -> usize {
    let (r, m) = (
        reference.depth.as_ref().unwrap(),
        method.depth.as_ref().unwrap(),
    );
    let (w, h) = (W as usize, H as usize);
    let t = |x: usize, y: usize| m[y * w + x] > 0.0;
    let mut n = 0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let crack = !t(x, y)
                && r[y * w + x] > 0.0
                && ((t(x - 1, y) && t(x + 1, y)) || (t(x, y - 1) && t(x, y + 1)));
            n += crack as usize;
        }
    }
    n
}

/// Crack pixels over 200 poses with and without the border permutations: without them the
/// same poses crack, with them at most a fifth as many remain (a far block's coarse level
/// can leave a one-pixel notch in a ridge line that no border causes).
#[test]
fn watertight_over_200_poses_and_cracks_without_border_permutations() {
    let data = terrain();
    let cams = poses(&data, 200);
    let settings = |stitch| GeomipmapSettings {
        distance_factor: 4.0,
        stitch,
        ..Default::default()
    };
    let brute = render(&data, MethodKind::Brute, &cams);
    let stitched = render(&data, settings(true), &cams);
    let unstitched = render(&data, settings(false), &cams);
    let (mut with, mut without, mut terrain_px) = (0, 0, 0);
    for (i, b) in brute.iter().enumerate() {
        terrain_px += b
            .depth
            .as_ref()
            .unwrap()
            .iter()
            .filter(|d| **d > 0.0)
            .count();
        let h = cracks(b, &stitched[i]);
        let hu = cracks(b, &unstitched[i]);
        if h > 0 {
            println!(
                "pose {i} kind {}: {h} crack px ({hu} unstitched) {:?}",
                i % 5,
                cams[i]
            );
        }
        with += h;
        without += hu;
    }
    println!(
        "geomipmap watertight: {terrain_px} terrain px, {with} crack px; {without} without border permutations"
    );
    // Measured: 1 crack pixel with the permutations (pose 108, present without them too: a
    // coarse level's notch in a far ridge, not a border), 13 without (docs/geomipmap.md).
    assert!(
        with * 5 <= without && without >= 5,
        "{with} crack px with border permutations, {without} without"
    );
    assert!(terrain_px > 200 * (W * H) as usize / 4, "{terrain_px}");
    // Fewer triangles than brute force on the flight poses, and fewer still for a smaller factor.
    let coarse = render(
        &data,
        GeomipmapSettings {
            distance_factor: 0.25,
            ..Default::default()
        },
        &cams[..20],
    );
    let fine: u64 = stitched[..20].iter().map(|f| f.triangles).sum();
    let coarse: u64 = coarse.iter().map(|f| f.triangles).sum();
    let full: u64 = brute[..20].iter().map(|f| f.triangles).sum();
    assert!(coarse < fine && fine < full, "{coarse} {fine} {full}");
}

fn render_on_earth(
    data: &Heightmap,
    lattice: &vkterrain::geo::Lattice,
    method: GeomipmapSettings,
    cams: &[Camera],
) -> Vec<OwnedFrame> {
    let gpu = common::gpu(false);
    let mut sink = CollectSink::default();
    {
        let options = common::options(W, H, 2);
        let mut r = Renderer::with_world(&gpu, data, method, options, None, Some(lattice)).unwrap();
        for c in cams {
            r.render(
                FrameRequest {
                    camera: *c,
                    sky: Some([1.0, 0.0, 1.0]),
                    lod_viewer: None,
                },
                &mut sink,
            )
            .unwrap();
        }
        r.finish(&mut sink).unwrap();
    }
    common::assert_no_validation_messages(&gpu);
    sink.frames
}

/// Pixels whose colour or depth differ between two frames.
fn differing_px(a: &OwnedFrame, b: &OwnedFrame) -> usize {
    let (da, db) = (a.depth.as_ref().unwrap(), b.depth.as_ref().unwrap());
    (0..da.len())
        .filter(|&i| da[i] != db[i] || a.rgba[i * 4..i * 4 + 4] != b.rgba[i * 4..i * 4 + 4])
        .count()
}

/// On the earth (the CI terrain anchored at 46.5 N, and a native geographic grid at 60 N whose
/// east-west spacing is half the north-south) culling loses no block: over 78 poses each,
/// among them views along the data's edges (the edge near a side plane) and from 40-150 km
/// away, the image with culling on equals the image with culling off pixel for pixel (colour
/// and depth), while culling drops blocks. Control: the old grid-frame box (`cull_box =
/// "grid"`) loses visible blocks on some poses (measured: 1 of the anchored terrain's, 39 of
/// the geographic grid's).
#[test]
fn culling_on_the_earth_loses_no_block() {
    let mut grid_total = 0;
    for (name, (data, lattice)) in [
        ("anchored CI terrain", common::poses::anchored_ci(513, 60.0)),
        ("60 N geographic grid", common::poses::geographic_60n(257)),
    ] {
        let cams = common::poses::earth_poses(&data, &lattice, 60);
        let with = |cull, cull_box| GeomipmapSettings {
            cull,
            cull_box,
            ..Default::default()
        };
        let culled = render_on_earth(&data, &lattice, with(true, CullBox::Lattice), &cams);
        let all = render_on_earth(&data, &lattice, with(false, CullBox::Lattice), &cams);
        let grid = render_on_earth(&data, &lattice, with(true, CullBox::Grid), &cams);
        let (mut lost, mut grid_lost_px, mut grid_poses) = (0, 0, 0);
        let (mut tris, mut tris_all, mut terrain_px) = (0, 0, 0);
        for (i, (c, a)) in culled.iter().zip(&all).enumerate() {
            let n = differing_px(c, a);
            if n > 0 {
                println!("{name} pose {i} {:?}: {n} px differ with culling", cams[i]);
            }
            lost += n;
            let g = differing_px(&grid[i], a);
            grid_lost_px += g;
            grid_poses += (g > 0) as usize;
            tris += c.triangles;
            tris_all += a.triangles;
            terrain_px += a
                .depth
                .as_ref()
                .unwrap()
                .iter()
                .filter(|d| **d > 0.0)
                .count();
        }
        println!(
            "geomipmap on the earth, {name}: {} poses, {terrain_px} terrain px; culling: {lost} px differ, \
             {tris} triangles ({tris_all} without); grid-frame box: {grid_lost_px} px differ on \
             {grid_poses} poses",
            cams.len()
        );
        assert_eq!(lost, 0, "{name}: culling changed {lost} px");
        assert!(tris < tris_all, "{name}: {tris} vs {tris_all}");
        assert!(
            terrain_px > cams.len() * (W * H) as usize / 4,
            "{name}: {terrain_px}"
        );
        grid_total += grid_poses;
    }
    assert!(grid_total > 0, "the grid-frame box lost nothing");
}
