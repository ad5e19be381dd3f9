//! XYZ terrain tiles (Terrarium, Mapbox terrain-RGB) made from the shared SRTM data and
//! served by a local HTTP server this test starts (with slow, erroring, corrupt and oversize
//! variants): `preprocess --xyz` round-trips the SRTM heights within the encoding's step, the
//! placement agrees with PROJ and with the closed-form Web Mercator inverse, and the live
//! source streams through the clipmap under faults without stalling or panicking. Placement
//! needs PROJ (GDAL's OSR): without the `gdal` feature only the fetcher test is built.
#![cfg_attr(not(feature = "gdal"), allow(unused))]

mod common;

use std::collections::HashMap;
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use glam::DVec3;
use vkterrain::clipmap::{Clipmap, ClipmapSettings, Geometry, StoreSource};
use vkterrain::dataset::preprocess::{self, Input, NoProgress, Options};
use vkterrain::dataset::tiles::Dataset;
use vkterrain::dataset::xyz::{Encoding, TileFetcher, XyzPyramid, XyzSettings, decode_tile};
use vkterrain::dataset::{Level0, PyramidReader, Terrain};
use vkterrain::lod::MethodKind;
use vkterrain::readback::CollectSink;
use vkterrain::render::Renderer;
use vkterrain::scene::Camera;

const R: f64 = 6_378_137.0;
const VOID: i16 = -32768;
/// Pyrenees, inside the SRTM pair N41E001 + N42E001.
const BBOX: [f64; 4] = [1.3, 42.3, 1.6, 42.55];
const ZOOM: u32 = 11;

/// The SRTM pair as one grid: row 0 = 43 N, 2401 rows, 1201 columns from 1 E.
fn srtm() -> Option<&'static (Vec<i16>, usize)> {
    static S: OnceLock<Option<(Vec<i16>, usize)>> = OnceLock::new();
    S.get_or_init(|| {
        let d = common::shared_data()?;
        let raw = |t: &str| {
            let mut z = zip::ZipArchive::new(
                std::fs::File::open(d.join(format!("srtm/{t}.hgt.zip"))).unwrap(),
            )
            .unwrap();
            let mut b = Vec::new();
            z.by_index(0).unwrap().read_to_end(&mut b).unwrap();
            b.chunks_exact(2)
                .map(|c| i16::from_be_bytes([c[0], c[1]]))
                .collect::<Vec<_>>()
        };
        let mut v = raw("N42E001");
        v.extend_from_slice(&raw("N41E001")[1201..]);
        Some((v, 1201))
    })
    .as_ref()
}

/// Longitude and latitude of pixel `(px, py)`'s centre at zoom `z` (spherical Mercator
/// inverse written out: the oracle).
fn pixel_lonlat(z: u32, px: u64, py: u64) -> (f64, f64) {
    let res = 2.0 * std::f64::consts::PI * R / (256u64 << z) as f64;
    let x = -std::f64::consts::PI * R + (px as f64 + 0.5) * res;
    let y = std::f64::consts::PI * R - (py as f64 + 0.5) * res;
    ((x / R).to_degrees(), (y / R).sinh().atan().to_degrees())
}

/// The SRTM sample nearest to a longitude/latitude (None: void or outside).
fn srtm_at(lon: f64, lat: f64) -> Option<f64> {
    let (v, w) = srtm()?;
    let c = ((lon - 1.0) * 1200.0).round();
    let g = ((43.0 - lat) * 1200.0).round();
    if c < 0.0 || g < 0.0 || c >= *w as f64 || g >= (v.len() / w) as f64 {
        return None;
    }
    let s = v[g as usize * w + c as usize];
    (s != VOID).then_some(s as f64)
}

/// Tile `z/x/y` as a PNG: every pixel the SRTM sample nearest its centre (0 m where none).
fn make_tile(z: u32, x: u64, y: u64, enc: Encoding) -> Vec<u8> {
    let mut img = image::RgbImage::new(256, 256);
    for j in 0..256u64 {
        for i in 0..256u64 {
            let (lon, lat) = pixel_lonlat(z, x * 256 + i, y * 256 + j);
            let h = srtm_at(lon, lat).unwrap_or(0.0);
            img.put_pixel(i as u32, j as u32, image::Rgb(enc.encode(h)));
        }
    }
    let mut out = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Fault {
    None,
    /// HTTP 500 for half the tiles of the zoom.
    Errors(u32),
    /// Answers after the delay (half the tiles of the zoom).
    Slow(u32, Duration),
    /// A truncated PNG (half the tiles of the zoom).
    Corrupt(u32),
    /// A body of 8 MiB (every tile of the zoom).
    Oversize(u32),
}

/// PNGs made so far, by `(z, x, y)`.
type Made = Mutex<HashMap<(u32, u64, u64), Arc<Vec<u8>>>>;

struct Server {
    url: String,
    fault: Mutex<Fault>,
    requests: AtomicU64,
    encoding: Encoding,
    made: Made,
}

impl Server {
    fn start(encoding: Encoding) -> Arc<Server> {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let server = Arc::new(Server {
            url: format!("http://{}", listener.local_addr().unwrap()),
            fault: Mutex::new(Fault::None),
            requests: AtomicU64::new(0),
            encoding,
            made: Mutex::new(HashMap::new()),
        });
        let s = server.clone();
        std::thread::spawn(move || {
            for stream in listener.incoming().flatten() {
                let s = s.clone();
                std::thread::spawn(move || s.serve(stream));
            }
        });
        server
    }

    fn template(&self) -> String {
        format!("{}/{{z}}/{{x}}/{{y}}.png", self.url)
    }

    fn set(&self, f: Fault) {
        *self.fault.lock().unwrap() = f;
    }

    fn tile(&self, z: u32, x: u64, y: u64) -> Arc<Vec<u8>> {
        if let Some(t) = self.made.lock().unwrap().get(&(z, x, y)) {
            return t.clone();
        }
        let t = Arc::new(make_tile(z, x, y, self.encoding));
        self.made.lock().unwrap().insert((z, x, y), t.clone());
        t
    }

    fn serve(&self, mut stream: TcpStream) {
        let mut req = Vec::new();
        let mut buf = [0u8; 1024];
        while !req.windows(4).any(|w| w == b"\r\n\r\n") && req.len() < 8192 {
            match stream.read(&mut buf) {
                Ok(0) | Err(_) => return,
                Ok(n) => req.extend_from_slice(&buf[..n]),
            }
        }
        self.requests.fetch_add(1, Ordering::SeqCst);
        let line = String::from_utf8_lossy(&req)
            .lines()
            .next()
            .unwrap_or("")
            .to_string();
        let path = line.split_whitespace().nth(1).unwrap_or("/");
        let parts: Vec<u64> = path
            .trim_start_matches('/')
            .trim_end_matches(".png")
            .split('/')
            .filter_map(|p| p.parse().ok())
            .collect();
        let respond = |stream: &mut TcpStream, status: &str, body: &[u8]| {
            let _ = write!(
                stream,
                "HTTP/1.1 {status}\r\nContent-Type: image/png\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                body.len()
            );
            let _ = stream.write_all(body);
        };
        let [z, x, y] = parts[..] else {
            respond(&mut stream, "404 Not Found", b"");
            return;
        };
        let z = z as u32;
        let half = (x + y) % 2 == 0;
        let fault = *self.fault.lock().unwrap();
        match fault {
            Fault::Errors(fz) if fz == z && half => {
                respond(&mut stream, "500 Internal Server Error", b"boom")
            }
            Fault::Slow(fz, d) if fz == z && half => {
                std::thread::sleep(d);
                respond(&mut stream, "200 OK", &self.tile(z, x, y));
            }
            Fault::Corrupt(fz) if fz == z && half => {
                let t = self.tile(z, x, y);
                respond(&mut stream, "200 OK", &t[..t.len() / 2]);
            }
            Fault::Oversize(fz) if fz == z => {
                respond(&mut stream, "200 OK", &vec![0u8; 8 << 20]);
            }
            _ => respond(&mut stream, "200 OK", &self.tile(z, x, y)),
        }
    }
}

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("vkt-xyz-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn settings(source: String, enc: Encoding, cache: &Path) -> XyzSettings {
    XyzSettings {
        source,
        encoding: enc,
        bbox: BBOX,
        zoom: ZOOM,
        cache_dir: Some(cache.to_path_buf()),
        timeout_s: 5.0,
        node_size: 64,
        ..Default::default()
    }
}

/// `preprocess --xyz` from an HTTP server and from a `z/x/y.png` directory, both encodings:
/// every level-0 sample equals the SRTM sample nearest its centre within the encoding's step
/// (0 m here: SRTM heights are integers), the grid lies on the zoom's pixel centres, PROJ's
/// inverse of the centres agrees with the closed form. Negative control: the neighbouring
/// pixel's SRTM value disagrees at many samples.
#[cfg(feature = "gdal")] // tile placement through PROJ (GDAL's OSR)
#[test]
fn xyz_tiles_round_trip_the_srtm_heights() {
    use gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};
    if srtm().is_none() {
        return;
    }
    let dir = tmpdir("roundtrip");
    for enc in [Encoding::Terrarium, Encoding::Mapbox] {
        let server = Server::start(enc);
        // The same tiles as files.
        let tiles_dir = dir.join(format!("{enc:?}-tiles"));
        let res = 2.0 * std::f64::consts::PI * R / (256u64 << ZOOM) as f64;
        let px = |lon: f64| ((lon.to_radians() * R + std::f64::consts::PI * R) / res) as u64;
        let py = |lat: f64| {
            ((std::f64::consts::PI * R - lat.to_radians().tan().asinh() * R) / res) as u64
        };
        for ty in py(BBOX[3]) / 256..=py(BBOX[1]) / 256 {
            for tx in px(BBOX[0]) / 256..=px(BBOX[2]) / 256 {
                let p = tiles_dir.join(format!("{ZOOM}/{tx}/{ty}.png"));
                std::fs::create_dir_all(p.parent().unwrap()).unwrap();
                std::fs::write(&p, make_tile(ZOOM, tx, ty, enc)).unwrap();
            }
        }
        for source in [server.template(), tiles_dir.display().to_string()] {
            let out = dir.join(format!("{enc:?}-{}", source.starts_with("http") as u8));
            let s = preprocess::run(
                &Options {
                    input: Input::Xyz(settings(source.clone(), enc, &dir.join("cache"))),
                    out: out.clone(),
                    center_size: 64,
                    force: true,
                    ..Default::default()
                },
                &NoProgress,
            )
            .unwrap();
            assert!(
                s.warnings.iter().any(|w| w.contains("not ground metres")),
                "{:?}",
                s.warnings
            );
            let ds = Dataset::open(&out).unwrap();
            let m = &ds.manifest;
            assert_eq!(m.vertical_datum, "unknown");
            let g = m.georef.as_ref().unwrap();
            assert_eq!(g.crs.authority.as_deref(), Some("EPSG:3857"));
            assert_eq!(g.step(), [res, res]);
            let (w, h, heights, _) = ds.level_raster(0).unwrap();
            let (mut compared, mut worst, mut shifted_differ) = (0, 0f64, 0);
            let mut geo = SpatialRef::from_epsg(4326).unwrap();
            geo.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
            let mut merc = SpatialRef::from_epsg(3857).unwrap();
            merc.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
            let to_geo = CoordTransform::new(&merc, &geo).unwrap();
            for row in 0..h as u64 {
                for col in 0..w as u64 {
                    let [x, y] = g.at(col as f64, row as f64);
                    // The sample is the centre of an integer pixel of the zoom.
                    let fx = (x + std::f64::consts::PI * R) / res - 0.5;
                    let fy = (std::f64::consts::PI * R - y) / res - 0.5;
                    assert!((fx - fx.round()).abs() < 1e-6 && (fy - fy.round()).abs() < 1e-6);
                    let (lon, lat) = pixel_lonlat(ZOOM, fx.round() as u64, fy.round() as u64);
                    if row % 97 == 0 && col % 89 == 0 {
                        let (mut xs, mut ys, mut zs) = ([x], [y], [0.0]);
                        to_geo.transform_coords(&mut xs, &mut ys, &mut zs).unwrap();
                        assert!((xs[0] - lon).abs() < 1e-9 && (ys[0] - lat).abs() < 1e-9);
                    }
                    let got = heights[(row * w as u64 + col) as usize] as f64;
                    if let Some(want) = srtm_at(lon, lat) {
                        worst = worst.max((got - want).abs());
                        compared += 1;
                        let east = pixel_lonlat(ZOOM, fx.round() as u64 + 1, fy.round() as u64);
                        if srtm_at(east.0, east.1).is_some_and(|v| v != got) {
                            shifted_differ += 1;
                        }
                    }
                }
            }
            eprintln!(
                "{enc:?} from {source}: {compared} samples, worst {worst} m, neighbour differs at {shifted_differ}"
            );
            assert!(compared > 100_000, "{compared}");
            assert!(worst <= enc.quantum(), "{worst}");
            assert!(shifted_differ > compared / 4);
        }
    }
}

/// The fetcher under fault injection: errors, timeouts, corrupt and oversize bodies are
/// one-line errors, counted, never cached, and a slow server costs at most the timeout; the
/// disk cache keeps within its bound and serves repeats without the network.
#[test]
fn tile_fetcher_counts_faults_and_bounds_its_cache() {
    if srtm().is_none() {
        return;
    }
    let dir = tmpdir("faults");
    let server = Server::start(Encoding::Terrarium);
    let mut s = settings(server.template(), Encoding::Terrarium, &dir.join("cache"));
    s.timeout_s = 0.5;
    s.cache_max_mb = 1;
    let f = TileFetcher::new(&s).unwrap();
    let (x0, y0) = (1032u32, 758u32);
    // Errors on even tiles.
    server.set(Fault::Errors(ZOOM));
    let e = f.tile(ZOOM, x0, y0).unwrap_err().to_string();
    assert!(e.contains("500") && !e.contains('\n'), "{e}");
    f.tile(ZOOM, x0 + 1, y0).unwrap();
    // Slow: bounded by the timeout.
    server.set(Fault::Slow(ZOOM, Duration::from_secs(3)));
    let t = Instant::now();
    let e = f.tile(ZOOM, x0 + 2, y0).unwrap_err().to_string();
    assert!(
        t.elapsed() < Duration::from_millis(2000),
        "{:?}",
        t.elapsed()
    );
    assert!(e.contains("timeout") || e.contains("imed out"), "{e}");
    // Corrupt and oversize bodies.
    server.set(Fault::Corrupt(ZOOM));
    let e = f.tile(ZOOM, x0 + 2, y0 + 2).unwrap_err().to_string();
    assert!(e.contains("PNG"), "{e}");
    server.set(Fault::Oversize(ZOOM));
    let e = f.tile(ZOOM, x0 + 3, y0 + 5).unwrap_err().to_string();
    assert!(!e.contains('\n'), "{e}");
    let c = f.counters.snapshot();
    assert_eq!((c.errors, c.timeouts, c.corrupt), (2, 1, 1), "{c:?}");
    // Nothing failed was cached: the same tiles succeed once the server recovers.
    server.set(Fault::None);
    f.tile(ZOOM, x0 + 2, y0 + 2).unwrap();
    // The cache stays within 1 MiB over many tiles (about 25 kB each); a repeat is a hit.
    for k in 0..80 {
        f.tile(ZOOM, x0 + k % 10, y0 + k / 10).unwrap();
        assert!(f.cache_bytes() <= 1 << 20, "{}", f.cache_bytes());
    }
    let before = f.counters.snapshot();
    f.tile(ZOOM, x0 + 9, y0 + 7).unwrap();
    let after = f.counters.snapshot();
    assert_eq!(after.fetched, before.fetched);
    assert_eq!(after.cache_hits, before.cache_hits + 1);
    assert!(after.evicted > 0, "{after:?}");
    // Decoding refuses what is not a terrain tile.
    assert!(decode_tile(b"not a png", Encoding::Terrarium, 256).is_err());
    let grey = {
        let mut out = Vec::new();
        image::GrayImage::new(256, 256)
            .write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
            .unwrap();
        out
    };
    let e = decode_tile(&grey, Encoding::Terrarium, 256)
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a terrain tile"), "{e}");
}

/// The live source through the clipmap while the server fails (errors, timeouts, corrupt
/// PNGs): frames keep coming (none waits for the network), failures are counted and drawn as
/// coarser data without holes; once the server recovers the view converges to full
/// resolution.
#[cfg(feature = "gdal")] // tile placement through PROJ (GDAL's OSR)
#[test]
fn live_xyz_source_streams_through_the_clipmap_under_faults() {
    if srtm().is_none() {
        return;
    }
    let gpu = common::gpu(false);
    let dir = tmpdir("live");
    let server = Server::start(Encoding::Terrarium);
    let mut s = settings(server.template(), Encoding::Terrarium, &dir.join("cache"));
    // A request may block a loader for 4 s; a frame that waited for one would take longer.
    s.timeout_s = 4.0;
    let store = Arc::new(XyzPyramid::open(&s).unwrap());
    let reader = Arc::new(PyramidReader::from_store(store.clone()).unwrap());
    let cm = live_clipmap(&store);
    let (ex, ey) = reader.extent();
    let [_, hi] = store.height_range;
    let cam = Camera {
        position: DVec3::new(0.5 * ex, 0.5 * ey, hi as f64 + 0.4 * ex),
        yaw_deg: 0.0,
        pitch_deg: -90.0,
        ..Camera::default()
    };
    let mut renderer = Renderer::with_clipmap(
        &gpu,
        Terrain::Pyramid(reader.clone()),
        MethodKind::Brute,
        common::options(160, 100, 2),
        Some(cm),
    )
    .unwrap();
    let mut sink = CollectSink::default();
    // The first frame builds pipelines; time the streaming frames after it.
    server.set(Fault::Errors(ZOOM));
    renderer.render(cam, &mut sink).unwrap();
    let (slowest, times) = render_under_faults(&mut renderer, &server, cam, &mut sink);
    renderer.finish(&mut sink).unwrap();
    let cm = renderer.clipmap().unwrap();
    let c = cm.counters;
    let t = cm.tile_counts().unwrap();
    eprintln!("under faults: {c:?} {t:?}, slowest frame {slowest:?}, frame ms {times:?}");
    assert!(c.load_errors > 0 && c.fallback_frames > 0, "{c:?}");
    assert!(t.errors > 0 && t.timeouts > 0 && t.corrupt > 0, "{t:?}");
    assert!(
        sink.frames
            .iter()
            .all(|f| f.depth.as_ref().unwrap().iter().all(|&d| d > 0.0)),
        "a frame has holes"
    );
    // Never a stall: no frame waited for a slow request (4 s timeout, 8 s answers).
    assert!(slowest < Duration::from_millis(3500), "{slowest:?}");
    // Recovered: every wanted node arrives.
    server.set(Fault::None);
    let mut frames = 0;
    loop {
        renderer.render(cam, &mut sink).unwrap();
        frames += 1;
        let cm = renderer.clipmap().unwrap();
        if cm.busy() == 0 && cm.views[0].fallback_cells == 0 {
            break;
        }
        assert!(frames < 400, "no convergence: {:?}", cm.counters);
    }
    renderer.finish(&mut sink).unwrap();
    // The clipmap's heights at level-0 samples are the tiles' (what PyramidReader reads).
    let samples: Vec<[f32; 2]> = (0..20)
        .map(|k| {
            [
                (0.3 + 0.02 * k as f64) as f32 * (ex / reader.spacing()) as f32,
                0.5 * (ey / reader.spacing()) as f32,
            ]
        })
        .map(|p| [p[0].round(), p[1].round()])
        .collect();
    let h = renderer.probe_heights(&samples).unwrap();
    for (p, g) in samples.iter().zip(&h) {
        assert_eq!(
            g[0],
            reader.sample(p[0] as u32, p[1] as u32).unwrap(),
            "at {p:?}"
        );
    }
    drop(renderer);
    common::assert_no_validation_messages(&gpu);
}

/// The clipmap over the live source `store`: one view of 8 nodes, two loader threads, up to
/// 16 requests in flight, a failed node retried after 2 frames.
#[cfg(feature = "gdal")]
fn live_clipmap(store: &Arc<XyzPyramid>) -> Clipmap {
    Clipmap::new(
        Geometry::of_store(&**store),
        ClipmapSettings {
            enabled: true,
            atlas_capacity: 200,
            node_count: 8,
            max_in_flight: 16,
            max_uploads_per_frame: 16,
            workers: 2,
            retry_frames: 2,
            blend_nodes: 0.5,
        },
        Arc::new(StoreSource(store.clone())),
        1,
    )
    .unwrap()
}

/// Renders `cam` while the server answers ZOOM's tiles with errors, then slowly (8 s), then
/// corrupt: 25 frames each, the corrupt phase until a corrupt tile was fetched (up to 250
/// frames): fetches of the slow phase may still hold every worker for their 8 s timeout when
/// it begins, so on a loaded machine 25 frames can pass without a fetch. The slowest frame and
/// every frame's time in ms.
#[cfg(feature = "gdal")]
fn render_under_faults(
    renderer: &mut Renderer,
    server: &Server,
    cam: Camera,
    sink: &mut CollectSink,
) -> (Duration, Vec<u128>) {
    let mut slowest = Duration::ZERO;
    let mut times = Vec::new();
    for fault in [
        Fault::Errors(ZOOM),
        Fault::Slow(ZOOM, Duration::from_secs(8)),
        Fault::Corrupt(ZOOM),
    ] {
        server.set(fault);
        for frame in 0..250 {
            let t = Instant::now();
            renderer.render(cam, sink).unwrap();
            slowest = slowest.max(t.elapsed());
            times.push(t.elapsed().as_millis());
            let corrupt_seen = || renderer.clipmap().unwrap().tile_counts().unwrap().corrupt > 0;
            if frame + 1 >= 25 && (!matches!(fault, Fault::Corrupt(_)) || corrupt_seen()) {
                break;
            }
        }
    }
    (slowest, times)
}
