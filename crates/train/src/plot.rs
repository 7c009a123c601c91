//! Charts drawn with [`plotters`], the one chart module of every figure equiarm writes (learning
//! curves, the experiment reports, the rotation experiment's accuracy against training pairs): a
//! white canvas, axes with "nice" ticks (1, 2 or 5 × 10^k, [`nice_ticks`]) or ticks the chart
//! names, a light grid, one polyline with point markers per [`Series`], an optional ± band per
//! series drawn as a translucent fill or as error bars, an optional dashed reference line, a legend
//! (right of the plot, inside it, or none), a title and axis labels; a linear or logarithmic x axis
//! ([`Scale`]); and a grid of such charts under one title ([`render_panels`]).
//!
//! plotters' bitmap backend draws into an RGB buffer that the `image` crate encodes as PNG. Text is
//! rasterised by plotters' `ab_glyph` font support with DejaVu Sans embedded from the `dejavu` crate
//! (Bitstream Vera / DejaVu font licence), so no system font, fontconfig or freetype is needed.
//!
//! Limitations: the y axis is linear; the x axis spans exactly the finite data unless
//! [`Chart::x_range`] fixes it (the y axis is widened to the enclosing ticks unless
//! [`Chart::y_range`] fixes it, and data outside a fixed y range is clipped at the plot's edge);
//! labels that do not fit are clipped at the image border rather than wrapped, and legend labels
//! are cut at 40 characters; points with a non-finite coordinate are skipped and break the polyline
//! (and band) there, like matplotlib; bands expect the points of a series in increasing x order.

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
    /// `Chart::x_range` is not finite and increasing, or a log-scale x axis would show x ≤ 0.
    #[error("chart x axis: {0}")]
    BadXAxis(String),
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
    /// between `y - band` and `y + band` (or as error bars, [`Series::bars`]); non-finite values
    /// leave a gap.
    pub band: Option<Vec<f64>>,
    /// Draw the band as a vertical error bar at each point instead of a fill (for points far apart,
    /// like a few training-set sizes).
    pub bars: bool,
}

impl Series {
    /// A series without a band.
    pub fn new(label: impl Into<String>, color: [u8; 3], points: Vec<(f64, f64)>) -> Self {
        Self { label: label.into(), color, points, band: None, bars: false }
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
    /// The x axis's scale.
    pub x_scale: Scale,
    /// Fixed x axis range; `None` spans the data.
    pub x_range: Option<(f64, f64)>,
    /// The x ticks to show (e.g. the training-set sizes that were run); `None` chooses them.
    pub x_ticks: Option<Vec<f64>>,
    /// A dashed black horizontal line at `y`, with its legend label (e.g. a bound).
    pub reference: Option<(String, f64)>,
    /// Where the legend goes.
    pub legend: Legend,
    /// Text size relative to the default (below 1 for the small panels of [`render_panels`]).
    pub text_scale: f64,
}

/// The x axis's scale.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Scale {
    /// Linear.
    #[default]
    Linear,
    /// Logarithmic: equal ratios are equal distances (x must be positive).
    Log,
}

/// Where a chart's legend goes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Legend {
    /// Right of the plot (the plot is narrowed to make room).
    #[default]
    Right,
    /// Inside the plot, in its lower-right corner.
    LowerRight,
    /// No legend.
    Hidden,
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
            x_scale: Scale::Linear,
            x_range: None,
            x_ticks: None,
            reference: None,
            legend: Legend::Right,
            text_scale: 1.0,
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

/// Registers DejaVu Sans (from the `dejavu` crate) as plotters' `sans-serif` font, once per process.
fn ensure_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok());
    if ok { Ok(()) } else { Err(PlotError::Draw("the embedded DejaVu Sans font could not be loaded".into())) }
}

/// Writes `text` in white on black, `size` px high, into the `width` × `height` rgb8 image `buf` (a
/// caption strip), left-aligned with a small margin.
pub fn caption(buf: &mut [u8], width: u32, height: u32, text: &str, size: u32) -> Result<(), PlotError> {
    ensure_font()?;
    let root = BitMapBackend::with_buffer(buf, (width, height)).into_drawing_area();
    root.fill(&BLACK).map_err(draw_err)?;
    let margin = (size / 3).max(1) as i32;
    root.draw_text(text, &(FONT, size).into_font().color(&WHITE), (margin, (height as i32 - size as i32) / 2))
        .map_err(draw_err)?;
    root.present().map_err(draw_err)
}

/// The viridis colour of `t` in [0, 1] (clamped), as rgb8: a perceptually even map for depth images.
pub fn viridis(t: f64) -> [u8; 3] {
    use plotters::style::colors::colormaps::{ColorMap, ViridisRGB};
    let c: RGBColor = ViridisRGB.get_color(t.clamp(0.0, 1.0) as f32);
    [c.0, c.1, c.2]
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
    if let Some((min, max)) = chart.x_range
        && !(min.is_finite() && max.is_finite() && min < max)
    {
        return Err(PlotError::BadXAxis(format!("x_range ({min}, {max}) must be finite with min < max")));
    }
    if chart.x_scale == Scale::Log {
        let low = chart.x_range.map(|r| r.0).into_iter();
        let xs = series.iter().flat_map(|s| s.points.iter().filter(|p| finite_point(p)).map(|p| p.0));
        if let Some(x) = low.chain(xs).find(|x| *x <= 0.0) {
            return Err(PlotError::BadXAxis(format!("a log scale cannot show x = {x}")));
        }
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
    x_log: bool,
}

fn axes(chart: &Chart, series: &[Series]) -> Axes {
    let ext = extent(series);
    let x_range = chart.x_range.unwrap_or_else(|| match chart.x_scale {
        Scale::Linear => widen_degenerate(ext.map_or((0.0, 1.0), |e| e.0)),
        Scale::Log => {
            let (a, b) = ext.map_or((1.0, 10.0), |e| e.0);
            if b > a { (a, b) } else { (a / 2.0, a * 2.0) }
        }
    });
    let x_ticks = match (&chart.x_ticks, chart.x_scale) {
        (Some(values), _) => chosen_ticks(values),
        (None, Scale::Linear) => nice_ticks(x_range.0, x_range.1, 8),
        (None, Scale::Log) => log_ticks(x_range),
    };
    let (y_range, y_ticks) = match chart.y_range {
        Some(r) => (r, nice_ticks(r.0, r.1, 6)),
        None => {
            let mut r = ext.map_or((0.0, 1.0), |e| e.1);
            if let Some((_, y)) = &chart.reference {
                r = (r.0.min(*y), r.1.max(*y));
            }
            let t = nice_ticks(widen_degenerate(r).0, widen_degenerate(r).1, 6);
            let r = (t.values[0], t.values[t.values.len() - 1]);
            (r, t)
        }
    };
    Axes { x_range, y_range, x_ticks, y_ticks, x_log: chart.x_scale == Scale::Log }
}

/// Ticks a chart names, sorted, labelled with the decimals their smallest gap needs.
fn chosen_ticks(values: &[f64]) -> Ticks {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    let gap = v.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
    let step = if gap.is_finite() { 10f64.powf(gap.log10().floor()) } else { 1.0 };
    Ticks { step, values: v }
}

/// 1, 2 and 5 × 10^k inside a positive range (the log scale's own ticks).
fn log_ticks((lo, hi): (f64, f64)) -> Ticks {
    let mut values = Vec::new();
    for k in (lo.log10().floor() as i32)..=(hi.log10().ceil() as i32) {
        for m in [1.0, 2.0, 5.0] {
            let v = m * 10f64.powi(k);
            if v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9) {
                values.push(v);
            }
        }
    }
    let step = values.first().map_or(1.0, |v| 10f64.powf(v.log10().floor()));
    Ticks { step, values }
}

/// A plotters axis, linear or logarithmic, whose ticks (grid lines and labels) are ours:
/// [`nice_ticks`] or the chart's own inside the range, labelled by `format_tick` with the ticks'
/// step.
#[derive(Clone)]
struct TickedAxis {
    range: (f64, f64),
    /// The axis in the coordinate it is linear in: x, or ln x on a log scale.
    linear: RangedCoordf64,
    log: bool,
    ticks: Vec<f64>,
    step: f64,
}

impl TickedAxis {
    fn new(range: (f64, f64), ticks: &Ticks, log: bool) -> Self {
        let linear = if log { (range.0.ln()..range.1.ln()).into() } else { (range.0..range.1).into() };
        Self { range, linear, log, ticks: ticks_inside(ticks, range), step: ticks.step }
    }
}

impl Ranged for TickedAxis {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.linear.map(&if self.log { value.ln() } else { *value }, limit)
    }

    /// Our ticks as plotters' bold key points; no light (minor) grid lines.
    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() { Vec::new() } else { self.ticks.clone() }
    }

    fn range(&self) -> Range<f64> {
        self.range.0..self.range.1
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
    let root = BitMapBackend::with_buffer(buf, (chart.width, chart.height)).into_drawing_area();
    let frame = draw_on(&root, chart, series)?;
    root.present().map_err(draw_err)?;
    Ok(frame)
}

/// `x` at fraction `t` of the x axis (geometric on a log scale).
fn x_at(axes: &Axes, t: f64) -> f64 {
    let (a, b) = axes.x_range;
    if axes.x_log { a * (b / a).powf(t) } else { a + t * (b - a) }
}

/// Draws the chart on `area` (which it fills: the chart's own width and height are not used).
fn draw_on<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    chart: &Chart,
    series: &[Series],
) -> Result<PlotArea, PlotError> {
    let axes = axes(chart, series);
    let (w, h) = area.dim_in_pixel();
    let base = area.get_base_pixel();
    area.fill(&WHITE).map_err(draw_err)?;

    let k = chart.text_scale;
    let (title_size, label_size, tick_size) = (TITLE_SIZE * k, LABEL_SIZE * k, TICK_SIZE * k);
    let tick_font = (FONT, tick_size).into_font().color(&BLACK);
    let label_font = (FONT, label_size).into_font().color(&BLACK);
    let text_w = |text: &str, font: &TextStyle| area.estimate_text_size(text, font).map(|(tw, _)| tw as i32);

    // The legend's entries: each series, then the reference line.
    let mut entries: Vec<(String, RGBColor, bool)> =
        series.iter().map(|s| (legend_label(s), rgb(s.color), false)).collect();
    if let Some((label, _)) = &chart.reference {
        entries.push((label.chars().take(LEGEND_MAX_CHARS).collect(), BLACK, true));
    }
    if chart.legend == Legend::Hidden {
        entries.clear();
    }
    let swatch_w = (SWATCH_W as f64 * k) as i32;
    let pad = (LEGEND_PAD as f64 * k).max(3.0) as i32;
    let mut legend_w = 0;
    for (label, _, _) in &entries {
        legend_w = legend_w.max(text_w(label, &label_font).map_err(draw_err)?);
    }
    if !entries.is_empty() {
        legend_w += 3 * pad + swatch_w;
    }

    // Margins sized from the text they hold, never more than a third of the canvas.
    let mut y_tick_w = 0;
    for v in ticks_inside(&axes.y_ticks, axes.y_range) {
        y_tick_w = y_tick_w.max(text_w(&format_tick(v, axes.y_ticks.step), &tick_font).map_err(draw_err)?);
    }
    let third_w = w as i32 / 3;
    let third_h = h as i32 / 3;
    let y_area = (y_tick_w + 12 + if chart.y_label.is_empty() { 0 } else { label_size as i32 + 10 }).min(third_w);
    let x_area =
        (tick_size as i32 + 14 + if chart.x_label.is_empty() { 0 } else { label_size as i32 + 10 }).min(third_h);
    let right = match chart.legend {
        Legend::Right if !entries.is_empty() => (legend_w + 2 * pad).max(24).min(third_w),
        _ => 24,
    };

    let mut builder = ChartBuilder::on(area);
    builder.margin((12.0 * k) as i32).margin_right(right).x_label_area_size(x_area).y_label_area_size(y_area);
    if !chart.title.is_empty() {
        builder.caption(&chart.title, (FONT, title_size).into_font().color(&BLACK));
    }
    let x_axis = TickedAxis::new(axes.x_range, &axes.x_ticks, axes.x_log);
    let y_axis = TickedAxis::new(axes.y_range, &axes.y_ticks, false);
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

    // Data: fills first, then lines, error bars and markers, so that lines stay on top of every fill.
    let (lo, hi) = axes.y_range;
    for s in series.iter().filter(|s| !s.bars) {
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
    for s in series.iter().filter(|s| s.bars) {
        let Some(band) = &s.band else { continue };
        let bar = |(p, h): (&(f64, f64), &f64)| {
            let ok = finite_point(p) && h.is_finite();
            ok.then(|| clip_polyline(&[(p.0, p.1 - h.abs()), (p.0, p.1 + h.abs())], lo, hi)).into_iter().flatten()
        };
        let style = rgb(s.color).stroke_width(LINE_WIDTH);
        ctx.draw_series(s.points.iter().zip(band).flat_map(bar).map(|run| PathElement::new(run, style)))
            .map_err(draw_err)?;
    }
    for s in series {
        let fill = rgb(s.color).filled();
        let inside = |p: &&(f64, f64)| finite_point(p) && p.1 >= lo && p.1 <= hi;
        ctx.draw_series(s.points.iter().filter(inside).map(|&p| Circle::new(p, MARKER_RADIUS, fill)))
            .map_err(draw_err)?;
    }
    if let Some((_, y)) = chart.reference.as_ref().filter(|(_, y)| (lo..=hi).contains(y)) {
        // 40 dashes, evenly spaced along the axis
        let dash = |d: usize| {
            PathElement::new(
                vec![(x_at(&axes, d as f64 / 40.0), *y), (x_at(&axes, (d as f64 + 0.5) / 40.0), *y)],
                BLACK.stroke_width(LINE_WIDTH),
            )
        };
        ctx.draw_series((0..40).map(dash)).map_err(draw_err)?;
    }

    // Axes box on top of the data (pixel ranges are the backend's; the area draws relative to its base).
    let (x_px, y_px) = ctx.plotting_area().get_pixel_range();
    let (bx, by) = base;
    let (x0, x1, y0, y1) = (x_px.start - bx, x_px.end - bx, y_px.start - by, y_px.end - by);
    area.draw(&Rectangle::new([(x0, y0), (x1 - 1, y1 - 1)], AXIS.stroke_width(1))).map_err(draw_err)?;

    // Legend: a swatch (line and marker, or a dashed line) and the label per entry.
    if !entries.is_empty() {
        let row_h = label_size as i32 + (9.0 * k) as i32;
        let box_h = pad + row_h * entries.len() as i32;
        let (lx, ly) = match chart.legend {
            Legend::LowerRight => (x1 - legend_w - pad, y1 - box_h - pad),
            _ => (x1 + 12, y0),
        };
        let frame = Rectangle::new([(lx, ly), (lx + legend_w, ly + box_h)], LEGEND_BORDER.stroke_width(1));
        if chart.legend == Legend::LowerRight {
            area.draw(&Rectangle::new([(lx, ly), (lx + legend_w, ly + box_h)], WHITE.mix(0.85).filled()))
                .map_err(draw_err)?;
        }
        area.draw(&frame).map_err(draw_err)?;
        for (i, (label, color, dashed)) in entries.iter().enumerate() {
            let cy = ly + pad / 2 + row_h * i as i32 + row_h / 2;
            let sx = lx + pad;
            let line = color.stroke_width(LINE_WIDTH);
            if *dashed {
                for d in 0..3 {
                    let x = sx + d * swatch_w / 3;
                    area.draw(&PathElement::new(vec![(x, cy), (x + swatch_w / 6, cy)], line)).map_err(draw_err)?;
                }
            } else {
                area.draw(&PathElement::new(vec![(sx, cy), (sx + swatch_w, cy)], line)).map_err(draw_err)?;
                area.draw(&Circle::new((sx + swatch_w / 2, cy), MARKER_RADIUS, color.filled())).map_err(draw_err)?;
            }
            let style = label_font.pos(plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Left,
                plotters::style::text_anchor::VPos::Center,
            ));
            area.draw(&Text::new(label.clone(), (sx + swatch_w + pad, cy), style)).map_err(draw_err)?;
        }
    }
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

/// Height of the title strip above [`render_panels`]'s charts, in pixels.
const PANELS_TITLE_H: u32 = 40;

/// Charts side by side, `cols` to a row (a row not filled is left blank), under one `title`: each
/// cell is as large as the largest chart's `width × height`. A chart's own title is its caption.
pub fn render_panels(title: &str, panels: &[(Chart, Vec<Series>)], cols: usize) -> Result<RgbImage, PlotError> {
    ensure_font()?;
    for (c, s) in panels {
        validate(c, s)?;
    }
    let cols = cols.max(1);
    let rows = panels.len().div_ceil(cols).max(1);
    let cell = panels.iter().fold((64, 64), |(w, h), (c, _)| (w.max(c.width), h.max(c.height)));
    let (w, h) = (cell.0 * cols as u32, PANELS_TITLE_H + cell.1 * rows as u32);
    let mut buf = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let (top, rest) = root.split_vertically(PANELS_TITLE_H);
        top.titled(title, (FONT, TITLE_SIZE * 0.9).into_font().color(&BLACK)).map_err(draw_err)?;
        for ((chart, series), area) in panels.iter().zip(rest.split_evenly((rows, cols))) {
            draw_on(&area, chart, series)?;
        }
        root.present().map_err(draw_err)?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| PlotError::Draw("the drawing buffer does not match the panels".into()))
}

/// [`render_panels`] written as a PNG file at `path`, whole or not at all.
pub fn write_panels_png(
    path: &Path,
    title: &str,
    panels: &[(Chart, Vec<Series>)],
    cols: usize,
) -> Result<(), PlotError> {
    encode_png(path, &render_panels(title, panels, cols)?)
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
    encode_png(path, &render(chart, series)?)
}

fn encode_png(path: &Path, img: &RgbImage) -> Result<(), PlotError> {
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
        let log = Chart { x_scale: Scale::Log, ..Chart::default() };
        let err = render(&log, &[Series::new("zero", palette(0), vec![(0.0, 1.0), (10.0, 1.0)])]).unwrap_err();
        assert!(matches!(err, PlotError::BadXAxis(_)) && err.to_string().contains("x = 0"), "{err}");
        let chart = Chart { x_range: Some((2.0, 1.0)), ..Chart::default() };
        assert!(matches!(render(&chart, &[]), Err(PlotError::BadXAxis(_))));
    }

    /// Whether `color` is within 2 px of `(x, y)`.
    fn near_pixel(img: &RgbImage, (x, y): (u32, u32), color: [u8; 3]) -> bool {
        (-2..=2).any(|dy: i32| {
            (-2..=2).any(|dx: i32| img.get_pixel(x.wrapping_add_signed(dx), y.wrapping_add_signed(dy)).0 == color)
        })
    }

    #[test]
    fn a_log_axis_puts_equal_ratios_at_equal_distances_with_the_ticks_named() {
        let chart = Chart {
            x_scale: Scale::Log,
            x_range: Some((10.0, 1000.0)),
            x_ticks: Some(vec![400.0, 100.0, 100.0]),
            y_range: Some((0.0, 1.0)),
            ..Chart::new("t", "x", "y")
        };
        let color = [200, 30, 40];
        let s = Series::new("s", color, vec![(100.0, 0.5)]);
        let (img, frame) = render_framed(&chart, &[s]);
        assert_eq!(frame.axes.x_ticks.values, vec![100.0, 400.0]);
        // 100 is the geometric middle of 10 … 1000
        let mid = ((frame.x_px.start + frame.x_px.end) / 2) as u32;
        let row = ((frame.y_px.start + frame.y_px.end) / 2) as u32;
        assert!(near_pixel(&img, (mid, row), color), "the point is not at the middle of the log axis");
        assert_eq!(log_ticks((1.0, 60.0)).values, vec![1.0, 2.0, 5.0, 10.0, 20.0, 50.0]);
    }

    #[test]
    fn error_bars_span_one_band_width_at_each_point_and_the_reference_is_dashed() {
        let chart = Chart {
            y_range: Some((0.0, 1.0)),
            reference: Some(("bound".into(), 0.25)),
            legend: Legend::LowerRight,
            ..Chart::new("t", "x", "y")
        };
        let color = [200, 30, 40];
        let s =
            Series { band: Some(vec![0.2, 0.2]), bars: true, ..Series::new("s", color, vec![(0.0, 0.6), (10.0, 0.6)]) };
        let (img, frame) = render_framed(&chart, &[s]);
        // on the bar of the first point, 0.15 above it; not between the points at that height
        let (x, y) = px(&frame, 0.0, 0.75);
        assert!(near_pixel(&img, (x + 2, y), color), "no error bar at ({x}, {y})");
        let (x, y) = px(&frame, 5.0, 0.75);
        assert!(!near_pixel(&img, (x, y), color), "a bar where there is no point");
        // the reference line: black dashes and gaps along y = 0.25
        let (_, ry) = px(&frame, 0.0, 0.25);
        let blacks = (frame.x_px.start as u32 + 4..frame.x_px.end as u32 - 4)
            .filter(|&x| (ry - 1..=ry + 1).any(|y| img.get_pixel(x, y).0 == [0, 0, 0]))
            .count();
        let width = (frame.x_px.end - frame.x_px.start - 8) as usize;
        assert!(blacks > width / 3 && blacks < width * 2 / 3, "{blacks} of {width} columns black: not dashed");
    }

    #[test]
    fn panels_are_laid_out_in_rows_under_one_title() {
        let chart = |t: &str| Chart {
            width: 200,
            height: 150,
            text_scale: 0.7,
            legend: Legend::Hidden,
            ..Chart::new(t, "", "")
        };
        let series = vec![Series::new("s", palette(0), vec![(1.0, 0.5), (2.0, 0.7)])];
        let panels: Vec<(Chart, Vec<Series>)> = ["a", "b", "c"].iter().map(|t| (chart(t), series.clone())).collect();
        let img = render_panels("three", &panels, 2).unwrap();
        assert_eq!((img.width(), img.height()), (400, PANELS_TITLE_H + 300));
        // the third panel (second row, first column) has its curve; the fourth cell is blank
        let drawn =
            |x0: u32, y0: u32| (x0..x0 + 200).any(|x| (y0..y0 + 150).any(|y| img.get_pixel(x, y).0 == palette(0)));
        assert!(drawn(0, PANELS_TITLE_H + 150) && !drawn(200, PANELS_TITLE_H + 150));
    }
}
