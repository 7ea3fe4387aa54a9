//! Monitor light: a monitor frame reduced to the network's light image.
//!
//! The model contract (`models/CONTRACT.md`) defines it: the frame as shown,
//! 8-bit sRGB decoded to linear light, box-averaged with area weights over
//! 16 rows × 32 columns; row 0 is the top of the screen, column 0 its left
//! edge as the user sees it. Python computes the same in
//! `train/lsyd/contract.py::light_from_frames`.

use std::path::Path;

use crate::frame::{AreaWeights, Frame, YuvMatrix};
use crate::parallel::beside;

pub const LIGHT_ROWS: usize = 16;
pub const LIGHT_COLS: usize = 32;
pub const LIGHT_LEN: usize = 3 * LIGHT_ROWS * LIGHT_COLS;

/// A light image: planar linear RGB, 3 × 16 × 32, values in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct Light(pub Vec<f32>);

/// Pixels of a frame from which its light is found on two threads: a few
/// ns a pixel on one thread (`paste_speed`'s "monitor light"), so a split
/// (about 20 µs, its last line) pays from a few tens of thousands.
const SPLIT_FROM: usize = 65_536;

/// Resolution of the table that decodes sRGB values that are not whole bytes (from YUV).
const DECODE_STEPS: usize = 4096;

/// The sRGB transfer function inverted: an sRGB value in [0, 1] as linear light.
pub fn srgb_to_linear(v: f32) -> f32 {
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
        let taps = ColumnTaps::new(frame.width);
        // Each row's sums into the light's columns; rows are independent until
        // they are summed into the light's rows, so large frames sum their two
        // halves on two threads, to the same floats.
        let mut rows = vec![[0f32; 3 * LIGHT_COLS]; frame.height];
        let sum_rows = |first: usize, rows: &mut [[f32; 3 * LIGHT_COLS]]| {
            let mut row = RowDecoder::new(frame);
            for (y, acc) in (first..).zip(rows) {
                row.decode(frame, y, t);
                taps.accumulate(&row.linear, acc);
            }
        };
        if frame.width * frame.height >= SPLIT_FROM {
            let mid = frame.height / 2;
            let (top, bottom) = rows.split_at_mut(mid);
            beside(|| sum_rows(mid, bottom), || sum_rows(0, top));
        } else {
            sum_rows(0, &mut rows);
        }
        light_of_rows(&rows)
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

/// The light from each frame row's sums into the light's columns
/// ([`ColumnTaps::accumulate`]): the rows averaged by area into the light's rows.
fn light_of_rows(rows: &[[f32; 3 * LIGHT_COLS]]) -> Light {
    let wy = AreaWeights::new(rows.len(), LIGHT_ROWS);
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

/// The frame columns each light column averages, with their weights: a run
/// of consecutive columns per light column, as [`AreaWeights`] gives them.
struct ColumnTaps {
    wx: AreaWeights,
}

impl ColumnTaps {
    fn new(width: usize) -> ColumnTaps {
        ColumnTaps {
            wx: AreaWeights::new(width, LIGHT_COLS),
        }
    }

    /// A row's linear RGB, weighted, summed into its light columns: planar
    /// RGB, [`LIGHT_COLS`] a channel. Each column's sum adds its terms in the
    /// order of the frame's columns, as adding each pixel into every column
    /// it feeds did, so the floats are the same; but the sums stay in
    /// registers, and six are built at once (two columns, three channels),
    /// so that each addition need not wait for the one before.
    fn accumulate(&self, linear: &[Vec<f32>; 3], acc: &mut [f32; 3 * LIGHT_COLS]) {
        const HALF: usize = LIGHT_COLS / 2;
        // A light column's weights, and the pixels they weigh of each channel.
        let column = |o: usize| {
            let weights = self.wx.weights[o].as_slice();
            let start = self.wx.start[o];
            (
                weights,
                linear.each_ref().map(|c| &c[start..][..weights.len()]),
            )
        };
        for o in 0..HALF {
            let ((lw, lp), (rw, rp)) = (column(o), column(o + HALF));
            let (mut l, mut r) = ([0f32; 3], [0f32; 3]);
            let both = lw.len().min(rw.len());
            for k in 0..both {
                for c in 0..3 {
                    l[c] += lw[k] * lp[c][k];
                    r[c] += rw[k] * rp[c][k];
                }
            }
            for k in both..lw.len() {
                for c in 0..3 {
                    l[c] += lw[k] * lp[c][k];
                }
            }
            for k in both..rw.len() {
                for c in 0..3 {
                    r[c] += rw[k] * rp[c][k];
                }
            }
            for c in 0..3 {
                acc[c * LIGHT_COLS + o] = l[c];
                acc[c * LIGHT_COLS + o + HALF] = r[c];
            }
        }
    }
}

/// `v.clamp(0.0, 1.0)` decoded by the fine table, at its nearest step (ties
/// away from zero, as `f32::round`, which is a call into the C library on
/// this build's baseline x86-64).
fn fine_to_linear(t: &Decode, v: f32) -> f32 {
    let scaled = v.clamp(0.0, 1.0) * DECODE_STEPS as f32;
    // Whole steps and the rest are exact below 2^23; NaN gives step 0, as a
    // cast of NaN does.
    let whole = scaled as usize;
    t.fine[whole + usize::from(scaled - whole as f32 >= 0.5)]
}

/// A frame's [`YuvMatrix`] with the quotients of every byte found once
/// ([`YuvMatrix::luma_quotient`], [`YuvMatrix::chroma_quotient`]).
struct YuvToRgb {
    matrix: YuvMatrix,
    luma: [f32; 256],
    chroma: [f32; 256],
}

impl YuvToRgb {
    fn new(m: &YuvMatrix) -> YuvToRgb {
        YuvToRgb {
            matrix: *m,
            luma: std::array::from_fn(|v| m.luma_quotient(v as f32)),
            chroma: std::array::from_fn(|v| m.chroma_quotient(v as f32)),
        }
    }
}

/// One row of a frame at a time as planar linear RGB, with what it needs
/// kept from row to row.
struct RowDecoder {
    /// The row's linear R, G and B.
    linear: [Vec<f32>; 3],
    /// A YUV row's quotients of Y, Cb and Cr per pixel, and the matrix's parts.
    quotients: [Vec<f32>; 3],
    yuv: Option<YuvToRgb>,
}

impl RowDecoder {
    fn new(frame: &Frame) -> RowDecoder {
        let row = || vec![0f32; frame.width];
        RowDecoder {
            linear: [row(), row(), row()],
            quotients: [row(), row(), row()],
            yuv: frame.format.is_yuv().then(|| YuvToRgb::new(&frame.matrix)),
        }
    }

    /// Linear RGB of every pixel of row `y` into `linear`.
    fn decode(&mut self, frame: &Frame, y: usize, t: &Decode) {
        let p0 = &frame.planes[0];
        let Some(m) = &self.yuv else {
            let (offsets, bpp) = frame.format.packed().expect("a packed RGB format");
            let row = &p0.data[y * p0.stride..][..frame.width * bpp];
            for (channel, off) in self.linear.iter_mut().zip(offsets) {
                for (v, pixel) in channel.iter_mut().zip(row.chunks_exact(bpp)) {
                    *v = t.bytes[pixel[off] as usize];
                }
            }
            return;
        };
        let [luma, cb, cr] = &mut self.quotients;
        for (q, &byte) in luma
            .iter_mut()
            .zip(&p0.data[y * p0.stride..][..frame.width])
        {
            *q = m.luma[byte as usize];
        }
        for (quotients, (plane, sub, bpp, byte)) in
            [cb, cr].into_iter().zip(frame.format.chroma_lanes())
        {
            let p = &frame.planes[plane];
            let samples = &p.data[(y / sub) * p.stride + byte..];
            match (sub, bpp) {
                (1, 1) => spread_chroma::<1, 1>(quotients, samples, &m.chroma),
                (2, 1) => spread_chroma::<2, 1>(quotients, samples, &m.chroma),
                (2, 2) => spread_chroma::<2, 2>(quotients, samples, &m.chroma),
                _ => unreachable!("chroma {sub}x subsampled, {bpp} bytes a sample"),
            }
        }
        let [r, g, b] = &mut self.linear;
        let [luma, cb, cr] = &self.quotients;
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            let done = unsafe { yuv_to_linear_avx2(m, t, [luma, cb, cr], [r, g, b]) };
            return yuv_to_linear(m, t, [luma, cb, cr], [r, g, b], done);
        }
        yuv_to_linear(m, t, [luma, cb, cr], [r, g, b], 0);
    }
}

/// A chroma channel's quotients over a row's pixels: each sample's over the
/// `SUB` pixels it covers; `samples` holds the channel's first byte and the
/// rest `BPP` bytes apart.
fn spread_chroma<const SUB: usize, const BPP: usize>(
    out: &mut [f32],
    samples: &[u8],
    quotients: &[f32; 256],
) {
    let mut samples = samples.iter().step_by(BPP);
    assert!(
        samples.len() >= out.len().div_ceil(SUB),
        "a chroma row shorter than its luma row"
    );
    let (whole, last) = out.as_chunks_mut::<SUB>();
    for (pixels, sample) in whole.iter_mut().zip(&mut samples) {
        *pixels = [quotients[*sample as usize]; SUB];
    }
    // An odd width's last sample covers one pixel.
    if !last.is_empty() {
        let sample = samples.next().expect("counted above");
        last.fill(quotients[*sample as usize]);
    }
}

/// Linear RGB of a row's YUV quotients, from pixel `from` on.
fn yuv_to_linear(
    m: &YuvToRgb,
    t: &Decode,
    [y, cb, cr]: [&[f32]; 3],
    [r, g, b]: [&mut [f32]; 3],
    from: usize,
) {
    for x in from..y.len() {
        let [red, green, blue] = m.matrix.rgb_of_quotients(y[x], cb[x], cr[x]);
        r[x] = fine_to_linear(t, red);
        g[x] = fine_to_linear(t, green);
        b[x] = fine_to_linear(t, blue);
    }
}

/// [`yuv_to_linear`] 8 pixels at a time, as many as fill whole vectors, the
/// fine table read by gathers; the same operations in the same order (no
/// fused multiply-adds), so the same floats. Returns the pixels done.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn yuv_to_linear_avx2(
    m: &YuvToRgb,
    t: &Decode,
    [y, cb, cr]: [&[f32]; 3],
    [r, g, b]: [&mut [f32]; 3],
) -> usize {
    use std::arch::x86_64::*;
    const LANES: usize = 8;
    let n = y
        .len()
        .min(cb.len())
        .min(cr.len())
        .min(r.len())
        .min(g.len())
        .min(b.len());
    let whole = n - n % LANES;
    // The constants as `rgb_of_quotients` computes them.
    let (kr, kb) = (m.matrix.kr, m.matrix.kb);
    let [red_cr, blue_cb, kr, kb, kg] =
        [2.0 * (1.0 - kr), 2.0 * (1.0 - kb), kr, kb, 1.0 - kr - kb].map(|v| _mm256_set1_ps(v));
    let (zero, one, half) = (
        _mm256_setzero_ps(),
        _mm256_set1_ps(1.0),
        _mm256_set1_ps(0.5),
    );
    let steps = _mm256_set1_ps(DECODE_STEPS as f32);
    debug_assert_eq!(t.fine.len(), DECODE_STEPS + 1);
    let fine = |v: __m256| {
        // The clamp: `max` gives its second operand, zero, for NaN (as the
        // clamp's step 0 does), and either zero ends at step 0.
        let scaled = _mm256_mul_ps(_mm256_min_ps(_mm256_max_ps(v, zero), one), steps);
        let whole = _mm256_cvttps_epi32(scaled);
        let rest = _mm256_sub_ps(scaled, _mm256_cvtepi32_ps(whole));
        // The comparison's mask is -1 where the rest reaches a half: one step up.
        let up = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GE_OQ>(rest, half));
        // SAFETY: `scaled` is in [0, DECODE_STEPS], so the steps are
        // 0..=DECODE_STEPS, and the table has DECODE_STEPS + 1 entries.
        unsafe { _mm256_i32gather_ps::<4>(t.fine.as_ptr(), _mm256_sub_epi32(whole, up)) }
    };
    for x in (0..whole).step_by(LANES) {
        // SAFETY: x + LANES <= whole <= every slice's length.
        unsafe {
            let [yv, cbv, crv] = [y, cb, cr].map(|s| _mm256_loadu_ps(s.as_ptr().add(x)));
            let red = _mm256_add_ps(yv, _mm256_mul_ps(red_cr, crv));
            let blue = _mm256_add_ps(yv, _mm256_mul_ps(blue_cb, cbv));
            let green = _mm256_div_ps(
                _mm256_sub_ps(
                    _mm256_sub_ps(yv, _mm256_mul_ps(kr, red)),
                    _mm256_mul_ps(kb, blue),
                ),
                kg,
            );
            _mm256_storeu_ps(r.as_mut_ptr().add(x), fine(red));
            _mm256_storeu_ps(g.as_mut_ptr().add(x), fine(green));
            _mm256_storeu_ps(b.as_mut_ptr().add(x), fine(blue));
        }
    }
    whole
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{ONE_FORMAT_OF_EACH_LAYOUT, OwnedFrame, test_noise};

    /// The light as first written, a pixel at a time through the frame's own
    /// accessors: what the fast [`Light::from_frame`] must give to the bit.
    fn reference_light(frame: &Frame) -> Light {
        let t = decode_tables();
        let wx = AreaWeights::new(frame.width, LIGHT_COLS);
        let mut col_taps: Vec<Vec<(usize, f32)>> = vec![Vec::new(); frame.width];
        for (o, (s, w)) in wx.start.iter().zip(&wx.weights).enumerate() {
            for (k, wk) in w.iter().enumerate() {
                col_taps[s + k].push((o, *wk));
            }
        }
        let fine = |v: f32| t.fine[(v.clamp(0.0, 1.0) * DECODE_STEPS as f32).round() as usize];
        let mut rows = vec![[0f32; 3 * LIGHT_COLS]; frame.height];
        for (y, acc) in rows.iter_mut().enumerate() {
            for (x, taps) in col_taps.iter().enumerate() {
                let p0 = &frame.planes[0];
                let rgb = match frame.format.packed() {
                    Some((offsets, bpp)) => {
                        offsets.map(|off| t.bytes[p0.data[y * p0.stride + x * bpp + off] as usize])
                    }
                    None => {
                        let (cb, cr) = frame.format.chroma_at(&frame.planes, x, y);
                        let luma = p0.data[y * p0.stride + x];
                        (frame.matrix.to_rgb(luma as f32, cb as f32, cr as f32)).map(fine)
                    }
                };
                for &(o, w) in taps {
                    for c in 0..3 {
                        acc[c * LIGHT_COLS + o] += w * rgb[c];
                    }
                }
            }
        }
        light_of_rows(&rows)
    }

    #[test]
    fn the_light_is_the_reference_to_the_bit_in_every_format_and_size() {
        let mut noise = test_noise(0x2545_f491);
        // Wider and narrower than the light, odd sizes, cells of whole and
        // fractional columns; limited and full range.
        let sizes = [(256, 144), (1, 1), (3, 2), (33, 17), (101, 57), (640, 360)];
        for format in ONE_FORMAT_OF_EACH_LAYOUT {
            for (w, h) in sizes {
                let full_range = YuvMatrix {
                    limited: false,
                    ..YuvMatrix::BT601_LIMITED
                };
                // Rows padded, and not: the last row then ends the buffer.
                for (matrix, padding) in [(YuvMatrix::BT709_LIMITED, 3), (full_range, 0)] {
                    let owned = OwnedFrame::new(format, (w, h), padding, matrix, &mut noise);
                    let (fast, plain) = (
                        Light::from_frame(&owned.frame()),
                        reference_light(&owned.frame()),
                    );
                    let bits = |l: &Light| l.0.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    assert_eq!(
                        bits(&fast),
                        bits(&plain),
                        "{format:?} {w}x{h} {matrix:?} {padding}"
                    );
                }
            }
        }
    }

    /// The vector build against the plain one on quotients built to reach
    /// the decoding table's ties: with Cb and Cr at zero, red and blue are Y.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_vector_conversion_is_the_plain_one_to_the_bit_at_ties() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 on this CPU: the vector build is not used");
            return;
        }
        let t = decode_tables();
        let steps = DECODE_STEPS as f32;
        let mut luma = vec![-0.5, 0.0, -0.0, 1.0, 1.5, f32::NAN, 0.5 / steps];
        for k in [0.0f32, 1.0, 7.0, 1000.0, 2047.0, 4095.0] {
            let tie = (k + 0.5) / steps;
            luma.extend([tie, tie.next_down(), tie.next_up()]);
        }
        // Those with no chroma, then as many more as fill the vectors, and a
        // vector's worth of ordinary pixels with chroma.
        let built = luma.len();
        let n = built.next_multiple_of(8) + 8;
        luma.resize(n, 0.25);
        let m = YuvToRgb::new(&YuvMatrix::BT709_LIMITED);
        let mut noise = test_noise(0x9e37_79b9);
        let mut chroma = || -> Vec<f32> {
            (0..n)
                .map(|i| {
                    if i < built {
                        0.0
                    } else {
                        m.chroma[noise() as usize]
                    }
                })
                .collect()
        };
        let (cb, cr) = (chroma(), chroma());
        let mut plain = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
        let mut vector = plain.clone();
        let [r, g, b] = &mut plain;
        yuv_to_linear(&m, t, [&luma, &cb, &cr], [r, g, b], 0);
        let [r, g, b] = &mut vector;
        // SAFETY: the CPU has AVX2, checked above.
        let done = unsafe { yuv_to_linear_avx2(&m, t, [&luma, &cb, &cr], [r, g, b]) };
        assert_eq!(done, n);
        let bits = |c: &Vec<f32>| c.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        for (c, (p, v)) in plain.iter().zip(&vector).enumerate() {
            assert_eq!(bits(p), bits(v), "channel {c}");
        }
    }

    #[test]
    fn the_fine_decoding_rounds_as_f32_round_does() {
        let t = decode_tables();
        // Ties, values just either side of them, the ends and beyond, NaN.
        let steps = DECODE_STEPS as f32;
        let mut values = vec![0.0, 1.0, -0.5, 2.0, f32::NAN, 0.5 / steps, 1.5 / steps];
        for k in [1.0f32, 7.0, 2047.0, 4095.0] {
            let tie = (k + 0.5) / steps;
            values.extend([
                tie,
                f32::from_bits(tie.to_bits() - 1),
                f32::from_bits(tie.to_bits() + 1),
            ]);
        }
        for v in values {
            let rounded = t.fine[(v.clamp(0.0, 1.0) * steps).round() as usize];
            assert_eq!(fine_to_linear(t, v).to_bits(), rounded.to_bits(), "{v}");
        }
    }

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
