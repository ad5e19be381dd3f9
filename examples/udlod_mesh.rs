//! The surface UDLOD draws, as the CPU mirror morphs it (`morph::morphed_vertex`, proven equal to
//! the GPU's in tests/udlod.rs): every tile the CPU reference selects with culling off, every
//! triangle of its full grid (quadrants uncollapsed: collapsing draws a subset of the same
//! surface). Per tau, over the flight's frames: the triangles, those inverted in the grid (a fold
//! of the morph), and the directed edges no triangle matches with the reverse edge, off the data's
//! border (0 for a closed surface: no gap between tiles or inside one). With `--pixel X,Y
//! --frame F` (one tau): the ray through that pixel's centre, the triangles it meets, those
//! covering the centre after snapping to 1/256 px with the depth llvmpipe would write there,
//! and the screen-space areas of the triangles near it (docs/udlod.md, "Open issues": the crack
//! pixel at grid 8, the main job's floating pixel). The flat world only (the scenario's grid
//! frame). CPU only.
//!
//!   cargo run --release --example udlod_mesh -- --config config/ci.toml [--frames 60] [--tau 0.5,1,2,4]
//!     [--grid 8] [--field-density 4] [--share 0.76] [--width 640 --height 360]
//!     [--pixel 217,114 --frame 7] [--split main]
//!
//! `--split main` is a what-if the renderer does not draw: each quad split along its diagonal
//! from (0, 0) to (1, 1) instead of the drawn one from (1, 0) to (0, 1) (the positions
//! unchanged), to count the triangles that split would invert.

use std::collections::HashMap;
use std::path::PathBuf;

use glam::DVec3;
use vkterrain::cli::render::{RenderArgs, prepare};
use vkterrain::dataset::Heightmap;
use vkterrain::lod::udlod::levels::{Levels, Tile};
use vkterrain::lod::udlod::morph;
use vkterrain::lod::udlod::params::SelectionParams;
use vkterrain::lod::udlod::select;
use vkterrain::lod::{MethodConfig, UdlodSettings};
use vkterrain::scene::Camera;

fn main() -> anyhow::Result<()> {
    let args = Args::parse()?;
    let p = prepare(&RenderArgs {
        config: args.config.clone(),
        width: args.width,
        height: args.height,
        ..Default::default()
    })?;
    let data = p.data.require_grid("udlod_mesh")?.clone();
    let mut settings = match &p.config.method {
        MethodConfig::Udlod(s) => s.clone(),
        _ => UdlodSettings::default(),
    };
    settings.grid_size = args.grid.unwrap_or(settings.grid_size);
    settings.field_density = args.field_density.unwrap_or(settings.field_density);
    settings.worst_case_share = args.share.unwrap_or(settings.worst_case_share);
    settings.cull = false;
    settings.validate()?;
    let levels = Levels::for_settings(&*data, &settings)?;
    let view = View {
        width: p.config.render.width,
        height: p.config.render.height,
    };
    println!(
        "{} {}x{}; grid {} field density {}; {}x{}",
        data.name,
        data.width,
        data.height,
        settings.grid_size,
        settings.field_density(),
        view.width,
        view.height
    );
    for &tau in &args.taus {
        let s = UdlodSettings {
            tau_px: tau,
            ..settings.clone()
        };
        if let Some((px, py)) = args.pixel {
            let cam = p.scenario.camera(args.frame);
            let mesh = Mesh::of_view(&levels, &data, &s, &cam, view, args.split);
            print_pixel(&mesh, &cam, view, [px as f64 + 0.5, py as f64 + 0.5]);
            continue;
        }
        let frames = args.frames.unwrap_or(p.frames as u64);
        let mut total = Counts::default();
        for frame in 0..frames {
            let cam = p.scenario.camera(frame);
            let c = Mesh::of_view(&levels, &data, &s, &cam, view, args.split).counts(&levels);
            if c.open_edges > 0 {
                println!("  tau {tau} frame {frame}: {} open edges", c.open_edges);
            }
            total.add(&c);
        }
        println!(
            "tau {tau}: {frames} frames, {} triangles, {} inverted in the grid ({:.3} %), {} open edges",
            total.triangles,
            total.inverted,
            100.0 * total.inverted as f64 / total.triangles.max(1) as f64,
            total.open_edges
        );
    }
    Ok(())
}

struct Args {
    config: Option<PathBuf>,
    frames: Option<u64>,
    taus: Vec<f64>,
    grid: Option<u32>,
    field_density: Option<u32>,
    share: Option<f64>,
    width: Option<u32>,
    height: Option<u32>,
    pixel: Option<(u32, u32)>,
    frame: u64,
    split: Split,
}

/// Which diagonal splits each quad.
#[derive(Clone, Copy, PartialEq)]
enum Split {
    /// From (1, 0) to (0, 1): what UDLOD draws (the index grid, `grid::IndexLayout`), the
    /// statistics and the reference surface assume (`interp::triangulated`).
    Anti,
    /// From (0, 0) to (1, 1): a what-if.
    Main,
}

impl Args {
    fn parse() -> anyhow::Result<Self> {
        let mut a = Args {
            config: None,
            frames: None,
            taus: vec![0.5, 1.0, 2.0, 4.0],
            grid: None,
            field_density: None,
            share: None,
            width: None,
            height: None,
            pixel: None,
            frame: 0,
            split: Split::Anti,
        };
        let mut it = std::env::args().skip(1);
        while let Some(flag) = it.next() {
            let value = it
                .next()
                .ok_or_else(|| anyhow::anyhow!("{flag} needs a value"))?;
            match flag.as_str() {
                "--config" => a.config = Some(PathBuf::from(value)),
                "--frames" => a.frames = Some(parse(&flag, &value)?),
                "--tau" => {
                    a.taus = value
                        .split(',')
                        .map(|t| parse(&flag, t))
                        .collect::<anyhow::Result<_>>()?
                }
                "--grid" => a.grid = Some(parse(&flag, &value)?),
                "--field-density" => a.field_density = Some(parse(&flag, &value)?),
                "--share" => a.share = Some(parse(&flag, &value)?),
                "--width" => a.width = Some(parse(&flag, &value)?),
                "--height" => a.height = Some(parse(&flag, &value)?),
                "--frame" => a.frame = parse(&flag, &value)?,
                "--pixel" => {
                    let (x, y) = value
                        .split_once(',')
                        .ok_or_else(|| anyhow::anyhow!("--pixel {value:?}: X,Y"))?;
                    a.pixel = Some((parse(&flag, x)?, parse(&flag, y)?));
                }
                "--split" => {
                    a.split = match value.as_str() {
                        "anti" => Split::Anti,
                        "main" => Split::Main,
                        _ => anyhow::bail!("--split {value:?}: anti or main"),
                    }
                }
                _ => anyhow::bail!("unknown argument {flag}"),
            }
        }
        if a.pixel.is_some() && a.taus.len() != 1 {
            anyhow::bail!("--pixel needs one --tau");
        }
        Ok(a)
    }
}

fn parse<T: std::str::FromStr>(flag: &str, text: &str) -> anyhow::Result<T>
where
    T::Err: std::fmt::Display,
{
    text.parse()
        .map_err(|e| anyhow::anyhow!("{flag} {text:?}: {e}"))
}

#[derive(Clone, Copy)]
struct View {
    width: u32,
    height: u32,
}

/// One triangle of a tile's full grid: its tile, quad `(i, j)` and half `k` (0: the
/// `(0,0) (1,0) (0,1)` half, 1: `(1,0) (1,1) (0,1)`, the index grid's order; with
/// [`Split::Main`] `(0,0) (1,0) (1,1)` and `(0,0) (1,1) (0,1)`), its morphed
/// positions in samples, and the same in metres with the data's height there.
struct Triangle {
    tile: Tile,
    quad: (u32, u32),
    half: usize,
    grid: [[f32; 2]; 3],
    world: [DVec3; 3],
}

struct Mesh {
    triangles: Vec<Triangle>,
}

#[derive(Default)]
struct Counts {
    triangles: usize,
    inverted: usize,
    open_edges: usize,
}

impl Counts {
    fn add(&mut self, o: &Counts) {
        self.triangles += o.triangles;
        self.inverted += o.inverted;
        self.open_edges += o.open_edges;
    }
}

impl Mesh {
    fn of_view(
        levels: &Levels,
        data: &Heightmap,
        s: &UdlodSettings,
        cam: &Camera,
        view: View,
        split: Split,
    ) -> Self {
        let p = SelectionParams::new(levels, data, s, cam, cam.position, view.width, view.height);
        let n = levels.grid_size;
        let mut triangles = Vec::new();
        for tile in select::select_tiles(levels, &p) {
            let vertex =
                |i: u32, j: u32| morph::morphed_vertex(levels, &p, tile, [i, j]).grid_pos();
            let grid: Vec<Vec<[f32; 2]>> = (0..=n)
                .map(|j| (0..=n).map(|i| vertex(i, j)).collect())
                .collect();
            for (j, i) in (0..n as usize).flat_map(|j| (0..n as usize).map(move |i| (j, i))) {
                let [c00, c10, c01, c11] = [
                    grid[j][i],
                    grid[j][i + 1],
                    grid[j + 1][i],
                    grid[j + 1][i + 1],
                ];
                let halves = match split {
                    Split::Anti => [[c00, c10, c01], [c10, c11, c01]],
                    Split::Main => [[c00, c10, c11], [c00, c11, c01]],
                };
                for (half, g) in halves.into_iter().enumerate() {
                    triangles.push(Triangle {
                        tile,
                        quad: (i as u32, j as u32),
                        half,
                        grid: g,
                        world: g.map(|v| world(data, v)),
                    });
                }
            }
        }
        Mesh { triangles }
    }

    /// Triangles, those inverted in the grid, and directed edges (between distinct positions,
    /// bit for bit) not matched by a reverse edge, off the data's border.
    fn counts(&self, levels: &Levels) -> Counts {
        let key = |v: [f32; 2]| (v[0].to_bits(), v[1].to_bits());
        // Per undirected edge (lower position first), its uses: +1 one way, -1 the other.
        let mut edges: HashMap<(PositionBits, PositionBits), i32> = HashMap::new();
        let mut inverted = 0;
        for t in &self.triangles {
            if grid_area(t.grid) < 0.0 {
                inverted += 1;
            }
            for (a, b) in [(0, 1), (1, 2), (2, 0)].map(|(a, b)| (key(t.grid[a]), key(t.grid[b]))) {
                match a.cmp(&b) {
                    std::cmp::Ordering::Less => *edges.entry((a, b)).or_default() += 1,
                    std::cmp::Ordering::Greater => *edges.entry((b, a)).or_default() -= 1,
                    std::cmp::Ordering::Equal => {}
                }
            }
        }
        let last = [(levels.width - 1) as f32, (levels.height - 1) as f32];
        let on_border = |a: [f32; 2], b: [f32; 2]| {
            (0..2).any(|i| (a[i] == 0.0 && b[i] == 0.0) || (a[i] == last[i] && b[i] == last[i]))
        };
        let unkey = |k: (u32, u32)| [f32::from_bits(k.0), f32::from_bits(k.1)];
        let open_edges = edges
            .iter()
            .filter(|&(&(a, b), &count)| count != 0 && !on_border(unkey(a), unkey(b)))
            .count();
        Counts {
            triangles: self.triangles.len(),
            inverted,
            open_edges,
        }
    }
}

/// A morphed position's bits: equal positions are equal keys.
type PositionBits = (u32, u32);

/// A position in samples as metres in the grid frame, at the data's height there.
fn world(data: &Heightmap, v: [f32; 2]) -> DVec3 {
    let (x, y) = (v[0] as f64 * data.spacing, v[1] as f64 * data.spacing);
    DVec3::new(x, y, data.height_at(x, y))
}

/// Twice the signed area in the grid (positive for the unmorphed grid's triangles).
fn grid_area(g: [[f32; 2]; 3]) -> f64 {
    let [a, b, c] = g.map(|v| [v[0] as f64, v[1] as f64]);
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Where the camera sees a point, in pixels (x right, y down).
fn screen(cam: &Camera, view: View, v: DVec3) -> [f64; 2] {
    let (right, up, forward) = cam.basis();
    let f = cam.focal_px(view.height);
    let d = v - cam.position;
    let z = forward.dot(d);
    [
        f * right.dot(d) / z + view.width as f64 / 2.0,
        view.height as f64 / 2.0 - f * up.dot(d) / z,
    ]
}

/// The triangles the ray through `pixel` (centre, in pixels) meets, nearest first, and the
/// screen-space area of every triangle of those tiles within two pixels of it.
fn print_pixel(mesh: &Mesh, cam: &Camera, view: View, pixel: [f64; 2]) {
    let dir = cam.pixel_ray(pixel[0], pixel[1], view.width, view.height);
    let mut hits: Vec<(f64, &Triangle, [f64; 3])> = mesh
        .triangles
        .iter()
        .filter_map(|t| ray_hit(cam.position, dir, t.world).map(|(d, bary)| (d, t, bary)))
        .collect();
    hits.sort_by(|a, b| a.0.total_cmp(&b.0));
    println!(
        "pixel centre {pixel:?}: the ray meets {} triangles",
        hits.len()
    );
    for (d, t, bary) in &hits {
        println!(
            "  at {d:.1} m: tile {:?} quad {:?} half {}, barycentric {:.5} / {:.5} / {:.5}",
            t.tile, t.quad, t.half, bary[0], bary[1], bary[2]
        );
    }
    print_raster_candidates(mesh, cam, view, pixel);
    for (_, hit, _) in hits.iter().take(1) {
        println!(
            "  triangles of tile {:?} within 2 px (twice the signed area, screen px² / grid samples²):",
            hit.tile
        );
        for t in mesh.triangles.iter().filter(|t| t.tile == hit.tile) {
            let s = t.world.map(|v| screen(cam, view, v));
            let near = s.iter().any(|v| (v[1] - pixel[1]).abs() <= 2.0)
                && s.iter().map(|v| v[0]).fold(f64::INFINITY, f64::min) <= pixel[0] + 2.0
                && s.iter().map(|v| v[0]).fold(f64::NEG_INFINITY, f64::max) >= pixel[0] - 2.0;
            if near {
                let area = (s[1][0] - s[0][0]) * (s[2][1] - s[0][1])
                    - (s[1][1] - s[0][1]) * (s[2][0] - s[0][0]);
                println!(
                    "    quad {:?} half {}: screen {area:.6}, grid {:.3}; screen {:.4?}",
                    t.quad,
                    t.half,
                    grid_area(t.grid),
                    s
                );
            }
        }
    }
}

/// How a rasterizer may see the pixel: the triangles whose screen positions, snapped to 1/256
/// px (llvmpipe's subpixel precision), cover its centre, with the view depth interpolated
/// there over the snapped triangle and over the unsnapped one (1/w linear in screen space).
/// llvmpipe tests coverage in fixed point but sets up depth from the unsnapped vertices, so a
/// sliver seen edge-on that covers a pixel centre only after snapping writes its plane's
/// extrapolation there (docs/udlod.md, "Open issues": a floating pixel on llvmpipe).
fn print_raster_candidates(mesh: &Mesh, cam: &Camera, view: View, pixel: [f64; 2]) {
    let (_, _, forward) = cam.basis();
    let edge = |a: [f64; 2], b: [f64; 2], p: [f64; 2]| {
        (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
    };
    // The view depth at `pixel` over triangle `s` (screen), and its doubled signed area.
    let depth_at = |s: [[f64; 2]; 3], inv_w: [f64; 3]| {
        let area = edge(s[0], s[1], s[2]);
        let w = [
            edge(s[1], s[2], pixel) / area,
            edge(s[2], s[0], pixel) / area,
            edge(s[0], s[1], pixel) / area,
        ];
        (
            1.0 / (w[0] * inv_w[0] + w[1] * inv_w[1] + w[2] * inv_w[2]),
            area,
            w,
        )
    };
    println!(
        "  triangles covering it after snapping to 1/256 px (view depth there over the snapped triangle; over the unsnapped one, as llvmpipe sets up depth):"
    );
    for t in &mesh.triangles {
        let inv_w = t.world.map(|v| 1.0 / forward.dot(v - cam.position));
        if inv_w.iter().any(|&w| w <= 0.0) {
            // Behind the camera: clipped before rasterization.
            continue;
        }
        let exact = t.world.map(|v| screen(cam, view, v));
        let snapped = exact.map(|v| v.map(|c| (c * 256.0).round() / 256.0));
        if edge(snapped[0], snapped[1], snapped[2]) == 0.0 {
            continue;
        }
        let (depth, area, w) = depth_at(snapped, inv_w);
        if w.iter().all(|&b| b >= 0.0) {
            let (plane_depth, plane_area, _) = depth_at(exact, inv_w);
            println!(
                "    tile {:?} quad {:?} half {}: {depth:.1} m; {plane_depth:.1} m; twice the screen area {area:.3e} / {plane_area:.3e} px², weights {w:.4?}, snapped {snapped:.4?}",
                t.tile, t.quad, t.half
            );
        }
    }
}

/// Distance along `dir` (unit) from `origin` to triangle `w` and the barycentric weights of the
/// hit (Moller-Trumbore in f64), if the ray meets it.
fn ray_hit(origin: DVec3, dir: DVec3, w: [DVec3; 3]) -> Option<(f64, [f64; 3])> {
    let (e1, e2) = (w[1] - w[0], w[2] - w[0]);
    let pv = dir.cross(e2);
    let det = e1.dot(pv);
    if det.abs() < 1e-12 {
        return None;
    }
    let tv = origin - w[0];
    let u = tv.dot(pv) / det;
    let qv = tv.cross(e1);
    let v = dir.dot(qv) / det;
    let d = e2.dot(qv) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && d > 0.0).then_some((d, [1.0 - u - v, u, v]))
}
