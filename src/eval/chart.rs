//! Charts of an evaluation, drawn with `plotters` as SVG and as PNG, both with their text: the
//! PNG's glyphs come from DejaVu Sans, embedded (`assets/fonts/`, no system font lookup), the
//! SVG names the same family. Axes become logarithmic where the data spans a decade or more;
//! ticks are plotters' round values; each point of a sweep can carry its parameter as a label;
//! series differ in colour and marker shape and are drawn half-transparent so none hides
//! another; a Pareto front is ringed and joined.

use std::ops::Range;
use std::path::Path;
use std::sync::Once;

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::error::{Error, Result};

/// Pixel size of every chart.
pub const SIZE: (u32, u32) = (960, 600);

const FONT: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// Colours of successive series (RGB).
const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded file is a valid TrueType font (checked by the chart tests).
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES);
    });
}

#[derive(Clone, Debug, Default)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// A label per point (e.g. the sweep parameter), or none.
    pub labels: Vec<String>,
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
    /// Points to ring and join (the Pareto front), in x order.
    pub highlight: Vec<(f64, f64)>,
    /// Start the y axis at 0 when it stays linear (frame times, triangle counts).
    pub y_from_zero: bool,
}

/// One axis: its range and whether it is logarithmic.
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    pub range: Range<f64>,
    pub log: bool,
}

impl Axis {
    /// The axis for `values` (finite ones): logarithmic over whole decades when all are
    /// positive and the largest is at least ten times the smallest, else linear with 5%
    /// margins (from 0 when `from_zero` and nothing is negative).
    pub fn fit(values: impl Iterator<Item = f64>, from_zero: bool) -> Axis {
        let v: Vec<f64> = values.filter(|v| v.is_finite()).collect();
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        if v.is_empty() {
            return Axis {
                range: 0.0..1.0,
                log: false,
            };
        }
        if lo > 0.0 && hi >= 10.0 * lo {
            return Axis {
                range: 10f64.powf(lo.log10().floor())..10f64.powf(hi.log10().ceil()),
                log: true,
            };
        }
        let span = (hi - lo).max(hi.abs() * 1e-3).max(1e-9);
        let start = if from_zero && lo >= 0.0 {
            0.0
        } else if lo >= 0.0 {
            (lo - 0.05 * span).max(0.0)
        } else {
            lo - 0.05 * span
        };
        Axis {
            range: start..hi + 0.05 * span,
            log: false,
        }
    }

    /// Where `v` lies along the axis: 0 at its start, 1 at its end.
    pub fn fraction(&self, v: f64) -> f64 {
        let (a, b) = (self.range.start, self.range.end);
        if self.log {
            (v.ln() - a.ln()) / (b.ln() - a.ln())
        } else {
            (v - a) / (b - a)
        }
    }
}

/// A tick label: few significant digits, no trailing noise.
pub fn format_tick(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.0e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

type DrawResult = std::result::Result<(), String>;

impl Chart {
    fn finite(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.series
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    }

    /// The axes the data gets.
    pub fn axes(&self) -> (Axis, Axis) {
        (
            Axis::fit(self.finite().map(|p| p.0), false),
            Axis::fit(self.finite().map(|p| p.1), self.y_from_zero),
        )
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
    ) -> DrawResult {
        register_font();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (x, y) = self.axes();
        let lin = |a: &Axis| -> RangedCoordf64 { a.range.clone().into() };
        match (x.log, y.log) {
            (false, false) => self.draw_in(&root, lin(&x), lin(&y), &x, &y),
            (true, false) => self.draw_in(&root, x.range.clone().log_scale(), lin(&y), &x, &y),
            (false, true) => self.draw_in(&root, lin(&x), y.range.clone().log_scale(), &x, &y),
            (true, true) => self.draw_in(
                &root,
                x.range.clone().log_scale(),
                y.range.clone().log_scale(),
                &x,
                &y,
            ),
        }?;
        root.present().map_err(|e| e.to_string())
    }

    fn draw_in<DB, X, Y>(
        &self,
        root: &DrawingArea<DB, plotters::coord::Shift>,
        x_spec: X,
        y_spec: Y,
        x: &Axis,
        y: &Axis,
    ) -> DrawResult
    where
        DB: DrawingBackend,
        X: AsRangedCoord<Value = f64>,
        Y: AsRangedCoord<Value = f64>,
        X::CoordDescType: ValueFormatter<f64>,
        Y::CoordDescType: ValueFormatter<f64>,
    {
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, (FONT, 22))
            .margin(16)
            .x_label_area_size(52)
            .y_label_area_size(76)
            .build_cartesian_2d(x_spec, y_spec)
            .map_err(draw_error)?;
        let log = |a: &Axis| if a.log { " (log)" } else { "" };
        chart
            .configure_mesh()
            .x_desc(format!("{}{}", self.x_label, log(x)))
            .y_desc(format!("{}{}", self.y_label, log(y)))
            .x_label_formatter(&|v| format_tick(*v))
            .y_label_formatter(&|v| format_tick(*v))
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 17))
            .light_line_style(BLACK.mix(0.05))
            .bold_line_style(BLACK.mix(0.15))
            .draw()
            .map_err(draw_error)?;
        let mut placed = LabelSlots::default();
        for (i, s) in self.series.iter().enumerate() {
            draw_labelled_series(&mut chart, i, s, x, y, &mut placed)?;
        }
        if !self.highlight.is_empty() {
            self.draw_pareto_front(&mut chart, x, y)?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.5))
            .draw()
            .map_err(draw_error)
    }

    /// The highlighted points (the Pareto front), within the axes: joined, ringed, and named in
    /// the legend.
    fn draw_pareto_front<'a, DB, X, Y>(
        &self,
        chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
        x: &Axis,
        y: &Axis,
    ) -> DrawResult
    where
        DB: DrawingBackend + 'a,
        X: Ranged<ValueType = f64>,
        Y: Ranged<ValueType = f64>,
    {
        let front: Vec<(f64, f64)> = self
            .highlight
            .iter()
            .copied()
            .filter(|&p| on_chart(x, y, p))
            .collect();
        chart
            .draw_series(LineSeries::new(
                front.clone(),
                BLACK.mix(0.5).stroke_width(1),
            ))
            .map_err(draw_error)?
            .label("Pareto front")
            .legend(|(lx, ly)| Circle::new((lx + 10, ly), 7, BLACK.stroke_width(2)));
        chart
            .draw_series(
                front
                    .iter()
                    .map(|&p| Circle::new(p, 9, BLACK.stroke_width(2))),
            )
            .map_err(draw_error)?;
        Ok(())
    }

    /// The chart as SVG text.
    pub fn to_svg(&self) -> Result<String> {
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
            self.draw(root).map_err(|e| Error::invalid("chart", e))?;
        }
        Ok(svg)
    }

    /// The chart rasterized, RGBA8.
    pub fn to_rgba(&self) -> Result<(u32, u32, Vec<u8>)> {
        let (w, h) = SIZE;
        let mut rgb = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area();
            self.draw(root).map_err(|e| Error::invalid("chart", e))?;
        }
        let rgba = rgb
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect();
        Ok((w, h, rgba))
    }

    /// Writes `<stem>.svg` and `<stem>.png` (atomically each).
    pub fn write(&self, dir: &Path, stem: &str) -> Result<()> {
        crate::output::write_atomic(&dir.join(format!("{stem}.svg")), self.to_svg()?.as_bytes())?;
        let (w, h, rgba) = self.to_rgba()?;
        crate::output::png::write_png(&dir.join(format!("{stem}.png")), w, h, &rgba)
    }
}

/// A plotters drawing error as the message of a [`DrawResult`].
fn draw_error<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> String {
    e.to_string()
}

/// Whether `p` is finite and within both axes (points outside are not drawn).
fn on_chart(x: &Axis, y: &Axis, (px, py): (f64, f64)) -> bool {
    px.is_finite() && py.is_finite() && x.range.contains(&px) && y.range.contains(&py)
}

/// Series `i` of a chart, its points within the axes: its line (if it has one), its legend
/// entry, its markers (if it has them) and its point labels, placed below labels already
/// drawn near them (`placed`).
fn draw_labelled_series<'a, DB, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    i: usize,
    s: &Series,
    x: &Axis,
    y: &Axis,
    placed: &mut LabelSlots,
) -> DrawResult
where
    DB: DrawingBackend + 'a,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let colour = PALETTE[i % PALETTE.len()];
    let pts: Vec<(f64, f64)> = s
        .points
        .iter()
        .copied()
        .filter(|&p| on_chart(x, y, p))
        .collect();
    let line_style = colour.mix(0.8).stroke_width(2);
    let legend_colour = colour;
    let shape = i;
    let anno = if s.line {
        chart
            .draw_series(LineSeries::new(pts.clone(), line_style))
            .map_err(draw_error)?
    } else {
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
            .map_err(draw_error)?
    };
    anno.label(&s.name).legend(move |(lx, ly)| {
        EmptyElement::at((lx, ly))
            + PathElement::new(vec![(0, 0), (20, 0)], legend_colour.stroke_width(2))
            + marker((10, 0), shape, legend_colour)
    });
    if s.markers {
        chart
            .draw_series(
                pts.iter()
                    .map(|&p| EmptyElement::at(p) + marker((0, 0), shape, colour)),
            )
            .map_err(draw_error)?;
    }
    let labelled: Vec<_> = merged_labels(s, x, y)
        .into_iter()
        .filter(|(p, _)| on_chart(x, y, *p))
        .map(|(p, text)| (p, text, placed.line_for(x.fraction(p.0), y.fraction(p.1))))
        .collect();
    chart
        .draw_series(labelled.into_iter().map(|(p, text, line)| {
            EmptyElement::at(p) + point_label(text, line, x.fraction(p.0) > 0.8, colour)
        }))
        .map_err(draw_error)?;
    Ok(())
}

/// A point's label, `line` lines below the first at its place, beside the point: to its right,
/// or ending at it near the right edge (`at_right_edge`; else it would be clipped).
fn point_label(
    text: String,
    line: i32,
    at_right_edge: bool,
    colour: RGBColor,
) -> Text<'static, (i32, i32), String> {
    let (dx, h) = if at_right_edge {
        (-7, HPos::Right)
    } else {
        (7, HPos::Left)
    };
    let style = (FONT, 13)
        .into_font()
        .color(&colour)
        .pos(Pos::new(h, VPos::Top));
    Text::new(text, (dx, -16 + LABEL_LINE_PX * line), style)
}

/// Points closer than this share of both axes are one place for their labels.
const SAME_PLACE: f64 = 0.01;
/// A label line's height (13 px text).
const LABEL_LINE_PX: i32 = 15;

/// Whether two points, as fractions of the axes, are one place for labels.
fn same_place(a: (f64, f64), b: (f64, f64)) -> bool {
    (a.0 - b.0).abs() < SAME_PLACE && (a.1 - b.1).abs() < SAME_PLACE
}

/// A series' labels, one per place: the labels of points that coincide on the chart (a sweep
/// whose settings draw the same frames) are merged, their common prefix up to the last `=`
/// or space written once (`tau_px=0.5`, `tau_px=1` -> `tau_px=0.5, 1`); otherwise they were
/// drawn over each other, unreadable.
fn merged_labels(s: &Series, x: &Axis, y: &Axis) -> Vec<((f64, f64), String)> {
    let at = |p: (f64, f64)| (x.fraction(p.0), y.fraction(p.1));
    let mut groups: Vec<((f64, f64), Vec<&str>)> = Vec::new();
    for (&p, label) in s.points.iter().zip(&s.labels) {
        if !(p.0.is_finite() && p.1.is_finite()) {
            continue;
        }
        match groups.iter_mut().find(|(q, _)| same_place(at(*q), at(p))) {
            Some((_, labels)) => labels.push(label),
            None => groups.push((p, vec![label])),
        }
    }
    groups
        .into_iter()
        .map(|(p, labels)| (p, merge_label_texts(&labels)))
        .collect()
}

/// `["tau_px=0.5", "tau_px=1"]` -> `"tau_px=0.5, 1"`; labels without a common `key=` or word
/// prefix are joined with ", ".
fn merge_label_texts(labels: &[&str]) -> String {
    let (first, rest) = match labels {
        [] => return String::new(),
        [one] => return one.to_string(),
        [first, rest @ ..] => (first, rest),
    };
    let mut common = rest.iter().fold(first.len(), |n, l| {
        first
            .bytes()
            .zip(l.bytes())
            .take(n)
            .take_while(|(a, b)| a == b)
            .count()
    });
    while !first.is_char_boundary(common) {
        common -= 1;
    }
    let prefix = first[..common]
        .rfind(['=', ' '])
        .map_or(0, |i| i + 1)
        .min(common);
    let mut tails: Vec<&str> = Vec::new();
    for l in labels {
        if !tails.contains(&&l[prefix..]) {
            tails.push(&l[prefix..]);
        }
    }
    format!("{}{}", &first[..prefix], tails.join(", "))
}

/// How near (as fractions of the axes) another series' label must start to share a label's
/// lines: about a label's width to the side and a line's height (15 px of a ~500 px plot).
const LABEL_BOX: (f64, f64) = (0.15, 0.035);

/// Where labels went (as fractions of the axes): a label starting within [`LABEL_BOX`] of
/// labels already drawn goes below them, one line each.
#[derive(Default)]
struct LabelSlots(Vec<(f64, f64)>);

impl LabelSlots {
    /// The line (0, 1, ...) this label takes below those near it.
    fn line_for(&mut self, fx: f64, fy: f64) -> i32 {
        let near =
            |q: &&(f64, f64)| (q.0 - fx).abs() < LABEL_BOX.0 && (q.1 - fy).abs() < LABEL_BOX.1;
        let line = self.0.iter().filter(near).count();
        self.0.push((fx, fy));
        line as i32
    }
}

/// Marker `shape` (circle, triangle, square, diamond, in turn) centred at `at` (pixels).
fn marker(at: (i32, i32), shape: usize, colour: RGBColor) -> Polygon<(i32, i32)> {
    let (corners, turn) = match shape % 4 {
        0 => (16, 0.0),
        1 => (3, -90.0f64),
        2 => (4, 45.0),
        _ => (4, 0.0),
    };
    let r = if corners == 4 { 6.0 } else { 5.5 };
    let vertices = (0..corners)
        .map(|k| {
            let a = (turn + 360.0 * k as f64 / corners as f64).to_radians();
            (
                at.0 + (r * a.cos()).round() as i32,
                at.1 + (r * a.sin()).round() as i32,
            )
        })
        .collect::<Vec<_>>();
    Polygon::new(vertices, colour.filled())
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_the_non_dominated_points() {
        let pts = [(1.0, 5.0), (2.0, 2.0), (3.0, 3.0), (4.0, 1.0), (2.0, 2.5)];
        assert_eq!(pareto_front(&pts), vec![0, 1, 3]);
    }

    #[test]
    fn axes_go_logarithmic_over_decades_only() {
        let log = Axis::fit([0.02, 0.5, 3.0].into_iter(), false);
        assert!(log.log && log.range == (0.01..10.0), "{log:?}");
        let lin = Axis::fit([2.0, 3.0, f64::NAN].into_iter(), true);
        assert!(
            !lin.log && lin.range.start == 0.0 && lin.range.end > 3.0,
            "{lin:?}"
        );
        // Linear from the data's minimum (never below 0 for non-negative data).
        let lin = Axis::fit([0.1, 0.9].into_iter(), false);
        assert!(
            !lin.log && lin.range.start >= 0.0 && lin.range.start < 0.1,
            "{lin:?}"
        );
        assert_eq!(format_tick(0.25), "0.25");
        assert_eq!(format_tick(2.0), "2");
        assert_eq!(format_tick(1500.0), "1500");
        assert_eq!(format_tick(0.0001), "1e-4");
    }

    fn chart(x_label: &str) -> Chart {
        Chart {
            title: "Frame time vs error <test>".into(),
            x_label: x_label.into(),
            y_label: "frame time (ms)".into(),
            series: vec![
                Series {
                    name: "udlod".into(),
                    points: vec![(0.4, 3.0), (1.1, 2.0), (3.9, 1.5)],
                    labels: vec!["tau_px=0.5".into(), "tau_px=1".into(), "tau_px=4".into()],
                    markers: true,
                    line: true,
                },
                Series {
                    name: "pgm".into(),
                    points: vec![(8.0, 1.0), (f64::NAN, 2.0)],
                    labels: vec!["120x525".into()],
                    markers: true,
                    line: false,
                },
            ],
            highlight: vec![(0.4, 3.0), (1.1, 2.0), (3.9, 1.5), (8.0, 1.0)],
            y_from_zero: true,
        }
    }

    #[test]
    fn labels_of_coinciding_points_are_merged() {
        assert_eq!(
            merge_label_texts(&["tau_px=0.5", "tau_px=1", "tau_px=4"]),
            "tau_px=0.5, 1, 4"
        );
        assert_eq!(
            merge_label_texts(&["120x525 warp_rows=0", "120x525 warp_rows=1"]),
            "120x525 warp_rows=0, 1"
        );
        assert_eq!(merge_label_texts(&["a=1", "b=2"]), "a=1, b=2");
        assert_eq!(merge_label_texts(&["x=1", "x=1"]), "x=1");
        assert_eq!(merge_label_texts(&["é=1", "é=2"]), "é=1, 2");
        // Three taus drawing the same frames, a fourth apart; a second series on the same spot.
        let mut c = chart("error (px)");
        c.series[0].points = vec![(0.5, 10.0), (0.5, 10.0), (0.5, 10.0), (2.0, 4.0)];
        c.series[0].labels = ["tau_px=0.5", "tau_px=1", "tau_px=2", "tau_px=4"]
            .map(String::from)
            .to_vec();
        c.series[1].points = vec![(0.5, 10.0)];
        let svg = c.to_svg().unwrap();
        // plotters writes each text element's content on a line of its own.
        let text = |label: &str| format!("\n{label}\n</text>");
        assert!(svg.contains(&text("tau_px=0.5, 1, 2")), "merged label");
        assert!(svg.contains(&text("tau_px=4")));
        assert!(
            !svg.contains(&text("tau_px=1")),
            "no label drawn over another"
        );
        // The second series' label at the same place goes one line lower.
        let y_of = |label: &str| {
            let end = svg.find(&text(label)).unwrap();
            let start = svg[..end].rfind("<text").unwrap();
            let y = &svg[start..end];
            let y = &y[y.find("y=\"").unwrap() + 3..];
            y[..y.find('"').unwrap()].parse::<f64>().unwrap()
        };
        let (first, second) = (y_of("tau_px=0.5, 1, 2"), y_of("120x525"));
        assert!(
            (second - first - LABEL_LINE_PX as f64).abs() < 1.0,
            "stacked: {first} then {second}"
        );
    }

    /// Dark pixels (text, lines) in a region of an RGBA image.
    fn dark(rgba: &[u8], w: u32, (x0, y0, x1, y1): (u32, u32, u32, u32)) -> usize {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| ((y * w + x) * 4) as usize))
            .filter(|&i| rgba[i] < 128 && rgba[i + 1] < 128 && rgba[i + 2] < 128)
            .count()
    }

    #[test]
    fn charts_carry_their_titles_labels_and_legend() {
        let c = chart("screen-space error (px)");
        let svg = c.to_svg().unwrap();
        for text in [
            "Frame time vs error &lt;test&gt;",
            "screen-space error (px) (log)",
            "frame time (ms)",
            "tau_px=0.5",
            "120x525",
            "udlod",
            "pgm",
            "Pareto front",
        ] {
            assert!(svg.contains(text), "SVG lacks {text:?}");
        }
        assert!(svg.contains("<text"), "labels are SVG text");
        // The label of the point near the right edge ends at it (not clipped); the others start
        // at theirs.
        let element = |label: &str| {
            let end = svg.find(label).expect("label drawn");
            svg[..end].rsplit("<text").next().unwrap().to_string()
        };
        assert!(element("120x525").contains("text-anchor=\"end\""));
        assert!(!element("tau_px=0.5").contains("text-anchor=\"end\""));
        // The PNG has text in the label areas: the x-axis title band below the plot, the
        // y-axis band on the left, the title above; an unlabelled x axis leaves its band
        // emptier (negative control).
        let (w, h, rgba) = c.to_rgba().unwrap();
        let below = (w / 3, h - 30, 2 * w / 3, h);
        let left = (0, h / 4, 30, 3 * h / 4);
        let top = (w / 4, 0, 3 * w / 4, 36);
        for band in [below, left, top] {
            assert!(dark(&rgba, w, band) > 40, "no text in {band:?}");
        }
        let (_, _, bare) = chart("").to_rgba().unwrap();
        assert!(dark(&bare, w, below) * 2 < dark(&rgba, w, below));
    }
}
