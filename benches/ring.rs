//! Shared-memory ring benchmark. Part 1 (no GPU): producer cost per frame (copy into the slot)
//! at 1280x720 and 1920x1080 RGBA8, publish-to-wake-up latency (median/p99), and publishing
//! throughput with 0 and 4 consumers attached. Part 2 (the Vulkan device, lavapipe in CI): the
//! renderer publishing into the ring by copy and zero-copy (`VK_EXT_external_memory_host`, the
//! GPU writes into the slot): publish cost on the host, frames/s and capture-to-consumer
//! latency with 0 and 4 consumers. Consumers are threads with their own read-only mapping (the
//! same code path as separate processes). Results also go to `target/bench/ring.json`.
//! `VKTERRAIN_BENCH_SECONDS` sets the length of each run (default 2); `VKTERRAIN_BENCH_RENDER=0`
//! skips part 2.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use vkterrain::dataset::Heightmap;
use vkterrain::driver::{Gpu, GpuOptions};
use vkterrain::lod::MethodKind;
use vkterrain::output::ring::sys::monotonic_ns;
use vkterrain::output::ring::{
    FrameMeta, Geometry, Next, ProducerOptions, RingLocation, RingProducer, RingReader,
    ZeroCopyRequest,
};
use vkterrain::render::stats::Percentiles;
use vkterrain::render::{RenderOptions, Renderer};
use vkterrain::scene::Camera;

fn geometry(w: u32, h: u32) -> Geometry {
    Geometry::new(w, h, 4, false)
}

fn euid() -> u32 {
    // SAFETY: no arguments.
    unsafe { libc::geteuid() }
}

fn meta(g: Geometry) -> FrameMeta {
    FrameMeta {
        width: g.width,
        height: g.height,
        ..Default::default()
    }
}

/// `n` reader threads on the ring, each running `read` on its own reader (and `stop`) and
/// returning what it returns.
fn readers<T: Send + 'static>(
    name: &RingLocation,
    n: usize,
    stop: &Arc<AtomicBool>,
    read: impl Fn(&mut RingReader, &AtomicBool) -> T + Clone + Send + 'static,
) -> Vec<std::thread::JoinHandle<T>> {
    (0..n)
        .map(|_| {
            let (name, stop, read) = (name.clone(), stop.clone(), read.clone());
            std::thread::spawn(move || {
                let mut r = RingReader::open(&name, Some(euid())).unwrap();
                read(&mut r, &stop)
            })
        })
        .collect()
}

/// Consumers that read (with `copy`, copying the pixels of) every frame they can get until
/// `stop`: each returns the frames it received.
fn consumers(
    name: &RingLocation,
    n: usize,
    copy: bool,
    stop: &Arc<AtomicBool>,
) -> Vec<std::thread::JoinHandle<u64>> {
    readers(name, n, stop, move |r, stop| {
        r.copy_pixels = copy;
        while !stop.load(Ordering::Relaxed) {
            if r.wait_next(Duration::from_millis(50)).unwrap() == Next::Closed {
                break;
            }
        }
        r.stats().received
    })
}

type Json = serde_json::Map<String, serde_json::Value>;

fn main() -> anyhow::Result<()> {
    let seconds: f64 = std::env::var("VKTERRAIN_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2.0);
    let dir = std::path::PathBuf::from(format!("/dev/shm/vkt-bench-{}", std::process::id()));
    let name = RingLocation::new(&dir, "bench")?;
    let mut json = serde_json::Map::new();
    throughput_part(seconds, &name, &mut json)?;
    latency_part(&name, &mut json)?;
    if std::env::var("VKTERRAIN_BENCH_RENDER").as_deref() != Ok("0") {
        render_part(seconds, &name, &mut json)?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    let root = env!("CARGO_MANIFEST_DIR");
    std::fs::create_dir_all(format!("{root}/target/bench"))?;
    std::fs::write(
        format!("{root}/target/bench/ring.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    Ok(())
}

/// Part 1: publishing as fast as it goes for `seconds` per row, at two sizes, with no
/// consumer, 4 copying every frame they can (competing for the same cores and memory
/// bandwidth), and 4 that only verify the metadata (the protocol's own cost).
fn throughput_part(seconds: f64, name: &RingLocation, json: &mut Json) -> anyhow::Result<()> {
    println!(
        "{:<10} {:>9} {:>13} {:>13} {:>13} {:>12} {:>12}",
        "size", "consumers", "publish med", "publish p99", "memcpy med", "frames/s", "read/s each"
    );
    for (w, h) in [(1280u32, 720u32), (1920, 1080)] {
        let g = geometry(w, h);
        let pixels: Vec<u8> = (0..g.pixel_bytes()).map(|i| (i * 7) as u8).collect();
        let memcpy = memcpy_ms(&pixels);
        for (n_consumers, copy) in [(0usize, true), (4, true), (4, false)] {
            let run = publish_run(name, g, &pixels, n_consumers, copy, seconds)?;
            let label = if copy { "" } else { " meta" };
            println!(
                "{:<10} {:>9} {:>10.3} ms {:>10.3} ms {:>10.3} ms {:>12.0} {:>12.0}",
                format!("{w}x{h}"),
                format!("{n_consumers}{label}"),
                run.publish_ms.median,
                run.publish_ms.p99,
                memcpy.median,
                run.frames_per_s,
                run.reads_per_s_each
            );
            json.insert(
                format!("{w}x{h}_consumers{n_consumers}{}", label.replace(' ', "_")),
                serde_json::json!({
                    "publish_ms": run.publish_ms, "memcpy_ms": memcpy,
                    "frames_per_s": run.frames_per_s,
                    "reads_per_s_per_consumer": run.reads_per_s_each,
                }),
            );
        }
    }
    Ok(())
}

/// A plain memcpy of `pixels` into a fresh buffer, 100 times, for reference.
fn memcpy_ms(pixels: &[u8]) -> Percentiles {
    let mut dst = vec![0u8; pixels.len()];
    Percentiles::of(
        (0..100)
            .map(|_| {
                let t = Instant::now();
                dst.copy_from_slice(std::hint::black_box(pixels));
                std::hint::black_box(&dst);
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

/// One row of part 1.
struct PublishRun {
    publish_ms: Percentiles,
    frames_per_s: f64,
    reads_per_s_each: f64,
}

/// Publishing `pixels` for `seconds` with `n_consumers` attached.
fn publish_run(
    name: &RingLocation,
    g: Geometry,
    pixels: &[u8],
    n_consumers: usize,
    copy: bool,
    seconds: f64,
) -> anyhow::Result<PublishRun> {
    let mut p = RingProducer::create(name, g, &ProducerOptions::default())?;
    let stop = Arc::new(AtomicBool::new(false));
    let threads = consumers(name, n_consumers, copy, &stop);
    std::thread::sleep(Duration::from_millis(100));
    let m = meta(g);
    let mut costs = Vec::new();
    let start = Instant::now();
    while start.elapsed().as_secs_f64() < seconds {
        let t = Instant::now();
        p.publish(&m, pixels, None)?;
        costs.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let elapsed = start.elapsed().as_secs_f64();
    let published = p.published();
    p.close();
    stop.store(true, Ordering::Relaxed);
    let reads: Vec<u64> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    let reads_per_s_each = if reads.is_empty() {
        0.0
    } else {
        reads.iter().sum::<u64>() as f64 / reads.len() as f64 / elapsed
    };
    Ok(PublishRun {
        publish_ms: Percentiles::of(costs),
        frames_per_s: published as f64 / elapsed,
        reads_per_s_each,
    })
}

/// Latency: frames paced 5 ms apart so that the consumer sleeps in the futex each time.
fn latency_part(name: &RingLocation, json: &mut Json) -> anyhow::Result<()> {
    println!("\npublish -> consumer wake-up latency (1280x720, 400 frames 5 ms apart, 1 consumer)");
    for copy in [false, true] {
        let (wake, from_capture) = latency_run(name, copy)?;
        let (n, wake, cap) = (
            wake.len(),
            Percentiles::of(wake),
            Percentiles::of(from_capture),
        );
        let what = if copy { "wake + copy" } else { "wake only" };
        println!(
            "  {what:<12} {n} frames: publish->return median {:.1} us, p99 {:.1} us; capture->return median {:.1} us, p99 {:.1} us",
            wake.median, wake.p99, cap.median, cap.p99
        );
        json.insert(
            format!("latency_{}", if copy { "copy" } else { "nocopy" }),
            serde_json::json!({"frames": n, "publish_to_return_us": wake, "capture_to_return_us": cap}),
        );
    }
    Ok(())
}

/// 400 frames published 5 ms apart to one consumer (copying the pixels or not): per frame it
/// received, publish -> return and capture -> return in microseconds.
fn latency_run(name: &RingLocation, copy: bool) -> anyhow::Result<(Vec<f64>, Vec<f64>)> {
    let g = geometry(1280, 720);
    let pixels = vec![0x55u8; g.pixel_bytes() as usize];
    let mut p = RingProducer::create(name, g, &ProducerOptions::default())?;
    let reader_name = name.clone();
    let t = std::thread::spawn(move || {
        let mut r = RingReader::open(&reader_name, Some(euid())).unwrap();
        r.copy_pixels = copy;
        let (mut wake, mut from_capture) = (Vec::new(), Vec::new());
        loop {
            match r.wait_next(Duration::from_secs(2)).unwrap() {
                Next::Frame(m) => {
                    let now = monotonic_ns();
                    wake.push((now - m.publish_ns) as f64 / 1e3);
                    from_capture.push((now - m.capture_ns) as f64 / 1e3);
                }
                Next::Closed | Next::Timeout => break,
                Next::Restarted { .. } => {}
            }
        }
        (wake, from_capture)
    });
    std::thread::sleep(Duration::from_millis(100));
    let mut m = meta(g);
    for _ in 0..400 {
        m.capture_ns = monotonic_ns();
        p.publish(&m, &pixels, None)?;
        std::thread::sleep(Duration::from_millis(5));
    }
    p.close();
    Ok(t.join().unwrap())
}

/// A sink that publishes into the ring and times the host side of publishing.
struct Timed<'a> {
    ring: &'a mut RingProducer,
    ms: Vec<f64>,
}

impl vkterrain::readback::FrameSink for Timed<'_> {
    fn frame(&mut self, f: &vkterrain::readback::FrameView<'_>) -> vkterrain::Result<()> {
        let t = Instant::now();
        self.ring.frame(f)?;
        self.ms.push(t.elapsed().as_secs_f64() * 1e3);
        Ok(())
    }
    fn direct_target(&mut self, i: u64, b: u64) -> Option<vkterrain::readback::DirectTarget> {
        self.ring.direct_target(i, b)
    }
}

/// Part 2: the renderer (brute force over a small plane, so the frame is mostly clear, raster
/// and readback) publishing by copy and zero-copy.
fn render_part(seconds: f64, name: &RingLocation, json: &mut Json) -> anyhow::Result<()> {
    let gpu = Gpu::new(&GpuOptions::default().with_env())?;
    let data = vkterrain::dataset::procedural::analytic::plane(65, 10.0, 0.0, 0.0, 0.0)?;
    println!(
        "\nrenderer -> ring on {} (brute force, 65x65 plane, 2 frames in flight, 4 slots)",
        gpu.info.name
    );
    println!(
        "{:<10} {:>10} {:>9} {:>14} {:>14} {:>10} {:>18}",
        "size", "path", "consumers", "publish med", "publish p99", "frames/s", "capture->read med"
    );
    for (w, h) in [(1280u32, 720u32), (1920, 1080)] {
        for zero_copy in [false, true] {
            for n_consumers in [0usize, 4] {
                let run = render_run(&gpu, &data, name, (w, h), zero_copy, n_consumers, seconds)?;
                println!(
                    "{:<10} {:>10} {:>9} {:>11.3} ms {:>11.3} ms {:>10.1} {:>15.0} us",
                    format!("{w}x{h}"),
                    run.path,
                    n_consumers,
                    run.publish_ms.median,
                    run.publish_ms.p99,
                    run.frames_per_s,
                    run.capture_to_consumer_us.median
                );
                json.insert(
                    format!("render_{w}x{h}_{}_consumers{n_consumers}", run.path),
                    serde_json::json!({"publish_ms": run.publish_ms, "frames_per_s": run.frames_per_s,
                        "capture_to_consumer_us": run.capture_to_consumer_us, "device": gpu.info.name}),
                );
            }
        }
    }
    Ok(())
}

/// One row of part 2.
struct RenderRun {
    /// "copy" or "zero-copy": what the ring could set up.
    path: &'static str,
    publish_ms: Percentiles,
    frames_per_s: f64,
    capture_to_consumer_us: Percentiles,
}

/// The renderer publishing into the ring for `seconds` after 5 frames of warm-up, with
/// `n_consumers` attached.
fn render_run(
    gpu: &Arc<Gpu>,
    data: &Heightmap,
    name: &RingLocation,
    (w, h): (u32, u32),
    zero_copy: bool,
    n_consumers: usize,
    seconds: f64,
) -> anyhow::Result<RenderRun> {
    let mut renderer = Renderer::new(gpu, data, MethodKind::Brute, render_options(w, h))?;
    let popts = ProducerOptions {
        zero_copy: zero_copy.then(|| ZeroCopyRequest {
            gpu: gpu.clone(),
            frames_in_flight: 2,
        }),
        ..Default::default()
    };
    let mut ring = RingProducer::create(name, Geometry::new(w, h, 4, false), &popts)?;
    let path = if ring.zero_copy() {
        "zero-copy"
    } else {
        "copy"
    };
    if zero_copy && !ring.zero_copy() {
        println!("  zero-copy unavailable: {:?}", ring.zero_copy_note());
    }
    let stop = Arc::new(AtomicBool::new(false));
    let readers = latency_consumers(name, n_consumers, &stop);
    let mut sink = Timed {
        ring: &mut ring,
        ms: Vec::new(),
    };
    let camera = Camera {
        position: glam::DVec3::new(320.0, 320.0, 50.0),
        pitch_deg: -10.0,
        ..Camera::default()
    };
    for _ in 0..5 {
        renderer.render(camera, &mut sink)?;
    }
    renderer.finish(&mut sink)?;
    sink.ms.clear();
    let start = Instant::now();
    let mut frames = 0u64;
    while start.elapsed().as_secs_f64() < seconds {
        renderer.render(camera, &mut sink)?;
        frames += 1;
    }
    renderer.finish(&mut sink)?;
    let frames_per_s = frames as f64 / start.elapsed().as_secs_f64();
    let publish_ms = Percentiles::of(std::mem::take(&mut sink.ms));
    stop.store(true, Ordering::Relaxed);
    let lat: Vec<f64> = readers
        .into_iter()
        .flat_map(|t| t.join().unwrap())
        .collect();
    // The renderer before the ring, as the service drops them: with zero-copy its readback
    // writes into the ring's slots.
    drop(renderer);
    drop(ring);
    Ok(RenderRun {
        path,
        publish_ms,
        frames_per_s,
        capture_to_consumer_us: Percentiles::of(lat),
    })
}

fn render_options(width: u32, height: u32) -> RenderOptions {
    RenderOptions {
        width,
        height,
        frames_in_flight: 2,
        readback_depth: false,
        light: vkterrain::frame::Lighting {
            sun_dir: [0.0, 0.0, 1.0],
            sky: [0.2, 0.4, 0.8],
            haze_distance_m: 0.0,
        },
        views: 1,
        earth: Default::default(),
    }
}

/// Consumers that record each frame's capture -> read latency (microseconds) until `stop`.
fn latency_consumers(
    name: &RingLocation,
    n: usize,
    stop: &Arc<AtomicBool>,
) -> Vec<std::thread::JoinHandle<Vec<f64>>> {
    readers(name, n, stop, |r, stop| {
        let mut lat = Vec::new();
        while !stop.load(Ordering::Relaxed) {
            if let Ok(Next::Frame(m)) = r.wait_next(Duration::from_millis(50)) {
                lat.push((monotonic_ns() - m.capture_ns) as f64 / 1e3);
            }
        }
        lat
    })
}
