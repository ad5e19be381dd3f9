//! The chunked clipmap: graceful degradation while nodes are missing, convergence to the
//! full-data render, toroidal recentring, CPU/GPU agreement of `sample_height`, atlas
//! exhaustion and loader errors. GPU tests run with validation (incl. synchronization) on.

mod common;

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use glam::{DVec2, DVec3};
use vkterrain::clipmap::quadtree::NO_NODE;
use vkterrain::clipmap::{
    Clipmap, ClipmapSettings, DatasetSource, Geometry, NodeData, NodeKey, NodeSource,
};
use vkterrain::dataset::{Heightmap, Level0, PyramidReader, Terrain, tiles};
use vkterrain::gpu_constants::CLIPMAP_LOD_SHIFT;
use vkterrain::lod::MethodKind;
use vkterrain::lod::udlod::field::{FieldKey, SplitField};
use vkterrain::lod::udlod::levels::Levels;
use vkterrain::readback::{CollectSink, OwnedFrame};
use vkterrain::render::{FrameRequest, Renderer};
use vkterrain::scene::Camera;

const SIZE: u32 = 513;
const CENTER: u32 = 32;
/// Largest colour difference (8-bit codes) between a converged clipmap frame and the
/// single-texture render of the same data.
const COLOUR_TOLERANCE: u8 = 2;
/// Relative depth difference allowed between the same camera drawn at two viewport offsets
/// (plane-equation interpolation is set up from window coordinates, a few ulp).
const DEPTH_REL_TOLERANCE: f32 = 1e-5;

/// A 513² procedural data set with 32-texel nodes (17x17 leaf nodes, 6 levels), built once.
fn dataset() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| common::procedural_pyramid("clipmap", SIZE, 3, CENTER))
}

fn heightmap() -> Heightmap {
    tiles::load(dataset(), Some(0), u64::MAX).unwrap()
}

/// Fails every node in `withheld` until `release` is set (a loader that loses nodes).
struct Withholding {
    inner: DatasetSource,
    withheld: HashSet<NodeKey>,
    release: AtomicBool,
}

impl NodeSource for Withholding {
    fn load(&self, key: NodeKey) -> vkterrain::Result<NodeData> {
        if !self.release.load(Ordering::SeqCst) && self.withheld.contains(&key) {
            return Err(vkterrain::Error::invalid("test", "node withheld"));
        }
        self.inner.load(key)
    }
}

/// About `percent` % of the non-root nodes, chosen by a fixed hash.
fn withheld(geometry: &Geometry, percent: u64) -> HashSet<NodeKey> {
    let mut out = HashSet::new();
    for (lod, &(nx, ny)) in geometry.levels.iter().enumerate() {
        if lod + 1 == geometry.levels.len() {
            continue;
        }
        for y in 0..ny {
            for x in 0..nx {
                let h =
                    (x as u64 * 73_856_093) ^ (y as u64 * 19_349_663) ^ (lod as u64 * 83_492_791);
                if h.wrapping_mul(2_654_435_761) % 100 < percent {
                    out.insert(NodeKey {
                        lod: lod as u32,
                        x,
                        y,
                    });
                }
            }
        }
    }
    out
}

fn settings(node_count: u32, capacity: u32) -> ClipmapSettings {
    ClipmapSettings {
        enabled: true,
        atlas_capacity: capacity,
        node_count,
        max_in_flight: 64,
        max_uploads_per_frame: 32,
        workers: 2,
        retry_frames: 3,
        blend_nodes: 0.5,
    }
}

/// Straight down over the centre, the whole image covered by terrain.
fn camera_over(data: &Heightmap, fx: f64, fy: f64) -> Camera {
    let (ex, ey) = data.extent();
    let (_, hi) = data.height_range();
    Camera {
        position: DVec3::new(fx * ex, fy * ey, hi as f64 + 0.25 * ex),
        yaw_deg: 0.0,
        pitch_deg: -90.0,
        ..Camera::default()
    }
}

/// Every cell of every view's windows points at a resident ancestor (or itself).
fn assert_cells_resolve(cm: &Clipmap) {
    for view in &cm.views {
        let n = view.node_count;
        for (l, lv) in view.levels.iter().enumerate() {
            let [ox, oy, nx, ny] = *lv;
            for y in oy..(oy + n as i32).min(ny) {
                for x in ox..(ox + n as i32).min(nx) {
                    let cell = ((l as u32 * n + y as u32 % n) * n + x as u32 % n) as usize;
                    let e = view.entries[cell];
                    assert_ne!(e, NO_NODE, "cell {l}/{x}/{y} has no node");
                    let layer = (e & 0xffff) as u16;
                    let al = e >> CLIPMAP_LOD_SHIFT;
                    assert!(al as usize >= l);
                    let s = al - l as u32;
                    let want = NodeKey {
                        lod: al,
                        x: x as u32 >> s,
                        y: y as u32 >> s,
                    };
                    assert_eq!(cm.atlas.layer_of(want), Some(layer), "cell {l}/{x}/{y}");
                }
            }
        }
    }
}

/// CPU `sample_height` == GPU `clipmap_height` for the last frame's state, at integer and
/// fractional positions all over the data (float precision: a few ulp at most).
fn assert_cpu_equals_gpu(renderer: &Renderer, what: &str) {
    assert_cpu_equals_gpu_in_view(renderer, 0, what)
}

/// [`assert_cpu_equals_gpu`] for view `view` of a multi-view renderer.
fn assert_cpu_equals_gpu_in_view(renderer: &Renderer, view: usize, what: &str) {
    let mut points = Vec::new();
    for k in 0..8192u32 {
        let u = (k as f32 * 0.618_034).fract() * (SIZE - 1) as f32;
        let v = (k as f32 * 0.414_213_6).fract() * (SIZE - 1) as f32;
        points.push(if k % 2 == 0 {
            [u.floor(), v.floor()]
        } else {
            [u, v]
        });
    }
    let gpu_h = renderer.probe_heights_in_view(view, &points).unwrap();
    let cm = renderer.clipmap().unwrap();
    let mut worst = 0f32;
    for (p, g) in points.iter().zip(&gpu_h) {
        let cpu = cm.sample_height(view, *p);
        let d = (cpu - g[0]).abs();
        worst = worst.max(d);
        assert!(
            d <= 4.0 * f32::EPSILON * cpu.abs().max(1.0),
            "{what}: at {p:?}: cpu {cpu} gpu {}",
            g[0]
        );
    }
    eprintln!(
        "{what}: max |cpu - gpu| over {} points: {worst:e} m",
        points.len()
    );
}

fn no_sky(frame: &OwnedFrame) -> bool {
    frame.depth.as_ref().unwrap().iter().all(|&d| d > 0.0)
}

#[test]
fn withheld_nodes_fall_back_then_converge_to_the_full_data_render() {
    let gpu = common::gpu(false);
    let data = heightmap();
    let ds = DatasetSource::open(dataset()).unwrap();
    let geometry = Geometry::of(&ds.dataset);
    let withheld = withheld(&geometry, 35);
    assert!(withheld.len() > 50);
    let source = Arc::new(Withholding {
        inner: ds,
        withheld,
        release: AtomicBool::new(false),
    });
    // A window as large as level 0 (17 nodes): once converged every cell is a level-0 node.
    let cm = Clipmap::new(geometry, settings(18, 420), source.clone(), 1).unwrap();
    let options = common::options(256, 160, 2);
    let cam = camera_over(&data, 0.5, 0.5);
    let reference = common::render(&gpu, &data, options.clone(), &[cam.into()]);
    let mut sink = CollectSink::default();
    let mut renderer =
        Renderer::with_clipmap(&gpu, &data, MethodKind::Brute, options, Some(cm)).unwrap();
    // Withheld: streaming settles with fallbacks; every frame is watertight.
    for _ in 0..30 {
        renderer.render(cam, &mut sink).unwrap();
        assert_cells_resolve(renderer.clipmap().unwrap());
    }
    renderer.finish(&mut sink).unwrap();
    let c = renderer.clipmap().unwrap().counters;
    assert!(c.load_errors > 0, "{c:?}");
    assert!(renderer.clipmap().unwrap().views[0].fallback_cells > 0);
    assert!(sink.frames.iter().all(no_sky), "a frame has holes");
    assert_cpu_equals_gpu(&renderer, "fallbacks");

    // Released: retried nodes arrive; the image converges to the full-data render exactly.
    source.release.store(true, Ordering::SeqCst);
    let mut frames = 0;
    loop {
        renderer.render(cam, &mut sink).unwrap();
        assert_cells_resolve(renderer.clipmap().unwrap());
        frames += 1;
        let cm = renderer.clipmap().unwrap();
        if cm.busy() == 0 && cm.views[0].fallback_cells == 0 {
            break;
        }
        assert!(frames < 300, "no convergence: {:?}", cm.counters);
    }
    renderer.finish(&mut sink).unwrap();
    let last = sink.frames.last().unwrap();
    assert!(
        last.depth == reference[0].depth,
        "depth differs from the full-data render"
    );
    // Colour: normals and albedo now come from the atlas (texel-centred, filtered per node);
    // the single-texture path maps albedo edge to edge, so allow filtering differences.
    let diffs: Vec<u8> = last
        .rgba
        .iter()
        .zip(&reference[0].rgba)
        .map(|(a, b)| a.abs_diff(*b))
        .collect();
    let max = diffs.iter().copied().max().unwrap();
    let mean = diffs.iter().map(|&d| d as f64).sum::<f64>() / diffs.len() as f64;
    eprintln!("colour vs the full-data render: max {max}, mean {mean:.3} codes");
    assert!(
        max <= COLOUR_TOLERANCE && mean <= 0.05,
        "max {max}, mean {mean}"
    );
    // Converged at level 0: GPU clipmap heights equal the single texture's at every sample.
    let samples: Vec<[f32; 2]> = (0..SIZE)
        .step_by(7)
        .flat_map(|y| (0..SIZE).step_by(5).map(move |x| [x as f32, y as f32]))
        .collect();
    let h = renderer.probe_heights(&samples).unwrap();
    for (p, g) in samples.iter().zip(&h) {
        assert_eq!(g[0], data.sample(p[0] as u32, p[1] as u32), "at {p:?}");
    }
    drop(renderer);
    common::assert_no_validation_messages(&gpu);
}

#[test]
fn moving_by_one_node_changes_one_row_or_column_per_level() {
    let ds = DatasetSource::open(dataset()).unwrap();
    let geometry = Geometry::of(&ds.dataset);
    let n = 6;
    let mut cm = Clipmap::new(geometry, settings(n, 300), Arc::new(ds), 1).unwrap();
    let c = CENTER as f64;
    let start = DVec2::new(8.3 * c, 7.6 * c);
    for (step, d) in [
        DVec2::new(c, 0.0),
        DVec2::new(0.0, c),
        DVec2::new(-c, 0.0),
        DVec2::new(0.0, -c),
    ]
    .into_iter()
    .enumerate()
    {
        cm.update(&[start]);
        let before = cm.views[0].keys.clone();
        cm.update(&[start + d]);
        let view = &cm.views[0];
        assert_eq!(view.changed[0], n, "step {step}: level 0");
        let cells = (n * n) as usize;
        for (l, &ch) in view.changed.iter().enumerate() {
            assert!(
                ch == 0 || ch == n,
                "step {step}: level {l} changed {ch} cells"
            );
            let old: HashSet<_> = before[l * cells..(l + 1) * cells].iter().collect();
            let new: HashSet<_> = view.keys[l * cells..(l + 1) * cells].iter().collect();
            let range = l * cells..(l + 1) * cells;
            for (was, now) in before[range.clone()].iter().zip(&view.keys[range]) {
                // Toroidal: a cell changes only when its node left the window; nodes that stay
                // keep their cell.
                if was != now {
                    assert!(!new.contains(was), "step {step}: {was:?} moved");
                    assert!(!old.contains(now), "step {step}: {now:?} moved");
                }
            }
        }
    }
}

#[test]
fn views_share_one_atlas() {
    let ds = DatasetSource::open(dataset()).unwrap();
    let geometry = Geometry::of(&ds.dataset);
    let src: Arc<dyn NodeSource> = Arc::new(ds);
    let mut one = Clipmap::new(geometry.clone(), settings(6, 300), src.clone(), 1).unwrap();
    let mut two = Clipmap::new(geometry, settings(6, 300), src, 2).unwrap();
    let p = DVec2::new(100.0, 200.0);
    for _ in 0..200 {
        one.update(&[p]);
        two.update(&[p, p]);
        if one.busy() == 0 && two.busy() == 0 && one.counters.requested > 0 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    // Two identical views: the same nodes, requested and stored once.
    assert_eq!(one.counters.requested, two.counters.requested);
    assert_eq!(one.atlas.resident(), two.atlas.resident());
    assert_eq!(one.atlas_bytes(), two.atlas_bytes());
    // Two distant views: both resolve, within the one fixed-capacity atlas.
    for _ in 0..200 {
        two.update(&[p, DVec2::new(480.0, 20.0)]);
        if two.busy() == 0 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    assert!(two.atlas.resident() <= 300);
    assert_cells_resolve(&two);
    assert_eq!(two.views[1].fallback_cells, 0);
}

fn copy_dir(from: &Path, to: &Path) {
    let _ = std::fs::remove_dir_all(to);
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

#[test]
fn atlas_exhaustion_and_loader_errors_degrade_gracefully() {
    let gpu = common::gpu(false);
    let data = heightmap();
    // Missing L1.bin, and a NaN in node (2, 2) of L2: errors, not crashes.
    let broken = dataset().with_file_name("broken");
    copy_dir(dataset(), &broken);
    let record = tiles::Dataset::open(&broken).unwrap().manifest.levels[2].record_size;
    std::fs::remove_file(broken.join("L1.bin")).unwrap();
    {
        use std::io::{Seek, SeekFrom, Write};
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .open(broken.join("L2.bin"))
            .unwrap();
        f.seek(SeekFrom::Start(64 + 12 * record + 16 + 40)).unwrap();
        f.write_all(&f32::NAN.to_le_bytes()).unwrap();
    }
    let ds = DatasetSource::open(&broken).unwrap();
    let geometry = Geometry::of(&ds.dataset);
    // 50 layers for a wanted set of ~110 nodes (levels 2.. need 39): exhausted.
    let mut s = settings(6, 50);
    s.retry_frames = 1000;
    let cm = Clipmap::new(geometry, s, Arc::new(ds), 1).unwrap();
    let mut sink = CollectSink::default();
    // Heights from the pyramid (node-by-node reader), not the height map: no level-0 array.
    let level0 = Arc::new(PyramidReader::open(&broken).unwrap());
    let mut renderer = Renderer::with_clipmap(
        &gpu,
        Terrain::Pyramid(level0.clone()),
        MethodKind::Udlod,
        common::options(192, 120, 2),
        Some(cm),
    )
    .unwrap();
    assert!(level0.cached_bytes() <= level0.max_cached_bytes());
    for k in 0..24 {
        let f = 0.3 + 0.4 * k as f64 / 24.0;
        renderer
            .render(camera_over(&data, f, 0.5), &mut sink)
            .unwrap();
        let cm = renderer.clipmap().unwrap();
        assert!(cm.atlas.resident() <= 50);
        assert_cells_resolve(cm);
    }
    renderer.finish(&mut sink).unwrap();
    let c = renderer.clipmap().unwrap().counters;
    eprintln!("{c:?}");
    assert!(c.load_errors > 0, "{c:?}");
    assert!(c.deferred > 0, "{c:?}");
    assert!(c.evictions > 0, "{c:?}");
    assert!(sink.frames.iter().all(no_sky), "a frame has holes");
    // Several levels, blend bands, fallbacks over missing and corrupt nodes: still one formula.
    assert_cpu_equals_gpu(&renderer, "exhausted atlas");
    drop(renderer);
    common::assert_no_validation_messages(&gpu);
}

#[test]
fn bad_settings_and_mismatched_data_are_one_line_errors() {
    let ds = DatasetSource::open(dataset()).unwrap();
    let geometry = Geometry::of(&ds.dataset);
    let src: Arc<dyn NodeSource> = Arc::new(ds);
    for s in [
        ClipmapSettings {
            node_count: 5,
            ..settings(6, 64)
        },
        settings(6, 1),
        ClipmapSettings {
            max_in_flight: 0,
            ..settings(6, 64)
        },
    ] {
        let e = Clipmap::new(geometry.clone(), s, src.clone(), 1)
            .err()
            .expect("rejected")
            .to_string();
        assert!(!e.contains('\n'), "{e}");
    }
    let gpu = common::gpu(false);
    let cm = Clipmap::new(geometry, settings(6, 64), src, 1).unwrap();
    let small = tiles::load(dataset(), Some(1), u64::MAX).unwrap();
    let e = Renderer::with_clipmap(
        &gpu,
        &small,
        MethodKind::Brute,
        common::options(64, 64, 1),
        Some(cm),
    )
    .err()
    .expect("level 1 is not level 0")
    .to_string();
    assert!(e.contains("level 0"), "{e}");
    common::assert_no_validation_messages(&gpu);
}

/// Updates until every wanted node is resident (or panics after a while).
fn settle(cm: &mut Clipmap, viewers: &[DVec2]) {
    for _ in 0..2000 {
        cm.update(viewers);
        if cm.busy() == 0 && cm.views.iter().all(|v| v.fallback_cells == 0) {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    panic!("streaming did not settle: {:?}", cm.counters);
}

/// Largest height step between neighbouring points 1/256 sample apart on a line from the viewer
/// outwards across several ring edges (a continuous surface gives ~slope / 256; a step at a
/// ring edge gives the whole difference between the levels).
fn max_step(cm: &Clipmap, viewer: DVec2) -> f32 {
    let mut worst = 0f32;
    let mut prev = cm.sample_height(0, [viewer.x as f32, viewer.y as f32]);
    for k in 1..(256 * 240) {
        let p = [viewer.x as f32 + k as f32 / 256.0, viewer.y as f32];
        let h = cm.sample_height(0, p);
        worst = worst.max((h - prev).abs());
        prev = h;
    }
    worst
}

#[test]
fn ring_edges_blend_without_steps() {
    let ds = DatasetSource::open(dataset()).unwrap();
    let data = heightmap();
    let geometry = Geometry::of(&ds.dataset);
    let src: Arc<dyn NodeSource> = Arc::new(ds);
    let viewer = DVec2::new(200.3, 251.7);
    let mut blended = Clipmap::new(geometry.clone(), settings(4, 300), src.clone(), 1).unwrap();
    let mut stepped = Clipmap::new(
        geometry,
        ClipmapSettings {
            blend_nodes: 0.0,
            ..settings(4, 300)
        },
        src,
        1,
    )
    .unwrap();
    settle(&mut blended, &[viewer]);
    settle(&mut stepped, &[viewer]);
    // The full-resolution surface's largest step on the same line (bilinear, 1/256 sample).
    let mut exact = 0f64;
    for k in 1..(256 * 240) {
        let x = |k: i32| (viewer.x + k as f64 / 256.0) * data.spacing;
        let y = viewer.y * data.spacing;
        exact = exact.max((data.height_at(x(k), y) - data.height_at(x(k - 1), y)).abs());
    }
    let (b, s) = (max_step(&blended, viewer), max_step(&stepped, viewer));
    eprintln!(
        "largest step per 1/256 sample: exact {exact:.4} m, blended {b:.4} m, unblended {s:.4} m"
    );
    assert!(
        s as f64 > 5.0 * exact,
        "no step at the ring edges to remove"
    );
    assert!((b as f64) < 2.0 * exact, "blending leaves a step");
}

/// A loader that takes `delay` per node of levels 0 and 1 (coarser ones are immediate).
struct Slow {
    inner: DatasetSource,
    delay: std::time::Duration,
}

impl NodeSource for Slow {
    fn load(&self, key: NodeKey) -> vkterrain::Result<NodeData> {
        if key.lod <= 1 {
            std::thread::sleep(self.delay);
        }
        self.inner.load(key)
    }
}

#[test]
fn slow_loads_are_bounded_prioritised_and_cancelled_when_unwanted() {
    let ds = DatasetSource::open(dataset()).unwrap();
    let geometry = Geometry::of(&ds.dataset);
    let src = Arc::new(Slow {
        inner: ds,
        delay: std::time::Duration::from_millis(15),
    });
    let mut s = settings(6, 300);
    s.workers = 1;
    s.max_in_flight = 6;
    let mut cm = Clipmap::new(geometry, s, src, 1).unwrap();
    let a = DVec2::new(40.0, 40.0);
    let started = std::time::Instant::now();
    cm.update(&[a]);
    // The update never waits for the loader.
    assert!(started.elapsed() < std::time::Duration::from_millis(15));
    assert!(cm.busy() <= 6);
    // Coarse first: levels 2.. (39 nodes) become resident before any level-1 or level-0 node.
    let coarse = |cm: &Clipmap| {
        cm.views[0]
            .keys
            .iter()
            .flatten()
            .filter(|k| k.lod >= 2 && cm.atlas.layer_of(**k).is_some())
            .count()
    };
    let mut frames = 0;
    while coarse(&cm) < 39 {
        let fine = cm.atlas.resident() - coarse(&cm);
        assert_eq!(fine, 0, "a level-0/1 node arrived before the coarse levels");
        std::thread::sleep(std::time::Duration::from_millis(2));
        cm.update(&[a]);
        assert!(cm.busy() <= 6);
        frames += 1;
        assert!(frames < 500, "{:?}", cm.counters);
    }
    // Now level-1/0 nodes around `a` are queued (15 ms each). Jump to the far corner: they are
    // no longer wanted and are skipped or dropped.
    for _ in 0..3 {
        cm.update(&[a]);
    }
    let b = DVec2::new(500.0, 500.0);
    for _ in 0..40 {
        cm.update(&[b]);
        assert!(cm.busy() <= 6);
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert!(cm.counters.cancelled > 0, "{:?}", cm.counters);
    assert_cells_resolve(&cm);
}

/// A renderer on the earth takes only a clipmap whose shading planes hold world-axes normals
/// through its own lattice (`Geometry::with_world`); the grid's normals there would light the
/// terrain by the wrong vertical. One-line error, nothing built.
#[test]
fn an_earth_renderer_refuses_a_clipmap_with_grid_frame_normals() {
    let gpu = common::gpu(true);
    let data = heightmap();
    let step = 1.0 / 1200.0;
    let lattice =
        vkterrain::geo::Lattice::geographic(data.width, data.height, [8.0, 60.0], [step, step])
            .unwrap();
    let open = |world: Option<Arc<vkterrain::geo::Lattice>>| {
        let ds = DatasetSource::open(dataset()).unwrap();
        let geometry = Geometry::of(&ds.dataset).with_world(world);
        Clipmap::new(geometry, settings(6, 80), Arc::new(ds), 1).unwrap()
    };
    let renderer = |cm: Clipmap| {
        Renderer::with_world(
            &gpu,
            &data,
            MethodKind::Brute,
            common::options(64, 40, 1),
            Some(cm),
            Some(&lattice),
        )
    };
    let refused = renderer(open(None))
        .err()
        .expect("grid-frame normals refused");
    let message = refused.to_string();
    assert!(
        message.contains("normals are not in the renderer's axes"),
        "{message}"
    );
    assert!(!message.contains('\n'), "{message}");
    // Control: the same clipmap built through the renderer's lattice is taken.
    assert!(renderer(open(Some(Arc::new(lattice.clone())))).is_ok());
    common::assert_no_validation_messages(&gpu);
}

#[test]
fn legacy_barrier_path_streams_without_validation_messages() {
    let gpu = common::gpu(true);
    let data = heightmap();
    let ds = DatasetSource::open(dataset()).unwrap();
    let geometry = Geometry::of(&ds.dataset);
    let cm = Clipmap::new(geometry, settings(6, 80), Arc::new(ds), 1).unwrap();
    let mut sink = CollectSink::default();
    let mut renderer = Renderer::with_clipmap(
        &gpu,
        &data,
        MethodKind::Brute,
        common::options(128, 80, 3),
        Some(cm),
    )
    .unwrap();
    for k in 0..12 {
        let f = 0.35 + 0.3 * k as f64 / 12.0;
        renderer
            .render(camera_over(&data, f, 0.5), &mut sink)
            .unwrap();
    }
    renderer.finish(&mut sink).unwrap();
    assert!(renderer.clipmap().unwrap().counters.uploaded > 0);
    assert!(sink.frames.iter().all(no_sky));
    assert_cpu_equals_gpu(&renderer, "legacy path");
    drop(renderer);
    common::assert_no_validation_messages(&gpu);
}

#[test]
fn shading_planes_carry_normals_albedo_and_their_mips() {
    let ds = DatasetSource::open(dataset()).unwrap();
    let geometry = Geometry::of(&ds.dataset);
    let key = NodeKey { lod: 0, x: 3, y: 4 };
    let node = ds.load(key).unwrap();
    let planes = geometry.shading(key, &node);
    let side = geometry.side() as usize;
    assert_eq!(geometry.shading_mips(), 4);
    assert_eq!(planes.len() as u64, geometry.shading_texels() * 8);
    // Normal of a centre texel = the single-texture path's normal of the same sample.
    let data = heightmap();
    let normals = data.normals_snorm8(None);
    let (b, c) = (geometry.border as usize, CENTER as usize);
    let texels = [(0usize, 0usize), (5, 17), (31, 31)];
    let same_texels = |planes: &[u8], normals: &[u8]| {
        for (i, j) in texels {
            let (u, v) = (3 * c + i, 4 * c + j);
            let at = ((j + b) * side + i + b) * 4;
            let want = (v * data.width as usize + u) * 4;
            assert_eq!(planes[at..at + 4], normals[want..want + 4], "texel {i},{j}");
        }
    };
    same_texels(&planes, &normals);
    // On the earth (a geographic grid of 3" at 60 N) both take their normals to world axes
    // through the lattice, and agree again; the grid frame's would not (control).
    let step = 1.0 / 1200.0;
    let lattice =
        vkterrain::geo::Lattice::geographic(data.width, data.height, [8.0, 60.0], [step, step])
            .unwrap();
    let earth = Geometry::of(&ds.dataset).with_world(Some(std::sync::Arc::new(lattice.clone())));
    let world_planes = earth.shading(key, &node);
    let world_normals = data.normals_snorm8(Some(&lattice));
    same_texels(&world_planes, &world_normals);
    assert_ne!(world_normals, normals);
    // Albedo mip 1 texel (x, y) = rounded mean of mip-0 texels (2x..2x+1, 2y..2y+1).
    let albedo = geometry.shading_texels() as usize * 4;
    let mip1 = albedo + side * side * 4;
    let half = geometry.mip_side(1) as usize;
    for (x, y) in [(0usize, 0usize), (7, 11), (half - 1, half - 1)] {
        for ch in 0..4 {
            let t = |i: usize, j: usize| planes[albedo + (j * side + i) * 4 + ch] as f32;
            let mean = (t(2 * x, 2 * y)
                + t(2 * x + 1, 2 * y)
                + t(2 * x, 2 * y + 1)
                + t(2 * x + 1, 2 * y + 1))
                / 4.0;
            assert_eq!(planes[mip1 + (y * half + x) * 4 + ch], mean.round() as u8);
        }
    }
}

/// Returns nodes of the wrong size for `bad_lods`.
struct Truncating {
    inner: DatasetSource,
    bad_lods: std::ops::RangeInclusive<u32>,
}

impl NodeSource for Truncating {
    fn load(&self, key: NodeKey) -> vkterrain::Result<NodeData> {
        let mut n = self.inner.load(key)?;
        if self.bad_lods.contains(&key.lod) {
            n.heights.truncate(7);
        }
        Ok(n)
    }
}

#[test]
fn nodes_of_the_wrong_size_from_any_source_are_errors_not_panics() {
    let ds = || DatasetSource::open(dataset()).unwrap();
    let geometry = Geometry::of(&ds().dataset);
    let lods = geometry.levels.len() as u32;
    // A bad root: creation fails with one line.
    let e = Clipmap::new(
        geometry.clone(),
        settings(6, 64),
        Arc::new(Truncating {
            inner: ds(),
            bad_lods: 0..=lods,
        }),
        1,
    )
    .err()
    .expect("bad root rejected")
    .to_string();
    assert!(e.contains("root") && !e.contains('\n'), "{e}");
    // Bad finer nodes: counted as load errors, lookups fall back.
    let mut cm = Clipmap::new(
        geometry,
        settings(6, 300),
        Arc::new(Truncating {
            inner: ds(),
            bad_lods: 0..=1,
        }),
        1,
    )
    .unwrap();
    for _ in 0..300 {
        cm.update(&[DVec2::new(250.0, 250.0)]);
        if cm.busy() == 0 && cm.counters.load_errors > 0 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    assert!(cm.counters.load_errors > 0, "{:?}", cm.counters);
    assert_cells_resolve(&cm);
    assert!(cm.sample_height(0, [250.0, 250.0]).is_finite());
}

/// Renders `cameras` side by side (one view each, `view_width` columns per view) through one
/// clipmap until every wanted node is resident; returns the last frame, the resident node
/// count and the device memory in use while the renderer was alive.
fn render_views_converged(
    gpu: &Arc<vkterrain::driver::Gpu>,
    data: &Heightmap,
    src: &Arc<dyn NodeSource>,
    cameras: &[Camera],
    view_width: u32,
) -> (OwnedFrame, usize, u64) {
    let geometry = Geometry::of(&DatasetSource::open(dataset()).unwrap().dataset);
    let cm = Clipmap::new(geometry, settings(6, 300), src.clone(), cameras.len()).unwrap();
    let mut options = common::options(view_width * cameras.len() as u32, 120, 2);
    options.views = cameras.len();
    let mut renderer =
        Renderer::with_clipmap(gpu, data, MethodKind::Udlod, options, Some(cm)).unwrap();
    let requests: Vec<FrameRequest> = cameras.iter().map(|&c| c.into()).collect();
    let mut sink = CollectSink::default();
    for frame in 0.. {
        renderer.render_views(&requests, &mut sink).unwrap();
        let cm = renderer.clipmap().unwrap();
        assert_cells_resolve(cm);
        assert!(cm.atlas.resident() <= 300);
        if cm.busy() == 0 && cm.views.iter().all(|v| v.fallback_cells == 0) {
            break;
        }
        assert!(frame < 300, "no convergence: {:?}", cm.counters);
    }
    renderer.finish(&mut sink).unwrap();
    assert!(sink.frames.iter().all(no_sky), "a frame has holes");
    for v in 0..cameras.len() {
        assert_cpu_equals_gpu_in_view(&renderer, v, &format!("view {v} of {}", cameras.len()));
    }
    let resident = renderer.clipmap().unwrap().atlas.resident();
    let allocated = gpu.allocated_bytes();
    (sink.frames.pop().unwrap(), resident, allocated)
}

#[test]
fn two_cameras_render_in_one_frame_through_one_atlas() {
    let gpu = common::gpu(false);
    let data = heightmap();
    let src: Arc<dyn NodeSource> = Arc::new(DatasetSource::open(dataset()).unwrap());
    // Far apart (their level-0 windows do not overlap), looking different ways, obliquely.
    let oblique = |fx, fy, yaw| {
        let mut c = camera_over(&data, fx, fy);
        c.position.z *= 0.5;
        c.pitch_deg = -60.0;
        c.yaw_deg = yaw;
        c
    };
    let (a, b) = (oblique(0.2, 0.25, 30.0), oblique(0.8, 0.75, 200.0));
    let w = 160;
    let (alone_a, resident_a, _) = render_views_converged(&gpu, &data, &src, &[a], w);
    let (alone_b, resident_b, _) = render_views_converged(&gpu, &data, &src, &[b], w);
    let (both, resident_both, bytes_both) = render_views_converged(&gpu, &data, &src, &[a, b], w);
    assert_eq!((both.width, both.height), (2 * w, 120));
    // Each half of the two-view frame is that camera's own frame: the views share the atlas
    // but not their lookups, LOD state or uniforms. Viewport offsets may move a rasterized
    // edge by a sub-pixel snap, so compare per pixel with a small allowance.
    for (v, alone) in [(0usize, &alone_a), (1, &alone_b)] {
        let (mut depth_diff, mut colour_diff, mut worst_colour) = (0usize, 0usize, 0u8);
        let mut worst_depth = 0f32;
        let both_depth = both.depth.as_ref().unwrap();
        let alone_depth = alone.depth.as_ref().unwrap();
        for y in 0..120usize {
            for x in 0..w as usize {
                let i = y * w as usize + x;
                let j = y * 2 * w as usize + v * w as usize + x;
                // Interpolated depth may round differently at another pixel offset.
                let rel = (both_depth[j] - alone_depth[i]).abs() / alone_depth[i].abs().max(1e-30);
                worst_depth = worst_depth.max(rel);
                if rel > DEPTH_REL_TOLERANCE {
                    depth_diff += 1;
                }
                let d = (0..4)
                    .map(|k| both.rgba[j * 4 + k].abs_diff(alone.rgba[i * 4 + k]))
                    .max()
                    .unwrap();
                if d > 0 {
                    colour_diff += 1;
                }
                worst_colour = worst_colour.max(d);
            }
        }
        eprintln!(
            "view {v}: {depth_diff} depth and {colour_diff} colour pixels differ from its own frame \
             (of {}), worst relative depth {worst_depth:e}, worst colour {worst_colour} codes",
            w * 120
        );
        assert!(
            depth_diff * 200 <= (w * 120) as usize,
            "view {v}: {depth_diff} depths differ"
        );
        assert!(
            colour_diff * 200 <= (w * 120) as usize,
            "view {v}: {colour_diff} colours differ"
        );
    }
    // One atlas: the coarse nodes both views want are stored once.
    eprintln!("resident nodes: a {resident_a}, b {resident_b}, both {resident_both}");
    assert!(resident_both >= resident_a.max(resident_b));
    assert!(resident_both < resident_a + resident_b);
    // Device memory: a second view adds its lookups, uniforms and LOD buffers (UDLOD's tile
    // lists per frame slot: 3 MiB at the default 65,536 tiles), not a second atlas (which
    // would add >= its size).
    let geometry = Geometry::of(&DatasetSource::open(dataset()).unwrap().dataset);
    let one_wide = {
        let cm = Clipmap::new(geometry.clone(), settings(6, 300), src.clone(), 1).unwrap();
        let atlas = cm.atlas_bytes();
        let _r = Renderer::with_clipmap(
            &gpu,
            &data,
            MethodKind::Udlod,
            common::options(2 * w, 120, 2),
            Some(cm),
        )
        .unwrap();
        (gpu.allocated_bytes(), atlas)
    };
    let (bytes_one, atlas_bytes) = one_wide;
    eprintln!(
        "device memory at {}x120: one view {bytes_one} B, two views {bytes_both} B, atlas {atlas_bytes} B",
        2 * w
    );
    assert!(bytes_both >= bytes_one);
    // UDLOD's final and temporary tile lists, per frame slot (2 in flight) and view: 16 bytes
    // a tile, `3 * max_tiles + 8` tiles (docs/udlod.md "Capacity").
    let max_tiles = vkterrain::lod::UdlodSettings::default().max_tiles as u64;
    let tile_lists = 2 * (3 * max_tiles + 8) * 16;
    assert!(
        bytes_both - bytes_one < atlas_bytes / 2 + tile_lists,
        "a second view added {} B (atlas {atlas_bytes} B, UDLOD's tile lists {tile_lists} B)",
        bytes_both - bytes_one
    );
    common::assert_no_validation_messages(&gpu);
}

#[test]
fn ring_edges_blend_shading_without_steps() {
    let gpu = common::gpu(false);
    let data = heightmap();
    let viewer = DVec2::new(200.3, 251.7);
    // The same line as `ring_edges_blend_without_steps`, across the level-0 and level-1
    // window edges, 1/256 sample apart.
    let line: Vec<[f32; 2]> = (0..256 * 240)
        .map(|k| [(viewer.x + k as f64 / 256.0) as f32, viewer.y as f32])
        .collect();
    let largest_normal_step = |blend_nodes: f64| -> f32 {
        let geometry = Geometry::of(&DatasetSource::open(dataset()).unwrap().dataset);
        let src: Arc<dyn NodeSource> = Arc::new(DatasetSource::open(dataset()).unwrap());
        let s = ClipmapSettings {
            blend_nodes,
            ..settings(4, 300)
        };
        let cm = Clipmap::new(geometry, s, src, 1).unwrap();
        let mut renderer = Renderer::with_clipmap(
            &gpu,
            &data,
            MethodKind::Brute,
            common::options(64, 48, 2),
            Some(cm),
        )
        .unwrap();
        let size = (SIZE - 1) as f64;
        let camera = camera_over(&data, viewer.x / size, viewer.y / size);
        let request = FrameRequest {
            camera,
            sky: None,
            lod_viewer: Some(DVec3::new(
                viewer.x * data.spacing,
                viewer.y * data.spacing,
                camera.position.z,
            )),
        };
        let mut sink = CollectSink::default();
        for frame in 0.. {
            renderer.render(request, &mut sink).unwrap();
            let cm = renderer.clipmap().unwrap();
            if cm.busy() == 0 && cm.views[0].fallback_cells == 0 {
                break;
            }
            assert!(frame < 300, "no convergence");
        }
        renderer.finish(&mut sink).unwrap();
        let normals = renderer
            .probe_in_view(0, &line, vkterrain::clipmap::probe::ProbeKind::Normals)
            .unwrap();
        normals
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).abs().max((w[1][1] - w[0][1]).abs()))
            .fold(0.0, f32::max)
    };
    let (blended, stepped) = (largest_normal_step(0.5), largest_normal_step(0.0));
    eprintln!(
        "largest normal change per 1/256 sample: blended {blended:.4}, unblended {stepped:.4}"
    );
    assert!(
        stepped > 0.005,
        "no shading step at the ring edges to remove"
    );
    assert!(blended * 10.0 < stepped, "blending leaves a shading step");
    common::assert_no_validation_messages(&gpu);
}

/// UDLOD's levels (per-tile min/max and errors, per-level errors, and the split field derived
/// from them) built from the
/// pyramid's level-0 nodes through the bounded reader equal those from the whole height map,
/// bit for bit; the reader loads each node about once per level sweep and never holds more
/// than its bound; bad positions and corrupt nodes are one-line errors.
#[test]
fn levels_from_the_pyramid_reader_equal_levels_from_the_height_map() {
    let data = heightmap();
    let reader = PyramidReader::open(dataset()).unwrap();
    assert_eq!((reader.width(), reader.height()), (data.width, data.height));
    assert_eq!(reader.spacing(), data.spacing);
    // Bit patterns (short `Debug`: the vectors hold thousands of entries).
    let bits = |v: &[f32]| Bits(v.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
    for (grid, field_max) in [(16, 1024.0), (8, 1.0), (4, 8.0)] {
        let a = Levels::new(&data, grid).unwrap();
        let b = Levels::new(&reader.sweep(), grid).unwrap();
        // Both equal the statistics as computed before `Level0` (sample by sample).
        let (mm, te, le) = reference_statistics(&data, &a);
        assert_eq!(
            bits(&mm),
            bits(&a.min_max.concat()),
            "reference min/max, grid {grid}"
        );
        assert_eq!(
            bits(&te),
            bits(&a.tile_error),
            "reference tile errors, grid {grid}"
        );
        assert_eq!(le, a.level_error, "reference level errors, grid {grid}");
        assert_eq!(a.tiles_per_side, b.tiles_per_side);
        assert_eq!(a.level_offsets, b.level_offsets);
        assert_eq!(
            (a.width, a.height, a.root_lod),
            (b.width, b.height, b.root_lod)
        );
        assert_eq!(a.spacing.to_bits(), b.spacing.to_bits());
        let mm = |l: &Levels| l.min_max.iter().flatten().copied().collect::<Vec<_>>();
        assert_eq!(bits(&mm(&a)), bits(&mm(&b)), "min/max, grid {grid}");
        assert_eq!(bits(&a.tile_error), bits(&b.tile_error), "tile errors");
        let e64 = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(e64(&a.level_error), e64(&b.level_error));
        assert!(a.level_error.iter().any(|&e| e > 0.0));
        let key = FieldKey {
            focal_px: 623.5,
            tau_px: 1.0,
            morph_range: 0.2,
            morph_levels: 2,
            field_max,
            share: vkterrain::lod::udlod::settings::worst_case_share(grid, 1),
            zone_rule: Default::default(),
        };
        let (fa, fb) = (SplitField::new(&a, key), SplitField::new(&b, key));
        assert_eq!(bits(&fa.corners), bits(&fb.corners), "split field");
        assert_eq!(bits(&fa.split), bits(&fb.split), "split distances");
        assert!(reader.cached_bytes() <= reader.max_cached_bytes());
    }
    // 17x17 level-0 nodes, cache 3 x 17 + 8 = 59: the three builds sweep 6 + 7 + 8 levels and
    // load every node about once per level sweep (a thrashing cache would reload nodes for
    // every tile row).
    let nodes = 17 * 17;
    assert_eq!(reader.capacity(), 59);
    let loads = reader.node_loads();
    eprintln!("node loads for 3 level builds: {loads}");
    assert!(loads <= 21 * nodes * 5 / 4, "{loads} node loads");
    // The reader's bilinear height equals the height map's, bit for bit.
    let (ex, ey) = data.extent();
    for k in 0..200 {
        let (x, y) = (
            ex * (k as f64 * 0.618).fract(),
            ey * (k as f64 * 0.382).fract(),
        );
        assert_eq!(
            reader.bilinear(x, y).unwrap().to_bits(),
            data.height_at(x, y).to_bits()
        );
    }
    reader.clear();
    assert_eq!(reader.cached_bytes(), 0);
    let e = reader.sample(SIZE, 0).unwrap_err().to_string();
    assert!(e.contains("outside") && !e.contains('\n'), "{e}");

    // A NaN in a level-0 node: an error naming the node, not data and not a panic.
    let broken = dataset().with_file_name("broken-l0");
    copy_dir(dataset(), &broken);
    let record = tiles::Dataset::open(&broken).unwrap().manifest.levels[0].record_size;
    {
        use std::io::{Seek, SeekFrom, Write};
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .open(broken.join("L0.bin"))
            .unwrap();
        // Node (1, 0): a texel inside its centre (row 2 + border 2, column 2 + border 2).
        let side = CENTER as u64 + 4;
        f.seek(SeekFrom::Start(64 + record + 16 + 4 * (4 * side + 4)))
            .unwrap();
        f.write_all(&f32::NAN.to_le_bytes()).unwrap();
    }
    let bad = PyramidReader::open(&broken).unwrap();
    let e = Levels::new(&bad.sweep(), 16).unwrap_err().to_string();
    assert!(e.contains("node 0/1/0") && !e.contains('\n'), "{e}");
}

/// UDLOD's per-tile min/max, tile errors and level errors exactly as `levels.rs` computed them
/// before `Level0` (every sample, four grid corners per sample), for `levels`' tiling.
fn reference_statistics(data: &Heightmap, levels: &Levels) -> (Vec<f32>, Vec<f32>, Vec<f64>) {
    let level_height = |lod: u32, c: u32, r: u32| {
        let step = 1u32 << lod;
        let s = |c: u32, r: u32| data.sample(c.min(data.width - 1), r.min(data.height - 1)) as f64;
        let (c0, r0) = (c / step * step, r / step * step);
        let (fx, fy) = ((c - c0) as f64 / step as f64, (r - r0) as f64 / step as f64);
        let (h00, h10, h01, h11) = (
            s(c0, r0),
            s(c0 + step, r0),
            s(c0, r0 + step),
            s(c0 + step, r0 + step),
        );
        if fx + fy <= 1.0 {
            h00 + (h10 - h00) * fx + (h01 - h00) * fy
        } else {
            h11 + (h01 - h11) * (1.0 - fx) + (h10 - h11) * (1.0 - fy)
        }
    };
    let (mut mm, mut te, mut le) = (Vec::new(), Vec::new(), Vec::new());
    for lod in 0..=levels.root_lod {
        let span = levels.grid_size << lod;
        let (nx, ny) = levels.tiles_per_side[lod as usize];
        let mut worst = 0.0f64;
        for ty in 0..ny {
            for tx in 0..nx {
                let (c0, r0) = (tx * span, ty * span);
                let (c1, r1) = (
                    (c0 + span).min(data.width - 1),
                    (r0 + span).min(data.height - 1),
                );
                let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                let mut error = 0.0f64;
                for r in r0..=r1 {
                    for c in c0..=c1 {
                        let h = data.sample(c, r);
                        lo = lo.min(h);
                        hi = hi.max(h);
                        if lod > 0 {
                            error = error.max((level_height(lod, c, r) - h as f64).abs());
                        }
                    }
                }
                // `Levels` holds level 0's tiles only in a one-level tree.
                if lod >= 1 || levels.root_lod == 0 {
                    mm.extend([lo, hi]);
                    te.push(error as f32);
                }
                worst = worst.max(error);
            }
        }
        le.push(worst);
    }
    (mm, te, le)
}

/// Bit patterns whose `Debug` shows only the length and the first entries, so a failed
/// `assert_eq!` stays readable.
#[derive(PartialEq)]
struct Bits(Vec<u32>);

impl std::fmt::Debug for Bits {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} entries, first {:?}",
            self.0.len(),
            &self.0[..self.0.len().min(4)]
        )
    }
}

fn bits(v: &[f32]) -> Bits {
    Bits(v.iter().map(|x| x.to_bits()).collect())
}

/// The two levels hold the same statistics, to the bit.
fn same(a: &Levels, b: &Levels) -> bool {
    let e64 = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let mm = |l: &Levels| l.min_max.iter().flatten().copied().collect::<Vec<_>>();
    a.tiles_per_side == b.tiles_per_side
        && a.level_offsets == b.level_offsets
        && (a.width, a.height, a.root_lod, a.grid_size)
            == (b.width, b.height, b.root_lod, b.grid_size)
        && a.spacing.to_bits() == b.spacing.to_bits()
        && bits(&mm(a)) == bits(&mm(b))
        && bits(&a.tile_error) == bits(&b.tile_error)
        && e64(&a.level_error) == e64(&b.level_error)
}

/// A split field of `d` nodes per tile side whose cells are the `stored` tiles (grid `g`;
/// `field_density = d` at `d` times the grid): the cells' heights fold into the tiles' as
/// they are read, equal to folding them in memory, and the levels equal those computed from
/// the settings (the default's field). One node per corner at the stored grid reads the
/// stored tiles; at twice the grid (not stored) it folds them, no level-0 node read; grid 16
/// (not stored) is computed from level 0. Returns the `d`-node field as read.
fn field_reads_equal_the_computed_ones(
    reader: &PyramidReader,
    data: &Heightmap,
    stored: &vkterrain::dataset::stats::TileStats,
    d: u32,
) -> vkterrain::dataset::stats::FieldStats {
    use vkterrain::dataset::stats::{FieldStats, Finest, TileStats};
    use vkterrain::lod::udlod::settings::UdlodSettings;
    let g = stored.grid_size;
    let finer = UdlodSettings {
        grid_size: d * g,
        field_density: d,
        ..UdlodSettings::default()
    };
    let field = reader.field_stats(g, d).unwrap();
    assert_eq!(reader.node_loads(), 0);
    assert!(field.cells.is_some() && !field.tiles.has_finest());
    assert_eq!(field, FieldStats::from_cells(stored.clone(), d).unwrap());
    let field_levels = Levels::from_field_stats(field.clone(), reader.spacing());
    let from_settings = Levels::for_settings(data, &finer).unwrap();
    assert!(same(&field_levels, &from_settings));
    assert_eq!(
        bits(&field_levels.field_error),
        bits(&from_settings.field_error)
    );
    assert_eq!(
        reader.field_stats(g, 1).unwrap(),
        FieldStats::from_cells(stored.clone(), 1).unwrap()
    );
    let not_stored = |grid: u32| {
        reader
            .store()
            .stored_stats(grid, Finest::Skip)
            .unwrap()
            .is_none()
    };
    assert!(not_stored(2 * g));
    let corners = reader.field_stats(2 * g, 1).unwrap();
    assert_eq!(reader.node_loads(), 0);
    assert_eq!(
        corners,
        FieldStats::from_cells(TileStats::compute(data, 2 * g, &|_| {}).unwrap(), 1).unwrap()
    );
    assert!(not_stored(16));
    let s16 = reader.tile_stats(16, Finest::Skip).unwrap();
    assert!(same(
        &Levels::from_stats(s16, reader.spacing()),
        &Levels::new(data, 16).unwrap()
    ));
    field
}

/// UDLOD's statistics stored by `vkterrain preprocess` equal the ones computed from level 0,
/// bit for bit (and the sample-by-sample definition), so start-up reads no level 0; a grid
/// size that was not stored is computed from level 0 to the same bits, and twice a stored grid
/// folded from it; UDLOD's finer split field reads the stored tiles as its cells keeping
/// their errors only, to the same bits as reading them whole. The stored grid 2 omits level
/// 0's tiles (flagged in its header); a file with them reads back to the same bits. Negative
/// controls: one stored minimum moved by one ulp (still a valid file) makes the levels and the
/// folded read differ; a NaN is a one-line error naming the file, from either read; the
/// header's flag cleared or unknown is a one-line error.
#[test]
fn stored_tile_statistics_equal_the_computed_ones() {
    use vkterrain::dataset::preprocess;
    use vkterrain::dataset::stats::{Finest, TileStats};
    use vkterrain::lod::udlod::settings::UdlodSettings;
    let data = heightmap();
    let reader = PyramidReader::open(dataset()).unwrap();
    // Stored (the cells of UDLOD's default split field, which preprocess stores): no level-0
    // node read.
    let g = preprocess::DEFAULT_STATS_GRID_SIZES[0];
    let udlod = UdlodSettings::default();
    assert_eq!(g, udlod.grid_size / udlod.field_density());
    let file_name = format!("stats-g{g}.bin");
    // Stored without level 0's tiles (a grid below `FINEST_STORED_FROM_GRID`; UDLOD skips
    // them): the file's size says so, and a read that keeps level 0 finds them not stored.
    assert!(g < preprocess::FINEST_STORED_FROM_GRID);
    let (w, h) = (data.width, data.height);
    let stored_len = std::fs::metadata(dataset().join(&file_name)).unwrap().len();
    assert_eq!(stored_len, TileStats::stored_size(w, h, g, false).unwrap());
    assert!(stored_len < TileStats::stored_size(w, h, g, true).unwrap() / 3);
    assert!(
        reader
            .store()
            .stored_stats(g, Finest::Keep)
            .unwrap()
            .is_none()
    );
    let stored = reader
        .store()
        .stored_stats(g, Finest::Skip)
        .unwrap()
        .expect("default grid stored");
    assert_eq!(reader.node_loads(), 0);
    let from_disk = Levels::from_stats(stored.clone(), reader.spacing());
    let computed = Levels::new(&data, g).unwrap();
    assert!(same(&from_disk, &computed), "stored statistics differ");
    let (mm, te, le) = reference_statistics(&data, &computed);
    assert_eq!(bits(&mm), bits(&from_disk.min_max.concat()));
    assert_eq!(bits(&te), bits(&from_disk.tile_error));
    assert_eq!(le, from_disk.level_error);
    // In parallel over the pyramid's level file: the same bits.
    let par = TileStats::compute(&data, g, &|_| {}).unwrap();
    assert_eq!(par.clone().without_finest(), stored);
    // UDLOD's read: the same statistics, a quarter of the tiles held.
    let coarse = reader.tile_stats(g, Finest::Skip).unwrap();
    assert!(par.has_finest() && !coarse.has_finest());
    assert_eq!(coarse, stored);
    assert!(same(
        &Levels::from_stats(coarse, reader.spacing()),
        &from_disk
    ));
    let d = 2;
    let field = field_reads_equal_the_computed_ones(&reader, &data, &stored, d);

    // A stored minimum one ulp lower: a valid file whose levels differ.
    let moved = dataset().with_file_name("moved-stats");
    copy_dir(dataset(), &moved);
    let file = moved.join(&file_name);
    a_moved_minimum_and_a_nan_are_noticed(&moved, &stored, &field, &computed, g, d);
    stats_with_level_0_read_back(&moved, &par, &stored, (w, h), g);
    the_header_flag_must_match(&file, (w, h), g);
    std::fs::remove_dir_all(&moved).ok();
}

/// In a copy (`moved`) of the data set whose statistics `stored` are: one stored minimum one
/// ulp lower (still a valid file) makes the levels and the folded read (`field`, `d` cells
/// per tile side) differ from `computed`; a NaN there is a one-line error naming the file,
/// from either read.
fn a_moved_minimum_and_a_nan_are_noticed(
    moved: &Path,
    stored: &vkterrain::dataset::stats::TileStats,
    field: &vkterrain::dataset::stats::FieldStats,
    computed: &Levels,
    g: u32,
    d: u32,
) {
    use vkterrain::dataset::stats::Finest;
    let file_name = format!("stats-g{g}.bin");
    let file = moved.join(&file_name);
    let mut bytes = std::fs::read(&file).unwrap();
    let levels = stored.levels.len();
    // A tile of level 1 (the first stored; level 0's tiles are not part of `Levels`) whose
    // minimum is its field tile's, so the folded read must see it too: (min, max, error).
    let (cells, tiles) = (&stored.levels[1], &field.tiles.levels[1]);
    let pick = (0..cells.min_max.len())
        .find(|&i| {
            let (x, y) = (i as u32 % cells.tiles.0, i as u32 / cells.tiles.0);
            let t = (y / d * tiles.tiles.0 + x / d) as usize;
            cells.min_max[i][0] == tiles.min_max[t][0]
        })
        .unwrap();
    let first_tile = 40 + 16 * levels + 12 * pick;
    let v = f32::from_le_bytes(bytes[first_tile..first_tile + 4].try_into().unwrap());
    bytes[first_tile..first_tile + 4]
        .copy_from_slice(&f32::from_bits(v.to_bits() - 1).to_le_bytes());
    std::fs::write(&file, &bytes).unwrap();
    let mutated = PyramidReader::open(moved).unwrap();
    let m = mutated
        .store()
        .stored_stats(g, Finest::Skip)
        .unwrap()
        .unwrap();
    assert!(!same(&Levels::from_stats(m, mutated.spacing()), computed));
    let moved_field = mutated.field_stats(g, d).unwrap();
    assert_ne!(
        moved_field.tiles, field.tiles,
        "the folded read missed the change"
    );
    // A NaN: refused with a one-line error naming the file.
    bytes[first_tile..first_tile + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&file, &bytes).unwrap();
    let e = mutated.tile_stats(g, Finest::Skip).unwrap_err().to_string();
    assert!(e.contains(&file_name) && !e.contains('\n'), "{e}");
    let e = mutated.field_stats(g, d).unwrap_err().to_string();
    assert!(e.contains(&file_name) && !e.contains('\n'), "{e}");
}

/// A file with level 0's tiles (as grids from `FINEST_STORED_FROM_GRID` up are stored),
/// written and read back: the same bits; a NaN in its level 0 is refused where level 0 is
/// read, and UDLOD's read never looks at it.
fn stats_with_level_0_read_back(
    moved: &Path,
    par: &vkterrain::dataset::stats::TileStats,
    stored: &vkterrain::dataset::stats::TileStats,
    (w, h): (u32, u32),
    g: u32,
) {
    use vkterrain::dataset::stats::{Finest, TileStats};
    let levels = stored.levels.len();
    let full = moved.join("full-stats.bin");
    par.write(&full).unwrap();
    assert_eq!(
        std::fs::metadata(&full).unwrap().len(),
        TileStats::stored_size(w, h, g, true).unwrap()
    );
    assert_eq!(TileStats::read(&full, w, h, g, Finest::Keep).unwrap(), *par);
    assert_eq!(
        TileStats::read(&full, w, h, g, Finest::Skip).unwrap(),
        *stored
    );
    let mut bytes = std::fs::read(&full).unwrap();
    let level0_tile = 40 + 16 * levels + 12 * 5;
    bytes[level0_tile..level0_tile + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&full, &bytes).unwrap();
    let e = TileStats::read(&full, w, h, g, Finest::Keep)
        .unwrap_err()
        .to_string();
    assert!(e.contains("level 0") && !e.contains('\n'), "{e}");
    assert!(TileStats::read(&full, w, h, g, Finest::Skip).is_ok());
}

/// The header's flag (byte 36) must match the file: cleared on the stored file (which has
/// no level 0) it is a size mismatch, an unknown flag a one-line error (written to `file`).
fn the_header_flag_must_match(file: &Path, (w, h): (u32, u32), g: u32) {
    use vkterrain::dataset::stats::{Finest, TileStats};
    let file_name = format!("stats-g{g}.bin");
    let mut bytes = std::fs::read(dataset().join(&file_name)).unwrap();
    assert_eq!(bytes[36], 1, "the stored file flags level 0 omitted");
    for (flag, expect) in [(0u8, "truncated or altered"), (2, "unknown header flags")] {
        bytes[36] = flag;
        std::fs::write(file, &bytes).unwrap();
        let e = TileStats::read(file, w, h, g, Finest::Skip)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(expect) && e.contains(&file_name) && !e.contains('\n'),
            "{e}"
        );
    }
}
