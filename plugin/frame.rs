//! Raw video frames without GStreamer: formats, plane views, colour matrices,
//! the face crop, and putting a lighting change back into a frame.
//!
//! The network sees a square crop resampled to its resolution. Its output goes
//! back as a lighting change, not as an upscaled image: per RGB channel a
//! smooth gain `g = (R + ε) / (I + ε)` of the network's relit image `R` over its
//! input `I` ([`change`]), and the frame becomes `(v' + ε) = g↑ · (v + ε)`, `↑` a bilinear
//! upsampling to the frame. The frame keeps its own detail and takes its
//! lighting from the network. The gain extends beyond the crop and fades out
//! round the face ([`gain_field`]), so the change has no edge. YUV is an affine
//! function of RGB, so the per-channel gains are an affine map of each pixel's
//! Y, U and V, applied to the planes directly: a YUV frame is never converted
//! as a whole.

use std::ops::Range;

use crate::parallel::beside;

/// Pixel layouts the element handles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PixelFormat {
    I420,
    Nv12,
    Y444,
    Rgba,
    Bgra,
    Rgbx,
    Bgrx,
    Rgb,
    Bgr,
}

/// One plane's part in the crop and the paste, which walk each plane once.
#[derive(Clone, Copy, Debug)]
struct Pass {
    plane: usize,
    /// Frame pixels one of the plane's pixels covers in each direction.
    subsample: usize,
    /// Per byte of one of the plane's pixels, the channel it holds (0-2: R, G,
    /// B or Y, Cb, Cr), `None` for padding.
    lanes: &'static [Option<usize>],
}

impl Pass {
    const fn new(plane: usize, subsample: usize, lanes: &'static [Option<usize>]) -> Pass {
        Pass {
            plane,
            subsample,
            lanes,
        }
    }
}

impl PixelFormat {
    /// The layout of every format, in the order the planes are walked.
    fn passes(self) -> &'static [Pass] {
        const Y: Pass = Pass::new(0, 1, &[Some(0)]);
        const I420: &[Pass] = &[Y, Pass::new(1, 2, &[Some(1)]), Pass::new(2, 2, &[Some(2)])];
        const NV12: &[Pass] = &[Y, Pass::new(1, 2, &[Some(1), Some(2)])];
        const Y444: &[Pass] = &[Y, Pass::new(1, 1, &[Some(1)]), Pass::new(2, 1, &[Some(2)])];
        const RGBX: &[Pass] = &[Pass::new(0, 1, &[Some(0), Some(1), Some(2), None])];
        const BGRX: &[Pass] = &[Pass::new(0, 1, &[Some(2), Some(1), Some(0), None])];
        const RGB: &[Pass] = &[Pass::new(0, 1, &[Some(0), Some(1), Some(2)])];
        const BGR: &[Pass] = &[Pass::new(0, 1, &[Some(2), Some(1), Some(0)])];
        match self {
            PixelFormat::I420 => I420,
            PixelFormat::Nv12 => NV12,
            PixelFormat::Y444 => Y444,
            PixelFormat::Rgba | PixelFormat::Rgbx => RGBX,
            PixelFormat::Bgra | PixelFormat::Bgrx => BGRX,
            PixelFormat::Rgb => RGB,
            PixelFormat::Bgr => BGR,
        }
    }

    /// Byte offsets of R, G and B and bytes per pixel, for packed RGB formats.
    pub(crate) fn packed(self) -> Option<([usize; 3], usize)> {
        match self.passes() {
            [pass] => {
                let offset = |c| pass.lanes.iter().position(|&l| l == Some(c));
                Some((
                    [0, 1, 2].map(|c| offset(c).expect("R, G and B")),
                    pass.lanes.len(),
                ))
            }
            _ => None,
        }
    }

    /// Cb and Cr of frame pixel (x, y) of a YUV frame: the plain read that the
    /// tests hold the faster readers (by [`PixelFormat::chroma_lanes`]) to.
    #[cfg(test)]
    pub(crate) fn chroma_at(self, planes: &[Plane; 3], x: usize, y: usize) -> (u8, u8) {
        assert!(self.is_yuv(), "{self:?} has no chroma");
        let mut cbcr = [0; 2];
        for pass in &self.passes()[1..] {
            let p = &planes[pass.plane];
            let (sub, bpp) = (pass.subsample, pass.lanes.len());
            let pixel = (y / sub) * p.stride + (x / sub) * bpp;
            for (b, lane) in pass.lanes.iter().enumerate() {
                if let Some(c) = *lane {
                    cbcr[c - 1] = p.data[pixel + b];
                }
            }
        }
        (cbcr[0], cbcr[1])
    }

    /// Where [`PixelFormat::chroma_at`] reads Cb and Cr: per channel its plane,
    /// the subsampling, the bytes a plane pixel and the byte within it; for code
    /// that reads many pixels and works out their offsets once.
    pub(crate) fn chroma_lanes(self) -> [(usize, usize, usize, usize); 2] {
        assert!(self.is_yuv(), "{self:?} has no chroma");
        let mut lanes = [(0, 1, 1, 0); 2];
        for pass in &self.passes()[1..] {
            for (b, lane) in pass.lanes.iter().enumerate() {
                if let Some(c) = *lane {
                    lanes[c - 1] = (pass.plane, pass.subsample, pass.lanes.len(), b);
                }
            }
        }
        lanes
    }

    pub fn is_yuv(self) -> bool {
        self.packed().is_none()
    }
}

/// The Y'CbCr matrix and range of a YUV stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YuvMatrix {
    pub kr: f32,
    pub kb: f32,
    /// Limited ("TV") range: Y in [16, 235], chroma in [16, 240].
    pub limited: bool,
}

impl YuvMatrix {
    pub const BT601_LIMITED: YuvMatrix = YuvMatrix {
        kr: 0.299,
        kb: 0.114,
        limited: true,
    };
    pub const BT709_LIMITED: YuvMatrix = YuvMatrix {
        kr: 0.2126,
        kb: 0.0722,
        limited: true,
    };

    fn scales(&self) -> (f32, f32, f32) {
        // (luma offset, luma scale, chroma scale), in units of 1/255.
        if self.limited {
            (16.0, 219.0, 224.0)
        } else {
            (0.0, 255.0, 255.0)
        }
    }

    /// 8-bit Y, Cb, Cr (as f32) to RGB in [0, 1], not clamped.
    pub fn to_rgb(&self, y: f32, cb: f32, cr: f32) -> [f32; 3] {
        self.rgb_of_quotients(
            self.luma_quotient(y),
            self.chroma_quotient(cb),
            self.chroma_quotient(cr),
        )
    }

    /// Y as a share of its range: the first step of [`YuvMatrix::to_rgb`],
    /// which depends on Y alone (for code that finds it once a byte).
    pub(crate) fn luma_quotient(&self, y: f32) -> f32 {
        let (yo, ys, _) = self.scales();
        (y - yo) / ys
    }

    /// Cb or Cr as a share of its range, about its middle.
    pub(crate) fn chroma_quotient(&self, c: f32) -> f32 {
        let (_, _, cs) = self.scales();
        (c - 128.0) / cs
    }

    /// The rest of [`YuvMatrix::to_rgb`], from the three quotients.
    pub(crate) fn rgb_of_quotients(&self, y: f32, cb: f32, cr: f32) -> [f32; 3] {
        let kg = 1.0 - self.kr - self.kb;
        let r = y + 2.0 * (1.0 - self.kr) * cr;
        let b = y + 2.0 * (1.0 - self.kb) * cb;
        let g = (y - self.kr * r - self.kb * b) / kg;
        [r, g, b]
    }

    /// RGB in [0, 1] to 8-bit Y, Cb, Cr as f32 (not rounded or clamped).
    pub fn from_rgb(&self, rgb: [f32; 3]) -> [f32; 3] {
        let (yo, ys, cs) = self.scales();
        let y = self.kr * rgb[0] + (1.0 - self.kr - self.kb) * rgb[1] + self.kb * rgb[2];
        let cb = (rgb[2] - y) / (2.0 * (1.0 - self.kb));
        let cr = (rgb[0] - y) / (2.0 * (1.0 - self.kr));
        [yo + ys * y, 128.0 + cs * cb, 128.0 + cs * cr]
    }
}

/// One plane: its bytes and row stride.
#[derive(Clone, Copy, Debug)]
pub struct Plane<'a> {
    pub data: &'a [u8],
    pub stride: usize,
}

/// A read-only frame.
#[derive(Clone, Copy, Debug)]
pub struct Frame<'a> {
    pub format: PixelFormat,
    pub width: usize,
    pub height: usize,
    pub planes: [Plane<'a>; 3],
    /// Used for YUV formats only.
    pub matrix: YuvMatrix,
}

/// A frame that owns its planes, each row `padding` bytes longer than its
/// pixels: for code that makes frames without GStreamer (tests, benchmarks).
#[derive(Clone)]
pub struct OwnedFrame {
    pub format: PixelFormat,
    pub width: usize,
    pub height: usize,
    /// Each plane's bytes and stride.
    pub planes: Vec<(Vec<u8>, usize)>,
    pub matrix: YuvMatrix,
}

/// Deterministic noise bytes from `seed` (xorshift32: cheap, no dependency),
/// for tests that fill frames with every kind of value.
#[cfg(test)]
pub(crate) fn test_noise(seed: u32) -> impl FnMut() -> u8 {
    let mut state = seed | 1;
    move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state >> 24) as u8
    }
}

/// One format of each layout, for tests that walk them all: planar and
/// semi-planar YUV with subsampled chroma, planar YUV without, packed RGB with
/// and without padding.
#[cfg(test)]
pub(crate) const ONE_FORMAT_OF_EACH_LAYOUT: [PixelFormat; 5] = [
    PixelFormat::I420,
    PixelFormat::Nv12,
    PixelFormat::Y444,
    PixelFormat::Bgrx,
    PixelFormat::Rgb,
];

impl OwnedFrame {
    /// A frame of `format` whose bytes, padding included, come from `fill` in order.
    pub fn new(
        format: PixelFormat,
        (width, height): (usize, usize),
        padding: usize,
        matrix: YuvMatrix,
        mut fill: impl FnMut() -> u8,
    ) -> OwnedFrame {
        let (cw, ch) = (width.div_ceil(2), height.div_ceil(2));
        let rows = match (format.packed(), format) {
            (Some((_, bpp)), _) => vec![(bpp * width, height)],
            (None, PixelFormat::I420) => vec![(width, height), (cw, ch), (cw, ch)],
            (None, PixelFormat::Nv12) => vec![(width, height), (2 * cw, ch)],
            (None, _) => vec![(width, height); 3],
        };
        let planes = rows
            .into_iter()
            .map(|(bytes, rows)| {
                let stride = bytes + padding;
                ((0..stride * rows).map(|_| fill()).collect(), stride)
            })
            .collect();
        OwnedFrame {
            format,
            width,
            height,
            planes,
            matrix,
        }
    }

    pub fn frame(&self) -> Frame<'_> {
        let plane = |i: usize| {
            let (data, stride) = &self.planes[i.min(self.planes.len() - 1)];
            Plane {
                data,
                stride: *stride,
            }
        };
        Frame {
            format: self.format,
            width: self.width,
            height: self.height,
            planes: [plane(0), plane(1), plane(2)],
            matrix: self.matrix,
        }
    }

    pub fn frame_mut(&mut self) -> FrameMut<'_> {
        let mut planes = self.planes.iter_mut().map(|(d, s)| (d.as_mut_slice(), *s));
        let first = planes.next().expect("every format has a plane");
        let second = planes.next().unwrap_or((&mut [], 0));
        let third = planes.next().unwrap_or((&mut [], 0));
        FrameMut {
            format: self.format,
            width: self.width,
            height: self.height,
            planes: [first, second, third],
            matrix: self.matrix,
        }
    }
}

impl<'a> Frame<'a> {
    /// A view of tightly packed 8-bit RGB pixels.
    pub fn packed_rgb(data: &'a [u8], width: usize, height: usize) -> Frame<'a> {
        let plane = Plane {
            data,
            stride: width * 3,
        };
        Frame {
            format: PixelFormat::Rgb,
            width,
            height,
            planes: [plane, plane, plane],
            matrix: YuvMatrix::BT601_LIMITED,
        }
    }
}

/// A frame being written.
pub struct FrameMut<'a> {
    pub format: PixelFormat,
    pub width: usize,
    pub height: usize,
    pub planes: [(&'a mut [u8], usize); 3],
    pub matrix: YuvMatrix,
}

impl FrameMut<'_> {
    /// The frame's rows before frame row `row` and from it on, each a view
    /// whose planes start at its own first row; size, format and matrix stay
    /// the frame's. `row` is even, so chroma rows go with their luma rows.
    pub(crate) fn split_rows(&mut self, row: usize) -> [FrameMut<'_>; 2] {
        assert!(row.is_multiple_of(2), "frames split at even rows");
        let mut subsample = [1; 3];
        for pass in self.format.passes() {
            subsample[pass.plane] = pass.subsample;
        }
        let mut halves = self
            .planes
            .iter_mut()
            .zip(subsample)
            .map(|((data, stride), sub)| {
                let (top, bottom) = data.split_at_mut((row / sub * *stride).min(data.len()));
                ((top, *stride), (bottom, *stride))
            });
        let mut next = || halves.next().expect("three planes");
        let [(t0, b0), (t1, b1), (t2, b2)] = [next(), next(), next()];
        let view = |planes| FrameMut {
            format: self.format,
            width: self.width,
            height: self.height,
            planes,
            matrix: self.matrix,
        };
        [view([t0, t1, t2]), view([b0, b1, b2])]
    }
}

/// A copy of a frame's bytes, to put back: work done on a frame before the
/// decision to leave it as it was (the denoising, run while the network
/// decides) must then be undone. Kept from frame to frame to spare its
/// allocation.
#[derive(Default)]
pub struct FrameCopy(Vec<u8>);

impl FrameCopy {
    pub fn save(&mut self, frame: &FrameMut) {
        self.0.clear();
        for (data, _) in &frame.planes {
            self.0.extend_from_slice(data);
        }
    }

    /// Puts back the bytes of the frame last saved; `frame` must be that one.
    pub fn restore(&self, frame: &mut FrameMut) {
        let mut at = 0;
        for (data, _) in frame.planes.iter_mut() {
            data.copy_from_slice(&self.0[at..at + data.len()]);
            at += data.len();
        }
    }
}

/// The square the network sees, in pixels of the frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    pub x: usize,
    pub y: usize,
    pub size: usize,
}

impl Crop {
    /// Whether `other` is this square moved or resized by at most 2% of its side:
    /// a followed face's crop from frame to frame, close enough that a lighting
    /// change computed for one serves the other.
    pub fn near(&self, other: Crop) -> bool {
        let tolerance = (self.size / 50).max(1);
        self.x.abs_diff(other.x) <= tolerance
            && self.y.abs_diff(other.y) <= tolerance
            && self.size.abs_diff(other.size) <= tolerance
    }

    /// A square of `size_fraction` of the frame's shorter side centred at
    /// (`cx`, `cy`) in fractions of the frame, moved inside the frame and kept
    /// even so chroma planes align.
    pub fn centred(width: usize, height: usize, cx: f64, cy: f64, size_fraction: f64) -> Crop {
        let short = width.min(height);
        let size = ((short as f64 * size_fraction.clamp(0.05, 1.0)).round() as usize)
            .clamp(2.min(short), short)
            & !1;
        let place = |centre: f64, extent: usize| {
            let x = (centre * extent as f64 - size as f64 / 2.0)
                .round()
                .max(0.0) as usize;
            x.min(extent - size) & !1
        };
        Crop {
            x: place(cx, width),
            y: place(cy, height),
            size,
        }
    }

    /// The same square in the pixels of a plane subsampled by `subsample`.
    fn in_plane(self, subsample: usize) -> Crop {
        Crop {
            x: self.x / subsample,
            y: self.y / subsample,
            size: self.size / subsample,
        }
    }
}

/// Area weights of resampling `n_in` samples to `n_out`: per output sample,
/// the first input index and the weights (summing to 1) of consecutive inputs.
#[derive(Clone, Debug)]
pub struct AreaWeights {
    pub start: Vec<usize>,
    pub weights: Vec<Vec<f32>>,
}

impl AreaWeights {
    pub fn new(n_in: usize, n_out: usize) -> AreaWeights {
        let scale = n_in as f64 / n_out as f64;
        let mut start = Vec::with_capacity(n_out);
        let mut weights = Vec::with_capacity(n_out);
        for i in 0..n_out {
            let (a, b) = (i as f64 * scale, (i + 1) as f64 * scale);
            let first = a.floor() as usize;
            let last = (b.ceil() as usize).min(n_in);
            let w: Vec<f64> = (first..last)
                .map(|j| (b.min(j as f64 + 1.0) - a.max(j as f64)).max(0.0))
                .collect();
            let sum: f64 = w.iter().sum();
            start.push(first);
            weights.push(w.iter().map(|v| (v / sum) as f32).collect());
        }
        AreaWeights { start, weights }
    }
}

/// Area resampling of the `area` (in the plane's pixels) of a plane with `BPP`
/// bytes a pixel, output rows `rows` only: calls `emit` with each output
/// pixel's index from the first of `rows` and the averages of its `BPP` bytes,
/// in raster order.
fn resample<const BPP: usize>(
    plane: &Plane,
    area: Crop,
    w: &AreaWeights,
    rows: Range<usize>,
    mut emit: impl FnMut(usize, &[f32]),
) {
    let res = w.start.len();
    // Vertically first: that pass runs over whole rows of bytes, all lanes at
    // once and vectorised, and leaves only `res` rows for the horizontal pass.
    let mut sums = vec![0f32; area.size * BPP];
    let mut inputs = Vec::new();
    for oy in rows.clone() {
        let (first, wy) = (w.start[oy], &w.weights[oy]);
        inputs.clear();
        inputs.extend((0..wy.len()).map(|k| {
            let start = (area.y + first + k) * plane.stride + area.x * BPP;
            &plane.data[start..start + sums.len()]
        }));
        weighted_sum(&mut sums, &inputs, wy);
        for (ox, (&first, wx)) in w.start.iter().zip(&w.weights).enumerate() {
            let mut pixel = [0f32; BPP];
            for (&wk, src) in wx.iter().zip(sums[first * BPP..].chunks_exact(BPP)) {
                for (p, &s) in pixel.iter_mut().zip(src) {
                    *p += wk * s;
                }
            }
            emit((oy - rows.start) * res + ox, &pixel);
        }
    }
}

/// `sums = Σ weights[k] · rows[k]`, lane by lane, adding the rows in order:
/// the crop's inner loop.
fn weighted_sum(sums: &mut [f32], rows: &[&[u8]], weights: &[f32]) {
    // AVX2 doubles the vectors' width and widens bytes to floats in fewer
    // steps; it cut the crop's time by a fifth (I420) to a half (BGRx) at 720p
    // on the build machine. The default x86-64 target only assumes SSE2, so
    // the same loop is built a second time for AVX2 and chosen at run time
    // (a cached check).
    // Where the CPU has AVX-512, a third build takes 16 lanes a vector.
    #[cfg(target_arch = "x86_64")]
    if has_avx512() {
        // SAFETY: the CPU has AVX-512 F, BW and VL, checked just above.
        return unsafe { weighted_sum_avx512(sums, rows, weights) };
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { weighted_sum_avx2(sums, rows, weights) };
    }
    weighted_sum_portable(sums, rows, weights)
}

/// Whether the CPU has the AVX-512 subsets the AVX-512 builds are built for.
#[cfg(target_arch = "x86_64")]
fn has_avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512bw")
        && std::arch::is_x86_feature_detected!("avx512vl")
}

/// `weighted_sum_portable` built for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn weighted_sum_avx2(sums: &mut [f32], rows: &[&[u8]], weights: &[f32]) {
    weighted_sum_portable(sums, rows, weights)
}

/// `weighted_sum_portable` built for AVX-512.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl")]
fn weighted_sum_avx512(sums: &mut [f32], rows: &[&[u8]], weights: &[f32]) {
    weighted_sum_portable(sums, rows, weights)
}

// Always inlined, so that `weighted_sum_avx2` and `weighted_sum_avx512` hold
// copies built for them.
#[inline(always)]
fn weighted_sum_portable(sums: &mut [f32], rows: &[&[u8]], weights: &[f32]) {
    // A block of lanes at a time through all the rows, rather than one row at
    // a time: the frame comes from memory, and this asks for a cache line of
    // every row at once, while the block's sums stay in registers or L1.
    const BLOCK: usize = 64;
    let whole = sums.len() / BLOCK * BLOCK;
    let (blocks, tail) = sums.split_at_mut(whole);
    for (b, out) in blocks.chunks_exact_mut(BLOCK).enumerate() {
        let mut block = [0f32; BLOCK];
        for (row, &w) in rows.iter().zip(weights) {
            add_weighted(&mut block, &row[b * BLOCK..(b + 1) * BLOCK], w);
        }
        out.copy_from_slice(&block);
    }
    tail.fill(0.0);
    for (row, &w) in rows.iter().zip(weights) {
        add_weighted(tail, &row[whole..], w);
    }
}

/// `sums += w · src`, lane by lane.
#[inline(always)]
fn add_weighted(sums: &mut [f32], src: &[u8], w: f32) {
    for (s, &p) in sums.iter_mut().zip(src) {
        *s += w * p as f32;
    }
}

/// Crops of this side or more are resampled on two threads, each half the
/// output's rows: at 720p the crop reads 0.8 MB from memory in about 0.3 ms
/// on one thread, and handing half to another costs about 20 µs
/// (`cargo run --release --example paste_speed`).
const SPLIT_CROP: usize = 480;

/// The crop resampled to `res`×`res`, as planar sRGB in [0, 1] (3 × res × res).
pub fn sample_crop(frame: &Frame, crop: Crop, res: usize) -> Vec<f32> {
    let split = if crop.size >= SPLIT_CROP {
        res / 2
    } else {
        res
    };
    sample_crop_split(frame, crop, res, split)
}

/// [`sample_crop`], its output rows from `split` on another thread (none where
/// `split` is `res`).
fn sample_crop_split(frame: &Frame, crop: Crop, res: usize, split: usize) -> Vec<f32> {
    let n = res * res;
    // R, G, B or Y, Cb, Cr in 8-bit units, planar.
    let mut out = vec![0f32; 3 * n];
    let [first, second, third] = planes_mut(&mut out, n);
    let [(r, r_rest), (g, g_rest), (b, b_rest)] =
        [first, second, third].map(|plane| plane.split_at_mut(split * res));
    let (top, bottom) = ([r, g, b], [r_rest, g_rest, b_rest]);
    // Per plane pass, its weights: computed once, read by both halves.
    let weights: Vec<AreaWeights> = frame
        .format
        .passes()
        .iter()
        .map(|pass| AreaWeights::new(crop.in_plane(pass.subsample).size, res))
        .collect();
    if split < res {
        beside(
            || sample_rows(frame, crop, &weights, split..res, bottom),
            || sample_rows(frame, crop, &weights, 0..split, top),
        );
    } else {
        sample_rows(frame, crop, &weights, 0..res, top);
    }
    if frame.format.is_yuv() {
        // Averaging Y, Cb and Cr and then converting equals averaging RGB: the
        // conversion is affine.
        for i in 0..n {
            let rgb = frame.matrix.to_rgb(out[i], out[n + i], out[2 * n + i]);
            for (c, v) in rgb.into_iter().enumerate() {
                out[c * n + i] = v;
            }
        }
    } else {
        out.iter_mut().for_each(|v| *v /= 255.0);
    }
    out
}

/// The three planes of `n` values of a planar image.
fn planes_mut(image: &mut [f32], n: usize) -> [&mut [f32]; 3] {
    let (first, rest) = image.split_at_mut(n);
    let (second, third) = rest.split_at_mut(n);
    [first, second, third]
}

/// Output rows `rows` of the crop resampled with `weights` (one a plane pass,
/// in the order of the format's passes), in 8-bit units, into `out`'s three
/// planes (R, G, B or Y, Cb, Cr) of those rows.
fn sample_rows(
    frame: &Frame,
    crop: Crop,
    weights: &[AreaWeights],
    rows: Range<usize>,
    mut out: [&mut [f32]; 3],
) {
    for (pass, w) in frame.format.passes().iter().zip(weights) {
        let area = crop.in_plane(pass.subsample);
        let plane = &frame.planes[pass.plane];
        let emit = |i: usize, pixel: &[f32]| {
            for (lane, &v) in pass.lanes.iter().zip(pixel) {
                if let Some(c) = *lane {
                    out[c][i] = v;
                }
            }
        };
        match pass.lanes.len() {
            1 => resample::<1>(plane, area, w, rows.clone(), emit),
            2 => resample::<2>(plane, area, w, rows.clone(), emit),
            3 => resample::<3>(plane, area, w, rows.clone(), emit),
            4 => resample::<4>(plane, area, w, rows.clone(), emit),
            bpp => unreachable!("no format has {bpp} bytes a pixel"),
        }
    }
}

/// A planar image of 3 × `from` × `from` area-resampled to 3 × `to` × `to`: a
/// smaller view of a crop already made, without a second pass over the frame.
pub fn resample_square(image: &[f32], from: usize, to: usize) -> Vec<f32> {
    // The policy passes the crop it made; a panic here would cross into GStreamer.
    debug_assert_eq!(
        image.len(),
        3 * from * from,
        "not a 3 x {from} x {from} image"
    );
    let weights = AreaWeights::new(from, to);
    let mut rows = vec![0f32; to * from];
    let mut out = vec![0f32; 3 * to * to];
    for (plane, resampled) in image
        .chunks_exact(from * from)
        .zip(out.chunks_exact_mut(to * to))
    {
        // Vertically, whole rows at a time; then along each of the `to` rows.
        rows.fill(0.0);
        for (y, row) in rows.chunks_exact_mut(from).enumerate() {
            let first = weights.start[y];
            for (k, &w) in weights.weights[y].iter().enumerate() {
                let src = &plane[(first + k) * from..][..from];
                row.iter_mut().zip(src).for_each(|(r, &v)| *r += w * v);
            }
        }
        for (row, dst) in rows.chunks_exact(from).zip(resampled.chunks_exact_mut(to)) {
            for (x, d) in dst.iter_mut().enumerate() {
                let first = weights.start[x];
                *d = (weights.weights[x].iter().enumerate())
                    .map(|(k, &w)| w * row[first + k])
                    .sum();
            }
        }
    }
    out
}

/// Rec. 709 luma of pixel `i` of a planar image of `n` pixels a channel.
pub(crate) fn luma(img: &[f32], n: usize, i: usize) -> f32 {
    0.2126 * img[i] + 0.7152 * img[n + i] + 0.0722 * img[2 * n + i]
}

/// Mean luma of a planar sRGB image, 3 × n.
pub fn mean_luma(img: &[f32]) -> f32 {
    let n = img.len() / 3;
    if n == 0 {
        return 0.0;
    }
    (0..n).map(|i| luma(img, n, i)).sum::<f32>() / n as f32
}

/// `x.round().clamp(0.0, 255.0) as u8` (NaN to 0 as there) in operations that
/// vectorise: `f32::round` is a call to libm's `roundf` on the default x86-64
/// target, which lacks SSE4.1's rounding instruction, and a float to integer
/// `as` saturates, which costs a compare and a select per lane.
// Always inlined, like `blend_row_portable`, into the AVX2 build.
#[inline(always)]
fn round_to_u8(x: f32) -> u8 {
    // Clamping first changes nothing, as rounding is monotone and 0 and 255 are
    // whole. Comparisons with NaN fail, so NaN becomes 0.
    let c = if x > 0.0 { x } else { 0.0 };
    let c = if c < 255.0 { c } else { 255.0 };
    // Adding 2^23 leaves nothing below the units, so the sum is c rounded to
    // the nearest whole number, ties to even, and that number is in its low
    // bits. `round` takes ties away from zero instead: where c is exactly half
    // above the even neighbour, add one. (`c - whole` is exact.)
    const SHIFT: f32 = 8_388_608.0;
    let shifted = c + SHIFT;
    let whole = shifted - SHIFT;
    (shifted.to_bits() + u32::from(c - whole == 0.5)) as u8
}

mod change;
mod denoise;
mod gain_field;
pub use change::{FacePlace, GAIN_EPSILON, LightingChange};
pub use denoise::DetailDenoiser;

#[cfg(test)]
mod reference;
#[cfg(test)]
mod tests;
