//! PNG versions of the report charts: a small RGB [`Canvas`] (lines, filled polygons with alpha,
//! 8×8 bitmap text from `font8x8`) drawn in the same layout as the SVG charts of
//! [`crate::report`], encoded with `png`. People paste PNGs into slides and issues; SVG stays the
//! primary, exact format.

/// An RGB image, white to start with.
#[derive(Debug, Clone)]
pub struct Canvas {
    pub width: usize,
    pub height: usize,
    pixels: Vec<[u8; 3]>,
}

/// Where a text's anchor point sits on it (as SVG's `text-anchor`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Anchor {
    Start,
    Middle,
    End,
}

/// Width and height of one glyph cell at scale 1 (px).
const GLYPH: usize = 8;

impl Canvas {
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            pixels: vec![[255; 3]; width * height],
        }
    }

    /// The pixel at (`x`, `y`), if inside.
    pub fn pixel(&self, x: usize, y: usize) -> Option<[u8; 3]> {
        (x < self.width && y < self.height).then(|| self.pixels[y * self.width + x])
    }

    /// Blends `rgb` over the pixel with opacity `alpha` (outside pixels are ignored).
    fn blend(&mut self, x: i64, y: i64, rgb: [u8; 3], alpha: f32) {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            return;
        }
        let p = &mut self.pixels[y as usize * self.width + x as usize];
        for (c, n) in p.iter_mut().zip(rgb) {
            *c = (*c as f32 * (1.0 - alpha) + n as f32 * alpha).round() as u8;
        }
    }

    /// A straight line `width` px wide (non-finite ends are skipped).
    pub fn line(&mut self, a: (f64, f64), b: (f64, f64), rgb: [u8; 3], width: f64) {
        if !(a.0.is_finite() && a.1.is_finite() && b.0.is_finite() && b.1.is_finite()) {
            return;
        }
        let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        let steps = (len * 2.0).ceil().max(1.0) as usize;
        let r = (width / 2.0).max(0.5);
        let ri = r.ceil() as i64;
        for s in 0..=steps {
            let t = s as f64 / steps as f64;
            let (x, y) = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
            for dy in -ri..=ri {
                for dx in -ri..=ri {
                    let (px, py) = (x.round() as i64 + dx, y.round() as i64 + dy);
                    let d = ((px as f64 - x).powi(2) + (py as f64 - y).powi(2)).sqrt();
                    if d <= r {
                        self.set(px, py, rgb);
                    }
                }
            }
        }
    }

    fn set(&mut self, x: i64, y: i64, rgb: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            self.pixels[y as usize * self.width + x as usize] = rgb;
        }
    }

    /// A polyline through the finite points.
    pub fn polyline(&mut self, points: &[(f64, f64)], rgb: [u8; 3], width: f64) {
        for w in points.windows(2) {
            self.line(w[0], w[1], rgb, width);
        }
    }

    /// Fills a polygon (even-odd rule, pixel centres) with `rgb` at opacity `alpha`.
    pub fn fill_polygon(&mut self, points: &[(f64, f64)], rgb: [u8; 3], alpha: f32) {
        let pts: Vec<(f64, f64)> = points
            .iter()
            .copied()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .collect();
        if pts.len() < 3 {
            return;
        }
        let y_min = pts
            .iter()
            .map(|p| p.1)
            .fold(f64::INFINITY, f64::min)
            .max(0.0);
        let y_max = pts
            .iter()
            .map(|p| p.1)
            .fold(f64::NEG_INFINITY, f64::max)
            .min(self.height as f64 - 1.0);
        let mut xs = Vec::new();
        for y in y_min.floor() as i64..=y_max.ceil() as i64 {
            let yc = y as f64 + 0.5;
            xs.clear();
            for i in 0..pts.len() {
                let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
                if (a.1 <= yc) != (b.1 <= yc) {
                    xs.push(a.0 + (yc - a.1) / (b.1 - a.1) * (b.0 - a.0));
                }
            }
            xs.sort_by(f64::total_cmp);
            for pair in xs.chunks(2) {
                if let [x0, x1] = pair {
                    for x in (x0 - 0.5).ceil() as i64..=(x1 - 0.5).floor() as i64 {
                        self.blend(x, y, rgb, alpha);
                    }
                }
            }
        }
    }

    /// Width of `text` in px at `scale`.
    pub fn text_width(text: &str, scale: usize) -> usize {
        text.chars().count() * GLYPH * scale
    }

    /// Horizontal text; `(x, y)` is the anchor on the baseline's line through the glyph centres.
    pub fn text(&mut self, x: f64, y: f64, text: &str, rgb: [u8; 3], scale: usize, anchor: Anchor) {
        let w = Self::text_width(text, scale) as f64;
        let x0 = match anchor {
            Anchor::Start => x,
            Anchor::Middle => x - w / 2.0,
            Anchor::End => x - w,
        }
        .round() as i64;
        let y0 = (y - (GLYPH * scale) as f64 / 2.0).round() as i64;
        for (k, c) in text.chars().enumerate() {
            let glyph = glyph(c);
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..GLYPH {
                    if bits >> col & 1 == 1 {
                        for sy in 0..scale {
                            for sx in 0..scale {
                                self.set(
                                    x0 + ((k * GLYPH + col) * scale + sx) as i64,
                                    y0 + (row * scale + sy) as i64,
                                    rgb,
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// Text rotated a quarter turn anticlockwise (reads bottom to top), centred on (`x`, `y`).
    pub fn text_vertical(&mut self, x: f64, y: f64, text: &str, rgb: [u8; 3]) {
        let len = Self::text_width(text, 1) as i64;
        let (x0, y0) = (
            x.round() as i64 - GLYPH as i64 / 2,
            y.round() as i64 + len / 2,
        );
        for (k, c) in text.chars().enumerate() {
            for (row, bits) in glyph(c).iter().enumerate() {
                for col in 0..GLYPH {
                    if bits >> col & 1 == 1 {
                        // Glyph (col, row) → canvas (row, -col) along the rotated baseline.
                        self.set(x0 + row as i64, y0 - (k * GLYPH + col) as i64, rgb);
                    }
                }
            }
        }
    }

    /// The image as PNG bytes (8-bit RGB).
    pub fn to_png(&self) -> Vec<u8> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.width as u32, self.height as u32);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            // Writing into a Vec cannot fail short of allocation failure.
            let mut writer = enc.write_header().expect("PNG header into memory");
            let data: Vec<u8> = self.pixels.iter().flatten().copied().collect();
            writer
                .write_image_data(&data)
                .expect("PNG data into memory");
        }
        out
    }
}

/// The 8×8 glyph of `c` (row-major, bit 0 = leftmost pixel); `?` for characters outside ASCII.
fn glyph(c: char) -> [u8; 8] {
    let table = &font8x8::legacy::BASIC_LEGACY;
    let fallback = match c {
        '—' | '–' => '-',
        '±' => '+',
        '×' => 'x',
        '·' => '.',
        c if c.is_ascii() => c,
        _ => '?',
    };
    table[fallback as usize]
}

/// `#rrggbb` as RGB (black when malformed).
pub fn parse_hex(colour: &str) -> [u8; 3] {
    let hex = colour.trim_start_matches('#');
    let byte = |i: usize| {
        hex.get(i..i + 2)
            .and_then(|h| u8::from_str_radix(h, 16).ok())
            .unwrap_or(0)
    };
    if hex.len() == 6 {
        [byte(0), byte(2), byte(4)]
    } else {
        [0, 0, 0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_polygons_and_text_land_where_they_are_drawn() {
        let mut c = Canvas::new(40, 30);
        c.line((2.0, 5.0), (30.0, 5.0), [255, 0, 0], 1.0);
        assert_eq!(c.pixel(15, 5), Some([255, 0, 0]));
        assert_eq!(c.pixel(15, 9), Some([255, 255, 255]));
        c.fill_polygon(
            &[(10.0, 10.0), (20.0, 10.0), (20.0, 20.0), (10.0, 20.0)],
            [0, 0, 255],
            0.5,
        );
        assert_eq!(c.pixel(15, 15), Some([128, 128, 255]));
        assert_eq!(c.pixel(25, 15), Some([255, 255, 255]));
        let mut t = Canvas::new(40, 20);
        t.text(20.0, 10.0, "8", [0, 0, 0], 1, Anchor::Middle);
        let dark = (0..40)
            .flat_map(|x| (0..20).map(move |y| (x, y)))
            .filter(|&(x, y)| t.pixel(x, y) == Some([0, 0, 0]))
            .count();
        assert!(dark > 10, "the glyph is drawn ({dark} px)");
        assert!(t.pixel(2, 2) == Some([255, 255, 255]));
    }

    #[test]
    fn png_round_trips_through_a_decoder() {
        let mut c = Canvas::new(16, 8);
        c.line((0.0, 3.0), (15.0, 3.0), [10, 200, 30], 1.0);
        let bytes = c.to_png();
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (16, 8));
        let at = |x: usize, y: usize| &buf[(y * 16 + x) * 3..(y * 16 + x) * 3 + 3];
        assert_eq!(at(7, 3), [10, 200, 30]);
        assert_eq!(at(7, 6), [255, 255, 255]);
        assert_eq!(parse_hex("#1f77b4"), [0x1f, 0x77, 0xb4]);
    }
}
