//! PNG plots of a run (`doma plot`): the loss curve, the per-frame EPE curve and three-view
//! scatters of the canonical, true and predicted test points coloured by error.
//!
//! A small raster canvas with a 5×7 bitmap font and a PNG encoder (stored deflate blocks),
//! written here rather than taken from `plotters`: its PNG path needs the `image` crate,
//! whose compression features would change the build of crates Burn depends on and so
//! rebuild all of Burn; and its text needs system fonts. The output is plain RGB PNG.

use std::path::Path;

use crate::Result;
use crate::io::{crc32, write_atomic};

/// An RGB colour.
pub type Rgb = [u8; 3];

/// An RGB raster, row-major, origin at the top left.
#[derive(Clone, Debug)]
pub struct Canvas {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    pixels: Vec<Rgb>,
}

/// The 5×7 glyphs: each row's five bits, most significant = leftmost.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_uppercase() {
        'A' => [14, 17, 17, 31, 17, 17, 17],
        'B' => [30, 17, 17, 30, 17, 17, 30],
        'C' => [14, 17, 16, 16, 16, 17, 14],
        'D' => [30, 17, 17, 17, 17, 17, 30],
        'E' => [31, 16, 16, 30, 16, 16, 31],
        'F' => [31, 16, 16, 30, 16, 16, 16],
        'G' => [14, 17, 16, 23, 17, 17, 15],
        'H' => [17, 17, 17, 31, 17, 17, 17],
        'I' => [14, 4, 4, 4, 4, 4, 14],
        'J' => [7, 2, 2, 2, 2, 18, 12],
        'K' => [17, 18, 20, 24, 20, 18, 17],
        'L' => [16, 16, 16, 16, 16, 16, 31],
        'M' => [17, 27, 21, 21, 17, 17, 17],
        'N' => [17, 17, 25, 21, 19, 17, 17],
        'O' => [14, 17, 17, 17, 17, 17, 14],
        'P' => [30, 17, 17, 30, 16, 16, 16],
        'Q' => [14, 17, 17, 17, 21, 18, 13],
        'R' => [30, 17, 17, 30, 20, 18, 17],
        'S' => [15, 16, 16, 14, 1, 1, 30],
        'T' => [31, 4, 4, 4, 4, 4, 4],
        'U' => [17, 17, 17, 17, 17, 17, 14],
        'V' => [17, 17, 17, 17, 17, 10, 4],
        'W' => [17, 17, 17, 21, 21, 21, 10],
        'X' => [17, 17, 10, 4, 10, 17, 17],
        'Y' => [17, 17, 10, 4, 4, 4, 4],
        'Z' => [31, 1, 2, 4, 8, 16, 31],
        '0' => [14, 17, 19, 21, 25, 17, 14],
        '1' => [4, 12, 4, 4, 4, 4, 14],
        '2' => [14, 17, 1, 2, 4, 8, 31],
        '3' => [31, 2, 4, 2, 1, 17, 14],
        '4' => [2, 6, 10, 18, 31, 2, 2],
        '5' => [31, 16, 30, 1, 1, 17, 14],
        '6' => [6, 8, 16, 30, 17, 17, 14],
        '7' => [31, 1, 2, 4, 8, 8, 8],
        '8' => [14, 17, 17, 14, 17, 17, 14],
        '9' => [14, 17, 17, 15, 1, 2, 12],
        '.' => [0, 0, 0, 0, 0, 12, 12],
        ',' => [0, 0, 0, 0, 12, 4, 8],
        '-' => [0, 0, 0, 31, 0, 0, 0],
        '+' => [0, 4, 4, 31, 4, 4, 0],
        '(' => [2, 4, 8, 8, 8, 4, 2],
        ')' => [8, 4, 2, 2, 2, 4, 8],
        '[' => [14, 8, 8, 8, 8, 8, 14],
        ']' => [14, 2, 2, 2, 2, 2, 14],
        '/' => [0, 1, 2, 4, 8, 16, 0],
        ':' => [0, 12, 12, 0, 12, 12, 0],
        '=' => [0, 0, 31, 0, 31, 0, 0],
        '_' => [0, 0, 0, 0, 0, 0, 31],
        '%' => [24, 25, 2, 4, 8, 19, 3],
        _ => [0; 7],
    }
}

impl Canvas {
    /// A white canvas.
    pub fn new(width: usize, height: usize) -> Self {
        Canvas {
            width,
            height,
            pixels: vec![[255; 3]; width * height],
        }
    }

    /// Sets one pixel (ignored outside the canvas).
    pub fn set(&mut self, x: i64, y: i64, c: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            self.pixels[y as usize * self.width + x as usize] = c;
        }
    }

    /// The pixel at `(x, y)`.
    pub fn get(&self, x: usize, y: usize) -> Rgb {
        self.pixels[y * self.width + x]
    }

    /// A one-pixel line (Bresenham).
    pub fn line(&mut self, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: Rgb) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        loop {
            self.set(x, y, c);
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// A filled square dot of half-width `r`.
    pub fn dot(&mut self, x: i64, y: i64, r: i64, c: Rgb) {
        for j in -r..=r {
            for i in -r..=r {
                self.set(x + i, y + j, c);
            }
        }
    }

    /// Text in the 5×7 font at `scale` pixels per font pixel, top-left at `(x, y)`.
    pub fn text(&mut self, x: i64, y: i64, s: &str, scale: i64, c: Rgb) {
        for (k, ch) in s.chars().enumerate() {
            let rows = glyph(ch);
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..5 {
                    if bits >> (4 - col) & 1 == 1 {
                        for j in 0..scale {
                            for i in 0..scale {
                                let px = x + (k as i64 * 6 + col) * scale + i;
                                self.set(px, y + r as i64 * scale + j, c);
                            }
                        }
                    }
                }
            }
        }
    }

    /// The width of `s` in pixels at `scale`.
    pub fn text_width(s: &str, scale: i64) -> i64 {
        s.chars().count() as i64 * 6 * scale
    }

    /// The canvas as PNG bytes (8-bit RGB, deflated by [`deflate_runs`]).
    pub fn to_png(&self) -> Vec<u8> {
        let mut raw = Vec::with_capacity(self.height * (1 + 3 * self.width));
        for row in self.pixels.chunks_exact(self.width) {
            raw.push(0); // filter: none
            for p in row {
                raw.extend_from_slice(p);
            }
        }
        let mut z = vec![0x78, 0x01];
        z.extend_from_slice(&deflate_runs(&raw));
        z.extend_from_slice(&adler32(&raw).to_be_bytes());
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        let mut ihdr = Vec::new();
        ihdr.extend_from_slice(&(self.width as u32).to_be_bytes());
        ihdr.extend_from_slice(&(self.height as u32).to_be_bytes());
        ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
        for (kind, data) in [(b"IHDR", ihdr), (b"IDAT", z), (b"IEND", Vec::new())] {
            png.extend_from_slice(&(data.len() as u32).to_be_bytes());
            let mut chunk = kind.to_vec();
            chunk.extend_from_slice(&data);
            png.extend_from_slice(&chunk);
            png.extend_from_slice(&crc32(&chunk).to_be_bytes());
        }
        png
    }

    /// Writes the PNG atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        write_atomic(path, &self.to_png())
    }
}

/// Bits into a byte stream, least significant first (deflate's order).
struct BitWriter {
    out: Vec<u8>,
    acc: u64,
    n: u32,
}

impl BitWriter {
    fn put(&mut self, value: u32, bits: u32) {
        self.acc |= (value as u64) << self.n;
        self.n += bits;
        while self.n >= 8 {
            self.out.push(self.acc as u8);
            self.acc >>= 8;
            self.n -= 8;
        }
    }

    /// A Huffman code, which deflate stores most significant bit first.
    fn put_code(&mut self, code: u32, bits: u32) {
        let reversed = code.reverse_bits() >> (32 - bits);
        self.put(reversed, bits);
    }

    fn finish(mut self) -> Vec<u8> {
        if self.n > 0 {
            self.out.push(self.acc as u8);
        }
        self.out
    }
}

/// The fixed-Huffman code of literal/length symbol `sym` (RFC 1951 §3.2.6).
fn fixed_code(sym: u32) -> (u32, u32) {
    match sym {
        0..=143 => (0x30 + sym, 8),
        144..=255 => (0x190 + sym - 144, 9),
        256..=279 => (sym - 256, 7),
        _ => (0xC0 + sym - 280, 8),
    }
}

const LENGTH_BASE: [u32; 29] = [
    3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59, 67, 83, 99, 115, 131,
    163, 195, 227, 258,
];
const LENGTH_EXTRA: [u32; 29] = [
    0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0,
];

/// A raw deflate stream (one fixed-Huffman block) whose only back-references are
/// repeats at distance 1 or 3 (a byte or an RGB pixel): plots are mostly runs of one
/// colour, so this shrinks them ~20–50× without a general LZ77 matcher.
pub fn deflate_runs(data: &[u8]) -> Vec<u8> {
    let mut w = BitWriter {
        out: Vec::with_capacity(data.len() / 16),
        acc: 0,
        n: 0,
    };
    w.put(1, 1); // final block
    w.put(1, 2); // fixed Huffman
    let mut i = 0;
    while i < data.len() {
        let run = |d: usize| {
            if i < d {
                return 0;
            }
            let mut n = 0;
            while n < 258 && i + n < data.len() && data[i + n] == data[i + n - d] {
                n += 1;
            }
            n
        };
        let (r1, r3) = (run(1), run(3));
        let (len, dist_code) = if r1 >= r3 { (r1, 0) } else { (r3, 2) };
        if len >= 3 {
            let k = LENGTH_BASE
                .iter()
                .rposition(|&b| b as usize <= len)
                .expect("len ≥ 3");
            let (code, bits) = fixed_code(257 + k as u32);
            w.put_code(code, bits);
            w.put(len as u32 - LENGTH_BASE[k], LENGTH_EXTRA[k]);
            w.put_code(dist_code, 5);
            i += len;
        } else {
            let (code, bits) = fixed_code(data[i] as u32);
            w.put_code(code, bits);
            i += 1;
        }
    }
    let (code, bits) = fixed_code(256);
    w.put_code(code, bits);
    w.finish()
}

fn adler32(bytes: &[u8]) -> u32 {
    let (mut a, mut b) = (1u32, 0u32);
    for chunk in bytes.chunks(5552) {
        for &x in chunk {
            a += x as u32;
            b += a;
        }
        a %= 65_521;
        b %= 65_521;
    }
    (b << 16) | a
}

/// A short label for an axis value.
fn tick_label(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if (1e-2..1e4).contains(&a) {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.1e}")
    }
}

/// "Nice" tick values covering `[lo, hi]`.
fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| span / s <= 6.0)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + 1e-9 * span {
        out.push(t);
        t += step;
    }
    out
}

const BLACK: Rgb = [0, 0, 0];
const GREY: Rgb = [200, 200, 200];

/// One curve of a [`line_plot`].
pub struct Series<'a> {
    /// Its legend.
    pub name: &'a str,
    /// Its colour.
    pub color: Rgb,
    /// `(x, y)` points (non-finite ones are skipped).
    pub points: Vec<(f64, f64)>,
}

/// A line plot with axes, ticks, labels and a legend; `log_y` plots `log10(y)`.
pub fn line_plot(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
    log_y: bool,
) -> Canvas {
    let (w, h) = (800i64, 500i64);
    let (left, right, top, bottom) = (90i64, 20i64, 40i64, 60i64);
    let mut c = Canvas::new(w as usize, h as usize);
    let map_y = |y: f64| if log_y { y.log10() } else { y };
    let pts: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|s| s.points.iter().map(|&(x, y)| (x, map_y(y))))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in &pts {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if pts.is_empty() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        (y0, y1) = (y0 - 0.5, y1 + 0.5);
    }
    let pad = 0.05 * (y1 - y0);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let px = |x: f64| left + ((x - x0) / (x1 - x0) * (w - left - right) as f64) as i64;
    let py = |y: f64| h - bottom - ((y - y0) / (y1 - y0) * (h - top - bottom) as f64) as i64;
    for t in ticks(x0, x1) {
        c.line((px(t), top), (px(t), h - bottom), GREY);
        let l = tick_label(t);
        c.text(
            px(t) - Canvas::text_width(&l, 1) / 2,
            h - bottom + 6,
            &l,
            1,
            BLACK,
        );
    }
    for t in ticks(y0, y1) {
        c.line((left, py(t)), (w - right, py(t)), GREY);
        let l = if log_y {
            tick_label(10f64.powf(t))
        } else {
            tick_label(t)
        };
        c.text(
            left - 6 - Canvas::text_width(&l, 1),
            py(t) - 3,
            &l,
            1,
            BLACK,
        );
    }
    c.line((left, h - bottom), (w - right, h - bottom), BLACK);
    c.line((left, top), (left, h - bottom), BLACK);
    c.text((w - Canvas::text_width(title, 2)) / 2, 10, title, 2, BLACK);
    c.text(
        (w - Canvas::text_width(x_label, 1)) / 2,
        h - 25,
        x_label,
        1,
        BLACK,
    );
    c.text(5, top - 14, y_label, 1, BLACK);
    for (k, s) in series.iter().enumerate() {
        let mut prev: Option<(i64, i64)> = None;
        for &(x, y) in &s.points {
            let y = map_y(y);
            if !(x.is_finite() && y.is_finite()) {
                prev = None;
                continue;
            }
            let p = (px(x), py(y));
            if let Some(q) = prev {
                c.line(q, p, s.color);
            }
            prev = Some(p);
        }
        let ly = top + 8 + 14 * k as i64;
        c.line(
            (w - right - 150, ly + 3),
            (w - right - 130, ly + 3),
            s.color,
        );
        c.text(w - right - 124, ly, s.name, 1, BLACK);
    }
    c
}

/// A colour for `t ∈ [0, 1]` on a blue → green → yellow → red ramp.
pub fn ramp(t: f64) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    let stops = [
        [40.0, 60.0, 200.0],
        [30.0, 170.0, 90.0],
        [230.0, 200.0, 30.0],
        [210.0, 30.0, 30.0],
    ];
    let s = t * 3.0;
    let i = (s.floor() as usize).min(2);
    let f = s - i as f64;
    std::array::from_fn(|c| (stops[i][c] * (1.0 - f) + stops[i + 1][c] * f) as u8)
}

/// Three orthographic views (x–y, x–z, z–y) of the canonical points (grey), the true
/// positions (black) and the predicted positions coloured by their L1 error on the
/// `ramp` from 0 to `max_error`.
pub fn three_views(
    title: &str,
    canonical: &[[f32; 3]],
    truth: &[[f32; 3]],
    predicted: &[[f32; 3]],
    max_error: f64,
) -> Canvas {
    let (panel, top, bottom) = (400i64, 40i64, 50i64);
    let mut c = Canvas::new((3 * panel) as usize, (panel + top + bottom) as usize);
    c.text(
        (3 * panel - Canvas::text_width(title, 2)) / 2,
        10,
        title,
        2,
        BLACK,
    );
    let all = canonical.iter().chain(truth).chain(predicted);
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    for p in all {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let span = (0..3).map(|k| hi[k] - lo[k]).fold(1e-6f32, f32::max) as f64;
    let views = [(0usize, 1usize, "X-Y"), (0, 2, "X-Z"), (2, 1, "Z-Y")];
    for (v, &(a, b, name)) in views.iter().enumerate() {
        let ox = v as i64 * panel;
        let to = |p: &[f32; 3]| {
            let u = (p[a] - lo[a]) as f64 / span;
            let w = (p[b] - lo[b]) as f64 / span;
            (
                ox + 20 + (u * (panel - 40) as f64) as i64,
                top + panel - 20 - (w * (panel - 40) as f64) as i64,
            )
        };
        c.line((ox, top), (ox, top + panel), GREY);
        c.text(ox + 8, top + 4, name, 1, BLACK);
        for p in canonical {
            let (x, y) = to(p);
            c.set(x, y, GREY);
        }
        for p in truth {
            let (x, y) = to(p);
            c.dot(x, y, 0, BLACK);
        }
        for (p, t) in predicted.iter().zip(truth) {
            let e: f64 = (0..3).map(|k| (p[k] - t[k]).abs() as f64).sum();
            let (x, y) = to(p);
            c.dot(x, y, 1, ramp(e / max_error.max(1e-12)));
        }
    }
    // The colour bar.
    let (bx, by) = (20i64, top + panel + 15);
    for i in 0..300 {
        let col = ramp(i as f64 / 299.0);
        c.line((bx + i, by), (bx + i, by + 10), col);
    }
    c.text(bx, by + 14, "0", 1, BLACK);
    let label = format!("L1 ERROR {}", tick_label(max_error));
    c.text(
        bx + 300 - Canvas::text_width(&label, 1),
        by + 14,
        &label,
        1,
        BLACK,
    );
    c.text(
        bx + 330,
        by,
        "GREY: CANONICAL  BLACK: TRUE  COLOURED: PREDICTED",
        1,
        BLACK,
    );
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deflate_runs_inflates_back() {
        use miniz_oxide::inflate::core::{DecompressorOxide, decompress, inflate_flags};
        let mut data = vec![255u8; 5000];
        data.extend((0..3000).map(|i| (i * 7 % 251) as u8));
        data.extend([10, 20, 30].repeat(400));
        data.extend([0, 1, 0, 1, 2]);
        let z = deflate_runs(&data);
        assert!(z.len() < data.len() / 2, "{} bytes", z.len());
        let mut out = vec![0u8; data.len()];
        let (status, _, n) = decompress(
            &mut Box::<DecompressorOxide>::default(),
            &z,
            &mut out,
            0,
            inflate_flags::TINFL_FLAG_USING_NON_WRAPPING_OUTPUT_BUF,
        );
        assert_eq!(status, miniz_oxide::inflate::TINFLStatus::Done);
        assert_eq!(&out[..n], &data[..]);
    }

    #[test]
    fn adler32_matches_the_reference_value() {
        assert_eq!(adler32(b"Wikipedia"), 0x11E6_0398);
    }

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        assert_eq!(ticks(0.0, 10.0), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        let t = ticks(0.013, 0.047);
        assert!(t.len() >= 3 && t[0] >= 0.013 && *t.last().unwrap() <= 0.047);
    }
}
