//! Small line/scatter charts written as SVG (with labels) and PNG (the same plot rasterized,
//! without text: the SVG carries the labels). No plotting crate is available offline here, and
//! the charts need only axes, polylines, markers and a legend.

use std::fmt::Write as _;
use std::path::Path;

use crate::error::Result;

/// Colours of successive series (RGB).
const PALETTE: [[u8; 3]; 8] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [23, 190, 207],
];

#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Draw markers at the points.
    pub markers: bool,
    /// Connect the points.
    pub line: bool,
}

#[derive(Clone, Debug, Default)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Points to ring (e.g. the Pareto front).
    pub highlight: Vec<(f64, f64)>,
    pub log_x: bool,
}

const W: f64 = 720.0;
const H: f64 = 440.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 190.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 50.0;

impl Chart {
    fn finite_points(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.series
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|(x, y)| x.is_finite() && y.is_finite() && (!self.log_x || *x > 0.0))
    }

    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let fx = |x: f64| if self.log_x { x.log10() } else { x };
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, 0.0f64, f64::MIN);
        for (x, y) in self.finite_points() {
            x0 = x0.min(fx(x));
            x1 = x1.max(fx(x));
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if x0 > x1 {
            (x0, x1, y1) = (0.0, 1.0, 1.0);
        }
        if x1 - x0 < 1e-12 {
            x0 -= 0.5;
            x1 += 0.5;
        }
        if y1 - y0 < 1e-12 {
            y1 = y0 + 1.0;
        }
        let (px, py) = (0.05 * (x1 - x0), 0.05 * (y1 - y0));
        ((x0 - px, x1 + px), (y0, y1 + py))
    }

    /// Maps data coordinates to image coordinates.
    fn mapper(&self) -> impl Fn(f64, f64) -> (f64, f64) + '_ {
        let ((x0, x1), (y0, y1)) = self.ranges();
        move |x, y| {
            let x = if self.log_x { x.max(1e-300).log10() } else { x };
            (
                LEFT + (x - x0) / (x1 - x0) * (W - LEFT - RIGHT),
                H - BOTTOM - (y - y0) / (y1 - y0) * (H - TOP - BOTTOM),
            )
        }
    }

    pub fn to_svg(&self) -> String {
        let map = self.mapper();
        let ((x0, x1), (y0, y1)) = self.ranges();
        let mut s = String::new();
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
        let _ = writeln!(
            s,
            r#"<text x="{}" y="22" font-size="15" text-anchor="middle">{}</text>"#,
            (W - RIGHT + LEFT) / 2.0,
            escape(&self.title)
        );
        // Axes and ticks.
        let (ax0, ay0) = (LEFT, H - BOTTOM);
        let _ = writeln!(
            s,
            r#"<path d="M{ax0} {TOP} L{ax0} {ay0} L{} {ay0}" stroke="black" fill="none"/>"#,
            W - RIGHT
        );
        for i in 0..=5 {
            let t = i as f64 / 5.0;
            let xv = x0 + t * (x1 - x0);
            let label = if self.log_x {
                format_number(10f64.powf(xv))
            } else {
                format_number(xv)
            };
            let px = LEFT + t * (W - LEFT - RIGHT);
            let _ = writeln!(
                s,
                r#"<line x1="{px}" y1="{ay0}" x2="{px}" y2="{}" stroke="black"/><text x="{px}" y="{}" text-anchor="middle">{label}</text>"#,
                ay0 + 5.0,
                ay0 + 18.0
            );
            let yv = y0 + t * (y1 - y0);
            let py = H - BOTTOM - t * (H - TOP - BOTTOM);
            let _ = writeln!(
                s,
                r##"<line x1="{}" y1="{py}" x2="{ax0}" y2="{py}" stroke="black"/><line x1="{ax0}" y1="{py}" x2="{}" y2="{py}" stroke="#ddd"/><text x="{}" y="{}" text-anchor="end">{}</text>"##,
                ax0 - 5.0,
                W - RIGHT,
                ax0 - 8.0,
                py + 4.0,
                format_number(yv)
            );
        }
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
            (W - RIGHT + LEFT) / 2.0,
            H - 10.0,
            escape(&self.x_label)
        );
        let _ = writeln!(
            s,
            r#"<text x="16" y="{}" text-anchor="middle" transform="rotate(-90 16 {})">{}</text>"#,
            (H - BOTTOM + TOP) / 2.0,
            (H - BOTTOM + TOP) / 2.0,
            escape(&self.y_label)
        );
        for (i, series) in self.series.iter().enumerate() {
            let [r, g, b] = PALETTE[i % PALETTE.len()];
            let colour = format!("rgb({r},{g},{b})");
            let pts: Vec<(f64, f64)> = series
                .points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite() && (!self.log_x || *x > 0.0))
                .map(|(x, y)| map(x, y))
                .collect();
            if series.line && pts.len() > 1 {
                let d: Vec<String> = pts.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
                let _ = writeln!(
                    s,
                    r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="1.5"/>"#,
                    d.join(" ")
                );
            }
            if series.markers {
                for (x, y) in &pts {
                    let _ = writeln!(
                        s,
                        r#"<circle cx="{x:.1}" cy="{y:.1}" r="3.5" fill="{colour}"/>"#
                    );
                }
            }
            let ly = TOP + 18.0 * i as f64;
            let _ = writeln!(
                s,
                r#"<rect x="{}" y="{}" width="12" height="12" fill="{colour}"/><text x="{}" y="{}">{}</text>"#,
                W - RIGHT + 12.0,
                ly,
                W - RIGHT + 30.0,
                ly + 10.0,
                escape(&series.name)
            );
        }
        for &(x, y) in &self.highlight {
            let (px, py) = map(x, y);
            let _ = writeln!(
                s,
                r#"<circle cx="{px:.1}" cy="{py:.1}" r="7" fill="none" stroke="black" stroke-width="1.5"/>"#
            );
        }
        if !self.highlight.is_empty() {
            let ly = TOP + 18.0 * self.series.len() as f64;
            let _ = writeln!(
                s,
                r#"<circle cx="{}" cy="{}" r="6" fill="none" stroke="black"/><text x="{}" y="{}">Pareto front</text>"#,
                W - RIGHT + 18.0,
                ly + 6.0,
                W - RIGHT + 30.0,
                ly + 10.0
            );
        }
        s.push_str("</svg>\n");
        s
    }

    /// The plot rasterized (axes, grid, series, highlights, legend swatches), RGBA8.
    pub fn to_rgba(&self) -> (u32, u32, Vec<u8>) {
        let (w, h) = (W as u32, H as u32);
        let mut img = vec![255u8; (w * h * 4) as usize];
        let mut put = |x: i64, y: i64, c: [u8; 3]| {
            if x >= 0 && y >= 0 && (x as u32) < w && (y as u32) < h {
                let i = ((y as u32 * w + x as u32) * 4) as usize;
                img[i..i + 3].copy_from_slice(&c);
            }
        };
        let line =
            |a: (f64, f64), b: (f64, f64), c: [u8; 3], put: &mut dyn FnMut(i64, i64, [u8; 3])| {
                let n = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).max(1);
                for k in 0..=n {
                    let t = k as f64 / n as f64;
                    put(
                        (a.0 + (b.0 - a.0) * t).round() as i64,
                        (a.1 + (b.1 - a.1) * t).round() as i64,
                        c,
                    );
                }
            };
        let map = self.mapper();
        let grey = [221, 221, 221];
        for i in 0..=5 {
            let py = H - BOTTOM - i as f64 / 5.0 * (H - TOP - BOTTOM);
            line((LEFT, py), (W - RIGHT, py), grey, &mut put);
        }
        line((LEFT, TOP), (LEFT, H - BOTTOM), [0; 3], &mut put);
        line(
            (LEFT, H - BOTTOM),
            (W - RIGHT, H - BOTTOM),
            [0; 3],
            &mut put,
        );
        for (i, series) in self.series.iter().enumerate() {
            let c = PALETTE[i % PALETTE.len()];
            let pts: Vec<(f64, f64)> = series
                .points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite() && (!self.log_x || *x > 0.0))
                .map(|(x, y)| map(x, y))
                .collect();
            if series.line {
                for pair in pts.windows(2) {
                    line(pair[0], pair[1], c, &mut put);
                }
            }
            if series.markers {
                for &(x, y) in &pts {
                    for dy in -3i64..=3 {
                        for dx in -3i64..=3 {
                            if dx * dx + dy * dy <= 10 {
                                put(x.round() as i64 + dx, y.round() as i64 + dy, c);
                            }
                        }
                    }
                }
            }
            let ly = (TOP + 18.0 * i as f64) as i64;
            for dy in 0..12 {
                for dx in 0..12 {
                    put((W - RIGHT + 12.0) as i64 + dx, ly + dy, c);
                }
            }
        }
        for &(x, y) in &self.highlight {
            let (px, py) = map(x, y);
            for k in 0..48 {
                let a = k as f64 / 48.0 * std::f64::consts::TAU;
                put(
                    (px + 7.0 * a.cos()).round() as i64,
                    (py + 7.0 * a.sin()).round() as i64,
                    [0; 3],
                );
            }
        }
        (w, h, img)
    }

    /// Writes `<stem>.svg` and `<stem>.png` (atomically each).
    pub fn write(&self, dir: &Path, stem: &str) -> Result<()> {
        crate::output::write_atomic(&dir.join(format!("{stem}.svg")), self.to_svg().as_bytes())?;
        let (w, h, rgba) = self.to_rgba();
        crate::output::png::write_png(&dir.join(format!("{stem}.png")), w, h, &rgba)
    }
}

/// Indices of the Pareto-optimal points (smaller x and smaller y are better): no other point is
/// at least as good in both and better in one.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    (0..points.len())
        .filter(|&i| {
            let (xi, yi) = points[i];
            xi.is_finite()
                && yi.is_finite()
                && !points
                    .iter()
                    .enumerate()
                    .any(|(j, &(xj, yj))| j != i && xj <= xi && yj <= yi && (xj < xi || yj < yi))
        })
        .collect()
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn format_number(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(0.01..100_000.0).contains(&a) {
        format!("{v:.1e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.2}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_the_non_dominated_points() {
        let pts = [(1.0, 5.0), (2.0, 2.0), (3.0, 3.0), (4.0, 1.0), (2.0, 2.5)];
        assert_eq!(pareto_front(&pts), vec![0, 1, 3]);
    }

    #[test]
    fn charts_draw_their_series() {
        let chart = Chart {
            title: "t <1>".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![Series {
                name: "a".into(),
                points: vec![(0.5, 1.0), (1.0, 2.0), (f64::NAN, 3.0)],
                markers: true,
                line: true,
            }],
            highlight: vec![(1.0, 2.0)],
            log_x: true,
        };
        let svg = chart.to_svg();
        assert!(svg.contains("<polyline") && svg.contains("t &lt;1&gt;") && svg.contains("Pareto"));
        let (w, h, rgba) = chart.to_rgba();
        let coloured = rgba.chunks(4).filter(|p| p[..3] == PALETTE[0]).count();
        assert!(coloured > 50, "{coloured} series pixels in {w}x{h}");
    }
}
