//! GeoMipMapping (Tabakovic's ATLOD), validation on: crack pixels over 200 poses with the
//! border permutations against the same poses without them (the control: T-junction cracks),
//! and fewer triangles than brute force, fewer still as the distance factor shrinks. Popping
//! (no morphing) is measured by `vkterrain eval` (docs/geomipmap.md).

mod common;

use vkterrain::dataset::Heightmap;
use vkterrain::dataset::procedural::{self, ProceduralParams};
use vkterrain::lod::blocks::BlockBounds;
use vkterrain::lod::geomipmap;
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
use common::surface::{Surface, classify, crack_candidates};

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

/// GeoMipMapping's own surface on the CPU for `cam`: every block at the level
/// `select_levels` gives it, with its border permutation (or none, `stitch` off), its
/// triangles from the shared index lists over samples clamped to the data as the vertex stage
/// clamps them.
fn block_surface<'a>(data: &'a Heightmap, cam: &Camera, factor: f64, stitch: bool) -> Surface<'a> {
    let q = geomipmap::BLOCK_QUADS;
    let bounds = BlockBounds::new(data, q).unwrap();
    let levels = geomipmap::select_levels(&bounds, data.spacing, [1.0, 1.0], cam.position, factor);
    let (cols, rows) = (bounds.cols, bounds.rows);
    let mut triangles = Vec::new();
    for j in 0..rows {
        for i in 0..cols {
            let mask = if stitch {
                geomipmap::border_mask(&levels, cols, rows, i, j)
            } else {
                0
            };
            let list = geomipmap::block_indices(levels[(j * cols + i) as usize], mask);
            let at = |k: u16| {
                let (x, y) = (k as u32 % (q + 1), k as u32 / (q + 1));
                [
                    (i * q + x).min(data.width - 1) as i32,
                    (j * q + y).min(data.height - 1) as i32,
                ]
            };
            triangles.extend(list.chunks(3).map(|t| [at(t[0]), at(t[1]), at(t[2])]));
        }
    }
    Surface::new(data, triangles)
}

/// Crack pixels over 200 poses with and without the border permutations: without them the
/// same poses crack (the control), with them none. A crack candidate (sky with the method's
/// terrain on both sides where brute force shows terrain) whose ray clears the method's own
/// surface everywhere is a notch in a coarse skyline, not a crack (`common::surface`).
#[test]
fn watertight_over_200_poses_and_cracks_without_border_permutations() {
    let data = terrain();
    let cams = poses(&data, 200);
    let factor = 4.0;
    let settings = |stitch| GeomipmapSettings {
        distance_factor: factor,
        stitch,
        ..Default::default()
    };
    let brute = render(&data, MethodKind::Brute, &cams);
    let rendered = [
        render(&data, settings(true), &cams),
        render(&data, settings(false), &cams),
    ];
    let (mut cracks, mut notches, mut terrain_px) = ([0, 0], Vec::new(), 0);
    let mut smallest_crack_margin = f64::INFINITY;
    for (i, b) in brute.iter().enumerate() {
        terrain_px += b
            .depth
            .as_ref()
            .unwrap()
            .iter()
            .filter(|d| **d > 0.0)
            .count();
        for (k, stitch) in [true, false].into_iter().enumerate() {
            let candidates = crack_candidates(b, &rendered[k][i]);
            if candidates.is_empty() {
                continue;
            }
            let surface = block_surface(&data, &cams[i], factor, stitch);
            let (c, n) = classify(&cams[i], &surface, &candidates, (W, H));
            cracks[k] += c.len();
            smallest_crack_margin = c.iter().fold(smallest_crack_margin, |a, &m| a.min(m));
            if stitch {
                if !c.is_empty() || !n.is_empty() {
                    println!(
                        "pose {i}: {} crack px, notches (hit margins {n:.4?} px)",
                        c.len()
                    );
                }
                notches.extend(n);
            }
        }
    }
    let [with, without] = cracks;
    println!(
        "geomipmap watertight: {terrain_px} terrain px, {with} crack px and {} notches (hit \
         margins {notches:.4?} px); {without} crack px without border permutations (smallest \
         hit margin {smallest_crack_margin:.3} px)",
        notches.len()
    );
    assert_eq!(with, 0, "crack px with border permutations");
    assert!(
        without >= 5,
        "only {without} crack px without border permutations"
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
    let fine: u64 = rendered[0][..20].iter().map(|f| f.triangles).sum();
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
