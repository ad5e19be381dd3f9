//! Shared-memory ring benchmark (no GPU): producer cost per frame (copy into the slot) at
//! 1280x720 and 1920x1080 RGBA8, publish-to-wake-up latency (median/p99), and publishing
//! throughput with 0 and 4 consumers attached. Consumers are threads with their own read-only
//! mapping (the same code path as separate processes). Results also go to
//! `target/bench/ring.json`. `VKTERRAIN_BENCH_SECONDS` sets the length of each throughput run
//! (default 2).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use vkterrain::output::ring::sys::monotonic_ns;
use vkterrain::output::ring::{
    FrameMeta, Geometry, Next, ProducerOptions, RingProducer, RingReader,
};
use vkterrain::render::stats::Percentiles;

fn geometry(w: u32, h: u32) -> Geometry {
    Geometry {
        width: w,
        height: h,
        slot_count: 4,
        depth: false,
    }
}

fn meta(g: Geometry) -> FrameMeta {
    FrameMeta {
        width: g.width,
        height: g.height,
        ..Default::default()
    }
}

/// Consumers that copy every frame they can get until `stop`.
fn consumers(
    name: &str,
    n: usize,
    copy: bool,
    stop: &Arc<AtomicBool>,
) -> Vec<std::thread::JoinHandle<u64>> {
    (0..n)
        .map(|_| {
            let name = name.to_string();
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut r = RingReader::open(&name).unwrap();
                r.copy_pixels = copy;
                while !stop.load(Ordering::Relaxed) {
                    if r.wait_next(Duration::from_millis(50)).unwrap() == Next::Closed {
                        break;
                    }
                }
                r.stats().received
            })
        })
        .collect()
}

fn main() -> anyhow::Result<()> {
    let seconds: f64 = std::env::var("VKTERRAIN_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2.0);
    let name = format!("vkt-bench-{}", std::process::id());
    let mut json = serde_json::Map::new();
    println!(
        "{:<10} {:>9} {:>13} {:>13} {:>13} {:>12} {:>12}",
        "size", "consumers", "publish med", "publish p99", "memcpy med", "frames/s", "read/s each"
    );
    for (w, h) in [(1280u32, 720u32), (1920, 1080)] {
        let g = geometry(w, h);
        let pixels: Vec<u8> = (0..g.pixel_bytes()).map(|i| (i * 7) as u8).collect();
        // Plain memcpy of the same size into a fresh buffer, for reference.
        let mut dst = vec![0u8; pixels.len()];
        let memcpy: Vec<f64> = (0..100)
            .map(|_| {
                let t = Instant::now();
                dst.copy_from_slice(std::hint::black_box(&pixels));
                std::hint::black_box(&dst);
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        let memcpy = Percentiles::of(memcpy);
        // 4 consumers copying every frame they can (competing for the same cores and memory
        // bandwidth), and 4 that only verify the metadata (the protocol's own cost).
        for (n_consumers, copy) in [(0usize, true), (4, true), (4, false)] {
            let mut p = RingProducer::create(&name, g, &ProducerOptions::default())?;
            let stop = Arc::new(AtomicBool::new(false));
            let threads = consumers(&name, n_consumers, copy, &stop);
            std::thread::sleep(Duration::from_millis(100));
            let m = meta(g);
            let mut costs = Vec::new();
            let start = Instant::now();
            while start.elapsed().as_secs_f64() < seconds {
                let t = Instant::now();
                p.publish(&m, &pixels, None)?;
                costs.push(t.elapsed().as_secs_f64() * 1e3);
            }
            let elapsed = start.elapsed().as_secs_f64();
            let published = p.published();
            p.close();
            stop.store(true, Ordering::Relaxed);
            let reads: Vec<u64> = threads.into_iter().map(|t| t.join().unwrap()).collect();
            let pc = Percentiles::of(costs);
            let fps = published as f64 / elapsed;
            let read_each = if reads.is_empty() {
                0.0
            } else {
                reads.iter().sum::<u64>() as f64 / reads.len() as f64 / elapsed
            };
            println!(
                "{:<10} {:>9} {:>10.3} ms {:>10.3} ms {:>10.3} ms {:>12.0} {:>12.0}",
                format!("{w}x{h}"),
                format!("{n_consumers}{}", if copy { "" } else { " meta" }),
                pc.median,
                pc.p99,
                memcpy.median,
                fps,
                read_each
            );
            json.insert(
                format!(
                    "{w}x{h}_consumers{n_consumers}{}",
                    if copy { "" } else { "_meta" }
                ),
                serde_json::json!({
                    "publish_ms": pc, "memcpy_ms": memcpy, "frames_per_s": fps,
                    "reads_per_s_per_consumer": read_each,
                }),
            );
        }
    }

    // Latency: frames paced 5 ms apart so that the consumer sleeps in the futex each time.
    println!("\npublish -> consumer wake-up latency (1280x720, 400 frames 5 ms apart, 1 consumer)");
    for copy in [false, true] {
        let g = geometry(1280, 720);
        let pixels = vec![0x55u8; g.pixel_bytes() as usize];
        let mut p = RingProducer::create(&name, g, &ProducerOptions::default())?;
        let reader_name = name.clone();
        let t = std::thread::spawn(move || {
            let mut r = RingReader::open(&reader_name).unwrap();
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
        let (wake, from_capture) = t.join().unwrap();
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
    let root = env!("CARGO_MANIFEST_DIR");
    std::fs::create_dir_all(format!("{root}/target/bench"))?;
    std::fs::write(
        format!("{root}/target/bench/ring.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    Ok(())
}
