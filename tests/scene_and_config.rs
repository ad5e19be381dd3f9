//! CPU-side pieces: camera maths, scenarios, configuration files, statistics, the index grid
//! and the height grid's validation.

use glam::{DVec3, Vec4};
use vkterrain::config::Config;
use vkterrain::dataset::Heightmap;
use vkterrain::dataset::procedural::{self, ProceduralParams, analytic};
use vkterrain::lod::brute::grid_indices;
use vkterrain::render::stats::Percentiles;
use vkterrain::scene::scenario::ScenarioFile;
use vkterrain::scene::{Camera, Scenario};

fn manifest(p: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

#[test]
fn reversed_z_maps_near_to_one_and_far_to_zero_and_inverts() {
    let cam = Camera {
        near: 0.5,
        far: 120_000.0,
        ..Camera::default()
    };
    let proj = cam.projection(16.0 / 9.0);
    for (dist, expected) in [(0.5, 1.0), (120_000.0, 0.0)] {
        let clip = proj * Vec4::new(0.0, 0.0, -(dist as f32), 1.0);
        assert!(
            (clip.z / clip.w - expected).abs() < 1e-6,
            "{dist} m -> {}",
            clip.z / clip.w
        );
    }
    for dist in [1.0, 37.0, 1_000.0, 99_000.0] {
        let clip = proj * Vec4::new(0.0, 0.0, -(dist as f32), 1.0);
        let back = cam.linear_depth(clip.z / clip.w);
        assert!(
            (back - dist).abs() / dist < 1e-5,
            "{dist} m round trips to {back} m"
        );
    }
}

#[test]
fn camera_basis_follows_the_documented_conventions() {
    let north = Camera {
        yaw_deg: 0.0,
        pitch_deg: 0.0,
        ..Camera::default()
    };
    let (right, up, forward) = north.basis();
    assert!((forward - DVec3::Y).length() < 1e-12 && (right - DVec3::X).length() < 1e-12);
    assert!((up - DVec3::Z).length() < 1e-12);
    let east = Camera {
        yaw_deg: 90.0,
        pitch_deg: 0.0,
        ..Camera::default()
    };
    assert!((east.basis().2 - DVec3::X).length() < 1e-12);
    let down = Camera {
        pitch_deg: -90.0,
        ..Camera::default()
    };
    assert!((down.basis().2 + DVec3::Z).length() < 1e-12);
    // Positive roll banks right: the camera's right vector tilts downwards.
    let rolled = Camera {
        roll_deg: 10.0,
        pitch_deg: 0.0,
        ..Camera::default()
    };
    assert!(rolled.basis().0.z < -0.1);
    // The centre pixel looks straight ahead; the top row looks up.
    let c = Camera::default();
    assert!((c.pixel_ray(320.0, 240.0, 640, 480) - c.basis().2).length() < 1e-12);
    assert!(c.pixel_ray(320.0, 0.0, 640, 480).z > c.basis().2.z);
}

#[test]
fn camera_rejects_bad_values() {
    let ok = Camera::default();
    assert!(ok.validate().is_ok());
    for bad in [
        Camera {
            position: DVec3::new(f64::NAN, 0.0, 0.0),
            ..ok
        },
        Camera {
            yaw_deg: f64::INFINITY,
            ..ok
        },
        Camera {
            pitch_deg: 91.0,
            ..ok
        },
        Camera {
            vfov_deg: 180.0,
            ..ok
        },
        Camera { near: 0.0, ..ok },
        Camera { far: 0.5, ..ok },
    ] {
        assert!(bad.validate().is_err(), "{bad:?} accepted");
    }
}

fn scenario(text: &str, data: &Heightmap) -> vkterrain::Result<Scenario> {
    let file: ScenarioFile = toml::from_str(text).unwrap();
    Scenario::resolve(&file, data)
}

#[test]
fn scenario_speed_times_and_short_way_headings() {
    let data = analytic::plane(33, 10.0, 100.0, 0.0, 0.0).unwrap();
    let s = scenario(
        "name = \"s\"\nfps = 10.0\nframes = 30\nspeed = 10.0\n\
         [[keyframe]]\nposition = [0.0, 0.0, 500.0]\nyaw = 350.0\n\
         [[keyframe]]\nposition = [0.0, 20.0, 500.0]\nyaw = 10.0\n",
        &data,
    )
    .unwrap();
    // 20 m at 10 m/s: the second key is at t = 2 s = frame 20; frame 10 is half way.
    let mid = s.camera(10);
    assert!(
        (mid.position - DVec3::new(0.0, 10.0, 500.0)).length() < 1e-9,
        "{}",
        mid.position
    );
    assert!(
        (mid.yaw_deg.rem_euclid(360.0) - 0.0).abs() < 1e-9 || (mid.yaw_deg - 360.0).abs() < 1e-9,
        "{}",
        mid.yaw_deg
    );
    assert_eq!(
        s.camera(25).position,
        s.camera(20).position,
        "holds the last key"
    );
    // Relative keyframes sit above the ground of the data set.
    let rel = scenario(
        "name = \"r\"\nframes = 1\n[[keyframe]]\nt = 0.0\nat = [0.5, 0.5]\nabove_ground = 50.0\n",
        &data,
    )
    .unwrap();
    assert!((rel.camera(0).position - DVec3::new(160.0, 160.0, 150.0)).length() < 1e-9);
    // Keyframes without time in a scenario without speed are an error.
    assert!(
        scenario(
            "name = \"x\"\nframes = 1\n[[keyframe]]\nposition = [0.0, 0.0, 1.0]\n",
            &data
        )
        .is_err()
    );
}

#[test]
fn shipped_configs_and_scenarios_load() {
    for c in ["config/default.toml", "config/ci.toml"] {
        let config = Config::load(Some(&manifest(c))).unwrap_or_else(|e| panic!("{c}: {e}"));
        config.validate().unwrap();
        let data = procedural::generate(&ProceduralParams {
            size: 65,
            ..Default::default()
        })
        .unwrap();
        let path = config.resolve(config.scenario.path.as_ref().unwrap());
        Scenario::load(&path, &data).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
    let data = analytic::plane(9, 1.0, 0.0, 0.0, 0.0).unwrap();
    let builtin = Scenario::builtin_default(&data).unwrap();
    assert!(builtin.frames > 0);
}

#[test]
fn percentiles_are_nearest_rank() {
    let p = Percentiles::of((1..=100).map(f64::from).collect());
    assert_eq!((p.median, p.p90, p.p99, p.max), (50.0, 90.0, 99.0, 100.0));
    assert!((p.mean - 50.5).abs() < 1e-12);
    let one = Percentiles::of(vec![7.0]);
    assert_eq!((one.median, one.p99), (7.0, 7.0));
}

#[test]
fn grid_indices_are_counter_clockwise_from_above() {
    let quads = 4;
    let idx = grid_indices(quads);
    assert_eq!(idx.len(), (quads * quads * 6) as usize);
    let pos = |i: u16| {
        (
            (i as u32 % (quads + 1)) as f64,
            (i as u32 / (quads + 1)) as f64,
        )
    };
    for t in idx.chunks(3) {
        let (a, b, c) = (pos(t[0]), pos(t[1]), pos(t[2]));
        let cross = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
        assert!(cross > 0.0, "triangle {t:?} is not CCW (x east, y north)");
    }
}

#[test]
fn height_grids_reject_bad_values() {
    assert!(Heightmap::new("t", 1, 5, 1.0, vec![0.0; 5]).is_err());
    assert!(Heightmap::new("t", 2, 2, 0.0, vec![0.0; 4]).is_err());
    assert!(Heightmap::new("t", 2, 2, 1.0, vec![0.0, f32::NAN, 0.0, 0.0]).is_err());
    assert!(Heightmap::new("t", 2, 2, 1.0, vec![0.0; 3]).is_err());
    let h = Heightmap::new("t", 2, 2, 10.0, vec![0.0, 10.0, 20.0, 30.0]).unwrap();
    assert_eq!(h.height_at(10.0, 10.0), 30.0);
    assert_eq!(h.height_at(5.0, 5.0), 15.0);
}

#[test]
fn procedural_terrain_is_deterministic_and_seeded() {
    let p = ProceduralParams {
        size: 65,
        ..Default::default()
    };
    let a = procedural::generate(&p).unwrap();
    let b = procedural::generate(&p).unwrap();
    assert_eq!(a.heights, b.heights);
    let c = procedural::generate(&ProceduralParams {
        seed: p.seed + 1,
        ..p
    })
    .unwrap();
    assert_ne!(a.heights, c.heights);
    let (lo, hi) = a.height_range();
    assert!(hi - lo > 100.0, "terrain has relief: {lo}..{hi}");
}

/// `kind = "xyz"` takes the tile source's keys beside it (no sub-table), resolves a relative
/// source against the config file's directory, and is valid only with the clipmap on.
#[test]
fn xyz_dataset_config_parses_with_its_keys_beside_kind() {
    use vkterrain::config::Config;
    use vkterrain::dataset::settings::DatasetConfig;
    use vkterrain::dataset::xyz::Encoding;
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("xyz.toml");
    std::fs::write(
        &path,
        "[dataset]\nkind = \"xyz\"\nsource = \"tiles/{z}/{x}/{y}.png\"\nencoding = \"mapbox\"\n\
         bbox = [1.3, 42.3, 1.6, 42.55]\nzoom = 11\ncache_max_mb = 64\n[clipmap]\nenabled = true\n",
    )
    .unwrap();
    let config = Config::load(Some(&path)).unwrap();
    let DatasetConfig::Xyz(x) = &config.dataset else {
        panic!("not an xyz data set: {:?}", config.dataset);
    };
    assert_eq!(x.encoding, Encoding::Mapbox);
    assert_eq!(x.bbox, [1.3, 42.3, 1.6, 42.55]);
    assert_eq!((x.zoom, x.cache_max_mb, x.tile_size), (11, 64, 256));
    assert_eq!(config.dataset.kind_name(), "xyz");
    assert!(config.dataset.streams_only());
    // A whole-grid load is refused with the way out in the message.
    let e = config
        .dataset
        .load(|p| p.to_path_buf())
        .unwrap_err()
        .to_string();
    assert!(e.contains("clipmap"), "{e}");
    // Opening the store resolves the directory template against the config's directory:
    // nothing is there, so the error names the resolved path.
    let e = config
        .open_store()
        .err()
        .expect("no tiles there")
        .to_string();
    assert!(
        e.contains(&tmp.path().join("tiles").display().to_string()),
        "{e}"
    );
}

/// `kind = "procedural"` takes the generator's character from the config (Hedberg's smooth /
/// average / uneven maps, config/hedberg_*.toml): each key changes the heights, the defaults
/// are the built-in terrain, and a non-positive height or feature size is a one-line error.
#[test]
fn procedural_config_sets_style_height_and_feature_size() {
    use vkterrain::config::Config;
    let tmp = tempfile::tempdir().unwrap();
    let load = |extra: &str| {
        let path = tmp.path().join("p.toml");
        std::fs::write(
            &path,
            format!("[dataset]\nkind = \"procedural\"\nsize = 65\n{extra}"),
        )
        .unwrap();
        let config = Config::load(Some(&path))?;
        config.validate()?;
        config.dataset.load(|p| p.to_path_buf())
    };
    let plain = load("").unwrap();
    let builtin = procedural::generate(&ProceduralParams {
        size: 65,
        ..Default::default()
    })
    .unwrap();
    assert_eq!(plain.heights, builtin.heights);
    assert_eq!(plain.name, builtin.name);
    for extra in [
        "style = \"alpine\"\n",
        "max_height = 600.0\n",
        "feature_size = 40000.0\n",
    ] {
        let other = load(extra).unwrap();
        assert_ne!(other.heights, plain.heights, "{extra}");
        assert_ne!(other.name, plain.name, "the description names {extra}");
    }
    let low = load("max_height = 600.0\n").unwrap();
    assert!(low.height_range().1 <= 600.0);
    for bad in ["max_height = 0.0\n", "feature_size = -1.0\n"] {
        let e = load(bad).unwrap_err().to_string();
        assert!(
            e.contains("must be positive") && !e.contains('\n'),
            "{bad}: {e}"
        );
    }
    assert!(load("style = \"lunar\"\n").is_err());
    for map in ["smooth", "average", "uneven"] {
        let c = format!("config/hedberg_{map}.toml");
        Config::load(Some(&manifest(&c)))
            .and_then(|c| c.validate())
            .unwrap_or_else(|e| panic!("{c}: {e}"));
    }
}
