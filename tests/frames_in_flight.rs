//! Frame k's readback must hold frame k's image, for every number of frames in flight: each
//! frame gets its own clear colour and camera, and the delivered pixels and metadata are
//! checked against the request with that index.

mod common;

use glam::DVec3;
use vkterrain::dataset::procedural::analytic;
use vkterrain::render::FrameRequest;
use vkterrain::scene::Camera;

const FRAMES: u64 = 7;

/// A clear colour unique to frame `k` (linear RGB; distinct after 8-bit sRGB encoding).
fn sky_of(k: u64) -> [f32; 3] {
    [0.05 + 0.1 * k as f32, 0.9 - 0.1 * k as f32, 0.5]
}

fn run(frames_in_flight: usize) {
    let gpu = common::gpu(false);
    let data = analytic::plane(65, 10.0, 0.0, 0.0, 0.0).unwrap();
    // Level cameras turning from frame to frame: the top rows are sky, the bottom terrain.
    let requests: Vec<FrameRequest> = (0..FRAMES)
        .map(|k| FrameRequest {
            camera: Camera {
                position: DVec3::new(320.0, 320.0, 50.0),
                yaw_deg: 30.0 * k as f64,
                pitch_deg: 0.0,
                ..Camera::default()
            },
            sky: Some(sky_of(k)),
            lod_viewer: None,
        })
        .collect();
    let frames = common::render(
        &gpu,
        &data,
        common::options(64, 48, frames_in_flight),
        &requests,
    );
    assert_eq!(
        frames.len(),
        FRAMES as usize,
        "every frame is delivered once"
    );
    for (k, frame) in frames.iter().enumerate() {
        let k = k as u64;
        assert_eq!(frame.index, k, "frames arrive in order");
        assert_eq!(
            frame.camera, requests[k as usize].camera,
            "frame {k} carries its own camera"
        );
        let sky = sky_of(k).map(common::srgb8);
        let top = frame.pixel(32, 0);
        for c in 0..3 {
            assert!(
                top[c].abs_diff(sky[c]) <= 1,
                "N={frames_in_flight}: frame {k} shows clear colour {top:?}, expected {sky:?}"
            );
        }
        // The terrain below the horizon was drawn into the same frame (depth nearer than far).
        assert!(
            frame.depth_at(32, 47).unwrap() > 0.0,
            "frame {k}: no terrain at the bottom"
        );
    }
}

#[test]
fn one_frame_in_flight() {
    run(1);
}

#[test]
fn two_frames_in_flight() {
    run(2);
}

#[test]
fn three_frames_in_flight() {
    run(3);
}
