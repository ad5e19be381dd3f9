//! Every scenario under `config/scenarios/` parses against the data set it is written for,
//! yields finite, valid cameras for all its frames, keeps flights above the ground, and looks
//! down at the angle its file name claims (`_downNN`: every frame's pitch is -NN deg).
//! The real data sets come from `../shared/data` (SRTM pairs preprocessed into a temporary
//! directory); without it the files are checked against procedural terrain only.

mod common;

use std::path::{Path, PathBuf};

use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options};
use vkterrain::dataset::procedural::{self, ProceduralParams};
use vkterrain::dataset::{Heightmap, load_png16, tiles};
use vkterrain::scene::{Camera, Scenario};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn scenario_files() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(root().join("config/scenarios"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    files
}

/// The SRTM pair of `south`/`north` tiles as the renderer would load it after
/// `vkterrain preprocess` (see config/pyrenees.toml, config/franconia.toml).
fn srtm_pair(data: &Path, south: &str, north: &str, tmp: &Path) -> Heightmap {
    let out = tmp.join(south);
    preprocess::run(
        &Options {
            input: Input::Files(vec![
                data.join(format!("srtm/{south}.hgt.zip")),
                data.join(format!("srtm/{north}.hgt.zip")),
            ]),
            out: out.clone(),
            force: true,
            ..Default::default()
        },
        &mut NoProgress,
    )
    .unwrap();
    tiles::load(&out, None, tiles::DEFAULT_MAX_SAMPLES).unwrap()
}

/// Data sets by file-name prefix; `None` without ../shared/data (a failure in CI).
fn real_datasets() -> Option<Vec<(&'static str, Heightmap)>> {
    let data = common::shared_data()?;
    // One directory per call: tests run in parallel threads of one process.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = std::env::temp_dir().join(format!("vkt-scenarios-{}-{call}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let puget = load_png16(&data.join("puget_sound/ps_height_1k.png"), 160.0, 0.1, None).unwrap();
    let sets = vec![
        ("puget_", puget),
        ("pyrenees_", srtm_pair(&data, "N41E001", "N42E001", &tmp)),
        ("franconia_", srtm_pair(&data, "N49E011", "N50E011", &tmp)),
    ];
    std::fs::remove_dir_all(&tmp).ok();
    Some(sets)
}

/// `_downNN` in a file name: the claimed look-down angle in degrees.
fn claimed_down(name: &str) -> Option<f64> {
    let i = name.rfind("_down")?;
    let digits: String = name[i + 5..]
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

fn cameras(s: &Scenario) -> Vec<Camera> {
    (0..s.frames as u64).map(|k| s.camera(k)).collect()
}

#[test]
fn every_scenario_parses_and_yields_valid_cameras_at_the_claimed_angles() {
    let procedural = procedural::generate(&ProceduralParams {
        size: 257,
        ..Default::default()
    })
    .unwrap();
    let real = real_datasets();
    let files = scenario_files();
    assert!(files.len() >= 13, "{} scenario files", files.len());
    let mut angle_claims = 0;
    for path in &files {
        let file = path.file_stem().unwrap().to_string_lossy().to_string();
        let data = real
            .as_ref()
            .and_then(|sets| sets.iter().find(|(p, _)| file.starts_with(p)))
            .map(|(_, d)| d);
        let on = data.unwrap_or(&procedural);
        let s = Scenario::load(path, on).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert!(s.frames > 0, "{file}: no frames");
        let cams = cameras(&s);
        for (k, c) in cams.iter().enumerate() {
            c.validate()
                .unwrap_or_else(|e| panic!("{file} frame {k}: {e}"));
            let p = c.position;
            assert!(p.is_finite(), "{file} frame {k}: {p}");
            if let Some(d) = data {
                let ground = d.height_at(p.x, p.y);
                assert!(
                    p.z > ground + 5.0,
                    "{file} frame {k}: camera at {:.1} m, ground {ground:.1} m",
                    p.z
                );
            }
        }
        if let Some(down) = claimed_down(&file) {
            angle_claims += 1;
            for (k, c) in cams.iter().enumerate() {
                assert!(
                    (c.pitch_deg + down).abs() <= 0.5,
                    "{file} frame {k}: pitch {} but the name claims {down} deg down",
                    c.pitch_deg
                );
            }
        }
    }
    assert!(angle_claims >= 10, "{angle_claims} files claim an angle");
}

fn load(file: &str, data: &Heightmap) -> Scenario {
    Scenario::load(&root().join("config/scenarios").join(file), data).unwrap()
}

/// Fischer's flights: straight lines at a constant speed of 2.1 m per 25 ms frame, constant
/// altitude and attitude, 45 deg FOV, 4 km view distance, over their own data sets (the
/// keyframes are fractions of the extent, so the line is long enough only there).
#[test]
fn fischer_flights_are_straight_constant_speed_lines() {
    let Some(sets) = real_datasets() else { return };
    let files: Vec<PathBuf> = scenario_files()
        .into_iter()
        .filter(|p| p.to_string_lossy().contains("fischer"))
        .collect();
    assert_eq!(files.len(), 4);
    for path in files {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let (_, data) = sets.iter().find(|(p, _)| name.starts_with(p)).unwrap();
        let s = Scenario::load(&path, data).unwrap();
        let cams = cameras(&s);
        assert_eq!(s.fps, 40.0);
        let first = cams[0];
        assert_eq!((first.vfov_deg, first.far), (45.0, 4000.0));
        let dir = (cams[1].position - first.position).normalize();
        for w in cams.windows(2) {
            let step = w[1].position - w[0].position;
            assert!((step.length() - 2.1).abs() < 1e-6, "{path:?}: step {step}");
            assert!(
                step.normalize().dot(dir) > 1.0 - 1e-9,
                "{path:?}: not straight"
            );
            assert!(step.z.abs() < 1e-6, "{path:?}: altitude changes");
            assert_eq!(
                (w[1].yaw_deg, w[1].pitch_deg),
                (first.yaw_deg, first.pitch_deg)
            );
        }
    }
}

#[test]
fn improved_pgm_flight_starts_over_everything_and_ends_low_looking_out() {
    let Some(sets) = real_datasets() else { return };
    let puget = &sets[0].1;
    let s = load("puget_improved_pgm_flight.toml", puget);
    let cams = cameras(&s);
    let (first, last) = (cams[0], *cams.last().unwrap());
    assert_eq!(first.pitch_deg, -90.0);
    // The whole data set fits in the first frame's vertical field of view (the narrower one).
    let (ex, ey) = puget.extent();
    let (_, hi) = puget.height_range();
    let covered = 2.0 * (first.position.z - hi as f64) * (first.vfov_deg.to_radians() / 2.0).tan();
    assert!(
        covered >= ex.max(ey),
        "sees {covered:.0} m of {:.0}",
        ex.max(ey)
    );
    assert!(last.pitch_deg > -10.0 && last.pitch_deg < 10.0);
    let above = last.position.z - puget.height_at(last.position.x, last.position.y);
    assert!(above < 300.0, "ends {above:.0} m above the ground");
    // Hovering: the last second does not move.
    let n = cams.len();
    assert!(cams[n - 30].position.distance(last.position) < 1e-6);
    // Toward the peaks: the highest sample lies within 10 deg of the final heading.
    let (mut best, mut at) = (f32::MIN, 0);
    for (i, &h) in puget.heights.iter().enumerate() {
        if h > best {
            (best, at) = (h, i);
        }
    }
    let peak = (
        (at as u32 % puget.width) as f64 * puget.spacing,
        (at as u32 / puget.width) as f64 * puget.spacing,
    );
    let bearing = (peak.0 - last.position.x)
        .atan2(peak.1 - last.position.y)
        .to_degrees()
        .rem_euclid(360.0);
    let off = (bearing - last.yaw_deg + 540.0).rem_euclid(360.0) - 180.0;
    assert!(
        off.abs() < 10.0,
        "peak at bearing {bearing:.1}, heading {}",
        last.yaw_deg
    );
}

#[test]
fn rotation_static_and_pan_scenarios_do_what_their_names_say() {
    let data = procedural::generate(&ProceduralParams {
        size: 257,
        ..Default::default()
    })
    .unwrap();
    // Pure rotation: one position, the heading turns a full circle.
    let cams = cameras(&load("puget_rotation_in_place_down20.toml", &data));
    let mut turned = 0.0;
    for w in cams.windows(2) {
        assert!(w[0].position.distance(w[1].position) < 1e-6);
        turned += (w[1].yaw_deg - w[0].yaw_deg + 540.0).rem_euclid(360.0) - 180.0;
    }
    assert!(turned > 350.0, "turned {turned} deg");
    // Static: every frame the same camera.
    let cams = cameras(&load("pyrenees_thin_peak_static.toml", &data));
    assert!(cams.iter().all(|c| *c == cams[0]));
    // Fast pan: at least 5 deg of heading per frame while it pans.
    let cams = cameras(&load("puget_fast_pan_down15.toml", &data));
    let fast = cams
        .windows(2)
        .filter(|w| ((w[1].yaw_deg - w[0].yaw_deg + 540.0).rem_euclid(360.0) - 180.0).abs() >= 5.0)
        .count();
    assert!(fast >= 55, "{fast} fast frames");
    // Straight down at three altitudes: 1, 10 and 100 km above the ground.
    for (file, km) in [
        ("puget_straight_down_1km_down90.toml", 1.0),
        ("puget_straight_down_10km_down90.toml", 10.0),
        ("puget_straight_down_100km_down90.toml", 100.0),
    ] {
        let c = load(file, &data).camera(0);
        let above = c.position.z - data.height_at(c.position.x, c.position.y);
        assert!((above - km * 1000.0).abs() < 1e-6, "{file}: {above}");
    }
}
