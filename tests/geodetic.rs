//! The terrain's true geometry on the WGS84 ellipsoid (issue 14, docs/coordinates.md
//! "Geodetic geometry"): the geolocation lattice on the GPU equals its CPU mirror and the GLSL
//! port; the horizon dips as the ellipsoid says; spikes at known latitude/longitude/height
//! project where independent f64 geodesy puts them; a camera far from the world origin moving
//! 1 mm per frame sees the centre pixel's depth change by 1 mm. The oracles' geodesy (WGS84
//! to ECEF, ENU rotation, radii of curvature) is written out in this file, not taken from the
//! code under test. Negative controls: the flat world fails the horizon and landmark checks.

mod common;

use std::sync::Arc;

use glam::{DVec2, DVec3};
use vkterrain::dataset::Heightmap;
use vkterrain::driver::Gpu;
use vkterrain::driver::shaders::{Spirv, TERRAIN_PROBE_COMP_SPV, TERRAIN_PROBE_SPV};
use vkterrain::geo::Lattice;
use vkterrain::lod::{MethodConfig, MethodKind, PgmSettings, UdlodSettings};
use vkterrain::readback::{CollectSink, OwnedFrame};
use vkterrain::render::{FrameRequest, Renderer, TerrainProbePoint};
use vkterrain::scene::Camera;

// ---- Independent f64 geodesy (the oracle) -------------------------------------------------

const A: f64 = 6_378_137.0;
const F: f64 = 1.0 / 298.257_223_563;

fn e2() -> f64 {
    F * (2.0 - F)
}

fn ecef(lat_deg: f64, lon_deg: f64, h: f64) -> DVec3 {
    let (lat, lon) = (lat_deg.to_radians(), lon_deg.to_radians());
    let n = A / (1.0 - e2() * lat.sin().powi(2)).sqrt();
    DVec3::new(
        (n + h) * lat.cos() * lon.cos(),
        (n + h) * lat.cos() * lon.sin(),
        (n * (1.0 - e2()) + h) * lat.sin(),
    )
}

/// World (ENU at `lat0, lon0`, height 0) coordinates of a geodetic point.
fn enu(lat0: f64, lon0: f64, lat: f64, lon: f64, h: f64) -> DVec3 {
    let (p, l) = (lat0.to_radians(), lon0.to_radians());
    let east = DVec3::new(-l.sin(), l.cos(), 0.0);
    let north = DVec3::new(-p.sin() * l.cos(), -p.sin() * l.sin(), p.cos());
    let up = DVec3::new(p.cos() * l.cos(), p.cos() * l.sin(), p.sin());
    let d = ecef(lat, lon, h) - ecef(lat0, lon0, 0.0);
    DVec3::new(d.dot(east), d.dot(north), d.dot(up))
}

/// Radius of curvature of the normal section at `azimuth_deg` (Euler).
fn radius_in_azimuth(lat_deg: f64, azimuth_deg: f64) -> f64 {
    let s2 = lat_deg.to_radians().sin().powi(2);
    let w = (1.0 - e2() * s2).sqrt();
    let m = A * (1.0 - e2()) / (w * w * w);
    let n = A / w;
    let az = azimuth_deg.to_radians();
    1.0 / (az.cos().powi(2) / m + az.sin().powi(2) / n)
}

/// Metres per degree of latitude at `lat_deg` (the meridian radius).
fn metres_per_deg_lat(lat_deg: f64) -> f64 {
    let w2 = 1.0 - e2() * lat_deg.to_radians().sin().powi(2);
    (A * (1.0 - e2()) / (w2 * w2.sqrt())).to_radians()
}

/// Metres per degree of longitude at `lat_deg` (the parallel's radius).
fn metres_per_deg_lon(lat_deg: f64) -> f64 {
    let lat = lat_deg.to_radians();
    (A / (1.0 - e2() * lat.sin().powi(2)).sqrt() * lat.cos()).to_radians()
}

/// Pixel (x right, y down, continuous; pixel centres at +0.5) of a world point.
fn pixel_of(camera: &Camera, p: DVec3, width: u32, height: u32) -> DVec2 {
    let (right, up, forward) = camera.basis();
    let d = p - camera.position;
    let f = camera.focal_px(height);
    DVec2::new(
        width as f64 / 2.0 + f * d.dot(right) / d.dot(forward),
        height as f64 / 2.0 - f * d.dot(up) / d.dot(forward),
    )
}

/// Pixel of a probed clip position (WebGPU clip space, y up).
fn pixel_of_clip(clip: [f32; 4], width: u32, height: u32) -> DVec2 {
    let (x, y, w) = (clip[0] as f64, clip[1] as f64, clip[3] as f64);
    DVec2::new(
        (x / w * 0.5 + 0.5) * width as f64,
        (0.5 - y / w * 0.5) * height as f64,
    )
}

/// EGM96 undulations `N` (metres, geoid above the ellipsoid) at `(lat, lon)` points, straight
/// from PROJ through GDAL's OSR (`EPSG:4979 -> EPSG:4326+5773`, `H = h - N`), pinned by
/// `cs2cs`'s value at 42.5 N 1.5 E.
#[cfg(feature = "gdal")]
fn egm96_undulations(points: &[(f64, f64)]) -> Vec<f64> {
    use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};
    let mut from = SpatialRef::from_epsg(4979).unwrap();
    let mut to = SpatialRef::from_definition("EPSG:4326+5773").unwrap();
    from.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    to.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    let t = CoordTransform::new(&from, &to).unwrap();
    let mut x: Vec<f64> = [1.5]
        .into_iter()
        .chain(points.iter().map(|p| p.1))
        .collect();
    let mut y: Vec<f64> = [42.5]
        .into_iter()
        .chain(points.iter().map(|p| p.0))
        .collect();
    let mut z = vec![0.0; x.len()];
    t.transform_coords(&mut x, &mut y, &mut z).unwrap();
    // `echo 42.5 1.5 0 | cs2cs EPSG:4979 EPSG:4326+5773` gives -52.828.
    assert!(
        (z[0] + 52.828).abs() < 0.001,
        "EGM96 at 42.5 N 1.5 E: {}",
        -z[0]
    );
    z[1..].iter().map(|v| -v).collect()
}

// ---- Rendering helpers ---------------------------------------------------------------------

/// A geographic grid: sample (col, row) at latitude `lat0 + row * d`, longitude
/// `lon0 + col * d`, heights from `h(lat, lon)`; spacing: the north-south metres (texturing
/// and the flat control only).
fn geographic(size: u32, lat0: f64, lon0: f64, d: f64, h: &dyn Fn(f64, f64) -> f64) -> Heightmap {
    geographic_steps(size, lat0, lon0, [d, d], h)
}

/// [`geographic`] with `[longitude, latitude]` steps in degrees.
fn geographic_steps(
    size: u32,
    lat0: f64,
    lon0: f64,
    d: [f64; 2],
    h: &dyn Fn(f64, f64) -> f64,
) -> Heightmap {
    let mut heights = Vec::with_capacity((size * size) as usize);
    for r in 0..size {
        for c in 0..size {
            heights.push(h(lat0 + r as f64 * d[1], lon0 + c as f64 * d[0]) as f32);
        }
    }
    Heightmap::new(
        "geographic",
        size,
        size,
        d[1] * metres_per_deg_lat(lat0),
        heights,
    )
    .unwrap()
}

struct Rendered {
    frames: Vec<OwnedFrame>,
    renderer: Renderer,
}

fn render(
    gpu: &Arc<Gpu>,
    data: &Heightmap,
    method: impl Into<MethodConfig>,
    lattice: Option<&Lattice>,
    (width, height): (u32, u32),
    cameras: &[Camera],
) -> Rendered {
    let mut sink = CollectSink::default();
    let mut renderer = Renderer::with_world(
        gpu,
        data,
        method,
        common::options(width, height, 2),
        None,
        lattice,
    )
    .expect("renderer");
    for c in cameras {
        renderer.render(FrameRequest::from(*c), &mut sink).unwrap();
    }
    renderer.finish(&mut sink).unwrap();
    Rendered {
        frames: sink.frames,
        renderer,
    }
}

/// [`probe`] with the WGSL terrain probe built for `r`'s terrain (its world and source of
/// heights).
fn probe_wgsl(r: &Renderer, pts: &[([i32; 2], [f32; 2])]) -> Vec<TerrainProbePoint> {
    probe(
        r,
        TERRAIN_PROBE_SPV.variant(r.terrain_variant()),
        c"probe_main",
        pts,
    )
}

fn probe(
    r: &Renderer,
    spv: Spirv,
    entry: &std::ffi::CStr,
    pts: &[([i32; 2], [f32; 2])],
) -> Vec<TerrainProbePoint> {
    let points: Vec<TerrainProbePoint> = pts
        .iter()
        .map(|(cell, frac)| TerrainProbePoint {
            cell: [cell[0], cell[1], 0, 0],
            pos: [
                cell[0] as f32 + frac[0],
                cell[1] as f32 + frac[1],
                frac[0],
                frac[1],
            ],
            ..Default::default()
        })
        .collect();
    r.probe_terrain_helpers(0, spv, entry, &points).unwrap()
}

/// SRTM3 N42E001 from `../shared/data` preprocessed (`vkterrain preprocess`) into a fresh
/// directory under the system's temporary directory named `name` and this process: (that
/// directory, the source `.hgt.zip`, the data set).
#[cfg(feature = "gdal")]
fn srtm3_n42e001(name: &str) -> (std::path::PathBuf, std::path::PathBuf, std::path::PathBuf) {
    use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options};
    let data_dir = common::shared_data().expect("../shared/data (the real data; CI has it)");
    let tmp = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
    let out = tmp.join("n42e001");
    let zip = data_dir.join("srtm/N42E001.hgt.zip");
    let options = Options {
        input: Input::Files(vec![zip.clone()]),
        out: out.clone(),
        force: true,
        ..Default::default()
    };
    preprocess::run(&options, &NoProgress).unwrap();
    (tmp, zip, out)
}

// ---- Tests ---------------------------------------------------------------------------------

#[test]
fn gpu_projection_equals_the_cpu_mirror_and_the_glsl_port() {
    let gpu = common::gpu(false);
    // 257 x 257 samples of 100 m with hills, anchored at 45 N 7 E (a local data set on the
    // earth: the plane dropped onto the ellipsoid).
    let (size, spacing) = (257u32, 100.0);
    let heights: Vec<f32> = (0..size * size)
        .map(|i| {
            let (c, r) = ((i % size) as f32, (i / size) as f32);
            300.0 + 200.0 * (c * 0.05).sin() * (r * 0.04).cos()
        })
        .collect();
    let data = Heightmap::new("hills", size, size, spacing, heights).unwrap();
    let frame = vkterrain::geo::EnuFrame::new(
        &vkterrain::geo::WGS84,
        vkterrain::geo::Geodetic::new(45.0, 7.0, 0.0),
    );
    let lattice = Lattice::anchored_plane(size, size, spacing, frame).unwrap();
    assert_eq!(lattice.step, 5);
    let camera = Camera {
        position: DVec3::new(3000.0, 2000.0, 1500.0),
        yaw_deg: 40.0,
        pitch_deg: -8.0,
        vfov_deg: 50.0,
        far: 1e6,
        ..Camera::default()
    };
    let (w, h) = (320u32, 200u32);
    let r = render(
        &gpu,
        &data,
        MethodKind::Brute,
        Some(&lattice),
        (w, h),
        &[camera],
    );
    // Every 7th sample, plus fractions between samples (UDLOD's morphs).
    let mut pts = Vec::new();
    for row in (0..size as i32).step_by(7) {
        for col in (0..size as i32).step_by(7) {
            pts.push(([col, row], [0.0, 0.0]));
            pts.push(([col, row], [0.37, 0.81]));
        }
    }
    let wgsl = probe_wgsl(&r.renderer, &pts);
    let glsl_spv = TERRAIN_PROBE_COMP_SPV.variant(r.renderer.terrain_variant());
    let glsl = probe(&r.renderer, glsl_spv, c"main", &pts);
    let differing = wgsl.iter().zip(&glsl).filter(|(a, b)| a != b).count();
    assert_eq!(
        differing, 0,
        "GLSL port differs from the WGSL on the lattice"
    );
    let view_proj = (camera.projection(w as f64 / h as f64) * camera.view_rotation()).as_dmat4();
    let (mut worst_px, mut worst_depth, mut worst_flat) = (0.0f64, 0.0f64, 0.0f64);
    let mut compared = 0;
    for ((cell, frac), got) in pts.iter().zip(&wgsl) {
        let s = DVec2::new(
            cell[0] as f64 + frac[0] as f64,
            cell[1] as f64 + frac[1] as f64,
        );
        let height = got.heights[1] as f64;
        let rel = lattice.position(s, height) - camera.position;
        let clip = view_proj * rel.extend(1.0);
        // In view (or just outside): far off-screen, a pixel is a tiny angle and f32 clip
        // coordinates resolve it to ~1e-6 of the pixel coordinate, not to 0.01 px.
        let ndc = clip.truncate().truncate() / clip.w;
        if clip.w < 10.0 || ndc.abs().max_element() > 1.2 {
            continue;
        }
        compared += 1;
        let cpu = pixel_of_clip(clip.as_vec4().to_array(), w, h);
        let gpu_px = pixel_of_clip(got.clip, w, h);
        worst_px = worst_px.max((cpu - gpu_px).length());
        worst_depth = worst_depth.max((clip.w - got.clip[3] as f64).abs() / clip.w);
        // The flat world's position of the same point (the negative control).
        let flat = DVec3::new(s.x * spacing, s.y * spacing, height) - camera.position;
        let fclip = view_proj * flat.extend(1.0);
        worst_flat =
            worst_flat.max((pixel_of_clip(fclip.as_vec4().to_array(), w, h) - gpu_px).length());
    }
    println!(
        "lattice GPU vs CPU: {compared} points, worst {worst_px:.2e} px, depth rel {worst_depth:.2e}; flat world off by up to {worst_flat:.2} px"
    );
    assert!(compared > 200, "{compared}");
    assert!(worst_px < 0.01, "GPU and CPU differ by {worst_px} px");
    assert!(
        worst_depth < 1e-5,
        "GPU and CPU depth differ by {worst_depth} relative"
    );
    assert!(
        worst_flat > 0.2,
        "the flat world should differ: {worst_flat} px"
    );
    drop(r);
    common::assert_no_validation_messages(&gpu);
}

/// Row (continuous, y down) where the centre column turns from sky to terrain: the top edge
/// of the first terrain pixel.
fn horizon_row(frame: &OwnedFrame) -> f64 {
    let x = frame.width / 2;
    (0..frame.height)
        .find(|&y| frame.depth_at(x, y).expect("depth") > 0.0)
        .expect("terrain in the centre column") as f64
}

#[test]
fn horizon_dips_as_the_ellipsoid_says() {
    let gpu = common::gpu(false);
    // Sea level (all heights 0) on a geographic grid: 45..55.24 N, 7..17.24 E, 0.02 deg.
    let (size, lat0, lon0, d) = (513u32, 45.0, 7.0, 0.02);
    let data = geographic(size, lat0, lon0, d, &|_, _| 0.0);
    let lattice = Lattice::geographic(size, size, [lon0, lat0], [d, d]).unwrap();
    let (w, h) = (64u32, 400u32);
    let azimuth = 30.0;
    // Level cameras over sample (0, 0) (the world origin) looking north-north-east into the
    // data, 8 deg vertical field of view (0.02 deg per pixel).
    let cameras: Vec<Camera> = [100.0, 1000.0, 10_000.0]
        .iter()
        .map(|&alt| Camera {
            position: DVec3::new(0.0, 0.0, alt),
            yaw_deg: azimuth,
            pitch_deg: 0.0,
            vfov_deg: 8.0,
            near: 1.0,
            far: 2e6,
            ..Camera::default()
        })
        .collect();
    let geo = render(
        &gpu,
        &data,
        MethodKind::Brute,
        Some(&lattice),
        (w, h),
        &cameras,
    );
    let flat = render(&gpu, &data, MethodKind::Brute, None, (w, h), &cameras);
    let r = radius_in_azimuth(lat0, azimuth);
    for (i, c) in cameras.iter().enumerate() {
        let alt = c.position.z;
        let dip = (r / (r + alt)).acos();
        let expected = h as f64 / 2.0 + c.focal_px(h) * dip.tan();
        let got = horizon_row(&geo.frames[i]);
        let got_flat = horizon_row(&flat.frames[i]);
        println!(
            "h = {alt} m: dip {:.4} deg, horizon row expected {expected:.2}, geodetic {got}, flat {got_flat}",
            dip.to_degrees()
        );
        assert!(
            (got - expected).abs() <= 0.5,
            "h = {alt} m: horizon at row {got}, the ellipsoid says {expected:.2}"
        );
        if alt >= 1000.0 {
            // Negative control: the flat earth's horizon is the data's far edge, far too high.
            assert!(
                (got_flat - expected).abs() > 5.0,
                "h = {alt} m: the flat world passed ({got_flat} vs {expected:.2})"
            );
        }
    }
    drop((geo, flat));
    common::assert_no_validation_messages(&gpu);
}

/// Three one-sample spikes (grid sample, height) on 20 m flat ground.
const SPIKES: [([i32; 2], f64); 3] = [([64, 64], 1500.0), ([200, 40], 800.0), ([128, 220], 2500.0)];

/// A `size`² geographic grid of `d`-degree steps from `[lat0, lon0]` with [`SPIKES`].
fn spiky_grid(size: u32, [lat0, lon0]: [f64; 2], d: f64) -> Heightmap {
    let heights = |la: f64, lo: f64| {
        for (s, hgt) in SPIKES {
            let (sl, so) = (lat0 + s[1] as f64 * d, lon0 + s[0] as f64 * d);
            if (la - sl).abs() < d / 2.0 && (lo - so).abs() < d / 2.0 {
                return hgt;
            }
        }
        20.0
    };
    geographic(size, lat0, lon0, d, &heights)
}

#[test]
fn landmark_spikes_project_where_f64_geodesy_puts_them() {
    let spikes = SPIKES;
    let gpu = common::gpu(false);
    let (size, d) = (257u32, 0.001);
    let (w, h) = (1024u32, 768u32);
    for lat0 in [0.0, 45.0, 70.0] {
        let lon0 = 10.0;
        // Spikes at three samples; heights above the ellipsoid.
        let data = spiky_grid(size, [lat0, lon0], d);
        let lattice = Lattice::geographic(size, size, [lon0, lat0], [d, d]).unwrap();
        for dist_km in [1.0, 10.0, 50.0, 200.0] {
            let (camera, tip, _) = camera_beside_spike([lat0, lon0], d, spikes[0], dist_km);
            let geo = render(
                &gpu,
                &data,
                MethodKind::Brute,
                Some(&lattice),
                (w, h),
                &[camera],
            );
            let flat = render(&gpu, &data, MethodKind::Brute, None, (w, h), &[camera]);
            let pts: Vec<_> = spikes.iter().map(|(s, _)| (*s, [0.0f32, 0.0])).collect();
            let got = probe_wgsl(&geo.renderer, &pts);
            let got_flat = probe_wgsl(&flat.renderer, &pts);
            for (k, (s, hs)) in spikes.iter().enumerate() {
                let p = enu(
                    lat0,
                    lon0,
                    lat0 + s[1] as f64 * d,
                    lon0 + s[0] as f64 * d,
                    *hs,
                );
                let expected = pixel_of(&camera, p, w, h);
                let px = pixel_of_clip(got[k].clip, w, h);
                let px_flat = pixel_of_clip(got_flat[k].clip, w, h);
                let err = (px - expected).length();
                println!(
                    "lat {lat0} cam {dist_km} km spike {k}: expected {expected:.2}, got {px:.2} (err {err:.3} px), flat err {:.1} px",
                    (px_flat - expected).length()
                );
                assert_eq!(got[k].heights[0], *hs as f32, "the spike's height");
                assert!(err <= 0.5, "lat {lat0}, {dist_km} km, spike {k}: {err} px");
                if dist_km <= 50.0 {
                    // Negative control. (From 200 km a spike 3 km below the camera is seen
                    // at a few degrees; the flat world's errors shrink there to ~1 px.)
                    assert!(
                        (px_flat - expected).length() > 2.0,
                        "the flat world passed at {dist_km} km"
                    );
                }
            }
            if dist_km > 10.0 {
                // Farther off, rays past the thin tip leave the data (sky behind it).
                continue;
            }
            spike_is_drawn_below_its_tip(&geo.frames[0], &camera, tip, (w, h));
        }
    }
    common::assert_no_validation_messages(&gpu);
}

/// The camera `dist_km` south-west of `spike` (its grid sample and height on the grid of
/// `d`-degree steps from `[lat0, lon0]`), 3 km up plus the earth's drop, aimed a little
/// beside it so the tip is off-centre; 5 deg field of view. The camera, the tip's point and
/// the camera's latitude, longitude and height.
fn camera_beside_spike(
    [lat0, lon0]: [f64; 2],
    d: f64,
    (sc, hs): ([i32; 2], f64),
    dist_km: f64,
) -> (Camera, DVec3, [f64; 3]) {
    let (slat, slon) = (lat0 + sc[1] as f64 * d, lon0 + sc[0] as f64 * d);
    let tip = enu(lat0, lon0, slat, slon, hs);
    let dist = dist_km * 1000.0;
    let m = metres_per_deg_lat(slat);
    let clat = slat - dist * 0.6 / m;
    let clon = slon - dist * 0.8 / (m * slat.to_radians().cos());
    let calt = 3000.0 + dist * dist / (2.0 * 6.37e6);
    let pos = enu(lat0, lon0, clat, clon, calt);
    let to = tip - pos;
    let camera = Camera {
        position: pos,
        yaw_deg: to.x.atan2(to.y).to_degrees() + 0.4,
        pitch_deg: (to.z / to.truncate().length()).atan().to_degrees() - 0.3,
        vfov_deg: 5.0,
        near: 1.0,
        far: 1e6,
        roll_deg: 0.0,
    };
    (camera, tip, [clat, clon, calt])
}

/// The tip is in view (rendered, not only probed): the spike's own depth (not terrain behind
/// it), within 2 % of the tip's, just below its pixel. (The spike is one sample wide: at 70 N
/// and 10 km it is ~1,300 px tall and ~33 px wide at its base, so within a pixel of the tip
/// it covers ~0.01 px.)
fn spike_is_drawn_below_its_tip(f: &OwnedFrame, camera: &Camera, tip: DVec3, (w, h): (u32, u32)) {
    let e = pixel_of(camera, tip, w, h);
    let (ex, ey) = (e.x as u32, e.y as u32);
    assert!(
        ex > 0 && ex + 1 < w && ey + 24 < h,
        "tip outside the image: {e}"
    );
    let tip_depth = (tip - camera.position).dot(camera.basis().2);
    let covered = (ey..ey + 24).any(|y| {
        (ex - 1..=ex + 1).any(|x| {
            let d = f.depth_at(x, y).unwrap();
            d > 0.0 && (camera.linear_depth(d) - tip_depth).abs() < 0.02 * tip_depth
        })
    });
    assert!(
        covered,
        "the spike is not drawn just below the tip's pixel {e}"
    );
}

/// Issue 14 rendered: landmark spikes on a synthetic geographic grid whose heights are above
/// EGM96 (Himalaya, 28 N 85 E, where the geoid rises ~12 m per 55 km northwards), its lattice
/// lifted by vkterrain's geoid (`Lattice::on_datum` with `Geoid::undulations`), seen by a camera
/// given by ellipsoidal height 10-50 km away: each tip projects within 0.5 px of f64 geodesy at
/// `(lat, lon, H + N96)` (`N` straight from PROJ here). Negative control: the placement before
/// (lattice on the ellipsoid, the camera's height converted with its own `N`) misses the
/// spikes 50 km away by more than 1 px.
#[cfg(feature = "gdal")]
#[test]
fn landmarks_above_the_geoid_project_where_their_ellipsoidal_height_puts_them() {
    use vkterrain::dataset::geoid::{Geoid, GeoidModel};
    let gpu = common::gpu(false);
    let (size, d) = (257u32, 0.002);
    let (w, h) = (1024u32, 768u32);
    let (lat0, lon0) = (28.0, 85.0);
    let spikes = SPIKES;
    let data = spiky_grid(size, [lat0, lon0], d);
    let on_ellipsoid = Lattice::geographic(size, size, [lon0, lat0], [d, d]).unwrap();
    let geoid = Geoid::new(GeoidModel::Egm96).unwrap();
    let lattice = on_ellipsoid
        .clone()
        .on_datum(|pts| geoid.undulations(pts))
        .unwrap();
    let spike_at = |s: [i32; 2]| (lat0 + s[1] as f64 * d, lon0 + s[0] as f64 * d);
    let n_spikes = egm96_undulations(&spikes.map(|(s, _)| spike_at(s)));
    for dist_km in [10.0, 50.0] {
        let (sc, hs) = spikes[0];
        let (camera, _, [clat, clon, calt]) =
            camera_beside_spike([lat0, lon0], d, (sc, hs + n_spikes[0]), dist_km);
        let n_camera = egm96_undulations(&[(clat, clon)])[0];
        // Before: the camera's height in EGM96 at the camera, the terrain on the ellipsoid.
        let before = Camera {
            position: enu(lat0, lon0, clat, clon, calt - n_camera),
            ..camera
        };
        let geo = render(
            &gpu,
            &data,
            MethodKind::Brute,
            Some(&lattice),
            (w, h),
            &[camera],
        );
        let old = render(
            &gpu,
            &data,
            MethodKind::Brute,
            Some(&on_ellipsoid),
            (w, h),
            &[before],
        );
        let pts: Vec<_> = spikes.iter().map(|(s, _)| (*s, [0.0f32, 0.0])).collect();
        let got = probe_wgsl(&geo.renderer, &pts);
        let got_old = probe_wgsl(&old.renderer, &pts);
        let mut worst_old = 0.0f64;
        for (k, (s, hs)) in spikes.iter().enumerate() {
            let (la, lo) = spike_at(*s);
            let expected = pixel_of(&camera, enu(lat0, lon0, la, lo, hs + n_spikes[k]), w, h);
            let err = (pixel_of_clip(got[k].clip, w, h) - expected).length();
            let err_old = (pixel_of_clip(got_old[k].clip, w, h) - expected).length();
            println!(
                "{dist_km} km, spike {k}: N {:.2} m (camera {n_camera:.2} m), expected {expected:.2}: err {err:.4} px; the camera's N: {err_old:.2} px",
                n_spikes[k]
            );
            assert!(err <= 0.5, "{dist_km} km, spike {k}: {err} px");
            worst_old = worst_old.max(err_old);
        }
        if dist_km >= 50.0 {
            assert!(worst_old > 1.0, "negative control: {worst_old} px");
        }
    }
    common::assert_no_validation_messages(&gpu);
}

/// A camera moving 1 mm per frame along its view axis, far from the world origin: the centre
/// pixel's view depth changes by 1 mm +- 0.2 mm per frame and no pixel is sky.
fn precision_at(gpu: &Arc<Gpu>, lat0: f64, lon0: f64, cam_lat: f64, cam_lon: f64) {
    let (size, d) = (513u32, 0.0008);
    let hills = |la: f64, lo: f64| 200.0 + 80.0 * (la * 900.0).sin() * (lo * 700.0).cos();
    let data = geographic(size, lat0, lon0, d, &hills);
    let lattice = Lattice::geographic(size, size, [lon0, lat0], [d, d]).unwrap();
    let ground = enu(lat0, lon0, cam_lat, cam_lon, hills(cam_lat, cam_lon));
    let base = Camera {
        position: ground + DVec3::new(0.0, 0.0, 150.0),
        yaw_deg: 20.0,
        pitch_deg: -35.0,
        vfov_deg: 40.0,
        near: 1.0,
        far: 1e5,
        ..Camera::default()
    };
    let (_, _, forward) = base.basis();
    let cameras: Vec<Camera> = (0..6)
        .map(|i| Camera {
            position: base.position + forward * (i as f64 * 1e-3),
            ..base
        })
        .collect();
    let (w, h) = (96u32, 64u32);
    let r = render(
        gpu,
        &data,
        MethodKind::Brute,
        Some(&lattice),
        (w, h),
        &cameras,
    );
    let depths: Vec<f64> = r
        .frames
        .iter()
        .zip(&cameras)
        .map(|(f, c)| c.linear_depth(f.depth_at(w / 2, h / 2).unwrap()))
        .collect();
    println!(
        "{cam_lat} N {cam_lon} E, {:.0} m from the world origin: centre depths {depths:?}",
        base.position.length()
    );
    assert!(base.position.truncate().length() > 10_000.0);
    for pair in depths.windows(2) {
        let step = pair[0] - pair[1];
        assert!(
            (step - 1e-3).abs() <= 0.2e-3,
            "depth changed by {:.3} mm for a 1 mm move",
            step * 1e3
        );
    }
    for f in &r.frames {
        let holes = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| f.depth_at(x, y).unwrap() == 0.0)
            .count();
        assert_eq!(holes, 0, "sky pixels (holes) in a view of the ground");
    }
}

#[test]
fn one_millimetre_moves_are_resolved_far_from_the_origin() {
    let gpu = common::gpu(false);
    // 80 N 179.9 E, the data ending short of the antimeridian; and on the equator.
    precision_at(&gpu, 79.85, 179.58, 80.0, 179.9);
    precision_at(&gpu, -0.2, 30.0, 0.0, 30.3);
    common::assert_no_validation_messages(&gpu);
}

/// Pixels where `method` shows sky and brute force terrain at the pixel and its 8 neighbours
/// (holes), and the pixels where brute force has terrain there (inside).
fn holes_against(brute: &OwnedFrame, method: &OwnedFrame) -> (usize, usize) {
    let (w, h) = (brute.width, brute.height);
    let (mut holes, mut inside) = (0, 0);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let all_terrain = (0..9).all(|k| {
                let (sx, sy) = (x + k % 3 - 1, y + k / 3 - 1);
                brute.depth_at(sx, sy).unwrap() > 0.0
            });
            if all_terrain {
                inside += 1;
                if method.depth_at(x, y).unwrap() == 0.0 {
                    holes += 1;
                }
            }
        }
    }
    (holes, inside)
}

/// PGM on the earth (docs/pgm.md, "On the earth") covers what brute force covers on a native
/// geographic grid (0.001 deg both ways at 46 N: 111 m north-south, 77 m east-west samples),
/// over 48 poses: straight down from high up, ordinary flight, grazing near the ground, from
/// outside the data, and high cameras (3-9 km) looking at the horizon, where the curved
/// surface's far part drops below the tangent plane. Negative control: the flat world's
/// projection on the earth (`earth_projection = false`, ground offsets read as grid offsets
/// from the camera's world cell) leaves many such pixels.
#[test]
fn pgm_on_the_earth_covers_what_brute_force_covers() {
    let gpu = common::gpu(false);
    let (size, lat0, lon0, d) = (385u32, 46.0, 8.0, 0.001);
    let hills = |la: f64, lo: f64| 900.0 + 300.0 * (la * 400.0).sin() * (lo * 300.0).cos();
    let data = geographic(size, lat0, lon0, d, &hills);
    let lattice = Lattice::geographic(size, size, [lon0, lat0], [d, d]).unwrap();
    let last = (size - 1) as f64;
    let n = 48;
    let cameras: Vec<Camera> = (0..n)
        .map(|i| {
            let f = i as f64 / n as f64;
            let u = (f * 7.31).fract();
            let v = (f * 3.17 + 0.13).fract();
            let mut s = DVec2::new(u * last, v * last);
            let (above, pitch) = match i % 6 {
                0 => (20_000.0, -90.0),
                1 => (2.0 + 20.0 * u, -2.0 + 3.0 * v),
                2 => {
                    s = DVec2::new(-0.2 * last, v * last);
                    (1500.0, -12.0)
                }
                3 | 4 => (3000.0 + 6000.0 * u, -3.0 * v),
                _ => (50.0 + 2500.0 * u, -5.0 - 55.0 * v),
            };
            let ground = data.height_at(s.x * data.spacing, s.y * data.spacing);
            Camera {
                position: lattice.position(s, ground + above),
                yaw_deg: if i % 6 == 2 {
                    60.0 + 60.0 * u
                } else {
                    360.0 * v
                },
                pitch_deg: pitch,
                near: 1.0,
                far: 1e6,
                ..Camera::default()
            }
        })
        .collect();
    let size_px = (160, 100);
    let brute = render(
        &gpu,
        &data,
        MethodKind::Brute,
        Some(&lattice),
        size_px,
        &cameras,
    );
    let on_earth = render(
        &gpu,
        &data,
        MethodKind::Pgm,
        Some(&lattice),
        size_px,
        &cameras,
    );
    let flat = PgmSettings {
        earth_projection: false,
        ..Default::default()
    };
    let flat = render(&gpu, &data, flat, Some(&lattice), size_px, &cameras);
    let (mut holes, mut flat_holes, mut inside, mut horizon_inside) = (0, 0, 0, 0);
    for (i, ((b, p), q)) in brute
        .frames
        .iter()
        .zip(&on_earth.frames)
        .zip(&flat.frames)
        .enumerate()
    {
        let (h, ins) = holes_against(b, p);
        let (fh, _) = holes_against(b, q);
        println!(
            "pose {i} {:?}: {h} holes of {ins}; flat projection {fh}",
            cameras[i]
        );
        holes += h;
        flat_holes += fh;
        inside += ins;
        if i % 6 == 3 || i % 6 == 4 {
            horizon_inside += ins;
            // The high cameras looking at the horizon: nothing lost.
            assert!(h <= 2, "pose {i}: {h} holes of {ins}");
        }
    }
    println!(
        "PGM on the earth: {holes} holes of {inside} inside pixels ({horizon_inside} in the horizon views); the flat projection: {flat_holes}"
    );
    assert!(
        inside > 48 * 160 * 100 / 3 && horizon_inside > 10_000,
        "{inside} {horizon_inside}"
    );
    assert!(holes * 2000 <= inside, "{holes} holes of {inside}");
    assert!(
        flat_holes > 20 * holes.max(50),
        "flat projection: {flat_holes}, earth: {holes}"
    );
    drop((brute, on_earth, flat));
    common::assert_no_validation_messages(&gpu);
}

#[test]
fn udlod_renders_the_earth_like_brute_force() {
    let gpu = common::gpu(false);
    // Square in metres at 46 N, as `tiles::load` resamples geographic grids (longitude step
    // 0.001 / cos 46 deg), so the grid's nominal spacing is the true one on both axes.
    let (size, lat0, lon0, d) = (513u32, 46.0, 8.0, 0.001);
    let dlon = d * metres_per_deg_lat(lat0) / (metres_per_deg_lon(lat0));
    let hills = |la: f64, lo: f64| 900.0 + 300.0 * (la * 400.0).sin() * (lo * 300.0).cos();
    let data = geographic_steps(size, lat0, lon0, [dlon, d], &hills);
    let lattice = Lattice::geographic(size, size, [lon0, lat0], [dlon, d]).unwrap();
    let camera = Camera {
        position: DVec3::new(5000.0, 3000.0, 2500.0),
        yaw_deg: 35.0,
        pitch_deg: -6.0,
        far: 1e6,
        ..Camera::default()
    };
    let (w, h) = (160u32, 100u32);
    let fine = UdlodSettings {
        tau_px: 0.25,
        ..Default::default()
    };
    let brute = render(
        &gpu,
        &data,
        MethodKind::Brute,
        Some(&lattice),
        (w, h),
        &[camera],
    );
    let udlod = render(&gpu, &data, fine.clone(), Some(&lattice), (w, h), &[camera]);
    let flat_r = render(&gpu, &data, fine, None, (w, h), &[camera]);
    let flat_brute = render(&gpu, &data, MethodKind::Brute, None, (w, h), &[camera]);
    // Pixels whose terrain/sky or depth (more than 1 %) differ.
    let compare = |a: &OwnedFrame, b: &OwnedFrame| {
        let mut differ = 0usize;
        for y in 0..h {
            for x in 0..w {
                let (da, db) = (a.depth_at(x, y).unwrap(), b.depth_at(x, y).unwrap());
                if (da == 0.0) != (db == 0.0) {
                    differ += 1;
                } else if da > 0.0 {
                    let (za, zb) = (camera.linear_depth(da), camera.linear_depth(db));
                    if (za - zb).abs() > 0.01 * za {
                        differ += 1;
                    }
                }
            }
        }
        differ as f64 / (w * h) as f64
    };
    let geo = compare(&brute.frames[0], &udlod.frames[0]);
    let flat = compare(&brute.frames[0], &flat_r.frames[0]);
    let flat_lod = compare(&flat_brute.frames[0], &flat_r.frames[0]);
    println!(
        "pixels differing from brute force: UDLOD on the earth {geo:.4}, UDLOD on the flat world {flat:.4}; on the flat world UDLOD vs brute force {flat_lod:.4}"
    );
    // UDLOD's own approximation (grazing far pixels whose depth moves > 1 %) is the same on
    // the earth as on the flat world: its distances follow the viewer onto the grid.
    assert!(
        geo <= (1.5 * flat_lod).max(flat_lod + 0.005),
        "UDLOD differs from brute force on {geo} of the pixels on the earth, {flat_lod} on the flat world"
    );
    // Negative control: UDLOD on the flat world draws a different surface (the far terrain
    // 10-120 m higher): clearly more pixels off than UDLOD's own approximation.
    assert!(
        flat > 1.5 * geo.max(0.01),
        "flat UDLOD matched the earth: {flat} vs {geo}"
    );
    drop((brute, udlod, flat_r, flat_brute));
    common::assert_no_validation_messages(&gpu);
}

/// Nothing lost, on a real georeferenced data set through the whole chain (`vkterrain
/// preprocess` of an SRTM3 tile, `[dataset] kind = "tiles"`, `Config::open_terrain` and
/// `open_renderer` on the ellipsoid): the grid is the source's own (1201 x 1201, nothing
/// resampled), and for **every** source sample, read independently with GDAL from the
/// `.hgt.zip` (its latitude/longitude from GDAL's geotransform), the renderer's vertex there
/// (`sample_height` and `project` of set 0, what brute force draws) has exactly the source
/// height (0 m), and where it is in view it projects where f64 geodesy puts that
/// latitude/longitude at the ellipsoidal height `H + N96` (SRTM's heights are above EGM96; `N`
/// from PROJ here) within 0.5 px. In metres (the CPU mirror `Lattice::position` of the same
/// lattice, proven equal to the GPU's in the first test), every sample lies within 2 cm of
/// that point, the ones 30+ km from the camera too. Voids (-32768) have no source height and
/// are counted apart. Negative controls: the same data loaded for the flat world is resampled
/// east-west (fewer columns: source samples are lost); the undulation taken at the camera
/// (before issue 14's geoid lattice) misses samples 30+ km away by more than a metre.
#[cfg(feature = "gdal")]
#[test]
fn every_source_sample_is_a_vertex_where_it_lies() {
    let (tmp, zip, out) = srtm3_n42e001("vkt-geodetic");
    let (source, gt) = srtm3_source(&zip);
    let (sw, sh) = (1201, 1201);
    let config_path = tmp.join("n42e001.toml");
    let config_text = format!(
        "[render]\nwidth = 320\nheight = 200\nreadback_depth = true\n\n[dataset]\nkind = \"tiles\"\npath = \"{}\"\n",
        out.display()
    );
    std::fs::write(&config_path, &config_text).unwrap();
    let config = vkterrain::config::Config::load(Some(&config_path)).unwrap();
    let terrain = config.open_terrain().unwrap();
    let grid = terrain.grid().unwrap().clone();
    assert_eq!(
        (grid.width, grid.height, grid.source_step),
        (1201, 1201, [1.0, 1.0])
    );
    // Negative control: the flat world's load resamples (cos 42.5 deg: ~886 columns).
    std::fs::write(
        &config_path,
        config_text.replace("[render]\n", "[render]\nearth = \"flat\"\n"),
    )
    .unwrap();
    let flat = vkterrain::config::Config::load(Some(&config_path)).unwrap();
    let flat_width = flat.open_terrain().unwrap().grid().unwrap().width;
    assert!(
        flat_width < 1000,
        "the flat world's grid has {flat_width} columns"
    );
    // The data set's own georeferencing maps the source's sample centres to grid samples.
    let georef = vkterrain::dataset::tiles::Dataset::open(&out)
        .unwrap()
        .manifest
        .georef
        .expect("SRTM is georeferenced");
    let t = georef.sample_to_crs;
    let grid_of = |lon: f64, lat: f64| ((lon - t[0]) / t[1], (lat - t[3]) / t[5]);
    let (lat0, lon0) = (t[3], t[0]);
    let gpu = common::gpu(false);
    let mut options = config.render_options();
    options.frames_in_flight = 1;
    let mut renderer = config
        .open_renderer(&gpu, &terrain, options)
        .expect("renderer");
    // Frames report the camera's height above the ellipsoid (world heights are ellipsoidal on
    // the geoid-lifted lattice); the flat world's renderer reports it in EGM96, as before.
    use vkterrain::output::ring::layout::{DATUM_EGM96, DATUM_ELLIPSOID};
    assert_eq!(renderer.world.map(|w| w.1), Some(DATUM_ELLIPSOID));
    let flat_renderer = flat
        .open_renderer(&gpu, &flat.open_terrain().unwrap(), flat.render_options())
        .unwrap();
    assert_eq!(flat_renderer.world.map(|w| w.1), Some(DATUM_EGM96));
    drop(flat_renderer);
    let camera = Camera {
        position: enu(lat0, lon0, 42.2, 1.2, 5000.0),
        yaw_deg: 45.0,
        pitch_deg: -25.0,
        far: 1e6,
        ..Camera::default()
    };
    let mut sink = CollectSink::default();
    renderer
        .render(FrameRequest::from(camera), &mut sink)
        .unwrap();
    renderer.finish(&mut sink).unwrap();
    let (pts, expected) = source_samples_on_the_grid(&source, gt, (sw, sh), grid_of);
    let got = probe_wgsl(&renderer, &pts);
    let lattice = config
        .open_lattice(&terrain, vkterrain::render::EarthGeometry::Ellipsoid)
        .unwrap()
        .expect("SRTM on the ellipsoid");
    let n_camera = egm96_undulations(&[(42.2, 1.2)])[0];
    let (w, h) = (320u32, 200u32);
    let SampleMisses {
        voids,
        height_misses,
        in_view,
        worst_px,
        worst_m,
        worst_far_m,
        far,
        camera_n_far_m,
    } = sample_misses(
        &pts,
        &expected,
        &got,
        &lattice,
        &camera,
        (w, h),
        [lat0, lon0],
    );
    println!(
        "{} source samples: {voids} voids, {height_misses} heights differ; {in_view} in view, worst {worst_px:.4} px from f64 geodesy at H + N96",
        sw * sh
    );
    println!(
        "lattice on EGM96 against f64 geodesy at H + N96: worst {worst_m:.4} m, {far} samples 30+ km from the camera worst {worst_far_m:.4} m; the camera's undulation ({n_camera:.3} m) there would miss by up to {camera_n_far_m:.3} m"
    );
    assert!(worst_m < 0.02 && far > 100_000, "{worst_m} m ({far} far)");
    assert!(camera_n_far_m > 1.0, "negative control: {camera_n_far_m} m");
    assert_eq!(height_misses, 0, "source heights not reproduced");
    assert!(voids < sw * sh / 100, "{voids} voids");
    summit_is_where_published(&expected, &got, [lat0, lon0], (w, h));
    assert!(in_view > 10_000, "{in_view} samples in view");
    assert!(
        worst_px <= 0.5,
        "a sample is {worst_px} px from where it lies"
    );
    drop(renderer);
    common::assert_no_validation_messages(&gpu);
    std::fs::remove_dir_all(&tmp).ok();
}

/// A probe's point: a grid sample and the fraction of a sample past it.
#[cfg(feature = "gdal")]
type ProbePoint = ([i32; 2], [f32; 2]);

/// A source sample's latitude, longitude (degrees) and height (m; -32768: void).
#[cfg(feature = "gdal")]
type SourceSample = (f64, f64, i16);

/// Every source sample (GDAL pixel centre of geotransform `gt`) -> lat/lon -> the grid's
/// sample through `grid_of` (asserted to fall on one): the probe's points and, for each, its
/// latitude, longitude and source height.
#[cfg(feature = "gdal")]
fn source_samples_on_the_grid(
    source: &[i16],
    gt: [f64; 6],
    (sw, sh): (usize, usize),
    grid_of: impl Fn(f64, f64) -> (f64, f64),
) -> (Vec<ProbePoint>, Vec<SourceSample>) {
    let mut pts = Vec::with_capacity(sw * sh);
    let mut expected = Vec::with_capacity(sw * sh);
    for gy in 0..sh {
        for gx in 0..sw {
            let lon = gt[0] + (gx as f64 + 0.5) * gt[1] + (gy as f64 + 0.5) * gt[2];
            let lat = gt[3] + (gx as f64 + 0.5) * gt[4] + (gy as f64 + 0.5) * gt[5];
            let (c, r) = grid_of(lon, lat);
            assert!(
                (c - c.round()).abs() < 1e-6 && (r - r.round()).abs() < 1e-6,
                "source sample ({gx}, {gy}) falls between grid samples: ({c}, {r})"
            );
            pts.push(([c.round() as i32, r.round() as i32], [0.0f32, 0.0]));
            expected.push((lat, lon, source[gy * sw + gx]));
        }
    }
    (pts, expected)
}

/// How far the renderer's vertices at the source samples lie from f64 geodesy at `H + N96`.
#[cfg(feature = "gdal")]
struct SampleMisses {
    voids: usize,
    /// Samples whose vertex height is not the source's.
    height_misses: usize,
    in_view: usize,
    /// Worst distance in pixels of an in-view vertex from the projected exact point.
    worst_px: f64,
    /// Worst distance in metres of the CPU lattice's point from the exact one, and of those
    /// 30+ km from the camera (`far` of them).
    worst_m: f64,
    worst_far_m: f64,
    far: usize,
    /// The negative control: how far the camera's undulation misses the far samples'.
    camera_n_far_m: f64,
}

#[cfg(feature = "gdal")]
fn sample_misses(
    pts: &[ProbePoint],
    expected: &[SourceSample],
    got: &[TerrainProbePoint],
    lattice: &Lattice,
    camera: &Camera,
    (w, h): (u32, u32),
    [lat0, lon0]: [f64; 2],
) -> SampleMisses {
    let geoid = egm96_undulations(&expected.iter().map(|e| (e.0, e.1)).collect::<Vec<_>>());
    let n_camera = egm96_undulations(&[(42.2, 1.2)])[0];
    let mut m = SampleMisses {
        voids: 0,
        height_misses: 0,
        in_view: 0,
        worst_px: 0.0,
        worst_m: 0.0,
        worst_far_m: 0.0,
        far: 0,
        camera_n_far_m: 0.0,
    };
    for (k, (g, &(lat, lon, src_h))) in got.iter().zip(expected).enumerate() {
        if src_h == -32768 {
            m.voids += 1;
            continue;
        }
        // In metres: the lattice's point (CPU mirror) against f64 geodesy at H + N.
        let n = geoid[k];
        let exact = enu(lat0, lon0, lat, lon, src_h as f64 + n);
        let s = DVec2::new(pts[k].0[0] as f64, pts[k].0[1] as f64);
        let miss = (lattice.position(s, src_h as f64) - exact).length();
        m.worst_m = m.worst_m.max(miss);
        if (exact - camera.position).length() > 30_000.0 {
            m.far += 1;
            m.worst_far_m = m.worst_far_m.max(miss);
            // The old placement: every height converted with the camera's undulation.
            m.camera_n_far_m = m.camera_n_far_m.max((n - n_camera).abs());
        }
        if g.heights[0] != src_h as f32 {
            m.height_misses += 1;
        }
        let px = pixel_of_clip(g.clip, w, h);
        if g.clip[3] < 10.0 || px.x < 0.0 || px.y < 0.0 || px.x > w as f64 || px.y > h as f64 {
            continue;
        }
        m.in_view += 1;
        let want = pixel_of(camera, exact, w, h);
        m.worst_px = m.worst_px.max((px - want).length());
    }
    m
}

/// SRTM3 N42E001's 1201 x 1201 heights read independently of the renderer (GDAL's SRTMHGT
/// driver through /vsizip/) and its geotransform.
#[cfg(feature = "gdal")]
fn srtm3_source(zip: &std::path::Path) -> (Vec<i16>, [f64; 6]) {
    let src = gdal::Dataset::open(format!("/vsizip/{}/N42E001.hgt", zip.display())).unwrap();
    let gt = src.geo_transform().unwrap();
    let (sw, sh) = src.raster_size();
    assert_eq!((sw, sh), (1201, 1201));
    let source = src
        .rasterband(1)
        .unwrap()
        .read_as::<i16>((0, 0), (sw, sh), (sw, sh), None)
        .unwrap()
        .data()
        .to_vec();
    (source, gt)
}

/// A named landmark: Pica d'Estats (3,143 m; 42 deg 39' 59" N, 1 deg 23' 51" E, as
/// published). Of the source samples `expected` (latitude, longitude, height) and their
/// probed vertices `got` (a `w` x `h` view), the highest within 1 km of those coordinates lies
/// within 150 m of them (the summit is where its coordinates say), it is as high as SRTM3 can
/// say (its 3" samples miss the sharp top: 3,100 m, 75 m away; within 60 m of the published
/// height), and it is in view, so the caller's check placed it within 0.5 px.
#[cfg(feature = "gdal")]
fn summit_is_where_published(
    expected: &[SourceSample],
    got: &[TerrainProbePoint],
    [lat0, lon0]: [f64; 2],
    (w, h): (u32, u32),
) {
    let (plat, plon, ph) = (
        42.0 + 39.0 / 60.0 + 59.0 / 3600.0,
        1.0 + 23.0 / 60.0 + 51.0 / 3600.0,
        3143.0,
    );
    let at_peak = enu(lat0, lon0, plat, plon, 0.0);
    let (k, top, off) = expected
        .iter()
        .enumerate()
        .map(|(k, (la, lo, hh))| {
            (
                k,
                *hh as f64,
                (enu(lat0, lon0, *la, *lo, 0.0) - at_peak).length(),
            )
        })
        .filter(|(_, _, d)| *d < 1000.0)
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .expect("samples near the summit");
    let summit_px = pixel_of_clip(got[k].clip, w, h);
    println!(
        "Pica d'Estats: highest vertex within 1 km {top} m (published {ph} m), {off:.0} m from the published position, drawn at {summit_px:.1}"
    );
    assert!(
        off < 150.0,
        "the highest vertex near the summit is {off} m from it"
    );
    assert!(
        (top - ph).abs() < 60.0,
        "the summit is {top} m, published {ph} m"
    );
    let on_screen = |p: DVec2| p.x > 0.0 && p.x < w as f64 && p.y > 0.0 && p.y < h as f64;
    assert!(
        got[k].clip[3] > 10.0 && on_screen(summit_px),
        "the summit is not in view: {summit_px}"
    );
}

/// The chunked clipmap on a native geographic grid drawn on the ellipsoid (SRTM3 N42E001,
/// 1201 x 1201 at 92 x 68 m, `[clipmap] enabled`): UDLOD through the clipmap, converged at each
/// of 200 poses (the crack tests' poses, laid on the earth over their grid samples like
/// scenario keyframes), covers every pixel brute force on the earth covers (watertight: no
/// sky where the exact surface is), and the clipmap's CPU height query equals the GPU's.
/// Negative control: the same data set through the flat world's clipmap is refused (its
/// spacing is not square).
#[cfg(feature = "gdal")]
#[test]
fn udlod_through_the_clipmap_is_watertight_on_a_native_geographic_grid() {
    use vkterrain::config::Config;
    let (tmp, _, out) = srtm3_n42e001("vkt-geodetic-cm");
    let (w, h) = (96u32, 64u32);
    let config_with = |extra: &str| {
        let path = tmp.join("c.toml");
        std::fs::write(
            &path,
            format!(
                "[render]\nwidth = {w}\nheight = {h}\nreadback_depth = true\nframes_in_flight = 1\n{extra}\n[dataset]\nkind = \"tiles\"\npath = \"{}\"\n",
                out.display()
            ),
        )
        .unwrap();
        Config::load(Some(&path)).unwrap()
    };
    let clipmap_text = "\n[clipmap]\nenabled = true\natlas_capacity = 400\nnode_count = 6\n";
    // Negative control first: the flat world's clipmap refuses the non-square grid.
    let flat = config_with(&format!("earth = \"flat\"\n{clipmap_text}"));
    let e = flat
        .open_terrain()
        .err()
        .expect("flat clipmap on geographic data")
        .to_string();
    assert!(e.contains("not square") && !e.contains('\n'), "{e}");
    let brute_cfg = config_with("");
    let cm_cfg = config_with(clipmap_text);
    let grid = brute_cfg.open_terrain().unwrap();
    let pyramid = cm_cfg.open_terrain().unwrap();
    let earth = brute_cfg
        .open_earth()
        .unwrap()
        .expect("SRTM lies on the earth");
    let gpu = common::gpu(false);
    let mut brute = brute_cfg
        .open_renderer(&gpu, &grid, brute_cfg.render_options())
        .unwrap();
    let mut cm_cfg_udlod = cm_cfg.clone();
    cm_cfg_udlod.method = MethodConfig::from(MethodKind::Udlod);
    let mut udlod = cm_cfg_udlod
        .open_renderer(&gpu, &pyramid, cm_cfg.render_options())
        .unwrap();
    let map = grid.grid().unwrap();
    let template = Camera::default();
    let cameras: Vec<Camera> = common::poses::poses(map, 200)
        .iter()
        .map(|c| {
            let pose = earth
                .grid_pose(&grid, c.position, c.yaw_deg, c.pitch_deg, c.roll_deg)
                .unwrap();
            // The pose's height is in the terrain's datum (EGM96): the world's is ellipsoidal.
            let z = earth
                .terrain_to_world(pose.lat_deg, pose.lon_deg, c.position.z)
                .unwrap();
            earth.camera_at(&pose, z, &template).unwrap()
        })
        .collect();
    let (mut holes, mut frames_total) = (0usize, 0usize);
    for (i, c) in cameras.iter().enumerate() {
        let mut sink = CollectSink::default();
        brute.render(FrameRequest::from(*c), &mut sink).unwrap();
        brute.finish(&mut sink).unwrap();
        let reference = sink.frames.pop().unwrap();
        let (f, frames) = converged_frame(&mut udlod, c, i);
        frames_total += frames;
        for y in 0..h {
            for x in 0..w {
                if reference.depth_at(x, y).unwrap() > 0.0 && f.depth_at(x, y).unwrap() == 0.0 {
                    holes += 1;
                }
            }
        }
    }
    let worst = clipmap_cpu_gpu_worst(&udlod);
    println!(
        "{} poses, {frames_total} clipmap frames: {holes} hole pixels; CPU vs GPU heights worst {worst:e} m",
        cameras.len()
    );
    assert_eq!(
        holes, 0,
        "UDLOD through the clipmap left holes on the earth"
    );
    assert!(
        worst <= 4.0 * f32::EPSILON * 3200.0,
        "CPU and GPU heights differ by {worst} m"
    );
    drop((brute, udlod));
    common::assert_no_validation_messages(&gpu);
    std::fs::remove_dir_all(&tmp).ok();
}

/// The one culling box on the earth (`Lattice::rect_box`, twin of WGSL `earth_box`) holds the
/// terrain it stands for: every point of the rectangle at every height between its bounds,
/// through the lattice, on a 2 x 0.2 degree geographic grid at 70 N (rows along parallels:
/// their middles bulge equatorward by `d^2 tan(lat) / 8R`; world frame at its corner and on
/// its middle meridian) and on the CI terrain anchored at 46.5 N, for the whole grid and
/// smaller rectangles. Controls: the corners' box without growth, and the box grown with the
/// surface's radius alone (`GEO_MIN_RADIUS`, no `cos(lat)`), miss points of the 70 N grid's
/// whole rectangle in the centred frame.
#[test]
fn the_earth_culling_box_holds_its_terrain() {
    use vkterrain::geo::{EnuFrame, Geodetic, WGS84};
    use vkterrain::gpu_constants::GEO_MIN_RADIUS;
    let high = Lattice::geographic(2401, 241, [20.0, 70.0], [1.0 / 1200.0, 1.0 / 1200.0]).unwrap();
    // The same grid in a world frame on its middle meridian: there a row's middle is its most
    // equatorward point, outside the corners' box (the frame at a corner sees rows run
    // monotonically).
    let centred = Lattice::new(
        2401,
        241,
        5,
        EnuFrame::new(&WGS84, Geodetic::new(70.1, 21.0, 0.0)),
        |c, r| Ok((70.0 + r / 1200.0, 20.0 + c / 1200.0)),
    )
    .unwrap();
    let frame = EnuFrame::new(&WGS84, Geodetic::new(46.5, 8.0, 0.0));
    let ci = Lattice::anchored_plane(513, 513, 60.0, frame).unwrap();
    // Points of `c0..=c1` x heights outside `b` (by more than 1 mm), and the worst excess.
    let misses = |l: &Lattice, c0: [i32; 2], c1: [i32; 2], h: [f64; 2], lo: DVec3, hi: DVec3| {
        let (mut n, mut worst) = (0, 0.0f64);
        for i in 0..=48 {
            for j in 0..=48 {
                for k in 0..=2 {
                    let s = DVec2::new(
                        c0[0] as f64 + (c1[0] - c0[0]) as f64 * i as f64 / 48.0,
                        c0[1] as f64 + (c1[1] - c0[1]) as f64 * j as f64 / 48.0,
                    );
                    let p = l.position(s, h[0] + (h[1] - h[0]) * k as f64 / 2.0);
                    let out = (lo - p).max(p - hi).max_element();
                    worst = worst.max(out);
                    n += (out > 1e-3) as usize;
                }
            }
        }
        (n, worst)
    };
    // (lattice, corner c0, corner c1, heights)
    type Case<'a> = (&'a Lattice, [i32; 2], [i32; 2], [f64; 2]);
    let cases: [Case; 6] = [
        (&centred, [0, 0], [2400, 240], [0.0, 2000.0]),
        (&high, [0, 0], [2400, 240], [0.0, 2000.0]),
        (&high, [1200, 0], [2400, 240], [-400.0, 9000.0]),
        (&high, [37, 11], [37 + 256, 11 + 128], [100.0, 150.0]),
        (&ci, [0, 0], [512, 512], [0.0, 3000.0]),
        (&ci, [256, 128], [512, 256], [500.0, 800.0]),
    ];
    for (l, c0, c1, h) in cases {
        let b = l.rect_box(c0, c1, h);
        let (n, worst) = misses(l, c0, c1, h, b.lo, b.hi);
        assert_eq!(
            n, 0,
            "{c0:?}..{c1:?} {h:?}: {n} points outside by up to {worst} m"
        );
    }
    // Controls on the 70 N grid's whole rectangle, centred frame.
    let (l, c0, c1, h) = cases[0];
    let b = l.rect_box(c0, c1, h);
    let d = (b.hi.truncate() - b.lo.truncate()).length();
    let grown = |r: f64| d * d / (8.0 * r) + 1e-3 * d;
    let bulge = grown(l.curve_radius());
    let hull = (b.lo + DVec3::splat(bulge), b.hi - DVec3::splat(bulge));
    let (n_hull, w_hull) = misses(l, c0, c1, h, hull.0, hull.1);
    let g = DVec3::splat(grown(GEO_MIN_RADIUS as f64));
    let (n_flat_r, w_flat_r) = misses(l, c0, c1, h, hull.0 - g, hull.1 + g);
    println!(
        "70 N, 2 x 0.2 degrees: curve radius {:.0} m, growth {bulge:.1} m; corners' box misses \
         {n_hull} points (by up to {w_hull:.1} m), growth over GEO_MIN_RADIUS ({:.1} m) misses \
         {n_flat_r} (by up to {w_flat_r:.1} m)",
        l.curve_radius(),
        g.x
    );
    assert!(n_hull > 0 && n_flat_r > 0, "{n_hull} {n_flat_r}");
}

/// Renders `c` through UDLOD's clipmap until it has converged (nothing loading, no
/// fallback): the converged frame and the frames it took. Bounded by time, not frames: the
/// loader's threads share the CPU with this file's other tests (a frame count ran out once).
#[cfg(feature = "gdal")]
fn converged_frame(udlod: &mut Renderer, c: &Camera, pose: usize) -> (OwnedFrame, usize) {
    let started = std::time::Instant::now();
    let mut frames = 0;
    loop {
        let mut sink = CollectSink::default();
        udlod.render(FrameRequest::from(*c), &mut sink).unwrap();
        udlod.finish(&mut sink).unwrap();
        let frame = sink.frames.pop();
        frames += 1;
        let cm = udlod.clipmap().unwrap();
        if cm.busy() == 0 && cm.views.iter().all(|v| v.fallback_cells == 0) {
            return (frame.unwrap(), frames);
        }
        if cm.busy() > 0 {
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        assert!(
            started.elapsed() < std::time::Duration::from_secs(120),
            "pose {pose}: the clipmap did not converge: {} busy, {:?} fallback cells, {:?}",
            cm.busy(),
            cm.views
                .iter()
                .map(|v| v.fallback_cells)
                .collect::<Vec<_>>(),
            cm.counters
        );
    }
}

/// The clipmap's CPU height query against the GPU's at 4,096 points of view 0 (half on
/// samples, half between): the largest difference.
#[cfg(feature = "gdal")]
fn clipmap_cpu_gpu_worst(udlod: &Renderer) -> f32 {
    let points: Vec<[f32; 2]> = (0..4096u32)
        .map(|k| {
            let u = (k as f32 * 0.618_034).fract() * 1200.0;
            let v = (k as f32 * 0.414_213_6).fract() * 1200.0;
            if k % 2 == 0 {
                [u.floor(), v.floor()]
            } else {
                [u, v]
            }
        })
        .collect();
    let gpu_h = udlod.probe_heights_in_view(0, &points).unwrap();
    let cm = udlod.clipmap().unwrap();
    points
        .iter()
        .zip(&gpu_h)
        .map(|(p, g)| (cm.sample_height(0, *p) - g[0]).abs())
        .fold(0f32, f32::max)
}

/// PGM's reference sphere on the CPU (`lod::pgm::earth::Sphere`, the shader's formula in f64):
/// a ray that meets the sphere lands where the textbook quadratic (written out here, in the
/// plane of the ray) puts it; the horizon is at `sqrt(2 a R)`-ish; distances fall steadily
/// with the depression and join continuously at the horizon, where rays above it take
/// distances out to the largest one. Negative control: the rays just above the horizon lie
/// beyond it (cutting them all at the largest distance would jump there).
#[test]
fn pgm_reference_sphere_hits_and_joins_at_the_horizon() {
    use vkterrain::lod::pgm::earth::Sphere;
    let d_max = 200_000.0;
    for (radius, height) in [
        (6_371_500.0, 10.0),
        (6_372_000.0, 3000.0),
        (6_400_000.0, 2.0),
    ] {
        let sphere = Sphere { radius, height };
        let e_h = sphere.horizon_depression();
        let d_h = sphere.horizon_distance();
        let approx = (2.0 * height * radius).sqrt();
        assert!((d_h - approx).abs() < 1e-3 * approx, "{d_h} vs {approx}");
        // The oracle: camera at (0, R + a), ray (cos e, -sin e); |p| = R, nearer root.
        for e_deg in [90.0, 60.0, 20.0, 5.0, 1.0, 0.2] {
            let e = f64::to_radians(e_deg);
            if e <= e_h {
                continue;
            }
            let (c, b) = (radius + height, -(radius + height) * e.sin());
            let t = -b - (b * b - (c * c - radius * radius)).sqrt();
            let (x, y) = (t * e.cos(), c - t * e.sin());
            let want = (radius * x.atan2(y)).min(d_max);
            let got = sphere.distance(e.sin(), d_max);
            assert!(
                (got - want).abs() <= 1e-6 * want + 1e-6,
                "e {e_deg}: {got} vs {want}"
            );
        }
        // Continuous at the horizon, falling with the depression everywhere.
        let below = sphere.distance((e_h * (1.0 + 1e-9)).sin(), d_max);
        let above = sphere.distance((e_h * (1.0 - 1e-9)).sin(), d_max);
        assert!((below - d_h).abs() < 0.01 * d_h && (above - d_h).abs() < 0.01 * d_h);
        let mut last = f64::INFINITY;
        for k in 0..=2000 {
            let s = -0.05 + 1.05 * k as f64 / 2000.0;
            let dist = sphere.distance(s, d_max);
            assert!(
                dist <= last + 1e-6 && dist <= d_max,
                "s {s}: {dist} after {last}"
            );
            last = dist;
        }
        assert_eq!(sphere.distance(-0.01, d_max), d_max);
        assert!(sphere.distance(1.0, d_max) < 1e-6);
        // Negative control: halfway between the horizon and the horizontal the distance lies
        // strictly between the horizon's and the largest (not cut at either).
        if d_h < d_max {
            let mid = sphere.distance((0.5 * e_h).sin(), d_max);
            assert!(mid > 1.001 * d_h && mid < 0.999 * d_max, "{mid} {d_h}");
        }
    }
}

/// Hardware tessellation's edge levels on a native geographic grid come from the edges' metric
/// lengths through the lattice: at 60 N a 0.001-degree grid's east-west edges are half its
/// north-south ones. Looking straight down from a height where an 8-sample patch's east-west
/// edge spans 0.75 of the target length on screen, its north-south edge 1.5 and its diagonal
/// 1.68, equal spacing gives every triangle patch outer levels (1, 2, 2) and inner level 2:
/// exactly 5 triangles each. Negative control: the same data on the flat world (one square
/// spacing, the north-south metres) measures the east-west edges twice as long and makes a
/// different count.
#[test]
fn tessellation_measures_geographic_edges_in_metres() {
    use vkterrain::lod::tessellation::settings::{Spacing, TessellationSettings};
    let gpu = common::gpu(false);
    let (size, lat0, lon0, d) = (65u32, 60.0, 10.0, 0.001);
    let data = geographic(size, lat0, lon0, d, &|_, _| 0.0);
    let lattice = Lattice::geographic(size, size, [lon0, lat0], [d, d]).unwrap();
    let settings = TessellationSettings {
        spacing: Spacing::Equal,
        edge_px: 8.0,
        patch_samples: 8,
        cull: false,
        ..Default::default()
    };
    let (w, h) = (200u32, 200u32);
    let vfov_deg: f64 = 30.0;
    let focal = h as f64 / (2.0 * (vfov_deg.to_radians() / 2.0).tan());
    // Where an east-west patch edge is 0.75 x 8 px on screen (flat terrain, straight down:
    // every edge lies at the camera's height in view depth).
    let ew_patch_m = 8.0 * d * metres_per_deg_lon(lat0 + 0.032);
    let above = ew_patch_m * focal / (0.75 * 8.0);
    let centre = lattice.position(DVec2::new(32.0, 32.0), 0.0);
    let camera = Camera {
        position: centre + DVec3::Z * above,
        pitch_deg: -90.0,
        vfov_deg,
        far: 1e6,
        ..Camera::default()
    };
    let patches = 2 * 8 * 8;
    let method = MethodConfig::Tessellation(settings);
    let earth = render(
        &gpu,
        &data,
        method.clone(),
        Some(&lattice),
        (w, h),
        &[camera, camera],
    );
    let flat = render(&gpu, &data, method, None, (w, h), &[camera, camera]);
    let (on_earth, on_flat) = (
        earth.frames.last().unwrap().triangles,
        flat.frames.last().unwrap().triangles,
    );
    println!("tessellated triangles: earth {on_earth}, flat world {on_flat} ({patches} patches)");
    assert_eq!(on_earth, 5 * patches, "levels (1, 2, 2) / 2 in every patch");
    assert_ne!(
        on_flat, on_earth,
        "the flat world's square spacing gave the same levels"
    );
    drop((earth, flat));
    common::assert_no_validation_messages(&gpu);
}
