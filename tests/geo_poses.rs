//! Poses on the earth against independent oracles: geodetic <-> ECEF equal to PROJ
//! (`EPSG:4979 -> EPSG:4978` through GDAL's OSR), the geoid's undulation as the height
//! difference between ellipsoidal and MSL poses, ground poses, WGS84 keyframes in scenarios,
//! and one-line errors where a pose cannot be placed.

use glam::DVec3;
use vkterrain::dataset::Heightmap;
use vkterrain::dataset::manifest::datum;
use vkterrain::dataset::settings::Anchor;
use vkterrain::dataset::world::{Placement, world_frame};
use vkterrain::geo::ellipsoid::Ellipsoid;
use vkterrain::geo::{GeoPose, Geodetic, HeightRef, WGS84};
use vkterrain::scene::scenario::ScenarioFile;
use vkterrain::scene::{Camera, Earth, Scenario};

/// A 101x101 grid at 30 m with heights 100 + col (so the ground under a pose is known).
fn ramp() -> Heightmap {
    let heights = (0..101 * 101).map(|i| 100.0 + (i % 101) as f32).collect();
    Heightmap::new("ramp", 101, 101, 30.0, heights).unwrap()
}

fn anchored(vertical_datum: &str) -> Earth {
    Earth::new(anchored_placement(vertical_datum))
}

fn anchored_placement(vertical_datum: &str) -> Placement {
    let frame = world_frame(
        None,
        Some(Anchor {
            lat_deg: 46.5,
            lon_deg: 8.0,
        }),
    )
    .unwrap()
    .unwrap();
    Placement {
        frame,
        georef: None,
        vertical_datum: vertical_datum.into(),
    }
}

fn pose(lat: f64, lon: f64, h: f64, r: HeightRef) -> GeoPose {
    GeoPose {
        lat_deg: lat,
        lon_deg: lon,
        height_m: h,
        height_ref: r,
        heading_deg: 200.0,
        pitch_deg: -15.0,
        roll_deg: 3.0,
    }
}

fn same_camera(a: &Camera, b: &Camera, tol_m: f64) -> bool {
    a.position.distance(b.position) <= tol_m
        && (a.yaw_deg - b.yaw_deg).abs() < 1e-9
        && (a.pitch_deg - b.pitch_deg).abs() < 1e-9
        && (a.roll_deg - b.roll_deg).abs() < 1e-9
}

#[cfg(feature = "gdal")]
#[test]
fn geodetic_to_ecef_equals_proj_within_a_millimetre() {
    use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};
    let mut geog = SpatialRef::from_epsg(4979).unwrap();
    let mut ecef = SpatialRef::from_epsg(4978).unwrap();
    geog.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    ecef.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
    let fwd = CoordTransform::new(&geog, &ecef).unwrap();
    let inv = CoordTransform::new(&ecef, &geog).unwrap();
    // Flattening 1/298 instead of 1/298.257: the negative control (18 m off at the poles).
    let wrong = Ellipsoid {
        a: WGS84.a,
        f: 1.0 / 298.0,
    };
    let mut wrong_seen = 0.0f64;
    let mut n = 0;
    for lat in [
        -89.5, -60.0, -33.9, 0.0, 0.001, 27.98, 46.5, 70.0, 80.0, 89.9,
    ] {
        for lon in [-179.9, -122.3, -0.5, 0.0, 8.0, 90.0, 179.9] {
            for h in [-430.0, 0.0, 4478.0, 8848.0, 35_000.0] {
                let (mut x, mut y, mut z) = ([lon], [lat], [h]);
                fwd.transform_coords(&mut x, &mut y, &mut z).unwrap();
                let proj = DVec3::new(x[0], y[0], z[0]);
                let ours = WGS84.to_ecef(Geodetic::new(lat, lon, h));
                assert!(
                    ours.distance(proj) < 1e-3,
                    "{lat} {lon} {h}: {ours} vs {proj}"
                );
                wrong_seen =
                    wrong_seen.max(wrong.to_ecef(Geodetic::new(lat, lon, h)).distance(proj));
                // And back: our inverse against PROJ's.
                let (mut gx, mut gy, mut gz) = ([proj.x], [proj.y], [proj.z]);
                inv.transform_coords(&mut gx, &mut gy, &mut gz).unwrap();
                let back = WGS84.to_geodetic(proj);
                let dlat = (back.lat_deg - gy[0]).to_radians() * WGS84.a;
                let dlon = (back.lon_deg - gx[0]).to_radians() * WGS84.a * lat.to_radians().cos();
                assert!(
                    dlat.abs() < 1e-3 && dlon.abs() < 1e-3,
                    "{lat} {lon} {h}: {back:?}"
                );
                assert!(
                    (back.height - gz[0]).abs() < 1e-3,
                    "{lat} {lon} {h}: {back:?} vs {}",
                    gz[0]
                );
                n += 1;
            }
        }
    }
    assert_eq!(n, 350);
    assert!(
        wrong_seen > 10.0,
        "a wrong flattening went unnoticed ({wrong_seen} m)"
    );
}

#[cfg(feature = "gdal")]
#[test]
fn msl_and_ellipsoidal_heights_differing_by_the_undulation_give_the_same_camera() {
    let data = ramp();
    let template = Camera::default();
    let (lat, lon) = (46.51, 8.02);
    for terrain_datum in [datum::LOCAL, datum::EGM96, datum::ELLIPSOID] {
        let earth = anchored(terrain_datum);
        let n = earth.msl_undulation(lat, lon).unwrap();
        assert!(
            (n - 50.7).abs() < 1.0,
            "EGM96 near 46.5 N 8 E is about +50.7 m: {n}"
        );
        let by_ellipsoid = earth
            .camera(
                &pose(lat, lon, 3000.0, HeightRef::Ellipsoid),
                &data,
                &template,
            )
            .unwrap();
        let by_msl = earth
            .camera(
                &pose(lat, lon, 3000.0 - n, HeightRef::Msl),
                &data,
                &template,
            )
            .unwrap();
        assert!(
            same_camera(&by_ellipsoid, &by_msl, 1e-6),
            "{terrain_datum}: {by_ellipsoid:?} vs {by_msl:?}"
        );
        // Negative control: the same number as MSL is N metres higher.
        let wrong = earth
            .camera(&pose(lat, lon, 3000.0, HeightRef::Msl), &data, &template)
            .unwrap();
        let dz = wrong.position.distance(by_ellipsoid.position);
        assert!((dz - n).abs() < 1e-6, "{terrain_datum}: {dz} vs N = {n}");
        // The reported pose (height in the terrain's datum + its undulation) comes back.
        let back = earth.pose(&by_msl).unwrap();
        assert!((back.height_m - 3000.0).abs() < 1e-6, "{back:?}");
        assert!((back.heading_deg - 200.0).abs() < 1e-8 && (back.lat_deg - lat).abs() < 1e-10);
    }
    // The terrain's datum decides where the camera goes: over EGM96 terrain an MSL height is
    // used as it is (the terrain's heights are MSL heights); over ellipsoidal terrain it
    // gains N.
    let over_egm96 = anchored(datum::EGM96)
        .camera(&pose(lat, lon, 2000.0, HeightRef::Msl), &data, &template)
        .unwrap();
    let over_ellipsoid = anchored(datum::ELLIPSOID)
        .camera(&pose(lat, lon, 2000.0, HeightRef::Msl), &data, &template)
        .unwrap();
    let n = anchored(datum::EGM96).msl_undulation(lat, lon).unwrap();
    assert!((over_ellipsoid.position.distance(over_egm96.position) - n).abs() < 1e-6);
}

#[test]
fn ground_poses_stand_on_the_terrain() {
    let data = ramp();
    let earth = anchored(datum::LOCAL);
    // A place about 1.5 km east and 1.2 km north of the anchor, inside the 3 km grid.
    let at = WGS84.to_geodetic(earth.frame().to_ecef(DVec3::new(1500.0, 1200.0, 0.0)));
    let cam = earth
        .camera(
            &pose(at.lat_deg, at.lon_deg, 250.0, HeightRef::Ground),
            &data,
            &Camera::default(),
        )
        .unwrap();
    // Ground there: 100 + x / 30 = 150 m, so the camera is 400 m above the ellipsoid point.
    let g = WGS84.to_geodetic(earth.frame().to_ecef(cam.position));
    // 0.1 mm: the f64 ECEF round trip through `to_geodetic` (seen: 2.3 micrometres).
    assert!((g.height - 400.0).abs() < 1e-4, "{g:?}");
    assert!((cam.position.x - 1500.0).abs() < 0.5 && (cam.position.y - 1200.0).abs() < 0.5);
    // Outside the data set: no ground, one line.
    let e = earth
        .camera(
            &pose(47.5, 8.0, 10.0, HeightRef::Ground),
            &data,
            &Camera::default(),
        )
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("outside the data set") && !e.contains('\n'),
        "{e}"
    );
}

#[test]
fn wgs84_keyframes_fly_over_the_earth_and_need_a_world_frame() {
    let data = ramp();
    let earth = anchored(datum::LOCAL);
    let text = r#"
        name = "geo"
        frames = 31
        fps = 30.0
        [[keyframe]]
        t = 0.0
        lat_deg = 46.5
        lon_deg = 8.0
        height_m = 1000.0
        heading_deg = 350.0
        pitch_deg = -10.0
        [[keyframe]]
        t = 1.0
        lat_deg = 46.95
        lon_deg = 8.0
        height_m = 1000.0
        heading_deg = 10.0
        pitch_deg = -10.0
    "#;
    let file: ScenarioFile = toml::from_str(text).unwrap();
    let s = Scenario::resolve_on(&file, &data, Some(&earth), false).unwrap();
    // Half-way (50 km north): on the ellipsoid-following path, 1000 m above the ellipsoid
    // (a straight chord would sag about 196 m below it), heading true north.
    let mid = s.camera(15);
    let g = earth.pose(&mid).unwrap();
    assert!((g.height_m - 1000.0).abs() < 1e-6, "{g:?}");
    assert!((g.lat_deg - 46.725).abs() < 1e-9 && g.heading_deg.min(360.0 - g.heading_deg) < 1e-6);
    assert!((g.pitch_deg + 10.0).abs() < 1e-9, "{g:?}");
    // Half-way is 25 km north of the anchor (46.5N): the world's z there is 1000 m less the
    // drop d^2 / 2R (about 49 m), computed here from the meridian radius, within 2 m.
    let d = mid.position.y;
    let drop = d * d / (2.0 * WGS84.meridian_radius(46.6));
    assert!(
        (mid.position.z - (1000.0 - drop)).abs() < 2.0 && drop > 40.0,
        "the world's z drops with curvature by {drop} m: {mid:?}"
    );
    // The ends are the keyframes.
    let end = earth.pose(&s.camera(30)).unwrap();
    assert!((end.lat_deg - 46.95).abs() < 1e-9 && (end.heading_deg - 10.0).abs() < 1e-6);
    // No world frame: one line naming the cause.
    let e = Scenario::resolve_on(&file, &data, None, false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("on the earth") && !e.contains('\n'), "{e}");
    // World angles do not mix with a WGS84 keyframe.
    let mixed: ScenarioFile =
        toml::from_str(&text.replacen("pitch_deg = -10.0", "pitch = -10.0", 1)).unwrap();
    let e = Scenario::resolve_on(&mixed, &data, Some(&earth), false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("heading_deg") && !e.contains('\n'), "{e}");
}

/// Keyframes given on the grid (`position`, `at`) over a data set drawn on the ellipsoid are
/// placed over their own samples there: the camera sits where the geolocation lattice puts
/// the sample at the keyframe's height (within the lattice's 1 cm interpolation), looks along
/// yaw/pitch against the lattice's own local axes there (grid north, up), and frames between
/// two keyframes keep their height above the drawn surface. Negative control: resolved flat
/// (`grid_on_earth` false), the same keyframe 90 km from the anchor is ~640 m too high above
/// the drawn surface.
#[test]
fn grid_keyframes_follow_the_terrain_onto_the_ellipsoid() {
    use glam::DVec2;
    use std::sync::Arc;
    use vkterrain::dataset::Terrain;
    let data = Heightmap::new("flat", 1001, 1001, 100.0, vec![500.0; 1001 * 1001]).unwrap();
    let earth = anchored(datum::LOCAL);
    let terrain = Terrain::from(Arc::new(data.clone()));
    let lattice = earth.placement.lattice(&terrain).unwrap();
    assert_eq!(lattice.step, 5);
    let text = r#"
        name = "grid"
        frames = 31
        fps = 30.0
        [[keyframe]]
        t = 0.0
        position = [80000.0, 40000.0, 2000.0]
        yaw = 30.0
        pitch = -20.0
        roll = 5.0
        [[keyframe]]
        t = 1.0
        position = [80000.0, 60000.0, 2000.0]
        yaw = 30.0
        pitch = -20.0
        roll = 5.0
    "#;
    let file: ScenarioFile = toml::from_str(text).unwrap();
    let s = Scenario::resolve_on(&file, &data, Some(&earth), true).unwrap();
    let c = s.camera(0);
    let expected = lattice.position(DVec2::new(800.0, 400.0), 2000.0);
    assert!(
        c.position.distance(expected) < 0.02,
        "camera {} vs the lattice's {expected}",
        c.position
    );
    // The lattice's local axes at that sample: up, grid north made orthogonal to it, east.
    let s0 = DVec2::new(800.0, 400.0);
    let base = lattice.position(s0, 0.0);
    let up = (lattice.position(s0, 1.0) - base).normalize();
    let north_dir = lattice.position(s0 + DVec2::Y, 0.0) - base;
    let north = (north_dir - up * north_dir.dot(up)).normalize();
    let east = north.cross(up);
    let (r, u, f) = vkterrain::geo::pose::euler_basis(30.0, -20.0, 5.0);
    let to_world = |v: DVec3| east * v.x + north * v.y + up * v.z;
    let (cr, cu, cf) = c.basis();
    for (got, want) in [(cr, to_world(r)), (cu, to_world(u)), (cf, to_world(f))] {
        assert!(got.angle_between(want) < 1e-5, "{got} vs {want}");
    }
    // Half-way: 2000 m above the drawn surface (the flat grid's ground is at 500 m).
    let (_, h_mid) = lattice.sample_at(s.camera(15).position);
    assert!((h_mid - 2000.0).abs() < 0.05, "{h_mid}");
    // Negative control: placed flat, the keyframe is the curvature drop too high.
    let flat = Scenario::resolve_on(&file, &data, Some(&earth), false).unwrap();
    let (_, h_flat) = lattice.sample_at(flat.camera(0).position);
    assert!(h_flat - 2000.0 > 500.0, "{h_flat}");
}

/// `[[render.extra_views]]` on the earth are rig offsets in the local frame at the main camera:
/// 50 km north of the world frame's origin, a rear view 10 m up pitched 5 deg down has, as a
/// WGS84 pose, the main camera's latitude/longitude, 10 m more height, heading + 180 and local
/// pitch -5. Negative control: applied in the world frame's axes (`ViewOffset::apply`, the
/// flat world), its local pitch is off by the frame's tilt there (~0.45 deg).
#[test]
fn extra_views_are_rig_offsets_in_the_local_frame_on_the_earth() {
    use vkterrain::scene::ViewOffset;
    let earth = anchored(datum::LOCAL);
    let frame = earth.frame();
    let main_pose = GeoPose {
        lat_deg: 46.95,
        lon_deg: 8.0,
        height_m: 1500.0,
        height_ref: HeightRef::Ellipsoid,
        heading_deg: 30.0,
        pitch_deg: 0.0,
        roll_deg: 0.0,
    };
    let w = main_pose.to_world(frame, 1500.0);
    let main = Camera {
        position: w.position,
        yaw_deg: w.yaw_deg,
        pitch_deg: w.pitch_deg,
        roll_deg: w.roll_deg,
        ..Camera::default()
    };
    let rig = ViewOffset {
        offset_m: [0.0, 0.0, 10.0],
        yaw_deg: 180.0,
        pitch_deg: Some(-5.0),
    };
    let pose_of = |c: &Camera| GeoPose::from_world(frame, &c.into());
    let g = pose_of(&rig.apply_on(&main, Some(frame)));
    assert!(
        (g.lat_deg - 46.95).abs() < 1e-9 && (g.lon_deg - 8.0).abs() < 1e-9,
        "{g:?}"
    );
    assert!((g.height_m - 1510.0).abs() < 1e-6, "{g:?}");
    assert!((g.heading_deg - 210.0).abs() < 1e-6, "{g:?}");
    assert!(
        (g.pitch_deg + 5.0).abs() < 1e-6 && g.roll_deg.abs() < 1e-6,
        "{g:?}"
    );
    let flat = pose_of(&rig.apply(&main));
    assert!((flat.pitch_deg + 5.0).abs() > 0.3, "{flat:?}");
    // Without a world frame `apply_on` is `apply`.
    assert_eq!(rig.apply_on(&main, None), rig.apply(&main));
}

/// Drawn on the ellipsoid, the lattice carries the terrain's geoid, so world heights are
/// ellipsoidal: a camera by ellipsoidal height `h` is at `h` above the ellipsoid at its own
/// position, by MSL height `H` at `H + N96` there, by ground height at the terrain there plus
/// the terrain's undulation plus `h`, over EGM96 and ellipsoidal terrain alike; the reported
/// pose gives `h` back. Negative control: the flat world's earth (heights in the terrain's
/// datum) puts the same ellipsoidal camera `N` lower.
#[cfg(feature = "gdal")]
#[test]
fn on_the_lattice_poses_keep_their_ellipsoidal_height() {
    let data = ramp();
    let template = Camera::default();
    let (lat, lon) = (46.51, 8.02);
    let height_at = |e: &Earth, c: &Camera| WGS84.to_geodetic(e.frame().to_ecef(c.position)).height;
    let n = anchored(datum::EGM96).msl_undulation(lat, lon).unwrap();
    for terrain_datum in [datum::EGM96, datum::ELLIPSOID, datum::LOCAL] {
        let earth = Earth::on_lattice(anchored_placement(terrain_datum));
        assert!(earth.ellipsoidal_world());
        let by_ellipsoid = earth
            .camera(
                &pose(lat, lon, 3000.0, HeightRef::Ellipsoid),
                &data,
                &template,
            )
            .unwrap();
        assert!((height_at(&earth, &by_ellipsoid) - 3000.0).abs() < 1e-6);
        let by_msl = earth
            .camera(
                &pose(lat, lon, 3000.0 - n, HeightRef::Msl),
                &data,
                &template,
            )
            .unwrap();
        assert!(
            same_camera(&by_ellipsoid, &by_msl, 1e-6),
            "{terrain_datum}: {by_ellipsoid:?} vs {by_msl:?}"
        );
        let back = earth.pose(&by_msl).unwrap();
        assert!((back.height_m - 3000.0).abs() < 1e-6, "{back:?}");
        // Ground: the ramp is 100 + x / 30 m in the terrain's datum, lifted by its undulation.
        let at = WGS84.to_geodetic(earth.frame().to_ecef(DVec3::new(1500.0, 1200.0, 0.0)));
        let ground = earth
            .camera(
                &pose(at.lat_deg, at.lon_deg, 250.0, HeightRef::Ground),
                &data,
                &template,
            )
            .unwrap();
        let n_there = earth.terrain_undulation(at.lat_deg, at.lon_deg).unwrap();
        let want = 150.0 + n_there + 250.0;
        let got = height_at(&earth, &ground);
        assert!(
            (got - want).abs() < 1e-3,
            "{terrain_datum}: ground camera at {got} m, want {want}"
        );
        assert_eq!(n_there == 0.0, terrain_datum != datum::EGM96, "{n_there}");
        // A grid height in the terrain's datum gains the terrain's undulation.
        let z = earth.terrain_to_world(lat, lon, 700.0).unwrap();
        assert_eq!(
            z,
            700.0
                + if terrain_datum == datum::EGM96 {
                    n
                } else {
                    0.0
                }
        );
    }
    // Negative control: the flat world's earth lowers the ellipsoidal camera into EGM96
    // heights at the camera.
    let old = anchored(datum::EGM96)
        .camera(
            &pose(lat, lon, 3000.0, HeightRef::Ellipsoid),
            &data,
            &template,
        )
        .unwrap();
    let new = Earth::on_lattice(anchored_placement(datum::EGM96))
        .camera(
            &pose(lat, lon, 3000.0, HeightRef::Ellipsoid),
            &data,
            &template,
        )
        .unwrap();
    let dz = old.position.distance(new.position);
    assert!((dz - n).abs() < 1e-6, "{dz} vs N = {n}");
}

/// Grid keyframes over EGM96 terrain drawn on the ellipsoid (a flat 500 m grid anchored at
/// 46.5 N 8 E, 100 km across, its lattice lifted onto EGM96 through PROJ): the keyframe camera
/// is where the lattice puts its grid position and height (within 2 cm), and half-way between
/// two keyframes 20 km apart its height above the drawn surface is the keyframes' within the
/// geoid's departure from linear (heights interpolate above the ellipsoid). Negative control:
/// the flat world's earth leaves the camera at its height above the ellipsoid, N (about 50 m)
/// too low over the geoid-lifted terrain.
#[cfg(feature = "gdal")]
#[test]
fn grid_keyframes_over_egm96_terrain_keep_their_height_above_the_geoid() {
    use glam::DVec2;
    use std::sync::Arc;
    use vkterrain::dataset::Terrain;
    let data = Heightmap::new("flat", 1001, 1001, 100.0, vec![500.0; 1001 * 1001]).unwrap();
    let placement = anchored_placement(datum::EGM96);
    let terrain = Terrain::from(Arc::new(data.clone()));
    let lattice = placement.lattice(&terrain).unwrap();
    let n = lattice.datum_heights();
    let (lo, hi) = n
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(*v), b.max(*v)));
    println!(
        "EGM96 over the lattice: {lo:.2} .. {hi:.2} m over {} nodes",
        n.len()
    );
    assert!(lo > 40.0 && hi < 60.0 && hi - lo > 1.0, "{lo} .. {hi}");
    let text = r#"
        name = "grid"
        frames = 31
        fps = 30.0
        [[keyframe]]
        t = 0.0
        position = [80000.0, 40000.0, 2000.0]
        yaw = 30.0
        pitch = -20.0
        [[keyframe]]
        t = 1.0
        position = [80000.0, 60000.0, 2000.0]
        yaw = 30.0
        pitch = -20.0
    "#;
    let file: ScenarioFile = toml::from_str(text).unwrap();
    let earth = Earth::on_lattice(placement.clone());
    let s = Scenario::resolve_on(&file, &data, Some(&earth), true).unwrap();
    let expected = lattice.position(DVec2::new(800.0, 400.0), 2000.0);
    let miss = s.camera(0).position.distance(expected);
    assert!(
        miss < 0.02,
        "keyframe camera {miss} m from the lattice's point"
    );
    let (_, h_mid) = lattice.sample_at(s.camera(15).position);
    println!("keyframe miss {miss:.4} m; half-way {h_mid:.4} m above the drawn geoid");
    // Between the keys the height is interpolated above the geoid, not above the ellipsoid:
    // the chord of the undulation between the keys would miss by `chord` half-way.
    let undulation = |c: &Camera| {
        let g = WGS84.to_geodetic(earth.frame().to_ecef(c.position));
        earth.msl_undulation(g.lat_deg, g.lon_deg).unwrap()
    };
    let (n0, n15, n30) = (
        undulation(&s.camera(0)),
        undulation(&s.camera(15)),
        undulation(&s.camera(30)),
    );
    let chord = (n0 + n30) / 2.0 - n15;
    println!("geoid chord half-way {:.4} m", chord);
    assert!(
        chord.abs() > 0.008,
        "the control needs a bent geoid: {chord}"
    );
    assert!((h_mid - 2000.0).abs() < 0.003, "{h_mid}");
    // Negative control: the flat world's earth.
    let old = Scenario::resolve_on(&file, &data, Some(&Earth::new(placement)), true).unwrap();
    let (_, h_old) = lattice.sample_at(old.camera(0).position);
    println!("the flat world's earth: {h_old:.2} m above the drawn geoid");
    assert!(h_old < 1960.0, "{h_old}");
}

/// Two WGS84 keyframes at one height above mean sea level, 20 km apart: half-way the camera
/// is at that height above the geoid there (`H + N` of its own position), not on the chord
/// of the undulation between the keys (1.2 cm off near 46.6 N 8.3 E).
#[cfg(feature = "gdal")]
#[test]
fn msl_keyframes_keep_their_height_above_the_geoid_between_keys() {
    let data = Heightmap::new("flat", 1001, 1001, 100.0, vec![500.0; 1001 * 1001]).unwrap();
    let earth = Earth::on_lattice(anchored_placement(datum::EGM96));
    let text = r#"
        name = "msl"
        frames = 31
        fps = 30.0
        [[keyframe]]
        t = 0.0
        lat_deg = 46.6
        lon_deg = 8.3
        height_m = 2000.0
        height_ref = "msl"
        heading_deg = 0.0
        pitch_deg = -10.0
        [[keyframe]]
        t = 1.0
        lat_deg = 46.78
        lon_deg = 8.3
        height_m = 2000.0
        height_ref = "msl"
        heading_deg = 0.0
        pitch_deg = -10.0
    "#;
    let file: ScenarioFile = toml::from_str(text).unwrap();
    let s = Scenario::resolve_on(&file, &data, Some(&earth), false).unwrap();
    let msl = |c: &Camera| {
        let g = WGS84.to_geodetic(earth.frame().to_ecef(c.position));
        let n = earth.msl_undulation(g.lat_deg, g.lon_deg).unwrap();
        (g.height - n, n)
    };
    let ((h0, n0), (h15, n15), (h30, n30)) =
        (msl(&s.camera(0)), msl(&s.camera(15)), msl(&s.camera(30)));
    let chord = (n0 + n30) / 2.0 - n15;
    println!("MSL heights {h0:.5} / {h15:.5} / {h30:.5} m; geoid chord half-way {chord:.4} m");
    assert!(
        chord.abs() > 0.008,
        "the control needs a bent geoid: {chord}"
    );
    for h in [h0, h15, h30] {
        assert!((h - 2000.0).abs() < 0.001, "{h}");
    }
}

/// EGM2008 heights on the ellipsoid need PROJ's EGM2008 grid (`egm08_25.gtx`, which Debian's
/// `proj-data` does not ship): without it opening the lattice is a one-line error naming the
/// geoid, never a lattice at `N = 0`; with it the lattice is lifted by `N08` (about +50 m
/// there, like EGM96's).
#[cfg(feature = "gdal")]
#[test]
fn egm2008_heights_without_their_grid_are_a_one_line_error() {
    use std::sync::Arc;
    use vkterrain::dataset::Terrain;
    use vkterrain::dataset::geoid::{Geoid, GeoidModel};
    let terrain = Terrain::from(Arc::new(ramp()));
    let placement = anchored_placement(datum::EGM2008);
    match Geoid::new(GeoidModel::Egm2008) {
        Err(_) => {
            let e = placement.lattice(&terrain).unwrap_err().to_string();
            println!("{e}");
            assert!(
                e.contains("EGM2008") && e.contains("egm08_25.gtx") && !e.contains('\n'),
                "{e}"
            );
            assert!(e.len() < 400, "{} bytes: {e}", e.len());
        }
        Ok(_) => {
            let l = placement.lattice(&terrain).unwrap();
            assert!(l.datum_heights().iter().all(|n| (n - 50.0).abs() < 5.0));
        }
    }
    // EGM96 heights there: lifted by N96.
    let l = anchored_placement(datum::EGM96).lattice(&terrain).unwrap();
    assert!(l.datum_heights().iter().all(|n| (n - 50.7).abs() < 1.0));
}
