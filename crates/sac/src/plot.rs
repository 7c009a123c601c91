//! Learning-curve PNGs drawn pixel by pixel, without a plotting library: a white canvas, axes with
//! "nice" ticks (1, 2 or 5 × 10^k), a light grid, one antialiased polyline with point markers per
//! [`Series`], optional translucent bands (e.g. ± standard error over seeds), a legend to the right
//! of the plot, a title and axis labels. Text uses an embedded 5×7 bitmap font (printable ASCII
//! 32–126, with short descenders for g, p, q and y; the title is drawn at twice the size).
//!
//! Limitations: one linear x axis and one linear y axis (no log scale); the x axis spans exactly
//! the finite data (the y axis is widened to the enclosing ticks unless [`Chart::y_range`] fixes
//! it); characters outside printable ASCII are drawn as `?`; labels that do not fit are clipped at
//! the image border rather than wrapped; points with a non-finite coordinate are skipped and break
//! the polyline (and band) there, like matplotlib; bands are filled column by column, so they expect
//! the points of a series in increasing x order.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use image::{ImageFormat, Rgb, RgbImage};

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
    /// Creating or writing the output file failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The output file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// PNG encoding failed.
    #[error("cannot encode {path} as PNG: {source}")]
    Encode {
        /// The output file.
        path: PathBuf,
        /// The underlying error.
        source: image::ImageError,
    },
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
    /// Text above the plot (drawn at twice the font size).
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
// Font: one line per printable ASCII character (32..=126): the character, then its 7 rows of
// 5 pixels ('#' = ink). Parsed at compile time into one bit mask per row (bit 4 = leftmost).
// The letters in DESCENDERS are drawn 2 rows lower, so that their last rows hang below the
// baseline (a 'g' that does not look like a '9').

const GLYPH_W: i64 = 5;
const GLYPH_H: i64 = 7;
/// Horizontal advance per character at scale 1 (glyph plus one blank column).
const ADVANCE: i64 = GLYPH_W + 1;

const FONT_SRC: &str = r##"  ..... ..... ..... ..... ..... ..... .....
! ..#.. ..#.. ..#.. ..#.. ..#.. ..... ..#..
" .#.#. .#.#. ..... ..... ..... ..... .....
# .#.#. .#.#. ##### .#.#. ##### .#.#. .#.#.
$ ..#.. .#### #.#.. .###. ..#.# ####. ..#..
% ##... ##..# ...#. ..#.. .#... #..## ...##
& .##.. #..#. #.#.. .#... #.#.# #..#. .##.#
' ..#.. ..#.. .#... ..... ..... ..... .....
( ...#. ..#.. .#... .#... .#... ..#.. ...#.
) .#... ..#.. ...#. ...#. ...#. ..#.. .#...
* ..... ..#.. #.#.# .###. #.#.# ..#.. .....
+ ..... ..#.. ..#.. ##### ..#.. ..#.. .....
, ..... ..... ..... ..... .##.. ..#.. .#...
- ..... ..... ..... ##### ..... ..... .....
. ..... ..... ..... ..... ..... .##.. .##..
/ ..... ....# ...#. ..#.. .#... #.... .....
0 .###. #...# #..## #.#.# ##..# #...# .###.
1 ..#.. .##.. ..#.. ..#.. ..#.. ..#.. .###.
2 .###. #...# ....# ...#. ..#.. .#... #####
3 ##### ...#. ..#.. ...#. ....# #...# .###.
4 ...#. ..##. .#.#. #..#. ##### ...#. ...#.
5 ##### #.... ####. ....# ....# #...# .###.
6 ..##. .#... #.... ####. #...# #...# .###.
7 ##### ....# ...#. ..#.. .#... .#... .#...
8 .###. #...# #...# .###. #...# #...# .###.
9 .###. #...# #...# .#### ....# ...#. .##..
: ..... .##.. .##.. ..... .##.. .##.. .....
; ..... .##.. .##.. ..... .##.. ..#.. .#...
< ...#. ..#.. .#... #.... .#... ..#.. ...#.
= ..... ..... ##### ..... ##### ..... .....
> .#... ..#.. ...#. ....# ...#. ..#.. .#...
? .###. #...# ....# ...#. ..#.. ..... ..#..
@ .###. #...# ....# .##.# #.#.# #.#.# .###.
A .###. #...# #...# ##### #...# #...# #...#
B ####. #...# #...# ####. #...# #...# ####.
C .###. #...# #.... #.... #.... #...# .###.
D ###.. #..#. #...# #...# #...# #..#. ###..
E ##### #.... #.... ####. #.... #.... #####
F ##### #.... #.... ####. #.... #.... #....
G .###. #...# #.... #.### #...# #...# .####
H #...# #...# #...# ##### #...# #...# #...#
I .###. ..#.. ..#.. ..#.. ..#.. ..#.. .###.
J ..### ...#. ...#. ...#. ...#. #..#. .##..
K #...# #..#. #.#.. ##... #.#.. #..#. #...#
L #.... #.... #.... #.... #.... #.... #####
M #...# ##.## #.#.# #.#.# #...# #...# #...#
N #...# #...# ##..# #.#.# #..## #...# #...#
O .###. #...# #...# #...# #...# #...# .###.
P ####. #...# #...# ####. #.... #.... #....
Q .###. #...# #...# #...# #.#.# #..#. .##.#
R ####. #...# #...# ####. #.#.. #..#. #...#
S .#### #.... #.... .###. ....# ....# ####.
T ##### ..#.. ..#.. ..#.. ..#.. ..#.. ..#..
U #...# #...# #...# #...# #...# #...# .###.
V #...# #...# #...# #...# #...# .#.#. ..#..
W #...# #...# #...# #.#.# #.#.# #.#.# .#.#.
X #...# #...# .#.#. ..#.. .#.#. #...# #...#
Y #...# #...# .#.#. ..#.. ..#.. ..#.. ..#..
Z ##### ....# ...#. ..#.. .#... #.... #####
[ .###. .#... .#... .#... .#... .#... .###.
\ ..... #.... .#... ..#.. ...#. ....# .....
] .###. ...#. ...#. ...#. ...#. ...#. .###.
^ ..#.. .#.#. #...# ..... ..... ..... .....
_ ..... ..... ..... ..... ..... ..... #####
` .#... ..#.. ...#. ..... ..... ..... .....
a ..... ..... .###. ....# .#### #...# .####
b #.... #.... #.##. ##..# #...# #...# ####.
c ..... ..... .###. #.... #.... #...# .###.
d ....# ....# .##.# #..## #...# #...# .####
e ..... ..... .###. #...# ##### #.... .###.
f ..##. .#..# .#... ###.. .#... .#... .#...
g .#### #...# #...# #...# .#### ....# .###.
h #.... #.... #.##. ##..# #...# #...# #...#
i ..#.. ..... .##.. ..#.. ..#.. ..#.. .###.
j ...#. ..... ..##. ...#. ...#. #..#. .##..
k #.... #.... #..#. #.#.. ##... #.#.. #..#.
l .##.. ..#.. ..#.. ..#.. ..#.. ..#.. .###.
m ..... ..... ##.#. #.#.# #.#.# #...# #...#
n ..... ..... #.##. ##..# #...# #...# #...#
o ..... ..... .###. #...# #...# #...# .###.
p ####. #...# #...# #...# ####. #.... #....
q .#### #...# #...# #...# .#### ....# ....#
r ..... ..... #.##. ##..# #.... #.... #....
s ..... ..... .###. #.... .###. ....# ####.
t .#... .#... ###.. .#... .#... .#..# ..##.
u ..... ..... #...# #...# #...# #..## .##.#
v ..... ..... #...# #...# #...# .#.#. ..#..
w ..... ..... #...# #...# #.#.# #.#.# .#.#.
x ..... ..... #...# .#.#. ..#.. .#.#. #...#
y #...# #...# #...# #...# .#### ....# .###.
z ..... ..... ##### ...#. ..#.. .#... #####
{ ...#. ..#.. ..#.. .#... ..#.. ..#.. ...#.
| ..#.. ..#.. ..#.. ..#.. ..#.. ..#.. ..#..
} .#... ..#.. ..#.. ...#. ..#.. ..#.. .#...
~ ..... ..... .#... #.#.# ...#. ..... .....
"##;

const fn parse_font(src: &str) -> [[u8; 7]; 95] {
    let b = src.as_bytes();
    let mut font = [[0u8; 7]; 95];
    let mut pos = 0;
    let mut g = 0;
    while g < 95 {
        assert!(b[pos] == 32 + g as u8, "font: glyph out of order");
        pos += 2;
        let mut row = 0;
        while row < 7 {
            let mut bits = 0u8;
            let mut col = 0;
            while col < 5 {
                bits <<= 1;
                match b[pos + col] {
                    b'#' => bits |= 1,
                    b'.' => {}
                    _ => panic!("font: row characters must be '#' or '.'"),
                }
                col += 1;
            }
            font[g][row] = bits;
            pos += 6; // five pixels and a space or newline
            row += 1;
        }
        g += 1;
    }
    font
}

static FONT: [[u8; 7]; 95] = parse_font(FONT_SRC);

const DESCENDERS: &str = "gpqy";
/// Rows a descending glyph is drawn below the others.
const DESCENT: i64 = 2;

/// Row offset at which `c` is drawn: [`DESCENT`] for letters with a descender, else 0.
fn glyph_drop(c: char) -> i64 {
    if DESCENDERS.contains(c) { DESCENT } else { 0 }
}

fn glyph(c: char) -> &'static [u8; 7] {
    let code = c as u32;
    if (32..=126).contains(&code) { &FONT[(code - 32) as usize] } else { &FONT[(b'?' - 32) as usize] }
}

/// Width in pixels of `text` at `scale`.
fn text_width(text: &str, scale: i64) -> i64 {
    let n = text.chars().count() as i64;
    if n == 0 { 0 } else { (n * ADVANCE - 1) * scale }
}

// ---------------------------------------------------------------------------------------------
// Canvas primitives.

struct Canvas {
    img: RgbImage,
}

/// Pixel rectangle `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug)]
struct Rect {
    x0: i64,
    y0: i64,
    x1: i64,
    y1: i64,
}

impl Canvas {
    fn new(w: u32, h: u32) -> Self {
        Self { img: RgbImage::from_pixel(w, h, Rgb([255, 255, 255])) }
    }

    fn w(&self) -> i64 {
        self.img.width() as i64
    }

    fn h(&self) -> i64 {
        self.img.height() as i64
    }

    /// Blends `color` over the pixel with opacity `alpha` (0..=1); off-canvas pixels are ignored.
    fn blend(&mut self, x: i64, y: i64, color: [u8; 3], alpha: f64) {
        if x < 0 || y < 0 || x >= self.w() || y >= self.h() || alpha <= 0.0 {
            return;
        }
        let a = alpha.min(1.0);
        let p = self.img.get_pixel_mut(x as u32, y as u32);
        for (c, &new) in p.0.iter_mut().zip(color.iter()) {
            *c = (*c as f64 * (1.0 - a) + new as f64 * a).round() as u8;
        }
    }

    fn fill_rect(&mut self, r: Rect, color: [u8; 3], alpha: f64) {
        for y in r.y0.max(0)..r.y1.min(self.h()) {
            for x in r.x0.max(0)..r.x1.min(self.w()) {
                self.blend(x, y, color, alpha);
            }
        }
    }

    fn rect_outline(&mut self, r: Rect, color: [u8; 3]) {
        self.fill_rect(Rect { y1: r.y0 + 1, ..r }, color, 1.0);
        self.fill_rect(Rect { y0: r.y1 - 1, ..r }, color, 1.0);
        self.fill_rect(Rect { x1: r.x0 + 1, ..r }, color, 1.0);
        self.fill_rect(Rect { x0: r.x1 - 1, ..r }, color, 1.0);
    }

    /// Antialiased segment of the given width, drawn only inside `clip`.
    fn line(&mut self, a: (f64, f64), b: (f64, f64), width: f64, color: [u8; 3], clip: Rect) {
        let half = width / 2.0;
        let pad = half + 1.0;
        let x0 = ((a.0.min(b.0) - pad).floor() as i64).max(clip.x0);
        let x1 = ((a.0.max(b.0) + pad).ceil() as i64).min(clip.x1);
        let y0 = ((a.1.min(b.1) - pad).floor() as i64).max(clip.y0);
        let y1 = ((a.1.max(b.1) + pad).ceil() as i64).min(clip.y1);
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let len2 = dx * dx + dy * dy;
        for y in y0..y1 {
            for x in x0..x1 {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let t = if len2 > 0.0 { (((px - a.0) * dx + (py - a.1) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
                let (cx, cy) = (a.0 + t * dx, a.1 + t * dy);
                let d = ((px - cx).powi(2) + (py - cy).powi(2)).sqrt();
                let coverage = (half + 0.5 - d).clamp(0.0, 1.0);
                self.blend(x, y, color, coverage);
            }
        }
    }

    /// Antialiased filled disc, drawn only inside `clip`.
    fn disc(&mut self, c: (f64, f64), radius: f64, color: [u8; 3], clip: Rect) {
        let x0 = ((c.0 - radius - 1.0).floor() as i64).max(clip.x0);
        let x1 = ((c.0 + radius + 1.0).ceil() as i64).min(clip.x1);
        let y0 = ((c.1 - radius - 1.0).floor() as i64).max(clip.y0);
        let y1 = ((c.1 + radius + 1.0).ceil() as i64).min(clip.y1);
        for y in y0..y1 {
            for x in x0..x1 {
                let d = ((x as f64 + 0.5 - c.0).powi(2) + (y as f64 + 0.5 - c.1).powi(2)).sqrt();
                self.blend(x, y, color, (radius + 0.5 - d).clamp(0.0, 1.0));
            }
        }
    }

    /// Text with its top-left corner at `(x, y)`.
    fn text(&mut self, x: i64, y: i64, text: &str, scale: i64, color: [u8; 3]) {
        for (i, c) in text.chars().enumerate() {
            let gx = x + i as i64 * ADVANCE * scale;
            let drop = glyph_drop(c);
            for (row, bits) in glyph(c).iter().enumerate() {
                let row = row as i64 + drop;
                for col in 0..GLYPH_W {
                    if bits & (1 << (GLYPH_W - 1 - col)) != 0 {
                        let r = Rect {
                            x0: gx + col * scale,
                            y0: y + row * scale,
                            x1: gx + (col + 1) * scale,
                            y1: y + (row + 1) * scale,
                        };
                        self.fill_rect(r, color, 1.0);
                    }
                }
            }
        }
    }

    /// Text rotated 90° counter-clockwise (reads bottom to top), its baseline-left corner at
    /// `(x, y)`: the text occupies `x .. x + 7·scale` horizontally and ends `width` pixels above `y`.
    fn text_up(&mut self, x: i64, y: i64, text: &str, scale: i64, color: [u8; 3]) {
        for (i, c) in text.chars().enumerate() {
            let along = i as i64 * ADVANCE * scale;
            let drop = glyph_drop(c);
            for (row, bits) in glyph(c).iter().enumerate() {
                let row = row as i64 + drop;
                for col in 0..GLYPH_W {
                    if bits & (1 << (GLYPH_W - 1 - col)) != 0 {
                        // Unrotated (col, row) maps to (row, -col).
                        let px = x + row * scale;
                        let py = y - along - (col + 1) * scale;
                        let r = Rect { x0: px, y0: py, x1: px + scale, y1: py + scale };
                        self.fill_rect(r, color, 1.0);
                    }
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Layout.

const BLACK: [u8; 3] = [0, 0, 0];
const AXIS: [u8; 3] = [60, 60, 60];
const GRID: [u8; 3] = [225, 225, 225];
const BAND_ALPHA: f64 = 0.2;
const LINE_WIDTH: f64 = 2.0;
const MARKER_RADIUS: f64 = 3.0;

/// Where data coordinates land on the canvas.
#[derive(Clone, Copy, Debug)]
struct Frame {
    plot: Rect,
    x_range: (f64, f64),
    y_range: (f64, f64),
}

impl Frame {
    fn px(&self, x: f64, y: f64) -> (f64, f64) {
        let fx = (x - self.x_range.0) / (self.x_range.1 - self.x_range.0);
        let fy = (y - self.y_range.0) / (self.y_range.1 - self.y_range.0);
        let w = (self.plot.x1 - self.plot.x0 - 1) as f64;
        let h = (self.plot.y1 - self.plot.y0 - 1) as f64;
        (self.plot.x0 as f64 + 0.5 + fx * w, self.plot.y1 as f64 - 0.5 - fy * h)
    }
}

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

/// Lays out the chart: axis ranges, ticks and the plot rectangle.
fn layout(chart: &Chart, series: &[Series]) -> (Frame, Ticks, Ticks) {
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
    let y_tick_w = y_ticks.values.iter().map(|&v| text_width(&format_tick(v, y_ticks.step), 1)).max().unwrap_or(0);
    let legend_w = legend_width(series);
    let (w, h) = (chart.width as i64, chart.height as i64);
    let top = if chart.title.is_empty() { 16 } else { 16 + 2 * GLYPH_H + 14 };
    let left = 12 + if chart.y_label.is_empty() { 0 } else { GLYPH_H + 10 } + y_tick_w + 8;
    let bottom = 8 + GLYPH_H + 8 + if chart.x_label.is_empty() { 0 } else { GLYPH_H + 10 };
    let right = if legend_w > 0 { legend_w + 24 } else { 24 };
    // Never let margins eat the whole canvas (tiny images still get a plot of some size).
    let x0 = left.min(w / 3);
    let x1 = (w - right).max(x0 + w / 3);
    let y0 = top.min(h / 3);
    let y1 = (h - bottom).max(y0 + h / 3);
    let frame = Frame { plot: Rect { x0, y0, x1, y1 }, x_range, y_range };
    (frame, x_ticks, y_ticks)
}

const SWATCH_W: i64 = 22;

fn legend_width(series: &[Series]) -> i64 {
    let max_label = series.iter().map(|s| text_width(&s.label, 1)).max();
    match max_label {
        None => 0,
        Some(t) => 8 + SWATCH_W + 6 + t.min(40 * ADVANCE) + 8,
    }
}

/// Draws the chart into an RGB image (what [`write_png`] encodes).
pub fn render(chart: &Chart, series: &[Series]) -> Result<RgbImage, PlotError> {
    validate(chart, series)?;
    let (frame, x_ticks, y_ticks) = layout(chart, series);
    let mut cv = Canvas::new(chart.width, chart.height);
    let plot = frame.plot;
    let inside = |v: f64, r: (f64, f64)| {
        let tol = (r.1 - r.0) * 1e-9;
        v >= r.0 - tol && v <= r.1 + tol
    };

    // Grid and ticks.
    for &v in x_ticks.values.iter().filter(|&&v| inside(v, frame.x_range)) {
        let px = frame.px(v, frame.y_range.0).0.floor() as i64;
        cv.fill_rect(Rect { x0: px, x1: px + 1, ..plot }, GRID, 1.0);
        cv.fill_rect(Rect { x0: px, x1: px + 1, y0: plot.y1, y1: plot.y1 + 4 }, AXIS, 1.0);
        let label = format_tick(v, x_ticks.step);
        let tw = text_width(&label, 1);
        let lx = (px - tw / 2).clamp(0, (cv.w() - tw).max(0));
        cv.text(lx, plot.y1 + 8, &label, 1, BLACK);
    }
    for &v in y_ticks.values.iter().filter(|&&v| inside(v, frame.y_range)) {
        let py = frame.px(frame.x_range.0, v).1.floor() as i64;
        cv.fill_rect(Rect { y0: py, y1: py + 1, ..plot }, GRID, 1.0);
        cv.fill_rect(Rect { x0: plot.x0 - 4, x1: plot.x0, y0: py, y1: py + 1 }, AXIS, 1.0);
        let label = format_tick(v, y_ticks.step);
        let tw = text_width(&label, 1);
        cv.text(plot.x0 - 8 - tw, py - GLYPH_H / 2, &label, 1, BLACK);
    }

    // Data: bands first, then lines, then markers, so that lines stay on top of every band.
    let inner = Rect { x0: plot.x0 + 1, y0: plot.y0 + 1, x1: plot.x1 - 1, y1: plot.y1 - 1 };
    for s in series {
        if let Some(band) = &s.band {
            draw_band(&mut cv, &frame, inner, s, band);
        }
    }
    for s in series {
        for pair in s.points.windows(2) {
            if finite_point(&pair[0]) && finite_point(&pair[1]) {
                let a = frame.px(pair[0].0, pair[0].1);
                let b = frame.px(pair[1].0, pair[1].1);
                cv.line(a, b, LINE_WIDTH, s.color, inner);
            }
        }
    }
    for s in series {
        for p in s.points.iter().filter(|p| finite_point(p)) {
            cv.disc(frame.px(p.0, p.1), MARKER_RADIUS, s.color, inner);
        }
    }

    // Axes box on top of the data.
    cv.rect_outline(plot, AXIS);

    // Title, axis labels, legend.
    if !chart.title.is_empty() {
        let tw = text_width(&chart.title, 2);
        cv.text(((cv.w() - tw) / 2).max(0), 12, &chart.title, 2, BLACK);
    }
    if !chart.x_label.is_empty() {
        let tw = text_width(&chart.x_label, 1);
        let cx = (plot.x0 + plot.x1) / 2;
        cv.text((cx - tw / 2).max(0), plot.y1 + 8 + GLYPH_H + 10, &chart.x_label, 1, BLACK);
    }
    if !chart.y_label.is_empty() {
        let tw = text_width(&chart.y_label, 1);
        let cy = (plot.y0 + plot.y1) / 2;
        cv.text_up(12, (cy + tw / 2).min(cv.h() - 1), &chart.y_label, 1, BLACK);
    }
    draw_legend(&mut cv, plot, series);
    Ok(cv.img)
}

/// Fills between `y - band` and `y + band`, one pixel column at a time, per segment.
fn draw_band(cv: &mut Canvas, frame: &Frame, clip: Rect, s: &Series, band: &[f64]) {
    for i in 1..s.points.len() {
        let (p, q) = (s.points[i - 1], s.points[i]);
        let (hp, hq) = (band[i - 1].abs(), band[i].abs());
        if !(finite_point(&p) && finite_point(&q) && hp.is_finite() && hq.is_finite()) {
            continue;
        }
        let (mut a_lo, mut a_hi) = (frame.px(p.0, p.1 - hp), frame.px(p.0, p.1 + hp));
        let (mut b_lo, mut b_hi) = (frame.px(q.0, q.1 - hq), frame.px(q.0, q.1 + hq));
        if a_lo.0 > b_lo.0 {
            std::mem::swap(&mut a_lo, &mut b_lo);
            std::mem::swap(&mut a_hi, &mut b_hi);
        }
        // Half-open pixel columns so that neighbouring segments never fill a column twice.
        let c0 = (a_lo.0 - 0.5).ceil() as i64;
        let c1 = (b_lo.0 - 0.5).ceil() as i64;
        let last = i == s.points.len() - 1;
        let c1 = if last { c1 + 1 } else { c1 };
        for x in c0.max(clip.x0)..c1.min(clip.x1) {
            let span = b_lo.0 - a_lo.0;
            let t = if span > 0.0 { ((x as f64 + 0.5 - a_lo.0) / span).clamp(0.0, 1.0) } else { 0.0 };
            let top = a_hi.1 + t * (b_hi.1 - a_hi.1);
            let bot = a_lo.1 + t * (b_lo.1 - a_lo.1);
            let y0 = ((top - 0.5).round() as i64).max(clip.y0);
            let y1 = ((bot - 0.5).round() as i64 + 1).min(clip.y1);
            for y in y0..y1 {
                cv.blend(x, y, s.color, BAND_ALPHA);
            }
        }
    }
}

fn draw_legend(cv: &mut Canvas, plot: Rect, series: &[Series]) {
    let width = legend_width(series);
    if width == 0 {
        return;
    }
    let row_h = GLYPH_H + 9;
    let x0 = plot.x1 + 12;
    let y0 = plot.y0;
    let r = Rect { x0, y0, x1: x0 + width, y1: y0 + 6 + row_h * series.len() as i64 + 2 };
    cv.rect_outline(r, [180, 180, 180]);
    let clip = Rect { x0: 0, y0: 0, x1: cv.w(), y1: cv.h() };
    for (i, s) in series.iter().enumerate() {
        let cy = y0 + 6 + row_h * i as i64 + GLYPH_H / 2;
        let sx = x0 + 8;
        let mid = cy as f64 + 0.5;
        cv.line((sx as f64, mid), ((sx + SWATCH_W) as f64, mid), LINE_WIDTH, s.color, clip);
        cv.disc(((sx + SWATCH_W / 2) as f64, mid), MARKER_RADIUS, s.color, clip);
        let label: String = s.label.chars().take(40).collect();
        cv.text(sx + SWATCH_W + 6, cy - GLYPH_H / 2, &label, 1, BLACK);
    }
}

/// Draws the chart and writes it as a PNG file at `path` (overwriting it). The file's directory must
/// already exist.
pub fn write_png(path: &Path, chart: &Chart, series: &[Series]) -> Result<(), PlotError> {
    if let Some(dir) = path.parent()
        && !dir.as_os_str().is_empty()
        && !dir.is_dir()
    {
        return Err(PlotError::MissingDirectory { path: path.to_path_buf(), dir: dir.to_path_buf() });
    }
    let img = render(chart, series)?;
    let file = File::create(path).map_err(|source| PlotError::Io { path: path.to_path_buf(), source })?;
    let mut out = BufWriter::new(file);
    img.write_to(&mut out, ImageFormat::Png)
        .map_err(|source| PlotError::Encode { path: path.to_path_buf(), source })?;
    out.into_inner()
        .map_err(|e| PlotError::Io { path: path.to_path_buf(), source: e.into_error() })?
        .sync_all()
        .map_err(|source| PlotError::Io { path: path.to_path_buf(), source })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scratch::Scratch;

    fn scratch(name: &str) -> Scratch {
        let dir = Scratch::new(&format!("plot_{name}"));
        std::fs::create_dir_all(&dir).unwrap();
        dir
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
    fn font_has_ink_for_required_characters() {
        for c in "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ.-+%()/_:".chars() {
            assert!(glyph(c).iter().any(|&r| r != 0), "{c:?} is blank");
        }
        assert!(glyph(' ').iter().all(|&r| r == 0));
        assert_eq!(glyph('é'), glyph('?'));
        // Distinct glyphs for characters that are easy to confuse.
        for (a, b) in [('0', 'O'), ('1', 'l'), ('5', 'S'), ('8', 'B'), ('-', '_'), ('.', ',')] {
            assert_ne!(glyph(a), glyph(b), "{a} vs {b}");
        }
    }

    #[test]
    fn png_decodes_at_the_requested_size() {
        let dir = scratch("size");
        let path = dir.join("curve.png");
        let chart =
            Chart { width: 640, height: 400, ..Chart::new("Block Picking", "environment steps", "success rate") };
        let s = Series::new("Equi SACfD", palette(0), vec![(0.0, 0.1), (1000.0, 0.5), (2000.0, 0.9)]);
        write_png(&path, &chart, &[s]).unwrap();
        let img = image::open(&path).unwrap();
        assert_eq!((img.width(), img.height()), (640, 400));
    }

    #[test]
    fn data_point_lands_where_it_should() {
        let chart = Chart { y_range: Some((0.0, 1.0)), ..Chart::new("t", "x", "y") };
        let color = [200, 30, 40];
        let s = Series::new("s", color, vec![(0.0, 0.0), (5.0, 0.5), (10.0, 1.0)]);
        let img = render(&chart, std::slice::from_ref(&s)).unwrap();
        let (frame, _, _) = layout(&chart, &[s]);
        assert_eq!(frame.x_range, (0.0, 10.0));
        let (px, py) = frame.px(5.0, 0.5);
        let (px, py) = (px.floor() as i64, py.floor() as i64);
        // The mapping agrees with the plot rectangle: the middle of the data is the middle of the plot.
        assert!((px - (frame.plot.x0 + frame.plot.x1) / 2).abs() <= 1);
        assert!((py - (frame.plot.y0 + frame.plot.y1) / 2).abs() <= 1);
        let found = (-2..=2).any(|dy| (-2..=2).any(|dx| img.get_pixel((px + dx) as u32, (py + dy) as u32).0 == color));
        assert!(found, "series colour not near ({px}, {py})");
        for y in 0..frame.plot.y0.min(20) as u32 {
            for x in 0..frame.plot.x0.min(20) as u32 {
                assert_ne!(img.get_pixel(x, y).0, color, "colour leaked to ({x}, {y})");
            }
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
        let dir = scratch("missing");
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
