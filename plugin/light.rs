//! Monitor light: a monitor frame reduced to the network's light image.
//!
//! The model contract (`models/CONTRACT.md`) defines it: the frame as shown,
//! 8-bit sRGB decoded to linear light, box-averaged with area weights over
//! 16 rows × 32 columns; row 0 is the top of the screen, column 0 its left
//! edge as the user sees it. Python computes the same in
//! `train/lsyd/contract.py::light_from_frames`.

use std::path::Path;

use crate::frame::{AreaWeights, Frame, PixelFormat};

pub const LIGHT_ROWS: usize = 16;
pub const LIGHT_COLS: usize = 32;
pub const LIGHT_LEN: usize = 3 * LIGHT_ROWS * LIGHT_COLS;

/// A light image: planar linear RGB, 3 × 16 × 32, values in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct Light(pub Vec<f32>);

/// Resolution of the table that decodes sRGB values that are not whole bytes (from YUV).
const DECODE_STEPS: usize = 4096;

fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// An 8-bit sRGB value as linear light in [0, 1] (from a table built once).
pub fn srgb_byte_to_linear(v: u8) -> f32 {
    decode_tables().bytes[v as usize]
}

/// The sRGB transfer function: linear light in [0, 1] to an 8-bit value.
pub fn linear_to_srgb_byte(v: f32) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

struct Decode {
    bytes: [f32; 256],
    fine: Vec<f32>,
}

fn decode_tables() -> &'static Decode {
    static TABLES: std::sync::OnceLock<Decode> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| Decode {
        bytes: std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)),
        fine: (0..=DECODE_STEPS)
            .map(|i| srgb_to_linear(i as f32 / DECODE_STEPS as f32))
            .collect(),
    })
}

impl Light {
    pub fn uniform(value: [f32; 3]) -> Light {
        let n = LIGHT_ROWS * LIGHT_COLS;
        Light(
            (0..3)
                .flat_map(|c| std::iter::repeat_n(value[c], n))
                .collect(),
        )
    }

    /// The light of a monitor frame of any supported format and size.
    pub fn from_frame(frame: &Frame) -> Light {
        let t = decode_tables();
        let wx = AreaWeights::new(frame.width, LIGHT_COLS);
        let wy = AreaWeights::new(frame.height, LIGHT_ROWS);
        // Which output columns each input column feeds, with which weights: at most
        // two for frames wider than the light, more for narrower ones.
        let mut col_taps: Vec<Vec<(usize, f32)>> = vec![Vec::new(); frame.width];
        for (o, (s, w)) in wx.start.iter().zip(&wx.weights).enumerate() {
            for (k, wk) in w.iter().enumerate() {
                col_taps[s + k].push((o, *wk));
            }
        }
        let mut rows = vec![[0f32; 3 * LIGHT_COLS]; frame.height];
        let mut linear = vec![[0f32; 3]; frame.width];
        for (y, acc) in rows.iter_mut().enumerate() {
            decode_row(frame, y, t, &mut linear);
            for (x, rgb) in linear.iter().enumerate() {
                for &(o, w) in &col_taps[x] {
                    for c in 0..3 {
                        acc[c * LIGHT_COLS + o] += w * rgb[c];
                    }
                }
            }
        }
        let mut out = vec![0f32; LIGHT_LEN];
        for (r, (s, w)) in wy.start.iter().zip(&wy.weights).enumerate() {
            for (k, wk) in w.iter().enumerate() {
                for c in 0..3 {
                    for col in 0..LIGHT_COLS {
                        out[(c * LIGHT_ROWS + r) * LIGHT_COLS + col] +=
                            wk * rows[s + k][c * LIGHT_COLS + col];
                    }
                }
            }
        }
        Light(out)
    }

    /// The light of a PNG image of monitor content (a target light).
    pub fn from_png(path: &Path) -> Result<Light, String> {
        let file = std::fs::File::open(path)
            .map_err(|e| format!("cannot open target image {}: {e}", path.display()))?;
        let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
        decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
        let mut reader = decoder
            .read_info()
            .map_err(|e| format!("{} is not a PNG image: {e}", path.display()))?;
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader
            .next_frame(&mut buf)
            .map_err(|e| format!("cannot decode {}: {e}", path.display()))?;
        let (w, h) = (info.width as usize, info.height as usize);
        let channels = match info.color_type {
            png::ColorType::Rgb => 3,
            png::ColorType::Rgba => 4,
            png::ColorType::Grayscale => 1,
            png::ColorType::GrayscaleAlpha => 2,
            png::ColorType::Indexed => {
                return Err(format!(
                    "{}: palette images are not supported",
                    path.display()
                ));
            }
        };
        let rgb: Vec<u8> = buf[..w * h * channels]
            .chunks_exact(channels)
            .flat_map(|p| {
                if channels >= 3 {
                    [p[0], p[1], p[2]]
                } else {
                    [p[0]; 3]
                }
            })
            .collect();
        Ok(Light::from_frame(&Frame::packed_rgb(&rgb, w, h)))
    }

    /// The light as an 8-bit sRGB image, packed RGB, each cell a `scale` × `scale`
    /// square: (32 × scale) × (16 × scale) pixels.
    pub fn to_rgb_image(&self, scale: usize) -> Vec<u8> {
        let (w, h) = (LIGHT_COLS * scale, LIGHT_ROWS * scale);
        let n = LIGHT_ROWS * LIGHT_COLS;
        let mut out = vec![0u8; w * h * 3];
        for (i, pixel) in out.chunks_exact_mut(3).enumerate() {
            let cell = (i / w / scale) * LIGHT_COLS + (i % w) / scale;
            for (c, v) in pixel.iter_mut().enumerate() {
                *v = linear_to_srgb_byte(self.0[c * n + cell]);
            }
        }
        out
    }

    /// Mean absolute difference to another light.
    pub fn distance(&self, other: &Light) -> f32 {
        self.0
            .iter()
            .zip(&other.0)
            .map(|(a, b)| (a - b).abs())
            .sum::<f32>()
            / LIGHT_LEN as f32
    }

    pub fn is_finite(&self) -> bool {
        self.0.iter().all(|v| v.is_finite())
    }
}

/// Linear RGB of every pixel of row `y`.
fn decode_row(frame: &Frame, y: usize, t: &Decode, out: &mut [[f32; 3]]) {
    let fine = |v: f32| t.fine[(v.clamp(0.0, 1.0) * DECODE_STEPS as f32).round() as usize];
    let p0 = &frame.planes[0];
    match frame.format {
        PixelFormat::I420 | PixelFormat::Nv12 | PixelFormat::Y444 => {
            let yrow = &p0.data[y * p0.stride..];
            for (x, o) in out.iter_mut().enumerate() {
                let (cb, cr) = frame.format.chroma_at(&frame.planes, x, y);
                let rgb = frame.matrix.to_rgb(yrow[x] as f32, cb as f32, cr as f32);
                *o = rgb.map(fine);
            }
        }
        format => {
            let (offsets, bpp) = format.packed().expect("a packed RGB format");
            let row = &p0.data[y * p0.stride..];
            for (x, o) in out.iter_mut().enumerate() {
                *o = offsets.map(|off| t.bytes[row[x * bpp + off] as usize]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_image_round_trips_through_its_srgb_bytes() {
        let mut light = Light::uniform([0.0, 0.5, 1.0]);
        light.0[0] = 0.25; // top-left cell's red
        let img = light.to_rgb_image(2);
        assert_eq!(img.len(), 64 * 32 * 3);
        let back = Light::from_frame(&Frame::packed_rgb(&img, 64, 32));
        assert!(back.distance(&light) < 0.003, "{}", back.distance(&light));
        assert!((back.0[0] - 0.25).abs() < 0.003 && back.0[1].abs() < 1e-6);
    }

    #[test]
    fn white_frame_is_unit_light() {
        let data = vec![255u8; 100 * 50 * 3];
        let l = Light::from_frame(&Frame::packed_rgb(&data, 100, 50));
        assert!(l.0.iter().all(|v| (v - 1.0).abs() < 1e-5));
    }

    #[test]
    fn screen_left_is_column_zero_and_top_is_row_zero() {
        let (w, h) = (64, 32);
        let mut data = vec![0u8; w * h * 3];
        for y in 0..h / 2 {
            for x in 0..w / 2 {
                data[(y * w + x) * 3] = 255;
            }
        }
        let l = Light::from_frame(&Frame::packed_rgb(&data, w, h));
        let red = |r: usize, c: usize| l.0[r * LIGHT_COLS + c];
        assert!((red(0, 0) - 1.0).abs() < 1e-5);
        assert!(red(LIGHT_ROWS - 1, LIGHT_COLS - 1).abs() < 1e-6);
    }

    #[test]
    fn frames_narrower_than_the_light_fill_every_cell() {
        // A 1x1 white frame and a 3x2 one: every cell sees the pixel it lies in.
        let l = Light::from_frame(&Frame::packed_rgb(&[255, 255, 255], 1, 1));
        assert!(l.0.iter().all(|v| (v - 1.0).abs() < 1e-5));
        let mut data = vec![0u8; 3 * 2 * 3];
        data[2 * 3] = 255; // top-right pixel red
        let l = Light::from_frame(&Frame::packed_rgb(&data, 3, 2));
        let red = |r: usize, c: usize| l.0[r * LIGHT_COLS + c];
        assert!((red(0, LIGHT_COLS - 1) - 1.0).abs() < 1e-5);
        assert!(red(0, 0).abs() < 1e-6 && red(LIGHT_ROWS - 1, LIGHT_COLS - 1).abs() < 1e-6);
    }

    #[test]
    fn fractional_cells_average_by_area() {
        // 48 columns into 32 cells: each cell covers 1.5 columns.
        let (w, h) = (48, 16);
        let mut data = vec![0u8; w * h * 3];
        for y in 0..h {
            data[(y * w) * 3 + 1] = 255; // column 0 green
        }
        let l = Light::from_frame(&Frame::packed_rgb(&data, w, h));
        let green = |c: usize| l.0[LIGHT_ROWS * LIGHT_COLS + c];
        assert!((green(0) - 1.0 / 1.5).abs() < 1e-5, "{}", green(0));
        assert!(green(1).abs() < 1e-6);
    }
}
