//! Scripted camera paths (`config/scenarios/*.toml`), frame-indexed so runs are reproducible.
//!
//! Time is `frame / fps`: never the wall clock, so frame `k` shows the same view on every
//! machine. Keyframes are either timed (`t` in seconds) or, when the scenario gives `speed`
//! (m/s), timed by the path length. Positions are absolute metres (`position = [x, y, z]`) or
//! relative to the data set (`at = [u, v]` as fractions of its extent, with `above_ground` or
//! `altitude` in metres), so one scenario can fly over any data set, or on the earth
//! (`lat_deg`, `lon_deg`, `height_m`, `height_ref`, `heading_deg`, `pitch_deg`, `roll_deg`:
//! a [`GeoPose`], for a data set with a world frame). Between two earth keyframes the camera
//! moves along latitude, longitude and height (not along the chord through the earth) and
//! turns its local heading the short way.

use std::path::Path;

use glam::DVec3;
use serde::Deserialize;

use super::{Camera, Earth};
use crate::dataset::Level0;
use crate::error::{Error, Result};
use crate::geo::{EnuFrame, GeoPose, HeightRef, WGS84};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    pub name: String,
    #[serde(default = "default_fps")]
    pub fps: f64,
    /// Frames rendered when the command line does not say.
    pub frames: u32,
    /// Constant speed along the path in m/s (keyframe times are then derived).
    pub speed: Option<f64>,
    #[serde(default = "default_vfov")]
    pub vfov_deg: f64,
    #[serde(default = "default_near")]
    pub near: f64,
    #[serde(default = "default_far")]
    pub far: f64,
    #[serde(rename = "keyframe")]
    pub keyframes: Vec<KeyframeSpec>,
}

fn default_fps() -> f64 {
    30.0
}
fn default_vfov() -> f64 {
    60.0
}
fn default_near() -> f64 {
    1.0
}
fn default_far() -> f64 {
    200_000.0
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyframeSpec {
    pub t: Option<f64>,
    pub position: Option<[f64; 3]>,
    pub at: Option<[f64; 2]>,
    pub above_ground: Option<f64>,
    pub altitude: Option<f64>,
    #[serde(default)]
    pub yaw: f64,
    #[serde(default)]
    pub pitch: f64,
    #[serde(default)]
    pub roll: f64,
    pub lat_deg: Option<f64>,
    pub lon_deg: Option<f64>,
    pub height_m: Option<f64>,
    pub height_ref: Option<HeightRef>,
    pub heading_deg: Option<f64>,
    pub pitch_deg: Option<f64>,
    pub roll_deg: Option<f64>,
}

impl KeyframeSpec {
    /// Whether this keyframe is a WGS84 pose.
    pub fn is_geo(&self) -> bool {
        self.lat_deg.is_some() || self.lon_deg.is_some() || self.height_m.is_some()
    }

    /// The camera position of a keyframe given on the grid (`position`, or `at` with
    /// `above_ground`/`altitude`) in the grid's world metres; its angles are `yaw`/`pitch`/
    /// `roll` (the WGS84 ones do not mix with it).
    fn grid_position<D: Level0 + ?Sized>(&self, i: usize, data: &D) -> Result<DVec3> {
        let bad = |m: &str| Err(Error::invalid("scenario", format!("keyframe {i}: {m}")));
        if self.heading_deg.is_some() || self.pitch_deg.is_some() || self.roll_deg.is_some() {
            return bad(
                "`heading_deg`/`pitch_deg`/`roll_deg` go with `lat_deg`/`lon_deg`/`height_m`; use `yaw`/`pitch`/`roll` with `position`/`at`",
            );
        }
        match (self.position, self.at) {
            (Some(p), None) => {
                if self.above_ground.is_some() || self.altitude.is_some() {
                    return bad("`above_ground`/`altitude` go with `at`, not `position`");
                }
                Ok(DVec3::from_array(p))
            }
            (None, Some([u, v])) => {
                let (ex, ey) = data.extent();
                let (x, y) = (u * ex, v * ey);
                let z = match (self.above_ground, self.altitude) {
                    (Some(a), None) => data.bilinear(x, y)? + a,
                    (None, Some(a)) => a,
                    _ => return bad("`at` needs exactly one of `above_ground`, `altitude`"),
                };
                Ok(DVec3::new(x, y, z))
            }
            _ => bad("give exactly one of `position`, `at`"),
        }
    }

    /// Keyframe `i` as the scenario interpolates it (time still NaN where not given).
    fn key<D: Level0 + ?Sized>(
        &self,
        i: usize,
        data: &D,
        earth: Option<&Earth>,
        grid_on_earth: bool,
        template: &Camera,
    ) -> Result<Key> {
        if self.is_geo() {
            let pose = self.geo_pose(i)?;
            let Some(earth) = earth else {
                return Err(Error::invalid(
                    "scenario",
                    format!(
                        "keyframe {i}: a WGS84 pose needs a data set on the earth (georeferenced, or [dataset] anchor)"
                    ),
                ));
            };
            let t = self.t.unwrap_or(f64::NAN);
            return Key::on_earth(earth, &pose, None, t, data, template);
        }
        let position = self.grid_position(i, data)?;
        if let (true, Some(earth)) = (grid_on_earth, earth) {
            let pose = earth.grid_pose(data, position, self.yaw, self.pitch, self.roll)?;
            let t = self.t.unwrap_or(f64::NAN);
            return Key::on_earth(earth, &pose, Some(position.z), t, data, template);
        }
        Ok(Key {
            t: self.t.unwrap_or(f64::NAN),
            position,
            yaw: self.yaw,
            pitch: self.pitch,
            roll: self.roll,
            geo: None,
            given: None,
        })
    }

    /// The keyframe's WGS84 pose; `yaw`/`pitch`/`roll` (world angles) do not mix with it.
    fn geo_pose(&self, i: usize) -> Result<GeoPose> {
        let bad = |m: &str| Err(Error::invalid("scenario", format!("keyframe {i}: {m}")));
        if self.position.is_some() || self.at.is_some() {
            return bad("give either `position`/`at` or `lat_deg`/`lon_deg`/`height_m`");
        }
        if self.yaw != 0.0 || self.pitch != 0.0 || self.roll != 0.0 {
            return bad(
                "a WGS84 keyframe takes `heading_deg`, `pitch_deg`, `roll_deg` (local north-east-down), not `yaw`/`pitch`/`roll`",
            );
        }
        let (Some(lat_deg), Some(lon_deg), Some(height_m)) =
            (self.lat_deg, self.lon_deg, self.height_m)
        else {
            return bad("a WGS84 keyframe needs all of `lat_deg`, `lon_deg`, `height_m`");
        };
        let pose = GeoPose {
            lat_deg,
            lon_deg,
            height_m,
            height_ref: self.height_ref.unwrap_or_default(),
            heading_deg: self.heading_deg.unwrap_or(0.0),
            pitch_deg: self.pitch_deg.unwrap_or(0.0),
            roll_deg: self.roll_deg.unwrap_or(0.0),
        };
        pose.validate(&format!("scenario keyframe {i}"))?;
        Ok(pose)
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Key {
    t: f64,
    position: DVec3,
    yaw: f64,
    pitch: f64,
    roll: f64,
    /// A WGS84 keyframe, its height in the world's datum (above the ellipsoid on the lattice,
    /// `Earth::world_height`), interpolated linearly between keys.
    geo: Option<GeoPose>,
    /// An earth key's pose as given (its height above its own reference) and, for a key
    /// given on the grid, its height in the terrain's datum: what the heights between two
    /// keys given alike are interpolated in ([`Scenario::own_datum_heights`]).
    given: Option<(GeoPose, Option<f64>)>,
}

impl Key {
    /// A key on the earth at time `t`: `pose` placed by `earth` (`world_height`: its height is
    /// already in the terrain's datum, as for grid keyframes; None: `height_m` above
    /// `height_ref`, as WGS84 keyframes give it), kept as a WGS84 pose with its height above
    /// the ellipsoid for the interpolation between keys.
    fn on_earth<D: Level0 + ?Sized>(
        earth: &Earth,
        pose: &GeoPose,
        world_height: Option<f64>,
        t: f64,
        data: &D,
        template: &Camera,
    ) -> Result<Key> {
        let c = match world_height {
            Some(h) => {
                let h = earth.terrain_to_world(pose.lat_deg, pose.lon_deg, h)?;
                earth.camera_at(pose, h, template)?
            }
            None => earth.camera(pose, data, template)?,
        };
        let height = WGS84.to_geodetic(earth.frame().to_ecef(c.position)).height;
        Ok(Key {
            t,
            position: c.position,
            yaw: c.yaw_deg,
            pitch: c.pitch_deg,
            roll: c.roll_deg,
            geo: Some(GeoPose {
                height_m: height,
                height_ref: HeightRef::Ellipsoid,
                ..*pose
            }),
            given: Some((*pose, world_height)),
        })
    }

    /// Whether the heights between this key and `next` follow a datum of their own (both
    /// above mean sea level, or both given on the grid in the terrain's datum) rather than
    /// the ellipsoid: their heights are then interpolated in that datum.
    fn shares_own_datum(&self, next: &Key) -> bool {
        match (self.given, next.given) {
            (Some((a, None)), Some((b, None))) => {
                a.height_ref == HeightRef::Msl && b.height_ref == HeightRef::Msl
            }
            (Some((_, Some(_))), Some((_, Some(_)))) => true,
            _ => false,
        }
    }
}

/// Samples per segment of a path's heights in the keys' own datum: the geoid's undulation
/// between them is linear over 1/64 of a segment (EGM96 bends by millimetres over
/// kilometres; docs/coordinates.md "Datums").
const SEGMENT_SAMPLES: usize = 64;

/// A resolved camera path.
#[derive(Clone, Debug)]
pub struct Scenario {
    pub name: String,
    pub fps: f64,
    pub frames: u32,
    template: Camera,
    keys: Vec<Key>,
    /// The world frame WGS84 keyframes are placed in.
    frame: Option<EnuFrame>,
    /// Per segment (key `i` to `i + 1`) whose keys share a datum of their own: the ellipsoidal
    /// heights of `SEGMENT_SAMPLES + 1` evenly spaced points of it, interpolated in that
    /// datum ([`Scenario::own_datum_heights`]); None: heights above the ellipsoid interpolate.
    segment_heights: Vec<Option<Vec<f64>>>,
}

impl Scenario {
    /// Reads and resolves a scenario file against a data set.
    pub fn load<D: Level0 + ?Sized>(path: &Path, data: &D) -> Result<Self> {
        Self::load_on(path, data, || Ok(None), false)
    }

    /// Reads and resolves a scenario file whose WGS84 keyframes (if any) are placed on `earth`
    /// (asked for only when the file has such keyframes or `grid_on_earth`). `grid_on_earth`:
    /// the terrain is drawn on the ellipsoid, so keyframes given on the grid are placed over
    /// their samples there too ([`Earth::grid_pose`]).
    pub fn load_on<D: Level0 + ?Sized>(
        path: &Path,
        data: &D,
        earth: impl FnOnce() -> Result<Option<Earth>>,
        grid_on_earth: bool,
    ) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let file: ScenarioFile = toml::from_str(&text).map_err(|e| Error::toml(path, &text, &e))?;
        let resolved = if grid_on_earth || file.keyframes.iter().any(KeyframeSpec::is_geo) {
            earth().and_then(|e| Self::resolve_on(&file, data, e.as_ref(), grid_on_earth))
        } else {
            Self::resolve(&file, data)
        };
        resolved.map_err(|e| Error::Config {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }

    /// The default flight, compiled in so the binary needs no files beside it.
    pub fn builtin_default<D: Level0 + ?Sized>(data: &D) -> Result<Self> {
        Self::builtin_default_on(data, None)
    }

    /// [`Scenario::builtin_default`] over the terrain drawn on `earth`'s ellipsoid.
    pub fn builtin_default_on<D: Level0 + ?Sized>(data: &D, earth: Option<&Earth>) -> Result<Self> {
        const TEXT: &str = include_str!("../../config/scenarios/default.toml");
        let file: ScenarioFile =
            toml::from_str(TEXT).map_err(|e| Error::invalid("built-in scenario", e.to_string()))?;
        Self::resolve_on(&file, data, earth, earth.is_some())
    }

    /// `data`: level-0 heights (exact; a tile pyramid is read node by node) for
    /// `above_ground` keyframes.
    pub fn resolve<D: Level0 + ?Sized>(file: &ScenarioFile, data: &D) -> Result<Self> {
        Self::resolve_on(file, data, None, false)
    }

    /// [`Scenario::resolve`] with WGS84 keyframes placed on `earth` (none: such keyframes are
    /// an error), and with `grid_on_earth` also the keyframes given on the grid (`at`,
    /// `position`: over their samples on the ellipsoid, [`Earth::grid_pose`]; frames between
    /// them then follow latitude, longitude and height like WGS84 keyframes).
    pub fn resolve_on<D: Level0 + ?Sized>(
        file: &ScenarioFile,
        data: &D,
        earth: Option<&Earth>,
        grid_on_earth: bool,
    ) -> Result<Self> {
        let bad = |m: String| Err(Error::invalid("scenario", m));
        if !(file.fps.is_finite() && file.fps > 0.0) {
            return bad(format!("fps {} must be positive", file.fps));
        }
        if file.keyframes.is_empty() {
            return bad("no [[keyframe]]".into());
        }
        let mut keys = Vec::with_capacity(file.keyframes.len());
        let template = Camera {
            vfov_deg: file.vfov_deg,
            near: file.near,
            far: file.far,
            ..Camera::default()
        };
        for (i, k) in file.keyframes.iter().enumerate() {
            keys.push(k.key(i, data, earth, grid_on_earth, &template)?);
        }
        Self::time_keys(file, &mut keys)?;
        let template = Camera {
            position: keys[0].position,
            yaw_deg: keys[0].yaw,
            pitch_deg: keys[0].pitch,
            roll_deg: keys[0].roll,
            ..template
        };
        let segment_heights = match earth {
            Some(e) => Self::own_datum_heights(&keys, e, data, &template)?,
            None => Vec::new(),
        };
        let scenario = Scenario {
            name: file.name.clone(),
            fps: file.fps,
            frames: file.frames,
            template,
            keys,
            frame: earth.map(|e| *e.frame()),
            segment_heights,
        };
        for k in &scenario.keys {
            let mut c = template;
            (c.position, c.yaw_deg, c.pitch_deg, c.roll_deg) = (k.position, k.yaw, k.pitch, k.roll);
            c.validate()?;
        }
        Ok(scenario)
    }

    /// Each key's time: from `speed` along the keys' straight segments, or each key's own
    /// `t`, which must then be given everywhere and not decrease.
    fn time_keys(file: &ScenarioFile, keys: &mut [Key]) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("scenario", m));
        match file.speed {
            Some(speed) => {
                if !(speed.is_finite() && speed > 0.0) {
                    return bad(format!("speed {speed} m/s must be positive"));
                }
                if file.keyframes.iter().any(|k| k.t.is_some()) {
                    return bad("with `speed`, keyframes take no `t`".into());
                }
                let mut t = 0.0;
                for i in 0..keys.len() {
                    if i > 0 {
                        t += keys[i].position.distance(keys[i - 1].position) / speed;
                    }
                    keys[i].t = t;
                }
            }
            None => {
                if keys.iter().any(|k| k.t.is_nan()) {
                    return bad("every keyframe needs `t` (or give the scenario a `speed`)".into());
                }
                if keys.windows(2).any(|w| w[1].t < w[0].t) {
                    return bad("keyframe times must not decrease".into());
                }
            }
        }
        Ok(())
    }

    /// Per segment whose keys share a datum of their own ([`Key::shares_own_datum`]): the
    /// heights above the ellipsoid of evenly spaced points along it, each placed as a key at
    /// the interpolated latitude, longitude and height in that datum would be
    /// ([`Key::on_earth`]), so a flight between two keys at one height above mean sea level
    /// (or over the terrain's datum) keeps that height instead of following the chord of the
    /// geoid between them.
    fn own_datum_heights<D: Level0 + ?Sized>(
        keys: &[Key],
        earth: &Earth,
        data: &D,
        template: &Camera,
    ) -> Result<Vec<Option<Vec<f64>>>> {
        let mut out = Vec::with_capacity(keys.len());
        for w in keys.windows(2) {
            let (Some((a, ha)), Some((b, hb))) = (w[0].given, w[1].given) else {
                out.push(None);
                continue;
            };
            if !w[0].shares_own_datum(&w[1]) {
                out.push(None);
                continue;
            }
            let mut heights = Vec::with_capacity(SEGMENT_SAMPLES + 1);
            for k in 0..=SEGMENT_SAMPLES {
                let s = k as f64 / SEGMENT_SAMPLES as f64;
                let pose = GeoPose {
                    lat_deg: a.lat_deg + (b.lat_deg - a.lat_deg) * s,
                    lon_deg: a.lon_deg + short_delta(a.lon_deg, b.lon_deg) * s,
                    height_m: a.height_m + (b.height_m - a.height_m) * s,
                    ..a
                };
                let given = ha.zip(hb).map(|(x, y)| x + (y - x) * s);
                let key = Key::on_earth(earth, &pose, given, 0.0, data, template)?;
                heights.push(key.geo.map_or(f64::NAN, |g| g.height_m));
            }
            out.push(Some(heights));
        }
        out.push(None);
        Ok(out)
    }

    /// A scenario holding one fixed camera.
    pub fn fixed(name: &str, camera: Camera, frames: u32) -> Result<Self> {
        camera.validate()?;
        let key = Key {
            t: 0.0,
            position: camera.position,
            yaw: camera.yaw_deg,
            pitch: camera.pitch_deg,
            roll: camera.roll_deg,
            geo: None,
            given: None,
        };
        Ok(Scenario {
            name: name.into(),
            fps: 30.0,
            frames,
            template: camera,
            keys: vec![key],
            frame: None,
            segment_heights: Vec::new(),
        })
    }

    /// Scenario time of frame `frame` in seconds.
    pub fn time(&self, frame: u64) -> f64 {
        frame as f64 / self.fps
    }

    /// The camera of frame `frame` (linear between keyframes, held after the last).
    pub fn camera(&self, frame: u64) -> Camera {
        let t = self.time(frame);
        let i = self.keys.partition_point(|k| k.t <= t);
        let (a, b) = match i {
            0 => (self.keys[0], self.keys[0]),
            i if i >= self.keys.len() => (self.keys[i - 1], self.keys[i - 1]),
            i => (self.keys[i - 1], self.keys[i]),
        };
        let segment = i
            .checked_sub(1)
            .and_then(|j| self.segment_heights.get(j)?.as_ref());
        let s = if b.t > a.t {
            ((t - a.t) / (b.t - a.t)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let lerp = |x: f64, y: f64| x + (y - x) * s;
        // Headings interpolate the short way round.
        let short = |from: f64, to: f64| from + short_delta(from, to) * s;
        // Strictly between two WGS84 keyframes: along latitude, longitude and height (at a key
        // itself, its camera exactly as resolved).
        if let (Some(ga), Some(gb), Some(frame)) = (a.geo, b.geo, &self.frame)
            && s > 0.0
            && s < 1.0
        {
            let pose = GeoPose {
                lat_deg: lerp(ga.lat_deg, gb.lat_deg),
                lon_deg: short(ga.lon_deg, gb.lon_deg),
                height_m: segment.map_or(lerp(ga.height_m, gb.height_m), |h| along(h, s)),
                heading_deg: short(ga.heading_deg, gb.heading_deg),
                pitch_deg: lerp(ga.pitch_deg, gb.pitch_deg),
                roll_deg: lerp(ga.roll_deg, gb.roll_deg),
                ..ga
            };
            let w = pose.to_world(frame, pose.height_m);
            return Camera {
                position: w.position,
                yaw_deg: w.yaw_deg,
                pitch_deg: w.pitch_deg,
                roll_deg: w.roll_deg,
                ..self.template
            };
        }
        let dyaw = short_delta(a.yaw, b.yaw);
        Camera {
            position: a.position.lerp(b.position, s),
            yaw_deg: a.yaw + dyaw * s,
            pitch_deg: lerp(a.pitch, b.pitch),
            roll_deg: lerp(a.roll, b.roll),
            ..self.template
        }
    }
}

/// The signed shortest turn from longitude (or heading) `from` to `to`, in degrees.
fn short_delta(from: f64, to: f64) -> f64 {
    (to - from + 540.0).rem_euclid(360.0) - 180.0
}

/// `samples` (evenly spaced over [0, 1]) interpolated linearly at `s`.
fn along(samples: &[f64], s: f64) -> f64 {
    let x = s.clamp(0.0, 1.0) * (samples.len() - 1) as f64;
    let i = (x.floor() as usize).min(samples.len() - 2);
    let f = x - i as f64;
    samples[i] + (samples[i + 1] - samples[i]) * f
}
