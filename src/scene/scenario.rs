//! Scripted camera paths (`config/scenarios/*.toml`), frame-indexed so runs are reproducible.
//!
//! Time is `frame / fps`: never the wall clock, so frame `k` shows the same view on every
//! machine. Keyframes are either timed (`t` in seconds) or, when the scenario gives `speed`
//! (m/s), timed by the path length. Positions are absolute metres (`position = [x, y, z]`) or
//! relative to the data set (`at = [u, v]` as fractions of its extent, with `above_ground` or
//! `altitude` in metres), so one scenario can fly over any data set.

use std::path::Path;

use glam::DVec3;
use serde::Deserialize;

use super::Camera;
use crate::dataset::Level0;
use crate::error::{Error, Result};

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
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Key {
    t: f64,
    position: DVec3,
    yaw: f64,
    pitch: f64,
    roll: f64,
}

/// A resolved camera path.
#[derive(Clone, Debug)]
pub struct Scenario {
    pub name: String,
    pub fps: f64,
    pub frames: u32,
    template: Camera,
    keys: Vec<Key>,
}

impl Scenario {
    /// Reads and resolves a scenario file against a data set.
    pub fn load<D: Level0 + ?Sized>(path: &Path, data: &D) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let file: ScenarioFile = toml::from_str(&text).map_err(|e| Error::toml(path, &text, &e))?;
        Self::resolve(&file, data).map_err(|e| Error::Config {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }

    /// The default flight, compiled in so the binary needs no files beside it.
    pub fn builtin_default<D: Level0 + ?Sized>(data: &D) -> Result<Self> {
        const TEXT: &str = include_str!("../../config/scenarios/default.toml");
        let file: ScenarioFile =
            toml::from_str(TEXT).map_err(|e| Error::invalid("built-in scenario", e.to_string()))?;
        Self::resolve(&file, data)
    }

    /// `data`: level-0 heights (exact; a tile pyramid is read node by node) for
    /// `above_ground` keyframes.
    pub fn resolve<D: Level0 + ?Sized>(file: &ScenarioFile, data: &D) -> Result<Self> {
        let bad = |m: String| Err(Error::invalid("scenario", m));
        if !(file.fps.is_finite() && file.fps > 0.0) {
            return bad(format!("fps {} must be positive", file.fps));
        }
        if file.keyframes.is_empty() {
            return bad("no [[keyframe]]".into());
        }
        let (ex, ey) = data.extent();
        let mut keys = Vec::with_capacity(file.keyframes.len());
        for (i, k) in file.keyframes.iter().enumerate() {
            let position = match (k.position, k.at) {
                (Some(p), None) => {
                    if k.above_ground.is_some() || k.altitude.is_some() {
                        return bad(format!(
                            "keyframe {i}: `above_ground`/`altitude` go with `at`, not `position`"
                        ));
                    }
                    DVec3::from_array(p)
                }
                (None, Some([u, v])) => {
                    let (x, y) = (u * ex, v * ey);
                    let z = match (k.above_ground, k.altitude) {
                        (Some(a), None) => data.bilinear(x, y)? + a,
                        (None, Some(a)) => a,
                        _ => {
                            return bad(format!(
                                "keyframe {i}: `at` needs exactly one of `above_ground`, `altitude`"
                            ));
                        }
                    };
                    DVec3::new(x, y, z)
                }
                _ => {
                    return bad(format!(
                        "keyframe {i}: give exactly one of `position`, `at`"
                    ));
                }
            };
            keys.push(Key {
                t: k.t.unwrap_or(f64::NAN),
                position,
                yaw: k.yaw,
                pitch: k.pitch,
                roll: k.roll,
            });
        }
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
        let template = Camera {
            position: keys[0].position,
            yaw_deg: keys[0].yaw,
            pitch_deg: keys[0].pitch,
            roll_deg: keys[0].roll,
            vfov_deg: file.vfov_deg,
            near: file.near,
            far: file.far,
        };
        let scenario = Scenario {
            name: file.name.clone(),
            fps: file.fps,
            frames: file.frames,
            template,
            keys,
        };
        for k in &scenario.keys {
            let mut c = template;
            (c.position, c.yaw_deg, c.pitch_deg, c.roll_deg) = (k.position, k.yaw, k.pitch, k.roll);
            c.validate()?;
        }
        Ok(scenario)
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
        };
        Ok(Scenario {
            name: name.into(),
            fps: 30.0,
            frames,
            template: camera,
            keys: vec![key],
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
        let s = if b.t > a.t {
            ((t - a.t) / (b.t - a.t)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let lerp = |x: f64, y: f64| x + (y - x) * s;
        // Headings interpolate the short way round.
        let dyaw = (b.yaw - a.yaw + 540.0).rem_euclid(360.0) - 180.0;
        Camera {
            position: a.position.lerp(b.position, s),
            yaw_deg: a.yaw + dyaw * s,
            pitch_deg: lerp(a.pitch, b.pitch),
            roll_deg: lerp(a.roll, b.roll),
            ..self.template
        }
    }
}
