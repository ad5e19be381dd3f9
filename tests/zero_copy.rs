//! Zero-copy publishing (validation on): the GPU writes each frame straight into its ring slot
//! (`VK_EXT_external_memory_host`). Frame k's slot holds frame k's image, the slot is marked as
//! being written (odd sequence) from recording until the frame is delivered, and the pixels are
//! the same as the copy path's.

mod common;

use std::time::Duration;

use glam::DVec3;
use vkterrain::dataset::procedural::analytic;
use vkterrain::lod::MethodKind;
use vkterrain::output::ring::{
    Geometry, Next, ProducerOptions, RingLocation, RingProducer, RingReader, ZeroCopyRequest,
};
use vkterrain::readback::{CollectSink, DirectTarget, FrameSink, FrameView};
use vkterrain::render::{FrameRequest, Renderer};
use vkterrain::scene::Camera;

fn euid() -> u32 {
    // SAFETY: no arguments.
    unsafe { libc::geteuid() }
}

fn requests() -> Vec<FrameRequest> {
    (0..7u64)
        .map(|k| FrameRequest {
            camera: Camera {
                position: DVec3::new(320.0, 320.0, 50.0),
                yaw_deg: 30.0 * k as f64,
                pitch_deg: -5.0,
                ..Camera::default()
            },
            sky: Some([0.05 + 0.1 * k as f32, 0.9 - 0.1 * k as f32, 0.5]),
            lod_viewer: None,
        })
        .collect()
}

/// Publishes into the ring and records, per delivered frame, the pixels a reader then sees and
/// whether the frame arrived in the ring slot itself.
struct Probe<'a> {
    ring: &'a mut RingProducer,
    reader: RingReader,
    frames: Vec<Vec<u8>>,
    in_place: Vec<bool>,
}

impl FrameSink for Probe<'_> {
    fn frame(&mut self, f: &FrameView<'_>) -> vkterrain::Result<()> {
        self.ring.frame(f)?;
        let Next::Frame(m) = self.reader.wait_next(Duration::from_secs(5)).unwrap() else {
            panic!("no frame in the ring");
        };
        assert_eq!(m.frame, f.index);
        self.frames.push(self.reader.pixels().to_vec());
        Ok(())
    }
    fn direct_target(&mut self, index: u64, bytes: u64) -> Option<DirectTarget> {
        let t = self.ring.direct_target(index, bytes);
        self.in_place.push(t.is_some());
        t
    }
}

fn seq_of_slot(path: &std::path::Path, r: &RingReader, frame: u64) -> u64 {
    let bytes = std::fs::read(path).unwrap();
    let off = r.layout().slot_offset(frame) as usize;
    u64::from_le_bytes(bytes[off..off + 8].try_into().unwrap())
}

#[test]
fn gpu_writes_frames_into_the_ring_slots() {
    let gpu = common::gpu(false);
    let data = analytic::plane(65, 10.0, 0.0, 0.0, 0.0).unwrap();
    let options = || {
        let mut o = common::options(64, 48, 2);
        o.readback_depth = false;
        o
    };
    // Reference: the copy path through the renderer's own readback buffer.
    let mut reference = CollectSink::default();
    {
        let mut r = Renderer::new(&gpu, &data, MethodKind::Brute, options()).unwrap();
        for q in requests() {
            r.render(q, &mut reference).unwrap();
        }
        r.finish(&mut reference).unwrap();
    }

    let dir = tempfile::tempdir().unwrap();
    let loc = RingLocation::new(dir.path().join("rings"), "zc").unwrap();
    let popts = ProducerOptions {
        zero_copy: Some(ZeroCopyRequest {
            gpu: gpu.clone(),
            frames_in_flight: 2,
        }),
        ..Default::default()
    };
    let mut ring = RingProducer::create(&loc, Geometry::new(64, 48, 3, false), &popts).unwrap();
    let offered = gpu.enabled.external_memory_host;
    assert_eq!(ring.zero_copy(), offered, "{:?}", ring.zero_copy_note());
    if std::env::var("CI").is_ok() {
        assert!(offered, "CI's lavapipe offers VK_EXT_external_memory_host");
    }
    let reader = RingReader::open(&loc, Some(euid())).unwrap();
    let mut probe = Probe {
        ring: &mut ring,
        reader,
        frames: Vec::new(),
        in_place: Vec::new(),
    };
    {
        let mut r = Renderer::new(&gpu, &data, MethodKind::Brute, options()).unwrap();
        for (k, q) in requests().into_iter().enumerate() {
            r.render(q, &mut probe).unwrap();
            // Frame k is in flight (2 frames in flight: delivered after frame k + 1 is
            // submitted): its slot says "being written" until then.
            if offered {
                let seq = seq_of_slot(&loc.segment_path(), &probe.reader, k as u64);
                assert_eq!(
                    seq,
                    2 * k as u64 + 1,
                    "frame {k}: slot not marked as being written"
                );
            }
        }
        r.finish(&mut probe).unwrap();
    }
    common::assert_no_validation_messages(&gpu);
    assert_eq!(probe.in_place, vec![offered; 7]);
    assert_eq!(probe.frames.len(), 7);
    for (k, (got, want)) in probe.frames.iter().zip(&reference.frames).enumerate() {
        assert!(
            got == &want.rgba,
            "frame {k}: the ring holds other pixels than the copy path"
        );
    }
    // Consecutive frames differ (each has its own sky): a stale slot would be caught above.
    assert!(probe.frames.windows(2).all(|w| w[0] != w[1]));
}
