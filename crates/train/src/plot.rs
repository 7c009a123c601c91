//! Learning-curve PNGs drawn with [`plotters`]: a white canvas, axes with "nice" ticks (1, 2 or
//! 5 × 10^k, [`nice_ticks`]), a light grid, one polyline with point markers per [`Series`], optional
//! translucent bands (e.g. mean ± standard error over seeds), a legend to the right of the plot, a
//! title and axis labels.
//!
//! plotters' bitmap backend draws into an RGB buffer that the `image` crate encodes as PNG. Text is
//! rasterised by plotters' `ab_glyph` font support with DejaVu Sans embedded from the `dejavu` crate
//! (Bitstream Vera / DejaVu font licence), so no system font, fontconfig or freetype is needed.
//!
//! Limitations: one linear x axis and one linear y axis (no log scale); the x axis spans exactly
//! the finite data (the y axis is widened to the enclosing ticks unless [`Chart::y_range`] fixes
//! it, and data outside a fixed range is clipped at the plot's edge); labels that do not fit are
//! clipped at the image border rather than wrapped, and legend labels are cut at 40 characters;
//! points with a non-finite coordinate are skipped and break the polyline (and band) there, like
//! matplotlib; bands expect the points of a series in increasing x order.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use image::{ImageFormat, RgbImage};
use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

/// What can go wrong while drawing or writing a chart.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The directory that should contain the output file does not exist.
    #[error("cannot write {path}: directory {dir} does not exist")]
    MissingDirectory {
        /// The requested output file.
        path: PathBuf,
        /// Its parent directory, which is missing.
        dir: PathBuf,
    },
    /// Creating or writing the output file failed (the file, and the cause).
    #[error(transparent)]
    Io(#[from] equiarm_types::files::FileError),
    /// PNG encoding failed.
    #[error("cannot encode {path} as PNG: {cause}")]
    Encode {
        /// The output file.
        path: PathBuf,
        /// The underlying error.
        cause: image::ImageError,
    },
    /// plotters failed to lay out or draw the chart (e.g. the embedded font could not be loaded).
    #[error("cannot draw the chart: {0}")]
    Draw(String),
    /// `Chart::width` or `Chart::height` is outside 64..=16384 pixels.
    #[error("chart size {width}x{height} is outside 64..=16384 pixels per side")]
    BadSize {
        /// Requested width (`Chart::width`).
        width: u32,
        /// Requested height (`Chart::height`).
        height: u32,
    },
    /// `Chart::y_range` is not finite or not increasing.
    #[error("Chart::y_range ({min}, {max}) must be finite with min < max")]
    BadYRange {
        /// Lower bound given.
        min: f64,
        /// Upper bound given.
        max: f64,
    },
    /// A series' `band` does not have one half-width per point.
    #[error("series {label:?}: band has {band} values but there are {points} points")]
    BandLength {
        /// `Series::label` of the offending series.
        label: String,
        /// Number of points.
        points: usize,
        /// Number of band values.
        band: usize,
    },
}

/// One curve of a chart.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Line, marker and band colour (RGB).
    pub color: [u8; 3],
    /// Data points `(x, y)`, normally in increasing x; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
    /// Optional ± half-width per point (same length as `points`), drawn as a translucent fill
    /// between `y - band` and `y + band`; non-finite values leave a gap.
    pub band: Option<Vec<f64>>,
}

impl Series {
    /// A series without a band.
    pub fn new(label: impl Into<String>, color: [u8; 3], points: Vec<(f64, f64)>) -> Self {
        Self { label: label.into(), color, points, band: None }
    }
}

/// Chart-wide settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Chart {
    /// Text above the plot (drawn larger than the other text).
    pub title: String,
    /// Text below the x axis.
    pub x_label: String,
    /// Text left of the y axis (drawn rotated).
    pub y_label: String,
    /// Fixed y axis range; `None` fits the data (and bands) and widens to the enclosing ticks.
    pub y_range: Option<(f64, f64)>,
    /// Image width in pixels (64..=16384).
    pub width: u32,
    /// Image height in pixels (64..=16384).
    pub height: u32,
}

impl Chart {
    /// A 900×560 chart with automatic y range.
    pub fn new(title: impl Into<String>, x_label: impl Into<String>, y_label: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            y_range: None,
            width: 900,
            height: 560,
        }
    }
}

impl Default for Chart {
    /// An untitled 900×560 chart with automatic y range.
    fn default() -> Self {
        Self::new("", "", "")
    }
}

/// Mean and standard error (s.d. / √n, with the n − 1 s.d.; 0 for one value; NaN for none): the
/// "mean ± s.e. over seeds" of every report's tables and bands.
pub fn mean_se(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, 0.0);
    }
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

/// A distinct colour for the `i`-th series (10 colours, then repeats): 0 blue (Equi), 1 orange
/// (CNN), 2 green, 3 red, 4 purple, 5 brown, 6 pink, 7 grey, 8 olive, 9 cyan.
pub fn palette(i: usize) -> [u8; 3] {
    const COLORS: [[u8; 3]; 10] = [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [127, 127, 127],
        [188, 189, 34],
        [23, 190, 207],
    ];
    COLORS[i % COLORS.len()]
}

/// Tick positions chosen by [`nice_ticks`].
#[derive(Clone, Debug, PartialEq)]
pub struct Ticks {
    /// Distance between ticks: 1, 2 or 5 × 10^k.
    pub step: f64,
    /// Tick values in increasing order; the first is ≤ the range's minimum and the last ≥ its
    /// maximum.
    pub values: Vec<f64>,
}

/// Ticks at multiples of a 1/2/5 × 10^k step covering `[min, max]` with about `target` intervals
/// (at least 1). The bounds may come in either order. A degenerate range (`min == max`) is widened
/// to a unit-sized one around the value; non-finite bounds give the ticks of `[0, 1]`.
pub fn nice_ticks(min: f64, max: f64, target: usize) -> Ticks {
    let (mut lo, mut hi) = if min <= max { (min, max) } else { (max, min) };
    if !lo.is_finite() || !hi.is_finite() {
        lo = 0.0;
        hi = 1.0;
    }
    let scale = lo.abs().max(hi.abs());
    if hi - lo <= scale * 1e-12 {
        let half = if scale > 0.0 { scale * 0.1 } else { 0.5 };
        lo -= half;
        hi += half;
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let mut exp = raw.log10().floor() as i32;
    let norm = raw / 10f64.powi(exp);
    let mantissa = if norm <= 1.0 {
        1.0
    } else if norm <= 2.0 {
        2.0
    } else if norm <= 5.0 {
        5.0
    } else {
        exp += 1;
        1.0
    };
    // k × step, computed as k·mantissa / 10^-exp for negative exponents so that e.g. 3 × 0.2 is the
    // double nearest 0.6 rather than 0.6000000000000001.
    let at = |k: i64| {
        if exp < 0 { k as f64 * mantissa / 10f64.powi(-exp) } else { k as f64 * mantissa * 10f64.powi(exp) }
    };
    let step = at(1);
    // Small tolerance so that a bound sitting on a tick (up to rounding) does not add a tick.
    let eps = 1e-9;
    let first = (lo / step + eps).floor() as i64;
    let last = (hi / step - eps).ceil() as i64;
    let values = (first..=last)
        .map(|k| {
            let v = at(k);
            if v.abs() < step * 1e-9 { 0.0 } else { v }
        })
        .collect();
    Ticks { step, values }
}

/// Tick label with as many decimals as the step needs (scientific notation for very large or very
/// small steps).
fn format_tick(v: f64, step: f64) -> String {
    if !(1e-4..1e7).contains(&step) {
        return format!("{v:e}");
    }
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}

// ---------------------------------------------------------------------------------------------
// Styling.

const FONT: &str = "sans-serif";
const TITLE_SIZE: f64 = 20.0;
const LABEL_SIZE: f64 = 15.0;
const TICK_SIZE: f64 = 13.0;
const AXIS: RGBColor = RGBColor(60, 60, 60);
const GRID: RGBColor = RGBColor(225, 225, 225);
const LEGEND_BORDER: RGBColor = RGBColor(180, 180, 180);
const BAND_ALPHA: f64 = 0.2;
const LINE_WIDTH: u32 = 2;
const MARKER_RADIUS: i32 = 3;
/// Legend: swatch length, gaps and the longest label kept (in characters).
const SWATCH_W: i32 = 22;
const LEGEND_PAD: i32 = 8;
const LEGEND_MAX_CHARS: usize = 40;

/// Registers DejaVu Sans (from the `dejavu` crate) as plotters' `sans-serif` font, once per process
/// (for charts drawn with plotters directly, like the rotation-estimation report's log-scale ones).
pub fn ensure_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok());
    if ok { Ok(()) } else { Err(PlotError::Draw("the embedded DejaVu Sans font could not be loaded".into())) }
}

fn rgb(c: [u8; 3]) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

fn draw_err(e: impl std::fmt::Display) -> PlotError {
    PlotError::Draw(e.to_string())
}

// ---------------------------------------------------------------------------------------------
// Layout: axis ranges and ticks, in data space.

fn finite_point(p: &(f64, f64)) -> bool {
    p.0.is_finite() && p.1.is_finite()
}

fn validate(chart: &Chart, series: &[Series]) -> Result<(), PlotError> {
    let ok = |v: u32| (64..=16384).contains(&v);
    if !ok(chart.width) || !ok(chart.height) {
        return Err(PlotError::BadSize { width: chart.width, height: chart.height });
    }
    if let Some((min, max)) = chart.y_range
        && !(min.is_finite() && max.is_finite() && min < max)
    {
        return Err(PlotError::BadYRange { min, max });
    }
    for s in series {
        if let Some(band) = &s.band
            && band.len() != s.points.len()
        {
            return Err(PlotError::BandLength { label: s.label.clone(), points: s.points.len(), band: band.len() });
        }
    }
    Ok(())
}

/// Data extent: x over finite points, y over finite points widened by finite bands.
fn extent(series: &[Series]) -> Option<((f64, f64), (f64, f64))> {
    let mut ext: Option<((f64, f64), (f64, f64))> = None;
    for s in series {
        for (i, p) in s.points.iter().enumerate() {
            if !finite_point(p) {
                continue;
            }
            let half = s.band.as_ref().map(|b| b[i]).filter(|h| h.is_finite()).map_or(0.0, f64::abs);
            let (ylo, yhi) = (p.1 - half, p.1 + half);
            ext = Some(match ext {
                None => ((p.0, p.0), (ylo, yhi)),
                Some(((x0, x1), (y0, y1))) => ((x0.min(p.0), x1.max(p.0)), (y0.min(ylo), y1.max(yhi))),
            });
        }
    }
    ext
}

fn widen_degenerate(r: (f64, f64)) -> (f64, f64) {
    let scale = r.0.abs().max(r.1.abs());
    if r.1 - r.0 > scale * 1e-12 {
        r
    } else if scale > 0.0 {
        (r.0 - scale * 0.1, r.1 + scale * 0.1)
    } else {
        (r.0 - 0.5, r.1 + 0.5)
    }
}

/// The axes of a chart: data ranges and the ticks shown inside them.
#[derive(Clone, Debug, PartialEq)]
struct Axes {
    x_range: (f64, f64),
    y_range: (f64, f64),
    x_ticks: Ticks,
    y_ticks: Ticks,
}

fn axes(chart: &Chart, series: &[Series]) -> Axes {
    let ext = extent(series);
    let x_range = widen_degenerate(ext.map_or((0.0, 1.0), |e| e.0));
    let x_ticks = nice_ticks(x_range.0, x_range.1, 8);
    let (y_range, y_ticks) = match chart.y_range {
        Some(r) => (r, nice_ticks(r.0, r.1, 6)),
        None => {
            let r = widen_degenerate(ext.map_or((0.0, 1.0), |e| e.1));
            let t = nice_ticks(r.0, r.1, 6);
            let r = (t.values[0], t.values[t.values.len() - 1]);
            (r, t)
        }
    };
    Axes { x_range, y_range, x_ticks, y_ticks }
}

/// A linear plotters axis whose ticks (grid lines and labels) are ours: [`nice_ticks`] inside the
/// range, labelled by `format_tick` with the ticks' step.
#[derive(Clone)]
struct TickedAxis {
    linear: RangedCoordf64,
    ticks: Vec<f64>,
    step: f64,
}

impl TickedAxis {
    fn new(range: (f64, f64), ticks: &Ticks) -> Self {
        Self { linear: (range.0..range.1).into(), ticks: ticks_inside(ticks, range), step: ticks.step }
    }
}

impl Ranged for TickedAxis {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.linear.map(value, limit)
    }

    /// Our ticks as plotters' bold key points; no light (minor) grid lines.
    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() { Vec::new() } else { self.ticks.clone() }
    }

    fn range(&self) -> Range<f64> {
        self.linear.range()
    }
}

impl ValueFormatter<f64> for TickedAxis {
    fn format_ext(&self, value: &f64) -> String {
        format_tick(*value, self.step)
    }
}

/// Tick values that lie in `range` (up to rounding).
fn ticks_inside(t: &Ticks, range: (f64, f64)) -> Vec<f64> {
    let tol = (range.1 - range.0) * 1e-9;
    t.values.iter().copied().filter(|&v| v >= range.0 - tol && v <= range.1 + tol).collect()
}

// ---------------------------------------------------------------------------------------------
// Clipping to the y range, in data space (plotters clamps coordinates to the plot instead, which
// would flatten out-of-range data onto the border).

/// Parameter interval `[t0, t1]` ⊆ `[0, 1]` of the segment `a → b` whose y lies in `[lo, hi]`.
fn clip_segment(a: (f64, f64), b: (f64, f64), lo: f64, hi: f64) -> Option<(f64, f64)> {
    let dy = b.1 - a.1;
    if dy == 0.0 {
        return (a.1 >= lo && a.1 <= hi).then_some((0.0, 1.0));
    }
    let (ta, tb) = ((lo - a.1) / dy, (hi - a.1) / dy);
    let (t0, t1) = (ta.min(tb).max(0.0), ta.max(tb).min(1.0));
    (t0 <= t1).then_some((t0, t1))
}

fn lerp(a: (f64, f64), b: (f64, f64), t: f64) -> (f64, f64) {
    (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1))
}

/// The parts of a polyline inside `lo ≤ y ≤ hi`, as polylines; non-finite points break it.
fn clip_polyline(points: &[(f64, f64)], lo: f64, hi: f64) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut open = false;
    for pair in points.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let clipped = if finite_point(&a) && finite_point(&b) { clip_segment(a, b, lo, hi) } else { None };
        let Some((t0, t1)) = clipped else {
            open = false;
            continue;
        };
        let (p, q) = (lerp(a, b, t0), lerp(a, b, t1));
        if open && t0 == 0.0 {
            if let Some(run) = out.last_mut() {
                run.push(q);
            }
        } else {
            out.push(vec![p, q]);
        }
        open = t1 == 1.0;
    }
    out
}

/// `min(max(y, lo), hi)` along a polyline, with the points where it crosses `lo` or `hi` added so
/// that the clamped curve is exact between the samples.
fn clamp_polyline(points: &[(f64, f64)], lo: f64, hi: f64) -> Vec<(f64, f64)> {
    let clamp = |p: (f64, f64)| (p.0, p.1.clamp(lo, hi));
    let mut out = Vec::with_capacity(points.len());
    for (i, &p) in points.iter().enumerate() {
        if i > 0 {
            let a = points[i - 1];
            let dy = p.1 - a.1;
            let mut cross: Vec<f64> = [lo, hi]
                .iter()
                .filter(|&&level| (a.1 - level) * (p.1 - level) < 0.0)
                .map(|&level| (level - a.1) / dy)
                .collect();
            cross.sort_by(f64::total_cmp);
            out.extend(cross.into_iter().map(|t| clamp(lerp(a, p, t))));
        }
        out.push(clamp(p));
    }
    out
}

/// The band of `s` as polygons (upper edge forward, lower edge back), one per run of consecutive
/// points with finite coordinates and half-widths, clipped to `lo ≤ y ≤ hi`.
fn band_polygons(s: &Series, band: &[f64], lo: f64, hi: f64) -> Vec<Vec<(f64, f64)>> {
    let mut polys = Vec::new();
    let mut run: Vec<((f64, f64), f64)> = Vec::new();
    let flush = |run: &mut Vec<((f64, f64), f64)>, polys: &mut Vec<Vec<(f64, f64)>>| {
        if run.len() >= 2 {
            let upper: Vec<_> = run.iter().map(|&(p, h)| (p.0, p.1 + h)).collect();
            let lower: Vec<_> = run.iter().map(|&(p, h)| (p.0, p.1 - h)).collect();
            let mut poly = clamp_polyline(&upper, lo, hi);
            poly.extend(clamp_polyline(&lower, lo, hi).into_iter().rev());
            polys.push(poly);
        }
        run.clear();
    };
    for (p, &h) in s.points.iter().zip(band) {
        if finite_point(p) && h.is_finite() {
            run.push((*p, h.abs()));
        } else {
            flush(&mut run, &mut polys);
        }
    }
    flush(&mut run, &mut polys);
    polys
}

// ---------------------------------------------------------------------------------------------
// Drawing.

/// Where the plot landed on the canvas: its pixel rectangle and the data ranges it shows (what the
/// tests check the pixels against).
#[derive(Clone, Debug)]
#[cfg_attr(not(test), allow(dead_code))]
struct PlotArea {
    x_px: Range<i32>,
    y_px: Range<i32>,
    axes: Axes,
}

fn legend_label(s: &Series) -> String {
    s.label.chars().take(LEGEND_MAX_CHARS).collect()
}

/// Draws the chart into `buf` (RGB, `chart.width × chart.height`).
fn draw(chart: &Chart, series: &[Series], buf: &mut [u8]) -> Result<PlotArea, PlotError> {
    let axes = axes(chart, series);
    let (w, h) = (chart.width, chart.height);
    let root = BitMapBackend::with_buffer(buf, (w, h)).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;

    let tick_font = (FONT, TICK_SIZE).into_font().color(&BLACK);
    let label_font = (FONT, LABEL_SIZE).into_font().color(&BLACK);
    let text_w = |text: &str, font: &TextStyle| root.estimate_text_size(text, font).map(|(tw, _)| tw as i32);

    // Margins sized from the text they hold, never more than a third of the canvas.
    let mut y_tick_w = 0;
    for v in ticks_inside(&axes.y_ticks, axes.y_range) {
        y_tick_w = y_tick_w.max(text_w(&format_tick(v, axes.y_ticks.step), &tick_font).map_err(draw_err)?);
    }
    let mut legend_w = 0;
    for s in series {
        legend_w = legend_w.max(text_w(&legend_label(s), &label_font).map_err(draw_err)?);
    }
    if !series.is_empty() {
        legend_w += 3 * LEGEND_PAD + SWATCH_W;
    }
    let third_w = w as i32 / 3;
    let third_h = h as i32 / 3;
    let y_area = (y_tick_w + 12 + if chart.y_label.is_empty() { 0 } else { LABEL_SIZE as i32 + 10 }).min(third_w);
    let x_area =
        (TICK_SIZE as i32 + 14 + if chart.x_label.is_empty() { 0 } else { LABEL_SIZE as i32 + 10 }).min(third_h);
    let right = (legend_w + 2 * LEGEND_PAD).max(24).min(third_w);

    let mut builder = ChartBuilder::on(&root);
    builder.margin(12).margin_right(right).x_label_area_size(x_area).y_label_area_size(y_area);
    if !chart.title.is_empty() {
        builder.caption(&chart.title, (FONT, TITLE_SIZE).into_font().color(&BLACK));
    }
    let x_axis = TickedAxis::new(axes.x_range, &axes.x_ticks);
    let y_axis = TickedAxis::new(axes.y_range, &axes.y_ticks);
    let mut ctx = builder.build_cartesian_2d(x_axis, y_axis).map_err(draw_err)?;

    let mut mesh = ctx.configure_mesh();
    mesh.bold_line_style(GRID)
        .light_line_style(TRANSPARENT)
        .axis_style(AXIS)
        .label_style(tick_font.clone())
        .axis_desc_style(label_font.clone());
    if !chart.x_label.is_empty() {
        mesh.x_desc(chart.x_label.as_str());
    }
    if !chart.y_label.is_empty() {
        mesh.y_desc(chart.y_label.as_str());
    }
    mesh.draw().map_err(draw_err)?;

    // Data: bands first, then lines, then markers, so that lines stay on top of every band.
    let (lo, hi) = axes.y_range;
    for s in series {
        if let Some(band) = &s.band {
            let fill = rgb(s.color).mix(BAND_ALPHA).filled();
            ctx.draw_series(band_polygons(s, band, lo, hi).into_iter().map(|poly| Polygon::new(poly, fill)))
                .map_err(draw_err)?;
        }
    }
    for s in series {
        let style = rgb(s.color).stroke_width(LINE_WIDTH);
        ctx.draw_series(clip_polyline(&s.points, lo, hi).into_iter().map(|run| PathElement::new(run, style)))
            .map_err(draw_err)?;
    }
    for s in series {
        let fill = rgb(s.color).filled();
        let inside = |p: &&(f64, f64)| finite_point(p) && p.1 >= lo && p.1 <= hi;
        ctx.draw_series(s.points.iter().filter(inside).map(|&p| Circle::new(p, MARKER_RADIUS, fill)))
            .map_err(draw_err)?;
    }

    // Axes box on top of the data.
    let (x_px, y_px) = ctx.plotting_area().get_pixel_range();
    root.draw(&Rectangle::new([(x_px.start, y_px.start), (x_px.end - 1, y_px.end - 1)], AXIS.stroke_width(1)))
        .map_err(draw_err)?;

    // Legend, right of the plot: a swatch (line and marker) and the label per series.
    if !series.is_empty() {
        let row_h = LABEL_SIZE as i32 + 9;
        let x0 = x_px.end + 12;
        let y0 = y_px.start;
        let box_h = LEGEND_PAD + row_h * series.len() as i32;
        root.draw(&Rectangle::new([(x0, y0), (x0 + legend_w, y0 + box_h)], LEGEND_BORDER.stroke_width(1)))
            .map_err(draw_err)?;
        for (i, s) in series.iter().enumerate() {
            let cy = y0 + LEGEND_PAD / 2 + row_h * i as i32 + row_h / 2;
            let sx = x0 + LEGEND_PAD;
            let color = rgb(s.color);
            root.draw(&PathElement::new(vec![(sx, cy), (sx + SWATCH_W, cy)], color.stroke_width(LINE_WIDTH)))
                .map_err(draw_err)?;
            root.draw(&Circle::new((sx + SWATCH_W / 2, cy), MARKER_RADIUS, color.filled())).map_err(draw_err)?;
            let style = label_font.pos(plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Left,
                plotters::style::text_anchor::VPos::Center,
            ));
            root.draw(&Text::new(legend_label(s), (sx + SWATCH_W + LEGEND_PAD, cy), style)).map_err(draw_err)?;
        }
    }
    root.present().map_err(draw_err)?;
    Ok(PlotArea { x_px, y_px, axes })
}

/// Draws the chart into an RGB image (what [`write_png`] encodes).
pub fn render(chart: &Chart, series: &[Series]) -> Result<RgbImage, PlotError> {
    validate(chart, series)?;
    ensure_font()?;
    let mut buf = vec![0u8; chart.width as usize * chart.height as usize * 3];
    draw(chart, series, &mut buf)?;
    RgbImage::from_raw(chart.width, chart.height, buf)
        .ok_or_else(|| PlotError::Draw("the drawing buffer does not match the chart size".into()))
}

/// Draws the chart and writes it as a PNG file at `path`, replacing it whole or not at all
/// ([`equiarm_types::files::replace`]). The file's directory must already exist.
pub fn write_png(path: &Path, chart: &Chart, series: &[Series]) -> Result<(), PlotError> {
    if let Some(dir) = path.parent()
        && !dir.as_os_str().is_empty()
        && !dir.is_dir()
    {
        return Err(PlotError::MissingDirectory { path: path.to_path_buf(), dir: dir.to_path_buf() });
    }
    let img = render(chart, series)?;
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, ImageFormat::Png).map_err(|cause| PlotError::Encode { path: path.to_path_buf(), cause })?;
    Ok(equiarm_types::files::replace(path, png.into_inner())?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_standard_error() {
        assert_eq!(mean_se(&[0.5]), (0.5, 0.0));
        let (m, se) = mean_se(&[0.8, 0.9, 1.0, 0.9]);
        assert!((m - 0.9).abs() < 1e-12 && (se - (0.02f64 / 3.0 / 4.0).sqrt()).abs() < 1e-12, "{m} {se}");
        let (m, se) = mean_se(&[0.2, 0.4, 0.6, 0.8]);
        // s.d. = sqrt(0.2/3), s.e. = s.d. / 2
        assert!((m - 0.5).abs() < 1e-12 && (se - (0.2f64 / 3.0).sqrt() / 2.0).abs() < 1e-12, "{m} {se}");
        assert!(mean_se(&[]).0.is_nan() && mean_se(&[]).1.is_nan());
    }

    /// Renders like [`render`], also returning where the plot landed.
    fn render_framed(chart: &Chart, series: &[Series]) -> (RgbImage, PlotArea) {
        validate(chart, series).unwrap();
        ensure_font().unwrap();
        let mut buf = vec![0u8; chart.width as usize * chart.height as usize * 3];
        let frame = draw(chart, series, &mut buf).unwrap();
        (RgbImage::from_raw(chart.width, chart.height, buf).unwrap(), frame)
    }

    /// Pixel of data point `(x, y)` (plotters maps the range ends to the plot's first and last
    /// pixel; ±1 px of rounding).
    fn px(f: &PlotArea, x: f64, y: f64) -> (u32, u32) {
        let (xr, yr) = (f.axes.x_range, f.axes.y_range);
        let fx = (x - xr.0) / (xr.1 - xr.0);
        let fy = (y - yr.0) / (yr.1 - yr.0);
        let col = f.x_px.start as f64 + fx * (f.x_px.end - f.x_px.start) as f64;
        let row = f.y_px.end as f64 - fy * (f.y_px.end - f.y_px.start) as f64;
        (col.round() as u32, row.round() as u32)
    }

    fn check_ticks(min: f64, max: f64) {
        let t = nice_ticks(min, max, 6);
        let mantissa = t.step / 10f64.powf(t.step.log10().floor());
        assert!([1.0, 2.0, 5.0].iter().any(|m| (mantissa - m).abs() < 1e-9), "step {} for {min}..{max}", t.step);
        assert!(t.values.len() >= 2 && t.values.len() <= 13, "{t:?}");
        assert!(t.values[0] <= min + 1e-12 && *t.values.last().unwrap() >= max - 1e-12, "{t:?}");
        for w in t.values.windows(2) {
            assert!((w[1] - w[0] - t.step).abs() < t.step * 1e-9, "{t:?}");
        }
    }

    #[test]
    fn ticks_are_1_2_5_steps_covering_the_range() {
        check_ticks(0.0, 1.0);
        check_ticks(0.0, 5000.0);
        check_ticks(-3.2, 7.9);
        check_ticks(0.001, 0.0042);
        check_ticks(-1e6, -2.0);
        assert_eq!(nice_ticks(0.0, 1.0, 5).values, vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
        assert_eq!(nice_ticks(0.0, 5000.0, 5).step, 1000.0);
        let t = nice_ticks(-3.2, 7.9, 6);
        assert_eq!(t.step, 2.0);
        assert_eq!(t.values, vec![-4.0, -2.0, 0.0, 2.0, 4.0, 6.0, 8.0]);
    }

    #[test]
    fn degenerate_and_bad_tick_ranges_still_give_ticks() {
        for v in [0.0, 3.0, -250.0] {
            let t = nice_ticks(v, v, 6);
            assert!(t.values.len() >= 2, "{t:?}");
            assert!(t.values[0] < v && *t.values.last().unwrap() > v, "{t:?}");
        }
        assert_eq!(nice_ticks(1.0, 0.0, 5), nice_ticks(0.0, 1.0, 5));
        assert!(nice_ticks(f64::NAN, 1.0, 5).values.len() >= 2);
        assert!(nice_ticks(0.0, 1.0, 0).values.len() >= 2);
    }

    #[test]
    fn tick_labels_use_the_steps_decimals() {
        assert_eq!(format_tick(0.4, 0.2), "0.4");
        assert_eq!(format_tick(5000.0, 1000.0), "5000");
        assert_eq!(format_tick(-0.05, 0.05), "-0.05");
    }

    #[test]
    fn axes_span_the_data_and_widen_y_to_ticks() {
        let s = Series {
            band: Some(vec![0.05, 0.1, 0.0]),
            ..Series::new("s", palette(0), vec![(100.0, 0.12), (2100.0, 0.5), (4923.0, 0.81)])
        };
        let a = axes(&Chart::default(), std::slice::from_ref(&s));
        assert_eq!(a.x_range, (100.0, 4923.0));
        assert_eq!(ticks_inside(&a.x_ticks, a.x_range), vec![1000.0, 2000.0, 3000.0, 4000.0]);
        // y: 0.07 (0.12 - band) .. 0.81, widened to the enclosing ticks (step 0.2).
        assert_eq!((a.y_range, a.y_ticks.step), ((0.0, 1.0), 0.2));
        let fixed = Chart { y_range: Some((0.0, 1.0)), ..Chart::default() };
        assert_eq!(axes(&fixed, &[s]).y_range, (0.0, 1.0));
    }

    #[test]
    fn clipping_keeps_the_inside_and_splits_at_the_border() {
        // A line from below the range to above it keeps only its inside part.
        let runs = clip_polyline(&[(0.0, -1.0), (1.0, 1.0), (2.0, 3.0)], 0.0, 2.0);
        assert_eq!(runs, vec![vec![(0.5, 0.0), (1.0, 1.0), (1.5, 2.0)]]);
        // Leaving and re-entering gives two runs; NaN breaks a run too.
        let runs =
            clip_polyline(&[(0.0, 0.5), (1.0, 1.5), (2.0, 0.5), (3.0, f64::NAN), (4.0, 0.5), (5.0, 0.5)], 0.0, 1.0);
        assert_eq!(
            runs,
            vec![vec![(0.0, 0.5), (0.5, 1.0)], vec![(1.5, 1.0), (2.0, 0.5)], vec![(4.0, 0.5), (5.0, 0.5)]]
        );
        // Clamping adds the crossing points.
        let c = clamp_polyline(&[(0.0, 0.5), (1.0, 1.5), (2.0, -0.5)], 0.0, 1.0);
        assert_eq!(c, vec![(0.0, 0.5), (0.5, 1.0), (1.0, 1.0), (1.25, 1.0), (1.75, 0.0), (2.0, 0.0)]);
    }

    #[test]
    fn png_decodes_at_the_requested_size() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let path = dir.join("curve.png");
        let chart =
            Chart { width: 640, height: 400, ..Chart::new("Block Picking", "environment steps", "success rate") };
        let s = Series::new("Equi SACfD", palette(0), vec![(0.0, 0.1), (1000.0, 0.5), (2000.0, 0.9)]);
        write_png(&path, &chart, &[s]).unwrap();
        let img = image::open(&path).unwrap();
        assert_eq!((img.width(), img.height()), (640, 400));
        // The smallest allowed size still draws.
        let tiny = Chart { width: 64, height: 64, ..Chart::new("t", "x", "y") };
        let img = render(&tiny, &[Series::new("s", palette(1), vec![(0.0, 0.0), (1.0, 1.0)])]).unwrap();
        assert_eq!((img.width(), img.height()), (64, 64));
    }

    #[test]
    fn data_point_lands_where_it_should() {
        let chart = Chart { y_range: Some((0.0, 1.0)), ..Chart::new("t", "x", "y") };
        let color = [200, 30, 40];
        let s = Series::new("s", color, vec![(0.0, 0.0), (5.0, 0.5), (10.0, 1.0)]);
        let (img, frame) = render_framed(&chart, std::slice::from_ref(&s));
        assert_eq!(frame.axes.x_range, (0.0, 10.0));
        let (px, py) = px(&frame, 5.0, 0.5);
        // The middle of the data is the middle of the plot.
        assert!((px as i32 - (frame.x_px.start + frame.x_px.end) / 2).abs() <= 1);
        assert!((py as i32 - (frame.y_px.start + frame.y_px.end) / 2).abs() <= 1);
        let found = (-2..=2).any(|dy: i32| {
            (-2..=2).any(|dx: i32| img.get_pixel(px.wrapping_add_signed(dx), py.wrapping_add_signed(dy)).0 == color)
        });
        assert!(found, "series colour not near ({px}, {py})");
        // Nothing of the series outside the plot, e.g. in the top-left corner.
        for y in 0..frame.y_px.start.min(20) as u32 {
            for x in 0..frame.x_px.start.min(20) as u32 {
                assert_ne!(img.get_pixel(x, y).0, color, "colour leaked to ({x}, {y})");
            }
        }
    }

    #[test]
    fn band_is_filled_between_the_curves_and_only_there() {
        let chart = Chart { y_range: Some((0.0, 1.0)), ..Chart::new("band", "x", "y") };
        let color = palette(0);
        let s = Series {
            band: Some(vec![0.2; 3]),
            ..Series::new("mean", color, vec![(0.0, 0.5), (5.0, 0.5), (10.0, 0.5)])
        };
        let (img, frame) = render_framed(&chart, &[s]);
        // Translucent band colour over white: 0.2 × colour + 0.8 × 255 per channel (±2 of rounding).
        let tint: [u8; 3] = color.map(|c| (c as f64 * BAND_ALPHA + 255.0 * (1.0 - BAND_ALPHA)).round() as u8);
        let near = |a: [u8; 3], b: [u8; 3]| a.iter().zip(b).all(|(&x, y)| (x as i32 - y as i32).abs() <= 2);
        // (Away from the grid lines at x = 0, 2, 4 … and y = 0, 0.2, 0.4 …, which the band tints too.)
        for x in [2.9, 7.1] {
            for y in [0.33, 0.45, 0.55, 0.67] {
                let (c, r) = px(&frame, x, y);
                assert!(
                    near(img.get_pixel(c, r).0, tint),
                    "({x}, {y}) at ({c}, {r}): {:?}, want {tint:?}",
                    img.get_pixel(c, r).0
                );
            }
            // Outside the band (0.3..0.7): no tint (white, or the grey grid).
            for y in [0.1, 0.25, 0.75, 0.9] {
                let (c, r) = px(&frame, x, y);
                let p = img.get_pixel(c, r).0;
                assert!(p[0] == p[1] && p[1] == p[2], "({x}, {y}) at ({c}, {r}) is tinted: {p:?}");
            }
            // The mean line itself is drawn on top in the full colour.
            let (c, r) = px(&frame, x, 0.5);
            let on_line = (-1..=1).any(|d: i32| img.get_pixel(c, r.wrapping_add_signed(d)).0 == color);
            assert!(on_line, "mean line not at ({c}, {r})");
        }
    }

    #[test]
    fn a_band_past_a_fixed_range_is_clipped_at_the_border() {
        let chart = Chart { y_range: Some((0.0, 1.0)), ..Chart::default() };
        let s = Series { band: Some(vec![0.5; 2]), ..Series::new("s", palette(2), vec![(0.0, 0.75), (1.0, 0.75)]) };
        let polys = band_polygons(&s, s.band.as_ref().unwrap(), 0.0, 1.0);
        assert_eq!(polys, vec![vec![(0.0, 1.0), (1.0, 1.0), (1.0, 0.25), (0.0, 0.25)]]);
        let (img, frame) = render_framed(&chart, &[s]);
        // Above the plot (between the title area and the plot's top edge) nothing is tinted.
        let (c, _) = px(&frame, 0.5, 1.0);
        for r in (frame.y_px.start - 6).max(0)..frame.y_px.start {
            let p = img.get_pixel(c, r as u32).0;
            assert!(p[0] == p[1] && p[1] == p[2], "band leaked above the plot at ({c}, {r}): {p:?}");
        }
    }

    #[test]
    fn text_is_drawn_for_title_labels_and_legend() {
        let chart = Chart::new("A title", "updates", "success");
        let s = Series::new("Equi SAC (4 seeds)", palette(0), vec![(0.0, 0.0), (1.0, 1.0)]);
        let (img, frame) = render_framed(&chart, &[s]);
        let dark = |img: &RgbImage, xs: Range<u32>, ys: Range<u32>| {
            ys.flat_map(|y| xs.clone().map(move |x| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&v| v < 100))
                .count()
        };
        let (w, h) = (img.width(), img.height());
        let (x0, x1, y0, y1) =
            (frame.x_px.start as u32, frame.x_px.end as u32, frame.y_px.start as u32, frame.y_px.end as u32);
        // Regions that hold only one piece of text each (clear of the tick labels), and the dark
        // (ink) pixels each must have: some, but far from a filled block.
        let regions = [
            ("title", 0..w, 0..y0 - 8),
            ("legend", x1 + 12..w, y0..y0 + 30),
            ("x label", x0..x1, y1 + 26..h),
            ("y label", 0..12 + LABEL_SIZE as u32 + 4, y0..y1),
        ];
        for (what, xs, ys) in regions {
            let area = xs.len() * ys.len();
            let ink = dark(&img, xs, ys);
            assert!(ink > 20 && ink < area / 4, "{what}: {ink} dark pixels of {area}");
        }
    }

    #[test]
    fn nan_points_and_empty_series_are_skipped() {
        let s = Series {
            band: Some(vec![0.1, f64::NAN, 0.1, 0.2]),
            ..Series::new("with gaps", palette(1), vec![(0.0, 0.2), (1.0, f64::NAN), (f64::NAN, 0.3), (3.0, 0.6)])
        };
        let empty = Series::new("empty", palette(2), vec![]);
        let all_nan = Series::new("nan", palette(3), vec![(f64::NAN, f64::NAN)]);
        let img = render(&Chart::default(), &[s, empty, all_nan]).unwrap();
        assert_eq!((img.width(), img.height()), (900, 560));
        render(&Chart::default(), &[]).unwrap();
    }

    #[test]
    fn bad_input_is_an_error_naming_it() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let path = dir.join("no_such_dir").join("c.png");
        let err = write_png(&path, &Chart::default(), &[]).unwrap_err();
        assert!(matches!(err, PlotError::MissingDirectory { .. }));
        assert!(err.to_string().contains("no_such_dir"), "{err}");
        let s = Series { band: Some(vec![0.1]), ..Series::new("short band", palette(0), vec![(0.0, 0.0), (1.0, 1.0)]) };
        let err = render(&Chart::default(), &[s]).unwrap_err();
        assert!(err.to_string().contains("short band"), "{err}");
        let chart = Chart { y_range: Some((1.0, 1.0)), ..Chart::default() };
        assert!(matches!(render(&chart, &[]), Err(PlotError::BadYRange { .. })));
        let chart = Chart { width: 0, ..Chart::default() };
        assert!(matches!(render(&chart, &[]), Err(PlotError::BadSize { .. })));
    }
}
